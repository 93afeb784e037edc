//! `figure.thermal_frame`: how a thermal frame is aligned with the path, in the style
//! of paper 003 (Chen et al.) Fig. 4 (Sec. 2.3, eqs 27-30): (a) one undistorted frame
//! as a heat map with the 140-150 °C band of freshly printed material outlined, (b) the
//! same frame with the detected corners (matched to a CAD vertex or not) and the
//! nozzle, and (c) the mosaic of all aligned frames on the build plane with the CAD
//! path overlaid. The paper's (c) (first aligned frame) and (d) (all aligned frames)
//! are one panel here: the mosaic is what the monitor stage publishes.
//!
//! The frame is drawn in pixel coordinates with v increasing downwards, as the camera
//! sees it; the mosaic in millimetres on the plane, equal aspect. One temperature
//! colour bar serves all panels.
//!
//! Inputs: a `thermal.monitor` stage (`frame_example.parquet`,
//! `detections_example.parquet`, `frame_example_meta.parquet`, `mosaic.parquet`) and,
//! optionally, a stage holding the CAD polygon `path.parquet` (`thermal.reprint_evaluate`).

use std::collections::BTreeSet;
use std::path::Path;

use polars::prelude::DataFrame;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::params::ParamError;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::thermal::{detections_example, frame_example, frame_example_meta, mosaic};

use crate::figures::thermal::common::{
    closed_outline, colour_level, draw_key, draw_runs, equal_aspect_chart, finite_range, level_colour, load_polygon,
    merge_runs, plane_chart, KeySwatch, PlaneChart, Vertex,
};
use crate::read::{f64s, ints, no_rows, read_parquet};
use crate::style::{draw_png_and_svg, house_mesh, text};

/// The `figure.thermal_frame` stage kind.
pub struct ThermalFrameFigure;

/// Figure size in pixels.
const SIZE_PX: (u32, u32) = (1500, 1150);
/// Width of the colour bar strip, in pixels.
const COLOUR_BAR_PX: u32 = 130;
/// Height of the frame row as a fraction of the area below the title.
const TOP_ROW_FRACTION: f64 = 0.52;
/// Height of the key band between the frame row and the mosaic, in pixels.
const KEY_PX: u32 = 40;
/// Colour of the band outline (white reads on every viridis colour).
const BAND_LINE: RGBColor = RGBColor(255, 255, 255);
/// Marker colours: matched corners, unmatched detections, the nozzle.
const MATCHED: RGBColor = RGBColor(0, 0, 0);
const UNMATCHED: RGBColor = RGBColor(214, 39, 40);
const NOZZLE: RGBColor = RGBColor(230, 159, 0);

pipeline::params! {
    /// The parameters of `figure.thermal_frame`.
    pub struct FrameParams {
        /// Lower edge of the outlined temperature band (°C); paper 003 Sec. 3.2: 140 °C.
        pub band_low_c: f64 [-50.0, 1000.0] = 140.0,
        /// Upper edge of the outlined temperature band (°C); paper 003 Sec. 3.2: 150 °C.
        pub band_high_c: f64 [-50.0, 1000.0] = 150.0,
        /// Figure title (default: a generic description).
        pub title: String = "",
    }
}

/// The monitor whose example frame and mosaic are drawn.
const MONITOR: Input = Input::one(
    "monitor",
    &[Source::Stage("thermal.monitor")],
    "an example frame, its detections and the mosaic (`frame_example.parquet`, `detections_example.parquet`, `frame_example_meta.parquet`, `mosaic.parquet`)",
)
.reading(&[
    Reads { table: &frame_example::TABLE, columns: &[frame_example::u_px, frame_example::v_px, frame_example::temp_c] },
    Reads { table: &mosaic::TABLE, columns: &[mosaic::x_mm, mosaic::y_mm, mosaic::temp_c] },
    Reads {
        table: &detections_example::TABLE,
        columns: &[detections_example::u_px, detections_example::v_px, detections_example::matched_vertex],
    },
    Reads {
        table: &frame_example_meta::TABLE,
        columns: &[
            frame_example_meta::layer,
            frame_example_meta::frame,
            frame_example_meta::nozzle_u_px,
            frame_example_meta::nozzle_v_px,
        ],
    },
]);

