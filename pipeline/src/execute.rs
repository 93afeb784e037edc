//! Executes a checked [`Plan`]: wave by wave, stages of a wave in parallel (rayon);
//! each stage skipped when its cache key is unchanged, otherwise run into a staging
//! folder that replaces its previous outputs only on success; published copies and
//! the manifest written atomically, the manifest last.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use rayon::prelude::*;

use crate::artifact::{copy_atomic, replace_dir, staging_dir, write_atomic};
use crate::cache::{decide, read_record, CacheKey, Decision, RECORD_FILE};
use crate::error::{RunError, StageError};
use crate::hash::{dir_hash, file_sha256, sha256_hex};
use crate::manifest::{Manifest, ManifestStage, OutputFile, StageRecord};
use crate::plan::{InputRef, Plan, PlannedStage};
use crate::stage::{InputArtifact, Registry, StageContext};
use crate::TOOL_VERSION;

/// How to run a plan.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Out folder: stage outputs under `runs/<run>/`, published tables at their paths.
    pub out_dir: PathBuf,
    /// Only say what would run and why.
    pub dry_run: bool,
    /// Run only this stage (and whatever of its upstream is out of date).
    pub only: Option<String>,
    /// Run even when cached (only the `--only` stage if one is given).
    pub force: bool,
    /// Draw progress bars for stages that run longer than a second.
    pub show_progress: bool,
}

/// What happened to one stage in this invocation.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// It ran.
    Ran,
    /// Its outputs were up to date.
    Cached,
    /// Dry run: it would run.
    WouldRun,
}

/// One line of the run summary.
#[derive(Debug, Clone)]
pub struct StageLine {
    /// Stage name.
    pub stage: String,
    /// Stage kind.
    pub kind: String,
    /// What happened.
    pub status: Status,
    /// Why it ran or would run.
    pub reason: String,
    /// Wall time in this invocation.
    pub wall_time_s: f64,
}

/// The result of [`run_plan`].
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// The run folder (`out/runs/<run>`).
    pub run_dir: PathBuf,
    /// The manifest written (none for a dry run).
    pub manifest_path: Option<PathBuf>,
    /// One line per selected stage, in plan order.
    pub stages: Vec<StageLine>,
}

impl RunSummary {
    /// How many stages ran (or would run, in a dry run).
    pub fn executed(&self) -> usize {
        self.stages.iter().filter(|s| s.status != Status::Cached).count()
    }
}

/// The outcome of one stage inside the executor.
struct Outcome {
    line: StageLine,
    record: Option<StageRecord>,
    published: BTreeMap<String, PathBuf>,
}

/// Runs `plan`; `log` receives one line per stage event.
pub fn run_plan(
    plan: &Plan,
    registry: &Registry,
    opts: &RunOptions,
    log: &(dyn Fn(&str) + Sync),
) -> Result<RunSummary, RunError> {
    let started = Instant::now();
    let selected = select(plan, opts.only.as_deref())?;
    let run_dir = opts.out_dir.join("runs").join(&plan.run_name);
    let exec = Executor {
        plan,
        registry,
        opts,
        run_dir: run_dir.clone(),
        dataset_hashes: hash_datasets(plan, &selected)?,
        progress: opts.show_progress.then(indicatif::MultiProgress::new),
    };
    let mut outcomes: Vec<Option<Outcome>> = (0..plan.stages.len()).map(|_| None).collect();
    for wave in &plan.waves {
        let jobs: Vec<usize> = wave.iter().copied().filter(|i| selected[*i]).collect();
        let results: Vec<(usize, Result<Outcome, RunError>)> =
            jobs.par_iter().map(|&i| (i, exec.process(i, &outcomes))).collect();
        for (i, result) in results {
            let outcome = result?;
            log(&format_line(&outcome.line));
            outcomes[i] = Some(outcome);
        }
    }
    if !opts.dry_run {
        keep_unselected(plan, &run_dir, &mut outcomes);
    }
    let outcomes: Vec<Outcome> = outcomes.into_iter().flatten().collect();
    let manifest_path = if opts.dry_run {
        None
    } else {
        Some(write_manifest(plan, &run_dir, &outcomes, started.elapsed().as_secs_f64())?)
    };
    let stages = outcomes.into_iter().map(|o| o.line).collect();
    Ok(RunSummary { run_dir, manifest_path, stages })
}

