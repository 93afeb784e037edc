//! Reading published Parquet tables into plain vectors for drawing: the pipeline's one
//! typed column reader (`pipeline::columns`, its null rule stated there) and what only
//! the figures and sections need.

use std::path::Path;

pub use pipeline::artifact::read_parquet;
pub use pipeline::columns::{bools, column, f64s, ints, strs};
use pipeline::StageError;
use polars::prelude::DataFrame;

/// Columns `mean`, `lo` and `hi` as (estimate, interval low, interval high) per row.
pub fn f64_triples(df: &DataFrame, [mean, lo, hi]: [&str; 3], path: &Path) -> Result<Vec<(f64, f64, f64)>, StageError> {
    let (m, l, h) = (f64s(df, mean, path)?, f64s(df, lo, path)?, f64s(df, hi, path)?);
    Ok((0..m.len()).map(|i| (m[i], l[i], h[i])).collect())
}

/// The error for a table that holds no rows of the selection a figure draws.
pub fn no_rows(path: &Path, column: &str, wanted: &str) -> StageError {
    StageError::BadInput {
        file: path.to_path_buf(),
        location: Some(column.into()),
        expected: format!("expected rows with {wanted}"),
    }
}
