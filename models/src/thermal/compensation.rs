//! Dynamic deposition compensation of paper 003, Sec. 2.4 (eqs 31-39) with the
//! parameters of Sec. 3.2: the width error against the desired width, the spans that
//! need compensation, the desired change of the deposition velocity, and the filtered
//! B-spline (FBS) solve that finds the input whose lagged response matches it.
//!
//! - Eq. 31: w_d = w0/cos ψ, with ψ the angle of the deposition direction from the path
//!   normal ([`super::dda`], which explains why ψ stands in for eq. 26's φ_eff).
//! - Eq. 32: Δw = w_l + w_r − 2w_d; unmeasured samples are NaN and stay NaN.
//! - Spans: continuous runs of |Δw| ≥ ε, runs closer than a small gap merged, each
//!   extended by 0.1 s at both ends (Sec. 3.2: Δt̂0 = Δt0 − 0.1 s, Δt̂1 = Δt1 + 0.1 s).
//! - Eq. 33 in our units: the printer's deposition velocity v_e (mm/s) is defined by
//!   E = 2·h·w0·v_e, so v_e = |v| when printing a straight line steadily. A width excess
//!   Δw at speed |v| is a flow excess ΔE = h·|v|·Δw, i.e. Δv_e = K_e·|v|·Δw/(2·w_d)
//!   (w_d in place of w0 so that a rotated deposition direction is measured against its
//!   own desired width). K_e is per span; Sec. 3.2 gives K_e = 1 + (150 − T_p)/15 with
//!   T_p the corner temperature in °C ([`paper_gain`]). Unmeasured samples (NaN) ask
//!   for nothing: the fit below leaves them out, so the spline bridges a gap in the
//!   camera's readings (the first samples of a layer, too thin for the threshold
//!   contour, a frame the camera skipped) instead of being pulled to zero there.
//! - Eqs 36-39: the input Δv_er = Σ N_i ΔV_i is a clamped cubic B-spline on uniform knots
//!   over the extended window (the paper's NURBS with unit weights, which is what an
//!   m-order spline with control pairs {Δt_i, ΔV_i} at fixed Δt_i amounts to); knot
//!   spacing 0.02 s by default, about τ/4, fine enough to shape the lag's response and
//!   coarse enough to keep ~20 unknowns per corner. Each N_i is sampled at T_s and
//!   filtered through G(s) with [`first_order_lag`] (Ñ_i, eq. 38); the control values
//!   minimise ‖Σ Ñ_i ΔV_i − Δv_e‖² over the window's measured samples subject to
//!   ΔV_min ≤ ΔV_i ≤ ΔV_max (−2 and +4 mm/s) and ΔV_0 = ΔV_n = 0, by an active-set
//!   bounded least squares (Lawson-Hanson style) on the normal equations with faer's
//!   Cholesky. The fit covers the extended window only, as eq. 39 does; the lag's tail
//!   after Δt̂1 is left to the extension.
//! - Eq. 37: the compensated command is v_ef = v_e − Δv_er.
//!
//! Choices of ours beside the paper's text (each run as a variant, on the camera's
//! widths and on the printer's true ones, by `specs/chen2024.toml`):
//! - Eq. 33 by swept area, as an option ([`velocity_change_from_sweep_mm_s`] with the
//!   κ_eff sector terms; with κ_eff = 0 it is eq. 33 read as h|v|cos ψ·Δw). Paper: "ΔE(t)
//!   = K_e(w_l + w_r − 2w_d)". Read literally it treats every sample as a slice of a
//!   straight bead; at a sharp apex the allocated directions fan round a nearly fixed
//!   point and neighbouring directions cross the same bulge. The swept area counts every
//!   point once, but on the eqs 5-11 printer it under-counts the apex excess (the
//!   chen2024 report's variants `sweep` and defaults), so `thermal.compensate` defaults
//!   to the literal reading.
//! - Tail ([`solve_fbs_with_tail`], `FbsParams::tail_s`). Paper: the fit (eq. 39) runs
//!   over [Δt̂0, Δt̂1] only. The lag's response to an input that ends at Δt̂1 goes on
//!   for ~3τ and starves the bead after a corner; fitting it to zero there removes that.
//!   Spans are solved in print order with the earlier spans' tails subtracted
//!   ([`compensate_spans`]), which superposition through the linear G allows.

use faer::prelude::*;
use faer::{Mat, Side};

use super::dynamics::first_order_lag;
use super::errors::{positive, ThermalError};

/// Degree of the B-spline (cubic).
const DEGREE: usize = 3;
/// Relative ridge of the bounded least squares ([`bounded_least_squares`]): far below
/// anything that moves a fit with every row present (outputs agree to ~1e-9 mm/s).
pub const RIDGE: f64 = 1e-10;

/// An inclusive range of sample indices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SampleSpan {
    /// First sample.
    pub first: usize,
    /// Last sample (inclusive).
    pub last: usize,
}

impl SampleSpan {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.last + 1 - self.first
    }

    /// Always false: a span holds at least one sample.
    pub fn is_empty(&self) -> bool {
        false
    }
}

