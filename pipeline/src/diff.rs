//! `amrepro diff`: the published numbers that changed between two out folders (as
//! `dvc metrics diff`), so that a researcher sees what a parameter (`run --set`) or a
//! code change did. The tables compared are those the runs' manifests
//! (`runs/*/manifest.json`) publish as Parquet; rows are matched on their key columns
//! (strings, integers, booleans: the ids and labels of docs/OUTPUTS.md's long tables)
//! and every float column both sides hold is compared, row by row.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt;
use std::path::{Path, PathBuf};

use polars::prelude::{DataFrame, DataType};

use crate::artifact::read_parquet;
use crate::columns::{opt_bools, opt_f64s, opt_ints, opt_strs};
use crate::error::StageError;
use crate::manifest::Manifest;

/// A published table and what wrote it.
#[derive(Debug, Clone, PartialEq)]
pub struct Published {
    /// The run (manifest) publishing it.
    pub run: String,
    /// The stage whose output it is.
    pub stage: String,
}

/// One number that changed.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    /// The row's key: `column=value` of each key column (with `#n` for the n-th row of
    /// a key that repeats, `row n` in a table without key columns).
    pub key: String,
    /// The float column.
    pub column: String,
    /// The value in the first folder (NaN for null).
    pub old: f64,
    /// The value in the second folder.
    pub new: f64,
}

impl Change {
    /// (new − old) / |old|: infinite from 0, NaN where either side is NaN.
    pub fn relative(&self) -> f64 {
        (self.new - self.old) / self.old.abs()
    }
}

/// What changed in one table published in both folders.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TableDiff {
    /// Its path relative to the out folders.
    pub table: PathBuf,
    /// The run and stage publishing it in the second folder.
    pub run: String,
    /// See `run`.
    pub stage: String,
    /// The key columns rows were matched on.
    pub keys: Vec<String>,
    /// Numbers compared (matched rows × float columns in both).
    pub compared: usize,
    /// The numbers that changed, in row order of the first folder, then column order.
    pub changes: Vec<Change>,
    /// Keys of rows only in the first folder.
    pub rows_only_a: Vec<String>,
    /// Keys of rows only in the second folder.
    pub rows_only_b: Vec<String>,
    /// Columns only in the first folder.
    pub columns_only_a: Vec<String>,
    /// Columns only in the second folder.
    pub columns_only_b: Vec<String>,
}

impl TableDiff {
    /// Whether anything differs.
    pub fn changed(&self) -> bool {
        !(self.changes.is_empty()
            && self.rows_only_a.is_empty()
            && self.rows_only_b.is_empty()
            && self.columns_only_a.is_empty()
            && self.columns_only_b.is_empty())
    }
}

/// What changed between two out folders.
#[derive(Debug, Clone, Default)]
pub struct OutDiff {
    /// The first folder.
    pub a: PathBuf,
    /// The second folder.
    pub b: PathBuf,
    /// Tables published in both, in path order (changed or not).
    pub tables: Vec<TableDiff>,
    /// Tables published only in the first folder, with what published them.
    pub only_a: Vec<(PathBuf, Published)>,
    /// Tables published only in the second folder.
    pub only_b: Vec<(PathBuf, Published)>,
    /// Manifests that could not be read (file, why), in either folder.
    pub unreadable: Unreadable,
    /// Changes listed per table by [`fmt::Display`] (the counts are always complete).
    pub max_listed: usize,
}

/// Manifests that could not be read: (file, why).
pub type Unreadable = Vec<(PathBuf, String)>;

/// The Parquet tables an out folder's manifests publish: path relative to the folder →
/// what published it. Unreadable manifests are returned beside them.
pub fn published_tables(out: &Path) -> std::io::Result<(BTreeMap<PathBuf, Published>, Unreadable)> {
    let manifests = Manifest::read_all(out)?;
    let mut tables = BTreeMap::new();
    for m in &manifests.runs {
        for s in &m.stages {
            for path in s.published.values().filter(|p| p.extension().is_some_and(|e| e == "parquet")) {
                tables.insert(path.clone(), Published { run: m.run.clone(), stage: s.record.stage.clone() });
            }
        }
    }
    Ok((tables, manifests.unreadable))
}

