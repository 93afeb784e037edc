//! The stage cache: a stage is skipped when its key hash — of (kind, kind version,
//! tool version, the program's code fingerprint, parameters, seed, input content
//! hashes) — equals the one recorded
//! beside its outputs and those outputs are intact. Otherwise the decision says why
//! it runs, in the terms `--dry-run` prints.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use serde::Serialize;

use crate::hash::{dir_hash, sha256_hex};
use crate::manifest::StageRecord;
use crate::params::Params;
use crate::TOOL_VERSION;

/// File name of the stage record inside a stage folder (hidden: not an output).
pub const RECORD_FILE: &str = ".stage.json";

/// Why a stage runs, or that it does not.
#[derive(Debug, Clone, PartialEq)]
pub enum Decision {
    /// Outputs are up to date.
    Cached,
    /// It must run, for these reasons.
    Run(Vec<String>),
}

/// The inputs of a cache key.
#[derive(Debug, Serialize)]
pub struct CacheKey<'a> {
    /// Stage kind.
    pub kind: &'a str,
    /// Kind version.
    pub kind_version: u32,
    /// Tool version.
    pub tool_version: &'a str,
    /// The program's code fingerprint ([`crate::Registry::code_fingerprint`]).
    pub code: &'a str,
    /// Parameters.
    pub params: &'a Params,
    /// Stage seed.
    pub seed: u64,
    /// Input name → content hash.
    pub inputs: &'a BTreeMap<String, String>,
}

impl CacheKey<'_> {
    /// The key's hash.
    pub fn hash(&self) -> String {
        sha256_hex(serde_json::to_string(self).expect("serialisable").as_bytes())
    }
}

/// Reads the record in `stage_dir`, if there is a valid one.
pub fn read_record(stage_dir: &Path) -> Option<StageRecord> {
    let text = std::fs::read_to_string(stage_dir.join(RECORD_FILE)).ok()?;
    serde_json::from_str(&text).ok()
}

/// Compares the key with the previous record and checks the outputs are intact.
pub fn decide(key: &CacheKey, key_hash: &str, previous: Option<&StageRecord>, stage_dir: &Path) -> Decision {
    let Some(prev) = previous else {
        return Decision::Run(vec!["no previous run".into()]);
    };
    if prev.key_hash == key_hash {
        return match dir_hash(stage_dir) {
            Ok((h, _)) if h == prev.output_hash => Decision::Cached,
            _ => Decision::Run(vec!["outputs missing or modified since the last run".into()]),
        };
    }
    Decision::Run(differences(key, prev))
}

fn differences(key: &CacheKey, prev: &StageRecord) -> Vec<String> {
    let mut why = Vec::new();
    if prev.kind != key.kind || prev.kind_version != key.kind_version {
        why.push(format!("kind changed: {} v{} → {} v{}", prev.kind, prev.kind_version, key.kind, key.kind_version));
    }
    if prev.tool_version != key.tool_version {
        why.push(format!("tool version changed: {} → {}", prev.tool_version, TOOL_VERSION));
    }
    if prev.code_fingerprint != key.code {
        let old = if prev.code_fingerprint.is_empty() { "none recorded" } else { &prev.code_fingerprint };
        why.push(format!("the program's code changed (fingerprint {old} → {})", key.code));
    }
    why.extend(param_changes(&prev.params, key.params));
    if prev.seed != key.seed {
        why.push(format!("seed changed: {} → {}", prev.seed, key.seed));
    }
    for (name, hash) in key.inputs {
        match prev.input_hashes.get(name) {
            Some(old) if old == hash => {}
            Some(_) => why.push(format!("input `{name}` changed")),
            None => why.push(format!("new input `{name}`")),
        }
    }
    if why.is_empty() {
        why.push("cache key changed".into());
    }
    why
}

fn param_changes(old: &Params, new: &Params) -> Vec<String> {
    let old: BTreeMap<_, _> = old.iter().collect();
    new.iter()
        .filter_map(|(name, value)| match old.get(name) {
            Some(prev) if *prev == value => None,
            Some(prev) => Some(format!("param {name}: {prev} → {value}")),
            None => Some(format!("new param {name} = {value}")),
        })
        .collect()
}

impl fmt::Display for Decision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Cached => write!(f, "up to date"),
            Self::Run(why) => write!(f, "{}", why.join("; ")),
        }
    }
}
