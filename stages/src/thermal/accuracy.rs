//! `thermal.accuracy_evaluate`: the frame pipeline of `thermal.monitor` against the
//! virtual printer's ground truth (`truth/` of the dataset; only evaluation stages read
//! it, ARCHITECTURE.md). Paper 003 reports the detector's mAP (99.5 %, Sec. 3.2) and no
//! localisation or width accuracy; DESIGN §5.3 asks for precision and recall of our
//! classical detector instead of mAP, and the issue for capture-time, homography and
//! width errors.
//!
//! Metrics (`accuracy.parquet`, one row each, long format):
//! - capture time (eq. 30): |t̂_c − t_c| over the localised frames, median and 90th
//!   percentile, beside the baseline |t_r − t_c| of taking the recorded time as is; the
//!   same for each estimator `frames.parquet` carries (`dlt_*`, `rigid_mount_*`), and the
//!   signed median offsets t̂_c − t_r and t_c − t_r (a constant capture delay such as the
//!   `camera_latency` effect shows in both; the recorded time cannot see it);
//! - nozzle (eq. 29): distance of P_N,i from the true nozzle at the capture time (mm);
//! - rigid mount: the fitted mount H_m against the true mount of `truth.toml`, median
//!   over the image of the distance between the plane points they give one pixel, beside
//!   the same for the nominal mount anchored at the nozzle pixel (the fit's start);
//! - corner vertices: the rigid estimator's ridge vertices that placed a nozzle, to the
//!   true corner pixels (raw px); and the nozzle those corners give with their true
//!   pixels, through the true mount (`nozzle_err_floor_median_mm`: the per-frame camera
//!   vibration, which one translation per frame cannot tell from a nozzle offset, is all
//!   that is left) and through the applied mount (`nozzle_err_true_vertices_median_mm`);
//! - homography (eq. 27): every true corner in a localised frame mapped through the
//!   frame's estimated H onto the plane, distance to its CAD vertex (mm);
//! - widths (Sec. 2.4): measured w_l + w_r against the true deposit's width along the
//!   same deposition direction (fill level 0.5), median absolute error and bias (mm);
//! - corner detection: detections against the true corners whose temperature is in
//!   the detector's band (the "newly printed corners" of Sec. 3.2), within 3 px, on every
//!   frame but those the monitor skipped as repeats of the frame before;
//! - frames placed from their corners, placed by their recorded time (no corner in view,
//!   `thermal.monitor`'s `place_cornerless`), filmed parked after the layer's last move
//!   (the nozzle of both also scored) and skipped.

use std::path::Path;

use models::stats::{finite_median, nearest_rank_quantile};

use datasets::thermal::deposition::edge_distance_mm;
use datasets::thermal::sequence::ThermalTruth;
use models::thermal::DepositGrid;
use pipeline::params::ParamError;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use vision::camera::Undistorter;
use vision::corners::{precision_recall, CornerDetection};
use vision::homography::Homography;

use super::common::{camera_model, f64s, ints, open_sequence, read_table};
use crate::roles;
use crate::table::{f64_col, frame, i64_col, if_present, opt_bools, opt_strs, str_col};
use tables::thermal::{
    accuracy, detections, directions, frames, mount, vertices, widths, FRAME_HOMOGRAPHY, MOUNT_HOMOGRAPHY,
};

/// The `thermal.accuracy_evaluate` stage kind.
pub struct AccuracyEvaluateStage;

/// The monitor scored.
pub const MONITOR: Input = Input::one(
    "monitor",
    &[Source::Stage("thermal.monitor")],
    "the sequence's monitor: its frames, detections, mount, vertices and widths tables",
)
.reading(&[
    Reads {
        table: &frames::TABLE,
        columns: &[frames::layer, frames::frame, frames::recorded_time_s, frames::estimated_time_s],
    },
    Reads {
        table: &detections::TABLE,
        columns: &[detections::layer, detections::frame, detections::raw_u_px, detections::raw_v_px],
    },
    Reads {
        table: &widths::TABLE,
        columns: &[widths::layer, widths::sample, widths::x_mm, widths::y_mm, widths::w_left_mm, widths::w_right_mm],
    },
    Reads { table: &directions::TABLE, columns: &[directions::dep_x, directions::dep_y] },
]);

