//! A clone of the repository alone, in an empty folder with nothing beside it, runs
//! `make run`: the measured data ships in `data/` and the specs find it there without
//! `AMREPRO_DATA`. The binary under test stands in for the clone's build (`make -o
//! build`), and the power studies are cut to the tests' size.

mod common;

use std::path::Path;
use std::process::Command;

use common::*;

#[test]
fn a_clone_alone_runs_make_run() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    assert!(root.join(".git").exists(), "{} is not a git checkout: this test clones it", root.display());
    let tmp = tempfile::tempdir().unwrap();
    let clone = tmp.path().join("clone");
    let status =
        Command::new("git").args(["clone", "-q", "--no-hardlinks"]).arg(root).arg(&clone).status().expect("git runs");
    assert!(status.success(), "git clone failed");
    assert!(!tmp.path().join("shared").exists());
    for spec in shipped_spec_names() {
        let file = clone.join("specs").join(format!("{spec}.toml"));
        let text = std::fs::read_to_string(&file).unwrap();
        std::fs::write(&file, cut_studies(&spec, &text)).unwrap();
    }
    let out = Command::new("make")
        .args(["-o", "build", "run", &format!("BIN={}", env!("CARGO_BIN_EXE_amrepro"))])
        .current_dir(&clone)
        .env_remove("AMREPRO_DATA")
        .env_remove("MAKEFLAGS")
        .output()
        .expect("make runs");
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "make run failed in a clone alone:\n{text}");
    assert!(text.contains("open the report:"), "{text}");
    assert_eq!(parquet_rows(&clone.join("out/fdm/line_summary.parquet")), 18);
    assert!(parquet_rows(&clone.join("out/discrepancy/causes.parquet")) > 0, "the real-data discrepancy spec ran");
    for spec in shipped_spec_names() {
        assert!(clone.join("out/runs").join(&spec).join("manifest.json").exists(), "{spec} did not run");
    }
}
