//! End to end, iterating as DVC users do (issue 54): `amrepro run --set STAGE.PARAM=VALUE`
//! (a parameter set on the command line, checked by the planner as the spec's own
//! values are) and `amrepro diff OUT_A OUT_B` (the published numbers that changed), on
//! the real FSU data.

mod common;

use common::*;

/// `--set` reruns what the parameter reaches, and `diff` lists the numbers it moved.
#[test]
fn a_parameter_set_on_the_command_line_reruns_its_stages_and_diff_lists_what_it_changed() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    let spec = spec.to_str().unwrap();
    ok(tmp.path(), &["run", "-q", "--out", "a", spec]);
    let set = ["--set", "line_summary.steady_to_mm=85", "--set", "line_summary.end_window_mm=20"];
    let dry = ok(tmp.path(), &[&["run", "--dry-run", "--out", "a"][..], &set, &[spec]].concat());
    let would: Vec<&str> = dry.lines().filter(|l| l.contains("would run ")).collect();
    assert_eq!(would.len(), 3, "line_summary and the two figures that read it:\n{dry}");
    assert!(would.iter().any(|l| l.contains("line_summary") && l.contains("param steady_to_mm: 80 → 85")), "{dry}");
    assert!(dry.contains("cached   import_taz5"), "{dry}");
    // Into a second out folder: the first keeps the spec's numbers.
    ok(tmp.path(), &["run", "-q", "--out", "b", "--set", "line_summary.steady_to_mm=85", spec]);
    let manifest = std::fs::read_to_string(tmp.path().join("b/runs/fsu_linewidth/manifest.json")).unwrap();
    assert!(manifest.contains("\"line_summary.steady_to_mm=85\""), "the manifest records the --set");
    let diff = ok(tmp.path(), &["diff", "a", "b"]);
    let summary = diff.lines().find(|l| l.starts_with("fdm/line_summary.parquet")).unwrap_or_else(|| panic!("{diff}"));
    assert!(
        summary.contains("stage line_summary of run fsu_linewidth") && summary.contains("numbers changed"),
        "{diff}"
    );
    let steady: Vec<&str> = diff.lines().filter(|l| l.contains(" steady_width_mm ")).collect();
    assert!(!steady.is_empty(), "the steady widths moved with the window:\n{diff}");
    assert!(steady.iter().all(|l| l.contains("printer=taz") && l.contains(" → ") && l.ends_with("%)")), "{diff}");
    assert!(!diff.contains("widths_taz5.parquet"), "the imports did not change:\n{diff}");
    assert!(diff.contains("numbers changed; 1 of 3 tables in both differ (0 only in a, 0 only in b)"), "{diff}");
    // A folder against itself: nothing changed.
    let same = ok(tmp.path(), &["diff", "a", "a"]);
    assert_eq!(same.trim(), "0 numbers changed; 0 of 3 tables in both differ (0 only in a, 0 only in a)");
    let err = fails(tmp.path(), &["diff", "a", "nowhere"]);
    assert!(err.contains("nowhere: not an out folder"), "{err}");
}

/// A `--set` naming an unknown stage or parameter, or giving a value out of range or of
/// the wrong type, is refused before anything runs, naming it.
#[test]
fn a_set_the_spec_cannot_take_is_refused_naming_it() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    let spec = spec.to_str().unwrap();
    let refused = |set: &str| fails(tmp.path(), &["run", "--dry-run", "--set", set, spec]);
    let err = refused("line_sumary.steady_to_mm=85");
    assert!(err.contains("--set line_sumary.steady_to_mm=85") && err.contains("no stage `line_sumary`"), "{err}");
    assert!(err.contains("line_summary"), "names the stages there are: {err}");
    let err = refused("line_summary.steady_to=85");
    assert!(err.contains("stage.line_summary.params.steady_to: unknown parameter"), "{err}");
    assert!(err.contains("steady_to_mm") && err.contains("(set by --set line_summary.steady_to=85)"), "{err}");
    let err = refused("line_summary.steady_to_mm=20000");
    assert!(err.contains("stage.line_summary.params.steady_to_mm") && err.contains("10000"), "{err}");
    assert!(err.contains("(set by --set line_summary.steady_to_mm=20000)"), "{err}");
    let err = refused("line_summary.steady_to_mm=wide");
    assert!(err.contains("stage.line_summary.params.steady_to_mm") && err.contains("\"wide\""), "{err}");
    let err = refused("import_taz5.printer=taz9");
    assert!(err.contains("stage.import_taz5.params.printer") && err.contains("taz9"), "{err}");
    let err = refused("steady_to_mm=85");
    assert!(err.contains("expected STAGE.PARAM=VALUE"), "{err}");
    assert!(!tmp.path().join("out").exists(), "nothing ran");
}
