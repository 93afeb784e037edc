//! `thermal.monitor`: paper 003 Secs 2.2-2.4 on a `thermal-sequence` dataset.
//!
//! 1. Deposition directions along the commanded trajectory with and without the
//!    allocation of Sec. 2.2 (eqs 1-26), for the flow the printer should deliver (the
//!    commanded flow through the nominal G(s) of eq. 34) → `directions.parquet`.
//! 2. Every frame localised twice (`vision::localiser`; a bad frame becomes a diagnostic
//!    row, never an abort): by the paper's per-frame homography (undistort, detect the
//!    hot corners in the band, pair them with the CAD corners predicted through the
//!    nominal mount from the recorded time, place each on its path vertex by
//!    intersecting its two bead ridges (`vision::vertex`), eq. 27 by DLT + RANSAC on ≥ 4
//!    pairs, the nozzle by eq. 29, the capture time by eq. 30), and by our rigid-mount
//!    estimator (one mount homography fitted to the whole sequence, one translation per
//!    frame from any number of young corners, then eqs 29-30 alike). The `localisation`
//!    parameter picks the one the widths and the tables use (default `rigid_mount`: it
//!    localises about three times as many frames, and its capture times beat the
//!    recorded time where the DLT's do not; `thermal.accuracy_evaluate` measures both)
//!    → `frames.parquet` (both capture times), `detections.parquet`, `mount.parquet`,
//!    `vertices.parquet`.
//! 3. Widths (Sec. 2.4): each trajectory sample is read in the localised frame in which
//!    its bead is `measure_age_s` old (± half a frame period), along its deposition
//!    direction, at the threshold temperature T_t → `widths.parquet` with the desired
//!    width of eq. 31 and the error of eq. 32.
//!
//! Age: the paper reads frames whose corners are at 140-150 °C, an age it does not
//! state. A corner's bulge stays hot while its heat spreads (σ² = σ0² + 2·D·age), so the
//! older the bead, the more the thermal contour smears the apex excess onto the thin
//! stretch just after the apex, where the head accelerates while the flow still lags.
//! We read each sample young, 0.1 s after deposition, 2 mm behind the nozzle at 20 mm/s;
//! much younger, some corners are not yet fully in view. `specs/chen2024.toml` runs
//! other ages as variants and its report scores them.
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

use datasets::thermal::sequence::ThermalSequence;
use models::progress::Progress;
use models::thermal::compensation::{desired_half_width_mm, width_error_mm};
use models::thermal::dda::DepositionDirections;
use models::thermal::geometry::half_widths_mm;
use models::thermal::{PrintSetup, Trajectory};
use pipeline::params::{ParamError, StageParams};
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use vision::camera::Undistorter;
use vision::localiser::{DetectionRow, Estimator, FrameOutcome, Localiser, LocaliserParams, Located, MountRow};
use vision::pipeline::PipelineParams;
use vision::sequence_widths::{FrameView, LayerWidths, Reading, SequenceWidths, Threshold};
use vision::widths::{bilinear, WidthQuery};

use super::common::{
    camera_model, deposition_directions, filmed_sequence, left_directions, open_sequence, trajectory_of, DatasetFrames,
};
use crate::progress::StageProgress;
use crate::roles;
use crate::table::{bool_col, f64_col, frame, i64_col, str_col};
use pipeline::schema::Table;
use tables::thermal::{
    detections, detections_example, directions, frame_example, frame_example_meta, frames, mosaic, mount, vertices,
    widths, FRAME_HOMOGRAPHY, MOUNT_HOMOGRAPHY,
};

/// The `thermal.monitor` stage kind.
pub struct MonitorStage;

pipeline::choice! {
    /// The estimator whose result the monitor uses.
    pub enum Localisation {
        /// The paper's per-frame homography (eq. 27).
        Dlt = "dlt",
        /// Our rigid-mount estimator.
        RigidMount = "rigid_mount",
    }
}

