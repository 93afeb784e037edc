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

/// A column of floats of `df` (read from `file`), nulls as NaN.
pub fn f64_column(df: &DataFrame, file: &Path, name: &str) -> Result<Vec<f64>, StageError> {
    let series = pipeline::artifact::column(df, name, file)?;
    let cast = series
        .cast(&polars::prelude::DataType::Float64)
        .map_err(|source| StageError::Table { path: file.into(), source })?;
    let values = cast.f64().map_err(|source| StageError::Table { path: file.into(), source })?;
    Ok(values.iter().map(|v| v.unwrap_or(f64::NAN)).collect())
}

/// A column of integers of `df` (read from `file`).
pub fn i64_column(df: &DataFrame, file: &Path, name: &str) -> Result<Vec<i64>, StageError> {
    let series = pipeline::artifact::column(df, name, file)?;
    let cast = series
        .cast(&polars::prelude::DataType::Int64)
        .map_err(|source| StageError::Table { path: file.into(), source })?;
    let values = cast.i64().map_err(|source| StageError::Table { path: file.into(), source })?;
    Ok(values.iter().map(|v| v.unwrap_or(-1)).collect())
}

/// A column of strings of `df` (read from `file`), nulls as empty strings.
pub fn str_column(df: &DataFrame, file: &Path, name: &str) -> Result<Vec<String>, StageError> {
    let series = pipeline::artifact::column(df, name, file)?;
    let values = series.str().map_err(|source| StageError::Table { path: file.into(), source })?;
    Ok(values.iter().map(|v| v.unwrap_or_default().to_string()).collect())
}

/// A column of booleans of `df` (read from `file`), nulls kept.
pub fn opt_bool_column(df: &DataFrame, file: &Path, name: &str) -> Result<Vec<Option<bool>>, StageError> {
    let series = pipeline::artifact::column(df, name, file)?;
    let values = series.bool().map_err(|source| StageError::Table { path: file.into(), source })?;
    Ok(values.iter().collect())
}

/// Reads an `fdm-widths` dataset folder.
pub fn read_fdm_widths(dir: &Path) -> Result<datasets::fdm_widths::FdmWidthsDataset, StageError> {
    datasets::fdm_widths::FdmWidthsDataset::read(dir).map_err(StageError::domain)
}
