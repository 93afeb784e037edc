//! `report.ren2021`: paper 000 (Ren et al. 2021) against our reproduction on the real
//! Taz 5 / Taz 6 data. Table II (leave-one-out RMSE per Table I sample, paper values
//! copied from the paper) beside our piecewise and lag-model RMSEs, and Fig. 9's claim
//! (transfer improves the median RMSE by up to 24 % with 1-2 training lines, the gap
//! closing as n grows) beside our median improvements per n and method.
//!
//! Inputs: a stage holding `loo.parquet`, then one holding `transfer_cv.parquet`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::NoParams;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{loo, loo_predictions, transfer_cv};
use tables::report::comparison;

use models::stats::finite_median;

use super::{comparison_frame, Row};
use crate::figures::fdm::loo_predictions::{read_samples, SAMPLE_READS};
use crate::html::{escape, format_sig};
use crate::read::{f64s, ints, read_parquet, strs};

/// The `report.ren2021` stage kind.
pub struct Ren2021Section;

/// The leave-one-out beside Table II: both models' (a `table.concat` of their stages).
const LOO: Input = Input::one(
    "loo",
    &[Source::Stage("fdm.piecewise_loo"), Source::Stage("fdm.lag_model")],
    "the held-out RMSE per printer, model and condition (`loo.parquet`) and the measured widths beside the predictions (`loo_predictions.parquet`)",
)
.reading(&[
    Reads {
        table: &loo::TABLE,
        columns: &[loo::printer, loo::model, loo::condition, loo::rmse_mm, loo::r_a, loo::r_f],
    },
    SAMPLE_READS,
]);

/// The transfer learning beside Fig. 9.
const TRANSFER: Input = Input::one(
    "transfer",
    &[Source::Stage("fdm.transfer_cv")],
    "the held-out RMSE per training-set size and method (`transfer_cv.parquet`)",
)
.reading(&[Reads {
    table: &transfer_cv::TABLE,
    columns: &[transfer_cv::method, transfer_cv::rmse_mm, transfer_cv::n_train],
}]);

/// Paper 000 Table II: LOO RMSE (mm) per Table I sample `(a mm/s², F mm/s)`.
pub const TABLE_II: [(&str, f64, f64, f64); 9] = [
    ("S800F9000", 800.0, 150.0, 0.068),
    ("S800F6000", 800.0, 100.0, 0.042),
    ("S800F3000", 800.0, 50.0, 0.034),
    ("S600F9000", 600.0, 150.0, 0.047),
    ("S600F6000", 600.0, 100.0, 0.047),
    ("S600F3000", 600.0, 50.0, 0.055),
    ("S400F9000", 400.0, 150.0, 0.041),
    ("S400F6000", 400.0, 100.0, 0.045),
    ("S400F3000", 400.0, 50.0, 0.030),
];

/// Paper 000 Fig. 9 / Sec. IV: the largest median improvement with 1-2 lines (%).
pub const PAPER_MAX_IMPROVEMENT_PCT: f64 = 24.0;

/// Leave-one-out results keyed by (printer, model, condition) → (rmse, r_a, r_f).
type LooMap = BTreeMap<(String, String, String), (f64, f64, f64)>;

