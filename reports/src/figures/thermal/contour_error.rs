//! `figure.thermal_contour_error`: the deposition contour error of eq. 41 at every
//! CAD contour point, before (conventional) and after (compensated) compensation, in
//! the style of paper 003 (Chen et al.) Fig. 11(c)-(d) and Table 3 (Sec. 3.3). Points
//! are coloured by error on one viridis scale shared by both panels (colour bar in
//! mm), drawn in order of error so the largest stay visible; panel titles carry the
//! max and RMS over all layers from `contour.parquet`.
//!
//! The paper plots the error of every layer on the 3D part; on the plane one layer
//! at a time reads better: by default the layer with the largest max error (over
//! both prints), or every layer overlaid when `layer = -2`.
//!
//! Input: a `thermal.reprint_evaluate` stage (`contour.parquet`, `contour_points.parquet`,
//! `path.parquet`).

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::thermal::{contour, contour_points, path};

use crate::figures::thermal::common::{closed_outline, colour_level, level_colour, load_polygon, plane_chart, Vertex};
use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_png_and_svg, text};

/// The `figure.thermal_contour_error` stage kind.
pub struct ThermalContourErrorFigure;

/// Figure size in pixels.
const SIZE_PX: (u32, u32) = (1500, 1100);
/// Width of the colour bar strip, in pixels.
const COLOUR_BAR_PX: u32 = 130;
/// The variants in drawing order.
pub const VARIANTS: [&str; 2] = ["conventional", "compensated"];

pipeline::params! {
    /// The parameters of `figure.thermal_contour_error`.
    pub struct ContourErrorParams {
        /// Layer to draw; −1: the layer with the largest max error over both prints; −2: every
        /// layer overlaid.
        pub layer: i64 [-2, 100_000] = -1,
        /// Figure title (default: a generic description).
        pub title: String = "",
    }
}

/// The re-print whose contour error is drawn.
const REPRINT: Input = Input::one(
    "reprint",
    &[Source::Stage("thermal.reprint_evaluate")],
    "the contour error per point and its summary, and the CAD polygon (`contour_points.parquet`, `contour.parquet`, `path.parquet`)",
)
.reading(&[
    Reads {
        table: &contour_points::TABLE,
        columns: &[
            contour_points::variant,
            contour_points::layer,
            contour_points::x_mm,
            contour_points::y_mm,
            contour_points::error_mm,
        ],
    },
    Reads { table: &contour::TABLE, columns: &[contour::variant, contour::max_mm, contour::rms_mm] },
    Reads { table: &path::TABLE, columns: &[path::vertex, path::x_mm, path::y_mm] },
]);

/// One contour point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Layer.
    pub layer: i64,
    /// CAD position (mm).
    pub x_mm: f64,
    /// CAD position (mm).
    pub y_mm: f64,
    /// Contour error e_t of eq. 41 (mm).
    pub error_mm: f64,
}

/// Everything the figure draws.
#[derive(Debug, Clone)]
pub struct Plot {
    /// Points of the conventional and of the compensated print.
    pub points: [Vec<Point>; 2],
    /// (max, RMS) over all layers of each print, from `contour.parquet` (mm).
    pub summary_mm: [(f64, f64); 2],
    /// The CAD polygon.
    pub polygon: Vec<Vertex>,
    /// The layer drawn (None: all).
    pub layer: Option<i64>,
}

impl Stage for ThermalContourErrorFigure {
    type Params = ContourErrorParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.thermal_contour_error",
        version: 1,
        summary: "Contour error (eq. 41) at the CAD contour points before and after compensation, shared viridis scale, max and RMS in the titles → thermal_contour_error.png/.svg",
        implements: "paper 003 Fig. 11(c)-(d), Table 3 (Sec. 3.3, eq. 41)",
        inputs: &[REPRINT],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &ContourErrorParams) -> Result<(), StageError> {
        let dir = &ctx.input(&REPRINT).dir;
        let points = load_points(&dir.join(contour_points::TABLE.file()))?;
        let layer = match p.layer {
            -2 => None,
            -1 => Some(worst_layer(&points)),
            l => Some(l),
        };
        let plot = Plot {
            points,
            summary_mm: load_summary(&dir.join(contour::TABLE.file()))?,
            polygon: load_polygon(dir)?,
            layer,
        };
        let title = crate::figures::common::title_or(&p.title, || {
            "Deposition contour error e_t (eq. 41) at the CAD contour points, before and after compensation".to_string()
        });
        let stem = ctx.output_path("thermal_contour_error")?;
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, &title, &plot), |a| draw(a, &title, &plot))
    }
}

