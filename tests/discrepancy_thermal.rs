//! The thermal discrepancy end to end: the shipped `specs/discrepancy_thermal.toml`
//! films four virtual prints (the printer's own physics, a camera latency, heat carried
//! from layer to layer, a flow lag with a τ off the nominal) and the engine, reading
//! only the monitor's tables and the sequence's process, names nothing on the first,
//! the latency on the second with an interval covering what the camera did, and no
//! wrong cause on the others; the report section is written from the tables.

mod common;

use std::path::Path;

use common::*;
use polars::prelude::{DataFrame, ParquetReader, SerReader};

fn read(path: &Path) -> DataFrame {
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

fn strings(df: &DataFrame, column: &str) -> Vec<String> {
    df.column(column).unwrap().str().unwrap().iter().map(|s| s.unwrap_or_default().to_string()).collect()
}

fn floats(df: &DataFrame, column: &str) -> Vec<f64> {
    df.column(column).unwrap().f64().unwrap().iter().map(|x| x.unwrap_or(f64::NAN)).collect()
}

#[test]
fn the_shipped_spec_names_the_camera_latency_and_nothing_wrong() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "discrepancy_thermal", tmp.path());
    ok(tmp.path(), &["run", "--out", "out", spec.to_str().unwrap()]);
    let out = tmp.path().join("out/discrepancy");
    let causes = read(&out.join("thermal_causes.parquet"));
    let (dataset, mechanism) = (strings(&causes, "dataset"), strings(&causes, "mechanism"));
    let named: Vec<bool> = causes.column("named").unwrap().bool().unwrap().iter().map(|b| b.unwrap()).collect();
    let named_in = |d: &str| -> Vec<&str> {
        (0..causes.height()).filter(|&i| named[i] && dataset[i] == d).map(|i| mechanism[i].as_str()).collect()
    };
    assert_eq!(named_in("print_paper_physics"), Vec::<&str>::new());
    assert_eq!(named_in("print_camera_latency"), ["camera_latency"]);
    assert_eq!(named_in("print_tau_mismatch"), Vec::<&str>::new(), "no candidate describes a τ error");
    let heat = named_in("print_layer_heat");
    assert!(heat.is_empty() || heat == ["layer_heat_accumulation"], "{heat:?}");
    // Eight layers per print, each a group.
    let groups = causes.column("groups").unwrap().i64().unwrap();
    assert!(groups.iter().all(|g| g == Some(8)));
    // The latency's interval covers what the camera did (10 ms).
    let extension = read(&out.join("thermal_extension.parquet"));
    let (param, lo, hi) = (strings(&extension, "parameter"), floats(&extension, "ci_lo"), floats(&extension, "ci_hi"));
    let k = param.iter().position(|p| p == "latency_s").unwrap();
    assert!(lo[k] <= 0.01 && 0.01 <= hi[k], "[{}, {}]", lo[k], hi[k]);
    let gain = read(&out.join("thermal_gain.parquet"));
    let (sets, ci_lo) = (strings(&gain, "dataset"), floats(&gain, "gain_ci_lo_pct"));
    let latency = sets.iter().position(|d| d == "print_camera_latency").unwrap();
    assert!(ci_lo[latency] > 0.0, "the extension predicts held-out layers better");
    let section = std::fs::read_to_string(tmp.path().join("out/runs/discrepancy_thermal/report/section.html")).unwrap();
    assert!(section.contains("camera latency") && section.contains("8 layers"), "{section}");
}

#[test]
fn an_odd_number_of_inputs_is_refused_with_the_pairs_it_expects() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = tmp.path().join("odd.toml");
    std::fs::write(
        &spec,
        r#"[run]
name = "odd"
title = "odd"
seed = 1

[stage.print]
kind = "thermal.generate_sequence"
params = { layers = 2 }

[stage.other_print]
kind = "thermal.generate_sequence"
params = { layers = 2 }

[stage.monitor]
kind = "thermal.monitor"
inputs = ["print"]

[stage.discrepancy]
kind = "thermal.discrepancy"
inputs = ["print", "monitor", "other_print"]
"#,
    )
    .unwrap();
    let err = fails(tmp.path(), &["run", "--out", "out", spec.to_str().unwrap()]);
    assert!(err.contains("(sequence, monitor) pairs") && err.contains("3 inputs"), "{err}");
}
