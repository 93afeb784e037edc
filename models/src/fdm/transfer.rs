//! Between-printer transfer learning of paper 000 (Ren et al. 2021, Sec. II-B,
//! Algorithm 1, eqs 4-6, Sec. III-B and Fig. 9).
//!
//! - Algorithm 1: the transferable parameters `θ = (β, γ, c, ρ)` (Sec. III-B: p1 and its
//!   `α1, α2` are absent on the target printer) are fitted line by line on the data-rich
//!   source printer (at the source's selected `r_a`, `r_F`, bp1 measured on each line),
//!   and `Σ̂ = 1/(K−1) Σ_k (θ_k − θ̄)(θ_k − θ̄)ᵀ`.
//! - Eq. 5: on the target printer the per-segment least squares get the penalty
//!   `λ (θ − μ)ᵀ Σ̂⁻¹ (θ − μ)`, i.e. the prior `θ ~ N(μ, Σ̂/λ)` (`q = 1` in eq. 4, with
//!   `σ²` absorbed into `λ`). For a fixed bp3 partition the MAP solves
//!   `(XᵀX + XᵀO + λΣ̂⁻¹) θ = Xᵀ(y − o₀) + λΣ̂⁻¹μ`, where the continuity offsets
//!   `w(bp_{i−1}) = Oθ + o₀` are held at their values under the solution itself (the
//!   constant-offset simplification of eq. 6, made self-consistent; see `fit.rs`). Without
//!   a prior this is the paper's per-segment fit; the public [`solve_map`] is the plain
//!   normal-equation solve of eq. 6 with faer. `w_start` (Taz 6 start width) has no
//!   prior. The paper writes `μ = 0` ([`transfer_zero_mean`]); centring the prior
//!   on the source mean ([`transfer_source_mean`]) is our extension. [`single`] is the
//!   same fit without a prior.
//! - `λ`: the paper leaves it to the user ("plenty of trials"). Our rule: with two or
//!   more target training lines, inner leave-one-out over those lines on a log grid
//!   (smallest mean held-out RMSE; ties go to the smaller `λ`). With one training line
//!   there is nothing to validate on, so the transfer is simulated on the source printer:
//!   each source line in turn plays the single target line, with the prior built from
//!   the other source lines, and predicts the remaining source lines; the `λ` with the
//!   smallest mean RMSE over all those predictions is used.
//! - `(r_a, r_F)` under the prior ([`PriorKinematics`]): by default every fit under a
//!   prior repeats the grid search of Sec. II-A (steps 2-8) for its own `λ`; with
//!   [`PriorKinematics::TargetPair`] it takes the pair the same lines select without
//!   prior and fits the prior there. The paper's prior is on `θ`, not on `(r_a, r_F)`,
//!   and it does not say which it did.
//! - Fig. 9 enumerates all training subsets of the nine target conditions:
//!   [`condition_subsets`], C(9, n) for n = 1..8, 510 in all;
//!   [`transfer_cv`](super::transfer_cv::transfer_cv) runs the whole cross-validation.

use faer::prelude::*;
use faer::{Mat, MatRef, Side};
use rayon::prelude::*;

use super::errors::{FitError, ParamError};
use super::fit::{fit_on_grid, full_grid, SegmentPrior, NP};
use super::hyperparams::PiecewiseValidParams;
use super::line::{rmse, MeasuredLine};
use super::piecewise::PiecewiseCoefficients;
use super::predict::FittedPiecewise;

/// Number of transferable parameters `(β, γ, c, ρ)`.
pub const TRANSFER_DIM: usize = 4;

/// Algorithm 1's output: per-line parameter vectors, their mean and covariance.
#[derive(Debug, Clone, PartialEq)]
pub struct ParameterCovariance {
    /// `θ_k = (β, γ, c, ρ)` of each source line.
    pub per_line: Vec<[f64; TRANSFER_DIM]>,
    /// Mean `θ̄`.
    pub mean: [f64; TRANSFER_DIM],
    /// Sample covariance `Σ̂` with the `1/(K−1)` normalisation.
    pub cov: [[f64; TRANSFER_DIM]; TRANSFER_DIM],
}

/// Algorithm 1: mean and `1/(K−1)` covariance of per-line parameter vectors.
pub fn estimate_covariance(per_line: &[[f64; TRANSFER_DIM]]) -> Result<ParameterCovariance, FitError> {
    let k = per_line.len();
    if k < 2 {
        return Err(FitError::NotEnoughData("a covariance needs at least two lines".into()));
    }
    let mut mean = [0.0; TRANSFER_DIM];
    for th in per_line {
        for i in 0..TRANSFER_DIM {
            mean[i] += th[i] / k as f64;
        }
    }
    let mut cov = [[0.0; TRANSFER_DIM]; TRANSFER_DIM];
    for th in per_line {
        for i in 0..TRANSFER_DIM {
            for j in 0..TRANSFER_DIM {
                cov[i][j] += (th[i] - mean[i]) * (th[j] - mean[j]) / (k - 1) as f64;
            }
        }
    }
    Ok(ParameterCovariance { per_line: per_line.to_vec(), mean, cov })
}

