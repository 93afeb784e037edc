//! Geometric corner vertices from the two bead ridges, for the correspondences of eq. 27
//! (paper 003 Sec. 2.3).
//!
//! The paper pairs the corner its detector (Faster R-CNN) finds with the CAD corner and
//! does not say where inside the detected box the corner point lies. Our hot-spot
//! detector ([`crate::corners`]) returns the heat peak, and the peak is not at the CAD
//! vertex: material piles up inside a corner, so the hottest point sits up to ~0.5 mm
//! (3-4 px) inside it along the bisector, by an amount that varies with the corner angle
//! and its age. Pairing the peak with the CAD vertex biases H(i) by a few tenths of a
//! millimetre, i.e. ~10 ms at 20 mm/s in eq. 30 (measured on the virtual printer: peak −
//! vertex up to 2.5 px, systematic in sign per corner).
//!
//! What we do instead: locate the vertex geometrically. Each arm of the corner is a
//! straight bead whose temperature ridge runs along the path; away from the bulge the
//! ridge is centred on the path. For each arm we read cross-sections of the undistorted
//! frame perpendicular to the arm at distances `s` from the corner (far enough that the
//! other arm is at least `min_arm_gap_mm` away, up to `span_mm` further), take the
//! sub-pixel ridge maximum of each (least-squares parabola over ±1.5 px of the hottest
//! sample), fit a straight line through them (total least squares), and intersect the two
//! lines. Straight plane lines stay straight in the undistorted image (a homography), so
//! the intersection is the image of the path vertex (the planner's 0.05 mm blend is
//! negligible), independent of the bulge. The arm directions come from the CAD path
//! through the nominal mount (the caller's prediction); the fitted lines correct them.
//! Two passes: the second starts from the first intersection, which puts the sampled
//! cross-sections onto the ridges.

use crate::frame::ThermalFrame;
use crate::widths::bilinear;

/// Settings of [`vertex_from_ridges`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VertexParams {
    /// Cross-sections start where the two arms are at least this far apart (mm), so the
    /// other arm's heat does not pull the ridge.
    pub min_arm_gap_mm: f64,
    /// ... and at least this far from the vertex (mm), beyond the corner bulge.
    pub min_offset_mm: f64,
    /// Length of each arm read, from the first cross-section (mm).
    pub span_mm: f64,
    /// Spacing of the cross-sections along the arm (mm).
    pub step_mm: f64,
    /// Half length of each cross-section (px).
    pub half_profile_px: f64,
    /// A ridge must stand this much above both ends of its cross-section (°C).
    pub min_prominence_c: f64,
    /// Ridge points needed per arm.
    pub min_points: usize,
    /// The vertex may lie at most this far from the starting point (px).
    pub max_shift_px: f64,
}

impl VertexParams {
    /// Sized for the Lepton at ~0.15 mm/px and 0.45 mm beads whose heat has spread to
    /// σ ≈ 0.3-0.4 mm: 1.2 mm between arms leaves the other arm's tail below 1 % at the
    /// ridge; 0.7 mm clears the bulge.
    pub fn defaults() -> Self {
        Self {
            min_arm_gap_mm: 1.2,
            min_offset_mm: 0.7,
            span_mm: 1.5,
            step_mm: 0.1,
            half_profile_px: 3.0,
            min_prominence_c: 2.0,
            min_points: 6,
            max_shift_px: 6.0,
        }
    }

    /// Distance of the first cross-section from the vertex (mm) for arms whose directions
    /// have cosine `cos_between`: where the arms are `min_arm_gap_mm` apart
    /// (gap = 2 s sin(θ/2)), and at least `min_offset_mm`.
    pub fn first_offset_mm(&self, cos_between: f64) -> f64 {
        let half_sin = ((1.0 - cos_between) / 2.0).sqrt().max(1e-6);
        self.min_offset_mm.max(self.min_arm_gap_mm / (2.0 * half_sin))
    }

