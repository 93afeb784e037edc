//! The five-phase piecewise width model of paper 000 (Ren et al. 2021, Sec. II-A, eqs 2-3).
//!
//! With nominal time `t`, nozzle speed `v(t)`, actual acceleration `a` and the speed
//! `F` at the end of the acceleration ramp:
//!
//! ```text
//! p1  0 < t ≤ bp1     w = 1 / (α1·v(t) + α2)
//! p2  bp1 < t ≤ bp2   w = β·sqrt((t − bp1)·v(t)·a) + w(bp1)
//! p3  bp2 < t ≤ bp3   w = γ·sqrt((t − bp2)·v(t)) + w(bp2)
//! p4  bp3 < t ≤ bp4   w = c
//! p5  bp4 < t         w = ρ·log(F / v(t)) + w(bp4)
//! bp1 = c0 + c1·a^c2                                   (eq. 2)
//! ```
//!
//! Readings of the text where it is ambiguous (all ours, stated here once):
//! - bp1 and the other breakpoints are times (the model is written in time, Sec. II-A);
//!   the power law of eq. 2 maps the actual acceleration to the bp1 time.
//! - `w(bp_{i-1})` is the model's own value at the previous breakpoint (continuity), so
//!   the prediction is one connected curve (prediction step 6).
//! - bp3 is where p3 first reaches `c`: `bp3 = bp2 + ((c − w(bp2))/γ)² / F`, capped at
//!   bp4. If `w(bp2) ≥ c` p4 starts at bp2; if `γ ≤ 0` p3 lasts until bp4 and p5 starts
//!   from p3's value at bp4 (`w(bp4) = c` only when the plateau was reached).
//! - Special case "bp1 after bp2": p2 is dropped and p3 starts at bp1 from `w(bp1)`,
//!   i.e. `(t − bp2)` and `w(bp2)` become `(t − max(bp1, bp2))` and `w(max(bp1, bp2))`
//!   (otherwise the curve would jump at bp1). bp1 is clamped to `[0, bp4]`.
//! - Special case "no cruise": bp2 = bp4, only p1, p2 and p5 remain, and `F` in p5 is the
//!   peak speed actually reached (the ramp's end speed), which keeps p5 continuous.
//! - No start blob (Taz 6, Sec. III-B): p1 and bp1 are removed; p2 starts at `t = 0`
//!   from a fitted intercept `w_start` (`w(bp1) = w_start`, `bp1 = 0`): the paper says
//!   only that "bp1 can be ignored", and p2 needs a starting width.

use super::kinematics::LineKinematics;

/// The phases of eq. 3.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WidthPhase {
    /// p1, pre-action: the start blob thins as the head accelerates.
    P1PreAction,
    /// p2, warm-up I: still accelerating, the width grows again.
    P2WarmUp,
    /// p3, warm-up II: at feed, the width keeps growing towards `c`.
    P3WarmUpAtFeed,
    /// p4, steady: nominal width `c`.
    P4Steady,
    /// p5, slow-down: decelerating, the width grows.
    P5SlowDown,
}

/// The coefficients of eq. 3 (`θ = {α1, α2, β, γ, c, ρ}`) plus the start width used
/// when there is no start blob.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PiecewiseCoefficients {
    /// p1 slope of the reciprocal width against speed (s/mm²).
    pub alpha1: f64,
    /// p1 intercept of the reciprocal width (1/mm).
    pub alpha2: f64,
    /// p2 growth coefficient.
    pub beta: f64,
    /// p3 growth coefficient.
    pub gamma: f64,
    /// Nominal (steady) width `c` (mm).
    pub c_mm: f64,
    /// p5 coefficient of `log(F/v)` (mm).
    pub rho: f64,
    /// Width at `t = 0` when the printer has no start blob (mm); unused otherwise.
    pub w_start_mm: f64,
}

impl PiecewiseCoefficients {
    /// Names of the transferable parameters (Sec. III-B): `β, γ, c, ρ`.
    pub const TRANSFER_NAMES: [&'static str; 4] = ["beta", "gamma", "c_mm", "rho"];

    /// The transferable vector `(β, γ, c, ρ)` of Sec. III-B.
    pub fn transfer_vector(&self) -> [f64; 4] {
        [self.beta, self.gamma, self.c_mm, self.rho]
    }

    /// p1 width `1/(α1·v + α2)` (mm).
    pub fn p1_width_mm(&self, speed_mm_s: f64) -> f64 {
        1.0 / (self.alpha1 * speed_mm_s + self.alpha2)
    }
}

/// The bp1 power law of eq. 2: `bp1 = c0 + c1·a^c2` (bp1 in s, `a` in mm/s²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bp1PowerLaw {
    /// Offset `c0` (s).
    pub c0_s: f64,
    /// Scale `c1`.
    pub c1: f64,
    /// Exponent `c2`.
    pub c2: f64,
}

