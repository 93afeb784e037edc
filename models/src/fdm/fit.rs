//! Fitting the five-phase piecewise model (paper 000, Sec. II-A, the 8-step procedure
//! after eq. 3), optionally with the informative prior of eqs 4-5 (Sec. II-B).
//!
//! For every pair `(r_a, r_F)` of the grid of eq. 1 (441 pairs by default, evaluated in
//! parallel with rayon, per-thread scratch buffers, no allocation per sample):
//!
//! 1. actual kinematics of every training line; nominal time and speed of every sample;
//! 2. bp2, bp4 from the kinematics; bp1 of each line is the time of its measured width
//!    minimum (smoothed, see `PiecewiseParams::smoothing_mm`), whose *position* does not
//!    depend on `r`;
//! 3. p1: `w = 1/(α1 v + α2)` on the pooled samples `t ≤ bp1` of all lines, fitted by
//!    linear least squares on `1/w = α1 v + α2` and refined by Gauss-Newton on the widths
//!    themselves (step halving, keeping `α1 v + α2 > 0` on the data);
//! 4. p2, p3, p4, p5: per-segment linear least squares with the continuity offsets
//!    `w(bp_{i-1})` of the model's own chain (eq. 3). For a fixed bp3 partition the
//!    offsets are linear in the parameters, and the parameters that minimise every
//!    segment's sum of squares with the offsets held at their own values solve one
//!    ≤ 5 × 5 non-symmetric system (stack LU; with a prior `λ Σ⁻¹` is added, eq. 5).
//!    Without a prior this equals the paper's sequential segment-by-segment fit. bp3
//!    starts at the first crossing of `c` by the smoothed measured widths, then follows
//!    the model (where p3 reaches `c`) until the partition stops changing. Segment sums
//!    come from prefix sums, and the first p4 sample of a bp3 from a bucket index of the
//!    sample times, so one partition update costs O(lines);
//! 5. the training RMSE of the whole fitted curve (measured bp1, model chain) is the
//!    grid criterion (step 6-8); the pair with the smallest RMSE wins (ties: first in
//!    grid order, so the result does not depend on the number of threads).
//!
//! The bp1 power law (eq. 2) is then fitted on the winning pair's bp1 times and actual
//! accelerations (`Bp1PowerLaw::fit`); the prediction of a new line uses it, never the
//! line's own width minimum.
//!
//! Code map: steps 1-2 and the per-line sums of step 4 depend only on the line and the
//! pair (`LineAtPair`); steps 3-4 for one training set at one pair, once per prior
//! configuration, are `evaluate_set`: the p1 fit of step 3 is `p1`, the chain fixed
//! point of step 4 under every configuration is `chains` (several configurations at
//! once, their LU solves side by side). The rows of β and w_start of the step-4
//! equations take the p2 sums only, so no partition changes them (`FIXED_ROWS`): the
//! chain solve scales them for the LU once per configuration, not once per iteration.
//! The plain grid search calls both for its lines; the Fig. 9 cross-validation
//! (`transfer_cv`) computes each `LineAtPair` once per pair and shares it between all
//! training subsets, and reuses a subset's p1 fit from the previous pair where the p1
//! samples did not change (`P1Memo`). Every path gives the same numbers, bit for bit.

use std::borrow::Borrow;

use rayon::prelude::*;

use super::errors::FitError;
use super::hyperparams::PiecewiseValidParams;
use super::kinematics::LineKinematics;
use super::line::MeasuredLine;
use super::piecewise::{
    bp3_time, p2_regressor, p3_regressor, p5_regressor, Bp1PowerLaw, LineChain, PiecewiseCoefficients,
};
use super::predict::FittedPiecewise;
use super::small_linalg::{equilibrate_row, spd_solve, LuBatch};

mod chains;
mod p1;

use chains::{solve_chains, ChainScratch, LANES, SINGULAR};
use p1::{fit_p1, P1Samples};

/// Number of chain parameters solved by least squares: `β, γ, c, ρ, w_start`.
pub(crate) const NP: usize = 5;
pub(crate) const BETA: usize = 0;
pub(crate) const GAMMA: usize = 1;
pub(crate) const C: usize = 2;
pub(crate) const RHO: usize = 3;
pub(crate) const W_START: usize = 4;

/// A Gaussian prior `N(μ, Σ/λ)` on `(β, γ, c, ρ, w_start)` given by its precision `Σ⁻¹`
/// (zero rows for parameters without a prior) and mean `μ`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SegmentPrior {
    pub(crate) precision: [[f64; NP]; NP],
    pub(crate) mean: [f64; NP],
}

/// Fits the piecewise model to the training lines with the paper's grid search over
/// `r_a`, `r_F` (no prior: the single-printer fit of Sec. II-A).
pub fn fit(lines: &[MeasuredLine], params: &PiecewiseValidParams) -> Result<FittedPiecewise, FitError> {
    let grid = full_grid(params);
    let mut fits = fit_on_grid(lines, params, &grid, None, &[0.0])?;
    Ok(fits.remove(0))
}

/// Fits at one fixed `(r_a, r_F)` pair (no grid search), e.g. the per-line fits of
/// Algorithm 1 at the source printer's selected pair.
pub fn fit_at(
    lines: &[MeasuredLine],
    params: &PiecewiseValidParams,
    r_a: f64,
    r_f: f64,
) -> Result<FittedPiecewise, FitError> {
    let mut fits = fit_on_grid(lines, params, &[(r_a, r_f)], None, &[0.0])?;
    Ok(fits.remove(0))
}

/// All `(r_a, r_F)` pairs of the grid, `r_a` major.
pub(crate) fn full_grid(params: &PiecewiseValidParams) -> Vec<(f64, f64)> {
    let r = params.r_values();
    r.iter().flat_map(|&ra| r.iter().map(move |&rf| (ra, rf))).collect()
}

/// The fit for each `λ` in `lambdas` (one fit when `prior` is `None`), each with its own
/// best grid pair.
pub(crate) fn fit_on_grid(
    lines: &[MeasuredLine],
    params: &PiecewiseValidParams,
    grid: &[(f64, f64)],
    prior: Option<&SegmentPrior>,
    lambdas: &[f64],
) -> Result<Vec<FittedPiecewise>, FitError> {
    if grid.is_empty() || lambdas.is_empty() {
        return Err(FitError::NotEnoughData("empty grid or λ list".into()));
    }
    let prepared = prepare_lines(lines, params)?;
    // With a prior, the fit without one comes first: the solves with the prior are also
    // started where it ends (see `chains`), as in every other grid search.
    let (n_lambda, first) = if prior.is_some() { (lambdas.len(), 1) } else { (1, 0) };
    let weighted = lambdas[..n_lambda].iter().map(|&l| prior.map(|p| WeightedPrior::new(p, l)));
    let configs: Vec<ChainPrior> = std::iter::repeat_n(None, first).chain(weighted).collect();
    let outcomes: Vec<Result<GridOutcome, FitError>> = grid
        .par_iter()
        .map_init(|| Scratch::new(&prepared), |scratch, &(ra, rf)| evaluate_pair(params, ra, rf, scratch, &configs))
        .collect();
    (0..n_lambda).map(|k| best_fit(&prepared, params, &outcomes, first + k, lambdas[k])).collect()
}

