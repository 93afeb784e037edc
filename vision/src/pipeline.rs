//! One thermal frame end to end, paper 003 Sec. 2.3-2.4: undistort, detect the hot
//! corners in the 140-150 °C band, pair them with the path corners predicted from the
//! recorded time, move each matched corner from its heat peak onto the path vertex by
//! intersecting the two bead ridges ([`crate::vertex`]: the peak sits inside the corner,
//! where material piles up; the paper does not say which point of a detection it pairs
//! with the CAD corner), estimate the frame's homography H(i) (eq. 27), place the nozzle
//! (eq. 29), estimate the capture time (eq. 30) and extract the half-widths along the
//! deposition directions (Sec. 2.4).
//!
//! A frame that cannot be used (too few corners, no homography, wrong size) is a
//! [`FrameSkip`] with its reason, never an error: the sequence goes on (Sec. 3.2 keeps
//! only "thermal images with sufficient newly printed corners"). A frame whose nozzle
//! position (eq. 29) lies more than `max_nozzle_offset_mm` from the commanded position at
//! the recorded time is skipped too: the camera is rigid on the nozzle and the timing
//! jitter is milliseconds, so such an H(i) is a wrong fit, not a measurement (ours; the
//! paper has no such check). All image buffers live
//! in a [`FrameWorkspace`] reused across frames.
//!
//! [`process_frame`] is [`observe_frame`] (undistort, detect, pair, place on the ridges)
//! followed by [`localise_dlt`] (eqs 27, 29, 30, widths); the rigid-mount extension
//! ([`crate::rigid`]) localises the same observation under one mount for the sequence.

use rand_chacha::ChaCha8Rng;

use crate::camera::{CameraError, Undistorter};
use crate::corners::{CornerDetection, CornerDetector, CornerParams};
use crate::frame::ThermalFrame;
use crate::homography::{estimate_homography, Homography, HomographyError, HomographyFit, HomographyParams};
use crate::localize::{estimate_capture_time, nozzle_position_mm, CaptureTimeEstimate, TrajectoryView, PAPER_WINDOW_S};
use crate::matching::{match_corners_into, CornerMatch, PredictedCorner, ARM_PROBE_MM};
use crate::mount::{MountError, MountParams};
use crate::vertex::{vertex_from_ridges, CornerArms, VertexParams};
use crate::widths::{extract_widths_into, WidthParams, WidthQuery};

/// Settings of every step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipelineParams {
    /// Corner detector.
    pub corners: CornerParams,
    /// Largest distance between a detection and its predicted corner (px).
    pub match_gate_px: f64,
    /// RANSAC homography.
    pub homography: HomographyParams,
    /// Half-width δt of the capture-time window (s).
    pub window_s: f64,
    /// Width extraction (threshold T_t).
    pub widths: WidthParams,
    /// Vertex location from the bead ridges; None: pair the heat peaks as detected.
    pub vertex: Option<VertexParams>,
    /// Largest plausible distance of the eq. 29 nozzle position from the commanded
    /// position at the recorded time (mm).
    pub max_nozzle_offset_mm: f64,
    /// Rigid-mount fit and nozzle placement (our extension, [`crate::mount`]).
    pub mount: MountParams,
    /// How far a ridge vertex searched from a mount prediction may move (px), see
    /// [`crate::rigid`].
    pub predicted_shift_px: f64,
}

impl PipelineParams {
    /// Paper settings (band 140-150 °C, δt = 10 ms) with the width threshold `threshold_c`.
    /// The 6 px gate covers ±10 ms of timing error at 20 mm/s (0.2 mm ≈ 1.5 px) plus a
    /// mounting error of about half a millimetre. The rigid-mount settings are ours: a
    /// prediction through the fitted mount is good to about a pixel, so a ridge vertex
    /// searched from it may move 3 px.
    pub fn paper_defaults(threshold_c: f64) -> Self {
        Self {
            corners: CornerParams::paper_defaults(),
            match_gate_px: 6.0,
            homography: HomographyParams::paper_defaults(),
            window_s: PAPER_WINDOW_S,
            widths: WidthParams::with_threshold(threshold_c),
            vertex: Some(VertexParams::defaults()),
            max_nozzle_offset_mm: 1.0,
            mount: MountParams::defaults(),
            predicted_shift_px: 3.0,
        }
    }
}

