//! `thermal.compensate`: the dynamic deposition compensation of paper 003 Sec. 2.4
//! (eqs 31-39) with the parameters of Sec. 3.2, from the widths `thermal.monitor` read.
//!
//! Spans where |Δw| ≥ ε (eq. 32) are extended by 0.1 s at both ends; spans whose
//! extended windows touch are merged so that every sample has one compensation. For
//! each span: the corner it belongs to (the CAD vertex nearest its largest error), the
//! corner temperature T_p (median temperature of that corner's detections, all inside
//! the monitor's band by construction), the gain K_e = 1 + (150 − T_p)/15 (Sec. 3.2,
//! T_p clamped to the paper's 140-150 °C band, or 1, see below),
//! the desired change of the deposition velocity (eq. 33) and the filtered-B-spline
//! input that produces it through G(s) within the bounds (eqs 36-39).
//!
//! Choices of ours, each beside the paper's text. What each costs or gains is measured,
//! not quoted here: `specs/chen2024.toml` runs the alternatives as variants (on the
//! thermal widths and, through `thermal.true_widths_evaluate`, on the printer's true ones) and
//! the report's table of variants scores them.
//! - Desired width (`desired_width = "cad"`). Paper eq. 31: "w_d(t) = w0/cos(φ_eff(t))",
//!   the width of a straight bead along a direction tilted by φ. At a sharp corner the
//!   inner deposition directions point into the wedge where the incoming and outgoing
//!   beads overlap: the ideal (CAD, mitred) bead itself is far wider than w0/cos ψ there
//!   (0.59 mm along the bisector of a 45° corner against 0.225 mm), so eq. 31 reads a
//!   perfect corner as over-deposited. We take the ideal bead's extent along each
//!   direction (`IdealBead::edge_distance_mm`), which equals w0/cos ψ on straight edges.
//! - Flow excess (`volume = "linear"`): eq. 33 as printed, h·|v|·cos ψ·Δw. The option
//!   `sweep` takes the area swept by the turning deposition segments instead (see
//!   models::thermal::compensation); it counts less of the excess at the apex, where
//!   most of it is, and thins the apexes less (variant `sweep`).
//! - Both signs (`add_material = true`). Paper eq. 33 is signed, and the spans are
//!   |Δw| ≥ ε. The earlier default dropped Δw < 0 because eq. 31's w0/cos ψ made them
//!   spurious; with the CAD desired width they are the real thinning after a corner
//!   (the head accelerates while the lagged flow is still low).
//! - Gain (`gain = "unit"`). Paper Sec. 3.2: "K_e = 1 + (150 − T_p)/15", identified by
//!   experiment on its printer and camera for corners in its 140-150 °C band. Our
//!   monitor's band is 90-220 °C (specs/chen2024.toml), so T_p is off the formula's
//!   scale (above 165 °C it turns negative); clamped to the band, it gives K_e = 1.67 to
//!   every corner read below 140 °C and 1 to every one above 150 °C. Without an identification
//!   experiment of ours, the mass balance (K_e = 1) is the neutral choice; `paper`
//!   keeps the clamped formula (variant `paper_gain`).
//! - Tail (`tail_s` = 3τ): the lagged output is fitted to zero for 0.26 s after each
//!   extended window (the paper fits the window only).
//!
//! Extension (`source = "lag_model"`, not the paper's method): the same filtered
//! B-spline solve, but the desired output is the flow excess eq. 34 predicts for the
//! nominal command, lag(v_e) − v_e, over the whole layer, with no widths. The paper
//! identifies τ (Sec. 3.2) and then corrects only what the camera sees; the widths read
//! along the deposition directions miss the part of a corner's flow excess that is
//! squeezed around the apex, between them (see the report), so the model-based
//! feed-forward is run beside the paper's width feedback and both are scored by their
//! own re-print. It knows nothing of the CAD bead: it also removes the excess that
//! filled the bead's tips.
//!
//! Inputs: the `thermal-sequence`, the monitor's folder (`widths.parquet`,
//! `directions.parquet`, `detections.parquet`) and, optionally, a folder whose
//! `widths.parquet` (same columns) replaces the monitor's: `thermal.true_widths_evaluate`, the
//! printer's true widths (an evaluation of the method with a perfect camera).
//!
//! Units: the deposition velocity v_e is the extruder's (E-axis) velocity in mm/s of
//! filament, E = A_fil·v_e. This is the reading under which the paper's numbers fit
//! together: w0 = K·α + b with K = 3.44 mm, b = 0.67 mm only gives a sub-millimetre
//! bead for a feed-to-deposition ratio α of a few percent, i.e. filament speed over
//! path speed, and the bounds ΔV ∈ [−2, 4] mm/s then allow the short retraction a
//! corner needs. A flow excess ΔE (mm³/s) is Δv_e = K_e·ΔE/A_fil.

