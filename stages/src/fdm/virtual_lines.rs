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
use pipeline::params::{Names, OneOf, ParamError};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{agreement, agreement_profiles};

use super::lines::PrinterLines;
use crate::progress::StageProgress;
use crate::roles;
use crate::table::{f64_col, frame, str_col};

/// The `fdm.generate_lines` stage kind.
pub struct GenerateLinesStage;

/// The virtual printer's calibrated profiles.
pub struct VirtualPrinters;

impl Names for VirtualPrinters {
    const NAMES: &'static [&'static str] = &PRINTERS;
}

pipeline::choice! {
    /// Sets of (acceleration, feed) conditions.
    pub enum Conditions {
        /// Paper 000 Table I.
        Ren2021 = "ren2021",
    }
}

pipeline::choice! {
    /// Bits per pixel of the photos.
    pub enum BitDepth {
        /// 8-bit grey.
        Eight = "8",
        /// 16-bit grey.
        Sixteen = "16",
    }
}

pipeline::params! {
    /// The parameters of `fdm.generate_lines`.
    pub struct GenerateLinesParams {
        /// Printer profile, calibrated to its real lines in data/fsu-linewidth.
        pub printer: OneOf<VirtualPrinters> = "taz5",
        /// (acceleration, feed) conditions: paper 000 Table I.
        pub conditions: Conditions = Conditions::Ren2021,
        /// Lines printed per condition.
        pub lines_per_condition: i64 [1, 100] = 1,
        /// Extra physical effects as `name=strength` pairs separated by commas (bed_tilt, gear_eccentricity, flow_saturation, camera_scale_error); empty: none.
        pub effects: String = "",
        /// The gear ripple's period in path length (mm), with gear_eccentricity.
        pub gear_period_mm: f64 [2.0, 60.0] = 12.0,
        /// The camera's scale (px/mm); the real data's 0.048 mm width steps suggest about 20.
        pub px_per_mm: f64 [2.0, 200.0] = 40.0,
        /// Bits per pixel of the photos.
        pub bit_depth: BitDepth = BitDepth::Eight,
    }
}

impl GenerateLinesParams {
    /// The effects, parsed and checked.
    fn effects(&self) -> Result<Effects, ParamError> {
        let pairs = crate::effects::pairs(&self.effects).map_err(|m| ParamError::new("effects", m))?;
        let effects = Effects::from_pairs(pairs).map_err(|e| ParamError::new("effects", e.to_string()))?;
        Ok(Effects { gear_period_mm: self.gear_period_mm, ..effects })
    }
}

impl Stage for GenerateLinesStage {
    type Params = GenerateLinesParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.generate_lines",
        version: 1,
        summary:
            "Virtual FDM printer + top-view camera → an fdm-lines dataset of paper 000's lines (the output folder)",
        implements: "DESIGN §5.1; paper 000 Table I (conditions), Sec. III (camera-measured widths)",
        inputs: &[],
        output: Output::Dataset("fdm-lines"),
    };

    fn check(p: &GenerateLinesParams) -> Result<(), ParamError> {
        p.effects().map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &GenerateLinesParams) -> Result<(), StageError> {
        let config = GenerateConfig {
            conditions: conditions_named(p.conditions.name()).unwrap_or_default(),
            lines_per_condition: p.lines_per_condition as usize,
            effects: p.effects().map_err(|e| StageError::params(ctx, e))?,
            camera: CameraSettings {
                px_per_mm: p.px_per_mm,
                bit_depth: match p.bit_depth {
                    BitDepth::Eight => 8,
                    BitDepth::Sixteen => 16,
                },
                ..CameraSettings::default()
            },
            ..GenerateConfig::new(p.printer.as_str(), ctx.seed)
        };
        generate_into_observed(&config, ctx.output_dir(), &StageProgress::new(ctx)).map_err(StageError::domain)?;
        Ok(())
    }
}

/// The `fdm.virtual_agreement` stage kind.
pub struct VirtualAgreementStage;

pipeline::params! {
    /// The parameters of `fdm.virtual_agreement`.
    pub struct VirtualAgreementParams {
        /// Virtual lines printed per held-out real line for the scatter and the 95 % band.
        pub draws: i64 [2, 1000] = 40,
        /// Spacing of the rows of agreement_profiles.parquet along the line (mm).
        pub profile_step_mm: f64 [0.05, 10.0] = 0.5,
    }
}

impl Stage for VirtualAgreementStage {
    type Params = VirtualAgreementParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.virtual_agreement",
        version: 1,
        summary: "Per real line: the virtual printer calibrated on the other lines vs the measured widths (held-out RMSE, the virtual scatter) → agreement.parquet, agreement_profiles.parquet",
        implements: "DESIGN §5.1 (virtual printers calibrated to the real data)",
        inputs: &[roles::FDM_WIDTHS_MANY],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&agreement::TABLE, &agreement_profiles::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &VirtualAgreementParams) -> Result<(), StageError> {
        let (draws, step_mm) = (p.draws as usize, p.profile_step_mm);
        let mut rows = AgreementRows::default();
        for input in ctx.inputs_of(&roles::FDM_WIDTHS_MANY) {
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
        ctx.write_table(agreement::TABLE.name, &mut rows.summary()?)?;
        ctx.write_table(agreement_profiles::TABLE.name, &mut rows.profiles()?)?;
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
            str_col(agreement::printer, self.printer.clone()),
            str_col(agreement::condition, self.condition.clone()),
            f64_col(agreement::accel_mm_s2, self.accel_mm_s2.clone()),
            f64_col(agreement::feed_mm_s, self.feed_mm_s.clone()),
            f64_col(agreement::rmse_mm, self.rmse_mm.clone()),
            f64_col(agreement::virtual_scatter_mm, self.scatter_mm.clone()),
            f64_col(agreement::rmse_over_scatter, ratio),
        ])
    }

    fn profiles(&self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            str_col(agreement_profiles::printer, self.profile_printer.clone()),
            str_col(agreement_profiles::condition, self.profile_condition.clone()),
            f64_col(agreement_profiles::position_mm, self.profile_position_mm.clone()),
            f64_col(agreement_profiles::real_mm, self.profile_real_mm.clone()),
            f64_col(agreement_profiles::virtual_mean_mm, self.profile_mean_mm.clone()),
            f64_col(agreement_profiles::virtual_lo_mm, self.profile_lo_mm.clone()),
            f64_col(agreement_profiles::virtual_hi_mm, self.profile_hi_mm.clone()),
        ])
    }
}
