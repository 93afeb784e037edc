//! Paper 000 from photos end to end through the shipped `specs/ren2021_virtual.toml`:
//! the segmentation's accuracy against the virtual printer's truth, the virtual printer
//! against the real lines, paper 000's leave-one-out on the photos beside the real
//! lines', and the discrepancy engine naming a hidden effect in photos and nothing in
//! clean ones; then `amrepro datasets generate fdm` and photos a lab could get wrong.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use common::*;
use polars::prelude::{DataFrame, ParquetReader, SerReader};
use tables::discrepancy::fdm::{causes, extension};
use tables::fdm::{agreement, loo, segment_accuracy, segment_diagnostics, transfer_cv};

fn read(path: &Path) -> DataFrame {
    ParquetReader::new(std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())))
        .finish()
        .unwrap()
}

fn f64s(df: &DataFrame, name: &str) -> Vec<f64> {
    df.column(name).unwrap().f64().unwrap().iter().map(|v| v.unwrap_or(f64::NAN)).collect()
}

fn strs(df: &DataFrame, name: &str) -> Vec<String> {
    df.column(name).unwrap().str().unwrap().iter().map(|v| v.unwrap().to_string()).collect()
}

fn bools(df: &DataFrame, name: &str) -> Vec<bool> {
    df.column(name).unwrap().bool().unwrap().iter().map(|v| v.unwrap()).collect()
}

fn median(v: Vec<f64>) -> f64 {
    models::stats::finite_median(v)
}

