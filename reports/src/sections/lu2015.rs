//! `report.lu2015`: paper 002 (Lu, Zheng, Mishra 2015) against our simulation. The
//! cylinder of Figs 11-12 (mean error and std, open vs closed loop, at [0 20%] and
//! [0 40%] droplet variation), the cuboid of Table II (average height and RMSD) and
//! the exact-recovery check of Sec. IV-C, each with the paper's number beside ours.
//!
//! Inputs: a stage holding the stacked `summary.parquet` of the print experiments, then
//! one holding `recovery.parquet`.

use std::fmt::Write as _;
use std::path::Path;

use pipeline::stage::Arity;
use pipeline::{ParamSpec, StageContext, StageError, StageKind};

use super::{comparison_frame, Row};
use crate::read::{f64s, read_parquet, strs};

/// The `report.lu2015` stage kind.
pub struct Lu2015Section;

/// One experiment the paper reports: (scenario, controller, variation %, metric,
/// paper value µm, where in the paper).
const PAPER: [(&str, &str, f64, Metric, f64, &str); 12] = [
    ("cylinder", "open_loop", 20.0, Metric::MeanError, 44.1, "Fig. 11"),
    ("cylinder", "open_loop", 20.0, Metric::Std, 15.0, "Fig. 11"),
    ("cylinder", "closed_loop", 20.0, Metric::MeanError, 0.7, "Fig. 11"),
    ("cylinder", "closed_loop", 20.0, Metric::Std, 4.1, "Fig. 11"),
    ("cylinder", "open_loop", 40.0, Metric::MeanError, 84.7, "Fig. 12"),
    ("cylinder", "open_loop", 40.0, Metric::Std, 16.6, "Fig. 12"),
    ("cylinder", "closed_loop", 40.0, Metric::MeanError, 1.9, "Fig. 12"),
    ("cylinder", "closed_loop", 40.0, Metric::Std, 4.5, "Fig. 12"),
    ("cuboid", "open_loop", 20.0, Metric::Average, 18.5, "Table II"),
    ("cuboid", "open_loop", 20.0, Metric::Rmsd, 8.7, "Table II"),
    ("cuboid", "closed_loop", 20.0, Metric::Average, 22.3, "Table II"),
    ("cuboid", "closed_loop", 20.0, Metric::Rmsd, 4.4, "Table II"),
];

/// A column of the summary table.
#[derive(Debug, Clone, Copy)]
enum Metric {
    MeanError,
    Std,
    Average,
    Rmsd,
}

impl Metric {
    fn column(self) -> &'static str {
        match self {
            Self::MeanError => "mean_err_um",
            Self::Std => "std_um",
            Self::Average => "avg_height_um",
            Self::Rmsd => "rmsd_um",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Self::MeanError => "mean error |h_d − mean H|",
            Self::Std => "std of H",
            Self::Average => "average height",
            Self::Rmsd => "RMSD from h_d",
        }
    }
}

impl StageKind for Lu2015Section {
    fn name(&self) -> &'static str {
        "report.lu2015"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Paper 002 vs ours: cylinder (Figs 11-12), cuboid (Table II), exact recovery (Sec. IV-C) → section.html, comparison.parquet"
    }
    fn implements(&self) -> &'static str {
        "paper 002 Figs 11-12, Table II, Sec. IV-C"
    }
    fn params(&self) -> &'static [ParamSpec] {
        &[]
    }
    fn arity(&self) -> Arity {
        Arity::exactly(2)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let summary = Summary::read(&ctx.inputs[0].dir.join("summary.parquet"))?;
        let (recovered, trials) = recovery(&ctx.inputs[1].dir.join("recovery.parquet"))?;
        let (mut rows, mut html) = experiments(&summary);
        let _ = writeln!(
            html,
            "<p>Exact recovery (Sec. IV-C: 20 × 20 grid, random initial heights and pattern, α = 1, search started from all ones): <b>{recovered} of {trials}</b> trials found the applied pattern exactly (paper: 50 of 50). Source: out/inkjet/recovery.parquet, stage recovery (inkjet.recovery).</p>"
        );
        rows.push(Row {
            section: "sec_iv_c",
            item: "trials recovered exactly".into(),
            paper: Some(50.0),
            ours: recovered as f64,
            unit: "trials",
            source: "out/inkjet/recovery.parquet (stage recovery, inkjet.recovery)".into(),
        });
        html += &discussion(&summary);
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table("comparison", &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

/// The stacked experiment summaries.
struct Summary {
    keys: Vec<(String, String, f64)>,
    path: std::path::PathBuf,
    df: polars::prelude::DataFrame,
}

impl Summary {
    fn read(path: &Path) -> Result<Self, StageError> {
        let df = read_parquet(path)?;
        let (scenario, controller) = (strs(&df, "scenario", path)?, strs(&df, "controller", path)?);
        let pct = f64s(&df, "variation_pct", path)?;
        let keys = scenario.into_iter().zip(controller).zip(pct).map(|((s, c), p)| (s, c, p)).collect();
        Ok(Self { keys, path: path.to_path_buf(), df })
    }

    /// Our value of `metric` for an experiment, if the spec ran it.
    fn value(&self, scenario: &str, controller: &str, pct: f64, metric: Metric) -> Option<f64> {
        let row = self.keys.iter().position(|(s, c, p)| s == scenario && c == controller && (p - pct).abs() < 1e-9)?;
        f64s(&self.df, metric.column(), &self.path).ok().map(|v| v[row])
    }
}

fn experiments(summary: &Summary) -> (Vec<Row>, String) {
    let mut html = String::from("<h3>Paper 002 vs ours</h3>\n<h4>Cylinder (Figs 11-12, h_d = 400 µm) and cuboid (Table II, h_d = 22.8 µm), µm</h4>\n<table><tr><th class=\"t\">experiment</th><th class=\"t\">controller</th><th>variation</th><th class=\"t\">metric</th><th>paper</th><th>ours</th><th class=\"t\">paper source</th></tr>\n");
    let mut rows = Vec::new();
    for (scenario, controller, pct, metric, paper, figure) in PAPER {
        let ours = summary.value(scenario, controller, pct, metric);
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{scenario}</td><td class=\"t\">{}</td><td>[0 {pct}%]</td><td class=\"t\">{}</td><td>{paper}</td><td>{}</td><td class=\"t\">{figure}</td></tr>",
            controller.replace('_', " "),
            metric.label(),
            ours.map_or("not run".into(), |v| format!("{v:.2}"))
        );
        if let Some(v) = ours {
            let item = format!("{scenario} {controller} [0 {pct}%] {}", metric.column());
            rows.push(Row {
                section: figure_key(figure),
                item,
                paper: Some(paper),
                ours: v,
                unit: "µm",
                source: "out/inkjet/summary.parquet (stages *_open, *_closed, inkjet.print_experiment)".into(),
            });
        }
    }
    html += "</table>\n<p class=\"run\">Ours: run lu2015, one stage per experiment (inkjet.print_experiment; the truth printer scales each droplet's h1, h2, h3 by (1 − u), u ~ U[0, p]; profiler noise 1 µm; closed loop α = 0.9, N = 1, M = 64), table out/inkjet/summary.parquet. Paper: Lu, Zheng, Mishra 2015, Figs 11-12 and Table II.</p>\n";
    (rows, html)
}

fn figure_key(figure: &str) -> &'static str {
    match figure {
        "Fig. 11" => "fig11",
        "Fig. 12" => "fig12",
        _ => "table_ii",
    }
}