/// Parameters of the filtered B-spline solve (eqs 34-39).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FbsParams {
    /// Knot spacing of the uniform cubic B-spline (s).
    pub knot_spacing_s: f64,
    /// Time constant τ of G(s) (s), Sec. 3.2: 0.0873 s.
    pub tau_s: f64,
    /// Lower bound ΔV_min on the control values (mm/s), Sec. 3.2: −2 mm/s.
    pub dv_min_mm_s: f64,
    /// Upper bound ΔV_max (mm/s), Sec. 3.2: +4 mm/s.
    pub dv_max_mm_s: f64,
    /// Time after the window over which the lagged output is still fitted to zero (s).
    /// The paper fits over the extended window only (0); the lag's response to the
    /// input keeps going for a few τ after Δt̂1 (module doc).
    pub tail_s: f64,
}

impl FbsParams {
    /// Sec. 3.2 of the paper, with our knot spacing (see the module doc).
    pub fn paper_defaults() -> Self {
        Self { knot_spacing_s: 0.02, tau_s: 0.0873, dv_min_mm_s: -2.0, dv_max_mm_s: 4.0, tail_s: 0.0 }
    }

    /// Checks spacing and τ positive and ΔV_min ≤ 0 ≤ ΔV_max (the fixed ends must be feasible).
    pub fn check(self) -> Result<Self, ThermalError> {
        positive("knot_spacing_s", self.knot_spacing_s)?;
        positive("tau_s", self.tau_s)?;
        if !(self.tail_s >= 0.0 && self.tail_s.is_finite()) {
            return Err(ThermalError::NotPositive { name: "tail_s", value: self.tail_s });
        }
        if !(self.dv_min_mm_s <= 0.0 && self.dv_max_mm_s >= 0.0) {
            return Err(ThermalError::BadBounds { min: self.dv_min_mm_s, max: self.dv_max_mm_s });
        }
        Ok(self)
    }
}

/// Result of the FBS solve over one extended window.
#[derive(Debug, Clone, PartialEq)]
pub struct FbsSolution {
    /// Control values ΔV_i (mm/s), first and last 0 (eq. 39).
    pub control_mm_s: Vec<f64>,
    /// Knot vector of the clamped cubic B-spline, relative to the window start (s).
    pub knots_s: Vec<f64>,
    /// Input sequence Δv_er at each window sample (mm/s), eq. 36.
    pub input_mm_s: Vec<f64>,
    /// Predicted output Σ Ñ_i ΔV_i at each window sample (mm/s), eq. 38.
    pub output_mm_s: Vec<f64>,
    /// ‖output − desired‖₂ over the window's measured samples (mm/s).
    pub residual_norm_mm_s: f64,
    /// Active-set iterations used.
    pub iterations: usize,
}

/// Desired half width w_d = w0/cos ψ (mm), eq. 31.
pub fn desired_half_width_mm(w0_mm: f64, psi_rad: &[f64]) -> Vec<f64> {
    psi_rad.iter().map(|p| w0_mm / p.cos()).collect()
}

/// Width error Δw = w_l + w_r − 2w_d (mm), eq. 32; NaN where a side was not measured.
pub fn width_error_mm(left_mm: &[f64], right_mm: &[f64], desired_half_width_mm: &[f64]) -> Vec<f64> {
    left_mm.iter().zip(right_mm).zip(desired_half_width_mm).map(|((l, r), d)| l + r - 2.0 * d).collect()
}

/// Continuous spans with |Δw| ≥ `threshold_mm` (ε); spans separated by at most
/// `merge_gap` samples are merged. NaN samples never start or continue a span.
pub fn error_spans(width_error_mm: &[f64], threshold_mm: f64, merge_gap: usize) -> Vec<SampleSpan> {
    let mut spans: Vec<SampleSpan> = Vec::new();
    for (k, dw) in width_error_mm.iter().enumerate() {
        if dw.abs() < threshold_mm || dw.is_nan() {
            continue;
        }
        match spans.last_mut() {
            Some(span) if k - span.last <= merge_gap + 1 => span.last = k,
            _ => spans.push(SampleSpan { first: k, last: k }),
        }
    }
    spans
}

/// Extends `span` by `extension_s` at both ends (Sec. 3.2: 0.1 s), within `0..samples`.
pub fn extend_span(span: SampleSpan, extension_s: f64, dt_s: f64, samples: usize) -> SampleSpan {
    let extra = (extension_s / dt_s).round() as usize;
    SampleSpan { first: span.first.saturating_sub(extra), last: (span.last + extra).min(samples.saturating_sub(1)) }
}

/// Deposition correction gain of Sec. 3.2: K_e = 1 + (150 − T_p)/15, T_p in °C.
pub fn paper_gain(corner_temp_c: f64) -> f64 {
    1.0 + (150.0 - corner_temp_c) / 15.0
}

/// Desired change of the deposition velocity Δv_e = K_e·|v|·Δw/(2·w_d) (mm/s), eq. 33
/// in our units (module doc); NaN where the width error is NaN (unmeasured).
pub fn desired_velocity_change_mm_s(
    width_error_mm: &[f64],
    speed_mm_s: &[f64],
    desired_half_width_mm: &[f64],
    gain: f64,
) -> Vec<f64> {
    width_error_mm
        .iter()
        .zip(speed_mm_s)
        .zip(desired_half_width_mm)
        .map(|((dw, v), wd)| gain * v * dw / (2.0 * wd))
        .collect()
}

/// Per-sample geometry of the deposition frame: what the swept-area form of eq. 33 needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepSample {
    /// Path speed |v| (mm/s).
    pub speed_mm_s: f64,
    /// Angle ψ of the deposition direction from the path normal (rad).
    pub psi_rad: f64,
    /// Effective curvature κ_eff = κ + κ_φ (1/mm), eq. 14: the deposition direction
    /// turns at κ_eff·|v| rad/s.
    pub kappa_eff_per_mm: f64,
}

