//! `thermal.monitor`: paper 003 Secs 2.2-2.4 on a `thermal-sequence` dataset.
//!
//! 1. Deposition directions along the commanded trajectory with and without the
//!    allocation of Sec. 2.2 (eqs 1-26), for the flow the printer should deliver (the
//!    commanded flow through the nominal G(s) of eq. 34) → `directions.parquet`.
//! 2. Every frame: decode (a bad frame becomes a diagnostic row, never an abort),
//!    undistort, detect the hot corners in the 140-150 °C band, pair them with the CAD
//!    corners predicted from the recorded time through the nominal mount, place each
//!    paired corner on its path vertex by intersecting its two bead ridges (the heat
//!    peak sits inside the corner; see `vision::vertex`), estimate the
//!    frame's homography (eq. 27, DLT + RANSAC), place the nozzle (eq. 29) and estimate
//!    the capture time (eq. 30) → `frames.parquet`, `detections.parquet`.
//! 3. Widths (Sec. 2.4): each trajectory sample is read in the localised frame in which
//!    its bead is `measure_age_s` old (± half a frame period), along its deposition
//!    direction, at the threshold temperature T_t → `widths.parquet` with the desired
//!    width of eq. 31 and the error of eq. 32.
//!
//! T_t: the paper does not give it. Heat spreads sideways as the bead cools, so the
//! contour at any fixed temperature drifts with age; we calibrate T_t per layer the way
//! the paper identifies w0 (Sec. 3.2, experimentally, on straight lines): the T_t at
//! which the median width of the straight samples (more than `straight_clearance_mm`
//! from any corner, and where eq. 34 with the nominal τ says the flow has settled after
//! the last corner) equals the nominal bead width. Set `calibrate_threshold = false` to
//! use `threshold_c` as given instead.
//!
//! Also written for the figures (Fig. 4): the undistorted frame with the most matched
//! corners, its detections, and a mosaic of all localised frames on the plane.

use std::path::Path;

use datasets::thermal::deposition::conventional_command;
use datasets::thermal::sequence::{FrameEntry, ThermalSequence};
use models::thermal::compensation::{desired_half_width_mm, width_error_mm};
use models::thermal::dda::DepositionDirections;
use models::thermal::dynamics::first_order_lag;
use models::thermal::geometry::half_widths_mm;
use models::thermal::{PrintSetup, Trajectory};
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vision::camera::Undistorter;
use vision::frame::ThermalFrame;
use vision::homography::Homography;
use vision::localize::TrajectoryView;
use vision::matching::PredictedCorner;
use vision::pipeline::{
    predict_path_corners_into, process_frame, FrameContext, FrameInput, FrameWorkspace, PathCorner, PipelineParams,
};
use vision::widths::{bilinear, extract_widths_into, WidthParams, WidthQuery};

use super::common::{
    camera_model, deposition_directions, left_directions, open_sequence, trajectory_of, vertex_passage_times,
};
use crate::table::{bool_col, f64_col, frame, i64_col, str_col};

/// The `thermal.monitor` stage kind.
pub struct MonitorStage;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "measure_age_s",
        ty: ParamType::Float { min: 0.05, max: 3.0 },
        default: ParamDefault::Float(0.25),
        doc: "Age of the bead (s since deposition) at which its width is read; each sample is read in the frame closest to this age (frames every 0.125 s, Sec. 3.2).",
    },
    ParamSpec {
        name: "calibrate_threshold",
        ty: ParamType::Bool,
        default: ParamDefault::Bool(true),
        doc: "Choose T_t per layer so that straight beads read the nominal width (the paper identifies w0 on straight lines, Sec. 3.2); false: use threshold_c.",
    },
    ParamSpec {
        name: "threshold_c",
        ty: ParamType::Float { min: 0.0, max: 300.0 },
        default: ParamDefault::Float(120.0),
        doc: "Threshold temperature T_t of the width contour (°C) when calibrate_threshold is false (the paper does not state its value).",
    },
    ParamSpec {
        name: "straight_clearance_mm",
        ty: ParamType::Float { min: 0.5, max: 10.0 },
        default: ParamDefault::Float(1.5),
        doc: "Samples farther than this from every CAD corner count as straight for the T_t calibration.",
    },
    ParamSpec {
        name: "band_low_c",
        ty: ParamType::Float { min: 0.0, max: 300.0 },
        default: ParamDefault::Float(140.0),
        doc: "Lower edge of the corner temperature band (°C), Sec. 3.2: 140 °C ≤ T_p ≤ 150 °C.",
    },
    ParamSpec {
        name: "band_high_c",
        ty: ParamType::Float { min: 0.0, max: 300.0 },
        default: ParamDefault::Float(150.0),
        doc: "Upper edge of the corner temperature band (°C), Sec. 3.2.",
    },
    ParamSpec {
        name: "window_s",
        ty: ParamType::Float { min: 0.001, max: 0.5 },
        default: ParamDefault::Float(0.010),
        doc: "Half width δt of the capture-time search window of eq. 30 (s); the paper: within 10 ms.",
    },
];

