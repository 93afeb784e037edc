//! Bad input: each case must fail with an error naming the file and line (or the spec
//! field) and what was expected, exit non-zero, and leave earlier good outputs
//! untouched and nothing half-written.

mod common;

use std::path::Path;

use common::*;

/// Runs the FSU spec on a good copy of the data, corrupts the copy with `corrupt`,
/// reruns, and checks the failure message and that the earlier outputs are intact.
fn fails_and_keeps_outputs(corrupt: impl Fn(&Path), expected: &[&str]) {
    let tmp = tempfile::tempdir().unwrap();
    let raw = copy_raw(tmp.path());
    let spec = fsu_spec(tmp.path(), &raw);
    let spec_text = std::fs::read_to_string(&spec)
        .unwrap()
        .replace("params = { printer = \"taz5\" }", "params = { printer = \"taz5\", verify_sha256 = false }");
    std::fs::write(&spec, spec_text).unwrap();
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let published = tmp.path().join("out/fdm/line_summary.parquet");
    let before = std::fs::read(&published).unwrap();
    let stage_before = listing(&tmp.path().join("out/runs/fsu_linewidth"));
    corrupt(&raw.join("taz5"));
    let err = fails(tmp.path(), &["run", spec.to_str().unwrap()]);
    for part in expected {
        assert!(err.contains(part), "expected `{part}` in:\n{err}");
    }
    assert_eq!(std::fs::read(&published).unwrap(), before, "published table untouched");
    assert_eq!(
        listing(&tmp.path().join("out/runs/fsu_linewidth")),
        stage_before,
        "outputs untouched, no temp or half-written files left"
    );
}

/// Every output file under `dir` with its size, sorted. Stage records are left out:
/// a sibling stage whose input folder changed may rightly rerun (same outputs, new
/// record); so is `.pending/`, where such a sibling's finished work is kept for the
/// next run. Any temp file left behind would show up here.
fn listing(dir: &Path) -> Vec<(String, u64)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                if !path.ends_with(".pending") {
                    stack.push(path);
                }
            } else if !path.ends_with(".stage.json") {
                files.push((path.strip_prefix(dir).unwrap().display().to_string(), path.metadata().unwrap().len()));
            }
        }
    }
    files.sort();
    files
}

#[test]
fn csv_row_that_is_not_two_numbers() {
    fails_and_keeps_outputs(
        |taz5| {
            let file = taz5.join("S600F6000_xiao120.csv");
            let mut lines: Vec<String> = std::fs::read_to_string(&file).unwrap().lines().map(String::from).collect();
            lines[41] = "2.0,wide".into();
            std::fs::write(&file, lines.join("\n")).unwrap();
        },
        &[
            "S600F6000_xiao120.csv:line 42",
            "expected two numbers `position_mm,width_mm`, got `2.0,wide`",
            "import_taz5",
        ],
    );
}

#[test]
fn empty_file() {
    fails_and_keeps_outputs(
        |taz5| std::fs::write(taz5.join("S400F3000_xiao120.csv"), "").unwrap(),
        &["S400F3000_xiao120.csv:line 1", "empty"],
    );
}

#[test]
fn file_name_that_does_not_parse() {
    fails_and_keeps_outputs(
        |taz5| std::fs::rename(taz5.join("S400F3000_xiao120.csv"), taz5.join("S400Fast_xiao120.csv")).unwrap(),
        &["S400Fast_xiao120.csv:file name", "expected a file name like `S800F9000_xiao120.csv`"],
    );
}

#[test]
fn missing_file_of_the_verified_release() {
    let tmp = tempfile::tempdir().unwrap();
    let raw = copy_raw(tmp.path());
    std::fs::remove_file(raw.join("taz6/S600F9000_ino120.csv")).unwrap();
    let spec = fsu_spec(tmp.path(), &raw);
    let err = fails(tmp.path(), &["run", spec.to_str().unwrap()]);
    assert!(err.contains("taz6/S600F9000_ino120.csv: missing") && err.contains("IISE-Co-learning"), "{err}");
    assert!(!tmp.path().join("out/fdm/line_summary.parquet").exists(), "nothing published from a failed run");
}

