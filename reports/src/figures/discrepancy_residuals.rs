//! `figure.discrepancy_residuals`: what a model gets wrong (DESIGN §7 step 1, show), in
//! any domain of the discrepancy engine: the held-out residuals (measured − predicted)
//! of the baseline and of the extended model against each candidate variable, bin
//! means with their 95 % intervals over groups, and each variable's structure share
//! (`residuals.parquet`); the named cause's signature is the structure the extension
//! removes. Reads an `fdm.discrepancy` (per printer, widths in mm), `inkjet.discrepancy`
//! (per dataset, heights in µm) or `thermal.discrepancy` stage (per filmed print, in
//! noise standard deviations); which one, it tells from the residual columns' names,
//! the only columns in which the domains' tables differ.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use polars::prelude::DataFrame;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::discrepancy::{fdm, inkjet, thermal, Engine};

use crate::read::{f64s, no_rows, read_parquet, strs};
use crate::style::{draw_house_legend, draw_png_and_svg, house_mesh, text, PALETTE};

/// Colour of the baseline in every discrepancy figure.
pub(crate) const BASELINE: RGBColor = PALETTE[1];
/// Colour of the extended model.
pub(crate) const EXTENDED: RGBColor = PALETTE[0];

/// The domains whose engine tables this figure reads, as their engine stages name them.
const DOMAINS: [(&str, &Engine); 3] = [
    ("fdm.discrepancy", &fdm::ENGINE),
    ("inkjet.discrepancy", &inkjet::ENGINE),
    ("thermal.discrepancy", &thermal::ENGINE),
];

pipeline::params! {
    /// The parameters of `figure.discrepancy_residuals`.
    pub struct ResidualsParams {
        /// Data set whose residuals are drawn: a printer of `fdm.discrepancy`, a dataset (input name) of `inkjet.discrepancy` or `thermal.discrepancy`.
        pub data_set: String,
    }
}

/// What the figure reads of one domain's engine run: the binned residuals and the
/// models' names. The columns every domain names alike are named through the FDM
/// declarations (the tables' template makes them the same).
macro_rules! residual_reads {
    ($domain:ident) => {{
        use tables::discrepancy::$domain::{gain, residuals, ENGINE};
        &[
            Reads {
                table: &residuals::TABLE,
                columns: &[
                    ENGINE.set,
                    residuals::model,
                    residuals::variable,
                    residuals::unit,
                    residuals::label,
                    residuals::bin_lo,
                    residuals::bin_hi,
                    ENGINE.mean_residual,
                    ENGINE.residual_ci_lo,
                    ENGINE.residual_ci_hi,
                    residuals::structure,
                ],
            },
            Reads { table: &gain::TABLE, columns: &[ENGINE.set, gain::baseline, gain::extended_model] },
        ]
    }};
}

/// The engine run whose held-out residuals are drawn.
const DISCREPANCY: Input = Input::one(
    "discrepancy",
    &[Source::Stage(DOMAINS[0].0), Source::Stage(DOMAINS[1].0), Source::Stage(DOMAINS[2].0)],
    "the engine's held-out residuals and the models' names (`residuals.parquet`, `gain.parquet`)",
)
.reading_by_kind(&[
    (DOMAINS[0].0, residual_reads!(fdm)),
    (DOMAINS[1].0, residual_reads!(inkjet)),
    (DOMAINS[2].0, residual_reads!(thermal)),
]);

/// Panels per row of the figure, one per candidate variable.
const PANEL_COLUMNS: usize = 3;

/// The `figure.discrepancy_residuals` stage kind.
pub struct DiscrepancyResidualsFigure;