use std::path::Path;

use datasets::thermal::sequence::ThermalSequence;
use models::stats::finite_median;
use models::thermal::compensation::{
    apply_spans, compensate_spans, desired_half_width_mm, paper_gain, velocity_change_from_sweep_mm_s, FbsParams,
    SampleSpan, SpanCompensation, SpanParams, SweepSample,
};
use models::thermal::dynamics::lag_excess;
use models::thermal::metrics::IdealBead;
use models::thermal::Trajectory;
use pipeline::params::StageParams;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;

use super::common::{f64s, ints, open_sequence, read_table, sample_index, trajectory_of};
use crate::roles;
use crate::table::{f64_col, frame, i64_col};
use models::thermal::setup::interior_angles_deg;
use tables::thermal::{command, compensation, detections, directions, spans, widths};

/// The temperature band over which the paper identified K_e (Sec. 3.2): its corners are
/// measured at 140-150 °C, so K_e runs from 1 to 1.67. A corner measured outside the band
/// (the monitor's band may be wider, see specs/chen2024.toml) is clamped to it: the
/// formula is not meant to be extrapolated (it turns negative above 165 °C).
const PAPER_BAND_C: (f64, f64) = (140.0, 150.0);

/// The `thermal.compensate` stage kind.
pub struct CompensateStage;

/// The monitor of the sequence.
pub const MONITOR: Input = Input::one(
    "monitor",
    &[Source::Stage("thermal.monitor")],
    "the sequence's monitor: its widths.parquet, directions.parquet and detections.parquet",
)
.reading(&[
    WIDTHS_READ,
    Reads {
        table: &directions::TABLE,
        columns: &[
            directions::sample,
            directions::dep_x,
            directions::dep_y,
            directions::psi_rad,
            directions::kappa_eff_per_mm,
            directions::speed_mm_s,
        ],
    },
    Reads { table: &detections::TABLE, columns: &[detections::matched_vertex, detections::temp_c] },
]);

/// What the compensation reads of a widths table (the monitor's, or one in its place).
const WIDTHS_READ: Reads =
    Reads { table: &widths::TABLE, columns: &[widths::layer, widths::sample, widths::w_left_mm, widths::w_right_mm] };

/// Widths read otherwise, in place of the monitor's.
pub const WIDTHS: Input = Input::optional(
    "widths",
    &[Source::Stage("thermal.true_widths_evaluate"), Source::Stage("thermal.monitor")],
    "a widths.parquet with the monitor's columns used in place of the monitor's: `thermal.true_widths_evaluate`, the printer's true widths (an evaluation of the method with a perfect camera)",
)
.reading(&[WIDTHS_READ]);

pipeline::choice! {
    /// What the compensation cancels.
    pub enum CompensationSource {
        /// The measured width errors (the paper, eqs 31-33).
        Widths = "widths",
        /// Our extension: the flow excess eq. 34 predicts for the nominal command.
        LagModel = "lag_model",
    }
}

pipeline::choice! {
    /// The deposition correction gain K_e.
    pub enum GainRule {
        /// 1 + (150 − T_p)/15 with T_p clamped to 140-150 °C (Sec. 3.2).
        Paper = "paper",
        /// 1: mass conservation.
        Unit = "unit",
    }
}

pipeline::choice! {
    /// The desired half widths along each deposition direction.
    pub enum DesiredWidth {
        /// The extent of the ideal (CAD, mitred) bead along it.
        Cad = "cad",
        /// w0/cos ψ, as eq. 31.
        Eq31 = "eq31",
    }
}

