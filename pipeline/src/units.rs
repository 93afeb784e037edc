//! Runs beyond one machine (DESIGN §8): a plan as a list of independent work units
//! that any number of workers run into one shared out folder, in any order and any
//! number of times, and a collect step that checks they are all there and finishes
//! the run as if it had run in one process, byte for byte.
//!
//! **Units.** A stage whose kind splits ([`Split`]) is one unit per piece of its work
//! (power-study draws, transfer subsets, re-prints); every other stage is one unit,
//! except the *tail*: stages that read a split stage's output, directly or not, and
//! feed no split stage. `collect` runs those (figures, sections: cheap), after the
//! merges. Indices are stable for a spec: stages in plan order, then units in the
//! order the kind lists them.
//!
//! **Shared folder.** Unit `u` of stage `s` lives in `OUT/units/<run>/<s>/<u:05>/`:
//! the stage folder itself (outputs and record) for a stage that is one unit, the
//! unit's part and a `.unit.json` for a split stage, whose merge goes to
//! `OUT/units/<run>/<s>/merged/`. A folder is written under a temp name unique to its
//! writer and renamed into place, so a reader sees a whole unit or none; if two
//! workers finish the same unit, the second finds the first's folder valid and
//! discards its own (they are identical: the same key gives the same bytes). A
//! folder counts only when its record's cache key is the one the spec and the
//! current inputs give and its files hash to what the record says; anything else is
//! rerun. A killed worker leaves only a temp folder, removed by the next `collect`
//! (under the out folder's lock: run `collect` after the workers, not beside them).
//!
//! **Collect.** Under the out folder's lock: every non-tail stage's output is resolved
//! (merging split stages whose merge is not there yet), any missing unit is named and
//! nothing is changed; otherwise the outputs become the run's pending stage folders
//! and the ordinary executor takes over ([`crate::execute`]): it finds them finished
//! ("resumed"), runs the tail and commits the run, manifest last.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::artifact::{replace_dir, staging_dir};
use crate::cache::{decide, read_record, CacheKey, Decision};
use crate::commit::PENDING_DIR;
use crate::error::{RunError, StageError};
use crate::execute::{
    caught, hash_datasets, io_error, run_plan_locked, select, stage_failed, stage_seed, RunOptions, RunSummary,
    StageJob,
};
use crate::hash::dir_hash;
use crate::lock::OutLock;
use crate::manifest::StageRecord;
use crate::plan::{InputRef, Plan};
use crate::stage::{InputArtifact, Registry, Split, StageContext};
use crate::TOOL_VERSION;

/// The folder of the shared out folder that holds the units.
pub const UNITS_DIR: &str = "units";
/// The record of a split stage's unit, in its folder.
const UNIT_FILE: &str = ".unit.json";
/// The folder of a split stage's merged outputs, beside its units.
const MERGED_DIR: &str = "merged";

/// One work unit of a plan, as `amrepro plan` lists it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorkUnit {
    /// Stable index in the plan's unit list.
    pub index: usize,
    /// The stage it belongs to.
    pub stage: String,
    /// The stage's kind.
    pub kind: String,
    /// Which part of the stage's work (`whole stage` for a stage that is one unit).
    pub unit: String,
    /// Its position among the stage's units, and how many the stage has.
    pub part: (usize, usize),
    /// The units it reads (by index); it can run once they have.
    pub needs: Vec<usize>,
    /// Its depth: 0 for a unit that needs none, else one more than the deepest it needs.
    pub level: usize,
    /// Datasets it reads, by name.
    pub datasets: Vec<String>,
    /// Estimated cost, relative: 1 is a light stage run once.
    pub cost: f64,
    /// The file whose presence says the unit is done (relative to the out folder).
    pub done_file: PathBuf,
}

/// A plan's work units and the stages `collect` runs itself.
#[derive(Debug, Clone)]
pub struct UnitPlan {
    /// Every unit, by index.
    pub units: Vec<WorkUnit>,
    /// Per stage, the range of its units' indices (empty for a tail stage).
    pub stage_units: Vec<std::ops::Range<usize>>,
    /// Per stage, whether `collect` runs it (it reads a split stage, feeds none).
    pub tail: Vec<bool>,
}