impl StageKind for MonitorStage {
    fn name(&self) -> &'static str {
        "thermal.monitor"
    }
    fn version(&self) -> u32 {
        2
    }
    fn summary(&self) -> &'static str {
        "Deposition directions, frame localisation and width extraction → directions, frames, detections, widths (+ Fig. 4 tables)"
    }
    fn implements(&self) -> &'static str {
        "paper 003 eqs 1-32 (Secs 2.1-2.4), Sec. 3.2"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let seq = open_sequence(&ctx.inputs[0].dir)?;
        let setup = seq.process.print_setup();
        let trajectory = trajectory_of(&seq)?;
        let (with_dda, without_dda) = deposition_directions(&seq, &trajectory, &setup)?;
        let mut directions = directions_frame(&trajectory, &with_dda, &without_dda, &setup)?;
        ctx.write_table("directions", &mut directions)?;
        let settings = Settings::from_params(ctx);
        let analysis = Analysis::new(&seq, &trajectory, &with_dda, &setup, settings)?;
        let frames = analysis.localise_all(ctx.seed)?;
        let widths = analysis.widths(&frames);
        write_frame_tables(ctx, &analysis.undistorter, &frames)?;
        let mut table = widths_frame(&trajectory, &with_dda, &setup, &widths)?;
        ctx.write_table("widths", &mut table)?;
        write_figure_tables(ctx, &seq, &analysis, &frames)
    }
}

/// The checked parameters.
#[derive(Debug, Clone, Copy)]
struct Settings {
    measure_age_s: f64,
    calibrate: bool,
    threshold_c: f64,
    straight_clearance_mm: f64,
    band_c: (f64, f64),
    window_s: f64,
}

impl Settings {
    fn from_params(ctx: &StageContext) -> Self {
        let p = &ctx.params;
        Self {
            measure_age_s: p.f64("measure_age_s"),
            calibrate: p.bool("calibrate_threshold"),
            threshold_c: p.f64("threshold_c"),
            straight_clearance_mm: p.f64("straight_clearance_mm"),
            band_c: (p.f64("band_low_c"), p.f64("band_high_c")),
            window_s: p.f64("window_s"),
        }
    }
}

/// A detection: (matched vertex or −1, undistorted pixel, temperature °C).
type DetectionRow = (i64, [f64; 2], f64);

/// One frame's outcome.
struct FrameOutcome {
    entry: FrameEntry,
    /// Why it was not used (None: used).
    skip: Option<String>,
    corners_found: usize,
    /// (vertex, u, v (undistorted px), temp) of every detection; vertex −1 if unmatched.
    detections: Vec<(i64, [f64; 2], f64)>,
    matched: usize,
    estimated_time_s: f64,
    at_window_edge: bool,
    reproj_err_mm: f64,
    plane_to_px: Option<Homography>,
    px_to_plane: Option<Homography>,
    undistorted: Option<ThermalFrame>,
}