/// What stays fixed over a sequence.
#[derive(Debug, Clone, Copy)]
pub struct FrameContext<'a> {
    /// Undistorter of the camera.
    pub undistorter: &'a Undistorter,
    /// Nominal H0: undistorted pixel → plane mm relative to the nozzle.
    pub h0: Homography,
    /// Nozzle pixel P_N⁽⁰⁾ in the raw image (dataset's `nozzle_px`).
    pub nozzle_px: [f64; 2],
    /// Commanded trajectory.
    pub trajectory: TrajectoryView<'a>,
    /// Settings.
    pub params: PipelineParams,
}

/// One frame's inputs.
#[derive(Debug, Clone, Copy)]
pub struct FrameInput<'a> {
    /// The raw (distorted) frame.
    pub frame: &'a ThermalFrame,
    /// Recorded time t_r (s).
    pub t_recorded_s: f64,
    /// Path corners with their predicted pixels for t_r (see [`predict_corners_into`]).
    pub predicted: &'a [PredictedCorner],
    /// Points and deposition directions where widths are wanted.
    pub width_queries: &'a [WidthQuery],
}

/// A processed frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// Corners detected in the band.
    pub corners_found: usize,
    /// Corners paired with path corners.
    pub matches: Vec<CornerMatch>,
    /// Image points paired with the path corners in eq. 27, one per match (undistorted
    /// px): the ridge intersection where it was found, else the heat peak.
    pub corner_px: Vec<[f64; 2]>,
    /// Matches placed by the ridge intersection.
    pub refined: usize,
    /// H(i) with inliers and RMS error (mm).
    pub homography: HomographyFit,
    /// Nozzle position P_N,i (world mm, eq. 29).
    pub nozzle_mm: [f64; 2],
    /// Capture time estimate (eq. 30).
    pub capture: CaptureTimeEstimate,
    /// (w_l, w_r) in mm per width query, None where no width could be read.
    pub widths_mm: Vec<Option<(f64, f64)>>,
}

/// Why a frame was skipped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameSkip {
    /// The frame does not fit the camera.
    #[error("frame does not fit the camera: {0}")]
    Camera(#[from] CameraError),
    /// Fewer than four paired corners (eq. 27 needs four).
    #[error("too few corners: {found} detected, {matched} matched, {needed} needed")]
    TooFewCorners {
        /// Corners detected in the band.
        found: usize,
        /// Corners paired with path corners.
        matched: usize,
        /// Four.
        needed: usize,
    },
    /// The homography could not be estimated.
    #[error("homography failed: {0}")]
    HomographyFailed(HomographyError),
    /// H(i) places the nozzle implausibly far from where the recorded time puts it.
    #[error("implausible homography: nozzle {offset_mm:.2} mm from its commanded position at t_r")]
    Implausible {
        /// Distance (mm).
        offset_mm: f64,
    },
    /// H(i) sends the nozzle pixel to infinity.
    #[error("nozzle pixel maps off the plane")]
    NozzleOffPlane,
    /// The rigid-mount localisation could not place the nozzle: no corner pairs, or
    /// pairs that disagree (see [`crate::rigid`]).
    #[error("rigid mount: {0}")]
    Mount(MountError),
}

/// Corner pairs of one frame: path corner ids, undistorted image points and their
/// vertices on the plane (world mm), index-aligned.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CornerPairs {
    /// Path corner ids.
    pub ids: Vec<u32>,
    /// Undistorted image points (px).
    pub image_px: Vec<[f64; 2]>,
    /// Path vertices (world mm).
    pub plane_mm: Vec<[f64; 2]>,
}

impl CornerPairs {
    /// Appends one pair.
    pub fn push(&mut self, id: u32, image_px: [f64; 2], plane_mm: [f64; 2]) {
        self.ids.push(id);
        self.image_px.push(image_px);
        self.plane_mm.push(plane_mm);
    }

    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True without pairs.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Empties it.
    pub fn clear(&mut self) {
        self.ids.clear();
        self.image_px.clear();
        self.plane_mm.clear();
    }
}

/// Buffers reused from frame to frame.
pub struct FrameWorkspace {
    undistorted: ThermalFrame,
    detector: CornerDetector,
    detections: Vec<CornerDetection>,
    matches: Vec<CornerMatch>,
    image_px: Vec<[f64; 2]>,
    plane_mm: Vec<[f64; 2]>,
    on_ridges: Vec<bool>,
    found: usize,
    refined: usize,
}