#[test]
fn photos_of_the_virtual_printers_reproduce_paper_000_and_hide_what_the_engine_finds() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "ren2021_virtual", &data_root().join("fsu-linewidth"));
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let out = tmp.path().join("out/fdm_virtual");

    // Segmentation: at 40 px/mm every photo within 0.01 mm RMSE and 0.005 mm bias, and
    // the edge fit beats the threshold count on every photo at every scale.
    let acc = read(&out.join(segment_accuracy::TABLE.file()));
    let (line, method, scale) = (
        strs(&acc, segment_accuracy::line_id),
        strs(&acc, segment_accuracy::method),
        f64s(&acc, segment_accuracy::px_per_mm),
    );
    let (rmse, bias, printer) = (
        f64s(&acc, segment_accuracy::rmse_mm),
        f64s(&acc, segment_accuracy::bias_mm),
        strs(&acc, segment_accuracy::printer),
    );
    let mut by_photo: BTreeMap<(String, String, u64), BTreeMap<String, f64>> = BTreeMap::new();
    for i in 0..acc.height() {
        assert!(rmse[i].is_finite(), "photo {} at {} px/mm was not measured", line[i], scale[i]);
        if method[i] == "edge_fit" && scale[i] == 40.0 {
            assert!(rmse[i] <= 0.01 && bias[i].abs() <= 0.005, "{} {}: {} {}", printer[i], line[i], rmse[i], bias[i]);
        }
        let key = (printer[i].clone(), line[i].clone(), scale[i] as u64);
        by_photo.entry(key).or_default().insert(method[i].clone(), rmse[i]);
    }
    let scales: std::collections::BTreeSet<u64> = by_photo.keys().map(|k| k.2).collect();
    assert_eq!(scales.into_iter().collect::<Vec<_>>(), [10, 20, 40]);
    for (photo, methods) in &by_photo {
        assert!(methods["edge_fit"] < methods["threshold"], "{photo:?}: {methods:?}");
    }

    // The virtual printers against the real lines, each held out of the calibration.
    let agreement = read(&out.join(agreement::TABLE.file()));
    // Pooled over a printer's lines, the real lines' RMSE is about the virtual lines' own
    // scatter: a real line is like one more virtual line.
    let (ap, rmse, scatter) = (
        strs(&agreement, agreement::printer),
        f64s(&agreement, agreement::rmse_mm),
        f64s(&agreement, agreement::virtual_scatter_mm),
    );
    assert_eq!(agreement.height(), 18);
    for p in ["taz5", "taz6"] {
        let pooled = |v: &[f64]| {
            let sq: Vec<f64> = (0..ap.len()).filter(|&i| ap[i] == p).map(|i| v[i] * v[i]).collect();
            (sq.iter().sum::<f64>() / sq.len() as f64).sqrt()
        };
        let ratio = pooled(&rmse) / pooled(&scatter);
        assert!((0.7..=1.4).contains(&ratio), "{p}: pooled RMSE over pooled virtual scatter {ratio}");
    }

    // Paper 000's leave-one-out on the photos: every line measured, medians of the lag
    // model within 30 % of the real lines'.
    let diagnostics = read(&out.join(segment_diagnostics::TABLE.file()));
    assert!(strs(&diagnostics, segment_diagnostics::status).iter().all(|s| s == "measured"));
    let runs = tmp.path().join("out/runs/ren2021_virtual");
    let loo_median = |file: &Path, p: &str| {
        let df = read(file);
        let (pr, model, r) = (strs(&df, loo::printer), strs(&df, loo::model), f64s(&df, loo::rmse_mm));
        median((0..df.height()).filter(|&i| pr[i] == p && model[i] == "lag").map(|i| r[i]).collect())
    };
    for p in ["taz5", "taz6"] {
        let (photos, real) =
            (loo_median(&out.join("loo.parquet"), p), loo_median(&runs.join("real_loo").join(loo::TABLE.file()), p));
        assert!((photos / real - 1.0).abs() < 0.3, "{p}: lag leave-one-out {photos} on photos, {real} on real lines");
    }
    assert!(read(&out.join(transfer_cv::TABLE.file())).height() > 0);

    // The engine names the hidden gear ripple, and nothing in the clean photos.
    let named = |stage: &str| -> Vec<String> {
        let df = read(&runs.join(stage).join(causes::TABLE.file()));
        let (m, n) = (strs(&df, causes::mechanism), bools(&df, causes::named));
        (0..df.height()).filter(|&i| n[i]).map(|i| m[i].clone()).collect()
    };
    assert_eq!(named("discrepancy_clean"), Vec::<String>::new());
    assert_eq!(named("discrepancy_hidden"), ["gear_eccentricity"]);

    // The same with paper 000's piecewise model as the baseline, on the same photos.
    let piecewise = tmp.path().join("piecewise.toml");
    let widths = |set: &str| runs.join(format!("widths_{set}")).display().to_string();
    let text = format!(
        "[run]\nname = \"piecewise\"\n\n[dataset.clean_widths]\npath = \"{}\"\n\n[dataset.hidden_widths]\npath = \"{}\"\n\n\
         [stage.clean]\nkind = \"fdm.discrepancy\"\ninputs = [\"clean_widths\"]\nparams = {{ start_blob = \"none\", baseline = \"piecewise_model\" }}\n\n\
         [stage.hidden]\nkind = \"fdm.discrepancy\"\ninputs = [\"hidden_widths\"]\nparams = {{ start_blob = \"none\", baseline = \"piecewise_model\" }}\n",
        widths("clean"),
        widths("hidden")
    );
    std::fs::write(&piecewise, text).unwrap();
    ok(tmp.path(), &["run", "-q", piecewise.to_str().unwrap()]);
    let piecewise_runs = tmp.path().join("out/runs/piecewise");
    let named_on = |stage: &str| -> Vec<String> {
        let df = read(&piecewise_runs.join(stage).join(causes::TABLE.file()));
        let (m, n) = (strs(&df, causes::mechanism), bools(&df, causes::named));
        assert!(strs(&df, causes::base_model).iter().all(|b| b.starts_with("piecewise_model")));
        (0..df.height()).filter(|&i| n[i]).map(|i| m[i].clone()).collect()
    };
    assert_eq!(named_on("clean"), Vec::<String>::new());
    assert_eq!(named_on("hidden"), ["gear_eccentricity"]);
    let ext = read(&piecewise_runs.join("hidden").join(extension::TABLE.file()));
    let (param, lo, hi) =
        (strs(&ext, extension::parameter), f64s(&ext, extension::ci_lo), f64s(&ext, extension::ci_hi));
    let k = param.iter().position(|p| p == "amplitude").unwrap();
    assert!(lo[k] <= 0.05 && 0.05 <= hi[k], "the amplitude's interval [{}, {}] covers the hidden 5 %", lo[k], hi[k]);

    let section = std::fs::read_to_string(runs.join("section/section.html")).unwrap();
    for text in ["The discrepancy engine on photos", "gear eccentricity=0.05", "edge fit", "threshold"] {
        assert!(section.contains(text), "section lacks `{text}`");
    }
    for figure in
        ["agreement_taz5/virtual_agreement.png", "segment_accuracy_fig/segment_accuracy.png", "fig9/transfer_cv.png"]
    {
        let bytes = std::fs::metadata(runs.join(figure)).unwrap().len();
        assert!(bytes > 20_000, "{figure}: {bytes} bytes");
    }
}

