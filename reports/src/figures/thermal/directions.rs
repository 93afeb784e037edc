//! `figure.thermal_directions`: the principal deposition directions around the
//! sharpest corners of the path, (a) without and (b) with deposition direction
//! allocation (DDA), in the style of paper 003 (Chen et al.) Fig. 3 (Sec. 2.2,
//! eqs 10-26).
//!
//! Every `every_k_samples`-th sample in the zoom box is drawn as a short red segment
//! along its deposition direction, from w_r behind the centre line to w_l ahead of it
//! (the half widths of eqs 10-11): the path normal with the no-DDA half widths in (a),
//! the allocated direction with the DDA half widths in (b). The ends of all samples'
//! segments form the estimated boundaries. Where the slender condition fails without
//! DDA (S_c > 1) the half widths are undefined (NaN): those samples are drawn in (a)
//! as grey normals of the nominal half width, so the reader sees where the model
//! breaks. Both panels of a row share one zoom box, fitted around the samples within
//! `zoom_mm` of the corner and their segments (equal-aspect millimetres); lines are
//! clipped to it.
//!
//! Inputs: a `thermal.monitor` stage (`directions.parquet`) and, optionally, a stage
//! holding the CAD polygon `path.parquet` (`thermal.reprint_evaluate`). Without the polygon
//! the zoom centres on the sample of largest path curvature and `vertices` is not used
//! (a malformed list is still refused when the spec is checked).

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::params::ParamError;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::thermal::directions;

use crate::figures::thermal::common::{
    clip_polyline, closed_outline, draw_key, finite_range, interior_angle_deg, load_polygon, plane_chart, KeySwatch,
    PlaneChart, Vertex,
};
use crate::read::{f64s, no_rows, read_parquet};
use crate::style::{draw_png_and_svg, text, PALETTE};

/// The `figure.thermal_directions` stage kind.
pub struct ThermalDirectionsFigure;

/// Pixels per row of two panels.
const ROW_PX: (u32, u32) = (1400, 700);
/// Height of the title band, in pixels.
const TITLE_PX: u32 = 48;
/// Colour of the deposition-direction segments (red, as in the paper).
const DIRECTION_RED: RGBColor = RGBColor(214, 39, 40);
/// Colour of the CAD polygon.
const CAD_GREY: RGBColor = RGBColor(150, 150, 150);
/// Height of the key band below the panels, in pixels.
const KEY_PX: u32 = 40;

pipeline::params! {
    /// The parameters of `figure.thermal_directions`.
    pub struct DirectionsParams {
        /// Comma-separated CAD vertex ids to zoom on, one row each (default: the sharpest
        /// corner, the 45° apex of the test path).
        pub vertices: String = "",
        /// Radius around each vertex whose samples the zoom box is fitted to (mm); 1.2 mm
        /// shows the corner and about five bead widths of each leg.
        pub zoom_mm: f64 [0.1, 100.0] = 1.2,
        /// Draw the deposition direction of every k-th sample (at 1 ms sampling and 20 mm/s,
        /// k = 8 is one segment per 0.16 mm on the straights, denser where the head slows).
        pub every_k_samples: usize [1, 100_000] = 8,
        /// Figure title (default: a generic description).
        pub title: String = "",
    }
}

/// The monitor whose deposition directions are drawn.
const MONITOR: Input = Input::one(
    "monitor",
    &[Source::Stage("thermal.monitor")],
    "the deposition directions and half widths per sample (`directions.parquet`)",
)
.reading(&[Reads {
    table: &directions::TABLE,
    columns: &[
        directions::x_mm,
        directions::y_mm,
        directions::kappa_per_mm,
        directions::normal_x,
        directions::normal_y,
        directions::dep_x,
        directions::dep_y,
        directions::w_left_mm,
        directions::w_right_mm,
        directions::w_left_no_dda_mm,
        directions::w_right_no_dda_mm,
    ],
}]);

/// The CAD polygon, when given; without it the zoom centres on the sample of largest
/// path curvature.
const POLYGON: Input = Input::optional(
    "polygon",
    &[Source::Stage("thermal.reprint_evaluate")],
    "the CAD polygon whose vertices are zoomed on (`path.parquet`)",
);

