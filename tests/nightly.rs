//! `amrepro nightly` end to end (docs/NIGHTLY.md): two clean nights give a history of
//! two and no regression; a night whose numbers moved (the spec's seed changed) exits 3
//! and names them; a nightly killed mid-run leaves the history readable and the next one
//! appends; the documented DuckDB and Polars queries run on the history, and the
//! documented command's options exist.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::*;

fn nightly(cwd: &Path, spec: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["nightly", "-q", "--history", "history", "--out", "out"];
    args.extend_from_slice(extra);
    args.push(spec.to_str().unwrap());
    amrepro(cwd, &args)
}

#[test]
fn nights_accumulate_regressions_are_flagged_and_a_kill_costs_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let spec = shipped_spec(dir, "lu2015", &data_root().join("fsu-linewidth"));
    for night in 1..=2 {
        let out = nightly(dir, &spec, &["--fail-on-regression"]);
        assert!(out.status.success(), "night {night}:\n{}", text(&out));
        assert!(text(&out).contains("0 regression(s)"), "{}", text(&out));
        std::thread::sleep(Duration::from_millis(1100)); // nights are named by the second
    }
    let history = nightly::history::read(&dir.join("history")).unwrap();
    assert_eq!(history.nights.len(), 2);
    let [first, second] = &history.nights[..] else { unreachable!() };
    assert!(first.numbers.len() > 20 && first.numbers.len() == second.numbers.len(), "{}", first.numbers.len());
    assert!(first.numbers.iter().any(|n| n.paper_value.is_some()), "paper values are kept");
    assert!(second.stages.iter().all(|s| s.status == "run" && s.cpu_time_s.is_some()), "every stage ran, measured");
    if cfg!(target_os = "linux") {
        assert!(second.stages.iter().all(|s| s.peak_rss_bytes.is_some_and(|b| b > 0)));
    }
    let page = std::fs::read_to_string(dir.join("out/report/nightly.html")).unwrap();
    assert!(page.contains("Regressions (0)"), "clean nights");
    assert!(page.matches("<svg").count() > second.numbers.len(), "a trend figure per number, and the timings");
    let index = std::fs::read_to_string(dir.join("out/report/index.html")).unwrap();
    assert!(index.contains("href=\"nightly.html\""), "the main report links the nightly one");

    let moved = dir.join("lu2015_seed2.toml");
    let shipped = std::fs::read_to_string(&spec).unwrap();
    assert!(shipped.contains("\nseed = 1\n"));
    std::fs::write(&moved, shipped.replace("\nseed = 1\n", "\nseed = 2\n")).unwrap();
    let out = nightly(dir, &moved, &["--fail-on-regression"]);
    assert_eq!(out.status.code(), Some(3), "a regression exits 3:\n{}", text(&out));
    assert!(text(&out).contains("regression(s) in the night"), "{}", text(&out));
    let page = std::fs::read_to_string(dir.join("out/report/nightly.html")).unwrap();
    assert!(!page.contains("Regressions (0)") && page.contains("left its band"), "the page names them");

    let files_before = history_files(dir);
    let mut child = Command::new(env!("CARGO_BIN_EXE_amrepro"))
        .args(["nightly", "-q", "--history", "history", "--out", "out", spec.to_str().unwrap()])
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while !dir.join("out/runs/lu2015/.pending").exists() && started.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert_eq!(history_files(dir), files_before, "a night killed while running leaves the history as it was");
    assert_eq!(nightly::history::read(&dir.join("history")).unwrap().nights.len(), 3);
    std::thread::sleep(Duration::from_millis(1100));
    let out = nightly(dir, &spec, &[]);
    assert!(out.status.success(), "without --fail-on-regression a night with findings exits 0:\n{}", text(&out));
    assert_eq!(nightly::history::read(&dir.join("history")).unwrap().nights.len(), 4, "appended after the kill");

    documented_queries_run(dir);
}

/// Every file of the history but its lock, with its bytes.
fn history_files(dir: &Path) -> Vec<(std::path::PathBuf, Vec<u8>)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.join("history")];
    while let Some(folder) = stack.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.file_name().is_some_and(|n| n != ".amrepro.lock") {
                files.push((path.clone(), std::fs::read(&path).unwrap()));
            }
        }
    }
    files.sort();
    files
}

fn documented_queries_run(dir: &Path) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = root.join("docs/NIGHTLY.md");
    let python = std::env::var("AMREPRO_PYTHON").unwrap_or_else(|_| "python3".into());
    let out = Command::new(&python)
        .arg(root.join("tests/analyst_queries.py"))
        .arg("--examples")
        .arg(&doc)
        .current_dir(dir)
        .output()
        .unwrap_or_else(|e| panic!("cannot start {python}: {e}; run `make test`, which installs duckdb and polars"));
    assert!(out.status.success(), "the queries of docs/NIGHTLY.md:\n{}", text(&out));
    assert!(text(&out).contains("4 passed"), "{}", text(&out));

    let text_doc = std::fs::read_to_string(&doc).unwrap();
    let help = String::from_utf8_lossy(&amrepro(dir, &["nightly", "--help"]).stdout).into_owned();
    let commands: Vec<&str> = text_doc.lines().filter(|l| l.contains("amrepro nightly --")).collect();
    assert!(!commands.is_empty());
    for line in commands {
        for flag in line.split_whitespace().filter(|w| w.starts_with("--")) {
            assert!(help.contains(flag), "docs/NIGHTLY.md shows `{flag}`, which `amrepro nightly` does not have");
        }
    }
}