impl Bp1PowerLaw {
    /// bp1 time (s) for an actual acceleration (mm/s²).
    pub fn bp1_s(&self, accel_mm_s2: f64) -> f64 {
        self.c0_s + self.c1 * accel_mm_s2.powf(self.c2)
    }

    /// Least-squares fit of eq. 2 to `(a, bp1)` pairs: a grid over `c2` (from `c2_min`
    /// to `c2_max` in steps of `c2_step`, skipping `c2 = 0` where `a^c2` is collinear with
    /// `c0`) with the closed-form linear least squares for `c0, c1` at each `c2`. With one
    /// distinct acceleration bp1 is the mean (`c1 = 0`); with two, `c2` is fixed at
    /// `c2_fallback`. Returns `None` for no points.
    pub fn fit(accels_mm_s2: &[f64], bp1_s: &[f64], c2_grid: (f64, f64, f64), c2_fallback: f64) -> Option<Self> {
        if accels_mm_s2.is_empty() || accels_mm_s2.len() != bp1_s.len() {
            return None;
        }
        let distinct = count_distinct(accels_mm_s2);
        if distinct == 1 {
            let mean = bp1_s.iter().sum::<f64>() / bp1_s.len() as f64;
            return Some(Self { c0_s: mean, c1: 0.0, c2: 1.0 });
        }
        if distinct == 2 {
            return linear_for_c2(accels_mm_s2, bp1_s, c2_fallback).map(|(law, _)| law);
        }
        let (lo, hi, step) = c2_grid;
        let n = ((hi - lo) / step + 1e-9).floor() as usize + 1;
        let mut best: Option<(Self, f64)> = None;
        for k in 0..n {
            let c2 = lo + k as f64 * step;
            if c2.abs() < 0.5 * step {
                continue;
            }
            if let Some((law, sse)) = linear_for_c2(accels_mm_s2, bp1_s, c2) {
                if best.is_none_or(|(_, b)| sse < b) {
                    best = Some((law, sse));
                }
            }
        }
        best.map(|(law, _)| law)
    }
}

/// Least squares for `c0, c1` at a fixed `c2`; returns the law and its SSE.
fn linear_for_c2(a: &[f64], y: &[f64], c2: f64) -> Option<(Bp1PowerLaw, f64)> {
    let n = a.len() as f64;
    let (mut sz, mut szz, mut sy, mut szy) = (0.0, 0.0, 0.0, 0.0);
    for (&ai, &yi) in a.iter().zip(y) {
        let z = ai.powf(c2);
        sz += z;
        szz += z * z;
        sy += yi;
        szy += z * yi;
    }
    let det = n * szz - sz * sz;
    // Written so that a NaN determinant also fails the test.
    let well_posed = det.abs() > 1e-12 * (n * szz).abs().max(f64::MIN_POSITIVE);
    if !well_posed {
        return None;
    }
    let c1 = (n * szy - sz * sy) / det;
    let c0 = (sy - c1 * sz) / n;
    let law = Bp1PowerLaw { c0_s: c0, c1, c2 };
    let sse = a.iter().zip(y).map(|(&ai, &yi)| (yi - law.bp1_s(ai)).powi(2)).sum();
    Some((law, sse))
}

fn count_distinct(values: &[f64]) -> usize {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v.dedup_by(|a, b| (*a - *b).abs() <= 1e-9 * b.abs().max(1.0));
    v.len()
}

/// The breakpoints and continuity offsets of eq. 3 for one line (all times in s, widths
/// in mm), computed from the coefficients and the actual kinematics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineChain {
    /// Whether p1 exists (start blob).
    pub has_start_blob: bool,
    /// bp1 (0 without a start blob), clamped to `[0, bp4]`.
    pub bp1_s: f64,
    /// bp2: end of the acceleration ramp.
    pub bp2_s: f64,
    /// Start of p3: `max(bp1, bp2)`.
    pub start3_s: f64,
    /// bp3: where p3 first reaches `c` (capped at bp4).
    pub bp3_s: f64,
    /// bp4: start of the deceleration ramp.
    pub bp4_s: f64,
    /// `w(bp1)`: the p1 width at bp1, or `w_start` without a blob.
    pub w_bp1_mm: f64,
    /// `w(max(bp1, bp2))`: the width where p3 starts.
    pub w_start3_mm: f64,
    /// `w(bp4)`: the width where p5 starts.
    pub w_bp4_mm: f64,
    /// Peak speed reached (`F`, or the triangular peak) (mm/s).
    pub top_speed_mm_s: f64,
    /// Actual acceleration (mm/s²).
    pub accel_mm_s2: f64,
}