/// The columns of `directions.parquet` this figure draws.
#[derive(Debug, Clone, Default)]
pub struct Directions {
    /// Sample positions (mm).
    pub xy_mm: Vec<(f64, f64)>,
    /// Path curvature κ (1/mm).
    pub kappa_per_mm: Vec<f64>,
    /// Unit path normal (no DDA).
    pub normal: Vec<(f64, f64)>,
    /// Unit deposition direction with DDA.
    pub dep: Vec<(f64, f64)>,
    /// Half widths (left, right) with DDA (mm).
    pub w_dda_mm: Vec<(f64, f64)>,
    /// Half widths (left, right) without DDA (mm; NaN where S_c > 1).
    pub w_no_dda_mm: Vec<(f64, f64)>,
}

/// Which of the two panels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    /// (a): path normals, no-DDA half widths.
    WithoutDda,
    /// (b): allocated directions, DDA half widths.
    WithDda,
}

/// One drawn deposition segment: from the right end through the centre to the left
/// end; `defined` is false where the half widths are NaN (drawn at nominal width).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Right end (mm).
    pub right: (f64, f64),
    /// Left end (mm).
    pub left: (f64, f64),
    /// Whether the model defines the half widths here.
    pub defined: bool,
}

impl Directions {
    /// The deposition segment of sample `i` in `variant`; undefined half widths are
    /// replaced by `nominal_mm` on both sides.
    pub fn segment(&self, i: usize, variant: Variant, nominal_mm: f64) -> Segment {
        let (dir, (wl, wr)) = match variant {
            Variant::WithoutDda => (self.normal[i], self.w_no_dda_mm[i]),
            Variant::WithDda => (self.dep[i], self.w_dda_mm[i]),
        };
        let defined = wl.is_finite() && wr.is_finite();
        let (wl, wr) = if defined { (wl, wr) } else { (nominal_mm, nominal_mm) };
        let (x, y) = self.xy_mm[i];
        Segment { right: (x - wr * dir.0, y - wr * dir.1), left: (x + wl * dir.0, y + wl * dir.1), defined }
    }

    /// The median of the finite DDA half widths: the nominal half width w0 on a path
    /// that is mostly straight.
    pub fn nominal_half_width_mm(&self) -> f64 {
        let mut w: Vec<f64> = self.w_dda_mm.iter().flat_map(|&(l, r)| [l, r]).filter(|w| w.is_finite()).collect();
        w.sort_by(f64::total_cmp);
        w.get(w.len() / 2).copied().unwrap_or(0.2)
    }

    fn len(&self) -> usize {
        self.xy_mm.len()
    }
}

/// One zoomed row: a title and the box centre.
#[derive(Debug, Clone)]
pub struct Zoom {
    /// Row caption (vertex and angle).
    pub label: String,
    /// Box centre (mm).
    pub centre_mm: (f64, f64),
}

impl Stage for ThermalDirectionsFigure {
    type Params = DirectionsParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.thermal_directions",
        version: 1,
        summary: "Principal deposition directions and estimated boundaries at the sharpest corners, without and with DDA → thermal_directions.png/.svg",
        implements: "paper 003 Fig. 3 (Sec. 2.2, eqs 10-26)",
        inputs: &[MONITOR, POLYGON],
        output: Output::Tables,
    };

    fn check(p: &DirectionsParams) -> Result<(), ParamError> {
        parse_vertices(&p.vertices, "vertices").map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &DirectionsParams) -> Result<(), StageError> {
        let directions = load(&ctx.input(&MONITOR).dir)?;
        let polygon = ctx.optional_input(&POLYGON).map(|i| load_polygon(&i.dir)).transpose()?;
        let zooms = match &polygon {
            Some(polygon) => {
                let wanted = parse_vertices(&p.vertices, "vertices").map_err(|e| StageError::params(ctx, e))?;
                zooms_at_vertices(polygon, &wanted, &ctx.stage)?
            }
            None => vec![zoom_at_max_curvature(&directions)],
        };
        let plot = Plot {
            directions,
            polygon: polygon.unwrap_or_default(),
            zooms,
            half_mm: p.zoom_mm,
            every_k: p.every_k_samples,
        };
        let title = crate::figures::common::title_or(&p.title, || {
            "Principal deposition directions (red) and estimated boundaries: (a) without DDA, (b) with DDA".to_string()
        });
        let stem = ctx.output_path("thermal_directions")?;
        let size = figure_size_px(plot.zooms.len());
        draw_png_and_svg(&stem, size, |a| draw(a, &title, &plot), |a| draw(a, &title, &plot))
    }
}

