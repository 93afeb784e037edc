//! `figure.fdm_pressure_advance`: what `fdm.pressure_advance` fitted, as a reader checks
//! it. Top: one panel per line of the pattern, ordered by its pressure advance K, the
//! widths measured on the first photo (blue) against the lag model's under the print's τ
//! (black); the panel of the recommended K is framed red, the flattest printed line's
//! green. Bottom: each line's measured unevenness (RMS of width over median − 1) against
//! its K, with τ's and the recommendation's 95 % intervals as bands.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::params::NoParams;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{pressure_advance as fits_t, pressure_advance_lines as lines_t, pressure_advance_widths as widths_t};

use crate::read::{f64s, ints, read_parquet, strs};
use crate::style::{draw_png_and_svg, house_mesh, text, PALETTE};

/// The `figure.fdm_pressure_advance` stage kind.
pub struct PressureAdvanceFigure;

/// The fit and its widths.
const FIT: Input = Input::one(
    "fit",
    &[Source::Stage("fdm.pressure_advance")],
    "the lag and pressure advance fitted to a print's photos",
)
.reading(&[
    Reads {
        table: &fits_t::TABLE,
        columns: &[
            fits_t::print,
            fits_t::subset,
            fits_t::tau_s,
            fits_t::tau_ci_lo_s,
            fits_t::tau_ci_hi_s,
            fits_t::recommended_pa_s,
            fits_t::pa_ci_lo_s,
            fits_t::pa_ci_hi_s,
            fits_t::flattest_line_pa_s,
        ],
    },
    Reads { table: &lines_t::TABLE, columns: &[lines_t::subset, lines_t::pressure_advance_s, lines_t::width_spread] },
    Reads {
        table: &widths_t::TABLE,
        columns: &[
            widths_t::photo_id,
            widths_t::line,
            widths_t::pressure_advance_s,
            widths_t::position_mm,
            widths_t::width_mm,
            widths_t::predicted_mm,
        ],
    },
]);

/// The subset of the fit over every photo (as the stage writes it).
const ALL_PHOTOS: &str = "all";
/// Panels per row of the line grid.
const COLUMNS: usize = 7;
const MEASURED: RGBColor = PALETTE[0];
const RECOMMENDED: RGBColor = RGBColor(214, 39, 40);
const FLATTEST: RGBColor = RGBColor(44, 160, 44);
const TAU: RGBColor = RGBColor(120, 120, 120);

impl Stage for PressureAdvanceFigure {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_pressure_advance",
        version: 1,
        summary: "Each line's measured vs modelled width ordered by its pressure advance, and the lines' unevenness against K with τ and the recommended K → pressure_advance.png/.svg",
        implements: "paper 000's lag (Sec. IV) with pressure advance, fitted to a photographed pattern",
        inputs: &[FIT],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let dir = ctx.input(&FIT).dir.clone();
        let fit = Fit::read(&dir.join(fits_t::TABLE.file()))?;
        let spreads = read_spreads(&dir.join(lines_t::TABLE.file()))?;
        let panels = read_panels(&dir.join(widths_t::TABLE.file()))?;
        let stem = ctx.output_path("pressure_advance")?;
        let rows = panels.len().div_ceil(COLUMNS).max(1);
        let size = (1600, 260 * rows as u32 + 520);
        let figure = Figure { fit, spreads, panels };
        draw_png_and_svg(&stem, size, |a| figure.draw(a), |a| figure.draw(a))
    }
}

/// The `all` row of `pressure_advance`.
struct Fit {
    print: String,
    tau: [f64; 3],
    pa: [f64; 3],
    flattest: f64,
}