impl Stage for DiscrepancyResidualsFigure {
    type Params = ResidualsParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.discrepancy_residuals",
        // 2: the legend goes to the corner of the first panel that it hides least of.
        version: 2,
        summary: "Held-out residuals of the baseline and the extended model against every candidate variable, bin means with 95 % intervals, in any domain of the discrepancy engine → discrepancy_residuals.png/.svg",
        implements: "DESIGN §7 step 1 (show)",
        inputs: &[DISCREPANCY],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &ResidualsParams) -> Result<(), StageError> {
        let set = &p.data_set;
        let dir = &ctx.input(&DISCREPANCY).dir;
        let path = dir.join(fdm::residuals::TABLE.file());
        let table = read_parquet(&path)?;
        let engine = engine_of(&table, &path)?;
        let panels = read_residuals(&table, &path, engine, set)?;
        let models = Models::read(&dir.join(fdm::gain::TABLE.file()), engine, set)?;
        let stem = ctx.output_path("discrepancy_residuals")?;
        let title = models.title(set);
        let rows = panels.len().div_ceil(PANEL_COLUMNS).max(1) as u32;
        draw_png_and_svg(
            &stem,
            (1500, 370 * rows + 40),
            |a| draw_residuals(a, &title, &models, &panels),
            |a| draw_residuals(a, &title, &models, &panels),
        )
    }
}

/// The domain of a `residuals.parquet`: the one whose data-set and residual columns it has.
fn engine_of(table: &DataFrame, path: &Path) -> Result<&'static Engine, StageError> {
    let has = |name: &str| table.column(name).is_ok();
    DOMAINS.iter().map(|d| d.1).find(|e| has(e.set) && has(e.mean_residual)).ok_or_else(|| {
        let expected: Vec<String> =
            DOMAINS.iter().map(|(_, e)| format!("`{}` with `{}`", e.set, e.mean_residual)).collect();
        no_rows(
            path,
            fdm::ENGINE.mean_residual,
            &format!("the residual columns of an engine table: {}", expected.join(", or ")),
        )
    })
}

/// The models a figure compares, as `gain.parquet` names them, and the residuals' axis.
pub(crate) struct Models {
    /// The baseline (`lag_model`).
    pub(crate) baseline: String,
    /// The baseline extended by the causes named (`lag_model + width_cap`), or the baseline.
    pub(crate) extended: String,
    /// The residual axis's description with the domain's unit.
    y_desc: String,
}

impl Models {
    /// The models of data set `set` in the `gain.parquet` at `path` of `engine`'s domain.
    pub(crate) fn read(path: &Path, engine: &Engine, set: &str) -> Result<Self, StageError> {
        let df = read_parquet(path)?;
        let sets = strs(&df, engine.set, path)?;
        let (baselines, extended) =
            (strs(&df, fdm::gain::baseline, path)?, strs(&df, fdm::gain::extended_model, path)?);
        let i = (0..df.height())
            .find(|&i| sets[i] == set)
            .ok_or_else(|| no_rows(path, engine.set, &format!("data set `{set}`")))?;
        let unit = engine.residuals.column(engine.mean_residual).map_or("", |c| c.unit);
        let y_desc = match unit {
            "1" => "residual (noise sd)".to_string(),
            unit => format!("residual ({unit})"),
        };
        Ok(Self { baseline: baselines[i].clone(), extended: extended[i].clone(), y_desc })
    }

    /// Nothing was named: the extended model is the baseline.
    pub(crate) fn unchanged(&self) -> bool {
        self.extended == self.baseline
    }

    /// The baseline in words (`lag model`).
    pub(crate) fn baseline_words(&self) -> String {
        self.baseline.replace('_', " ")
    }

    fn title(&self, set: &str) -> String {
        let baseline = self.baseline_words();
        if self.unchanged() {
            format!("{set}: held-out residual (measured − predicted) of the {baseline} (no cause named)")
        } else {
            format!("{set}: held-out residual (measured − predicted) of the {baseline} and of {}", self.extended)
        }
    }
}