fn recovery(path: &Path) -> Result<(usize, usize), StageError> {
    let df = read_parquet(path)?;
    let flips = df
        .column("flips_wrong")
        .and_then(|c| c.i64().map(|ca| ca.iter().map(|v| v.unwrap_or(-1)).collect::<Vec<i64>>()))
        .map_err(|source| StageError::Table { path: path.to_path_buf(), source })?;
    Ok((flips.iter().filter(|f| **f == 0).count(), flips.len()))
}

/// The paragraph on differences, with our numbers filled in from the summary.
fn discussion(summary: &Summary) -> String {
    let v = |s: &str, c: &str, p: f64, m: Metric| summary.value(s, c, p, m).map_or("—".into(), |x| format!("{x:.1}"));
    format!(
        "<h4>Where and why ours differs</h4>\n\
<p>Reading the paper's “[0 20%] / [0 40%] variation on h1, h2, h3” as a per-droplet volume shortfall (each droplet's h's scaled by (1 − u), u ~ U[0, p], DESIGN §5.2) \
gives open-loop mean errors of {} and {} µm against the paper's 44.1 and 84.7: that reading is confirmed for the mean. The open-loop standard deviation is not reproduced: \
ours is {} and {} µm against 15.0 and 16.6. With the corrected height model the open-loop part forms a shallow dome, and in our exploration of the footprint radius \
(models::inkjet::experiments) no cylinder gave more than about 7 µm; the paper either simulated a stronger edge loss or drew its variation differently (per layer or per \
nozzle rather than per droplet), which it does not state. The closed loop ends slightly above h_d (mean errors {} and {} µm, paper 0.7 and 1.9): the profiler's 1 µm \
noise makes the optimiser add droplets to cells that only read low. The cuboid open loop prints 3 layers, since Table II's ideal 22.8 µm equals three nominal layers of \
7.6 µm; the paper's separate 4-layer print is its model-verification experiment, not yet reproduced here. Its open-loop RMSD ({} µm, paper 8.7) is \
smaller for the same reason as the cylinder's std, and its closed loop also ends above h_d (average {} µm, paper 22.3).</p>\n",
        v("cylinder", "open_loop", 20.0, Metric::MeanError),
        v("cylinder", "open_loop", 40.0, Metric::MeanError),
        v("cylinder", "open_loop", 20.0, Metric::Std),
        v("cylinder", "open_loop", 40.0, Metric::Std),
        v("cylinder", "closed_loop", 20.0, Metric::MeanError),
        v("cylinder", "closed_loop", 40.0, Metric::MeanError),
        v("cuboid", "open_loop", 20.0, Metric::Rmsd),
        v("cuboid", "closed_loop", 20.0, Metric::Average),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_paper_number_maps_to_a_summary_column() {
        for (_, _, _, metric, paper, figure) in PAPER {
            assert!(paper > 0.0);
            assert!(["mean_err_um", "std_um", "avg_height_um", "rmsd_um"].contains(&metric.column()));
            assert!(["fig11", "fig12", "table_ii"].contains(&figure_key(figure)));
        }
    }
}
