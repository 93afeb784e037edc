//! Runs beyond one machine (docs/SCALE.md): a spec's work units run by several
//! processes at once into one shared out folder, then `collect`, give Parquet byte for
//! byte the same as one `amrepro run`; so does the Snakemake workflow `amrepro
//! snakefile` writes, run by Snakemake from PyPI; a unit killed mid-run leaves nothing
//! that counts, `collect` names what is missing, and the rerun still gives the same
//! bytes; two workers on one unit do not corrupt it.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::*;

/// `amrepro plan`'s units: (index, stage, level, needs).
fn plan(dir: &Path, spec: &Path) -> Vec<serde_json::Value> {
    let out = amrepro(dir, &["plan", spec.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out));
    String::from_utf8(out.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

fn worker(dir: &Path, spec: &Path, index: usize, out: &str) -> Child {
    Command::new(env!("CARGO_BIN_EXE_amrepro"))
        .args(["run-unit", spec.to_str().unwrap(), "--index", &index.to_string(), "--out", out])
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Runs the units level by level, every unit of a level in its own process at once
/// (and the first unit of each level twice, concurrently).
fn run_all_units(dir: &Path, spec: &Path, units: &[serde_json::Value], out: &str) {
    let levels = units.iter().map(|u| u["level"].as_u64().unwrap()).max().unwrap();
    for level in 0..=levels {
        let indices: Vec<usize> =
            units.iter().filter(|u| u["level"] == level).map(|u| u["index"].as_u64().unwrap() as usize).collect();
        let mut children: Vec<Child> = indices.iter().map(|&i| worker(dir, spec, i, out)).collect();
        children.push(worker(dir, spec, indices[0], out));
        for child in children {
            let done = child.wait_with_output().unwrap();
            assert!(done.status.success(), "{}", text(&done));
        }
    }
}

/// Every Parquet file of the run and its published copies, relative path → bytes.
fn parquet_files(out: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    for root in [out.join("runs/scale"), out.join("discrepancy")] {
        collect_parquet(&root, out, &mut files);
    }
    files
}

fn collect_parquet(dir: &Path, out: &Path, files: &mut BTreeMap<PathBuf, Vec<u8>>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            collect_parquet(&path, out, files);
        } else if path.extension().is_some_and(|e| e == "parquet") {
            files.insert(path.strip_prefix(out).unwrap().to_path_buf(), std::fs::read(&path).unwrap());
        }
    }
}

fn assert_same_parquet(dir: &Path, a: &str, b: &str) {
    let (one, other) = (parquet_files(&dir.join(a)), parquet_files(&dir.join(b)));
    assert!(one.len() >= 5, "{:?}", one.keys());
    assert_eq!(one.keys().collect::<Vec<_>>(), other.keys().collect::<Vec<_>>(), "{a} and {b} hold the same tables");
    for (path, bytes) in &one {
        assert!(bytes == &other[path], "{} differs between {a} and {b}", path.display());
    }
}

#[test]
fn units_spread_over_processes_give_the_bytes_of_one_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = split_study_spec(dir);
    ok(dir, &["run", "-q", "--out", "one", spec.to_str().unwrap()]);

    let units = plan(dir, &spec);
    assert_eq!(units.len(), 2 + 8, "two imports and the study's eight blocks: {units:?}");
    for (i, u) in units.iter().enumerate() {
        assert_eq!(u["index"], i);
        assert!(u["needs"].as_array().unwrap().iter().all(|n| n.as_u64().unwrap() < i as u64), "needs come first");
    }
    assert_eq!(units[2]["unit"], "base 0 draws 0-2");

    run_all_units(dir, &spec, &units, "shared");
    let again = ok(dir, &["run-unit", spec.to_str().unwrap(), "--index", "5", "--out", "shared"]);
    assert!(again.contains("already done"), "{again}");
    let collected = ok(dir, &["collect", spec.to_str().unwrap(), "--out", "shared"]);
    assert!(collected.contains("collected from its work units"), "{collected}");
    assert_same_parquet(dir, "one", "shared");
    assert!(dir.join("shared/report/index.html").is_file(), "collect writes the report");
}

#[test]
fn a_killed_unit_leaves_nothing_that_counts_and_its_rerun_gives_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = split_study_spec(dir);
    ok(dir, &["run", "-q", "--out", "one", spec.to_str().unwrap()]);
    let units = plan(dir, &spec);
    let unit_dir = dir.join("killed/units/scale/power/00000");

    let needs = fails(dir, &["run-unit", spec.to_str().unwrap(), "--index", "2", "--out", "killed"]);
    assert!(needs.contains("0 (taz5: whole stage)") && needs.contains("1 (taz6: whole stage)"), "{needs}");
    for i in [0, 1] {
        ok(dir, &["run-unit", spec.to_str().unwrap(), "--index", &i.to_string(), "--out", "killed"]);
    }
    let mut child = worker(dir, &spec, 2, "killed");
    let started = Instant::now();
    let staging = || {
        std::fs::read_dir(unit_dir.parent().unwrap())
            .map(|entries| entries.flatten().any(|e| e.file_name().to_string_lossy().starts_with(".00000.tmp-")))
            .unwrap_or(false)
    };
    while !staging() && started.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::sleep(Duration::from_millis(300));
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!unit_dir.exists(), "a killed unit leaves only its temp folder");

    let missing = fails(dir, &["collect", spec.to_str().unwrap(), "--out", "killed"]);
    assert!(missing.contains("2 (power: base 0 draws 0-2)") && missing.contains("9 (power: base 1 draws 9-9)"));
    assert!(!dir.join("killed/runs/scale/manifest.json").exists(), "a refused collect writes nothing");

    run_all_units(dir, &spec, &units, "killed");
    ok(dir, &["collect", "-q", spec.to_str().unwrap(), "--out", "killed"]);
    assert_same_parquet(dir, "one", "killed");
    let leftovers: Vec<_> =
        walk(&dir.join("killed")).into_iter().filter(|p| p.to_string_lossy().contains(".tmp-")).collect();
    assert!(leftovers.is_empty(), "collect removes the killed unit's temp folder: {leftovers:?}");
}

#[test]
fn the_snakemake_workflow_gives_the_bytes_of_one_run() {
    let python = std::env::var("AMREPRO_PYTHON").unwrap_or_else(|_| "python3".into());
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = split_study_spec(dir);
    ok(dir, &["run", "-q", "--out", "one", spec.to_str().unwrap()]);
    ok(dir, &["snakefile", spec.to_str().unwrap(), "--out", "snake", "-o", "Snakefile"]);
    let out = Command::new(&python)
        .args(["-m", "snakemake", "-s", "Snakefile", "--cores", "2", "--quiet"])
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("{python} -m snakemake: {e} (make test installs it from requirements-test.txt)"));
    assert!(out.status.success(), "snakemake failed:\n{}", text(&out));
    assert_same_parquet(dir, "one", "snake");
    let manifest = std::fs::read_to_string(dir.join("snake/runs/scale/manifest.json")).unwrap();
    assert!(manifest.contains("\"power_curves\""), "collect ran the tail");
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let path = entry.path();
        found.push(path.clone());
        if path.is_dir() {
            found.extend(walk(&path));
        }
    }
    found
}
