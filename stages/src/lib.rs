//! Domain stage kinds: each a small struct implementing [`pipeline::stage::Stage`],
//! registered in [`register`]. Stages read only their declared input folders (through
//! the `datasets` readers or Parquet) and write only through their context; they never
//! draw (figures live in `reports`).
#![deny(missing_docs)]

pub mod concat;
mod discrepancy_tables;
pub mod effects;
pub mod fdm;
pub mod inkjet;
pub mod parts;
pub mod progress;
pub mod roles;
pub mod table;
pub mod thermal;

use pipeline::Registry;

/// Registers every domain stage kind.
pub fn register(registry: &mut Registry) {
    fdm::register(registry);
    inkjet::register(registry);
    thermal::register(registry);
    registry.register(Box::new(concat::ConcatStage));
}