pipeline::choice! {
    /// How the flow excess follows from the half widths.
    pub enum Volume {
        /// The area swept by the turning deposition segments.
        Sweep = "sweep",
        /// h·|v|·cos ψ·Δw, eq. 33 as printed.
        Linear = "linear",
    }
}

pipeline::params! {
    /// The parameters of `thermal.compensate`.
    pub struct CompensateParams {
        /// What the compensation cancels: `widths` = the measured width errors (the paper, eqs 31-33); `lag_model` = our extension, the flow excess the deposition dynamics of eq. 34 predict for the nominal command, lag(v_e) − v_e over the whole layer, with no widths (feed-forward; module doc).
        pub source: CompensationSource = CompensationSource::Widths,
        /// First monitored layer whose widths drive the compensation (the paper's one-layer verification print is layer 0).
        pub layer: i64 [0, 19] = 0,
        /// Number of consecutive monitored layers from `layer` whose widths are combined (per sample, the median over the layers that read it); 1 = the paper's single layer.
        pub layers: i64 [1, 20] = 1,
        /// Largest tolerable width error ε (mm): spans with |Δw| ≥ ε are compensated (Sec. 2.4; the paper gives no value, 0.05 mm is about a third of a camera pixel on the plane).
        pub epsilon_mm: f64 [0.0, 2.0] = 0.05,
        /// Time added at both ends of each span for the deposition dynamics (s); Sec. 3.2: 0.1 s.
        pub extension_s: f64 [0.0, 1.0] = 0.1,
        /// Knot spacing of the cubic B-spline input (s); about τ/4 (the paper does not state it).
        pub knot_spacing_s: f64 [0.002, 0.5] = 0.02,
        /// Lower bound ΔV_min of the control points (mm/s of filament), Sec. 3.2: −2 mm/s.
        pub dv_min_mm_s: f64 [-100.0, 0.0] = -2.0,
        /// Upper bound ΔV_max of the control points (mm/s of filament), Sec. 3.2: 4 mm/s.
        pub dv_max_mm_s: f64 [0.0, 100.0] = 4.0,
        /// Also compensate where the bead is measured narrower than desired (Δw < 0) by adding material, as eq. 33 is signed; false: only over-deposition (module doc).
        pub add_material: bool = true,
        /// Deposition correction gain K_e: `unit` = 1 (mass conservation), `paper` = 1 + (150 − T_p)/15 with T_p the corner temperature clamped to 140-150 °C (Sec. 3.2; identified on the paper's printer, module doc).
        pub gain: GainRule = GainRule::Unit,
        /// Desired half widths along each deposition direction: `cad` = extent of the ideal (CAD, mitred) bead along it, `eq31` = w0/cos ψ as eq. 31 (a straight bead; counts the inner wedge of a sharp corner as excess).
        pub desired_width: DesiredWidth = DesiredWidth::Cad,
        /// Flow excess from the half widths: `linear` = h·|v|·cos ψ·Δw (eq. 33 as printed), `sweep` = area swept by the turning deposition segments (eqs 5-6 in the rotated frame, with the sector terms).
        pub volume: Volume = Volume::Linear,
        /// Time after each extended window over which the lagged output of its input is fitted to zero (s); 3τ = 0.26 s lets the response die out, 0 = the paper's window only.
        pub tail_s: f64 [0.0, 1.0] = 0.26,
    }
}

impl CompensateParams {
    /// `thermal.compensate`'s declared defaults (the paper's settings where it gives
    /// them, ours beside them where it does not; module doc), for [`compensate`].
    pub fn stage_defaults() -> Self {
        Self::defaults().expect("every parameter of thermal.compensate has a default")
    }
}

