//! `figure.fdm_transfer_matrix`: transfer among several printers (paper 000 Fig. 9
//! carried to every source → target task). One panel per target printer: the median
//! held-out RMSE improvement over single-printer learning against the number of target
//! training lines, for the source-centred prior and the negative-transfer guard from
//! each source (one colour per source; dashed: source-centred, solid: guarded) and for
//! co-learning from all the other printers (black, with its 95 % bootstrap interval);
//! grey dots: the bound in hindsight, how far the best prior and λ per training subset,
//! chosen on its own held-out lines, would go (not a method; `models::fdm::colearn`).
//! The y axis is clipped so that a catastrophic transfer cannot flatten the rest; a
//! clipped value is drawn as a triangle on the bottom edge. Reads
//! `transfer_matrix.parquet`.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
use polars::prelude::DataFrame;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::transfer_matrix;

use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_house_legend, draw_png_and_svg, house_mesh, text, PALETTE};

/// The `figure.fdm_transfer_matrix` stage kind.
pub struct TransferMatrixFigure;

pipeline::params! {
    /// The parameters of `figure.fdm_transfer_matrix`.
    pub struct TransferMatrixParams {
        /// Figure title (default: says what is compared and cites paper 000 Fig. 9).
        pub title: String = "",
    }
}

/// The transfer matrix drawn.
const MATRIX: Input = Input::one(
    "matrix",
    &[Source::Stage("fdm.transfer_matrix")],
    "the median improvements with their intervals per task, n and method (`transfer_matrix.parquet`)",
)
.reading(READS);

/// What [`load`] reads of `transfer_matrix.parquet`.
pub const READS: &[Reads] = &[Reads {
    table: &transfer_matrix::TABLE,
    columns: &[
        transfer_matrix::sources,
        transfer_matrix::target,
        transfer_matrix::method,
        transfer_matrix::n_train,
        transfer_matrix::improvement_pct,
        transfer_matrix::ci_lo_pct,
        transfer_matrix::ci_hi_pct,
    ],
}];

/// Figure size in pixels (panels in a grid of two columns).
const PANEL_PX: (u32, u32) = (760, 520);
/// The y axis never goes below this (%): worse transfers are marked on the edge.
const FLOOR_PCT: f64 = -40.0;
/// The legend's size (upper left, over small n): pixels per entry (14 px text and its
/// spacing) and of its padding, and the pixels of a panel that are not plot (caption,
/// margins, n labels), measured on the drawn figure.
const LEGEND_ENTRY_PX: f64 = 17.0;
const LEGEND_PAD_PX: f64 = 12.0;
const PANEL_NON_PLOT_PX: f64 = 85.0;
/// Gap between the legend's lower edge and the highest drawn value (fraction of the
/// plot's height).
const LEGEND_GAP: f64 = 0.04;
/// How far apart along n the clipped-value triangles of neighbouring series sit.
const CLIPPED_DODGE: f64 = 0.06;

/// One summary row of `transfer_matrix.parquet`.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// `+`-joined source printers.
    pub sources: String,
    /// Training lines.
    pub n_train: i64,
    /// Method name.
    pub method: String,
    /// Median improvement over single (%).
    pub improvement_pct: f64,
    /// Its 95 % interval (%).
    pub ci_pct: (f64, f64),
}

/// The summary rows by target printer.
pub type Matrix = BTreeMap<String, Vec<Cell>>;

impl Stage for TransferMatrixFigure {
    type Params = TransferMatrixParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_transfer_matrix",
        version: 5,
        summary: "Median improvement over single-printer learning vs target training lines, one panel per target: source-centred and guarded transfer from each source, co-learning with its interval, the bound in hindsight → transfer_matrix.png/.svg",
        implements: "paper 000 Fig. 9 over several printers",
        inputs: &[MATRIX],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &TransferMatrixParams) -> Result<(), StageError> {
        let matrix = load(&ctx.input(&MATRIX).dir)?;
        let title = crate::figures::common::title_or(&p.title, || {
            "Transfer among printers: median RMSE improvement over single-printer learning (cf. paper 000 Fig. 9)"
                .to_string()
        });
        let rows = matrix.len().div_ceil(2) as u32;
        let size = (2 * PANEL_PX.0, rows * PANEL_PX.1 + 60);
        let stem = ctx.output_path("transfer_matrix")?;
        draw_png_and_svg(&stem, size, |a| draw(a, &title, &matrix), |a| draw(a, &title, &matrix))
    }
}

/// Reads `<dir>/transfer_matrix.parquet`.
pub fn load(dir: &Path) -> Result<Matrix, StageError> {
    let path = dir.join(transfer_matrix::TABLE.file());
    matrix_of(&read_parquet(&path)?, &path)
}