impl Fit {
    fn read(path: &Path) -> Result<Self, StageError> {
        let df = read_parquet(path)?;
        let subsets = strs(&df, fits_t::subset, path)?;
        let row = subsets.iter().position(|s| s == ALL_PHOTOS).ok_or_else(|| StageError::BadInput {
            file: path.to_path_buf(),
            location: Some(fits_t::subset.into()),
            expected: format!("a row with subset `{ALL_PHOTOS}`"),
        })?;
        let at = |c: &str| -> Result<f64, StageError> { Ok(f64s(&df, c, path)?[row]) };
        Ok(Self {
            print: strs(&df, fits_t::print, path)?[row].clone(),
            tau: [at(fits_t::tau_s)?, at(fits_t::tau_ci_lo_s)?, at(fits_t::tau_ci_hi_s)?],
            pa: [at(fits_t::recommended_pa_s)?, at(fits_t::pa_ci_lo_s)?, at(fits_t::pa_ci_hi_s)?],
            flattest: at(fits_t::flattest_line_pa_s)?,
        })
    }
}

/// (K, spread) of every line of the `all` fit.
fn read_spreads(path: &Path) -> Result<Vec<(f64, f64)>, StageError> {
    let df = read_parquet(path)?;
    let subsets = strs(&df, lines_t::subset, path)?;
    let (k, spread) = (f64s(&df, lines_t::pressure_advance_s, path)?, f64s(&df, lines_t::width_spread, path)?);
    Ok((0..df.height()).filter(|&i| subsets[i] == ALL_PHOTOS).map(|i| (k[i], spread[i])).collect())
}

/// One line's panel: its K and (position, measured, modelled) on the first photo.
struct Panel {
    advance_s: f64,
    points: Vec<(f64, f64, f64)>,
}

fn read_panels(path: &Path) -> Result<Vec<Panel>, StageError> {
    let df = read_parquet(path)?;
    let photos = strs(&df, widths_t::photo_id, path)?;
    let lines = ints(&df, widths_t::line, path)?;
    let k = f64s(&df, widths_t::pressure_advance_s, path)?;
    let (x, w, m) = (
        f64s(&df, widths_t::position_mm, path)?,
        f64s(&df, widths_t::width_mm, path)?,
        f64s(&df, widths_t::predicted_mm, path)?,
    );
    let first = photos.first().cloned().unwrap_or_default();
    let mut by_line: BTreeMap<i64, Panel> = BTreeMap::new();
    for i in (0..df.height()).filter(|&i| photos[i] == first) {
        let panel = by_line.entry(lines[i]).or_insert_with(|| Panel { advance_s: k[i], points: Vec::new() });
        panel.points.push((x[i], w[i], m[i]));
    }
    let mut panels: Vec<Panel> = by_line.into_values().collect();
    panels.sort_by(|a, b| a.advance_s.total_cmp(&b.advance_s));
    Ok(panels)
}

struct Figure {
    fit: Fit,
    spreads: Vec<(f64, f64)>,
    panels: Vec<Panel>,
}