/// Per-line fits (Algorithm 1's loop) at a fixed `(r_a, r_F)`: `θ_k = (β, γ, c, ρ)`.
pub fn per_line_parameters(
    lines: &[MeasuredLine],
    params: &PiecewiseValidParams,
    r_a: f64,
    r_f: f64,
) -> Result<Vec<[f64; TRANSFER_DIM]>, FitError> {
    lines
        .par_iter()
        .map(|l| {
            let fit = super::fit::fit_at(std::slice::from_ref(l), params, r_a, r_f)?;
            Ok(fit.coefficients.transfer_vector())
        })
        .collect()
}

/// Solves the MAP normal equations `(XᵀX + λP) θ = Xᵀy + λPμ` with faer (Cholesky), where
/// `P = Σ⁻¹` is the prior precision. Errors on mismatched sizes or a system that is not
/// positive definite.
pub fn solve_map(
    xtx: MatRef<'_, f64>,
    xty: &[f64],
    prior_precision: MatRef<'_, f64>,
    prior_mean: &[f64],
    lambda: f64,
) -> Result<Vec<f64>, FitError> {
    let n = xtx.nrows();
    let square = |m: MatRef<'_, f64>| m.nrows() == n && m.ncols() == n;
    if !square(xtx) || !square(prior_precision) || xty.len() != n || prior_mean.len() != n {
        return Err(FitError::Dimension(format!(
            "MAP system of size {n}: XᵀX {}×{}, Xᵀy {}, P {}×{}, μ {}",
            xtx.nrows(),
            xtx.ncols(),
            xty.len(),
            prior_precision.nrows(),
            prior_precision.ncols(),
            prior_mean.len()
        )));
    }
    let a = Mat::from_fn(n, n, |i, j| xtx[(i, j)] + lambda * prior_precision[(i, j)]);
    let b = Mat::from_fn(n, 1, |i, _| {
        xty[i] + lambda * (0..n).map(|j| prior_precision[(i, j)] * prior_mean[j]).sum::<f64>()
    });
    let llt = a.llt(Side::Lower).map_err(|e| FitError::Singular(format!("MAP system: {e:?}")))?;
    let x = llt.solve(&b);
    Ok((0..n).map(|i| x[(i, 0)]).collect())
}

/// Where the prior is centred.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PriorMean {
    /// `μ = 0`, as eq. 4-5 are written in the paper.
    Zero,
    /// `μ = θ̄` of the source printer (our extension).
    SourceMean,
}

/// Unchecked transfer settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferParams {
    /// Candidate `λ` values (positive), searched by the rules in the module docs.
    pub lambda_grid: Vec<f64>,
    /// Which of `(β, γ, c, ρ)` get the prior. All four by default (Sec. III-B step 1);
    /// `[false, true, false, true]` is the γ-ρ-only variant of eq. 6.
    pub prior_on: [bool; TRANSFER_DIM],
    /// Where a fit under the prior takes its kinematic scales `(r_a, r_F)` of eq. 1.
    pub kinematics: PriorKinematics,
}

/// Where a fit under the prior (eq. 5) takes the kinematic scales `(r_a, r_F)` of eq. 1.
///
/// The prior of eqs 4-5 is on the shape parameters `(β, γ, c, ρ)`; `(r_a, r_F)`, the
/// ratios of the target's actual acceleration and feed to the G-code's, are not in it.
/// The paper does not say whether its grid search over them (Sec. II-A, steps 2-8) is
/// repeated under the prior.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PriorKinematics {
    /// The whole grid search is repeated under the prior: each `λ` picks its own pair by
    /// the penalised fit's training RMSE. Under a strong prior that pulls the shape away
    /// from the target's lines, the pair then absorbs part of the misfit and can end far
    /// from the pair the lines themselves give. The default, and what Fig. 9 uses.
    #[default]
    Grid,
    /// The pair is the target's own: the single-printer grid search on the same training
    /// lines without prior (Sec. II-A, steps 2-8), and every prior fit is made at that
    /// pair (a two-stage estimate: kinematics from the target, then the MAP of eq. 5).
    /// It needs one grid search per training set instead of one per prior and `λ`.
    TargetPair,
}

