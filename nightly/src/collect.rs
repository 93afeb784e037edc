//! What a finished run contributes to a night: its stages' costs (from the manifest)
//! and every compared number in its tables.
//!
//! A table is recognised by the declared columns it carries (the `tables` crate), not
//! its file name, so a new report section or power study is picked up without touching
//! this file:
//! - **comparison tables** ([`comparison`]: `section`, `item`, `our_value`): each row is
//!   a number, `section/item`, with the paper's value where the paper has one;
//! - **power tables** ([`power`]: `correct_rate`, `false_alarm_rate`): per row, the rate
//!   of naming the hidden effect, of naming a wrong one, and the interval's coverage,
//!   keyed by the row's text columns and its `strength`;
//! - **discrepancy verdicts** ([`causes`]: `verdict`, `named`, `mechanism`, `round`; the
//!   engine's `causes.parquet`, whose columns every domain names alike): per round, the
//!   cause named or why none was, as text.

use std::collections::BTreeMap;
use std::path::Path;

use pipeline::artifact::read_parquet;
use pipeline::columns::{bools, if_present, ints, opt_f64s, strs};
use pipeline::manifest::Manifest;
use pipeline::StageError;
use polars::prelude::{DataFrame, DataType};
use tables::discrepancy::fdm::causes;
use tables::discrepancy::power;
use tables::report::comparison;

use crate::{NumberRow, StageRow};

/// One row per stage of `manifest`.
pub fn stage_rows(manifest: &Manifest) -> Vec<StageRow> {
    manifest
        .stages
        .iter()
        .map(|s| StageRow {
            run: manifest.run.clone(),
            stage: s.record.stage.clone(),
            kind: s.record.kind.clone(),
            kind_version: i64::from(s.record.kind_version),
            status: s.status.clone(),
            wall_time_s: s.record.wall_time_s,
            cpu_time_s: s.record.cpu_time_s,
            peak_rss_bytes: s.record.peak_rss_bytes.and_then(|b| i64::try_from(b).ok()),
            rows: i64::try_from(s.record.rows).unwrap_or(i64::MAX),
        })
        .collect()
}

/// Every compared number in the tables of `manifest`'s stages under `out_dir`.
pub fn number_rows(out_dir: &Path, manifest: &Manifest) -> Result<Vec<NumberRow>, StageError> {
    let mut numbers = Vec::new();
    for stage in &manifest.stages {
        let stage_dir = out_dir.join("runs").join(&manifest.run).join(&stage.record.stage);
        for output in stage.record.outputs.iter().filter(|o| o.path.extension().is_some_and(|e| e == "parquet")) {
            let path = stage_dir.join(&output.path);
            let table = TableRef { run: &manifest.run, stage: &stage.record.stage, file: &output.path, path: &path };
            numbers.extend(table_numbers(&table)?);
        }
    }
    Ok(numbers)
}

/// Where a table sits.
struct TableRef<'a> {
    run: &'a str,
    stage: &'a str,
    file: &'a Path,
    path: &'a Path,
}

impl TableRef<'_> {
    fn number(
        &self,
        metric: String,
        paper_value: Option<f64>,
        value: Option<f64>,
        unit: &str,
        source: String,
    ) -> NumberRow {
        NumberRow {
            run: self.run.to_string(),
            stage: self.stage.to_string(),
            table: self.file.display().to_string(),
            metric,
            paper_value,
            value: value.filter(|v| v.is_finite()),
            text: None,
            unit: unit.to_string(),
            source,
        }
    }
}

fn table_numbers(table: &TableRef) -> Result<Vec<NumberRow>, StageError> {
    let df = read_parquet(table.path)?;
    let has = |names: &[&str]| names.iter().all(|n| df.column(n).is_ok());
    if has(&[comparison::section, comparison::item, comparison::our_value]) {
        comparison_numbers(&df, table)
    } else if has(&[power::correct_rate, power::false_alarm_rate]) {
        power_numbers(&df, table)
    } else if has(&[causes::verdict, causes::named, causes::mechanism, causes::round]) {
        verdicts(&df, table)
    } else {
        Ok(Vec::new())
    }
}

