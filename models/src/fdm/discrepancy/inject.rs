//! Hiding an effect in measured line widths by its physics (DESIGN §7), so that the
//! engine can be asked to find it — and so that a lab can learn how strong an effect
//! must be before the engine sees it on its own data.
//!
//! Each effect is the mechanism of the same name, applied to the measured widths:
//!
//! - `bed_tilt`, strength `c` (signed): the layer height grows linearly along the
//!   line, `h(x) = h̄·(1 + k(x/L − ½))`, and the width follows `1/h` by mass
//!   conservation, with `k = −c/(1 + c/2)` so that the width changes by `c` from the
//!   line's start to its end.
//! - `gear_eccentricity`, strength `A`: a flow ripple `1 + A·sin(2πx/P + φ)` with a
//!   fixed period `P` in path length (extruded filament at a steady section), its
//!   phase `φ` drawn per line, smoothed by the bead over `smoothing_mm` (a factor
//!   `sinc(π·smoothing/P)` on a sine).
//! - `flow_saturation`, strength `S`: the extruder delivers `1 − S·(v/v_ref)²` of the
//!   commanded flow at the line's own commanded speed `v(x)`, `v_ref` the data set's
//!   fastest cruise speed, so the width loss is `S` at the fastest line's cruise.
//! - `none`: the widths unchanged (the null).
//!
//! What was injected is returned as an [`Injection`], which the dataset writer keeps
//! in `truth/effect.toml` (read by evaluation only).

use std::f64::consts::PI;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::gear::attenuation;
use crate::fdm::line::MeasuredLine;

/// An effect that can be injected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Effect {
    /// Nothing (the null).
    None,
    /// Bed tilt along the line.
    BedTilt,
    /// Drive-gear runout ripple.
    GearEccentricity,
    /// Flow loss at high flow.
    FlowSaturation,
}

impl Effect {
    /// Every effect, `none` first.
    pub const ALL: [Effect; 4] = [Effect::None, Effect::BedTilt, Effect::GearEccentricity, Effect::FlowSaturation];

    /// The name, equal to the mechanism's (`none` for the null).
    pub fn name(&self) -> &'static str {
        match self {
            Self::None => "none",
            Self::BedTilt => "bed_tilt",
            Self::GearEccentricity => "gear_eccentricity",
            Self::FlowSaturation => "flow_saturation",
        }
    }

    /// The effect called `name`.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|e| e.name() == name)
    }

    /// Admissible strengths (inclusive), inside the mechanism's bounds.
    pub fn strength_range(&self) -> (f64, f64) {
        match self {
            Self::None => (0.0, 0.0),
            Self::BedTilt => (-0.4, 0.4),
            Self::GearEccentricity => (0.0, 0.4),
            Self::FlowSaturation => (0.0, 0.8),
        }
    }

    /// The name of the mechanism parameter that equals the strength.
    pub fn strength_parameter(&self) -> Option<&'static str> {
        match self {
            Self::None => None,
            Self::BedTilt => Some("width_change"),
            Self::GearEccentricity => Some("amplitude"),
            Self::FlowSaturation => Some("loss_at_fastest_feed"),
        }
    }
}

/// How an injection is made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InjectSettings {
    /// The bead's smoothing along the path (mm), as the model's.
    pub smoothing_mm: f64,
    /// The gear ripple's period (mm); `None` draws it log-uniformly in
    /// `[GEAR_PERIOD_DRAW_MM.0, GEAR_PERIOD_DRAW_MM.1]` from the seed.
    pub gear_period_mm: Option<f64>,
}

impl Default for InjectSettings {
    /// 0.5 mm smoothing (one nozzle diameter, paper 000 Table I), period drawn.
    fn default() -> Self {
        Self { smoothing_mm: 0.5, gear_period_mm: None }
    }
}

/// Range of drawn gear periods (mm): gear teeth to a small drive gear's runout.
pub const GEAR_PERIOD_DRAW_MM: (f64, f64) = (4.0, 40.0);