impl Figure {
    fn draw<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let [tau, tau_lo, tau_hi] = self.fit.tau;
        let [pa, pa_lo, pa_hi] = self.fit.pa;
        let title = format!(
            "{}: τ = {:.4} s ({:.4}–{:.4}), recommended K = {:.4} s ({:.4}–{:.4}), flattest printed line K = {:.3} s",
            self.fit.print, tau, tau_lo, tau_hi, pa, pa_lo, pa_hi, self.fit.flattest
        );
        let area = area.margin(10, 10, 10, 10).titled(&title, text(24.0)).map_err(|e| e.to_string())?;
        let key = "blue: width measured on the first photo · black: the lag model under τ and the line's K · red frame: the recommended K · green frame: the flattest printed line";
        area.draw_text(key, &text(16.0), (8, 0)).map_err(|e| e.to_string())?;
        let area = area.margin(24, 0, 0, 0);
        let (grid, bottom) = area.split_vertically(area.dim_in_pixel().1 as i32 - 470);
        self.draw_lines(&grid).map_err(|e| e.to_string())?;
        self.draw_spreads(&bottom).map_err(|e| e.to_string())
    }

    fn draw_lines<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let rows = self.panels.len().div_ceil(COLUMNS).max(1);
        let cells = area.split_evenly((rows, COLUMNS));
        let y_max =
            self.panels.iter().flat_map(|p| p.points.iter().map(|q| q.1.max(q.2))).fold(0.0_f64, f64::max) * 1.05;
        let nearest = |k: f64| {
            self.panels
                .iter()
                .enumerate()
                .min_by(|a, b| (a.1.advance_s - k).abs().total_cmp(&(b.1.advance_s - k).abs()))
                .map(|(i, _)| i)
        };
        let (recommended, flattest) = (nearest(self.fit.pa[0]), nearest(self.fit.flattest));
        for (i, (panel, cell)) in self.panels.iter().zip(&cells).enumerate() {
            let frame = if Some(i) == recommended {
                Some(RECOMMENDED)
            } else if Some(i) == flattest {
                Some(FLATTEST)
            } else {
                None
            };
            draw_panel(cell, panel, y_max.max(0.1), frame)?;
        }
        Ok(())
    }

    fn draw_spreads<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let k_max = self.spreads.iter().map(|s| s.0).fold(self.fit.pa[2].max(self.fit.tau[2]), f64::max) * 1.05;
        let s_max = self.spreads.iter().map(|s| s.1).filter(|s| s.is_finite()).fold(0.0_f64, f64::max) * 1.1;
        let mut chart = ChartBuilder::on(area)
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..k_max.max(1e-3), 0.0..s_max.max(1e-3))?;
        house_mesh(&mut chart)
            .x_desc("pressure advance K of the printed line (s)")
            .y_desc("measured unevenness (RMS of width/median − 1)")
            .x_label_formatter(&|x| format!("{x:.3}"))
            .y_label_formatter(&|y| format!("{y:.2}"))
            .draw()?;
        let band =
            |lo: f64, hi: f64, color: RGBColor| Rectangle::new([(lo, 0.0), (hi, s_max)], color.mix(0.18).filled());
        chart
            .draw_series([band(self.fit.tau[1], self.fit.tau[2], TAU)])?
            .label("τ, 95 % interval")
            .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], TAU.mix(0.3).filled()));
        chart
            .draw_series([band(self.fit.pa[1], self.fit.pa[2], RECOMMENDED)])?
            .label("recommended K, 95 % interval")
            .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], RECOMMENDED.mix(0.3).filled()));
        chart
            .draw_series(LineSeries::new(self.spreads.iter().copied(), MEASURED.stroke_width(2)))?
            .label("each printed line, measured")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 16, y)], MEASURED.stroke_width(2)));
        chart.draw_series(self.spreads.iter().map(|&(k, s)| Circle::new((k, s), 4, MEASURED.filled())))?;
        chart
            .draw_series([Circle::new(
                (self.fit.flattest, self.spreads.iter().find(|s| s.0 == self.fit.flattest).map_or(0.0, |s| s.1)),
                8,
                FLATTEST.stroke_width(3),
            )])?
            .label("flattest printed line")
            .legend(|(x, y)| Circle::new((x + 8, y), 6, FLATTEST.stroke_width(3)));
        crate::style::draw_house_legend(&mut chart, SeriesLabelPosition::UpperLeft)
    }
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel,
    y_max: f64,
    frame: Option<RGBColor>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    if let Some(color) = frame {
        let (w, h) = area.dim_in_pixel();
        area.draw(&Rectangle::new([(1, 1), (w as i32 - 2, h as i32 - 2)], color.stroke_width(4)))?;
    }
    let x_max = panel.points.iter().map(|p| p.0).fold(1.0_f64, f64::max);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("K = {:.3} s", panel.advance_s), text(16.0))
        .margin(8)
        .x_label_area_size(24)
        .y_label_area_size(36)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max)?;
    house_mesh(&mut chart)
        .x_labels(4)
        .y_labels(4)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.1}"))
        .draw()?;
    chart.draw_series(LineSeries::new(panel.points.iter().map(|p| (p.0, p.1)), MEASURED.stroke_width(1)))?;
    chart.draw_series(LineSeries::new(panel.points.iter().map(|p| (p.0, p.2)), BLACK.stroke_width(1)))?;
    Ok(())
}