impl Stage for CompensateStage {
    type Params = CompensateParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.compensate",
        version: 6,
        summary: "Width-error spans, corner gains and filtered-B-spline compensation → spans, compensation, command",
        implements: "paper 003 eqs 31-39 (Sec. 2.4), parameters of Sec. 3.2",
        inputs: &[roles::THERMAL_SEQUENCE, MONITOR, WIDTHS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&command::TABLE, &spans::TABLE, &compensation::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &CompensateParams) -> Result<(), StageError> {
        let seq = open_sequence(&ctx.input(&roles::THERMAL_SEQUENCE).dir)?;
        let monitor_dir = ctx.input(&MONITOR).dir.clone();
        let widths_dir = ctx.optional_input(&WIDTHS).map_or(monitor_dir.clone(), |i| i.dir.clone());
        let tables = MonitorInputs {
            dir: &monitor_dir,
            widths_dir: &widths_dir,
            widths: &read_table(&widths_dir, &widths::TABLE.file())?,
            directions: &read_table(&monitor_dir, &directions::TABLE.file())?,
            detections: &read_table(&monitor_dir, &detections::TABLE.file())?,
        };
        let tau_s = seq.process.print_setup().tau_s;
        let c = compensate(&seq, &tables, p, tau_s)?;
        let angles = interior_angles_deg(&seq.path_mm);
        let t_s = &c.trajectory.t_s;
        let mut rows = Rows::default();
        for (index, (s, &vertex)) in c.spans.iter().zip(&c.span_vertices).enumerate() {
            let max_dw = c.dw[s.span.first..=s.span.last].iter().copied().filter(|d| d.is_finite()).fold(0.0, f64::max);
            let temp = c.corner_temps_c[vertex];
            rows.span(index, vertex, angles[vertex], t_s, s.span, s.window, temp, s.gain, max_dw);
            rows.samples(index, vertex, t_s, s, &c.widths_mm);
        }
        rows.write(ctx)?;
        let mut table = frame(vec![
            i64_col(command::sample, (0..c.trajectory.len() as i64).collect()),
            f64_col(command::t_s, t_s.clone()),
            f64_col(command::v_e_mm_s, c.nominal_mm_s),
            f64_col(command::v_ef_mm_s, c.command_mm_s),
        ])?;
        ctx.write_table(command::TABLE.name, &mut table)?;
        Ok(())
    }
}

/// The monitor's tables the compensation reads, and the folder they belong to (named
/// in errors).
pub struct MonitorInputs<'a> {
    /// The monitor's output folder.
    pub dir: &'a Path,
    /// The folder `widths` comes from: the monitor's, or one with the same columns.
    pub widths_dir: &'a Path,
    /// `widths.parquet`.
    pub widths: &'a DataFrame,
    /// `directions.parquet`.
    pub directions: &'a DataFrame,
    /// `detections.parquet`.
    pub detections: &'a DataFrame,
}

/// A compensated layer.
pub struct Compensated {
    /// The commanded trajectory.
    pub trajectory: Trajectory,
    /// The conventional command v_e per sample (mm/s of filament).
    pub nominal_mm_s: Vec<f64>,
    /// The compensated command v_ef per sample.
    pub command_mm_s: Vec<f64>,
    /// The compensated spans.
    pub spans: Vec<SpanCompensation>,
    /// Each span's CAD vertex.
    pub span_vertices: Vec<usize>,
    /// The width error of every sample (mm; NaN: unmeasured).
    pub dw: Vec<f64>,
    /// Each sample's (measured, desired) full width (mm).
    pub widths_mm: Vec<(f64, f64)>,
    /// Each CAD corner's median detected temperature (°C; NaN: never detected).
    pub corner_temps_c: Vec<f64>,
}