impl Localisation {
    /// The frame localiser's estimator of this choice.
    pub fn estimator(self) -> Estimator {
        match self {
            Self::Dlt => Estimator::Dlt,
            Self::RigidMount => Estimator::RigidMount,
        }
    }
}

pipeline::params! {
    /// The parameters of `thermal.monitor`.
    pub struct MonitorParams {
        /// Age of the bead (s since deposition) at which its width is read; each sample is read in the frame closest to this age (frames every 0.125 s). Young, because a corner pile's heat spreads along the bead as it ages and smears the apex excess onto the thin stretch after it (module doc).
        pub measure_age_s: f64 [0.05, 3.0] = 0.1,
        /// Choose T_t per layer so that straight beads read the nominal width (the paper identifies w0 on straight lines, Sec. 3.2); false: use threshold_c.
        pub calibrate_threshold: bool = true,
        /// Threshold temperature T_t of the width contour (°C) when calibrate_threshold is false (the paper does not state its value).
        pub threshold_c: f64 [0.0, 300.0] = 120.0,
        /// Samples farther than this from every CAD corner count as straight for the T_t calibration.
        pub straight_clearance_mm: f64 [0.5, 10.0] = 1.5,
        /// Lower edge of the corner temperature band (°C), Sec. 3.2: 140 °C ≤ T_p ≤ 150 °C.
        pub band_low_c: f64 [0.0, 300.0] = 140.0,
        /// Upper edge of the corner temperature band (°C), Sec. 3.2.
        pub band_high_c: f64 [0.0, 300.0] = 150.0,
        /// Frame localisation used for the widths: `dlt`, the paper's per-frame homography from ≥ 4 corners in the band (eq. 27); `rigid_mount`, ours: one mount homography fitted to the whole sequence, one translation per frame from any ridge-placed corner (see `frames.parquet` for both capture times).
        pub localisation: Localisation = Localisation::RigidMount,
        /// rigid_mount only: corners printed longer ago than this (s, from the commanded trajectory) are not used; as a bead cools its heat spreads and the ridges of a corner's two arms pull each other inwards (≈ 0.1 mm after 2 s).
        pub max_corner_age_s: f64 [0.1, 100.0] = 0.8,
        /// rigid_mount only: place a frame with no readable corner (the first few of each layer) by the commanded position at its recorded time (plus the median capture offset of the frames placed from corners) through the fitted mount, so the widths of the layer's start are read; it gets no capture-time estimate (NaN in frames.parquet, `placed_by` = recorded_time). false: skip it, as the paper's method must.
        pub place_cornerless: bool = true,
        /// Half width δt of the capture-time search window of eq. 30 (s); the paper: within 10 ms.
        pub window_s: f64 [0.001, 0.5] = 0.010,
    }
}

impl Stage for MonitorStage {
    type Params = MonitorParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.monitor",
        version: 12,
        summary: "Deposition directions, frame localisation and width extraction → directions, frames, detections, widths (+ Fig. 4 tables)",
        implements: "paper 003 eqs 1-32 (Secs 2.1-2.4), Sec. 3.2",
        inputs: &[roles::THERMAL_SEQUENCE],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[
        &directions::TABLE,
        &widths::TABLE,
        &frames::TABLE,
        &detections::TABLE,
        &mount::TABLE,
        &vertices::TABLE,
        &frame_example::TABLE,
        &detections_example::TABLE,
        &frame_example_meta::TABLE,
        &mosaic::TABLE,
    ];

    fn check(p: &MonitorParams) -> Result<(), ParamError> {
        if p.band_low_c > p.band_high_c {
            return Err(ParamError::new(
                "band_low_c",
                format!(
                    "{} °C is above band_high_c ({} °C): the corner band would be empty",
                    p.band_low_c, p.band_high_c
                ),
            ));
        }
        Ok(())
    }

