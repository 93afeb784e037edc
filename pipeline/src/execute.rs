//! Executes a checked [`Plan`] in an out folder it holds the lock of ([`crate::lock`]):
//! wave by wave, stages of a wave in parallel, each in a rayon pool of its own
//! ([`on_stage_threads`]); each stage skipped when its cache key is unchanged,
//! otherwise run into a staging folder that becomes its pending outputs when it
//! succeeds (a panic is its error). Only when every stage has
//! succeeded does the run commit ([`crate::commit`]): stage folders, published copies
//! and the manifest change together, the manifest last.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use crate::artifact::{copy_synced, replace_dir, staging_dir, temp_sibling, write_synced};
use crate::cache::{decide, read_record, CacheKey, Decision, RECORD_FILE};
use crate::commit::{commit, roll_forward, Move, PENDING_DIR};
use crate::error::{RunError, StageError};
use crate::hash::{dir_hash, file_sha256, sha256_hex};
use crate::lock::{remove_stale_temps, OutLock};
use crate::manifest::{Manifest, ManifestStage, OutputFile, StageRecord};
use crate::plan::{InputRef, Plan, PlannedStage};
use crate::stage::{InputArtifact, Registry, StageContext};
use crate::usage::Meter;
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
    /// Run the stages one at a time and record each one's CPU time and peak memory
    /// ([`crate::usage`]: both are process-wide, so a stage's own only when it runs
    /// alone); for benchmark runs such as `amrepro nightly`.
    pub measure_usage: bool,
    /// Why a stage found finished in the run's pending folder counts as done (default:
    /// an earlier run finished it and then failed or was killed).
    pub resumed_because: Option<&'static str>,
}

/// What happened to one stage in this invocation.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// It ran.
    Ran,
    /// Its outputs were up to date.
    Cached,
    /// It had finished in an earlier run that then failed or was killed; its
    /// outputs, unchanged since, are committed by this run.
    Resumed,
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
        self.stages.iter().filter(|s| matches!(s.status, Status::Ran | Status::WouldRun)).count()
    }
}

/// The outcome of one stage inside the executor.
struct Outcome {
    line: StageLine,
    record: Option<StageRecord>,
    /// Where its outputs are now: its stage folder, or its pending folder.
    dir: PathBuf,
}

/// Takes the lock of `out_dir` for `what` (`run specs/x.toml`), completes a commit a
/// killed run left half done and removes the temp files killed runs left behind.
/// Hold the returned lock while writing anything into the out folder.
pub fn open_out_dir(out_dir: &Path, what: &str) -> Result<OutLock, RunError> {
    let lock = OutLock::acquire(out_dir, what)?;
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| RunError::Io { path, source }
    };
    let runs = out_dir.join("runs");
    if runs.is_dir() {
        for entry in std::fs::read_dir(&runs).map_err(io(&runs))? {
            roll_forward(&entry.map_err(io(&runs))?.path())?;
        }
    }
    remove_stale_temps(out_dir).map_err(io(out_dir))?;
    Ok(lock)
}

/// Runs `plan` under the lock of its out folder (a dry run takes none: it writes
/// nothing); `log` receives one line per stage event.
pub fn run_plan(
    plan: &Plan,
    registry: &Registry,
    opts: &RunOptions,
    log: &(dyn Fn(&str) + Sync),
) -> Result<RunSummary, RunError> {
    if opts.dry_run {
        return execute_plan(plan, registry, opts, log);
    }
    let lock = open_out_dir(&opts.out_dir, &format!("run {}", plan.spec_file.display()))?;
    run_plan_locked(plan, registry, opts, log, &lock)
}

/// [`run_plan`] for a caller that already holds the out folder's lock from
/// [`open_out_dir`] (to build the report under the same lock, say).
pub fn run_plan_locked(
    plan: &Plan,
    registry: &Registry,
    opts: &RunOptions,
    log: &(dyn Fn(&str) + Sync),
    lock: &OutLock,
) -> Result<RunSummary, RunError> {
    debug_assert_eq!(lock.path().parent(), Some(opts.out_dir.as_path()), "the lock of another out folder");
    execute_plan(plan, registry, opts, log)
}