pipeline::params! {
    /// The parameters of `thermal.accuracy_evaluate`.
    pub struct AccuracyParams {
        /// A detection within this distance of a true corner (raw pixels) is a true positive.
        pub match_radius_px: f64 [0.5, 20.0] = 3.0,
        /// True corners at or above this temperature count as positives (°C); the detector's band, Sec. 3.2.
        pub band_low_c: f64 [0.0, 300.0] = 140.0,
        /// True corners at or below this temperature count as positives (°C).
        pub band_high_c: f64 [0.0, 300.0] = 150.0,
    }
}

impl Stage for AccuracyEvaluateStage {
    type Params = AccuracyParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.accuracy_evaluate",
        version: 8,
        summary: "Frame pipeline against ground truth: capture time, homography, widths, corner precision/recall → accuracy.parquet",
        implements: "paper 003 eqs 27-32 and Sec. 3.2 (mAP → precision/recall), DESIGN §5.3 (evaluation: reads truth/)",
        inputs: &[roles::THERMAL_SEQUENCE, MONITOR],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&accuracy::TABLE];

    fn check(p: &AccuracyParams) -> Result<(), ParamError> {
        if p.band_low_c > p.band_high_c {
            return Err(ParamError::new(
                "band_low_c",
                format!("{} °C is above band_high_c ({} °C): no corner could count", p.band_low_c, p.band_high_c),
            ));
        }
        Ok(())
    }

    fn run(&self, ctx: &mut StageContext, p: &AccuracyParams) -> Result<(), StageError> {
        let sequence_dir = &ctx.input(&roles::THERMAL_SEQUENCE).dir;
        let seq = open_sequence(sequence_dir)?;
        let truth = ThermalTruth::open(sequence_dir).map_err(StageError::domain)?;
        let monitor = ctx.input(&MONITOR).dir.clone();
        let frames = FrameRows::read(&monitor)?;
        let undistorter = Undistorter::new(&camera_model(&seq.camera)).map_err(StageError::domain)?;
        let mut metrics = Metrics::default();
        capture_time_metrics(&frames, &truth, &mut metrics);
        estimator_metrics(&frames, &truth, &mut metrics);
        nozzle_metrics(&frames, &truth, &mut metrics);
        let mounts = mount_metrics(&monitor, &seq, &truth, &undistorter, &mut metrics)?;
        vertex_metrics(&monitor, &seq, &truth, &undistorter, mounts.as_ref(), &mut metrics)?;
        homography_metrics(&frames, &truth, &seq.path_mm, &undistorter, &mut metrics);
        width_metrics(&monitor, &truth, &mut metrics)?;
        let band = (p.band_low_c, p.band_high_c);
        detection_metrics(&monitor, &frames, &truth, band, p.match_radius_px, &mut metrics)?;
        let used = frames.used.iter().filter(|u| **u).count();
        metrics.push("frames_used", used as f64, "frames", used, "frames placed from their corners (eqs 27-30)");
        let dead_reckoned = frames.by_recorded_time.iter().filter(|r| **r).count();
        metrics.push(
            "frames_placed_by_recorded_time",
            dead_reckoned as f64,
            "frames",
            dead_reckoned,
            "no corner in view: placed at the commanded position at t_r + median offset through the fitted mount, widths only",
        );
        let parked = frames.parked.iter().filter(|r| **r).count();
        metrics.push(
            "frames_parked",
            parked as f64,
            "frames",
            parked,
            "filmed after the layer's last move: placed (corners, or the end point) but not timed (eq. 30 needs motion), widths only",
        );
        let skipped = frames.used.len() - used - dead_reckoned - parked;
        metrics.push(
            "frames_skipped",
            skipped as f64,
            "frames",
            skipped,
            "bad, out-of-order or corner-poor frames (see frames.parquet skip_reason)",
        );
        ctx.write_table(accuracy::TABLE.name, &mut metrics.into_frame()?)?;
        Ok(())
    }
}