/// One variable's bins for both models.
struct ResidualPanel {
    variable: String,
    unit: String,
    /// Per model (`baseline`, `extended`): structure share and `(x, mean, lo, hi)` bins.
    models: BTreeMap<String, (f64, Vec<[f64; 4]>)>,
    /// Category labels at their codes, for a categorical variable: one without a unit
    /// whose every bin holds one value (the FDM phase, a droplet count); a variable
    /// without a unit binned in ranges (a layer or nozzle index) keeps a numeric axis.
    labels: Vec<(f64, String)>,
    /// Some bin spans a range of values.
    binned_in_ranges: bool,
}

fn read_residuals(df: &DataFrame, path: &Path, engine: &Engine, set: &str) -> Result<Vec<ResidualPanel>, StageError> {
    use fdm::residuals as r;
    let (sets, models, variables) =
        (strs(df, engine.set, path)?, strs(df, r::model, path)?, strs(df, r::variable, path)?);
    let (units, labels) = (strs(df, r::unit, path)?, strs(df, r::label, path)?);
    let (lo, hi, mean) =
        (f64s(df, r::bin_lo, path)?, f64s(df, r::bin_hi, path)?, f64s(df, engine.mean_residual, path)?);
    let (ci_lo, ci_hi, structure) =
        (f64s(df, engine.residual_ci_lo, path)?, f64s(df, engine.residual_ci_hi, path)?, f64s(df, r::structure, path)?);
    let mut panels: Vec<ResidualPanel> = Vec::new();
    for i in (0..df.height()).filter(|&i| sets[i] == set) {
        let index = match panels.iter().position(|p| p.variable == variables[i]) {
            Some(k) => k,
            None => {
                panels.push(ResidualPanel {
                    variable: variables[i].clone(),
                    unit: units[i].clone(),
                    models: BTreeMap::new(),
                    labels: Vec::new(),
                    binned_in_ranges: false,
                });
                panels.len() - 1
            }
        };
        let panel = &mut panels[index];
        let x = 0.5 * (lo[i] + hi[i]);
        panel.binned_in_ranges |= lo[i] != hi[i];
        if units[i].is_empty() && !panel.labels.iter().any(|l| l.0 == x) {
            panel.labels.push((x, labels[i].clone()));
        }
        let entry = panel.models.entry(models[i].clone()).or_insert((structure[i], Vec::new()));
        if mean[i].is_finite() {
            entry.1.push([x, mean[i], ci_lo[i], ci_hi[i]]);
        }
    }
    if panels.is_empty() {
        return Err(no_rows(path, engine.set, &format!("data set `{set}`")));
    }
    for panel in panels.iter_mut().filter(|p| p.binned_in_ranges) {
        panel.labels.clear();
    }
    Ok(panels)
}

