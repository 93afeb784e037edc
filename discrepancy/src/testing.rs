//! A small synthetic domain for the engine's own tests: groups of samples `y(x)` on
//! `x ∈ [0, 1]` with AR(1) noise (correlated within a group, as widths along a line
//! are), a constant baseline, and three candidates — a linear trend, a quadratic
//! bow, and a ripple of fixed frequency whose phase is free per group (a nuisance).
//! Fits go through [`crate::least_squares::minimize`], the ripple's per-group
//! amplitudes are profiled out by a 2 × 2 least squares inside the residuals.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::least_squares::{minimize, LmSettings};
use crate::mechanism::{Mechanism, Nuisance, Parameter, Scale};
use crate::model::{Group, Model, ModelError, Variable, VariableKind};

pub(crate) const RIPPLE_CYCLES: f64 = 3.0;

pub(crate) struct Samples {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
}

impl Group for Samples {
    fn observed(&self) -> &[f64] {
        &self.y
    }
}

const fn param(name: &'static str, lo: f64, hi: f64) -> Parameter {
    Parameter { name, unit: "1", lo, hi, meaning: "test parameter", scale: Scale::Linear }
}

struct Trend;
struct Bow;
struct Ripple;

impl Mechanism for Trend {
    fn name(&self) -> &'static str {
        "trend"
    }
    fn physics(&self) -> &'static str {
        "y gains s·(x − ½)"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 1] = [param("slope", -10.0, 10.0)];
        &P
    }
}

impl Mechanism for Bow {
    fn name(&self) -> &'static str {
        "bow"
    }
    fn physics(&self) -> &'static str {
        "y gains q·((x − ½)² − 1/12)"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 1] = [param("curvature", -50.0, 50.0)];
        &P
    }
}

impl Mechanism for Ripple {
    fn name(&self) -> &'static str {
        "ripple"
    }
    fn physics(&self) -> &'static str {
        "y gains A sin(2π·3x + φ_g), φ_g free per group"
    }
    fn params(&self) -> &'static [Parameter] {
        static P: [Parameter; 1] = [param("amplitude", 0.0, 10.0)];
        &P
    }
    fn nuisance(&self) -> Nuisance {
        Nuisance::PerGroup
    }
}

pub(crate) const TREND: usize = 0;
pub(crate) const BOW: usize = 1;
pub(crate) const RIPPLE: usize = 2;

static CANDIDATES: [&dyn Mechanism; 3] = [&Trend, &Bow, &Ripple];
static VARIABLES: [Variable; 1] = [Variable { name: "x", unit: "1", kind: VariableKind::Continuous }];
static LEVEL: [Parameter; 1] = [param("level", -100.0, 100.0)];

pub(crate) struct Toy;

/// Fitted toy: `(level, slope, curvature)` and the ripple amplitude (RMS of the
/// per-group amplitudes of the training groups).
#[derive(Clone, Debug)]
pub(crate) struct ToyFit {
    active: Vec<usize>,
    shared: [f64; 3],
    amplitude: f64,
}

fn shape(c: usize, x: f64) -> f64 {
    match c {
        TREND => x - 0.5,
        BOW => (x - 0.5).powi(2) - 1.0 / 12.0,
        _ => 0.0,
    }
}

impl ToyFit {
    /// Whether candidate `c` is active in this fit.
    pub(crate) fn has(&self, c: usize) -> bool {
        self.active.contains(&c)
    }

    fn smooth_part(&self, x: f64) -> f64 {
        self.shared[0] + self.shared[1] * shape(TREND, x) + self.shared[2] * shape(BOW, x)
    }
}

/// Per-group ripple coefficients of residual `r` at `x` on the samples `use_i`.
fn ripple_coefficients(x: &[f64], r: &[f64], use_i: impl Fn(usize) -> bool) -> (f64, f64) {
    let (mut ss, mut sc, mut cc, mut sr, mut cr) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for i in (0..x.len()).filter(|&i| use_i(i)) {
        let (s, c) = (2.0 * std::f64::consts::PI * RIPPLE_CYCLES * x[i]).sin_cos();
        ss += s * s;
        sc += s * c;
        cc += c * c;
        sr += s * r[i];
        cr += c * r[i];
    }
    let det = ss * cc - sc * sc;
    if det.abs() < 1e-12 {
        return (0.0, 0.0);
    }
    ((cc * sr - sc * cr) / det, (ss * cr - sc * sr) / det)
}

impl Model for Toy {
    type Group = Samples;
    type Fit = ToyFit;