/// A measured line with what the fit derives from the data alone.
pub(crate) struct PreparedLine<'a> {
    line: &'a MeasuredLine,
    smoothed: Vec<f64>,
    /// Position of the measured width minimum (bp1), if the printer has a start blob.
    bp1_pos_mm: Option<f64>,
    /// Mean measured width (the fallback initial `c`).
    mean_width_mm: f64,
    /// `1/w` of the p1 samples (those up to the measured bp1), for the p1 fit.
    p1_inverse_widths: Vec<f64>,
}

pub(crate) fn prepare_lines<'a>(
    lines: &'a [MeasuredLine],
    params: &PiecewiseValidParams,
) -> Result<Vec<PreparedLine<'a>>, FitError> {
    if lines.is_empty() {
        return Err(FitError::NotEnoughData("no training lines".into()));
    }
    let out = lines.iter().enumerate().map(|(i, l)| prepare_line(l, i, params)).collect::<Result<Vec<_>, _>>()?;
    check_p1_count(&out, params)?;
    Ok(out)
}

/// Validates one line (`index` names it in errors) and derives its smoothed widths,
/// measured bp1 position and mean width.
pub(crate) fn prepare_line<'a>(
    line: &'a MeasuredLine,
    index: usize,
    params: &PiecewiseValidParams,
) -> Result<PreparedLine<'a>, FitError> {
    line.validate(index)?;
    let smoothed = moving_average(&line.positions_mm, &line.widths_mm, params.get().smoothing_mm);
    let bp1_pos_mm = params.has_start_blob().then(|| measured_bp1_position(line, &smoothed, params));
    let mean_width_mm = line.widths_mm.iter().sum::<f64>() / line.len() as f64;
    let p1_end = bp1_pos_mm.map_or(0, |x1| line.positions_mm.partition_point(|&x| x <= x1));
    let p1_inverse_widths = line.widths_mm[..p1_end].iter().map(|w| 1.0 / w).collect();
    Ok(PreparedLine { line, smoothed, bp1_pos_mm, mean_width_mm, p1_inverse_widths })
}

/// With a start blob, the pooled p1 fit of a training set needs at least three samples.
pub(crate) fn check_p1_count<'a, P: Borrow<PreparedLine<'a>>>(
    prepared: &[P],
    params: &PiecewiseValidParams,
) -> Result<(), FitError> {
    if params.has_start_blob() {
        let n_p1: usize = prepared.iter().map(|p| p1_count(p.borrow())).sum();
        if n_p1 < 3 {
            return Err(FitError::NotEnoughData(format!("only {n_p1} samples before the width minima (phase p1)")));
        }
    }
    Ok(())
}

fn p1_count(p: &PreparedLine) -> usize {
    p.bp1_pos_mm.map_or(0, |x| p.line.positions_mm.partition_point(|&xi| xi <= x))
}

/// Position of the smoothed width minimum in `[0, min(x_dec, fraction·L)]`.
fn measured_bp1_position(line: &MeasuredLine, smoothed: &[f64], params: &PiecewiseValidParams) -> f64 {
    let k = &line.nominal;
    let x_max = k.decel_start_mm().min(params.get().bp1_search_fraction * k.length_mm);
    let end = line.positions_mm.partition_point(|&x| x <= x_max).max(1);
    let mut best = 0;
    for i in 1..end {
        if smoothed[i] < smoothed[best] {
            best = i;
        }
    }
    line.positions_mm[best]
}

/// Centred moving average over a window of `window_mm` (all samples within ±window/2).
pub(crate) fn moving_average(xs: &[f64], ys: &[f64], window_mm: f64) -> Vec<f64> {
    if window_mm <= 0.0 {
        return ys.to_vec();
    }
    let half = 0.5 * window_mm;
    let mut prefix = Vec::with_capacity(ys.len() + 1);
    prefix.push(0.0);
    for &y in ys {
        prefix.push(prefix.last().copied().unwrap_or(0.0) + y);
    }
    let (mut lo, mut hi) = (0, 0);
    xs.iter()
        .map(|&x| {
            while xs[lo] < x - half {
                lo += 1;
            }
            while hi < xs.len() && xs[hi] <= x + half {
                hi += 1;
            }
            (prefix[hi] - prefix[lo]) / (hi - lo) as f64
        })
        .collect()
}

/// Running sums of `(x, y)` pairs for one segment's least squares.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Moments {
    pub(crate) n: f64,
    pub(crate) sx: f64,
    pub(crate) sxx: f64,
    pub(crate) sy: f64,
    pub(crate) syy: f64,
    pub(crate) sxy: f64,
}

impl Moments {
    fn add(&mut self, x: f64, y: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sxx += x * x;
        self.sy += y;
        self.syy += y * y;
        self.sxy += x * y;
    }

    fn minus(&self, o: &Self) -> Self {
        Self {
            n: self.n - o.n,
            sx: self.sx - o.sx,
            sxx: self.sxx - o.sxx,
            sy: self.sy - o.sy,
            syy: self.syy - o.syy,
            sxy: self.sxy - o.sxy,
        }
    }

    /// `Σ (y − off − θ x)²`.
    fn sse(&self, off: f64, theta: f64) -> f64 {
        let r = self.syy - 2.0 * off * self.sy + self.n * off * off - 2.0 * theta * (self.sxy - off * self.sx)
            + theta * theta * self.sxx;
        r.max(0.0)
    }
}

/// Per-line buffers of one grid pair: nominal times and speeds of every sample and the
/// prefix sums of the p3 regressor over the region `(start3, bp4]`. When `indexed`, also
/// the running maximum of the smoothed widths over that region (for the initial bp3)
/// and a bucket index of the region's times (for the partition lookups of the chain
/// solve). Both cost O(n) per pair and save a scan or a binary search per lookup: worth
/// it when many training sets and priors share the line, not in a single fit.
struct LineScratch {
    t: Vec<f64>,
    v: Vec<f64>,
    pre3: Vec<Moments>,
    indexed: bool,
    max3: Vec<f64>,
    buckets: TimeBuckets,
}

/// Equal-width buckets over the times `t[i3..i4]` of the p3/p4 region: bucket `b`
/// starts at `t0 + b·width`, `below` samples of the region have a time at or before
/// that edge, and `next` holds the times of the two samples after it (kept side by side:
/// one cache line per lookup). Counting the region samples with `t ≤ bp3` then starts at
/// the bucket of `bp3` and takes a step or two instead of a binary search. The times
/// belong to increasing positions and are therefore ascending, so the count is the
/// `partition_point` a binary search would find.
#[derive(Default)]
struct TimeBuckets {
    t0: f64,
    width: f64,
    per_s: f64,
    buckets: Vec<Bucket>,
}

/// One bucket of [`TimeBuckets`]: its edge, the region samples at or before it and the
/// times of the next two (`∞` past the region).
#[derive(Debug, Clone, Copy)]
struct Bucket {
    edge: f64,
    next: [f64; 2],
    below: u32,
}