/// The long metric table.
#[derive(Default)]
struct Metrics {
    metric: Vec<String>,
    value: Vec<f64>,
    unit: Vec<String>,
    n: Vec<i64>,
    note: Vec<String>,
}

impl Metrics {
    fn push(&mut self, metric: &str, value: f64, unit: &str, n: usize, note: &str) {
        self.metric.push(metric.into());
        self.value.push(value);
        self.unit.push(unit.into());
        self.n.push(n as i64);
        self.note.push(note.into());
    }

    fn into_frame(self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            str_col(accuracy::metric, self.metric),
            f64_col(accuracy::value, self.value),
            str_col(accuracy::unit, self.unit),
            i64_col(accuracy::n, self.n),
            str_col(accuracy::note, self.note),
        ])
    }
}

/// The columns of `frames.parquet` this stage needs.
struct FrameRows {
    layer: Vec<i64>,
    frame: Vec<i64>,
    recorded_s: Vec<f64>,
    estimated_s: Vec<f64>,
    used: Vec<bool>,
    /// Placed by the recorded time (`placed_by` = recorded_time): no estimate of its own.
    by_recorded_time: Vec<bool>,
    /// Filmed after the layer's last move (`placed_by` = parked): placed, not timed.
    parked: Vec<bool>,
    /// Skipped as a repeat of the frame before (`repeat_of_frame` ≥ 0; absent in older
    /// tables: none).
    repeated: Vec<bool>,
    at_window_edge: Vec<bool>,
    homography: Vec<Option<Homography>>,
    /// Per estimator in `frames.parquet` (column prefix, capture times; NaN = skipped).
    estimators: Vec<(&'static str, Vec<f64>)>,
    /// P_N,i (mm) where the table has it.
    nozzle_mm: Option<Vec<[f64; 2]>>,
}

impl FrameRows {
    /// (layer, frame) of the frames the monitor skipped as repeats of the frame before:
    /// the detector does not run on them, so they are left out of its precision and recall.
    fn repeats(&self) -> Vec<(i64, i64)> {
        (0..self.repeated.len()).filter(|&i| self.repeated[i]).map(|i| (self.layer[i], self.frame[i])).collect()
    }

