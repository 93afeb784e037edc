//! The dataset commands and dataset folders against a hostile user: writers never
//! replace a folder that is not theirs and leave nothing behind; a path that is a
//! file, a linked sub-folder and a sequence of bad frames are each named in one short
//! message.

mod common;

use std::path::Path;

use common::*;

/// Every entry of `dir`, sorted (hidden ones too: a staging folder would show).
fn entries(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
    names.sort();
    names
}

/// A folder holding a file of its own.
fn foreign(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("thesis");
    std::fs::create_dir_all(&path).unwrap();
    std::fs::write(path.join("chapter1.tex"), "years of work").unwrap();
    path
}

#[test]
fn generate_thermal_replaces_only_its_own_output() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    foreign(dir);
    let err = fails(dir, &["datasets", "generate", "thermal", "--seed", "1", "--out", "thesis"]);
    assert!(err.contains("thesis: exists and is not an earlier output of `datasets generate thermal`"), "{err}");
    let err = fails(dir, &["datasets", "generate", "thermal", "--seed", "1", "--out", "."]);
    assert!(err.contains("expected a folder name (not `.`, `..` or `/`)"), "{err}");
    assert_eq!(entries(dir), ["thesis"], "nothing written, no staging folder left");
    assert_eq!(entries(&dir.join("thesis")), ["chapter1.tex"]);
    ok(dir, &["datasets", "generate", "thermal", "--seed", "1", "--out", "seq"]);
    ok(dir, &["datasets", "generate", "thermal", "--seed", "2", "--out", "seq"]);
    assert_eq!(entries(dir), ["seq", "thesis"]);
}

#[test]
fn generate_inkjet_refuses_the_current_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let err =
        fails(tmp.path(), &["datasets", "generate", "inkjet", "--scenario", "cuboid", "--seed", "1", "--out", "."]);
    assert!(err.contains("expected a folder name"), "{err}");
    assert!(entries(tmp.path()).is_empty());
}

#[test]
fn import_refuses_a_foreign_printer_folder_and_names_bad_raw_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let raw = copy_raw(dir);
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::rename(foreign(dir), out.join("taz5")).unwrap();
    let src = raw.to_str().unwrap();
    let err = fails(dir, &["datasets", "import", "fsu-linewidth", "--src", src, "--out", "out"]);
    assert!(err.contains("taz5: exists and is not an earlier output of `datasets import fsu-linewidth`"), "{err}");
    assert_eq!(entries(&out), ["taz5"], "taz6 not written either, no staging folder left");
    assert_eq!(entries(&out.join("taz5")), ["chapter1.tex"]);
    // --no-verify: a raw row out of order is named in the raw file at import, not later in the copy.
    let file = raw.join("taz5/S600F6000_xiao120.csv");
    let mut lines: Vec<String> = std::fs::read_to_string(&file).unwrap().lines().map(String::from).collect();
    lines.swap(10, 11);
    std::fs::write(&file, lines.join("\n")).unwrap();
    let args = ["datasets", "import", "fsu-linewidth", "--no-verify", "--src", src, "--out", "fresh"];
    let err = fails(dir, &args);
    assert!(err.contains("S600F6000_xiao120.csv:line 12, field position_mm: expected increasing positions"), "{err}");
    assert!(!dir.join("fresh").exists());
}

#[test]
fn a_dataset_path_that_is_a_file_or_holds_a_linked_folder_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(dir, &["datasets", "generate", "thermal", "--seed", "3", "--out", "seq"]);
    std::fs::write(dir.join("notes.txt"), "not a dataset").unwrap();
    let spec = |path: &str| {
        let file = dir.join("spec.toml");
        let text = format!(
            "[run]\nname = \"t\"\n[dataset.seq]\npath = \"{path}\"\n[stage.monitor]\nkind = \"thermal.monitor\"\ninputs = [\"seq\"]\n"
        );
        std::fs::write(&file, text).unwrap();
        file.to_str().unwrap().to_string()
    };
    let err = fails(dir, &["run", "-q", &spec("notes.txt")]);
    assert!(err.contains("notes.txt is a file, expected a dataset folder"), "{err}");
    std::fs::rename(dir.join("seq/frames"), dir.join("frames_elsewhere")).unwrap();
    std::os::unix::fs::symlink(dir.join("frames_elsewhere"), dir.join("seq/frames")).unwrap();
    let err = fails(dir, &["run", "-q", &spec("seq")]);
    assert!(err.contains("frames: a symbolic link to a folder"), "{err}");
}

#[test]
fn when_no_frame_can_be_used_the_reasons_are_grouped() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(dir, &["datasets", "generate", "thermal", "--seed", "3", "--out", "seq"]);
    let blank = datasets::thermal::sequence::encode_png16(160, 120, &[0; 160 * 120]);
    for entry in std::fs::read_dir(dir.join("seq/frames")).unwrap() {
        std::fs::write(entry.unwrap().path(), &blank).unwrap();
    }
    std::fs::write(
        dir.join("spec.toml"),
        "[run]\nname = \"t\"\n[dataset.seq]\npath = \"seq\"\n[stage.monitor]\nkind = \"thermal.monitor\"\ninputs = [\"seq\"]\n",
    )
    .unwrap();
    let err = fails(dir, &["run", "-q", "spec.toml"]);
    assert!(err.contains("none could: layer 0, frames 0-64 (65 frames): all pixels invalid (all-NaN)"), "{err}");
    assert!(err.len() < 1000, "one line per reason, not per frame ({} bytes):\n{err}", err.len());
}