impl TimeBuckets {
    fn build(&mut self, t: &[f64]) {
        self.buckets.clear();
        let (Some(&t0), Some(&t1)) = (t.first(), t.last()) else {
            return;
        };
        let n = t.len();
        self.t0 = t0;
        self.width = (t1 - t0) / n as f64;
        self.per_s = if self.width > 0.0 { 1.0 / self.width } else { 0.0 };
        let mut j = 0;
        for b in 0..n {
            let edge = self.t0 + b as f64 * self.width;
            while j < n && t[j] <= edge {
                j += 1;
            }
            let next = |k: usize| t.get(j + k).copied().unwrap_or(f64::INFINITY);
            self.buckets.push(Bucket { edge, next: [next(0), next(1)], below: j as u32 });
        }
    }

    /// Number of leading samples of `t` (the ascending slice the buckets were built on)
    /// with `t ≤ x`, i.e. `t.partition_point(|&ti| ti <= x)`.
    fn count_le(&self, t: &[f64], x: f64) -> usize {
        // Also catches NaN and an empty region.
        let inside = !self.buckets.is_empty() && x >= self.t0;
        if !inside {
            return 0;
        }
        // x ≥ t0 here, so the bucket index is at least 0 (and at most the last).
        let mut b = (((x - self.t0) * self.per_s) as i64).min(self.buckets.len() as i64 - 1) as usize;
        // Rounding may put x just below its bucket's edge.
        while self.buckets[b].edge > x {
            b -= 1;
        }
        let bucket = self.buckets[b];
        // With one bucket per sample, x is usually at most two samples past its bucket's
        // edge: those steps without a branch, the rare further ones in the loop.
        let [next, after] = bucket.next;
        let mut j = bucket.below as usize + usize::from(next <= x) + usize::from(after <= x);
        if after <= x {
            while j < t.len() && t[j] <= x {
                j += 1;
            }
        }
        j
    }
}

/// One training line at one grid pair `(r_a, r_F)`: everything the fit needs of it that
/// depends neither on the other training lines nor on `λ`. All the per-sample work of
/// the grid search happens here, so the line can be computed once per pair and shared
/// by every training set that contains it.
pub(crate) struct LineAtPair<'p> {
    prep: &'p PreparedLine<'p>,
    buf: LineScratch,
    /// Breakpoints and segment sums; `w_bp1` and `bp3_init` are set per training set.
    fit: LineFit,
    /// Speed at bp1, from which `w(bp1)` follows once the pooled p1 law is known.
    v_bp1: f64,
    /// Width sum and sample count over the second half of the p3/p4 region.
    c_sum: f64,
    c_n: f64,
    /// Number of p1 samples (those up to the measured bp1).
    p1_end: usize,
    /// The p1 samples' speeds at the last update, whether that update succeeded, and
    /// whether they were the same, bit for bit, at the successful update before it
    /// ([`P1Memo`]).
    p1_speeds: Vec<f64>,
    p1_valid: bool,
    p1_unchanged: bool,
}

/// A training set's pooled p1 fit (`None`: it failed) at the grid pair its owner
/// evaluated last, kept for the next pair. Where none of the set's p1 speeds changed
/// between the two pairs (often: the p1 samples lie early in the acceleration ramp, which
/// `r_F` does not change), the p1 samples are the same, so the fit, a function of them,
/// is the same: it is reused instead of recomputed.
pub(crate) type P1Memo = Option<Option<((f64, f64), f64)>>;

impl<'p> LineAtPair<'p> {
    /// Buffers for one line in one fit; call [`Self::update`] before use.
    pub(crate) fn new(prep: &'p PreparedLine<'p>) -> Self {
        Self::with_index(prep, false)
    }

    /// Buffers for a line shared by many training sets and priors, with the lookup
    /// indices of `LineScratch` (same results, faster repeated lookups).
    pub(crate) fn indexed(prep: &'p PreparedLine<'p>) -> Self {
        Self::with_index(prep, true)
    }

    fn with_index(prep: &'p PreparedLine<'p>, indexed: bool) -> Self {
        let n = prep.line.len();
        let buf = LineScratch {
            t: vec![0.0; n],
            v: vec![0.0; n],
            pre3: Vec::with_capacity(n + 1),
            indexed,
            max3: Vec::new(),
            buckets: TimeBuckets::default(),
        };
        let (p1_speeds, p1_valid, p1_unchanged) = (Vec::new(), false, false);
        let (fit, v_bp1, c_sum, c_n, p1_end) = (LineFit::default(), 0.0, 0.0, 0.0, 0);
        Self { prep, buf, fit, v_bp1, c_sum, c_n, p1_end, p1_speeds, p1_valid, p1_unchanged }
    }

    /// Recomputes everything for the grid pair `(r_a, r_F)`. On error the contents are
    /// stale and must not be used.
    pub(crate) fn update(&mut self, r_a: f64, r_f: f64) -> Result<(), FitError> {
        let p = self.prep;
        let was_valid = std::mem::replace(&mut self.p1_valid, false);
        let kin = p.line.nominal.scaled(r_a, r_f)?;
        let ls = &mut self.buf;
        kin.time_and_speed_into(&p.line.positions_mm, &mut ls.t, &mut ls.v);
        self.p1_end = p.bp1_pos_mm.map_or(0, |x1| p.line.positions_mm.partition_point(|&x| x <= x1));
        let speeds = &ls.v[..self.p1_end];
        let same =
            |old: &[f64]| old.len() == speeds.len() && old.iter().zip(speeds).all(|(a, b)| a.to_bits() == b.to_bits());
        self.p1_unchanged = was_valid && same(&self.p1_speeds);
        self.p1_speeds.clear();
        self.p1_speeds.extend_from_slice(speeds);
        let (lf, v_bp1) = line_moments(p, &kin, ls);
        let mid = 0.5 * (lf.start3 + lf.bp4);
        let j = lf.i3 + ls.t[lf.i3..lf.i4].partition_point(|&t| t < mid);
        let m = ls.pre3[lf.i4 - lf.i3].minus(&ls.pre3[j - lf.i3]);
        if ls.indexed {
            let mut run = f64::NEG_INFINITY;
            ls.max3.clear();
            ls.max3.extend(p.smoothed[lf.i3..lf.i4].iter().map(|&s| {
                run = run.max(s);
                run
            }));
            ls.buckets.build(&ls.t[lf.i3..lf.i4]);
        }
        (self.fit, self.v_bp1, self.c_sum, self.c_n) = (lf, v_bp1, m.sy, m.n);
        self.p1_valid = true;
        Ok(())
    }
}

/// Per-thread buffers of the plain grid search: every training line at the current pair.
struct Scratch<'p> {
    lines: Vec<LineAtPair<'p>>,
    set: SetScratch,
}

impl<'p> Scratch<'p> {
    fn new(prepared: &'p [PreparedLine<'p>]) -> Self {
        Self { lines: prepared.iter().map(LineAtPair::new).collect(), set: SetScratch::default() }
    }
}

