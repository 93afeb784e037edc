//! Figure stage kinds: each reads published tables of its input stages and draws one
//! figure as PNG and SVG, in the style of the paper it reproduces.

mod discrepancy;
mod infill;
mod inkjet_height_maps;
mod inkjet_model_vs_scan;
mod inkjet_pipe_junction;
mod loo_predictions;
mod power_by_effect;
mod r_surface;
mod segment_accuracy;
#[cfg(test)]
pub(crate) mod test_util;
mod thermal_common;
mod thermal_contour_error;
mod thermal_corners;
mod thermal_directions;
mod thermal_frame;
mod thermal_overdeposition;
#[cfg(test)]
pub(crate) mod thermal_test_data;
mod transfer_cv;
pub(crate) mod transfer_matrix;
mod virtual_agreement;
mod width_profiles;

pub use discrepancy::{DiscoveryPowerFigure, DiscrepancyLinesFigure, DiscrepancyResidualsFigure};
pub use infill::InfillFigure;
pub use inkjet_height_maps::InkjetHeightMapsFigure;
pub use inkjet_model_vs_scan::InkjetModelVsScanFigure;
pub use inkjet_pipe_junction::InkjetPipeJunctionFigure;
pub use loo_predictions::LooPredictionsFigure;
pub use power_by_effect::DiscoveryPowerByEffectFigure;
pub use r_surface::RSurfaceFigure;
pub use segment_accuracy::SegmentAccuracyFigure;
pub use thermal_contour_error::ThermalContourErrorFigure;
pub use thermal_corners::ThermalCornersFigure;
pub use thermal_directions::ThermalDirectionsFigure;
pub use thermal_frame::ThermalFrameFigure;
pub use thermal_overdeposition::ThermalOverdepositionFigure;
pub use transfer_cv::TransferCvFigure;
pub use transfer_matrix::TransferMatrixFigure;
pub use virtual_agreement::VirtualAgreementFigure;
pub use width_profiles::WidthProfilesFigure;

use pipeline::params::ParamDefault;
use pipeline::{ParamSpec, ParamType, Registry};
use plotters::coord::cartesian::Cartesian2d;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::{ChartContext, DrawingAreaErrorKind, DrawingBackend};

use crate::style::house_mesh;

/// Registers every figure kind.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(WidthProfilesFigure));
    registry.register(Box::new(LooPredictionsFigure));
    registry.register(Box::new(DiscoveryPowerByEffectFigure));
    registry.register(Box::new(RSurfaceFigure));
    registry.register(Box::new(TransferCvFigure));
    registry.register(Box::new(TransferMatrixFigure));
    registry.register(Box::new(InfillFigure));
    registry.register(Box::new(InkjetHeightMapsFigure));
    registry.register(Box::new(ThermalDirectionsFigure));
    registry.register(Box::new(ThermalFrameFigure));
    registry.register(Box::new(ThermalCornersFigure));
    registry.register(Box::new(ThermalOverdepositionFigure));
    registry.register(Box::new(ThermalContourErrorFigure));
    registry.register(Box::new(InkjetModelVsScanFigure));
    registry.register(Box::new(InkjetPipeJunctionFigure));
    registry.register(Box::new(DiscrepancyResidualsFigure));
    registry.register(Box::new(DiscrepancyLinesFigure));
    registry.register(Box::new(DiscoveryPowerFigure));
    registry.register(Box::new(VirtualAgreementFigure));
    registry.register(Box::new(SegmentAccuracyFigure));
}

/// The `title` parameter of a figure whose default title is a fixed description.
const TITLE: ParamSpec = ParamSpec {
    name: "title",
    ty: ParamType::Text,
    default: ParamDefault::Str(""),
    doc: "Figure title (default: a generic description).",
};

/// The figure's `title` parameter, or `default()` when the spec leaves it empty.
fn title_or(ctx: &pipeline::StageContext, default: impl FnOnce() -> String) -> String {
    match ctx.params.str("title") {
        "" => default(),
        title => title.to_string(),
    }
}

/// The axes of a line-width profile (paper 000 Figs 3, 6): position along the line
/// (mm, whole numbers) against width (mm, one decimal).
fn draw_width_profile_mesh<DB: DrawingBackend>(
    chart: &mut ChartContext<DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    house_mesh(chart)
        .x_desc("position along the line (mm)")
        .y_desc("width (mm)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.1}"))
        .draw()
}

/// The distinct values, ascending (the rows and columns of a panel grid).
pub(crate) fn distinct(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// A vertical viridis colour bar for `lo..hi` in `bands` equal bands (band k has
/// viridis(k / (bands − 1)), as the heat maps colour their cells), labelled `desc`
/// with `decimals` decimals. The one colour bar of every heat-map figure.
pub(crate) fn draw_viridis_bar<DB: DrawingBackend>(
    area: &plotters::drawing::DrawingArea<DB, plotters::coord::Shift>,
    (lo, hi): (f64, f64),
    desc: &str,
    decimals: usize,
    bands: usize,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    use plotters::prelude::{ChartBuilder, Rectangle};
    let mut chart = ChartBuilder::on(area)
        .margin_top(12)
        .margin_bottom(52)
        .margin_left(4)
        .margin_right(10)
        .right_y_label_area_size(72)
        .build_cartesian_2d(0.0..1.0, lo..hi)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(desc)
        .label_style(crate::style::text(14.0))
        .axis_desc_style(crate::style::text(15.0))
        .y_label_formatter(&|y| format!("{y:.decimals$}"))
        .draw()?;
    let step = (hi - lo) / bands as f64;
    let band = |k: usize| {
        let y = lo + k as f64 * step;
        let colour = r_surface::viridis(k as f64 / (bands.max(2) - 1) as f64);
        Rectangle::new([(0.0, y), (1.0, y + step)], plotters::style::Color::filled(&colour))
    };
    chart.draw_series((0..bands).map(band))?;
    Ok(())
}
