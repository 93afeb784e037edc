//! Geometric corner vertices from the two bead ridges, for the correspondences of eq. 27
//! (paper 003 Sec. 2.3).
//!
//! The paper pairs the corner its detector (Faster R-CNN) finds with the CAD corner and
//! does not say where inside the detected box the corner point lies. Our hot-spot
//! detector ([`crate::corners`]) returns the heat peak, and the peak is not at the CAD
//! vertex: material piles up inside a corner, so the hottest point sits inside it along
//! the bisector, by an amount that varies with the corner angle and its age. Pairing the
//! peak with the CAD vertex biases H(i), systematically per corner, and through eq. 30
//! the capture time.
//!
//! What we do instead: locate the vertex geometrically. Each arm of the corner is a
//! straight bead whose temperature ridge runs along the path; away from the corner the
//! ridge is centred on the path. For each arm we read cross-sections of the undistorted
//! frame perpendicular to the arm at distances `s` from the corner (far enough that the
//! two arms are at least `min_arm_gap_mm` apart, up to `span_mm` further), take the
//! sub-pixel ridge maximum of each (least-squares parabola over ±1.5 px of the hottest
//! sample), draw through their centroid the line with the arm's direction as the caller
//! predicts it, and intersect the two lines. Straight plane lines stay straight in the
//! undistorted image (a homography), so the intersection is the image of the path vertex
//! (the planner's 0.05 mm blend is negligible), independent of the bulge. Two passes: the
//! second starts from the first intersection, which puts the cross-sections at the
//! intended distances.
//!
//! Why the directions are held, not fitted, and why the arms are read this far out:
//! - Near a sharp corner the arm's ridge is pulled towards the other arm: the deposition
//!   directions rotate (DDA, eqs 13-26) over the first millimetre or so from the vertex,
//!   material piles up on the inner side along the bisector, and its heat spreads over
//!   the arms. In the frames (blurred by the camera's PSF) the inward pull depends on the
//!   arm gap g = 2 s sin(θ/2), about the same for every angle, and dies out as the gap
//!   grows; `min_arm_gap_mm` starts the reading where it has.
//! - A fitted direction (total least squares along each arm) is tilted by the pull at the
//!   arm's near end, and the intersection extrapolates the tilt back over
//!   `min_offset_mm` + `span_mm`/2 and divides it by sin(θ/2): a vertex biased inwards
//!   along the bisector, systematically per corner, which a mount fit then absorbs (see
//!   `thermal.monitor`). A held direction turns a sideways pull into its mean over the
//!   read span instead of an extrapolated tilt.
//!
//! The held direction must be right: with s̄ the mean distance read,
//! both arms turned by δ the same way (a roll of the mount) move the vertex sideways by
//! s̄·δ/cos(θ/2), and arms opened or closed by δ each move it along the bisector by
//! s̄·δ/sin(θ/2) (tested). The callers take it from
//! the nominal mount (the paper's DLT and the rigid estimator's first pass) or, for the
//! rigid estimator's later passes, still from the nominal mount while the positions come
//! from the fitted one ([`crate::rigid::predict_corners_with_arms_into`]).

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
    /// σ ≈ 0.3-0.4 mm: from 1.6 mm between the arms neither the other arm nor the corner's
    /// pile pulls the ridge by more than 0.001 mm (module doc; 1.2 mm, the former value,
    /// let them pull it by 0.02 mm); 0.7 mm clears the bulge of obtuse corners.
    pub fn defaults() -> Self {
        Self {
            min_arm_gap_mm: 1.6,
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

/// The image of the path vertex, starting near `start_px` (e.g. the heat peak or a
/// prediction): each arm's line has the direction `arms.dirs` gives it and passes through
/// the centroid of its ridge points; the vertex is where the two meet. None when an arm
/// has too few ridge points, the arms are nearly parallel or the vertex moves more than
/// `max_shift_px`.
pub fn vertex_from_ridges(
    image: &ThermalFrame,
    start_px: [f64; 2],
    arms: &CornerArms,
    params: &VertexParams,
) -> Option<[f64; 2]> {
    if arms.sin_between() < 0.2 {
        return None;
    }
    let first = intersect_arms(image, start_px, arms, params)?;
    let second = intersect_arms(image, first, arms, params)?;
    let shift = (second[0] - start_px[0]).hypot(second[1] - start_px[1]);
    (shift <= params.max_shift_px).then_some(second)
}

/// One pass of [`vertex_from_ridges`] from `apex_px`.
fn intersect_arms(
    image: &ThermalFrame,
    apex_px: [f64; 2],
    arms: &CornerArms,
    params: &VertexParams,
) -> Option<[f64; 2]> {
    let s0_mm = params.first_offset_mm(arms.cos_between());
    let mut through = [[0.0; 2]; 2];
    let mut points = [[0.0; 2]; MAX_SECTIONS];
    for k in 0..2 {
        let n = ridge_points(image, apex_px, arms.dirs[k], arms.px_per_mm[k], s0_mm, params, &mut points);
        if n < params.min_points {
            return None;
        }
        through[k] = centroid(&points[..n]);
    }
    intersect((through[0], arms.dirs[0]), (through[1], arms.dirs[1]))
}

/// Most cross-sections read per arm.
const MAX_SECTIONS: usize = 64;

/// The ridge maxima of one arm's cross-sections, `s0_mm` to `s0_mm + span_mm` from
/// `apex_px` along `dir`, written into `points`; returns how many were found.
fn ridge_points(
    image: &ThermalFrame,
    apex_px: [f64; 2],
    dir: [f64; 2],
    px_per_mm: f64,
    s0_mm: f64,
    params: &VertexParams,
    points: &mut [[f64; 2]; MAX_SECTIONS],
) -> usize {
    let normal = [-dir[1], dir[0]];
    let steps = (params.span_mm / params.step_mm).round() as usize;
    let mut n = 0;
    for i in 0..=steps.min(MAX_SECTIONS - 1) {
        let s_px = (s0_mm + i as f64 * params.step_mm) * px_per_mm;
        let centre = [apex_px[0] + s_px * dir[0], apex_px[1] + s_px * dir[1]];
        if let Some(r) = ridge_offset_px(image, centre, normal, params) {
            points[n] = [centre[0] + r * normal[0], centre[1] + r * normal[1]];
            n += 1;
        }
    }
    n
}

fn centroid(points: &[[f64; 2]]) -> [f64; 2] {
    let sum = points.iter().fold([0.0; 2], |s, p| [s[0] + p[0], s[1] + p[1]]);
    [sum[0] / points.len() as f64, sum[1] / points.len() as f64]
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
        (corner_polyline(vertex, 30.0, 6.0), [vertex[0], vertex[1] - bulge_mm])
    }

    /// A corner at `vertex` opening downwards, arms `arm_mm` long at ±`half_angle_deg`
    /// from the vertical, a 130 °C bead on a 60 °C part.
    fn corner_polyline(vertex: [f64; 2], half_angle_deg: f64, arm_mm: f64) -> HotPolyline {
        let (sin, cos) = half_angle_deg.to_radians().sin_cos();
        let (a, b) = (
            [vertex[0] - arm_mm * sin, vertex[1] - arm_mm * cos],
            [vertex[0] + arm_mm * sin, vertex[1] - arm_mm * cos],
        );
        HotPolyline {
            vertices_mm: vec![a, vertex, b],
            background_c: 60.0,
            bead_c: 130.0,
            bead_sigma_mm: 0.3,
            corner_excess_c: 0.0,
            corner_sigma_mm: 0.45,
        }
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

    /// A noise-free corner drawn directly in the image: vertex at (80, 30) px, arms at
    /// ±θ/2 from +v, Gaussian ridges of σ = 2 px, 7 px per mm along both arms.
    fn image_corner(theta: f64) -> (ThermalFrame, CornerArms, [f64; 2]) {
        let vertex = [80.0, 30.0];
        let half = 0.5 * theta;
        let dirs = [[-half.sin(), half.cos()], [half.sin(), half.cos()]];
        let mut frame = ThermalFrame::filled(160, 120, 60.0);
        for v in 0..120 {
            for u in 0..160 {
                let d = [u as f64 - vertex[0], v as f64 - vertex[1]];
                let dist2 = dirs
                    .iter()
                    .map(|a| {
                        let along = dot(d, *a).max(0.0);
                        (d[0] - along * a[0]).powi(2) + (d[1] - along * a[1]).powi(2)
                    })
                    .fold(f64::INFINITY, f64::min);
                frame.temp_c[v * 160 + u] = (60.0 + 70.0 * (-0.5 * dist2 / 4.0).exp()) as f32;
            }
        }
        (frame, CornerArms { dirs, px_per_mm: [7.0, 7.0] }, vertex)
    }

    fn rotated(d: [f64; 2], delta: f64) -> [f64; 2] {
        let (s, c) = delta.sin_cos();
        [c * d[0] - s * d[1], s * d[0] + c * d[1]]
    }

    #[test]
    fn exact_arms_give_the_vertex_and_turned_arms_move_it_by_the_closed_form() {
        let theta = 60f64.to_radians();
        let (frame, arms, vertex) = image_corner(theta);
        let params = VertexParams::defaults();
        let found = vertex_from_ridges(&frame, [81.0, 31.5], &arms, &params).unwrap();
        assert!((found[0] - vertex[0]).hypot(found[1] - vertex[1]) < 0.01, "{found:?}");
        // Mean distance read: s0 + span/2 (mm) at 7 px/mm.
        let s_mean_px = 7.0 * (params.first_offset_mm(theta.cos()) + 0.5 * params.span_mm);
        let delta = 0.004;
        // Both arms turned the same way: the vertex moves sideways by s̄·δ/cos(θ/2).
        let roll = CornerArms { dirs: [rotated(arms.dirs[0], delta), rotated(arms.dirs[1], delta)], ..arms };
        let moved = vertex_from_ridges(&frame, vertex, &roll, &params).unwrap();
        let (sideways, along) = (moved[0] - vertex[0], moved[1] - vertex[1]);
        let expected = s_mean_px * delta / (0.5 * theta).cos();
        assert!((sideways.abs() - expected).abs() < 0.03 * expected && along.abs() < 0.05 * expected, "{moved:?}");
        // Both arms opened by δ: it moves along the bisector by s̄·δ/sin(θ/2).
        let open = CornerArms { dirs: [rotated(arms.dirs[0], -delta), rotated(arms.dirs[1], delta)], ..arms };
        let moved = vertex_from_ridges(&frame, vertex, &open, &params).unwrap();
        let expected = s_mean_px * delta / (0.5 * theta).sin();
        assert!(((moved[1] - vertex[1]).abs() - expected).abs() < 0.03 * expected, "{moved:?}");
        assert!((moved[0] - vertex[0]).abs() < 0.05 * expected, "{moved:?}");
    }

    #[test]
    fn a_pile_along_the_bisector_does_not_pull_the_vertex() {
        // A 45° corner with an elongated hot pile inside it along the bisector (the eqs
        // 5-11 printer piles material there): it pulls the arms' ridges towards each
        // other near the vertex, where the cross-sections do not reach.
        let cam = CameraModel::lepton35(Distortion::default());
        let vertex = [0.4, 2.0];
        let poly = corner_polyline(vertex, 22.5, 5.0);
        let pile = |p: [f64; 2]| {
            let (across, along) = (p[0] - vertex[0], vertex[1] - 0.6 - p[1]);
            30.0 * (-0.5 * (across / 0.3).powi(2) - 0.5 * (along / 0.6).powi(2)).exp()
        };
        let mut frame = render_raw_frame(&cam, [0.0, 0.0], |p| poly.temp_c(p) + pile(p));
        add_noise(&mut frame, 0.05, 5);
        let h0 = cam.nominal_homography();
        let to_px = h0.inverse().unwrap();
        let arm_pt = |q: [f64; 2]| {
            let len = (q[0] - vertex[0]).hypot(q[1] - vertex[1]);
            to_px.apply([vertex[0] + (q[0] - vertex[0]) / len, vertex[1] + (q[1] - vertex[1]) / len])
        };
        let arms = CornerArms::from_points(
            to_px.apply(vertex),
            [arm_pt(poly.vertices_mm[0]), arm_pt(poly.vertices_mm[2])],
            1.0,
        )
        .unwrap();
        let params = VertexParams::defaults();
        assert!(
            (params.first_offset_mm(45f64.to_radians().cos()) - 1.6 / (2.0 * 22.5f64.to_radians().sin())).abs() < 1e-12
        );
        let found = h0.apply(vertex_from_ridges(&frame, to_px.apply(vertex), &arms, &params).unwrap());
        let err_mm = (found[0] - vertex[0]).hypot(found[1] - vertex[1]);
        assert!(err_mm < 0.02, "vertex off by {err_mm} mm");
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
