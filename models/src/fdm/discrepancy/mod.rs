//! What the lag model gets wrong on measured line widths (DESIGN §7, paper 000's
//! data): the FDM domain of the [`discrepancy`] engine.
//!
//! - [`mechanisms`]: the candidate causes, each a [`discrepancy::Mechanism`] with its
//!   physics, parameters, units and bounds.
//! - [`forward`]: one forward model of a line in which any set of them is switched on.
//! - [`FdmModel`]: the baseline (the lag model of [`crate::fdm::lag`], `fdm.lag_model`)
//!   as a [`discrepancy::Model`]: bounded least squares of every active parameter on
//!   the training lines, the gear's period searched on a grid and its phase per line.
//! - [`piecewise_baseline`]: paper 000's piecewise model as the baseline instead, with
//!   the candidates that act on the width it predicts (tilt, gear, saturation).
//! - [`variables`]: the candidate variables the residuals are shown against.
//! - [`inject`]: hiding an effect in a data set by its physics; [`surrogate`] and
//!   [`power`]: the power study that asks how strong an effect must be to be found.
//!
//! A group is one printed line. A prediction uses nothing of the held-out line but its
//! commanded kinematics, except the gear's phase, which is cross-fitted on the line's
//! other half.

pub mod fit;
pub mod forward;
pub mod gear;
pub mod inject;
pub mod mechanisms;
pub mod piecewise_baseline;
pub mod power;
pub mod surrogate;
pub mod variables;

use std::sync::OnceLock;

use ::discrepancy::{Group, Mechanism, Model, ModelError, Parameter, Variable};

use self::forward::{LineSetting, Theta};
use self::gear::GearTable;
use self::mechanisms::{CANDIDATES, GEAR_ECCENTRICITY, LAG_PARAMS, LAG_PARAMS_WITH_BLOB};
use crate::fdm::line::MeasuredLine;

/// Samples per line used in the fits (every k-th measurement, k chosen per line): the
/// widths are measured every ~0.05 mm and are correlated over a nozzle diameter, so
/// ~200 samples over 120 mm lose nothing and keep a 2 mm ripple sampled at 0.6 mm. Held-out
/// scores use every measurement.
pub const FIT_SAMPLES_PER_LINE: usize = 200;

/// One printed line as a group of the engine.
#[derive(Debug)]
pub struct FdmLine {
    /// Label for tables (the condition, e.g. `S800F9000`).
    pub label: String,
    /// Nominal kinematics and measured widths.
    pub line: MeasuredLine,
    fit_positions_mm: Vec<f64>,
    fit_widths_mm: Vec<f64>,
    gear_table: OnceLock<GearTable>,
}

impl FdmLine {
    /// A group from a measured line.
    pub fn new(label: impl Into<String>, line: MeasuredLine) -> Self {
        let stride = (line.len() / FIT_SAMPLES_PER_LINE).max(1);
        let fit_positions_mm = line.positions_mm.iter().step_by(stride).copied().collect();
        let fit_widths_mm = line.widths_mm.iter().step_by(stride).copied().collect();
        Self { label: label.into(), line, fit_positions_mm, fit_widths_mm, gear_table: OnceLock::new() }
    }

    /// The positions used in fits.
    pub fn fit_positions_mm(&self) -> &[f64] {
        &self.fit_positions_mm
    }

    /// The widths used in fits.
    pub fn fit_widths_mm(&self) -> &[f64] {
        &self.fit_widths_mm
    }

    /// The gear period search's table at the fit positions (built on first use).
    pub fn gear_table(&self) -> &GearTable {
        self.gear_table.get_or_init(|| GearTable::new(&self.fit_positions_mm))
    }
}

impl Clone for FdmLine {
    fn clone(&self) -> Self {
        Self::new(self.label.clone(), self.line.clone())
    }
}

impl Group for FdmLine {
    fn observed(&self) -> &[f64] {
        &self.line.widths_mm
    }
}

/// The lag model as the engine's baseline, extensible by [`CANDIDATES`].
#[derive(Debug, Clone, PartialEq)]
pub struct FdmModel {
    /// Whether the lines start with a blob (the initial flow excess `b` is fitted).
    pub has_start_blob: bool,
    /// Setting shared by all lines (smoothing, the saturation's reference speed).
    pub setting: LineSetting,
    /// Typical steady width of the data (mm), for the commanded-flow variable only.
    pub reference_width_mm: f64,
}