/// The CAD polygon overlaid on the mosaic, when given.
const POLYGON: Input = Input::optional(
    "polygon",
    &[Source::Stage("thermal.reprint_evaluate")],
    "the CAD polygon drawn over the mosaic (`path.parquet`)",
);

/// One pixel or plane cell with its temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// Column (px) or x (mm).
    pub x: f64,
    /// Row (px) or y (mm).
    pub y: f64,
    /// Temperature (°C).
    pub temp_c: f64,
}

/// A detected corner in the example frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Column (px).
    pub u_px: f64,
    /// Row (px).
    pub v_px: f64,
    /// The CAD vertex it was matched to, if any.
    pub vertex: Option<i64>,
}

/// Everything the figure draws.
#[derive(Debug, Clone)]
pub struct FrameData {
    /// Pixels of the example frame (x = u, y = v).
    pub frame: Vec<Cell>,
    /// Detected corners.
    pub detections: Vec<Detection>,
    /// Layer and frame number of the example.
    pub layer_frame: (i64, i64),
    /// Nozzle position in the frame (px).
    pub nozzle_px: (f64, f64),
    /// Mosaic cells on the plane (mm), NaN cells dropped.
    pub mosaic: Vec<Cell>,
    /// The CAD polygon (empty when not an input).
    pub polygon: Vec<Vertex>,
    /// The outlined band (°C).
    pub band_c: (f64, f64),
}

impl Stage for ThermalFrameFigure {
    type Params = FrameParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.thermal_frame",
        version: 2,
        summary: "An undistorted thermal frame with its 140-150 °C band, its detected corners and the nozzle, and the mosaic of aligned frames on the plane → thermal_frame.png/.svg",
        implements: "paper 003 Fig. 4 (Sec. 2.3, eqs 27-30)",
        inputs: &[MONITOR, POLYGON],
        output: Output::Tables,
    };

    fn check(p: &FrameParams) -> Result<(), ParamError> {
        if p.band_low_c >= p.band_high_c {
            let message = format!("band_low_c ({}) must be below band_high_c ({})", p.band_low_c, p.band_high_c);
            return Err(ParamError::new("band_low_c", message));
        }
        Ok(())
    }

    fn run(&self, ctx: &mut StageContext, p: &FrameParams) -> Result<(), StageError> {
        let mut data = load(&ctx.input(&MONITOR).dir, (p.band_low_c, p.band_high_c))?;
        if let Some(input) = ctx.optional_input(&POLYGON) {
            data.polygon = load_polygon(&input.dir)?;
        }
        let title = crate::figures::common::title_or(&p.title, || {
            "Thermal frame alignment: undistorted frame, detected corners, aligned frames on the plane".to_string()
        });
        let stem = ctx.output_path("thermal_frame")?;
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, &title, &data), |a| draw(a, &title, &data))
    }
}

/// The cells of `table` (columns `x`, `y` and `temp`) with a finite temperature.
fn cells(dir: &Path, table: &Table, [x, y, temp_col]: [&str; 3]) -> Result<Vec<Cell>, StageError> {
    let path = dir.join(table.file());
    let df = read_parquet(&path)?;
    let temp = f64s(&df, temp_col, &path)?;
    let (xs, ys) = (coords(&df, x, &path)?, coords(&df, y, &path)?);
    let cells: Vec<Cell> = (0..df.height())
        .filter(|&i| temp[i].is_finite())
        .map(|i| Cell { x: xs[i], y: ys[i], temp_c: temp[i] })
        .collect();
    if cells.is_empty() {
        return Err(no_rows(&path, temp_col, "a finite temperature"));
    }
    Ok(cells)
}

/// A coordinate column written as integers (pixel indices) or floats.
fn coords(df: &DataFrame, name: &str, path: &Path) -> Result<Vec<f64>, StageError> {
    match df.column(name).map(|c| c.dtype().is_integer()) {
        Ok(true) => Ok(ints(df, name, path)?.into_iter().map(|v| v as f64).collect()),
        _ => f64s(df, name, path),
    }
}

