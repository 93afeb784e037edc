//! The virtual FDM printer of paper 000's single lines (DESIGN §5.1): what a printed
//! line's two edges are, from its G-code kinematics and the printer's physics.
//!
//! ```text
//! motion      Marlin trapezoid from the jerk speed (8 mm/s) to F and back, a and F
//!             scaled by the printer's r_a, r_F (paper 000 eq. 1)
//! extrusion   τ dq/dt = w0·v(t) − q, q(0) = w0·v0 + b       (first-order lag, start blob b)
//! width       w = q/v, w ← w0 + E·tanh((w − w0)/E) above w0   (mass conservation, capped at low speed)
//!             box-smoothed over one nozzle diameter along the path
//! height      w ← w/(1 + η), η ~ N(0, s²) drawn per line        (the bed's unevenness
//!             under each line gives it its own first-layer height; mass conservation)
//! wander      w ← w·(1 + δ(x)), δ an Ornstein–Uhlenbeck process in path length
//!             (filament diameter and melt temperature drift: slow swells)
//! edges       left = w/2 + e_l(x), right = w/2 + e_r(x), e_l, e_r independent
//!             Ornstein–Uhlenbeck processes (edge roughness)
//! ```
//!
//! The lag, the blob and the cap are [`super::discrepancy::forward`]'s forward model
//! with the mechanisms the discrepancy engine names on the printer's real lines
//! (`fdm.discrepancy` on `data/fsu-linewidth`: the width cap on the Taz 5, nothing
//! beyond the lag on the Taz 6), so the five phases of paper 000 emerge from the
//! physics: the blob falls as the head accelerates (p1), the lag thins the line while
//! accelerating (p2, p3), steady width in the cruise (p4), the lag widens it while
//! decelerating, up to the cap (p5). No phase is drawn in.
//!
//! [`calibrate`] fits a profile to measured lines; [`PrinterProfile::taz5`] and
//! [`PrinterProfile::taz6`] are its result on the real data (checked by a test that
//! refits them). The switchable [`Effects`] carry the names of the engine's mechanisms
//! (`bed_tilt`, `gear_eccentricity`, `flow_saturation`) and their physics is the
//! mechanisms' own; `camera_scale_error` acts in the camera, not here.

use std::f64::consts::PI;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::discrepancy::forward::{widths, LineSetting, Scratch, Theta};
use super::discrepancy::gear::{self, attenuation};
use super::kinematics::LineKinematics;

mod calibrate;

pub use calibrate::{calibrate, held_out_agreement, HeldOutAgreement};

/// Spacing of the printed line's truth (mm): 2 px at 40 px/mm.
pub const TRUTH_STEP_MM: f64 = 0.05;
/// Bead smoothing along the path (mm): one 0.5 mm nozzle diameter (paper 000 Table I).
pub const SMOOTHING_MM: f64 = 0.5;
/// Layer height of the single lines (mm). Paper 000 does not state it; half the 0.5 mm
/// nozzle is the usual choice. It enters only the metadata and the tilt's physics
/// through the relative change `Δh/h`.
pub const LAYER_HEIGHT_MM: f64 = 0.25;

/// An Ornstein–Uhlenbeck process along the path: standard deviation and correlation
/// length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wander {
    /// Standard deviation (relative for the width wander, mm for an edge).
    pub sd: f64,
    /// Correlation length along the path (mm).
    pub length_mm: f64,
}

/// A virtual printer's physics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrinterProfile {
    /// Lag, steady width, start blob and width cap (other mechanisms neutral), with
    /// the printer's `r_a`, `r_F`.
    pub theta: Theta,
    /// Whether the line starts with a dwell blob.
    pub has_start_blob: bool,
    /// Relative deviation of each line's layer height (the bed's unevenness).
    pub line_height_sd: f64,
    /// Relative width wander (slow swells).
    pub wander: Wander,
    /// Each edge's roughness (mm).
    pub edge: Wander,
}

