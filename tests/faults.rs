//! Fault tests of the real binary (ARCHITECTURE.md, "Failure semantics"): a panic in a
//! stage, a stage that fails after others finished, two runs into one out folder,
//! temp files of killed runs, `kill -9` at random moments, a full and a read-only out
//! folder, a corrupt manifest. After each, the published copies and the manifest must
//! agree with the files, and no temp file or staging folder may remain.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::text;
use pipeline::hash::{dir_hash, file_sha256};
use pipeline::Manifest;

/// Runs `amrepro args...` with the test stage kind registered.
fn amrepro(cwd: &Path, args: &[&str]) -> Output {
    command(cwd, args).output().expect("amrepro runs")
}

fn command(cwd: &Path, args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_amrepro"));
    cmd.args(args).current_dir(cwd).env_remove("AMREPRO_DATA").env(pipeline::testing::ENV_VAR, "1");
    cmd
}

/// A spec `f` with stage `a` (publishing `t/a.txt`) and stage `b` reading it; `b_params`
/// is `b`'s inline params table body.
fn write_spec(dir: &Path, a_text: &str, b_params: &str) -> PathBuf {
    let path = dir.join("s.toml");
    let spec = format!(
        "[run]\nname = \"f\"\n\
         [stage.a]\nkind = \"test.fault\"\nparams = {{ text = \"{a_text}\" }}\npublish = {{ \"value.txt\" = \"t/a.txt\" }}\n\
         [stage.b]\nkind = \"test.fault\"\ninputs = [\"a\"]\nparams = {{ {b_params} }}\npublish = {{ \"value.txt\" = \"t/b.txt\" }}\n"
    );
    std::fs::write(&path, spec).unwrap();
    path
}

fn run_ok(dir: &Path, spec: &Path, out: &Path) -> String {
    let result = amrepro(dir, &["run", "--out", &out.display().to_string(), &spec.display().to_string()]);
    let text = text(&result);
    assert!(result.status.success(), "{text}");
    text
}

fn run_fails(dir: &Path, spec: &Path, out: &Path) -> String {
    let result = amrepro(dir, &["run", "--out", &out.display().to_string(), &spec.display().to_string()]);
    let text = text(&result);
    assert!(!result.status.success(), "should have failed:\n{text}");
    text
}

/// Every file under `dir` with its bytes (what a reader of the out folder sees).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    entries(dir)
        .into_iter()
        .filter(|p| p.is_file() && p.file_name().is_some_and(|n| n != ".amrepro.lock"))
        .map(|p| (p.strip_prefix(dir).unwrap().to_path_buf(), std::fs::read(&p).unwrap()))
        .collect()
}

/// Every file and folder under `dir`.
fn entries(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path.clone());
            }
            found.push(path);
        }
    }
    found
}

/// The out folder agrees with its manifests ([`assert_manifests_true`]) and holds no
/// temp file, staging folder or pending work.
fn assert_consistent(out: &Path) {
    assert_manifests_true(out);
    for manifest in Manifest::read_all(out).unwrap().runs {
        let pending = out.join("runs").join(&manifest.run).join(".pending");
        assert!(!pending.exists(), "{}: a pending folder after a complete run", pending.display());
    }
    assert_no_temps(out);
}

/// Every manifest is readable, every stage folder hashes to its record and every
/// published copy to its output. A killed run may also have left `.pending/` and temp
/// files (the next run reuses the first and removes the second).
fn assert_manifests_true(out: &Path) {
    let found = Manifest::read_all(out).unwrap();
    assert!(found.unreadable.is_empty(), "{:?}", found.unreadable);
    for manifest in &found.runs {
        let run_dir = out.join("runs").join(&manifest.run);
        for stage in &manifest.stages {
            let r = &stage.record;
            let (hash, _) = dir_hash(&run_dir.join(&r.stage)).unwrap();
            assert_eq!(hash, r.output_hash, "{}/{}: stage folder differs from the manifest", manifest.run, r.stage);
            for (from, to) in &stage.published {
                let output = r.outputs.iter().find(|o| o.path == Path::new(from)).unwrap();
                let copy = file_sha256(&out.join(to)).unwrap();
                assert_eq!(copy, output.sha256, "{}: published copy differs from the manifest", to.display());
            }
        }
    }
}