/// Stages left out by `--only` keep their last outputs: record those in the manifest
/// too, so the manifest (and the report drawn from it) always covers the whole spec.
fn keep_unselected(plan: &Plan, run_dir: &Path, outcomes: &mut [Option<Outcome>]) {
    for (stage, slot) in plan.stages.iter().zip(outcomes.iter_mut()).filter(|(_, o)| o.is_none()) {
        if let Some(record) = read_record(&run_dir.join(&stage.name)) {
            let published = stage.publish.iter().cloned().collect();
            let line = line(stage, Status::Cached, "not selected by --only".into(), 0.0);
            *slot = Some(Outcome { line, record: Some(record), published });
        }
    }
}

/// Marks the stages to consider: all, or the `--only` stage and its upstream.
fn select(plan: &Plan, only: Option<&str>) -> Result<Vec<bool>, RunError> {
    let Some(name) = only else {
        return Ok(vec![true; plan.stages.len()]);
    };
    let target = plan.stage_index(name).ok_or_else(|| {
        let names: Vec<&str> = plan.stages.iter().map(|s| s.name.as_str()).collect();
        RunError::Selection(format!("--only {name}: no such stage; stages: {}", names.join(", ")))
    })?;
    let mut selected = vec![false; plan.stages.len()];
    selected[target] = true;
    for i in (0..=target).rev() {
        if selected[i] {
            for input in &plan.stages[i].inputs {
                if let InputRef::Stage(j) = input {
                    selected[*j] = true;
                }
            }
        }
    }
    Ok(selected)
}

fn hash_datasets(plan: &Plan, selected: &[bool]) -> Result<Vec<Option<String>>, RunError> {
    let used =
        |d: usize| plan.stages.iter().zip(selected).any(|(s, sel)| *sel && s.inputs.contains(&InputRef::Dataset(d)));
    plan.datasets
        .iter()
        .enumerate()
        .map(|(d, ds)| {
            if !used(d) {
                return Ok(None);
            }
            if !ds.dir.is_dir() {
                return Err(RunError::MissingDataset {
                    name: ds.name.clone(),
                    dir: ds.dir.clone(),
                    source_hint: ds.source.clone(),
                });
            }
            let (hash, _) = dir_hash(&ds.dir).map_err(|source| RunError::Io { path: ds.dir.clone(), source })?;
            Ok(Some(hash))
        })
        .collect()
}

struct Executor<'a> {
    plan: &'a Plan,
    registry: &'a Registry,
    opts: &'a RunOptions,
    run_dir: PathBuf,
    dataset_hashes: Vec<Option<String>>,
    progress: Option<indicatif::MultiProgress>,
}