impl LineChain {
    /// Breakpoints and offsets for actual kinematics `kin` and a bp1 time (ignored when
    /// `has_start_blob` is false).
    pub fn new(coef: &PiecewiseCoefficients, kin: &LineKinematics, has_start_blob: bool, bp1_s: f64) -> Self {
        let bp2 = kin.accel_end_s();
        let bp4 = kin.decel_start_s();
        let top = kin.peak_speed_mm_s();
        let a = kin.accel_mm_s2;
        let (bp1, w_bp1) = if has_start_blob {
            let bp1 = bp1_s.clamp(0.0, bp4);
            (bp1, coef.p1_width_mm(kin.speed_at_time(bp1)))
        } else {
            (0.0, coef.w_start_mm)
        };
        let start3 = bp1.max(bp2);
        let w3 = if bp1 < bp2 { w_bp1 + coef.beta * p2_regressor(bp2, top, bp1, a) } else { w_bp1 };
        let bp3 = if start3 < bp4 { bp3_time(w3, coef.c_mm, coef.gamma, start3, bp4, top) } else { bp4 };
        let w_bp4 = if bp3 < bp4 { coef.c_mm } else { w3 + coef.gamma * p3_regressor(bp4, top, start3) };
        Self {
            has_start_blob,
            bp1_s: bp1,
            bp2_s: bp2,
            start3_s: start3,
            bp3_s: bp3,
            bp4_s: bp4,
            w_bp1_mm: w_bp1,
            w_start3_mm: w3,
            w_bp4_mm: w_bp4,
            top_speed_mm_s: top,
            accel_mm_s2: a,
        }
    }

    /// The phase of eq. 3 a time falls in.
    pub fn phase_at(&self, t_s: f64) -> WidthPhase {
        if self.has_start_blob && t_s <= self.bp1_s {
            WidthPhase::P1PreAction
        } else if t_s <= self.bp2_s {
            WidthPhase::P2WarmUp
        } else if t_s <= self.bp3_s {
            WidthPhase::P3WarmUpAtFeed
        } else if t_s <= self.bp4_s {
            WidthPhase::P4Steady
        } else {
            WidthPhase::P5SlowDown
        }
    }

    /// Width (mm) of eq. 3 at time `t_s` where the speed is `speed_mm_s`.
    pub fn width_at(&self, coef: &PiecewiseCoefficients, t_s: f64, speed_mm_s: f64) -> f64 {
        match self.phase_at(t_s) {
            WidthPhase::P1PreAction => coef.p1_width_mm(speed_mm_s),
            WidthPhase::P2WarmUp => {
                self.w_bp1_mm + coef.beta * p2_regressor(t_s, speed_mm_s, self.bp1_s, self.accel_mm_s2)
            }
            WidthPhase::P3WarmUpAtFeed => self.w_start3_mm + coef.gamma * p3_regressor(t_s, speed_mm_s, self.start3_s),
            WidthPhase::P4Steady => coef.c_mm,
            WidthPhase::P5SlowDown => self.w_bp4_mm + coef.rho * p5_regressor(speed_mm_s, self.top_speed_mm_s),
        }
    }
}

/// p2 regressor `sqrt((t − bp1)·v·a)`.
pub(crate) fn p2_regressor(t_s: f64, v: f64, bp1_s: f64, a: f64) -> f64 {
    ((t_s - bp1_s).max(0.0) * v * a).sqrt()
}

/// p3 regressor `sqrt((t − start3)·v)`.
pub(crate) fn p3_regressor(t_s: f64, v: f64, start3_s: f64) -> f64 {
    ((t_s - start3_s).max(0.0) * v).sqrt()
}

/// p5 regressor `log(F/v)` with `F` the peak speed.
pub(crate) fn p5_regressor(v: f64, top_speed: f64) -> f64 {
    (top_speed / v).ln()
}

