//! `figure.inkjet_height_maps`: the printed part of two ink-jet prints, open loop and
//! closed loop, in the style of paper 002 (Lu, Zheng, Mishra 2015) Figs 11-12: aerial
//! views (here heat maps of the final height on a shared colour scale, cells without
//! material in light grey) and a side view
//! (the cross-section through the middle row of the grid, with the desired height).
//! Reads `height_map.parquet` and `summary.parquet` of two `inkjet.print_experiment`
//! stages, the open-loop print first.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::inkjet::{height_map, summary};

use crate::figures::common::viridis;
use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_png_and_svg, house_mesh, text, PALETTE};

/// The `figure.inkjet_height_maps` stage kind.
pub struct InkjetHeightMapsFigure;

/// Figure size in pixels.
const SIZE_PX: (u32, u32) = (1400, 900);
/// Width of the shared colour bar strip at the right of the aerial views, in pixels.
const COLOUR_BAR_PX: u32 = 120;
/// Height of the top row (aerial views) as a fraction of the area below the title.
const TOP_ROW_FRACTION: f64 = 0.58;
/// Colour of cells without material (height ≤ 0), so the part's outline stands out.
const NO_MATERIAL: RGBColor = RGBColor(225, 225, 225);

pipeline::params! {
    /// The parameters of `figure.inkjet_height_maps`.
    pub struct HeightMapsParams {
        /// Figure title (default: a generic description).
        pub title: String = "",
        /// Desired part height (µm), drawn as a dashed line in the side view (paper 002: 400 µm).
        pub desired_height_um: f64 [0.0, 10_000.0],
    }
}

/// What the figure reads of each print.
const PRINT_READS: &[Reads] = &[
    Reads {
        table: &height_map::TABLE,
        columns: &[height_map::x_index, height_map::y_index, height_map::x_um, height_map::y_um, height_map::height_um],
    },
    Reads {
        table: &summary::TABLE,
        columns: &[summary::controller, summary::layers, summary::mean_err_um, summary::std_um],
    },
];

/// The open-loop print (drawn first).
const OPEN_LOOP: Input = Input::one(
    "open_loop",
    &[Source::Stage("inkjet.print_experiment")],
    "the open-loop print (`height_map.parquet`, `summary.parquet`)",
)
.reading(PRINT_READS);

/// The closed-loop print.
const CLOSED_LOOP: Input = Input::one(
    "closed_loop",
    &[Source::Stage("inkjet.print_experiment")],
    "the closed-loop print (`height_map.parquet`, `summary.parquet`)",
)
.reading(PRINT_READS);

/// One grid cell of a height map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// Column index of the cell.
    pub x_index: i64,
    /// Row index of the cell.
    pub y_index: i64,
    /// Cell centre along x (µm).
    pub x_um: f64,
    /// Cell centre along y (µm).
    pub y_um: f64,
    /// Final height of the cell (µm).
    pub height_um: f64,
}

/// One print: its final height map and its summary.
#[derive(Debug, Clone)]
pub struct Print {
    /// Controller name (`open_loop`, `closed_loop`).
    pub controller: String,
    /// Number of layers printed.
    pub layers: i64,
    /// Mean error of the top surface against the desired height (µm).
    pub mean_err_um: f64,
    /// Standard deviation of the top surface (µm).
    pub std_um: f64,
    /// Every grid cell.
    pub cells: Vec<Cell>,
}

impl Print {
    /// The panel title: controller, layers, mean error and std.
    pub fn caption(&self) -> String {
        format!(
            "{}: {} layers, mean error {:.1} µm, std {:.1} µm",
            self.controller.replace('_', " "),
            self.layers,
            self.mean_err_um,
            self.std_um
        )
    }

    fn max_height_um(&self) -> f64 {
        self.cells.iter().map(|c| c.height_um).filter(|h| h.is_finite()).fold(0.0, f64::max)
    }
}

impl Stage for InkjetHeightMapsFigure {
    type Params = HeightMapsParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.inkjet_height_maps",
        version: 1,
        summary: "Aerial heat maps (shared scale) and middle-row cross-section of an open-loop and a closed-loop ink-jet print → inkjet_height_maps.png/.svg",
        implements: "paper 002 Figs 11-12 (aerial and side views)",
        inputs: &[OPEN_LOOP, CLOSED_LOOP],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &HeightMapsParams) -> Result<(), StageError> {
        let prints = [load(&ctx.input(&OPEN_LOOP).dir)?, load(&ctx.input(&CLOSED_LOOP).dir)?];
        let desired = p.desired_height_um;
        let title = crate::figures::common::title_or(&p.title, || {
            "Printed part: aerial views and middle-row side view, open vs closed loop".to_string()
        });
        let stem = ctx.output_path("inkjet_height_maps")?;
        draw_png_and_svg(
            &stem,
            SIZE_PX,
            |a| draw_titled(a, &title, &prints, desired),
            |a| draw_titled(a, &title, &prints, desired),
        )
    }
}