impl FrameWorkspace {
    /// Buffers for the undistorter's frame size.
    pub fn new(undistorter: &Undistorter, params: &PipelineParams) -> Result<Self, crate::corners::CornerError> {
        let cam = undistorter.camera();
        Ok(Self {
            undistorted: ThermalFrame::filled(cam.width_px, cam.height_px, f32::NAN),
            detector: CornerDetector::new(cam.width_px, cam.height_px, params.corners)?,
            detections: Vec::new(),
            matches: Vec::new(),
            image_px: Vec::new(),
            plane_mm: Vec::new(),
            on_ridges: Vec::new(),
            found: 0,
            refined: 0,
        })
    }

    /// Empties the per-frame results (the undistorted image is marked all NaN).
    fn clear(&mut self) {
        self.undistorted.temp_c.fill(f32::NAN);
        self.detections.clear();
        self.matches.clear();
        self.image_px.clear();
        self.plane_mm.clear();
        self.on_ridges.clear();
        (self.found, self.refined) = (0, 0);
    }

    /// The last observed frame's pairs whose image point is a ridge intersection (the
    /// heat peaks are left out: they sit up to ~0.5 mm inside their corner), with the
    /// path corner ids of `predicted` (the slice the frame was observed with).
    pub fn ridge_pairs(&self, predicted: &[PredictedCorner]) -> CornerPairs {
        let mut out = CornerPairs::default();
        for (k, m) in self.matches.iter().enumerate().filter(|(k, _)| self.on_ridges[*k]) {
            out.push(predicted[m.predicted].id, self.image_px[k], self.plane_mm[k]);
        }
        out
    }

    /// The last undistorted frame.
    pub fn undistorted(&self) -> &ThermalFrame {
        &self.undistorted
    }

    /// The last frame's detections.
    pub fn detections(&self) -> &[CornerDetection] {
        &self.detections
    }

    /// The last observed frame's pairs of detections with predicted corners (those
    /// whose peak was dropped for lack of ridges when four others had them are left out).
    pub fn matches(&self) -> &[CornerMatch] {
        &self.matches
    }
}

/// Predicted undistorted pixels of path corners for a nozzle at `nozzle_mm` (world):
/// px = H0⁻¹(corner − nozzle). Corners behind the camera are left out.
pub fn predict_corners_into(
    h0: &Homography,
    nozzle_mm: [f64; 2],
    corners: &[(u32, [f64; 2])],
    out: &mut Vec<PredictedCorner>,
) {
    out.clear();
    let Some(inv) = h0.inverse() else { return };
    for &(id, c) in corners {
        let px = inv.apply([c[0] - nozzle_mm[0], c[1] - nozzle_mm[1]]);
        if px[0].is_finite() && px[1].is_finite() {
            out.push(PredictedCorner { id, plane_mm: c, px, arm_px: None });
        }
    }
}

/// A path corner with the unit plane directions of its two arms (towards the previous
/// and the next vertex).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathCorner {
    /// Caller's id.
    pub id: u32,
    /// Vertex (world mm).
    pub vertex_mm: [f64; 2],
    /// Unit directions of the two arms on the plane.
    pub arm_dirs: [[f64; 2]; 2],
}

impl PathCorner {
    /// The corners of a closed polygon, ids = vertex indices; None for vertices whose
    /// neighbour coincides with them.
    pub fn of_closed_path(path_mm: &[[f64; 2]]) -> Vec<PathCorner> {
        let n = path_mm.len();
        let unit = |from: [f64; 2], to: [f64; 2]| {
            let d = [to[0] - from[0], to[1] - from[1]];
            let len = d[0].hypot(d[1]);
            (len > 1e-12).then(|| [d[0] / len, d[1] / len])
        };
        (0..n)
            .filter_map(|i| {
                let v = path_mm[i];
                let prev = unit(v, path_mm[(i + n - 1) % n])?;
                let next = unit(v, path_mm[(i + 1) % n])?;
                Some(PathCorner { id: i as u32, vertex_mm: v, arm_dirs: [prev, next] })
            })
            .collect()
    }
}