/// Everything the per-frame work needs, built once.
struct Analysis<'a> {
    seq: &'a ThermalSequence,
    trajectory: &'a Trajectory,
    undistorter: Undistorter,
    h0: Homography,
    params: PipelineParams,
    path_corners: Vec<PathCorner>,
    passage_s: Vec<f64>,
    queries: Vec<WidthQuery>,
    straight: Vec<bool>,
    settings: Settings,
    bead_width_mm: f64,
}

impl<'a> Analysis<'a> {
    fn new(
        seq: &'a ThermalSequence,
        trajectory: &'a Trajectory,
        directions: &DepositionDirections,
        setup: &PrintSetup,
        settings: Settings,
    ) -> Result<Self, StageError> {
        let camera = camera_model(&seq.camera);
        let undistorter = Undistorter::new(&camera).map_err(StageError::domain)?;
        let mut params = PipelineParams::paper_defaults(settings.threshold_c);
        params.corners.band_lo_c = settings.band_c.0 as f32;
        params.corners.band_hi_c = settings.band_c.1 as f32;
        params.window_s = settings.window_s;
        let left = left_directions(directions);
        let queries = (0..trajectory.len())
            .map(|k| WidthQuery { p_mm: [trajectory.x_mm[k], trajectory.y_mm[k]], n_left: left[k] })
            .collect();
        let corners: Vec<(u32, [f64; 2])> = seq.path_mm.iter().enumerate().map(|(i, p)| (i as u32, *p)).collect();
        let settled = settled_flow(setup, trajectory);
        let straight = (0..trajectory.len())
            .map(|k| {
                let p = [trajectory.x_mm[k], trajectory.y_mm[k]];
                settled[k]
                    && corners.iter().all(|(_, c)| (c[0] - p[0]).hypot(c[1] - p[1]) > settings.straight_clearance_mm)
            })
            .collect();
        Ok(Self {
            seq,
            trajectory,
            h0: camera.nominal_homography(),
            undistorter,
            params,
            passage_s: vertex_passage_times(seq, trajectory),
            path_corners: PathCorner::of_closed_path(&seq.path_mm),
            queries,
            straight,
            settings,
            bead_width_mm: setup.bead_width_mm,
        })
    }

