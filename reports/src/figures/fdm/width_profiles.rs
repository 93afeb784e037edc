//! `figure.fdm_width_profiles`: measured line width against position for every line
//! of one printer, one panel per condition (rows: acceleration, columns: feed), in the
//! style of paper 000 Fig. 3(a). Reads `widths.parquet` of an `fdm.import` stage and
//! marks each line's steady width from `line_summary.parquet` when that is an input.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{line_summary, widths};

use crate::read::{f64s, read_parquet, strs};
use crate::style::{draw_png_and_svg, text, PALETTE};

use super::draw_width_profile_mesh;
use crate::figures::common::distinct;

/// The `figure.fdm_width_profiles` stage kind.
pub struct WidthProfilesFigure;

pipeline::params! {
    /// The parameters of `figure.fdm_width_profiles`.
    pub struct WidthProfilesParams {
        /// Printer whose lines are drawn.
        pub printer: String,
        /// Figure title (default: the printer name).
        pub title: String = "",
    }
}

/// The measured widths: `widths.parquet` of an `fdm.import` stage (an `fdm-widths`
/// dataset folder holds no such table).
const WIDTHS: Input =
    Input::one("widths", &[Source::Stage("fdm.import")], "every line's measured widths (`widths.parquet`)").reading(&[
        Reads {
            table: &widths::TABLE,
            columns: &[
                widths::printer,
                widths::condition,
                widths::accel_mm_s2,
                widths::feed_mm_s,
                widths::position_mm,
                widths::width_mm,
            ],
        },
    ]);

/// The steady widths, when given.
const SUMMARY: Input = Input::optional(
    "summary",
    &[Source::Stage("fdm.line_summary")],
    "each line's steady width (`line_summary.parquet`), marked dashed",
)
.reading(&[Reads {
    table: &line_summary::TABLE,
    columns: &[line_summary::printer, line_summary::condition, line_summary::steady_width_mm],
}]);

/// One line's profile.
struct Profile {
    accel_mm_s2: f64,
    feed_mm_s: f64,
    points: Vec<(f64, f64)>,
    steady_width_mm: Option<f64>,
}

impl Stage for WidthProfilesFigure {
    type Params = WidthProfilesParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_width_profiles",
        version: 1,
        summary:
            "Width vs position of every line of one printer, a panel per (acceleration, feed) → width_profiles.png/.svg",
        implements: "paper 000 Fig. 3(a)",
        inputs: &[WIDTHS, SUMMARY],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &WidthProfilesParams) -> Result<(), StageError> {
        let printer = &p.printer;
        let mut profiles = read_profiles(&ctx.input(&WIDTHS).dir.join(widths::TABLE.file()), printer)?;
        if let Some(summary) = ctx.optional_input(&SUMMARY) {
            add_steady_widths(&summary.dir.join(line_summary::TABLE.file()), printer, &mut profiles)?;
        }
        let title =
            crate::figures::common::title_or(&p.title, || format!("Measured line width along the line: {printer}"));
        let stem = ctx.output_path("width_profiles")?;
        let profiles: Vec<Profile> = profiles.into_values().collect();
        draw_png_and_svg(&stem, (1500, 1050), |a| draw(a, &title, &profiles), |a| draw(a, &title, &profiles))
    }
}

fn read_profiles(path: &Path, printer: &str) -> Result<BTreeMap<String, Profile>, StageError> {
    use widths as t;
    let df = read_parquet(path)?;
    let (printers, conditions) = (strs(&df, t::printer, path)?, strs(&df, t::condition, path)?);
    let (accel, feed) = (f64s(&df, t::accel_mm_s2, path)?, f64s(&df, t::feed_mm_s, path)?);
    let (pos, width) = (f64s(&df, t::position_mm, path)?, f64s(&df, t::width_mm, path)?);
    let mut profiles: BTreeMap<String, Profile> = BTreeMap::new();
    for i in (0..df.height()).filter(|i| printers[*i] == printer) {
        profiles
            .entry(conditions[i].clone())
            .or_insert_with(|| Profile {
                accel_mm_s2: accel[i],
                feed_mm_s: feed[i],
                points: Vec::new(),
                steady_width_mm: None,
            })
            .points
            .push((pos[i], width[i]));
    }
    if profiles.is_empty() {
        return Err(StageError::BadInput {
            file: path.to_path_buf(),
            location: Some(t::printer.into()),
            expected: format!("expected rows of printer `{printer}`"),
        });
    }
    Ok(profiles)
}

fn add_steady_widths(path: &Path, printer: &str, profiles: &mut BTreeMap<String, Profile>) -> Result<(), StageError> {
    use line_summary as t;
    let df = read_parquet(path)?;
    let (printers, conditions) = (strs(&df, t::printer, path)?, strs(&df, t::condition, path)?);
    let steady = f64s(&df, t::steady_width_mm, path)?;
    for i in (0..df.height()).filter(|i| printers[*i] == printer) {
        if let Some(p) = profiles.get_mut(&conditions[i]) {
            p.steady_width_mm = Some(steady[i]);
        }
    }
    Ok(())
}

fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, profiles: &[Profile]) -> Result<(), String> {
    let area = area.margin(14, 6, 6, 18).titled(title, text(28.0)).map_err(|e| e.to_string())?;
    let accels = distinct(profiles.iter().map(|p| p.accel_mm_s2));
    let feeds = distinct(profiles.iter().map(|p| p.feed_mm_s));
    let panels = area.split_evenly((accels.len(), feeds.len()));
    let y_max = profiles.iter().flat_map(|p| p.points.iter().map(|q| q.1)).fold(0.0_f64, f64::max) * 1.05;
    for p in profiles {
        let row = accels.iter().position(|a| *a == p.accel_mm_s2).expect("collected");
        let col = feeds.iter().position(|f| *f == p.feed_mm_s).expect("collected");
        draw_panel(&panels[row * feeds.len() + col], p, y_max, PALETTE[col]).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &Profile,
    y_max: f64,
    color: RGBColor,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let x_max = p.points.last().map_or(120.0, |q| q.0);
    let caption = format!("a = {} mm/s², F = {} mm/s", p.accel_mm_s2, p.feed_mm_s);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(19.0))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(52)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max)?;
    draw_width_profile_mesh(&mut chart)?;
    chart.draw_series(LineSeries::new(p.points.iter().copied(), color.stroke_width(2)))?;
    if let Some(steady) = p.steady_width_mm {
        let dashed = DashedLineSeries::new([(0.0, steady), (x_max, steady)], 6, 4, BLACK.stroke_width(1));
        chart.draw_series(dashed)?.label(format!("steady {steady:.3} mm"));
    }
    Ok(())
}
