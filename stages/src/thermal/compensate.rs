//! `thermal.compensate`: the dynamic deposition compensation of paper 003 Sec. 2.4
//! (eqs 31-39) with the parameters of Sec. 3.2, from the widths `thermal.monitor` read.
//!
//! Spans where |Δw| ≥ ε (eq. 32) are extended by 0.1 s at both ends; spans whose
//! extended windows touch are merged so that every sample has one compensation. For
//! each span: the corner it belongs to (the CAD vertex nearest its largest error), the
//! corner temperature T_p (median temperature of that corner's detections, all inside
//! the monitor's band by construction), the gain K_e = 1 + (150 − T_p)/15 (Sec. 3.2,
//! T_p clamped to the paper's 140-150 °C band),
//! the desired change of the deposition velocity (eq. 33) and the filtered-B-spline
//! input that produces it through G(s) within the bounds (eqs 36-39).
//!
//! Only over-deposition by default: near sharp corners the desired width of eq. 31,
//! w0/cos ψ, grows without bound as the allocated direction turns towards the path
//! (ψ → 90°), so the measured width falls short of it exactly where the bead bulges, and
//! compensating that "under-deposition" would add material to the bulge. The paper's
//! evaluation (O_E, eq. 40; Figs 9-10) is about over-deposition alone; negative Δw are
//! set to zero unless `add_material` is true.
//!
//! Units: the deposition velocity v_e is the extruder's (E-axis) velocity in mm/s of
//! filament, E = A_fil·v_e. This is the reading under which the paper's numbers fit
//! together: w0 = K·α + b with K = 3.44 mm, b = 0.67 mm only gives a sub-millimetre
//! bead for a feed-to-deposition ratio α of a few percent, i.e. filament speed over
//! path speed, and the bounds ΔV ∈ [−2, 4] mm/s then allow the short retraction a
//! corner needs. A width excess Δw at path speed |v| is a flow excess h·|v|·Δw, so
//! Δv_e = K_e·h·|v|·Δw/A_fil (models::thermal::compensation works in path-equivalent
//! units; the conversion factor is W·h/A_fil).

use std::path::Path;

use models::thermal::compensation::{
    desired_velocity_change_mm_s, error_spans, extend_span, paper_gain, solve_fbs, FbsParams, SampleSpan,
};
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use super::common::{f64_column, i64_column, interior_angles_deg, open_sequence, read_table, trajectory_of};
use crate::table::{f64_col, frame, i64_col};

/// The temperature band over which the paper identified K_e (Sec. 3.2): its corners are
/// measured at 140-150 °C, so K_e runs from 1 to 1.67. A corner measured outside the band
/// (the monitor's band may be wider, see specs/chen2024.toml) is clamped to it: the
/// formula is not meant to be extrapolated (it turns negative above 165 °C).
const PAPER_BAND_C: (f64, f64) = (140.0, 150.0);

/// The `thermal.compensate` stage kind.
pub struct CompensateStage;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "layer",
        ty: ParamType::Int { min: 0, max: 19 },
        default: ParamDefault::Int(0),
        doc: "Monitored layer whose widths drive the compensation (the paper's one-layer verification print).",
    },
    ParamSpec {
        name: "epsilon_mm",
        ty: ParamType::Float { min: 0.0, max: 2.0 },
        default: ParamDefault::Float(0.05),
        doc: "Largest tolerable width error ε (mm): spans with |Δw| ≥ ε are compensated (Sec. 2.4; the paper gives no value, 0.05 mm is about a third of a camera pixel on the plane).",
    },
    ParamSpec {
        name: "extension_s",
        ty: ParamType::Float { min: 0.0, max: 1.0 },
        default: ParamDefault::Float(0.1),
        doc: "Time added at both ends of each span for the deposition dynamics (s); Sec. 3.2: 0.1 s.",
    },
    ParamSpec {
        name: "knot_spacing_s",
        ty: ParamType::Float { min: 0.002, max: 0.5 },
        default: ParamDefault::Float(0.02),
        doc: "Knot spacing of the cubic B-spline input (s); about τ/4 (the paper does not state it).",
    },
    ParamSpec {
        name: "dv_min_mm_s",
        ty: ParamType::Float { min: -100.0, max: 0.0 },
        default: ParamDefault::Float(-2.0),
        doc: "Lower bound ΔV_min of the control points (mm/s of filament), Sec. 3.2: −2 mm/s.",
    },
    ParamSpec {
        name: "dv_max_mm_s",
        ty: ParamType::Float { min: 0.0, max: 100.0 },
        default: ParamDefault::Float(4.0),
        doc: "Upper bound ΔV_max of the control points (mm/s of filament), Sec. 3.2: 4 mm/s.",
    },
    ParamSpec {
        name: "add_material",
        ty: ParamType::Bool,
        default: ParamDefault::Bool(false),
        doc: "Also compensate spans measured narrower than desired (Δw < 0) by adding material; false: only over-deposition is compensated (module doc says why).",
    },
    ParamSpec {
        name: "gain",
        ty: ParamType::Choice(&["paper", "unit"]),
        default: ParamDefault::Str("paper"),
        doc: "Deposition correction gain K_e: `paper` = 1 + (150 − T_p)/15 with T_p the corner temperature (Sec. 3.2), `unit` = 1 (pure mass conservation).",
    },
];

