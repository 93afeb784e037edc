//! `figure.fdm_r_surface`: the training RMSE of the piecewise width model (paper 000
//! eqs 2-3) over the grid of speed-deviation factors r_a × r_F of eq. (1), one heat map
//! per printer. Not a figure of the paper: it shows whether the grid-search optimum the
//! paper reports is sharp or sits in a flat valley. Reads `r_surface.parquet`.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use pipeline::params::NoParams;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::r_surface;

use crate::figures::common::{grid_step, viridis};
use crate::read::{f64s, no_rows, read_parquet, strs};
use crate::style::{draw_png_and_svg, text};

/// The `figure.fdm_r_surface` stage kind.
pub struct RSurfaceFigure;

/// The leave-one-out whose surfaces are drawn. `r_surface.parquet` is written by
/// `fdm.piecewise_loo`; the role also takes `fdm.lag_model` so that a `table.concat` of
/// both models' leave-one-out (which stacks the piecewise surfaces) is accepted, and the
/// planner checks that one of the concatenated stages writes the surface.
const LOO: Input = Input::one(
    "loo",
    &[Source::Stage("fdm.piecewise_loo"), Source::Stage("fdm.lag_model")],
    "the training RMSE over the r_a × r_F grid per printer (`r_surface.parquet`)",
)
.reading(&[Reads {
    table: &r_surface::TABLE,
    columns: &[r_surface::printer, r_surface::r_a, r_surface::r_f, r_surface::training_rmse_mm],
}]);

/// Pixels per printer panel (heat map and its colour bar).
const PANEL_PX: (u32, u32) = (700, 700);
/// Width of the colour bar strip of each panel, in pixels.
const COLOUR_BAR_PX: u32 = 110;
/// A grid point within this relative distance of the minimum counts as "as good".
const NEAR_OPTIMUM_REL: f64 = 0.01;
/// An optimum is called sharp when at most this fraction of the grid is as good.
const SHARP_MAX_FRACTION: f64 = 0.05;

/// One printer's RMSE surface.
#[derive(Debug)]
pub struct Surface {
    /// Printer name.
    pub printer: String,
    /// Grid points (r_a, r_F, training RMSE in mm).
    pub cells: Vec<(f64, f64, f64)>,
}

impl Stage for RSurfaceFigure {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_r_surface",
        version: 1,
        summary: "Heat map per printer of the piecewise model's training RMSE over r_a × r_F, minimum marked → r_surface.png/.svg",
        implements: "not in paper 000: the r_a × r_F grid search of eq. (1), §II-A",
        inputs: &[LOO],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let surfaces = load(&ctx.input(&LOO).dir)?;
        let stem = ctx.output_path("r_surface")?;
        let size = figure_size_px(surfaces.len());
        draw_png_and_svg(&stem, size, |a| draw(a, &surfaces), |a| draw(a, &surfaces))
    }
}

/// Reads every printer's surface from `<dir>/r_surface.parquet`, by printer name.
pub fn load(dir: &Path) -> Result<Vec<Surface>, StageError> {
    use r_surface as t;
    let path = dir.join(t::TABLE.file());
    let df = read_parquet(&path)?;
    let printers = strs(&df, t::printer, &path)?;
    let (r_a, r_f, rmse) =
        (f64s(&df, t::r_a, &path)?, f64s(&df, t::r_f, &path)?, f64s(&df, t::training_rmse_mm, &path)?);
    let mut by_printer: BTreeMap<String, Vec<(f64, f64, f64)>> = BTreeMap::new();
    for i in (0..df.height()).filter(|&i| rmse[i].is_finite()) {
        by_printer.entry(printers[i].clone()).or_default().push((r_a[i], r_f[i], rmse[i]));
    }
    if by_printer.is_empty() {
        return Err(no_rows(&path, t::training_rmse_mm, "a finite training RMSE"));
    }
    Ok(by_printer.into_iter().map(|(printer, cells)| Surface { printer, cells }).collect())
}

/// The figure size for `n_printers` panels side by side.
pub fn figure_size_px(n_printers: usize) -> (u32, u32) {
    (PANEL_PX.0 * n_printers.max(1) as u32, PANEL_PX.1)
}