    fn run(&self, ctx: &mut StageContext, p: &MonitorParams) -> Result<(), StageError> {
        let seq = open_sequence(&ctx.input(&roles::THERMAL_SEQUENCE).dir)?;
        let setup = seq.process.print_setup();
        let trajectory = trajectory_of(&seq)?;
        let (with_dda, without_dda) = deposition_directions(&seq, &trajectory, &setup)?;
        let mut directions = directions_frame(&trajectory, &with_dda, &without_dda, &setup)?;
        ctx.write_table(directions::TABLE.name, &mut directions)?;
        let analysis = Analysis::new(&seq, &trajectory, &with_dda, &setup, p)?;
        let (frames, mounts) = analysis.localise(ctx.seed, p.localisation, &StageProgress::new(ctx))?;
        let widths = analysis.widths(&frames);
        write_frame_tables(ctx, &analysis.localiser.undistorter, &frames, p.localisation)?;
        write_mount_tables(ctx, &analysis.localiser.undistorter, &frames, &mounts)?;
        let mut table = widths_frame(&trajectory, &with_dda, &setup, &widths)?;
        ctx.write_table(widths::TABLE.name, &mut table)?;
        write_figure_tables(ctx, &seq, &analysis, &frames)
    }
}

/// The tables [`MonitorStage`] writes that the analyses downstream read, in memory.
pub struct MonitorTables {
    /// `frames.parquet`.
    pub frames: polars::prelude::DataFrame,
    /// `widths.parquet`.
    pub widths: polars::prelude::DataFrame,
    /// `directions.parquet`.
    pub directions: polars::prelude::DataFrame,
    /// `detections.parquet`.
    pub detections: polars::prelude::DataFrame,
}

/// [`MonitorTables`] of `seq` as [`MonitorStage`] writes them, with its parameters
/// `params` and localisation seed `seed`, without a stage: for studies that monitor
/// many sequences.
pub fn monitor_tables(
    seq: &datasets::thermal::ThermalSequence,
    params: &MonitorParams,
    seed: u64,
) -> Result<MonitorTables, StageError> {
    let setup = seq.process.print_setup();
    let trajectory = trajectory_of(seq)?;
    let (with_dda, without_dda) = deposition_directions(seq, &trajectory, &setup)?;
    let analysis = Analysis::new(seq, &trajectory, &with_dda, &setup, params)?;
    let (frames, _) = analysis.localise(seed, params.localisation, &())?;
    let widths = analysis.widths(&frames);
    Ok(MonitorTables {
        frames: frames_frame(&frames, params.localisation)?,
        widths: widths_frame(&trajectory, &with_dda, &setup, &widths)?,
        directions: directions_frame(&trajectory, &with_dda, &without_dda, &setup)?,
        detections: detections_frame(&analysis.localiser.undistorter, &frames)?,
    })
}

pipeline::params! {
    /// The monitor's parameters a study that films its own prints sets (the others keep
    /// the monitor's defaults), with the studies' defaults.
    pub struct StudyMonitor {
        /// The monitor's band_low_c (as in specs/chen2024.toml).
        pub band_low_c: f64 [0.0, 300.0] = 90.0,
        /// The monitor's band_high_c.
        pub band_high_c: f64 [0.0, 300.0] = 220.0,
        /// The monitor's max_corner_age_s.
        pub max_corner_age_s: f64 [0.1, 100.0] = 0.8,
        /// The monitor's window_s, eq. 30's search half-width: wide enough that a camera delay is measured, not cut off.
        pub window_s: f64 [0.001, 0.5] = 0.05,
    }
}

impl StudyMonitor {
    /// The monitor's parameters: these four, the others at the monitor's defaults,
    /// checked as the planner checks a `thermal.monitor` stage.
    pub fn monitor_params(&self) -> Result<MonitorParams, ParamError> {
        let defaults = MonitorParams::defaults().expect("every parameter of thermal.monitor has a default");
        let params = MonitorParams {
            band_low_c: self.band_low_c,
            band_high_c: self.band_high_c,
            max_corner_age_s: self.max_corner_age_s,
            window_s: self.window_s,
            ..defaults
        };
        MonitorStage::check(&params)?;
        Ok(params)
    }
}