/// Reads the example frame, its detections and meta, and the mosaic from `dir`.
pub fn load(dir: &Path, band_c: (f64, f64)) -> Result<FrameData, StageError> {
    let frame = cells(dir, &frame_example::TABLE, [frame_example::u_px, frame_example::v_px, frame_example::temp_c])?;
    let mosaic = cells(dir, &mosaic::TABLE, [mosaic::x_mm, mosaic::y_mm, mosaic::temp_c])?;
    let path = dir.join(detections_example::TABLE.file());
    let df = read_parquet(&path)?;
    let (u, v, matched) = (
        coords(&df, detections_example::u_px, &path)?,
        coords(&df, detections_example::v_px, &path)?,
        ints(&df, detections_example::matched_vertex, &path)?,
    );
    let detections = (0..df.height())
        .map(|i| Detection { u_px: u[i], v_px: v[i], vertex: (matched[i] >= 0).then_some(matched[i]) })
        .collect();
    let path = dir.join(frame_example_meta::TABLE.file());
    let df = read_parquet(&path)?;
    if df.height() == 0 {
        return Err(no_rows(&path, frame_example_meta::layer, "one row"));
    }
    let (layer, frame_no) =
        (ints(&df, frame_example_meta::layer, &path)?[0], ints(&df, frame_example_meta::frame, &path)?[0]);
    let nozzle_px =
        (f64s(&df, frame_example_meta::nozzle_u_px, &path)?[0], f64s(&df, frame_example_meta::nozzle_v_px, &path)?[0]);
    Ok(FrameData { frame, detections, layer_frame: (layer, frame_no), nozzle_px, mosaic, polygon: Vec::new(), band_c })
}

/// The pixel edges that bound the set of pixels whose temperature lies in `band_c`:
/// each edge between a band pixel and a non-band (or absent) neighbour, as two end
/// points in (u, v) pixel coordinates. Together they outline the band, in an order that
/// depends only on the set of band pixels (so the SVG is byte-reproducible).
pub fn band_outline(frame: &[Cell], band_c: (f64, f64)) -> Vec<[(f64, f64); 2]> {
    let key = |c: &Cell| (c.x.round() as i64, c.y.round() as i64);
    let inside: BTreeSet<(i64, i64)> =
        frame.iter().filter(|c| c.temp_c >= band_c.0 && c.temp_c <= band_c.1).map(key).collect();
    let mut edges = Vec::new();
    for &(u, v) in &inside {
        let (x, y) = (u as f64, v as f64);
        let sides = [
            ((u - 1, v), [(x - 0.5, y - 0.5), (x - 0.5, y + 0.5)]),
            ((u + 1, v), [(x + 0.5, y - 0.5), (x + 0.5, y + 0.5)]),
            ((u, v - 1), [(x - 0.5, y - 0.5), (x + 0.5, y - 0.5)]),
            ((u, v + 1), [(x - 0.5, y + 0.5), (x + 0.5, y + 0.5)]),
        ];
        edges.extend(sides.iter().filter(|(n, _)| !inside.contains(n)).map(|(_, e)| *e));
    }
    let row_major = |e: &[(f64, f64); 2]| [e[0].1, e[0].0, e[1].1, e[1].0];
    edges.sort_by(|a, b| {
        row_major(a).iter().zip(row_major(b).iter()).fold(std::cmp::Ordering::Equal, |o, (x, y)| o.then(x.total_cmp(y)))
    });
    edges
}

/// Draws (a) and (b) side by side on top, (c) below, one colour bar at the right.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, data: &FrameData) -> Result<(), String> {
    let area = area.margin(10, 6, 6, 10).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    let (panels, bar) = area.split_horizontally(area.dim_in_pixel().0.saturating_sub(COLOUR_BAR_PX));
    let top_px = (panels.dim_in_pixel().1 as f64 * TOP_ROW_FRACTION) as u32;
    let (top, rest) = panels.split_vertically(top_px);
    let (key, bottom) = rest.split_vertically(KEY_PX);
    let (a, b) = top.split_horizontally(top.dim_in_pixel().0 / 2);
    let range = finite_range(data.frame.iter().chain(&data.mosaic).map(|c| c.temp_c));
    let (layer, frame) = data.layer_frame;
    let caption = format!("(a) undistorted frame (layer {layer}, frame {frame})");
    draw_frame_panel(&a, data, range, &caption, false).map_err(|e| e.to_string())?;
    draw_frame_panel(&b, data, range, "(b) detected corners and nozzle", true).map_err(|e| e.to_string())?;
    draw_mosaic(&bottom, data, range).map_err(|e| e.to_string())?;
    draw_key(&key, &key_items(data)).map_err(|e| e.to_string())?;
    crate::figures::common::draw_viridis_bar(&bar, range, "temperature (°C)", 0, super::common::COLOUR_LEVELS)
        .map_err(|e| e.to_string())
}