/// `f` over `jobs` on at most as many threads as rayon's global pool has, the results
/// in the order of `jobs`, each thread running its jobs one after another in a rayon
/// pool of its own (of the global pool's size). A stage's parallel work so stays in
/// its own pool: under `par_iter` over the stages, a pool thread waiting for its
/// stage's work stole other queued stages whole, so a stage's measured wall time held
/// theirs (a 0.03 s stage measured 27 s beside the re-prints); and in one shared pool
/// a stage that starts beside a long one waits for all of that one's queued work (a
/// 3 s stage measured 187 s beside the power study). Now a stage's time is its own
/// work, slowed only by sharing the cores with the stages beside it. A panic outside a
/// stage's own (caught) run is passed on.
fn on_stage_threads<T: Send>(jobs: &[usize], f: impl Fn(&usize) -> T + Sync) -> Vec<T> {
    let threads = rayon::current_num_threads();
    let workers = threads.min(jobs.len());
    if workers <= 1 {
        return jobs.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let work = |worker: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(move |i| format!("amrepro-stages{worker}-{i}"))
            .build()
            .ok();
        let mut done = Vec::new();
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(job) = jobs.get(k) else { return done };
            let result = match &pool {
                Some(pool) => pool.install(|| f(job)),
                None => f(job),
            };
            done.push((k, result));
        }
    };
    let mut results: Vec<Option<T>> = (0..jobs.len()).map(|_| None).collect();
    std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers).map(|w| scope.spawn(move || work(w))).collect();
        for handle in handles {
            let done = handle.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            for (k, result) in done {
                results[k] = Some(result);
            }
        }
    });
    results.into_iter().map(|r| r.expect("every job is taken by one thread")).collect()
}

fn execute_plan(
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
        let process = |&i: &usize| (i, exec.process(i, &outcomes));
        let results: Vec<(usize, Result<Outcome, RunError>)> = match opts.measure_usage {
            true => jobs.iter().map(process).collect(),
            false => on_stage_threads(&jobs, process),
        };
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
    let manifest_path = match opts.dry_run {
        true => None,
        false => Some(exec.commit(&outcomes, started.elapsed().as_secs_f64())?),
    };
    let stages = outcomes.into_iter().map(|o| o.line).collect();
    Ok(RunSummary { run_dir, manifest_path, stages })
}

/// Stages left out by `--only` keep their last outputs: record those in the manifest
/// too, so the manifest (and the report drawn from it) always covers the whole spec.
fn keep_unselected(plan: &Plan, run_dir: &Path, outcomes: &mut [Option<Outcome>]) {
    for (stage, slot) in plan.stages.iter().zip(outcomes.iter_mut()).filter(|(_, o)| o.is_none()) {
        let dir = run_dir.join(&stage.name);
        if let Some(record) = read_record(&dir) {
            let line = line(stage, Status::Cached, "not selected by --only".into(), 0.0);
            *slot = Some(Outcome { line, record: Some(record), dir });
        }
    }
}

