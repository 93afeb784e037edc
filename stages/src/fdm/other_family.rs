//! `fdm.other_family`: an `fdm-widths` dataset of a printer of another family, made from
//! measured lines by a stated physical transformation (`models::fdm::other_family_widths`:
//! a wider nozzle scales every width, a slower melt response lags it along the path).
//! Transfer studies need printers that clearly differ from the source; until a lab's
//! lines of another printer family are at hand, this is one with known differences.
//! The output folder is the dataset; its `printer` is the `printer` parameter.

use datasets::fdm_widths::FdmWidthsDataset;
use models::fdm::other_family_widths;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use crate::table::read_fdm_widths;

/// The `fdm.other_family` stage kind.
pub struct OtherFamilyStage;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "printer",
        ty: ParamType::Text,
        default: ParamDefault::Required,
        doc: "Name of the derived printer (its dataset.toml `printer`).",
    },
    ParamSpec {
        name: "width_scale",
        ty: ParamType::Float { min: 0.2, max: 5.0 },
        default: ParamDefault::Float(1.0),
        doc: "Every width times this (a nozzle this many times wider at the same kinematics).",
    },
    ParamSpec {
        name: "lag_mm",
        ty: ParamType::Float { min: 0.0, max: 60.0 },
        default: ParamDefault::Float(0.0),
        doc: "First-order lag of the widths along the path (mm): a slower melt response; 0 keeps the shape.",
    },
];

impl StageKind for OtherFamilyStage {
    fn name(&self) -> &'static str {
        "fdm.other_family"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "A printer of another family from measured lines: widths scaled (wider nozzle) and lagged along the path (slower melt) → an fdm-widths dataset (the output folder)"
    }
    fn implements(&self) -> &'static str {
        "test printers for paper 000's transfer (Sec. III-B) beyond the Taz 5 / Taz 6"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let mut dataset: FdmWidthsDataset = read_fdm_widths(&ctx.inputs[0].dir)?;
        let (scale, lag_mm) = (ctx.params.f64("width_scale"), ctx.params.f64("lag_mm"));
        let name = ctx.params.str("printer").trim().to_string();
        if name.is_empty() || name == dataset.manifest.printer {
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
