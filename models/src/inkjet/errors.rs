//! Parameter errors of the paper-002 models (Lu, Zheng, Mishra 2015).
//!
//! Only invalid inputs are errors: once a grid, a coefficient set and the controller
//! parameters are checked, the simulation and the optimiser cannot fail.

use thiserror::Error;

/// An input of the inkjet model or controller that cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum InkjetError {
    /// A grid needs at least one cell in each direction and a positive spacing.
    #[error("invalid grid {m_x} x {m_y} with spacing {spacing_um} um")]
    InvalidGrid {
        /// Number of cells along x.
        m_x: usize,
        /// Number of cells along y.
        m_y: usize,
        /// Droplet spacing in µm.
        spacing_um: f64,
    },
    /// Two grids that must match do not.
    #[error("grid mismatch: {what} has {found} cells, expected {expected}")]
    GridMismatch {
        /// Which input has the wrong size.
        what: &'static str,
        /// Number of cells found.
        found: usize,
        /// Number of cells expected.
        expected: usize,
    },
    /// A pattern's shape differs from the grid's.
    #[error("pattern is {found_x} x {found_y}, grid is {m_x} x {m_y}")]
    PatternShape {
        /// Pattern cells along x.
        found_x: usize,
        /// Pattern cells along y.
        found_y: usize,
        /// Grid cells along x.
        m_x: usize,
        /// Grid cells along y.
        m_y: usize,
    },
    /// Height-change coefficients must be finite, h1 > 0 and h2, h3 >= 0.
    #[error("invalid droplet coefficients h1={h1_um}, h2={h2_um}, h3={h3_um} um")]
    InvalidCoefficients {
        /// Centre height change in µm.
        h1_um: f64,
        /// Side-neighbour height change in µm.
        h2_um: f64,
        /// Corner-neighbour height change in µm.
        h3_um: f64,
    },
    /// A controller parameter is out of its range.
    #[error("invalid controller parameter {name} = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// The offending value.
        value: f64,
        /// The allowed range.
        reason: &'static str,
    },
    /// The target footprint has no cell, so eq. 8 has nothing to average.
    #[error("the target footprint is empty")]
    EmptyFootprint,
    /// An extra effect of the virtual printer that does not exist.
    #[error("unknown effect `{name}` (known effects: {known})")]
    UnknownEffect {
        /// The name given.
        name: String,
        /// The known names, comma-separated.
        known: String,
    },
    /// An effect strength outside its admissible range.
    #[error("effect {name}: strength {strength} is outside [{min}, {max}] ({unit})")]
    EffectStrength {
        /// The effect.
        name: &'static str,
        /// The strength given.
        strength: f64,
        /// Smallest admissible strength.
        min: f64,
        /// Largest admissible strength.
        max: f64,
        /// What the strength measures.
        unit: &'static str,
    },
    /// The same effect given twice.
    #[error("effect {name} given twice")]
    DuplicateEffect {
        /// The effect.
        name: &'static str,
    },
    /// An effects list item that is not `name=strength`.
    #[error("cannot read effect `{item}`: expected name=strength, e.g. curing_shrinkage=0.05")]
    EffectSyntax {
        /// The item as written.
        item: String,
    },
}