impl UnitPlan {
    /// The units of `plan`.
    pub fn new(plan: &Plan, registry: &Registry) -> Self {
        let splits: Vec<Option<&dyn Split>> = plan.stages.iter().map(|s| split_of(registry, s.kind)).collect();
        let tail = tail_stages(plan, &splits);
        let mut units: Vec<WorkUnit> = Vec::new();
        let mut stage_units: Vec<std::ops::Range<usize>> = Vec::with_capacity(plan.stages.len());
        for (s, stage) in plan.stages.iter().enumerate() {
            let start = units.len();
            if !tail[s] {
                let needs: Vec<usize> = upstream_stages(plan, s).flat_map(|j| stage_units[j].clone()).collect();
                let datasets: Vec<String> = stage
                    .inputs
                    .iter()
                    .filter(|&i| matches!(i, InputRef::Dataset(_)))
                    .map(|i| plan.input_name(*i).to_string())
                    .collect();
                let parts = match splits[s] {
                    Some(split) => split.units(&stage.params, stage.inputs.len()),
                    None => vec![crate::stage::Unit { key: "whole stage".into(), cost: 1.0 }],
                };
                let count = parts.len();
                let level = needs.iter().map(|&n| units[n].level + 1).max().unwrap_or(0);
                for (u, part) in parts.into_iter().enumerate() {
                    let done = unit_dir(Path::new(""), plan, s, u).join(match splits[s] {
                        Some(_) => UNIT_FILE,
                        None => crate::cache::RECORD_FILE,
                    });
                    units.push(WorkUnit {
                        index: units.len(),
                        stage: stage.name.clone(),
                        kind: stage.kind.to_string(),
                        unit: part.key,
                        part: (u, count),
                        needs: needs.clone(),
                        level,
                        datasets: datasets.clone(),
                        cost: part.cost,
                        done_file: done,
                    });
                }
            }
            stage_units.push(start..units.len());
        }
        Self { units, stage_units, tail }
    }
}

fn split_of<'r>(registry: &'r Registry, kind: &str) -> Option<&'r dyn Split> {
    registry.get(kind).and_then(|k| k.split())
}

/// The stages `s` reads.
fn upstream_stages(plan: &Plan, s: usize) -> impl Iterator<Item = usize> + '_ {
    plan.stages[s].inputs.iter().filter_map(|i| match i {
        InputRef::Stage(j) => Some(*j),
        InputRef::Dataset(_) => None,
    })
}

/// Stages that read a split stage (directly or not), are not split and feed no split
/// stage.
fn tail_stages(plan: &Plan, splits: &[Option<&dyn Split>]) -> Vec<bool> {
    let n = plan.stages.len();
    let mut after_split = vec![false; n];
    for s in 0..n {
        after_split[s] = upstream_stages(plan, s).any(|j| splits[j].is_some() || after_split[j]);
    }
    let mut before_split = vec![false; n];
    for s in (0..n).rev() {
        if splits[s].is_some() || before_split[s] {
            for j in upstream_stages(plan, s) {
                before_split[j] = true;
            }
        }
    }
    (0..n).map(|s| splits[s].is_none() && after_split[s] && !before_split[s]).collect()
}

/// `OUT/units/<run>/<stage>/<u:05>`.
fn unit_dir(out_dir: &Path, plan: &Plan, s: usize, u: usize) -> PathBuf {
    out_dir.join(UNITS_DIR).join(&plan.run_name).join(&plan.stages[s].name).join(format!("{u:05}"))
}

/// The record of one unit of a split stage.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct UnitRecord {
    stage: String,
    unit: usize,
    key: String,
    /// The stage's cache key hash (every unit of a stage shares it).
    key_hash: String,
    /// Hash of the part's files.
    output_hash: String,
    wall_time_s: f64,
}

/// What `run-unit` did.
#[derive(Debug, Clone, PartialEq)]
pub enum UnitStatus {
    /// It ran, taking this long.
    Ran {
        /// Wall time in seconds.
        wall_time_s: f64,
    },
    /// Its folder was there and valid: nothing to do.
    AlreadyDone,
    /// It ran, but another worker had finished it first; its folder was kept.
    FinishedElsewhere,
}