/// What one grid pair needs of one line: breakpoints, index ranges and segment sums.
#[derive(Debug, Clone, Copy, Default)]
struct LineFit {
    start3: f64,
    bp4: f64,
    top: f64,
    w_bp1: f64,
    /// p2 regressor at the start of p3 (0 when p2 is empty).
    g_start3: f64,
    /// p3 regressor at bp4.
    s_bp4: f64,
    p2: Moments,
    p5: Moments,
    i3: usize,
    i4: usize,
    bp3_init: f64,
}

/// Result of one grid pair: p1 coefficients, and per λ the chain parameters and SSE.
struct GridOutcome {
    r_a: f64,
    r_f: f64,
    alpha: (f64, f64),
    per_lambda: Vec<([f64; NP], f64)>,
}

fn evaluate_pair(
    params: &PiecewiseValidParams,
    r_a: f64,
    r_f: f64,
    scratch: &mut Scratch,
    configs: &[ChainPrior],
) -> Result<GridOutcome, FitError> {
    for line in scratch.lines.iter_mut() {
        line.update(r_a, r_f)?;
    }
    let mut per_lambda = Vec::with_capacity(configs.len());
    let alpha = evaluate_set(&scratch.lines, params, (&mut scratch.set, &mut None), configs, &mut per_lambda)?;
    Ok(GridOutcome { r_a, r_f, alpha, per_lambda })
}

/// The prior of one chain solve: none, or a prior with its weight `λ`.
pub(crate) type ChainPrior = Option<WeightedPrior>;

/// The prior terms of eq. 5 at one `λ`, multiplied out once: `λ·Σ⁻¹` for the matrix and
/// the products `(λ·Σ⁻¹)_ij · μ_j` for the right-hand side (same values, in the same
/// order, as forming them in every iteration).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WeightedPrior {
    matrix: [[f64; NP]; NP],
    rhs_terms: [[f64; NP]; NP],
}

impl WeightedPrior {
    pub(crate) fn new(prior: &SegmentPrior, lambda: f64) -> Self {
        let matrix: [[f64; NP]; NP] = std::array::from_fn(|i| std::array::from_fn(|j| lambda * prior.precision[i][j]));
        let rhs_terms = std::array::from_fn(|i| std::array::from_fn(|j| matrix[i][j] * prior.mean[j]));
        Self { matrix, rhs_terms }
    }
}

/// The partition of one line's p3/p4 region: first p4 sample, plateau reached.
type PartitionKey = (usize, bool);

/// Reusable buffers of [`evaluate_set`].
#[derive(Default)]
pub(crate) struct SetScratch {
    p1: P1Samples,
    data: Vec<LineFit>,
    initial: Vec<PartitionKey>,
    chains: ChainScratch,
}

/// Fits one training set (`lines`, all at the same grid pair) once per prior
/// configuration in `configs`: the pooled p1 law, the initial `c` and bp3, then the
/// chain solve. Returns the p1 coefficients `(α1, α2)`; `out` receives per configuration
/// the chain parameters and the training SSE, or `(NaN, ∞)` where the segment equations
/// are singular (which disqualifies the pair for that configuration only).
pub(crate) fn evaluate_set<'p, L: Borrow<LineAtPair<'p>>>(
    lines: &[L],
    params: &PiecewiseValidParams,
    (set, p1): (&mut SetScratch, &mut P1Memo),
    configs: &[ChainPrior],
    out: &mut Vec<([f64; NP], f64)>,
) -> Result<(f64, f64), FitError> {
    let start = set_up(lines, params, set, p1)?;
    let (data, initial) = (&set.data, &set.initial);
    let blob = params.has_start_blob();
    let problem = ChainProblem { data, lines, blob, c_init: start.c_init, initial, first: start.first };
    out.clear();
    out.resize(configs.len(), SINGULAR);
    solve_chains(&problem, configs, params, start.sse_p1, &mut set.chains, out);
    Ok(start.alpha)
}

/// What [`evaluate_set`] derives from a training set before its chain solves.
struct SetStart {
    /// The pooled p1 law `(α1, α2)` and its SSE (0 without a start blob).
    alpha: (f64, f64),
    sse_p1: f64,
    c_init: f64,
    /// Data part of the segment equations for the initial partition.
    first: Equations,
}

/// The pooled p1 law (from `p1` if it still holds, [`P1Memo`]), the initial `c` and
/// every line's initial bp3 partition (into `set.data` and `set.initial`), and the
/// first partition's equations.
fn set_up<'p, L: Borrow<LineAtPair<'p>>>(
    lines: &[L],
    params: &PiecewiseValidParams,
    set: &mut SetScratch,
    p1: &mut P1Memo,
) -> Result<SetStart, FitError> {
    let blob = params.has_start_blob();
    let (alpha, sse1) = if blob {
        pooled_p1(lines, &mut set.p1, p1).ok_or_else(|| FitError::Singular("phase p1 fit".into()))?
    } else {
        ((0.0, 0.0), 0.0)
    };
    let p1_coef = PiecewiseCoefficients { alpha1: alpha.0, alpha2: alpha.1, ..Default::default() };
    let c_init = initial_c(lines);
    // The data part of the first partition's equations is the same for every prior.
    let mut first = ([[0.0; NP]; NP], [0.0; NP]);
    set.data.clear();
    set.initial.clear();
    for l in lines.iter().map(Borrow::borrow) {
        let mut lf = l.fit;
        lf.w_bp1 = if l.prep.bp1_pos_mm.is_some() { p1_coef.p1_width_mm(l.v_bp1) } else { 0.0 };
        lf.bp3_init = initial_bp3(&lf, &l.buf, &l.prep.smoothed, c_init);
        let key = partition_key(&lf, &l.buf, lf.bp3_init);
        accumulate_line(&lf, &l.buf, blob, key, &mut first.0, &mut first.1);
        set.data.push(lf);
        set.initial.push(key);
    }
    Ok(SetStart { alpha, sse_p1: sse1, c_init, first })
}

/// The p1 fit of the pooled p1 samples of `lines`, or `memo`'s if none of their speeds
/// changed since it was made; `memo` then holds this one.
fn pooled_p1<'p, L: Borrow<LineAtPair<'p>>>(
    lines: &[L],
    samples: &mut P1Samples,
    memo: &mut P1Memo,
) -> Option<((f64, f64), f64)> {
    if let Some(fit) = (*memo).filter(|_| lines.iter().all(|l| l.borrow().p1_unchanged)) {
        return fit;
    }
    samples.clear();
    for l in lines.iter().map(Borrow::borrow) {
        let end = l.p1_end;
        samples.extend(&l.buf.v[..end], &l.prep.line.widths_mm[..end], &l.prep.p1_inverse_widths[..end]);
    }
    let fit = fit_p1(samples);
    *memo = Some(fit);
    fit
}