    fn read(dir: &Path) -> Result<Self, StageError> {
        let file = dir.join(frames::TABLE.file());
        let df = read_table(dir, &frames::TABLE.file())?;
        let h: Vec<Vec<f64>> = FRAME_HOMOGRAPHY.iter().map(|name| f64s(&df, name, &file)).collect::<Result<_, _>>()?;
        let estimated_s = f64s(&df, frames::estimated_time_s, &file)?;
        let homography = (0..estimated_s.len())
            .map(|r| {
                let m = [[h[0][r], h[1][r], h[2][r]], [h[3][r], h[4][r], h[5][r]], [h[6][r], h[7][r], h[8][r]]];
                m.iter().flatten().all(|v| v.is_finite()).then_some(Homography { m })
            })
            .collect();
        let optional = |name: &str| if_present(&df, name, &file, f64s);
        let mut estimators = Vec::new();
        for (prefix, column) in [("dlt", frames::dlt_time_s), ("rigid_mount", frames::rigid_mount_time_s)] {
            if let Some(t) = optional(column)? {
                estimators.push((prefix, t));
            }
        }
        let nozzle_mm = match (optional(frames::nozzle_x_mm)?, optional(frames::nozzle_y_mm)?) {
            (Some(x), Some(y)) => Some(x.iter().zip(&y).map(|(x, y)| [*x, *y]).collect()),
            _ => None,
        };
        let n = estimated_s.len();
        let placed_by = if_present(&df, frames::placed_by, &file, opt_strs)?.unwrap_or_else(|| vec![None; n]);
        let placed = |how: &str| -> Vec<bool> { placed_by.iter().map(|p| p.as_deref() == Some(how)).collect() };
        let repeated = if_present(&df, frames::repeat_of_frame, &file, ints)?
            .map_or_else(|| vec![false; n], |r| r.iter().map(|r| *r >= 0).collect());
        let at_window_edge = if_present(&df, frames::at_window_edge, &file, opt_bools)?
            .map_or_else(|| vec![false; n], |e| e.iter().map(|v| *v == Some(true)).collect());
        Ok(Self {
            layer: ints(&df, frames::layer, &file)?,
            frame: ints(&df, frames::frame, &file)?,
            recorded_s: f64s(&df, frames::recorded_time_s, &file)?,
            used: estimated_s.iter().map(|t| t.is_finite()).collect(),
            by_recorded_time: placed("recorded_time"),
            parked: placed("parked"),
            repeated,
            at_window_edge,
            estimated_s,
            homography,
            estimators,
            nozzle_mm,
        })
    }
}

fn truth_frame(truth: &ThermalTruth, layer: i64, frame: i64) -> Option<&datasets::thermal::sequence::TruthFrame> {
    truth.frames.iter().find(|f| f.layer as i64 == layer && f.frame as i64 == frame)
}

/// |t − t_c| (ms) of the frames with a finite `times` entry, and the recorded-time
/// baseline |t_r − t_c| on the same frames.
fn time_errors(frames: &FrameRows, truth: &ThermalTruth, times: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (mut ours, mut baseline) = (Vec::new(), Vec::new());
    for i in (0..times.len()).filter(|&i| times[i].is_finite()) {
        if let Some(t) = truth_frame(truth, frames.layer[i], frames.frame[i]) {
            ours.push(1e3 * (times[i] - t.capture_time_s).abs());
            baseline.push(1e3 * (frames.recorded_s[i] - t.capture_time_s).abs());
        }
    }
    (ours, baseline)
}

fn capture_time_metrics(frames: &FrameRows, truth: &ThermalTruth, metrics: &mut Metrics) {
    let (mut ours, baseline) = time_errors(frames, truth, &frames.estimated_s);
    let n = ours.len();
    metrics.push("capture_time_err_median_ms", median(&ours), "ms", n, "|t̂_c − t_c|, eq. 30");
    metrics.push(
        "capture_time_err_p90_ms",
        nearest_rank_quantile(&mut ours, 0.9),
        "ms",
        n,
        "90th percentile of |t̂_c − t_c|",
    );
    metrics.push(
        "capture_time_err_baseline_median_ms",
        median(&baseline),
        "ms",
        n,
        "|t_r − t_c|: the recorded time taken as the capture time",
    );
    let (mut offset, mut true_offset) = (Vec::new(), Vec::new());
    for i in (0..frames.used.len()).filter(|&i| frames.used[i]) {
        if let Some(t) = truth_frame(truth, frames.layer[i], frames.frame[i]) {
            offset.push(1e3 * (frames.estimated_s[i] - frames.recorded_s[i]));
            true_offset.push(1e3 * (t.capture_time_s - frames.recorded_s[i]));
        }
    }
    let n = offset.len();
    metrics.push("capture_offset_median_ms", median(&offset), "ms", n, "median of t̂_c − t_r (signed)");
    metrics.push(
        "capture_offset_true_median_ms",
        median(&true_offset),
        "ms",
        n,
        "median of t_c − t_r (signed): a constant capture delay shows here",
    );
    let edge = frames.at_window_edge.iter().zip(&frames.used).filter(|(e, u)| **e && **u).count();
    metrics.push("frames_at_window_edge", edge as f64, "frames", n, "t̂_c on the edge of t_r ± δt (eq. 30 window)");
}

/// The capture-time error of each estimator `frames.parquet` carries, on its own frames.
fn estimator_metrics(frames: &FrameRows, truth: &ThermalTruth, metrics: &mut Metrics) {
    for (prefix, times) in &frames.estimators {
        let (mut ours, baseline) = time_errors(frames, truth, times);
        let n = ours.len();
        let name = |what: &str| format!("{prefix}_{what}");
        metrics.push(&name("capture_time_err_median_ms"), median(&ours), "ms", n, "|t̂_c − t_c| of this estimator");
        metrics.push(
            &name("capture_time_err_p90_ms"),
            nearest_rank_quantile(&mut ours, 0.9),
            "ms",
            n,
            "90th percentile",
        );
        metrics.push(
            &name("capture_time_err_baseline_median_ms"),
            median(&baseline),
            "ms",
            n,
            "|t_r − t_c| on the frames this estimator localised",
        );
        metrics.push(&name("frames_used"), n as f64, "frames", n, "frames this estimator localised");
    }
}

/// Distance of P_N,i (eq. 29) from the true nozzle at the capture time.
/// Also for the frames placed by their recorded time and those filmed parked.
fn nozzle_metrics(frames: &FrameRows, truth: &ThermalTruth, metrics: &mut Metrics) {
    let Some(nozzle) = &frames.nozzle_mm else { return };
    let errors = |rows: &[bool]| -> Vec<f64> {
        (0..nozzle.len())
            .filter(|&i| rows[i] && nozzle[i][0].is_finite())
            .filter_map(|i| {
                let t = truth_frame(truth, frames.layer[i], frames.frame[i])?;
                Some((nozzle[i][0] - t.nozzle_mm[0]).hypot(nozzle[i][1] - t.nozzle_mm[1]))
            })
            .collect()
    };
    let placed = errors(&frames.used);
    let n = placed.len();
    metrics.push("nozzle_err_median_mm", median(&placed), "mm", n, "|P_N,i − true nozzle at t_c|, eq. 29");
    let dead_reckoned = errors(&frames.by_recorded_time);
    if !dead_reckoned.is_empty() {
        let n = dead_reckoned.len();
        let note = "frames placed by their recorded time (plus the median capture offset) to the true nozzle at t_c";
        metrics.push("recorded_time_nozzle_err_median_mm", median(&dead_reckoned), "mm", n, note);
    }
    let parked = errors(&frames.parked);
    if !parked.is_empty() {
        let n = parked.len();
        let note = "frames filmed after the layer's last move to the true (parked) nozzle";
        metrics.push("parked_nozzle_err_median_mm", median(&parked), "mm", n, note);
    }
}

/// The applied and the true mount (undistorted pixel → plane mm relative to the nozzle).
struct Mounts {
    applied: Homography,
    truth: Homography,
}

/// The mount that placed the frames (`applied` row of `mount.parquet`) and the nominal
/// one against the truth; returns the applied and the true mount.
fn mount_metrics(
    monitor: &Path,
    seq: &datasets::thermal::ThermalSequence,
    truth: &ThermalTruth,
    undistorter: &Undistorter,
    metrics: &mut Metrics,
) -> Result<Option<Mounts>, StageError> {
    if !monitor.join(mount::TABLE.file()).is_file() {
        return Ok(None);
    }
    let file = monitor.join(mount::TABLE.file());
    let df = read_table(monitor, &mount::TABLE.file())?;
    let h: Vec<Vec<f64>> = MOUNT_HOMOGRAPHY.iter().map(|name| f64s(&df, name, &file)).collect::<Result<_, _>>()?;
    let applied = opt_bools(&df, mount::applied, &file)?;
    let Some(last) = applied.iter().position(|a| *a == Some(true)) else { return Ok(None) };
    let fitted = Homography {
        m: [
            [h[0][last], h[1][last], h[2][last]],
            [h[3][last], h[4][last], h[5][last]],
            [h[6][last], h[7][last], h[8][last]],
        ],
    };
    let true_mount =
        Homography { m: datasets::thermal::camera::nominal_homography(&seq.camera.intrinsics, &truth.truth.mount) };
    let nominal =
        Homography { m: datasets::thermal::camera::nominal_homography(&seq.camera.intrinsics, &seq.camera.mount) };
    let nozzle_px = undistorter.undistort_px(seq.camera.nozzle_px);
    let anchored = vision::mount::anchored_at_nozzle(&nominal, nozzle_px).unwrap_or(nominal);
    let cam = undistorter.camera();
    for (name, h, note) in [
        ("mount_err_median_mm", fitted, "applied mount H_m vs the true mount, median over the image"),
        (
            "mount_err_nominal_median_mm",
            anchored,
            "nominal mount anchored at P_N⁽⁰⁾ vs the true mount, median over the image",
        ),
    ] {
        let gaps = image_gaps_mm(&h, &true_mount, cam.width_px, cam.height_px);
        let n = gaps.len();
        metrics.push(name, median(&gaps), "mm", n, note);
    }
    Ok(Some(Mounts { applied: fitted, truth: true_mount }))
}

/// Distances between the plane points two pixel → plane maps give the pixels of an
/// 8-pixel grid over the image (mm); empty when `a` is not finite.
fn image_gaps_mm(a: &Homography, b: &Homography, width: usize, height: usize) -> Vec<f64> {
    let mut out = Vec::new();
    for v in (4..height).step_by(8) {
        for u in (4..width).step_by(8) {
            let (p, q) = (a.apply([u as f64, v as f64]), b.apply([u as f64, v as f64]));
            let d = (p[0] - q[0]).hypot(p[1] - q[1]);
            if d.is_finite() {
                out.push(d);
            }
        }
    }
    out
}

/// The rigid estimator's vertices that placed a nozzle against the true corner pixels,
/// and the nozzle those corners would give with their true pixels: through the true
/// mount (the floor the per-frame camera vibration sets, which one translation per frame
/// cannot tell from a nozzle offset) and through the applied mount (the vertices' share
/// of the nozzle error removed, the mount's left).
fn vertex_metrics(
    monitor: &Path,
    seq: &datasets::thermal::ThermalSequence,
    truth: &ThermalTruth,
    undistorter: &Undistorter,
    mounts: Option<&Mounts>,
    metrics: &mut Metrics,
) -> Result<(), StageError> {
    if !monitor.join(vertices::TABLE.file()).is_file() {
        return Ok(());
    }
    let file = monitor.join(vertices::TABLE.file());
    let df = read_table(monitor, &vertices::TABLE.file())?;
    let (layer, frame_no, vertex) =
        (ints(&df, vertices::layer, &file)?, ints(&df, vertices::frame, &file)?, ints(&df, vertices::vertex, &file)?);
    let (u, v) = (f64s(&df, vertices::raw_u_px, &file)?, f64s(&df, vertices::raw_v_px, &file)?);
    let used: Vec<bool> = opt_bools(&df, vertices::used, &file)?.into_iter().map(|b| b == Some(true)).collect();
    let true_corner = |i: usize| {
        truth
            .corners
            .iter()
            .find(|c| c.layer as i64 == layer[i] && c.frame as i64 == frame_no[i] && c.vertex as i64 == vertex[i])
    };
    let mut errors: Vec<f64> = (0..layer.len())
        .filter(|&i| used[i])
        .filter_map(|i| true_corner(i).map(|c| (u[i] - c.pixel[0]).hypot(v[i] - c.pixel[1])))
        .collect();
    let n = errors.len();
    metrics.push(
        "vertex_err_median_px",
        median(&errors),
        "px",
        n,
        "ridge vertices that placed a nozzle, to the true corner pixels (raw)",
    );
    metrics.push("vertex_err_p90_px", nearest_rank_quantile(&mut errors, 0.9), "px", n, "90th percentile");
    let Some(mounts) = mounts else { return Ok(()) };
    let (mut floor, mut applied) = (Vec::new(), Vec::new());
    let mut i = 0;
    while i < layer.len() {
        let end = (i..layer.len()).find(|&j| (layer[j], frame_no[j]) != (layer[i], frame_no[i])).unwrap_or(layer.len());
        let pairs: Vec<([f64; 2], [f64; 2])> = (i..end)
            .filter(|&k| used[k])
            .filter_map(|k| true_corner(k).map(|c| (undistorter.undistort_px(c.pixel), seq.path_mm[c.vertex])))
            .collect();
        if let (false, Some(t)) = (pairs.is_empty(), truth_frame(truth, layer[i], frame_no[i])) {
            for (h, out) in [(&mounts.truth, &mut floor), (&mounts.applied, &mut applied)] {
                let n = mean_offset_mm(h, &pairs);
                out.push((n[0] - t.nozzle_mm[0]).hypot(n[1] - t.nozzle_mm[1]));
            }
        }
        i = end;
    }
    let n = floor.len();
    metrics.push(
        "nozzle_err_floor_median_mm",
        median(&floor),
        "mm",
        n,
        "the used corners' true pixels through the true mount: the camera-vibration floor",
    );
    metrics.push(
        "nozzle_err_true_vertices_median_mm",
        median(&applied),
        "mm",
        n,
        "the used corners' true pixels through the applied mount: the mount's share",
    );
    Ok(())
}

/// The nozzle position n = mean of c − H_m(x) over (undistorted pixel x, vertex c) pairs.
fn mean_offset_mm(mount: &Homography, pairs: &[([f64; 2], [f64; 2])]) -> [f64; 2] {
    let sum = pairs.iter().fold([0.0; 2], |s, (x, c)| {
        let p = mount.apply(*x);
        [s[0] + c[0] - p[0], s[1] + c[1] - p[1]]
    });
    [sum[0] / pairs.len() as f64, sum[1] / pairs.len() as f64]
}

fn homography_metrics(
    frames: &FrameRows,
    truth: &ThermalTruth,
    path_mm: &[[f64; 2]],
    undistorter: &Undistorter,
    metrics: &mut Metrics,
) {
    let mut errors = Vec::new();
    for i in (0..frames.used.len()).filter(|&i| frames.used[i]) {
        let Some(h) = frames.homography[i] else { continue };
        let in_frame =
            truth.corners.iter().filter(|c| c.layer as i64 == frames.layer[i] && c.frame as i64 == frames.frame[i]);
        for corner in in_frame {
            let plane = h.apply(undistorter.undistort_px(corner.pixel));
            let cad = path_mm[corner.vertex];
            errors.push((plane[0] - cad[0]).hypot(plane[1] - cad[1]));
        }
    }
    let n = errors.len();
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / n.max(1) as f64).sqrt();
    metrics.push(
        "homography_err_median_mm",
        median(&errors),
        "mm",
        n,
        "true corner pixels through the estimated H, to their CAD vertex",
    );
    metrics.push("reprojection_rms_mm", rms, "mm", n, "RMS of the same distances");
}