impl FdmModel {
    /// The model for `lines`: the saturation's reference speed is their fastest cruise
    /// speed (from the commanded kinematics only), smoothing over one 0.5 mm nozzle
    /// diameter (paper 000 Table I) as `fdm.lag_model`.
    pub fn new(lines: &[FdmLine], has_start_blob: bool, smoothing_mm: f64) -> Self {
        let v_ref_mm_s = lines.iter().map(|l| l.line.nominal.peak_speed_mm_s()).fold(0.0, f64::max);
        let reference_width_mm = crate::stats::finite_median(lines.iter().flat_map(|l| middle_widths(&l.line)));
        Self { has_start_blob, setting: LineSetting { smoothing_mm, v_ref_mm_s }, reference_width_mm }
    }
}

/// The widths of the middle third of a line.
pub(crate) fn middle_widths(line: &MeasuredLine) -> impl Iterator<Item = f64> + '_ {
    let l = line.nominal.length_mm;
    line.positions_mm
        .iter()
        .zip(&line.widths_mm)
        .filter(move |(x, _)| **x >= l / 3.0 && **x <= 2.0 * l / 3.0)
        .map(|(_, w)| *w)
}

/// A fitted lag model with its active extensions.
#[derive(Debug, Clone, PartialEq)]
pub struct FdmFit {
    /// Active mechanisms, in the order added.
    pub active: Vec<usize>,
    /// All physical parameters (inactive ones neutral).
    pub theta: Theta,
    /// The gear ripple's relative amplitude, shared by the lines (0 when off).
    pub gear_amplitude: f64,
    /// RMSE on the training lines' fit samples (mm).
    pub training_rmse_mm: f64,
}

impl Model for FdmModel {
    type Group = FdmLine;
    type Fit = FdmFit;

    fn name(&self) -> &'static str {
        "lag_model"
    }

    fn params(&self) -> &'static [Parameter] {
        if self.has_start_blob {
            &LAG_PARAMS_WITH_BLOB
        } else {
            &LAG_PARAMS
        }
    }

    fn candidates(&self) -> &[&'static dyn Mechanism] {
        &CANDIDATES
    }

    fn variables(&self) -> &[Variable] {
        &variables::VARIABLES
    }

    fn variable_values(&self, group: &FdmLine, variable: usize) -> Vec<f64> {
        variables::values(self, group, variable)
    }

    fn fit(&self, active: &[usize], train: &[&FdmLine], warm: Option<&FdmFit>) -> Result<FdmFit, ModelError> {
        fit::fit(self, active, train, warm)
    }

    fn predict(&self, fit: &FdmFit, group: &FdmLine, calibrate: Option<&[bool]>) -> Result<Vec<f64>, ModelError> {
        fit::predict(self, fit, group, calibrate)
    }

    fn estimates(&self, fit: &FdmFit) -> Vec<f64> {
        let t = &fit.theta;
        let mut out = vec![t.tau_s, t.w0_mm];
        if self.has_start_blob {
            out.push(t.blob_mm2_s);
        }
        for &c in &fit.active {
            out.extend(mechanism_values(c, fit));
        }
        out
    }
}

/// The reported values of mechanism `c`'s parameters, as [`Mechanism::params`] lists them.
fn mechanism_values(c: usize, fit: &FdmFit) -> Vec<f64> {
    use self::mechanisms::*;
    let t = &fit.theta;
    match c {
        BED_TILT => vec![t.tilt_width_change],
        GEAR_ECCENTRICITY => vec![t.gear_period_mm, fit.gear_amplitude],
        FLOW_SATURATION => vec![t.saturation_loss],
        NONLINEAR_LAG => vec![t.lag_offset_s, t.lag_speed_mm_s],
        TWO_STAGE_LAG => vec![t.tau_slow_s, t.slow_fraction],
        WIDTH_CAP => vec![t.max_excess_mm],
        _ => vec![t.r_a, t.r_f],
    }
}

/// Whether `active` includes the gear ripple.
fn has_gear(active: &[usize]) -> bool {
    active.contains(&GEAR_ECCENTRICITY)
}