/// Reads `contour_points.parquet` into the conventional and compensated points.
pub fn load_points(path: &Path) -> Result<[Vec<Point>; 2], StageError> {
    let df = read_parquet(path)?;
    let (variant, layer) = (strs(&df, contour_points::variant, path)?, ints(&df, contour_points::layer, path)?);
    let (x, y, e) = (
        f64s(&df, contour_points::x_mm, path)?,
        f64s(&df, contour_points::y_mm, path)?,
        f64s(&df, contour_points::error_mm, path)?,
    );
    let mut points: [Vec<Point>; 2] = [Vec::new(), Vec::new()];
    for i in 0..df.height() {
        if let Some(k) = VARIANTS.iter().position(|v| *v == variant[i]) {
            points[k].push(Point { layer: layer[i], x_mm: x[i], y_mm: y[i], error_mm: e[i] });
        }
    }
    if points.iter().any(Vec::is_empty) {
        return Err(no_rows(path, contour_points::variant, "points of both variants, conventional and compensated"));
    }
    Ok(points)
}

/// Reads (max, RMS) per variant from `contour.parquet`.
pub fn load_summary(path: &Path) -> Result<[(f64, f64); 2], StageError> {
    let df = read_parquet(path)?;
    let variant = strs(&df, contour::variant, path)?;
    let (max, rms) = (f64s(&df, contour::max_mm, path)?, f64s(&df, contour::rms_mm, path)?);
    let row = |name: &str| {
        variant
            .iter()
            .position(|v| v == name)
            .map(|i| (max[i], rms[i]))
            .ok_or_else(|| no_rows(path, contour::variant, name))
    };
    Ok([row(VARIANTS[0])?, row(VARIANTS[1])?])
}

/// The layer holding the largest finite error of either print.
pub fn worst_layer(points: &[Vec<Point>; 2]) -> i64 {
    let mut max_by_layer: BTreeMap<i64, f64> = BTreeMap::new();
    for p in points.iter().flatten().filter(|p| p.error_mm.is_finite()) {
        let m = max_by_layer.entry(p.layer).or_insert(f64::NEG_INFINITY);
        *m = m.max(p.error_mm);
    }
    max_by_layer.into_iter().max_by(|a, b| a.1.total_cmp(&b.1)).map_or(0, |(layer, _)| layer)
}

impl Plot {
    /// The points of print `k` on the drawn layer(s), smallest error first.
    pub fn drawn(&self, k: usize) -> Vec<Point> {
        let mut v: Vec<Point> = self.points[k]
            .iter()
            .filter(|p| p.error_mm.is_finite() && self.layer.is_none_or(|l| p.layer == l))
            .copied()
            .collect();
        v.sort_by(|a, b| a.error_mm.total_cmp(&b.error_mm));
        v
    }

    fn layer_label(&self) -> String {
        self.layer.map_or("all layers overlaid".into(), |l| format!("layer {l} shown"))
    }
}

