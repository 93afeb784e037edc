//! Physics baseline for paper 000's line widths (DESIGN §5.1; not in the paper): mass
//! conservation with a first-order extrusion lag.
//!
//! With `q = Q/h` (flow per layer height, mm²/s) the layer height cancels:
//!
//! ```text
//! q_cmd(t) = w0 · v(t)               commanded flow for the nominal width w0
//! τ · dq/dt = q_cmd − q              melt/Bowden lag
//! q(0) = w0 · v0 + b                 start state: b > 0 is the dwell-pressure blob
//! w(t) = q(t) / v(t)                 deposited width (mass conservation)
//! ```
//!
//! then `w` is smoothed along the path with a centred box over about one nozzle diameter
//! (`smoothing_mm`, 0.5 mm). Modelling choices (ours):
//! - the start blob is the initial flow excess `b` of the same first-order state, so it
//!   decays with the same `τ` (one mechanism, three parameters `τ, w0, b`); `b` is free
//!   in sign (a deficit is allowed) and fixed at 0 when `has_start_blob` is false;
//! - the ODE is integrated on a uniform position grid (`grid_step_mm`) with the exact
//!   discretisation for an input linear in time between grid points (first-order hold):
//!   `u₊ = φu + (1 − φ)v₀ + (v₁ − v₀)(1 − τ(1 − φ)/Δt)`, `φ = exp(−Δt/τ)`; the speed is
//!   exactly linear in time on each ramp, so this is exact except across bp2 and bp4;
//! - the solution is linear in `(w0, b)`: `w = w0·B1(t) + b·B2(t)` with `B1 = u/v`
//!   (`u` the response to `v`, `u(0) = v0`) and `B2 = exp(−t/τ)/v`. For a given `τ`,
//!   `(w0, b)` are the closed-form linear least squares on all training lines; `τ` is
//!   found by a log-spaced grid followed by golden-section refinement in `ln τ`;
//! - nominal kinematics are used (no `r_a`, `r_F` search): prediction needs only the
//!   new line's G-code values.

use super::errors::{FitError, ParamError};
use super::fit::moving_average;
use super::kinematics::LineKinematics;
use super::line::MeasuredLine;
use super::small_linalg::spd_solve;

/// Unchecked settings of the lag fit.
#[derive(Debug, Clone, PartialEq)]
pub struct LagParams {
    /// Smallest time constant searched (s).
    pub tau_min_s: f64,
    /// Largest time constant searched (s).
    pub tau_max_s: f64,
    /// Points of the log-spaced `τ` grid before golden-section refinement.
    pub tau_grid_points: usize,
    /// Golden-section iterations in `ln τ`.
    pub golden_iterations: usize,
    /// Box smoothing length along the path (mm): about one nozzle diameter.
    pub smoothing_mm: f64,
    /// Step of the integration grid along the path (mm).
    pub grid_step_mm: f64,
    /// Whether the initial flow excess `b` is fitted (start blob) or 0.
    pub has_start_blob: bool,
}

/// Checked settings of the lag fit.
#[derive(Debug, Clone, PartialEq)]
pub struct LagValidParams(LagParams);

impl LagParams {
    /// Defaults: `τ ∈ [5 ms, 3 s]` (direct drive ≈ 0.02-0.1 s, Bowden ≈ 0.3-1 s,
    /// DESIGN §5.1), 40 grid points, 60 golden-section steps, smoothing over the 0.5 mm
    /// nozzle of Table I, 0.05 mm integration grid, with start blob (Taz 5).
    pub fn paper_defaults() -> Self {
        Self {
            tau_min_s: 0.005,
            tau_max_s: 3.0,
            tau_grid_points: 40,
            golden_iterations: 60,
            smoothing_mm: 0.5,
            grid_step_mm: 0.05,
            has_start_blob: true,
        }
    }