impl PriorKinematics {
    /// Every rule.
    pub const ALL: [Self; 2] = [Self::Grid, Self::TargetPair];

    /// Stable name: `grid` or `target_pair`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Grid => "grid",
            Self::TargetPair => "target_pair",
        }
    }

    /// The rule of a [`name`](Self::name).
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// Checked transfer settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferValidParams(TransferParams);

impl TransferParams {
    /// `λ ∈ {10⁻⁶, 10^-5.5, …, 10⁴}` (21 values; the paper gives no range, and with
    /// `μ = 0` even `λ = 10⁻³` shrinks `β` hard, so the grid reaches far down) and the
    /// prior on all four transferable parameters.
    pub fn paper_defaults() -> Self {
        Self {
            lambda_grid: Self::log_lambda_grid(0.5),
            prior_on: [true; TRANSFER_DIM],
            kinematics: PriorKinematics::Grid,
        }
    }

    /// `λ` from 10⁻⁶ to 10⁴, one value every `step_decades` decades (0.5: the 21 of
    /// [`paper_defaults`](Self::paper_defaults); 1: the 11 of the transfer matrix). Empty
    /// unless `step_decades` is positive and finite, which [`check`](Self::check) refuses.
    pub fn log_lambda_grid(step_decades: f64) -> Vec<f64> {
        const LOWEST_DECADE: f64 = -6.0;
        const DECADES: f64 = 10.0;
        if !(step_decades.is_finite() && step_decades > 0.0) {
            return Vec::new();
        }
        let count = (DECADES / step_decades + 1e-9).floor() as usize + 1;
        (0..count).map(|k| 10f64.powf(LOWEST_DECADE + step_decades * k as f64)).collect()
    }

    /// The γ-ρ-only reading of eq. 6 ("the estimation of γ and ρ can be made jointly",
    /// Sec. III-B): the prior acts on `γ, ρ` only, `β` and `c` are fitted freely.
    pub fn paper_eq6() -> Self {
        Self { prior_on: [false, true, false, true], ..Self::paper_defaults() }
    }

    /// Checks the settings.
    pub fn check(self) -> Result<TransferValidParams, ParamError> {
        if self.lambda_grid.is_empty() {
            return Err(ParamError::OutOfRange { name: "lambda_grid", value: 0.0, reason: "needs at least one value" });
        }
        if let Some(&bad) = self.lambda_grid.iter().find(|l| !(l.is_finite() && **l > 0.0)) {
            return Err(ParamError::OutOfRange {
                name: "lambda_grid",
                value: bad,
                reason: "values must be positive and finite",
            });
        }
        if !self.prior_on.iter().any(|&b| b) {
            return Err(ParamError::OutOfRange {
                name: "prior_on",
                value: 0.0,
                reason: "at least one parameter needs the prior",
            });
        }
        Ok(TransferValidParams(self))
    }
}

impl TransferValidParams {
    /// The checked settings.
    pub fn get(&self) -> &TransferParams {
        &self.0
    }
}

/// What the source printer contributes: Algorithm 1's covariance at the source's selected
/// `(r_a, r_F)`, and the single-line `λ` of each prior mean (source simulation).
#[derive(Debug, Clone, PartialEq)]
pub struct SourcePrior {
    /// Per-line parameters, mean and covariance of the source.
    pub covariance: ParameterCovariance,
    /// The source fit on all its lines.
    pub source_fit: FittedPiecewise,
    /// `λ` for one target line with `μ = 0`.
    pub single_line_lambda_zero: f64,
    /// `λ` for one target line with `μ = θ̄`.
    pub single_line_lambda_source: f64,
}

impl SourcePrior {
    /// Fits the source printer on all its lines, runs Algorithm 1 at the selected
    /// `(r_a, r_F)`, and simulates single-line transfer on the source to pick `λ`.
    pub fn build(
        source_lines: &[MeasuredLine],
        source_params: &PiecewiseValidParams,
        transfer: &TransferValidParams,
    ) -> Result<Self, FitError> {
        let (source_fit, covariance) = source_covariance(source_lines, source_params)?;
        let per_line = &covariance.per_line;
        let simulate = |mean| simulate_single_line_lambda(source_lines, source_params, per_line, transfer, mean);
        Ok(Self {
            single_line_lambda_zero: simulate(PriorMean::Zero)?,
            single_line_lambda_source: simulate(PriorMean::SourceMean)?,
            covariance,
            source_fit,
        })
    }

    pub(crate) fn single_line_lambda(&self, mean: PriorMean) -> f64 {
        match mean {
            PriorMean::Zero => self.single_line_lambda_zero,
            PriorMean::SourceMean => self.single_line_lambda_source,
        }
    }
}

