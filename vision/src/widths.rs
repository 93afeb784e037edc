//! Deposited half-width extraction, paper 003 Sec. 2.4: "the contour with the threshold
//! temperature T_t is applied to extract the left and right deposition half-width
//! w_l(T_t, t) and w_r(T_t, t)" along the critical deposition directions (Sec. 2.2).
//!
//! For a path point p (plane mm) with unit left deposition direction n, the undistorted
//! frame is sampled (bilinear) at H⁻¹(p ± r·n) for r = 0, step, 2·step, … up to a reach;
//! the half-width on each side is the first r where the temperature falls below T_t,
//! placed between the two bracketing samples by linear interpolation. The paper draws a
//! contour of the whole image; sampling only along the deposition directions gives the
//! same crossing for the points asked about, at a fraction of the cost.
//!
//! No width (None) when p itself is below T_t, NaN or outside the frame, or when a side
//! meets NaN, leaves the frame or stays above T_t over the whole reach before crossing.

use crate::frame::ThermalFrame;
use crate::homography::Homography;

/// Width extraction settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WidthParams {
    /// Threshold temperature T_t (°C).
    pub threshold_c: f64,
    /// Sampling step along the deposition direction (mm).
    pub step_mm: f64,
    /// Furthest distance searched on each side (mm).
    pub reach_mm: f64,
}

impl WidthParams {
    /// A 0.02 mm step (≈ 1/7 pixel at 0.14 mm/px) and a 2 mm reach (five nozzle
    /// diameters); T_t must come from the caller (the paper does not state its value).
    pub fn with_threshold(threshold_c: f64) -> Self {
        Self { threshold_c, step_mm: 0.02, reach_mm: 2.0 }
    }
}

/// One width query: a path point and its unit left deposition direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WidthQuery {
    /// Point on the path (world mm).
    pub p_mm: [f64; 2],
    /// Unit left deposition direction n_k.
    pub n_left: [f64; 2],
}

/// Left and right half-widths (mm) at one query point, or None (see module doc).
pub fn half_widths(
    frame: &ThermalFrame,
    plane_to_px: &Homography,
    query: &WidthQuery,
    params: &WidthParams,
) -> Option<(f64, f64)> {
    let centre = sample_plane(frame, plane_to_px, query.p_mm)?;
    if centre < params.threshold_c {
        return None;
    }
    let left = crossing_mm(frame, plane_to_px, query, 1.0, centre, params)?;
    let right = crossing_mm(frame, plane_to_px, query, -1.0, centre, params)?;
    Some((left, right))
}

/// [`half_widths`] for every query, into `out` (cleared, one entry per query).
pub fn extract_widths_into(
    frame: &ThermalFrame,
    plane_to_px: &Homography,
    queries: &[WidthQuery],
    params: &WidthParams,
    out: &mut Vec<Option<(f64, f64)>>,
) {
    out.clear();
    out.extend(queries.iter().map(|q| half_widths(frame, plane_to_px, q, params)));
}

/// Distance from p along `sign`·n to the first threshold crossing.
fn crossing_mm(
    frame: &ThermalFrame,
    plane_to_px: &Homography,
    q: &WidthQuery,
    sign: f64,
    centre_c: f64,
    params: &WidthParams,
) -> Option<f64> {
    let steps = (params.reach_mm / params.step_mm).ceil() as usize;
    let mut prev = centre_c;
    for k in 1..=steps {
        let r = k as f64 * params.step_mm;
        let p = [q.p_mm[0] + sign * r * q.n_left[0], q.p_mm[1] + sign * r * q.n_left[1]];
        let t = sample_plane(frame, plane_to_px, p)?;
        if t < params.threshold_c {
            let frac = (prev - params.threshold_c) / (prev - t);
            return Some(r - params.step_mm + frac * params.step_mm);
        }
        prev = t;
    }
    None
}

/// Bilinear temperature at the pixel of plane point `p`; None outside or on NaN taps.
fn sample_plane(frame: &ThermalFrame, plane_to_px: &Homography, p: [f64; 2]) -> Option<f64> {
    let px = plane_to_px.apply(p);
    bilinear(frame, px[0], px[1])
}

