//! Rasters the photo's fit works on: the G-code's material drawn on a bed grid in mm,
//! Gaussian blur, box downsampling and bilinear sampling with the gradient.
//! Hand-written: kornia-imgproc 0.2.0 blurs only its own image type and samples no
//! gradient, and these loops are a few lines each.

use rayon::prelude::*;

use super::PrintedPath;

/// A row-major grid of values over the bed or the image.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Values, index `row * width + column`.
    pub values: Vec<f32>,
}

/// A raster laid over the bed: cell (i, j) has its centre at
/// `origin_mm + ((i + ½)·res_mm, (j + ½)·res_mm)`.
#[derive(Debug, Clone, PartialEq)]
pub struct BedRaster {
    /// The grid.
    pub raster: Raster,
    /// The bed point at the grid's corner (mm).
    pub origin_mm: [f64; 2],
    /// Cell size (mm).
    pub res_mm: f64,
}

impl BedRaster {
    /// The fraction of each cell covered by printed material (paths as capsules of their
    /// width, anti-aliased over one cell), over the paths' bounding box with `margin_mm`.
    pub fn material(paths: &[PrintedPath], res_mm: f64, margin_mm: f64) -> Self {
        let (lo, hi) = bounds(paths);
        let origin_mm = [lo[0] - margin_mm, lo[1] - margin_mm];
        let width = ((hi[0] - lo[0] + 2.0 * margin_mm) / res_mm).ceil() as usize;
        let height = ((hi[1] - lo[1] + 2.0 * margin_mm) / res_mm).ceil() as usize;
        let mut values = vec![0.0f32; width * height];
        for path in paths {
            draw_capsule(&mut values, width, height, origin_mm, res_mm, path);
        }
        Self { raster: Raster { width, height, values }, origin_mm, res_mm }
    }

    /// The bed point at the centre of cell (i, j) (mm).
    #[inline]
    pub fn centre_mm(&self, i: usize, j: usize) -> [f64; 2] {
        [self.origin_mm[0] + (i as f64 + 0.5) * self.res_mm, self.origin_mm[1] + (j as f64 + 0.5) * self.res_mm]
    }
}

