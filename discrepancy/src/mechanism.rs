//! A candidate cause: a named physical mechanism with a small parametric extension of
//! the baseline. The domain crate implements [`Mechanism`] for each of its candidates;
//! the engine uses only what this trait says (names, units, bounds, whether a
//! parameter belongs to one group only), never the physics itself.

/// One fitted parameter of a baseline or a mechanism.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Parameter {
    /// Name with its unit in it (`tau_s`, `period_mm`).
    pub name: &'static str,
    /// Unit as printed in tables (`s`, `mm`, `1` for a fraction).
    pub unit: &'static str,
    /// Smallest admissible value.
    pub lo: f64,
    /// Largest admissible value.
    pub hi: f64,
    /// One line: what the parameter means physically.
    pub meaning: &'static str,
    /// Scale on which its uncertainty is symmetric (intervals are built on it).
    pub scale: Scale,
}

impl Parameter {
    /// A parameter whose interval is symmetric on its value.
    pub const fn linear(name: &'static str, unit: &'static str, lo: f64, hi: f64, meaning: &'static str) -> Self {
        Self { name, unit, lo, hi, meaning, scale: Scale::Linear }
    }
}

/// The scale on which a parameter's interval is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Symmetric on the value itself.
    Linear,
    /// Symmetric on its logarithm (positive scale parameters such as time constants).
    Log,
}

/// Whether a mechanism carries parameters that belong to one group only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Nuisance {
    /// Every parameter is shared by all groups.
    None,
    /// Some parameters belong to one group (a gear's phase on one line): for a held-out
    /// group they are estimated on one part of it and scored on the other
    /// (cross-fitting), never on the same samples.
    PerGroup,
}

/// A named physical cause with a parametric extension of the baseline.
pub trait Mechanism: Send + Sync {
    /// Registry name (`bed_tilt`).
    fn name(&self) -> &'static str;
    /// One sentence: the physics of the extension.
    fn physics(&self) -> &'static str;
    /// Its shared parameters, in the order the model's estimates list them.
    fn params(&self) -> &'static [Parameter];
    /// Whether it has per-group nuisance parameters.
    fn nuisance(&self) -> Nuisance {
        Nuisance::None
    }
}

/// A mechanism that is fully described by its name, physics and shared parameters (no
/// per-group nuisance): most domains' candidates, declared as statics.
#[derive(Debug)]
pub struct Candidate {
    name: &'static str,
    physics: &'static str,
    params: &'static [Parameter],
}

impl Candidate {
    /// A candidate called `name`.
    pub const fn new(name: &'static str, physics: &'static str, params: &'static [Parameter]) -> Self {
        Self { name, physics, params }
    }
}

impl Mechanism for Candidate {
    fn name(&self) -> &'static str {
        self.name
    }
    fn physics(&self) -> &'static str {
        self.physics
    }
    fn params(&self) -> &'static [Parameter] {
        self.params
    }
}
