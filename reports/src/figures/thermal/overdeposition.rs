//! `figure.thermal_overdeposition`: the first layer's deposit around every corner,
//! before (conventional) and after (compensated) compensation, in the style of paper
//! 003 (Chen et al.) Fig. 10 (Sec. 3.3, eq. 40): desired deposition (the ideal bead,
//! filled) in grey, over-deposition (filled outside the ideal bead) in red,
//! under-deposition (ideal but empty) in blue, with the CAD polygon, and O_E = A_o / A_c
//! before and after in each panel's title. Each corner is a pair of panels on one
//! square zoom box (equal-aspect millimetres); pairs are laid out in rows.
//!
//! Input: a `thermal.reprint_evaluate` stage (`corners.parquet`, `deposit_regions.parquet`,
//! `path.parquet`).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::params::ParamError;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::thermal::{corners, deposit_regions, path};

use crate::figures::common::grid_step;
use crate::figures::thermal::common::{
    clip_polyline, closed_outline, draw_key, draw_runs, load_polygon, merge_runs, plane_chart, KeySwatch, Vertex,
};
use crate::figures::thermal::directions::parse_vertices;
use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_png_and_svg, text};

/// The `figure.thermal_overdeposition` stage kind.
pub struct ThermalOverdepositionFigure;

/// Side of one square panel, in pixels (before its title).
const PANEL_PX: u32 = 310;
/// Height of the title band and of the key band, in pixels.
const TITLE_PX: u32 = 84;
const KEY_PX: u32 = 44;
/// Class colours: desired (grey), over (red), under (blue).
const DESIRED: RGBColor = RGBColor(170, 170, 170);
const OVER: RGBColor = RGBColor(214, 39, 40);
const UNDER: RGBColor = RGBColor(0, 114, 178);

pipeline::params! {
    /// The parameters of `figure.thermal_overdeposition`.
    pub struct OverdepositionParams {
        /// Comma-separated vertex ids to draw (default: every corner of corners.parquet).
        pub vertices: String = "",
        /// Half side of the square box around each corner (mm); 1 mm holds the corner region
        /// of a 0.45 mm bead.
        pub zoom_mm: f64 [0.1, 100.0] = 1.0,
        /// Corners (before/after pairs) per row of the figure.
        pub pairs_per_row: usize [1, 20] = 3,
        /// Figure title (default: a generic description with the mean O_E).
        pub title: String = "",
    }
}

/// The re-print whose corners are drawn.
const REPRINT: Input = Input::one(
    "reprint",
    &[Source::Stage("thermal.reprint_evaluate")],
    "the corners' O_E, the deposit classes and the CAD polygon (`corners.parquet`, `deposit_regions.parquet`, `path.parquet`)",
)
.reading(&[
    Reads {
        table: &corners::TABLE,
        columns: &[corners::corner, corners::angle_deg, corners::oe_before_pct, corners::oe_after_pct],
    },
    Reads {
        table: &deposit_regions::TABLE,
        columns: &[deposit_regions::variant, deposit_regions::class, deposit_regions::x_mm, deposit_regions::y_mm],
    },
    Reads { table: &path::TABLE, columns: &[path::vertex, path::x_mm, path::y_mm] },
]);

/// A deposit class of one grid cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    /// Ideal bead and filled.
    Desired,
    /// Filled outside the ideal bead.
    Over,
    /// Ideal bead but empty.
    Under,
}

impl Class {
    fn parse(s: &str) -> Option<Self> {
        match s {
            "desired" => Some(Self::Desired),
            "over" => Some(Self::Over),
            "under" => Some(Self::Under),
            _ => None,
        }
    }

    fn colour(self) -> RGBColor {
        match self {
            Self::Desired => DESIRED,
            Self::Over => OVER,
            Self::Under => UNDER,
        }
    }
}

/// Cells (x mm, y mm, class) of the conventional and of the compensated print.
pub type Cells = [Vec<(f64, f64, Class)>; 2];

