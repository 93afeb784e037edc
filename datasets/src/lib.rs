//! On-disk dataset formats (DESIGN §4), importers of measured data and, in later
//! issues, the virtual printers that generate datasets in the same formats.
//!
//! A dataset is one folder with a `dataset.toml` (kind, printer, units, provenance), a
//! per-item table and the item files. Analysis stages read datasets only through the
//! readers here, never through a generator's internals. This crate does no tables
//! through polars: dataset tables are plain CSV so anyone can write them by hand.
#![deny(missing_docs)]

pub mod csv_table;
pub mod error;
pub mod fdm_inject;
pub mod fdm_lines;
pub mod fdm_photos;
pub mod fdm_widths;
pub mod fsu;
pub mod inkjet;
pub mod limits;
pub mod manifest;
pub mod output;
pub mod paths;
pub mod text;
pub mod thermal;

pub use error::DatasetError;

/// A random stream of the seed, independent of the others and of thread scheduling.
pub(crate) fn stream(seed: u64, id: u64) -> rand_chacha::ChaCha8Rng {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(id);
    rng
}
