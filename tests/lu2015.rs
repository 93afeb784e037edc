//! Paper 002 through the shipped `specs/lu2015.toml`: the "done when" numbers of the
//! reproduction on the simulated truth printer (cylinder Figs 11-12, cuboid Table II,
//! exact recovery Sec. IV-C, pipe junction Figs 13-15), and the model residuals on the
//! virtual inkjet-scans datasets.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::*;
use polars::prelude::{DataFrame, ParquetReader, SerReader};
use tables::inkjet::{edge_deformation, recovery, scan_residuals, summary};

fn read(path: &Path) -> DataFrame {
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

/// (scenario, controller, variation %, open-loop layers or 0).
type Key = (String, String, i64, i64);

/// Key → (mean error µm, std µm, RMSD µm).
fn summary(df: &DataFrame) -> BTreeMap<Key, (f64, f64, f64)> {
    let s = |n: &str| df.column(n).unwrap().str().unwrap().iter().map(|v| v.unwrap().to_string()).collect::<Vec<_>>();
    let f = |n: &str| df.column(n).unwrap().f64().unwrap().iter().map(|v| v.unwrap()).collect::<Vec<_>>();
    let (scenario, controller, pct) = (s(summary::scenario), s(summary::controller), f(summary::variation_pct));
    let (mean, std, rmsd) = (f(summary::mean_err_um), f(summary::std_um), f(summary::rmsd_um));
    let layers: Vec<i64> = df.column(summary::layers).unwrap().i64().unwrap().iter().map(|v| v.unwrap()).collect();
    // Closed-loop layer counts vary; key them as 0.
    (0..df.height())
        .map(|i| {
            let l = if controller[i] == "open_loop" { layers[i] } else { 0 };
            ((scenario[i].clone(), controller[i].clone(), pct[i].round() as i64, l), (mean[i], std[i], rmsd[i]))
        })
        .collect()
}

#[test]
fn reproduces_the_cylinder_cuboid_and_recovery_targets() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "lu2015", tmp.path()); // no measured data: simulated printer
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let rows = summary(&read(&tmp.path().join("out/inkjet/summary.parquet")));
    let get = |s: &str, c: &str, p: i64, l: i64| rows[&(s.to_string(), c.to_string(), p, l)];
    // Figs 11-12: open-loop mean error 44.1 and 84.7 µm; ours within ±30 %.
    for (pct, paper_um) in [(20, 44.1), (40, 84.7)] {
        let (open, _, _) = get("cylinder", "open_loop", pct, 53);
        assert!((open - paper_um).abs() <= 0.3 * paper_um, "open loop {pct} %: {open} µm vs paper {paper_um}");
        let (closed, std, _) = get("cylinder", "closed_loop", pct, 0);
        assert!(closed < 2.0 && std < 6.0, "closed loop {pct} %: mean error {closed} µm, std {std} µm");
    }
    // Table II: closed-loop RMSD at most 60 % of open-loop (paper 4.4 / 8.7), for the
    // 3-layer and the 4-layer open-loop cuboid.
    let (_, _, closed_rmsd) = get("cuboid", "closed_loop", 20, 0);
    for layers in [3, 4] {
        let (_, _, open_rmsd) = get("cuboid", "open_loop", 20, layers);
        assert!(closed_rmsd <= 0.6 * open_rmsd, "cuboid RMSD {closed_rmsd} vs open {open_rmsd} ({layers} layers)");
    }
    // Figs 13-14: the closed loop flattens the two-material block and cuts the part's
    // edge deformation.
    let (open_block, _, _) = get("pipe_junction", "open_loop", 20, 26);
    let (closed_block, _, _) = get("pipe_junction", "closed_loop", 20, 0);
    assert!(closed_block < 2.0 && closed_block < open_block, "{closed_block} vs {open_block}");
    let edges = read(&tmp.path().join("out/inkjet/edge_deformation.parquet"));
    let rmse = |c: &str, r: &str| {
        let (ctl, reg) = (
            edges.column(edge_deformation::controller).unwrap().str().unwrap(),
            edges.column(edge_deformation::region).unwrap().str().unwrap(),
        );
        let i = (0..edges.height()).find(|&i| ctl.get(i) == Some(c) && reg.get(i) == Some(r)).unwrap();
        edges.column(edge_deformation::rmse_um).unwrap().f64().unwrap().get(i).unwrap()
    };
    for region in ["edge", "interior"] {
        assert!(rmse("closed_loop", region) < 0.6 * rmse("open_loop", region), "{region}");
    }
    // Model residuals on the virtual scans: one row per layer for each of 6 datasets;
    // curing shrinkage makes the model over-predict (negative bias) more than no effect.
    let residuals = read(&tmp.path().join("out/inkjet/scan_residuals.parquet"));
    assert_eq!(residuals.height(), 6 * 53);
    let effects = residuals.column(scan_residuals::effects).unwrap().str().unwrap();
    let bias = residuals.column(scan_residuals::bias_um).unwrap().f64().unwrap();
    let mean_bias = |name: &str| {
        let idx: Vec<usize> = (0..residuals.height()).filter(|&i| effects.get(i) == Some(name)).collect();
        idx.iter().map(|&i| bias.get(i).unwrap()).sum::<f64>() / idx.len() as f64
    };
    assert!(mean_bias("curing_shrinkage=0.05") < mean_bias("none") - 0.2);
    // Sec. IV-C: the exact pattern found in 50 of 50 trials.
    let recovery = read(&tmp.path().join("out/inkjet/recovery.parquet"));
    let recovered =
        recovery.column(recovery::recovered).unwrap().bool().unwrap().iter().filter(|v| *v == Some(true)).count();
    assert_eq!((recovery.height(), recovered), (50, 50));
    let comparison = read(&tmp.path().join("out/inkjet/paper_comparison.parquet"));
    // 12 numbers of Figs 11-12 and Table II, the recovery count, Table II against the 3-
    // and 4-layer cuboid (4), the pipe junction's edge/interior RMS open and closed (4),
    // mean RMS and bias of the residuals for 6 datasets (12).
    assert_eq!(comparison.height(), 13 + 4 + 4 + 12);
    for (figure, file) in [
        ("fig11", "inkjet_height_maps.png"),
        ("fig12", "inkjet_height_maps.png"),
        ("fig23_24", "inkjet_height_maps.png"),
        ("fig8", "inkjet_model_vs_scan.png"),
        ("fig21_22", "inkjet_model_vs_scan.png"),
        ("fig13_14", "inkjet_pipe_junction.png"),
    ] {
        assert!(tmp.path().join("out/runs/lu2015").join(figure).join(file).is_file(), "{figure}");
    }
    // The generated scans are an inkjet-scans dataset any reader can open.
    let scans = datasets::inkjet::InkjetScans::read(&tmp.path().join("out/runs/lu2015/scans_none")).unwrap();
    assert_eq!((scans.grid.scenario.as_str(), scans.layers()), ("cylinder", 53));
    let report = std::fs::read_to_string(tmp.path().join("out/report/index.html")).unwrap();
    assert!(report.contains("Paper 002 vs ours") && report.contains("Where and why ours differs"));
}