impl Stage for Ren2021Section {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.ren2021",
        version: 2,
        summary: "Paper 000 vs ours: Table II and Fig. 9 side by side, with a paragraph on the differences → section.html, comparison.parquet",
        implements: "paper 000 Table II, Fig. 9, Sec. IV",
        inputs: &[LOO, TRANSFER],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let loo = read_loo(&ctx.input(&LOO).dir.join(loo::TABLE.file()))?;
        let steady = steady_widths(&ctx.input(&LOO).dir.join(loo_predictions::TABLE.file()), "taz6")?;
        let medians = transfer_medians(&ctx.input(&TRANSFER).dir.join(transfer_cv::TABLE.file()))?;
        let (loo_rows, loo_html) = table_ii(&loo);
        let (fig9_rows, fig9_html) = fig9(&medians);
        let mut html = String::from("<h3>Paper 000 vs ours</h3>\n");
        html += &loo_html;
        html += &fig9_html;
        html += &discussion(&loo, &medians, &steady);
        let rows: Vec<Row> = loo_rows.into_iter().chain(fig9_rows).collect();
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

fn read_loo(path: &Path) -> Result<LooMap, StageError> {
    let df = read_parquet(path)?;
    let (printer, model, condition) =
        (strs(&df, loo::printer, path)?, strs(&df, loo::model, path)?, strs(&df, loo::condition, path)?);
    let (rmse, r_a, r_f) = (f64s(&df, loo::rmse_mm, path)?, f64s(&df, loo::r_a, path)?, f64s(&df, loo::r_f, path)?);
    Ok((0..df.height())
        .map(|i| ((printer[i].clone(), model[i].clone(), condition[i].clone()), (rmse[i], r_a[i], r_f[i])))
        .collect())
}

/// Each measured line's steady width on `printer`: the median measured width over the
/// middle half of the line's length (where every Table I condition cruises), by
/// condition, read from the held-out predictions' measured widths (one model's rows,
/// as every model lists the same samples).
fn steady_widths(path: &Path, printer: &str) -> Result<BTreeMap<String, f64>, StageError> {
    let samples = read_samples(path, printer)?;
    let one_model = samples.keys().map(|(_, model)| model.clone()).min();
    Ok(samples
        .into_iter()
        .filter(|((_, model), _)| Some(model) == one_model.as_ref())
        .map(|((condition, _), line)| {
            // `read_samples` sorts each line by position.
            let (lo, hi) = (line.first().map_or(f64::NAN, |s| s[0]), line.last().map_or(f64::NAN, |s| s[0]));
            let (from, to) = (lo + 0.25 * (hi - lo), lo + 0.75 * (hi - lo));
            let middle = line.iter().filter(|s| s[0] >= from && s[0] <= to).map(|s| s[1]);
            (condition, finite_median(middle))
        })
        .collect())
}

/// Median held-out RMSE per (method, n_train).
fn transfer_medians(path: &Path) -> Result<BTreeMap<(String, i64), f64>, StageError> {
    let df = read_parquet(path)?;
    let method = strs(&df, transfer_cv::method, path)?;
    let rmse = f64s(&df, transfer_cv::rmse_mm, path)?;
    let n = ints(&df, transfer_cv::n_train, path)?;
    let mut groups: BTreeMap<(String, i64), Vec<f64>> = BTreeMap::new();
    for i in 0..df.height() {
        groups.entry((method[i].clone(), n[i])).or_default().push(rmse[i]);
    }
    Ok(groups.into_iter().map(|(k, v)| (k, finite_median(v))).collect())
}

fn get(loo: &LooMap, printer: &str, model: &str, condition: &str) -> Option<(f64, f64, f64)> {
    loo.get(&(printer.to_string(), model.to_string(), condition.to_string())).copied()
}

fn table_ii(loo: &LooMap) -> (Vec<Row>, String) {
    let mut rows = Vec::new();
    let mut html = String::from("<h4>Table II: leave-one-out RMSE on the Taz 5 (mm)</h4>\n<table><tr><th>sample</th><th class=\"t\">condition</th><th>a (mm/s²)</th><th>F (mm/s)</th><th>paper</th><th>ours, piecewise</th><th>r_a, r_F chosen</th><th>ours, lag model</th></tr>\n");
    for (k, (cond, a, f, paper)) in TABLE_II.iter().enumerate() {
        let ours = get(loo, "taz5", "piecewise", cond);
        let lag = get(loo, "taz5", "lag", cond);
        let cell = |v: Option<(f64, f64, f64)>| v.map_or("—".to_string(), |x| format!("{:.3}", x.0));
        let r = ours.map_or("—".to_string(), |x| format!("{:.2}, {:.2}", x.1, x.2));
        let _ = writeln!(html, "<tr><td>{}</td><td class=\"t\">{cond}</td><td>{a}</td><td>{f}</td><td>{paper:.3}</td><td>{}</td><td>{r}</td><td>{}</td></tr>", k + 1, cell(ours), cell(lag));
        if let Some((rmse, _, _)) = ours {
            rows.push(Row {
                section: "table_ii",
                item: format!("taz5 {cond} piecewise rmse"),
                paper: Some(*paper),
                ours: rmse,
                unit: "mm",
                source: "out/fdm/loo.parquet (stage piecewise_taz5, fdm.piecewise_loo)".into(),
            });
        }
    }
    let summary = loo_summary(loo);
    for (item, paper, ours) in &summary {
        let _ = writeln!(
            html,
            "<tr><td></td><td class=\"t\" colspan=\"3\"><b>{}</b></td><td>{}</td><td>{}</td><td></td><td></td></tr>",
            escape(item),
            paper.map_or("—".into(), |p| format!("{p:.3}")),
            format_sig(*ours)
        );
        rows.push(Row {
            section: "table_ii",
            item: item.clone(),
            paper: *paper,
            ours: *ours,
            unit: "mm",
            source: "out/fdm/loo.parquet".into(),
        });
    }
    html += "</table>\n<p class=\"run\">Paper: Table II of Ren et al. 2021. Ours: run ren2021, stages piecewise_taz5 (fdm.piecewise_loo, r ∈ [0.9, 1.1] step 0.01) and lag_taz5 (fdm.lag_model), table out/fdm/loo.parquet.</p>\n";
    (rows, html)
}

/// Median, min, max of our piecewise Taz 5 LOO and the per-feed means, with the
/// paper's where it has one.
fn loo_summary(loo: &LooMap) -> Vec<(String, Option<f64>, f64)> {
    let values = |printer: &str, model: &str| -> Vec<f64> {
        loo.iter().filter(|((p, m, _), _)| p == printer && m == model).map(|(_, v)| v.0).collect()
    };
    let paper: Vec<f64> = TABLE_II.iter().map(|t| t.3).collect();
    let ours = values("taz5", "piecewise");
    let mut out = vec![
        (
            "median, Taz 5 piecewise".to_string(),
            Some(finite_median(paper.iter().copied())),
            finite_median(ours.iter().copied()),
        ),
        ("min, Taz 5 piecewise".to_string(), Some(0.030), ours.iter().copied().fold(f64::INFINITY, f64::min)),
        ("max, Taz 5 piecewise".to_string(), Some(0.068), ours.iter().copied().fold(0.0, f64::max)),
    ];
    for feed in [50.0, 100.0, 150.0] {
        let conds: Vec<&str> = TABLE_II.iter().filter(|t| t.2 == feed).map(|t| t.0).collect();
        let mean = |src: &dyn Fn(&str) -> Option<f64>| -> f64 {
            let v: Vec<f64> = conds.iter().filter_map(|c| src(c)).collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        };
        let paper_mean = mean(&|c| TABLE_II.iter().find(|t| t.0 == c).map(|t| t.3));
        let our_mean = mean(&|c| get(loo, "taz5", "piecewise", c).map(|x| x.0));
        out.push((format!("mean at F = {feed} mm/s, Taz 5 piecewise"), Some(paper_mean), our_mean));
    }
    for (printer, model) in [("taz5", "lag"), ("taz6", "piecewise"), ("taz6", "lag")] {
        out.push((
            format!("median, {} {model}", printer.replace("taz", "Taz ")),
            None,
            finite_median(values(printer, model)),
        ));
    }
    out
}

const METHODS: [&str; 3] = ["single", "transfer_zero_mean", "transfer_source_mean"];

fn improvement_pct(medians: &BTreeMap<(String, i64), f64>, method: &str, n: i64) -> Option<f64> {
    let single = medians.get(&("single".to_string(), n))?;
    let m = medians.get(&(method.to_string(), n))?;
    Some(100.0 * (single - m) / single)
}

fn fig9(medians: &BTreeMap<(String, i64), f64>) -> (Vec<Row>, String) {
    let ns: Vec<i64> = medians.keys().map(|k| k.1).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
    let mut html = String::from("<h4>Fig. 9: transfer Taz 5 → Taz 6, median held-out RMSE (mm) and improvement over single-printer learning</h4>\n<table><tr><th>n training lines</th>");
    for m in METHODS {
        let _ = write!(html, "<th>{m}</th>");
    }
    html += "<th>improvement, zero mean (%)</th><th>improvement, source mean (%)</th><th>paper</th></tr>\n";
    let mut rows = Vec::new();
    for n in &ns {
        let _ = write!(html, "<tr><td>{n}</td>");
        for m in METHODS {
            let _ = write!(
                html,
                "<td>{}</td>",
                medians.get(&(m.to_string(), *n)).map_or("—".into(), |v| format!("{v:.4}"))
            );
        }
        for m in &METHODS[1..] {
            let imp = improvement_pct(medians, m, *n);
            let _ = write!(html, "<td>{}</td>", imp.map_or("—".into(), |v| format!("{v:+.1}")));
            if let Some(v) = imp {
                let paper = (*n <= 2).then_some(PAPER_MAX_IMPROVEMENT_PCT);
                rows.push(Row {
                    section: "fig9",
                    item: format!("median improvement {m} n={n}"),
                    paper,
                    ours: v,
                    unit: "%",
                    source: "out/fdm/transfer_cv.parquet (stage transfer, fdm.transfer_cv)".into(),
                });
            }
        }
        let paper = if *n <= 2 {
            "up to +24"
        } else if *n >= 7 {
            "≈ 0 (gap closed)"
        } else {
            "decreasing"
        };
        let _ = writeln!(html, "<td>{paper}</td></tr>");
    }
    html += "</table>\n<p class=\"run\">Paper: Fig. 9(b) and Sec. IV of Ren et al. 2021 (“up to 24 %” with 1-2 training lines; close for large n; no per-n numbers are printed). Ours: run ren2021, stage transfer (fdm.transfer_cv: every subset of n Taz 6 lines, tested on the other 9 − n), table out/fdm/transfer_cv.parquet.</p>\n";
    (rows, html)
}

fn discussion(loo: &LooMap, medians: &BTreeMap<(String, i64), f64>, taz6_steady: &BTreeMap<String, f64>) -> String {
    let summary = loo_summary(loo);
    let ours_median = summary[0].2;
    let (worst, best) = extremes(loo, "taz5", "piecewise");
    let edge = loo.iter().filter(|((_, m, _), v)| m == "piecewise" && (at_edge(v.1) || at_edge(v.2))).count();
    let total = loo.iter().filter(|((_, m, _), _)| m == "piecewise").count();
    let best_imp =
        |m: &str| [1, 2].iter().filter_map(|n| improvement_pct(medians, m, *n)).fold(f64::NEG_INFINITY, f64::max);
    let late_imp = |m: &str| [7, 8].iter().filter_map(|n| improvement_pct(medians, m, *n)).collect::<Vec<_>>();
    let steady: Vec<f64> = taz6_steady.values().copied().filter(|w| w.is_finite()).collect();
    let (lo, hi) = steady.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &w| (a.min(w), b.max(w)));
    let steady_range = if steady.is_empty() {
        String::new()
    } else {
        format!(
            " (the median over the middle half of each line runs from {lo:.2} to {hi:.2} mm over its {} lines; fdm/loo_predictions.parquet)",
            steady.len()
        )
    };
    format!(
        "<h4>Where and why ours differs</h4>\n<p>On the same measured Taz 5 lines our leave-one-out median RMSE is {ours_median:.3} mm against the paper's 0.045 mm; \
our worst line is {worst} (paper: S800F9000, 150 mm/s) and our best {best} (paper: S400F3000, 50 mm/s). Our fit uses nothing of the held-out line but its G-code kinematics \
(nominal width and bp1 law from the training lines only), the raw files as published (the authors' own code trims bad first and last samples on S400F9000; we do not), and our \
own choices where the paper is silent (1 mm smoothing before locating bp1, Gauss-Newton for p1): these move single lines by a few hundredths of a millimetre.</p>\n\
<p>The chosen r_a, r_F sit on the edge of the paper's [0.9, 1.1] grid in {edge} of {total} folds: the model uses the kinematic scale factors to stretch its ramps, which is where \
the extrusion lag that the piecewise form does not contain shows through (the lag-model baseline has it, but a single time constant mis-sizes the end bulge on most lines).</p>\n\
<p>Transfer: with 1-2 Taz 6 lines the paper's zero-mean prior improves the median by at most {:.1} % and the source-centred prior by at most {:.1} % (paper: up to 24 %); \
at n = 7-8 the improvements are {} % (zero mean) and {} % (source mean) where the paper reports the gap closing. The zero-mean prior shrinks the nominal width c toward 0 \
when λ is chosen on very few lines; centring the prior on the source estimates avoids that. The Taz 6's steady widths differ between conditions{steady_range}, which one \
nominal width c per printer cannot follow: this limits every method on the Taz 6.</p>\n",
        best_imp("transfer_zero_mean"),
        best_imp("transfer_source_mean"),
        signed_list(&late_imp("transfer_zero_mean")),
        signed_list(&late_imp("transfer_source_mean")),
    )
}