/// The initial `c`: the pooled mean width over the second half of the p3/p4 regions (the
/// mean of the line means if those are empty).
fn initial_c<'p, L: Borrow<LineAtPair<'p>>>(lines: &[L]) -> f64 {
    let (mut c_sum, mut c_n) = (0.0, 0.0);
    for l in lines.iter().map(Borrow::borrow) {
        c_sum += l.c_sum;
        c_n += l.c_n;
    }
    if c_n > 0.0 {
        return c_sum / c_n;
    }
    let means = lines.iter().map(|l| l.borrow().prep.mean_width_mm);
    means.sum::<f64>() / lines.len() as f64
}

/// Initial bp3 of a line: the first sample of its p3/p4 region where the smoothed
/// measured width reaches `c_init` (bp4 if it never does); with the index, found on the
/// running maximum.
fn initial_bp3(lf: &LineFit, ls: &LineScratch, smoothed: &[f64], c_init: f64) -> f64 {
    let first = if ls.indexed {
        let j = ls.max3.partition_point(|&m| m < c_init);
        (j < ls.max3.len() && !c_init.is_nan()).then_some(lf.i3 + j)
    } else {
        (lf.i3..lf.i4).find(|&i| smoothed[i] >= c_init)
    };
    first.map_or(lf.bp4, |i| ls.t[i])
}

/// Segment sums of one line at one grid pair (fills the line's prefix sums); returns
/// them with `w_bp1 = 0` and the speed at bp1.
fn line_moments(p: &PreparedLine, kin: &LineKinematics, ls: &mut LineScratch) -> (LineFit, f64) {
    let (t, v, y) = (&ls.t, &ls.v, &p.line.widths_mm);
    let a = kin.accel_mm_s2;
    let bp2 = kin.accel_end_s();
    let bp4 = kin.decel_start_s();
    let top = kin.peak_speed_mm_s();
    let (bp1, v_bp1) = match p.bp1_pos_mm {
        Some(x1) => {
            let bp1 = kin.time_at_position(x1).min(bp4);
            (bp1, kin.speed_at_time(bp1))
        }
        None => (0.0, 0.0),
    };
    let i1 = match p.bp1_pos_mm {
        Some(_) => t.partition_point(|&ti| ti <= bp1),
        None => 0,
    };
    let i2 = t.partition_point(|&ti| ti <= bp2).max(i1);
    let mut p2 = Moments::default();
    for i in i1..i2 {
        p2.add(p2_regressor(t[i], v[i], bp1, a), y[i]);
    }
    let start3 = bp1.max(bp2);
    let i3 = t.partition_point(|&ti| ti <= start3);
    let i4 = t.partition_point(|&ti| ti <= bp4).max(i3);
    ls.pre3.clear();
    let mut acc = Moments::default();
    ls.pre3.push(acc);
    for i in i3..i4 {
        acc.add(p3_regressor(t[i], v[i], start3), y[i]);
        ls.pre3.push(acc);
    }
    let mut p5 = Moments::default();
    for i in i4..t.len() {
        p5.add(p5_regressor(v[i], top), y[i]);
    }
    let lf = LineFit {
        start3,
        bp4,
        top,
        w_bp1: 0.0,
        g_start3: if bp1 < bp2 { p2_regressor(bp2, top, bp1, a) } else { 0.0 },
        s_bp4: p3_regressor(bp4, top, start3),
        p2,
        p5,
        i3,
        i4,
        bp3_init: bp4,
    };
    (lf, v_bp1)
}

/// Offsets and p3/p4 split of one line for given chain parameters and partition.
struct LineState {
    w1: f64,
    w3: f64,
    w4: f64,
    m3: Moments,
    m4: Moments,
}

fn line_state(lf: &LineFit, ls: &LineScratch, blob: bool, theta: &[f64; NP], key: PartitionKey) -> LineState {
    let (j3, plateau) = key;
    let w1 = if blob { lf.w_bp1 } else { theta[W_START] };
    let w3 = w1 + theta[BETA] * lf.g_start3;
    let m3 = ls.pre3[j3 - lf.i3];
    let m4 = ls.pre3[lf.i4 - lf.i3].minus(&m3);
    let w4 = if plateau { theta[C] } else { w3 + theta[GAMMA] * lf.s_bp4 };
    LineState { w1, w3, w4, m3, m4 }
}

/// The model's bp3 for the given parameters (see `LineChain`).
fn chain_bp3(lf: &LineFit, blob: bool, theta: &[f64; NP]) -> f64 {
    let w1 = if blob { lf.w_bp1 } else { theta[W_START] };
    let w3 = w1 + theta[BETA] * lf.g_start3;
    if lf.start3 < lf.bp4 {
        bp3_time(w3, theta[C], theta[GAMMA], lf.start3, lf.bp4, lf.top)
    } else {
        lf.bp4
    }
}

/// One training set at one grid pair, ready for [`solve_chains`].
struct ChainProblem<'a, L> {
    data: &'a [LineFit],
    lines: &'a [L],
    blob: bool,
    c_init: f64,
    /// Partition of the initial bp3 of every line.
    initial: &'a [PartitionKey],
    /// Data part of the segment equations for that partition.
    first: Equations,
}

/// Segment equations `(A, b)` of the parameters `(β, γ, c, ρ, w_start)`.
type Equations = ([[f64; NP]; NP], [f64; NP]);

impl<'p, L: Borrow<LineAtPair<'p>>> ChainProblem<'_, L> {
    fn line<'s>(&'s self, k: usize) -> &'s LineScratch
    where
        'p: 's,
    {
        &self.lines[k].borrow().buf
    }

    /// Data part of the segment equations for a partition, into `(a, b)`, except the
    /// [`FIXED_ROWS`], which no partition changes: those stay 0 (they are `first`'s).
    fn partition_rows_into(&self, keys: &[PartitionKey], (a, b): &mut Equations) {
        for (row, rhs) in a.iter_mut().zip(b.iter_mut()) {
            *row = [0.0; NP];
            *rhs = 0.0;
        }
        for (k, (lf, &key)) in self.data.iter().zip(keys).enumerate() {
            accumulate_partition_rows(lf, self.line(k), self.blob, key, a, b);
        }
    }

    /// SSE of p2-p5 over all lines for the chain of `theta` with the given partition.
    fn sse_at(&self, keys: &[PartitionKey], theta: &[f64; NP]) -> f64 {
        self.data
            .iter()
            .zip(keys)
            .enumerate()
            .map(|(k, (lf, &key))| {
                let st = line_state(lf, self.line(k), self.blob, theta, key);
                lf.p2.sse(st.w1, theta[BETA])
                    + st.m3.sse(st.w3, theta[GAMMA])
                    + st.m4.sse(theta[C], 0.0)
                    + lf.p5.sse(st.w4, theta[RHO])
            })
            .sum()
    }

    /// The partition of line `k` under the chain of `theta` (bp3 from the model).
    fn model_key(&self, k: usize, theta: &[f64; NP]) -> PartitionKey {
        let lf = &self.data[k];
        partition_key(lf, self.line(k), chain_bp3(lf, self.blob, theta))
    }

    /// SSE of p2-p5 for the chain of `theta` (bp3 from the model).
    fn sse(&self, theta: &[f64; NP]) -> f64 {
        self.data
            .iter()
            .enumerate()
            .map(|(k, lf)| {
                let st = line_state(lf, self.line(k), self.blob, theta, self.model_key(k, theta));
                lf.p2.sse(st.w1, theta[BETA])
                    + st.m3.sse(st.w3, theta[GAMMA])
                    + st.m4.sse(theta[C], 0.0)
                    + lf.p5.sse(st.w4, theta[RHO])
            })
            .sum()
    }
}