/// Marks the stages to consider: all, or the `--only` stage and its upstream.
pub(crate) fn select(plan: &Plan, only: Option<&str>) -> Result<Vec<bool>, RunError> {
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

pub(crate) fn hash_datasets(plan: &Plan, selected: &[bool]) -> Result<Vec<Option<String>>, RunError> {
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
        let pending_dir = self.run_dir.join(PENDING_DIR).join(&stage.name);
        let seed = stage_seed(self.plan.seed, &stage.name);
        let inputs = match self.input_hashes(stage, done) {
            Ok(inputs) => inputs,
            Err(rebuilt) => return Ok(self.would_run(stage, vec![format!("input `{rebuilt}` will be rebuilt")])),
        };
        let code = self.registry.code(stage.kind);
        let key = CacheKey {
            kind: stage.kind,
            kind_version: stage.kind_version,
            tool_version: TOOL_VERSION,
            code: &code.fingerprint,
            code_parts: &code.parts,
            params: &stage.params,
            seed,
            inputs: &inputs,
        };
        let key_hash = key.hash();
        if self.forced(stage) {
            return self.run_or_not(stage, done, seed, key_hash, inputs, vec!["--force".into()]);
        }
        let previous = read_record(&stage_dir);
        let why = match decide(&key, &key_hash, previous.as_ref(), &stage_dir) {
            Decision::Cached => return Ok(outcome(stage, Status::Cached, String::new(), previous, stage_dir)),
            Decision::Run(why) => why,
        };
        let pending = read_record(&pending_dir);
        if decide(&key, &key_hash, pending.as_ref(), &pending_dir) == Decision::Cached {
            let why =
                self.opts.resumed_because.unwrap_or("finished in an earlier run that did not complete").to_string();
            return Ok(outcome(stage, Status::Resumed, why, pending, pending_dir));
        }
        self.run_or_not(stage, done, seed, key_hash, inputs, why)
    }

    fn run_or_not(
        &self,
        stage: &PlannedStage,
        done: &[Option<Outcome>],
        seed: u64,
        key_hash: String,
        inputs: BTreeMap<String, String>,
        why: Vec<String>,
    ) -> Result<Outcome, RunError> {
        match self.opts.dry_run {
            true => Ok(self.would_run(stage, why)),
            false => self.execute(stage, done, seed, key_hash, inputs, why.join("; ")),
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
        outcome(stage, Status::WouldRun, why.join("; "), None, PathBuf::new())
    }

    /// Runs the stage into a staging folder that becomes its pending folder when it
    /// succeeds; on failure the staging folder is removed and nothing else changes.
    fn execute(
        &self,
        stage: &PlannedStage,
        done: &[Option<Outcome>],
        seed: u64,
        key_hash: String,
        input_hashes: BTreeMap<String, String>,
        reason: String,
    ) -> Result<Outcome, RunError> {
        let pending_dir = self.run_dir.join(PENDING_DIR).join(&stage.name);
        let staged = staging_dir(&pending_dir).map_err(|e| io_error(&pending_dir, e))?;
        let job = StageJob {
            registry: self.registry,
            stage,
            inputs: self.input_artifacts(stage, done),
            input_hashes,
            seed,
            key_hash,
        };
        let record = job.run_into(&staged, self.progress.as_ref(), self.opts.measure_usage).and_then(|record| {
            replace_dir(&staged, &pending_dir).map(|()| record).map_err(|e| io_error(&pending_dir, e))
        });
        let record = record.inspect_err(|_| {
            let _ = std::fs::remove_dir_all(&staged);
        })?;
        let wall_time_s = record.wall_time_s;
        Ok(outcome(stage, Status::Ran, reason, Some(record), pending_dir).timed(wall_time_s))
    }

    /// The input folders: datasets, and upstream outputs where they are in this run
    /// (pending if the upstream ran or resumed).
    fn input_artifacts(&self, stage: &PlannedStage, done: &[Option<Outcome>]) -> Vec<InputArtifact> {
        stage
            .inputs
            .iter()
            .zip(&stage.input_roles)
            .map(|(input, role)| InputArtifact {
                name: self.plan.input_name(*input).to_string(),
                role,
                dir: match input {
                    InputRef::Dataset(d) => self.plan.datasets[*d].dir.clone(),
                    InputRef::Stage(j) => done[*j].as_ref().expect("upstream ran in an earlier wave").dir.clone(),
                },
            })
            .collect()
    }

    /// Commits the run: pending stage folders into place, changed published copies
    /// and the manifest, all written in full before the first rename.
    fn commit(&self, outcomes: &[Outcome], wall_time_s: f64) -> Result<PathBuf, RunError> {
        let mut moves: Vec<Move> = outcomes
            .iter()
            .filter(|o| matches!(o.line.status, Status::Ran | Status::Resumed))
            .map(|o| Move { from: o.dir.clone(), to: self.run_dir.join(&o.line.stage), folder: true })
            .collect();
        let written = self.stage_new_files(outcomes, wall_time_s, &mut moves);
        let manifest_path = written.inspect_err(|_| discard_files(&moves))?;
        commit(&self.run_dir, &moves).inspect_err(|_| discard_files(&moves))?;
        Ok(manifest_path)
    }

    /// Writes the changed published copies and the manifest as temp files, adding
    /// their renames to `moves`; returns the manifest's final path.
    fn stage_new_files(
        &self,
        outcomes: &[Outcome],
        wall_time_s: f64,
        moves: &mut Vec<Move>,
    ) -> Result<PathBuf, RunError> {
        let mut stages = Vec::with_capacity(outcomes.len());
        for o in outcomes {
            let record = o.record.clone().expect("non-dry runs record every stage");
            let published = self.stage_published(o, &record, moves)?;
            stages.push(ManifestStage {
                record,
                status: o.line.status.manifest_word().into(),
                reason: o.line.reason.clone(),
                this_run_wall_time_s: o.line.wall_time_s,
                published,
            });
        }
        let path = self.run_dir.join("manifest.json");
        let json = serde_json::to_vec_pretty(&self.manifest(stages, wall_time_s)?).expect("serialisable");
        let tmp = temp_sibling(&path);
        write_synced(&tmp, |f| std::io::Write::write_all(f, &json).map_err(|e| StageError::io(&tmp, e)))
            .map_err(|e| RunError::bookkeeping(&tmp, e))?;
        moves.push(Move { from: tmp, to: path.clone(), folder: false });
        Ok(path)
    }

    /// Copies each published output whose copy differs to a temp file beside it.
    fn stage_published(
        &self,
        o: &Outcome,
        record: &StageRecord,
        moves: &mut Vec<Move>,
    ) -> Result<BTreeMap<String, PathBuf>, RunError> {
        let stage = &self.plan.stages[self.plan.stage_index(&o.line.stage).expect("planned stage")];
        let fail = |source| RunError::Stage { stage: stage.name.clone(), kind: stage.kind.to_string(), source };
        let mut published = BTreeMap::new();
        for (from, to) in &stage.publish {
            let Some(output) = record.outputs.iter().find(|f| f.path == Path::new(from)) else {
                let expected = format!("stage publishes `{from}` but did not write it");
                return Err(fail(StageError::BadInput { file: o.dir.join(from), location: None, expected }));
            };
            let dst = self.opts.out_dir.join(to);
            if file_sha256(&dst).ok().as_deref() != Some(output.sha256.as_str()) {
                let tmp = temp_sibling(&dst);
                copy_synced(&o.dir.join(from), &tmp).map_err(fail)?;
                moves.push(Move { from: tmp, to: dst, folder: false });
            }
            published.insert(from.clone(), to.clone());
        }
        Ok(published)
    }

    fn manifest(&self, stages: Vec<ManifestStage>, wall_time_s: f64) -> Result<Manifest, RunError> {
        let spec_file = &self.plan.spec_file;
        let spec_sha256 = file_sha256(spec_file).map_err(|source| RunError::Io { path: spec_file.clone(), source })?;
        Ok(Manifest {
            tool_version: TOOL_VERSION.to_string(),
            run: self.plan.run_name.clone(),
            title: self.plan.title.clone(),
            spec_file: spec_file.clone(),
            spec_sha256,
            overrides: self.plan.overrides.clone(),
            finished_unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            wall_time_s,
            stages,
        })
    }
}

/// One stage ready to run: its inputs resolved and its cache key computed.
pub(crate) struct StageJob<'a> {
    pub registry: &'a Registry,
    pub stage: &'a PlannedStage,
    pub inputs: Vec<InputArtifact>,
    pub input_hashes: BTreeMap<String, String>,
    pub seed: u64,
    pub key_hash: String,
}

