//! docs/SCALE.md where it shows commands: its Slurm script, run with a stand-in
//! `sbatch` that runs each array task at once, finishes a split study with the bytes of
//! one `amrepro run`; its Kubernetes Indexed Job's command, run once per completion
//! index (all at once, in reverse order, so units wait for what they need), does too,
//! and the Job's `completions` is the shipped spec's unit count; every `amrepro`
//! option the page and its examples show exists.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use common::*;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A stand-in for `sbatch` on PATH: prints a job id and runs `--wrap` once per index of
/// `--array` (with `SLURM_ARRAY_TASK_ID` set), in parallel, failing if a task fails.
fn fake_sbatch(bin: &Path) {
    let script = r#"#!/bin/sh
array="" wrap=""
for arg in "$@"; do
    case "$arg" in
        --array=*) array="${arg#--array=}" ;;
        --wrap=*) wrap="${arg#--wrap=}" ;;
    esac
done
echo "$$"
if [ -z "$array" ]; then sh -c "$wrap" >&2; exit $?; fi
pids=""
for part in $(echo "$array" | tr ',' ' '); do
    first="${part%-*}" last="${part#*-}"
    i=$first
    while [ "$i" -le "$last" ]; do
        SLURM_ARRAY_TASK_ID=$i sh -c "$wrap" >&2 &
        pids="$pids $!"
        i=$((i + 1))
    done
done
for pid in $pids; do wait "$pid" || exit 1; done
"#;
    let path = bin.join("sbatch");
    std::fs::write(&path, script).unwrap();
    make_executable(&path);
}

/// A scratch folder with the split study's spec, its one-process run in `one/`, and
/// `bin/` holding `amrepro` (for PATH): (folder, spec, bin).
fn scratch_with_one_run() -> (tempfile::TempDir, PathBuf, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = split_study_spec(dir);
    ok(dir, &["run", "-q", "--out", "one", spec.to_str().unwrap()]);
    let bin = dir.join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_amrepro"), bin.join("amrepro")).unwrap();
    (tmp, spec, bin)
}

fn make_executable(path: &Path) {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

fn path_with(bin: &Path) -> String {
    format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default())
}

fn published(dir: &Path, out: &str) -> Vec<Vec<u8>> {
    ["power.parquet", "power_draws.parquet"]
        .iter()
        .map(|f| std::fs::read(dir.join(out).join("discrepancy").join(f)).unwrap())
        .collect()
}

#[test]
fn the_slurm_script_runs_the_units_level_by_level_and_collects() {
    let (tmp, spec, bin) = scratch_with_one_run();
    let dir = tmp.path();
    fake_sbatch(&bin);
    let out = Command::new("sh")
        .arg(root().join("docs/examples/slurm-units.sh"))
        .current_dir(dir)
        .env("PATH", path_with(&bin))
        .env("SPEC", &spec)
        .env("OUT", dir.join("slurm"))
        .env_remove("AMREPRO_DATA")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out));
    let said = text(&out);
    assert!(said.contains("level 0: units 0-1") && said.contains("level 1: units 2-9"), "{said}");
    assert!(said.contains("collect: job"), "{said}");
    assert!(published(dir, "one") == published(dir, "slurm"), "the script's run gives the bytes of one run");
}

/// The Indexed Job's container command and its `completions`.
fn indexed_job() -> (String, usize) {
    let yaml = std::fs::read_to_string(root().join("docs/examples/k8s-indexed-job.yaml")).unwrap();
    let command = yaml.lines().find(|l| l.trim_start().starts_with("- amrepro run-unit")).expect("the unit command");
    let completions = yaml
        .lines()
        .find_map(|l| l.trim().strip_prefix("completions:"))
        .and_then(|v| v.split('#').next())
        .map(|v| v.trim().parse().unwrap())
        .expect("completions");
    (command.trim_start().trim_start_matches("- ").to_string(), completions)
}

#[test]
fn the_indexed_jobs_command_runs_every_unit_and_its_count_is_the_specs() {
    let (command, completions) = indexed_job();
    assert!(command.contains("\"$JOB_COMPLETION_INDEX\"") && command.contains("--wait"), "{command}");
    let shipped = root().join("specs/discrepancy_fdm.toml");
    assert!(command.contains("/work/specs/discrepancy_fdm.toml"), "{command}");
    let plan = ok(root(), &["plan", shipped.to_str().unwrap()]);
    let units = plan.lines().filter(|l| l.starts_with('{')).count();
    assert_eq!(completions, units, "the example's completions must be the spec's unit count");

    let (tmp, spec, bin) = scratch_with_one_run();
    let dir = tmp.path();
    let here = command
        .replace("/work/specs/discrepancy_fdm.toml", spec.to_str().unwrap())
        .replace("/shared/out", dir.join("k8s").to_str().unwrap());
    let units = 10;
    let pods: Vec<Child> = (0..units)
        .rev()
        .map(|index| {
            Command::new("sh")
                .args(["-c", &here])
                .current_dir(dir)
                .env("PATH", path_with(&bin))
                .env("JOB_COMPLETION_INDEX", index.to_string())
                .env_remove("AMREPRO_DATA")
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for pod in pods {
        let done = pod.wait_with_output().unwrap();
        assert!(done.status.success(), "{}", text(&done));
    }
    ok(dir, &["collect", "-q", spec.to_str().unwrap(), "--out", "k8s"]);
    assert!(published(dir, "one") == published(dir, "k8s"), "the Job's units give the bytes of one run");
}

/// Every `amrepro SUBCOMMAND … --flag` in the page and its examples names a flag the
/// subcommand has.
#[test]
fn every_option_the_page_shows_exists() {
    let files: Vec<PathBuf> = ["docs/SCALE.md", "docs/examples/slurm-units.sh", "docs/examples/k8s-indexed-job.yaml"]
        .iter()
        .map(|f| root().join(f))
        .collect();
    let mut checked = 0;
    for file in &files {
        let text_doc = std::fs::read_to_string(file).unwrap();
        for line in text_doc.lines() {
            let words: Vec<&str> =
                line.split_whitespace().map(|w| w.trim_matches(|c| c == '`' || c == '"' || c == '\\')).collect();
            let Some(at) = words.iter().position(|w| *w == "amrepro" || w.ends_with("$AMREPRO")) else {
                continue;
            };
            let Some(sub) = words.get(at + 1).filter(|s| ["plan", "run-unit", "collect", "snakefile"].contains(s))
            else {
                continue;
            };
            let help = String::from_utf8_lossy(&amrepro(root(), &[sub, "--help"]).stdout).into_owned();
            for flag in words[at + 2..].iter().filter(|w| w.starts_with("--")) {
                let flag: String = flag.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
                let flag = flag.as_str();
                assert!(help.contains(flag), "{} shows `amrepro {sub} {flag}`, which does not exist", file.display());
                checked += 1;
            }
        }
    }
    assert!(checked >= 10, "the page shows options: {checked}");
}