    /// How far along each arm the cross-sections reach (mm): a corner can be placed only
    /// once both arms are printed (and visible) this far from it.
    pub fn arm_reach_mm(&self, cos_between: f64) -> f64 {
        self.first_offset_mm(cos_between) + self.span_mm
    }
}

/// The two arms of a corner as seen in the undistorted image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerArms {
    /// Unit image directions of the two arms, pointing away from the vertex.
    pub dirs: [[f64; 2]; 2],
    /// Image scale along each arm (px per plane mm).
    pub px_per_mm: [f64; 2],
}

impl CornerArms {
    /// Arms from the predicted vertex pixel and the predicted pixels of one point on
    /// each arm, `arm_mm` along it; None when a point coincides with the vertex.
    pub fn from_points(vertex_px: [f64; 2], arm_px: [[f64; 2]; 2], arm_mm: f64) -> Option<Self> {
        let mut dirs = [[0.0; 2]; 2];
        let mut px_per_mm = [0.0; 2];
        for k in 0..2 {
            let d = [arm_px[k][0] - vertex_px[0], arm_px[k][1] - vertex_px[1]];
            let len = d[0].hypot(d[1]);
            if len.is_nan() || len <= 1e-9 {
                return None;
            }
            dirs[k] = [d[0] / len, d[1] / len];
            px_per_mm[k] = len / arm_mm;
        }
        Some(Self { dirs, px_per_mm })
    }

    /// Sine of the angle between the arms (0 for a straight or folded path).
    fn sin_between(&self) -> f64 {
        cross(self.dirs[0], self.dirs[1]).abs()
    }

    /// Cosine of the angle between the arms.
    fn cos_between(&self) -> f64 {
        dot(self.dirs[0], self.dirs[1])
    }
}

/// The image of the path vertex as the intersection of the two ridge lines, starting
/// near `start_px` (e.g. the heat peak); None when an arm has too few ridge points, the
/// lines are nearly parallel or the vertex moves more than `max_shift_px`.
pub fn vertex_from_ridges(
    image: &ThermalFrame,
    start_px: [f64; 2],
    arms: &CornerArms,
    params: &VertexParams,
) -> Option<[f64; 2]> {
    if arms.sin_between() < 0.2 {
        return None;
    }
    let first = intersect_ridges(image, start_px, arms, params)?;
    let second = intersect_ridges(image, first.0, &first.1, params)?;
    let shift = (second.0[0] - start_px[0]).hypot(second.0[1] - start_px[1]);
    (shift <= params.max_shift_px).then_some(second.0)
}

/// One pass: ridge lines of both arms from `apex_px`, their intersection and the arms
/// re-aimed along the fitted lines.
fn intersect_ridges(
    image: &ThermalFrame,
    apex_px: [f64; 2],
    arms: &CornerArms,
    params: &VertexParams,
) -> Option<([f64; 2], CornerArms)> {
    let s0_mm = params.first_offset_mm(arms.cos_between());
    let mut lines = [([0.0; 2], [0.0; 2]); 2];
    for k in 0..2 {
        lines[k] = ridge_line(image, apex_px, arms.dirs[k], arms.px_per_mm[k], s0_mm, params)?;
    }
    let vertex = intersect(lines[0], lines[1])?;
    let mut refined = *arms;
    for (k, (_, dir)) in lines.iter().enumerate() {
        // Keep the fitted direction pointing away from the vertex.
        refined.dirs[k] = if dot(*dir, arms.dirs[k]) >= 0.0 { *dir } else { [-dir[0], -dir[1]] };
    }
    Some((vertex, refined))
}

