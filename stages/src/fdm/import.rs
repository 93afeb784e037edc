//! `fdm.import`: converts raw measured line widths into an `fdm-widths` dataset
//! (DESIGN §4) and a long Parquet table of every measurement.
//!
//! Source format `fsu-linewidth`: the FSU Taz 5 / Taz 6 release behind paper 000's
//! Table II (see `datasets::fsu`), each file verified against its published SHA-256.

use datasets::fsu::{self, FsuPrinter, ImportOptions};
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use crate::table::{f64_col, frame, str_col};

/// The `fdm.import` stage kind.
pub struct ImportStage;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "source_format",
        ty: ParamType::Choice(&["fsu-linewidth"]),
        default: ParamDefault::Str("fsu-linewidth"),
        doc: "Layout of the raw data: `fsu-linewidth` = S{a}F{F mm/min}_{tag}120.csv files per printer folder.",
    },
    ParamSpec {
        name: "printer",
        ty: ParamType::Choice(&["taz5", "taz6"]),
        default: ParamDefault::Required,
        doc: "Which printer folder to import.",
    },
    ParamSpec {
        name: "verify_sha256",
        ty: ParamType::Bool,
        default: ParamDefault::Bool(true),
        doc:
            "Check every file against the published release's SHA-256 (off only for your own data in the same layout).",
    },
];

impl StageKind for ImportStage {
    fn name(&self) -> &'static str {
        "fdm.import"
    }
    fn version(&self) -> u32 {
        // 2: every raw row is checked at import (an invalid dataset was written before).
        2
    }
    fn summary(&self) -> &'static str {
        "Raw measured line widths → an fdm-widths dataset (dataset.toml, lines.csv, widths/*.csv) plus widths.parquet"
    }
    fn implements(&self) -> &'static str {
        "paper 000 Sec. III (measured widths), Table I (conditions); DESIGN §4 fdm-widths"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let printer = FsuPrinter::parse(ctx.params.str("printer")).expect("checked choice");
        let opts = ImportOptions { verify_sha256: ctx.params.bool("verify_sha256") };
        let dataset = fsu::read_printer(&ctx.inputs[0].dir, printer, opts).map_err(StageError::domain)?;
        dataset.write(ctx.output_dir()).map_err(StageError::domain)?;
        let mut long = widths_table(&dataset)?;
        ctx.write_table("widths", &mut long)?;
        Ok(())
    }
}

/// One row per measurement: printer, condition, kinematics, position, width.
fn widths_table(dataset: &datasets::fdm_widths::FdmWidthsDataset) -> Result<polars::prelude::DataFrame, StageError> {
    let n: usize = dataset.lines.iter().map(|l| l.positions_mm.len()).sum();
    let (mut printer, mut condition) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut accel, mut feed, mut pos, mut width) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for line in &dataset.lines {
        for (x, w) in line.positions_mm.iter().zip(&line.widths_mm) {
            printer.push(dataset.manifest.printer.clone());
            condition.push(line.condition.clone());
            accel.push(line.motion.accel_mm_s2);
            feed.push(line.motion.feed_mm_s);
            pos.push(*x);
            width.push(*w);
        }
    }
    frame(vec![
        str_col("printer", printer),
        str_col("condition", condition),
        f64_col("accel_mm_s2", accel),
        f64_col("feed_mm_s", feed),
        f64_col("position_mm", pos),
        f64_col("width_mm", width),
    ])
}