/// [`load`] of the table already read from `path`.
pub fn matrix_of(df: &DataFrame, path: &Path) -> Result<Matrix, StageError> {
    use transfer_matrix as t;
    let (sources, target, method) =
        (strs(df, t::sources, path)?, strs(df, t::target, path)?, strs(df, t::method, path)?);
    let n_train = ints(df, t::n_train, path)?;
    let (imp, lo, hi) =
        (f64s(df, t::improvement_pct, path)?, f64s(df, t::ci_lo_pct, path)?, f64s(df, t::ci_hi_pct, path)?);
    let mut matrix = Matrix::new();
    for i in (0..df.height()).filter(|&i| imp[i].is_finite() && method[i] != "single") {
        matrix.entry(target[i].clone()).or_default().push(Cell {
            sources: sources[i].clone(),
            n_train: n_train[i],
            method: method[i].clone(),
            improvement_pct: imp[i],
            ci_pct: (lo[i], hi[i]),
        });
    }
    if matrix.is_empty() {
        return Err(no_rows(path, t::improvement_pct, "a finite improvement of a transfer method"));
    }
    Ok(matrix)
}

/// One panel per target, two per row.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, matrix: &Matrix) -> Result<(), String> {
    let area = area.margin(12, 6, 6, 14).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    let rows = matrix.len().div_ceil(2);
    let panels = area.split_evenly((rows, 2));
    for ((target, cells), panel) in matrix.iter().zip(&panels) {
        draw_panel(panel, target, cells).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    target: &str,
    cells: &[Cell],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let n_max = cells.iter().map(|c| c.n_train).max().unwrap_or(1) as f64;
    let mut sources: Vec<&str> =
        cells.iter().filter(|c| !c.sources.contains('+')).map(|c| c.sources.as_str()).collect();
    sources.sort_unstable();
    sources.dedup();
    let co: Vec<&Cell> = cells.iter().filter(|c| c.method == CO_LEARNING).collect();
    let bound = bound_series(cells);
    let entries =
        sources.len() * SINGLE_SOURCE_SERIES.len() + usize::from(!co.is_empty()) + usize::from(!bound.is_empty());
    let top = axis_top(drawn_top_pct(cells).clamp(10.0, 100.0), entries);
    let y = |v: f64| v.max(FLOOR_PCT);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("target {target}"), text(18.0))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.5..n_max + 0.5, FLOOR_PCT..top)?;
    house_mesh(&mut chart)
        .x_desc("target training lines n")
        .y_desc("median RMSE improvement (%)")
        .x_labels(n_max as usize)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    chart.draw_series(DashedLineSeries::new([(0.5, 0.0), (n_max + 0.5, 0.0)], 6, 4, BLACK.stroke_width(1)))?;
    let slots = (sources.len() * SINGLE_SOURCE_SERIES.len()) as f64;
    for (k, source) in sources.iter().enumerate() {
        let colour = PALETTE[k % PALETTE.len()];
        for (m, (method, dashed)) in SINGLE_SOURCE_SERIES.into_iter().enumerate() {
            let pts = series(cells, source, method);
            // Source-centred: dashed and lighter (the legend's swatch and the clipped-value
            // triangles are lighter too).
            let shade = if dashed { colour.mix(0.55) } else { colour.to_rgba() };
            let style = shade.stroke_width(if dashed { 2 } else { 3 });
            let label = format!("{source}: {}", if dashed { "source-centred" } else { "guarded" });
            let drawn = if dashed {
                chart.draw_series(DashedLineSeries::new(pts.iter().map(|p| (p.0, y(p.1))), 8, 5, style))?
            } else {
                chart.draw_series(LineSeries::new(pts.iter().map(|p| (p.0, y(p.1))), style))?
            };
            drawn.label(label).legend(move |(x, yy)| PathElement::new([(x, yy), (x + 20, yy)], style));
            // Clipped values: a triangle on the floor in the series' colour, each series
            // shifted a little along n so that several clipped at one n all show.
            let slot = (k * SINGLE_SOURCE_SERIES.len() + m) as f64;
            let dodge = CLIPPED_DODGE * (slot - (slots - 1.0) / 2.0);
            let clipped = pts.iter().filter(|p| p.1 < FLOOR_PCT);
            chart
                .draw_series(clipped.map(|p| TriangleMarker::new((p.0 + dodge, FLOOR_PCT + 1.5), 6, shade.filled())))?;
        }
    }
    if !co.is_empty() {
        let style = BLACK.stroke_width(3);
        let pts: Vec<(f64, f64)> = co.iter().map(|c| (c.n_train as f64, y(c.improvement_pct))).collect();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), style))?
            .label("co-learning from all others (95 % interval)")
            .legend(move |(x, yy)| PathElement::new([(x, yy), (x + 20, yy)], style));
        chart.draw_series(co.iter().map(|c| {
            let x = c.n_train as f64;
            PathElement::new([(x, y(c.ci_pct.0)), (x, y(c.ci_pct.1))], BLACK.stroke_width(1))
        }))?;
    }
    if !bound.is_empty() {
        let style = RGBColor(120, 120, 120).stroke_width(2);
        chart
            .draw_series(DashedLineSeries::new(bound.iter().map(|p| (p.0, y(p.1))), 3, 4, style))?
            .label("bound in hindsight (prior and λ best on the held-out lines)")
            .legend(move |(x, yy)| PathElement::new([(x, yy), (x + 20, yy)], style));
    }
    draw_house_legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