/// As [`predict_corners_into`], with the probe points of both arms (see
/// [`PredictedCorner::arm_px`]).
pub fn predict_path_corners_into(
    h0: &Homography,
    nozzle_mm: [f64; 2],
    corners: &[PathCorner],
    out: &mut Vec<PredictedCorner>,
) {
    out.clear();
    let Some(inv) = h0.inverse() else { return };
    let to_px = |p: [f64; 2]| inv.apply([p[0] - nozzle_mm[0], p[1] - nozzle_mm[1]]);
    let finite = |p: [f64; 2]| p[0].is_finite() && p[1].is_finite();
    for c in corners {
        let px = to_px(c.vertex_mm);
        if !finite(px) {
            continue;
        }
        let probe = |d: [f64; 2]| to_px([c.vertex_mm[0] + ARM_PROBE_MM * d[0], c.vertex_mm[1] + ARM_PROBE_MM * d[1]]);
        let arms = [probe(c.arm_dirs[0]), probe(c.arm_dirs[1])];
        let arm_px = (finite(arms[0]) && finite(arms[1])).then_some(arms);
        out.push(PredictedCorner { id: c.id, plane_mm: c.vertex_mm, px, arm_px });
    }
}

/// Runs one frame end to end: [`observe_frame`] then [`localise_dlt`].
pub fn process_frame(
    ctx: &FrameContext<'_>,
    input: &FrameInput<'_>,
    ws: &mut FrameWorkspace,
    rng: &mut ChaCha8Rng,
) -> Result<FrameResult, FrameSkip> {
    observe_frame(ctx, input, ws)?;
    localise_dlt(ctx, input, ws, rng)
}

/// What a frame shows, before any homography: undistort it, detect the hot corners in
/// the band, pair them with `input.predicted` and place each pair's image point on the
/// ridge intersection where it can (the pairs of eq. 27, below). The results stay in
/// `ws` ([`FrameWorkspace::undistorted`], [`FrameWorkspace::detections`],
/// [`FrameWorkspace::ridge_pairs`]); the workspace is emptied first, so a frame that
/// fails here leaves nothing of the previous one.
pub fn observe_frame(ctx: &FrameContext<'_>, input: &FrameInput<'_>, ws: &mut FrameWorkspace) -> Result<(), FrameSkip> {
    ws.clear();
    ctx.undistorter.undistort_into(input.frame, &mut ws.undistorted)?;
    ws.detector.detect_into(&ws.undistorted, &mut ws.detections);
    match_corners_into(&ws.detections, input.predicted, ctx.params.match_gate_px, &mut ws.matches);
    ws.found = ws.detections.len();
    ws.refined = fill_correspondences(ws, input.predicted, ctx.params.vertex.as_ref());
    Ok(())
}

/// The paper's localisation of an observed frame (after [`observe_frame`] on the same
/// workspace): H(i) by RANSAC + DLT on at least four pairs (eq. 27), the nozzle
/// (eq. 29), the capture time (eq. 30) and the half-widths (Sec. 2.4).
pub fn localise_dlt(
    ctx: &FrameContext<'_>,
    input: &FrameInput<'_>,
    ws: &mut FrameWorkspace,
    rng: &mut ChaCha8Rng,
) -> Result<FrameResult, FrameSkip> {
    let p = &ctx.params;
    let (found, matched) = (ws.found, ws.matches.len());
    if matched < crate::homography::MIN_CORRESPONDENCES {
        return Err(FrameSkip::TooFewCorners { found, matched, needed: crate::homography::MIN_CORRESPONDENCES });
    }
    let fit =
        estimate_homography(&ws.image_px, &ws.plane_mm, &p.homography, rng).map_err(FrameSkip::HomographyFailed)?;
    let nozzle_mm = nozzle_position_mm(&fit.homography, ctx.undistorter.undistort_px(ctx.nozzle_px));
    if !nozzle_mm[0].is_finite() || !nozzle_mm[1].is_finite() {
        return Err(FrameSkip::NozzleOffPlane);
    }
    check_plausible(ctx, nozzle_mm, input.t_recorded_s)?;
    let capture = estimate_capture_time(&ctx.trajectory, nozzle_mm, input.t_recorded_s, p.window_s);
    let plane_to_px = fit.homography.inverse().ok_or(FrameSkip::NozzleOffPlane)?;
    let mut widths_mm = Vec::with_capacity(input.width_queries.len());
    extract_widths_into(&ws.undistorted, &plane_to_px, input.width_queries, &p.widths, &mut widths_mm);
    Ok(FrameResult {
        corners_found: found,
        matches: ws.matches.clone(),
        corner_px: ws.image_px.clone(),
        refined: ws.refined,
        homography: fit,
        nozzle_mm,
        capture,
        widths_mm,
    })
}

