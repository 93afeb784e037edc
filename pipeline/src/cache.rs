//! The stage cache: a stage is skipped when its key hash — of (kind, kind version,
//! tool version, the fingerprint of the code the kind runs, parameters, seed, input
//! content hashes) — equals the one recorded
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
    /// The fingerprint of the code the kind runs ([`crate::Registry::code`]).
    pub code: &'a str,
    /// The parts that fingerprint is taken over (not hashed again: the fingerprint
    /// holds them), for saying which changed.
    #[serde(skip)]
    pub code_parts: &'a BTreeMap<String, String>,
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
        why.push(code_change(prev, key));
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

/// Which code changed: the parts whose hashes differ, are new or are gone, when both
/// the record and the key name parts; the program's code otherwise.
fn code_change(prev: &StageRecord, key: &CacheKey) -> String {
    let old = if prev.code_fingerprint.is_empty() { "none recorded" } else { &prev.code_fingerprint };
    let fingerprints = format!("fingerprint {old} → {}", key.code);
    if prev.code_parts.is_empty() || key.code_parts.is_empty() {
        return format!("the program's code changed ({fingerprints})");
    }
    let names = prev.code_parts.keys().chain(key.code_parts.keys());
    let mut changed: Vec<&str> =
        names.filter(|n| prev.code_parts.get(*n) != key.code_parts.get(*n)).map(String::as_str).collect();
    changed.sort_unstable();
    changed.dedup();
    format!("code of {} changed ({fingerprints})", changed.join(", "))
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