/// The values with their sign to one decimal, and those that round to zero as `0.0`
/// (no `-0.0` for a loss that rounds away).
fn signed_list(values: &[f64]) -> String {
    let signed = |v: f64| if (v * 10.0).round() == 0.0 { "0.0".to_string() } else { format!("{v:+.1}") };
    values.iter().map(|&v| signed(v)).collect::<Vec<_>>().join(" and ")
}

fn at_edge(r: f64) -> bool {
    (r - 0.9).abs() < 1e-9 || (r - 1.1).abs() < 1e-9
}

fn extremes(loo: &LooMap, printer: &str, model: &str) -> (String, String) {
    let mut v: Vec<(&String, f64)> =
        loo.iter().filter(|((p, m, _), _)| p == printer && m == model).map(|((_, _, c), x)| (c, x.0)).collect();
    v.sort_by(|a, b| a.1.total_cmp(&b.1));
    let fmt = |x: Option<&(&String, f64)>| x.map_or("—".into(), |(c, r)| format!("{c} ({r:.3} mm)"));
    (fmt(v.last()), fmt(v.first()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::write_declared;
    use polars::prelude::df;

    #[test]
    fn a_steady_width_is_the_median_over_the_middle_half_of_its_line() {
        // Line A of taz6: widths 1..=9 at 0..=8 mm, whose middle half (2-6 mm) has
        // median 5; line B rises then falls, its middle 0.7, 0.9, 0.8, 0.8, 0.7 → 0.8. Another
        // printer's and another model's rows are not read.
        let x: Vec<f64> = (0..9).map(f64::from).collect();
        let a: Vec<f64> = (1..=9).map(f64::from).collect();
        let b = [0.1, 0.2, 0.7, 0.9, 0.8, 0.8, 0.7, 0.2, 0.1];
        let lines = [
            ("taz6", "A", "lag", &a[..]),
            ("taz6", "B", "lag", &b[..]),
            ("taz6", "A", "piecewise", &b[..]),
            ("taz5", "A", "lag", &b[..]),
        ];
        let rows: Vec<(&str, &str, &str, f64, f64)> = lines
            .iter()
            .flat_map(|&(printer, condition, model, widths)| {
                x.iter().zip(widths).map(move |(&xi, &wi)| (printer, condition, model, xi, wi))
            })
            .collect();
        let frame = df!(
            loo_predictions::printer => rows.iter().map(|r| r.0).collect::<Vec<_>>(),
            loo_predictions::condition => rows.iter().map(|r| r.1).collect::<Vec<_>>(),
            loo_predictions::model => rows.iter().map(|r| r.2).collect::<Vec<_>>(),
            loo_predictions::position_mm => rows.iter().map(|r| r.3).collect::<Vec<_>>(),
            loo_predictions::measured_width_mm => rows.iter().map(|r| r.4).collect::<Vec<_>>(),
            loo_predictions::predicted_width_mm => vec![0.0; rows.len()],
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        write_declared(dir.path(), &loo_predictions::TABLE, frame);
        let steady = steady_widths(&dir.path().join(loo_predictions::TABLE.file()), "taz6").unwrap();
        assert_eq!(steady.len(), 2);
        assert_eq!((steady["A"], steady["B"]), (5.0, 0.8));
        assert!(steady_widths(&dir.path().join(loo_predictions::TABLE.file()), "taz7").unwrap().is_empty());
    }

    #[test]
    fn signed_values_that_round_to_zero_read_0_0() {
        assert_eq!(signed_list(&[-0.004, 14.8, -2.96, 0.04]), "0.0 and +14.8 and -3.0 and 0.0");
    }

    #[test]
    fn paper_table_ii_median_is_0_045() {
        assert_eq!(finite_median(TABLE_II.iter().map(|t| t.3)), 0.045);
    }
}