fn width_metrics(monitor: &Path, truth: &ThermalTruth, metrics: &mut Metrics) -> Result<(), StageError> {
    let file = monitor.join(widths::TABLE.file());
    let df = read_table(monitor, &widths::TABLE.file())?;
    let dirs_file = monitor.join(directions::TABLE.file());
    let dirs = read_table(monitor, &directions::TABLE.file())?;
    let (dep_x, dep_y) = (f64s(&dirs, directions::dep_x, &dirs_file)?, f64s(&dirs, directions::dep_y, &dirs_file)?);
    let layer = ints(&df, widths::layer, &file)?;
    let sample = ints(&df, widths::sample, &file)?;
    let (x, y) = (f64s(&df, widths::x_mm, &file)?, f64s(&df, widths::y_mm, &file)?);
    let (wl, wr) = (f64s(&df, widths::w_left_mm, &file)?, f64s(&df, widths::w_right_mm, &file)?);
    let mut deposits: Vec<Option<DepositGrid>> = Vec::new();
    let (mut abs_err, mut signed) = (Vec::new(), Vec::new());
    for i in (0..layer.len()).filter(|&i| wl[i].is_finite() && wr[i].is_finite()) {
        let l = layer[i] as usize;
        if deposits.len() <= l {
            deposits.resize(l + 1, None);
        }
        if deposits[l].is_none() {
            deposits[l] = Some(truth.deposit(l).map_err(StageError::domain)?);
        }
        let grid = deposits[l].as_ref().expect("just loaded");
        let k = sample[i] as usize;
        let d = [dep_x[k], dep_y[k]];
        let true_width = edge_distance_mm(grid, [x[i], y[i]], d) + edge_distance_mm(grid, [x[i], y[i]], [-d[0], -d[1]]);
        let err = wl[i] + wr[i] - true_width;
        abs_err.push(err.abs());
        signed.push(err);
    }
    let n = abs_err.len();
    metrics.push(
        "width_err_median_mm",
        median(&abs_err),
        "mm",
        n,
        "|(w_l + w_r) − true width| along the deposition direction",
    );
    metrics.push("width_bias_median_mm", median(&signed), "mm", n, "median of the signed width error");
    Ok(())
}

