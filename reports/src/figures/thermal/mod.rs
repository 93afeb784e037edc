//! Figures of paper 003 (thermal-camera monitoring and compensation): deposition
//! directions, a camera frame, the corners, over-deposition and the contour error.

mod common;
mod contour_error;
mod corners;
mod directions;
mod frame;
mod overdeposition;
#[cfg(test)]
pub(crate) mod test_data;

pub use contour_error::ThermalContourErrorFigure;
pub use corners::ThermalCornersFigure;
pub use directions::ThermalDirectionsFigure;
pub use frame::ThermalFrameFigure;
pub use overdeposition::ThermalOverdepositionFigure;