/// Reads one print from `<dir>/height_map.parquet` and `<dir>/summary.parquet`.
pub fn load(dir: &Path) -> Result<Print, StageError> {
    let path = dir.join(height_map::TABLE.file());
    let df = read_parquet(&path)?;
    let (xi, yi) = (ints(&df, height_map::x_index, &path)?, ints(&df, height_map::y_index, &path)?);
    let (x, y, h) = (
        f64s(&df, height_map::x_um, &path)?,
        f64s(&df, height_map::y_um, &path)?,
        f64s(&df, height_map::height_um, &path)?,
    );
    let cells: Vec<Cell> = (0..df.height())
        .map(|i| Cell { x_index: xi[i], y_index: yi[i], x_um: x[i], y_um: y[i], height_um: h[i] })
        .collect();
    if cells.is_empty() {
        return Err(no_rows(&path, height_map::height_um, "one row per grid cell"));
    }
    let path = dir.join(summary::TABLE.file());
    let df = read_parquet(&path)?;
    if df.height() == 0 {
        return Err(no_rows(&path, summary::controller, "one summary row"));
    }
    Ok(Print {
        controller: strs(&df, summary::controller, &path)?.swap_remove(0),
        layers: ints(&df, summary::layers, &path)?[0],
        mean_err_um: f64s(&df, summary::mean_err_um, &path)?[0],
        std_um: f64s(&df, summary::std_um, &path)?[0],
        cells,
    })
}

/// The middle row index of the grid: halfway between the smallest and largest
/// `y_index` (rounded down).
pub fn middle_row(cells: &[Cell]) -> i64 {
    let lo = cells.iter().map(|c| c.y_index).min().unwrap_or(0);
    let hi = cells.iter().map(|c| c.y_index).max().unwrap_or(0);
    lo + (hi - lo) / 2
}

/// The cross-section through row `y_index`: (x in mm, height in µm), sorted by x.
pub fn cross_section(cells: &[Cell], y_index: i64) -> Vec<(f64, f64)> {
    let mut row: Vec<(f64, f64)> =
        cells.iter().filter(|c| c.y_index == y_index).map(|c| (c.x_um / 1000.0, c.height_um)).collect();
    row.sort_by(|a, b| a.0.total_cmp(&b.0));
    row
}

/// The grid spacing of `values`: the smallest gap between distinct values (1 µm when
/// there is a single value).
fn spacing(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    let step = v.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 1e-9).fold(f64::INFINITY, f64::min);
    if step.is_finite() {
        step
    } else {
        1.0
    }
}

fn draw_titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    prints: &[Print; 2],
    desired_um: f64,
) -> Result<(), String> {
    let area = area.margin(12, 8, 8, 12).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    draw(&area, prints, desired_um)
}

/// Draws the two aerial views with a shared colour bar (top) and the middle-row
/// cross-section of both prints with the desired height (bottom).
pub fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    prints: &[Print; 2],
    desired_um: f64,
) -> Result<(), String> {
    let top_px = (area.dim_in_pixel().1 as f64 * TOP_ROW_FRACTION) as u32;
    let (top, bottom) = area.split_vertically(top_px);
    let (maps, bar) = top.split_horizontally(top.dim_in_pixel().0.saturating_sub(COLOUR_BAR_PX));
    let max_um = prints.iter().map(Print::max_height_um).fold(desired_um, f64::max).max(1e-6);
    let panels = maps.split_evenly((1, 2));
    for (panel, print) in panels.iter().zip(prints) {
        draw_aerial(panel, print, max_um).map_err(|e| e.to_string())?;
    }
    crate::figures::common::draw_viridis_bar(&bar, (0.0, max_um), "height (µm)", 0, 120).map_err(|e| e.to_string())?;
    draw_side_view(&bottom, prints, desired_um).map_err(|e| e.to_string())
}