/// The fraction of grid points whose RMSE is within `rel` of the minimum: small when
/// the optimum is sharp, large when the surface is a flat valley.
pub fn near_optimum_fraction(rmse_mm: &[f64], rel: f64) -> f64 {
    let min = rmse_mm.iter().copied().fold(f64::INFINITY, f64::min);
    let near = rmse_mm.iter().filter(|r| **r <= min * (1.0 + rel)).count();
    near as f64 / rmse_mm.len().max(1) as f64
}

/// Draws one heat map per printer side by side.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, surfaces: &[Surface]) -> Result<(), String> {
    let title = "Training RMSE of the piecewise model over r_a × r_F (not in the paper: is the optimum sharp?)";
    let area = area.margin(12, 6, 6, 10).titled(title, text(22.0)).map_err(|e| e.to_string())?;
    let panels = area.split_evenly((1, surfaces.len().max(1)));
    for (panel, surface) in panels.iter().zip(surfaces) {
        draw_panel(panel, surface).map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The grid point with the lowest RMSE.
fn minimum(cells: &[(f64, f64, f64)]) -> (f64, f64, f64) {
    cells.iter().copied().min_by(|a, b| a.2.total_cmp(&b.2)).unwrap_or((1.0, 1.0, f64::NAN))
}

fn rmse_range_mm(cells: &[(f64, f64, f64)]) -> (f64, f64) {
    let lo = cells.iter().map(|c| c.2).fold(f64::INFINITY, f64::min);
    let hi = cells.iter().map(|c| c.2).fold(f64::NEG_INFINITY, f64::max);
    if hi > lo {
        (lo, hi)
    } else {
        (lo, lo + 1e-6)
    }
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    surface: &Surface,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let rmse: Vec<f64> = surface.cells.iter().map(|c| c.2).collect();
    let fraction = near_optimum_fraction(&rmse, NEAR_OPTIMUM_REL);
    let verdict = if fraction <= SHARP_MAX_FRACTION { "sharp" } else { "flat" };
    let caption = format!(
        "{}: optimum {verdict} ({:.1} % of grid within {:.0} % of min)",
        surface.printer,
        100.0 * fraction,
        100.0 * NEAR_OPTIMUM_REL
    );
    let area = area.titled(&caption, text(18.0))?;
    let (map, bar) = area.split_horizontally(area.dim_in_pixel().0.saturating_sub(COLOUR_BAR_PX));
    let range = rmse_range_mm(&surface.cells);
    draw_heat_map(&map, surface, range)?;
    crate::figures::common::draw_viridis_bar(&bar, range, "training RMSE (mm)", label_decimals(range.1 - range.0), 120)
}

fn draw_heat_map<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    surface: &Surface,
    (lo, hi): (f64, f64),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let half_a = grid_step(surface.cells.iter().map(|c| c.0)) / 2.0;
    let half_f = grid_step(surface.cells.iter().map(|c| c.1)) / 2.0;
    let span = |pick: fn(&(f64, f64, f64)) -> f64, half: f64| {
        let lo = surface.cells.iter().map(pick).fold(f64::INFINITY, f64::min);
        let hi = surface.cells.iter().map(pick).fold(f64::NEG_INFINITY, f64::max);
        (lo - half)..(hi + half)
    };
    let mut chart = ChartBuilder::on(area)
        .margin(10)
        .x_label_area_size(44)
        .y_label_area_size(60)
        .build_cartesian_2d(span(|c| c.0, half_a), span(|c| c.1, half_f))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("r_a (acceleration factor)")
        .y_desc("r_F (feed factor)")
        .label_style(text(14.0))
        .axis_desc_style(text(15.0))
        .x_label_formatter(&|x| format!("{x:.2}"))
        .y_label_formatter(&|y| format!("{y:.2}"))
        .draw()?;
    let cell = |&(a, f, r): &(f64, f64, f64)| {
        Rectangle::new([(a - half_a, f - half_f), (a + half_a, f + half_f)], viridis((r - lo) / (hi - lo)).filled())
    };
    chart.draw_series(surface.cells.iter().map(cell))?;
    mark_minimum(&mut chart, surface, (half_a, half_f))
}