impl StageKind for CompensateStage {
    fn name(&self) -> &'static str {
        "thermal.compensate"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Width-error spans, corner gains and filtered-B-spline compensation → spans, compensation, command"
    }
    fn implements(&self) -> &'static str {
        "paper 003 eqs 31-39 (Sec. 2.4), parameters of Sec. 3.2"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(2)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let seq = open_sequence(&ctx.inputs[0].dir)?;
        let setup = seq.process.print_setup();
        let trajectory = trajectory_of(&seq)?;
        let monitor_dir = ctx.inputs[1].dir.clone();
        let mut measured = MeasuredWidths::read(&monitor_dir, ctx.params.i64("layer"), trajectory.len())?;
        let corner_temps = corner_temperatures(&monitor_dir, seq.path_mm.len())?;
        let fbs = FbsParams {
            knot_spacing_s: ctx.params.f64("knot_spacing_s"),
            tau_s: setup.tau_s,
            dv_min_mm_s: ctx.params.f64("dv_min_mm_s"),
            dv_max_mm_s: ctx.params.f64("dv_max_mm_s"),
        };
        let extension_s = ctx.params.f64("extension_s");
        let merge_gap = (2.0 * extension_s / trajectory.dt_s).ceil() as usize + 1;
        if !ctx.params.bool("add_material") {
            measured.dw_mm.iter_mut().for_each(|dw| *dw = dw.max(0.0));
        }
        let spans = error_spans(&measured.dw_mm, ctx.params.f64("epsilon_mm"), merge_gap);
        let to_filament = setup.bead_width_mm * setup.layer_height_mm / setup.filament_area_mm2();
        let speed = trajectory.speed_mm_s();
        let angles = interior_angles_deg(&seq.path_mm);
        let mut command: Vec<f64> = speed.iter().map(|v| setup.nominal_deposition_velocity_mm_s(*v)).collect();
        let nominal = command.clone();
        let mut rows = Rows::default();
        for (index, span) in spans.iter().enumerate() {
            let window = extend_span(*span, extension_s, trajectory.dt_s, trajectory.len());
            let vertex = span_vertex(&seq.path_mm, &trajectory, &measured.dw_mm, *span);
            let corner_temp_c = corner_temps[vertex];
            let gain = match ctx.params.str("gain") {
                "paper" if corner_temp_c.is_finite() => paper_gain(corner_temp_c.clamp(PAPER_BAND_C.0, PAPER_BAND_C.1)),
                _ => 1.0,
            };
            let range = window.first..=window.last;
            let desired: Vec<f64> = desired_velocity_change_mm_s(
                &measured.dw_mm[range.clone()],
                &speed[range.clone()],
                &measured.w_desired_half_mm[range.clone()],
                gain,
            )
            .iter()
            .map(|dv| dv * to_filament)
            .collect();
            let solution = solve_fbs(&desired, trajectory.dt_s, &fbs).map_err(StageError::domain)?;
            for (j, dv) in solution.input_mm_s.iter().enumerate() {
                command[window.first + j] -= dv;
            }
            let max_dw =
                measured.dw_mm[span.first..=span.last].iter().copied().filter(|d| d.is_finite()).fold(0.0, f64::max);
            rows.span(index, vertex, angles[vertex], &trajectory.t_s, *span, window, corner_temp_c, gain, max_dw);
            rows.samples(index, vertex, &trajectory.t_s, window, &measured.dw_mm, &desired, &solution);
        }
        rows.write(ctx)?;
        let mut table = frame(vec![
            i64_col("sample", (0..trajectory.len() as i64).collect()),
            f64_col("t_s", trajectory.t_s.clone()),
            f64_col("v_e_mm_s", nominal),
            f64_col("v_ef_mm_s", command),
        ])?;
        ctx.write_table("command", &mut table)?;
        Ok(())
    }
}

