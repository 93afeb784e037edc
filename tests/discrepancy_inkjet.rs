//! The ink-jet discrepancy end to end: the shipped `specs/discrepancy_inkjet.toml`
//! prints three cylinders on the virtual printer (the paper's physics only, curing
//! shrinkage hidden, nozzle bias hidden) and the engine, reading only the
//! inkjet-scans format, names nothing on the first and the hidden cause on the others,
//! with a strength interval and a held-out gain; printers calibrated by the engine
//! print in closed loop with the paper's and the extended model, with intervals over
//! printers; the study spec runs with a cut power study; a print with too few layers for the test is refused with a clear message.

mod common;

use std::path::Path;

use common::*;
use tables::inkjet::control_gain;

#[test]
fn the_shipped_spec_names_each_hidden_cause_and_nothing_on_the_papers_physics() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "discrepancy_inkjet", tmp.path());
    ok(tmp.path(), &["run", "--out", "out", spec.to_str().unwrap()]);
    let out = tmp.path().join("out/discrepancy");
    let causes = read_table(&out.join("inkjet_causes.parquet"));
    let (dataset, mechanism) = (strings(&causes, "dataset"), strings(&causes, "mechanism"));
    let named: Vec<bool> = causes.column("named").unwrap().bool().unwrap().iter().map(|b| b.unwrap()).collect();
    let named_in = |d: &str| -> Vec<&str> {
        (0..causes.height()).filter(|&i| named[i] && dataset[i] == d).map(|i| mechanism[i].as_str()).collect()
    };
    assert_eq!(named_in("print_paper_physics"), Vec::<&str>::new());
    assert_eq!(named_in("print_curing_shrinkage"), ["curing_shrinkage"]);
    assert_eq!(named_in("print_nozzle_bias"), ["nozzle_bias"]);
    // The shrinkage's interval covers what the printer did (0.03).
    let extension = read_table(&out.join("inkjet_extension.parquet"));
    let (mech, lo, hi) = (strings(&extension, "mechanism"), floats(&extension, "ci_lo"), floats(&extension, "ci_hi"));
    let k = mech.iter().position(|m| m == "curing_shrinkage").unwrap();
    assert!(lo[k] <= 0.03 && 0.03 <= hi[k], "[{}, {}]", lo[k], hi[k]);
    // The extended models predict held-out layer blocks better, with intervals above 0.
    let gain = read_table(&out.join("inkjet_gain.parquet"));
    let (sets, ci_lo) = (strings(&gain, "dataset"), floats(&gain, "gain_ci_lo_pct"));
    for (d, lo) in sets.iter().zip(&ci_lo) {
        if d != "print_paper_physics" {
            assert!(*lo > 1.0, "{d}: gain interval from {lo} %");
        }
    }
    // The control gain: three controller models per effect, each over the same three
    // printers, intervals around every mean, the paper's controller against itself 0.
    let control = read_table(&out.join("inkjet_control_gain.parquet"));
    assert_eq!(control.height(), 9);
    let (controller, printers) =
        (strings(&control, control_gain::controller), control.column(control_gain::printers).unwrap().i64().unwrap());
    assert!(printers.iter().all(|n| n == Some(3)));
    let (rmsd, lo, hi) = (
        floats(&control, control_gain::rmsd_um),
        floats(&control, control_gain::rmsd_ci_lo),
        floats(&control, control_gain::rmsd_ci_hi),
    );
    let vs_paper = floats(&control, control_gain::rmsd_vs_paper_um);
    for i in 0..control.height() {
        assert!(lo[i] <= rmsd[i] && rmsd[i] <= hi[i] && rmsd[i] > 0.0, "row {i}");
        assert_eq!(vs_paper[i] == 0.0, controller[i] == "paper", "row {i}");
    }
    let trials = read_table(&out.join("inkjet_control_trials.parquet"));
    assert_eq!(trials.height(), 27);
    let section = std::fs::read_to_string(tmp.path().join("out/runs/discrepancy_inkjet/report/section.html")).unwrap();
    assert!(
        section.contains("curing shrinkage") && section.contains("nozzle bias") && section.contains("layer blocks")
    );
    assert!(
        section.contains("Does the extended model print better?")
            && section.contains("the extended controller's RMSD is")
    );
    for print in ["print_paper_physics", "print_curing_shrinkage", "print_nozzle_bias"] {
        let png = tmp.path().join(format!("out/runs/discrepancy_inkjet/residuals_{print}/discrepancy_residuals.png"));
        assert!(std::fs::metadata(&png).unwrap().len() > 20_000, "{}", png.display());
    }
}

