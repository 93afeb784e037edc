//! Axis and end refinement (step 1 of [`super`]): the metadata's start point and direction
//! may be off by ~10 px and ~1°, which over 120 mm moves the line by a few of its widths,
//! so the segmenter finds the line itself before it measures anything.
//!
//! Pass 1 samples coarse band-averaged profiles across the nominal axis at
//! [`AXIS_PROFILES`] positions, in a lateral window that grows with the distance from the
//! start to cover the angle slack. In each, the two edges are the extrema of opposite sign
//! of the Gaussian-smoothed derivative; their midpoints are fitted by a straight line
//! (least squares, then two passes dropping residuals beyond 3 robust σ from the MAD).
//! Pass 2 repeats this in a narrow window around the refined axis and also measures the
//! line's contrast and polarity (brighter or darker than the bed). Then the profile
//! along the axis gives both ends (derivative extrema of the right sign near the nominal
//! ends), and the start becomes the origin of the positions.

use super::errors::{EndSearch, LineError};
use super::image::GrayImage;
use super::profile::{band_offsets, gaussian_derivative, mean, median, peak, sample_across, sample_along};
use super::profile::{AxisFrame, SampleGrid};
use super::CheckedGeometry;

/// Number of coarse profiles per pass (a few dozen, spread over the middle 80 % of the line).
pub const AXIS_PROFILES: usize = 32;
/// How far the stated start may be off (px); the metadata's "~10 px" with a margin.
pub const START_SLACK_PX: f64 = 12.0;
/// How far the stated direction may be off (rad); the metadata's "~1°" with a margin.
pub const ANGLE_SLACK_RAD: f64 = 1.5 * std::f64::consts::PI / 180.0;
/// Half-length of the window searched for each line end, along the axis (px); clipped
/// where the photo ends, down to [`MIN_END_WINDOW_PX`].
pub const END_WINDOW_PX: f64 = START_SLACK_PX + 12.0;
/// Shortest end window that can show an end (px): its step is read between 6 px flanks
/// on either side of it.
pub const MIN_END_WINDOW_PX: f64 = 24.0;
/// An edge must stand this many robust σ above the derivative's noise.
const EDGE_SNR: f64 = 6.0;
/// An end must show at least this fraction of the line's contrast.
const END_STEP_FRACTION: f64 = 0.5;
/// Half-length (px) and sub-samples of the band averaged along the path in a coarse profile.
const COARSE_BAND: (f64, usize) = (4.0, 5);
/// Gaussian-derivative σ of the coarse profiles (samples of 1 px).
const COARSE_DERIVATIVE_SIGMA: f64 = 1.5;

/// The line as found: start, direction, length, polarity and contrast.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FoundLine {
    /// Frame whose origin is the refined start and whose direction is the refined axis.
    pub axis: AxisFrame,
    /// Distance between the found ends (px).
    pub length_px: f64,
    /// +1 for a line brighter than the bed, −1 for a darker one.
    pub polarity: f64,
    /// Median intensity step across the line (signed like `polarity`).
    pub contrast: f64,
    /// Profiles that contributed to the final axis fit.
    pub inliers: usize,
}

/// Finds the line near the nominal geometry (see the module doc).
pub fn find_line(img: &GrayImage, geom: &CheckedGeometry) -> Result<FoundLine, LineError> {
    let nominal = AxisFrame::new(geom.start_px, geom.direction_rad);
    let coarse = AxisPass { axis: nominal, half_window_px: geom.half_window_px + START_SLACK_PX, angle_slack: true };
    let (axis1, pass1) = coarse.run(img, geom, None)?;
    let fine = AxisPass { axis: axis1, half_window_px: geom.half_window_px + 8.0, angle_slack: false };
    let (axis2, pass2) = fine.run(img, geom, Some(pass1.polarity))?;
    check_inside(img, &axis2, geom)?;
    let contrast = pass2.contrast;
    let start_px = find_end(img, &axis2, geom, 0.0, pass2.polarity, contrast, "start")?;
    let end_px = find_end(img, &axis2, geom, geom.length_px, -pass2.polarity, contrast, "end")?;
    let origin = axis2.point(start_px, 0.0);
    let axis = AxisFrame { origin_px: origin, ..axis2 };
    Ok(FoundLine { axis, length_px: end_px - start_px, polarity: pass2.polarity, contrast, inliers: pass2.inliers })
}