/// The source fit on all lines and Algorithm 1 at its selected `(r_a, r_F)`: the part of
/// [`SourcePrior::build`] that the priors need (without the single-line `λ`).
pub(crate) fn source_covariance(
    source_lines: &[MeasuredLine],
    source_params: &PiecewiseValidParams,
) -> Result<(FittedPiecewise, ParameterCovariance), FitError> {
    if source_lines.len() < 3 {
        return Err(FitError::NotEnoughData("the source printer needs at least three lines".into()));
    }
    let source_fit = super::fit::fit(source_lines, source_params)?;
    let per_line = per_line_parameters(source_lines, source_params, source_fit.r_a, source_fit.r_f)?;
    Ok((source_fit, estimate_covariance(&per_line)?))
}

/// How `λ` was chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LambdaRule {
    /// No prior (single-printer fit).
    NoPrior,
    /// Inner leave-one-out on the target training lines.
    InnerCrossValidation,
    /// Single target line: simulated transfer on the source printer.
    SourceSimulation,
}

/// A target-printer fit with its `λ` and how it was chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TransferFit {
    /// The fitted model (its `lambda` field repeats the chosen `λ`).
    pub model: FittedPiecewise,
    /// Chosen `λ` (0 without prior).
    pub lambda: f64,
    /// How `λ` was chosen.
    pub rule: LambdaRule,
}

/// Single-printer learning on the target lines (no prior).
pub fn single(target_lines: &[MeasuredLine], target_params: &PiecewiseValidParams) -> Result<TransferFit, FitError> {
    Ok(TransferFit { model: super::fit::fit(target_lines, target_params)?, lambda: 0.0, rule: LambdaRule::NoPrior })
}

/// Transfer with the paper's zero-mean prior `N(0, Σ̂/λ)`.
pub fn transfer_zero_mean(
    target_lines: &[MeasuredLine],
    target_params: &PiecewiseValidParams,
    source: &SourcePrior,
    transfer: &TransferValidParams,
) -> Result<TransferFit, FitError> {
    transfer_fit(target_lines, target_params, source, transfer, PriorMean::Zero)
}

/// Transfer with the prior centred on the source mean, `N(θ̄, Σ̂/λ)` (our extension).
pub fn transfer_source_mean(
    target_lines: &[MeasuredLine],
    target_params: &PiecewiseValidParams,
    source: &SourcePrior,
    transfer: &TransferValidParams,
) -> Result<TransferFit, FitError> {
    transfer_fit(target_lines, target_params, source, transfer, PriorMean::SourceMean)
}

/// Transfer fit with `λ` chosen by the module's rule.
pub fn transfer_fit(
    target_lines: &[MeasuredLine],
    target_params: &PiecewiseValidParams,
    source: &SourcePrior,
    transfer: &TransferValidParams,
    mean: PriorMean,
) -> Result<TransferFit, FitError> {
    let prior = segment_prior(&source.covariance, mean, transfer)?;
    let (lambda, rule) = if target_lines.len() >= 2 {
        let lambdas = &transfer.get().lambda_grid;
        let scores = inner_cv_rmse(target_lines, target_params, &prior, transfer)?;
        (lambdas[argmin(&scores)], LambdaRule::InnerCrossValidation)
    } else {
        (source.single_line_lambda(mean), LambdaRule::SourceSimulation)
    };
    let mut fits = fit_with_prior(target_lines, target_params, &prior, &[lambda], transfer.get().kinematics)?;
    Ok(TransferFit { model: fits.remove(0), lambda, rule })
}

/// The prior `N(μ, Σ/λ)` on the chain parameters for a covariance and mean choice.
/// Only the parameters in `prior_on` enter (their sub-covariance is inverted).
pub fn prior_precision(
    covariance: &ParameterCovariance,
    transfer: &TransferValidParams,
) -> Result<[[f64; TRANSFER_DIM]; TRANSFER_DIM], FitError> {
    let idx: Vec<usize> = (0..TRANSFER_DIM).filter(|&i| transfer.get().prior_on[i]).collect();
    let m = idx.len();
    let sub = Mat::from_fn(m, m, |i, j| covariance.cov[idx[i]][idx[j]]);
    let llt = sub.llt(Side::Lower).map_err(|_| {
        let variances: Vec<String> =
            idx.iter().map(|&i| format!("{} {:.2e}", PiecewiseCoefficients::TRANSFER_NAMES[i], covariance.cov[i][i])).collect();
        FitError::Singular(format!(
            "Algorithm 1's covariance of the source lines' parameters is singular, so it gives no prior: some parameter \
             does not vary from line to line, or varies only with the others (variances across the lines: {})",
            variances.join(", ")
        ))
    })?;
    let inv = llt.solve(Mat::<f64>::identity(m, m));
    let mut p = [[0.0; TRANSFER_DIM]; TRANSFER_DIM];
    for (a, &i) in idx.iter().enumerate() {
        for (b, &j) in idx.iter().enumerate() {
            p[i][j] = 0.5 * (inv[(a, b)] + inv[(b, a)]);
        }
    }
    Ok(p)
}

