//! Figure stage kinds: each reads published tables of its input stages and draws one
//! figure as PNG and SVG, in the style of the paper it reproduces.

mod infill;
mod inkjet_height_maps;
mod inkjet_model_vs_scan;
mod inkjet_pipe_junction;
mod loo_predictions;
mod r_surface;
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
mod width_profiles;

pub use infill::InfillFigure;
pub use inkjet_height_maps::InkjetHeightMapsFigure;
pub use inkjet_model_vs_scan::InkjetModelVsScanFigure;
pub use inkjet_pipe_junction::InkjetPipeJunctionFigure;
pub use loo_predictions::LooPredictionsFigure;
pub use r_surface::RSurfaceFigure;
pub use thermal_contour_error::ThermalContourErrorFigure;
pub use thermal_corners::ThermalCornersFigure;
pub use thermal_directions::ThermalDirectionsFigure;
pub use thermal_frame::ThermalFrameFigure;
pub use thermal_overdeposition::ThermalOverdepositionFigure;
pub use transfer_cv::TransferCvFigure;
pub use width_profiles::WidthProfilesFigure;

use pipeline::Registry;
use plotters::coord::cartesian::Cartesian2d;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::{ChartContext, DrawingAreaErrorKind, DrawingBackend};

use crate::style::house_mesh;

/// Registers every figure kind.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(WidthProfilesFigure));
    registry.register(Box::new(LooPredictionsFigure));
    registry.register(Box::new(RSurfaceFigure));
    registry.register(Box::new(TransferCvFigure));
    registry.register(Box::new(InfillFigure));
    registry.register(Box::new(InkjetHeightMapsFigure));
    registry.register(Box::new(ThermalDirectionsFigure));
    registry.register(Box::new(ThermalFrameFigure));
    registry.register(Box::new(ThermalCornersFigure));
    registry.register(Box::new(ThermalOverdepositionFigure));
    registry.register(Box::new(ThermalContourErrorFigure));
    registry.register(Box::new(InkjetModelVsScanFigure));
    registry.register(Box::new(InkjetPipeJunctionFigure));
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