/// Eqs 31-39 on `seq` from the monitor's `tables`, with the stage's parameters `params`
/// and the deposition dynamics
/// G(s) of eq. 34 with time constant `tau_s` (the nominal τ, or a fitted one).
pub fn compensate(
    seq: &ThermalSequence,
    tables: &MonitorInputs<'_>,
    params: &CompensateParams,
    tau_s: f64,
) -> Result<Compensated, StageError> {
    let setup = seq.process.print_setup();
    let trajectory = trajectory_of(seq)?;
    let layers = params.layer..params.layer + params.layers;
    let measured =
        MeasuredWidths::read(tables.widths, &tables.widths_dir.join(widths::TABLE.file()), layers, trajectory.len())?;
    let frame_geometry =
        DepositionFrame::read(tables.directions, &tables.dir.join(directions::TABLE.file()), trajectory.len())?;
    let corner_temps_c =
        corner_temperatures(tables.detections, &tables.dir.join(detections::TABLE.file()), seq.path_mm.len())?;
    let bead = IdealBead::new(&seq.path_mm, setup.bead_width_mm / 2.0).map_err(StageError::domain)?;
    let desired = match params.desired_width {
        DesiredWidth::Eq31 => frame_geometry.eq31_desired(setup.bead_width_mm / 2.0),
        DesiredWidth::Cad => frame_geometry.cad_desired(&trajectory, &bead),
    };
    let mut sweep = frame_geometry.sweep.clone();
    if params.volume == Volume::Linear {
        sweep.iter_mut().for_each(|s| s.kappa_eff_per_mm = 0.0);
    }
    let widths_mm: Vec<(f64, f64)> =
        measured.sides_mm.iter().zip(&desired).map(|(m, d)| (m.0 + m.1, d.0 + d.1)).collect();
    let mut dw: Vec<f64> = widths_mm.iter().map(|(m, d)| m - d).collect();
    let mut dv = velocity_change_from_sweep_mm_s(
        &measured.sides_mm,
        &desired,
        &sweep,
        setup.layer_height_mm,
        setup.filament_area_mm2(),
        1.0,
    );
    if !params.add_material {
        // (f64::max would turn an unmeasured NaN into 0.)
        dw.iter_mut().filter(|d| d.is_finite()).for_each(|d| *d = d.max(0.0));
        dv.iter_mut().filter(|d| d.is_finite()).for_each(|d| *d = d.max(0.0));
    }
    let span_params = SpanParams {
        epsilon_mm: params.epsilon_mm,
        extension_s: params.extension_s,
        fbs: FbsParams {
            knot_spacing_s: params.knot_spacing_s,
            tau_s,
            dv_min_mm_s: params.dv_min_mm_s,
            dv_max_mm_s: params.dv_max_mm_s,
            tail_s: params.tail_s,
        },
    };
    let paper_gain_on = params.gain == GainRule::Paper;
    let vertex_of = |span: SampleSpan| span_vertex(&seq.path_mm, &trajectory, &dw, span);
    let gain = |span: SampleSpan| {
        let t = corner_temps_c[vertex_of(span)];
        if paper_gain_on && t.is_finite() {
            paper_gain(t.clamp(PAPER_BAND_C.0, PAPER_BAND_C.1))
        } else {
            1.0
        }
    };
    let nominal_mm_s = setup.conventional_command(&trajectory);
    let spans = if params.source == CompensationSource::LagModel {
        // The flow excess eq. 34 predicts for the nominal command (mm/s of filament).
        let excess = lag_excess(&nominal_mm_s, trajectory.dt_s, tau_s);
        let whole_layer = vec![f64::INFINITY; trajectory.len()];
        let span_params = SpanParams { epsilon_mm: 0.0, ..span_params };
        compensate_spans(&whole_layer, &excess, trajectory.dt_s, &span_params, |_| 1.0)
    } else {
        compensate_spans(&dw, &dv, trajectory.dt_s, &span_params, gain)
    }
    .map_err(StageError::domain)?;
    let command_mm_s = apply_spans(&nominal_mm_s, &spans);
    let span_vertices = spans.iter().map(|s| vertex_of(s.span)).collect();
    Ok(Compensated { trajectory, nominal_mm_s, command_mm_s, spans, span_vertices, dw, widths_mm, corner_temps_c })
}

/// The monitored half widths (left, right) of a run of consecutive layers, indexed by
/// trajectory sample: per sample and side, the median over the layers that read it
/// (every layer prints the same path, so a sample a frame missed in one layer may be
/// read in another); NaN where no layer read it.
struct MeasuredWidths {
    sides_mm: Vec<(f64, f64)>,
}

impl MeasuredWidths {
    fn read(df: &DataFrame, file: &Path, layers: std::ops::Range<i64>, samples: usize) -> Result<Self, StageError> {
        let layer = ints(df, widths::layer, file)?;
        let sample = ints(df, widths::sample, file)?;
        let left = f64s(df, widths::w_left_mm, file)?;
        let right = f64s(df, widths::w_right_mm, file)?;
        let mut readings: Vec<(Vec<f64>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); samples];
        let mut found = 0;
        for i in (0..layer.len()).filter(|&i| layers.contains(&layer[i])) {
            let k = sample_index(file, i, sample[i], samples)?;
            readings[k].0.push(left[i]);
            readings[k].1.push(right[i]);
            found += 1;
        }
        if found == 0 {
            return Err(StageError::BadInput {
                file: file.to_path_buf(),
                location: Some("column layer".into()),
                expected: format!("rows of layers {}..={}", layers.start, layers.end - 1),
            });
        }
        let sides_mm = readings.into_iter().map(|(l, r)| (finite_median(l), finite_median(r))).collect();
        Ok(Self { sides_mm })
    }
}