/// Draws the two prints stacked, sharing one colour bar at the right.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, plot: &Plot) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let area = area.margin(10, 6, 6, 10).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    let (panels, bar) = area.split_horizontally(area.dim_in_pixel().0.saturating_sub(COLOUR_BAR_PX));
    let drawn = [plot.drawn(0), plot.drawn(1)];
    let max_mm = drawn.iter().flatten().map(|p| p.error_mm).fold(0.0, f64::max).max(1e-6);
    let rows = panels.split_evenly((2, 1));
    for (k, row) in rows.iter().enumerate() {
        let (max, rms) = plot.summary_mm[k];
        let caption = format!("{}: max {max:.4} mm, RMS {rms:.4} mm (all layers); {}", VARIANTS[k], plot.layer_label());
        draw_panel(row, &caption, &drawn[k], &plot.polygon, max_mm).map_err(e)?;
    }
    crate::figures::common::draw_viridis_bar(
        &bar,
        (0.0, max_mm),
        "contour error e_t (mm)",
        2,
        super::common::COLOUR_LEVELS,
    )
    .map_err(e)
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    caption: &str,
    points: &[Point],
    polygon: &[Vertex],
    max_mm: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let area = area.titled(caption, text(18.0))?;
    let xs = polygon.iter().map(|v| v.x_mm).chain(points.iter().map(|p| p.x_mm));
    let ys = polygon.iter().map(|v| v.y_mm).chain(points.iter().map(|p| p.y_mm));
    let ((x0, x1), (y0, y1)) =
        (crate::figures::thermal::common::finite_range(xs), crate::figures::thermal::common::finite_range(ys));
    let pad = 0.04 * (x1 - x0).max(y1 - y0);
    let mut chart = plane_chart(&area, (x0 - pad)..(x1 + pad), (y0 - pad)..(y1 + pad), 0)?;
    chart.draw_series(LineSeries::new(closed_outline(polygon), RGBColor(200, 200, 200).stroke_width(1)))?;
    let dot =
        |p: &Point| Circle::new((p.x_mm, p.y_mm), 3, level_colour(colour_level(p.error_mm, (0.0, max_mm))).filled());
    chart.draw_series(points.iter().map(dot))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, write_table};
    use crate::figures::thermal::test_data::{corner_path, write_reprint};
    use polars::df;

    fn p(layer: i64, error_mm: f64) -> Point {
        Point { layer, x_mm: 0.0, y_mm: 0.0, error_mm }
    }

    #[test]
    fn worst_layer_holds_the_largest_error_and_drawn_is_sorted() {
        let points = [vec![p(0, 0.5), p(1, 0.9), p(2, f64::NAN)], vec![p(2, 0.8), p(0, 0.1)]];
        assert_eq!(worst_layer(&points), 1);
        let plot = Plot { points, summary_mm: [(0.9, 0.5); 2], polygon: Vec::new(), layer: None };
        let all: Vec<f64> = plot.drawn(0).iter().map(|p| p.error_mm).collect();
        assert_eq!(all, vec![0.5, 0.9], "NaN dropped, ascending");
        let one = Plot { layer: Some(0), ..plot };
        assert_eq!(one.drawn(1), vec![p(0, 0.1)]);
    }

    #[test]
    fn missing_variant_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let df = df!("variant" => ["conventional"], "max_mm" => [1.0], "rms_mm" => [0.3]).expect("frame");
        write_table(dir.path(), "contour", df);
        let err = load_summary(&dir.path().join("contour.parquet")).expect_err("no compensated").to_string();
        assert!(err.contains("contour.parquet") && err.contains("compensated"), "{err}");
    }

    #[test]
    fn draws_the_worst_layer_before_and_after() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_reprint(dir.path());
        let points = load_points(&dir.path().join("contour_points.parquet")).expect("loads");
        assert_eq!(worst_layer(&points), 1, "the synthetic error peaks in layer 1");
        let plot = Plot {
            layer: Some(worst_layer(&points)),
            points,
            summary_mm: load_summary(&dir.path().join("contour.parquet")).expect("loads"),
            polygon: load_polygon(dir.path()).expect("loads"),
        };
        assert_eq!(plot.summary_mm[0], (1.52, 0.41));
        assert_eq!(plot.polygon.len(), corner_path().len());
        let stem = dir.path().join("thermal_contour_error");
        let title = "Synthetic contour error (cf. paper 003 Fig. 11, Table 3)";
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, title, &plot), |a| draw(a, title, &plot)).expect("draws");
        assert_drawn(&stem);
    }
}