/// One corner's evaluation (a row of `corners.parquet`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// CAD vertex id.
    pub vertex: i64,
    /// Corner angle (degrees).
    pub angle_deg: f64,
    /// O_E before and after compensation (%).
    pub oe_pct: (f64, f64),
}

/// Everything the figure draws.
#[derive(Debug, Clone)]
pub struct Plot {
    /// The corners drawn, in order.
    pub corners: Vec<Corner>,
    /// Cells of the conventional and of the compensated print.
    pub cells: Cells,
    /// Grid spacing of the cells (mm).
    pub step_mm: f64,
    /// The CAD polygon.
    pub polygon: Vec<Vertex>,
    /// Half side of the zoom box (mm).
    pub half_mm: f64,
    /// Corners per row.
    pub pairs_per_row: usize,
}

impl Stage for ThermalOverdepositionFigure {
    type Params = OverdepositionParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.thermal_overdeposition",
        version: 1,
        summary: "Desired, over- and under-deposition around every corner before and after compensation, O_E in each title → thermal_overdeposition.png/.svg",
        implements: "paper 003 Fig. 10 (Sec. 3.3, eq. 40)",
        inputs: &[REPRINT],
        output: Output::Tables,
    };

    fn check(p: &OverdepositionParams) -> Result<(), ParamError> {
        parse_vertices(&p.vertices, "vertices").map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &OverdepositionParams) -> Result<(), StageError> {
        let dir = &ctx.input(&REPRINT).dir;
        let wanted = parse_vertices(&p.vertices, "vertices").map_err(|e| StageError::params(ctx, e))?;
        let (cells, step_mm) = load_cells(&dir.join(deposit_regions::TABLE.file()))?;
        let plot = Plot {
            corners: load_corners(&dir.join(corners::TABLE.file()), &wanted)?,
            cells,
            step_mm,
            polygon: load_polygon(dir)?,
            half_mm: p.zoom_mm,
            pairs_per_row: p.pairs_per_row,
        };
        let title = crate::figures::common::title_or(&p.title, || default_title(&plot.corners));
        let stem = ctx.output_path("thermal_overdeposition")?;
        let size = figure_size_px(plot.corners.len(), plot.pairs_per_row);
        draw_png_and_svg(&stem, size, |a| draw(a, &title, &plot), |a| draw(a, &title, &plot))
    }
}

/// The default title, with the mean O_E before and after over the corners drawn.
pub fn default_title(corners: &[Corner]) -> String {
    let (before, after) = mean_oe_pct(corners);
    format!(
        "First layer at the corners, before | after compensation: mean O_E = A_o / A_c {before:.1} % → {after:.1} % (paper: 106.75 % → 31.73 %)"
    )
}

