//! Drawing helpers shared by the paper 003 figures (`figure.thermal_*`): the CAD
//! polygon of `path.parquet`, equal-aspect plane charts in millimetres, grid cells
//! merged into row runs (a 0.02 mm deposit grid has tens of thousands of cells; one
//! rectangle per run keeps the SVG small), a vertical viridis colour bar, and the
//! interior angle of a polygon corner.

use std::ops::Range;
use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::StageError;
use tables::thermal::path;

use crate::figures::common::viridis;
use crate::read::{f64s, ints, no_rows, read_parquet};
use crate::style::{house_mesh, text};

/// A chart on the plane (x, y in mm).
pub type PlaneChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Number of colour levels cells are quantised to before merging (the eye does not
/// resolve more steps of viridis).
pub const COLOUR_LEVELS: usize = 64;

/// One vertex of the CAD polygon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Vertex {
    /// Vertex id (its index along the path).
    pub id: i64,
    /// Position (mm).
    pub x_mm: f64,
    /// Position (mm).
    pub y_mm: f64,
}

/// Reads the CAD polygon from `<dir>/path.parquet`, sorted by vertex id.
pub fn load_polygon(dir: &Path) -> Result<Vec<Vertex>, StageError> {
    let path = dir.join(path::TABLE.file());
    let df = read_parquet(&path)?;
    let (id, x, y) = (ints(&df, path::vertex, &path)?, f64s(&df, path::x_mm, &path)?, f64s(&df, path::y_mm, &path)?);
    let mut polygon: Vec<Vertex> = (0..df.height()).map(|i| Vertex { id: id[i], x_mm: x[i], y_mm: y[i] }).collect();
    if polygon.len() < 3 {
        return Err(no_rows(&path, path::vertex, "at least three polygon vertices"));
    }
    polygon.sort_by_key(|v| v.id);
    Ok(polygon)
}

/// The interior angle (degrees, in [0, 180]) at vertex `k` of a closed polygon: the
/// angle between the edges to its neighbours.
pub fn interior_angle_deg(polygon: &[Vertex], k: usize) -> f64 {
    let n = polygon.len();
    let (prev, at, next) = (polygon[(k + n - 1) % n], polygon[k], polygon[(k + 1) % n]);
    let a = (prev.x_mm - at.x_mm, prev.y_mm - at.y_mm);
    let b = (next.x_mm - at.x_mm, next.y_mm - at.y_mm);
    let cos = (a.0 * b.0 + a.1 * b.1) / (a.0.hypot(a.1) * b.0.hypot(b.1));
    cos.clamp(-1.0, 1.0).acos().to_degrees()
}

/// The polygon's points closed back onto the first, for drawing.
pub fn closed_outline(polygon: &[Vertex]) -> Vec<(f64, f64)> {
    polygon.iter().chain(polygon.first()).map(|v| (v.x_mm, v.y_mm)).collect()
}

/// Widens the shorter of two ranges about its centre so that one millimetre takes the
/// same number of pixels along x and y on a plot of `plot_px` = (width, height).
pub fn equal_aspect(xs: Range<f64>, ys: Range<f64>, plot_px: (u32, u32)) -> (Range<f64>, Range<f64>) {
    let (w_px, h_px) = (plot_px.0.max(1) as f64, plot_px.1.max(1) as f64);
    let (dx, dy) = ((xs.end - xs.start).max(1e-9), (ys.end - ys.start).max(1e-9));
    let mm_per_px = (dx / w_px).max(dy / h_px);
    let widen = |r: Range<f64>, len: f64| {
        let c = (r.start + r.end) / 2.0;
        (c - len / 2.0)..(c + len / 2.0)
    };
    (widen(xs, mm_per_px * w_px), widen(ys, mm_per_px * h_px))
}

/// Builds an equal-aspect chart of at least `xs` × `ys` (mm) on `area`, with the house
/// mesh (no grid lines, x and y in mm with `decimals` decimals) drawn.
pub fn plane_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    xs: Range<f64>,
    ys: Range<f64>,
    decimals: usize,
) -> Result<PlaneChart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut chart = equal_aspect_chart(area, xs, ys)?;
    let (w_px, h_px) = chart.plotting_area().dim_in_pixel();
    house_mesh(&mut chart)
        .disable_mesh()
        .x_labels(label_count(w_px))
        .y_labels(label_count(h_px))
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .x_label_formatter(&|x| format!("{x:.decimals$}"))
        .y_label_formatter(&|y| format!("{y:.decimals$}"))
        .draw()?;
    Ok(chart)
}

