//! `fdm.import`: converts raw measured line widths into an `fdm-widths` dataset
//! (DESIGN §4) and a long Parquet table of every measurement.
//!
//! Source format `fsu-linewidth`: the FSU Taz 5 / Taz 6 release behind paper 000's
//! Table II (see `datasets::fsu`), each file verified against its published SHA-256.

use datasets::fsu::{self, FsuPrinter, ImportOptions};
use pipeline::params::{Names, OneOf};
use pipeline::schema::Table;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::widths;

use crate::table::{f64_col, frame, str_col};

/// The `fdm.import` stage kind.
pub struct ImportStage;

pipeline::choice! {
    /// Layouts of raw measured line widths the importer reads.
    pub enum SourceFormat {
        /// The FSU release: S{a}F{F mm/min}_{tag}120.csv files per printer folder.
        FsuLinewidth = "fsu-linewidth",
    }
}

/// The printer folders of the FSU release.
pub struct FsuPrinters;

impl Names for FsuPrinters {
    const NAMES: &'static [&'static str] = &FsuPrinter::NAMES;
}

pipeline::params! {
    /// The parameters of `fdm.import`.
    pub struct ImportParams {
        /// Layout of the raw data: `fsu-linewidth` = S{a}F{F mm/min}_{tag}120.csv files per printer folder.
        pub source_format: SourceFormat = SourceFormat::FsuLinewidth,
        /// Which printer folder to import.
        pub printer: OneOf<FsuPrinters>,
        /// Check every file against the published release's SHA-256 (off only for your own data in the same layout).
        pub verify_sha256: bool = true,
    }
}

/// The raw data.
const RAW: Input = Input::one("raw", &[Source::RawFolder], "the raw release: one folder per printer");

impl Stage for ImportStage {
    type Params = ImportParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.import",
        // 2: every raw row is checked at import (an invalid dataset was written before).
        version: 2,
        summary: "Raw measured line widths → an fdm-widths dataset (dataset.toml, lines.csv, widths/*.csv) plus widths.parquet",
        implements: "paper 000 Sec. III (measured widths), Table I (conditions); DESIGN §4 fdm-widths",
        inputs: &[RAW],
        output: Output::Dataset("fdm-widths"),
    };
    const WRITES: &'static [&'static Table] = &[&widths::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &ImportParams) -> Result<(), StageError> {
        let printer = FsuPrinter::parse(p.printer.as_str()).expect("the planner checked the name");
        let opts = ImportOptions { verify_sha256: p.verify_sha256 };
        let dataset = fsu::read_printer(&ctx.input(&RAW).dir, printer, opts).map_err(StageError::domain)?;
        dataset.write(ctx.output_dir()).map_err(StageError::domain)?;
        let mut long = widths_table(&dataset)?;
        ctx.write_table(widths::TABLE.name, &mut long)?;
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
        str_col(widths::printer, printer),
        str_col(widths::condition, condition),
        f64_col(widths::accel_mm_s2, accel),
        f64_col(widths::feed_mm_s, feed),
        f64_col(widths::position_mm, pos),
        f64_col(widths::width_mm, width),
    ])
}