/// `amrepro datasets generate fdm` into `dir/name` with `extra` options.
fn generate(dir: &Path, name: &str, extra: &[&str]) -> std::path::PathBuf {
    let out = dir.join(name);
    let mut args = vec!["datasets", "generate", "fdm", "--printer", "taz6", "--seed", "4", "--px-per-mm", "20"];
    args.extend(extra);
    args.extend(["--out", out.to_str().unwrap()]);
    ok(dir, &args);
    out
}

#[test]
fn the_same_seed_generates_the_same_photos_and_bad_effects_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (generate(tmp.path(), "a", &[]), generate(tmp.path(), "b", &[]));
    for file in ["lines.csv", "dataset.toml", "images/S800F9000.png", "truth/placement.csv"] {
        assert_eq!(std::fs::read(a.join(file)).unwrap(), std::fs::read(b.join(file)).unwrap(), "{file}");
    }
    let c = generate(tmp.path(), "c", &["--effect", "bed_tilt", "--strength", "-0.05"]);
    assert!(std::fs::read_to_string(c.join("dataset.toml")).unwrap().contains("bed_tilt = -0.05"));
    let out = tmp.path().join("d");
    let text = fails(
        tmp.path(),
        &[
            "datasets",
            "generate",
            "fdm",
            "--printer",
            "taz5",
            "--seed",
            "1",
            "--effect",
            "bed_tilt",
            "--strength",
            "0.9",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert!(text.contains("bed_tilt") && text.contains("[-0.4, 0.4]"), "{text}");
    assert!(!out.exists());
}

#[test]
fn photos_a_lab_could_get_wrong_are_reported_one_by_one_and_the_rest_are_measured() {
    let tmp = tempfile::tempdir().unwrap();
    let photos = generate(tmp.path(), "photos", &[]);
    // A truncated PNG, a photo with no line, a line leaving the frame, a wrong px/mm.
    let image = |id: &str| photos.join(format!("images/{id}.png"));
    let bytes = std::fs::read(image("S400F3000")).unwrap();
    std::fs::write(image("S400F3000"), &bytes[..bytes.len() / 2]).unwrap();
    let csv = photos.join("lines.csv");
    let rows: Vec<String> = std::fs::read_to_string(&csv).unwrap().lines().map(String::from).collect();
    let edited: Vec<String> = rows
        .iter()
        .map(|row| {
            let mut f: Vec<String> = row.split(',').map(String::from).collect();
            match f[0].as_str() {
                "S400F6000" => f[11] = "5".into(),   // start_y_px: above the line, on bare bed
                "S400F9000" => f[10] = "900".into(), // start_x_px: the end is out of the frame
                "S600F3000" => f[3] = "40".into(),   // px_per_mm twice the camera's
                _ => {}
            }
            f.join(",")
        })
        .collect();
    std::fs::write(&csv, edited.join("\n") + "\n").unwrap();
    let spec = tmp.path().join("spec.toml");
    let text = format!(
        "[run]\nname = \"bad\"\n\n[dataset.photos]\npath = \"{}\"\n\n[stage.widths]\nkind = \"fdm.segment_widths\"\ninputs = [\"photos\"]\n",
        photos.display()
    );
    std::fs::write(&spec, text).unwrap();
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let diagnostics = read(&tmp.path().join("out/runs/bad/widths/segment_diagnostics.parquet"));
    let (ids, status, problem) = (
        strs(&diagnostics, segment_diagnostics::line_id),
        strs(&diagnostics, segment_diagnostics::status),
        strs(&diagnostics, segment_diagnostics::problem),
    );
    let problem_of = |id: &str| {
        let i = ids.iter().position(|x| x == id).unwrap();
        assert_eq!(status[i], "skipped", "{id}");
        problem[i].clone()
    };
    let truncated = problem_of("S400F3000");
    assert!(truncated.contains("S400F3000.png") && truncated.to_lowercase().contains("png"), "{truncated}");
    assert!(problem_of("S400F6000").contains("no line"), "{}", problem_of("S400F6000"));
    assert!(problem_of("S400F9000").contains("leaves the frame"), "{}", problem_of("S400F9000"));
    assert!(problem_of("S600F3000").contains("px_per_mm"), "{}", problem_of("S600F3000"));
    assert_eq!(status.iter().filter(|s| *s == "measured").count(), 5);
    let widths = std::fs::read_to_string(tmp.path().join("out/runs/bad/widths/lines.csv")).unwrap();
    assert_eq!(widths.lines().count(), 6, "a header and the five measured lines:\n{widths}");
}