/// Area swept per second by the left and right deposition segments of lengths `left_mm`
/// and `right_mm` (mm²/s): |v|(cos ψ·w_l − ½κ_eff·w_l²) + |v|(cos ψ·w_r + ½κ_eff·w_r²),
/// eqs 5-6 in the rotated frame of the allocation (a segment whose foot moves at |v|
/// and which turns at κ_eff|v| sweeps cos ψ·|v| per unit length, less the sector it
/// turns back over on the inner side, plus the one it fans out over on the outer side).
/// With ψ = 0 and w_l = w_r = w on a straight line this is 2w|v|, eq. 2. Integrated
/// over time it counts every point of the plane once, with the sign of the sweep, even
/// where neighbouring segments cross at a sharp apex: the signed sweep, not the sum of
/// lengths, is what mass conservation relates to the flow.
pub fn swept_area_rate_mm2_s(left_mm: f64, right_mm: f64, sample: &SweepSample) -> f64 {
    let (v, c, k) = (sample.speed_mm_s, sample.psi_rad.cos(), sample.kappa_eff_per_mm);
    v * (c * left_mm - 0.5 * k * left_mm * left_mm) + v * (c * right_mm + 0.5 * k * right_mm * right_mm)
}

/// Eq. 33 by mass conservation in the deposition frame: the flow excess
/// ΔE = K_e·h·(swept rate of the measured − of the desired half widths) (mm³/s) at
/// every sample, converted to a deposition velocity by `flow_per_velocity_mm2`
/// (E = that × v_e: the filament area for an E-axis velocity). NaN where a side was
/// not measured.
pub fn velocity_change_from_sweep_mm_s(
    measured_mm: &[(f64, f64)],
    desired_mm: &[(f64, f64)],
    sweep: &[SweepSample],
    layer_height_mm: f64,
    flow_per_velocity_mm2: f64,
    gain: f64,
) -> Vec<f64> {
    measured_mm
        .iter()
        .zip(desired_mm)
        .zip(sweep)
        .map(|((m, d), g)| {
            let excess = swept_area_rate_mm2_s(m.0, m.1, g) - swept_area_rate_mm2_s(d.0, d.1, g);
            gain * layer_height_mm * excess / flow_per_velocity_mm2
        })
        .collect()
}

/// One compensated span of [`compensate_spans`].
#[derive(Debug, Clone, PartialEq)]
pub struct SpanCompensation {
    /// Samples with |Δw| ≥ ε.
    pub span: SampleSpan,
    /// The span extended at both ends (Sec. 3.2): where the input lives.
    pub window: SampleSpan,
    /// Gain K_e used.
    pub gain: f64,
    /// Desired output change Δv_e over the window and its tail, after subtracting the
    /// lagged tails of earlier spans (mm/s).
    pub desired_mm_s: Vec<f64>,
    /// The FBS solution over the window and its tail.
    pub solution: FbsSolution,
}

/// Settings of [`compensate_spans`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpanParams {
    /// ε (mm): samples with |Δw| ≥ ε need compensation (Sec. 2.4).
    pub epsilon_mm: f64,
    /// Extension of each span at both ends (s), Sec. 3.2: 0.1 s.
    pub extension_s: f64,
    /// The FBS solve (its `tail_s` also sets how far a span's lagged output reaches).
    pub fbs: FbsParams,
}

/// Sec. 2.4 over one layer: spans of |`width_error_mm`| ≥ ε, extended, merged where the
/// extended windows touch; for each, the desired output `desired_unit_gain_mm_s` (Δv_e
/// with K_e = 1, NaN where unmeasured) times `gain(span)` over the window, solved by
/// FBS; after the window the output is fitted to zero for `tail_s`. Spans are solved in
/// print order and each one's desired output has the lagged tails of the earlier ones
/// subtracted (G is linear, so their responses add).
pub fn compensate_spans(
    width_error_mm: &[f64],
    desired_unit_gain_mm_s: &[f64],
    dt_s: f64,
    params: &SpanParams,
    mut gain: impl FnMut(SampleSpan) -> f64,
) -> Result<Vec<SpanCompensation>, ThermalError> {
    let n = width_error_mm.len();
    let merge_gap = (2.0 * params.extension_s / dt_s).ceil() as usize + 1;
    let tail = (params.fbs.tail_s / dt_s).round() as usize;
    let mut planned = vec![0.0; n];
    let mut out = Vec::new();
    for span in error_spans(width_error_mm, params.epsilon_mm, merge_gap) {
        let window = extend_span(span, params.extension_s, dt_s, n);
        let end = (window.last + 1 + tail).min(n);
        let k_e = gain(span);
        let desired: Vec<f64> = (window.first..end)
            .map(|k| if k <= window.last { k_e * desired_unit_gain_mm_s[k] } else { 0.0 } - planned[k])
            .collect();
        let solution = solve_fbs_with_tail(&desired, end - window.last - 1, dt_s, &params.fbs)?;
        planned[window.first..end].iter_mut().zip(&solution.output_mm_s).for_each(|(p, o)| *p += o);
        out.push(SpanCompensation { span, window, gain: k_e, desired_mm_s: desired, solution });
    }
    Ok(out)
}