/// Total-least-squares line (point, unit direction) through the ridge maxima of one arm.
fn ridge_line(
    image: &ThermalFrame,
    apex_px: [f64; 2],
    dir: [f64; 2],
    px_per_mm: f64,
    s0_mm: f64,
    params: &VertexParams,
) -> Option<([f64; 2], [f64; 2])> {
    let normal = [-dir[1], dir[0]];
    let steps = (params.span_mm / params.step_mm).round() as usize;
    let (mut n, mut sum, mut sxx, mut syy, mut sxy) = (0usize, [0.0; 2], 0.0, 0.0, 0.0);
    let mut points = [[0.0; 2]; 64];
    for i in 0..=steps.min(63) {
        let s_px = (s0_mm + i as f64 * params.step_mm) * px_per_mm;
        let centre = [apex_px[0] + s_px * dir[0], apex_px[1] + s_px * dir[1]];
        if let Some(r) = ridge_offset_px(image, centre, normal, params) {
            let p = [centre[0] + r * normal[0], centre[1] + r * normal[1]];
            points[n] = p;
            sum = [sum[0] + p[0], sum[1] + p[1]];
            n += 1;
        }
    }
    if n < params.min_points {
        return None;
    }
    let mean = [sum[0] / n as f64, sum[1] / n as f64];
    for p in &points[..n] {
        let (dx, dy) = (p[0] - mean[0], p[1] - mean[1]);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    // Principal axis of the scatter: angle ½·atan2(2 sxy, sxx − syy).
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Some((mean, [angle.cos(), angle.sin()]))
}

/// Sub-pixel offset of the temperature maximum along `normal` from `centre` (px), by a
/// least-squares parabola over ±1.5 px around the hottest of the samples every 0.5 px.
fn ridge_offset_px(image: &ThermalFrame, centre: [f64; 2], normal: [f64; 2], params: &VertexParams) -> Option<f64> {
    const STEP_PX: f64 = 0.5;
    const MAX_SAMPLES: usize = 41;
    let half = ((params.half_profile_px / STEP_PX).round() as usize).min(MAX_SAMPLES / 2);
    let count = 2 * half + 1;
    let mut profile = [0.0; MAX_SAMPLES];
    for (j, slot) in profile[..count].iter_mut().enumerate() {
        let r = (j as f64 - half as f64) * STEP_PX;
        *slot = bilinear(image, centre[0] + r * normal[0], centre[1] + r * normal[1])?;
    }
    let profile = &profile[..count];
    let (peak, &peak_c) = profile.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    let fit_half = 3usize;
    if peak < fit_half || peak + fit_half >= count {
        return None;
    }
    if peak_c - profile[0] < params.min_prominence_c || peak_c - profile[count - 1] < params.min_prominence_c {
        return None;
    }
    let vertex = parabola_vertex(&profile[peak - fit_half..=peak + fit_half])?;
    let offset = (peak as f64 - half as f64 + vertex) * STEP_PX;
    (vertex.abs() <= fit_half as f64).then_some(offset)
}

/// Vertex (in samples from the centre) of the least-squares parabola through an odd
/// number of equally spaced samples.
fn parabola_vertex(y: &[f64]) -> Option<f64> {
    let m = (y.len() / 2) as f64;
    // Orthogonal basis on x = −m..m: 1, x, x² − c with c = mean(x²).
    let xs = || (0..y.len()).map(|j| j as f64 - m);
    let c = xs().map(|x| x * x).sum::<f64>() / y.len() as f64;
    let (mut b_num, mut b_den, mut a_num, mut a_den) = (0.0, 0.0, 0.0, 0.0);
    for (x, &v) in xs().zip(y) {
        b_num += x * v;
        b_den += x * x;
        let q = x * x - c;
        a_num += q * v;
        a_den += q * q;
    }
    let (a, b) = (a_num / a_den, b_num / b_den);
    (a < 0.0).then(|| -b / (2.0 * a))
}

/// Intersection of two lines given as (point, direction); None when nearly parallel.
fn intersect(l1: ([f64; 2], [f64; 2]), l2: ([f64; 2], [f64; 2])) -> Option<[f64; 2]> {
    let denom = cross(l1.1, l2.1);
    if denom.abs() < 0.2 {
        return None;
    }
    let d = [l2.0[0] - l1.0[0], l2.0[1] - l1.0[1]];
    let t = cross(d, l2.1) / denom;
    Some([l1.0[0] + t * l1.1[0], l1.0[1] + t * l1.1[1]])
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraModel, Distortion};
    use crate::synth::{add_noise, render_raw_frame, HotPolyline};

    /// A 60° corner at `vertex` whose heat peak sits `bulge_mm` inside along the bisector.
    fn scene(vertex: [f64; 2], bulge_mm: f64) -> (HotPolyline, [f64; 2]) {
        let a = [vertex[0] - 3.0, vertex[1] - 5.196];
        let b = [vertex[0] + 3.0, vertex[1] - 5.196];
        let poly = HotPolyline {
            vertices_mm: vec![a, vertex, b],
            background_c: 60.0,
            bead_c: 130.0,
            bead_sigma_mm: 0.3,
            corner_excess_c: 0.0,
            corner_sigma_mm: 0.45,
        };
        (poly, [vertex[0], vertex[1] - bulge_mm])
    }

    #[test]
    fn an_offset_hot_spot_still_yields_the_vertex_within_0_05_mm() {
        let cam = CameraModel::lepton35(Distortion::default());
        let vertex = [0.6, 1.5];
        let (poly, bulge) = scene(vertex, 0.5);
        let bulge_blob = |p: [f64; 2]| {
            let r2 = (p[0] - bulge[0]).powi(2) + (p[1] - bulge[1]).powi(2);
            25.0 * (-r2 / (2.0 * 0.35f64.powi(2))).exp()
        };
        let mut frame = render_raw_frame(&cam, [0.0, 0.0], |p| poly.temp_c(p) + bulge_blob(p));
        add_noise(&mut frame, 0.05, 4);
        let h0 = cam.nominal_homography();
        let to_px = h0.inverse().unwrap();
        let vertex_px = to_px.apply(vertex);
        let hot_px = to_px.apply(bulge);
        let arm_pt = |q: [f64; 2]| {
            let len = (q[0] - vertex[0]).hypot(q[1] - vertex[1]);
            to_px.apply([vertex[0] + (q[0] - vertex[0]) / len, vertex[1] + (q[1] - vertex[1]) / len])
        };
        let arms = CornerArms::from_points(vertex_px, [arm_pt(poly.vertices_mm[0]), arm_pt(poly.vertices_mm[2])], 1.0)
            .unwrap();
        let found = vertex_from_ridges(&frame, hot_px, &arms, &VertexParams::defaults()).unwrap();
        let found_mm = h0.apply(found);
        let err_mm = (found_mm[0] - vertex[0]).hypot(found_mm[1] - vertex[1]);
        assert!(err_mm < 0.05, "vertex off by {err_mm} mm (hot spot was 0.5 mm off)");
    }

    #[test]
    fn parabola_vertex_of_exact_parabola() {
        let y: Vec<f64> = (0..7).map(|j| -((j as f64 - 3.0) - 0.4).powi(2) + 5.0).collect();
        assert!((parabola_vertex(&y).unwrap() - 0.4).abs() < 1e-12);
        assert!(parabola_vertex(&[1.0, 0.0, 1.0]).is_none(), "a minimum is no ridge");
    }

    #[test]
    fn lines_intersect_where_expected_and_parallel_lines_do_not() {
        let p = intersect(([0.0, 1.0], [1.0, 0.0]), ([2.0, 5.0], [0.0, 1.0])).unwrap();
        assert!((p[0] - 2.0).abs() < 1e-12 && (p[1] - 1.0).abs() < 1e-12);
        assert!(intersect(([0.0, 0.0], [1.0, 0.0]), ([0.0, 1.0], [1.0, 0.01])).is_none());
    }

    #[test]
    fn a_flat_frame_has_no_ridges() {
        let frame = ThermalFrame::filled(160, 120, 60.0);
        let arms = CornerArms { dirs: [[1.0, 0.0], [0.0, 1.0]], px_per_mm: [7.0, 7.0] };
        assert!(vertex_from_ridges(&frame, [80.0, 60.0], &arms, &VertexParams::defaults()).is_none());
    }
}
