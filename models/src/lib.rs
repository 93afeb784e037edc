//! Numeric process models of the reproduced papers.
//!
//! Pure numerics: no file I/O, no tables, no plotting. Each submodule implements one
//! paper's model and cites the equations it implements:
//!
//! - [`fdm`]: Ren et al. 2021 (paper 000): nozzle kinematics, the five-phase piecewise
//!   line-width model, the first-order extrusion-lag baseline, covariance-prior transfer.
//! - [`inkjet`]: Lu, Zheng, Mishra 2015 (paper 002): layer-to-layer droplet height model
//!   and the model-predictive controller.
//! - [`thermal`]: Chen et al. 2024 (paper 003): path geometry, deposition direction
//!   allocation, filtered-B-spline compensation and the evaluation metrics.
//! - [`stats`]: the shared median.
//! - [`progress`]: how a long computation tells its progress.
#![deny(missing_docs)]

pub mod fdm;
pub mod inkjet;
pub mod progress;
pub mod stats;
pub mod thermal;