/// Bilinear interpolation at (u, v) (pixel centres at integers); None outside or NaN.
pub fn bilinear(frame: &ThermalFrame, u: f64, v: f64) -> Option<f64> {
    let (w, h) = (frame.width, frame.height);
    if !(u >= 0.0 && v >= 0.0 && u <= (w - 1) as f64 && v <= (h - 1) as f64) {
        return None;
    }
    let (u0, v0) = ((u as usize).min(w - 2), (v as usize).min(h - 2));
    let (fu, fv) = (u - u0 as f64, v - v0 as f64);
    let i = v0 * w + u0;
    let t = &frame.temp_c;
    let (a, b, c, d) = (t[i] as f64, t[i + 1] as f64, t[i + w] as f64, t[i + w + 1] as f64);
    let val = (1.0 - fv) * ((1.0 - fu) * a + fu * b) + fv * ((1.0 - fu) * c + fu * d);
    val.is_finite().then_some(val)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraModel, Distortion};
    use crate::synth::{render_raw_frame, StraightBead};

    fn bead(half_width_mm: f64) -> StraightBead {
        let a = 30f64.to_radians();
        StraightBead {
            origin_mm: [0.3, 0.8],
            dir: [a.cos(), a.sin()],
            half_width_mm,
            edge_mm: 0.08,
            background_c: 60.0,
            amplitude_c: 120.0,
        }
    }

    #[test]
    fn threshold_crossing_recovers_the_bead_half_width_within_0_02_mm() {
        // T_t at the mid level bg + A/2 = 120 °C is crossed exactly at the half width w
        // (logistic edge, see synth::StraightBead), on both sides, along the tilted view.
        let cam = CameraModel::lepton35(Distortion::default());
        let h_plane_to_px = cam.nominal_homography().inverse().unwrap();
        for w in [0.25, 0.4, 0.6] {
            let scene = bead(w);
            let frame = render_raw_frame(&cam, [0.0, 0.0], |p| scene.temp_c(p));
            let n_left = [-scene.dir[1], scene.dir[0]];
            for s in [-4.0, -1.0, 0.0, 2.5, 5.0] {
                let p = [scene.origin_mm[0] + s * scene.dir[0], scene.origin_mm[1] + s * scene.dir[1]];
                let q = WidthQuery { p_mm: p, n_left };
                let (wl, wr) = half_widths(&frame, &h_plane_to_px, &q, &WidthParams::with_threshold(120.0)).unwrap();
                assert!((wl - w).abs() < 0.02 && (wr - w).abs() < 0.02, "w {w} s {s}: {wl} {wr}");
            }
        }
    }

    #[test]
    fn offset_point_gives_unequal_sides_that_sum_to_the_width() {
        // Moving p by δ to the left shortens w_l and lengthens w_r by δ.
        let cam = CameraModel::lepton35(Distortion::default());
        let h = cam.nominal_homography().inverse().unwrap();
        let scene = bead(0.4);
        let frame = render_raw_frame(&cam, [0.0, 0.0], |p| scene.temp_c(p));
        let n_left = [-scene.dir[1], scene.dir[0]];
        let delta = 0.1;
        let p = [scene.origin_mm[0] + delta * n_left[0], scene.origin_mm[1] + delta * n_left[1]];
        let (wl, wr) =
            half_widths(&frame, &h, &WidthQuery { p_mm: p, n_left }, &WidthParams::with_threshold(120.0)).unwrap();
        assert!((wl - 0.3).abs() < 0.02 && (wr - 0.5).abs() < 0.02, "{wl} {wr}");
    }

    #[test]
    fn no_width_below_threshold_outside_or_on_nan() {
        let cam = CameraModel::lepton35(Distortion::default());
        let h = cam.nominal_homography().inverse().unwrap();
        let scene = bead(0.4);
        let mut frame = render_raw_frame(&cam, [0.0, 0.0], |p| scene.temp_c(p));
        let params = WidthParams::with_threshold(120.0);
        let n_left = [-scene.dir[1], scene.dir[0]];
        // Background point: below T_t.
        assert_eq!(half_widths(&frame, &h, &WidthQuery { p_mm: [0.3, 5.0], n_left }, &params), None);
        // Far outside the field of view.
        assert_eq!(half_widths(&frame, &h, &WidthQuery { p_mm: [80.0, 0.8], n_left }, &params), None);
        // NaN frame.
        frame.temp_c.iter_mut().for_each(|t| *t = f32::NAN);
        assert_eq!(half_widths(&frame, &h, &WidthQuery { p_mm: scene.origin_mm, n_left }, &params), None);
    }
}