/// One pass of coarse profiles around `axis`.
struct AxisPass {
    axis: AxisFrame,
    half_window_px: f64,
    angle_slack: bool,
}

/// What a pass learnt besides the axis.
struct PassSummary {
    polarity: f64,
    contrast: f64,
    inliers: usize,
}

/// The edges found in one coarse profile (sample indices, sub-sample).
#[derive(Debug, Clone, Copy)]
struct EdgePair {
    left: f64,
    right: f64,
    polarity: f64,
    contrast: f64,
}

impl AxisPass {
    /// Samples the profiles, finds their edge pairs and fits the midline.
    fn run(
        &self,
        img: &GrayImage,
        geom: &CheckedGeometry,
        polarity: Option<f64>,
    ) -> Result<(AxisFrame, PassSummary), LineError> {
        let band: Vec<f64> = band_offsets(COARSE_BAND.0, COARSE_BAND.1).collect();
        let max_half = self.half_px(geom.length_px).ceil();
        let mut values = vec![f64::NAN; 2 * max_half as usize + 1];
        let mut scratch = vec![0.0; values.len()];
        let mut found = Vec::with_capacity(AXIS_PROFILES);
        for i in 0..AXIS_PROFILES {
            let s_px = geom.length_px * (0.1 + 0.8 * i as f64 / (AXIS_PROFILES - 1) as f64);
            let half = self.half_px(s_px).ceil();
            let count = 2 * half as usize + 1;
            sample_clipped(img, &self.axis, s_px, -half, &band, &mut values[..count]);
            if let Some(pair) = edge_pair(&values[..count], &mut scratch[..count], geom.nominal_width_px) {
                found.push((s_px, -half + 0.5 * (pair.left + pair.right), pair));
            }
        }
        let polarity = polarity.unwrap_or_else(|| majority_polarity(&found));
        found.retain(|(_, _, pair)| pair.polarity == polarity);
        let min_found = (AXIS_PROFILES / 2).max(8);
        if found.len() < min_found {
            let reason = format!("at least {min_found} with the same polarity are needed");
            return Err(LineError::NoLine { found: found.len(), tried: AXIS_PROFILES, reason });
        }
        let s: Vec<f64> = found.iter().map(|f| f.0).collect();
        let t: Vec<f64> = found.iter().map(|f| f.1).collect();
        let (line, inliers) = fit_line_robust(&s, &t).ok_or_else(|| LineError::NoLine {
            found: found.len(),
            tried: AXIS_PROFILES,
            reason: "their midpoints do not lie on a straight line".into(),
        })?;
        let mut contrasts: Vec<f64> = found.iter().map(|f| f.2.contrast).collect();
        let summary = PassSummary { polarity, contrast: median(&mut contrasts), inliers };
        Ok((self.shifted(line), summary))
    }

    /// Half-width of the window at path coordinate `s_px`.
    fn half_px(&self, s_px: f64) -> f64 {
        let slack = if self.angle_slack { s_px.abs() * ANGLE_SLACK_RAD.tan() } else { 0.0 };
        self.half_window_px + slack
    }

    /// The axis moved onto the fitted midline t = c0 + c1·s.
    fn shifted(&self, [c0, c1]: [f64; 2]) -> AxisFrame {
        let a = &self.axis;
        let dir = [a.dir[0] + c1 * a.normal[0], a.dir[1] + c1 * a.normal[1]];
        AxisFrame::new(a.point(0.0, c0), dir[1].atan2(dir[0]))
    }
}

/// Fills `out` with the coarse profile from `t0_px` at 1 px; NaN where it leaves the image.
fn sample_clipped(img: &GrayImage, axis: &AxisFrame, s_px: f64, t0_px: f64, band: &[f64], out: &mut [f64]) {
    for (j, slot) in out.iter_mut().enumerate() {
        let grid = SampleGrid { t0_px: t0_px + j as f64, dt_px: 1.0, count: 1, band_px: band };
        let mut one = [0.0];
        *slot = if sample_across(img, axis, s_px, grid, &mut one) { one[0] } else { f64::NAN };
    }
}

