//! End to end on the real FSU data: a full run, the cache, dry runs after a parameter
//! edit, byte-identical outputs, `graph`, `stages` and the importer CLI.

mod common;

use common::*;

#[test]
fn run_publishes_18_lines_then_caches_everything() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    let first = ok(tmp.path(), &["run", spec.to_str().unwrap()]);
    assert!(first.contains("executed 5 of 5 stages"), "{first}");
    let summary = tmp.path().join("out/fdm/line_summary.parquet");
    assert_eq!(parquet_rows(&summary), 18, "9 Taz 5 + 9 Taz 6 lines");
    for figure in
        ["profiles_taz5/width_profiles.png", "profiles_taz5/width_profiles.svg", "profiles_taz6/width_profiles.png"]
    {
        assert!(tmp.path().join("out/runs/fsu_linewidth").join(figure).is_file(), "{figure}");
    }
    let report = std::fs::read_to_string(tmp.path().join("out/report/index.html")).unwrap();
    assert!(report.contains("fdm/line_summary.parquet") && report.contains("width_profiles.png"));
    let second = ok(tmp.path(), &["run", spec.to_str().unwrap()]);
    assert!(second.contains("nothing executed"), "{second}");
    assert!(!second.contains("  ran "), "{second}");
}

#[test]
fn dry_run_after_a_param_edit_lists_exactly_the_affected_stages() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let text = std::fs::read_to_string(&spec).unwrap().replace("steady_to_mm = 80.0", "steady_to_mm = 85.0");
    std::fs::write(&spec, text).unwrap();
    let dry = ok(tmp.path(), &["run", "--dry-run", spec.to_str().unwrap()]);
    let would: Vec<&str> = dry.lines().filter(|l| l.contains("would run ")).collect();
    assert_eq!(would.len(), 3, "line_summary and the two figures that read it:\n{dry}");
    assert!(would.iter().any(|l| l.contains("line_summary") && l.contains("param steady_to_mm: 80 → 85")), "{dry}");
    assert!(
        would.iter().any(|l| l.contains("profiles_taz5") && l.contains("input `line_summary` will be rebuilt")),
        "{dry}"
    );
    assert!(dry.contains("cached   import_taz5") && dry.contains("cached   import_taz6"), "{dry}");
    let rerun = ok(tmp.path(), &["run", spec.to_str().unwrap()]);
    assert!(rerun.contains("executed 3 of 5 stages"), "{rerun}");
}

#[test]
fn only_and_force_rerun_one_stage() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let forced = ok(tmp.path(), &["run", "--only", "line_summary", "--force", spec.to_str().unwrap()]);
    assert!(forced.contains("ran      line_summary") && forced.contains("--force"), "{forced}");
    assert!(forced.contains("cached   import_taz5") && !forced.contains("profiles_taz5"), "{forced}");
    let manifest = std::fs::read_to_string(tmp.path().join("out/runs/fsu_linewidth/manifest.json")).unwrap();
    assert!(
        manifest.contains("\"profiles_taz5\"") && manifest.contains("not selected by --only"),
        "the manifest still covers every stage"
    );
    let err = fails(tmp.path(), &["run", "--only", "line_sumary", spec.to_str().unwrap()]);
    assert!(err.contains("no such stage"), "{err}");
}