impl Executor<'_> {
    fn process(&self, i: usize, done: &[Option<Outcome>]) -> Result<Outcome, RunError> {
        let stage = &self.plan.stages[i];
        let stage_dir = self.run_dir.join(&stage.name);
        let seed = stage_seed(self.plan.seed, &stage.name);
        let inputs = match self.input_hashes(stage, done) {
            Ok(inputs) => inputs,
            Err(rebuilt) => return Ok(self.would_run(stage, vec![format!("input `{rebuilt}` will be rebuilt")])),
        };
        let key = CacheKey {
            kind: stage.kind,
            kind_version: stage.kind_version,
            tool_version: TOOL_VERSION,
            params: &stage.params,
            seed,
            inputs: &inputs,
        };
        let key_hash = key.hash();
        let previous = read_record(&stage_dir);
        let decision = match self.forced(stage) {
            true => Decision::Run(vec!["--force".into()]),
            false => decide(&key, &key_hash, previous.as_ref(), &stage_dir),
        };
        match (decision, self.opts.dry_run) {
            (Decision::Cached, _) => self.cached(stage, previous.expect("cached implies a record")),
            (Decision::Run(why), true) => Ok(self.would_run(stage, why)),
            (Decision::Run(why), false) => self.execute(stage, &stage_dir, seed, key_hash, inputs, why.join("; ")),
        }
    }

    fn forced(&self, stage: &PlannedStage) -> bool {
        self.opts.force && self.opts.only.as_deref().is_none_or(|only| only == stage.name)
    }

    /// Input name → content hash; `Err(name)` when an upstream stage has no outputs
    /// yet because it would rerun (dry run).
    fn input_hashes(&self, stage: &PlannedStage, done: &[Option<Outcome>]) -> Result<BTreeMap<String, String>, String> {
        stage
            .inputs
            .iter()
            .map(|input| {
                let name = self.plan.input_name(*input).to_string();
                let hash = match input {
                    InputRef::Dataset(d) => self.dataset_hashes[*d].clone(),
                    InputRef::Stage(j) => {
                        done[*j].as_ref().and_then(|o| o.record.as_ref()).map(|r| r.output_hash.clone())
                    }
                };
                hash.map(|h| (name.clone(), h)).ok_or(name)
            })
            .collect()
    }

    fn would_run(&self, stage: &PlannedStage, why: Vec<String>) -> Outcome {
        Outcome { line: line(stage, Status::WouldRun, why.join("; "), 0.0), record: None, published: BTreeMap::new() }
    }

    fn cached(&self, stage: &PlannedStage, record: StageRecord) -> Result<Outcome, RunError> {
        let published = if self.opts.dry_run { BTreeMap::new() } else { self.publish(stage, &record)? };
        Ok(Outcome { line: line(stage, Status::Cached, String::new(), 0.0), record: Some(record), published })
    }

    fn execute(
        &self,
        stage: &PlannedStage,
        stage_dir: &Path,
        seed: u64,
        key_hash: String,
        input_hashes: BTreeMap<String, String>,
        reason: String,
    ) -> Result<Outcome, RunError> {
        let fail =
            |source: StageError| RunError::Stage { stage: stage.name.clone(), kind: stage.kind.to_string(), source };
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| RunError::Io { path, source }
        };
        let staged = staging_dir(stage_dir).map_err(io(stage_dir))?;
        let mut ctx = StageContext {
            stage: stage.name.clone(),
            params: stage.params.clone(),
            inputs: self.input_artifacts(stage),
            seed,
            stage_hash: key_hash.clone(),
            params_hash: sha256_hex(serde_json::to_string(&stage.params).expect("serialisable").as_bytes()),
            out_dir: staged.clone(),
            rows: 0,
            progress: self.progress.clone(),
        };
        let started = Instant::now();
        if let Err(e) = self.run_kind(stage, &mut ctx) {
            let _ = std::fs::remove_dir_all(&staged);
            return Err(fail(e));
        }
        let wall_time_s = started.elapsed().as_secs_f64();
        let (output_hash, files) = dir_hash(&staged).map_err(io(&staged))?;
        let record = StageRecord {
            stage: stage.name.clone(),
            kind: stage.kind.to_string(),
            kind_version: stage.kind_version,
            tool_version: TOOL_VERSION.to_string(),
            key_hash,
            params: stage.params.clone(),
            seed,
            input_hashes,
            output_hash,
            outputs: files.into_iter().map(|(path, sha256)| OutputFile { path, sha256 }).collect(),
            rows: ctx.rows,
            wall_time_s,
        };
        let json = serde_json::to_vec_pretty(&record).expect("serialisable");
        write_atomic(&staged.join(RECORD_FILE), &json).map_err(fail)?;
        replace_dir(&staged, stage_dir).map_err(io(stage_dir))?;
        let published = self.publish(stage, &record)?;
        Ok(Outcome { line: line(stage, Status::Ran, reason, wall_time_s), record: Some(record), published })
    }

    /// Runs the kind; a spinner appears if it is still running after a second.
    fn run_kind(&self, stage: &PlannedStage, ctx: &mut StageContext) -> Result<(), StageError> {
        let kind = self.registry.get(stage.kind).expect("planned kinds are registered");
        let Some(multi) = &self.progress else {
            return kind.run(ctx);
        };
        let (done_tx, done_rx) = mpsc::channel::<()>();
        std::thread::scope(|scope| {
            scope.spawn(|| spinner_after_a_second(multi, &stage.name, done_rx));
            let result = kind.run(ctx);
            let _ = done_tx.send(());
            result
        })
    }

    fn input_artifacts(&self, stage: &PlannedStage) -> Vec<InputArtifact> {
        stage
            .inputs
            .iter()
            .map(|input| InputArtifact {
                name: self.plan.input_name(*input).to_string(),
                dir: match input {
                    InputRef::Dataset(d) => self.plan.datasets[*d].dir.clone(),
                    InputRef::Stage(j) => self.run_dir.join(&self.plan.stages[*j].name),
                },
            })
            .collect()
    }

    /// Copies the stage's published outputs to their stable paths, unless a copy with
    /// the same content is already there.
    fn publish(&self, stage: &PlannedStage, record: &StageRecord) -> Result<BTreeMap<String, PathBuf>, RunError> {
        let stage_dir = self.run_dir.join(&stage.name);
        let mut published = BTreeMap::new();
        for (from, to) in &stage.publish {
            let Some(output) = record.outputs.iter().find(|o| o.path == Path::new(from)) else {
                let expected = format!("stage publishes `{from}` but did not write it");
                let source = StageError::BadInput { file: stage_dir.join(from), location: None, expected };
                return Err(RunError::Stage { stage: stage.name.clone(), kind: stage.kind.to_string(), source });
            };
            let dst = self.opts.out_dir.join(to);
            if file_sha256(&dst).ok().as_deref() != Some(output.sha256.as_str()) {
                copy_atomic(&stage_dir.join(from), &dst).map_err(|source| RunError::Stage {
                    stage: stage.name.clone(),
                    kind: stage.kind.to_string(),
                    source,
                })?;
            }
            published.insert(from.clone(), to.clone());
        }
        Ok(published)
    }
}