impl PrinterProfile {
    /// The Taz 5: [`calibrate`] on the real Taz 5 lines (lag, blob and width cap).
    pub fn taz5() -> Self {
        Self {
            theta: Theta { max_excess_mm: 0.167_71, ..Theta::lag(0.094_99, 0.783_98, 12.934) },
            has_start_blob: true,
            line_height_sd: 0.019_497,
            wander: Wander { sd: 0.051_513, length_mm: 9.172_0 },
            edge: Wander { sd: 0.018_190, length_mm: 0.483_77 },
        }
    }

    /// The Taz 6: [`calibrate`] on the real Taz 6 lines (lag only, no blob).
    pub fn taz6() -> Self {
        Self {
            theta: Theta::lag(0.024_463, 0.750_74, 0.0),
            has_start_blob: false,
            line_height_sd: 0.119_02,
            wander: Wander { sd: 0.066_039, length_mm: 13.042 },
            edge: Wander { sd: 0.015_249, length_mm: 0.569_57 },
        }
    }

    /// The profile called `name` (`taz5`, `taz6`).
    pub fn named(name: &str) -> Option<Self> {
        match name {
            "taz5" => Some(Self::taz5()),
            "taz6" => Some(Self::taz6()),
            _ => None,
        }
    }
}

/// The names of the printer profiles.
pub const PRINTERS: [&str; 2] = ["taz5", "taz6"];

/// Switchable extra effects, each named as the discrepancy mechanism it is (default
/// none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Effects {
    /// `bed_tilt`: relative width change from the line's start to its end, by the
    /// layer height changing linearly along the bed (mass conservation, `w ∝ 1/h`).
    pub bed_tilt: f64,
    /// `gear_eccentricity`: relative amplitude of the drive gear's flow ripple, with a
    /// fixed period in path length and a random phase per line.
    pub gear_eccentricity: f64,
    /// The gear ripple's period in path length (mm).
    pub gear_period_mm: f64,
    /// `flow_saturation`: relative width loss at the fastest line's cruise flow,
    /// growing as `(v/v_ref)²` (filament slip, melt capacity).
    pub flow_saturation: f64,
    /// `camera_scale_error`: the camera's true px/mm over the recorded one, minus 1
    /// (applied by the camera).
    pub camera_scale_error: f64,
}

impl Default for Effects {
    fn default() -> Self {
        Self {
            bed_tilt: 0.0,
            gear_eccentricity: 0.0,
            gear_period_mm: 12.0,
            flow_saturation: 0.0,
            camera_scale_error: 0.0,
        }
    }
}

/// The effect names and their admissible strengths.
pub const EFFECTS: [(&str, f64, f64); 4] = [
    ("bed_tilt", -0.4, 0.4),
    ("gear_eccentricity", 0.0, 0.4),
    ("flow_saturation", 0.0, 0.8),
    ("camera_scale_error", -0.2, 0.2),
];

/// Why effects were refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    /// Not an effect of this printer.
    #[error("unknown effect `{0}` (known: bed_tilt, gear_eccentricity, flow_saturation, camera_scale_error)")]
    Unknown(String),
    /// Outside its range.
    #[error("strength {strength} of `{name}` is outside [{lo}, {hi}]")]
    Strength {
        /// The effect.
        name: String,
        /// The strength asked for.
        strength: f64,
        /// Smallest admissible.
        lo: f64,
        /// Largest admissible.
        hi: f64,
    },
}