/// The compensated command v_ef = v_e − Σ Δv_er over all spans (eq. 37).
pub fn apply_spans(v_e_mm_s: &[f64], spans: &[SpanCompensation]) -> Vec<f64> {
    spans
        .iter()
        .fold(v_e_mm_s.to_vec(), |command, s| compensated_command(&command, s.window.first, &s.solution.input_mm_s))
}

/// Compensated command v_ef = v_e − Δv_er (eq. 37), with `input_mm_s` applied from
/// sample `window_first` on.
pub fn compensated_command(v_e_mm_s: &[f64], window_first: usize, input_mm_s: &[f64]) -> Vec<f64> {
    let mut out = v_e_mm_s.to_vec();
    for (o, dv) in out[window_first..].iter_mut().zip(input_mm_s) {
        *o -= dv;
    }
    out
}

/// Eqs 36-39: the bounded filtered-B-spline fit of `desired_mm_s` (Δv_e on the extended
/// window's samples, period `dt_s`; NaN samples are left out of the fit).
pub fn solve_fbs(desired_mm_s: &[f64], dt_s: f64, params: &FbsParams) -> Result<FbsSolution, ThermalError> {
    solve_fbs_with_tail(desired_mm_s, 0, dt_s, params)
}

/// [`solve_fbs`] where the last `tail` samples of `desired_mm_s` lie after the window:
/// the input spline lives on the first `len − tail` samples and is zero after them,
/// while its lagged output is fitted over all samples (the tail's desired values are
/// what the output should be there, usually 0).
pub fn solve_fbs_with_tail(
    desired_mm_s: &[f64],
    tail: usize,
    dt_s: f64,
    params: &FbsParams,
) -> Result<FbsSolution, ThermalError> {
    let params = params.check()?;
    positive("dt_s", dt_s)?;
    let samples = desired_mm_s.len();
    let window = samples.saturating_sub(tail).max(2);
    let knots_s = clamped_uniform_knots((window - 1) as f64 * dt_s, params.knot_spacing_s);
    let mut basis = sampled_basis(&knots_s, samples, dt_s);
    for r in window..samples {
        (0..basis.ncols()).for_each(|c| basis[(r, c)] = 0.0);
    }
    let filtered = filter_columns(&basis, dt_s, params.tau_s);
    let n_basis = basis.ncols();
    // Interior control points only: ΔV_0 = ΔV_n = 0 (eq. 39).
    // Unmeasured samples (NaN) get no row weight: the fit leaves them out.
    let measured = |r: usize| desired_mm_s[r].is_finite();
    let interior = Mat::from_fn(samples, n_basis - 2, |r, c| if measured(r) { filtered[(r, c + 1)] } else { 0.0 });
    let target: Vec<f64> = (0..samples).map(|r| if measured(r) { desired_mm_s[r] } else { 0.0 }).collect();
    let lower = vec![params.dv_min_mm_s; n_basis - 2];
    let upper = vec![params.dv_max_mm_s; n_basis - 2];
    let (x, iterations) = bounded_least_squares(interior.as_ref(), &target, &lower, &upper)?;
    let mut control_mm_s = vec![0.0; n_basis];
    control_mm_s[1..n_basis - 1].copy_from_slice(&x);
    let input_mm_s = combine(&basis, &control_mm_s);
    let output_mm_s = combine(&filtered, &control_mm_s);
    let residual_norm_mm_s = output_mm_s
        .iter()
        .zip(desired_mm_s)
        .filter(|(_, d)| d.is_finite())
        .map(|(o, d)| (o - d).powi(2))
        .sum::<f64>()
        .sqrt();
    Ok(FbsSolution { control_mm_s, knots_s, input_mm_s, output_mm_s, residual_norm_mm_s, iterations })
}

/// Knots of a clamped cubic B-spline on [0, length_s] with spacing at most `spacing_s`.
pub fn clamped_uniform_knots(length_s: f64, spacing_s: f64) -> Vec<f64> {
    let intervals = (length_s / spacing_s).ceil().max(1.0) as usize;
    let step = length_s / intervals as f64;
    let mut knots = vec![0.0; DEGREE];
    knots.extend((0..=intervals).map(|i| i as f64 * step));
    knots.extend(std::iter::repeat_n(length_s, DEGREE));
    knots
}

/// The B-spline basis N_i sampled at t = k·dt_s, k = 0..samples (rows: samples, columns: i).
pub fn sampled_basis(knots_s: &[f64], samples: usize, dt_s: f64) -> Mat<f64> {
    let n_basis = knots_s.len() - DEGREE - 1;
    let mut basis = Mat::<f64>::zeros(samples, n_basis);
    let mut values = [0.0; DEGREE + 1];
    for r in 0..samples {
        let span = basis_functions(knots_s, r as f64 * dt_s, &mut values);
        for (j, v) in values.iter().enumerate() {
            basis[(r, span - DEGREE + j)] = *v;
        }
    }
    basis
}

/// Every column filtered through G(s) = 1/(τs+1) from rest: Ñ_i of eq. 38.
pub fn filter_columns(basis: &Mat<f64>, dt_s: f64, tau_s: f64) -> Mat<f64> {
    let mut out = Mat::<f64>::zeros(basis.nrows(), basis.ncols());
    let mut column = vec![0.0; basis.nrows()];
    for c in 0..basis.ncols() {
        column.iter_mut().enumerate().for_each(|(r, v)| *v = basis[(r, c)]);
        for (r, y) in first_order_lag(&column, dt_s, tau_s, 0.0).into_iter().enumerate() {
            out[(r, c)] = y;
        }
    }
    out
}