/// Everything the per-frame work needs, built once.
struct Analysis<'a> {
    seq: &'a ThermalSequence,
    trajectory: &'a Trajectory,
    localiser: Localiser<'a, DatasetFrames<'a>>,
    queries: Vec<WidthQuery>,
    straight: Vec<bool>,
    settings: &'a MonitorParams,
    bead_width_mm: f64,
}

impl<'a> Analysis<'a> {
    fn new(
        seq: &'a ThermalSequence,
        trajectory: &'a Trajectory,
        directions: &DepositionDirections,
        setup: &PrintSetup,
        settings: &'a MonitorParams,
    ) -> Result<Self, StageError> {
        let camera = camera_model(&seq.camera);
        let undistorter = Undistorter::new(&camera).map_err(StageError::domain)?;
        let mut params = PipelineParams::paper_defaults(settings.threshold_c);
        params.corners.band_lo_c = settings.band_low_c as f32;
        params.corners.band_hi_c = settings.band_high_c as f32;
        params.window_s = settings.window_s;
        let left = left_directions(directions);
        let queries = (0..trajectory.len())
            .map(|k| WidthQuery { p_mm: [trajectory.x_mm[k], trajectory.y_mm[k]], n_left: left[k] })
            .collect();
        let corners: Vec<(u32, [f64; 2])> = seq.path_mm.iter().enumerate().map(|(i, p)| (i as u32, *p)).collect();
        let settled = setup.settled_samples(trajectory, SETTLED_FLOW_TOLERANCE);
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
            localiser: Localiser::new(
                filmed_sequence(seq, trajectory),
                undistorter,
                LocaliserParams {
                    pipeline: params,
                    max_corner_age_s: settings.max_corner_age_s,
                    place_cornerless: settings.place_cornerless,
                },
            ),
            queries,
            straight,
            settings,
            bead_width_mm: setup.bead_width_mm,
        })
    }

    /// Every frame localised by both estimators, `method`'s placement chosen, and the
    /// rigid mount of every pass.
    fn localise(
        &self,
        seed: u64,
        method: Localisation,
        progress: &dyn Progress,
    ) -> Result<(Vec<FrameOutcome>, Vec<MountRow>), StageError> {
        self.localiser.run(seed, method.estimator(), progress).map_err(StageError::domain)
    }

    /// Widths of every layer's samples at the (calibrated) threshold
    /// (`vision::sequence_widths`).
    fn widths(&self, frames: &[FrameOutcome]) -> Vec<LayerWidths> {
        let threshold = if self.settings.calibrate_threshold {
            Threshold::Calibrated {
                low_c: self.seq.process.bed_temp_c + 1.0,
                high_c: self.seq.process.nozzle_temp_c,
                nominal_width_mm: self.bead_width_mm,
            }
        } else {
            Threshold::Fixed(self.settings.threshold_c)
        };
        let reading = Reading {
            measure_age_s: self.settings.measure_age_s,
            frame_period_s: self.seq.camera.frame_period_s,
            widths: self.localiser.params.widths,
            threshold,
        };
        let views: Vec<FrameView> = frames
            .iter()
            .map(|f| FrameView {
                layer: f.entry.layer,
                placed: f.located().map(|l| (l.t_s, &l.plane_to_px)),
                image: f.undistorted.as_ref(),
            })
            .collect();
        SequenceWidths { t_s: &self.trajectory.t_s, queries: &self.queries, straight: &self.straight, reading }
            .layers(&views)
    }
}

/// Largest relative gap between the lagged and the commanded flow at which a sample's
/// bead counts as settled for the T_t calibration (`PrintSetup::settled_samples`: after
/// each corner the head accelerates while the flow still lags, so a short leg is thinner
/// than the nominal bead along most of its length).
const SETTLED_FLOW_TOLERANCE: f64 = 0.02;