    /// Checks the ranges and returns the valid type.
    pub fn check(self) -> Result<LagValidParams, ParamError> {
        let bad = |name, value, reason| Err(ParamError::OutOfRange { name, value, reason });
        if !(self.tau_min_s > 0.0 && self.tau_min_s.is_finite()) {
            return bad("tau_min_s", self.tau_min_s, "must be positive");
        }
        if !(self.tau_max_s > self.tau_min_s && self.tau_max_s.is_finite()) {
            return bad("tau_max_s", self.tau_max_s, "must exceed tau_min_s");
        }
        if self.tau_grid_points < 3 {
            return bad("tau_grid_points", self.tau_grid_points as f64, "at least 3");
        }
        if self.smoothing_mm.is_nan() || self.smoothing_mm < 0.0 {
            return bad("smoothing_mm", self.smoothing_mm, "must be non-negative");
        }
        if !(self.grid_step_mm > 0.0 && self.grid_step_mm.is_finite()) {
            return bad("grid_step_mm", self.grid_step_mm, "must be positive");
        }
        Ok(LagValidParams(self))
    }
}

impl LagValidParams {
    /// The checked settings.
    pub fn get(&self) -> &LagParams {
        &self.0
    }
}

/// A fitted lag model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedLag {
    /// Extrusion time constant `τ` (s).
    pub tau_s: f64,
    /// Nominal width `w0` (mm): the steady-state width.
    pub w0_mm: f64,
    /// Initial flow excess `b` per layer height (mm²/s).
    pub blob_flow_mm2_s: f64,
    /// Smoothing length used (mm).
    pub smoothing_mm: f64,
    /// Integration grid step used (mm).
    pub grid_step_mm: f64,
    /// RMSE on the training lines (mm).
    pub training_rmse_mm: f64,
}

impl FittedLag {
    /// Predicted widths (mm) at `positions_mm` of a line with nominal kinematics.
    pub fn predict(&self, nominal: &LineKinematics, positions_mm: &[f64]) -> Result<Vec<f64>, FitError> {
        let (b1, b2) = lag_basis(nominal, self.tau_s, positions_mm, self.smoothing_mm, self.grid_step_mm);
        Ok(b1.iter().zip(&b2).map(|(x1, x2)| self.w0_mm * x1 + self.blob_flow_mm2_s * x2).collect())
    }
}

/// The two basis responses at `positions_mm`: `B1` (width per unit `w0`) and `B2`
/// (width per unit initial flow excess `b`), both smoothed over `smoothing_mm`.
pub fn lag_basis(
    kin: &LineKinematics,
    tau_s: f64,
    positions_mm: &[f64],
    smoothing_mm: f64,
    grid_step_mm: f64,
) -> (Vec<f64>, Vec<f64>) {
    let n = (kin.length_mm / grid_step_mm).ceil().max(1.0) as usize;
    let xs: Vec<f64> = (0..=n).map(|j| (j as f64 * grid_step_mm).min(kin.length_mm)).collect();
    let ts: Vec<f64> = xs.iter().map(|&x| kin.time_at_position(x)).collect();
    let vs: Vec<f64> = xs.iter().map(|&x| kin.speed_at_position(x)).collect();
    let u = first_order_response(&ts, &vs, tau_s);
    let b1: Vec<f64> = u.iter().zip(&vs).map(|(u, v)| u / v).collect();
    let b2: Vec<f64> = ts.iter().zip(&vs).map(|(t, v)| (-t / tau_s).exp() / v).collect();
    let b1 = moving_average(&xs, &b1, smoothing_mm);
    let b2 = moving_average(&xs, &b2, smoothing_mm);
    (interpolate(&xs, &b1, positions_mm), interpolate(&xs, &b2, positions_mm))
}