/// Compares the published tables of out folders `a` and `b`; numbers whose relative
/// difference is at most `rel_tol` (of the larger magnitude) count as unchanged.
pub fn diff_out_dirs(a: &Path, b: &Path, rel_tol: f64) -> Result<OutDiff, StageError> {
    fn io(dir: &Path) -> impl FnOnce(std::io::Error) -> StageError + '_ {
        move |source| StageError::Io { path: dir.join("runs"), source }
    }
    let (tables_a, mut unreadable) = published_tables(a).map_err(io(a))?;
    let (tables_b, unreadable_b) = published_tables(b).map_err(io(b))?;
    unreadable.extend(unreadable_b);
    let mut diff = OutDiff { a: a.into(), b: b.into(), unreadable, max_listed: usize::MAX, ..OutDiff::default() };
    for (path, published) in &tables_b {
        if !tables_a.contains_key(path) {
            diff.only_b.push((path.clone(), published.clone()));
        }
    }
    for (path, published) in tables_a {
        let Some(in_b) = tables_b.get(&path) else {
            diff.only_a.push((path, published));
            continue;
        };
        let mut table = diff_tables(&a.join(&path), &b.join(&path), rel_tol)?;
        (table.table, table.run, table.stage) = (path, in_b.run.clone(), in_b.stage.clone());
        diff.tables.push(table);
    }
    Ok(diff)
}

/// Compares two versions of one table (module docs); the result's `table`, `run` and
/// `stage` are left empty.
pub fn diff_tables(a: &Path, b: &Path, rel_tol: f64) -> Result<TableDiff, StageError> {
    let (df_a, df_b) = (read_parquet(a)?, read_parquet(b)?);
    let names = |df: &DataFrame| -> Vec<String> { df.get_column_names().iter().map(|c| c.to_string()).collect() };
    let (names_a, names_b) = (names(&df_a), names(&df_b));
    let dtype = |df: &DataFrame, c: &str| df.column(c).map(|col| col.dtype().clone()).ok();
    let is_key = |t: &DataType| t.is_integer() || matches!(t, DataType::String | DataType::Boolean);
    let both: Vec<&String> = names_a.iter().filter(|c| names_b.contains(c)).collect();
    let keys: Vec<String> = both
        .iter()
        .filter(|c| dtype(&df_a, c).as_ref().is_some_and(is_key) && dtype(&df_b, c).as_ref().is_some_and(is_key))
        .map(|c| c.to_string())
        .collect();
    let floats: Vec<&String> = both
        .iter()
        .copied()
        .filter(|c| dtype(&df_a, c).is_some_and(|t| t.is_float()) && dtype(&df_b, c).is_some_and(|t| t.is_float()))
        .collect();
    let (rows_a, rows_b) = (row_keys(&df_a, &keys, a)?, row_keys(&df_b, &keys, b)?);
    let index_b: HashMap<&str, usize> = rows_b.iter().enumerate().map(|(i, k)| (k.as_str(), i)).collect();
    let set_a: BTreeSet<&str> = rows_a.iter().map(String::as_str).collect();
    let mut diff = TableDiff {
        keys: keys.clone(),
        rows_only_a: rows_a.iter().filter(|k| !index_b.contains_key(k.as_str())).cloned().collect(),
        rows_only_b: rows_b.iter().filter(|k| !set_a.contains(k.as_str())).cloned().collect(),
        columns_only_a: names_a.iter().filter(|c| !names_b.contains(c)).cloned().collect(),
        columns_only_b: names_b.iter().filter(|c| !names_a.contains(c)).cloned().collect(),
        ..TableDiff::default()
    };
    let values: Vec<(Vec<f64>, Vec<f64>)> = floats
        .iter()
        .map(|c| Ok((nan_for_null(opt_f64s(&df_a, c, a)?), nan_for_null(opt_f64s(&df_b, c, b)?))))
        .collect::<Result<_, StageError>>()?;
    for (i, key) in rows_a.iter().enumerate() {
        let Some(&j) = index_b.get(key.as_str()) else { continue };
        for (column, (va, vb)) in floats.iter().zip(&values) {
            diff.compared += 1;
            if !same(va[i], vb[j], rel_tol) {
                diff.changes.push(Change { key: key.clone(), column: column.to_string(), old: va[i], new: vb[j] });
            }
        }
    }
    Ok(diff)
}