fn key_items(data: &FrameData) -> Vec<(String, KeySwatch)> {
    let matched = data.detections.iter().filter(|d| d.vertex.is_some()).count();
    let mut items = vec![
        (
            format!("{:.0}-{:.0} °C band outline", data.band_c.0, data.band_c.1),
            KeySwatch::Outlined(RGBColor(60, 60, 60), BAND_LINE),
        ),
        (format!("corner matched to a CAD vertex ({matched})"), KeySwatch::Circle(MATCHED)),
        (format!("detection not matched ({})", data.detections.len() - matched), KeySwatch::Cross(UNMATCHED)),
        ("nozzle".to_string(), KeySwatch::Triangle(NOZZLE)),
    ];
    if !data.polygon.is_empty() {
        items.push(("CAD path (in c)".to_string(), KeySwatch::LineOn(RGBColor(60, 60, 60), WHITE)));
    }
    items
}

/// The frame in pixel coordinates; rows are plotted at y = v_max − v so that v grows
/// downwards, and labelled with v.
fn draw_frame_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &FrameData,
    range: (f64, f64),
    caption: &str,
    markers: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let area = area.titled(caption, text(18.0))?;
    let (u_max, v_max) = data.frame.iter().fold((0.0_f64, 0.0_f64), |(u, v), c| (u.max(c.x), v.max(c.y)));
    let flip = |(u, v): (f64, f64)| (u, -v);
    let mut chart = equal_aspect_chart(&area, -0.5..u_max + 0.5, -(v_max + 0.5)..0.5)?;
    house_mesh(&mut chart)
        .disable_mesh()
        .x_desc("u (px)")
        .y_desc("v (px)")
        .x_label_formatter(&|u| format!("{u:.0}"))
        .y_label_formatter(&|y| format!("{:.0}", 0.0 - y))
        .draw()?;
    let levelled: Vec<(f64, f64, usize)> =
        data.frame.iter().map(|c| (c.x, -c.y, colour_level(c.temp_c, range))).collect();
    draw_runs(&mut chart, &merge_runs(&levelled, 1.0), 1.0, level_colour)?;
    let line = BAND_LINE.stroke_width(1);
    let outline = band_outline(&data.frame, data.band_c);
    chart.draw_series(outline.iter().map(|e| PathElement::new([flip(e[0]), flip(e[1])], line)))?;
    if markers {
        draw_markers(&mut chart, data, flip)?;
    }
    Ok(())
}

fn draw_markers<DB: DrawingBackend>(
    chart: &mut PlaneChart<DB>,
    data: &FrameData,
    flip: impl Fn((f64, f64)) -> (f64, f64),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let matched: Vec<(Detection, (f64, f64))> =
        data.detections.iter().filter(|d| d.vertex.is_some()).map(|d| (*d, flip((d.u_px, d.v_px)))).collect();
    chart.draw_series(matched.iter().map(|(_, p)| Circle::new(*p, 9, MATCHED.stroke_width(3))))?;
    let label_style = text(16.0).color(&WHITE);
    let label = |(d, p): &(Detection, (f64, f64))| {
        Text::new(format!("v{}", d.vertex.unwrap_or(-1)), (p.0 + 5.0, p.1 + 9.0), label_style.clone())
    };
    chart.draw_series(matched.iter().map(label))?;
    let unmatched = data.detections.iter().filter(|d| d.vertex.is_none()).map(|d| flip((d.u_px, d.v_px)));
    chart.draw_series(unmatched.map(|p| Cross::new(p, 8, UNMATCHED.stroke_width(3))))?;
    chart.draw_series([TriangleMarker::new(flip(data.nozzle_px), 11, NOZZLE.filled())])?;
    Ok(())
}