/// How many tick labels fit along an axis of `px` pixels (one per 70 px, at least 3).
pub fn label_count(px: u32) -> usize {
    (px as usize / 70).max(3)
}

/// Builds an equal-aspect chart of at least `xs` × `ys` on `area` (no mesh drawn):
/// the ranges are widened until one unit takes as many pixels along x as along y.
pub fn equal_aspect_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    xs: Range<f64>,
    ys: Range<f64>,
) -> Result<PlaneChart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let build = |xs: Range<f64>, ys: Range<f64>| {
        ChartBuilder::on(area)
            .margin(8)
            .margin_right(16)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(xs, ys)
    };
    // Building without a caption draws nothing: the first build only measures.
    let plot_px = build(xs.clone(), ys.clone())?.plotting_area().dim_in_pixel();
    let (xs, ys) = equal_aspect(xs, ys, plot_px);
    build(xs, ys)
}

/// A run of equal cells along one grid row: x from `x0` to `x1` (cell edges), centre
/// row `y`, and the shared value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Run<C> {
    /// Left edge (mm).
    pub x0: f64,
    /// Right edge (mm).
    pub x1: f64,
    /// Row centre (mm).
    pub y: f64,
    /// The value every cell of the run has.
    pub value: C,
}

/// Merges cells `(x, y, value)` of a regular grid with spacing `step` into row runs of
/// neighbouring cells with equal values. The runs cover exactly the cells given.
pub fn merge_runs<C: PartialEq + Copy>(cells: &[(f64, f64, C)], step: f64) -> Vec<Run<C>> {
    let mut sorted: Vec<(f64, f64, C)> = cells.to_vec();
    sorted.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.total_cmp(&b.0)));
    let half = step / 2.0;
    let mut runs: Vec<Run<C>> = Vec::new();
    for (x, y, value) in sorted {
        match runs.last_mut() {
            Some(r) if r.value == value && (r.y - y).abs() < 1e-3 * step && (x - half - r.x1).abs() < 1e-3 * step => {
                r.x1 = x + half
            }
            _ => runs.push(Run { x0: x - half, x1: x + half, y, value }),
        }
    }
    runs
}

/// Draws `runs` as filled rectangles of height `step`, coloured by `colour`.
pub fn draw_runs<DB: DrawingBackend, C: Copy>(
    chart: &mut PlaneChart<DB>,
    runs: &[Run<C>],
    step: f64,
    colour: impl Fn(C) -> RGBColor,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let half = step / 2.0;
    let rect = |r: &Run<C>| Rectangle::new([(r.x0, r.y - half), (r.x1, r.y + half)], colour(r.value).filled());
    chart.draw_series(runs.iter().map(rect))?;
    Ok(())
}

/// The colour level (0..COLOUR_LEVELS) of `value` on the scale `lo..hi`.
pub fn colour_level(value: f64, (lo, hi): (f64, f64)) -> usize {
    let t = ((value - lo) / (hi - lo).max(1e-12)).clamp(0.0, 1.0);
    (t * (COLOUR_LEVELS - 1) as f64).round() as usize
}

/// Viridis at colour level `level`.
pub fn level_colour(level: usize) -> RGBColor {
    viridis(level as f64 / (COLOUR_LEVELS - 1) as f64)
}

/// The smallest and largest finite value (0..1 when there is none, widened when equal).
pub fn finite_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) =
        values.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    match (lo.is_finite(), hi > lo) {
        (false, _) => (0.0, 1.0),
        (true, false) => (lo - 0.5, lo + 0.5),
        (true, true) => (lo, hi),
    }
}