/// Bounded least squares min ‖A x − b‖² s.t. lower ≤ x ≤ upper (0 must be feasible),
/// by a primal active set on the normal equations. Returns x and the iterations used.
/// A ridge of [`RIDGE`] times the largest diagonal of AᵀA keeps the normal equations
/// definite when rows are missing (unmeasured samples): an unknown that no row sees,
/// or that only a lag's faint tail sees, goes to 0 instead of failing the Cholesky.
pub fn bounded_least_squares(
    a: MatRef<'_, f64>,
    b: &[f64],
    lower: &[f64],
    upper: &[f64],
) -> Result<(Vec<f64>, usize), ThermalError> {
    let n = a.ncols();
    let mut hessian = a.transpose() * a;
    let ridge = RIDGE * (0..n).map(|i| hessian[(i, i)]).fold(f64::MIN_POSITIVE, f64::max);
    for i in 0..n {
        hessian[(i, i)] += ridge;
    }
    let b_mat = Mat::from_fn(b.len(), 1, |r, _| b[r]);
    let rhs_mat = a.transpose() * b_mat.as_ref();
    let rhs: Vec<f64> = (0..n).map(|i| rhs_mat[(i, 0)]).collect();
    let scale = rhs.iter().fold(1.0_f64, |m, g| m.max(g.abs()));
    let mut x = vec![0.0; n];
    let mut state = vec![Bound::Free; n];
    for iteration in 1..=(10 * n + 50) {
        let target = solve_free(&hessian, &rhs, &x, &state)?;
        if let Some((alpha, blocking)) = step_to_bounds(&x, &target, &state, lower, upper) {
            for i in 0..n {
                if state[i] == Bound::Free {
                    x[i] += alpha * (target[i] - x[i]);
                }
            }
            for (i, bound) in blocking {
                x[i] = if bound == Bound::Lower { lower[i] } else { upper[i] };
                state[i] = bound;
            }
            continue;
        }
        x = target;
        match most_violated_multiplier(&hessian, &rhs, &x, &state, 1e-12 * scale) {
            Some(i) => state[i] = Bound::Free,
            None => return Ok((x, iteration)),
        }
    }
    Err(ThermalError::BoundedLeastSquares { unknowns: n })
}

/// Which bound a variable of the active set sits on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Bound {
    Free,
    Lower,
    Upper,
}

/// Minimiser over the free variables with the bound ones held (full-length vector).
fn solve_free(hessian: &Mat<f64>, rhs: &[f64], x: &[f64], state: &[Bound]) -> Result<Vec<f64>, ThermalError> {
    let free: Vec<usize> = (0..x.len()).filter(|&i| state[i] == Bound::Free).collect();
    let mut target = x.to_vec();
    if free.is_empty() {
        return Ok(target);
    }
    let sub = Mat::from_fn(free.len(), free.len(), |r, c| hessian[(free[r], free[c])]);
    let sub_rhs = Mat::from_fn(free.len(), 1, |r, _| {
        let i = free[r];
        rhs[i] - (0..x.len()).filter(|&j| state[j] != Bound::Free).map(|j| hessian[(i, j)] * x[j]).sum::<f64>()
    });
    let llt = sub.llt(Side::Lower).map_err(|_| ThermalError::BoundedLeastSquares { unknowns: x.len() })?;
    let z = llt.solve(&sub_rhs);
    for (r, &i) in free.iter().enumerate() {
        target[i] = z[(r, 0)];
    }
    Ok(target)
}

/// If the free target leaves the box: the largest feasible step fraction from x towards
/// it and the variables that block there.
fn step_to_bounds(
    x: &[f64],
    target: &[f64],
    state: &[Bound],
    lower: &[f64],
    upper: &[f64],
) -> Option<(f64, Vec<(usize, Bound)>)> {
    let mut alpha = 1.0;
    let mut blocking = Vec::new();
    for i in 0..x.len() {
        if state[i] != Bound::Free {
            continue;
        }
        let (limit, bound) = if target[i] < lower[i] {
            ((lower[i] - x[i]) / (target[i] - x[i]), Bound::Lower)
        } else if target[i] > upper[i] {
            ((upper[i] - x[i]) / (target[i] - x[i]), Bound::Upper)
        } else {
            continue;
        };
        if limit < alpha - 1e-15 {
            alpha = limit;
            blocking.clear();
        }
        if limit <= alpha + 1e-15 {
            blocking.push((i, bound));
        }
    }
    (!blocking.is_empty()).then_some((alpha.max(0.0), blocking))
}

/// A bound variable whose Lagrange multiplier has the wrong sign (the most negative),
/// if any: at a lower bound the gradient of ½‖Ax−b‖² must be ≥ 0, at an upper ≤ 0.
fn most_violated_multiplier(hessian: &Mat<f64>, rhs: &[f64], x: &[f64], state: &[Bound], tol: f64) -> Option<usize> {
    let mut worst = (-tol, None);
    for i in 0..x.len() {
        let grad = (0..x.len()).map(|j| hessian[(i, j)] * x[j]).sum::<f64>() - rhs[i];
        let multiplier = match state[i] {
            Bound::Free => continue,
            Bound::Lower => grad,
            Bound::Upper => -grad,
        };
        if multiplier < worst.0 {
            worst = (multiplier, Some(i));
        }
    }
    worst.1
}