fn nan_for_null(values: Vec<Option<f64>>) -> Vec<f64> {
    values.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect()
}

/// Equal within `rel_tol` of the larger magnitude; two NaNs are the same number.
fn same(a: f64, b: f64, rel_tol: f64) -> bool {
    a == b || (a.is_nan() && b.is_nan()) || (a - b).abs() <= rel_tol * a.abs().max(b.abs())
}

/// Each row's key: `column=value` over `keys`, `#n` added to the n-th repeat of a key,
/// `row n` without key columns.
fn row_keys(df: &DataFrame, keys: &[String], path: &Path) -> Result<Vec<String>, StageError> {
    let mut texts = vec![Vec::new(); df.height()];
    for key in keys {
        let dtype = df
            .column(key)
            .map(|c| c.dtype().clone())
            .map_err(|source| StageError::Table { path: path.to_path_buf(), source })?;
        let shown: Vec<String> = match dtype {
            DataType::String => opt_strs(df, key, path)?.into_iter().map(|v| v.unwrap_or("null".into())).collect(),
            DataType::Boolean => opt_bools(df, key, path)?.into_iter().map(shown).collect(),
            _ => opt_ints(df, key, path)?.into_iter().map(shown).collect(),
        };
        for (text, value) in texts.iter_mut().zip(shown) {
            text.push(format!("{key}={value}"));
        }
    }
    let mut seen: HashMap<String, usize> = HashMap::new();
    Ok(texts
        .into_iter()
        .enumerate()
        .map(|(row, parts)| {
            let key = if parts.is_empty() { format!("row {row}") } else { parts.join(" ") };
            let n = seen.entry(key.clone()).or_default();
            *n += 1;
            if *n > 1 {
                format!("{key} #{n}")
            } else {
                key
            }
        })
        .collect())
}

fn shown<T: fmt::Display>(value: Option<T>) -> String {
    value.map_or("null".into(), |v| v.to_string())
}

/// A relative change in percent, with two decimals, or in scientific notation when it
/// is below 0.01 %.
fn percent(relative: f64) -> String {
    let pct = 100.0 * relative;
    match pct {
        p if p.is_nan() => "n/a".into(),
        p if p.is_infinite() => "from 0".into(),
        p if p.abs() >= 0.01 => format!("{p:+.2} %"),
        p => format!("{p:+.1e} %"),
    }
}

impl fmt::Display for OutDiff {
    /// Per changed table: its path, the stage that writes it and how many of its
    /// numbers changed, then one line per changed number (key, column, old → new,
    /// relative change), rows and columns only on one side; tables only on one side;
    /// a summary line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (a, b) = (self.a.display(), self.b.display());
        for (file, why) in &self.unreadable {
            writeln!(f, "warning: left out, {}: {why}", file.display())?;
        }
        for t in self.tables.iter().filter(|t| t.changed()) {
            let (n, of) = (t.changes.len(), t.compared);
            writeln!(f, "{} (stage {} of run {}): {n} of {of} numbers changed", t.table.display(), t.stage, t.run)?;
            let key_width = t.changes.iter().take(self.max_listed).map(|c| c.key.len()).max().unwrap_or(0);
            let col_width = t.changes.iter().take(self.max_listed).map(|c| c.column.len()).max().unwrap_or(0);
            for c in t.changes.iter().take(self.max_listed) {
                let change = percent(c.relative());
                writeln!(f, "  {:key_width$}  {:col_width$}  {} → {}  ({change})", c.key, c.column, c.old, c.new)?;
            }
            if n > self.max_listed {
                writeln!(f, "  … and {} more", n - self.max_listed)?;
            }
            for (side, rows) in [(&a, &t.rows_only_a), (&b, &t.rows_only_b)] {
                if !rows.is_empty() {
                    let listed: Vec<&str> = rows.iter().take(self.max_listed).map(String::as_str).collect();
                    let more = if rows.len() > listed.len() { ", …" } else { "" };
                    writeln!(f, "  {} rows only in {side}: {}{more}", rows.len(), listed.join("; "))?;
                }
            }
            for (side, columns) in [(&a, &t.columns_only_a), (&b, &t.columns_only_b)] {
                if !columns.is_empty() {
                    writeln!(f, "  columns only in {side}: {}", columns.join(", "))?;
                }
            }
        }
        for (side, only) in [(&a, &self.only_a), (&b, &self.only_b)] {
            for (path, p) in only {
                writeln!(f, "only in {side}: {} (stage {} of run {})", path.display(), p.stage, p.run)?;
            }
        }
        let changed = self.tables.iter().filter(|t| t.changed()).count();
        let numbers: usize = self.tables.iter().map(|t| t.changes.len()).sum();
        writeln!(
            f,
            "{numbers} numbers changed; {changed} of {} tables in both differ ({} only in {a}, {} only in {b})",
            self.tables.len(),
            self.only_a.len(),
            self.only_b.len()
        )
    }
}

