//! Report-section stage kinds: each reads published tables of one paper's run and
//! writes `section.html` (embedded in the report) and `comparison.parquet` (paper's
//! number beside ours, with where ours came from).

mod ren2021;

pub use ren2021::Ren2021Section;

use pipeline::Registry;

/// Registers every report-section kind.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(Ren2021Section));
}