fn assert_no_temps(out: &Path) {
    let is_temp = |p: &PathBuf| pipeline::lock::is_temp_name(&p.file_name().unwrap().to_string_lossy());
    let temps: Vec<PathBuf> = entries(out).into_iter().filter(is_temp).collect();
    assert!(temps.is_empty(), "temp files left: {temps:?}");
}

/// Waits for `child` at most `limit`; kills it and fails the test if it hangs.
fn wait_or_fail(mut child: Child, limit: Duration) -> Output {
    let started = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > limit {
            child.kill().unwrap();
            panic!("amrepro hung for more than {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

#[test]
fn a_panic_in_a_stage_is_its_error_and_the_run_ends_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    write_spec(dir.path(), "a1", "action = \"panic\", sleep_ms = 1300");
    let out = dir.path().join("out");
    // Not --quiet: the progress spinner (which starts after a second) must stop too.
    let child = command(dir.path(), &["run", "--out", "out", "s.toml"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let result = wait_or_fail(child, Duration::from_secs(60));
    let text = text(&result);
    assert!(!result.status.success(), "{text}");
    assert!(text.contains("stage `b` (test.fault) failed: internal error, a bug in amrepro"), "{text}");
    assert!(text.contains("test.fault told to panic (at pipeline/src/testing.rs:"), "{text}");
    assert!(!text.contains("panicked at") && !text.contains("RUST_BACKTRACE"), "a Rust panic report:\n{text}");
    assert!(!out.join("t").exists() && !out.join("runs/f/manifest.json").exists(), "nothing published");
    assert_no_temps(&out);
}

#[test]
fn a_failed_run_changes_nothing_readers_see_and_the_next_run_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    run_ok(dir.path(), &write_spec(dir.path(), "a1", "text = \"b1\""), &out);
    let before = snapshot(&out);

    let failing = write_spec(dir.path(), "a2", "action = \"fail\"");
    let text = run_fails(dir.path(), &failing, &out);
    assert!(text.contains("as the last complete run left them"), "{text}");
    assert_eq!(text.matches("told to fail").count(), 1, "the stage error said once:\n{text}");
    let after: BTreeMap<_, _> = snapshot(&out).into_iter().filter(|(p, _)| !p.starts_with("runs/f/.pending")).collect();
    assert_eq!(after, before, "stage folders, published copies, manifest and report unchanged");
    assert!(out.join("runs/f/.pending/a/value.txt").exists(), "the finished stage is kept");

    let text = run_ok(dir.path(), &write_spec(dir.path(), "a2", "text = \"b2\""), &out);
    assert!(text.contains("resumed  a"), "the stage that finished in the failed run is reused:\n{text}");
    assert!(text.contains("executed 1 of 2 stages"), "{text}");
    assert_eq!(std::fs::read_to_string(out.join("t/b.txt")).unwrap(), "b2\na2\n");
    assert_consistent(&out);
}

#[test]
fn a_second_run_into_the_same_out_folder_is_refused_naming_the_holder() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    write_spec(dir.path(), "a1", "sleep_ms = 3000");
    let first = command(dir.path(), &["run", "--quiet", "--out", "out", "s.toml"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lock = out.join(".amrepro.lock");
    let started = Instant::now();
    while std::fs::read_to_string(&lock).map_or(true, |t| t.is_empty()) {
        assert!(started.elapsed() < Duration::from_secs(20), "the first run never took the lock");
        std::thread::sleep(Duration::from_millis(20));
    }
    let other = dir.path().join("other.toml");
    std::fs::write(&other, "[run]\nname = \"g\"\n[stage.x]\nkind = \"test.fault\"\n").unwrap();
    let second = amrepro(dir.path(), &["run", "--out", "out", "other.toml"]);
    let text = text(&second);
    assert!(!second.status.success(), "{text}");
    let holder = format!("is in use by pid {} (amrepro run s.toml)", first.id());
    assert!(text.contains(&holder), "expected `{holder}` in:\n{text}");
    let report = amrepro(dir.path(), &["report", "--out", "out"]);
    assert!(!report.status.success(), "the report waits for the run too");
    let first = wait_or_fail(first, Duration::from_secs(60));
    assert!(first.status.success(), "{}", self::text(&first));
    run_ok(dir.path(), &other, &out);
    assert_consistent(&out);
}

#[test]
fn temp_files_left_by_killed_runs_are_removed_at_the_next_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let spec = write_spec(dir.path(), "a1", "text = \"b1\"");
    run_ok(dir.path(), &spec, &out);
    let leftovers = [
        out.join("t/.a.txt.tmp-99999"),
        out.join("runs/f/.manifest.json.tmp-99998"),
        out.join("runs/f/.pending/.b.tmp-99999/value.txt"),
        out.join("runs/f/.a.old-99997/value.txt"),
    ];
    for path in &leftovers {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, "half").unwrap();
    }
    run_ok(dir.path(), &spec, &out);
    for path in &leftovers {
        assert!(!path.exists(), "{} not cleaned", path.display());
    }
    assert_consistent(&out);
}

#[test]
fn a_corrupt_manifest_of_another_run_is_named_and_left_out_of_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let broken = out.join("runs/older/manifest.json");
    std::fs::create_dir_all(broken.parent().unwrap()).unwrap();
    std::fs::write(&broken, "{ \"tool_version\": ").unwrap();
    let text = run_ok(dir.path(), &write_spec(dir.path(), "a1", "text = \"b1\""), &out);
    assert!(text.contains(&format!("warning: the report leaves out a run: {}", broken.display())), "{text}");
    let html = std::fs::read_to_string(out.join("report/index.html")).unwrap();
    assert!(html.contains("Left out:") && html.contains("runs/older/manifest.json"), "named in the report");
    assert!(html.contains("id=\"f\""), "the good run is in the report");
}

/// `kill -9` at seeded random moments: first on a fresh out folder (each run resumes
/// what the killed one finished), then on forced reruns of a complete one. After each
/// kill the out folder agrees with its manifest (or holds a commit the next run
/// completes); the last run's Parquet is byte-identical to an uninterrupted run's.
#[test]
fn kill_9_at_random_moments_resumes_to_byte_identical_parquet() {
    let dir = tempfile::tempdir().unwrap();
    let spec = common::shipped_spec(dir.path(), "lu2015", &common::data_root());
    let spec = spec.display().to_string();
    let reference = dir.path().join("reference");
    let started = Instant::now();
    let result = amrepro(dir.path(), &["run", "--quiet", "--out", "reference", &spec]);
    assert!(result.status.success(), "{}", text(&result));
    let full_ms = started.elapsed().as_millis() as u64;

    let mut rng = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next_ms = |limit: u64| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng % limit.max(1)
    };
    let out = dir.path().join("killed");
    // One run killed at a random moment; true when the kill hit it still running.
    let mut kill_once = |force: bool, within_ms: u64| -> bool {
        let mut args = vec!["run", "--quiet", "--out", "killed", spec.as_str()];
        if force {
            args.insert(1, "--force");
        }
        let mut child = command(dir.path(), &args).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
        std::thread::sleep(Duration::from_millis(next_ms(within_ms)));
        let landed = child.try_wait().unwrap().is_none();
        let _ = child.kill();
        child.wait().unwrap();
        let journal = out.join("runs/lu2015/.pending/commit.json");
        if out.join("runs/lu2015/manifest.json").exists() && !journal.exists() {
            assert_manifests_true(&out);
        }
        landed
    };
    // Resuming runs do less each time, so later ones may finish before their kill;
    // kills in the first half of a full run's time make the first one land.
    let resumed_kills = (0..5).filter(|_| kill_once(false, full_ms / 2)).count();
    // A forced rerun always redoes the whole run: kill until five have landed.
    let mut forced_kills = 0;
    for _ in 0..20 {
        forced_kills += usize::from(kill_once(true, full_ms));
        if forced_kills == 5 {
            break;
        }
    }
    assert!(resumed_kills >= 1, "no kill hit a resuming run");
    assert_eq!(forced_kills, 5, "only {forced_kills} of 20 forced reruns were hit while running");
    let result = amrepro(dir.path(), &["run", "--quiet", "--out", "killed", &spec]);
    assert!(result.status.success(), "{}", text(&result));
    assert_consistent(&out);
    let parquet = |root: &Path| -> BTreeMap<PathBuf, Vec<u8>> {
        snapshot(root).into_iter().filter(|(p, _)| p.extension().is_some_and(|e| e == "parquet")).collect()
    };
    let (want, got) = (parquet(&reference), parquet(&out));
    assert!(!want.is_empty());
    assert_eq!(want.keys().collect::<Vec<_>>(), got.keys().collect::<Vec<_>>());
    for (path, bytes) in &want {
        assert!(got[path] == *bytes, "{} differs after the kills", path.display());
    }
}

