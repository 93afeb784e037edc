//! Sampling the photo along and across the line (step 2 of [`super`]), and the small 1-D
//! tools the axis and edge steps share: bilinear interpolation, a Gaussian-derivative
//! filter, sub-sample extrema and a median. All hand-written: kornia-imgproc 0.2.0
//! filters whole images, while these act on a few hundred samples along arbitrary
//! directions; none allocates.

use super::image::GrayImage;

/// A straight line frame in pixels: origin, unit direction d and unit normal n = (−d_y, d_x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisFrame {
    /// Origin (px, image coordinates).
    pub origin_px: [f64; 2],
    /// Unit direction d.
    pub dir: [f64; 2],
    /// Unit normal n (to the right of d in an image with v down).
    pub normal: [f64; 2],
}

impl AxisFrame {
    /// The frame at `origin_px` with direction angle `direction_rad` (image coordinates).
    pub fn new(origin_px: [f64; 2], direction_rad: f64) -> Self {
        let (sin, cos) = direction_rad.sin_cos();
        Self { origin_px, dir: [cos, sin], normal: [-sin, cos] }
    }

    /// The direction angle (rad).
    pub fn direction_rad(&self) -> f64 {
        self.dir[1].atan2(self.dir[0])
    }

    /// Image point at path coordinate `s_px` and lateral coordinate `t_px`.
    #[inline]
    pub fn point(&self, s_px: f64, t_px: f64) -> [f64; 2] {
        [
            self.origin_px[0] + s_px * self.dir[0] + t_px * self.normal[0],
            self.origin_px[1] + s_px * self.dir[1] + t_px * self.normal[1],
        ]
    }
}

/// Where profile samples go: `count` samples from `t0_px` every `dt_px` across the line,
/// each averaged over the path offsets `band_px` (px along d).
#[derive(Debug, Clone, Copy)]
pub struct SampleGrid<'a> {
    /// Lateral coordinate of the first sample (px).
    pub t0_px: f64,
    /// Lateral spacing (px).
    pub dt_px: f64,
    /// Number of lateral samples.
    pub count: usize,
    /// Offsets along the path averaged into each sample (px).
    pub band_px: &'a [f64],
}

/// Bilinear intensity at image point (u, v) (pixel centres at +0.5); `None` outside the
/// square spanned by the pixel centres.
#[inline]
pub fn bilinear(img: &GrayImage, u: f64, v: f64) -> Option<f64> {
    let (x, y) = (u - 0.5, v - 0.5);
    let (max_x, max_y) = ((img.width as f64) - 1.0, (img.height as f64) - 1.0);
    if !(x >= 0.0 && y >= 0.0 && x <= max_x && y <= max_y) {
        return None;
    }
    // x, y ≥ 0: truncation is the floor, without a call to libm's floor
    let (i0, j0) = (x as usize, y as usize);
    let (fx, fy) = (x - i0 as f64, y - j0 as f64);
    let (i1, j1) = ((i0 + 1).min(img.width - 1), (j0 + 1).min(img.height - 1));
    let top = f64::from(img.at(i0, j0)) * (1.0 - fx) + f64::from(img.at(i1, j0)) * fx;
    let bottom = f64::from(img.at(i0, j1)) * (1.0 - fx) + f64::from(img.at(i1, j1)) * fx;
    Some(top * (1.0 - fy) + bottom * fy)
}

/// Fills `out[..grid.count]` with the band-averaged profile across the line at `s_px`;
/// `false` (and `out` partly written) if any sample point lies outside the image.
pub fn sample_across(img: &GrayImage, axis: &AxisFrame, s_px: f64, grid: SampleGrid<'_>, out: &mut [f64]) -> bool {
    let out = &mut out[..grid.count];
    out.fill(0.0);
    let step = [grid.dt_px * axis.normal[0], grid.dt_px * axis.normal[1]];
    for &ds in grid.band_px {
        let first = axis.point(s_px + ds, grid.t0_px);
        if !add_segment(img, first, step, out) {
            return false;
        }
    }
    let weight = 1.0 / grid.band_px.len() as f64;
    out.iter_mut().for_each(|v| *v *= weight);
    true
}

/// Adds the bilinear samples at `first + j · step` to `out[j]`; `false` if the segment
/// leaves the image. The image is convex, so checking both ends checks every sample.
fn add_segment(img: &GrayImage, first: [f64; 2], step: [f64; 2], out: &mut [f64]) -> bool {
    let last_j = out.len().saturating_sub(1) as f64;
    let last = [first[0] + last_j * step[0], first[1] + last_j * step[1]];
    if bilinear(img, first[0], first[1]).is_none() || bilinear(img, last[0], last[1]).is_none() {
        return false;
    }
    let (max_i, max_j) = (img.width - 1, img.height - 1);
    for (j, slot) in out.iter_mut().enumerate() {
        let x = (first[0] - 0.5 + j as f64 * step[0]).max(0.0);
        let y = (first[1] - 0.5 + j as f64 * step[1]).max(0.0);
        let (i0, j0) = ((x as usize).min(max_i), (y as usize).min(max_j));
        let (fx, fy) = ((x - i0 as f64) as f32, (y - j0 as f64) as f32);
        let (i1, j1) = ((i0 + 1).min(max_i), (j0 + 1).min(max_j));
        let (row0, row1) = (&img.pixels[j0 * img.width..], &img.pixels[j1 * img.width..]);
        let top = row0[i0] + (row0[i1] - row0[i0]) * fx;
        let bottom = row1[i0] + (row1[i1] - row1[i0]) * fx;
        *slot += f64::from(top + (bottom - top) * fy);
    }
    true
}