fn spinner_after_a_second(multi: &indicatif::MultiProgress, name: &str, done: mpsc::Receiver<()>) {
    if done.recv_timeout(Duration::from_secs(1)).is_ok() {
        return;
    }
    let spinner = multi.add(indicatif::ProgressBar::new_spinner());
    spinner.set_style(indicatif::ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template"));
    spinner.set_message(format!("running {name}"));
    while done.recv_timeout(Duration::from_millis(120)).is_err() {
        spinner.tick();
    }
    spinner.finish_and_clear();
}

/// A stage's seed: the first 8 bytes of SHA-256(run seed, stage name), so stages
/// draw independent streams and renaming one stage changes only its own.
pub fn stage_seed(run_seed: u64, stage: &str) -> u64 {
    let hex = sha256_hex(format!("{run_seed}:{stage}").as_bytes());
    u64::from_str_radix(&hex[..16], 16).expect("hex digits")
}

fn line(stage: &PlannedStage, status: Status, reason: String, wall_time_s: f64) -> StageLine {
    StageLine { stage: stage.name.clone(), kind: stage.kind.to_string(), status, reason, wall_time_s }
}

fn format_line(line: &StageLine) -> String {
    match line.status {
        Status::Ran => {
            format!("  ran      {:<24} {:<26} {:>7.2} s  ({})", line.stage, line.kind, line.wall_time_s, line.reason)
        }
        Status::Cached => format!("  cached   {:<24} {}", line.stage, line.kind),
        Status::WouldRun => format!("  would run {:<23} {:<26} because {}", line.stage, line.kind, line.reason),
    }
}

fn write_manifest(plan: &Plan, run_dir: &Path, outcomes: &[Outcome], wall_time_s: f64) -> Result<PathBuf, RunError> {
    let spec_sha256 =
        file_sha256(&plan.spec_file).map_err(|source| RunError::Io { path: plan.spec_file.clone(), source })?;
    let stages = outcomes
        .iter()
        .map(|o| ManifestStage {
            record: o.record.clone().expect("non-dry runs record every stage"),
            status: if o.line.status == Status::Ran { "run" } else { "cached" }.into(),
            reason: o.line.reason.clone(),
            this_run_wall_time_s: o.line.wall_time_s,
            published: o.published.clone(),
        })
        .collect();
    let manifest = Manifest {
        tool_version: TOOL_VERSION.to_string(),
        run: plan.run_name.clone(),
        title: plan.title.clone(),
        spec_file: plan.spec_file.clone(),
        spec_sha256,
        finished_unix_s: std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()),
        wall_time_s,
        stages,
    };
    let path = run_dir.join("manifest.json");
    let json = serde_json::to_vec_pretty(&manifest).expect("serialisable");
    write_atomic(&path, &json).map_err(|e| match e {
        StageError::Io { path, source } => RunError::Io { path, source },
        other => RunError::Io { path: path.clone(), source: std::io::Error::other(other.to_string()) },
    })?;
    Ok(path)
}