/// The partition of one line's p3/p4 region for a bp3: first p4 sample, plateau reached.
fn partition_key(lf: &LineFit, ls: &LineScratch, bp3: f64) -> PartitionKey {
    let region = &ls.t[lf.i3..lf.i4];
    let count = if ls.indexed { ls.buckets.count_le(region, bp3) } else { region.partition_point(|&t| t <= bp3) };
    let j3 = lf.i3 + count;
    (j3, bp3 < lf.bp4)
}

/// Whether every relative difference `|a − b| / (1 + |b|)` of two parameter vectors is
/// below `tolerance` (NaN is not). Stops at the first that is not: this runs for up to
/// seven earlier states in every iteration of the chain solve, and mostly the first
/// difference is far above the tolerance. So before the division, `d > 2·tol·s` (all
/// floating point) answers "not below" at once: it implies `d/s > tol` exactly (the two
/// roundings of `2·tol·s` lose far less than the factor 2), and then the rounded
/// quotient is not below `tol` either. Otherwise the quotient decides, as before.
fn within_tolerance(a: &[f64; NP], b: &[f64; NP], tolerance: f64) -> bool {
    (0..NP).all(|k| {
        let (d, s) = ((a[k] - b[k]).abs(), 1.0 + b[k].abs());
        let far = d > 2.0 * tolerance * s;
        !far && d / s < tolerance
    })
}

/// Adds one line's segment equations for a partition. Row `k` is the normal equation of
/// parameter `k` over its own segment; the offsets' dependence on the other parameters
/// gives the off-diagonal terms (`M[γ][β] = g(bp2)·Σs`, …). The rows of β and w_start
/// ([`FIXED_ROWS`]) take p2 sums only; the partition sets those of γ, c and ρ.
fn accumulate_line(
    lf: &LineFit,
    ls: &LineScratch,
    blob: bool,
    key: PartitionKey,
    a: &mut [[f64; NP]; NP],
    b: &mut [f64; NP],
) {
    accumulate_fixed_rows(lf, blob, a, b);
    accumulate_partition_rows(lf, ls, blob, key, a, b);
}

/// Constant part of w(bp1): the p1 width at bp1, or 0 when w_start is a parameter.
fn constant_w1(lf: &LineFit, blob: bool) -> f64 {
    if blob {
        lf.w_bp1
    } else {
        0.0
    }
}

/// [`accumulate_line`] for the rows of β and w_start.
fn accumulate_fixed_rows(lf: &LineFit, blob: bool, a: &mut [[f64; NP]; NP], b: &mut [f64; NP]) {
    let (p2, w1) = (&lf.p2, constant_w1(lf, blob));
    a[BETA][BETA] += p2.sxx;
    b[BETA] += p2.sxy - w1 * p2.sx;
    if !blob {
        a[W_START][W_START] += p2.n;
        a[W_START][BETA] += p2.sx;
        a[BETA][W_START] += p2.sx;
        b[W_START] += p2.sy;
    }
}

/// [`accumulate_line`] for the rows of γ, c and ρ.
fn accumulate_partition_rows(
    lf: &LineFit,
    ls: &LineScratch,
    blob: bool,
    (j3, plateau): PartitionKey,
    a: &mut [[f64; NP]; NP],
    b: &mut [f64; NP],
) {
    let m3 = ls.pre3[j3 - lf.i3];
    let m4 = ls.pre3[lf.i4 - lf.i3].minus(&m3);
    let (p5, g3, w1) = (&lf.p5, lf.g_start3, constant_w1(lf, blob));
    a[GAMMA][GAMMA] += m3.sxx;
    a[GAMMA][BETA] += g3 * m3.sx;
    b[GAMMA] += m3.sxy - w1 * m3.sx;
    a[C][C] += m4.n;
    b[C] += m4.sy;
    a[RHO][RHO] += p5.sxx;
    b[RHO] += p5.sxy;
    if plateau {
        a[RHO][C] += p5.sx;
    } else {
        a[RHO][BETA] += g3 * p5.sx;
        a[RHO][GAMMA] += lf.s_bp4 * p5.sx;
        b[RHO] -= w1 * p5.sx;
    }
    if !blob {
        a[GAMMA][W_START] += m3.sx;
        if !plateau {
            a[RHO][W_START] += p5.sx;
        }
    }
}

#[cfg(test)]
fn add_prior(a: &mut [[f64; NP]; NP], b: &mut [f64; NP], prior: &WeightedPrior) {
    for i in 0..NP {
        for j in 0..NP {
            a[i][j] += prior.matrix[i][j];
            b[i] += prior.rhs_terms[i][j];
        }
    }
}

/// A parameter with neither data nor prior (an empty segment) keeps its current value.
#[cfg(test)]
fn pin_unidentified(a: &mut [[f64; NP]; NP], b: &mut [f64; NP], theta: &[f64; NP]) {
    for k in 0..NP {
        if a[k][k] == 0.0 {
            a[k] = [0.0; NP];
            a[k][k] = 1.0;
            b[k] = theta[k];
        }
    }
}

/// Rows of the segment equations that [`accumulate_line`] fills from the p2 sums alone
/// (β's and w_start's), so that no partition changes them.
const FIXED_ROWS: [usize; 2] = [BETA, W_START];

/// Which rows the chain solves pass to the LU solve already equilibrated.
const EQUILIBRATED: [bool; NP] = {
    let mut done = [false; NP];
    done[FIXED_ROWS[0]] = true;
    done[FIXED_ROWS[1]] = true;
    done
};

/// A row of the equations that no partition changes, with its prior, as the LU solve
/// equilibrates it: once per configuration instead of once per iteration.
#[derive(Debug, Clone, Copy)]
enum FixedRow {
    /// Scaled to unit maximum ([`equilibrate_row`]).
    Scaled([f64; NP], f64),
    /// Pinned (neither data nor prior): the unit row `x_k = θ_k`, which scaling leaves
    /// as it is (its maximum is 1).
    Pinned,
}

/// The [`FIXED_ROWS`] of a configuration, or `None` when one of them fails the LU
/// solve's scaling (a zero or non-finite row: then every solve of the configuration
/// fails, the first one included).
fn fixed_rows(first: &Equations, prior: &ChainPrior) -> Option<[FixedRow; 2]> {
    let mut rows = [FixedRow::Pinned; 2];
    for (fixed, &i) in rows.iter_mut().zip(&FIXED_ROWS) {
        let (mut row, mut rhs) = with_prior(first, i, prior);
        if row[i] != 0.0 {
            equilibrate_row(&mut row, &mut rhs).then_some(())?;
            *fixed = FixedRow::Scaled(row, rhs);
        }
    }
    Some(rows)
}

