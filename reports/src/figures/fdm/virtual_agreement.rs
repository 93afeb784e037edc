//! `figure.fdm_virtual_agreement`: every real line of one printer against the virtual
//! printer calibrated on the printer's other lines, one panel per condition (rows:
//! acceleration, columns: feed) as paper 000 Fig. 3(a): the measured widths, the
//! virtual mean profile and the 95 % band of virtual lines. Reads
//! `agreement.parquet` and `agreement_profiles.parquet` of an `fdm.virtual_agreement`
//! stage.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{agreement, agreement_profiles};

use crate::read::{f64s, no_rows, read_parquet, strs};
use crate::style::{draw_house_legend, draw_png_and_svg, text, PALETTE};

use super::draw_width_profile_mesh;
use crate::figures::common::distinct;

/// The `figure.fdm_virtual_agreement` stage kind.
pub struct VirtualAgreementFigure;

pipeline::params! {
    /// The parameters of `figure.fdm_virtual_agreement`.
    pub struct VirtualAgreementParams {
        /// Printer whose lines are drawn.
        pub printer: String,
    }
}

/// The agreement study drawn.
const AGREEMENT: Input = Input::one(
    "agreement",
    &[Source::Stage("fdm.virtual_agreement")],
    "the real and virtual profiles per line (`agreement.parquet`, `agreement_profiles.parquet`)",
)
.reading(&[
    Reads {
        table: &agreement::TABLE,
        columns: &[
            agreement::printer,
            agreement::condition,
            agreement::accel_mm_s2,
            agreement::feed_mm_s,
            agreement::rmse_mm,
            agreement::virtual_scatter_mm,
        ],
    },
    Reads {
        table: &agreement_profiles::TABLE,
        columns: &[
            agreement_profiles::printer,
            agreement_profiles::condition,
            agreement_profiles::position_mm,
            agreement_profiles::real_mm,
            agreement_profiles::virtual_mean_mm,
            agreement_profiles::virtual_lo_mm,
            agreement_profiles::virtual_hi_mm,
        ],
    },
]);

/// The profile columns drawn, in the order of a panel's rows.
const PROFILE_COLUMNS: [&str; 5] = [
    agreement_profiles::position_mm,
    agreement_profiles::real_mm,
    agreement_profiles::virtual_mean_mm,
    agreement_profiles::virtual_lo_mm,
    agreement_profiles::virtual_hi_mm,
];

/// Colour of the measured widths.
const MEASURED: RGBColor = RGBColor(70, 70, 70);

/// One condition's panel.
struct Panel {
    condition: String,
    accel_mm_s2: f64,
    feed_mm_s: f64,
    rmse_mm: f64,
    scatter_mm: f64,
    /// (position, real, virtual mean, virtual lo, virtual hi), mm.
    rows: Vec<[f64; 5]>,
}

impl Stage for VirtualAgreementFigure {
    type Params = VirtualAgreementParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_virtual_agreement",
        version: 1,
        summary: "Real lines vs the virtual printer calibrated on the other lines (mean and 95 % band), a panel per condition → virtual_agreement.png/.svg",
        implements: "DESIGN §5.1 (virtual printer calibrated to the real data), in the style of paper 000 Fig. 3(a)",
        inputs: &[AGREEMENT],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &VirtualAgreementParams) -> Result<(), StageError> {
        let printer = &p.printer;
        let panels = load(&ctx.input(&AGREEMENT).dir, printer)?;
        let title = format!("Real {printer} lines and the virtual {printer} calibrated without them");
        let stem = ctx.output_path("virtual_agreement")?;
        draw_png_and_svg(&stem, (1500, 1100), |a| draw(a, &title, &panels), |a| draw(a, &title, &panels))
    }
}