/// The top of the y axis (%) that leaves the legend of `entries` entries its height above
/// `data_top`, the highest drawn value, with [`LEGEND_GAP`] between them: with the
/// legend taking the fraction `f` of the plot's height from the top,
/// `(top − data_top) / (top − FLOOR_PCT) = f`.
fn axis_top(data_top: f64, entries: usize) -> f64 {
    let plot_px = f64::from(PANEL_PX.1) - PANEL_NON_PLOT_PX;
    let f = ((LEGEND_PAD_PX + LEGEND_ENTRY_PX * entries as f64) / plot_px + LEGEND_GAP).min(0.8);
    (data_top - f * FLOOR_PCT) / (1.0 - f)
}

/// Not a method: per training subset the prior and `λ` best on its own held-out lines
/// (`models::fdm::colearn`), drawn as how far any choice of them could go.
const BOUND: &str = "hindsight_bound";

/// `(n, improvement)` of the bound in hindsight, ascending in `n`: per `n` the largest
/// over the panel's tasks (the task with every other printer as a source, where there is
/// one, searches every prior the others do).
fn bound_series(cells: &[Cell]) -> Vec<(f64, f64)> {
    let mut best: BTreeMap<i64, f64> = BTreeMap::new();
    for c in cells.iter().filter(|c| c.method == BOUND && c.improvement_pct.is_finite()) {
        let v = best.entry(c.n_train).or_insert(f64::NEG_INFINITY);
        *v = v.max(c.improvement_pct);
    }
    best.into_iter().map(|(n, v)| (n as f64, v)).collect()
}

/// The single-source methods a panel draws per source, each with whether its line is
/// dashed (the source-centred prior) or solid (the guard).
const SINGLE_SOURCE_SERIES: [(&str, bool); 2] = [("transfer_source_mean", true), ("guarded", false)];

/// The co-learning method, drawn with its intervals.
const CO_LEARNING: &str = "co_learning";

/// The highest value a panel draws: the single-source lines (source-centred and
/// guarded), the co-learning line and its intervals' tops, the bound in hindsight (its
/// largest over the tasks, as drawn); not the methods it leaves
/// out (the zero-mean prior) nor the intervals it does not draw.
fn drawn_top_pct(cells: &[Cell]) -> f64 {
    let single_source = |c: &Cell| !c.sources.contains('+') && SINGLE_SOURCE_SERIES.iter().any(|(m, _)| *m == c.method);
    let drawn = cells.iter().filter_map(|c| match c.method.as_str() {
        CO_LEARNING => Some(c.improvement_pct.max(c.ci_pct.1)),
        BOUND => Some(c.improvement_pct),
        _ if single_source(c) => Some(c.improvement_pct),
        _ => None,
    });
    drawn.filter(|v| v.is_finite()).fold(f64::NEG_INFINITY, f64::max)
}