/// Embeds the precision and mean into the fit's `(β, γ, c, ρ, w_start)` parameters.
pub(crate) fn segment_prior(
    covariance: &ParameterCovariance,
    mean: PriorMean,
    transfer: &TransferValidParams,
) -> Result<SegmentPrior, FitError> {
    let p = prior_precision(covariance, transfer)?;
    let mut prior = SegmentPrior { precision: [[0.0; NP]; NP], mean: [0.0; NP] };
    for i in 0..TRANSFER_DIM {
        prior.precision[i][..TRANSFER_DIM].copy_from_slice(&p[i]);
        if mean == PriorMean::SourceMean {
            prior.mean[i] = covariance.mean[i];
        }
    }
    Ok(prior)
}

/// MAP fits of the target lines for each `λ`, at the `(r_a, r_F)` that `kinematics`
/// gives: each `λ` with its own grid search, or all at the lines' single-printer pair.
pub(crate) fn fit_with_prior(
    lines: &[MeasuredLine],
    params: &PiecewiseValidParams,
    prior: &SegmentPrior,
    lambdas: &[f64],
    kinematics: PriorKinematics,
) -> Result<Vec<FittedPiecewise>, FitError> {
    let grid = match kinematics {
        PriorKinematics::Grid => full_grid(params),
        PriorKinematics::TargetPair => {
            let own = super::fit::fit(lines, params)?;
            vec![(own.r_a, own.r_f)]
        }
    };
    fit_on_grid(lines, params, &grid, Some(prior), lambdas)
}

/// Mean leave-one-out RMSE over the training lines for each `λ`.
fn inner_cv_rmse(
    lines: &[MeasuredLine],
    params: &PiecewiseValidParams,
    prior: &SegmentPrior,
    transfer: &TransferValidParams,
) -> Result<Vec<f64>, FitError> {
    let TransferParams { lambda_grid: lambdas, kinematics, .. } = transfer.get();
    let per_fold = super::loo::run_folds(lines, |train, test, _| {
        let fits = fit_with_prior(train, params, prior, lambdas, *kinematics)?;
        fits.iter()
            .map(|f| Ok(rmse(&f.predict(&test.nominal, &test.positions_mm)?, &test.widths_mm)))
            .collect::<Result<Vec<f64>, FitError>>()
    })?;
    Ok(mean_columns(&per_fold, lambdas.len()))
}

/// Source simulation of single-line transfer (see the module docs).
fn simulate_single_line_lambda(
    lines: &[MeasuredLine],
    params: &PiecewiseValidParams,
    per_line: &[[f64; TRANSFER_DIM]],
    transfer: &TransferValidParams,
    mean: PriorMean,
) -> Result<f64, FitError> {
    let lambdas = &transfer.get().lambda_grid;
    let per_line_scores = (0..lines.len())
        .into_par_iter()
        .map(|j| {
            let others: Vec<[f64; TRANSFER_DIM]> =
                per_line.iter().enumerate().filter(|&(i, _)| i != j).map(|(_, t)| *t).collect();
            let prior = segment_prior(&estimate_covariance(&others)?, mean, transfer)?;
            let one = std::slice::from_ref(&lines[j]);
            let fits = fit_with_prior(one, params, &prior, lambdas, transfer.get().kinematics)?;
            fits.iter().map(|f| mean_rmse_on_others(f, lines, j)).collect::<Result<Vec<f64>, FitError>>()
        })
        .collect::<Result<Vec<Vec<f64>>, FitError>>()?;
    Ok(lambdas[argmin(&mean_columns(&per_line_scores, lambdas.len()))])
}

fn mean_rmse_on_others(model: &FittedPiecewise, lines: &[MeasuredLine], skip: usize) -> Result<f64, FitError> {
    let mut total = 0.0;
    for (_, l) in lines.iter().enumerate().filter(|&(i, _)| i != skip) {
        total += rmse(&model.predict(&l.nominal, &l.positions_mm)?, &l.widths_mm);
    }
    Ok(total / (lines.len() - 1) as f64)
}

/// Column means of equally long rows (summed in row order).
pub(crate) fn mean_columns(rows: &[Vec<f64>], n: usize) -> Vec<f64> {
    (0..n).map(|k| rows.iter().map(|r| r[k]).sum::<f64>() / rows.len() as f64).collect()
}