/// The skip reasons of `frames`, counted: "12 × too few corners: …; 3 × …".
fn skip_summary(frames: &[FrameOutcome]) -> String {
    let mut groups: std::collections::BTreeMap<&str, Vec<(usize, usize)>> = std::collections::BTreeMap::new();
    for f in frames {
        if let Some(reason) = f.shared_skip_reason() {
            groups.entry(reason).or_default().push((f.entry.layer, f.entry.frame));
        }
    }
    let plural = |n: usize| if n == 1 { "frame" } else { "frames" };
    groups
        .iter()
        .map(|(reason, ids)| format!("{} ({} {}): {reason}", frame_ranges(ids), ids.len(), plural(ids.len())))
        .collect::<Vec<_>>()
        .join("; ")
}

/// `layer 0, frames 3-40, 42; layer 1, frame 0` for `(layer, frame)` pairs.
fn frame_ranges(ids: &[(usize, usize)]) -> String {
    let mut ids = ids.to_vec();
    ids.sort_unstable();
    let mut layers: Vec<(usize, Vec<(usize, usize)>)> = Vec::new();
    for (layer, frame) in ids {
        match layers.last_mut() {
            Some((l, runs)) if *l == layer => match runs.last_mut() {
                Some((_, end)) if *end + 1 == frame => *end = frame,
                _ => runs.push((frame, frame)),
            },
            _ => layers.push((layer, vec![(frame, frame)])),
        }
    }
    let run = |&(a, b): &(usize, usize)| if a == b { a.to_string() } else { format!("{a}-{b}") };
    layers
        .iter()
        .map(|(layer, runs)| {
            let single = runs.len() == 1 && runs[0].0 == runs[0].1;
            let list: Vec<String> = runs.iter().map(run).collect();
            format!("layer {layer}, {} {}", if single { "frame" } else { "frames" }, list.join(", "))
        })
        .collect::<Vec<_>>()
        .join("; ")
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
        i64_col(directions::sample, (0..n as i64).collect()),
        f64_col(directions::t_s, trajectory.t_s.clone()),
        f64_col(directions::x_mm, trajectory.x_mm.clone()),
        f64_col(directions::y_mm, trajectory.y_mm.clone()),
        f64_col(directions::speed_mm_s, speed),
        f64_col(directions::kappa_per_mm, with.curvature_per_mm.clone()),
        f64_col(directions::kappa_eff_per_mm, with.effective_curvature_per_mm.clone()),
        f64_col(directions::psi_rad, with.psi_rad.clone()),
        f64_col(directions::slender_before, with.slender_before.clone()),
        f64_col(directions::slender_after, with.slender_after.clone()),
        f64_col(directions::normal_x, normal.iter().map(|d| d[0]).collect()),
        f64_col(directions::normal_y, normal.iter().map(|d| d[1]).collect()),
        f64_col(directions::dep_x, left.iter().map(|d| d[0]).collect()),
        f64_col(directions::dep_y, left.iter().map(|d| d[1]).collect()),
        f64_col(directions::w_left_mm, wl),
        f64_col(directions::w_right_mm, wr),
        f64_col(directions::w_left_no_dda_mm, wl0),
        f64_col(directions::w_right_no_dda_mm, wr0),
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
        i64_col(widths::layer, layer_col),
        i64_col(widths::sample, sample_col),
        f64_col(widths::t_s, t),
        f64_col(widths::x_mm, x),
        f64_col(widths::y_mm, y),
        f64_col(widths::temp_c, temp),
        f64_col(widths::w_left_mm, wl),
        f64_col(widths::w_right_mm, wr),
        f64_col(widths::w_desired_mm, wd),
        f64_col(widths::dw_mm, dw),
        i64_col(widths::frame_index, frame_col),
        f64_col(widths::threshold_c, tt),
    ])
}

