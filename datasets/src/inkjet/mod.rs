//! The `inkjet-scans` dataset kind (DESIGN §4) of paper 002 (Lu, Zheng, Mishra 2015):
//! layer-by-layer profiler scans of an ink-jet print on the droplet grid, with the
//! pattern printed before each scan, and the generator that writes such datasets from
//! the virtual printer ([`models::inkjet::printer`]).
//!
//! ```text
//! dataset.toml        kind = "inkjet-scans", format_version = 1, printer, units, provenance
//! grid.toml           m_x, m_y, spacing_um, desired_height_um, scenario, controller,
//!                     variation_pct, [part] h1_um h2_um h3_um, [support] (two materials),
//!                     [profiler] noise_um spot_sigma_um
//! target.csv          i,j,desired_um         one row per cell of the desired footprint
//! scans.csv           layer,i,j,height_um    measured height of every cell; layer 0 is
//!                                            the substrate before printing, layer k the
//!                                            scan after printing layer k
//! patterns.csv        layer,i,j,material     the cells printed in layer k >= 1, with
//!                                            their material (`part` or `support`)
//! truth/heights.csv   layer,i,j,height_um    true heights, same layout as scans.csv
//!                                            (virtual datasets only; evaluation only)
//! ```
//!
//! Cell `(i, j)` lies at `(i·spacing, j·spacing)` µm, `0 ≤ i < m_x`, `0 ≤ j < m_y`.

mod format;
mod generate;

pub use format::{CoeffsToml, GridToml, InkjetScans, ProfilerToml, FORMAT_VERSION, KIND, READABLE_VERSIONS};
pub use generate::{generate, write_dataset, GenerateError, GenerateOptions, Scenario, GENERATOR, OUTPUT};
pub use models::inkjet::experiments::ControlLaw;
pub use models::inkjet::printer::{Effect, Effects};