impl StageJob<'_> {
    /// The context the stage runs in, writing into `out_dir`.
    pub fn context(&self, out_dir: PathBuf, progress: Option<&indicatif::MultiProgress>) -> StageContext {
        StageContext {
            stage: self.stage.name.clone(),
            params: self.stage.params.clone(),
            inputs: self.inputs.clone(),
            seed: self.seed,
            stage_hash: self.key_hash.clone(),
            params_hash: sha256_hex(serde_json::to_string(&self.stage.params).expect("serialisable").as_bytes()),
            out_dir,
            rows: 0,
            progress: progress.cloned(),
            writes: self.registry.get(self.stage.kind).map_or(&[], |k| k.writes()),
        }
    }

    /// Runs the stage into the empty folder `staged` and writes its record there
    /// (CPU time and peak memory measured when `measure_usage`).
    pub fn run_into(
        self,
        staged: &Path,
        progress: Option<&indicatif::MultiProgress>,
        measure_usage: bool,
    ) -> Result<StageRecord, RunError> {
        let (registry, stage) = (self.registry, self.stage);
        self.record_run(staged, progress, measure_usage, 0.0, |ctx| run_kind(registry, stage, ctx))
    }

    /// Runs `body` in the stage's context writing into the empty folder `staged`, then
    /// writes the stage's record there; `earlier_wall_s` is time spent on the stage's
    /// work elsewhere (a split stage's units), added to the record's wall time.
    pub fn record_run(
        self,
        staged: &Path,
        progress: Option<&indicatif::MultiProgress>,
        measure_usage: bool,
        earlier_wall_s: f64,
        body: impl FnOnce(&mut StageContext) -> Result<(), StageError>,
    ) -> Result<StageRecord, RunError> {
        let stage = self.stage;
        let mut ctx = self.context(staged.to_path_buf(), progress);
        let started = Instant::now();
        let meter = measure_usage.then(Meter::start);
        body(&mut ctx).map_err(|e| stage_failed(stage, e))?;
        let wall_time_s = earlier_wall_s + started.elapsed().as_secs_f64();
        let usage = meter.as_ref().map(Meter::finish);
        let (output_hash, files) = dir_hash(staged).map_err(|e| io_error(staged, e))?;
        let record = StageRecord {
            stage: stage.name.clone(),
            kind: stage.kind.to_string(),
            kind_version: stage.kind_version,
            tool_version: TOOL_VERSION.to_string(),
            code_fingerprint: self.registry.code(stage.kind).fingerprint.clone(),
            code_parts: self.registry.code(stage.kind).parts.clone(),
            key_hash: self.key_hash,
            params: stage.params.clone(),
            seed: self.seed,
            input_hashes: self.input_hashes,
            output_hash,
            outputs: files.into_iter().map(|(path, sha256)| OutputFile { path, sha256 }).collect(),
            rows: ctx.rows,
            wall_time_s,
            cpu_time_s: usage.and_then(|u| u.cpu_time_s),
            peak_rss_bytes: usage.and_then(|u| u.peak_rss_bytes),
        };
        write_record(staged, &record).map_err(|e| stage_failed(stage, e))?;
        Ok(record)
    }
}