fn load(dir: &Path, printer: &str) -> Result<Vec<Panel>, StageError> {
    let path = dir.join(agreement::TABLE.file());
    let df = read_parquet(&path)?;
    let (printers, conditions) = (strs(&df, agreement::printer, &path)?, strs(&df, agreement::condition, &path)?);
    let (accel, feed) = (f64s(&df, agreement::accel_mm_s2, &path)?, f64s(&df, agreement::feed_mm_s, &path)?);
    let (rmse, scatter) = (f64s(&df, agreement::rmse_mm, &path)?, f64s(&df, agreement::virtual_scatter_mm, &path)?);
    let mut panels: Vec<Panel> = (0..df.height())
        .filter(|&i| printers[i] == printer)
        .map(|i| Panel {
            condition: conditions[i].clone(),
            accel_mm_s2: accel[i],
            feed_mm_s: feed[i],
            rmse_mm: rmse[i],
            scatter_mm: scatter[i],
            rows: Vec::new(),
        })
        .collect();
    if panels.is_empty() {
        return Err(no_rows(&path, agreement::printer, printer));
    }
    let path = dir.join(agreement_profiles::TABLE.file());
    let df = read_parquet(&path)?;
    let (printers, conditions) =
        (strs(&df, agreement_profiles::printer, &path)?, strs(&df, agreement_profiles::condition, &path)?);
    let columns = PROFILE_COLUMNS.map(|c| f64s(&df, c, &path)).into_iter().collect::<Result<Vec<_>, _>>()?;
    for i in (0..df.height()).filter(|&i| printers[i] == printer) {
        if let Some(p) = panels.iter_mut().find(|p| p.condition == conditions[i]) {
            p.rows.push([columns[0][i], columns[1][i], columns[2][i], columns[3][i], columns[4][i]]);
        }
    }
    Ok(panels)
}

fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, panels: &[Panel]) -> Result<(), String> {
    let area = area.margin(14, 6, 6, 18).titled(title, text(28.0)).map_err(|e| e.to_string())?;
    let accels = distinct(panels.iter().map(|p| p.accel_mm_s2));
    let feeds = distinct(panels.iter().map(|p| p.feed_mm_s));
    let areas = area.split_evenly((accels.len(), feeds.len()));
    let y_max = panels.iter().flat_map(|p| p.rows.iter().map(|r| r[1].max(r[4]))).fold(0.0_f64, f64::max) * 1.05;
    for (k, p) in panels.iter().enumerate() {
        let row = accels.iter().position(|a| *a == p.accel_mm_s2).expect("collected");
        let col = feeds.iter().position(|f| *f == p.feed_mm_s).expect("collected");
        draw_panel(&areas[row * feeds.len() + col], p, y_max, k == 0).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &Panel,
    y_max: f64,
    legend: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let x_max = p.rows.last().map_or(120.0, |r| r[0]);
    let caption = format!(
        "a = {} mm/s², F = {} mm/s: RMSE {:.3} mm (virtual scatter {:.3})",
        p.accel_mm_s2, p.feed_mm_s, p.rmse_mm, p.scatter_mm
    );
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(16.0))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(52)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max)?;
    draw_width_profile_mesh(&mut chart)?;
    let band: Vec<(f64, f64)> =
        p.rows.iter().map(|r| (r[0], r[4])).chain(p.rows.iter().rev().map(|r| (r[0], r[3]))).collect();
    chart
        .draw_series(std::iter::once(Polygon::new(band, PALETTE[0].mix(0.22).filled())))?
        .label("virtual: 95 % of lines")
        .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], PALETTE[0].mix(0.22).filled()));
    chart
        .draw_series(LineSeries::new(p.rows.iter().map(|r| (r[0], r[1])), MEASURED.stroke_width(1)))?
        .label("measured")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], MEASURED.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(p.rows.iter().map(|r| (r[0], r[2])), PALETTE[0].stroke_width(2)))?
        .label("virtual: mean")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], PALETTE[0].stroke_width(2)));
    if legend {
        draw_house_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}
