//! Stages of paper 000 (Ren et al. 2021): importing measured line widths and
//! summarising them; the model stages come with the paper-000 issue.

mod import;
mod line_summary;

pub use import::ImportStage;
pub use line_summary::{summarize_line, LineSummary, LineSummaryStage, SummaryWindows};

use pipeline::Registry;

/// Registers the paper-000 stage kinds.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(ImportStage));
    registry.register(Box::new(LineSummaryStage));
}