/// Runs `f`, a panic becoming its error.
pub(crate) fn caught(f: impl FnOnce() -> Result<(), StageError>) -> Result<(), StageError> {
    crate::panic::catch(f).unwrap_or_else(|m| Err(StageError::Panic(m)))
}

/// Writes `record` as the record file of the stage folder `dir`.
pub(crate) fn write_record(dir: &Path, record: &StageRecord) -> Result<(), StageError> {
    let json = serde_json::to_vec_pretty(record).expect("serialisable");
    crate::artifact::write_atomic(&dir.join(RECORD_FILE), &json)
}

pub(crate) fn stage_failed(stage: &PlannedStage, source: StageError) -> RunError {
    RunError::Stage { stage: stage.name.clone(), kind: stage.kind.to_string(), source }
}

pub(crate) fn io_error(path: &Path, source: std::io::Error) -> RunError {
    RunError::Io { path: path.to_path_buf(), source }
}

/// Runs the kind, a panic becoming its error. A kind that splits draws its own
/// progress bar over its units; any other gets a spinner if it is still running
/// after a second, stopped however the kind ends.
fn run_kind(registry: &Registry, stage: &PlannedStage, ctx: &mut StageContext) -> Result<(), StageError> {
    let kind = registry.get(stage.kind).expect("planned kinds are registered");
    let run = |ctx: &mut StageContext| caught(|| kind.run(ctx));
    let Some(multi) = ctx.progress.clone().filter(|_| kind.split().is_none()) else {
        return run(ctx);
    };
    let (done_tx, done_rx) = mpsc::channel::<()>();
    std::thread::scope(|scope| {
        scope.spawn(|| spinner_after_a_second(&multi, &stage.name, done_rx));
        let result = run(ctx);
        drop(done_tx);
        result
    })
}

/// Removes the temp files of a commit that will not happen.
fn discard_files(moves: &[Move]) {
    for mv in moves.iter().filter(|mv| !mv.folder) {
        let _ = std::fs::remove_file(&mv.from);
    }
}

fn outcome(stage: &PlannedStage, status: Status, reason: String, record: Option<StageRecord>, dir: PathBuf) -> Outcome {
    Outcome { line: line(stage, status, reason, 0.0), record, dir }
}