/// Exact first-order-hold solution of `τ u' = v − u`, `u(0) = v(0)`, at the times `ts`.
pub fn first_order_response(ts: &[f64], vs: &[f64], tau_s: f64) -> Vec<f64> {
    let mut u = Vec::with_capacity(ts.len());
    let Some(&v_first) = vs.first() else {
        return u;
    };
    u.push(v_first);
    for j in 1..ts.len() {
        let dt = ts[j] - ts[j - 1];
        let prev = u[j - 1];
        if dt <= 0.0 {
            u.push(prev);
            continue;
        }
        let phi = (-dt / tau_s).exp();
        let one_minus = -(-dt / tau_s).exp_m1();
        let ramp = 1.0 - tau_s * one_minus / dt;
        u.push(phi * prev + one_minus * vs[j - 1] + (vs[j] - vs[j - 1]) * ramp);
    }
    u
}

/// Linear interpolation of `(xs, ys)` (xs ascending) at `at`, clamped at the ends.
fn interpolate(xs: &[f64], ys: &[f64], at: &[f64]) -> Vec<f64> {
    at.iter()
        .map(|&x| {
            let k = xs.partition_point(|&xi| xi <= x);
            if k == 0 {
                ys[0]
            } else if k >= xs.len() {
                ys[xs.len() - 1]
            } else {
                let (x0, x1) = (xs[k - 1], xs[k]);
                let f = (x - x0) / (x1 - x0);
                ys[k - 1] + f * (ys[k] - ys[k - 1])
            }
        })
        .collect()
}

/// Fits `τ`, `w0` and (with a start blob) `b` to the training lines.
pub fn fit_lag(lines: &[MeasuredLine], params: &LagValidParams) -> Result<FittedLag, FitError> {
    if lines.is_empty() {
        return Err(FitError::NotEnoughData("no training lines".into()));
    }
    for (i, l) in lines.iter().enumerate() {
        l.validate(i)?;
    }
    let p = params.get();
    let (lo, hi) = (p.tau_min_s.ln(), p.tau_max_s.ln());
    let m = p.tau_grid_points;
    let grid: Vec<f64> = (0..m).map(|k| lo + (hi - lo) * k as f64 / (m - 1) as f64).collect();
    let sse_at = |ln_tau: f64| solve_linear(lines, p, ln_tau.exp()).map(|s| s.2);
    let mut best = (0, f64::INFINITY);
    for (k, &g) in grid.iter().enumerate() {
        let s = sse_at(g)?;
        if s < best.1 {
            best = (k, s);
        }
    }
    let a = grid[best.0.saturating_sub(1)];
    let b = grid[(best.0 + 1).min(m - 1)];
    let ln_tau = golden_section(a, b, p.golden_iterations, |x| sse_at(x).unwrap_or(f64::INFINITY));
    let ln_tau = if sse_at(ln_tau)? <= best.1 { ln_tau } else { grid[best.0] };
    let tau_s = ln_tau.exp();
    let (w0_mm, blob, sse) = solve_linear(lines, p, tau_s)?;
    let n: usize = lines.iter().map(MeasuredLine::len).sum();
    Ok(FittedLag {
        tau_s,
        w0_mm,
        blob_flow_mm2_s: blob,
        smoothing_mm: p.smoothing_mm,
        grid_step_mm: p.grid_step_mm,
        training_rmse_mm: (sse / n as f64).sqrt(),
    })
}

/// Closed-form `(w0, b)` for a given `τ`, and the SSE.
fn solve_linear(lines: &[MeasuredLine], p: &LagParams, tau_s: f64) -> Result<(f64, f64, f64), FitError> {
    let (mut a, mut rhs, mut syy) = ([[0.0; 2]; 2], [0.0; 2], 0.0);
    for l in lines {
        let (b1, b2) = lag_basis(&l.nominal, tau_s, &l.positions_mm, p.smoothing_mm, p.grid_step_mm);
        for ((x1, x2), y) in b1.iter().zip(&b2).zip(&l.widths_mm) {
            a[0][0] += x1 * x1;
            a[0][1] += x1 * x2;
            a[1][1] += x2 * x2;
            rhs[0] += x1 * y;
            rhs[1] += x2 * y;
            syy += y * y;
        }
    }
    a[1][0] = a[0][1];
    let sol = if p.has_start_blob {
        spd_solve(&a, &rhs).ok_or_else(|| FitError::Singular("lag (w0, b)".into()))?
    } else {
        [rhs[0] / a[0][0], 0.0]
    };
    let sse = syy - 2.0 * (sol[0] * rhs[0] + sol[1] * rhs[1])
        + sol[0] * sol[0] * a[0][0]
        + 2.0 * sol[0] * sol[1] * a[0][1]
        + sol[1] * sol[1] * a[1][1];
    Ok((sol[0], sol[1], sse.max(0.0)))
}

