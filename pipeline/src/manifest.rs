//! The run manifest (`manifest.json`, written last) and the per-stage record
//! (`.stage.json`, inside each stage folder) from which the cache decides.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::params::Params;

/// One output file of a stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputFile {
    /// Path relative to the stage folder.
    pub path: PathBuf,
    /// Hex SHA-256 of its contents.
    pub sha256: String,
}

/// Everything the engine knows about one stage's last successful execution.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageRecord {
    /// Stage name in the spec.
    pub stage: String,
    /// Stage kind.
    pub kind: String,
    /// Kind version.
    pub kind_version: u32,
    /// Tool version that produced the outputs.
    pub tool_version: String,
    /// Code fingerprint of the program that produced them (empty in records written
    /// before the cache held it, and by programs without one).
    #[serde(default)]
    pub code_fingerprint: String,
    /// The parts the code fingerprint is taken over, by name, with their hashes
    /// ([`crate::stage::Code`]): what says which code changed (empty in records written
    /// before the cache held them, and by programs naming none).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub code_parts: BTreeMap<String, String>,
    /// Cache key: hash of (kind, version, tool version, code fingerprint, params, seed,
    /// inputs).
    pub key_hash: String,
    /// The parameters it ran with.
    pub params: Params,
    /// The stage seed.
    pub seed: u64,
    /// Input name → content hash.
    pub input_hashes: BTreeMap<String, String>,
    /// Hash over all output files (what downstream stages key on).
    pub output_hash: String,
    /// Output files.
    pub outputs: Vec<OutputFile>,
    /// Table rows written.
    pub rows: u64,
    /// Wall time of the execution that produced the outputs, in seconds.
    pub wall_time_s: f64,
    /// CPU time (user + system, all threads) of that execution, in seconds; recorded
    /// only when the run measured it ([`crate::RunOptions::measure_usage`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_time_s: Option<f64>,
    /// Peak resident memory of that execution, in bytes; recorded as `cpu_time_s` is,
    /// and only where the system reports it ([`crate::usage`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_rss_bytes: Option<u64>,
}

/// A stage's entry in the run manifest.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ManifestStage {
    /// The record of the outputs in place.
    #[serde(flatten)]
    pub record: StageRecord,
    /// `run` or `cached` in this invocation.
    pub status: String,
    /// Why it ran (empty when cached).
    pub reason: String,
    /// Wall time in this invocation (near zero when cached).
    pub this_run_wall_time_s: f64,
    /// Published copies: output file → path relative to the out folder.
    pub published: BTreeMap<String, PathBuf>,
}

/// The manifest of one run of one spec.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Manifest {
    /// Tool version.
    pub tool_version: String,
    /// Run name.
    pub run: String,
    /// Run title.
    pub title: String,
    /// The spec file, as given.
    pub spec_file: PathBuf,
    /// Hash of the spec file's text.
    pub spec_sha256: String,
    /// Parameters set on the command line in place of the spec's (`amrepro run --set
    /// STAGE.PARAM=VALUE`); empty when the spec's own values ran.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub overrides: Vec<String>,
    /// Unix time at which the run finished.
    pub finished_unix_s: u64,
    /// Total wall time of this invocation, in seconds.
    pub wall_time_s: f64,
    /// Stages in plan order.
    pub stages: Vec<ManifestStage>,
}

/// The manifests under an out folder: those that could be read, and those that
/// could not (a corrupt file must not stop the report of every other run).
#[derive(Debug, Default)]
pub struct Manifests {
    /// Readable manifests, sorted by run name.
    pub runs: Vec<Manifest>,
    /// `(file, why)` of each manifest that could not be read.
    pub unreadable: Vec<(PathBuf, String)>,
}

impl Manifest {
    /// Reads a manifest file; the error names the file and, for bad JSON, the line
    /// and column.
    pub fn read(path: &Path) -> std::io::Result<Self> {
        let named = |what: String| std::io::Error::other(format!("{}: {what}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| named(e.to_string()))?;
        serde_json::from_str(&text).map_err(|e| named(format!("not a readable run manifest ({e})")))
    }

    /// Every `runs/*/manifest.json` under the out folder, sorted by run name, and
    /// those that could not be read.
    pub fn read_all(out_dir: &Path) -> std::io::Result<Manifests> {
        let runs = out_dir.join("runs");
        let mut found = Manifests::default();
        if !runs.exists() {
            return Ok(found);
        }
        for entry in std::fs::read_dir(&runs)? {
            let path = entry?.path().join("manifest.json");
            if !path.exists() {
                continue;
            }
            match Self::read(&path) {
                Ok(manifest) => found.runs.push(manifest),
                Err(e) => found.unreadable.push((path, e.to_string())),
            }
        }
        found.runs.sort_by(|a, b| a.run.cmp(&b.run));
        found.unreadable.sort();
        Ok(found)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_corrupt_manifest_is_named_and_set_aside() {
        let dir = tempfile::tempdir().unwrap();
        let bad = dir.path().join("runs/broken/manifest.json");
        std::fs::create_dir_all(bad.parent().unwrap()).unwrap();
        std::fs::write(&bad, "{\n  \"tool_version\": ").unwrap();
        let found = Manifest::read_all(dir.path()).unwrap();
        assert!(found.runs.is_empty());
        let (path, why) = &found.unreadable[0];
        assert_eq!(path, &bad);
        assert!(why.contains(&bad.display().to_string()) && why.contains("line 2"), "{why}");
    }
}