/// bp3: first time p3 reaches `c` (capped at bp4; at `start3` if already there).
pub(crate) fn bp3_time(w3: f64, c: f64, gamma: f64, start3: f64, bp4: f64, v: f64) -> f64 {
    if w3 >= c {
        start3
    } else if gamma <= 0.0 {
        bp4
    } else {
        let dt = ((c - w3) / gamma).powi(2) / v;
        (start3 + dt).min(bp4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn coef() -> PiecewiseCoefficients {
        PiecewiseCoefficients {
            alpha1: 0.02,
            alpha2: 1.0,
            beta: 0.002,
            gamma: 0.03,
            c_mm: 0.8,
            rho: 0.1,
            w_start_mm: 0.5,
        }
    }

    #[test]
    fn chain_is_continuous_at_every_breakpoint() {
        // Continuity by construction: evaluate just before and after each breakpoint.
        let kin = LineKinematics::paper_line(600.0, 100.0).unwrap();
        for blob in [true, false] {
            let ch = LineChain::new(&coef(), &kin, blob, 0.05);
            assert!(ch.bp3_s > ch.start3_s && ch.bp3_s < ch.bp4_s);
            let bps = [ch.bp1_s, ch.bp2_s, ch.bp3_s, ch.bp4_s];
            for &b in bps.iter().skip(usize::from(!blob)) {
                let (t0, t1) = (b - 1e-10, b + 1e-10);
                let w0 = ch.width_at(&coef(), t0, kin.speed_at_time(t0));
                let w1 = ch.width_at(&coef(), t1, kin.speed_at_time(t1));
                assert!((w0 - w1).abs() < 1e-4, "jump at {b}: {w0} vs {w1}");
            }
        }
    }

    #[test]
    fn bp3_is_where_p3_reaches_c() {
        // w3 + γ·sqrt((bp3 − start3)·F) = c exactly.
        let kin = LineKinematics::paper_line(400.0, 150.0).unwrap();
        let ch = LineChain::new(&coef(), &kin, true, 0.1);
        let s = p3_regressor(ch.bp3_s, 150.0, ch.start3_s);
        assert!((ch.w_start3_mm + coef().gamma * s - coef().c_mm).abs() < 1e-12);
        assert_eq!(ch.w_bp4_mm, coef().c_mm);
    }

    #[test]
    fn late_bp1_drops_p2_and_no_cruise_drops_p3_p4() {
        let kin = LineKinematics::paper_line(800.0, 50.0).unwrap();
        let bp2 = kin.accel_end_s();
        let ch = LineChain::new(&coef(), &kin, true, bp2 + 0.05);
        assert_eq!(ch.start3_s, ch.bp1_s);
        assert_eq!(ch.w_start3_mm, ch.w_bp1_mm);
        assert_eq!(ch.phase_at(bp2 + 0.01), WidthPhase::P1PreAction);
        let short = LineKinematics::new(400.0, 150.0, 8.0, 10.0).unwrap();
        let ch = LineChain::new(&coef(), &short, true, 0.01);
        assert_eq!(ch.bp2_s, ch.bp4_s);
        assert_eq!(ch.bp3_s, ch.bp4_s);
        let t_end = short.total_time_s();
        // p5 uses the triangular peak speed, so log(F/v) starts at 0 at bp4.
        assert_eq!(ch.phase_at(t_end), WidthPhase::P5SlowDown);
        let w_end = ch.width_at(&coef(), t_end, 8.0);
        let expect = ch.w_bp4_mm + 0.1 * (short.peak_speed_mm_s() / 8.0).ln();
        assert!((w_end - expect).abs() < 1e-12);
    }

    #[test]
    fn power_law_fit_recovers_exact_law() {
        // Three distinct accelerations determine c0, c1, c2; c2 = −0.5 lies on the grid.
        let truth = Bp1PowerLaw { c0_s: 0.02, c1: 2.0, c2: -0.5 };
        let a = [400.0, 400.0, 600.0, 800.0, 800.0];
        let y: Vec<f64> = a.iter().map(|&ai| truth.bp1_s(ai)).collect();
        let fit = Bp1PowerLaw::fit(&a, &y, (-3.0, 3.0, 0.01), -1.0).unwrap();
        assert!((fit.c2 - truth.c2).abs() < 1e-9);
        assert!((fit.c0_s - truth.c0_s).abs() < 1e-9 && (fit.c1 - truth.c1).abs() < 1e-9);
        let one = Bp1PowerLaw::fit(&[500.0, 500.0], &[0.1, 0.2], (-3.0, 3.0, 0.01), -1.0);
        assert!((one.unwrap().bp1_s(900.0) - 0.15).abs() < 1e-12);
        let two = Bp1PowerLaw::fit(&[400.0, 800.0], &[0.2, 0.1], (-3.0, 3.0, 0.01), -1.0);
        assert!((two.unwrap().bp1_s(400.0) - 0.2).abs() < 1e-12);
    }
}