/// Index of the smallest finite value (first on ties).
pub(crate) fn argmin(values: &[f64]) -> usize {
    let mut best = 0;
    for (k, &v) in values.iter().enumerate() {
        if v < values[best] || !values[best].is_finite() {
            best = k;
        }
    }
    best
}

/// A training subset of the target conditions (Fig. 9).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ConditionSubset {
    /// Condition indices, ascending.
    pub indices: Vec<usize>,
    /// Stable id: `n{size}-` followed by the indices joined by `_`, e.g. `n3-0_4_8`.
    pub id: String,
}

/// The stable id of a subset (see [`ConditionSubset::id`]).
pub fn subset_id(indices: &[usize]) -> String {
    let parts: Vec<String> = indices.iter().map(usize::to_string).collect();
    format!("n{}-{}", indices.len(), parts.join("_"))
}

/// All subsets of `size` out of `n_conditions` in lexicographic order.
pub fn condition_subsets(n_conditions: usize, size: usize) -> Vec<ConditionSubset> {
    let mut out = Vec::new();
    if size == 0 || size > n_conditions {
        return out;
    }
    let mut idx: Vec<usize> = (0..size).collect();
    loop {
        out.push(ConditionSubset { id: subset_id(&idx), indices: idx.clone() });
        let Some(pos) = (0..size).rev().find(|&i| idx[i] < n_conditions - size + i) else {
            return out;
        };
        idx[pos] += 1;
        for i in pos + 1..size {
            idx[i] = idx[i - 1] + 1;
        }
    }
}

/// All proper, non-empty subsets (sizes `1..n_conditions`), by size then
/// lexicographically: 510 for nine conditions.
pub fn all_condition_subsets(n_conditions: usize) -> Vec<ConditionSubset> {
    (1..n_conditions).flat_map(|n| condition_subsets(n_conditions, n)).collect()
}

#[cfg(test)]
mod tests {
    use super::super::fit::fit;
    use super::super::hyperparams::PiecewiseParams;
    use super::super::small_linalg::spd_solve;
    use super::super::test_support::{synthetic_lines, synthetic_truth};
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_spd(n: usize, rng: &mut ChaCha8Rng) -> Mat<f64> {
        let m = Mat::from_fn(n, n, |_, _| rng.random_range(-1.0..1.0));
        Mat::from_fn(n, n, |i, j| (0..n).map(|k| m[(k, i)] * m[(k, j)]).sum::<f64>() + if i == j { 0.5 } else { 0.0 })
    }

    #[test]
    fn a_source_parameter_that_does_not_vary_is_named_as_a_singular_covariance() {
        // Lines of identical steady width c: Algorithm 1's covariance has no variance in c.
        let per_line: Vec<[f64; TRANSFER_DIM]> =
            (0..5).map(|k| [0.1 * k as f64, (k * k) as f64, 0.75, -0.02 * (k % 2) as f64]).collect();
        let covariance = estimate_covariance(&per_line).unwrap();
        let transfer = TransferParams::paper_defaults().check().unwrap();
        let err = prior_precision(&covariance, &transfer).unwrap_err().to_string();
        assert!(err.contains("does not vary from line to line") && err.contains("c_mm 0.00e0"), "{err}");
        let varied: Vec<[f64; TRANSFER_DIM]> =
            per_line.iter().enumerate().map(|(k, p)| [p[0], p[1], 0.7 + 0.01 * (k % 3) as f64, p[3]]).collect();
        assert!(prior_precision(&estimate_covariance(&varied).unwrap(), &transfer).is_ok());
    }