/// The bounding box of the paths' axes (mm).
pub fn bounds(paths: &[PrintedPath]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in paths {
        for q in [p.start_mm, p.end_mm] {
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
    }
    (lo, hi)
}

fn draw_capsule(values: &mut [f32], width: usize, height: usize, origin: [f64; 2], res: f64, path: &PrintedPath) {
    let half = path.width_mm / 2.0;
    let (a, b) = (path.start_mm, path.end_mm);
    let cell = |x: f64, k: usize| ((x - origin[k]) / res).floor();
    let i0 = cell(a[0].min(b[0]) - half - res, 0).max(0.0) as usize;
    let i1 = (cell(a[0].max(b[0]) + half + res, 0).max(0.0) as usize).min(width.saturating_sub(1));
    let j0 = cell(a[1].min(b[1]) - half - res, 1).max(0.0) as usize;
    let j1 = (cell(a[1].max(b[1]) + half + res, 1).max(0.0) as usize).min(height.saturating_sub(1));
    for j in j0..=j1 {
        for i in i0..=i1 {
            let p = [origin[0] + (i as f64 + 0.5) * res, origin[1] + (j as f64 + 0.5) * res];
            let cover = ((half - distance_to_segment(p, a, b)) / res + 0.5).clamp(0.0, 1.0) as f32;
            let v = &mut values[j * width + i];
            *v = v.max(cover);
        }
    }
}

/// The normalised Gaussian of width `sigma` over ±⌈3σ⌉ cells.
fn gaussian_kernel(sigma: f64) -> Vec<f32> {
    let radius = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f32> = (-radius..=radius).map(|k| (-(k * k) as f64 / (2.0 * sigma * sigma)).exp() as f32).collect();
    let norm: f32 = kernel.iter().sum();
    kernel.iter().map(|k| k / norm).collect()
}

/// One row blurred by `kernel` (odd length), the row's ends clamped; each value summed in
/// kernel order.
fn blur_line(line: &[f32], kernel: &[f32], out: &mut [f32]) {
    let (w, radius) = (line.len(), kernel.len() / 2);
    let clamped = |i: usize, out: &mut f32| {
        let mut sum = 0.0f32;
        for (k, &kv) in kernel.iter().enumerate() {
            sum += kv * line[(i + k).saturating_sub(radius).min(w - 1)];
        }
        *out = sum;
    };
    if w <= 2 * radius {
        out.iter_mut().enumerate().for_each(|(i, o)| clamped(i, o));
        return;
    }
    // the interior, where the kernel stays inside the row, as one vectorisable pass per tap
    let interior = &mut out[radius..w - radius];
    interior.fill(0.0);
    for (k, &kv) in kernel.iter().enumerate() {
        for (o, &v) in interior.iter_mut().zip(&line[k..k + w - 2 * radius]) {
            *o += kv * v;
        }
    }
    for i in (0..radius).chain(w - radius..w) {
        clamped(i, &mut out[i]);
    }
}

/// Distance from `p` to the segment `a`–`b` (a square root, not `hypot`: bed millimetres
/// neither overflow nor underflow, and `hypot` was a tenth of the photo's calibration).
#[inline]
pub fn distance_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let len2 = d[0] * d[0] + d[1] * d[1];
    let t = if len2 > 0.0 { (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let (dx, dy) = (p[0] - a[0] - t * d[0], p[1] - a[1] - t * d[1]);
    (dx * dx + dy * dy).sqrt()
}

impl Raster {
    /// Separable Gaussian blur of width `sigma` cells, edges clamped; rows in parallel
    /// (each value summed in kernel order, so the result does not depend on the threads).
    pub fn blurred(&self, sigma: f64) -> Raster {
        if sigma < 0.3 {
            return self.clone();
        }
        let kernel = gaussian_kernel(sigma);
        let w = self.width.max(1);
        let mut rows = vec![0.0f32; self.values.len()];
        rows.par_chunks_mut(w).zip(self.values.par_chunks(w)).for_each(|(out, line)| blur_line(line, &kernel, out));
        let mut out = vec![0.0f32; self.values.len()];
        let (radius, last) = ((kernel.len() / 2) as isize, self.height as isize - 1);
        out.par_chunks_mut(w).enumerate().for_each(|(j, out_row)| {
            for (k, &kv) in kernel.iter().enumerate() {
                let source = (j as isize + k as isize - radius).clamp(0, last) as usize;
                for (o, &v) in out_row.iter_mut().zip(&rows[source * w..(source + 1) * w]) {
                    *o += kv * v;
                }
            }
        });
        Raster { width: self.width, height: self.height, values: out }
    }

    /// The mean of each `factor` × `factor` block (a partial block at the right and bottom
    /// edges averages what it has); rows of blocks in parallel.
    pub fn downsampled(&self, factor: usize) -> Raster {
        if factor <= 1 {
            return self.clone();
        }
        let (w, h) = (self.width.div_ceil(factor), self.height.div_ceil(factor));
        let mut values = vec![0.0f32; w * h];
        values.par_chunks_mut(w).enumerate().for_each(|(block_row, out)| {
            let rows = block_row * factor..((block_row + 1) * factor).min(self.height);
            let count_y = rows.len();
            for j in rows {
                for (i, &v) in self.values[j * self.width..(j + 1) * self.width].iter().enumerate() {
                    out[i / factor] += v;
                }
            }
            for (b, o) in out.iter_mut().enumerate() {
                let count_x = ((b + 1) * factor).min(self.width) - b * factor;
                *o /= (count_x * count_y) as f32;
            }
        });
        Raster { width: w, height: h, values }
    }

    /// [`Self::sample`] with (x, y) clamped into the centres' hull: outside, the border's
    /// value and no gradient across the border, so a point that leaves the raster still
    /// counts (as flat border) instead of dropping out of a sum.
    #[inline]
    pub fn sample_clamped(&self, x: f64, y: f64) -> (f64, [f64; 2]) {
        let (hi_x, hi_y) = (self.width as f64 - 0.5 - 1e-9, self.height as f64 - 0.5 - 1e-9);
        let (cx, cy) = (x.clamp(0.5, hi_x), y.clamp(0.5, hi_y));
        let (value, mut grad) = self.sample(cx, cy).unwrap_or((0.0, [0.0; 2]));
        if cx != x {
            grad[0] = 0.0;
        }
        if cy != y {
            grad[1] = 0.0;
        }
        (value, grad)
    }

    /// Bilinear value and gradient (per cell) at (x, y) in cell units with the top-left
    /// cell's corner at 0, 0 (cell centres at +½); `None` outside the centres' hull.
    #[inline]
    pub fn sample(&self, x: f64, y: f64) -> Option<(f64, [f64; 2])> {
        let (fx, fy) = (x - 0.5, y - 0.5);
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (i, j) = (fx as usize, fy as usize);
        if i + 1 >= self.width || j + 1 >= self.height {
            return None;
        }
        let (tx, ty) = (fx - i as f64, fy - j as f64);
        let at = |a: usize, b: usize| f64::from(self.values[b * self.width + a]);
        let (v00, v10, v01, v11) = (at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1));
        let top = v00 + (v10 - v00) * tx;
        let bottom = v01 + (v11 - v01) * tx;
        let value = top + (bottom - top) * ty;
        let gx = (v10 - v00) * (1.0 - ty) + (v11 - v01) * ty;
        let gy = bottom - top;
        Some((value, [gx, gy]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path(a: [f64; 2], b: [f64; 2], w: f64) -> PrintedPath {
        PrintedPath { start_mm: a, end_mm: b, width_mm: w, speed_changes_mm: Vec::new() }
    }

    #[test]
    fn a_drawn_bead_covers_its_area() {
        // a 10 mm × 1 mm capsule: 10 + π/4 mm²
        let r = BedRaster::material(&[path([0.0, 0.0], [10.0, 0.0], 1.0)], 0.02, 1.0);
        let area: f64 = r.raster.values.iter().map(|&v| f64::from(v)).sum::<f64>() * 0.02 * 0.02;
        assert!((area - (10.0 + std::f64::consts::PI / 4.0)).abs() < 0.01, "{area}");
    }

    #[test]
    fn blur_keeps_the_sum_and_downsampling_the_mean() {
        let mut values = vec![0.0f32; 40 * 30];
        values[15 * 40 + 20] = 1.0;
        let r = Raster { width: 40, height: 30, values };
        let b = r.blurred(2.0);
        assert!((b.values.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        let d = r.downsampled(4);
        assert_eq!((d.width, d.height), (10, 8));
        assert!((d.values.iter().sum::<f32>() - 1.0 / 16.0).abs() < 1e-7);
    }

    #[test]
    fn bilinear_sampling_is_exact_on_a_plane() {
        let values = (0..20 * 10).map(|k| (2.0 * (k % 20) as f32) + 3.0 * (k / 20) as f32).collect();
        let r = Raster { width: 20, height: 10, values };
        let (v, g) = r.sample(5.25, 3.75).unwrap();
        assert!((v - (2.0 * 4.75 + 3.0 * 3.25)).abs() < 1e-9);
        assert!((g[0] - 2.0).abs() < 1e-9 && (g[1] - 3.0).abs() < 1e-9);
        assert!(r.sample(0.2, 3.0).is_none() && r.sample(19.9, 3.0).is_none());
    }
}