fn comparison_numbers(df: &DataFrame, table: &TableRef) -> Result<Vec<NumberRow>, StageError> {
    let path = table.path;
    let (section, item) = (strs(df, comparison::section, path)?, strs(df, comparison::item, path)?);
    let paper = if_present(df, comparison::paper_value, path, opt_f64s)?.unwrap_or_else(|| vec![None; df.height()]);
    let ours = opt_f64s(df, comparison::our_value, path)?;
    let text = |name: &str| -> Result<Vec<String>, StageError> {
        Ok(if_present(df, name, path, strs)?.unwrap_or_else(|| vec![String::new(); df.height()]))
    };
    let (unit, source) = (text(comparison::unit)?, text(comparison::source)?);
    Ok((0..df.height())
        .map(|i| table.number(format!("{}/{}", section[i], item[i]), paper[i], ours[i], &unit[i], source[i].clone()))
        .collect())
}

/// `correct_rate`, `false_alarm_rate` and (where present) `coverage_rate` of each row.
fn power_numbers(df: &DataFrame, table: &TableRef) -> Result<Vec<NumberRow>, StageError> {
    let keys = row_keys(df, table.path, &[])?;
    let draws = match df.column(power::draws) {
        Ok(_) => ints(df, power::draws, table.path)?.into_iter().map(Some).collect(),
        Err(_) => vec![None; df.height()],
    };
    let mut numbers = Vec::new();
    for rate in [power::correct_rate, power::false_alarm_rate, power::coverage_rate] {
        let Ok(_) = df.column(rate) else { continue };
        let values = opt_f64s(df, rate, table.path)?;
        for (i, key) in keys.iter().enumerate() {
            let source = match draws[i] {
                Some(n) => format!("{} ({n} draws)", table.file.display()),
                None => table.file.display().to_string(),
            };
            numbers.push(table.number(format!("{key}/{rate}"), None, values[i], "1", source));
        }
    }
    Ok(numbers)
}

/// Per (key, round): `named MECHANISM`, or the round's verdict when nothing was named.
fn verdicts(df: &DataFrame, table: &TableRef) -> Result<Vec<NumberRow>, StageError> {
    let path = table.path;
    let keys = row_keys(df, path, &[causes::base_model, causes::mechanism, causes::verdict, causes::failure])?;
    let (round, named, mechanism, verdict) = (
        ints(df, causes::round, path)?,
        bools(df, causes::named, path)?,
        strs(df, causes::mechanism, path)?,
        strs(df, causes::verdict, path)?,
    );
    let mut rounds: BTreeMap<(String, i64), String> = BTreeMap::new();
    for i in 0..df.height() {
        let slot = rounds.entry((keys[i].clone(), round[i])).or_insert_with(|| verdict[i].clone());
        if named[i] {
            *slot = format!("named {}", mechanism[i]);
        }
    }
    let source = format!("{} (verdict of the round)", table.file.display());
    Ok(rounds
        .into_iter()
        .map(|((key, r), text)| NumberRow {
            text: Some(text),
            ..table.number(format!("{key}/round={r}/verdict"), None, None, "", source.clone())
        })
        .collect())
}