/// Σ_i columns_i · control_i at every row.
fn combine(columns: &Mat<f64>, control: &[f64]) -> Vec<f64> {
    (0..columns.nrows()).map(|r| control.iter().enumerate().map(|(c, p)| columns[(r, c)] * p).sum()).collect()
}

/// The DEGREE+1 non-zero basis values at `t` (The NURBS Book, A2.1-A2.2); returns the
/// knot span index.
fn basis_functions(knots: &[f64], t: f64, values: &mut [f64; DEGREE + 1]) -> usize {
    let n_basis = knots.len() - DEGREE - 1;
    let span =
        if t >= knots[n_basis] { n_basis - 1 } else { (DEGREE..n_basis).rfind(|&s| knots[s] <= t).unwrap_or(DEGREE) };
    let (mut left, mut right) = ([0.0; DEGREE + 1], [0.0; DEGREE + 1]);
    values[0] = 1.0;
    for j in 1..=DEGREE {
        left[j] = t - knots[span + 1 - j];
        right[j] = knots[span + j] - t;
        let mut saved = 0.0;
        for r in 0..j {
            let temp = values[r] / (right[r + 1] + left[j - r]);
            values[r] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        values[j] = saved;
    }
    span
}

#[cfg(test)]
mod tests {
    use super::*;

    const DT: f64 = 0.001;

    /// A corner-like desired output: a smooth bump of `peak` mm/s over a 0.45 s window.
    fn bump(peak: f64) -> Vec<f64> {
        (0..450).map(|k| peak * (-((k as f64 - 225.0) / 50.0).powi(2)).exp()).collect()
    }

    fn gradient(a: &Mat<f64>, x: &[f64], b: &[f64]) -> Vec<f64> {
        let residual: Vec<f64> =
            (0..a.nrows()).map(|r| (0..a.ncols()).map(|c| a[(r, c)] * x[c]).sum::<f64>() - b[r]).collect();
        (0..a.ncols()).map(|c| (0..a.nrows()).map(|r| a[(r, c)] * residual[r]).sum()).collect()
    }

    fn interior_filtered(samples: usize, params: &FbsParams) -> Mat<f64> {
        let knots = clamped_uniform_knots((samples - 1) as f64 * DT, params.knot_spacing_s);
        let filtered = filter_columns(&sampled_basis(&knots, samples, DT), DT, params.tau_s);
        Mat::from_fn(samples, filtered.ncols() - 2, |r, c| filtered[(r, c + 1)])
    }

    #[test]
    fn basis_is_a_partition_of_unity_and_filtering_is_linear() {
        let knots = clamped_uniform_knots(0.3, 0.02);
        let basis = sampled_basis(&knots, 301, DT);
        for r in 0..basis.nrows() {
            let sum: f64 = (0..basis.ncols()).map(|c| basis[(r, c)]).sum();
            assert!((sum - 1.0).abs() < 1e-12, "row {r}: {sum}");
        }
        // Ñ_i is G(s) applied to N_i, and G is linear: filtering Σ N_i P_i gives Σ Ñ_i P_i.
        let filtered = filter_columns(&basis, DT, 0.0873);
        let column: Vec<f64> = (0..basis.nrows()).map(|r| basis[(r, 4)]).collect();
        let lagged = first_order_lag(&column, DT, 0.0873, 0.0);
        assert!((0..basis.nrows()).all(|r| (filtered[(r, 4)] - lagged[r]).abs() < 1e-15));
        let control: Vec<f64> = (0..basis.ncols()).map(|i| (i as f64 * 0.7).sin()).collect();
        let direct = first_order_lag(&combine(&basis, &control), DT, 0.0873, 0.0);
        let through_basis = combine(&filtered, &control);
        assert!(direct.iter().zip(&through_basis).all(|(a, b)| (a - b).abs() < 1e-12));
    }

    #[test]
    fn unconstrained_solution_satisfies_the_normal_equations() {
        let params = FbsParams { dv_min_mm_s: -1e6, dv_max_mm_s: 1e6, ..FbsParams::paper_defaults() };
        let desired = bump(1.0);
        let sol = solve_fbs(&desired, DT, &params).unwrap();
        let a = interior_filtered(desired.len(), &params);
        let x = &sol.control_mm_s[1..sol.control_mm_s.len() - 1];
        let g = gradient(&a, x, &desired);
        let scale = desired.iter().map(|d| d.abs()).sum::<f64>();
        assert!(g.iter().all(|v| v.abs() < 1e-9 * scale), "{g:?}");
    }

    #[test]
    fn bound_constrained_solution_satisfies_kkt() {
        // A 6 mm/s bump needs inputs above ΔV_max = 4 mm/s and undershoot below −2 mm/s.
        let params = FbsParams::paper_defaults();
        let desired = bump(6.0);
        let sol = solve_fbs(&desired, DT, &params).unwrap();
        let a = interior_filtered(desired.len(), &params);
        let x = &sol.control_mm_s[1..sol.control_mm_s.len() - 1];
        let g = gradient(&a, x, &desired);
        let tol = 1e-8 * desired.iter().map(|d| d.abs()).sum::<f64>();
        let mut active = 0;
        for (xi, gi) in x.iter().zip(&g) {
            assert!(*xi >= params.dv_min_mm_s - 1e-12 && *xi <= params.dv_max_mm_s + 1e-12);
            if (*xi - params.dv_max_mm_s).abs() < 1e-12 {
                active += 1;
                assert!(*gi <= tol, "upper bound: gradient {gi} must be ≤ 0");
            } else if (*xi - params.dv_min_mm_s).abs() < 1e-12 {
                active += 1;
                assert!(*gi >= -tol, "lower bound: gradient {gi} must be ≥ 0");
            } else {
                assert!(gi.abs() <= tol, "free: gradient {gi}");
            }
        }
        assert!(active > 0, "the bounds must bind for this test to mean anything");
    }

    #[test]
    fn response_of_a_feasible_spline_is_recovered_exactly() {
        let params = FbsParams::paper_defaults();
        let samples = 400;
        let knots = clamped_uniform_knots((samples - 1) as f64 * DT, params.knot_spacing_s);
        let n_basis = knots.len() - DEGREE - 1;
        // Inside [ΔV_min, ΔV_max] = [−2, 4] mm/s, touching neither bound.
        let mut truth: Vec<f64> = (0..n_basis).map(|i| 1.0 + 2.5 * (i as f64 * 0.5).sin()).collect();
        truth[0] = 0.0;
        truth[n_basis - 1] = 0.0;
        let filtered = filter_columns(&sampled_basis(&knots, samples, DT), DT, params.tau_s);
        let desired = combine(&filtered, &truth);
        let sol = solve_fbs(&desired, DT, &params).unwrap();
        for (got, want) in sol.control_mm_s.iter().zip(&truth) {
            assert!((got - want).abs() < 1e-7, "{got} vs {want}");
        }
        assert!(sol.residual_norm_mm_s < 1e-8);
    }

    #[test]
    fn unmeasured_samples_are_left_out_of_the_fit() {
        // The bump with its rising half unmeasured: the fit must not pull the output to
        // zero there. It matches the measured half as well as with everything measured,
        // and the output it gives the gap rises towards the bump instead of staying at 0.
        let params = FbsParams::paper_defaults();
        let full = bump(1.0);
        let mut gappy = full.clone();
        gappy[100..225].iter_mut().for_each(|d| *d = f64::NAN);
        let sol = solve_fbs(&gappy, DT, &params).unwrap();
        let measured_err: f64 = (225..450).map(|k| (sol.output_mm_s[k] - full[k]).powi(2)).sum::<f64>().sqrt();
        let zeroed: Vec<f64> = gappy.iter().map(|d| if d.is_nan() { 0.0 } else { *d }).collect();
        let old = solve_fbs(&zeroed, DT, &params).unwrap();
        let old_err: f64 = (225..450).map(|k| (old.output_mm_s[k] - full[k]).powi(2)).sum::<f64>().sqrt();
        assert!(measured_err < 0.5 * old_err, "{measured_err} vs {old_err}");
        assert!(sol.output_mm_s[200] > 0.5 * full[200], "{} vs {}", sol.output_mm_s[200], full[200]);
        let all_measured: f64 = (0..450)
            .filter(|&k| gappy[k].is_finite())
            .map(|k| (sol.output_mm_s[k] - full[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!((sol.residual_norm_mm_s - all_measured).abs() < 1e-9);
        // A window with nothing measured after its first half: the unknowns no row sees are 0.
        let mut blind = full.clone();
        blind[200..].iter_mut().for_each(|d| *d = f64::NAN);
        let sol = solve_fbs(&blind, DT, &params).unwrap();
        assert!(sol.control_mm_s.iter().all(|c| c.is_finite()));
    }

    #[test]
    fn end_control_points_and_input_ends_are_zero() {
        let sol = solve_fbs(&bump(3.0), DT, &FbsParams::paper_defaults()).unwrap();
        assert_eq!(sol.control_mm_s[0], 0.0);
        assert_eq!(*sol.control_mm_s.last().unwrap(), 0.0);
        // A clamped spline takes its end control values at the window ends: smooth hand-over (eq. 39).
        assert!(sol.input_mm_s[0].abs() < 1e-12 && sol.input_mm_s.last().unwrap().abs() < 1e-12);
        let v_e = vec![20.0; 600];
        let command = compensated_command(&v_e, 100, &sol.input_mm_s);
        assert_eq!(command[99], 20.0);
        assert!((command[100 + 225] - (20.0 - sol.input_mm_s[225])).abs() < 1e-12);
    }

    #[test]
    fn spans_merge_small_gaps_and_extend_by_the_paper_margin() {
        let mut dw = vec![0.0; 1000];
        dw[300..320].iter_mut().for_each(|v| *v = 0.1);
        dw[323..340].iter_mut().for_each(|v| *v = -0.2);
        dw[600..610].iter_mut().for_each(|v| *v = 0.2);
        dw[605] = f64::NAN;
        let spans = error_spans(&dw, 0.05, 5);
        assert_eq!(spans, vec![SampleSpan { first: 300, last: 339 }, SampleSpan { first: 600, last: 609 },]);
        let extended = extend_span(spans[0], 0.1, DT, 1000);
        assert_eq!(extended, SampleSpan { first: 200, last: 439 });
        assert_eq!(extend_span(spans[1], 0.5, DT, 1000).last, 999);
    }

    #[test]
    fn swept_area_is_eq_2_on_a_line_and_a_disc_sector_on_a_pivot() {
        // Straight line, ψ = 0: 2w|v| (eq. 2 per unit time).
        let line = SweepSample { speed_mm_s: 20.0, psi_rad: 0.0, kappa_eff_per_mm: 0.0 };
        assert!((swept_area_rate_mm2_s(0.225, 0.225, &line) - 2.0 * 0.225 * 20.0).abs() < 1e-12);
        // A fan turning through π at a nearly fixed foot (κ_eff|v| = π rad/s for 1 s) with
        // w_l = w_r = r sweeps the outer half disc (+πr²/2) and the inner one backwards
        // (−πr²/2) on top of the 2r|v| strip: the net is 2r|v|, each point counted once.
        let (r, v) = (0.3, 1e-3);
        let pivot = SweepSample { speed_mm_s: v, psi_rad: 0.0, kappa_eff_per_mm: std::f64::consts::PI / v };
        let outer_only = swept_area_rate_mm2_s(0.0, r, &pivot);
        assert!((outer_only - (r * v + std::f64::consts::FRAC_PI_2 * r * r)).abs() < 1e-12);
        assert!((swept_area_rate_mm2_s(r, r, &pivot) - 2.0 * r * v).abs() < 1e-12);
        // A measured bead equal to the desired one asks for nothing; 0.1 mm more on a line
        // at 20 mm/s is ΔE = h·20·0.1 mm³/s, Δv_e = ΔE/A_fil.
        let dv = velocity_change_from_sweep_mm_s(
            &[(0.225, 0.225), (0.275, 0.275), (f64::NAN, 0.2)],
            &[(0.225, 0.225); 3],
            &[line; 3],
            0.25,
            2.405,
            1.0,
        );
        assert!(dv[0].abs() < 1e-15 && (dv[1] - 0.25 * 20.0 * 0.1 / 2.405).abs() < 1e-12 && dv[2].is_nan());
    }

    #[test]
    fn tail_fit_brings_the_lagged_output_back_to_zero_after_the_window() {
        // A bump that ends at the window's end: without the tail the lag's response keeps
        // going after Δt̂1; fitted over 3τ more it must be much smaller there.
        let desired = bump(1.0);
        let tail = 262;
        let mut extended = desired.clone();
        extended.extend(std::iter::repeat_n(0.0, tail));
        let params = FbsParams::paper_defaults();
        let after = |sol: &FbsSolution| -> f64 {
            // The lagged response after the window, continued from the window's last output.
            let last = *sol.output_mm_s[..desired.len()].last().unwrap();
            let decay = (-DT / params.tau_s).exp();
            (1..=tail).map(|j| (last * decay.powi(j as i32)).powi(2)).sum::<f64>().sqrt()
        };
        let plain = solve_fbs(&desired, DT, &params).unwrap();
        let with_tail = solve_fbs_with_tail(&extended, tail, DT, &params).unwrap();
        assert!(with_tail.input_mm_s[desired.len()..].iter().all(|v| *v == 0.0));
        let tail_norm: f64 = with_tail.output_mm_s[desired.len()..].iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(tail_norm < 0.5 * after(&plain), "{tail_norm} vs {}", after(&plain));
    }

    #[test]
    fn spans_add_their_lagged_responses() {
        // Two error spans close in time: the second's desired output has the first's tail
        // subtracted, so the summed lagged input matches the desired output better than
        // solving each alone would.
        let n = 1500;
        let mut dw = vec![0.0; n];
        dw[300..400].iter_mut().for_each(|v| *v = 0.2);
        dw[800..900].iter_mut().for_each(|v| *v = 0.2);
        let desired: Vec<f64> = dw.iter().map(|d| 5.0 * d).collect();
        let params = SpanParams {
            epsilon_mm: 0.05,
            extension_s: 0.1,
            fbs: FbsParams { tail_s: 0.26, ..FbsParams::paper_defaults() },
        };
        let spans = compensate_spans(&dw, &desired, DT, &params, |_| 1.0).unwrap();
        assert_eq!(spans.len(), 2);
        let command = apply_spans(&vec![0.0; n], &spans);
        let output = first_order_lag(&command, DT, params.fbs.tau_s, 0.0);
        let err: f64 = output.iter().zip(&desired).map(|(o, d)| (-o - d).powi(2)).sum::<f64>().sqrt();
        let norm: f64 = desired.iter().map(|d| d * d).sum::<f64>().sqrt();
        assert!(err < 0.35 * norm, "{err} vs {norm}");
    }

    #[test]
    fn gain_and_desired_velocity_follow_eq_33() {
        assert_eq!(paper_gain(150.0), 1.0);
        assert_eq!(paper_gain(135.0), 2.0);
        // A 0.1 mm excess on a 0.45 mm bead at 10 mm/s: ΔE = h·10·0.1, Δv_e = 10·0.1/0.45.
        let dv = desired_velocity_change_mm_s(&[0.1, f64::NAN], &[10.0, 10.0], &[0.225, 0.225], 1.0);
        assert!((dv[0] - 10.0 * 0.1 / 0.45).abs() < 1e-12 && dv[1].is_nan());
        let wd = desired_half_width_mm(0.225, &[0.0, std::f64::consts::FRAC_PI_3]);
        assert!((wd[1] - 0.45).abs() < 1e-12);
        let err = width_error_mm(&[0.3, f64::NAN], &[0.2, 0.2], &wd);
        assert!((err[0] - 0.05).abs() < 1e-12 && err[1].is_nan());
    }
}