/// The allocated deposition frame of every sample, from the monitor's `directions.parquet`.
struct DepositionFrame {
    left_dir: Vec<[f64; 2]>,
    psi_rad: Vec<f64>,
    sweep: Vec<SweepSample>,
}

impl DepositionFrame {
    fn read(df: &DataFrame, file: &Path, samples: usize) -> Result<Self, StageError> {
        let sample = ints(df, directions::sample, file)?;
        let col = |name: &str| f64s(df, name, file);
        let (dep_x, dep_y, psi, kappa, speed) = (
            col(directions::dep_x)?,
            col(directions::dep_y)?,
            col(directions::psi_rad)?,
            col(directions::kappa_eff_per_mm)?,
            col(directions::speed_mm_s)?,
        );
        let zero = SweepSample { speed_mm_s: 0.0, psi_rad: 0.0, kappa_eff_per_mm: 0.0 };
        let mut out =
            Self { left_dir: vec![[0.0, 1.0]; samples], psi_rad: vec![0.0; samples], sweep: vec![zero; samples] };
        for i in 0..sample.len() {
            let k = sample_index(file, i, sample[i], samples)?;
            out.left_dir[k] = [dep_x[i], dep_y[i]];
            out.psi_rad[k] = psi[i];
            out.sweep[k] = SweepSample { speed_mm_s: speed[i], psi_rad: psi[i], kappa_eff_per_mm: kappa[i] };
        }
        Ok(out)
    }

    /// Eq. 31 on both sides: w0/cos ψ.
    fn eq31_desired(&self, w0_mm: f64) -> Vec<(f64, f64)> {
        desired_half_width_mm(w0_mm, &self.psi_rad).into_iter().map(|w| (w, w)).collect()
    }

    /// The ideal bead's extent along the deposition direction on both sides.
    fn cad_desired(&self, trajectory: &Trajectory, bead: &IdealBead) -> Vec<(f64, f64)> {
        (0..trajectory.len())
            .map(|k| {
                let p = [trajectory.x_mm[k], trajectory.y_mm[k]];
                let [dx, dy] = self.left_dir[k];
                (bead.edge_distance_mm(p, [dx, dy]), bead.edge_distance_mm(p, [-dx, -dy]))
            })
            .collect()
    }
}

/// Median temperature of each CAD corner's matched detections (NaN: never detected).
fn corner_temperatures(df: &DataFrame, file: &Path, vertices: usize) -> Result<Vec<f64>, StageError> {
    let vertex = ints(df, detections::matched_vertex, file)?;
    let temp = f64s(df, detections::temp_c, file)?;
    Ok((0..vertices)
        .map(|v| {
            let mut t: Vec<f64> = (0..vertex.len()).filter(|&i| vertex[i] == v as i64).map(|i| temp[i]).collect();
            t.sort_by(f64::total_cmp);
            if t.is_empty() {
                f64::NAN
            } else {
                t[t.len() / 2]
            }
        })
        .collect())
}

/// The CAD vertex nearest the sample of the span's largest width error.
fn span_vertex(path_mm: &[[f64; 2]], trajectory: &Trajectory, dw: &[f64], span: SampleSpan) -> usize {
    let worst = (span.first..=span.last).max_by(|&a, &b| dw[a].abs().total_cmp(&dw[b].abs())).unwrap_or(span.first);
    let p = [trajectory.x_mm[worst], trajectory.y_mm[worst]];
    (0..path_mm.len())
        .min_by(|&a, &b| {
            let da = (path_mm[a][0] - p[0]).hypot(path_mm[a][1] - p[1]);
            let db = (path_mm[b][0] - p[0]).hypot(path_mm[b][1] - p[1]);
            da.total_cmp(&db)
        })
        .unwrap_or(0)
}

