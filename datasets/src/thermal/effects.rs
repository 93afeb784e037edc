//! The switchable extra effects of the virtual thermal printer (DESIGN §5.3, "switchable
//! extra effects for discovery tests"). Paper 003 assumes none of them: its capture
//! time model is eq. 28 with small zero-mean fluctuations, its deposition dynamics use
//! one identified τ (eq. 34, Sec. 3.2), and it reads widths from a fixed threshold
//! contour (Sec. 2.4) of a single layer. Each effect has a strength; an effect that is
//! not named is off (strength 0). All of them are recorded in `dataset.toml`.
//!
//! | name | strength means | where it acts |
//! |---|---|---|
//! | `camera_latency` | constant capture delay (s), added to every t_c | camera |
//! | `tau_mismatch` | actual τ = nominal τ·(1 + strength) | deposition |
//! | `heat_diffusion_widening` | lateral diffusivity × (1 + strength) | heat |
//! | `layer_heat_accumulation` | fraction of a layer's residual excess heat carried into the next layer's substrate | heat |
//! | `melt_squeeze_out` | fraction of the extruded volume that flows to the nearest free space instead of staying along the deposition direction | deposition |

use std::collections::BTreeMap;

use thiserror::Error;

/// Names of the known effects, in the order of the table above.
pub const KNOWN_EFFECTS: [&str; 5] =
    ["camera_latency", "tau_mismatch", "heat_diffusion_widening", "layer_heat_accumulation", "melt_squeeze_out"];

/// An effect setting that cannot be used.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EffectError {
    /// The name is not one of [`KNOWN_EFFECTS`].
    #[error("unknown effect `{name}`; known effects: {}", KNOWN_EFFECTS.join(", "))]
    Unknown {
        /// The name given.
        name: String,
    },
    /// The strength is outside the effect's range.
    #[error("effect `{name}`: strength {strength} is outside {range}")]
    OutOfRange {
        /// Effect name.
        name: String,
        /// The strength given.
        strength: f64,
        /// The allowed range, for the message.
        range: &'static str,
    },
}

/// Checked effect strengths (0 = off).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Effects {
    /// Constant capture delay added to every true capture time (s), in [0, 0.5].
    pub camera_latency_s: f64,
    /// Relative error of the printer's τ against the nominal, in (−1, 10].
    pub tau_mismatch: f64,
    /// Relative increase of the lateral diffusivity, in [0, 20].
    pub heat_diffusion_widening: f64,
    /// Fraction of residual heat carried into the next layer's substrate, in [0, 1].
    pub layer_heat_accumulation: f64,
    /// Fraction of each sample's volume that squeezes out to the nearest free space, in [0, 1].
    pub melt_squeeze_out: f64,
}

impl Effects {
    /// No extra effect.
    pub fn none() -> Self {
        Self::default()
    }

    /// Checks `(name, strength)` pairs; a name given twice keeps the last strength.
    pub fn from_pairs<'a>(pairs: impl IntoIterator<Item = (&'a str, f64)>) -> Result<Self, EffectError> {
        let mut effects = Self::none();
        for (name, strength) in pairs {
            effects.set(name, strength)?;
        }
        Ok(effects)
    }

    /// Sets one effect by name after checking its range.
    pub fn set(&mut self, name: &str, strength: f64) -> Result<(), EffectError> {
        let (slot, ok, range): (&mut f64, bool, &'static str) = match name {
            "camera_latency" => (&mut self.camera_latency_s, (0.0..=0.5).contains(&strength), "[0, 0.5] s"),
            "tau_mismatch" => (&mut self.tau_mismatch, strength > -1.0 && strength <= 10.0, "(-1, 10]"),
            "heat_diffusion_widening" => {
                (&mut self.heat_diffusion_widening, (0.0..=20.0).contains(&strength), "[0, 20]")
            }
            "layer_heat_accumulation" => (&mut self.layer_heat_accumulation, (0.0..=1.0).contains(&strength), "[0, 1]"),
            "melt_squeeze_out" => (&mut self.melt_squeeze_out, (0.0..=1.0).contains(&strength), "[0, 1]"),
            _ => return Err(EffectError::Unknown { name: name.to_string() }),
        };
        if !(strength.is_finite() && ok) {
            return Err(EffectError::OutOfRange { name: name.to_string(), strength, range });
        }
        *slot = strength;
        Ok(())
    }

    /// The effects that are on, by name, for the `dataset.toml` provenance.
    pub fn to_map(&self) -> BTreeMap<String, f64> {
        let all = [
            ("camera_latency", self.camera_latency_s),
            ("tau_mismatch", self.tau_mismatch),
            ("heat_diffusion_widening", self.heat_diffusion_widening),
            ("layer_heat_accumulation", self.layer_heat_accumulation),
            ("melt_squeeze_out", self.melt_squeeze_out),
        ];
        all.iter().filter(|(_, s)| *s != 0.0).map(|(n, s)| (n.to_string(), *s)).collect()
    }

    /// The printer's actual deposition time constant for a nominal τ (s).
    pub fn actual_tau_s(&self, nominal_tau_s: f64) -> f64 {
        nominal_tau_s * (1.0 + self.tau_mismatch)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_names_are_rejected_with_the_known_list() {
        let err = Effects::from_pairs([("bed_tilt", 0.1)]).unwrap_err();
        let text = err.to_string();
        assert!(text.contains("unknown effect `bed_tilt`"), "{text}");
        for name in KNOWN_EFFECTS {
            assert!(text.contains(name), "{text}");
        }
    }

    #[test]
    fn strengths_round_trip_through_the_map() {
        let effects = Effects::from_pairs([("tau_mismatch", 0.5), ("camera_latency", 0.02)]).unwrap();
        let map = effects.to_map();
        assert_eq!(map.len(), 2);
        assert_eq!(Effects::from_pairs(map.iter().map(|(k, v)| (k.as_str(), *v))).unwrap(), effects);
        assert!((effects.actual_tau_s(0.1) - 0.15).abs() < 1e-12);
    }

    #[test]
    fn out_of_range_strengths_are_rejected() {
        assert!(matches!(Effects::from_pairs([("layer_heat_accumulation", 1.5)]), Err(EffectError::OutOfRange { .. })));
        assert!(Effects::from_pairs([("tau_mismatch", f64::NAN)]).is_err());
        assert!(Effects::from_pairs([("tau_mismatch", -1.0)]).is_err());
    }
}
