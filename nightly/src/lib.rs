//! The nightly benchmark (DESIGN §8): what every shipped spec computed and what it
//! cost, night after night, and what moved.
//!
//! A night runs every spec from scratch (the CLI's `amrepro nightly` does that through
//! `pipeline`) and becomes a [`Night`]: per spec whether it ran ([`RunRow`]), per stage
//! its wall time, CPU time, peak memory and rows ([`StageRow`], from the manifest), and
//! every compared number ([`NumberRow`], from the runs' tables: [`collect`]). The
//! nights accumulate in a Parquet history partitioned by date ([`history`]), never
//! rewritten; [`regress`] compares the latest night with the nights before it, and
//! [`page`] draws the trends and the regressions into `report/nightly.html`.

#![deny(missing_docs)]

pub mod collect;
pub mod history;
pub mod page;
pub mod regress;

/// When and where a night ran.
#[derive(Debug, Clone, PartialEq)]
pub struct NightInfo {
    /// Unique, sortable id: `20261202T220533Z-<commit prefix>`.
    pub night: String,
    /// UTC date the night started, `YYYY-MM-DD` (the history's partition).
    pub date: String,
    /// Unix time the night started, in seconds.
    pub started_unix_s: i64,
    /// Unix time the night finished, in seconds.
    pub finished_unix_s: i64,
    /// `git rev-parse HEAD` of the checkout, or `unknown`.
    pub commit: String,
    /// Host name, or `unknown`.
    pub host: String,
    /// Logical cores the night had.
    pub cores: i64,
    /// amrepro's version.
    pub tool_version: String,
}

impl NightInfo {
    /// A night starting at `started_unix_s` (UTC) on `commit`.
    pub fn new(started_unix_s: i64, commit: &str, host: &str, cores: i64) -> Self {
        let at = chrono::DateTime::from_timestamp(started_unix_s, 0).unwrap_or_default();
        let short: String = commit.chars().take(10).collect();
        Self {
            night: format!("{}-{short}", at.format("%Y%m%dT%H%M%SZ")),
            date: at.format("%Y-%m-%d").to_string(),
            started_unix_s,
            finished_unix_s: started_unix_s,
            commit: commit.to_string(),
            host: host.to_string(),
            cores,
            tool_version: pipeline::TOOL_VERSION.to_string(),
        }
    }
}

/// One spec's run in a night.
#[derive(Debug, Clone, PartialEq)]
pub struct RunRow {
    /// The run's name (the spec's `run`), or the spec file's stem when it did not plan.
    pub run: String,
    /// The spec file.
    pub spec_file: String,
    /// Whether the run completed.
    pub ok: bool,
    /// Why it failed (empty when it did not).
    pub error: String,
    /// Wall time of the whole run, in seconds.
    pub wall_time_s: f64,
}

/// One stage's execution in a night.
#[derive(Debug, Clone, PartialEq)]
pub struct StageRow {
    /// The run.
    pub run: String,
    /// The stage name.
    pub stage: String,
    /// Its kind.
    pub kind: String,
    /// The kind's version.
    pub kind_version: i64,
    /// `run` for a stage executed this night (a nightly forces every stage).
    pub status: String,
    /// Wall time, in seconds.
    pub wall_time_s: f64,
    /// CPU time (user + system, all threads), in seconds, where measured.
    pub cpu_time_s: Option<f64>,
    /// Peak resident memory, in bytes, where the system reports it.
    pub peak_rss_bytes: Option<i64>,
    /// Table rows the stage wrote.
    pub rows: i64,
}

/// One compared number (or verdict) a run produced.
#[derive(Debug, Clone, PartialEq)]
pub struct NumberRow {
    /// The run.
    pub run: String,
    /// The stage whose table holds it.
    pub stage: String,
    /// That table's file inside the stage folder.
    pub table: String,
    /// What it is, unique within (run, stage, table): `table_ii/Taz 5 RMSE` or
    /// `taz5/bed_tilt/strength=0.05/correct_rate`.
    pub metric: String,
    /// The paper's value, where the paper gives one.
    pub paper_value: Option<f64>,
    /// Ours (`None` for a verdict, or a number that was not finite).
    pub value: Option<f64>,
    /// A verdict's text (`named gear_eccentricity`), `None` for a number.
    pub text: Option<String>,
    /// Unit.
    pub unit: String,
    /// Where ours comes from.
    pub source: String,
}

impl NumberRow {
    /// The identity of the series this number belongs to across nights.
    pub fn series(&self) -> SeriesKey {
        SeriesKey {
            run: self.run.clone(),
            stage: self.stage.clone(),
            table: self.table.clone(),
            metric: self.metric.clone(),
        }
    }
}

/// (run, stage, table, metric): one compared number across nights.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SeriesKey {
    /// The run.
    pub run: String,
    /// The stage.
    pub stage: String,
    /// The table.
    pub table: String,
    /// The metric.
    pub metric: String,
}

/// Everything one night recorded.
#[derive(Debug, Clone, PartialEq)]
pub struct Night {
    /// When and where.
    pub info: NightInfo,
    /// One row per spec.
    pub runs: Vec<RunRow>,
    /// One row per stage of every run that completed.
    pub stages: Vec<StageRow>,
    /// Every compared number of every run that completed.
    pub numbers: Vec<NumberRow>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_night_is_named_by_its_utc_start_and_commit() {
        let info = NightInfo::new(1_796_162_733, "0f7d7e1abcdef0123", "ci", 2);
        assert_eq!(info.date, "2026-12-01");
        assert_eq!(info.night, "20261201T220533Z-0f7d7e1abc");
    }
}
