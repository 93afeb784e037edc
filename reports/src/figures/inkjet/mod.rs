//! Figures of paper 002 (ink-jet layer-to-layer control): height maps, the height
//! model against the scans, and the pipe junction's two materials.

mod height_maps;
mod model_vs_scan;
mod pipe_junction;

pub use height_maps::InkjetHeightMapsFigure;
pub use model_vs_scan::InkjetModelVsScanFigure;
pub use pipe_junction::InkjetPipeJunctionFigure;
