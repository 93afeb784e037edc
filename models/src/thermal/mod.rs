//! Paper 003: Chen, Yang, Liu, Duan, "In-situ Additive Manufacturing Deposition
//! Trajectory Monitoring and Compensation with Thermal Camera".
//!
//! Code map, one file per step:
//! - [`setup`]: the printing parameters of Table 1 and the corner test path (Fig. 7a).
//! - [`trajectory`]: the commanded motion: corner blending within the tolerance of
//!   Table 1 and an acceleration-limited speed profile, sampled at a fixed period.
//! - [`deposit`]: a deposited layer as fill fractions on a grid (what eqs 40-41 measure).
//! - [`dynamics`]: the first-order deposition dynamics G(s) = 1/(τs+1) of eq. 34.
//! - [`geometry`]: velocity, direction and curvature from the samples (eqs 1, 4), the
//!   left/right half widths of a curved bead (eqs 8-11) and the slender condition (eq. 12).
//! - [`dda`]: the deposition direction allocation of Sec. 2.2 (eqs 13-26) and the bead
//!   boundary points of Fig. 3.
//! - [`compensation`]: the width error, compensation spans and the filtered B-spline
//!   compensation of Sec. 2.4 (eqs 31-39).
//! - [`metrics`]: the ideal (CAD) bead, the over-deposition index (eq. 40) and the
//!   contour error (eq. 41) on deposited layers.
//!
//! Architecture Invariant: pure numerics: no I/O; the planner and the dynamics are
//! shared by the virtual printer (`datasets`) and the analysis stages, so both see the
//! same commanded trajectory.

pub mod compensation;
pub mod dda;
pub mod deposit;
pub mod discrepancy;
pub mod dynamics;
pub mod errors;
pub mod geometry;
pub mod metrics;
pub mod setup;
pub mod trajectory;

pub use deposit::DepositGrid;
pub use errors::ThermalError;
pub use setup::PrintSetup;
pub use trajectory::{Corner, Trajectory};
