//! `report.lu2015`: paper 002 (Lu, Zheng, Mishra 2015) against our simulation. The
//! cylinder of Figs 11-12 (mean error and std, open vs closed loop, at [0 20%] and
//! [0 40%] droplet variation), the cuboid of Table II (average height and RMSD) and
//! the exact-recovery check of Sec. IV-C, each with the paper's number beside ours; the
//! 4-layer cuboid of Sec. V-D-1 beside the 3-layer one; the two-material pipe junction
//! (Figs 13-15) with its edge deformation; and the layer-to-layer model tested on
//! virtual `inkjet-scans` datasets with each extra effect of the printer.
//!
//! Inputs, in order: the stacked `summary.parquet` of the print experiments,
//! `recovery.parquet`, the stacked `edge_deformation.parquet` and the stacked
//! `scan_residuals.parquet`.

use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::NoParams;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::inkjet::{edge_deformation, recovery, scan_residuals, summary};
use tables::report::comparison;

use super::{comparison_frame, Row};
use crate::read::{f64s, read_parquet, strs};

/// The `report.lu2015` stage kind.
pub struct Lu2015Section;

/// The print experiments' summaries (a `table.concat` of them).
const SUMMARY: Input = Input::one(
    "summary",
    &[Source::Stage("inkjet.print_experiment")],
    "every experiment's mean error, std, average height and RMSD (`summary.parquet`)",
)
.reading(&[Reads {
    table: &summary::TABLE,
    columns: &[
        summary::scenario,
        summary::controller,
        summary::variation_pct,
        summary::layers,
        summary::mean_err_um,
        summary::std_um,
        summary::avg_height_um,
        summary::rmsd_um,
    ],
}]);

/// The exact-recovery check of Sec. IV-C.
const RECOVERY: Input = Input::one(
    "recovery",
    &[Source::Stage("inkjet.recovery")],
    "the trials that recovered the applied pattern (`recovery.parquet`)",
)
.reading(&[Reads { table: &recovery::TABLE, columns: &[recovery::flips_wrong] }]);

/// The pipe junction's prints (a `table.concat` of them).
const EDGE_DEFORMATION: Input = Input::one(
    "edge_deformation",
    &[Source::Stage("inkjet.print_experiment")],
    "the pipe junction's edge deformation per region (`edge_deformation.parquet`)",
)
.reading(&[Reads {
    table: &edge_deformation::TABLE,
    columns: &[
        edge_deformation::controller,
        edge_deformation::region,
        edge_deformation::cells,
        edge_deformation::rmse_um,
        edge_deformation::max_abs_um,
        edge_deformation::mean_err_um,
    ],
}]);

/// The model's residuals on virtual scans (a `table.concat` of them).
const SCAN_RESIDUALS: Input = Input::one(
    "scan_residuals",
    &[Source::Stage("inkjet.scan_residuals")],
    "the layer-to-layer model's residuals per scan set (`scan_residuals.parquet`)",
)
.reading(&[Reads {
    table: &scan_residuals::TABLE,
    columns: &[
        scan_residuals::effects,
        scan_residuals::layer,
        scan_residuals::rmse_um,
        scan_residuals::bias_um,
        scan_residuals::max_abs_um,
    ],
}]);

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
            Self::MeanError => summary::mean_err_um,
            Self::Std => summary::std_um,
            Self::Average => summary::avg_height_um,
            Self::Rmsd => summary::rmsd_um,
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