/// Runs `script` (sh) in a new mount namespace where it may mount a small tmpfs;
/// `None` where this machine allows no such namespace.
fn in_mount_namespace(script: &str) -> Option<Output> {
    let probe = Command::new("unshare").args(["-rm", "true"]).output();
    if !probe.is_ok_and(|o| o.status.success()) {
        eprintln!("skipped: this machine allows no mount namespace (unshare -rm), so no small tmpfs to fill");
        return None;
    }
    Some(
        Command::new("unshare")
            .args(["-rm", "sh", "-ec", script])
            .env(pipeline::testing::ENV_VAR, "1")
            .output()
            .unwrap(),
    )
}

/// A complete run on a small tmpfs, then a run that cannot complete there (`then`:
/// shell lines between the two runs), then a copy of what is left for the checks.
fn run_on_small_tmpfs(then: &str, second_b_params: &str) -> Option<(tempfile::TempDir, String)> {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    std::fs::create_dir_all(root.join("mnt")).unwrap();
    write_spec(root, "a1", "text = \"b1\"");
    std::fs::copy(root.join("s.toml"), root.join("first.toml")).unwrap();
    write_spec(root, "a2", second_b_params);
    let bin = env!("CARGO_BIN_EXE_amrepro");
    let script = format!(
        "cd {root}\nmount -t tmpfs -o size=2m tmpfs mnt\n\
         {bin} run --quiet --out mnt/out first.toml\n{then}\n\
         {bin} run --quiet --out mnt/out s.toml > second.log 2>&1 || echo $? > second.rc\n\
         cp -a mnt/out snapshot\n",
        root = root.display()
    );
    let result = in_mount_namespace(&script)?;
    assert!(result.status.success(), "{}", text(&result));
    assert!(root.join("second.rc").exists(), "the second run should have failed");
    let log = std::fs::read_to_string(root.join("second.log")).unwrap();
    Some((dir, log))
}

