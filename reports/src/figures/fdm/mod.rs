//! Figures of paper 000 (line widths, the r_a × r_F surface, transfer learning), of
//! the virtual FDM printer and camera, and of the FDM discrepancy engine.

mod discrepancy;
mod infill;
pub(crate) mod loo_predictions;
mod photo_overlay;
mod pressure_advance;
mod r_surface;
mod segment_accuracy;
mod transfer_cv;
pub(crate) mod transfer_matrix;
mod virtual_agreement;
mod width_profiles;

pub use discrepancy::{DiscoveryPowerFigure, DiscrepancyLinesFigure};
pub use infill::InfillFigure;
pub use loo_predictions::LooPredictionsFigure;
pub use photo_overlay::PhotoOverlayFigure;
pub use pressure_advance::PressureAdvanceFigure;
pub use r_surface::RSurfaceFigure;
pub use segment_accuracy::SegmentAccuracyFigure;
pub use transfer_cv::TransferCvFigure;
pub use transfer_matrix::TransferMatrixFigure;
pub use virtual_agreement::VirtualAgreementFigure;
pub use width_profiles::WidthProfilesFigure;

use plotters::coord::cartesian::Cartesian2d;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::{ChartContext, DrawingAreaErrorKind, DrawingBackend};

use crate::style::house_mesh;

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