impl Effects {
    /// Checked effects from `(name, strength)` pairs; a name may appear once.
    pub fn from_pairs<'a>(pairs: impl IntoIterator<Item = (&'a str, f64)>) -> Result<Self, EffectError> {
        let mut effects = Self::default();
        for (name, strength) in pairs {
            let &(_, lo, hi) =
                EFFECTS.iter().find(|(n, ..)| *n == name).ok_or_else(|| EffectError::Unknown(name.into()))?;
            if !(strength.is_finite() && (lo..=hi).contains(&strength)) {
                return Err(EffectError::Strength { name: name.into(), strength, lo, hi });
            }
            match name {
                "bed_tilt" => effects.bed_tilt = strength,
                "gear_eccentricity" => effects.gear_eccentricity = strength,
                "flow_saturation" => effects.flow_saturation = strength,
                _ => effects.camera_scale_error = strength,
            }
        }
        Ok(effects)
    }

    /// The non-zero effects as `(name, strength)`, in [`EFFECTS`] order.
    pub fn active(&self) -> Vec<(&'static str, f64)> {
        let values = [self.bed_tilt, self.gear_eccentricity, self.flow_saturation, self.camera_scale_error];
        EFFECTS.iter().zip(values).filter(|(_, v)| *v != 0.0).map(|((n, ..), v)| (*n, v)).collect()
    }
}

/// One printed line: its two edges every [`TRUTH_STEP_MM`] of path.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintedLine {
    /// Positions along the path (mm), `0, Δ, 2Δ, … ≤ L`.
    pub positions_mm: Vec<f64>,
    /// Distance of the left edge from the path (mm).
    pub left_mm: Vec<f64>,
    /// Distance of the right edge from the path (mm).
    pub right_mm: Vec<f64>,
}

impl PrintedLine {
    /// The true width at each position (mm).
    pub fn widths_mm(&self) -> Vec<f64> {
        self.left_mm.iter().zip(&self.right_mm).map(|(l, r)| l + r).collect()
    }
}

/// Linear interpolation on the truth grid of `samples` values ([`TRUTH_STEP_MM`] apart
/// from 0): the two samples around `x_mm` and the weight of the second, held at the
/// first and last sample outside the grid. `value = v[i] + f·(v[j] − v[i])`.
pub fn truth_grid_weights(samples: usize, x_mm: f64) -> (usize, usize, f64) {
    let last = samples - 1;
    let u = (x_mm / TRUTH_STEP_MM).max(0.0);
    let i = (u.floor() as usize).min(last.saturating_sub(1));
    (i, (i + 1).min(last), (u - i as f64).min(1.0))
}

/// Why a line could not be printed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PrintError {
    /// The physics gave no valid width (a parameter outside physics).
    #[error("the printer's parameters give no valid width profile for this line")]
    NoWidth,
    /// An edge crossed the path (roughness larger than the half width).
    #[error("the printed line has a non-positive half width at {position_mm:.2} mm")]
    Thin {
        /// Where.
        position_mm: f64,
    },
}

/// Prints one line of nominal kinematics `kin` with `effects`; `v_ref_mm_s` is the
/// fastest cruise speed of the set (the saturation's reference), `rng` this line's
/// random stream (gear phase, wander, roughness).
pub fn print_line(
    profile: &PrinterProfile,
    effects: &Effects,
    kin: &LineKinematics,
    v_ref_mm_s: f64,
    rng: &mut ChaCha8Rng,
) -> Result<PrintedLine, PrintError> {
    let n = (kin.length_mm / TRUTH_STEP_MM + 1e-9).floor() as usize + 1;
    let positions_mm: Vec<f64> = (0..n).map(|i| i as f64 * TRUTH_STEP_MM).collect();
    let theta =
        Theta { tilt_width_change: effects.bed_tilt, saturation_loss: effects.flow_saturation, ..profile.theta };
    let setting = LineSetting { smoothing_mm: SMOOTHING_MM, v_ref_mm_s };
    let mut w = vec![0.0; n];
    if !widths(&theta, kin, &setting, &positions_mm, &mut Scratch::default(), &mut w) {
        return Err(PrintError::NoWidth);
    }
    // Drawn whether or not the gear ripples, so that switching an effect on leaves the
    // line's other random parts as they were (the same seed prints the same line).
    let phase = rng.random_range(0.0..2.0 * PI);
    if effects.gear_eccentricity != 0.0 {
        let g = attenuation(effects.gear_period_mm, SMOOTHING_MM);
        gear::apply(&positions_mm, &mut w, effects.gear_period_mm, g, effects.gear_eccentricity, phase);
    }
    let height = 1.0 + profile.line_height_sd * Normal::new(0.0, 1.0).expect("unit normal").sample(rng);
    let wander = ornstein_uhlenbeck(n, profile.wander, rng);
    let (e_left, e_right) = (ornstein_uhlenbeck(n, profile.edge, rng), ornstein_uhlenbeck(n, profile.edge, rng));
    let half: Vec<f64> = w.iter().zip(&wander).map(|(w, d)| 0.5 * w * (1.0 + d) / height).collect();
    let left_mm: Vec<f64> = half.iter().zip(&e_left).map(|(h, e)| h + e).collect();
    let right_mm: Vec<f64> = half.iter().zip(&e_right).map(|(h, e)| h + e).collect();
    if let Some(i) = left_mm.iter().zip(&right_mm).position(|(l, r)| !(*l > 0.0 && *r > 0.0)) {
        return Err(PrintError::Thin { position_mm: positions_mm[i] });
    }
    Ok(PrintedLine { positions_mm, left_mm, right_mm })
}