/// The rows of `spans.parquet` and `compensation.parquet`.
#[derive(Default)]
struct Rows {
    span: Vec<i64>,
    vertex: Vec<i64>,
    angle_deg: Vec<f64>,
    t_start_s: Vec<f64>,
    t_end_s: Vec<f64>,
    t_ext_start_s: Vec<f64>,
    t_ext_end_s: Vec<f64>,
    corner_temp_c: Vec<f64>,
    gain_ke: Vec<f64>,
    max_dw_mm: Vec<f64>,
    s_span: Vec<i64>,
    s_vertex: Vec<i64>,
    s_t: Vec<f64>,
    s_dw: Vec<f64>,
    s_measured: Vec<f64>,
    s_wanted: Vec<f64>,
    s_desired: Vec<f64>,
    s_output: Vec<f64>,
    s_input: Vec<f64>,
}

impl Rows {
    #[allow(clippy::too_many_arguments)]
    fn span(
        &mut self,
        index: usize,
        vertex: usize,
        angle_deg: f64,
        t_s: &[f64],
        span: SampleSpan,
        window: SampleSpan,
        corner_temp_c: f64,
        gain: f64,
        max_dw: f64,
    ) {
        self.span.push(index as i64);
        self.vertex.push(vertex as i64);
        self.angle_deg.push(angle_deg);
        self.t_start_s.push(t_s[span.first]);
        self.t_end_s.push(t_s[span.last]);
        self.t_ext_start_s.push(t_s[window.first]);
        self.t_ext_end_s.push(t_s[window.last]);
        self.corner_temp_c.push(corner_temp_c);
        self.gain_ke.push(gain);
        self.max_dw_mm.push(max_dw);
    }

    /// The window's samples; `widths_mm` holds each trajectory sample's (measured,
    /// desired) full width w_l + w_r.
    fn samples(&mut self, index: usize, vertex: usize, t_s: &[f64], s: &SpanCompensation, widths_mm: &[(f64, f64)]) {
        for j in 0..s.window.len() {
            let k = s.window.first + j;
            self.s_span.push(index as i64);
            self.s_vertex.push(vertex as i64);
            self.s_t.push(t_s[k]);
            self.s_dw.push(widths_mm[k].0 - widths_mm[k].1);
            self.s_measured.push(widths_mm[k].0);
            self.s_wanted.push(widths_mm[k].1);
            self.s_desired.push(s.desired_mm_s[j]);
            self.s_output.push(s.solution.output_mm_s[j]);
            self.s_input.push(s.solution.input_mm_s[j]);
        }
    }

    fn write(self, ctx: &mut StageContext) -> Result<(), StageError> {
        let mut spans = frame(vec![
            i64_col(spans::span, self.span),
            i64_col(spans::vertex, self.vertex),
            f64_col(spans::angle_deg, self.angle_deg),
            f64_col(spans::t_start_s, self.t_start_s),
            f64_col(spans::t_end_s, self.t_end_s),
            f64_col(spans::t_ext_start_s, self.t_ext_start_s),
            f64_col(spans::t_ext_end_s, self.t_ext_end_s),
            f64_col(spans::corner_temp_c, self.corner_temp_c),
            f64_col(spans::gain_ke, self.gain_ke),
            f64_col(spans::max_dw_mm, self.max_dw_mm),
        ])?;
        ctx.write_table(spans::TABLE.name, &mut spans)?;
        let mut samples = frame(vec![
            i64_col(compensation::span, self.s_span),
            i64_col(compensation::vertex, self.s_vertex),
            f64_col(compensation::t_s, self.s_t),
            f64_col(compensation::dw_mm, self.s_dw),
            f64_col(compensation::w_measured_mm, self.s_measured),
            f64_col(compensation::w_desired_mm, self.s_wanted),
            f64_col(compensation::dv_desired_mm_s, self.s_desired),
            f64_col(compensation::dv_output_mm_s, self.s_output),
            f64_col(compensation::dv_input_mm_s, self.s_input),
        ])?;
        ctx.write_table(compensation::TABLE.name, &mut samples)?;
        Ok(())
    }
}
