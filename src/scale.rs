//! `amrepro plan`, `run-unit`, `collect` and `snakefile`: a spec run as independent
//! work units by any number of processes or machines sharing one out folder
//! (`pipeline::units`, docs/SCALE.md).

use std::time::{Duration, Instant};

use anyhow::{Context, Result};

use pipeline::error::RunError;
use pipeline::execute::{open_out_dir, RunOptions};
use pipeline::snakefile::{snakefile as snakefile_text, SnakefileTarget};
use pipeline::units::{Shared, UnitPlan, UnitStatus};
use pipeline::Plan;

use crate::cli::{CollectArgs, PlanArgs, RunUnitArgs, SnakefileArgs};
use crate::commands::{registry, write_report};

/// How often a waiting `run-unit` looks again for the units it needs.
const WAIT_POLL: Duration = Duration::from_secs(2);

pub fn plan(args: PlanArgs) -> Result<()> {
    let registry = registry();
    let plan = Plan::from_file(&args.spec, &registry)?;
    let units = UnitPlan::new(&plan, &registry);
    if let Some(level) = args.array_of_level {
        let indices: Vec<usize> = units.units.iter().filter(|u| u.level == level).map(|u| u.index).collect();
        outln!("{}", index_ranges(&indices))?;
        return Ok(());
    }
    for unit in &units.units {
        outln!("{}", serde_json::to_string(unit).expect("serialisable"))?;
    }
    let tail: Vec<&str> =
        plan.stages.iter().zip(&units.tail).filter(|(_, t)| **t).map(|(s, _)| s.name.as_str()).collect();
    let levels = units.units.iter().map(|u| u.level + 1).max().unwrap_or(0);
    eprintln!(
        "{}: {} work units in {levels} level(s); `collect` runs {} itself",
        args.spec.display(),
        units.units.len(),
        if tail.is_empty() { "no stage".to_string() } else { tail.join(", ") }
    );
    Ok(())
}

/// `3,5-9,12`: the indices as a Slurm array list.
fn index_ranges(indices: &[usize]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < indices.len() {
        let mut j = i;
        while j + 1 < indices.len() && indices[j + 1] == indices[j] + 1 {
            j += 1;
        }
        parts.push(if i == j { indices[i].to_string() } else { format!("{}-{}", indices[i], indices[j]) });
        i = j + 1;
    }
    parts.join(",")
}

pub fn run_unit(args: RunUnitArgs) -> Result<()> {
    let registry = registry();
    let plan = Plan::from_file(&args.spec, &registry)?;
    let units = UnitPlan::new(&plan, &registry);
    let what = match units.units.get(args.index) {
        Some(u) => format!("unit {} ({}: {})", u.index, u.stage, u.unit),
        None => format!("unit {}", args.index),
    };
    let started = Instant::now();
    let status = loop {
        let stage = units.units.get(args.index).map(|u| u.stage.as_str());
        let mut shared = Shared::open(&plan, &registry, &args.out, stage)?;
        match shared.run_unit(args.index) {
            Err(RunError::UnitsMissing { .. }) if started.elapsed() < Duration::from_secs(args.wait) => {
                std::thread::sleep(WAIT_POLL)
            }
            Err(err @ RunError::UnitsMissing { .. }) => return Err(err.into()),
            result => {
                break result.with_context(|| format!("{what} failed; the shared out folder holds nothing of it"))?
            }
        }
    };
    if !args.quiet {
        match status {
            UnitStatus::Ran { wall_time_s } => eprintln!("{what}: ran in {wall_time_s:.2} s"),
            UnitStatus::AlreadyDone => eprintln!("{what}: already done"),
            UnitStatus::FinishedElsewhere => eprintln!("{what}: another worker finished it first; kept theirs"),
        }
    }
    Ok(())
}

pub fn collect(args: CollectArgs) -> Result<()> {
    let registry = registry();
    let plan = Plan::from_file(&args.spec, &registry)?;
    let lock = open_out_dir(&args.out, &format!("collect {}", args.spec.display()))?;
    let opts = RunOptions {
        out_dir: args.out.clone(),
        show_progress: !args.quiet,
        resumed_because: Some("collected from its work units"),
        ..RunOptions::default()
    };
    let quiet = args.quiet;
    let log = move |line: &str| {
        if !quiet {
            eprintln!("{line}");
        }
    };
    let shared = Shared::open(&plan, &registry, &args.out, None)?;
    let summary = shared
        .collect(&opts, &log, &lock)
        .with_context(|| format!("collect of {} failed; nothing in the run folder changed", args.spec.display()))?;
    let report = write_report(&args.out)?;
    if !quiet {
        outln!("collected {} stages ({} run here)", summary.stages.len(), summary.executed())?;
        if let Some(manifest) = summary.manifest_path {
            outln!("manifest: {}", manifest.display())?;
        }
        outln!("report:   {}", report.display())?;
    }
    Ok(())
}

pub fn snakefile(args: SnakefileArgs) -> Result<()> {
    let registry = registry();
    let plan = Plan::from_file(&args.spec, &registry)?;
    let units = UnitPlan::new(&plan, &registry);
    let absolute = |p: &std::path::Path| std::path::absolute(p).with_context(|| format!("resolving {}", p.display()));
    let amrepro = std::env::current_exe().context("finding the amrepro executable")?;
    let (spec, out) = (absolute(&args.spec)?, absolute(&args.out)?);
    let text = snakefile_text(&plan, &units, &SnakefileTarget { amrepro: &amrepro, spec: &spec, out: &out });
    match args.output {
        None => out!("{text}")?,
        Some(path) => pipeline::artifact::write_atomic(&path, text.as_bytes())
            .with_context(|| format!("writing the Snakefile {}", path.display()))?,
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_become_a_slurm_array_list() {
        assert_eq!(index_ranges(&[3, 5, 6, 7, 8, 9, 12]), "3,5-9,12");
        assert_eq!(index_ranges(&[]), "");
        assert_eq!(index_ranges(&[0]), "0");
    }
}