/// `n` samples `TRUTH_STEP_MM` apart of a stationary OU process (exact AR(1) steps).
fn ornstein_uhlenbeck(n: usize, process: Wander, rng: &mut ChaCha8Rng) -> Vec<f64> {
    if process.sd == 0.0 {
        return vec![0.0; n];
    }
    let rho = (-TRUTH_STEP_MM / process.length_mm).exp();
    let innovation = process.sd * (1.0 - rho * rho).sqrt();
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let mut x = process.sd * normal.sample(rng);
    (0..n)
        .map(|_| {
            let now = x;
            x = rho * x + innovation * normal.sample(rng);
            now
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::calibrate::rms;
    use super::*;

    /// A profile without wander and roughness: its lines are the deterministic physics.
    fn quiet(profile: PrinterProfile) -> PrinterProfile {
        PrinterProfile {
            line_height_sd: 0.0,
            wander: Wander { sd: 0.0, length_mm: 1.0 },
            edge: Wander { sd: 0.0, length_mm: 1.0 },
            ..profile
        }
    }

    fn rng(seed: u64) -> ChaCha8Rng {
        rand::SeedableRng::seed_from_u64(seed)
    }

    fn line(accel: f64, feed: f64) -> LineKinematics {
        LineKinematics::paper_line(accel, feed).unwrap()
    }

    #[test]
    fn a_clean_taz5_line_has_the_five_phases_from_its_physics() {
        // No roughness, no wander: the blob at the start falls (p1), the width dips
        // below w0 while accelerating (p2-p3), is w0 in the cruise (p4) and rises
        // while decelerating, capped at w0 + E (p5).
        let profile = quiet(PrinterProfile::taz5());
        let kin = line(800.0, 150.0);
        let printed = print_line(&profile, &Effects::default(), &kin, 150.0, &mut rng(1)).unwrap();
        let w = printed.widths_mm();
        let at = |x: f64| w[(x / TRUTH_STEP_MM).round() as usize];
        let w0 = profile.theta.w0_mm;
        assert!(at(0.0) > w0 * 1.1 && at(0.0) > at(0.3), "start blob {} {}", at(0.0), at(0.3));
        let dip = (20..400).map(|i| w[i]).fold(f64::INFINITY, f64::min);
        assert!(dip < w0 * 0.97, "acceleration dip {dip}");
        assert!((at(100.0) - w0).abs() < 2e-3, "steady {}", at(100.0));
        let bulge = w[w.len() - 30..].iter().copied().fold(0.0, f64::max);
        assert!(bulge > w0 * 1.1 && bulge <= w0 + profile.theta.max_excess_mm + 1e-9, "end bulge {bulge}");
    }

    #[test]
    fn tilt_is_a_linear_trend_and_the_gear_has_its_period() {
        let profile = quiet(PrinterProfile::taz6());
        let kin = line(600.0, 100.0);
        let clean = print_line(&profile, &Effects::default(), &kin, 150.0, &mut rng(3)).unwrap().widths_mm();
        let tilted =
            print_line(&profile, &Effects { bed_tilt: 0.1, ..Effects::default() }, &kin, 150.0, &mut rng(3)).unwrap();
        let ratio: Vec<f64> = tilted.widths_mm().iter().zip(&clean).map(|(t, c)| t / c).collect();
        let (first, last) = (ratio[0], ratio[ratio.len() - 1]);
        assert!((last / first - 1.1).abs() < 1e-9, "end to end {}", last / first);
        let geared = Effects { gear_eccentricity: 0.05, gear_period_mm: 8.0, ..Effects::default() };
        let ripple: Vec<f64> = print_line(&profile, &geared, &kin, 150.0, &mut rng(3))
            .unwrap()
            .widths_mm()
            .iter()
            .zip(&clean)
            .map(|(g, c)| g / c - 1.0)
            .collect();
        let period_samples = (8.0 / TRUTH_STEP_MM) as usize;
        let shifted = ripple.iter().zip(&ripple[period_samples..]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let amplitude = ripple.iter().copied().fold(0.0, f64::max);
        assert!(shifted < 1e-9 && (amplitude - 0.05 * attenuation(8.0, SMOOTHING_MM)).abs() < 1e-4);
    }

    #[test]
    fn saturation_takes_its_loss_at_the_fastest_cruise_and_less_below() {
        let profile = quiet(PrinterProfile::taz6());
        let effects = Effects { flow_saturation: 0.1, ..Effects::default() };
        for (feed, expected) in [(150.0, 0.9), (75.0, 0.975)] {
            let kin = line(800.0, feed);
            let clean = print_line(&profile, &Effects::default(), &kin, 150.0, &mut rng(5)).unwrap().widths_mm();
            let lossy = print_line(&profile, &effects, &kin, 150.0, &mut rng(5)).unwrap().widths_mm();
            let mid = clean.len() / 2;
            assert!((lossy[mid] / clean[mid] - expected).abs() < 1e-9, "{feed}: {}", lossy[mid] / clean[mid]);
        }
    }

    #[test]
    fn the_same_seed_prints_the_same_edges_and_roughness_has_its_statistics() {
        let profile = PrinterProfile { edge: Wander { sd: 0.01, length_mm: 0.3 }, ..quiet(PrinterProfile::taz6()) };
        let kin = line(400.0, 50.0);
        let a = print_line(&profile, &Effects::default(), &kin, 150.0, &mut rng(9)).unwrap();
        assert_eq!(a, print_line(&profile, &Effects::default(), &kin, 150.0, &mut rng(9)).unwrap());
        assert_ne!(a, print_line(&profile, &Effects::default(), &kin, 150.0, &mut rng(10)).unwrap());
        let d: Vec<f64> = a.left_mm.iter().zip(&a.right_mm).map(|(l, r)| l - r).collect();
        let sd = rms(&d) / 2f64.sqrt();
        assert!((sd - 0.01).abs() < 0.002, "edge sd {sd}");
    }

    #[test]
    fn effects_parse_by_name_and_refuse_what_is_not_physics() {
        let e = Effects::from_pairs([("bed_tilt", -0.02), ("camera_scale_error", 0.01)]).unwrap();
        assert_eq!(e.active(), vec![("bed_tilt", -0.02), ("camera_scale_error", 0.01)]);
        assert!(matches!(Effects::from_pairs([("gravity", 1.0)]), Err(EffectError::Unknown(_))));
        assert!(matches!(Effects::from_pairs([("flow_saturation", 0.9)]), Err(EffectError::Strength { .. })));
        assert!(matches!(Effects::from_pairs([("bed_tilt", f64::NAN)]), Err(EffectError::Strength { .. })));
    }
}
