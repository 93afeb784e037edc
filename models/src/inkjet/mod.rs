//! Paper 002: Lu, Zheng, Mishra 2015, "A Layer-To-Layer Model and Feedback Control of
//! Ink-Jet 3-D Printing" (IEEE/ASME Trans. Mechatronics 20(3)).
//!
//! Code map, one file per step:
//! - [`grid`]: the droplet grid, height maps and patterns (Sec. III-A, eq. 1).
//! - [`height_model`]: the layer-to-layer height-change model, single and two material
//!   (eqs 2-7, corrected per DESIGN §5.2).
//! - [`objective`]: the cost of eq. 8 and its running sums.
//! - [`horizon`]: the N-layer prediction and the incremental / naive flip evaluation.
//! - [`mpc`]: the stochastic greedy search (Sec. IV-C).
//! - [`controller`]: open-loop and closed-loop layer patterns (Sec. IV-A).
//! - [`printer`]: the virtual printer and profiler (DESIGN §5.2), with switchable
//!   extra effects; the one machine of the experiments and the dataset generator.
//! - [`experiments`]: the paper's simulations (Figs 11-12, Table II, Sec. IV-C).
//! - [`pipe_junction`]: the two-material pipe junction (Figs 13-15) and its
//!   edge-deformation metrics.
//! - [`discrepancy`]: what eqs 2-7 get wrong on a print's scans (DESIGN §7): the
//!   candidate mechanisms, the extended model as the engine's `Model`, the power study.
//!
//! Architecture Invariant: pure numerics: no I/O, every random stream comes from a
//! caller-supplied seeded generator, and results do not depend on the thread count.

pub mod controller;
pub mod discrepancy;
pub mod errors;
pub mod experiments;
pub mod grid;
pub mod height_model;
pub mod horizon;
pub mod mpc;
pub mod objective;
pub mod pipe_junction;
pub mod printer;

pub use errors::InkjetError;
pub use grid::{Grid, HeightMap, Pattern};
pub use height_model::DropletCoeffs;