/// `(n, improvement)` of one single-source method, ascending in `n`.
fn series(cells: &[Cell], source: &str, method: &str) -> Vec<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = cells
        .iter()
        .filter(|c| c.sources == source && c.method == method)
        .map(|c| (c.n_train as f64, c.improvement_pct))
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, declared, write_declared};
    use polars::df;
    use tables::fdm::transfer_matrix as t;

    #[test]
    fn the_axis_top_leaves_the_legend_its_height_above_the_data() {
        // The legend's fraction of the plot's height, from the top, ends above the
        // highest drawn value by the gap: more entries raise the top, and the data keep
        // their place below the legend whatever their height.
        let plot_px = f64::from(PANEL_PX.1) - PANEL_NON_PLOT_PX;
        for entries in [3, 8, 12] {
            let legend = (LEGEND_PAD_PX + LEGEND_ENTRY_PX * entries as f64) / plot_px;
            for data_top in [10.0, 37.6, 100.0] {
                let top = axis_top(data_top, entries);
                let room = (top - data_top) / (top - FLOOR_PCT);
                assert!((room - legend - LEGEND_GAP).abs() < 1e-12, "{entries} {data_top}: {room}");
            }
            assert!(axis_top(20.0, entries + 1) > axis_top(20.0, entries));
        }
    }

    #[test]
    fn draws_one_panel_per_target_and_rejects_an_empty_table() {
        let tmp = tempfile::tempdir().expect("tempdir");
        let dir = tmp.path();
        let mut rows = Vec::new();
        for (sources, target) in [("a", "b"), ("b", "a"), ("a+c", "b")] {
            for n in 1..=3i64 {
                for m in ["single", "transfer_source_mean", "guarded", "co_learning"] {
                    rows.push((
                        sources,
                        target,
                        n,
                        m,
                        5.0 * n as f64 - if m == "transfer_source_mean" { 80.0 } else { 0.0 },
                    ));
                }
            }
        }
        type Row<'a> = (&'a str, &'a str, i64, &'a str, f64);
        let col = |f: &dyn Fn(&Row) -> String| rows.iter().map(f).collect::<Vec<String>>();
        let table = df!(
            t::sources => col(&|r| r.0.to_string()),
            t::target => col(&|r| r.1.to_string()),
            t::n_train => rows.iter().map(|r| r.2).collect::<Vec<i64>>(),
            t::method => col(&|r| r.3.to_string()),
            t::median_rmse_mm => rows.iter().map(|_| 0.05).collect::<Vec<f64>>(),
            t::improvement_pct => rows.iter().map(|r| r.4).collect::<Vec<f64>>(),
            t::ci_lo_pct => rows.iter().map(|r| r.4 - 3.0).collect::<Vec<f64>>(),
            t::ci_hi_pct => rows.iter().map(|r| r.4 + 3.0).collect::<Vec<f64>>(),
        )
        .unwrap();
        let table = declared(&t::TABLE, table);
        write_declared(dir, &t::TABLE, table.clone());
        let matrix = load(dir).unwrap();
        assert_eq!(matrix.keys().collect::<Vec<_>>(), ["a", "b"]);
        assert!(matrix["b"].iter().all(|c| c.method != "single"), "single is the baseline, not a series");
        let stem = dir.join("transfer_matrix");
        draw_png_and_svg(&stem, (1520, 1100), |a| draw(a, "t", &matrix), |a| draw(a, "t", &matrix)).expect("draws");
        assert_drawn(&stem);
        write_declared(dir, &t::TABLE, table.head(Some(0)));
        assert!(load(dir).is_err());
    }

    #[test]
    fn the_axis_top_is_the_highest_value_drawn() {
        let cell = |sources: &str, method: &str, improvement_pct: f64, ci_hi: f64| Cell {
            sources: sources.into(),
            n_train: 2,
            method: method.into(),
            improvement_pct,
            ci_pct: (improvement_pct - 1.0, ci_hi),
        };
        // The zero-mean line is not drawn, nor the single-source intervals: only the
        // lines and the co-learning interval lift the top.
        let mut cells = vec![
            cell("a", "transfer_zero_mean", 90.0, 95.0),
            cell("a", "transfer_source_mean", 12.0, 80.0),
            cell("a", "guarded", 15.0, 70.0),
        ];
        assert_eq!(drawn_top_pct(&cells), 15.0);
        cells.push(cell("a+b", "co_learning", 14.0, 33.0));
        assert_eq!(drawn_top_pct(&cells), 33.0);
        // The bound in hindsight is drawn without its interval.
        cells.push(cell("a+b", "hindsight_bound", 40.0, 90.0));
        assert_eq!(drawn_top_pct(&cells), 40.0);
    }

    #[test]
    fn the_bound_drawn_is_the_largest_over_the_tasks_at_each_n() {
        let cell = |sources: &str, n_train: i64, method: &str, improvement_pct: f64| Cell {
            sources: sources.into(),
            n_train,
            method: method.into(),
            improvement_pct,
            ci_pct: (f64::NAN, f64::NAN),
        };
        let cells = vec![
            cell("a", 2, "hindsight_bound", 5.0),
            cell("a+b", 2, "hindsight_bound", 9.0),
            cell("b", 2, "hindsight_bound", 7.0),
            cell("a", 1, "hindsight_bound", -3.0),
            cell("a+b", 1, "guarded", 50.0),
            cell("a", 3, "hindsight_bound", f64::NAN),
        ];
        assert_eq!(bound_series(&cells), vec![(1.0, -3.0), (2.0, 9.0)]);
    }
}