/// `frames.parquet`: one row per frame, both localisations' capture times.
fn frames_frame(frames: &[FrameOutcome], method: Localisation) -> Result<polars::prelude::DataFrame, StageError> {
    let located = |f: &FrameOutcome| f.located().copied();
    let homography_cols: Vec<_> = (0..9)
        .map(|i| {
            let values =
                frames.iter().map(|f| located(f).map_or(f64::NAN, |l| l.px_to_plane.m[i / 3][i % 3])).collect();
            f64_col(FRAME_HOMOGRAPHY[i], values)
        })
        .collect();
    let of = |g: fn(&Located) -> f64| -> Vec<f64> {
        frames.iter().map(|f| located(f).map_or(f64::NAN, |l| g(&l))).collect()
    };
    let time_of = |r: &Result<Located, String>| r.as_ref().map_or(f64::NAN, |l| l.estimated_time_s());
    let mut columns = vec![
        i64_col(frames::layer, frames.iter().map(|f| f.entry.layer as i64).collect()),
        i64_col(frames::frame, frames.iter().map(|f| f.entry.frame as i64).collect()),
        f64_col(frames::recorded_time_s, frames.iter().map(|f| f.entry.recorded_time_s).collect()),
        f64_col(frames::estimated_time_s, of(|l| l.estimated_time_s())),
        i64_col(frames::corners_found, frames.iter().map(|f| f.corners_found as i64).collect()),
        i64_col(frames::corners_matched, frames.iter().map(|f| f.matched as i64).collect()),
        f64_col(frames::reproj_err_mm, of(|l| l.fit_err_mm)),
        bool_col(frames::used, frames.iter().map(FrameOutcome::localised).collect()),
        str_col(
            frames::placed_by,
            frames.iter().map(|f| located(f).map_or("", |l| l.placed_by.name()).to_string()).collect(),
        ),
        bool_col(frames::at_window_edge, frames.iter().map(|f| located(f).is_some_and(|l| l.at_window_edge)).collect()),
        str_col(frames::skip_reason, frames.iter().map(|f| f.skip_reason().unwrap_or_default().to_string()).collect()),
        i64_col(frames::repeat_of_frame, frames.iter().map(|f| f.repeat_of.map_or(-1, |r| r as i64)).collect()),
    ];
    columns.extend(homography_cols);
    columns.extend([
        str_col(frames::localisation, vec![method.name().to_string(); frames.len()]),
        i64_col(frames::corners_used, frames.iter().map(|f| located(f).map_or(0, |l| l.pairs as i64)).collect()),
        f64_col(frames::nozzle_x_mm, of(|l| l.nozzle_mm[0])),
        f64_col(frames::nozzle_y_mm, of(|l| l.nozzle_mm[1])),
        f64_col(frames::dlt_time_s, frames.iter().map(|f| time_of(&f.dlt)).collect()),
        f64_col(frames::rigid_mount_time_s, frames.iter().map(|f| time_of(&f.rigid)).collect()),
    ]);
    frame(columns)
}

/// `frames.parquet` and `detections.parquet`.
fn write_frame_tables(
    ctx: &mut StageContext,
    undistorter: &Undistorter,
    frames: &[FrameOutcome],
    method: Localisation,
) -> Result<(), StageError> {
    ctx.write_table(frames::TABLE.name, &mut frames_frame(frames, method)?)?;
    ctx.write_table(detections::TABLE.name, &mut detections_frame(undistorter, frames)?)?;
    Ok(())
}

/// `detections.parquet`: every hot corner found, with its frame, pixel and temperature.
fn detections_frame(
    undistorter: &Undistorter,
    frames: &[FrameOutcome],
) -> Result<polars::prelude::DataFrame, StageError> {
    let rows: Vec<(&FrameOutcome, &DetectionRow)> =
        frames.iter().flat_map(|f| f.detections.iter().map(move |d| (f, d))).collect();
    let raw: Vec<[f64; 2]> = rows.iter().map(|(_, d)| undistorter.distort_px(d.1)).collect();
    frame(vec![
        i64_col(detections::layer, rows.iter().map(|(f, _)| f.entry.layer as i64).collect()),
        i64_col(detections::frame, rows.iter().map(|(f, _)| f.entry.frame as i64).collect()),
        f64_col(detections::u_px, rows.iter().map(|(_, d)| d.1[0]).collect()),
        f64_col(detections::v_px, rows.iter().map(|(_, d)| d.1[1]).collect()),
        f64_col(detections::raw_u_px, raw.iter().map(|p| p[0]).collect()),
        f64_col(detections::raw_v_px, raw.iter().map(|p| p[1]).collect()),
        f64_col(detections::temp_c, rows.iter().map(|(_, d)| d.2).collect()),
        i64_col(detections::matched_vertex, rows.iter().map(|(_, d)| d.0).collect()),
    ])
}