fn draw_mosaic<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &FrameData,
    range: (f64, f64),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let caption = "(c) aligned frames stitched on the plane (latest frame per cell) with the CAD path";
    let area = area.titled(caption, text(18.0))?;
    let step = crate::figures::common::grid_step(data.mosaic.iter().map(|c| c.x));
    let xs = data.mosaic.iter().map(|c| c.x).chain(data.polygon.iter().map(|v| v.x_mm));
    let ys = data.mosaic.iter().map(|c| c.y).chain(data.polygon.iter().map(|v| v.y_mm));
    let ((x0, x1), (y0, y1)) = (finite_range(xs), finite_range(ys));
    let mut chart = plane_chart(&area, (x0 - step)..(x1 + step), (y0 - step)..(y1 + step), 0)?;
    let levelled: Vec<(f64, f64, usize)> =
        data.mosaic.iter().map(|c| (c.x, c.y, colour_level(c.temp_c, range))).collect();
    draw_runs(&mut chart, &merge_runs(&levelled, step), step, level_colour)?;
    if !data.polygon.is_empty() {
        chart.draw_series(DashedLineSeries::new(closed_outline(&data.polygon), 8, 5, WHITE.stroke_width(2)))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, write_table};
    use crate::figures::thermal::test_data::{corner_path, frame_example, mosaic, path_table, write_monitor};

    #[test]
    fn band_outline_of_a_block_is_its_perimeter() {
        // A 3 × 2 block of band pixels inside a 5 × 4 frame: perimeter 2·(3 + 2) = 10 edges.
        let frame: Vec<Cell> = (0..4)
            .flat_map(|v| (0..5).map(move |u| (u, v)))
            .map(|(u, v)| {
                let inside = (1..4).contains(&u) && (1..3).contains(&v);
                Cell { x: u as f64, y: v as f64, temp_c: if inside { 145.0 } else { 200.0 } }
            })
            .collect();
        let edges = band_outline(&frame, (140.0, 150.0));
        assert_eq!(edges.len(), 10);
        let length: f64 = edges.iter().map(|e| (e[1].0 - e[0].0).hypot(e[1].1 - e[0].1)).sum();
        assert!((length - 10.0).abs() < 1e-12);
        assert!(band_outline(&frame, (0.0, 10.0)).is_empty());
    }

    #[test]
    fn band_outline_order_depends_only_on_the_band() {
        // A checkerboard: diagonal band pixels share corners, so edges tie on their start.
        let frame: Vec<Cell> = (0..12)
            .flat_map(|v| (0..12).map(move |u| (u, v)))
            .map(|(u, v)| Cell { x: u as f64, y: v as f64, temp_c: if (u + v) % 2 == 0 { 145.0 } else { 200.0 } })
            .collect();
        let edges = band_outline(&frame, (140.0, 150.0));
        assert_eq!(edges.len(), 72 * 4);
        let mut reversed = frame.clone();
        reversed.reverse();
        for _ in 0..8 {
            assert!(band_outline(&reversed, (140.0, 150.0)) == edges, "the same edges in the same order");
        }
    }

    #[test]
    fn missing_table_or_column_is_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let err = load(dir.path(), (140.0, 150.0)).expect_err("no tables").to_string();
        assert!(err.contains("frame_example.parquet"), "{err}");
        let (frame, _, _) = frame_example();
        write_table(dir.path(), "frame_example", frame);
        write_table(dir.path(), "mosaic", mosaic(&corner_path()).drop("temp_c").expect("drops"));
        let err = load(dir.path(), (140.0, 150.0)).expect_err("no temp_c").to_string();
        assert!(err.contains("mosaic.parquet") && err.contains("temp_c"), "{err}");
    }

    #[test]
    fn draws_frame_detections_and_mosaic() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_monitor(dir.path());
        write_table(dir.path(), "path", path_table(&corner_path()));
        let mut data = load(dir.path(), (140.0, 150.0)).expect("loads");
        data.polygon = load_polygon(dir.path()).expect("loads");
        assert_eq!(data.frame.len(), 160 * 120);
        assert_eq!(data.detections.iter().filter(|d| d.vertex.is_none()).count(), 1);
        assert!(!band_outline(&data.frame, data.band_c).is_empty());
        let stem = dir.path().join("thermal_frame");
        let title = "Synthetic frame and mosaic (cf. paper 003 Fig. 4)";
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, title, &data), |a| draw(a, title, &data)).expect("draws");
        assert_drawn(&stem);
    }
}
