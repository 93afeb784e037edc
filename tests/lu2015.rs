//! Paper 002 through the shipped `specs/lu2015.toml`: the "done when" numbers of the
//! reproduction on the simulated truth printer (cylinder Figs 11-12, cuboid Table II,
//! exact recovery Sec. IV-C).

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::*;
use polars::prelude::{DataFrame, ParquetReader, SerReader};

fn read(path: &Path) -> DataFrame {
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

/// (scenario, controller, variation %) → (mean error µm, std µm, RMSD µm).
fn summary(df: &DataFrame) -> BTreeMap<(String, String, i64), (f64, f64, f64)> {
    let s = |n: &str| df.column(n).unwrap().str().unwrap().iter().map(|v| v.unwrap().to_string()).collect::<Vec<_>>();
    let f = |n: &str| df.column(n).unwrap().f64().unwrap().iter().map(|v| v.unwrap()).collect::<Vec<_>>();
    let (scenario, controller, pct) = (s("scenario"), s("controller"), f("variation_pct"));
    let (mean, std, rmsd) = (f("mean_err_um"), f("std_um"), f("rmsd_um"));
    (0..df.height())
        .map(|i| ((scenario[i].clone(), controller[i].clone(), pct[i].round() as i64), (mean[i], std[i], rmsd[i])))
        .collect()
}

#[test]
fn reproduces_the_cylinder_cuboid_and_recovery_targets() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "lu2015", tmp.path()); // no measured data: simulated printer
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let rows = summary(&read(&tmp.path().join("out/inkjet/summary.parquet")));
    let get = |s: &str, c: &str, p: i64| rows[&(s.to_string(), c.to_string(), p)];
    // Figs 11-12: open-loop mean error 44.1 and 84.7 µm; ours within ±30 %.
    for (pct, paper_um) in [(20, 44.1), (40, 84.7)] {
        let (open, _, _) = get("cylinder", "open_loop", pct);
        assert!((open - paper_um).abs() <= 0.3 * paper_um, "open loop {pct} %: {open} µm vs paper {paper_um}");
        let (closed, std, _) = get("cylinder", "closed_loop", pct);
        assert!(closed < 2.0 && std < 6.0, "closed loop {pct} %: mean error {closed} µm, std {std} µm");
    }
    // Table II: closed-loop RMSD at most 60 % of open-loop (paper 4.4 / 8.7).
    let (_, _, open_rmsd) = get("cuboid", "open_loop", 20);
    let (_, _, closed_rmsd) = get("cuboid", "closed_loop", 20);
    assert!(closed_rmsd <= 0.6 * open_rmsd, "cuboid RMSD {closed_rmsd} vs open {open_rmsd}");
    // Sec. IV-C: the exact pattern found in 50 of 50 trials.
    let recovery = read(&tmp.path().join("out/inkjet/recovery.parquet"));
    let recovered = recovery.column("recovered").unwrap().bool().unwrap().iter().filter(|v| *v == Some(true)).count();
    assert_eq!((recovery.height(), recovered), (50, 50));
    let comparison = read(&tmp.path().join("out/inkjet/paper_comparison.parquet"));
    assert_eq!(comparison.height(), 13, "12 numbers of Figs 11-12 and Table II, plus the recovery count");
    for figure in ["fig11", "fig12"] {
        assert!(tmp.path().join("out/runs/lu2015").join(figure).join("inkjet_height_maps.png").is_file(), "{figure}");
    }
    let report = std::fs::read_to_string(tmp.path().join("out/report/index.html")).unwrap();
    assert!(report.contains("Paper 002 vs ours") && report.contains("Where and why ours differs"));
}