/// The shared out folder of one plan, seen by a worker or by `collect`.
pub struct Shared<'a> {
    plan: &'a Plan,
    registry: &'a Registry,
    units: UnitPlan,
    out_dir: PathBuf,
    dataset_hashes: Vec<Option<String>>,
    /// Per stage, once resolved: its finished output (folder and record), if there.
    resolved: Vec<Option<Option<Resolved>>>,
}

#[derive(Debug, Clone)]
struct Resolved {
    dir: PathBuf,
    record: StageRecord,
}

/// A stage's inputs as resolved in the shared folder, and its cache key.
#[derive(Clone)]
struct Keyed {
    inputs: Vec<InputArtifact>,
    input_hashes: BTreeMap<String, String>,
    seed: u64,
    key_hash: String,
}

impl<'a> Shared<'a> {
    /// The shared folder `out_dir` for `plan`, hashing the datasets that `stage` and
    /// its upstream read (every stage's when `None`).
    pub fn open(plan: &'a Plan, registry: &'a Registry, out_dir: &Path, stage: Option<&str>) -> Result<Self, RunError> {
        let selected = select(plan, stage)?;
        Ok(Self {
            plan,
            registry,
            units: UnitPlan::new(plan, registry),
            out_dir: out_dir.to_path_buf(),
            dataset_hashes: hash_datasets(plan, &selected)?,
            resolved: vec![None; plan.stages.len()],
        })
    }

    /// Runs unit `index` unless its folder is there and valid.
    pub fn run_unit(&mut self, index: usize) -> Result<UnitStatus, RunError> {
        let Some(unit) = self.units.units.get(index).cloned() else {
            return Err(RunError::Selection(format!(
                "--index {index}: {} has units 0 to {} (`amrepro plan {}` lists them)",
                self.plan.spec_file.display(),
                self.units.units.len().saturating_sub(1),
                self.plan.spec_file.display()
            )));
        };
        let s = self.plan.stage_index(&unit.stage).expect("a unit's stage is planned");
        let Some(keyed) = self.keyed(s)? else {
            let missing = self.missing_before(s);
            return Err(RunError::UnitsMissing {
                spec: self.plan.spec_file.clone(),
                for_what: format!("unit {index} ({}: {})", unit.stage, unit.unit),
                missing,
            });
        };
        let u = unit.part.0;
        let dst = unit_dir(&self.out_dir, self.plan, s, u);
        if self.unit_valid(s, u, &keyed.key_hash) {
            return Ok(UnitStatus::AlreadyDone);
        }
        let key_hash = keyed.key_hash.clone();
        let staged = unique_staging(&dst)?;
        let started = Instant::now();
        let written = match split_of(self.registry, self.plan.stages[s].kind) {
            Some(split) => self.run_part(split, s, u, &unit.unit, keyed, &staged),
            None => self.job(s, keyed).run_into(&staged, None, false).map(|_| ()),
        };
        written.inspect_err(|_| {
            let _ = fs::remove_dir_all(&staged);
        })?;
        match publish_first(&staged, &dst, || self.unit_valid(s, u, &key_hash))? {
            true => Ok(UnitStatus::Ran { wall_time_s: started.elapsed().as_secs_f64() }),
            false => Ok(UnitStatus::FinishedElsewhere),
        }
    }

    /// Runs unit `u` of the split stage `s` into `staged`, with its record.
    fn run_part(
        &self,
        split: &dyn Split,
        s: usize,
        u: usize,
        key: &str,
        keyed: Keyed,
        staged: &Path,
    ) -> Result<(), RunError> {
        let stage = &self.plan.stages[s];
        let key_hash = keyed.key_hash.clone();
        let mut ctx = self.job(s, keyed).context(staged.to_path_buf(), None);
        let started = Instant::now();
        caught(|| split.run_unit(&mut ctx, u)).map_err(|e| stage_failed(stage, e))?;
        let (output_hash, _) = dir_hash(staged).map_err(|e| io_error(staged, e))?;
        let record = UnitRecord {
            stage: stage.name.clone(),
            unit: u,
            key: key.to_string(),
            key_hash,
            output_hash,
            wall_time_s: started.elapsed().as_secs_f64(),
        };
        let json = serde_json::to_vec_pretty(&record).expect("serialisable");
        crate::artifact::write_atomic(&staged.join(UNIT_FILE), &json).map_err(|e| stage_failed(stage, e))
    }