/// The mean O_E (%) before and after over `corners`, ignoring non-finite values.
pub fn mean_oe_pct(corners: &[Corner]) -> (f64, f64) {
    let mean = |pick: fn(&Corner) -> f64| {
        let v: Vec<f64> = corners.iter().map(pick).filter(|x| x.is_finite()).collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    (mean(|c| c.oe_pct.0), mean(|c| c.oe_pct.1))
}

/// The figure size for `n` corners, `per_row` corners per row.
pub fn figure_size_px(n: usize, per_row: usize) -> (u32, u32) {
    let per_row = per_row.clamp(1, n.max(1));
    let rows = n.max(1).div_ceil(per_row) as u32;
    (2 * per_row as u32 * PANEL_PX, TITLE_PX + KEY_PX + rows * (PANEL_PX + 30))
}

/// Reads `corners.parquet`, keeping the vertices in `wanted` (all when empty).
pub fn load_corners(path: &Path, wanted: &[i64]) -> Result<Vec<Corner>, StageError> {
    let df = read_parquet(path)?;
    let (vertex, angle) = (ints(&df, corners::corner, path)?, f64s(&df, corners::angle_deg, path)?);
    let (before, after) = (f64s(&df, corners::oe_before_pct, path)?, f64s(&df, corners::oe_after_pct, path)?);
    let corners: Vec<Corner> = (0..df.height())
        .map(|i| Corner { vertex: vertex[i], angle_deg: angle[i], oe_pct: (before[i], after[i]) })
        .filter(|c| wanted.is_empty() || wanted.contains(&c.vertex))
        .collect();
    if let Some(missing) = wanted.iter().find(|w| !corners.iter().any(|c| c.vertex == **w)) {
        return Err(no_rows(path, corners::corner, &format!("corner {missing}")));
    }
    if corners.is_empty() {
        return Err(no_rows(path, corners::corner, "one row per evaluated corner"));
    }
    Ok(corners)
}

/// Reads `deposit_regions.parquet` into the conventional and compensated cells and
/// the grid spacing. An unknown variant or class is an error naming the row.
pub fn load_cells(path: &Path) -> Result<(Cells, f64), StageError> {
    let df = read_parquet(path)?;
    let (variant, class) = (strs(&df, deposit_regions::variant, path)?, strs(&df, deposit_regions::class, path)?);
    let (x, y) = (f64s(&df, deposit_regions::x_mm, path)?, f64s(&df, deposit_regions::y_mm, path)?);
    let mut cells: [Vec<(f64, f64, Class)>; 2] = [Vec::new(), Vec::new()];
    for i in 0..df.height() {
        let bad = |column: &str, expected: &str| StageError::BadInput {
            file: path.to_path_buf(),
            location: Some(format!("{column}, row {i}")),
            expected: expected.to_string(),
        };
        let k = match variant[i].as_str() {
            "conventional" => 0,
            "compensated" => 1,
            _ => return Err(bad("variant", "expected conventional or compensated")),
        };
        let c = Class::parse(&class[i]).ok_or_else(|| bad("class", "expected desired, over or under"))?;
        cells[k].push((x[i], y[i], c));
    }
    if cells.iter().any(Vec::is_empty) {
        return Err(no_rows(path, deposit_regions::variant, "cells of both variants, conventional and compensated"));
    }
    let step = grid_step(cells[0].iter().take(10_000).map(|c| c.0));
    Ok((cells, step))
}

/// Draws the before/after pairs in rows, with one key below.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, plot: &Plot) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let area = area.margin(10, 4, 4, 10);
    let (head, rest) = area.split_vertically(TITLE_PX - 10);
    draw_title(&head, title).map_err(e)?;
    let (grid, key) = rest.split_vertically(rest.dim_in_pixel().1.saturating_sub(KEY_PX));
    let per_row = plot.pairs_per_row.clamp(1, plot.corners.len().max(1));
    let rows = plot.corners.len().max(1).div_ceil(per_row);
    let panels = grid.split_evenly((rows, 2 * per_row));
    for (k, corner) in plot.corners.iter().enumerate() {
        for side in 0..2 {
            draw_panel(&panels[2 * k + side], plot, corner, side).map_err(e)?;
        }
    }
    let items = [
        ("desired deposition".to_string(), KeySwatch::Fill(DESIRED)),
        ("over-deposition".to_string(), KeySwatch::Fill(OVER)),
        ("under-deposition".to_string(), KeySwatch::Fill(UNDER)),
        ("CAD path".to_string(), KeySwatch::Line(BLACK)),
    ];
    draw_key(&key, &items).map_err(e)
}