/// Reads `<dir>/directions.parquet`.
pub fn load(dir: &Path) -> Result<Directions, StageError> {
    let path = dir.join(directions::TABLE.file());
    let df = read_parquet(&path)?;
    let col = |name: &str| f64s(&df, name, &path);
    let zip = |a: Vec<f64>, b: Vec<f64>| a.into_iter().zip(b).collect::<Vec<(f64, f64)>>();
    let directions = Directions {
        xy_mm: zip(col(directions::x_mm)?, col(directions::y_mm)?),
        kappa_per_mm: col(directions::kappa_per_mm)?,
        normal: zip(col(directions::normal_x)?, col(directions::normal_y)?),
        dep: zip(col(directions::dep_x)?, col(directions::dep_y)?),
        w_dda_mm: zip(col(directions::w_left_mm)?, col(directions::w_right_mm)?),
        w_no_dda_mm: zip(col(directions::w_left_no_dda_mm)?, col(directions::w_right_no_dda_mm)?),
    };
    if directions.len() == 0 {
        return Err(no_rows(&path, directions::x_mm, "one row per trajectory sample"));
    }
    Ok(directions)
}

/// Parses a list of vertex ids, the parameter `field`: comma-separated integers, empty
/// for the default.
pub fn parse_vertices(raw: &str, field: &'static str) -> Result<Vec<i64>, ParamError> {
    raw.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<i64>().map_err(|_| ParamError::new(field, format!("`{s}` is not an integer vertex id"))))
        .collect()
}

/// The zoom rows for `wanted` vertex ids, or for the sharpest corner when empty.
pub fn zooms_at_vertices(polygon: &[Vertex], wanted: &[i64], stage: &str) -> Result<Vec<Zoom>, StageError> {
    let zoom = |k: usize| {
        let v = polygon[k];
        let label = format!("vertex {} ({:.0}° corner)", v.id, interior_angle_deg(polygon, k));
        Zoom { label, centre_mm: (v.x_mm, v.y_mm) }
    };
    if wanted.is_empty() {
        let sharpest = (0..polygon.len())
            .min_by(|&a, &b| interior_angle_deg(polygon, a).total_cmp(&interior_angle_deg(polygon, b)))
            .unwrap_or(0);
        return Ok(vec![zoom(sharpest)]);
    }
    wanted
        .iter()
        .map(|id| {
            polygon.iter().position(|v| v.id == *id).map(zoom).ok_or_else(|| StageError::Params {
                stage: stage.to_string(),
                message: format!("vertices: the path has no vertex {id}"),
            })
        })
        .collect()
}

/// A zoom on the sample of largest |κ| (used when no polygon is given).
pub fn zoom_at_max_curvature(d: &Directions) -> Zoom {
    let i = (0..d.len()).max_by(|&a, &b| d.kappa_per_mm[a].abs().total_cmp(&d.kappa_per_mm[b].abs())).unwrap_or(0);
    Zoom { label: format!("largest curvature, sample {i}"), centre_mm: d.xy_mm[i] }
}

/// The figure size for `rows` zoomed corners.
pub fn figure_size_px(rows: usize) -> (u32, u32) {
    (ROW_PX.0, TITLE_PX + KEY_PX + ROW_PX.1 * rows.max(1) as u32)
}

/// Everything a drawing needs.
#[derive(Debug)]
pub struct Plot {
    /// The directions table.
    pub directions: Directions,
    /// The CAD polygon (empty when not an input).
    pub polygon: Vec<Vertex>,
    /// One row per zoom.
    pub zooms: Vec<Zoom>,
    /// Radius around the corner whose samples the zoom box holds (mm).
    pub half_mm: f64,
    /// Draw every k-th sample.
    pub every_k: usize,
}

impl Plot {
    /// Indices of the samples within `radius_mm` of the zoom centre.
    fn near(&self, zoom: &Zoom, radius_mm: f64) -> Vec<usize> {
        let (cx, cy) = zoom.centre_mm;
        (0..self.directions.len())
            .filter(|&i| {
                let (x, y) = self.directions.xy_mm[i];
                (x - cx).hypot(y - cy) <= radius_mm
            })
            .collect()
    }

    /// The box drawn for `zoom`: around the samples within `half_mm` of the corner and
    /// the ends of their segments in both variants, so the corner fills the panel.
    pub fn zoom_box(&self, zoom: &Zoom) -> (Range<f64>, Range<f64>) {
        let nominal = self.directions.nominal_half_width_mm();
        let ends = self.near(zoom, self.half_mm).into_iter().flat_map(|i| {
            let (a, b) = (
                self.directions.segment(i, Variant::WithoutDda, nominal),
                self.directions.segment(i, Variant::WithDda, nominal),
            );
            [self.directions.xy_mm[i], a.left, a.right, b.left, b.right]
        });
        let (xs, ys): (Vec<f64>, Vec<f64>) = ends.chain([zoom.centre_mm]).unzip();
        let ((x0, x1), (y0, y1)) = (finite_range(xs.into_iter()), finite_range(ys.into_iter()));
        let pad = 0.05 * (x1 - x0).max(y1 - y0);
        ((x0 - pad)..(x1 + pad), (y0 - pad)..(y1 + pad))
    }
}