fn draw_aerial<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    print: &Print,
    max_um: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let half_x = spacing(print.cells.iter().map(|c| c.x_um)) / 2000.0;
    let half_y = spacing(print.cells.iter().map(|c| c.y_um)) / 2000.0;
    let span = |pick: fn(&Cell) -> f64, half: f64| {
        let lo = print.cells.iter().map(pick).fold(f64::INFINITY, f64::min) / 1000.0;
        let hi = print.cells.iter().map(pick).fold(f64::NEG_INFINITY, f64::max) / 1000.0;
        (lo - half)..(hi + half)
    };
    let (xs, ys) = (span(|c| c.x_um, half_x), span(|c| c.y_um, half_y));
    // Keep the map square in millimetres: pad the shorter axis.
    let (xs, ys) = square_ranges(xs, ys);
    let area = area.titled(&print.caption(), text(18.0))?;
    // Square cells: pad the wider side of the plotting area.
    let (w, h) = area.dim_in_pixel();
    let (label_x_px, label_y_px, margin_px) = (44, 56, 8);
    let plot_w = w.saturating_sub(label_y_px + 3 * margin_px);
    let plot_h = h.saturating_sub(label_x_px + 2 * margin_px);
    let (pad_w, pad_h) = (plot_w.saturating_sub(plot_h) / 2, plot_h.saturating_sub(plot_w) / 2);
    let mut chart = ChartBuilder::on(&area)
        .margin_top(margin_px + pad_h)
        .margin_bottom(margin_px + pad_h)
        .margin_left(margin_px + pad_w)
        .margin_right(2 * margin_px + pad_w)
        .x_label_area_size(label_x_px)
        .y_label_area_size(label_y_px)
        .build_cartesian_2d(xs, ys)?;
    house_mesh(&mut chart)
        .disable_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .x_label_formatter(&|x| format!("{x:.1}"))
        .y_label_formatter(&|y| format!("{y:.1}"))
        .draw()?;
    let cell = |c: &Cell| {
        let (x, y) = (c.x_um / 1000.0, c.y_um / 1000.0);
        let colour = if c.height_um > 0.0 { viridis(c.height_um / max_um) } else { NO_MATERIAL };
        Rectangle::new([(x - half_x, y - half_y), (x + half_x, y + half_y)], colour.filled())
    };
    chart.draw_series(print.cells.iter().map(cell))?;
    Ok(())
}

/// Widens the shorter of two ranges about its centre so both have the same length.
fn square_ranges(xs: std::ops::Range<f64>, ys: std::ops::Range<f64>) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let (wx, wy) = (xs.end - xs.start, ys.end - ys.start);
    let widen = |r: std::ops::Range<f64>, w: f64| {
        let c = (r.start + r.end) / 2.0;
        (c - w / 2.0)..(c + w / 2.0)
    };
    let w = wx.max(wy);
    (widen(xs, w), widen(ys, w))
}

