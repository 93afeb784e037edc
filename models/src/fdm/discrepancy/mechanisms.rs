//! The candidate causes of the FDM line-width discrepancy, each a named physical
//! mechanism with a small parametric extension of the lag model (the forward model in
//! [`super::forward`] says exactly where each acts). Bounds are physical: a tilt that
//! changes the width by half end to end, a lag of 3 s, r_a and r_F in paper 000's
//! `[0.9, 1.1]` (eq. 1).

use ::discrepancy::{Mechanism, Nuisance, Parameter, Scale};

/// Index of [`BedTilt`] among the candidates.
pub const BED_TILT: usize = 0;
/// Index of [`GearEccentricity`].
pub const GEAR_ECCENTRICITY: usize = 1;
/// Index of [`FlowSaturation`].
pub const FLOW_SATURATION: usize = 2;
/// Index of [`NonlinearLag`].
pub const NONLINEAR_LAG: usize = 3;
/// Index of [`TwoStageLag`].
pub const TWO_STAGE_LAG: usize = 4;
/// Index of [`WidthCap`].
pub const WIDTH_CAP: usize = 5;
/// Index of [`KinematicsDeviation`].
pub const KINEMATICS_DEVIATION: usize = 6;

/// Every candidate, in index order.
pub static CANDIDATES: [&dyn Mechanism; 7] =
    [&BedTilt, &GearEccentricity, &FlowSaturation, &NonlinearLag, &TwoStageLag, &WidthCap, &KinematicsDeviation];

/// The candidate called `name`, by index.
pub fn candidate_index(name: &str) -> Option<usize> {
    CANDIDATES.iter().position(|c| c.name() == name)
}

const fn linear(name: &'static str, unit: &'static str, lo: f64, hi: f64, meaning: &'static str) -> Parameter {
    Parameter { name, unit, lo, hi, meaning, scale: Scale::Linear }
}

const fn log(name: &'static str, unit: &'static str, lo: f64, hi: f64, meaning: &'static str) -> Parameter {
    Parameter { name, unit, lo, hi, meaning, scale: Scale::Log }
}

/// The lag model's parameters with a start blob (Taz 5).
pub static LAG_PARAMS_WITH_BLOB: [Parameter; 3] = [TAU, W0, BLOB];
/// Without a start blob (Taz 6).
pub static LAG_PARAMS: [Parameter; 2] = [TAU, W0];

const TAU: Parameter =
    log("tau_s", "s", 0.005, 3.0, "time constant of the melt's first-order lag behind the commanded flow");
const W0: Parameter = linear("w0_mm", "mm", 0.05, 5.0, "steady-state width: commanded flow over speed");
const BLOB: Parameter =
    linear("blob_flow_mm2_s", "mm²/s", -200.0, 200.0, "flow excess per layer height at the start, from dwell pressure");

/// The bed is not parallel to the gantry: the layer height changes linearly along the
/// line, and by mass conservation the width changes as `1/h` (a trend along the line).
pub struct BedTilt;

impl Mechanism for BedTilt {
    fn name(&self) -> &'static str {
        "bed_tilt"
    }
    fn physics(&self) -> &'static str {
        "layer height linear along the bed, width ∝ 1/h by mass conservation"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 1] =
            [linear("width_change", "1", -0.5, 0.5, "relative width change from the line's start to its end")];
        &P
    }
}

/// The drive gear's runout (or its teeth) modulates the filament feed with a fixed
/// period in extruded filament, which at a steady bead section is a fixed period in
/// path length; one gear gives one amplitude, but its phase differs from line to line
/// (a per-line nuisance, estimated on half of a held-out line). The ripple
/// is the relative flow at the nozzle; the bead's smoothing over `smoothing_mm`
/// attenuates it by `sinc(π·smoothing/period)`.
pub struct GearEccentricity;

impl Mechanism for GearEccentricity {
    fn name(&self) -> &'static str {
        "gear_eccentricity"
    }
    fn physics(&self) -> &'static str {
        "drive-gear runout: flow ripple with a fixed period in extruded filament, phase free per line"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 2] = [
            linear("period_mm", "mm", 2.0, 60.0, "ripple period in path length"),
            linear("amplitude", "1", 0.0, 0.5, "relative flow ripple at the nozzle, one gear for all lines"),
        ];
        &P
    }
    fn nuisance(&self) -> Nuisance {
        Nuisance::PerGroup
    }
}

