//! What a domain gives the engine: its grouped data ([`Group`]), the variables the
//! residuals are shown against ([`Variable`]), and a baseline that can be extended by
//! any set of its candidate mechanisms and fitted and predicted ([`Model`]).

use crate::mechanism::{Mechanism, Parameter};

/// One whole experiment (a printed line, a print, a layer): observations in a fixed
/// order. Cross-fitting splits a group into its first and second half in that order.
pub trait Group: Sync {
    /// The observed values, one per sample.
    fn observed(&self) -> &[f64];
}

/// How a variable's values are binned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VariableKind {
    /// Real-valued: equal-count bins, or one bin per value when there are few values.
    Continuous,
    /// A category coded `0, 1, …` with these labels: one bin per category.
    Categorical(&'static [&'static str]),
}

/// A candidate variable of the residual structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Variable {
    /// Name with unit (`position_mm`).
    pub name: &'static str,
    /// Unit as printed (`mm`, `s`, `` for a category).
    pub unit: &'static str,
    /// Binning rule.
    pub kind: VariableKind,
}

/// A model error: a fit that failed or a prediction that could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// The fit did not produce a usable model (singular, diverged, not enough data).
    #[error("fit failed: {0}")]
    Fit(String),
    /// A prediction could not be made for a group.
    #[error("prediction failed: {0}")]
    Predict(String),
}

/// A baseline model that can be extended by any set of its candidate mechanisms.
///
/// Mechanisms are referred to by their index in [`Model::candidates`]; `active` lists
/// the extensions in the order they were added.
pub trait Model: Sync {
    /// The grouped data type.
    type Group: Group;
    /// A fitted model (baseline plus the active extensions).
    type Fit: Clone + Send + Sync;

    /// The baseline's name (`lag_model`).
    fn name(&self) -> &'static str;
    /// The baseline's own parameters.
    fn params(&self) -> &'static [Parameter];
    /// The candidate mechanisms.
    fn candidates(&self) -> &[&'static dyn Mechanism];
    /// Variables to show the residuals against.
    fn variables(&self) -> &[Variable];
    /// The values of variable `variable` at each sample of `group`.
    fn variable_values(&self, group: &Self::Group, variable: usize) -> Vec<f64>;

    /// Fits the baseline extended by `active` on `train`. `warm` is a fit of a subset
    /// of `active` on the same groups, a starting point: it must not carry information
    /// about any group outside `train`.
    fn fit(&self, active: &[usize], train: &[&Self::Group], warm: Option<&Self::Fit>) -> Result<Self::Fit, ModelError>;

    /// Predicts every sample of `group` (not among the training groups). When a
    /// mechanism of the fit has per-group nuisance parameters, they are estimated on
    /// the samples where `calibrate` is true only; otherwise `calibrate` is ignored.
    fn predict(&self, fit: &Self::Fit, group: &Self::Group, calibrate: Option<&[bool]>)
        -> Result<Vec<f64>, ModelError>;

    /// The fitted shared parameters: the baseline's, then each active mechanism's in
    /// `active` order, as [`Model::params`] and [`Mechanism::params`] list them.
    fn estimates(&self, fit: &Self::Fit) -> Vec<f64>;

    /// The observations of `group` that `mechanism` can move, when the groups join kinds
    /// of observation that no mechanism shares (a camera's timing and a bead's width):
    /// the candidate is then scored on those only, or one kind's residuals would dilute
    /// another's evidence in proportion to how many there are. Default `None`: every
    /// candidate is scored on every observation.
    fn moved_by(&self, mechanism: usize, group: &Self::Group) -> Option<Vec<bool>> {
        let _ = (mechanism, group);
        None
    }
}