fn mark_minimum<DB: DrawingBackend>(
    chart: &mut ChartContext<DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    surface: &Surface,
    (half_a, half_f): (f64, f64),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (a, f, rmse) = minimum(&surface.cells);
    chart.draw_series([Cross::new((a, f), 9, WHITE.stroke_width(3))])?;
    // Write the value on the side of the cross facing the middle of the grid, so it
    // stays inside the map even when the optimum sits on an edge.
    let (x_range, y_range) = (chart.x_range(), chart.y_range());
    let right = a < (x_range.start + x_range.end) / 2.0;
    let up = f < (y_range.start + y_range.end) / 2.0;
    let pos = Pos::new(if right { HPos::Left } else { HPos::Right }, if up { VPos::Bottom } else { VPos::Top });
    let anchor = (a + if right { 2.0 } else { -2.0 } * half_a, f + if up { 2.0 } else { -2.0 } * half_f);
    let label = format!("min {rmse:.4} mm at ({a:.2}, {f:.2})");
    let style = text(15.0).color(&WHITE).pos(pos);
    chart.draw_series([Text::new(label, anchor, style)])?;
    Ok(())
}

/// Decimals that resolve a fifth of `span_mm` on an axis label.
fn label_decimals(span_mm: f64) -> usize {
    if span_mm > 0.0 {
        (-(span_mm / 5.0).log10()).ceil().clamp(0.0, 6.0) as usize
    } else {
        3
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, write_declared};
    use polars::df;

    #[test]
    fn near_optimum_fraction_counts_points_within_tolerance_of_min() {
        let rmse = [1.0, 1.005, 1.02, 2.0];
        assert_eq!(near_optimum_fraction(&rmse, 0.01), 0.5);
        assert_eq!(near_optimum_fraction(&rmse, 0.0), 0.25);
    }

    /// Two printers on the paper's 21 × 21 grid: taz5 a narrow bowl (sharp optimum at
    /// 0.97, 1.02), taz6 a long valley along r_a (flat).
    fn surface_table() -> polars::prelude::DataFrame {
        let r: Vec<f64> = (0..21).map(|k| 0.90 + 0.01 * k as f64).collect();
        let (mut printer, mut r_a, mut r_f, mut rmse) = (vec![], vec![], vec![], vec![]);
        for (name, k_a, k_f) in [("taz5", 8.0, 12.0), ("taz6", 0.005, 2.0)] {
            for &a in &r {
                for &f in &r {
                    printer.push(name);
                    r_a.push(a);
                    r_f.push(f);
                    rmse.push(0.04 + k_a * (a - 0.97).powi(2) + k_f * (f - 1.02).powi(2));
                }
            }
        }
        use r_surface as t;
        df!(t::printer => printer, t::r_a => r_a, t::r_f => r_f, t::training_rmse_mm => rmse).expect("frame")
    }

    #[test]
    fn draws_one_heat_map_per_printer() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_declared(dir.path(), &r_surface::TABLE, surface_table());
        let surfaces = load(dir.path()).expect("loads");
        assert_eq!(surfaces.len(), 2);
        assert!(surfaces.iter().all(|s| s.cells.len() == 441));
        let (a, f, _) = minimum(&surfaces[0].cells);
        assert!((a - 0.97).abs() < 1e-9 && (f - 1.02).abs() < 1e-9);
        let fraction = |s: &Surface| near_optimum_fraction(&s.cells.iter().map(|c| c.2).collect::<Vec<_>>(), 0.01);
        assert!(fraction(&surfaces[0]) <= SHARP_MAX_FRACTION, "the narrow bowl is sharp");
        assert!(fraction(&surfaces[1]) > SHARP_MAX_FRACTION, "the long valley is flat");
        let stem = dir.path().join("r_surface");
        let size = figure_size_px(surfaces.len());
        draw_png_and_svg(&stem, size, |a| draw(a, &surfaces), |a| draw(a, &surfaces)).expect("draws");
        assert_drawn(&stem);
    }
}
