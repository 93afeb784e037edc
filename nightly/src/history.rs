//! The history: every night's tables, as Parquet partitioned by date.
//!
//! ```text
//! HISTORY/runs/date=2026-12-02/20261202T020000Z-0f7d7e1abc.parquet     one row per spec
//! HISTORY/stages/date=2026-12-02/20261202T020000Z-0f7d7e1abc.parquet   one row per stage
//! HISTORY/numbers/date=2026-12-02/20261202T020000Z-0f7d7e1abc.parquet  one row per compared number
//! HISTORY/nights/date=2026-12-02/20261202T020000Z-0f7d7e1abc.parquet   one row: the night (written last)
//! ```
//!
//! One file per table and night, so a night never rewrites an earlier one, and the
//! `date=` folders are Hive partitions: DuckDB and Polars prune by date without opening
//! the other files. Every table carries the `night` column to join on; the date comes
//! from the folder name.
//!
//! Appending is atomic per file (temp file, sync, rename) and the `nights` file is the
//! commit marker: a night is in the history when, and only when, its `nights` file is.
//! A nightly killed while appending leaves files of a night with no marker; readers
//! ignore them, and the next append (under the history's lock, so no other writer can be
//! mid-append) removes them and any temp files.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use pipeline::artifact::{read_parquet, write_parquet, TableMeta};
use pipeline::columns::{bools, ints, opt_f64s, opt_ints, opt_strs, strs};
use pipeline::error::RunError;
use pipeline::lock::{remove_stale_temps, OutLock};
use pipeline::StageError;
use polars::prelude::{Column, DataFrame, IntoColumn, NamedFrom, Series};

use crate::{Night, NightInfo, NumberRow, RunRow, StageRow};

/// The history's tables.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Table {
    /// One row per spec and night.
    Runs,
    /// One row per stage and night.
    Stages,
    /// One row per compared number and night.
    Numbers,
    /// One row per night: the commit marker, written last.
    Nights,
}

impl Table {
    /// Every table, in the order an append writes them (the marker last).
    pub const ALL: [Table; 4] = [Table::Runs, Table::Stages, Table::Numbers, Table::Nights];

    /// The table's declaration: its folder name and its columns.
    pub fn declaration(self) -> &'static pipeline::schema::Table {
        match self {
            Table::Runs => &runs::TABLE,
            Table::Stages => &stages::TABLE,
            Table::Numbers => &numbers::TABLE,
            Table::Nights => &nights::TABLE,
        }
    }

    /// The table's folder name.
    pub fn name(self) -> &'static str {
        self.declaration().name
    }
}

pipeline::table! {
    /// One row per spec and night.
    pub mod runs = "runs" {
        /// The night (`nights.night`).
        night: Str "",
        /// The spec's run name.
        run: Str "",
        /// The spec file, relative to the repository.
        spec_file: Str "",
        /// Whether the run succeeded.
        ok: Bool "",
        /// Its error (empty when ok).
        error: Str "",
        /// Wall time of the whole run.
        wall_time_s: Float64 "s",
    }
}

pipeline::table! {
    /// One row per stage and night.
    pub mod stages = "stages" {
        /// The night (`nights.night`).
        night: Str "",
        /// The spec's run name.
        run: Str "",
        /// The stage's name in its spec.
        stage: Str "",
        /// The stage kind.
        kind: Str "",
        /// The kind's version.
        kind_version: Int64 "1",
        /// `run` (a nightly forces every stage).
        status: Str "",
        /// Its wall time.
        wall_time_s: Float64 "s",
        /// Its CPU time, user + system over all threads (null where not measured).
        cpu_time_s: Float64 "s",
        /// Its peak resident memory (null where the system does not report it).
        peak_rss_bytes: Int64 "B",
        /// Rows it wrote.
        rows: Int64 "1",
    }
}

pipeline::table! {
    /// One row per compared number and night.
    pub mod numbers = "numbers" {
        /// The night (`nights.night`).
        night: Str "",
        /// The spec's run name.
        run: Str "",
        /// The stage that wrote it.
        stage: Str "",
        /// Its file in the stage folder.
        table: Str "",
        /// What it is: `section/item` of a comparison, `KEY/strength=S/correct_rate` of a power table, `KEY/round=R/verdict`.
        metric: Str "",
        /// The paper's value (null where the paper has none).
        paper_value: Float64 "",
        /// Our value (null for a verdict).
        value: Float64 "",
        /// The verdict: `named MECHANISM`, `none`, `too_few_groups` (null for a number).
        text: Str "",
        /// The value's unit.
        unit: Str "",
        /// Where it comes from.
        source: Str "",
    }
}

