//! Turns `fdm-widths` datasets (the on-disk format) into the numeric models' input
//! type, and carries each line's printer and condition along for the tables.

use std::path::Path;

use datasets::fdm_widths::FdmWidthsDataset;
use models::fdm::{LineKinematics, MeasuredLine};
use pipeline::StageError;

use crate::table::read_fdm_widths;

/// One printer's lines, read from a dataset folder.
pub struct PrinterLines {
    /// Printer name from `dataset.toml`.
    pub printer: String,
    /// Condition label per line.
    pub conditions: Vec<String>,
    /// The lines, in `lines.csv` order.
    pub lines: Vec<MeasuredLine>,
}

impl PrinterLines {
    /// Reads the dataset in `dir`.
    pub fn read(dir: &Path) -> Result<Self, StageError> {
        let dataset = read_fdm_widths(dir)?;
        Self::from_dataset(&dataset, dir)
    }

    /// Converts a dataset; a line the models reject is an error naming its file.
    pub fn from_dataset(dataset: &FdmWidthsDataset, dir: &Path) -> Result<Self, StageError> {
        let mut lines = Vec::with_capacity(dataset.lines.len());
        for line in &dataset.lines {
            let m = line.motion;
            let bad = |e: String| StageError::BadInput {
                file: dir.join("lines.csv"),
                location: Some(format!("line_id {}", line.line_id)),
                expected: e,
            };
            let nominal = LineKinematics::new(m.accel_mm_s2, m.feed_mm_s, m.jerk_mm_s, m.length_mm)
                .map_err(|e| bad(e.to_string()))?;
            let measured = MeasuredLine::new(nominal, line.positions_mm.clone(), line.widths_mm.clone())
                .map_err(|e| bad(e.to_string()))?;
            lines.push(measured);
        }
        Ok(Self {
            printer: dataset.manifest.printer.clone(),
            conditions: dataset.lines.iter().map(|l| l.condition.clone()).collect(),
            lines,
        })
    }
}

/// A model error as a stage error.
pub fn fit_failed(what: &str, err: impl std::fmt::Display) -> StageError {
    StageError::Domain(format!("{what}: {err}").into())
}

/// A paper-000 model's hyper-parameter error as the planner's error on the stage
/// parameter of the same name.
pub fn model_param_error(err: models::fdm::ParamError) -> pipeline::params::ParamError {
    match &err {
        models::fdm::ParamError::OutOfRange { name, .. } => pipeline::params::ParamError::new(name, err.to_string()),
    }
}