    #[test]
    fn map_solution_satisfies_its_normal_equations() {
        // Residual of (XᵀX + λΣ⁻¹)θ − (Xᵀy + λΣ⁻¹μ) must vanish to rounding, with a
        // tolerance that grows with the problem size and the matrix scale.
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for &(rows, n, lambda) in &[(50usize, 4usize, 0.3), (200, 5, 10.0), (3, 4, 1.0)] {
            let x = Mat::from_fn(rows, n, |_, _| rng.random_range(-2.0..2.0));
            let y: Vec<f64> = (0..rows).map(|_| rng.random_range(-1.0..1.0)).collect();
            let xtx = Mat::from_fn(n, n, |i, j| (0..rows).map(|r| x[(r, i)] * x[(r, j)]).sum());
            let xty: Vec<f64> = (0..n).map(|i| (0..rows).map(|r| x[(r, i)] * y[r]).sum()).collect();
            let prec = random_spd(n, &mut rng);
            let mu: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let theta = solve_map(xtx.as_ref(), &xty, prec.as_ref(), &mu, lambda).unwrap();
            let scale = (0..n)
                .flat_map(|i| (0..n).map(move |j| (i, j)))
                .map(|(i, j)| (xtx[(i, j)] + lambda * prec[(i, j)]).abs())
                .fold(0.0, f64::max);
            let norm_theta = theta.iter().map(|t| t.abs()).fold(0.0, f64::max);
            for i in 0..n {
                let lhs: f64 = (0..n).map(|j| (xtx[(i, j)] + lambda * prec[(i, j)]) * theta[j]).sum();
                let rhs = xty[i] + lambda * (0..n).map(|j| prec[(i, j)] * mu[j]).sum::<f64>();
                let tol = 1e-13 * (rows * n) as f64 * (scale * norm_theta + rhs.abs()).max(1.0);
                assert!((lhs - rhs).abs() < tol, "row {i}: {lhs} vs {rhs}");
            }
            // The allocation-free solver of the grid search gives the same θ.
            if n == 5 {
                let a: [[f64; 5]; 5] =
                    std::array::from_fn(|i| std::array::from_fn(|j| xtx[(i, j)] + lambda * prec[(i, j)]));
                let b: [f64; 5] =
                    std::array::from_fn(|i| xty[i] + lambda * (0..5).map(|j| prec[(i, j)] * mu[j]).sum::<f64>());
                let small = spd_solve(&a, &b).unwrap();
                for i in 0..5 {
                    assert!((small[i] - theta[i]).abs() < 1e-10 * (1.0 + theta[i].abs()));
                }
            }
        }
        let bad = solve_map(
            Mat::<f64>::identity(2, 2).as_ref(),
            &[1.0],
            Mat::<f64>::identity(2, 2).as_ref(),
            &[0.0, 0.0],
            1.0,
        );
        assert!(matches!(bad, Err(FitError::Dimension(_))));
    }

    #[test]
    fn map_limits_are_least_squares_and_prior_mean() {
        // λ → 0 gives the least-squares solution, λ → ∞ the prior mean.
        let xtx = Mat::from_fn(2, 2, |i, j| [[4.0, 1.0], [1.0, 3.0]][i][j]);
        let xty = [1.0, 2.0];
        let p = Mat::<f64>::identity(2, 2);
        let mu = [5.0, -3.0];
        let ls = solve_map(xtx.as_ref(), &xty, p.as_ref(), &mu, 0.0).unwrap();
        assert!((4.0 * ls[0] + ls[1] - 1.0).abs() < 1e-12 && (ls[0] + 3.0 * ls[1] - 2.0).abs() < 1e-12);
        let strong = solve_map(xtx.as_ref(), &xty, p.as_ref(), &mu, 1e12).unwrap();
        assert!((strong[0] - 5.0).abs() < 1e-9 && (strong[1] + 3.0).abs() < 1e-9);
    }

    #[test]
    fn covariance_uses_k_minus_one() {
        // θ = (1,0,0,0), (3,0,0,0): mean 2, variance ((1)² + (1)²)/(2 − 1) = 2.
        let c = estimate_covariance(&[[1.0, 0.0, 0.0, 0.0], [3.0, 0.0, 0.0, 0.0]]).unwrap();
        assert_eq!(c.mean[0], 2.0);
        assert_eq!(c.cov[0][0], 2.0);
        assert!(matches!(estimate_covariance(&[[0.0; 4]]), Err(FitError::NotEnoughData(_))));
    }