#[test]
fn missing_data_folder_says_where_to_get_it() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &tmp.path().join("nowhere"));
    let err = fails(tmp.path(), &["run", spec.to_str().unwrap()]);
    assert!(
        err.contains("dataset `fsu_raw`") && err.contains("does not exist") && err.contains("AMREPRO_DATA"),
        "{err}"
    );
}

#[test]
fn negative_feed_in_a_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let src = data_root().join("fsu-linewidth");
    ok(
        tmp.path(),
        &["datasets", "import", "fsu-linewidth", "--printer", "taz5", "--src", src.to_str().unwrap(), "--out", "ds"],
    );
    let lines = tmp.path().join("ds/taz5/lines.csv");
    let text = std::fs::read_to_string(&lines)
        .unwrap()
        .replace("S600F6000,S600F6000,600,100,", "S600F6000,S600F6000,600,-100,");
    std::fs::write(&lines, text).unwrap();
    let spec = tmp.path().join("mine.toml");
    let body = "[run]\nname = \"mine\"\n\n[dataset.mine]\npath = \"ds/taz5\"\n\n[stage.summary]\nkind = \"fdm.line_summary\"\ninputs = [\"mine\"]\n";
    std::fs::write(&spec, body).unwrap();
    let err = fails(tmp.path(), &["run", spec.to_str().unwrap()]);
    assert!(err.contains("lines.csv:line 6, field feed_mm_s: expected a positive number, got -100"), "{err}");
}