/// Fills `out[..count]` with the profile along the line at lateral offset 0, from
/// `s0_px` every `ds_px`, averaged over the lateral offsets `band_px`; `false` if outside.
pub fn sample_along(
    img: &GrayImage,
    axis: &AxisFrame,
    s0_px: f64,
    ds_px: f64,
    band_px: &[f64],
    out: &mut [f64],
) -> bool {
    let swapped = AxisFrame { origin_px: axis.origin_px, dir: axis.normal, normal: axis.dir };
    let grid = SampleGrid { t0_px: s0_px, dt_px: ds_px, count: out.len(), band_px };
    sample_across(img, &swapped, 0.0, grid, out)
}

/// `count` evenly spaced offsets covering ±`half_px` as the centres of equal sub-intervals.
pub fn band_offsets(half_px: f64, count: usize) -> impl Iterator<Item = f64> {
    let count = count.max(1);
    (0..count).map(move |m| ((m as f64 + 0.5) / count as f64 - 0.5) * 2.0 * half_px)
}

/// Largest radius of a [`DerivativeKernel`] (samples).
const MAX_KERNEL_RADIUS: usize = 24;

/// The weights of a Gaussian-derivative filter, k · exp(−k²/2σ²) for k = 1..radius.
#[derive(Debug, Clone, Copy)]
pub struct DerivativeKernel {
    weights: [f64; MAX_KERNEL_RADIUS],
    radius: usize,
}

impl DerivativeKernel {
    /// The kernel of width σ (samples), cut at 3σ (at most 24 samples).
    pub fn new(sigma_samples: f64) -> Self {
        let radius = ((3.0 * sigma_samples).ceil() as usize).clamp(1, MAX_KERNEL_RADIUS);
        let inv_two_var = 0.5 / (sigma_samples * sigma_samples);
        let weights = std::array::from_fn(|i| {
            let k = (i + 1) as f64;
            if i < radius {
                k * (-k * k * inv_two_var).exp()
            } else {
                0.0
            }
        });
        Self { weights, radius }
    }

    /// Filters `values` into `out` (edges clamped); the scale is arbitrary but fixed.
    pub fn apply(&self, values: &[f64], out: &mut [f64]) {
        let last = values.len().saturating_sub(1);
        for (i, slot) in out.iter_mut().enumerate().take(values.len()) {
            let mut sum = 0.0;
            for (k, weight) in self.weights[..self.radius].iter().enumerate() {
                let k = k + 1;
                sum += weight * (values[(i + k).min(last)] - values[i.saturating_sub(k)]);
            }
            *slot = sum;
        }
    }
}

/// Gaussian-derivative filter of `values` (σ in samples) into `out`, edges clamped.
pub fn gaussian_derivative(values: &[f64], sigma_samples: f64, out: &mut [f64]) {
    DerivativeKernel::new(sigma_samples).apply(values, out);
}

/// Index of the largest `sign · values[i]` over `range` and its sub-sample position
/// (parabola through the three samples around it).
pub fn peak(values: &[f64], range: std::ops::Range<usize>, sign: f64) -> Option<(usize, f64)> {
    let best =
        range.filter(|&i| i < values.len()).max_by(|&i, &j| (sign * values[i]).total_cmp(&(sign * values[j])))?;
    if best == 0 || best + 1 >= values.len() {
        return Some((best, best as f64));
    }
    let (left, mid, right) = (sign * values[best - 1], sign * values[best], sign * values[best + 1]);
    let curvature = left - 2.0 * mid + right;
    let offset = if curvature < 0.0 { (0.5 * (left - right) / curvature).clamp(-0.5, 0.5) } else { 0.0 };
    Some((best, best as f64 + offset))
}

/// Median of `values` (reorders them); NaN when empty.
pub fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mid = values.len() / 2;
    let (_, upper, _) = values.select_nth_unstable_by(mid, f64::total_cmp);
    let upper = *upper;
    if values.len() % 2 == 1 {
        upper
    } else {
        let lower = values[..mid].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lower + upper)
    }
}

/// Mean of `values[range]` (clipped to the slice); NaN when empty.
pub fn mean(values: &[f64], start: usize, end: usize) -> f64 {
    let slice = &values[start.min(values.len())..end.min(values.len())];
    slice.iter().sum::<f64>() / slice.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bilinear_reproduces_a_plane_and_refuses_outside() {
        let pixels = (0..20).map(|k| ((k % 5) as f32) * 0.1 + ((k / 5) as f32) * 0.01).collect();
        let img = GrayImage::new(5, 4, pixels).unwrap();
        // Value at pixel centre (i + 0.5, j + 0.5) is 0.1 i + 0.01 j: a plane, so exact.
        let got = bilinear(&img, 2.25, 1.75).unwrap();
        assert!((got - (0.1 * 1.75 + 0.01 * 1.25)).abs() < 1e-6);
        assert!(bilinear(&img, 0.4, 1.0).is_none() && bilinear(&img, 2.0, 3.6).is_none());
        assert!(bilinear(&img, 4.5, 3.5).is_some(), "the last pixel centre is inside");
    }

    #[test]
    fn derivative_filter_peaks_on_a_step_and_the_peak_is_sub_sample() {
        let values: Vec<f64> = (0..40).map(|i| if (i as f64) < 20.3 { 0.0 } else { 1.0 }).collect();
        let mut d = vec![0.0; 40];
        gaussian_derivative(&values, 2.0, &mut d);
        let (_, x) = peak(&d, 0..40, 1.0).unwrap();
        assert!((x - 20.5).abs() < 0.01, "step between samples 20 and 21: {x}");
    }

    #[test]
    fn median_of_odd_and_even() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }
}
