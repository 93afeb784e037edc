//! Paper 000 on the real data, end to end through the shipped `specs/ren2021.toml`:
//! the "done when" numbers of the reproduction (leave-one-out RMSE range and trend on
//! the Taz 5, the size of the transfer table, the model column) and the figures.

mod common;

use std::path::Path;

use common::*;
use polars::prelude::{DataFrame, ParquetReader, SerReader};
use tables::fdm::{loo, transfer_cv};

fn read(path: &Path) -> DataFrame {
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

fn f64s(df: &DataFrame, name: &str) -> Vec<f64> {
    df.column(name).unwrap().f64().unwrap().iter().map(|v| v.unwrap()).collect()
}

fn strs(df: &DataFrame, name: &str) -> Vec<String> {
    df.column(name).unwrap().str().unwrap().iter().map(|v| v.unwrap().to_string()).collect()
}

/// Least-squares slope of `y` on `x`.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    sxy / sxx
}

#[test]
fn reproduces_table_ii_and_fig9_tables_on_the_real_data() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "ren2021", &data_root().join("fsu-linewidth"));
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let out = tmp.path().join("out/fdm");

    let folds = read(&out.join("loo.parquet"));
    assert_eq!(folds.height(), 36, "2 printers × 9 lines × 2 models");
    let (printer, model) = (strs(&folds, loo::printer), strs(&folds, loo::model));
    let (rmse, feed) = (f64s(&folds, loo::rmse_mm), f64s(&folds, loo::feed_mm_s));
    let taz5: Vec<usize> = (0..folds.height()).filter(|&i| printer[i] == "taz5" && model[i] == "piecewise").collect();
    assert_eq!(taz5.len(), 9);
    let mut taz5_rmse: Vec<f64> = taz5.iter().map(|&i| rmse[i]).collect();
    for r in &taz5_rmse {
        assert!(
            (0.015..=0.10).contains(r),
            "every Taz 5 LOO RMSE in [0.015, 0.10] mm (paper 0.030-0.068): {taz5_rmse:?}"
        );
    }
    taz5_rmse.sort_by(f64::total_cmp);
    assert!((0.03..=0.07).contains(&taz5_rmse[4]), "median {} in [0.03, 0.07] mm (paper 0.045)", taz5_rmse[4]);
    let feeds: Vec<f64> = taz5.iter().map(|&i| feed[i]).collect();
    let errors: Vec<f64> = taz5.iter().map(|&i| rmse[i]).collect();
    assert!(slope(&feeds, &errors) > 0.0, "RMSE rises with feed on average (paper: worst at 150, best at 50 mm/s)");

    let transfer = read(&out.join("transfer_cv.parquet"));
    let subsets: std::collections::BTreeSet<(String, String)> =
        strs(&transfer, transfer_cv::subset).into_iter().zip(strs(&transfer, transfer_cv::method)).collect();
    assert_eq!(subsets.len(), 510 * 3, "every subset of n = 1..8 of 9 lines, 3 methods");
    // Each subset of n lines is tested on the other 9 − n: Σ C(9,n)(9 − n) = 9·(2^8 − 1) = 2295 per method.
    assert_eq!(transfer.height(), 3 * 9 * 255);

    let comparison = read(&out.join("paper_comparison.parquet"));
    assert!(comparison.height() > 9);
    let run = tmp.path().join("out/runs/ren2021");
    for figure in
        ["fig6_taz5/loo_predictions.png", "r_surface_fig/r_surface.png", "fig9/transfer_cv.png", "fig7/infill.png"]
    {
        assert!(run.join(figure).is_file(), "{figure}");
    }
    let report = std::fs::read_to_string(tmp.path().join("out/report/index.html")).unwrap();
    assert!(report.contains("Paper 000 vs ours") && report.contains("Where and why ours differs"));
}