    #[test]
    fn log_lambda_grids_run_from_one_millionth_to_ten_thousand() {
        let half = TransferParams::log_lambda_grid(0.5);
        assert_eq!(half.len(), 21);
        assert_eq!((half[0], half[2], half[20]), (1e-6, 1e-5, 1e4));
        let whole = TransferParams::log_lambda_grid(1.0);
        let powers: Vec<f64> = (0..11).map(|k| 10f64.powi(k - 6)).collect();
        assert_eq!(whole, powers, "whole decades are the powers of ten, bit for bit");
        assert_eq!(TransferParams::log_lambda_grid(3.0), [1e-6, 1e-3, 1.0, 1e3]);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let grid = TransferParams::log_lambda_grid(bad);
            assert!(grid.is_empty(), "{bad}");
            assert!(TransferParams { lambda_grid: grid, ..TransferParams::paper_defaults() }.check().is_err());
        }
    }

    #[test]
    fn subsets_of_nine_conditions() {
        // C(9, n) per size and 510 = 2⁹ − 2 proper non-empty subsets; ids unique, stable.
        let binom = [1, 9, 36, 84, 126, 126, 84, 36, 9, 1];
        for n in 1..=8 {
            assert_eq!(condition_subsets(9, n).len(), binom[n]);
        }
        let all = all_condition_subsets(9);
        assert_eq!(all.len(), 510);
        let ids: std::collections::HashSet<&str> = all.iter().map(|s| s.id.as_str()).collect();
        assert_eq!(ids.len(), 510);
        assert_eq!(all[0].id, "n1-0");
        assert_eq!(all[9].id, "n2-0_1");
        assert_eq!(all[509].id, "n8-1_2_3_4_5_6_7_8");
        assert!(all.iter().all(|s| s.indices.windows(2).all(|w| w[0] < w[1])));
    }

    #[test]
    fn prior_with_vanishing_lambda_reproduces_single_fit() {
        // With λ → 0 the MAP fixed point is the paper's per-segment least squares.
        let truth = synthetic_truth(false);
        let mut lines = synthetic_lines(&truth, 0.2);
        for (k, l) in lines.iter_mut().enumerate() {
            for (i, w) in l.widths_mm.iter_mut().enumerate() {
                *w += 0.01 * ((i * 5 + k) as f64).cos();
            }
        }
        let params = PiecewiseParams::paper_defaults_without_blob().check().unwrap();
        let transfer = TransferParams::paper_defaults().check().unwrap();
        let cov = estimate_covariance(&[
            [0.004, 0.02, 0.8, 0.12],
            [0.005, 0.025, 0.78, 0.13],
            [0.003, 0.018, 0.82, 0.1],
            [0.0045, 0.021, 0.79, 0.125],
            [0.0042, 0.019, 0.81, 0.11],
        ])
        .unwrap();
        let prior = segment_prior(&cov, PriorMean::SourceMean, &transfer).unwrap();
        let with = fit_with_prior(&lines[..4], &params, &prior, &[1e-12], PriorKinematics::Grid).unwrap();
        let without = fit(&lines[..4], &params).unwrap();
        let (a, b) = (with[0].coefficients, without.coefficients);
        assert_eq!((with[0].r_a, with[0].r_f), (without.r_a, without.r_f));
        for (x, y) in [(a.beta, b.beta), (a.gamma, b.gamma), (a.c_mm, b.c_mm), (a.rho, b.rho)] {
            assert!((x - y).abs() < 1e-6 * (1.0 + y.abs()), "{x} vs {y}");
        }
        // A very strong prior pulls the transferable parameters onto the source mean.
        let strong = fit_with_prior(&lines[..4], &params, &prior, &[1e9], PriorKinematics::Grid).unwrap();
        let s = strong[0].coefficients.transfer_vector();
        for i in 0..4 {
            assert!((s[i] - cov.mean[i]).abs() < 1e-3 * (1.0 + cov.mean[i].abs()));
        }
    }

    #[test]
    fn transfer_fit_picks_lambda_by_the_documented_rule() {
        // Source: model-generated lines with a blob plus per-line perturbations; target:
        // a no-blob model. One target line → source simulation; two → inner CV.
        let source_truth = synthetic_truth(true);
        let mut source = synthetic_lines(&source_truth, 0.2);
        for (k, l) in source.iter_mut().enumerate() {
            for w in l.widths_mm.iter_mut() {
                *w *= 1.0 + 0.01 * (k as f64 - 4.0);
            }
        }
        let target = synthetic_lines(&synthetic_truth(false), 0.2);
        let sp = PiecewiseParams::paper_defaults().check().unwrap();
        let tp = PiecewiseParams::paper_defaults_without_blob().check().unwrap();
        let transfer = TransferParams::paper_defaults().check().unwrap();
        let prior = SourcePrior::build(&source, &sp, &transfer).unwrap();
        assert_eq!(prior.covariance.per_line.len(), 9);
        let grid = &transfer.get().lambda_grid;
        let one = transfer_source_mean(&target[..1], &tp, &prior, &transfer).unwrap();
        assert_eq!(one.rule, LambdaRule::SourceSimulation);
        assert_eq!(one.lambda, prior.single_line_lambda_source);
        let two = transfer_zero_mean(&target[..2], &tp, &prior, &transfer).unwrap();
        assert_eq!(two.rule, LambdaRule::InnerCrossValidation);
        assert!(grid.contains(&two.lambda) && grid.contains(&one.lambda));
        assert_eq!(two.model.lambda, two.lambda);
        let s = single(&target[..2], &tp).unwrap();
        assert_eq!(s.rule, LambdaRule::NoPrior);
        let bad = TransferParams { prior_on: [false; 4], ..TransferParams::paper_defaults() };
        assert!(bad.check().is_err());
    }
}