/// What was injected.
#[derive(Debug, Clone, PartialEq)]
pub struct Injection {
    /// The effect.
    pub effect: Effect,
    /// Its strength, in the unit of [`Effect::strength_parameter`].
    pub strength: f64,
    /// The seed of its random parts.
    pub seed: u64,
    /// The gear's period (mm), when injected.
    pub gear_period_mm: Option<f64>,
    /// The gear's phase per line (rad), in line order, when injected.
    pub gear_phases_rad: Vec<f64>,
    /// The saturation's reference speed (mm/s), when injected.
    pub reference_speed_mm_s: Option<f64>,
}

/// Why an injection was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InjectError {
    /// The strength is outside the effect's range.
    #[error("strength {strength} of `{effect}` is outside [{lo}, {hi}]")]
    Strength {
        /// The effect's name.
        effect: &'static str,
        /// The strength asked for.
        strength: f64,
        /// Smallest admissible.
        lo: f64,
        /// Largest admissible.
        hi: f64,
    },
    /// A gear period outside 2-60 mm.
    #[error("gear period {0} mm is outside [2, 60] mm")]
    Period(f64),
    /// The injected widths are not all positive.
    #[error("the injection leaves a non-positive width on line {0}")]
    Width(usize),
}

/// `lines` with `effect` of `strength` injected, and the record of what was injected.
pub fn inject(
    lines: &[MeasuredLine],
    effect: Effect,
    strength: f64,
    seed: u64,
    settings: &InjectSettings,
) -> Result<(Vec<MeasuredLine>, Injection), InjectError> {
    let (lo, hi) = effect.strength_range();
    if !(strength.is_finite() && (lo..=hi).contains(&strength)) {
        return Err(InjectError::Strength { effect: effect.name(), strength, lo, hi });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut record = Injection {
        effect,
        strength,
        seed,
        gear_period_mm: None,
        gear_phases_rad: Vec::new(),
        reference_speed_mm_s: None,
    };
    let factors: Vec<Box<dyn Fn(f64) -> f64>> = match effect {
        Effect::None => lines.iter().map(|_| Box::new(|_| 1.0) as Box<dyn Fn(f64) -> f64>).collect(),
        Effect::BedTilt => lines.iter().map(|l| tilt_factor(strength, l.nominal.length_mm)).collect(),
        Effect::GearEccentricity => {
            let period = gear_period(settings, &mut rng)?;
            let g = attenuation(period, settings.smoothing_mm);
            record.gear_period_mm = Some(period);
            record.gear_phases_rad = lines.iter().map(|_| rng.random::<f64>() * 2.0 * PI).collect();
            record
                .gear_phases_rad
                .iter()
                .map(|&phase| {
                    Box::new(move |x: f64| 1.0 + strength * g * (2.0 * PI * x / period + phase).sin())
                        as Box<dyn Fn(f64) -> f64>
                })
                .collect()
        }
        Effect::FlowSaturation => {
            let v_ref = lines.iter().map(|l| l.nominal.peak_speed_mm_s()).fold(0.0, f64::max);
            record.reference_speed_mm_s = Some(v_ref);
            lines
                .iter()
                .map(|l| {
                    let k = l.nominal;
                    Box::new(move |x: f64| 1.0 - strength * (k.speed_at_position(x) / v_ref).powi(2))
                        as Box<dyn Fn(f64) -> f64>
                })
                .collect()
        }
    };
    let injected = lines
        .iter()
        .zip(&factors)
        .enumerate()
        .map(|(i, (l, factor))| {
            let widths: Vec<f64> = l.positions_mm.iter().zip(&l.widths_mm).map(|(&x, &w)| w * factor(x)).collect();
            if widths.iter().any(|w| !(w.is_finite() && *w > 0.0)) {
                return Err(InjectError::Width(i));
            }
            Ok(MeasuredLine { widths_mm: widths, ..l.clone() })
        })
        .collect::<Result<_, _>>()?;
    Ok((injected, record))
}

/// Width factor of a bed tilt changing the width by `change` from start to end.
fn tilt_factor(change: f64, length_mm: f64) -> Box<dyn Fn(f64) -> f64> {
    let k = -change / (1.0 + change / 2.0);
    Box::new(move |x: f64| 1.0 / (1.0 + k * (x.clamp(0.0, length_mm) / length_mm - 0.5)))
}

fn gear_period(settings: &InjectSettings, rng: &mut ChaCha8Rng) -> Result<f64, InjectError> {
    let drawn = {
        let (lo, hi) = GEAR_PERIOD_DRAW_MM;
        (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp()
    };
    let period = settings.gear_period_mm.unwrap_or(drawn);
    if !(2.0..=60.0).contains(&period) {
        return Err(InjectError::Period(period));
    }
    Ok(period)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fdm::kinematics::LineKinematics;

    fn flat_lines() -> Vec<MeasuredLine> {
        [(400.0, 50.0), (800.0, 150.0)]
            .iter()
            .map(|&(a, f)| {
                let k = LineKinematics::paper_line(a, f).unwrap();
                let xs: Vec<f64> = (0..=1200).map(|i| i as f64 * 0.1).collect();
                MeasuredLine::new(k, xs, vec![0.8; 1201]).unwrap()
            })
            .collect()
    }

    #[test]
    fn each_effect_has_its_stated_size() {
        let lines = flat_lines();
        let settings = InjectSettings::default();
        let (tilted, _) = inject(&lines, Effect::BedTilt, -0.02, 1, &settings).unwrap();
        let w = &tilted[0].widths_mm;
        assert!((w[1200] / w[0] - 0.98).abs() < 1e-12, "{}", w[1200] / w[0]);
        let (sat, rec) = inject(&lines, Effect::FlowSaturation, 0.05, 1, &settings).unwrap();
        assert_eq!(rec.reference_speed_mm_s, Some(150.0));
        assert!((sat[1].widths_mm[600] / 0.8 - 0.95).abs() < 1e-12);
        // The slow line loses (50/150)² of it in its cruise.
        assert!((sat[0].widths_mm[600] / 0.8 - (1.0 - 0.05 / 9.0)).abs() < 1e-12);
        let fixed = InjectSettings { gear_period_mm: Some(10.0), ..settings };
        let (gear, rec) = inject(&lines, Effect::GearEccentricity, 0.02, 7, &fixed).unwrap();
        let peak = gear[0].widths_mm.iter().fold(0.0f64, |m, w| m.max(w / 0.8 - 1.0));
        assert!((peak - 0.02 * attenuation(10.0, 0.5)).abs() < 1e-4, "{peak}");
        assert_eq!(rec.gear_phases_rad.len(), 2);
        assert_ne!(rec.gear_phases_rad[0], rec.gear_phases_rad[1]);
        let (same, _) = inject(&lines, Effect::None, 0.0, 3, &settings).unwrap();
        assert_eq!(same, lines);
    }

    #[test]
    fn refuses_strengths_out_of_range_and_is_seeded() {
        let lines = flat_lines();
        let s = InjectSettings::default();
        assert!(matches!(inject(&lines, Effect::FlowSaturation, 0.95, 1, &s), Err(InjectError::Strength { .. })));
        assert!(inject(&lines, Effect::None, 0.1, 1, &s).is_err());
        let bad = InjectSettings { gear_period_mm: Some(100.0), ..s };
        assert!(matches!(inject(&lines, Effect::GearEccentricity, 0.02, 1, &bad), Err(InjectError::Period(_))));
        let a = inject(&lines, Effect::GearEccentricity, 0.02, 5, &s).unwrap();
        let b = inject(&lines, Effect::GearEccentricity, 0.02, 5, &s).unwrap();
        assert_eq!(a, b);
        assert_eq!(Effect::parse("bed_tilt"), Some(Effect::BedTilt));
    }
}
