//! Paper 003: Chen, Yang, Liu, Duan, "In-situ Additive Manufacturing Deposition
//! Trajectory Monitoring and Compensation with Thermal Camera".
//!
//! Code map, one file per step:
//! - [`setup`]: the printing parameters of Table 1 and the corner test path (Fig. 7a).
//! - [`trajectory`]: the commanded motion: corner blending within the tolerance of
//!   Table 1 and an acceleration-limited speed profile, sampled at a fixed period.
//! - [`deposit`]: a deposited layer as fill fractions on a grid (what eqs 40-41 measure).
//! - [`dynamics`]: the first-order deposition dynamics G(s) = 1/(τs+1) of eq. 34.
//!
//! Architecture Invariant: pure numerics: no I/O; the planner and the dynamics are
//! shared by the virtual printer (`datasets`) and the analysis stages, so both see the
//! same commanded trajectory.

pub mod deposit;
pub mod dynamics;
pub mod errors;
pub mod setup;
pub mod trajectory;

pub use deposit::DepositGrid;
pub use errors::ThermalError;
pub use setup::PrintSetup;
pub use trajectory::{Corner, Trajectory};
