//! Paper 003 through the shipped `specs/chen2024.toml` and the `thermal-sequence`
//! format: the tables, figures and report section it promises, and bad frames turned
//! into diagnostics while the run goes on.

mod common;

use std::path::Path;

use common::*;
use polars::prelude::{DataFrame, ParquetReader, SerReader};
use tables::thermal::{accuracy, contour, contour_regions, corners, frames, width_errors, widths};

fn read(path: &Path) -> DataFrame {
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

fn f64s(df: &DataFrame, name: &str) -> Vec<f64> {
    df.column(name).unwrap().f64().unwrap().iter().map(|v| v.unwrap_or(f64::NAN)).collect()
}

fn strs(df: &DataFrame, name: &str) -> Vec<String> {
    df.column(name).unwrap().str().unwrap().iter().map(|v| v.unwrap_or_default().to_string()).collect()
}

#[test]
fn chen2024_writes_its_tables_figures_and_section() {
    let tmp = tempfile::tempdir().unwrap();
    let spec = shipped_spec(tmp.path(), "chen2024", tmp.path()); // virtual printer: no measured data
    ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    let out = tmp.path().join("out/thermal");
    let frames = read(&out.join(frames::TABLE.file()));
    for column in ["layer", "frame", "recorded_time_s", "estimated_time_s", "corners_found", "reproj_err_mm", "used"] {
        assert!(frames.column(column).is_ok(), "frames.parquet lacks {column}");
    }
    for column in ["dlt_time_s", "rigid_mount_time_s", "nozzle_x_mm", "nozzle_y_mm", "corners_used"] {
        assert!(frames.column(column).is_ok(), "frames.parquet lacks {column}");
    }
    // The rigid mount places every frame that shows one readable corner (all but the
    // first few and the last), the paper's DLT only those with four in the band.
    let used = frames.column(frames::used).unwrap().bool().unwrap().iter().filter(|u| *u == Some(true)).count();
    assert!(used >= 40, "only {used} of {} frames localised", frames.height());
    let dlt_used = f64s(&frames, frames::dlt_time_s).iter().filter(|t| t.is_finite()).count();
    assert!(used > 2 * dlt_used, "rigid mount {used} frames, DLT {dlt_used}");
    let corners = read(&out.join(corners::TABLE.file()));
    assert_eq!(corners.height(), 18, "one row per corner of the test path");
    for column in ["corner", "angle_deg", "oe_before_pct", "oe_after_pct"] {
        assert!(corners.column(column).is_ok(), "corners.parquet lacks {column} (the issue's columns)");
    }
    let contour = read(&out.join(contour::TABLE.file()));
    for column in ["variant", "max_mm", "rms_mm"] {
        assert!(contour.column(column).is_ok(), "contour.parquet lacks {column} (the issue's columns)");
    }
    let before = f64s(&corners, corners::oe_before_pct);
    assert!(before.iter().all(|v| v.is_finite() && *v >= 0.0));
    assert_eq!(strs(&contour, contour::variant), ["conventional", "compensated"]);
    assert!(f64s(&contour, contour::max_mm).iter().all(|v| v.is_finite() && *v > 0.0));
    // The bar that the paper's method meets on the shipped spec: the mean O_E
    // falls by at least 50 %. The RMS contour error falls by 28 %, short of its 30 %, and
    // the max hardly at all (the report says why): this guards what they reach.
    let mean = |v: Vec<f64>| v.iter().sum::<f64>() / v.len() as f64;
    let (oe_before, oe_after) = (mean(before), mean(f64s(&corners, corners::oe_after_pct)));
    assert!(oe_after <= 0.5 * oe_before, "mean O_E {oe_before} % → {oe_after} %");
    let (max, rms) = (f64s(&contour, contour::max_mm), f64s(&contour, contour::rms_mm));
    assert!(rms[1] <= 0.75 * rms[0], "RMS contour error {} → {} mm", rms[0], rms[1]);
    assert!(max[1] <= max[0], "max contour error {} → {} mm", max[0], max[1]);
    // Where it lies: a row per corner, the seam and the straight runs, whose squares add
    // up to the whole; the valleys' bulges shrink, and the compensated maximum is where
    // the print falls short of a sharp apex's mitred tip.
    let regions = read(&out.join(contour_regions::TABLE.file()));
    assert_eq!(regions.height(), 20);
    let kinds = strs(&regions, contour_regions::kind);
    for variant in [contour_regions::sq_share_before, contour_regions::sq_share_after] {
        let share: f64 = f64s(&regions, variant).iter().sum();
        assert!((share - 1.0).abs() < 1e-9, "{variant}: {share}");
    }
    let (max_before, max_after) =
        (f64s(&regions, contour_regions::max_before_mm), f64s(&regions, contour_regions::max_after_mm));
    for i in (0..kinds.len()).filter(|&i| kinds[i] == "valley") {
        assert!(max_after[i] < 0.7 * max_before[i], "valley {i}: {} → {}", max_before[i], max_after[i]);
    }
    let worst = (0..kinds.len()).max_by(|&a, &b| max_after[a].total_cmp(&max_after[b])).unwrap();
    let short = regions.column(contour_regions::max_after_short).unwrap().bool().unwrap().get(worst);
    assert_eq!((kinds[worst].as_str(), short), ("apex", Some(true)));
    assert!((max_after[worst] - max[1]).abs() < 1e-12);
    // Frames with no corner in view are placed by their recorded time, for widths only:
    // no capture-time estimate of their own, and not in the capture-time statistics.
    let placed_by = strs(&frames, frames::placed_by);
    let estimated = f64s(&frames, frames::estimated_time_s);
    let dead_reckoned: Vec<usize> = (0..placed_by.len()).filter(|&i| placed_by[i] == "recorded_time").collect();
    assert!(!dead_reckoned.is_empty(), "the first frames of each layer show no corner");
    assert!(dead_reckoned.iter().all(|&i| estimated[i].is_nan()));
    let used_flags = frames.column(frames::used).unwrap().bool().unwrap().clone();
    assert!(dead_reckoned.iter().all(|&i| used_flags.get(i) == Some(false)), "used = localised by eqs 27-30");
    // The camera films on through the layer change: a frame recorded after the layer's
    // last move is placed but not timed, and the last stretch of the layer is read.
    let recorded = f64s(&frames, frames::recorded_time_s);
    let parked: Vec<usize> = (0..placed_by.len()).filter(|&i| placed_by[i] == "parked").collect();
    assert!(parked.len() >= 5 * 6, "about eight frames of every layer change: {}", parked.len());
    assert!(parked.iter().all(|&i| estimated[i].is_nan() && used_flags.get(i) == Some(false) && recorded[i] > 7.1));
    let widths = read(&out.join(widths::TABLE.file()));
    let (t, left) = (f64s(&widths, widths::t_s), f64s(&widths, widths::w_left_mm));
    let last_read = (0..t.len()).filter(|&i| left[i].is_finite()).map(|i| t[i]).fold(0.0, f64::max);
    assert!(last_read > 7.1, "the layer's last samples (to 7.119 s) are read: last {last_read} s");
    // The shipped camera has the Lepton habits: a frame that repeats the image before it
    // is skipped with a reason naming that frame.
    let repeat_of =
        frames.column(frames::repeat_of_frame).unwrap().i64().unwrap().into_no_null_iter().collect::<Vec<_>>();
    let reasons = strs(&frames, frames::skip_reason);
    let repeats: Vec<usize> = (0..repeat_of.len()).filter(|&i| repeat_of[i] >= 0).collect();
    assert!(!repeats.is_empty(), "the Lepton repeats and freezes");
    for i in repeats {
        assert_eq!(used_flags.get(i), Some(false));
        assert!(reasons[i].starts_with(&format!("same image as frame {}", repeat_of[i])), "{}", reasons[i]);
    }
    let accuracy = read(&out.join(accuracy::TABLE.file()));
    let metrics = strs(&accuracy, accuracy::metric);
    for metric in ["capture_time_err_median_ms", "capture_time_err_baseline_median_ms", "width_err_median_mm"] {
        assert!(metrics.iter().any(|m| m == metric), "accuracy.parquet lacks {metric}");
    }
    // The capture-time estimate must beat taking the recorded time as is (the bar).
    let values = f64s(&accuracy, accuracy::value);
    let metric = |name: &str| values[metrics.iter().position(|m| m == name).unwrap()];
    assert_eq!(metric("frames_placed_by_recorded_time"), dead_reckoned.len() as f64);
    assert_eq!(metric("frames_used") as usize, estimated.iter().filter(|t| t.is_finite()).count());
    let (ours, baseline) = (metric("capture_time_err_median_ms"), metric("capture_time_err_baseline_median_ms"));
    assert!(ours < 0.75 * baseline, "capture time error {ours} ms vs recorded time {baseline} ms");
    for table in ["widths", "compensation", "spans", "paper_comparison", "lag_model_corners", "lag_model_contour"] {
        assert!(out.join(format!("{table}.parquet")).is_file(), "{table}.parquet");
    }
    // Five layers are filmed; the compensation reads the first.
    let layers = frames.column("layer").unwrap().i64().unwrap().into_no_null_iter().max();
    assert_eq!(layers, Some(4));
    // The extension is scored beside the paper's method, with its own rows.
    let comparison = read(&out.join("paper_comparison.parquet"));
    let items = strs(&comparison, "item");
    assert!(items.iter().any(|i| i.starts_with("extension (lag model)")), "{items:?}");
    // The variants the report discusses are run, not quoted: one row each, what sets it
    // apart read from its stages, and the widths' error against the truth by region.
    let variants = read(&out.join("compensation_variants.parquet"));
    let names = strs(&variants, "variant");
    let expected = [
        "defaults",
        "lag",
        "paper_gain",
        "as_printed",
        "sweep",
        "first_layer",
        "no_habits",
        "read_sooner",
        "read_later",
        "read_latest",
        "cornerless_unplaced",
        "true_widths",
        "true_widths_as_printed",
    ];
    assert_eq!(names, expected);
    let changes = strs(&variants, "changes");
    let change = |name: &str| changes[names.iter().position(|n| n == name).unwrap()].clone();
    assert_eq!(change("paper_gain"), "compensate_paper_gain: gain = \"paper\" (compensate: \"unit\")");
    assert_eq!(change("read_later"), "monitor_read_later: measure_age_s = 0.15 (monitor: 0.1)");
    assert!(change("no_habits").contains("lepton_habits = false (sequence: true)"), "{}", change("no_habits"));
    assert!(change("true_widths").contains("also reads true_widths"), "{}", change("true_widths"));
    assert!(f64s(&variants, "oe_change_pct").iter().all(|c| c.is_finite() && *c < 0.0), "every variant lowers O_E");
    let errors = read(&out.join(width_errors::TABLE.file()));
    assert_eq!(
        strs(&errors, width_errors::region).iter().filter(|r| *r == "corner").count(),
        5,
        "one row per filmed layer"
    );
    let medians = f64s(&errors, width_errors::median_abs_err_mm);
    assert!(medians.iter().all(|m| m.is_finite() && *m >= 0.0 && *m < 0.2), "{medians:?}");
    let runs = tmp.path().join("out/runs/chen2024");
    let section = std::fs::read_to_string(runs.join("comparison/section.html")).unwrap();
    assert!(!section.contains("was not run"), "every variant the discussion cites is in the spec");
    assert!(section.contains("(variant read_sooner)") && section.contains("width_errors.parquet of stage true_widths"));
    for (stage, stem) in [
        ("fig3", "thermal_directions"),
        ("fig4", "thermal_frame"),
        ("fig8", "thermal_corners"),
        ("fig10", "thermal_overdeposition"),
        ("fig11", "thermal_contour_error"),
    ] {
        assert!(runs.join(stage).join(format!("{stem}.png")).is_file(), "{stage}");
    }
    let report = std::fs::read_to_string(tmp.path().join("out/report/index.html")).unwrap();
    assert!(report.contains("Paper 003"), "the report has the paper-003 section");
    assert!(!report.contains("frames/L00_F"), "the virtual camera's frames are data, not figures of the report");
    assert!(report.matches("<figure>").count() >= 5, "the five paper-003 figures");
}

/// Writes a 16-bit grayscale PNG of `width` × `height` filled with `value`.
fn png16(width: usize, height: usize, value: u16) -> Vec<u8> {
    datasets::thermal::sequence::encode_png16(width, height, &vec![value; width * height])
}

#[test]
fn bad_frames_are_diagnosed_by_name_and_the_run_goes_on() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(dir, &["datasets", "generate", "thermal", "--seed", "3", "--out", "seq"]);
    let frames = dir.join("seq/frames");
    std::fs::write(frames.join("L00_F0030.png"), png16(80, 60, 30000)).unwrap(); // wrong size
    let whole = std::fs::read(frames.join("L00_F0031.png")).unwrap();
    std::fs::write(frames.join("L00_F0031.png"), &whole[..whole.len() / 3]).unwrap(); // truncated
    std::fs::write(frames.join("L00_F0032.png"), png16(160, 120, 0)).unwrap(); // no reading anywhere: all NaN
                                                                               // Frame 34 claims to have been recorded before frame 33: out of order.
    let csv = std::fs::read_to_string(dir.join("seq/frames.csv")).unwrap();
    let csv = csv.replace("0,34,4.250000,", "0,34,4.100000,");
    std::fs::write(dir.join("seq/frames.csv"), csv).unwrap();
    let spec = dir.join("spec.toml");
    std::fs::write(
        &spec,
        "[run]\nname = \"bad_frames\"\nseed = 3\n\n[dataset.seq]\npath = \"seq\"\n\n\
         [stage.monitor]\nkind = \"thermal.monitor\"\ninputs = [\"seq\"]\n\
         params = { band_low_c = 90.0, band_high_c = 220.0 }\n",
    )
    .unwrap();
    ok(dir, &["run", "-q", spec.to_str().unwrap()]);
    let table = read(&dir.join("out/runs/bad_frames/monitor/frames.parquet"));
    let reasons = strs(&table, "skip_reason");
    let frame_no: Vec<i64> = table.column("frame").unwrap().i64().unwrap().iter().map(|v| v.unwrap()).collect();
    let reason = |f: i64| reasons[frame_no.iter().position(|&x| x == f).unwrap()].clone();
    assert!(reason(30).contains("L00_F0030.png") && reason(30).contains("160"), "{}", reason(30));
    assert!(reason(31).contains("L00_F0031.png"), "{}", reason(31));
    assert!(reason(32).contains("L00_F0032.png"), "{}", reason(32));
    assert!(reason(34).contains("out of order"), "{}", reason(34));
    let used = table.column("used").unwrap().bool().unwrap().iter().filter(|u| *u == Some(true)).count();
    assert!(used >= 5, "the other frames are still localised ({used})");
}