/// Draws one row (without / with DDA) per zoom and one key below.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, plot: &Plot) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let area = area.margin(10, 6, 6, 10).titled(title, text(24.0)).map_err(e)?;
    let (grid, key) = area.split_vertically(area.dim_in_pixel().1.saturating_sub(KEY_PX));
    let rows = grid.split_evenly((plot.zooms.len().max(1), 2));
    for (k, zoom) in plot.zooms.iter().enumerate() {
        for (j, variant) in [Variant::WithoutDda, Variant::WithDda].into_iter().enumerate() {
            draw_panel(&rows[2 * k + j], plot, zoom, variant).map_err(e)?;
        }
    }
    let mut items = vec![
        ("path centre line".to_string(), KeySwatch::Line(BLACK)),
        ("deposition direction, w_r behind to w_l ahead".to_string(), KeySwatch::Line(DIRECTION_RED)),
        ("S_c > 1 without DDA: width undefined (w0 drawn)".to_string(), KeySwatch::Line(PALETTE[6])),
        ("estimated boundary".to_string(), KeySwatch::Line(PALETTE[0])),
    ];
    if !plot.polygon.is_empty() {
        items.push(("CAD path".to_string(), KeySwatch::Line(CAD_GREY)));
    }
    draw_key(&key, &items).map_err(e)
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    plot: &Plot,
    zoom: &Zoom,
    variant: Variant,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let name = match variant {
        Variant::WithoutDda => "(a) without DDA",
        Variant::WithDda => "(b) with DDA",
    };
    let area = area.titled(&format!("{name}: {}", zoom.label), text(18.0))?;
    let (xs, ys) = plot.zoom_box(zoom);
    let mut chart = plane_chart(&area, xs, ys, 1)?;
    let (xs, ys) = (chart.x_range(), chart.y_range());
    // Samples a little outside the box still draw segments that reach into it.
    let reach = 0.75 * (xs.end - xs.start).hypot(ys.end - ys.start);
    let near = plot.near(zoom, reach);
    let nominal = plot.directions.nominal_half_width_mm();
    let segments: Vec<Segment> = near.iter().map(|&i| plot.directions.segment(i, variant, nominal)).collect();
    let mut lines = Lines { chart: &mut chart, xs, ys };
    if !plot.polygon.is_empty() {
        lines.dashed(&closed_outline(&plot.polygon), CAD_GREY.stroke_width(1))?;
    }
    let picked = segments.iter().zip(&near).filter(|(_, i)| **i % plot.every_k.max(1) == 0).map(|(s, _)| s);
    for s in picked {
        let colour = if s.defined { DIRECTION_RED } else { PALETTE[6] };
        lines.solid(&[s.right, s.left], colour.stroke_width(2))?;
    }
    // The estimated boundaries: left ends and right ends in path order, broken where
    // the model is undefined.
    let picks: [EndOf; 2] = [|s| s.left, |s| s.right];
    for pick in picks {
        for piece in segments.split(|s| !s.defined) {
            lines.solid(&piece.iter().map(pick).collect::<Vec<_>>(), PALETTE[0].stroke_width(2))?;
        }
    }
    let centre: Vec<(f64, f64)> = near.iter().map(|&i| plot.directions.xy_mm[i]).collect();
    lines.solid(&centre, BLACK.stroke_width(2))
}

/// Picks one end of a segment.
type EndOf = fn(&Segment) -> (f64, f64);

/// Polylines drawn on a zoomed chart, clipped to its box.
struct Lines<'c, 'a, DB: DrawingBackend> {
    chart: &'c mut PlaneChart<'a, DB>,
    xs: Range<f64>,
    ys: Range<f64>,
}

