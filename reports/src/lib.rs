//! Figures (plotters) and the HTML report. This crate reads published artifacts only
//! (Parquet tables, manifests); it never fits or simulates.
//!
//! Figures are stage kinds (`figure.*`) so the engine caches and orders them like any
//! other stage; the HTML report is rebuilt from the run manifests after every run.
#![deny(missing_docs)]

pub mod figures;
pub mod html;
pub mod read;
pub mod sections;
pub mod style;

use pipeline::Registry;

/// Registers every figure stage kind.
pub fn register(registry: &mut Registry) {
    figures::register(registry);
    sections::register(registry);
}