fn draw_side_view<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    prints: &[Print; 2],
    desired_um: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let row = middle_row(&prints[0].cells);
    let sections: Vec<Vec<(f64, f64)>> = prints.iter().map(|p| cross_section(&p.cells, row)).collect();
    let all = || sections.iter().flatten();
    let x_lo = all().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let x_hi = all().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let (x_lo, x_hi) = if x_hi > x_lo { (x_lo, x_hi) } else { (0.0, 1.0) };
    let y_hi = all().map(|p| p.1).fold(desired_um, f64::max).max(1e-6) * 1.15;
    let y_mm = prints[0].cells.iter().find(|c| c.y_index == row).map_or(f64::NAN, |c| c.y_um / 1000.0);
    let caption = format!("Side view: cross-section through the middle row (y index {row}, y = {y_mm:.2} mm)");
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(18.0))
        .margin(8)
        .margin_right(20)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(x_lo..x_hi, 0.0..y_hi)?;
    house_mesh(&mut chart)
        .x_desc("x (mm)")
        .y_desc("height (µm)")
        .x_label_formatter(&|x| format!("{x:.1}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()?;
    for (k, (print, section)) in prints.iter().zip(&sections).enumerate() {
        let colour = PALETTE[k];
        chart
            .draw_series(LineSeries::new(section.iter().copied(), colour.stroke_width(3)))?
            .label(print.controller.replace('_', " "))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], colour.stroke_width(3)));
    }
    let dashed = DashedLineSeries::new([(x_lo, desired_um), (x_hi, desired_um)], 8, 5, BLACK.stroke_width(2));
    chart
        .draw_series(dashed)?
        .label(format!("desired height {desired_um:.0} µm"))
        .legend(|(x, y)| PathElement::new([(x, y), (x + 24, y)], BLACK.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerMiddle)
        .label_font(text(15.0))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, declared, noise, write_declared};
    use polars::df;
    use polars::prelude::DataFrame;

    const N: i64 = 20;
    const PITCH_UM: f64 = 250.0;

    /// A 20 × 20 cylinder-like part: a dome (open loop) or a flat top with noise
    /// (closed loop) inside a circle, zero outside.
    fn height_map(dome_um: f64, noise_um: f64) -> DataFrame {
        let (mut xi, mut yi, mut x, mut y, mut h) = (vec![], vec![], vec![], vec![], vec![]);
        let c = (N - 1) as f64 / 2.0;
        for j in 0..N {
            for i in 0..N {
                let r = ((i as f64 - c).powi(2) + (j as f64 - c).powi(2)).sqrt() / (c + 0.5);
                let height = if r <= 1.0 {
                    400.0 + dome_um * (1.0 - r * r) + noise_um * noise((j * N + i) as usize)
                } else {
                    0.0
                };
                xi.push(i);
                yi.push(j);
                x.push(i as f64 * PITCH_UM);
                y.push(j as f64 * PITCH_UM);
                h.push(height);
            }
        }
        df!(height_map::x_index => xi, height_map::y_index => yi, height_map::x_um => x, height_map::y_um => y, height_map::height_um => h).expect("frame")
    }

    fn summary(controller: &str, layers: i64, mean_err: f64, std: f64) -> DataFrame {
        df!(
            summary::scenario => ["cylinder"], summary::controller => [controller], summary::variation_pct => [20.0],
            summary::layers => [layers], summary::mean_err_um => [mean_err], summary::std_um => [std], summary::rmsd_um => [std],
            summary::avg_height_um => [400.0 + mean_err]
        )
        .expect("frame")
    }

    fn write_print(dir: &Path, controller: &str, dome_um: f64, noise_um: f64) {
        write_declared(dir, &height_map::TABLE, declared(&height_map::TABLE, height_map(dome_um, noise_um)));
        write_declared(
            dir,
            &summary::TABLE,
            declared(&summary::TABLE, summary(controller, 53, dome_um / 2.0, noise_um / 3.0)),
        );
    }

    #[test]
    fn middle_row_cross_section_is_sorted_and_in_mm() {
        let cell = |x_index, y_index, height_um| Cell {
            x_index,
            y_index,
            x_um: x_index as f64 * 100.0,
            y_um: y_index as f64 * 100.0,
            height_um,
        };
        let cells: Vec<Cell> =
            (0..5).flat_map(|j| (0..3).rev().map(move |i| cell(i, j, (10 * j + i) as f64))).collect();
        assert_eq!(middle_row(&cells), 2);
        assert_eq!(cross_section(&cells, 2), vec![(0.0, 20.0), (0.1, 21.0), (0.2, 22.0)]);
        // An even number of rows: the lower of the two middle rows.
        let even: Vec<Cell> = cells.iter().copied().filter(|c| c.y_index < 4).collect();
        assert_eq!(middle_row(&even), 1);
        assert!(cross_section(&cells, 9).is_empty());
    }

    #[test]
    fn loads_and_draws_open_and_closed_loop() {
        let (open, closed, out) = (
            tempfile::tempdir().expect("tempdir"),
            tempfile::tempdir().expect("tempdir"),
            tempfile::tempdir().expect("tempdir"),
        );
        write_print(open.path(), "open_loop", 90.0, 12.0);
        write_print(closed.path(), "closed_loop", 0.0, 9.0);
        let prints = [load(open.path()).expect("loads"), load(closed.path()).expect("loads")];
        assert_eq!(prints[0].cells.len(), (N * N) as usize);
        assert_eq!(prints[0].caption(), "open loop: 53 layers, mean error 45.0 µm, std 4.0 µm");
        let section = cross_section(&prints[0].cells, middle_row(&prints[0].cells));
        assert_eq!(section.len(), N as usize);
        assert!(section[N as usize / 2].1 > 450.0, "the dome peaks in the middle");
        let stem = out.path().join("inkjet_height_maps");
        let title = "Synthetic cylinder, h_d = 400 µm (cf. paper 002 Fig. 11)";
        draw_png_and_svg(
            &stem,
            SIZE_PX,
            |a| draw_titled(a, title, &prints, 400.0),
            |a| draw_titled(a, title, &prints, 400.0),
        )
        .expect("draws");
        assert_drawn(&stem);
    }
}