/// Row `i` of the data part `(a, b)` with the prior added (`λΣ⁻¹` to `A`, then the
/// terms of `λΣ⁻¹μ` one by one to `b`).
fn with_prior((a, b): &Equations, i: usize, prior: &ChainPrior) -> ([f64; NP], f64) {
    let (mut row, mut rhs) = (a[i], b[i]);
    if let Some(prior) = prior {
        for j in 0..NP {
            row[j] += prior.matrix[i][j];
            rhs += prior.rhs_terms[i][j];
        }
    }
    (row, rhs)
}

/// The equations of one chain iteration into `lane` of `batch`: the data part with the
/// prior added, a parameter with neither data nor prior (an empty segment) pinned at
/// its current value `theta`, and the [`FIXED_ROWS`] as `fixed` holds them (solve with
/// [`EQUILIBRATED`]). Row by row, so that nothing larger than a row is copied.
fn load_lane(
    (batch, lane): (&mut LuBatch<NP, LANES>, usize),
    equations: &Equations,
    prior: &ChainPrior,
    theta: &[f64; NP],
    fixed: &[FixedRow; 2],
) {
    let unit = |i: usize| -> [f64; NP] { std::array::from_fn(|j| if j == i { 1.0 } else { 0.0 }) };
    for i in 0..NP {
        let (row, rhs) = match FIXED_ROWS.iter().position(|&f| f == i).map(|k| fixed[k]) {
            Some(FixedRow::Scaled(row, rhs)) => (row, rhs),
            Some(FixedRow::Pinned) => (unit(i), theta[i]),
            None => match with_prior(equations, i, prior) {
                (row, _) if row[i] == 0.0 => (unit(i), theta[i]),
                free => free,
            },
        };
        batch.set_row(lane, i, &row, rhs);
    }
}

/// The best grid pair for configuration `k` (its prior at `lambda`), turned into a fitted model.
fn best_fit(
    prepared: &[PreparedLine],
    params: &PiecewiseValidParams,
    outcomes: &[Result<GridOutcome, FitError>],
    k: usize,
    lambda: f64,
) -> Result<FittedPiecewise, FitError> {
    let mut best: Option<(&GridOutcome, f64)> = None;
    for o in outcomes.iter().flatten() {
        let sse = o.per_lambda[k].1;
        if sse.is_finite() && best.is_none_or(|(_, b)| sse < b) {
            best = Some((o, sse));
        }
    }
    let Some((o, sse)) = best else {
        return Err(outcomes
            .iter()
            .find_map(|r| r.as_ref().err().cloned())
            .unwrap_or_else(|| FitError::Singular("no grid pair gave a solvable fit".into())));
    };
    let bp1_law = if params.has_start_blob() { Some(fit_bp1_law(prepared, params, o.r_a, o.r_f)?) } else { None };
    debug_assert!(sse.is_finite());
    let mut fitted = fitted_model(params, (o.r_a, o.r_f), o.alpha, &o.per_lambda[k].0, bp1_law, lambda);
    fitted.training_rmse_mm = direct_training_rmse(prepared, &fitted)?;
    Ok(fitted)
}

/// The fitted model of a grid pair, its p1 coefficients and chain parameters (training
/// RMSE left at 0 for the caller to fill in).
pub(crate) fn fitted_model(
    params: &PiecewiseValidParams,
    (r_a, r_f): (f64, f64),
    alpha: (f64, f64),
    theta: &[f64; NP],
    bp1_law: Option<Bp1PowerLaw>,
    lambda: f64,
) -> FittedPiecewise {
    let coefficients = PiecewiseCoefficients {
        alpha1: alpha.0,
        alpha2: alpha.1,
        beta: theta[BETA],
        gamma: theta[GAMMA],
        c_mm: theta[C],
        rho: theta[RHO],
        w_start_mm: theta[W_START],
    };
    FittedPiecewise {
        r_a,
        r_f,
        coefficients,
        bp1_law,
        has_start_blob: params.has_start_blob(),
        training_rmse_mm: 0.0,
        lambda,
    }
}

/// RMSE of eq. 3 evaluated sample by sample on the training lines with their measured
/// bp1 (the quantity the grid search minimises, recomputed without the cancellation of
/// the prefix-sum form).
fn direct_training_rmse(prepared: &[PreparedLine], fitted: &FittedPiecewise) -> Result<f64, FitError> {
    let (mut sse, mut n) = (0.0, 0usize);
    for p in prepared {
        let kin = fitted.actual_kinematics(&p.line.nominal)?;
        let bp1 = p.bp1_pos_mm.map_or(0.0, |x| kin.time_at_position(x));
        let chain = LineChain::new(&fitted.coefficients, &kin, fitted.has_start_blob, bp1);
        for (&x, &w) in p.line.positions_mm.iter().zip(&p.line.widths_mm) {
            let pred = chain.width_at(&fitted.coefficients, kin.time_at_position(x), kin.speed_at_position(x));
            sse += (pred - w).powi(2);
            n += 1;
        }
    }
    Ok((sse / n as f64).sqrt())
}

/// Eq. 2 fitted on the measured bp1 times of the training lines at `(r_a, r_F)`.
pub(crate) fn fit_bp1_law<'a, P: Borrow<PreparedLine<'a>>>(
    prepared: &[P],
    params: &PiecewiseValidParams,
    r_a: f64,
    r_f: f64,
) -> Result<Bp1PowerLaw, FitError> {
    let mut accels = Vec::with_capacity(prepared.len());
    let mut times = Vec::with_capacity(prepared.len());
    for p in prepared.iter().map(Borrow::borrow) {
        let kin = p.line.nominal.scaled(r_a, r_f)?;
        if let Some(x1) = p.bp1_pos_mm {
            accels.push(kin.accel_mm_s2);
            times.push(kin.time_at_position(x1));
        }
    }
    let q = params.get();
    Bp1PowerLaw::fit(&accels, &times, (q.bp1_c2_min, q.bp1_c2_max, q.bp1_c2_step), q.bp1_c2_fallback)
        .ok_or_else(|| FitError::Singular("bp1 power law".into()))
}