/// Each row's identity: its text columns (but `except`) and its `strength`, joined by `/`.
fn row_keys(df: &DataFrame, path: &Path, except: &[&str]) -> Result<Vec<String>, StageError> {
    let mut parts: Vec<Vec<String>> = vec![Vec::new(); df.height()];
    for column in df.columns() {
        let name = column.name().as_str();
        if except.contains(&name) {
            continue;
        }
        if column.dtype() == &DataType::String {
            for (part, value) in parts.iter_mut().zip(strs(df, name, path)?) {
                part.push(value);
            }
        } else if name == power::strength {
            for (part, value) in parts.iter_mut().zip(opt_f64s(df, name, path)?) {
                part.push(format!("strength={}", value.map_or("null".into(), |v| v.to_string())));
            }
        }
    }
    Ok(parts.into_iter().map(|p| p.join("/")).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use pipeline::artifact::{write_parquet, TableMeta};
    use pipeline::manifest::{ManifestStage, OutputFile, StageRecord};
    use polars::prelude::{IntoColumn, NamedFrom, Series};

    fn write(dir: &Path, name: &str, columns: Vec<polars::prelude::Column>) -> OutputFile {
        let height = columns[0].len();
        let mut df = DataFrame::new(height, columns).unwrap();
        let meta = TableMeta { stage: "s".into(), stage_hash: "h".into(), params_hash: "p".into(), schema_version: 1 };
        write_parquet(&dir.join(name), &mut df, &meta).unwrap();
        OutputFile { path: name.into(), sha256: String::new() }
    }

    macro_rules! col {
        ($name:expr, $values:expr) => {
            Series::new($name.into(), $values).into_column()
        };
    }

    fn stage(name: &str, outputs: Vec<OutputFile>) -> ManifestStage {
        ManifestStage {
            record: StageRecord {
                stage: name.into(),
                kind: "k".into(),
                kind_version: 1,
                tool_version: "0".into(),
                code_fingerprint: String::new(),
                code_parts: Default::default(),
                key_hash: String::new(),
                params: Default::default(),
                seed: 0,
                input_hashes: Default::default(),
                output_hash: String::new(),
                outputs,
                rows: 4,
                wall_time_s: 1.5,
                cpu_time_s: Some(2.5),
                peak_rss_bytes: Some(1 << 20),
            },
            status: "run".into(),
            reason: String::new(),
            this_run_wall_time_s: 1.5,
            published: Default::default(),
        }
    }

    #[test]
    fn comparisons_power_rates_and_verdicts_are_found_by_their_columns() {
        let out = tempfile::tempdir().unwrap();
        let dir = out.path().join("runs/r/s");
        std::fs::create_dir_all(&dir).unwrap();
        let comparison = write(
            &dir,
            "comparison.parquet",
            vec![
                col!("section", ["table_ii", "fig9"]),
                col!("item", ["rmse", "gain"]),
                col!("paper_value", [Some(0.1), None]),
                col!("our_value", [0.12, f64::NAN]),
                col!("unit", ["mm", "%"]),
                col!("source", ["loo.parquet", "cv.parquet"]),
            ],
        );
        let power = write(
            &dir,
            "power.parquet",
            vec![
                col!("base", ["taz5", "taz5"]),
                col!("effect", ["none", "bed_tilt"]),
                col!("strength", [0.0, 0.05]),
                col!("draws", [200i64, 28]),
                col!("correct_rate", [0.0, 0.9]),
                col!("false_alarm_rate", [0.02, 0.0]),
            ],
        );
        let causes = write(
            &dir,
            "causes.parquet",
            vec![
                col!("printer", ["taz5", "taz5", "taz5", "taz6"]),
                col!("round", [1i64, 1, 2, 1]),
                col!("base_model", ["lag", "lag", "lag + width_cap", "lag"]),
                col!("mechanism", ["bed_tilt", "width_cap", "bed_tilt", "bed_tilt"]),
                col!("named", [false, true, false, false]),
                col!("verdict", ["named", "named", "none", "too_few_groups"]),
            ],
        );
        let other = write(&dir, "widths.parquet", vec![col!("width_mm", [0.5, 0.6])]);
        let manifest = Manifest {
            tool_version: "0".into(),
            run: "r".into(),
            title: String::new(),
            spec_file: "r.toml".into(),
            spec_sha256: String::new(),
            overrides: Vec::new(),
            finished_unix_s: 0,
            wall_time_s: 1.5,
            stages: vec![stage("s", vec![comparison, power, causes, other])],
        };
        let numbers = number_rows(out.path(), &manifest).unwrap();
        let shown: Vec<(String, Option<f64>, Option<String>)> =
            numbers.iter().map(|n| (n.metric.clone(), n.value, n.text.clone())).collect();
        let expected = [
            ("table_ii/rmse", Some(0.12), None),
            ("fig9/gain", None, None),
            ("taz5/none/strength=0/correct_rate", Some(0.0), None),
            ("taz5/bed_tilt/strength=0.05/correct_rate", Some(0.9), None),
            ("taz5/none/strength=0/false_alarm_rate", Some(0.02), None),
            ("taz5/bed_tilt/strength=0.05/false_alarm_rate", Some(0.0), None),
            ("taz5/round=1/verdict", None, Some("named width_cap")),
            ("taz5/round=2/verdict", None, Some("none")),
            ("taz6/round=1/verdict", None, Some("too_few_groups")),
        ];
        let expected: Vec<(String, Option<f64>, Option<String>)> =
            expected.iter().map(|(m, v, t)| (m.to_string(), *v, t.map(str::to_string))).collect();
        assert_eq!(shown, expected);
        assert_eq!(numbers[0].paper_value, Some(0.1));
        assert_eq!(numbers[2].source, "power.parquet (200 draws)");
        let stages = stage_rows(&manifest);
        assert_eq!((stages[0].cpu_time_s, stages[0].peak_rss_bytes, stages[0].rows), (Some(2.5), Some(1 << 20), 4));
    }
}