impl Outcome {
    fn timed(mut self, wall_time_s: f64) -> Self {
        self.line.wall_time_s = wall_time_s;
        self
    }
}

impl Status {
    /// The word for the manifest's `status`.
    fn manifest_word(&self) -> &'static str {
        match self {
            Self::Ran => "run",
            Self::Cached => "cached",
            Self::Resumed => "resumed",
            Self::WouldRun => "would run",
        }
    }
}

fn spinner_after_a_second(multi: &indicatif::MultiProgress, name: &str, done: mpsc::Receiver<()>) {
    if done.recv_timeout(Duration::from_secs(1)) != Err(mpsc::RecvTimeoutError::Timeout) {
        return;
    }
    let spinner = multi.add(indicatif::ProgressBar::new_spinner());
    spinner.set_style(indicatif::ProgressStyle::with_template("{spinner} {msg} {elapsed}").expect("valid template"));
    spinner.set_message(format!("running {name}"));
    while done.recv_timeout(Duration::from_millis(120)) == Err(mpsc::RecvTimeoutError::Timeout) {
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
            format!("  ran      {:<24} {:<32} {:>7.2} s  ({})", line.stage, line.kind, line.wall_time_s, line.reason)
        }
        Status::Cached => format!("  cached   {:<24} {}", line.stage, line.kind),
        Status::Resumed => format!("  resumed  {:<24} {:<32} ({})", line.stage, line.kind, line.reason),
        Status::WouldRun => format!("  would run {:<23} {:<32} because {}", line.stage, line.kind, line.reason),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stage::Code;
    use crate::testing::FaultKind;

    /// A registry of `test.fault` under the code fingerprint `code`.
    fn registry(code: &str) -> Registry {
        let mut registry = Registry::with_code_fingerprint(code);
        registry.register(Box::new(FaultKind));
        registry
    }

    /// Runs `spec` into `out` with `registry`: each stage's status and reason.
    fn run(spec: &Path, out: &Path, registry: &Registry) -> Vec<(Status, String)> {
        let plan = Plan::from_file(spec, registry).unwrap();
        let opts = RunOptions { out_dir: out.to_path_buf(), ..RunOptions::default() };
        let summary = run_plan(&plan, registry, &opts, &|_| {}).unwrap();
        summary.stages.into_iter().map(|s| (s.status, s.reason)).collect()
    }

    #[test]
    fn another_build_of_the_program_reruns_every_stage_and_says_why() {
        let dir = tempfile::tempdir().unwrap();
        let (spec, out) = (dir.path().join("s.toml"), dir.path().join("out"));
        let text = "[run]\nname = \"c\"\n\
                    [stage.a]\nkind = \"test.fault\"\nparams = { text = \"x\" }\n\
                    [stage.b]\nkind = \"test.fault\"\ninputs = [\"a\"]\n";
        std::fs::write(&spec, text).unwrap();
        let (first, second) = (registry("0123456789abcdef"), registry("fedcba9876543210"));
        assert!(run(&spec, &out, &first).iter().all(|(s, _)| *s == Status::Ran));
        assert!(run(&spec, &out, &first).iter().all(|(s, _)| *s == Status::Cached), "same build: cached");
        let rerun = run(&spec, &out, &second);
        assert!(rerun.iter().all(|(s, _)| *s == Status::Ran), "{rerun:?}");
        let why = "the program's code changed (fingerprint 0123456789abcdef → fedcba9876543210)";
        assert!(rerun[0].1.contains(why), "{}", rerun[0].1);
        let record = read_record(&out.join("runs/c/a")).unwrap();
        assert_eq!(record.code_fingerprint, "fedcba9876543210");
        assert!(run(&spec, &out, &second).iter().all(|(s, _)| *s == Status::Cached));
        // A record from before the key held the code (no fingerprint, another key).
        let path = out.join("runs/c/a").join(RECORD_FILE);
        let mut old: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
        let fields = old.as_object_mut().unwrap();
        fields.remove("code_fingerprint");
        fields.insert("key_hash".into(), "0".repeat(64).into());
        std::fs::write(&path, serde_json::to_vec(&old).unwrap()).unwrap();
        let rerun = run(&spec, &out, &second);
        assert_eq!(rerun[0].0, Status::Ran);
        assert!(rerun[0].1.contains("fingerprint none recorded → fedcba9876543210"), "{}", rerun[0].1);
    }

    /// A registry of `test.fault` (defined in `pipeline`) whose crates' code is given
    /// as (crate, [(part, hash)]).
    fn registry_by_crate(crates: &[(&str, &[(&str, &str)])]) -> Registry {
        let code = |parts: &[(&str, &str)]| {
            let parts: BTreeMap<String, String> = parts.iter().map(|(p, h)| (p.to_string(), h.to_string())).collect();
            Code { fingerprint: crate::hash::sha256_hex(format!("{parts:?}").as_bytes())[..16].into(), parts }
        };
        let by_crate = crates.iter().map(|(c, parts)| (c.to_string(), code(parts))).collect();
        let mut registry = Registry::with_code(code(&[("program", "p")]), by_crate);
        registry.register(Box::new(FaultKind));
        registry
    }

    #[test]
    fn a_kind_reruns_when_the_code_of_its_own_crate_changes_and_names_the_part() {
        let dir = tempfile::tempdir().unwrap();
        let (spec, out) = (dir.path().join("s.toml"), dir.path().join("out"));
        std::fs::write(&spec, "[run]\nname = \"p\"\n[stage.a]\nkind = \"test.fault\"\n").unwrap();
        let pipeline: &[(&str, &str)] = &[("pipeline", "1"), ("toolchain", "t")];
        let first = registry_by_crate(&[("pipeline", pipeline), ("other", &[("other", "1"), ("toolchain", "t")])]);
        assert_eq!(run(&spec, &out, &first)[0].0, Status::Ran);
        // Another crate's code changed: still cached.
        let other = registry_by_crate(&[("pipeline", pipeline), ("other", &[("other", "2"), ("toolchain", "t")])]);
        assert_eq!(run(&spec, &out, &other)[0].0, Status::Cached);
        let changed = registry_by_crate(&[("pipeline", &[("pipeline", "2"), ("toolchain", "u")])]);
        let rerun = run(&spec, &out, &changed);
        assert_eq!(rerun[0].0, Status::Ran);
        let (old, new) = (&first.code("test.fault").fingerprint, &changed.code("test.fault").fingerprint);
        let why = format!("code of pipeline, toolchain changed (fingerprint {old} → {new})");
        assert!(rerun[0].1.contains(&why), "{}", rerun[0].1);
        let record = read_record(&out.join("runs/p/a")).unwrap();
        assert_eq!((&record.code_fingerprint, record.code_parts.get("pipeline").map(String::as_str)), (new, Some("2")));
    }

    #[test]
    fn stages_of_a_wave_run_in_order_each_in_a_pool_of_its_own() {
        use rayon::prelude::*;
        let name = || std::thread::current().name().unwrap_or("").to_string();
        let pool_of = |thread: &str| thread.rsplit_once('-').map(|(pool, _)| pool.to_string()).unwrap_or_default();
        let outer = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
        let jobs: Vec<usize> = (0..7).collect();
        let results = outer.install(|| {
            on_stage_threads(&jobs, |&j| {
                // A stage's own parallel work, and the threads it ran on.
                let threads: Vec<String> = (0..64usize).into_par_iter().map(|_| name()).collect();
                (j, name(), threads, rayon::current_num_threads())
            })
        });
        assert_eq!(results.iter().map(|r| r.0).collect::<Vec<_>>(), jobs, "results in the order of the jobs");
        let pools: std::collections::BTreeSet<String> = results.iter().map(|r| pool_of(&r.1)).collect();
        assert!(pools.len() <= 3 && pools.iter().all(|p| p.starts_with("amrepro-stages")), "{pools:?}");
        for (j, body, threads, size) in &results {
            assert_eq!(*size, 3, "job {j}: a pool of the outer pool's size");
            assert!(
                threads.iter().all(|t| pool_of(t) == pool_of(body)),
                "job {j} ran work outside its pool: {threads:?}"
            );
        }
        let caught = std::panic::catch_unwind(|| on_stage_threads(&jobs, |&j| assert_ne!(j, 5, "job five")));
        assert!(caught.is_err(), "a panic outside a stage's caught run is passed on");
    }
}