/// A nozzle position is plausible when it lies within `max_nozzle_offset_mm` of the
/// commanded position at the recorded time (the camera is rigid on the nozzle and the
/// timing error is milliseconds, so a larger offset is a wrong fit).
pub fn check_plausible(ctx: &FrameContext<'_>, nozzle_mm: [f64; 2], t_recorded_s: f64) -> Result<(), FrameSkip> {
    let commanded = ctx.trajectory.position_mm(t_recorded_s);
    let offset_mm = (nozzle_mm[0] - commanded[0]).hypot(nozzle_mm[1] - commanded[1]);
    if offset_mm > ctx.params.max_nozzle_offset_mm {
        return Err(FrameSkip::Implausible { offset_mm });
    }
    Ok(())
}

/// The pairs of eq. 27: each match's image point (ridge intersection where found, else
/// the heat peak) with its path vertex. When at least four were placed by the ridges,
/// the others are dropped (a peak is biased by up to ~0.5 mm, and with few pairs one
/// biased pair moves the whole H); `ws.matches` keeps only the pairs used. Returns how
/// many were placed by the ridges.
fn fill_correspondences(
    ws: &mut FrameWorkspace,
    predicted: &[PredictedCorner],
    vertex: Option<&VertexParams>,
) -> usize {
    ws.image_px.clear();
    ws.plane_mm.clear();
    ws.on_ridges.clear();
    let mut refined = 0;
    for m in &ws.matches {
        let d = &ws.detections[m.detection];
        let pred = &predicted[m.predicted];
        let peak = [d.u_px, d.v_px];
        let ridge = vertex.zip(pred.arm_px).and_then(|(params, arm_px)| {
            let arms = CornerArms::from_points(pred.px, arm_px, ARM_PROBE_MM)?;
            vertex_from_ridges(&ws.undistorted, peak, &arms, params)
        });
        refined += usize::from(ridge.is_some());
        ws.on_ridges.push(ridge.is_some());
        ws.image_px.push(ridge.unwrap_or(peak));
        ws.plane_mm.push(pred.plane_mm);
    }
    if refined >= crate::homography::MIN_CORRESPONDENCES {
        let keep = &ws.on_ridges;
        let mut i = 0;
        ws.matches.retain(|_| (keep[i], i += 1).0);
        let mut i = 0;
        ws.image_px.retain(|_| (keep[i], i += 1).0);
        let mut i = 0;
        ws.plane_mm.retain(|_| (keep[i], i += 1).0);
        ws.on_ridges.retain(|&r| r);
    }
    refined
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraModel, Distortion};
    use crate::synth::{add_noise, render_raw_frame, HotPolyline};
    use rand::SeedableRng;

    const ZIGZAG_REL: [[f64; 2]; 7] =
        [[-11.0, -2.0], [-8.0, 2.5], [-4.0, -2.0], [0.0, 2.5], [4.0, -2.0], [8.0, 2.5], [11.0, -1.0]];

    struct Case {
        nominal: CameraModel,
        truth: CameraModel,
        t: Vec<f64>,
        x: Vec<f64>,
        y: Vec<f64>,
        scene: HotPolyline,
        t_capture_s: f64,
    }

    /// The nozzle moves along +x at 20 mm/s; the zigzag is fixed in the world around
    /// where the nozzle is at the capture time; the true mount is off by 0.3 mm and 1°.
    fn case() -> Case {
        let distortion = Distortion { k1: -0.1, k2: 0.02, p1: 0.0005, p2: -0.0005 };
        let nominal = CameraModel::lepton35(distortion);
        let mut truth = nominal;
        truth.mount.look_at_mm = [0.2, -0.3];
        truth.mount.tilt_deg = 46.0;
        let t: Vec<f64> = (0..4000).map(|i| i as f64 * 0.001).collect();
        let (x, y) = t.iter().map(|&t| (-30.0 + 20.0 * t, 10.0)).unzip();
        let t_capture_s = 1.5043;
        let nozzle = [-30.0 + 20.0 * t_capture_s, 10.0];
        let scene = HotPolyline {
            vertices_mm: ZIGZAG_REL.iter().map(|p| [p[0] + nozzle[0] + 0.37, p[1] + nozzle[1]]).collect(),
            background_c: 60.0,
            bead_c: 128.0,
            bead_sigma_mm: 0.25,
            // Peak 146 °C: pixel sampling and the undistortion's bilinear resampling
            // lower a 0.45 mm blob's hottest pixel by up to ~4 °C, keep it in the band.
            corner_excess_c: 18.0,
            corner_sigma_mm: 0.45,
        };
        Case { nominal, truth, t, x, y, scene, t_capture_s }
    }

    #[test]
    fn a_synthetic_frame_is_localized_in_space_and_time() {
        let c = case();
        let traj = TrajectoryView::new(&c.t, &c.x, &c.y).unwrap();
        let nozzle_true = traj.position_mm(c.t_capture_s);
        let mut frame = render_raw_frame(&c.truth, nozzle_true, |p| c.scene.temp_c(p));
        add_noise(&mut frame, 0.05, 11);
        let undistorter = Undistorter::new(&c.nominal).unwrap();
        let params = PipelineParams::paper_defaults(94.0);
        let ctx = FrameContext {
            undistorter: &undistorter,
            h0: c.nominal.nominal_homography(),
            nozzle_px: c.truth.plane_to_raw_px([0.0, 0.0]).unwrap(),
            trajectory: traj,
            params,
        };
        let t_recorded_s = 1.5;
        let corners: Vec<(u32, [f64; 2])> =
            c.scene.corners_mm().iter().enumerate().map(|(i, &p)| (i as u32, p)).collect();
        let mut predicted = Vec::new();
        predict_corners_into(&ctx.h0, traj.position_mm(t_recorded_s), &corners, &mut predicted);
        // Width queries on the middle of the second arm, left normal of its direction.
        let (a, b) = (c.scene.vertices_mm[2], c.scene.vertices_mm[3]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let dir = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
        let queries: Vec<WidthQuery> = (0..5)
            .map(|k| {
                let s = 0.35 + 0.075 * k as f64;
                WidthQuery { p_mm: [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])], n_left: [-dir[1], dir[0]] }
            })
            .collect();
        let input = FrameInput { frame: &frame, t_recorded_s, predicted: &predicted, width_queries: &queries };
        let mut ws = FrameWorkspace::new(&undistorter, &params).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let res = process_frame(&ctx, &input, &mut ws, &mut rng).unwrap();
        assert_eq!(res.matches.len(), 5);
        // Corner positions carry a ≤ 0.4 px bias (see corners.rs), ≈ 0.05 mm on the plane.
        assert!(res.homography.rms_error_mm < 0.06, "rms {}", res.homography.rms_error_mm);
        let err_mm = (res.nozzle_mm[0] - nozzle_true[0]).hypot(res.nozzle_mm[1] - nozzle_true[1]);
        assert!(err_mm < 0.06, "nozzle off by {err_mm} mm");
        // 0.06 mm along a 20 mm/s path is 3 ms; recorded time was 4.3 ms early.
        assert!((res.capture.t_s - c.t_capture_s).abs() < 0.003, "t {}", res.capture.t_s);
        assert!(!res.capture.at_window_edge);
        // Gaussian bead, σ = 0.25 mm, 68 °C over background: T_t = 94 °C (half height) is
        // crossed at σ·sqrt(2 ln 2) = 0.294 mm on each side.
        for w in &res.widths_mm {
            let (wl, wr) = w.unwrap();
            assert!((wl - 0.294).abs() < 0.04 && (wr - 0.294).abs() < 0.04, "{wl} {wr}");
        }
    }

    #[test]
    fn a_cold_frame_is_skipped_with_its_reason() {
        let c = case();
        let traj = TrajectoryView::new(&c.t, &c.x, &c.y).unwrap();
        let undistorter = Undistorter::new(&c.nominal).unwrap();
        let params = PipelineParams::paper_defaults(94.0);
        let ctx = FrameContext {
            undistorter: &undistorter,
            h0: c.nominal.nominal_homography(),
            nozzle_px: [79.5, 59.5],
            trajectory: traj,
            params,
        };
        let frame = ThermalFrame::filled(160, 120, 60.0);
        let input = FrameInput { frame: &frame, t_recorded_s: 1.0, predicted: &[], width_queries: &[] };
        let mut ws = FrameWorkspace::new(&undistorter, &params).unwrap();
        let skip = process_frame(&ctx, &input, &mut ws, &mut ChaCha8Rng::seed_from_u64(0)).unwrap_err();
        assert_eq!(skip, FrameSkip::TooFewCorners { found: 0, matched: 0, needed: 4 });
        let small = ThermalFrame::filled(80, 60, 60.0);
        let input = FrameInput { frame: &small, ..input };
        let skip = process_frame(&ctx, &input, &mut ws, &mut ChaCha8Rng::seed_from_u64(0)).unwrap_err();
        assert!(matches!(skip, FrameSkip::Camera(_)));
    }
}