fn detection_metrics(
    monitor: &Path,
    frames: &FrameRows,
    truth: &ThermalTruth,
    band_c: (f64, f64),
    radius_px: f64,
    metrics: &mut Metrics,
) -> Result<(), StageError> {
    let file = monitor.join(detections::TABLE.file());
    let df = read_table(monitor, &detections::TABLE.file())?;
    let (layer, frame_no) = (ints(&df, detections::layer, &file)?, ints(&df, detections::frame, &file)?);
    let (u, v) = (f64s(&df, detections::raw_u_px, &file)?, f64s(&df, detections::raw_v_px, &file)?);
    let repeats = frames.repeats();
    let mut keys: Vec<(i64, i64)> =
        truth.frames.iter().map(|f| (f.layer as i64, f.frame as i64)).filter(|key| !repeats.contains(key)).collect();
    keys.sort_unstable();
    keys.dedup();
    let (mut tp, mut detections, mut positives) = (0usize, 0usize, 0usize);
    for (l, f) in keys {
        let dets: Vec<CornerDetection> = (0..layer.len())
            .filter(|&i| layer[i] == l && frame_no[i] == f)
            .map(|i| CornerDetection { u_px: u[i], v_px: v[i], temp_c: f32::NAN, score: 0.0 })
            .collect();
        let truth_px: Vec<[f64; 2]> = truth
            .corners
            .iter()
            .filter(|c| c.layer as i64 == l && c.frame as i64 == f && c.temp_c >= band_c.0 && c.temp_c <= band_c.1)
            .map(|c| c.pixel)
            .collect();
        let counts = precision_recall(&dets, &truth_px, radius_px);
        tp += counts.true_positives;
        detections += counts.detections;
        positives += counts.truths;
    }
    let ratio = |num: usize, den: usize| if den == 0 { f64::NAN } else { num as f64 / den as f64 };
    metrics.push(
        "corner_precision",
        ratio(tp, detections),
        "fraction",
        detections,
        "detections within the radius of a true in-band corner",
    );
    metrics.push(
        "corner_recall",
        ratio(tp, positives),
        "fraction",
        positives,
        "true in-band corners with a detection within the radius",
    );
    Ok(())
}