impl<DB: DrawingBackend> Lines<'_, '_, DB> {
    fn solid(&mut self, points: &[(f64, f64)], style: ShapeStyle) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        for piece in clip_polyline(points, &self.xs, &self.ys) {
            self.chart.draw_series(LineSeries::new(piece, style))?;
        }
        Ok(())
    }

    fn dashed(&mut self, points: &[(f64, f64)], style: ShapeStyle) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        for piece in clip_polyline(points, &self.xs, &self.ys) {
            self.chart.draw_series(DashedLineSeries::new(piece, 6, 4, style))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, write_table};
    use crate::figures::thermal::test_data::{corner_path, directions, path_table};

    fn straight(n: usize) -> Directions {
        Directions {
            xy_mm: (0..n).map(|i| (i as f64 * 0.1, 0.0)).collect(),
            kappa_per_mm: (0..n).map(|i| if i == 3 { 5.0 } else { 0.0 }).collect(),
            normal: vec![(0.0, 1.0); n],
            dep: vec![(0.6, 0.8); n],
            w_dda_mm: vec![(0.3, 0.2); n],
            w_no_dda_mm: (0..n).map(|i| if i == 2 { (f64::NAN, f64::NAN) } else { (0.25, 0.25) }).collect(),
        }
    }

    #[test]
    fn segments_run_from_w_right_behind_to_w_left_ahead() {
        let d = straight(5);
        let s = d.segment(1, Variant::WithDda, 0.2);
        // Along (0.6, 0.8): 0.3 mm ahead, 0.2 mm behind; total length w_l + w_r.
        assert!((s.left.0 - (0.1 + 0.18)).abs() < 1e-12 && (s.left.1 - 0.24).abs() < 1e-12);
        assert!((s.right.0 - (0.1 - 0.12)).abs() < 1e-12 && (s.right.1 + 0.16).abs() < 1e-12);
        let len = (s.left.0 - s.right.0).hypot(s.left.1 - s.right.1);
        assert!((len - 0.5).abs() < 1e-12);
        let undefined = d.segment(2, Variant::WithoutDda, 0.2);
        assert!(!undefined.defined && (undefined.left.1 - 0.2).abs() < 1e-12);
        assert_eq!(zoom_at_max_curvature(&d).centre_mm, (3.0 * 0.1, 0.0));
    }

    #[test]
    fn vertex_list_parses_and_unknown_ids_are_errors() {
        assert_eq!(parse_vertices(" 9, 7 ,", "vertices").expect("parses"), vec![9, 7]);
        assert!(parse_vertices("", "vertices").expect("parses").is_empty());
        let err = parse_vertices("nine", "vertices").expect_err("not an integer");
        assert_eq!(err.field, "vertices");
        assert!(err.message.contains("`nine`"), "{}", err.message);
        let dir = tempfile::tempdir().expect("tempdir");
        write_table(dir.path(), "path", path_table(&corner_path()));
        let polygon = load_polygon(dir.path()).expect("loads");
        let default = zooms_at_vertices(&polygon, &[], "s").expect("zooms");
        assert_eq!(default[0].label, "vertex 9 (45° corner)", "the sharpest corner is the 45° apex");
        let err = zooms_at_vertices(&polygon, &[42], "s").expect_err("no vertex 42").to_string();
        assert!(err.contains("no vertex 42"), "{err}");
    }

    #[test]
    fn missing_column_names_file_and_column() {
        let dir = tempfile::tempdir().expect("tempdir");
        let df = directions(&corner_path()).drop("dep_y").expect("drops");
        write_table(dir.path(), "directions", df);
        let err = load(dir.path()).expect_err("dep_y is missing").to_string();
        assert!(err.contains("directions.parquet") && err.contains("dep_y"), "{err}");
        let err = load_polygon(dir.path()).expect_err("no path table").to_string();
        assert!(err.contains("path.parquet"), "{err}");
    }

    #[test]
    fn draws_the_45_and_60_degree_apexes() {
        let dir = tempfile::tempdir().expect("tempdir");
        let poly = corner_path();
        write_table(dir.path(), "directions", directions(&poly));
        write_table(dir.path(), "path", path_table(&poly));
        let polygon = load_polygon(dir.path()).expect("loads");
        let plot = Plot {
            directions: load(dir.path()).expect("loads"),
            zooms: zooms_at_vertices(&polygon, &[9, 7], "s").expect("zooms"),
            polygon,
            half_mm: 1.2,
            every_k: 8,
        };
        assert!((plot.directions.nominal_half_width_mm() - 0.225).abs() < 0.01);
        let stem = dir.path().join("thermal_directions");
        let title = "Synthetic corner test path (cf. paper 003 Fig. 3)";
        let size = figure_size_px(plot.zooms.len());
        draw_png_and_svg(&stem, size, |a| draw(a, title, &plot), |a| draw(a, title, &plot)).expect("draws");
        assert_drawn(&stem);
    }
}