/// The strongest rising and falling edge of a coarse profile, if both are clear and the
/// distance between them is plausible for the nominal width.
fn edge_pair(values: &[f64], scratch: &mut [f64], nominal_width_px: f64) -> Option<EdgePair> {
    let (start, end) = longest_finite_run(values)?;
    let run = &values[start..end];
    let margin = (3.0 * COARSE_DERIVATIVE_SIGMA).ceil() as usize;
    if run.len() < 2 * margin + 4 {
        return None;
    }
    let derivative = &mut scratch[..run.len()];
    gaussian_derivative(run, COARSE_DERIVATIVE_SIGMA, derivative);
    let inner = margin..run.len() - margin;
    let (rise, rise_x) = peak(derivative, inner.clone(), 1.0)?;
    let (fall, fall_x) = peak(derivative, inner, -1.0)?;
    let (strength, separation) = (derivative[rise].min(-derivative[fall]), (fall_x - rise_x).abs());
    let noise = flank_noise(derivative, rise_x.min(fall_x), rise_x.max(fall_x));
    let plausible = (0.3 * nominal_width_px..=3.0 * nominal_width_px).contains(&separation);
    if strength < EDGE_SNR * noise || !plausible {
        return None;
    }
    let (left, right) = (rise_x.min(fall_x), rise_x.max(fall_x));
    let polarity = if rise_x < fall_x { 1.0 } else { -1.0 };
    let contrast = step_across(run, left, right);
    Some(EdgePair { left: left + start as f64, right: right + start as f64, polarity, contrast })
}

/// Robust σ (1.4826 · median |D|) of the derivative outside the bar and its edge responses,
/// or of all samples when the flanks are too short.
fn flank_noise(derivative: &[f64], left: f64, right: f64) -> f64 {
    let reach = 3.0 * COARSE_DERIVATIVE_SIGMA + 4.0;
    let outside = |i: &usize| (*i as f64) < left - reach || (*i as f64) > right + reach;
    let mut magnitudes: Vec<f64> = (0..derivative.len()).filter(outside).map(|i| derivative[i].abs()).collect();
    if magnitudes.len() < 8 {
        magnitudes = derivative.iter().map(|d| d.abs()).collect();
    }
    1.4826 * median(&mut magnitudes)
}

/// Mean inside the bar minus the mean of both flanks (samples of 1 px).
fn step_across(run: &[f64], left: f64, right: f64) -> f64 {
    let (l, r) = (left.round() as usize, right.round() as usize);
    let inside = mean(run, l + 3, r.saturating_sub(2));
    let flanks = 0.5 * (mean(run, l.saturating_sub(10), l.saturating_sub(4)) + mean(run, r + 5, r + 11));
    let inside = if inside.is_finite() { inside } else { run[(l + r) / 2] };
    inside - flanks
}

/// The longest run of finite samples, as a half-open index range.
fn longest_finite_run(values: &[f64]) -> Option<(usize, usize)> {
    let mut best: Option<(usize, usize)> = None;
    let mut start = None;
    for (i, v) in values.iter().chain(std::iter::once(&f64::NAN)).enumerate() {
        match (v.is_finite(), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                if best.is_none_or(|(bs, be)| i - s > be - bs) {
                    best = Some((s, i));
                }
                start = None;
            }
            _ => {}
        }
    }
    best
}

/// The polarity most profiles agree on (+1 when tied).
fn majority_polarity(found: &[(f64, f64, EdgePair)]) -> f64 {
    let bright = found.iter().filter(|f| f.2.polarity > 0.0).count();
    if 2 * bright >= found.len() {
        1.0
    } else {
        -1.0
    }
}

/// Least-squares line t = c0 + c1·s, refitted twice without residuals beyond 3 robust σ
/// (σ from the MAD, at least 0.5 px so that a perfect fit does not reject everything).
pub fn fit_line_robust(s: &[f64], t: &[f64]) -> Option<([f64; 2], usize)> {
    let mut keep = vec![true; s.len()];
    let mut line = fit_line(s, t, &keep)?;
    for _ in 0..2 {
        let mut residuals: Vec<f64> = s.iter().zip(t).map(|(&s, &t)| (t - line[0] - line[1] * s).abs()).collect();
        let limit = 3.0 * (1.4826 * median(&mut residuals.clone())).max(0.5 / 3.0);
        for (k, r) in keep.iter_mut().zip(residuals.iter_mut()) {
            *k = *r <= limit;
        }
        line = fit_line(s, t, &keep)?;
    }
    Some((line, keep.iter().filter(|&&k| k).count()))
}