pipeline::table! {
    /// One row per night: the commit marker, written last.
    pub mod nights = "nights" {
        /// The night: its start (UTC) and commit, `YYYYMMDDTHHMMSSZ-COMMIT`.
        night: Str "",
        /// Its start, Unix time.
        started_unix_s: Int64 "s",
        /// Its end, Unix time.
        finished_unix_s: Int64 "s",
        /// The commit it ran.
        commit: Str "",
        /// The machine.
        host: Str "",
        /// Its cores.
        cores: Int64 "1",
        /// The amrepro version.
        tool_version: Str "",
    }
}

/// What can go wrong with a history.
#[derive(Debug, thiserror::Error)]
pub enum HistoryError {
    /// Another process is appending.
    #[error(transparent)]
    Locked(#[from] RunError),
    /// A file could not be read or written; names it.
    #[error(transparent)]
    File(#[from] StageError),
    /// The night is there already.
    #[error("{}: night {night} is already in the history (a history is appended to, never rewritten)", dir.display())]
    NightExists {
        /// The history folder.
        dir: PathBuf,
        /// The night.
        night: String,
    },
}

/// Every complete night of a history, oldest first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct History {
    /// The nights, sorted by start time.
    pub nights: Vec<Night>,
}

/// Appends `night` to the history in `dir` (created if absent), under the history's lock.
pub fn append(dir: &Path, night: &Night) -> Result<PathBuf, HistoryError> {
    let _lock = OutLock::acquire(dir, &format!("nightly append {}", night.info.night))?;
    remove_stale_temps(dir).map_err(|e| StageError::io(dir, e))?;
    let complete = complete_nights(dir)?;
    if complete.contains(&night.info.night) {
        return Err(HistoryError::NightExists { dir: dir.to_path_buf(), night: night.info.night.clone() });
    }
    remove_incomplete(dir, &complete)?;
    let meta = TableMeta {
        stage: "nightly".into(),
        stage_hash: night.info.night.clone(),
        params_hash: String::new(),
        schema_version: 1,
    };
    let mut marker = PathBuf::new();
    for table in Table::ALL {
        let path = partition_file(dir, table, &night.info);
        let mut frame = match table {
            Table::Runs => runs_frame(night),
            Table::Stages => stages_frame(night),
            Table::Numbers => numbers_frame(night),
            Table::Nights => nights_frame(&night.info),
        }
        .map_err(|source| StageError::Table { path: path.clone(), source })?;
        table.declaration().check_frame(&frame).map_err(StageError::Declaration)?;
        write_parquet(&path, &mut frame, &meta)?;
        marker = path;
    }
    Ok(marker)
}

/// Reads every complete night of the history in `dir` (an absent folder is an empty
/// history).
pub fn read(dir: &Path) -> Result<History, HistoryError> {
    let mut nights: BTreeMap<String, Night> = BTreeMap::new();
    for path in table_files(dir, Table::Nights)? {
        for info in read_nights(&path)? {
            let night = Night { info, runs: vec![], stages: vec![], numbers: vec![] };
            nights.insert(night.info.night.clone(), night);
        }
    }
    for table in [Table::Runs, Table::Stages, Table::Numbers] {
        for path in table_files(dir, table)? {
            let Some(night) = nights.get_mut(&night_of_file(&path)) else {
                continue;
            };
            let frame = read_parquet(&path)?;
            match table {
                Table::Runs => night.runs = read_runs(&frame, &path)?,
                Table::Stages => night.stages = read_stages(&frame, &path)?,
                Table::Numbers => night.numbers = read_numbers(&frame, &path)?,
                Table::Nights => unreachable!("read above"),
            }
        }
    }
    let mut nights: Vec<Night> = nights.into_values().collect();
    nights.sort_by(|a, b| (a.info.started_unix_s, &a.info.night).cmp(&(b.info.started_unix_s, &b.info.night)));
    Ok(History { nights })
}

/// `dir/table/date=D/NIGHT.parquet`.
pub fn partition_file(dir: &Path, table: Table, info: &NightInfo) -> PathBuf {
    dir.join(table.name()).join(format!("date={}", info.date)).join(format!("{}.parquet", info.night))
}

fn night_of_file(path: &Path) -> String {
    path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The `*.parquet` files of one table, in every date partition, sorted.
fn table_files(dir: &Path, table: Table) -> Result<Vec<PathBuf>, StageError> {
    let root = dir.join(table.name());
    let mut files = Vec::new();
    if !root.is_dir() {
        return Ok(files);
    }
    for partition in std::fs::read_dir(&root).map_err(|e| StageError::io(&root, e))? {
        let partition = partition.map_err(|e| StageError::io(&root, e))?.path();
        let is_partition = partition.file_name().is_some_and(|n| n.to_string_lossy().starts_with("date="));
        if !is_partition || !partition.is_dir() {
            continue;
        }
        for file in std::fs::read_dir(&partition).map_err(|e| StageError::io(&partition, e))? {
            let file = file.map_err(|e| StageError::io(&partition, e))?.path();
            let name = file.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            if name.ends_with(".parquet") && !name.starts_with('.') {
                files.push(file);
            }
        }
    }
    files.sort();
    Ok(files)
}

fn complete_nights(dir: &Path) -> Result<BTreeSet<String>, StageError> {
    Ok(table_files(dir, Table::Nights)?.iter().map(|p| night_of_file(p)).collect())
}

/// Removes the files of nights whose marker was never written (a killed append).
fn remove_incomplete(dir: &Path, complete: &BTreeSet<String>) -> Result<(), StageError> {
    for table in Table::ALL.into_iter().filter(|t| *t != Table::Nights) {
        for path in table_files(dir, table)? {
            if !complete.contains(&night_of_file(&path)) {
                std::fs::remove_file(&path).map_err(|e| StageError::io(&path, e))?;
            }
        }
    }
    Ok(())
}

// ---- columns: each table's columns are written and read here, once ----

fn text(name: &str, values: impl Iterator<Item = String>) -> Column {
    Series::new(name.into(), values.collect::<Vec<String>>()).into_column()
}

/// Every table's first column, the night to join on (the same name in each declaration;
/// a test checks it).
const NIGHT: &str = nights::night;

fn night_column(night: &Night, rows: usize) -> Column {
    text(NIGHT, std::iter::repeat_n(night.info.night.clone(), rows))
}

fn frame(columns: Vec<Column>) -> Result<DataFrame, polars::error::PolarsError> {
    let height = columns.first().map_or(0, |c| c.len());
    DataFrame::new(height, columns)
}

fn nights_frame(info: &NightInfo) -> Result<DataFrame, polars::error::PolarsError> {
    let one = |name: &str, v: &str| text(name, std::iter::once(v.to_string()));
    frame(vec![
        one(nights::night, &info.night),
        Series::new(nights::started_unix_s.into(), [info.started_unix_s]).into_column(),
        Series::new(nights::finished_unix_s.into(), [info.finished_unix_s]).into_column(),
        one(nights::commit, &info.commit),
        one(nights::host, &info.host),
        Series::new(nights::cores.into(), [info.cores]).into_column(),
        one(nights::tool_version, &info.tool_version),
    ])
}

fn read_nights(path: &Path) -> Result<Vec<NightInfo>, StageError> {
    let df = read_parquet(path)?;
    let (night, commit, host, tool) = (
        strs(&df, nights::night, path)?,
        strs(&df, nights::commit, path)?,
        strs(&df, nights::host, path)?,
        strs(&df, nights::tool_version, path)?,
    );
    let (started, finished, cores) = (
        ints(&df, nights::started_unix_s, path)?,
        ints(&df, nights::finished_unix_s, path)?,
        ints(&df, nights::cores, path)?,
    );
    let date = date_of_partition(path)?;
    Ok((0..df.height())
        .map(|i| NightInfo {
            night: night[i].clone(),
            date: date.clone(),
            started_unix_s: started[i],
            finished_unix_s: finished[i],
            commit: commit[i].clone(),
            host: host[i].clone(),
            cores: cores[i],
            tool_version: tool[i].clone(),
        })
        .collect())
}

fn date_of_partition(path: &Path) -> Result<String, StageError> {
    let folder = path.parent().and_then(|p| p.file_name()).map(|n| n.to_string_lossy().into_owned());
    folder.and_then(|f| f.strip_prefix("date=").map(str::to_string)).ok_or_else(|| StageError::BadInput {
        file: path.to_path_buf(),
        location: None,
        expected: "expected to sit in a `date=YYYY-MM-DD` folder".into(),
    })
}

fn runs_frame(night: &Night) -> Result<DataFrame, polars::error::PolarsError> {
    let rows = &night.runs;
    frame(vec![
        night_column(night, rows.len()),
        text(runs::run, rows.iter().map(|r| r.run.clone())),
        text(runs::spec_file, rows.iter().map(|r| r.spec_file.clone())),
        Series::new(runs::ok.into(), rows.iter().map(|r| r.ok).collect::<Vec<bool>>()).into_column(),
        text(runs::error, rows.iter().map(|r| r.error.clone())),
        Series::new(runs::wall_time_s.into(), rows.iter().map(|r| r.wall_time_s).collect::<Vec<f64>>()).into_column(),
    ])
}

fn read_runs(df: &DataFrame, path: &Path) -> Result<Vec<RunRow>, StageError> {
    let (run, spec, ok, error) = (
        strs(df, runs::run, path)?,
        strs(df, runs::spec_file, path)?,
        bools(df, runs::ok, path)?,
        strs(df, runs::error, path)?,
    );
    let wall = opt_f64s(df, runs::wall_time_s, path)?;
    Ok((0..df.height())
        .map(|i| RunRow {
            run: run[i].clone(),
            spec_file: spec[i].clone(),
            ok: ok[i],
            error: error[i].clone(),
            wall_time_s: wall[i].unwrap_or(f64::NAN),
        })
        .collect())
}

fn stages_frame(night: &Night) -> Result<DataFrame, polars::error::PolarsError> {
    let rows = &night.stages;
    let f64s = |name: &str, f: fn(&StageRow) -> Option<f64>| {
        Series::new(name.into(), rows.iter().map(f).collect::<Vec<Option<f64>>>()).into_column()
    };
    let i64s = |name: &str, f: fn(&StageRow) -> Option<i64>| {
        Series::new(name.into(), rows.iter().map(f).collect::<Vec<Option<i64>>>()).into_column()
    };
    frame(vec![
        night_column(night, rows.len()),
        text(stages::run, rows.iter().map(|r| r.run.clone())),
        text(stages::stage, rows.iter().map(|r| r.stage.clone())),
        text(stages::kind, rows.iter().map(|r| r.kind.clone())),
        i64s(stages::kind_version, |r| Some(r.kind_version)),
        text(stages::status, rows.iter().map(|r| r.status.clone())),
        f64s(stages::wall_time_s, |r| Some(r.wall_time_s)),
        f64s(stages::cpu_time_s, |r| r.cpu_time_s),
        i64s(stages::peak_rss_bytes, |r| r.peak_rss_bytes),
        i64s(stages::rows, |r| Some(r.rows)),
    ])
}

fn read_stages(df: &DataFrame, path: &Path) -> Result<Vec<StageRow>, StageError> {
    let (run, stage, kind, status) = (
        strs(df, stages::run, path)?,
        strs(df, stages::stage, path)?,
        strs(df, stages::kind, path)?,
        strs(df, stages::status, path)?,
    );
    let (version, rows) = (ints(df, stages::kind_version, path)?, ints(df, stages::rows, path)?);
    let (wall, cpu, peak) = (
        opt_f64s(df, stages::wall_time_s, path)?,
        opt_f64s(df, stages::cpu_time_s, path)?,
        opt_ints(df, stages::peak_rss_bytes, path)?,
    );
    Ok((0..df.height())
        .map(|i| StageRow {
            run: run[i].clone(),
            stage: stage[i].clone(),
            kind: kind[i].clone(),
            kind_version: version[i],
            status: status[i].clone(),
            wall_time_s: wall[i].unwrap_or(f64::NAN),
            cpu_time_s: cpu[i],
            peak_rss_bytes: peak[i],
            rows: rows[i],
        })
        .collect())
}

fn numbers_frame(night: &Night) -> Result<DataFrame, polars::error::PolarsError> {
    let rows = &night.numbers;
    let f64s = |name: &str, f: fn(&NumberRow) -> Option<f64>| {
        Series::new(name.into(), rows.iter().map(f).collect::<Vec<Option<f64>>>()).into_column()
    };
    frame(vec![
        night_column(night, rows.len()),
        text(numbers::run, rows.iter().map(|r| r.run.clone())),
        text(numbers::stage, rows.iter().map(|r| r.stage.clone())),
        text(numbers::table, rows.iter().map(|r| r.table.clone())),
        text(numbers::metric, rows.iter().map(|r| r.metric.clone())),
        f64s(numbers::paper_value, |r| r.paper_value),
        f64s(numbers::value, |r| r.value),
        Series::new(numbers::text.into(), rows.iter().map(|r| r.text.clone()).collect::<Vec<Option<String>>>())
            .into_column(),
        text(numbers::unit, rows.iter().map(|r| r.unit.clone())),
        text(numbers::source, rows.iter().map(|r| r.source.clone())),
    ])
}

fn read_numbers(df: &DataFrame, path: &Path) -> Result<Vec<NumberRow>, StageError> {
    let (run, stage, table, metric) = (
        strs(df, numbers::run, path)?,
        strs(df, numbers::stage, path)?,
        strs(df, numbers::table, path)?,
        strs(df, numbers::metric, path)?,
    );
    let (paper, value, verdict) = (
        opt_f64s(df, numbers::paper_value, path)?,
        opt_f64s(df, numbers::value, path)?,
        opt_strs(df, numbers::text, path)?,
    );
    let (unit, source) = (strs(df, numbers::unit, path)?, strs(df, numbers::source, path)?);
    Ok((0..df.height())
        .map(|i| NumberRow {
            run: run[i].clone(),
            stage: stage[i].clone(),
            table: table[i].clone(),
            metric: metric[i].clone(),
            paper_value: paper[i],
            value: value[i],
            text: verdict[i].clone(),
            unit: unit[i].clone(),
            source: source[i].clone(),
        })
        .collect())
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A night at `day` (days after 2026-12-01, 02:00 UTC) with one run, one stage and
    /// two numbers.
    pub(crate) fn night(day: i64, value: f64, wall_s: f64) -> Night {
        let info = NightInfo::new(1_796_090_400 + day * 86_400, "0123456789abcdef", "ci", 2);
        let number = |metric: &str, paper: Option<f64>, value: Option<f64>, text: Option<&str>| NumberRow {
            run: "ren2021".into(),
            stage: "comparison".into(),
            table: "comparison.parquet".into(),
            metric: metric.into(),
            paper_value: paper,
            value,
            text: text.map(str::to_string),
            unit: "mm".into(),
            source: "loo.parquet".into(),
        };
        Night {
            info,
            runs: vec![RunRow {
                run: "ren2021".into(),
                spec_file: "specs/ren2021.toml".into(),
                ok: true,
                error: String::new(),
                wall_time_s: wall_s + 1.0,
            }],
            stages: vec![StageRow {
                run: "ren2021".into(),
                stage: "loo".into(),
                kind: "fdm.loo".into(),
                kind_version: 3,
                status: "run".into(),
                wall_time_s: wall_s,
                cpu_time_s: Some(2.0 * wall_s),
                peak_rss_bytes: None,
                rows: 36,
            }],
            numbers: vec![
                number("table_ii/rmse", Some(0.1), Some(value), None),
                number("taz5/round=1", None, None, Some("named width_cap")),
            ],
        }
    }

    #[test]
    fn every_table_starts_with_the_night_and_the_guide_lists_its_columns() {
        let guide = include_str!("../../docs/NIGHTLY.md");
        for table in Table::ALL {
            let declared = table.declaration();
            assert_eq!(declared.columns[0].name, NIGHT, "{}", declared.name);
            let row = guide
                .lines()
                .find(|l| l.starts_with(&format!("| `{}` |", declared.name)))
                .unwrap_or_else(|| panic!("docs/NIGHTLY.md has no row for `{}`", declared.name));
            for column in declared.columns {
                assert!(
                    row.contains(&format!("`{}`", column.name)),
                    "docs/NIGHTLY.md: `{}` lacks `{}`",
                    declared.name,
                    column.name
                );
            }
        }
    }

    #[test]
    fn nights_are_appended_and_read_back_whole() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (night(0, 0.12, 3.0), night(1, 0.13, 3.1));
        append(dir.path(), &a).unwrap();
        let first = std::fs::read(partition_file(dir.path(), Table::Numbers, &a.info)).unwrap();
        append(dir.path(), &b).unwrap();
        assert_eq!(std::fs::read(partition_file(dir.path(), Table::Numbers, &a.info)).unwrap(), first, "not rewritten");
        assert_eq!(read(dir.path()).unwrap().nights, vec![a.clone(), b]);
        let again = append(dir.path(), &a).unwrap_err();
        assert!(matches!(again, HistoryError::NightExists { .. }), "{again}");
    }

    #[test]
    fn a_night_without_its_marker_is_ignored_then_swept() {
        let dir = tempfile::tempdir().unwrap();
        let done = night(0, 0.12, 3.0);
        append(dir.path(), &done).unwrap();
        let killed = night(1, 0.5, 9.0);
        append(dir.path(), &killed).unwrap();
        std::fs::remove_file(partition_file(dir.path(), Table::Nights, &killed.info)).unwrap();
        let half = partition_file(dir.path(), Table::Stages, &killed.info).with_file_name(".x.parquet.tmp-4242");
        std::fs::write(&half, b"PAR1 half").unwrap();
        assert_eq!(read(dir.path()).unwrap().nights, vec![done.clone()], "the killed night is not read");
        append(dir.path(), &night(2, 0.12, 3.0)).unwrap();
        assert!(!partition_file(dir.path(), Table::Numbers, &killed.info).exists() && !half.exists());
        assert_eq!(read(dir.path()).unwrap().nights.len(), 2);
    }
}