#[test]
fn version_names_the_code_every_stage_record_holds() {
    let tmp = tempfile::tempdir().unwrap();
    let version = ok(tmp.path(), &["--version"]);
    let field = |name: &str| {
        version.lines().find_map(|l| l.strip_prefix(name)).unwrap_or_else(|| panic!("no `{name}` in:\n{version}"))
    };
    let hex = |code: &str| code.len() == 16 && code.chars().all(|c| c.is_ascii_hexdigit());
    assert!(hex(field("code fingerprint: ")), "{version}");
    // Each crate's code: the kinds it defines are cached on it.
    let by_crate: std::collections::BTreeMap<&str, &str> =
        field("code by crate: ").split(", ").filter_map(|c| c.split_once(' ')).collect();
    assert!(by_crate.values().all(|c| hex(c)) && by_crate["stages"] != by_crate["reports"], "{version}");
    let built_by = field("built by: ");
    assert!(built_by.starts_with("rustc ") && built_by.contains("; target: "), "{version}");
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let manifest = std::fs::read_to_string(tmp.path().join("out/runs/fsu_linewidth/manifest.json")).unwrap();
    let manifest: serde_json::Value = serde_json::from_str(&manifest).unwrap();
    let stages = manifest["stages"].as_array().expect("a stages list");
    assert_eq!(stages.len(), 5);
    for stage in stages {
        let crate_name = if stage["kind"].as_str().unwrap().starts_with("figure.") { "reports" } else { "stages" };
        assert_eq!(stage["code_fingerprint"], by_crate[crate_name], "{stage}");
        let parts = stage["code_parts"].as_object().expect("the parts of its code");
        assert!(parts.contains_key(crate_name) && parts.contains_key("Cargo.lock"), "{stage}");
        assert_eq!(parts.contains_key("reports"), crate_name == "reports", "{stage}");
    }
}

#[test]
fn same_spec_gives_byte_identical_parquet() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    ok(tmp.path(), &["run", "-q", "--out", "a", spec.to_str().unwrap()]);
    ok(tmp.path(), &["run", "-q", "--out", "b", spec.to_str().unwrap()]);
    for table in ["fdm/line_summary.parquet", "fdm/widths_taz5.parquet", "fdm/widths_taz6.parquet"] {
        let a = std::fs::read(tmp.path().join("a").join(table)).unwrap();
        let b = std::fs::read(tmp.path().join("b").join(table)).unwrap();
        assert!(a == b, "{table} differs between two runs of the same spec");
    }
}

#[test]
fn graph_and_stage_listing() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = fsu_spec(tmp.path(), &data_root().join("fsu-linewidth"));
    let dot = ok(tmp.path(), &["graph", spec.to_str().unwrap()]);
    assert!(
        dot.contains("\"dataset:fsu_raw\" -> \"import_taz5\"") && dot.contains("\"line_summary\" -> \"profiles_taz5\""),
        "{dot}"
    );
    let mermaid = ok(tmp.path(), &["graph", "--format", "mermaid", spec.to_str().unwrap()]);
    assert!(mermaid.starts_with("flowchart LR") && mermaid.contains("import_taz5 --> line_summary"), "{mermaid}");
    let stages = ok(tmp.path(), &["stages"]);
    assert!(
        stages.contains("fdm.line_summary") && stages.contains("steady_from_mm") && stages.contains("paper 000"),
        "{stages}"
    );
}

/// docs/STAGES.md is generated from the registry; `UPDATE_DOCS=1` rewrites it.
#[test]
fn stages_doc_is_current() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let generated = ok(root, &["stages", "--markdown"]);
    let doc = root.join("docs/STAGES.md");
    if std::env::var("UPDATE_DOCS").is_ok() {
        std::fs::write(&doc, &generated).unwrap();
    }
    let current = std::fs::read_to_string(&doc).unwrap_or_default();
    assert!(
        current == generated,
        "docs/STAGES.md is stale: run `UPDATE_DOCS=1 cargo test --release --test run_fsu stages_doc`"
    );
}

#[test]
fn import_cli_writes_one_dataset_per_printer() {
    let tmp = tempfile::tempdir().unwrap();
    let src = data_root().join("fsu-linewidth");
    let out = ok(tmp.path(), &["datasets", "import", "fsu-linewidth", "--src", src.to_str().unwrap(), "--out", "ds"]);
    assert!(out.contains("ds/taz5") && out.contains("ds/taz6"), "{out}");
    let lines = std::fs::read_to_string(tmp.path().join("ds/taz6/lines.csv")).unwrap();
    assert_eq!(lines.lines().count(), 10, "header + 9 lines");
    assert!(lines.contains("S800F9000,S800F9000,800,150,8,120,widths/S800F9000.csv"), "{lines}");
    let manifest = std::fs::read_to_string(tmp.path().join("ds/taz6/dataset.toml")).unwrap();
    assert!(manifest.contains("kind = \"fdm-widths\"") && manifest.contains("type = \"measured\""), "{manifest}");
}