/// Ordinary least squares of t on s over the kept points; `None` with fewer than 3.
fn fit_line(s: &[f64], t: &[f64], keep: &[bool]) -> Option<[f64; 2]> {
    let points = || s.iter().zip(t).zip(keep).filter(|(_, &k)| k).map(|(p, _)| p);
    let n = points().count() as f64;
    if n < 3.0 {
        return None;
    }
    let (s_mean, t_mean) = (points().map(|(s, _)| s).sum::<f64>() / n, points().map(|(_, t)| t).sum::<f64>() / n);
    let sxx: f64 = points().map(|(s, _)| (s - s_mean).powi(2)).sum();
    let sxt: f64 = points().map(|(s, t)| (s - s_mean) * (t - t_mean)).sum();
    (sxx > 0.0).then(|| [t_mean - sxt / sxx * s_mean, sxt / sxx])
}

/// Checks that the rectangle the segmenter samples (the line from its stated start to its
/// stated length, the lateral window with a margin) lies inside the image; the ends'
/// search windows beyond it are clipped where the photo ends ([`find_end`]).
fn check_inside(img: &GrayImage, axis: &AxisFrame, geom: &CheckedGeometry) -> Result<(), LineError> {
    let margin_px = geom.half_window_px + 2.0;
    for s_px in [0.0, geom.length_px] {
        for t_px in [-margin_px, margin_px] {
            let [u, v] = axis.point(s_px, t_px);
            let inside = u >= 0.5 && v >= 0.5 && u <= img.width as f64 - 0.5 && v <= img.height as f64 - 0.5;
            if !inside {
                let (width, height, s_mm) = (img.width, img.height, s_px / geom.px_per_mm);
                return Err(LineError::LeavesFrame { s_mm, margin_px, u_px: u, v_px: v, width, height });
            }
        }
    }
    Ok(())
}

/// The range of path coordinates (px) along `axis` over which the points at every
/// lateral offset of `offsets_px` lie between the image's outer pixel centres.
fn inside_range(img: &GrayImage, axis: &AxisFrame, offsets_px: &[f64]) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for &t_px in offsets_px {
        let p0 = axis.point(0.0, t_px);
        for (c, side) in [(0, img.width), (1, img.height)] {
            let (min, max) = (0.5, side as f64 - 0.5);
            if axis.dir[c].abs() < 1e-12 {
                if p0[c] < min || p0[c] > max {
                    return (0.0, -1.0);
                }
                continue;
            }
            let (s1, s2) = ((min - p0[c]) / axis.dir[c], (max - p0[c]) / axis.dir[c]);
            (lo, hi) = (lo.max(s1.min(s2)), hi.min(s1.max(s2)));
        }
    }
    (lo, hi)
}

