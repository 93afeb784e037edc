//! `fdm.other_family`: an `fdm-widths` dataset of a printer of another family, made from
//! measured lines by a stated physical transformation (`models::fdm::other_family_widths`:
//! a wider nozzle scales every width, a slower melt response lags it along the path).
//! Transfer studies need printers that clearly differ from the source; until a lab's
//! lines of another printer family are at hand, this is one with known differences.
//! The output folder is the dataset; its `printer` is the `printer` parameter.

use datasets::fdm_widths::FdmWidthsDataset;
use models::fdm::other_family_widths;
use pipeline::params::ParamError;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};

use crate::roles;
use crate::table::read_fdm_widths;

/// The `fdm.other_family` stage kind.
pub struct OtherFamilyStage;

pipeline::params! {
    /// The parameters of `fdm.other_family`.
    pub struct OtherFamilyParams {
        /// Name of the derived printer (its dataset.toml `printer`).
        pub printer: String,
        /// Every width times this (a nozzle this many times wider at the same kinematics).
        pub width_scale: f64 [0.2, 5.0] = 1.0,
        /// First-order lag of the widths along the path (mm): a slower melt response; 0 keeps the shape.
        pub lag_mm: f64 [0.0, 60.0] = 0.0,
    }
}

impl Stage for OtherFamilyStage {
    type Params = OtherFamilyParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.other_family",
        version: 1,
        summary: "A printer of another family from measured lines: widths scaled (wider nozzle) and lagged along the path (slower melt) → an fdm-widths dataset (the output folder)",
        implements: "test printers for paper 000's transfer (Sec. III-B) beyond the Taz 5 / Taz 6",
        inputs: &[roles::FDM_WIDTHS],
        output: Output::Dataset("fdm-widths"),
    };

    fn check(p: &OtherFamilyParams) -> Result<(), ParamError> {
        if p.printer.trim().is_empty() {
            return Err(ParamError::new("printer", "must name a new printer (got an empty name)"));
        }
        Ok(())
    }

    fn run(&self, ctx: &mut StageContext, p: &OtherFamilyParams) -> Result<(), StageError> {
        let mut dataset: FdmWidthsDataset = read_fdm_widths(&ctx.input(&roles::FDM_WIDTHS).dir)?;
        let (scale, lag_mm) = (p.width_scale, p.lag_mm);
        let name = p.printer.trim().to_string();
        if name == dataset.manifest.printer {
            return Err(StageError::Params {
                stage: ctx.stage.clone(),
                message: format!("printer must name a new printer (got `{name}`)"),
            });
        }
        for line in &mut dataset.lines {
            line.widths_mm = other_family_widths(&line.positions_mm, &line.widths_mm, scale, lag_mm);
        }
        dataset.manifest.description = format!(
            "{}'s lines as a printer of another family: widths × {scale}, lagged over {lag_mm} mm of path (fdm.other_family).",
            dataset.manifest.printer
        );
        dataset.manifest.printer = name;
        dataset.write(ctx.output_dir()).map_err(StageError::domain)?;
        Ok(())
    }
}