/// A long title over two lines, split at " | " when it does not fit in one.
fn draw_title<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = text(22.0);
    let width = area.dim_in_pixel().0 as i32;
    let fits = area.estimate_text_size(title, &style)?.0 as i32 <= width;
    let lines: Vec<&str> = if fits { vec![title] } else { title.splitn(2, ": ").collect() };
    for (k, line) in lines.iter().enumerate() {
        let w = area.estimate_text_size(line, &style)?.0 as i32;
        area.draw(&Text::new(line.to_string(), ((width - w) / 2, 4 + 30 * k as i32), style.clone()))?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    plot: &Plot,
    corner: &Corner,
    side: usize,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (when, oe) = if side == 0 { ("before", corner.oe_pct.0) } else { ("after", corner.oe_pct.1) };
    let caption = format!("v{} {:.0}° {when}: O_E {oe:.1} %", corner.vertex, corner.angle_deg);
    let area = area.titled(&caption, text(16.0))?;
    let Some(v) = plot.polygon.iter().find(|v| v.id == corner.vertex) else {
        return Ok(());
    };
    let (cx, cy, h) = (v.x_mm, v.y_mm, plot.half_mm);
    let mut chart = plane_chart(&area, (cx - h)..(cx + h), (cy - h)..(cy + h), 1)?;
    let (xs, ys) = (chart.x_range(), chart.y_range());
    let margin = plot.step_mm;
    let inside: Vec<(f64, f64, Class)> = plot.cells[side]
        .iter()
        .filter(|c| {
            c.0 >= xs.start - margin && c.0 <= xs.end + margin && c.1 >= ys.start - margin && c.1 <= ys.end + margin
        })
        .copied()
        .collect();
    draw_runs(&mut chart, &merge_runs(&inside, plot.step_mm), plot.step_mm, Class::colour)?;
    for piece in clip_polyline(&closed_outline(&plot.polygon), &xs, &ys) {
        chart.draw_series(LineSeries::new(piece, BLACK.stroke_width(1)))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, write_table};
    use crate::figures::thermal::test_data::{corner_path, corners, write_reprint};
    use polars::df;

    #[test]
    fn mean_oe_ignores_nan_and_title_carries_it() {
        let c = |b, a| Corner { vertex: 0, angle_deg: 90.0, oe_pct: (b, a) };
        assert_eq!(mean_oe_pct(&[c(100.0, 20.0), c(110.0, 40.0), c(f64::NAN, f64::NAN)]), (105.0, 30.0));
        assert!(default_title(&[c(100.0, 20.0)]).contains("100.0 % → 20.0 %"));
    }

    #[test]
    fn figure_size_fits_all_pairs() {
        assert_eq!(figure_size_px(11, 3), (6 * PANEL_PX, TITLE_PX + KEY_PX + 4 * (PANEL_PX + 30)));
        assert_eq!(figure_size_px(2, 3).0, 4 * PANEL_PX, "a short row is not padded");
    }

    #[test]
    fn bad_class_or_missing_vertex_is_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let df =
            df!("variant" => ["conventional"], "x_mm" => [0.0], "y_mm" => [0.0], "class" => ["blob"]).expect("frame");
        write_table(dir.path(), "deposit_regions", df);
        let err = load_cells(&dir.path().join("deposit_regions.parquet")).expect_err("bad class").to_string();
        assert!(err.contains("deposit_regions.parquet") && err.contains("class, row 0"), "{err}");
        write_table(dir.path(), "corners", corners(&corner_path()).drop("oe_after_pct").expect("drops"));
        let err = load_corners(&dir.path().join("corners.parquet"), &[]).expect_err("no column").to_string();
        assert!(err.contains("corners.parquet") && err.contains("oe_after_pct"), "{err}");
    }

    #[test]
    fn draws_every_corner_before_and_after() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_reprint(dir.path());
        let (cells, step_mm) = load_cells(&dir.path().join("deposit_regions.parquet")).expect("loads");
        assert!((step_mm - 0.02).abs() < 1e-9);
        let over = |k: usize| cells[k].iter().filter(|c| c.2 == Class::Over).count();
        assert!(over(0) > 3 * over(1), "the synthetic compensation removes most over-deposition");
        let plot = Plot {
            corners: load_corners(&dir.path().join("corners.parquet"), &[]).expect("loads"),
            cells,
            step_mm,
            polygon: load_polygon(dir.path()).expect("loads"),
            half_mm: 1.0,
            pairs_per_row: 3,
        };
        let stem = dir.path().join("thermal_overdeposition");
        let title = default_title(&plot.corners);
        let size = figure_size_px(plot.corners.len(), 3);
        draw_png_and_svg(&stem, size, |a| draw(a, &title, &plot), |a| draw(a, &title, &plot)).expect("draws");
        assert_drawn(&stem);
        let svg_bytes = std::fs::metadata(stem.with_extension("svg")).expect("svg").len();
        assert!(svg_bytes < 8_000_000, "runs keep the SVG small: {svg_bytes} bytes");
    }
}