    /// Localises every frame of the sequence, in file order.
    fn localise_all(&self, seed: u64) -> Result<Vec<FrameOutcome>, StageError> {
        let view = TrajectoryView::new(&self.trajectory.t_s, &self.trajectory.x_mm, &self.trajectory.y_mm)
            .map_err(StageError::domain)?;
        let ctx = FrameContext {
            undistorter: &self.undistorter,
            h0: self.h0,
            nozzle_px: self.seq.camera.nozzle_px,
            trajectory: view,
            params: self.params,
        };
        let mut workspace = FrameWorkspace::new(&self.undistorter, &self.params).map_err(StageError::domain)?;
        let mut last_time: Option<(usize, f64)> = None;
        let mut outcomes = Vec::with_capacity(self.seq.frames.len());
        for entry in &self.seq.frames {
            let order_problem = match last_time {
                Some((layer, t)) if layer == entry.layer && entry.recorded_time_s <= t => Some(format!(
                    "recorded time {:.4} s is not after the previous frame's {:.4} s (out of order)",
                    entry.recorded_time_s, t
                )),
                _ => None,
            };
            let outcome = match order_problem {
                Some(reason) => skipped(entry, reason),
                None => {
                    last_time = Some((entry.layer, entry.recorded_time_s));
                    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((entry.layer as u64) << 32 | entry.frame as u64));
                    self.localise(&ctx, entry, &mut workspace, &mut rng)
                }
            };
            outcomes.push(outcome);
        }
        Ok(outcomes)
    }

    /// One frame: decode, predict, localise (a failure is a diagnostic, not an error).
    fn localise(
        &self,
        ctx: &FrameContext<'_>,
        entry: &FrameEntry,
        workspace: &mut FrameWorkspace,
        rng: &mut ChaCha8Rng,
    ) -> FrameOutcome {
        let path = self.seq.frame_path(entry);
        let frame = match ThermalFrame::from_png_file(&path) {
            Ok(frame) => frame,
            Err(e) => return skipped(entry, format!("{}: {e}", display_rel(&path))),
        };
        let t_r = entry.recorded_time_s;
        let nozzle = ctx.trajectory.position_mm(t_r);
        let printed: Vec<PathCorner> =
            self.path_corners.iter().copied().filter(|c| self.passage_s[c.id as usize] <= t_r).collect();
        let mut predicted: Vec<PredictedCorner> = Vec::new();
        predict_path_corners_into(&self.h0, nozzle, &printed, &mut predicted);
        let input = FrameInput { frame: &frame, t_recorded_s: t_r, predicted: &predicted, width_queries: &[] };
        let result = process_frame(ctx, &input, workspace, rng);
        let detections = collect_detections(workspace, result.as_ref().ok(), &predicted);
        match result {
            Ok(r) => {
                let plane_to_px = r.homography.homography.inverse();
                FrameOutcome {
                    entry: entry.clone(),
                    skip: None,
                    corners_found: r.corners_found,
                    matched: r.matches.len(),
                    detections,
                    estimated_time_s: r.capture.t_s,
                    at_window_edge: r.capture.at_window_edge,
                    reproj_err_mm: r.homography.rms_error_mm,
                    plane_to_px,
                    px_to_plane: Some(r.homography.homography),
                    undistorted: Some(workspace.undistorted().clone()),
                }
            }
            Err(skip) => {
                let found = detections.len();
                FrameOutcome { corners_found: found, detections, ..skipped(entry, skip.to_string()) }
            }
        }
    }

    /// For each trajectory sample, the used frame in which its bead is closest to the
    /// measuring age (within half a frame period).
    fn frame_of_samples(&self, frames: &[FrameOutcome], layer: usize) -> Vec<Option<usize>> {
        let half_period = 0.5 * self.seq.camera.frame_period_s;
        let mut best: Vec<Option<(usize, f64)>> = vec![None; self.trajectory.len()];
        for (i, f) in frames.iter().enumerate().filter(|(_, f)| f.skip.is_none() && f.entry.layer == layer) {
            for (k, slot) in best.iter_mut().enumerate() {
                let miss = (f.estimated_time_s - self.trajectory.t_s[k] - self.settings.measure_age_s).abs();
                if miss <= half_period && slot.is_none_or(|(_, m)| miss < m) {
                    *slot = Some((i, miss));
                }
            }
        }
        best.into_iter().map(|b| b.map(|(i, _)| i)).collect()
    }

    /// Widths of every layer's samples at the (calibrated) threshold.
    fn widths(&self, frames: &[FrameOutcome]) -> Vec<LayerWidths> {
        let layers = frames.iter().map(|f| f.entry.layer).max().map_or(0, |l| l + 1);
        (0..layers)
            .map(|layer| {
                let owner = self.frame_of_samples(frames, layer);
                let threshold_c = if self.settings.calibrate {
                    self.calibrated_threshold(frames, &owner)
                } else {
                    self.settings.threshold_c
                };
                let measured = self.read_widths(frames, &owner, threshold_c);
                LayerWidths { layer, threshold_c, owner, measured }
            })
            .collect()
    }

    /// Half widths and centre temperature of every sample at `threshold_c`.
    fn read_widths(&self, frames: &[FrameOutcome], owner: &[Option<usize>], threshold_c: f64) -> Vec<Measured> {
        let params = WidthParams { threshold_c, ..self.params.widths };
        let mut out = Vec::with_capacity(1);
        owner
            .iter()
            .zip(&self.queries)
            .map(|(frame, query)| {
                let Some(f) = frame.map(|i| &frames[i]) else { return Measured::default() };
                let (Some(image), Some(h)) = (&f.undistorted, &f.plane_to_px) else { return Measured::default() };
                extract_widths_into(image, h, std::slice::from_ref(query), &params, &mut out);
                let px = h.apply(query.p_mm);
                let temp_c = bilinear(image, px[0], px[1]).unwrap_or(f64::NAN);
                let (left, right) = out[0].unwrap_or((f64::NAN, f64::NAN));
                Measured { left_mm: left, right_mm: right, temp_c }
            })
            .collect()
    }

    /// T_t at which the median straight-bead width equals the nominal width (bisection:
    /// the contour narrows as the threshold rises).
    fn calibrated_threshold(&self, frames: &[FrameOutcome], owner: &[Option<usize>]) -> f64 {
        let straight_owner: Vec<Option<usize>> =
            owner.iter().zip(&self.straight).map(|(o, s)| if *s { *o } else { None }).collect();
        let median_width = |t: f64| -> f64 {
            let mut w: Vec<f64> = self
                .read_widths(frames, &straight_owner, t)
                .iter()
                .map(|m| m.left_mm + m.right_mm)
                .filter(|w| w.is_finite())
                .collect();
            median(&mut w)
        };
        let (mut lo, mut hi) = (self.seq.process.bed_temp_c + 1.0, self.seq.process.nozzle_temp_c);
        for _ in 0..30 {
            let mid = 0.5 * (lo + hi);
            let w = median_width(mid);
            if !w.is_finite() || w < self.bead_width_mm {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// The widths read on one layer.
struct LayerWidths {
    layer: usize,
    threshold_c: f64,
    owner: Vec<Option<usize>>,
    measured: Vec<Measured>,
}

/// One sample's reading.
#[derive(Debug, Clone, Copy)]
struct Measured {
    left_mm: f64,
    right_mm: f64,
    temp_c: f64,
}

impl Default for Measured {
    fn default() -> Self {
        Self { left_mm: f64::NAN, right_mm: f64::NAN, temp_c: f64::NAN }
    }
}

/// Largest relative gap between the lagged and the commanded flow at which a sample's
/// bead counts as settled for the T_t calibration.
const SETTLED_FLOW_TOLERANCE: f64 = 0.02;

/// Samples where the nominal deposition dynamics (eq. 34 with the nominal τ) have
/// settled: the lagged conventional command is within [`SETTLED_FLOW_TOLERANCE`] of the
/// command. After each corner the head accelerates while the flow still lags, so a short
/// leg of the test path is thinner than the nominal bead along most of its length; only
/// settled samples may calibrate T_t to the nominal width.
fn settled_flow(setup: &PrintSetup, trajectory: &Trajectory) -> Vec<bool> {
    let command = conventional_command(setup, trajectory);
    let lagged = first_order_lag(&command, trajectory.dt_s, setup.tau_s, 0.0);
    let steady = setup.nominal_deposition_velocity_mm_s(setup.feed_mm_s);
    lagged.iter().zip(&command).map(|(l, c)| (l - c).abs() <= SETTLED_FLOW_TOLERANCE * steady).collect()
}

fn skipped(entry: &FrameEntry, reason: String) -> FrameOutcome {
    FrameOutcome {
        entry: entry.clone(),
        skip: Some(reason),
        corners_found: 0,
        detections: Vec::new(),
        matched: 0,
        estimated_time_s: f64::NAN,
        at_window_edge: false,
        reproj_err_mm: f64::NAN,
        plane_to_px: None,
        px_to_plane: None,
        undistorted: None,
    }
}

/// The detections of the last processed frame with the vertex each was matched to.
fn collect_detections(
    workspace: &FrameWorkspace,
    result: Option<&vision::pipeline::FrameResult>,
    predicted: &[PredictedCorner],
) -> Vec<(i64, [f64; 2], f64)> {
    workspace
        .detections()
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let vertex = result
                .and_then(|r| r.matches.iter().find(|m| m.detection == i))
                .map_or(-1, |m| i64::from(predicted[m.predicted].id));
            (vertex, [d.u_px, d.v_px], f64::from(d.temp_c))
        })
        .collect()
}

/// The skip reasons of `frames`, counted: "12 × too few corners: …; 3 × …".
fn skip_summary(frames: &[FrameOutcome]) -> String {
    let mut counts: std::collections::BTreeMap<&str, usize> = std::collections::BTreeMap::new();
    for reason in frames.iter().filter_map(|f| f.skip.as_deref()) {
        *counts.entry(reason).or_default() += 1;
    }
    counts.iter().map(|(r, n)| format!("{n} × {r}")).collect::<Vec<_>>().join("; ")
}

fn display_rel(path: &Path) -> String {
    let parts: Vec<_> = path.iter().rev().take(2).collect();
    parts.iter().rev().map(|p| p.to_string_lossy()).collect::<Vec<_>>().join("/")
}

fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// `directions.parquet`: the deposition frame with and without DDA (Fig. 3).
fn directions_frame(
    trajectory: &Trajectory,
    with: &DepositionDirections,
    without: &DepositionDirections,
    setup: &PrintSetup,
) -> Result<polars::prelude::DataFrame, StageError> {
    let n = trajectory.len();
    let speed = trajectory.speed_mm_s();
    let left = left_directions(with);
    let normal = left_directions(without);
    let h = setup.layer_height_mm;
    let (mut wl, mut wr, mut wl0, mut wr0) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    for k in 0..n {
        let q = with.reach_mm[k];
        let dda = models::thermal::geometry::half_widths_from_reach(q, with.effective_curvature_per_mm[k]);
        (wl[k], wr[k]) = (dda.left_mm, dda.right_mm);
        let plain = half_widths_mm(q * speed[k] * h, speed[k], h, without.curvature_per_mm[k]);
        let slender = without.slender_before[k] <= 1.0;
        wl0[k] = if slender { plain.left_mm } else { f64::NAN };
        wr0[k] = if slender { plain.right_mm } else { f64::NAN };
    }
    frame(vec![
        i64_col("sample", (0..n as i64).collect()),
        f64_col("t_s", trajectory.t_s.clone()),
        f64_col("x_mm", trajectory.x_mm.clone()),
        f64_col("y_mm", trajectory.y_mm.clone()),
        f64_col("speed_mm_s", speed),
        f64_col("kappa_per_mm", with.curvature_per_mm.clone()),
        f64_col("kappa_eff_per_mm", with.effective_curvature_per_mm.clone()),
        f64_col("psi_rad", with.psi_rad.clone()),
        f64_col("slender_before", with.slender_before.clone()),
        f64_col("slender_after", with.slender_after.clone()),
        f64_col("normal_x", normal.iter().map(|d| d[0]).collect()),
        f64_col("normal_y", normal.iter().map(|d| d[1]).collect()),
        f64_col("dep_x", left.iter().map(|d| d[0]).collect()),
        f64_col("dep_y", left.iter().map(|d| d[1]).collect()),
        f64_col("w_left_mm", wl),
        f64_col("w_right_mm", wr),
        f64_col("w_left_no_dda_mm", wl0),
        f64_col("w_right_no_dda_mm", wr0),
    ])
}

/// `widths.parquet`: per layer and sample, the reading and eqs 31-32.
fn widths_frame(
    trajectory: &Trajectory,
    directions: &DepositionDirections,
    setup: &PrintSetup,
    layers: &[LayerWidths],
) -> Result<polars::prelude::DataFrame, StageError> {
    let w0 = setup.bead_width_mm / 2.0;
    let desired = desired_half_width_mm(w0, &directions.psi_rad);
    let mut cols: [Vec<f64>; 9] = Default::default();
    let (mut layer_col, mut sample_col, mut frame_col) = (Vec::new(), Vec::new(), Vec::new());
    for lw in layers {
        let left: Vec<f64> = lw.measured.iter().map(|m| m.left_mm).collect();
        let right: Vec<f64> = lw.measured.iter().map(|m| m.right_mm).collect();
        let dw = width_error_mm(&left, &right, &desired);
        for k in 0..trajectory.len() {
            layer_col.push(lw.layer as i64);
            sample_col.push(k as i64);
            frame_col.push(lw.owner[k].map_or(-1, |i| i as i64));
            let row = [
                trajectory.t_s[k],
                trajectory.x_mm[k],
                trajectory.y_mm[k],
                lw.measured[k].temp_c,
                left[k],
                right[k],
                2.0 * desired[k],
                dw[k],
                lw.threshold_c,
            ];
            for (col, v) in cols.iter_mut().zip(row) {
                col.push(v);
            }
        }
    }
    let [t, x, y, temp, wl, wr, wd, dw, tt] = cols;
    frame(vec![
        i64_col("layer", layer_col),
        i64_col("sample", sample_col),
        f64_col("t_s", t),
        f64_col("x_mm", x),
        f64_col("y_mm", y),
        f64_col("temp_c", temp),
        f64_col("w_left_mm", wl),
        f64_col("w_right_mm", wr),
        f64_col("w_desired_mm", wd),
        f64_col("dw_mm", dw),
        i64_col("frame_index", frame_col),
        f64_col("threshold_c", tt),
    ])
}

/// `frames.parquet` and `detections.parquet`.
fn write_frame_tables(
    ctx: &mut StageContext,
    undistorter: &Undistorter,
    frames: &[FrameOutcome],
) -> Result<(), StageError> {
    let used: Vec<bool> = frames.iter().map(|f| f.skip.is_none()).collect();
    let homography_cols: Vec<_> = (0..9)
        .map(|i| {
            let values = frames.iter().map(|f| f.px_to_plane.map_or(f64::NAN, |h| h.m[i / 3][i % 3])).collect();
            f64_col(&format!("h{}{}", i / 3 + 1, i % 3 + 1), values)
        })
        .collect();
    let mut columns = vec![
        i64_col("layer", frames.iter().map(|f| f.entry.layer as i64).collect()),
        i64_col("frame", frames.iter().map(|f| f.entry.frame as i64).collect()),
        f64_col("recorded_time_s", frames.iter().map(|f| f.entry.recorded_time_s).collect()),
        f64_col("estimated_time_s", frames.iter().map(|f| f.estimated_time_s).collect()),
        i64_col("corners_found", frames.iter().map(|f| f.corners_found as i64).collect()),
        i64_col("corners_matched", frames.iter().map(|f| f.matched as i64).collect()),
        f64_col("reproj_err_mm", frames.iter().map(|f| f.reproj_err_mm).collect()),
        bool_col("used", used),
        bool_col("at_window_edge", frames.iter().map(|f| f.at_window_edge).collect()),
        str_col("skip_reason", frames.iter().map(|f| f.skip.clone().unwrap_or_default()).collect()),
    ];
    columns.extend(homography_cols);
    ctx.write_table("frames", &mut frame(columns)?)?;
    let rows: Vec<(&FrameOutcome, &DetectionRow)> =
        frames.iter().flat_map(|f| f.detections.iter().map(move |d| (f, d))).collect();
    let raw: Vec<[f64; 2]> = rows.iter().map(|(_, d)| undistorter.distort_px(d.1)).collect();
    let mut detections = frame(vec![
        i64_col("layer", rows.iter().map(|(f, _)| f.entry.layer as i64).collect()),
        i64_col("frame", rows.iter().map(|(f, _)| f.entry.frame as i64).collect()),
        f64_col("u_px", rows.iter().map(|(_, d)| d.1[0]).collect()),
        f64_col("v_px", rows.iter().map(|(_, d)| d.1[1]).collect()),
        f64_col("raw_u_px", raw.iter().map(|p| p[0]).collect()),
        f64_col("raw_v_px", raw.iter().map(|p| p[1]).collect()),
        f64_col("temp_c", rows.iter().map(|(_, d)| d.2).collect()),
        i64_col("matched_vertex", rows.iter().map(|(_, d)| d.0).collect()),
    ])?;
    ctx.write_table("detections", &mut detections)?;
    Ok(())
}

/// Fig. 4's tables: the frame with the most matched corners (earliest on ties), its
/// detections and nozzle, and the mosaic of every localised frame on the plane.
fn write_figure_tables(
    ctx: &mut StageContext,
    seq: &ThermalSequence,
    analysis: &Analysis<'_>,
    frames: &[FrameOutcome],
) -> Result<(), StageError> {
    let best = frames
        .iter()
        .filter(|f| f.skip.is_none())
        .max_by(|a, b| a.matched.cmp(&b.matched).then(b.entry.recorded_time_s.total_cmp(&a.entry.recorded_time_s)));
    let Some(best) = best else {
        return Err(StageError::BadInput {
            file: seq.dir.join("frames.csv"),
            location: None,
            expected: format!("at least one frame that can be localised; none could: {}", skip_summary(frames)),
        });
    };
    let image = best.undistorted.as_ref().expect("used frames keep their image");
    let (mut u, mut v, mut t) = (Vec::new(), Vec::new(), Vec::new());
    for row in 0..image.height {
        for col in 0..image.width {
            u.push(col as i64);
            v.push(row as i64);
            t.push(f64::from(image.at(col, row)));
        }
    }
    ctx.write_table("frame_example", &mut frame(vec![i64_col("u_px", u), i64_col("v_px", v), f64_col("temp_c", t)])?)?;
    let d = &best.detections;
    let mut det = frame(vec![
        f64_col("u_px", d.iter().map(|x| x.1[0]).collect()),
        f64_col("v_px", d.iter().map(|x| x.1[1]).collect()),
        f64_col("temp_c", d.iter().map(|x| x.2).collect()),
        i64_col("matched_vertex", d.iter().map(|x| x.0).collect()),
    ])?;
    ctx.write_table("detections_example", &mut det)?;
    let nozzle = analysis.undistorter.undistort_px(seq.camera.nozzle_px);
    let mut meta = frame(vec![
        i64_col("layer", vec![best.entry.layer as i64]),
        i64_col("frame", vec![best.entry.frame as i64]),
        f64_col("nozzle_u_px", vec![nozzle[0]]),
        f64_col("nozzle_v_px", vec![nozzle[1]]),
    ])?;
    ctx.write_table("frame_example_meta", &mut meta)?;
    let mut mosaic = mosaic_frame(analysis, frames, best.entry.layer)?;
    ctx.write_table("mosaic", &mut mosaic)?;
    Ok(())
}

/// Cell size of the mosaic (mm): about one camera pixel on the plane.
const MOSAIC_CELL_MM: f64 = 0.1;

/// The localised frames of `layer` stitched on the plane, the latest frame on top
/// (Fig. 4d).
fn mosaic_frame(
    analysis: &Analysis<'_>,
    frames: &[FrameOutcome],
    layer: usize,
) -> Result<polars::prelude::DataFrame, StageError> {
    let tr = analysis.trajectory;
    let fold = |v: &[f64], f: fn(f64, f64) -> f64, init: f64| v.iter().copied().fold(init, f);
    let (x0, x1) = (fold(&tr.x_mm, f64::min, f64::INFINITY) - 3.0, fold(&tr.x_mm, f64::max, f64::NEG_INFINITY) + 3.0);
    let (y0, y1) = (fold(&tr.y_mm, f64::min, f64::INFINITY) - 3.0, fold(&tr.y_mm, f64::max, f64::NEG_INFINITY) + 3.0);
    let nx = ((x1 - x0) / MOSAIC_CELL_MM).ceil() as usize;
    let ny = ((y1 - y0) / MOSAIC_CELL_MM).ceil() as usize;
    let mut temp = vec![f64::NAN; nx * ny];
    for f in frames.iter().filter(|f| f.skip.is_none() && f.entry.layer == layer) {
        let (Some(image), Some(h)) = (&f.undistorted, &f.plane_to_px) else { continue };
        for (i, cell) in temp.iter_mut().enumerate() {
            let p = [x0 + ((i % nx) as f64 + 0.5) * MOSAIC_CELL_MM, y0 + ((i / nx) as f64 + 0.5) * MOSAIC_CELL_MM];
            let px = h.apply(p);
            if let Some(value) = bilinear(image, px[0], px[1]) {
                *cell = value;
            }
        }
    }
    let keep: Vec<usize> = (0..nx * ny).filter(|&i| temp[i].is_finite()).collect();
    frame(vec![
        f64_col("x_mm", keep.iter().map(|&i| x0 + ((i % nx) as f64 + 0.5) * MOSAIC_CELL_MM).collect()),
        f64_col("y_mm", keep.iter().map(|&i| y0 + ((i / nx) as f64 + 0.5) * MOSAIC_CELL_MM).collect()),
        f64_col("temp_c", keep.iter().map(|&i| temp[i]).collect()),
    ])
}