fn draw_residuals<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    models: &Models,
    panels: &[ResidualPanel],
) -> Result<(), String> {
    let width_px = area.dim_in_pixel().0 as f64;
    let area = area.margin(12, 6, 6, 14).titled(title, text(title_size(title, width_px))).map_err(|e| e.to_string())?;
    let cells = area.split_evenly((panels.len().div_ceil(PANEL_COLUMNS), PANEL_COLUMNS));
    // No panel's scale is finer than a third of the largest mean of any, so that a
    // variable without structure does not look as if it had some.
    let floor = panels.iter().map(largest_mean).fold(0.0f64, f64::max) / 3.0;
    for (k, (panel, cell)) in panels.iter().zip(&cells).enumerate() {
        draw_residual_panel(cell, panel, models, floor, k == 0).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The title's font size: 24 px, smaller for a title too long to fit `width_px` (a
/// character of this font is about half its size wide; long model names do this).
fn title_size(title: &str, width_px: f64) -> f64 {
    let chars = title.chars().count().max(1) as f64;
    24.0f64.min(0.95 * width_px / (0.5 * chars))
}

fn largest_mean(panel: &ResidualPanel) -> f64 {
    panel.models.values().flat_map(|m| m.1.iter().map(|b| b[1].abs())).filter(|v| v.is_finite()).fold(0.0f64, f64::max)
}

/// The panel's half-height: the largest bin mean (at least `floor`), or interval end
/// within three times it (a bin with few lines has a wide interval that would flatten
/// every mean).
fn residual_span(panel: &ResidualPanel, floor: f64) -> f64 {
    let bins = || panel.models.values().flat_map(|m| m.1.iter());
    let means = largest_mean(panel).max(floor).max(0.005);
    let ends = bins().flat_map(|b| [b[2].abs(), b[3].abs()]).filter(|v| v.is_finite() && *v <= 3.0 * means);
    ends.fold(means, f64::max) * 1.15
}

fn draw_residual_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &ResidualPanel,
    models: &Models,
    floor: f64,
    legend: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let span = residual_span(panel, floor);
    let share = |m: &str| panel.models.get(m).map_or(f64::NAN, |v| v.0);
    let caption = if models.unchanged() {
        format!("{}: structure {:.0} %", panel.variable, 100.0 * share("baseline"))
    } else {
        format!("{}: structure {:.0} % → {:.0} %", panel.variable, 100.0 * share("baseline"), 100.0 * share("extended"))
    };
    let xs: Vec<f64> = panel.models.values().flat_map(|m| m.1.iter().map(|b| b[0])).collect();
    let (x_min, x_max) = xs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    let pad = ((x_max - x_min) * 0.06).max(0.5 * if panel.unit.is_empty() { 1.0 } else { 1e-6 });
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(17.0))
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(58)
        .build_cartesian_2d((x_min - pad)..(x_max + pad), -span..span)?;
    let labels = panel.labels.clone();
    let x_desc =
        if panel.unit.is_empty() { panel.variable.clone() } else { format!("{} ({})", panel.variable, panel.unit) };
    house_mesh(&mut chart)
        .x_desc(x_desc)
        .y_desc(models.y_desc.as_str())
        .x_labels(if labels.is_empty() { 6 } else { labels.len() })
        .x_label_formatter(&|x| match labels.iter().find(|l| (l.0 - x).abs() < 1e-9) {
            Some(l) => l.1.clone(),
            None if labels.is_empty() => format_tick(*x),
            None => String::new(),
        })
        .y_label_formatter(&|y| format!("{y:.3}"))
        .draw()?;
    chart.draw_series(LineSeries::new([(x_min - pad, 0.0), (x_max + pad, 0.0)], BLACK.mix(0.5).stroke_width(1)))?;
    let offset = 0.012 * (x_max - x_min + 2.0 * pad);
    let series = [
        ("baseline", BASELINE, -offset, models.baseline.clone()),
        ("extended", EXTENDED, offset, models.extended.clone()),
    ];
    let unchanged = models.unchanged();
    for (model, colour, shift, label) in series {
        let Some((_, bins)) = panel.models.get(model) else { continue };
        if unchanged && model == "extended" {
            continue;
        }
        let shift = if unchanged { 0.0 } else { shift };
        let style = colour.stroke_width(2);
        let clip = |y: f64| y.clamp(-span, span);
        chart.draw_series(
            bins.iter()
                .filter(|b| b[2].is_finite() && b[3].is_finite())
                .map(move |b| PathElement::new([(b[0] + shift, clip(b[2])), (b[0] + shift, clip(b[3]))], style)),
        )?;
        chart
            .draw_series(bins.iter().map(move |b| Circle::new((b[0] + shift, b[1]), 4, colour.filled())))?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 8, y), 4, colour.filled()));
    }
    if legend {
        draw_house_legend(&mut chart, quietest_corner(panel, span, x_min - pad, x_max + pad))?;
    }
    Ok(())
}