#[test]
fn a_full_out_folder_fails_cleanly_and_keeps_the_last_complete_run() {
    let Some((dir, log)) = run_on_small_tmpfs("", "pad_bytes = 8000000") else { return };
    let snapshot_dir = dir.path().join("snapshot");
    assert!(log.contains("No space left on device") && log.contains("mnt/out/runs/f/.pending"), "{log}");
    assert!(!log.contains("panicked"), "{log}");
    assert_eq!(std::fs::read_to_string(snapshot_dir.join("t/a.txt")).unwrap(), "a1\n", "the last complete run");
    assert_manifests_true(&snapshot_dir);
    assert_no_temps(&snapshot_dir);
}

#[test]
fn a_read_only_out_folder_fails_cleanly_and_keeps_the_last_complete_run() {
    let Some((dir, log)) = run_on_small_tmpfs("mount -o remount,ro mnt", "text = \"b2\"") else { return };
    let snapshot_dir = dir.path().join("snapshot");
    assert!(log.contains("Read-only file system") && log.contains("mnt/out"), "{log}");
    assert!(!log.contains("panicked"), "{log}");
    assert_eq!(std::fs::read_to_string(snapshot_dir.join("t/a.txt")).unwrap(), "a1\n");
    assert_consistent(&snapshot_dir);
}