/// Clips the segment `a`-`b` to the box `xs` × `ys` (Liang-Barsky); None when it
/// lies wholly outside. Plotters does not clip elements to the plotting area, so
/// anything drawn on a zoomed chart goes through this.
pub fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    xs: &Range<f64>,
    ys: &Range<f64>,
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    let edges = [(-dx, a.0 - xs.start), (dx, xs.end - a.0), (-dy, a.1 - ys.start), (dy, ys.end - a.1)];
    for (p, q) in edges {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else if p < 0.0 {
            t0 = t0.max(q / p);
        } else {
            t1 = t1.min(q / p);
        }
    }
    (t0 <= t1).then_some(((a.0 + t0 * dx, a.1 + t0 * dy), (a.0 + t1 * dx, a.1 + t1 * dy)))
}

/// Clips a polyline to the box `xs` × `ys`: the pieces that lie inside it.
pub fn clip_polyline(points: &[(f64, f64)], xs: &Range<f64>, ys: &Range<f64>) -> Vec<Vec<(f64, f64)>> {
    let mut pieces: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for w in points.windows(2) {
        match clip_segment(w[0], w[1], xs, ys) {
            Some((p, q)) => {
                let joins = open && pieces.last().and_then(|l| l.last()).is_some_and(|l| *l == p);
                if !joins {
                    pieces.push(vec![p]);
                }
                pieces.last_mut().expect("pushed").push(q);
                // The piece continues only if the segment ended inside the box.
                open = q == w[1];
            }
            None => open = false,
        }
    }
    pieces
}

/// How a key entry is drawn.
#[derive(Debug, Clone, Copy)]
pub enum KeySwatch {
    /// A filled square.
    Fill(RGBColor),
    /// A line.
    Line(RGBColor),
    /// A square of the first colour outlined in the second.
    Outlined(RGBColor, RGBColor),
    /// A line of the second colour across a square of the first.
    LineOn(RGBColor, RGBColor),
    /// A circle outline.
    Circle(RGBColor),
    /// A cross.
    Cross(RGBColor),
    /// A filled triangle.
    Triangle(RGBColor),
}

