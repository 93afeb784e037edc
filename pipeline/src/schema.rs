//! Table schemas: a Parquet table's columns declared once — name (with its unit),
//! type, unit and meaning — as a [`Table`] constant that the stage writing the table,
//! every stage and report reading it, the test fixtures and the docs use. The
//! declarations of the project's tables live in the `tables` crate; this module holds
//! only the types, the [`crate::table!`] macro and the checks: a written frame must
//! match its declaration exactly ([`Table::check_frame`]), and the planner refuses a
//! stage whose input role reads a column the upstream kind does not write
//! ([`Reads`], `plan`).

use std::fmt;

use polars::prelude::{DataFrame, DataType};

/// The type of a declared column, as Parquet stores it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dtype {
    /// `float64` (a null is NaN to every reader).
    Float64,
    /// `int64`.
    Int64,
    /// A UTF-8 string.
    Str,
    /// A boolean.
    Bool,
}

impl Dtype {
    /// The polars type a column of this type has.
    pub fn polars(self) -> DataType {
        match self {
            Self::Float64 => DataType::Float64,
            Self::Int64 => DataType::Int64,
            Self::Str => DataType::String,
            Self::Bool => DataType::Boolean,
        }
    }
}

impl fmt::Display for Dtype {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Float64 => "float64",
            Self::Int64 => "int64",
            Self::Str => "string",
            Self::Bool => "bool",
        })
    }
}

/// One declared column.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Column {
    /// The name in the file, with its unit (`w_left_mm`).
    pub name: &'static str,
    /// Its type.
    pub dtype: Dtype,
    /// Its unit (`mm`, `s`, `°C`, `1` for a dimensionless number, empty for a label).
    pub unit: &'static str,
    /// One sentence: what it holds.
    pub meaning: &'static str,
}

/// A declared table: the file a stage writes (`name.parquet`) and its columns in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Table {
    /// The file name without `.parquet`.
    pub name: &'static str,
    /// One sentence: what a row is.
    pub doc: &'static str,
    /// The columns, in file order.
    pub columns: &'static [Column],
}

impl Table {
    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&'static Column> {
        self.columns.iter().find(|c| c.name == name)
    }

    /// The file name, `name.parquet`.
    pub fn file(&self) -> String {
        format!("{}.parquet", self.name)
    }

    /// Whether `df` has exactly the declared columns, in order, of the declared types.
    pub fn check_frame(&self, df: &DataFrame) -> Result<(), String> {
        let found: Vec<(String, DataType)> =
            df.columns().iter().map(|c| (c.name().to_string(), c.dtype().clone())).collect();
        let declared: Vec<(String, DataType)> =
            self.columns.iter().map(|c| (c.name.to_string(), c.dtype.polars())).collect();
        if found == declared {
            return Ok(());
        }
        let show =
            |cols: &[(String, DataType)]| cols.iter().map(|(n, t)| format!("{n}: {t}")).collect::<Vec<_>>().join(", ");
        Err(format!("{} declares [{}], the frame has [{}]", self.file(), show(&declared), show(&found)))
    }
}

/// What a stage reads of an input role's upstream tables: a declared table and the
/// columns it reads from it. The planner checks that the upstream kind writes that table
/// with those columns of those types.
#[derive(Debug, Clone, Copy)]
pub struct Reads {
    /// The table read.
    pub table: &'static Table,
    /// The names of the columns read.
    pub columns: &'static [&'static str],
}

/// Declares a table once: a module holding each column's name as a constant (named as
/// the column, so a reader writes `widths::w_left_mm` and a renamed column breaks every
/// reader's build) and the [`Table`] as `TABLE`.
///
/// ```
/// pipeline::table! {
///     /// One row per measured sample.
///     pub mod widths = "widths" {
///         /// Position along the line.
///         position_mm: Float64 "mm",
///         /// The line's condition.
///         condition: Str "",
///     }
/// }
/// assert_eq!(widths::position_mm, "position_mm");
/// assert_eq!(widths::TABLE.columns[1].meaning, "The line's condition.");
/// ```
#[macro_export]
macro_rules! table {
    (
        $(#[doc = $doc:literal])*
        $vis:vis mod $module:ident = $file:literal {
            $( $(#[doc = $cdoc:literal])* $column:ident : $dtype:ident $unit:literal ),* $(,)?
        }
    ) => {
        $(#[doc = $doc])*
        #[allow(non_upper_case_globals, dead_code)]
        $vis mod $module {
            $(
                $(#[doc = $cdoc])*
                pub const $column: &str = stringify!($column);
            )*
            /// The declaration.
            pub const TABLE: $crate::schema::Table = $crate::schema::Table {
                name: $file,
                doc: concat!($($doc),*).trim_ascii(),
                columns: &[$(
                    $crate::schema::Column {
                        name: stringify!($column),
                        dtype: $crate::schema::Dtype::$dtype,
                        unit: $unit,
                        meaning: concat!($($cdoc),*).trim_ascii(),
                    },
                )*],
            };
        }
    };
}

#[cfg(test)]
mod tests {
    use polars::prelude::{df, IntoColumn, NamedFrom, Series};

    crate::table! {
        /// A test table.
        mod samples = "samples" {
            /// Where.
            x_mm: Float64 "mm",
            /// Which.
            layer: Int64 "1",
        }
    }

    #[test]
    fn a_frame_must_have_the_declared_columns_in_order_and_types() {
        let good = df!("x_mm" => [1.0, 2.0], "layer" => [0i64, 1]).unwrap();
        assert_eq!(samples::TABLE.check_frame(&good), Ok(()));
        let swapped = df!("layer" => [0i64, 1], "x_mm" => [1.0, 2.0]).unwrap();
        assert!(samples::TABLE.check_frame(&swapped).is_err());
        let mut retyped = good.clone();
        retyped.with_column(Series::new("layer".into(), [0.0, 1.0]).into_column()).unwrap();
        let err = samples::TABLE.check_frame(&retyped).unwrap_err();
        assert!(err.starts_with("samples.parquet declares [x_mm: f64, layer: i64]"), "{err}");
        assert_eq!(samples::TABLE.column(samples::layer).map(|c| c.unit), Some("1"));
    }
}