    fn job(&self, s: usize, keyed: Keyed) -> StageJob<'_> {
        StageJob {
            registry: self.registry,
            stage: &self.plan.stages[s],
            inputs: keyed.inputs,
            input_hashes: keyed.input_hashes,
            seed: keyed.seed,
            key_hash: keyed.key_hash,
        }
    }

    /// Stage `s`'s inputs and cache key, if every stage it reads is finished.
    fn keyed(&mut self, s: usize) -> Result<Option<Keyed>, RunError> {
        let stage = &self.plan.stages[s];
        let (mut inputs, mut input_hashes) = (Vec::new(), BTreeMap::new());
        for (input, role) in stage.inputs.iter().zip(&stage.input_roles) {
            let name = self.plan.input_name(*input).to_string();
            let (dir, hash) = match *input {
                InputRef::Dataset(d) => (
                    self.plan.datasets[d].dir.clone(),
                    self.dataset_hashes[d].clone().expect("selected datasets are hashed"),
                ),
                InputRef::Stage(j) => match self.resolve(j)? {
                    Some(r) => (r.dir, r.record.output_hash),
                    None => return Ok(None),
                },
            };
            input_hashes.insert(name.clone(), hash);
            inputs.push(InputArtifact { name, role, dir });
        }
        let seed = stage_seed(self.plan.seed, &stage.name);
        let key_hash = self.cache_key(s, seed, &input_hashes).hash();
        Ok(Some(Keyed { inputs, input_hashes, seed, key_hash }))
    }

    fn cache_key<'k>(&'k self, s: usize, seed: u64, inputs: &'k BTreeMap<String, String>) -> CacheKey<'k> {
        let stage = &self.plan.stages[s];
        let code = self.registry.code(stage.kind);
        CacheKey {
            kind: stage.kind,
            kind_version: stage.kind_version,
            tool_version: TOOL_VERSION,
            code: &code.fingerprint,
            code_parts: &code.parts,
            params: &stage.params,
            seed,
            inputs,
        }
    }

    /// Stage `s`'s finished output in the shared folder, merging a split stage whose
    /// units are all there; `None` while a unit it needs is missing.
    fn resolve(&mut self, s: usize) -> Result<Option<Resolved>, RunError> {
        if let Some(done) = &self.resolved[s] {
            return Ok(done.clone());
        }
        let found = match self.keyed(s)? {
            None => None,
            Some(keyed) => match split_of(self.registry, self.plan.stages[s].kind) {
                None => self.valid_stage_dir(s, unit_dir(&self.out_dir, self.plan, s, 0), &keyed),
                Some(split) => self.merged(split, s, keyed)?,
            },
        };
        self.resolved[s] = Some(found.clone());
        Ok(found)
    }

    fn valid_stage_dir(&self, s: usize, dir: PathBuf, keyed: &Keyed) -> Option<Resolved> {
        let record = read_record(&dir)?;
        let key = self.cache_key(s, keyed.seed, &keyed.input_hashes);
        (decide(&key, &keyed.key_hash, Some(&record), &dir) == Decision::Cached).then_some(Resolved { dir, record })
    }

    /// The merged outputs of split stage `s`: there already, or merged now from its
    /// parts if they are all there.
    fn merged(&self, split: &dyn Split, s: usize, keyed: Keyed) -> Result<Option<Resolved>, RunError> {
        let dst = unit_dir(&self.out_dir, self.plan, s, 0).with_file_name(MERGED_DIR);
        if let Some(done) = self.valid_stage_dir(s, dst.clone(), &keyed) {
            return Ok(Some(done));
        }
        let range = self.units.stage_units[s].clone();
        let parts: Vec<PathBuf> = (0..range.len()).map(|u| unit_dir(&self.out_dir, self.plan, s, u)).collect();
        if (0..parts.len()).any(|u| !self.unit_valid(s, u, &keyed.key_hash)) {
            return Ok(None);
        }
        let parts_wall_s: f64 = parts.iter().filter_map(|p| read_unit_record(p)).map(|r| r.wall_time_s).sum();
        let staged = unique_staging(&dst)?;
        let record = self
            .job(s, keyed.clone())
            .record_run(&staged, None, false, parts_wall_s, |ctx| caught(|| split.merge(ctx, &parts)))
            .inspect_err(|_| {
                let _ = fs::remove_dir_all(&staged);
            })?;
        let valid_there = || self.valid_stage_dir(s, dst.clone(), &keyed);
        if publish_first(&staged, &dst, || valid_there().is_some())? {
            return Ok(Some(Resolved { dir: dst, record }));
        }
        Ok(valid_there())
    }

    /// Whether unit `u` of stage `s` has a valid folder for the key `key_hash`.
    fn unit_valid(&self, s: usize, u: usize, key_hash: &str) -> bool {
        let dir = unit_dir(&self.out_dir, self.plan, s, u);
        let record_matches =
            |hash: &str, output_hash: &str| hash == key_hash && dir_hash(&dir).is_ok_and(|(h, _)| h == output_hash);
        match split_of(self.registry, self.plan.stages[s].kind) {
            Some(_) => {
                read_unit_record(&dir).is_some_and(|r| r.unit == u && record_matches(&r.key_hash, &r.output_hash))
            }
            None => read_record(&dir).is_some_and(|r| record_matches(&r.key_hash, &r.output_hash)),
        }
    }

    /// The units not yet (validly) there among those stage `s` needs, as
    /// `index (stage: unit)`; stages before them count as missing too.
    fn missing_before(&mut self, s: usize) -> Vec<String> {
        let mut missing = Vec::new();
        for j in upstream_stages(self.plan, s).collect::<Vec<_>>() {
            if matches!(self.resolve(j), Ok(Some(_))) {
                continue;
            }
            missing.extend(self.missing_units_of(j));
        }
        missing.sort();
        missing.dedup();
        missing
    }

    /// The units of stage `s` that are not there, or all of them when its inputs are not.
    fn missing_units_of(&mut self, s: usize) -> Vec<String> {
        let key_hash = match self.keyed(s) {
            Ok(Some(k)) => Some(k.key_hash),
            _ => None,
        };
        let mut missing = match key_hash {
            None => self.missing_before(s),
            Some(_) => Vec::new(),
        };
        for index in self.units.stage_units[s].clone() {
            let unit = &self.units.units[index];
            if key_hash.as_deref().is_none_or(|k| !self.unit_valid(s, unit.part.0, k)) {
                missing.push(format!("{index} ({}: {})", unit.stage, unit.unit));
            }
        }
        missing
    }

    /// Under the out folder's lock: checks every unit is there (naming those that are
    /// not, changing nothing), puts the finished stages in place as the run's pending
    /// outputs and runs the plan, which resumes them and runs the tail.
    pub fn collect(
        mut self,
        opts: &RunOptions,
        log: &(dyn Fn(&str) + Sync),
        lock: &OutLock,
    ) -> Result<RunSummary, RunError> {
        let stages: Vec<usize> = (0..self.plan.stages.len()).filter(|s| !self.units.tail[*s]).collect();
        let mut missing = Vec::new();
        let mut found = Vec::new();
        for &s in &stages {
            match self.resolve(s)? {
                Some(r) => found.push((s, r)),
                None => missing.extend(self.missing_units_of(s)),
            }
        }
        if !missing.is_empty() {
            missing.sort();
            missing.dedup();
            let spec = self.plan.spec_file.clone();
            return Err(RunError::UnitsMissing { spec, for_what: "collect".into(), missing });
        }
        let run_dir = opts.out_dir.join("runs").join(&self.plan.run_name);
        found.par_iter().try_for_each(|(s, r)| self.stage_pending(&run_dir, *s, r))?;
        run_plan_locked(self.plan, self.registry, opts, log, lock)
    }

    /// Copies a finished stage into the run's pending folder, unless the run's stage
    /// folder holds the same outputs already.
    fn stage_pending(&self, run_dir: &Path, s: usize, found: &Resolved) -> Result<(), RunError> {
        let name = &self.plan.stages[s].name;
        let current = read_record(&run_dir.join(name));
        let same =
            current.is_some_and(|c| c.key_hash == found.record.key_hash && c.output_hash == found.record.output_hash);
        if same && dir_hash(&run_dir.join(name)).is_ok_and(|(h, _)| h == found.record.output_hash) {
            return Ok(());
        }
        let pending = run_dir.join(PENDING_DIR).join(name);
        let staged = staging_dir(&pending).map_err(|e| io_error(&pending, e))?;
        copy_tree(&found.dir, &staged)
            .and_then(|()| replace_dir(&staged, &pending))
            .inspect_err(|_| {
                let _ = fs::remove_dir_all(&staged);
            })
            .map_err(|e| io_error(&pending, e))
    }
}

