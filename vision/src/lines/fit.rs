//! Levenberg–Marquardt fit of the edge model ([`super::model`]) to one sampled profile
//! (step 3 of [`super`]). Six parameters, so the normal equations are a 6 × 6 system,
//! accumulated in one pass over the samples and solved by a hand-written Cholesky
//! factorisation; nothing is allocated.

use super::model::{EdgeParams, N_PARAMS};

/// Most LM iterations before giving up.
const MAX_ITERATIONS: usize = 40;
/// An accepted step moving the edges and σ by less than this (px), and the contrast by
/// less than 0.1 %, ends the fit; the
/// error left after it is far smaller (Gauss–Newton converges quadratically near the optimum).
const STEP_TOLERANCE_PX: f64 = 1e-2;
/// Smallest PSF width the fit may reach (px); below it the model is a hard step.
pub const MIN_SIGMA_PX: f64 = 0.2;

/// A converged fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeFit {
    /// The fitted parameters.
    pub params: EdgeParams,
    /// Root-mean-square residual of the samples.
    pub rms_residual: f64,
    /// LM iterations used.
    pub iterations: usize,
}

/// Samples of a profile at t = `t0_px + j · dt_px`.
#[derive(Debug, Clone, Copy)]
pub struct Profile<'a> {
    /// Lateral coordinate of the first sample (px).
    pub t0_px: f64,
    /// Sample spacing (px).
    pub dt_px: f64,
    /// Intensities.
    pub values: &'a [f64],
}

impl Profile<'_> {
    /// Lateral coordinate of sample `j` (px).
    #[inline]
    pub fn t_px(&self, j: usize) -> f64 {
        self.t0_px + j as f64 * self.dt_px
    }
}

/// Fits the edge model from `init`; `None` if it does not converge to a valid bar.
pub fn fit_edges(profile: Profile<'_>, init: EdgeParams) -> Option<EdgeFit> {
    let mut params = init;
    let mut normal = NormalEquations::at(profile, &params)?;
    let mut lambda = 1e-3;
    for iteration in 1..=MAX_ITERATIONS {
        let delta = normal.damped_step(lambda)?;
        let trial = EdgeParams::from_array(add(params.as_array(), delta));
        let trial_normal = if is_valid(&trial) { NormalEquations::at(profile, &trial) } else { None };
        match trial_normal {
            Some(next) if next.cost <= normal.cost => {
                (params, normal) = (trial, next);
                lambda = (lambda / 3.0).max(1e-9);
                let edges_settled = delta[3].abs().max(delta[4].abs()).max(delta[5].abs()) < STEP_TOLERANCE_PX;
                if edges_settled && delta[2].abs() <= 1e-3 * params.contrast.abs() {
                    let rms_residual = (normal.cost / profile.values.len() as f64).sqrt();
                    return Some(EdgeFit { params, rms_residual, iterations: iteration });
                }
            }
            _ => lambda *= 4.0,
        }
        if lambda > 1e10 {
            return None;
        }
    }
    None
}

/// A bar with ordered edges and a positive PSF.
fn is_valid(p: &EdgeParams) -> bool {
    p.sigma_px >= MIN_SIGMA_PX && p.right_px > p.left_px && p.as_array().iter().all(|v| v.is_finite())
}

fn add(a: [f64; N_PARAMS], b: [f64; N_PARAMS]) -> [f64; N_PARAMS] {
    std::array::from_fn(|k| a[k] + b[k])
}

/// JᵀJ, Jᵀr and the residual sum of squares at one parameter point.
struct NormalEquations {
    jtj: [[f64; N_PARAMS]; N_PARAMS],
    jtr: [f64; N_PARAMS],
    cost: f64,
}

impl NormalEquations {
    /// Accumulates the normal equations over the samples (upper triangle, then mirrored).
    fn at(profile: Profile<'_>, params: &EdgeParams) -> Option<Self> {
        let mut jtj = [[0.0; N_PARAMS]; N_PARAMS];
        let mut jtr = [0.0; N_PARAMS];
        let mut cost = 0.0;
        for (j, &y) in profile.values.iter().enumerate() {
            let (model, grad) = params.value_and_gradient(profile.t_px(j));
            let r = y - model;
            cost += r * r;
            if grad[3] == 0.0 && grad[4] == 0.0 && grad[5] == 0.0 {
                // Far from both edges only b0, b1 and A have a gradient: a 3 × 3 block.
                accumulate::<3>(&mut jtj, &mut jtr, &grad, r);
            } else {
                accumulate::<N_PARAMS>(&mut jtj, &mut jtr, &grad, r);
            }
        }
        for row in 0..N_PARAMS {
            for col in 0..row {
                jtj[row][col] = jtj[col][row];
            }
        }
        cost.is_finite().then_some(Self { jtj, jtr, cost })
    }

    /// Solves (JᵀJ + λ·diag(JᵀJ)) δ = Jᵀr; `None` if the system is singular.
    fn damped_step(&self, lambda: f64) -> Option<[f64; N_PARAMS]> {
        let mut m = self.jtj;
        for k in 0..N_PARAMS {
            m[k][k] += lambda * self.jtj[k][k].max(1e-12);
        }
        cholesky_solve(m, self.jtr)
    }
}

