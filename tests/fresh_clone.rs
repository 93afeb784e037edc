//! A clone of the repository alone, in an empty folder with nothing beside it, runs a
//! real-data spec: the measured data ships in `data/` and the specs find it there
//! without `AMREPRO_DATA`.

mod common;

use std::path::Path;
use std::process::Command;

use common::*;

#[test]
fn a_clone_alone_runs_the_real_data_spec() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    assert!(root.join(".git").exists(), "{} is not a git checkout: this test clones it", root.display());
    let tmp = tempfile::tempdir().unwrap();
    let clone = tmp.path().join("clone");
    let status =
        Command::new("git").args(["clone", "-q", "--no-hardlinks"]).arg(root).arg(&clone).status().expect("git runs");
    assert!(status.success(), "git clone failed");
    assert!(!tmp.path().join("shared").exists());
    let text = ok(&clone, &["run", "-q", "specs/fsu_linewidth.toml"]);
    assert!(text.contains("report:"), "{text}");
    assert_eq!(parquet_rows(&clone.join("out/fdm/line_summary.parquet")), 18);
}