    fn name(&self) -> &'static str {
        "constant"
    }
    fn params(&self) -> &'static [Parameter] {
        &LEVEL
    }
    fn candidates(&self) -> &[&'static dyn Mechanism] {
        &CANDIDATES
    }
    fn variables(&self) -> &[Variable] {
        &VARIABLES
    }
    fn variable_values(&self, group: &Samples, _variable: usize) -> Vec<f64> {
        group.x.clone()
    }

    fn fit(&self, active: &[usize], train: &[&Samples], warm: Option<&ToyFit>) -> Result<ToyFit, ModelError> {
        let ripple = active.contains(&RIPPLE);
        let on = |c: usize| active.contains(&c);
        let m: usize = train.iter().map(|g| g.y.len()).sum();
        let start = warm.map_or([0.0; 3], |w| w.shared);
        let (lo, hi) = ([-100.0, -10.0, -50.0], [100.0, 10.0, 50.0]);
        let mut amp_sq = 0.0;
        let residuals = |p: &[f64], out: &mut [f64]| {
            let fit = ToyFit {
                active: active.to_vec(),
                shared: [p[0], if on(TREND) { p[1] } else { 0.0 }, if on(BOW) { p[2] } else { 0.0 }],
                amplitude: 0.0,
            };
            let mut k = 0;
            for g in train {
                let r: Vec<f64> = g.x.iter().zip(&g.y).map(|(x, y)| y - fit.smooth_part(*x)).collect();
                let (a, b) = if ripple { ripple_coefficients(&g.x, &r, |_| true) } else { (0.0, 0.0) };
                for (i, x) in g.x.iter().enumerate() {
                    let (s, c) = (2.0 * std::f64::consts::PI * RIPPLE_CYCLES * x).sin_cos();
                    out[k] = r[i] - a * s - b * c;
                    k += 1;
                }
            }
            true
        };
        let sol = minimize(residuals, &start, &lo, &hi, m, &LmSettings::default())
            .ok_or_else(|| ModelError::Fit("toy fit".into()))?;
        let shared = [sol.x[0], if on(TREND) { sol.x[1] } else { 0.0 }, if on(BOW) { sol.x[2] } else { 0.0 }];
        let mut fit = ToyFit { active: active.to_vec(), shared, amplitude: 0.0 };
        if ripple {
            for g in train {
                let r: Vec<f64> = g.x.iter().zip(&g.y).map(|(x, y)| y - fit.smooth_part(*x)).collect();
                let (a, b) = ripple_coefficients(&g.x, &r, |_| true);
                amp_sq += a * a + b * b;
            }
            fit.amplitude = (amp_sq / train.len() as f64).sqrt();
        }
        Ok(fit)
    }

    fn predict(&self, fit: &ToyFit, group: &Samples, calibrate: Option<&[bool]>) -> Result<Vec<f64>, ModelError> {
        let smooth: Vec<f64> = group.x.iter().map(|&x| fit.smooth_part(x)).collect();
        if !fit.active.contains(&RIPPLE) {
            return Ok(smooth);
        }
        let mask = calibrate.ok_or_else(|| ModelError::Predict("ripple needs calibration samples".into()))?;
        let r: Vec<f64> = group.y.iter().zip(&smooth).map(|(y, s)| y - s).collect();
        let (a, b) = ripple_coefficients(&group.x, &r, |i| mask[i]);
        Ok(group
            .x
            .iter()
            .zip(&smooth)
            .map(|(x, s)| {
                let (sn, cs) = (2.0 * std::f64::consts::PI * RIPPLE_CYCLES * x).sin_cos();
                s + a * sn + b * cs
            })
            .collect())
    }

    fn estimates(&self, fit: &ToyFit) -> Vec<f64> {
        let mut out = vec![fit.shared[0]];
        for &c in &fit.active {
            out.push(match c {
                TREND => fit.shared[1],
                BOW => fit.shared[2],
                _ => fit.amplitude,
            });
        }
        out
    }
}

/// Hidden effects of one synthetic data set.
#[derive(Clone, Copy, Default)]
pub(crate) struct Hidden {
    pub slope: f64,
    pub curvature: f64,
    pub ripple_amplitude: f64,
}

/// `groups` groups of `n` samples with AR(1) noise (σ, lag-one correlation ρ) and the
/// hidden effects; the ripple's phase is drawn per group.
pub(crate) fn draw(groups: usize, n: usize, sigma: f64, rho: f64, hidden: Hidden, seed: u64) -> Vec<Samples> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..groups)
        .map(|_| {
            let phase = rng.random::<f64>() * std::f64::consts::TAU;
            let level = 1.0;
            let mut e = 0.0;
            let x: Vec<f64> = (0..n).map(|i| (i as f64 + 0.5) / n as f64).collect();
            let y = x
                .iter()
                .map(|&xi| {
                    let z: f64 = (0..12).map(|_| rng.random::<f64>()).sum::<f64>() - 6.0;
                    e = rho * e + (1.0 - rho * rho).sqrt() * sigma * z;
                    level
                        + hidden.slope * shape(TREND, xi)
                        + hidden.curvature * shape(BOW, xi)
                        + hidden.ripple_amplitude * (std::f64::consts::TAU * RIPPLE_CYCLES * xi + phase).sin()
                        + e
                })
                .collect();
            Samples { x, y }
        })
        .collect()
}
