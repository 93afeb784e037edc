//! Reading published Parquet tables into plain vectors for drawing.

use std::path::Path;

pub use pipeline::artifact::{column, read_parquet};
use pipeline::StageError;
use polars::prelude::DataFrame;

/// Column `name` as floats (nulls become NaN).
pub fn f64s(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<f64>, StageError> {
    let bad = |e: polars::error::PolarsError| StageError::Table { path: path.to_path_buf(), source: e };
    let col = column(df, name, path)?;
    let ca = col.f64().map_err(bad)?;
    Ok(ca.iter().map(|v| v.unwrap_or(f64::NAN)).collect())
}

/// Columns `mean`, `lo` and `hi` as (estimate, interval low, interval high) per row.
pub fn f64_triples(df: &DataFrame, [mean, lo, hi]: [&str; 3], path: &Path) -> Result<Vec<(f64, f64, f64)>, StageError> {
    let (m, l, h) = (f64s(df, mean, path)?, f64s(df, lo, path)?, f64s(df, hi, path)?);
    Ok((0..m.len()).map(|i| (m[i], l[i], h[i])).collect())
}

/// Column `name` as strings.
pub fn strs(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<String>, StageError> {
    let bad = |e: polars::error::PolarsError| StageError::Table { path: path.to_path_buf(), source: e };
    let col = column(df, name, path)?;
    let ca = col.str().map_err(bad)?;
    Ok(ca.iter().map(|v| v.unwrap_or_default().to_string()).collect())
}

/// Column `name` as 64-bit integers (nulls are an error).
pub fn i64s(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<i64>, StageError> {
    let bad = |e: polars::error::PolarsError| StageError::Table { path: path.to_path_buf(), source: e };
    let col = column(df, name, path)?;
    let ca = col.i64().map_err(bad)?;
    ca.iter()
        .enumerate()
        .map(|(row, v)| {
            v.ok_or_else(|| StageError::BadInput {
                file: path.to_path_buf(),
                location: Some(format!("{name}, row {row}")),
                expected: "expected an integer, found null".into(),
            })
        })
        .collect()
}

/// The error for a table that holds no rows of the selection a figure draws.
pub fn no_rows(path: &Path, column: &str, wanted: &str) -> StageError {
    StageError::BadInput {
        file: path.to_path_buf(),
        location: Some(column.into()),
        expected: format!("expected rows with {wanted}"),
    }
}

/// Column `name` as 64-bit integers, from any integer type (ids are written as i32,
/// counts as i64). A non-integer column or a null is an error naming the column.
pub fn ints(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<i64>, StageError> {
    let bad = |e: polars::error::PolarsError| StageError::Table { path: path.to_path_buf(), source: e };
    let col = column(df, name, path)?;
    if !col.dtype().is_integer() {
        return Err(StageError::BadInput {
            file: path.to_path_buf(),
            location: Some(name.into()),
            expected: format!("expected an integer column, found {}", col.dtype()),
        });
    }
    let wide = col.cast(&polars::prelude::DataType::Int64).map_err(bad)?;
    let ca = wide.i64().map_err(bad)?;
    ca.iter().enumerate().map(|(row, v)| v.ok_or_else(|| null_at(path, name, row))).collect()
}

/// Column `name` as booleans (nulls are an error).
pub fn bools(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<bool>, StageError> {
    let bad = |e: polars::error::PolarsError| StageError::Table { path: path.to_path_buf(), source: e };
    let ca = column(df, name, path)?.bool().map_err(bad)?;
    ca.iter().enumerate().map(|(row, v)| v.ok_or_else(|| null_at(path, name, row))).collect()
}

fn null_at(path: &Path, name: &str, row: usize) -> StageError {
    StageError::BadInput {
        file: path.to_path_buf(),
        location: Some(format!("{name}, row {row}")),
        expected: "expected a value, found null".into(),
    }
}