/// Draws a one-line key of `items` centred on `area` (for small multiples, where one
/// key for the figure reads better than a legend in every panel).
pub fn draw_key<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    items: &[(String, KeySwatch)],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = text(16.0);
    let widths: Vec<i32> = items
        .iter()
        .map(|(label, _)| area.estimate_text_size(label, &style).map(|(w, _)| w as i32 + 60))
        .collect::<Result<_, _>>()?;
    let (w, h) = area.dim_in_pixel();
    let mut x = (w as i32 - widths.iter().sum::<i32>()) / 2;
    let y = h as i32 / 2;
    for ((label, swatch), width) in items.iter().zip(widths) {
        match swatch {
            KeySwatch::Fill(c) => area.draw(&Rectangle::new([(x, y - 9), (x + 18, y + 9)], c.filled()))?,
            KeySwatch::Line(c) => area.draw(&PathElement::new([(x - 4, y), (x + 22, y)], c.stroke_width(2)))?,
            KeySwatch::Outlined(fill, line) => {
                area.draw(&Rectangle::new([(x, y - 9), (x + 18, y + 9)], fill.filled()))?;
                area.draw(&Rectangle::new([(x, y - 9), (x + 18, y + 9)], line.stroke_width(2)))?
            }
            KeySwatch::LineOn(fill, line) => {
                area.draw(&Rectangle::new([(x, y - 9), (x + 18, y + 9)], fill.filled()))?;
                area.draw(&PathElement::new([(x, y), (x + 18, y)], line.stroke_width(2)))?
            }
            KeySwatch::Circle(c) => area.draw(&Circle::new((x + 9, y), 7, c.stroke_width(3)))?,
            KeySwatch::Cross(c) => area.draw(&Cross::new((x + 9, y), 7, c.stroke_width(3)))?,
            KeySwatch::Triangle(c) => area.draw(&TriangleMarker::new((x + 9, y), 8, c.filled()))?,
        }
        area.draw(&Text::new(label.clone(), (x + 28, y - 9), style.clone()))?;
        x += width;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Vec<Vertex> {
        [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)]
            .iter()
            .enumerate()
            .map(|(i, &(x_mm, y_mm))| Vertex { id: i as i64, x_mm, y_mm })
            .collect()
    }

    #[test]
    fn square_corners_are_right_angles_and_a_spike_is_sharp() {
        let sq = square();
        assert!((0..4).all(|k| (interior_angle_deg(&sq, k) - 90.0).abs() < 1e-9));
        // An isosceles tooth of apex 2·atan(1/5): the apex angle in closed form.
        let tooth: Vec<Vertex> = [(0.0, 0.0), (1.0, 5.0), (2.0, 0.0)]
            .iter()
            .enumerate()
            .map(|(i, &(x_mm, y_mm))| Vertex { id: i as i64, x_mm, y_mm })
            .collect();
        let apex = 2.0 * (1.0_f64 / 5.0).atan().to_degrees();
        assert!((interior_angle_deg(&tooth, 1) - apex).abs() < 1e-9);
        assert_eq!(closed_outline(&sq).len(), 5);
    }

    #[test]
    fn equal_aspect_gives_the_same_mm_per_pixel_on_both_axes() {
        let (xs, ys) = equal_aspect(0.0..30.0, 5.0..15.0, (600, 400));
        let per_px = |r: &Range<f64>, px: f64| (r.end - r.start) / px;
        assert!((per_px(&xs, 600.0) - per_px(&ys, 400.0)).abs() < 1e-12);
        // x (30 mm over 600 px) is the limiting axis: it stays; y widens about 10 mm.
        assert_eq!(xs, 0.0..30.0);
        assert!(((ys.start + ys.end) / 2.0 - 10.0).abs() < 1e-12 && ys.end - ys.start >= 10.0);
    }

    #[test]
    fn runs_cover_exactly_the_cells_and_break_at_gaps_and_value_changes() {
        let step = 0.02;
        // Row 0: five cells a a b b (gap) b; row 1: three cells a.
        let mut cells: Vec<(f64, f64, u8)> =
            [(0, 0), (1, 0), (2, 1), (3, 1), (5, 1)].iter().map(|&(i, v)| (i as f64 * step, 0.0, v)).collect();
        cells.extend((0..3).map(|i| (i as f64 * step, step, 0)));
        let runs = merge_runs(&cells, step);
        assert_eq!(runs.len(), 4);
        let covered: f64 = runs.iter().map(|r| r.x1 - r.x0).sum();
        assert!((covered - cells.len() as f64 * step).abs() < 1e-12, "area is conserved");
        assert!((runs[0].x1 - runs[0].x0 - 2.0 * step).abs() < 1e-12);
    }

    #[test]
    fn colour_levels_span_the_scale() {
        assert_eq!(colour_level(0.0, (0.0, 2.0)), 0);
        assert_eq!(colour_level(2.0, (0.0, 2.0)), COLOUR_LEVELS - 1);
        assert_eq!(colour_level(9.0, (0.0, 2.0)), COLOUR_LEVELS - 1);
        assert_eq!(level_colour(0), viridis(0.0));
        assert_eq!(finite_range([f64::NAN, 3.0, 1.0].into_iter()), (1.0, 3.0));
        assert_eq!(finite_range([f64::NAN].into_iter()), (0.0, 1.0));
    }
    #[test]
    fn clipping_keeps_the_part_inside_the_box() {
        let (xs, ys) = (0.0..1.0, 0.0..1.0);
        // A diagonal from (-1, -1) to (2, 2) enters at (0, 0) and leaves at (1, 1).
        assert_eq!(clip_segment((-1.0, -1.0), (2.0, 2.0), &xs, &ys), Some(((0.0, 0.0), (1.0, 1.0))));
        assert_eq!(clip_segment((2.0, 0.5), (3.0, 0.5), &xs, &ys), None);
        assert_eq!(clip_segment((0.2, 0.2), (0.4, 0.6), &xs, &ys), Some(((0.2, 0.2), (0.4, 0.6))));
        // A polyline that leaves and re-enters the box gives two pieces.
        let line = [(0.5, 0.5), (1.5, 0.5), (1.5, 0.8), (0.5, 0.8)];
        let pieces = clip_polyline(&line, &xs, &ys);
        assert_eq!(pieces, vec![vec![(0.5, 0.5), (1.0, 0.5)], vec![(1.0, 0.8), (0.5, 0.8)]]);
    }
}
