//! The declarative spec as written: TOML parsed into serde structs, with no checking
//! beyond the syntax and the set of known fields. [`crate::plan`] checks the rest.
//!
//! ```toml
//! [run]
//! name = "fsu_linewidth"
//! seed = 1
//!
//! [dataset.fsu_raw]
//! path = "${AMREPRO_DATA:-../data}/fsu-linewidth"
//!
//! [stage.import_taz5]
//! kind = "fdm.import"
//! inputs = ["fsu_raw"]
//! params = { printer = "taz5" }
//! publish = { "widths.parquet" = "fdm/widths_taz5.parquet" }
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::SpecError;

/// A whole spec file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawSpec {
    /// Run-wide settings.
    pub run: RawRun,
    /// External datasets by name.
    #[serde(default)]
    pub dataset: BTreeMap<String, RawDataset>,
    /// Stages by name.
    #[serde(default)]
    pub stage: BTreeMap<String, RawStage>,
}

/// The `[run]` table.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawRun {
    /// Run name: the folder under `out/runs/`.
    pub name: String,
    /// Seed from which every stage's random stream is derived.
    #[serde(default)]
    pub seed: u64,
    /// What the run reproduces, shown in the report.
    #[serde(default)]
    pub title: String,
}

/// A `[dataset.NAME]` table: a folder in the dataset format (or raw data an import
/// stage converts).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawDataset {
    /// Folder path; `${VAR}` and `${VAR:-default}` are expanded, and a relative path
    /// is taken relative to the spec file's folder.
    pub path: String,
    /// Where to get the data when the folder is missing.
    #[serde(default)]
    pub source: String,
}

/// A `[stage.NAME]` table.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawStage {
    /// Registered stage kind.
    pub kind: String,
    /// Names of datasets or other stages, in order.
    #[serde(default)]
    pub inputs: Vec<String>,
    /// Parameters, checked against the kind's declarations.
    #[serde(default)]
    pub params: BTreeMap<String, toml::Value>,
    /// Output file (relative to the stage folder) → stable path under the out folder.
    #[serde(default)]
    pub publish: BTreeMap<String, String>,
}

/// Reads and parses a spec file; syntax errors and unknown fields name the line.
pub fn read_spec(file: &Path) -> Result<RawSpec, SpecError> {
    let text =
        std::fs::read_to_string(file).map_err(|e| SpecError::new(file, "file", format!("cannot read spec: {e}")))?;
    parse_spec(file, &text)
}

/// Parses spec text (`file` only names it in errors).
pub fn parse_spec(file: &Path, text: &str) -> Result<RawSpec, SpecError> {
    toml::from_str(text).map_err(|e| {
        let location = e
            .span()
            .map(|span| line_col(text, span.start))
            .map(|(line, col)| format!("line {line}, column {col}"))
            .unwrap_or_else(|| "spec".into());
        SpecError::new(file, location, e.message().trim().to_string())
    })
}

/// One `--set STAGE.PARAM=VALUE` of `amrepro run`: a parameter value given on the
/// command line in place of the spec's (as `dvc exp run -S`), checked by the planner as
/// the spec's own values are.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// The stage's name in the spec.
    pub stage: String,
    /// The parameter's name.
    pub param: String,
    /// The value: the text read as a TOML value (a number, a boolean, a quoted string,
    /// an array), or as a string when it is none (`--set s.method=paper`).
    pub value: toml::Value,
}

impl Override {
    /// Parses `STAGE.PARAM=VALUE`; the error says what is missing.
    pub fn parse(text: &str) -> Result<Self, String> {
        let expected = || format!("`{text}`: expected STAGE.PARAM=VALUE");
        let (target, value) = text.split_once('=').ok_or_else(expected)?;
        let (stage, param) = target.trim().split_once('.').ok_or_else(expected)?;
        if stage.is_empty() || param.is_empty() {
            return Err(expected());
        }
        let value = value.trim();
        let parsed = toml::from_str::<toml::Table>(&format!("v = {value}")).ok().and_then(|mut t| t.remove("v"));
        let value = parsed.unwrap_or_else(|| toml::Value::String(value.to_string()));
        Ok(Self { stage: stage.to_string(), param: param.to_string(), value })
    }

    /// Where the planner puts an error about its value: `stage.NAME.params.PARAM`.
    pub fn location(&self) -> String {
        format!("stage.{}.params.{}", self.stage, self.param)
    }
}

impl std::fmt::Display for Override {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{}={}", self.stage, self.param, self.value)
    }
}

/// Sets each override's parameter in `spec`, later ones winning; a stage the spec
/// does not have is an error naming it and the stages it has (the parameter and its
/// value are the planner's to check).
pub fn apply_overrides(spec: &mut RawSpec, overrides: &[Override]) -> Result<(), (String, String)> {
    for o in overrides {
        let known: Vec<&str> = spec.stage.keys().map(String::as_str).collect();
        let known = known.join(", ");
        let Some(stage) = spec.stage.get_mut(&o.stage) else {
            return Err((format!("--set {o}"), format!("no stage `{}` in the spec; its stages: {known}", o.stage)));
        };
        stage.params.insert(o.param.clone(), o.value.clone());
    }
    Ok(())
}

/// 1-based line and column of byte `offset` in `text`.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rfind('\n').map_or(before.len(), |nl| before.len() - nl - 1) + 1;
    (line, col)
}

/// Expands `${VAR}` and `${VAR:-default}` with `lookup`, then resolves a relative path
/// against `base`. An unset variable without default is an error message.
pub fn expand_path(raw: &str, base: &Path, lookup: impl Fn(&str) -> Option<String>) -> Result<PathBuf, String> {
    let mut out = String::new();
    let mut rest = raw;
    while let Some(start) = rest.find("${") {
        out.push_str(&rest[..start]);
        let end = rest[start..].find('}').ok_or("unclosed `${` in path")? + start;
        let expr = &rest[start + 2..end];
        let (var, default) = match expr.split_once(":-") {
            Some((v, d)) => (v, Some(d)),
            None => (expr, None),
        };
        let value = lookup(var)
            .filter(|v| !v.is_empty())
            .or_else(|| default.map(str::to_string))
            .ok_or_else(|| format!("environment variable {var} is not set and has no default"))?;
        out.push_str(&value);
        rest = &rest[end + 1..];
    }
    out.push_str(rest);
    let path = PathBuf::from(out);
    Ok(if path.is_absolute() { path } else { base.join(path) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn syntax_error_names_line_and_column() {
        let err = parse_spec(Path::new("s.toml"), "[run]\nname = \"x\"\n[stage.a]\nkind = \n").unwrap_err();
        assert!(err.location.starts_with("line 4"), "{err}");
    }

    #[test]
    fn unknown_field_names_its_line() {
        let err = parse_spec(Path::new("s.toml"), "[run]\nname = \"x\"\n[stage.a]\nknd = \"k\"\n").unwrap_err();
        assert!(err.location.starts_with("line 4"), "{err}");
        assert!(err.message.contains("knd"), "{err}");
    }

    #[test]
    fn expands_variables_with_defaults() {
        let env = |v: &str| (v == "SET").then(|| "/data".to_string());
        let base = Path::new("/specs");
        assert_eq!(expand_path("${SET}/x", base, env).unwrap(), PathBuf::from("/data/x"));
        assert_eq!(expand_path("${UNSET:-../d}/x", base, env).unwrap(), PathBuf::from("/specs/../d/x"));
        assert!(expand_path("${UNSET}/x", base, env).is_err());
    }
}
