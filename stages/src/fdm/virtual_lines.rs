//! The virtual FDM printer in the pipeline (DESIGN §5.1):
//!
//! - `fdm.generate_lines`: prints and photographs paper 000's lines; the stage's output
//!   folder *is* the `fdm-lines` dataset, read downstream as a lab's photos would be.
//! - `fdm.virtual_agreement`: how well the virtual printer reproduces the real lines:
//!   for each real line, the printer calibrated on the printer's other lines prints
//!   it, and the measured widths are compared with the virtual mean profile and with
//!   the virtual lines' own scatter → `agreement.parquet`, `agreement_profiles.parquet`.

use datasets::fdm_lines::camera::CameraSettings;
use datasets::fdm_lines::generate::{conditions_named, generate_into_observed, GenerateConfig};
use models::fdm::printer::{held_out_agreement, Effects, PrinterProfile, PRINTERS};
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use super::lines::PrinterLines;
use crate::progress::StageProgress;
use crate::table::{f64_col, frame, str_col};

/// The `fdm.generate_lines` stage kind.
pub struct GenerateLinesStage;

const GENERATE_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "printer",
        ty: ParamType::Choice(&PRINTERS),
        default: ParamDefault::Str("taz5"),
        doc: "Printer profile, calibrated to its real lines in data/fsu-linewidth.",
    },
    ParamSpec {
        name: "conditions",
        ty: ParamType::Choice(&["ren2021"]),
        default: ParamDefault::Str("ren2021"),
        doc: "(acceleration, feed) conditions: paper 000 Table I.",
    },
    ParamSpec {
        name: "lines_per_condition",
        ty: ParamType::Int { min: 1, max: 100 },
        default: ParamDefault::Int(1),
        doc: "Lines printed per condition.",
    },
    ParamSpec {
        name: "effects",
        ty: ParamType::Text,
        default: ParamDefault::Str(""),
        doc: "Extra physical effects as `name=strength` pairs separated by commas (bed_tilt, gear_eccentricity, flow_saturation, camera_scale_error); empty: none.",
    },
    ParamSpec {
        name: "gear_period_mm",
        ty: ParamType::Float { min: 2.0, max: 60.0 },
        default: ParamDefault::Float(12.0),
        doc: "The gear ripple's period in path length (mm), with gear_eccentricity.",
    },
    ParamSpec {
        name: "px_per_mm",
        ty: ParamType::Float { min: 2.0, max: 200.0 },
        default: ParamDefault::Float(40.0),
        doc: "The camera's scale (px/mm); the real data's 0.048 mm width steps suggest about 20.",
    },
    ParamSpec {
        name: "bit_depth",
        ty: ParamType::Choice(&["8", "16"]),
        default: ParamDefault::Str("8"),
        doc: "Bits per pixel of the photos.",
    },
];

impl StageKind for GenerateLinesStage {
    fn name(&self) -> &'static str {
        "fdm.generate_lines"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Virtual FDM printer + top-view camera → an fdm-lines dataset of paper 000's lines (the output folder)"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §5.1; paper 000 Table I (conditions), Sec. III (camera-measured widths)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        GENERATE_PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(0)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let params_error = |message: String| StageError::Params { stage: ctx.stage.clone(), message };
        let pairs = crate::effects::pairs(ctx.params.str("effects")).map_err(params_error)?;
        let effects = Effects::from_pairs(pairs).map_err(|e| params_error(format!("effects: {e}")))?;
        let config = GenerateConfig {
            conditions: conditions_named(ctx.params.str("conditions")).unwrap_or_default(),
            lines_per_condition: ctx.params.i64("lines_per_condition") as usize,
            effects: Effects { gear_period_mm: ctx.params.f64("gear_period_mm"), ..effects },
            camera: CameraSettings {
                px_per_mm: ctx.params.f64("px_per_mm"),
                bit_depth: if ctx.params.str("bit_depth") == "16" { 16 } else { 8 },
                ..CameraSettings::default()
            },
            ..GenerateConfig::new(ctx.params.str("printer"), ctx.seed)
        };
        generate_into_observed(&config, ctx.output_dir(), &StageProgress::new(ctx)).map_err(StageError::domain)?;
        Ok(())
    }
}

/// The `fdm.virtual_agreement` stage kind.
pub struct VirtualAgreementStage;

const AGREEMENT_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "draws",
        ty: ParamType::Int { min: 2, max: 1000 },
        default: ParamDefault::Int(40),
        doc: "Virtual lines printed per held-out real line for the scatter and the 95 % band.",
    },
    ParamSpec {
        name: "profile_step_mm",
        ty: ParamType::Float { min: 0.05, max: 10.0 },
        default: ParamDefault::Float(0.5),
        doc: "Spacing of the rows of agreement_profiles.parquet along the line (mm).",
    },
];