/// Every unit of a split kind, in parallel, into `.units/` of the stage's output
/// folder, then the merge, then the parts removed: a one-process run goes through
/// exactly the steps a spread-out run does. Draws a progress bar over the units.
pub fn run_split(split: &dyn Split, ctx: &mut StageContext) -> Result<(), StageError> {
    let units = split.units(&ctx.params, ctx.inputs.len());
    let root = ctx.output_dir().join(".units");
    let bar = ctx.progress(units.len() as u64);
    let parts: Vec<PathBuf> = (0..units.len())
        .into_par_iter()
        .map(|u| {
            let dir = root.join(format!("{u:05}"));
            fs::create_dir_all(&dir).map_err(|e| StageError::io(&dir, e))?;
            split.run_unit(&mut ctx.for_unit(dir.clone()), u)?;
            bar.inc(1);
            Ok(dir)
        })
        .collect::<Result<_, StageError>>()?;
    bar.finish_and_clear();
    split.merge(ctx, &parts)?;
    fs::remove_dir_all(&root).map_err(|e| StageError::io(&root, e))
}

fn read_unit_record(dir: &Path) -> Option<UnitRecord> {
    serde_json::from_slice(&fs::read(dir.join(UNIT_FILE)).ok()?).ok()
}

/// A fresh staging folder beside `dst` whose name no other writer, on this machine
/// or another sharing the folder, will pick: `.NAME.tmp-<pid><nanoseconds>`.
fn unique_staging(dst: &Path) -> Result<PathBuf, RunError> {
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    let name = dst.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
    let staged = dst.with_file_name(format!(".{name}.tmp-{}{nanos:09}", std::process::id()));
    fs::create_dir_all(&staged).map_err(|e| io_error(&staged, e))?;
    Ok(staged)
}

/// Renames `staged` onto `dst`. If another writer got there first and its folder is
/// valid, ours is discarded (`Ok(false)`); an invalid folder there is replaced.
fn publish_first(staged: &Path, dst: &Path, dst_valid: impl Fn() -> bool) -> Result<bool, RunError> {
    if dst.exists() && dst_valid() {
        let _ = fs::remove_dir_all(staged);
        return Ok(false);
    }
    match fs::rename(staged, dst) {
        Ok(()) => Ok(true),
        Err(_) if dst.exists() && dst_valid() => {
            let _ = fs::remove_dir_all(staged);
            Ok(false)
        }
        Err(_) => replace_dir(staged, dst).map(|()| true).map_err(|e| io_error(dst, e)),
    }
}

/// Copies the files under `from` (hidden ones included) into the folder `to`.
fn copy_tree(from: &Path, to: &Path) -> std::io::Result<()> {
    for entry in fs::read_dir(from)? {
        let entry = entry?;
        let target = to.join(entry.file_name());
        if entry.file_type()?.is_dir() {
            fs::create_dir_all(&target)?;
            copy_tree(&entry.path(), &target)?;
        } else {
            fs::copy(entry.path(), &target)?;
        }
    }
    Ok(())
}
