//! Bounded nonlinear least squares: Levenberg–Marquardt with Marquardt's diagonal
//! scaling, a forward-difference Jacobian, and box constraints by projection (a
//! variable at a bound whose gradient points out of the box is held for that step).
//! Small problems (a handful of parameters, thousands of residuals) are what the
//! mechanisms' fits are; the normal equations are solved by faer's Cholesky.
//!
//! Hand-written because the maintained crates either take no bounds or bring a solver
//! framework far larger than these ten-parameter fits need.

use faer::prelude::Solve;
use faer::{Mat, Side};

/// Stopping rules of [`minimize`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmSettings {
    /// Most Jacobian evaluations.
    pub max_iterations: usize,
    /// Stop when an accepted step lowers the sum of squares by less than this fraction.
    pub relative_tolerance: f64,
    /// Forward-difference step as a fraction of the parameter's box width.
    pub difference_step: f64,
}

impl Default for LmSettings {
    /// 50 iterations, 1e-9 relative fall, steps of 1e-7 of the box.
    fn default() -> Self {
        Self { max_iterations: 50, relative_tolerance: 1e-9, difference_step: 1e-7 }
    }
}

/// The result of [`minimize`].
#[derive(Debug, Clone, PartialEq)]
pub struct LmSolution {
    /// The parameters at the minimum found.
    pub x: Vec<f64>,
    /// Sum of squared residuals there.
    pub sse: f64,
    /// Jacobian evaluations used.
    pub iterations: usize,
}

/// Minimises `Σ r_i(x)²` over the box `lo ≤ x ≤ hi` from `x0`. `residuals(x, r)`
/// writes the `m` residuals into `r` and returns false when `x` cannot be evaluated
/// (treated as an infinitely bad point). Returns `None` when `x0` itself cannot be
/// evaluated.
pub fn minimize<F>(
    mut residuals: F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    m: usize,
    settings: &LmSettings,
) -> Option<LmSolution>
where
    F: FnMut(&[f64], &mut [f64]) -> bool,
{
    let n = x0.len();
    let mut x: Vec<f64> = x0.iter().zip(lo.iter().zip(hi)).map(|(v, (l, h))| v.clamp(*l, *h)).collect();
    let mut r = vec![0.0; m];
    let mut sse = eval(&mut residuals, &x, &mut r)?;
    let (mut jac, mut r_trial, mut x_trial) = (vec![0.0; m * n], vec![0.0; m], vec![0.0; n]);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    while iterations < settings.max_iterations && sse > 0.0 {
        iterations += 1;
        jacobian(&mut residuals, &x, &r, lo, hi, settings.difference_step, &mut jac, &mut r_trial);
        let (jtj, grad) = normal_equations(&jac, &r, m, n);
        let free: Vec<usize> = (0..n).filter(|&j| !held_at_bound(x[j], grad[j], lo[j], hi[j])).collect();
        if free.is_empty() {
            break;
        }
        let Some(trial) =
            try_steps(&mut residuals, &jtj, &grad, &free, &x, lo, hi, sse, &mut lambda, &mut x_trial, &mut r_trial)
        else {
            break;
        };
        let fall = (sse - trial) / sse;
        x.copy_from_slice(&x_trial);
        r.copy_from_slice(&r_trial);
        sse = trial;
        if fall <= settings.relative_tolerance {
            break;
        }
    }
    Some(LmSolution { x, sse, iterations })
}

/// Damped steps of growing `λ` until one lowers the sum of squares; the accepted point
/// and residuals are left in `x_trial`, `r_trial`.
#[allow(clippy::too_many_arguments)]
fn try_steps<F: FnMut(&[f64], &mut [f64]) -> bool>(
    f: &mut F,
    jtj: &[f64],
    grad: &[f64],
    free: &[usize],
    x: &[f64],
    lo: &[f64],
    hi: &[f64],
    sse: f64,
    lambda: &mut f64,
    x_trial: &mut [f64],
    r_trial: &mut [f64],
) -> Option<f64> {
    for _ in 0..12 {
        let Some(step) = damped_step(jtj, grad, free, *lambda) else {
            *lambda *= 10.0;
            continue;
        };
        x_trial.copy_from_slice(x);
        for (k, &j) in free.iter().enumerate() {
            x_trial[j] = (x[j] + step[k]).clamp(lo[j], hi[j]);
        }
        match eval(f, x_trial, r_trial) {
            Some(trial) if trial < sse => {
                *lambda = (*lambda / 3.0).max(1e-12);
                return Some(trial);
            }
            _ => *lambda *= 4.0,
        }
    }
    None
}

fn eval<F: FnMut(&[f64], &mut [f64]) -> bool>(f: &mut F, x: &[f64], r: &mut [f64]) -> Option<f64> {
    if !f(x, r) {
        return None;
    }
    let sse: f64 = r.iter().map(|v| v * v).sum();
    sse.is_finite().then_some(sse)
}