impl StageKind for VirtualAgreementStage {
    fn name(&self) -> &'static str {
        "fdm.virtual_agreement"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Per real line: the virtual printer calibrated on the other lines vs the measured widths (held-out RMSE, the virtual scatter) → agreement.parquet, agreement_profiles.parquet"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §5.1 (virtual printers calibrated to the real data)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        AGREEMENT_PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::at_least(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let draws = ctx.params.i64("draws") as usize;
        let step_mm = ctx.params.f64("profile_step_mm");
        let mut rows = AgreementRows::default();
        for input in &ctx.inputs {
            let printer = PrinterLines::read(&input.dir)?;
            let profile = PrinterProfile::named(&printer.printer).ok_or_else(|| StageError::BadInput {
                file: input.dir.join("dataset.toml"),
                location: Some("printer".into()),
                expected: format!(
                    "expected a printer with a virtual profile ({PRINTERS:?}), got `{}`",
                    printer.printer
                ),
            })?;
            let cap = profile.theta.max_excess_mm.is_finite();
            let agreement = held_out_agreement(&printer.lines, profile.has_start_blob, cap, draws, ctx.seed)
                .map_err(|e| super::lines::fit_failed("calibrating the virtual printer", e))?;
            rows.push(&printer, &agreement, step_mm);
        }
        ctx.write_table("agreement", &mut rows.summary()?)?;
        ctx.write_table("agreement_profiles", &mut rows.profiles()?)?;
        Ok(())
    }
}

#[derive(Default)]
struct AgreementRows {
    printer: Vec<String>,
    condition: Vec<String>,
    accel_mm_s2: Vec<f64>,
    feed_mm_s: Vec<f64>,
    rmse_mm: Vec<f64>,
    scatter_mm: Vec<f64>,
    profile_printer: Vec<String>,
    profile_condition: Vec<String>,
    profile_position_mm: Vec<f64>,
    profile_real_mm: Vec<f64>,
    profile_mean_mm: Vec<f64>,
    profile_lo_mm: Vec<f64>,
    profile_hi_mm: Vec<f64>,
}

impl AgreementRows {
    fn push(&mut self, printer: &PrinterLines, agreement: &[models::fdm::printer::HeldOutAgreement], step_mm: f64) {
        for a in agreement {
            let (line, condition) = (&printer.lines[a.line], &printer.conditions[a.line]);
            self.printer.push(printer.printer.clone());
            self.condition.push(condition.clone());
            self.accel_mm_s2.push(line.nominal.accel_mm_s2);
            self.feed_mm_s.push(line.nominal.feed_mm_s);
            self.rmse_mm.push(a.rmse_mm);
            self.scatter_mm.push(a.virtual_scatter_mm);
            let mut next_mm = 0.0;
            for (i, &x) in line.positions_mm.iter().enumerate() {
                if x + 1e-9 < next_mm {
                    continue;
                }
                next_mm = x + step_mm;
                self.profile_printer.push(printer.printer.clone());
                self.profile_condition.push(condition.clone());
                self.profile_position_mm.push(x);
                self.profile_real_mm.push(line.widths_mm[i]);
                self.profile_mean_mm.push(a.mean_mm[i]);
                self.profile_lo_mm.push(a.band_mm.0[i]);
                self.profile_hi_mm.push(a.band_mm.1[i]);
            }
        }
    }

    fn summary(&self) -> Result<polars::prelude::DataFrame, StageError> {
        let ratio: Vec<f64> = self.rmse_mm.iter().zip(&self.scatter_mm).map(|(r, s)| r / s).collect();
        frame(vec![
            str_col("printer", self.printer.clone()),
            str_col("condition", self.condition.clone()),
            f64_col("accel_mm_s2", self.accel_mm_s2.clone()),
            f64_col("feed_mm_s", self.feed_mm_s.clone()),
            f64_col("rmse_mm", self.rmse_mm.clone()),
            f64_col("virtual_scatter_mm", self.scatter_mm.clone()),
            f64_col("rmse_over_scatter", ratio),
        ])
    }

    fn profiles(&self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            str_col("printer", self.profile_printer.clone()),
            str_col("condition", self.profile_condition.clone()),
            f64_col("position_mm", self.profile_position_mm.clone()),
            f64_col("real_mm", self.profile_real_mm.clone()),
            f64_col("virtual_mean_mm", self.profile_mean_mm.clone()),
            f64_col("virtual_lo_mm", self.profile_lo_mm.clone()),
            f64_col("virtual_hi_mm", self.profile_hi_mm.clone()),
        ])
    }
}