/// The extruder delivers less than commanded at high volumetric flow (filament slip,
/// the melt zone's capacity; cf. Klipper's `v + A·v² + B·v³` extrusion correction): a
/// relative loss `S·(v/v_ref)²` at commanded speed `v`, `v_ref` the data set's fastest
/// feed.
pub struct FlowSaturation;

impl Mechanism for FlowSaturation {
    fn name(&self) -> &'static str {
        "flow_saturation"
    }
    fn physics(&self) -> &'static str {
        "extruder delivers less at high flow: width loss S·(v/v_ref)², v_ref the fastest feed"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 1] =
            [linear("loss_at_fastest_feed", "1", 0.0, 0.9, "relative width loss at the fastest line's cruise flow")];
        &P
    }
}

/// The melt's stored volume is not proportional to its flow (Klipper/Kalico non-linear
/// pressure advance `K_lin·v + K_off·tanh(v/v_lin)`): the lag's time constant grows to
/// `τ + τ_off·sech²(q/(w0·v_lin))` at low flow.
pub struct NonlinearLag;

impl Mechanism for NonlinearLag {
    fn name(&self) -> &'static str {
        "nonlinear_lag"
    }
    fn physics(&self) -> &'static str {
        "lag constant depends on flow: τ + τ_off·sech²(v/v_lin) (non-linear pressure advance)"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 2] = [
            linear("lag_offset_s", "s", 0.0, 3.0, "extra time constant at low flow"),
            log("lag_speed_mm_s", "mm/s", 1.0, 500.0, "speed below which the extra lag acts"),
        ];
        &P
    }
}

/// Melt plus a compliant feed (Bowden tube, filament between gear and melt): part of
/// the flow follows the command with a second, slower time constant.
pub struct TwoStageLag;

impl Mechanism for TwoStageLag {
    fn name(&self) -> &'static str {
        "two_stage_lag"
    }
    fn physics(&self) -> &'static str {
        "melt plus feed compliance: a share f of the flow lags with a second time constant τ₂"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 2] = [
            log("tau_slow_s", "s", 0.02, 10.0, "time constant of the slow (compliant) path"),
            linear("slow_fraction", "1", 0.0, 1.0, "share of the flow through the slow path"),
        ];
        &P
    }
}

/// At low speed the excess melt builds height instead of width: the bead's extra width
/// saturates toward a largest excess `E`, `w0 + E·tanh((w − w0)/E)`.
pub struct WidthCap;

impl Mechanism for WidthCap {
    fn name(&self) -> &'static str {
        "width_cap"
    }
    fn physics(&self) -> &'static str {
        "excess melt at low speed builds height, not width: extra width saturates at E"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 1] =
            [log("max_excess_mm", "mm", 0.02, 20.0, "largest extra width over w0 the bead takes")];
        &P
    }
}

/// The printer's actual acceleration and feed differ from the G-code's by `r_a`, `r_F`
/// (paper 000 eq. 1); the extruder stays synchronised with the motion.
pub struct KinematicsDeviation;

impl Mechanism for KinematicsDeviation {
    fn name(&self) -> &'static str {
        "kinematics_deviation"
    }
    fn physics(&self) -> &'static str {
        "actual acceleration and feed are r_a·a0 and r_F·F0 (paper 000 eq. 1)"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 2] = [
            linear("r_a", "1", 0.9, 1.1, "actual over commanded acceleration"),
            linear("r_f", "1", 0.9, 1.1, "actual over commanded feed"),
        ];
        &P
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_names_and_bounds_agree() {
        let names: Vec<&str> = CANDIDATES.iter().map(|c| c.name()).collect();
        assert_eq!(
            names,
            [
                "bed_tilt",
                "gear_eccentricity",
                "flow_saturation",
                "nonlinear_lag",
                "two_stage_lag",
                "width_cap",
                "kinematics_deviation"
            ]
        );
        assert_eq!(candidate_index("width_cap"), Some(WIDTH_CAP));
        for c in CANDIDATES {
            assert!(!c.physics().is_empty());
            assert!(c.params().iter().all(|p| p.lo < p.hi && !p.meaning.is_empty()), "{}", c.name());
        }
        assert_eq!(CANDIDATES[GEAR_ECCENTRICITY].nuisance(), Nuisance::PerGroup);
        assert_eq!(candidate_index("none"), None);
    }
}