/// `init` with b0, b1 and A replaced by their least-squares values for its a, b and σ
/// (the model is linear in them), so that LM starts on the right level and contrast.
pub fn with_linear_parameters(profile: Profile<'_>, init: EdgeParams) -> EdgeParams {
    let mut m = [[0.0; 3]; 3];
    let mut y = [0.0; 3];
    for (j, &value) in profile.values.iter().enumerate() {
        let (_, grad) = init.value_and_gradient(profile.t_px(j));
        let basis = [grad[0], grad[1], grad[2]];
        for row in 0..3 {
            y[row] += basis[row] * value;
            for col in 0..3 {
                m[row][col] += basis[row] * basis[col];
            }
        }
    }
    match cholesky_solve(m, y) {
        Some([b0, b1, contrast]) => EdgeParams { b0, b1, contrast, ..init },
        None => init,
    }
}

/// Adds one sample's gradient to the upper triangle of JᵀJ and to Jᵀr (first `N` parameters).
#[inline(always)]
fn accumulate<const N: usize>(
    jtj: &mut [[f64; N_PARAMS]; N_PARAMS],
    jtr: &mut [f64; N_PARAMS],
    grad: &[f64; N_PARAMS],
    r: f64,
) {
    for row in 0..N {
        jtr[row] += grad[row] * r;
        for col in row..N {
            jtj[row][col] += grad[row] * grad[col];
        }
    }
}

/// Solves M x = y for a symmetric positive definite N × N M (Cholesky, in place).
pub(crate) fn cholesky_solve<const N: usize>(mut m: [[f64; N]; N], mut y: [f64; N]) -> Option<[f64; N]> {
    for j in 0..N {
        let diag = m[j][j] - (0..j).map(|k| m[j][k] * m[j][k]).sum::<f64>();
        if diag <= 0.0 || !diag.is_finite() {
            return None;
        }
        m[j][j] = diag.sqrt();
        for i in j + 1..N {
            m[i][j] = (m[i][j] - (0..j).map(|k| m[i][k] * m[j][k]).sum::<f64>()) / m[j][j];
        }
    }
    for i in 0..N {
        y[i] = (y[i] - (0..i).map(|k| m[i][k] * y[k]).sum::<f64>()) / m[i][i];
    }
    for i in (0..N).rev() {
        y[i] = (y[i] - (i + 1..N).map(|k| m[k][i] * y[k]).sum::<f64>()) / m[i][i];
    }
    Some(y)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth() -> EdgeParams {
        EdgeParams { b0: 0.31, b1: 0.0007, contrast: 0.42, left_px: -15.3, right_px: 17.05, sigma_px: 1.6 }
    }

    fn sampled(p: &EdgeParams) -> Vec<f64> {
        (0..193).map(|j| p.value(-48.0 + 0.5 * j as f64)).collect()
    }

    #[test]
    fn noiseless_profile_recovers_the_parameters() {
        // The model is exact here, so LM must land on the truth from a start 2 px off.
        let values = sampled(&truth());
        let profile = Profile { t0_px: -48.0, dt_px: 0.5, values: &values };
        let init = EdgeParams { b0: 0.3, b1: 0.0, contrast: 0.35, left_px: -13.0, right_px: 19.0, sigma_px: 1.0 };
        let fit = fit_edges(profile, init).expect("converges");
        for (got, want) in fit.params.as_array().iter().zip(truth().as_array()) {
            // The fit stops once a step moves the edges by < 0.01 px; the next would be ~10⁻⁴².
            assert!((got - want).abs() < 1e-4, "{got} vs {want}");
        }
        assert!(fit.rms_residual < 1e-6, "{}", fit.rms_residual);
        assert!(fit.iterations < 20, "{} iterations", fit.iterations);
    }

    #[test]
    fn dark_bar_fits_with_negative_contrast() {
        let dark = EdgeParams { contrast: -0.42, b0: 0.8, ..truth() };
        let values = sampled(&dark);
        let profile = Profile { t0_px: -48.0, dt_px: 0.5, values: &values };
        let init = EdgeParams { contrast: -0.3, b0: 0.75, left_px: -16.0, right_px: 16.0, ..truth() };
        let fit = fit_edges(profile, init).expect("converges");
        assert!((fit.params.right_px - fit.params.left_px - 32.35).abs() < 1e-4);
    }

    #[test]
    fn flat_profile_does_not_converge_to_a_bar() {
        let values = vec![0.5; 193];
        let profile = Profile { t0_px: -48.0, dt_px: 0.5, values: &values };
        let fit = fit_edges(profile, truth());
        assert!(
            fit.is_none_or(|f| (f.params.contrast * (f.params.right_px - f.params.left_px)).abs() < 1e-3),
            "{fit:?}"
        );
    }

    #[test]
    fn cholesky_solves_a_known_system() {
        let mut m = [[0.0; N_PARAMS]; N_PARAMS];
        for i in 0..N_PARAMS {
            for j in 0..N_PARAMS {
                m[i][j] = 1.0 / (1.0 + (i as f64 - j as f64).abs()) + if i == j { 2.0 } else { 0.0 };
            }
        }
        let x_true = [1.0, -2.0, 0.5, 3.0, -1.0, 0.25];
        let y: [f64; N_PARAMS] = std::array::from_fn(|i| (0..N_PARAMS).map(|j| m[i][j] * x_true[j]).sum());
        let x = cholesky_solve(m, y).unwrap();
        for (a, b) in x.iter().zip(x_true) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}