/// The median of the finite values: [`finite_median`], as every published median.
fn median(values: &[f64]) -> f64 {
    finite_median(values.iter().copied())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_gaps_are_zero_for_the_same_map_and_the_shift_for_a_translated_one() {
        let h = Homography { m: [[0.15, 0.01, -12.0], [0.002, 0.21, -13.0], [0.0001, 0.0012, 1.0]] };
        assert!(image_gaps_mm(&h, &h, 160, 120).iter().all(|&d| d == 0.0));
        // T(0.3, −0.4)·H moves every plane point by 0.5 mm.
        let shifted = Homography { m: [[1.0, 0.0, 0.3], [0.0, 1.0, -0.4], [0.0, 0.0, 1.0]] }.then_after(&h);
        let gaps = image_gaps_mm(&shifted, &h, 160, 120);
        assert_eq!(gaps.len(), 20 * 15, "an 8-pixel grid over 160 × 120");
        assert!(gaps.iter().all(|d| (d - 0.5).abs() < 1e-9));
    }

    #[test]
    fn true_pixels_through_their_mount_give_the_nozzle_back() {
        let h = Homography { m: [[0.15, 0.01, -12.0], [0.002, 0.21, -13.0], [0.0001, 0.0012, 1.0]] };
        let inv = h.inverse().unwrap();
        let nozzle = [12.5, -3.25];
        let pairs: Vec<([f64; 2], [f64; 2])> = [[14.0, 1.0], [9.0, 4.0], [20.0, -2.0]]
            .iter()
            .map(|c| (inv.apply([c[0] - nozzle[0], c[1] - nozzle[1]]), *c))
            .collect();
        let n = mean_offset_mm(&h, &pairs);
        assert!((n[0] - nozzle[0]).abs() < 1e-9 && (n[1] - nozzle[1]).abs() < 1e-9, "{n:?}");
    }

    #[test]
    fn the_median_is_the_middle_mean_of_the_finite_values() {
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&[4.0, f64::NAN, 3.0]), 3.5);
        assert!(median(&[]).is_nan());
    }
}
