//! Figure stage kinds: each reads published tables of its input stages and draws one
//! figure as PNG and SVG, in the style of the paper it reproduces. Grouped by domain:
//! `fdm` (paper 000 and the FDM discrepancy), `inkjet` (paper 002), `thermal`
//! (paper 003), and the two every domain of the discrepancy engine draws: its held-out
//! residuals (`discrepancy_residuals`) and a discovery study's power by effect.

mod common;
pub(crate) mod discrepancy_residuals;
pub(crate) mod fdm;
pub(crate) mod inkjet;
mod power_by_effect;
#[cfg(test)]
pub(crate) mod test_util;
pub(crate) mod thermal;

pub use discrepancy_residuals::DiscrepancyResidualsFigure;
pub use fdm::{
    DiscoveryPowerFigure, DiscrepancyLinesFigure, InfillFigure, LooPredictionsFigure, PhotoOverlayFigure,
    PressureAdvanceFigure, RSurfaceFigure, SegmentAccuracyFigure, TransferCvFigure, TransferMatrixFigure,
    VirtualAgreementFigure, WidthProfilesFigure,
};
pub use inkjet::{InkjetHeightMapsFigure, InkjetModelVsScanFigure, InkjetPipeJunctionFigure};
pub use power_by_effect::DiscoveryPowerByEffectFigure;
pub use thermal::{
    ThermalContourErrorFigure, ThermalCornersFigure, ThermalDirectionsFigure, ThermalFrameFigure,
    ThermalOverdepositionFigure,
};

use pipeline::Registry;

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
    registry.register(Box::new(PhotoOverlayFigure));
    registry.register(Box::new(PressureAdvanceFigure));
}
