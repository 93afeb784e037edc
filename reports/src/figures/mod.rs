//! Figure stage kinds: each reads published tables of its input stages and draws one
//! figure as PNG and SVG, in the style of the paper it reproduces.

mod infill;
mod inkjet_height_maps;
mod loo_predictions;
mod r_surface;
#[cfg(test)]
mod test_util;
mod transfer_cv;
mod width_profiles;

pub use infill::InfillFigure;
pub use inkjet_height_maps::InkjetHeightMapsFigure;
pub use loo_predictions::LooPredictionsFigure;
pub use r_surface::RSurfaceFigure;
pub use transfer_cv::TransferCvFigure;
pub use width_profiles::WidthProfilesFigure;

use pipeline::Registry;

/// Registers every figure kind.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(WidthProfilesFigure));
    registry.register(Box::new(LooPredictionsFigure));
    registry.register(Box::new(RSurfaceFigure));
    registry.register(Box::new(TransferCvFigure));
    registry.register(Box::new(InfillFigure));
    registry.register(Box::new(InkjetHeightMapsFigure));
}