/// The corner of a panel whose legend would hide the fewest bin means and interval
/// ends: a legend takes about the outer half of the width and the outer quarter of the
/// height (the upper right on a tie).
fn quietest_corner(panel: &ResidualPanel, span: f64, x_lo: f64, x_hi: f64) -> SeriesLabelPosition {
    let x_mid = 0.5 * (x_lo + x_hi);
    let points = || {
        let ends =
            panel.models.values().flat_map(|m| m.1.iter().flat_map(|b| [(b[0], b[1]), (b[0], b[2]), (b[0], b[3])]));
        ends.filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    let hidden = |upper: bool, right: bool| {
        points()
            .filter(|&(x, y)| (x >= x_mid) == right && if upper { y >= span / 2.0 } else { y <= -span / 2.0 })
            .count()
    };
    let corners = [
        (SeriesLabelPosition::UpperRight, hidden(true, true)),
        (SeriesLabelPosition::UpperLeft, hidden(true, false)),
        (SeriesLabelPosition::LowerRight, hidden(false, true)),
        (SeriesLabelPosition::LowerLeft, hidden(false, false)),
    ];
    corners.into_iter().min_by_key(|(_, n)| *n).map_or(SeriesLabelPosition::UpperRight, |(corner, _)| corner)
}

fn format_tick(x: f64) -> String {
    if x.abs() >= 100.0 {
        format!("{x:.0}")
    } else if x.abs() >= 1.0 {
        format!("{x:.1}")
    } else {
        format!("{x:.2}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, declared, write_declared};
    use pipeline::schema::Table;
    use polars::df;
    use polars::prelude::{Column, NamedFrom, Series};

    /// A domain's `residuals.parquet` for data set `set`: three variables (one with a
    /// unit, one without binned in ranges, one categorical) × two models, a linear trend of the bin means that the extension
    /// shrinks tenfold.
    fn residuals_table(engine: &Engine, set: &str, bins: usize) -> DataFrame {
        let (mut model, mut variable, mut unit, mut label) = (vec![], vec![], vec![], vec![]);
        let (mut lo, mut hi, mut mean) = (vec![], vec![], vec![]);
        for m in ["baseline", "extended"] {
            for v in ["position_mm", "layer", "phase"] {
                for b in 0..bins {
                    let edges =
                        if v == "phase" { (b as f64, b as f64) } else { (10.0 * b as f64, 10.0 * (b + 1) as f64) };
                    let scale = if m == "baseline" { 0.1 } else { 0.01 };
                    model.push(m);
                    variable.push(v);
                    unit.push(if v == "position_mm" { "mm" } else { "" });
                    label.push(format!("p{b}"));
                    lo.push(edges.0);
                    hi.push(edges.1);
                    mean.push(scale * (b as f64 - 6.0) / 6.0);
                }
            }
        }
        let n = mean.len();
        let ci_lo: Vec<f64> = mean.iter().map(|v| v - 0.01).collect();
        let ci_hi: Vec<f64> = mean.iter().map(|v| v + 0.01).collect();
        use fdm::residuals as r;
        let mut table = df!(r::model => model, r::variable => variable, r::unit => unit, r::label => label,
            r::bin_lo => lo, r::bin_hi => hi, r::structure => vec![0.3; n])
        .unwrap();
        for (name, values) in
            [(engine.mean_residual, mean), (engine.residual_ci_lo, ci_lo), (engine.residual_ci_hi, ci_hi)]
        {
            table.with_column(Column::from(Series::new(name.into(), values))).unwrap();
        }
        table.with_column(Column::from(Series::new(engine.set.into(), vec![set; n]))).unwrap();
        declared(engine.residuals, table)
    }

    fn gain_table(engine: &Engine, set: &str, baseline: &str, extended: &str) -> DataFrame {
        let mut table = df!(fdm::gain::baseline => [baseline], fdm::gain::extended_model => [extended]).unwrap();
        table.with_column(Column::from(Series::new(engine.set.into(), [set]))).unwrap();
        declared(engine.gain, table)
    }

    fn write(dir: &Path, table: &'static Table, df: DataFrame) {
        write_declared(dir, table, df);
    }

    #[test]
    fn draws_the_residuals_of_every_domain_from_its_tables() {
        let cases = [
            (&fdm::ENGINE, "taz5", "lag_model", "lag_model + width_cap", "residual (mm)"),
            (&inkjet::ENGINE, "print_nozzle_bias", "layer_model", "layer_model + nozzle_bias", "residual (µm)"),
            (
                &thermal::ENGINE,
                "print_tau",
                "capture_and_layer_model",
                "capture_and_layer_model",
                "residual (noise sd)",
            ),
        ];
        for (engine, set, baseline, extended, y_desc) in cases {
            let dir = tempfile::tempdir().unwrap();
            let bins = 12;
            write(dir.path(), engine.residuals, residuals_table(engine, set, bins));
            write(dir.path(), engine.gain, gain_table(engine, set, baseline, extended));
            let path = dir.path().join(engine.residuals.file());
            let table = read_parquet(&path).unwrap();
            assert_eq!(engine_of(&table, &path).unwrap(), engine, "{set}");
            let panels = read_residuals(&table, &path, engine, set).unwrap();
            assert_eq!(panels.len(), 3);
            assert_eq!(panels[2].labels.len(), bins, "the categorical variable's labels");
            assert!(panels[0].labels.is_empty() && panels[1].labels.is_empty(), "numeric axes");
            assert!(read_residuals(&table, &path, engine, "another").is_err());
            let models = Models::read(&dir.path().join(engine.gain.file()), engine, set).unwrap();
            assert_eq!(models.y_desc, y_desc);
            let title = models.title(set);
            let expected = format!("of the {}", baseline.replace('_', " "));
            assert!(title.contains(&expected), "{title}");
            assert_eq!(models.unchanged(), baseline == extended);
            assert_eq!(title.contains("no cause named"), models.unchanged(), "{title}");
            let stem = dir.path().join("r");
            let draw = |a: &DrawingArea<BitMapBackend, Shift>| draw_residuals(a, &title, &models, &panels);
            let draw_svg = |a: &DrawingArea<SVGBackend, Shift>| draw_residuals(a, &title, &models, &panels);
            draw_png_and_svg(&stem, (1500, 1150), draw, draw_svg).unwrap();
            assert_drawn(&stem);
        }
    }

    #[test]
    fn the_legend_goes_to_the_corner_it_hides_least_of() {
        let panel = |bins: Vec<[f64; 4]>| ResidualPanel {
            variable: "v".into(),
            unit: String::new(),
            models: BTreeMap::from([("baseline".to_string(), (0.0, bins))]),
            labels: vec![],
            binned_in_ranges: false,
        };
        // Quiet everywhere: the upper right.
        let flat = panel(vec![[0.0, 0.0, -0.1, 0.1], [10.0, 0.0, -0.1, 0.1]]);
        assert_eq!(quietest_corner(&flat, 1.0, 0.0, 10.0), SeriesLabelPosition::UpperRight);
        // High means on both sides and a low interval end on the left: the lower right.
        let busy = panel(vec![[1.0, 0.0, -0.8, 0.1], [2.0, 0.7, 0.6, 0.8], [8.0, 0.8, 0.7, 0.9], [9.0, 0.6, 0.5, 0.7]]);
        assert_eq!(quietest_corner(&busy, 1.0, 0.0, 10.0), SeriesLabelPosition::LowerRight);
    }

    #[test]
    fn a_long_title_gets_a_smaller_font_that_fits() {
        assert_eq!(title_size("short", 1500.0), 24.0);
        let long = "x".repeat(150);
        let size = title_size(&long, 1500.0);
        assert!(size < 24.0 && 0.5 * size * 150.0 <= 0.95 * 1500.0 + 1e-9, "{size}");
    }

    #[test]
    fn a_table_of_no_domain_is_named_with_what_was_expected() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("residuals.parquet");
        let table = df!("dataset" => ["a"], "mean_residual_in" => [0.1]).unwrap();
        let err = engine_of(&table, &path).unwrap_err().to_string();
        assert!(err.contains("residuals.parquet") && err.contains("`printer` with `mean_residual_mm`"), "{err}");
        assert!(err.contains("`dataset` with `mean_residual_sd`"), "{err}");
    }
}