/// The measured bp1 times (s) of the lines at `(r_a, r_F)` (for diagnostics and tests);
/// `None` entries without a start blob.
pub fn measured_bp1_times(
    lines: &[MeasuredLine],
    params: &PiecewiseValidParams,
    r_a: f64,
    r_f: f64,
) -> Result<Vec<Option<f64>>, FitError> {
    let prepared = prepare_lines(lines, params)?;
    prepared
        .iter()
        .map(|p| {
            let kin = p.line.nominal.scaled(r_a, r_f)?;
            Ok(p.bp1_pos_mm.map(|x| kin.time_at_position(x)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{synthetic_lines, synthetic_truth};
    use super::*;
    use crate::fdm::hyperparams::PiecewiseParams;

    fn exact_params(blob: bool) -> PiecewiseValidParams {
        PiecewiseParams { smoothing_mm: 0.0, has_start_blob: blob, ..PiecewiseParams::paper_defaults() }
            .check()
            .unwrap()
    }

    #[test]
    fn p1_gauss_newton_recovers_exact_reciprocal_law() {
        // Noiseless w = 1/(0.02 v + 1.1) must be fitted exactly.
        let s: Vec<(f64, f64)> = (0..40)
            .map(|i| {
                let v = 8.0 + i as f64;
                (v, 1.0 / (0.02 * v + 1.1))
            })
            .collect();
        let ((a1, a2), sse) = fit_p1(&mut P1Samples::from_pairs(&s)).unwrap();
        assert!((a1 - 0.02).abs() < 1e-9 && (a2 - 1.1).abs() < 1e-9 && sse < 1e-20);
    }

    #[test]
    fn grid_search_recovers_known_model() {
        // Widths generated by the model itself at r_a = 1.03, r_F = 0.97 (on the grid),
        // sampled like the real data (0.048 mm): the grid search must land within one
        // step. Without a blob the recovery is exact; with it the measured bp1 is the
        // sample nearest the true minimum, and the sqrt singularity of p2 at bp1 turns
        // that sub-sample error into a few per cent on β and γ.
        for blob in [true, false] {
            let truth = synthetic_truth(blob);
            let lines = synthetic_lines(&truth, 0.048);
            let fit = fit(&lines, &exact_params(blob)).unwrap();
            assert!((fit.r_a - truth.r_a).abs() <= 0.0101, "r_a {}", fit.r_a);
            assert!((fit.r_f - truth.r_f).abs() <= 0.0101, "r_f {}", fit.r_f);
            let tol = if blob { 0.1 } else { 1e-6 };
            assert!(fit.training_rmse_mm < tol * 0.03, "rmse {}", fit.training_rmse_mm);
            let (t, f) = (truth.coefficients, fit.coefficients);
            for (name, a, b) in
                [("beta", f.beta, t.beta), ("gamma", f.gamma, t.gamma), ("c", f.c_mm, t.c_mm), ("rho", f.rho, t.rho)]
            {
                assert!((a - b).abs() < tol * b.abs(), "{name}: {a} vs {b}");
            }
            if blob {
                assert!((f.alpha1 - t.alpha1).abs() < 1e-6 * t.alpha1);
                assert!((f.alpha2 - t.alpha2).abs() < 1e-6 * t.alpha2);
            } else {
                assert!((f.w_start_mm - t.w_start_mm).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn blob_recovery_improves_with_finer_sampling() {
        // At the true (r_a, r_F), bp1's quantisation error shrinks with the sample step,
        // and so must the error of β and γ (consistency of the procedure).
        let truth = synthetic_truth(true);
        let err = |step: f64| {
            let lines = synthetic_lines(&truth, step);
            let f = fit_at(&lines, &exact_params(true), truth.r_a, truth.r_f).unwrap().coefficients;
            let t = truth.coefficients;
            ((f.beta - t.beta) / t.beta).abs() + ((f.gamma - t.gamma) / t.gamma).abs()
        };
        let (coarse, fine) = (err(0.048), err(0.004));
        assert!(fine < 0.3 * coarse && fine < 0.02, "coarse {coarse}, fine {fine}");
    }

    #[test]
    fn prefix_sum_criterion_equals_direct_evaluation() {
        // The grid criterion (prefix-sum SSE) must equal the SSE of evaluating eq. 3
        // sample by sample with the measured bp1: an identity, checked on data the model
        // does not fit exactly.
        let truth = synthetic_truth(true);
        let mut lines = synthetic_lines(&truth, 0.1);
        for (k, l) in lines.iter_mut().enumerate() {
            for (i, w) in l.widths_mm.iter_mut().enumerate() {
                *w += 0.02 * ((i * 7 + k * 3) as f64).sin();
            }
        }
        let params = exact_params(true);
        let prepared = prepare_lines(&lines, &params).unwrap();
        let mut scratch = Scratch::new(&prepared);
        let o = evaluate_pair(&params, 1.02, 0.98, &mut scratch, &[None]).unwrap();
        let n: usize = lines.iter().map(MeasuredLine::len).sum();
        let criterion = (o.per_lambda[0].1 / n as f64).sqrt();
        let fit = fit_at(&lines, &params, 1.02, 0.98).unwrap();
        assert!(criterion > 1e-3);
        assert!((criterion - fit.training_rmse_mm).abs() < 1e-9 * criterion);
        let theta = o.per_lambda[0].0;
        assert_eq!(fit.coefficients.gamma, theta[GAMMA]);
        assert_eq!(fit.coefficients.alpha1, o.alpha.0);
    }

    #[test]
    fn within_tolerance_short_cut_agrees_with_the_quotient() {
        // The early "not below" (`d > 2·tol·s`) must never answer otherwise than the
        // quotient test it skips: differences at, just around and far from the tolerance
        // and from twice it, and NaN, infinite and zero entries.
        use rand::{Rng, SeedableRng};
        let quotient =
            |a: &[f64; NP], b: &[f64; NP], tol: f64| (0..NP).all(|k| (a[k] - b[k]).abs() / (1.0 + b[k].abs()) < tol);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(18);
        let factors = [0.0, 0.5, 1.0 - 1e-15, 1.0, 1.0 + 1e-15, 2.0 - 1e-15, 2.0, 2.0 + 1e-15, 3.0, 1e300];
        let specials = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 0.0, -0.0, 1e-300];
        let (mut below, mut not_below) = (0, 0);
        for case in 0..200_000 {
            let tol = 10f64.powi(rng.random_range(-14..-2));
            let b: [f64; NP] =
                std::array::from_fn(|_| rng.random_range(-2.0..2.0) * 10f64.powi(rng.random_range(-3..3)));
            // One component probes the boundaries; the others are well within tolerance.
            let probe = rng.random_range(0..NP);
            let mut a: [f64; NP] = std::array::from_fn(|k| {
                let f = if k == probe { factors[rng.random_range(0..factors.len())] } else { 0.5 };
                b[k] + f * if rng.random_bool(0.5) { tol } else { -tol } * (1.0 + b[k].abs())
            });
            if case % 7 == 0 {
                a[probe] = specials[rng.random_range(0..specials.len())];
            }
            let expected = quotient(&a, &b, tol);
            assert_eq!(within_tolerance(&a, &b, tol), expected, "{a:?} {b:?} {tol}");
            if expected {
                below += 1
            } else {
                not_below += 1
            }
        }
        assert!(below > 1000 && not_below > 1000, "{below} below, {not_below} not");
    }

    #[test]
    fn moving_average_is_centred_box() {
        let xs: Vec<f64> = (0..10).map(|i| i as f64).collect();
        let ys: Vec<f64> = xs.iter().map(|x| x * x).collect();
        let m = moving_average(&xs, &ys, 2.0);
        assert!((m[5] - (16.0 + 25.0 + 36.0) / 3.0).abs() < 1e-12);
        assert!((m[0] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn too_few_lines_is_an_error() {
        assert!(matches!(fit(&[], &exact_params(true)), Err(FitError::NotEnoughData(_))));
    }
}
