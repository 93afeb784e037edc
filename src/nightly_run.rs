//! `amrepro nightly`: every spec from scratch, one stage at a time (so each stage's CPU
//! time and peak memory are its own), into one night of the history; then the
//! regressions and `report/nightly.html` (the `nightly` crate does the bookkeeping).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};

use nightly::regress::{findings, Rules};
use nightly::{collect, history, page, Night, NightInfo, RunRow};
use pipeline::execute::{open_out_dir, run_plan_locked, RunOptions};
use pipeline::{Manifest, OutLock, Plan, Registry};

use crate::cli::NightlyArgs;
use crate::commands::{registry, write_report};

/// The exit status of a night with a regression under `--fail-on-regression`.
pub const REGRESSION_EXIT: u8 = 3;

/// A night that regressed, under `--fail-on-regression`.
#[derive(Debug, thiserror::Error)]
#[error("{count} regression(s) in the night; see {}", page.display())]
pub struct Regressed {
    /// How many.
    pub count: usize,
    /// The nightly report.
    pub page: PathBuf,
}

/// Runs the night.
pub fn run(args: NightlyArgs) -> Result<()> {
    let specs = match args.specs.is_empty() {
        true => shipped_specs()?,
        false => args.specs.clone(),
    };
    let registry = registry();
    let started_unix_s = unix_now();
    let lock = open_out_dir(&args.out, "nightly")?;
    let mut night = Night {
        info: NightInfo::new(started_unix_s, &git_commit(), &host_name(), cores()),
        runs: Vec::new(),
        stages: Vec::new(),
        numbers: Vec::new(),
    };
    for spec in &specs {
        if !args.quiet {
            eprintln!("nightly: running {} from scratch", spec.display());
        }
        record_spec(&mut night, spec, &registry, &args, &lock);
    }
    night.info.finished_unix_s = unix_now();
    let marker = history::append(&args.history, &night)
        .with_context(|| format!("appending the night to the history {}", args.history.display()))?;
    let history = history::read(&args.history).with_context(|| format!("reading {}", args.history.display()))?;
    let rules = Rules::default();
    let found = findings(&history, &rules);
    let page = page::write(&args.out, &history, &found, &rules).context("writing the nightly report")?;
    write_report(&args.out)?;
    drop(lock);
    let regressions = found.iter().filter(|f| f.regression).count();
    // A closed standard output ends the printing, not the verdict: a regression still fails.
    let printed = (|| -> Result<()> {
        outln!("night {} of {} in {}", night.info.night, history.nights.len(), marker.display())?;
        outln!(
            "{} spec(s), {} failed; {} stages, {} compared numbers; {regressions} regression(s), {} improvement(s)",
            night.runs.len(),
            night.runs.iter().filter(|r| !r.ok).count(),
            night.stages.len(),
            night.numbers.len(),
            found.len() - regressions
        )?;
        outln!("nightly report: {}", page.display())
    })();
    if args.fail_on_regression && regressions > 0 {
        return Err(Regressed { count: regressions, page }.into());
    }
    printed
}

/// Runs one spec with every stage forced and adds what it gave to the night; a spec
/// that fails is recorded as failed (the night goes on: a regression is news, not a
/// reason to lose the other specs' numbers).
fn record_spec(night: &mut Night, spec: &Path, registry: &Registry, args: &NightlyArgs, lock: &OutLock) {
    let started = Instant::now();
    let stem = spec.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let result = run_spec(spec, registry, args, lock);
    let wall_time_s = started.elapsed().as_secs_f64();
    let mut row =
        RunRow { run: stem, spec_file: spec.display().to_string(), ok: false, error: String::new(), wall_time_s };
    match result {
        Ok((manifest, numbers)) => {
            row.run = manifest.run.clone();
            row.ok = true;
            night.stages.extend(collect::stage_rows(&manifest));
            night.numbers.extend(numbers);
        }
        Err(e) => {
            row.error = format!("{e:#}");
            eprintln!("nightly: {} failed: {}", spec.display(), row.error);
        }
    }
    night.runs.push(row);
}

fn run_spec(
    spec: &Path,
    registry: &Registry,
    args: &NightlyArgs,
    lock: &OutLock,
) -> Result<(Manifest, Vec<nightly::NumberRow>)> {
    let plan = Plan::from_file(spec, registry)?;
    let opts = RunOptions {
        out_dir: args.out.clone(),
        force: true,
        measure_usage: true,
        show_progress: !args.quiet,
        ..RunOptions::default()
    };
    let quiet = args.quiet;
    let log = move |line: &str| {
        if !quiet {
            eprintln!("{line}");
        }
    };
    let summary = run_plan_locked(&plan, registry, &opts, &log, lock)?;
    let path = summary.manifest_path.expect("a run that is not dry writes a manifest");
    let manifest = Manifest::read(&path)?;
    let numbers = collect::number_rows(&args.out, &manifest)?;
    Ok((manifest, numbers))
}

/// `specs/*.toml` of the current folder, sorted.
fn shipped_specs() -> Result<Vec<PathBuf>> {
    let dir = Path::new("specs");
    let entries = std::fs::read_dir(dir).with_context(|| {
        format!("no specs given and no {} folder here to take the shipped ones from", dir.display())
    })?;
    let mut specs = Vec::new();
    for entry in entries {
        let path = entry.with_context(|| format!("reading {}", dir.display()))?.path();
        if path.extension().is_some_and(|e| e == "toml") {
            specs.push(path);
        }
    }
    specs.sort();
    if specs.is_empty() {
        bail!("no specs given and no specs/*.toml here");
    }
    Ok(specs)
}

fn unix_now() -> i64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() as i64)
}

/// `git rev-parse HEAD`, or `unknown` outside a checkout or without git.
fn git_commit() -> String {
    std::process::Command::new("git")
        .args(["rev-parse", "HEAD"])
        .stderr(std::process::Stdio::null())
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .filter(|c| !c.is_empty())
        .unwrap_or_else(|| "unknown".into())
}

fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown".into())
}

fn cores() -> i64 {
    std::thread::available_parallelism().map_or(1, |n| n.get() as i64)
}