/// A spec with typos: each error names the spec file and the line or field.
#[test]
fn spec_typos_name_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let cases = [
        ("[run]\nname = \"x\"\n[stage.a]\nknd = \"fdm.import\"\n", "line 4"),
        ("[run]\nname = \"x\"\n[stage.a]\nkind = \"fdm.line_sumary\"\n", "stage.a.kind: unknown stage kind `fdm.line_sumary`; did you mean `fdm.line_summary`?"),
        ("[run]\nname = \"x\"\n[stage.a]\nkind = \"fdm.line_summary\"\ninputs = [\"b\"]\n", "stage.a.inputs: `b` is neither a dataset nor a stage"),
        ("[run]\nname = \"x\"\n[dataset.d]\npath = \".\"\n[stage.a]\nkind = \"fdm.line_summary\"\ninputs = [\"d\"]\nparams = { steady_to_mm = \"far\" }\n", "stage.a.params.steady_to_mm: expected number in [0, 10000]"),
        ("[run]\nname = \"x\"\n[dataset.d]\npath = \".\"\n[stage.a]\nkind = \"fdm.line_summary\"\ninputs = [\"d\"]\nparams = { steady_to_m = 1.0 }\n", "stage.a.params.steady_to_m: unknown parameter"),
        ("[run]\nname = \"x\"\n[stage.a]\nkind = \"fdm.line_summary\"\ninputs = [\"b\"]\n[stage.b]\nkind = \"fdm.line_summary\"\ninputs = [\"a\"]\n", "cycle among stages: a → b"),
        ("[run]\nname = \"x\"\n[dataset.d]\npath = \".\"\n[stage.a]\nkind = \"fdm.import\"\ninputs = [\"d\"]\n", "stage.a.params.printer: required"),
        ("[run]\nname = \"x\"\n[dataset.d]\npath = \".\"\n[stage.a]\nkind = \"fdm.import\"\ninputs = [\"d\", \"d\"]\nparams = { printer = \"taz5\" }\n", "stage.a.inputs: `fdm.import` takes its inputs in this order: raw (one: a folder of raw data (no dataset.toml)); got 2 input(s)"),
        ("[run]\nname = \"x\"\n[dataset.d]\npath = \".\"\n[stage.a]\nkind = \"fdm.line_summary\"\ninputs = [\"d\"]\n", "stage.a.inputs: role `widths` of `fdm.line_summary` takes a `fdm-widths` dataset (or a stage writing one); got `d`, a folder without dataset.toml"),
        ("[run]\nname = \"x\"\n[stage.g]\nkind = \"inkjet.generate_scans\"\nparams = { scenario = \"cuboid\" }\n[stage.a]\nkind = \"fdm.lag_model\"\ninputs = [\"g\"]\nparams = { start_blob = true }\n", "stage.a.inputs: role `widths` of `fdm.lag_model` takes a `fdm-widths` dataset (or a stage writing one); got `g`, a `inkjet.generate_scans` stage (writing a `inkjet-scans` dataset)"),
        ("[run]\nname = \"x\"\n[dataset.raw]\npath = \"/nonexistent/fsu\"\n[stage.t]\nkind = \"fdm.import\"\ninputs = [\"raw\"]\nparams = { printer = \"taz5\" }\n[stage.lag]\nkind = \"fdm.lag_model\"\ninputs = [\"t\"]\nparams = { start_blob = true }\n[stage.fig]\nkind = \"figure.fdm_r_surface\"\ninputs = [\"lag\"]\n", "stage.fig.inputs: role `loo` of `figure.fdm_r_surface` reads `r_surface.parquet`, which a `fdm.lag_model` stage does not write; got `lag`, a `fdm.lag_model` stage"),
        ("[run]\nname = \"x\"\n[stage.a]\nkind = \"inkjet.generate_scans\"\nparams = { scenario = \"cuboid\", effects = \"curing_shrinkage=0.01, nozle_bias=0.02\" }\n", "stage.a.params.effects: "),
        // A missing column: the printer's true widths stand in for the monitor's in the
        // compensation, but they carry no temperatures for the corners figure.
        ("[run]\nname = \"x\"\n[stage.seq]\nkind = \"thermal.generate_sequence\"\n[stage.monitor]\nkind = \"thermal.monitor\"\ninputs = [\"seq\"]\n[stage.truth]\nkind = \"thermal.true_widths_evaluate\"\ninputs = [\"seq\", \"monitor\"]\n[stage.comp]\nkind = \"thermal.compensate\"\ninputs = [\"seq\", \"monitor\", \"truth\"]\n[stage.fig]\nkind = \"figure.thermal_corners\"\ninputs = [\"truth\", \"comp\"]\n", "stage.fig.inputs: role `monitor` of `figure.thermal_corners` reads column `temp_c` of `widths.parquet`, which a `thermal.true_widths_evaluate` stage does not write; got `truth`"),
    ];
    for (i, (body, expected)) in cases.iter().enumerate() {
        let spec = tmp.path().join(format!("typo{i}.toml"));
        std::fs::write(&spec, body).unwrap();
        let err = fails(tmp.path(), &["run", spec.to_str().unwrap()]);
        assert!(err.contains(&format!("typo{i}.toml: ")), "names the file: {err}");
        assert!(err.contains(expected), "case {i}: expected `{expected}` in: {err}");
        assert!(!tmp.path().join("out").exists(), "nothing written for an invalid spec");
    }
}

/// Parameters valid one by one but not together are refused by the planner, before
/// anything runs, naming the spec, the stage and the field.
#[test]
fn steady_window_that_ends_before_it_starts() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    let text = std::fs::read_to_string(&spec).unwrap().replace("steady_from_mm = 50.0", "steady_from_mm = 90.0");
    std::fs::write(&spec, text).unwrap();
    let err = fails(tmp.path(), &["run", spec.to_str().unwrap()]);
    assert!(
        err.contains(
            "fsu_linewidth.toml: stage.line_summary.params.steady_to_mm: expected steady_from_mm < steady_to_mm, got 90 and 80"
        ),
        "{err}"
    );
    assert!(!tmp.path().join("out").exists(), "nothing ran");
}