/// Forward differences, stepping into the box at an upper bound; column `j` of the
/// `m × n` Jacobian is `jac[j·m .. (j+1)·m]`.
#[allow(clippy::too_many_arguments)]
fn jacobian<F: FnMut(&[f64], &mut [f64]) -> bool>(
    f: &mut F,
    x: &[f64],
    r: &[f64],
    lo: &[f64],
    hi: &[f64],
    rel_step: f64,
    jac: &mut [f64],
    scratch: &mut [f64],
) {
    let m = r.len();
    let mut xp = x.to_vec();
    for j in 0..x.len() {
        let width = (hi[j] - lo[j]).abs();
        let mut h = rel_step * width.max(x[j].abs()).max(1e-12);
        if x[j] + h > hi[j] {
            h = -h;
        }
        xp[j] = x[j] + h;
        let column = &mut jac[j * m..(j + 1) * m];
        if f(&xp, scratch) && scratch.iter().all(|v| v.is_finite()) {
            for i in 0..m {
                column[i] = (scratch[i] - r[i]) / h;
            }
        } else {
            column.fill(0.0);
        }
        xp[j] = x[j];
    }
}

fn normal_equations(jac: &[f64], r: &[f64], m: usize, n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut jtj = vec![0.0; n * n];
    let mut grad = vec![0.0; n];
    for a in 0..n {
        let ca = &jac[a * m..(a + 1) * m];
        grad[a] = ca.iter().zip(r).map(|(j, r)| j * r).sum();
        for b in 0..=a {
            let cb = &jac[b * m..(b + 1) * m];
            let v: f64 = ca.iter().zip(cb).map(|(p, q)| p * q).sum();
            jtj[a * n + b] = v;
            jtj[b * n + a] = v;
        }
    }
    (jtj, grad)
}

/// A variable at a bound with the descent direction (−gradient) pointing outward.
fn held_at_bound(x: f64, grad: f64, lo: f64, hi: f64) -> bool {
    (x <= lo && grad > 0.0) || (x >= hi && grad < 0.0)
}

/// Solves `(JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr` on the free variables.
fn damped_step(jtj: &[f64], grad: &[f64], free: &[usize], lambda: f64) -> Option<Vec<f64>> {
    let n = grad.len();
    let k = free.len();
    let scale = free.iter().map(|&j| jtj[j * n + j]).fold(0.0f64, f64::max).max(f64::MIN_POSITIVE);
    let a = Mat::from_fn(k, k, |p, q| {
        let v = jtj[free[p] * n + free[q]];
        if p == q {
            v + lambda * v.max(1e-12 * scale)
        } else {
            v
        }
    });
    let b = Mat::from_fn(k, 1, |p, _| -grad[free[p]]);
    let llt = a.llt(Side::Lower).ok()?;
    let step = llt.solve(&b);
    let out: Vec<f64> = (0..k).map(|p| step[(p, 0)]).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_exponential_decay_exactly() {
        // y = 2 exp(−t/0.3) + 0.5 sampled without noise: the minimum is the truth, SSE 0.
        let ts: Vec<f64> = (0..60).map(|i| i as f64 * 0.02).collect();
        let ys: Vec<f64> = ts.iter().map(|t| 2.0 * (-t / 0.3).exp() + 0.5).collect();
        let f = |x: &[f64], r: &mut [f64]| {
            for (i, t) in ts.iter().enumerate() {
                r[i] = x[0] * (-t / x[1]).exp() + x[2] - ys[i];
            }
            true
        };
        let sol =
            minimize(f, &[1.0, 0.1, 0.0], &[0.0, 0.01, -5.0], &[10.0, 5.0, 5.0], 60, &LmSettings::default()).unwrap();
        assert!((sol.x[0] - 2.0).abs() < 1e-6 && (sol.x[1] - 0.3).abs() < 1e-6 && (sol.x[2] - 0.5).abs() < 1e-6);
        assert!(sol.sse < 1e-16, "{}", sol.sse);
    }

    #[test]
    fn respects_bounds_and_stops_on_the_active_one() {
        // min (x − 3)² on [0, 1] is at the bound x = 1 with SSE 4.
        let sol = minimize(
            |x, r| {
                r[0] = x[0] - 3.0;
                true
            },
            &[0.2],
            &[0.0],
            &[1.0],
            1,
            &LmSettings::default(),
        )
        .unwrap();
        assert_eq!(sol.x[0], 1.0);
        assert!((sol.sse - 4.0).abs() < 1e-12);
        assert!(minimize(|_, _| false, &[0.2], &[0.0], &[1.0], 1, &LmSettings::default()).is_none());
    }
}
