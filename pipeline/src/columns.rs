//! The one typed reader of a published table's columns, for stages, reports and the
//! nightly history alike, with one null rule: **a null reads as its type's missing
//! value where the type has one — NaN for a float, the empty string for a string — and
//! is an error naming the file, column and row where it has none (integers,
//! booleans)**. Where a null means something of its own (a time not measured, a
//! verdict not reached), read the column with its `opt_` reader, which keeps it. A
//! column of the wrong type is an error naming it and its type; integers widen to
//! `i64`, and integers read as floats.

use std::path::Path;

use polars::prelude::{Column, DataFrame, DataType, PolarsError};

pub use crate::artifact::column;
use crate::error::StageError;

/// Column `name` of `df` (read from `path`) as floats: a float or integer column;
/// nulls become NaN.
pub fn f64s(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<f64>, StageError> {
    Ok(opt_f64s(df, name, path)?.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect())
}

/// Column `name` as strings; nulls become empty strings.
pub fn strs(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<String>, StageError> {
    Ok(opt_strs(df, name, path)?.into_iter().map(Option::unwrap_or_default).collect())
}

/// Column `name` as 64-bit integers, from any integer type (ids are written as i32,
/// counts as i64); a null is an error naming its row.
pub fn ints(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<i64>, StageError> {
    required(opt_ints(df, name, path)?, name, path)
}

/// Column `name` as booleans; a null is an error naming its row.
pub fn bools(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<bool>, StageError> {
    required(opt_bools(df, name, path)?, name, path)
}

/// [`f64s`] with its nulls kept.
pub fn opt_f64s(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<Option<f64>>, StageError> {
    let col = typed(df, name, path, |t| t.is_float() || t.is_integer(), "numbers")?;
    let wide = col.cast(&DataType::Float64).map_err(table_error(path))?;
    Ok(wide.f64().map_err(table_error(path))?.iter().collect())
}

/// [`strs`] with its nulls kept.
pub fn opt_strs(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<Option<String>>, StageError> {
    let col = typed(df, name, path, |t| matches!(t, DataType::String), "strings")?;
    Ok(col.str().map_err(table_error(path))?.iter().map(|v| v.map(str::to_string)).collect())
}

/// [`ints`] with its nulls kept.
pub fn opt_ints(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<Option<i64>>, StageError> {
    let col = typed(df, name, path, DataType::is_integer, "integers")?;
    let wide = col.cast(&DataType::Int64).map_err(table_error(path))?;
    Ok(wide.i64().map_err(table_error(path))?.iter().collect())
}

/// [`bools`] with its nulls kept.
pub fn opt_bools(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<Option<bool>>, StageError> {
    let col = typed(df, name, path, |t| matches!(t, DataType::Boolean), "booleans")?;
    Ok(col.bool().map_err(table_error(path))?.iter().collect())
}

/// `read` of column `name` when `df` has it, `None` when it has not (a column a later
/// version of the writing stage added, read from an older table).
pub fn if_present<T>(
    df: &DataFrame,
    name: &str,
    path: &Path,
    read: fn(&DataFrame, &str, &Path) -> Result<Vec<T>, StageError>,
) -> Result<Option<Vec<T>>, StageError> {
    if df.column(name).is_err() {
        return Ok(None);
    }
    read(df, name, path).map(Some)
}

/// The values, or an error naming the first null's row.
fn required<T>(values: Vec<Option<T>>, name: &str, path: &Path) -> Result<Vec<T>, StageError> {
    values.into_iter().enumerate().map(|(row, v)| v.ok_or_else(|| null_at(path, name, row))).collect()
}

/// Column `name`, checked to hold `what` (its type passing `accepts`).
fn typed<'a>(
    df: &'a DataFrame,
    name: &str,
    path: &Path,
    accepts: impl Fn(&DataType) -> bool,
    what: &str,
) -> Result<&'a Column, StageError> {
    let col = column(df, name, path)?;
    if accepts(col.dtype()) {
        return Ok(col);
    }
    Err(StageError::BadInput {
        file: path.to_path_buf(),
        location: Some(name.into()),
        expected: format!("expected a column of {what}, found {}", col.dtype()),
    })
}

fn table_error(path: &Path) -> impl Fn(PolarsError) -> StageError + '_ {
    move |source| StageError::Table { path: path.to_path_buf(), source }
}

fn null_at(path: &Path, name: &str, row: usize) -> StageError {
    StageError::BadInput {
        file: path.to_path_buf(),
        location: Some(format!("{name}, row {row}")),
        expected: "expected a value, found null".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use polars::prelude::{IntoColumn, NamedFrom, Series};

    fn table() -> DataFrame {
        let columns = vec![
            Series::new("x".into(), [Some(1.5), None]).into_column(),
            Series::new("n32".into(), [Some(3i32), Some(-1)]).into_column(),
            Series::new("gap".into(), [Some(7i64), None]).into_column(),
            Series::new("name".into(), [Some("a"), None]).into_column(),
            Series::new("flag".into(), [Some(true), None]).into_column(),
        ];
        DataFrame::new(2, columns).unwrap()
    }

    fn message(e: StageError) -> String {
        e.to_string()
    }

    #[test]
    fn a_null_is_the_missing_value_of_a_float_or_string() {
        let (df, path) = (table(), Path::new("t.parquet"));
        let x = f64s(&df, "x", path).unwrap();
        assert_eq!(x[0], 1.5);
        assert!(x[1].is_nan());
        assert_eq!(strs(&df, "name", path).unwrap(), ["a", ""]);
        assert_eq!(opt_bools(&df, "flag", path).unwrap(), [Some(true), None]);
        assert_eq!(opt_f64s(&df, "x", path).unwrap(), [Some(1.5), None]);
        assert_eq!(opt_ints(&df, "gap", path).unwrap(), [Some(7), None]);
        assert_eq!(opt_strs(&df, "name", path).unwrap(), [Some("a".to_string()), None]);
    }

    #[test]
    fn a_null_integer_or_boolean_is_an_error_naming_file_column_and_row() {
        let (df, path) = (table(), Path::new("t.parquet"));
        let gap = message(ints(&df, "gap", path).unwrap_err());
        assert!(gap.contains("t.parquet") && gap.contains("gap, row 1") && gap.contains("null"), "{gap}");
        let flag = message(bools(&df, "flag", path).unwrap_err());
        assert!(flag.contains("flag, row 1"), "{flag}");
    }

    #[test]
    fn integers_widen_and_read_as_floats_but_other_types_are_refused() {
        let (df, path) = (table(), Path::new("t.parquet"));
        assert_eq!(ints(&df, "n32", path).unwrap(), [3, -1]);
        assert_eq!(f64s(&df, "n32", path).unwrap(), [3.0, -1.0]);
        let wrong = message(f64s(&df, "name", path).unwrap_err());
        assert!(wrong.contains("name") && wrong.contains("expected a column of numbers, found str"), "{wrong}");
        assert!(message(ints(&df, "x", path).unwrap_err()).contains("integers, found f64"));
        assert!(message(bools(&df, "n32", path).unwrap_err()).contains("booleans, found i32"));
        assert!(message(strs(&df, "missing", path).unwrap_err()).contains("expected a column `missing`"));
        assert_eq!(if_present(&df, "missing", path, f64s).unwrap(), None);
        assert_eq!(if_present(&df, "n32", path, ints).unwrap(), Some(vec![3, -1]));
        assert!(if_present(&df, "name", path, f64s).is_err(), "a present column of the wrong type is still refused");
    }
}
