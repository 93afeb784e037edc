//! Paper 000 (Ren et al. 2021, "Improved Modeling of Kinematics-Induced Geometric
//! Variations in Extrusion-Based AM Through Between-Printer Transfer Learning"): the
//! numeric core.
//!
//! - [`kinematics`]: trapezoidal nozzle motion of one straight line (Sec. II-A, eq. 1).
//! - [`piecewise`]: the five-phase width model (eqs 2-3) and its breakpoint chain.
//! - [`hyperparams`], [`fit`](mod@fit), [`predict`]: the 8-step fitting procedure with the
//!   `r_a`, `r_F` grid search, and prediction from kinematics only.
//! - [`loo`]: leave-one-out evaluation (Sec. III-A, Table II).
//! - [`lag`]: physics baseline: mass conservation with a first-order extrusion lag
//!   (DESIGN §5.1), not in the paper.
//! - [`discrepancy`](mod@discrepancy): what the lag model gets wrong on measured widths — the
//!   candidate mechanisms, their forward model, injection and the power study, as the
//!   FDM domain of the generic `discrepancy` engine (DESIGN §7).
//! - [`printer`]: the virtual FDM printer's physics (DESIGN §5.1): the lag model with the
//!   mechanisms the discrepancy engine names on the real lines, wander and edge roughness,
//!   the switchable effects, and its calibration to measured lines.
//! - [`planner`]: the firmware's look-ahead motion planner over G-code moves (Klipper's
//!   square-corner velocity, Marlin's jerk or junction deviation), for real prints (issue 53).
//! - [`printed_lines`]: the straight printed lines of a planned print, with the commanded
//!   speed, time and filament along each.
//! - [`pressure_advance`]: Klipper's pressure advance and Marlin's linear advance ahead of
//!   the melt's first-order lag, and the widths a printed line deposits under them.
//! - [`transfer`]: covariance prior and MAP transfer (Algorithm 1, eqs 4-6, Fig. 9).
//! - [`transfer_cv`](mod@transfer_cv): the Fig. 9 cross-validation over all training
//!   subsets of the target lines × {single, zero-mean, source-mean transfer} in one call.
//!
//! Architecture invariant: no file I/O and no tables here; functions take slices and
//! structs and return structs.

pub mod colearn;
pub mod discrepancy;
pub mod errors;
pub mod fit;
pub mod hyperparams;
pub mod kinematics;
pub mod lag;
pub mod line;
pub mod loo;
pub mod pa_tuning;
pub mod piecewise;
pub mod planner;
pub mod predict;
pub mod pressure_advance;
pub mod printed_lines;
pub mod printer;
mod small_linalg;
pub mod synthetic;
pub mod transfer;
pub mod transfer_cv;

#[cfg(test)]
mod test_support;

pub use colearn::{
    default_tasks, summarise, transfer_matrix, transfer_matrix_for_target, MatrixMethod, MatrixRow, MatrixSummary,
    StudyPrinter, TransferTask,
};
pub use errors::{FitError, KinematicsError, ParamError};
pub use fit::{fit, fit_at};
pub use hyperparams::{PiecewiseParams, PiecewiseValidParams};
pub use kinematics::{KinematicSamples, LineKinematics, MotionPhase};
pub use lag::{fit_lag, FittedLag, LagParams, LagValidParams};
pub use line::{other_family_widths, rmse, MeasuredLine};
pub use loo::{leave_one_out, leave_one_out_lag, LagLooFold, LooFold};
pub use piecewise::{Bp1PowerLaw, LineChain, PiecewiseCoefficients, WidthPhase};
pub use predict::FittedPiecewise;
pub use transfer::{
    all_condition_subsets, condition_subsets, estimate_covariance, single, solve_map, transfer_source_mean,
    transfer_zero_mean, ConditionSubset, LambdaRule, ParameterCovariance, PriorKinematics, PriorMean, SourcePrior,
    TransferFit, TransferParams, TransferValidParams,
};
pub use transfer_cv::{
    transfer_cv, transfer_cv_blocks, transfer_cv_from_parts, transfer_cv_part, GridPart, GridWinner, TransferCvRow,
    TransferMethod, MAX_TARGET_LINES,
};
