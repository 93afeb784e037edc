//! The discrepancy engine (DESIGN §7): given a baseline model, a list of candidate
//! mechanisms and grouped data, it **shows** what the model gets wrong, **names** the
//! cause, **extends** the model and measures the **gain**.
//!
//! It knows nothing of additive manufacturing. A domain implements [`Model`] for its
//! baseline (how to fit a set of active mechanisms on some groups and predict a
//! held-out one) and [`Mechanism`] for each candidate cause (a name, its physics in one
//! line, its parameters with units and bounds). A *group* is a whole experiment — a
//! printed line, a print, a layer — and every split holds out whole groups.
//!
//! - [`show`]: the baseline's held-out residuals binned against every candidate
//!   variable, each bin's mean with a group-cluster 95 % interval, and per variable the
//!   share of the residual sum of squares the bin means explain.
//! - [`engine`]: the rounds. Each candidate is fitted and scored by leave-one-group-out
//!   cross-validation; per held-out group the log ratio of squared error before and
//!   after is the unit of evidence. A one-sided sign-flip permutation test over groups
//!   gives each candidate a p-value (of "no gain", or with `min_gain_pct` of "no gain
//!   worth naming", a minimum-effect test), Holm's step-down holds the family-wise
//!   false-alarm rate at α over the candidates of a round, and the cause named is the
//!   significant candidate with the largest held-out gain. The extended model becomes the baseline
//!   and the search repeats. Too few groups to reach α/m is a verdict of its own.
//! - Extend and gain (also in [`engine`]): the extended model fitted on all groups with
//!   delete-one-group jackknife intervals (the cross-validation's own fold fits), and
//!   the held-out RMSE before and after with a bootstrap-over-groups interval, over the
//!   observations the named mechanisms move (as each was scored in its round).
//! - [`stats`]: the tests and intervals; [`least_squares`]: a bounded
//!   Levenberg–Marquardt solver for the domains' nonlinear fits.
//!
//! Architecture invariant: no I/O, no tables, no plotting, no domain knowledge; every
//! random stream is seeded by [`Settings::seed`], and results do not depend on the
//! number of threads.
#![deny(missing_docs)]

pub mod engine;
pub mod least_squares;
pub mod mechanism;
pub mod model;
pub mod power;
pub mod show;
pub mod split;
pub mod stats;

#[cfg(test)]
mod testing;

pub use engine::{
    discover, discover_warm, CandidateScore, Discovery, EngineError, Estimate, Gain, HeldOut, Round, Settings, Verdict,
};
pub use mechanism::{Candidate, Mechanism, Nuisance, Parameter, Scale};
pub use model::{Group, Model, ModelError, Variable, VariableKind};
pub use show::{BinStat, VariableStructure};
