//! Error types of the paper-000 models (Ren et al. 2021): invalid kinematics, invalid
//! hyper-parameters (caught once by `.check()`), and fit failures. Parameter errors are
//! kept apart from run errors, as CONVENTIONS.md asks.

use thiserror::Error;

/// A straight-line motion that the planner of Sec. II-A cannot describe.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum KinematicsError {
    /// A kinematic quantity is zero, negative or not finite.
    #[error("{name} must be positive and finite, got {value}")]
    NotPositive {
        /// Which quantity.
        name: &'static str,
        /// The offending value.
        value: f64,
    },
    /// The target feed does not exceed the start speed (jerk), so there is no
    /// acceleration phase at all.
    #[error("feed {feed_mm_s} mm/s must exceed the start speed (jerk) {jerk_mm_s} mm/s")]
    FeedNotAboveJerk {
        /// Target feed (mm/s).
        feed_mm_s: f64,
        /// Start/end speed (mm/s).
        jerk_mm_s: f64,
    },
}

/// A hyper-parameter outside its valid range (returned by the `.check()` methods).
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ParamError {
    /// A parameter is outside its allowed range.
    #[error("parameter `{name}` = {value} is invalid: {reason}")]
    OutOfRange {
        /// Parameter name.
        name: &'static str,
        /// The offending value.
        value: f64,
        /// What the valid range is.
        reason: &'static str,
    },
}

/// A fit that could not be carried out on the given data.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FitError {
    /// A measured line is malformed (lengths differ, unsorted positions, non-finite values).
    #[error("measured line{}: {reason}", line.map(|i| format!(" {i}")).unwrap_or_default())]
    BadLine {
        /// Index of the line in the input slice (`None` for a line checked alone).
        line: Option<usize>,
        /// What is wrong.
        reason: String,
    },
    /// Too few lines or samples for the requested fit.
    #[error("not enough data: {0}")]
    NotEnoughData(String),
    /// The kinematics of a line are invalid.
    #[error(transparent)]
    Kinematics(#[from] KinematicsError),
    /// A linear system (normal equations, MAP) is singular or not positive definite.
    #[error("singular system: {0}")]
    Singular(String),
    /// Dimensions of the inputs disagree.
    #[error("dimension mismatch: {0}")]
    Dimension(String),
    /// A failure on the named source printer's lines (its prior could not be built).
    #[error("source printer `{printer}`: {error}")]
    Source {
        /// The source printer's name.
        printer: String,
        /// What failed.
        error: Box<FitError>,
    },
    /// A failure another process met and recorded as its text (a work unit of a
    /// spread-out run, e.g. [`GridPart`](super::transfer_cv::GridPart)).
    #[error("{0}")]
    Recorded(String),
}