/// The monitored widths of one layer, indexed by trajectory sample.
struct MeasuredWidths {
    dw_mm: Vec<f64>,
    w_desired_half_mm: Vec<f64>,
}

impl MeasuredWidths {
    fn read(monitor_dir: &Path, layer: i64, samples: usize) -> Result<Self, StageError> {
        let file = monitor_dir.join("widths.parquet");
        let df = read_table(monitor_dir, "widths.parquet")?;
        let layers = i64_column(&df, &file, "layer")?;
        let sample = i64_column(&df, &file, "sample")?;
        let dw = f64_column(&df, &file, "dw_mm")?;
        let desired = f64_column(&df, &file, "w_desired_mm")?;
        let mut out = Self { dw_mm: vec![f64::NAN; samples], w_desired_half_mm: vec![f64::NAN; samples] };
        let mut found = 0;
        for i in (0..layers.len()).filter(|&i| layers[i] == layer) {
            let k = usize::try_from(sample[i]).ok().filter(|&k| k < samples).ok_or_else(|| StageError::BadInput {
                file: file.clone(),
                location: Some(format!("row {i}, column sample")),
                expected: format!("a trajectory sample index below {samples}, found {}", sample[i]),
            })?;
            out.dw_mm[k] = dw[i];
            out.w_desired_half_mm[k] = desired[i] / 2.0;
            found += 1;
        }
        if found == 0 {
            return Err(StageError::BadInput {
                file,
                location: Some("column layer".into()),
                expected: format!("rows of layer {layer}"),
            });
        }
        Ok(out)
    }
}

/// Median temperature of each CAD corner's matched detections (NaN: never detected).
fn corner_temperatures(monitor_dir: &Path, vertices: usize) -> Result<Vec<f64>, StageError> {
    let file = monitor_dir.join("detections.parquet");
    let df = read_table(monitor_dir, "detections.parquet")?;
    let vertex = i64_column(&df, &file, "matched_vertex")?;
    let temp = f64_column(&df, &file, "temp_c")?;
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
fn span_vertex(path_mm: &[[f64; 2]], trajectory: &models::thermal::Trajectory, dw: &[f64], span: SampleSpan) -> usize {
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

    #[allow(clippy::too_many_arguments)]
    fn samples(
        &mut self,
        index: usize,
        vertex: usize,
        t_s: &[f64],
        window: SampleSpan,
        dw: &[f64],
        desired: &[f64],
        solution: &models::thermal::compensation::FbsSolution,
    ) {
        for j in 0..window.len() {
            self.s_span.push(index as i64);
            self.s_vertex.push(vertex as i64);
            self.s_t.push(t_s[window.first + j]);
            self.s_dw.push(dw[window.first + j]);
            self.s_desired.push(desired[j]);
            self.s_output.push(solution.output_mm_s[j]);
            self.s_input.push(solution.input_mm_s[j]);
        }
    }

    fn write(self, ctx: &mut StageContext) -> Result<(), StageError> {
        let mut spans = frame(vec![
            i64_col("span", self.span),
            i64_col("vertex", self.vertex),
            f64_col("angle_deg", self.angle_deg),
            f64_col("t_start_s", self.t_start_s),
            f64_col("t_end_s", self.t_end_s),
            f64_col("t_ext_start_s", self.t_ext_start_s),
            f64_col("t_ext_end_s", self.t_ext_end_s),
            f64_col("corner_temp_c", self.corner_temp_c),
            f64_col("gain_ke", self.gain_ke),
            f64_col("max_dw_mm", self.max_dw_mm),
        ])?;
        ctx.write_table("spans", &mut spans)?;
        let mut samples = frame(vec![
            i64_col("span", self.s_span),
            i64_col("vertex", self.s_vertex),
            f64_col("t_s", self.s_t),
            f64_col("dw_mm", self.s_dw),
            f64_col("dv_desired_mm_s", self.s_desired),
            f64_col("dv_output_mm_s", self.s_output),
            f64_col("dv_input_mm_s", self.s_input),
        ])?;
        ctx.write_table("compensation", &mut samples)?;
        Ok(())
    }
}