/// The path coordinate (px) of the line end near `s_nominal_px`, where the intensity
/// along the axis changes with the sign `derivative_sign` (+1 entering a bright line or
/// leaving a dark one) by at least half the line's contrast.
fn find_end(
    img: &GrayImage,
    axis: &AxisFrame,
    geom: &CheckedGeometry,
    s_nominal_px: f64,
    derivative_sign: f64,
    contrast: f64,
    which: &'static str,
) -> Result<f64, LineError> {
    const DS_PX: f64 = 0.5;
    let band: Vec<f64> = band_offsets(0.25 * geom.nominal_width_px, 5).collect();
    // The window, clipped (to whole steps, a step inside) where the photo ends.
    let (inside_lo, inside_hi) = inside_range(img, axis, &band);
    let s0_px = (s_nominal_px - END_WINDOW_PX).max(inside_lo + DS_PX);
    let s1_px = (s_nominal_px + END_WINDOW_PX).min(inside_hi - DS_PX);
    let count = if s1_px > s0_px { ((s1_px - s0_px) / DS_PX) as usize + 1 } else { 0 };
    let (mut values, mut derivative) = (vec![0.0; count], vec![0.0; count]);
    let window_mm = END_WINDOW_PX / geom.px_per_mm;
    let mismatch =
        |found| LineError::LengthMismatch { which, window_mm, found, length_mm: geom.length_px / geom.px_per_mm };
    let contrast = contrast.abs();
    let flank = (6.0 / DS_PX) as usize;
    let inside_px = count as f64 * DS_PX;
    if inside_px < MIN_END_WINDOW_PX || !sample_along(img, axis, s0_px, DS_PX, &band, &mut values) {
        return Err(mismatch(EndSearch::WindowClipped { inside_px, needed_px: MIN_END_WINDOW_PX }));
    }
    gaussian_derivative(&values, 2.0, &mut derivative);
    let at_border = EndSearch::AtWindowBorder { contrast };
    let (index, x) = peak(&derivative, flank..count - flank, derivative_sign).ok_or(mismatch(at_border))?;
    // A peak on the searched range's first sample has no flank before it inside the
    // window: the change goes on beyond the window, no end is inside it.
    if index == flank {
        return Err(mismatch(at_border));
    }
    let after = mean(&values, index + flank, index + 2 * flank);
    let before = mean(&values, index.saturating_sub(2 * flank), index - flank);
    let step = (after - before) * derivative_sign;
    if !step.is_finite() {
        return Err(mismatch(at_border));
    }
    if step < END_STEP_FRACTION * contrast {
        return Err(mismatch(EndSearch::WeakStep { step, contrast }));
    }
    Ok(s0_px + x * DS_PX)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robust_line_ignores_outliers() {
        // t = 3 + 0.02 s with two midpoints 20 px off (a blob, a scratch): both dropped.
        let s: Vec<f64> = (0..30).map(|i| 100.0 * i as f64).collect();
        let mut t: Vec<f64> = s.iter().map(|s| 3.0 + 0.02 * s).collect();
        t[4] += 20.0;
        t[17] -= 20.0;
        let ([c0, c1], inliers) = fit_line_robust(&s, &t).unwrap();
        assert!((c0 - 3.0).abs() < 1e-9 && (c1 - 0.02).abs() < 1e-12);
        assert_eq!(inliers, 28);
    }

    /// A bright bar 200 px long and 10 px wide on a dark bed, from (40, 20) along +x.
    fn bar() -> GrayImage {
        let (w, h) = (300, 40);
        let lit = |i: usize, j: usize| (40..240).contains(&i) && (15..25).contains(&j);
        GrayImage::new(w, h, (0..w * h).map(|k| if lit(k % w, k / w) { 0.8 } else { 0.2 }).collect()).unwrap()
    }

    fn bar_geometry(length_mm: f64) -> super::super::LineGeometry {
        super::super::LineGeometry {
            start_px: [40.0, 20.0],
            direction_rad: 0.0,
            length_mm,
            px_per_mm: 10.0,
            nominal_width_mm: 1.0,
        }
    }

    #[test]
    fn an_end_found_at_the_window_border_says_so_instead_of_a_nan_step() {
        // The stated length puts the end 19 px past the bar's: the end's window (±24 px)
        // starts 5 px before the real end, whose edge is strongest on the first sample
        // searched (6 px in), with no flank before it. The step was NaN in the message.
        let img = bar();
        let geom = CheckedGeometry::new(&img, &bar_geometry(21.9), 0.05).unwrap();
        let err = find_line(&img, &geom).unwrap_err();
        let LineError::LengthMismatch { which: "end", found: EndSearch::AtWindowBorder { contrast }, .. } = err else {
            panic!("{err:?}")
        };
        assert!((contrast - 0.6).abs() < 1e-6, "{contrast}");
        let text = err.to_string();
        assert!(!text.contains("NaN") && text.contains("half the line's contrast (0.300)"), "{text}");
        // The right length finds both ends.
        let geom = CheckedGeometry::new(&img, &bar_geometry(20.0), 0.05).unwrap();
        let line = find_line(&img, &geom).unwrap();
        assert!((line.length_px - 200.0).abs() < 0.5, "{}", line.length_px);
    }

    #[test]
    fn longest_run_skips_nans() {
        let v = [f64::NAN, 1.0, 2.0, f64::NAN, 1.0, 2.0, 3.0, f64::NAN];
        assert_eq!(longest_finite_run(&v), Some((4, 7)));
        assert_eq!(longest_finite_run(&[f64::NAN]), None);
    }
}
