//! `amrepro datasets generate inkjet`: writes an inkjet-scans dataset that reads back,
//! records its effects, and rejects unknown effects, bad strengths and unpaired flags
//! with a clear message and a non-zero exit, writing nothing.

mod common;

use common::*;
use datasets::inkjet::InkjetScans;
use datasets::manifest::Provenance;
use polars::prelude::{ParquetReader, SerReader};
use tables::inkjet::scan_residuals;

#[test]
fn generates_a_readable_dataset_with_its_effects() {
    let tmp = tempfile::tempdir().unwrap();
    let args = [
        "datasets",
        "generate",
        "inkjet",
        "--scenario",
        "cuboid",
        "--seed",
        "3",
        "--effect",
        "curing_shrinkage",
        "--strength",
        "0.1",
        "--effect",
        "substrate_tilt",
        "--strength",
        "-2",
        "--controller",
        "closed_loop",
        "--out",
        "scans",
    ];
    let stdout = ok(tmp.path(), &args);
    assert!(stdout.contains("curing_shrinkage=0.1,substrate_tilt=-2"), "{stdout}");
    let dataset = InkjetScans::read(&tmp.path().join("scans")).unwrap();
    assert_eq!((dataset.grid.scenario.as_str(), dataset.grid.controller.as_str()), ("cuboid", "closed_loop"));
    let Provenance::Virtual { effects, seed, .. } = &dataset.manifest.provenance else { panic!("virtual provenance") };
    assert_eq!(*seed, 3);
    assert_eq!((effects["curing_shrinkage"], effects["substrate_tilt"]), (0.1, -2.0));
    assert!(dataset.layers() >= 2 && tmp.path().join("scans/truth/heights.csv").is_file());
    // The same command again gives the same files.
    let before = std::fs::read(tmp.path().join("scans/scans.csv")).unwrap();
    ok(tmp.path(), &args);
    assert_eq!(std::fs::read(tmp.path().join("scans/scans.csv")).unwrap(), before);
}

#[test]
fn bad_effects_fail_clearly_and_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let base = ["datasets", "generate", "inkjet", "--scenario", "cuboid", "--seed", "1", "--out", "scans"];
    let with = |extra: &[&'static str]| [&base[..], extra].concat();
    let err = fails(tmp.path(), &with(&["--effect", "warp", "--strength", "0.1"]));
    assert!(err.contains("unknown effect `warp`") && err.contains("curing_shrinkage"), "{err}");
    let err = fails(tmp.path(), &with(&["--effect", "levelling_flow", "--strength", "0.9"]));
    assert!(err.contains("levelling_flow") && err.contains("outside [0, 0.25]"), "{err}");
    let err = fails(tmp.path(), &with(&["--effect", "nozzle_bias"]));
    assert!(err.contains("every --effect needs one --strength"), "{err}");
    let err = fails(tmp.path(), &with(&["--effect", "nozzle_bias", "--strength", "lots"]));
    assert!(err.contains("lots"), "{err}");
    let err =
        fails(tmp.path(), &["datasets", "generate", "inkjet", "--scenario", "sphere", "--seed", "1", "--out", "x"]);
    assert!(err.contains("sphere"), "{err}");
    assert!(!tmp.path().join("scans").exists() && !tmp.path().join("x").exists());
}

#[test]
fn a_generated_dataset_declared_in_a_spec_is_analysed() {
    let tmp = tempfile::tempdir().unwrap();
    let args = [
        "datasets",
        "generate",
        "inkjet",
        "--scenario",
        "cuboid",
        "--seed",
        "5",
        "--layers",
        "4",
        "--effect",
        "volume_drift",
        "--strength",
        "0.01",
        "--out",
        "mine",
    ];
    ok(tmp.path(), &args);
    let spec = tmp.path().join("mine.toml");
    std::fs::write(
        &spec,
        "[run]\nname = \"mine\"\ntitle = \"my scans\"\nseed = 1\n\n[dataset.mine]\npath = \"mine\"\n\n\
         [stage.residuals]\nkind = \"inkjet.scan_residuals\"\ninputs = [\"mine\"]\n\
         publish = { \"scan_residuals.parquet\" = \"mine/scan_residuals.parquet\" }\n",
    )
    .unwrap();
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let path = tmp.path().join("out/mine/scan_residuals.parquet");
    let df = ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap();
    assert_eq!(df.height(), 4);
    let effects = df.column(scan_residuals::effects).unwrap().str().unwrap();
    assert_eq!(effects.get(0), Some("volume_drift=0.01"));
    // Droplets grow by 1 % per layer: the model's under-prediction grows layer by layer.
    let bias: Vec<f64> =
        df.column(scan_residuals::bias_um).unwrap().f64().unwrap().iter().map(|v| v.unwrap()).collect();
    assert!(bias[3] > bias[0], "{bias:?}");
}