/// `mount.parquet` (the rigid mounts, one row per pass: 0 the nominal start, 1 the fit
/// to the detections' pairs, 2 and up the re-pairing rounds; H_m row-major, pairs, frames and RMS residual, or the reason a fit failed, and
/// which one placed the frames) and `vertices.parquet` (every ridge-placed corner pair
/// of the rigid estimator, and whether it placed the nozzle).
fn write_mount_tables(
    ctx: &mut StageContext,
    undistorter: &Undistorter,
    frames: &[FrameOutcome],
    mounts: &[MountRow],
) -> Result<(), StageError> {
    let fit_value = |m: &MountRow, g: &dyn Fn(&vision::mount::MountFit) -> f64| m.fit.as_ref().map_or(f64::NAN, g);
    let mut columns = vec![i64_col(mount::pass, mounts.iter().map(|m| m.pass).collect())];
    for (i, name) in MOUNT_HOMOGRAPHY.iter().enumerate() {
        columns.push(f64_col(name, mounts.iter().map(|m| fit_value(m, &|f| f.mount.m[i / 3][i % 3])).collect()));
    }
    columns.extend([
        i64_col(mount::pairs_used, mounts.iter().map(|m| m.fit.as_ref().map_or(0, |f| f.pairs_used as i64)).collect()),
        i64_col(
            mount::frames_used,
            mounts.iter().map(|m| m.fit.as_ref().map_or(0, |f| f.frames_used as i64)).collect(),
        ),
        f64_col(mount::rms_mm, mounts.iter().map(|m| fit_value(m, &|f| f.rms_mm)).collect()),
        bool_col(mount::applied, mounts.iter().map(|m| m.applied).collect()),
        str_col(mount::error, mounts.iter().map(|m| m.fit.as_ref().err().cloned().unwrap_or_default()).collect()),
    ]);
    ctx.write_table(mount::TABLE.name, &mut frame(columns)?)?;
    let rows: Vec<(&FrameOutcome, usize)> =
        frames.iter().flat_map(|f| (0..f.pairs.len()).map(move |k| (f, k))).collect();
    let px = |(f, k): &(&FrameOutcome, usize)| f.pairs.image_px[*k];
    let raw: Vec<[f64; 2]> = rows.iter().map(|r| undistorter.distort_px(px(r))).collect();
    let mut vertices = frame(vec![
        i64_col(vertices::layer, rows.iter().map(|(f, _)| f.entry.layer as i64).collect()),
        i64_col(vertices::frame, rows.iter().map(|(f, _)| f.entry.frame as i64).collect()),
        i64_col(vertices::vertex, rows.iter().map(|(f, k)| i64::from(f.pairs.ids[*k])).collect()),
        f64_col(vertices::u_px, rows.iter().map(|r| px(r)[0]).collect()),
        f64_col(vertices::v_px, rows.iter().map(|r| px(r)[1]).collect()),
        f64_col(vertices::raw_u_px, raw.iter().map(|p| p[0]).collect()),
        f64_col(vertices::raw_v_px, raw.iter().map(|p| p[1]).collect()),
        bool_col(vertices::used, rows.iter().map(|(f, k)| f.pair_used.get(*k).copied().unwrap_or(false)).collect()),
    ])?;
    ctx.write_table(vertices::TABLE.name, &mut vertices)?;
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
        .filter(|f| f.localised())
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
    ctx.write_table(
        frame_example::TABLE.name,
        &mut frame(vec![
            i64_col(frame_example::u_px, u),
            i64_col(frame_example::v_px, v),
            f64_col(frame_example::temp_c, t),
        ])?,
    )?;
    let d = &best.detections;
    let mut det = frame(vec![
        f64_col(detections_example::u_px, d.iter().map(|x| x.1[0]).collect()),
        f64_col(detections_example::v_px, d.iter().map(|x| x.1[1]).collect()),
        f64_col(detections_example::temp_c, d.iter().map(|x| x.2).collect()),
        i64_col(detections_example::matched_vertex, d.iter().map(|x| x.0).collect()),
    ])?;
    ctx.write_table(detections_example::TABLE.name, &mut det)?;
    let nozzle = analysis.localiser.undistorter.undistort_px(seq.camera.nozzle_px);
    let mut meta = frame(vec![
        i64_col(frame_example_meta::layer, vec![best.entry.layer as i64]),
        i64_col(frame_example_meta::frame, vec![best.entry.frame as i64]),
        f64_col(frame_example_meta::nozzle_u_px, vec![nozzle[0]]),
        f64_col(frame_example_meta::nozzle_v_px, vec![nozzle[1]]),
    ])?;
    ctx.write_table(frame_example_meta::TABLE.name, &mut meta)?;
    let mut mosaic = mosaic_frame(analysis, frames, best.entry.layer)?;
    ctx.write_table(mosaic::TABLE.name, &mut mosaic)?;
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
    for f in frames.iter().filter(|f| f.entry.layer == layer) {
        let (Some(image), Some(h)) = (&f.undistorted, f.located().map(|l| &l.plane_to_px)) else { continue };
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
        f64_col(mosaic::x_mm, keep.iter().map(|&i| x0 + ((i % nx) as f64 + 0.5) * MOSAIC_CELL_MM).collect()),
        f64_col(mosaic::y_mm, keep.iter().map(|&i| y0 + ((i / nx) as f64 + 0.5) * MOSAIC_CELL_MM).collect()),
        f64_col(mosaic::temp_c, keep.iter().map(|&i| temp[i]).collect()),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn localisation_names_round_trip() {
        for name in Localisation::NAMES {
            assert_eq!(Localisation::parse(name).map(Localisation::name), Some(*name));
        }
    }

    #[test]
    fn frames_are_listed_as_runs_per_layer() {
        let ids = [(0, 42), (0, 3), (0, 4), (0, 5), (1, 0), (0, 40)];
        assert_eq!(frame_ranges(&ids), "layer 0, frames 3-5, 40, 42; layer 1, frame 0");
        assert_eq!(frame_ranges(&[(2, 7), (2, 8)]), "layer 2, frames 7-8");
    }

    #[test]
    fn a_study_sets_four_of_the_monitor_s_parameters_with_the_monitor_s_names_and_ranges() {
        for study in StudyMonitor::specs() {
            let monitor = MonitorParams::specs().iter().find(|m| m.name == study.name).expect("a monitor parameter");
            assert_eq!(study.ty.to_string(), monitor.ty.to_string(), "{}", study.name);
        }
        let study = StudyMonitor::defaults().expect("all defaulted");
        let p = study.monitor_params().unwrap();
        assert_eq!((p.band_low_c, p.band_high_c, p.max_corner_age_s, p.window_s), (90.0, 220.0, 0.8, 0.05));
        let monitor = MonitorParams::defaults().expect("all defaulted");
        assert_eq!(MonitorParams { band_low_c: 90.0, band_high_c: 220.0, window_s: 0.05, ..monitor }, p);
    }

    #[test]
    fn an_inverted_corner_band_is_refused_before_anything_runs() {
        let study = StudyMonitor { band_low_c: 200.0, band_high_c: 150.0, ..StudyMonitor::defaults().unwrap() };
        assert_eq!(study.monitor_params().unwrap_err().field, "band_low_c");
        let p = MonitorParams { band_low_c: 150.0, band_high_c: 150.0, ..MonitorParams::defaults().unwrap() };
        assert!(MonitorStage::check(&p).is_ok(), "a one-temperature band is a band");
    }
}
