//! Helpers shared by the figure tests: synthetic tables written the way stages write
//! them, a deterministic noise source, and a check that a figure was really drawn.
//! Set `AMREPRO_KEEP_FIGURES=<folder>` to keep copies of the drawn PNGs for looking at.

use std::path::Path;

use pipeline::artifact::{write_parquet, TableMeta};
use pipeline::schema::Table;
use polars::prelude::{Column, DataFrame};

/// A blank 1400×700 PNG compresses to a few kB; a drawn figure with text and data is
/// well above this.
const MIN_PNG_BYTES: u64 = 20_000;

/// Writes `df` as `<dir>/<name>.parquet` through the pipeline's Parquet writer.
pub fn write_table(dir: &Path, name: &str, mut df: DataFrame) {
    let meta = TableMeta { stage: "test".into(), stage_hash: "0".into(), params_hash: "0".into(), schema_version: 1 };
    write_parquet(&dir.join(format!("{name}.parquet")), &mut df, &meta).expect("test table is written");
}

/// Writes `df` as the declared table `table` (`<dir>/<table>.parquet`), after checking
/// it has exactly the columns and types the writing stage declares, so a fixture cannot
/// drift from its writer.
pub fn write_declared(dir: &Path, table: &Table, df: DataFrame) {
    if let Err(e) = table.check_frame(&df) {
        panic!("the fixture does not match its declaration: {e}");
    }
    write_table(dir, table.name, df);
}

/// The fixture `df` as the declared table `table`: its columns in declared order, each
/// cast to its declared type (a fixture may write `i32` ids), every declared column the
/// fixture does not set null. Panics on a column `table` does not declare, so a fixture
/// cannot hold a stale name.
pub fn declared(table: &Table, df: DataFrame) -> DataFrame {
    for name in df.get_column_names() {
        assert!(table.column(name).is_some(), "{} declares no column `{name}`", table.file());
    }
    let columns: Vec<Column> = table
        .columns
        .iter()
        .map(|c| match df.column(c.name) {
            Ok(given) => given.strict_cast(&c.dtype.polars()).expect("the fixture's column casts to its declared type"),
            Err(_) => Column::full_null(c.name.into(), df.height(), &c.dtype.polars()),
        })
        .collect();
    DataFrame::new(df.height(), columns).expect("columns of equal length")
}

/// Asserts `<stem>.png` and `<stem>.svg` exist and the PNG holds more than a blank
/// canvas; copies the PNG to `$AMREPRO_KEEP_FIGURES` when that is set.
pub fn assert_drawn(stem: &Path) {
    let png = stem.with_extension("png");
    let bytes = std::fs::metadata(&png).expect("PNG is written").len();
    assert!(bytes > MIN_PNG_BYTES, "{} has only {bytes} bytes", png.display());
    assert!(stem.with_extension("svg").exists(), "SVG is written");
    if let Some(keep) = std::env::var_os("AMREPRO_KEEP_FIGURES") {
        let name = png.file_name().expect("stem has a file name");
        std::fs::copy(&png, Path::new(&keep).join(name)).expect("PNG is copied");
    }
}

/// Deterministic noise in [-0.5, 0.5) (the classic shader hash), so tests need no RNG.
pub fn noise(i: usize) -> f64 {
    let x = (i as f64 * 12.9898).sin() * 43_758.545_3;
    x - x.floor() - 0.5
}

/// A width profile with the paper's shape: a blob at the start, a steady width that
/// shrinks with feed, and thinning over the last millimetres (paper 000 Fig. 3(a)).
pub fn synthetic_width_mm(x_mm: f64, length_mm: f64, feed_mm_s: f64) -> f64 {
    let steady_mm = 0.55 - 0.001 * feed_mm_s;
    steady_mm + 0.15 * (-x_mm / 3.0).exp() - 0.12 * (-(length_mm - x_mm) / 2.5).exp()
}