impl Stage for Lu2015Section {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.lu2015",
        version: 3,
        summary: "Paper 002 vs ours: cylinder (Figs 11-12), cuboid (Table II, 3 and 4 layers), exact recovery (Sec. IV-C), pipe junction edge deformation (Figs 13-15), model residuals on virtual scans per effect → section.html, comparison.parquet",
        implements: "paper 002 Figs 11-15, Table II, Sec. IV-C, Sec. V-D-1",
        inputs: &[SUMMARY, RECOVERY, EDGE_DEFORMATION, SCAN_RESIDUALS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let summary = Summary::read(&ctx.input(&SUMMARY).dir.join(summary::TABLE.file()))?;
        let (recovered, trials) = recovery(&ctx.input(&RECOVERY).dir.join(recovery::TABLE.file()))?;
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
        html += &cuboid_layers(&summary, &mut rows);
        html += &pipe_junction(
            &summary,
            &ctx.input(&EDGE_DEFORMATION).dir.join(edge_deformation::TABLE.file()),
            &mut rows,
        )?;
        html += &scan_residuals(&ctx.input(&SCAN_RESIDUALS).dir.join(scan_residuals::TABLE.file()), &mut rows)?;
        html += &discussion(&summary);
        html += &std_gap(&summary);
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

/// The stacked experiment summaries.
struct Summary {
    keys: Vec<(String, String, f64)>,
    layers: Vec<i64>,
    path: std::path::PathBuf,
    df: polars::prelude::DataFrame,
}

impl Summary {
    fn read(path: &Path) -> Result<Self, StageError> {
        let df = read_parquet(path)?;
        let (scenario, controller) = (strs(&df, summary::scenario, path)?, strs(&df, summary::controller, path)?);
        let pct = f64s(&df, summary::variation_pct, path)?;
        let keys = scenario.into_iter().zip(controller).zip(pct).map(|((s, c), p)| (s, c, p)).collect();
        let layers = crate::read::ints(&df, summary::layers, path)?;
        Ok(Self { keys, layers, path: path.to_path_buf(), df })
    }

    /// Our value of `metric` for an experiment, if the spec ran it (the first such row:
    /// for the cuboid the nominal 3-layer print).
    fn value(&self, scenario: &str, controller: &str, pct: f64, metric: Metric) -> Option<f64> {
        let row = self.keys.iter().position(|(s, c, p)| s == scenario && c == controller && (p - pct).abs() < 1e-9)?;
        f64s(&self.df, metric.column(), &self.path).ok().map(|v| v[row])
    }

    /// Layers printed by an experiment, if the spec ran it.
    fn layers_of(&self, scenario: &str, controller: &str, pct: f64) -> Option<i64> {
        let row = self.keys.iter().position(|(s, c, p)| s == scenario && c == controller && (p - pct).abs() < 1e-9)?;
        Some(self.layers[row])
    }

    /// Like [`Summary::value`] for the row that printed exactly `layers` layers.
    fn value_with_layers(
        &self,
        scenario: &str,
        controller: &str,
        pct: f64,
        layers: i64,
        metric: Metric,
    ) -> Option<f64> {
        let row = (0..self.keys.len()).find(|&r| {
            let (s, c, p) = &self.keys[r];
            s == scenario && c == controller && (p - pct).abs() < 1e-9 && self.layers[r] == layers
        })?;
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
    let flips = crate::read::ints(&df, recovery::flips_wrong, path)?;
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
7.6 µm; the 4-layer variant is compared above. Its open-loop RMSD ({} µm, paper 8.7) is \
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

/// The 3- and 4-layer open-loop cuboids against Table II, and which is closer.
fn cuboid_layers(summary: &Summary, rows: &mut Vec<Row>) -> String {
    let mut html = String::from("<h4>Cuboid: 3 or 4 open-loop layers (Table II, Sec. V-D), [0 20%]</h4>\n<table><tr><th>layers</th><th>average height (paper 18.5)</th><th>RMSD (paper 8.7)</th><th>distance to Table II</th></tr>\n");
    let mut best: Option<(i64, f64)> = None;
    for layers in [3, 4] {
        let avg = summary.value_with_layers("cuboid", "open_loop", 20.0, layers, Metric::Average);
        let rmsd = summary.value_with_layers("cuboid", "open_loop", 20.0, layers, Metric::Rmsd);
        let (Some(avg), Some(rmsd)) = (avg, rmsd) else { continue };
        // Relative distance to both Table II numbers.
        let distance = (((avg - 18.5) / 18.5).powi(2) + ((rmsd - 8.7) / 8.7).powi(2)).sqrt();
        let _ = writeln!(html, "<tr><td>{layers}</td><td>{avg:.2}</td><td>{rmsd:.2}</td><td>{distance:.2}</td></tr>");
        if best.is_none_or(|(_, d)| distance < d) {
            best = Some((layers, distance));
        }
        for (metric, paper) in [(Metric::Average, 18.5), (Metric::Rmsd, 8.7)] {
            let ours = if matches!(metric, Metric::Average) { avg } else { rmsd };
            rows.push(Row {
                section: "table_ii",
                item: format!("cuboid open_loop [0 20%] {layers} layers {}", metric.column()),
                paper: Some(paper),
                ours,
                unit: "µm",
                source: format!(
                    "out/inkjet/summary.parquet (stage cuboid{}_20_open, inkjet.print_experiment, layers = {layers})",
                    if layers == 4 { "4" } else { "" }
                ),
            });
        }
    }
    html += "</table>\n";
    if let Some((layers, _)) = best {
        let _ = writeln!(
            html,
            "<p>Distance = √((Δavg/18.5)² + (ΔRMSD/8.7)²). The {layers}-layer print matches Table II's open-loop column better. The paper's Sec. V-D-1 says its model-verification cuboid was four layers high (Figs 21-22), while Table II's ideal 22.8 µm is exactly three nominal 7.6 µm layers; the paper does not say how many layers its Table II open-loop cuboid had. Ours: stages cuboid_20_open (3) and cuboid4_20_open (4), out/inkjet/summary.parquet.</p>"
        );
    }
    html
}

/// Edge deformation of the pipe junction, open vs closed loop.
fn pipe_junction(summary: &Summary, path: &Path, rows: &mut Vec<Row>) -> Result<String, StageError> {
    let df = read_parquet(path)?;
    let (controller, region) =
        (strs(&df, edge_deformation::controller, path)?, strs(&df, edge_deformation::region, path)?);
    let (rmse, max, mean) = (
        f64s(&df, edge_deformation::rmse_um, path)?,
        f64s(&df, edge_deformation::max_abs_um, path)?,
        f64s(&df, edge_deformation::mean_err_um, path)?,
    );
    let cells = crate::read::ints(&df, edge_deformation::cells, path)?;
    let mut html = String::from("<h4>Pipe junction (Figs 13-15): two materials, 100 × 100 grid, h_d = 200 µm, [0 20%]</h4>\n<p>Error of the printed part's top surface (the height after the last layer that deposited part material at a cell) against the desired top of the pipe walls; edge = part cells within 2 cells of the part's plan-view boundary. The paper shows this only as pictures (\u{201c}visible deformation near the edge\u{201d} open loop, \u{201c}no visible deformation\u{201d} closed loop), with no number.</p>\n<table><tr><th class=\"t\">controller</th><th class=\"t\">region</th><th>cells</th><th>RMS error (µm)</th><th>max |error| (µm)</th><th>mean error (µm)</th></tr>\n");
    for r in 0..df.height() {
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{}</td><td>{}</td><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td></tr>",
            controller[r].replace('_', " "),
            region[r],
            cells[r],
            rmse[r],
            max[r],
            mean[r]
        );
        rows.push(Row {
            section: "figs_13_15",
            item: format!("pipe_junction {} {} part-top rmse_um", controller[r], region[r]),
            paper: None,
            ours: rmse[r],
            unit: "µm",
            source:
                "out/inkjet/edge_deformation.parquet (stages pipe_20_open, pipe_20_closed, inkjet.print_experiment)"
                    .into(),
        });
    }
    let v = |c: &str, m: Metric| summary.value("pipe_junction", c, 20.0, m).map_or("—".into(), |x| format!("{x:.1}"));
    let _ = writeln!(
        html,
        "</table>\n<p>The whole printed block (part and support) ends at a mean error of {} µm open loop and {} µm closed loop, std {} and {} µm (out/inkjet/summary.parquet, scenario pipe_junction). Our choices, none given by the paper: a T junction of two horizontal pipes (outer radius 20 cells, bore 13 cells, cross-sections squashed to the 200 µm block height), the part material (Table I droplets) chosen per cell and layer by Fig. 10's rule from the measured height (closed loop) or from the assumed fixed layer height (open loop); support droplets g1 = 4.0, g2 = 0.8, g3 = 0.3 µm, a support that spreads more and adds 8.4 instead of 7.6 µm per droplet, so that a fixed-layer-height open loop misplaces the material boundary (models::inkjet::pipe_junction). The part top is quantised to whole layers: closed loop it ends on average a fraction of a layer above the desired surface, because a cell switches to support only once its measured height has left the part.</p>",
        v("open_loop", Metric::MeanError),
        v("closed_loop", Metric::MeanError),
        v("open_loop", Metric::Std),
        v("closed_loop", Metric::Std),
    );
    if let Some(layers) = summary.layers_of("pipe_junction", "closed_loop", 20.0) {
        let _ = writeln!(
            html,
            "<p>The closed loop printed {layers} layers (open loop 26). On 8 836 cells some cell always reads low by the profiler's 1 µm noise, so the optimiser keeps adding a few droplets per layer and the paper's stopping rule (stop when nothing is deposited) fires late or not at all; the print then ends at the safety cap of 4 × 26 + 10 = 114 layers (models::inkjet::experiments). The trickle layers hold a few droplets each and move the mean by about a micrometre.</p>"
        );
    }
    Ok(html)
}

/// The model's one-layer residuals on the virtual scans, one row per effect.
fn scan_residuals(path: &Path, rows: &mut Vec<Row>) -> Result<String, StageError> {
    let df = read_parquet(path)?;
    let effects = strs(&df, scan_residuals::effects, path)?;
    let layer = crate::read::ints(&df, scan_residuals::layer, path)?;
    let (rmse, bias, max) = (
        f64s(&df, scan_residuals::rmse_um, path)?,
        f64s(&df, scan_residuals::bias_um, path)?,
        f64s(&df, scan_residuals::max_abs_um, path)?,
    );
    let mut names: Vec<String> = effects.clone();
    names.dedup();
    let mut html = String::from("<h4>The layer-to-layer model on virtual scans (inkjet-scans datasets, one extra effect each)</h4>\n<p>Each dataset is an open-loop cylinder ([0 20%] shortfall, scans after every one of 53 layers) from the virtual printer with one extra effect switched on (DESIGN §5.2). The nominal model (eqs 2-7, Table I) predicts each scan from the previous scan and the printed pattern; residual = measured − predicted over the footprint. The paper has no such test (its Sec. V-D-1 compares one four-layer print by eye, Figs 21-22).</p>\n<table><tr><th class=\"t\">effects</th><th>layers</th><th>mean RMS residual (µm)</th><th>mean bias (µm)</th><th>bias, first layer</th><th>bias, last layer</th><th>largest |residual|</th></tr>\n");
    for name in &names {
        let idx: Vec<usize> = (0..df.height()).filter(|&r| &effects[r] == name).collect();
        let n = idx.len().max(1) as f64;
        let mean_rmse = idx.iter().map(|&r| rmse[r]).sum::<f64>() / n;
        let mean_bias = idx.iter().map(|&r| bias[r]).sum::<f64>() / n;
        let first = idx.iter().min_by_key(|&&r| layer[r]).map_or(f64::NAN, |&r| bias[r]);
        let last = idx.iter().max_by_key(|&&r| layer[r]).map_or(f64::NAN, |&r| bias[r]);
        let largest = idx.iter().map(|&r| max[r]).fold(0.0, f64::max);
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{name}</td><td>{}</td><td>{mean_rmse:.2}</td><td>{mean_bias:.2}</td><td>{first:.2}</td><td>{last:.2}</td><td>{largest:.2}</td></tr>",
            idx.len()
        );
        for (what, value) in [("mean rmse_um", mean_rmse), ("mean bias_um", mean_bias)] {
            rows.push(Row {
                section: "scan_residuals",
                item: format!("cylinder open_loop [0 20%] effects {name}: {what}"),
                paper: None,
                ours: value,
                unit: "µm",
                source: "out/inkjet/scan_residuals.parquet (stages scans_* → residuals_*, inkjet.generate_scans, inkjet.scan_residuals)".into(),
            });
        }
    }
    html += "</table>\n<p>Without extra effects the residual is the profiler noise on two scans (≈ √2 µm RMS) plus the droplet shortfall the nominal model ignores (a bias near −0.76 µm per layer, the mean 10 % of 7.6 µm). Curing shrinkage deepens that bias by its fraction of the layer; volume drift makes the bias move from the first to the last layer; levelling flow and nozzle bias move material sideways and show in the RMS and the largest residual more than in the mean. A substrate tilt leaves no trace: the model predicts each layer from the measured previous one, so a tilt already in the scan is carried along (it shows in the part's height, not in the model's one-layer error). Source: out/inkjet/scan_residuals.parquet.</p>\n";
    Ok(html)
}

/// The per-cell std of the summed shortfall of the open-loop cylinder's independent
/// droplets, each short by a uniform fraction of `[0, p]` of the Table I droplet:
/// `h·√n·p/√12` (µm), with the droplet height `h` and layer count `n` of
/// `models::inkjet::experiments::cylinder`; `(h, n, std)`.
fn shortfall_std_um(p: f64) -> (f64, usize, f64) {
    let scenario = models::inkjet::experiments::cylinder(p);
    let (droplet_um, layers) = (scenario.model.droplet_volume_um(), scenario.open_loop_layers);
    (droplet_um, layers, droplet_um * (layers as f64).sqrt() * p / 12f64.sqrt())
}

/// Why our open-loop std is smaller than the paper's.
fn std_gap(summary: &Summary) -> String {
    let v =
        |p: f64, m: Metric| summary.value("cylinder", "open_loop", p, m).map_or("—".into(), |x| format!("{x:.1}"));
    let (droplet_um, layers, shortfall_std) = shortfall_std_um(0.2);
    format!(
        "<h4>The open-loop std gap (ours {} / {} µm, paper 15.0 / 16.6 µm)</h4>\n<p>Without any droplet variation our open-loop cylinder's std is {} µm (stage cylinder_0_open, mean error {} µm): that is the deterministic dome of the corrected model over the footprint, rim cells included. The random shortfall does not add to it (std {} µm at [0 20%]): {layers} independent droplets per cell average out (per-cell std of their sum ≈ h·√n·p/√12 with h = {droplet_um:.1} µm per droplet and n = {layers} layers, {shortfall_std:.1} µm at p = 20 %; models::inkjet::experiments::cylinder), and a lower part also has a shallower dome. The paper's std barely grows from 20 % to 40 % variation (15.0 → 16.6), so most of its std is deterministic too: its dome is about twice as deep as ours. Other readings of the variation do not help: a fixed per-nozzle variation would make column-to-column differences accumulate over {layers} layers and roughly double the std from 20 % to 40 %, and a per-layer variation moves every cell together and leaves the std unchanged. Our std already includes the edge roll-off (it is over every footprint cell, the footprint chosen to reproduce the mean errors 44.1 / 84.7); leaving the rim out would make it smaller still, so the metric's cell set does not explain the gap. The paper names no other mechanism than the flow to the neighbours of eqs 3-5, whose eq. 4 is OCR-damaged in our copy; a model that sends more volume off the part at the rim would deepen the dome but also raise the open-loop mean error, which we already match. We keep the model as DESIGN §5.2 corrects it and report the gap.</p>\n",
        v(20.0, Metric::Std),
        v(40.0, Metric::Std),
        v(0.0, Metric::Std),
        v(0.0, Metric::MeanError),
        v(20.0, Metric::Std),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cylinder_shortfall_std_is_the_uniform_sum_closed_form() {
        // Table I: a droplet adds 7.6 µm, so 400 µm is 53 layers; a uniform shortfall on
        // [0, p] of h has variance (h·p)²/12 per droplet.
        let (droplet_um, layers, std_um) = shortfall_std_um(0.2);
        assert!((droplet_um - 7.6).abs() < 1e-9 && layers == 53);
        assert!((std_um - 7.6 * 53f64.sqrt() * 0.2 / 12f64.sqrt()).abs() < 1e-9, "{std_um}");
    }

    #[test]
    fn every_paper_number_maps_to_a_summary_column() {
        for (_, _, _, metric, paper, figure) in PAPER {
            assert!(paper > 0.0);
            assert!(summary::TABLE.column(metric.column()).is_some());
            assert!(["fig11", "fig12", "table_ii"].contains(&figure_key(figure)));
        }
    }
}