#[test]
fn the_power_study_spec_runs_cut_to_a_few_prints() {
    let tmp = tempfile::tempdir().unwrap();
    let shipped = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/studies/discrepancy_inkjet_power.toml"),
    )
    .unwrap();
    let (study, control) = (
        "null_draws = 200, draws = 40",
        "printers = 20, curing_shrinkage = \"0.05\", volume_drift = \"0.002\", nozzle_bias = \"0.05\"",
    );
    assert!(shipped.contains(study) && shipped.contains(control), "the shipped study changed; update this test");
    let cut = shipped
        .replace(study, "null_draws = 2, draws = 1, radius_cells = 6, layers = 24, layers_per_group = 3")
        .replace(
            "inputs = [\"print_paper_physics\", \"print_curing_shrinkage\", \"print_nozzle_bias\"]",
            "inputs = [\"print_curing_shrinkage\"]",
        )
        .replace(
            control,
            "printers = 2, radius_cells = 6, calibration_layers = 24, layers_per_group = 3, curing_shrinkage = \"0.05\", volume_drift = \"\", nozzle_bias = \"\"",
        );
    let spec = tmp.path().join("study.toml");
    std::fs::write(&spec, cut).unwrap();
    ok(tmp.path(), &["run", "--out", "out", spec.to_str().unwrap()]);
    let power = read_table(&tmp.path().join("out/discrepancy/inkjet_power.parquet"));
    let effects = strings(&power, "effect");
    assert_eq!(effects.iter().filter(|e| *e == "none").count(), 1);
    assert!(effects.contains(&"nozzle_bias".to_string()) && effects.contains(&"substrate_tilt".to_string()));
    let draws = read_table(&tmp.path().join("out/discrepancy/inkjet_power_draws.parquet"));
    assert_eq!(draws.height(), 2 + 9);
    assert!(draws.column("p_coefficient_split").is_ok());
    let section =
        std::fs::read_to_string(tmp.path().join("out/runs/discrepancy_inkjet_power/report/section.html")).unwrap();
    assert!(section.contains("How often is a hidden effect named?"));
    let control = read_table(&tmp.path().join("out/discrepancy/inkjet_control_gain.parquet"));
    assert_eq!(strings(&control, control_gain::controller), ["paper", "mean_droplet", "extended"]);
    assert!(section.contains("Does the extended model print better?"));
}

#[test]
fn a_print_with_too_few_layers_is_refused_with_the_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = tmp.path().join("few.toml");
    std::fs::write(
        &spec,
        r#"[run]
name = "few"
title = "too few layers"
seed = 1

[stage.cuboid]
kind = "inkjet.generate_scans"
params = { scenario = "cuboid", variation_pct = 20.0 }

[stage.discrepancy]
kind = "inkjet.discrepancy"
inputs = ["cuboid"]
"#,
    )
    .unwrap();
    let err = fails(tmp.path(), &["run", "--out", "out", spec.to_str().unwrap()]);
    assert!(err.contains("dataset `cuboid`") && err.contains("groups of 4 layers"), "{err}");
    assert!(!tmp.path().join("out/runs/few/manifest.json").exists());
}
