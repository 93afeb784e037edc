//! Small helpers to build polars tables from typed rows and to read the datasets a
//! stage declared as inputs, turning domain errors into stage errors.

use std::path::Path;

use pipeline::StageError;
use polars::prelude::{Column, DataFrame, IntoColumn, NamedFrom, Series};

/// A column of floats.
pub fn f64_col(name: &str, values: Vec<f64>) -> Column {
    Series::new(name.into(), values).into_column()
}

/// A column of strings.
pub fn str_col(name: &str, values: Vec<String>) -> Column {
    Series::new(name.into(), values).into_column()
}

/// A column of 64-bit integers.
pub fn i64_col(name: &str, values: Vec<i64>) -> Column {
    Series::new(name.into(), values).into_column()
}

/// A column of booleans.
pub fn bool_col(name: &str, values: Vec<bool>) -> Column {
    Series::new(name.into(), values).into_column()
}

/// A table from columns of equal length.
pub fn frame(columns: Vec<Column>) -> Result<DataFrame, StageError> {
    let height = columns.first().map_or(0, |c| c.len());
    DataFrame::new(height, columns).map_err(|source| StageError::Table { path: "(in memory)".into(), source })
}

pub use pipeline::columns::{bools, f64s, if_present, ints, opt_bools, opt_strs, strs};

/// Reads an `fdm-widths` dataset folder.
pub fn read_fdm_widths(dir: &Path) -> Result<datasets::fdm_widths::FdmWidthsDataset, StageError> {
    datasets::fdm_widths::FdmWidthsDataset::read(dir).map_err(StageError::domain)
}
