//! Parameter errors of the paper-003 models (Chen et al.).

use thiserror::Error;

/// An input of the thermal-monitoring models that cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ThermalError {
    /// A parameter that must be positive and finite is not.
    #[error("{name} must be positive and finite, got {value}")]
    NotPositive {
        /// Parameter name with unit.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A path needs at least three distinct vertices to be closed.
    #[error("a closed path needs at least 3 vertices, got {found}")]
    TooFewVertices {
        /// Number of vertices given.
        found: usize,
    },
    /// A corner's blend does not fit between its neighbours.
    #[error(
        "corner {corner}: blending needs {needed_mm:.3} mm of each edge, the shorter edge has {available_mm:.3} mm"
    )]
    BlendDoesNotFit {
        /// Vertex index.
        corner: usize,
        /// Tangent length the blend needs.
        needed_mm: f64,
        /// Half the shorter adjacent edge.
        available_mm: f64,
    },
    /// The deposition direction allocation could not place a span's rotation (Sec. 2.2).
    #[error("deposition direction allocation: the span at t = {t_s:.4} s leaves {residual_rad} rad unplaced")]
    DirectionAllocation {
        /// Start time of the violating span (s).
        t_s: f64,
        /// Rotation left over (rad).
        residual_rad: f64,
    },
    /// The allocation met more violating spans than its limit (Sec. 2.2): the bead's
    /// half-widths (flow over speed and layer height, eqs 5-11) leave no room at the
    /// path's corners.
    #[error(
        "deposition direction allocation: more than {max_spans} spans break the bound by t = {t_s:.4} s: \
         the bead is far wider than the path's corners allow (check the flow against the layer height and the bead width)"
    )]
    TooManySpans {
        /// Start time of the span past the limit (s).
        t_s: f64,
        /// The limit (`DdaParams::max_spans`).
        max_spans: usize,
    },
    /// Compensation bounds that exclude zero (the fixed end control points of eq. 39).
    #[error("compensation bounds must satisfy min <= 0 <= max, got [{min}, {max}] mm/s")]
    BadBounds {
        /// ΔV_min (mm/s).
        min: f64,
        /// ΔV_max (mm/s).
        max: f64,
    },
    /// The bounded least-squares solve of eq. 39 failed (singular basis or no convergence).
    #[error("bounded least squares with {unknowns} unknowns did not converge or is singular")]
    BoundedLeastSquares {
        /// Number of free control values.
        unknowns: usize,
    },
    /// An input that cannot be used, with the reason.
    #[error("{name} = {value}: {reason}")]
    InvalidParameter {
        /// What was given.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What was expected.
        reason: &'static str,
    },
    /// Two samples of a trajectory table disagree in length or spacing.
    #[error("trajectory table: {message}")]
    BadTrajectory {
        /// What is wrong.
        message: String,
    },
}

/// Checks that a value is positive and finite.
pub(crate) fn positive(name: &'static str, value: f64) -> Result<f64, ThermalError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(ThermalError::NotPositive { name, value })
    }
}