#[cfg(test)]
mod tests {
    use polars::prelude::{df, ParquetWriter};

    use super::*;

    fn write(path: &Path, df: &mut DataFrame) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        ParquetWriter::new(std::fs::File::create(path).unwrap()).finish(df).unwrap();
    }

    #[test]
    fn rows_are_matched_on_their_keys_and_each_changed_float_is_listed() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.parquet"), dir.path().join("b.parquet"));
        write(
            &a,
            &mut df!("printer" => ["taz5", "taz5", "taz6"], "line" => [1i32, 2, 1], "w_mm" => [0.5, 0.6, 0.7],
                     "gone" => [1.0, 2.0, 3.0])
            .unwrap(),
        );
        // Rows in another order, one row replaced, one value changed, one a NaN on both sides.
        write(
            &b,
            &mut df!("printer" => ["taz6", "taz5", "taz7"], "line" => [1i32, 1, 1], "w_mm" => [0.77, 0.5, 0.1],
                     "new" => ["x", "y", "z"])
            .unwrap(),
        );
        let d = diff_tables(&a, &b, 0.0).unwrap();
        assert_eq!(d.keys, ["printer", "line"]);
        assert_eq!(d.compared, 2, "two matched rows, one float column in both");
        assert_eq!(
            d.changes,
            [Change { key: "printer=taz6 line=1".into(), column: "w_mm".into(), old: 0.7, new: 0.77 }]
        );
        assert!((d.changes[0].relative() - 0.1).abs() < 1e-12);
        assert_eq!(
            (d.rows_only_a.as_slice(), d.rows_only_b.as_slice()),
            (&["printer=taz5 line=2".to_string()][..], &["printer=taz7 line=1".to_string()][..])
        );
        assert_eq!(
            (d.columns_only_a.as_slice(), d.columns_only_b.as_slice()),
            (&["gone".to_string()][..], &["new".to_string()][..])
        );
        // Within a relative tolerance of 20 % nothing changed.
        assert!(diff_tables(&a, &b, 0.2).unwrap().changes.is_empty());
    }

    #[test]
    fn repeated_keys_and_keyless_tables_match_by_order_and_nan_equals_nan() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.parquet"), dir.path().join("b.parquet"));
        write(&a, &mut df!("x" => [1.0, f64::NAN, 3.0]).unwrap());
        write(&b, &mut df!("x" => [1.0, f64::NAN, 0.0]).unwrap());
        let d = diff_tables(&a, &b, 0.0).unwrap();
        assert_eq!(d.changes, [Change { key: "row 2".into(), column: "x".into(), old: 3.0, new: 0.0 }]);
        write(&a, &mut df!("k" => ["s", "s"], "x" => [1.0, 2.0]).unwrap());
        write(&b, &mut df!("k" => ["s", "s"], "x" => [1.0, 2.5]).unwrap());
        let d = diff_tables(&a, &b, 0.0).unwrap();
        assert_eq!(d.changes, [Change { key: "k=s #2".into(), column: "x".into(), old: 2.0, new: 2.5 }]);
        assert_eq!(percent(0.25), "+25.00 %");
        assert_eq!(percent(-1e-7), "-1.0e-5 %");
        assert_eq!((percent(f64::INFINITY), percent(f64::NAN)), ("from 0".to_string(), "n/a".to_string()));
    }
}