/// Golden-section minimisation of `f` on `[a, b]`.
fn golden_section(mut a: f64, mut b: f64, iterations: usize, f: impl Fn(f64) -> f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..iterations {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

#[cfg(test)]
mod tests {
    use super::super::test_support::TABLE_I;
    use super::*;

    fn lines_from(model: &FittedLag) -> Vec<MeasuredLine> {
        TABLE_I
            .iter()
            .map(|&(a, f)| {
                let k = LineKinematics::paper_line(a, f).unwrap();
                let xs: Vec<f64> = (0..2500).map(|i| i as f64 * 0.048).collect();
                let ws = model.predict(&k, &xs).unwrap();
                MeasuredLine::new(k, xs, ws).unwrap()
            })
            .collect()
    }

    #[test]
    fn first_order_hold_is_exact_for_ramp_input() {
        // τu' = v − u with v = v0 + k t, u(0) = v0 has the closed form
        // u = v0 + k t − kτ(1 − exp(−t/τ)); the discretisation must match it for any step.
        let (v0, k, tau) = (8.0, 600.0, 0.13);
        let ts: Vec<f64> = (0..50).map(|i| (i as f64 * 0.013).powf(1.3)).collect();
        let vs: Vec<f64> = ts.iter().map(|t| v0 + k * t).collect();
        let u = first_order_response(&ts, &vs, tau);
        for (t, u) in ts.iter().zip(&u) {
            let exact = v0 + k * t - k * tau * (1.0 - (-t / tau).exp());
            assert!((u - exact).abs() < 1e-10 * (1.0 + exact.abs()), "{u} vs {exact}");
        }
    }

    #[test]
    fn recovers_known_tau_from_noiseless_data() {
        // Data drawn from the model with τ = 0.12 s: the fit must return τ, w0, b.
        let truth = FittedLag {
            tau_s: 0.12,
            w0_mm: 0.8,
            blob_flow_mm2_s: 3.0,
            smoothing_mm: 0.5,
            grid_step_mm: 0.05,
            training_rmse_mm: 0.0,
        };
        let lines = lines_from(&truth);
        let params = LagParams::paper_defaults().check().unwrap();
        let fit = fit_lag(&lines, &params).unwrap();
        assert!((fit.tau_s - 0.12).abs() < 1e-5, "tau {}", fit.tau_s);
        assert!((fit.w0_mm - 0.8).abs() < 1e-6);
        assert!((fit.blob_flow_mm2_s - 3.0).abs() < 1e-4);
        assert!(fit.training_rmse_mm < 1e-6);
    }

    #[test]
    fn steady_state_width_is_w0_and_end_bulges() {
        // In the cruise, long after the ramp, q → w0·F so w → w0; while decelerating the
        // lagging flow exceeds w0·v, so the end is wider than w0 (mass conservation).
        let m = FittedLag {
            tau_s: 0.05,
            w0_mm: 0.8,
            blob_flow_mm2_s: 0.0,
            smoothing_mm: 0.5,
            grid_step_mm: 0.05,
            training_rmse_mm: 0.0,
        };
        let k = LineKinematics::paper_line(800.0, 100.0).unwrap();
        let w = m.predict(&k, &[100.0, 119.9]).unwrap();
        // Residual lag 40 τ after the ramp ends is far below rounding of the width.
        assert!((w[0] - 0.8).abs() < 1e-6, "{}", w[0]);
        assert!(w[1] > 0.9);
        let bad = LagParams { tau_max_s: 0.001, ..LagParams::paper_defaults() };
        assert!(bad.check().is_err());
    }
}
