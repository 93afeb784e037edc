//! The melt's lag τ and the pressure advance to set, from the widths of a printed
//! pressure-advance pattern (issue 55 item 2): every line printed under its own advance
//! K_l, measured along its length (on one or several photos of the print).
//!
//! Model (paper 000's first-order lag with the firmware's advance, [`super::pressure_advance`]):
//! line `l`'s width at `x` is `s_l · W(x; τ, K_l)`, with `W = S[E]' + (K_l − τ)·S[u_τ]'`
//! the deposit per mm of path under its G-code's speed profile (0 where it falls below a
//! quarter of the commanded: a gap, as the measurement reports one), and `s_l` the line's
//! steady width over its nominal width (the squish of a first layer varies across the
//! bed; it is free per line, found in closed form). τ is common to the lines of a print
//! and found by grouped least squares: the sum over lines of each line's squared error,
//! profiled over `s_l`, minimised over a log-spaced grid of τ, a finer grid around its
//! minimum and the parabola through the fine points around it (in log τ; the error is
//! smooth in τ: a gap's edge moves continuously through the model's cells).
//!
//! - **Interval**: delete-one-line jackknife on log τ (a line is a group: its photos are
//!   the same line), Student-t with lines − 1 degrees of freedom.
//! - **Held-out error**: each line predicted under the τ fitted without it; only its level
//!   `s_l` is fitted on the line itself (one number: the shape is held out).
//! - **Recommended K**: the advance that makes the predicted width flattest, the least
//!   squares of `W − commanded` over every position of every line (closed form: W is
//!   linear in K); without smoothing this is K = τ exactly. Its interval is the same
//!   jackknife over the lines' leave-one-out τ.
//! - **Noise**: each line's sample-to-sample scatter, `1.4826·median|Δw|/√2` over
//!   neighbouring positions within a bead, median over lines and photos.

use rayon::prelude::*;

use super::pressure_advance::{deposit_parts, DepositParts, DepositSettings};
use super::printed_lines::PrintedLine;
use crate::stats::finite_median;

/// How a print's lag is fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TuningSettings {
    /// Smallest and largest τ searched (s).
    pub tau_range_s: (f64, f64),
    /// Ratio between neighbouring τ on the grid over the whole range (> 1).
    pub coarse_ratio: f64,
    /// Ratio between neighbouring τ on the grid around the coarse minimum (> 1), which
    /// spans two coarse steps either side.
    pub fine_ratio: f64,
    /// Model positions' spacing (mm).
    pub step_mm: f64,
    /// Box smoothing of the modelled width along the path (mm): about a nozzle diameter.
    pub smoothing_mm: f64,
    /// A modelled deposit below this fraction of the commanded width is a gap (width 0),
    /// as a measured bead thinner than this is reported as a gap.
    pub gap_fraction: f64,
    /// Confidence level of the intervals.
    pub level: f64,
}

impl Default for TuningSettings {
    /// τ from 2 ms to 1 s in 15 % steps, then 1 % steps around the minimum, a 0.05 mm model grid smoothed over a 0.4 mm
    /// nozzle, a gap below a quarter of the commanded width, 95 % intervals.
    fn default() -> Self {
        Self {
            tau_range_s: (0.002, 1.0),
            coarse_ratio: 1.15,
            fine_ratio: 1.01,
            step_mm: 0.05,
            smoothing_mm: 0.4,
            gap_fraction: 0.25,
            level: 0.95,
        }
    }
}

/// One line's widths measured along it, one series per photo.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredLine {
    /// Index of the line in the print's lines.
    pub line: usize,
    /// Per photo: (position from the line's G-code start (mm), width (mm), 0 in a gap),
    /// in order of position.
    pub series: Vec<Vec<(f64, f64)>>,
}

/// Why a print's lag cannot be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TuningError {
    /// Fewer than two lines have measured widths.
    #[error("expected at least 2 measured lines to fit a lag, got {0}")]
    TooFewLines(usize),
    /// A measured line is not among the print's lines.
    #[error("measured line {line} is not among the print's {lines} lines")]
    UnknownLine {
        /// The measured line's index.
        line: usize,
        /// How many lines the print has.
        lines: usize,
    },
    /// The settings are out of range.
    #[error("tuning settings: {0}")]
    Settings(String),
}

/// The golden section's final bracket in log τ (0.01 %).
const LOG_TAU_TOLERANCE: f64 = 1e-4;

/// Where the fitted τ lies in the searched range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TauStatus {
    /// Inside the range: a minimum was found.
    Fitted,
    /// At an end of the range: the data want a τ outside it.
    AtBound,
}

/// One line's fit.
#[derive(Debug, Clone, PartialEq)]
pub struct LineFit {
    /// Index of the line in the print's lines.
    pub line: usize,
    /// Its pressure advance (s).
    pub advance_s: f64,
    /// Measured over modelled width `s_l` at the print's τ (the line's squish).
    pub level: f64,
    /// RMSE at the print's τ (mm).
    pub rmse_mm: f64,
    /// τ fitted without this line (s).
    pub tau_without_s: f64,
    /// RMSE of this line predicted under `tau_without_s` (mm).
    pub heldout_rmse_mm: f64,
    /// Positions measured (all photos).
    pub positions: usize,
    /// Sample-to-sample noise of its widths (mm), median over its photos.
    pub noise_mm: f64,
    /// How uneven its measured width is: RMS of width over its median − 1, gaps as 0
    /// (what a person judging the lines by eye looks for: the flattest line).
    pub spread: f64,
}

/// A print's fitted lag and recommended advance.
#[derive(Debug, Clone, PartialEq)]
pub struct Tuning {
    /// τ (s).
    pub tau_s: f64,
    /// Its interval (s).
    pub tau_ci_s: (f64, f64),
    /// Whether τ is inside the searched range.
    pub status: TauStatus,
    /// The advance that makes the width flattest under τ (s).
    pub recommended_pa_s: f64,
    /// Its interval (s).
    pub pa_ci_s: (f64, f64),
    /// Held-out RMSE over every position of every line (mm).
    pub heldout_rmse_mm: f64,
    /// RMSE at τ over every position (mm).
    pub rmse_mm: f64,
    /// Median over lines of the sample-to-sample noise (mm).
    pub noise_mm: f64,
    /// The advance of the line whose measured width is flattest (least spread) (s).
    pub flattest_line_advance_s: f64,
    /// Per line.
    pub lines: Vec<LineFit>,
}

/// A line's model widths at its measured positions.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePrediction {
    /// Per photo series (as [`MeasuredLine::series`]): the model's width at each position (mm).
    pub series: Vec<Vec<f64>>,
    /// The line's level `s_l`.
    pub level: f64,
}

/// Fits τ to the `measured` lines of `lines` (lines without a measured position are left
/// out) and recommends the advance.
pub fn tune(
    lines: &[PrintedLine],
    measured: &[MeasuredLine],
    settings: &TuningSettings,
) -> Result<Tuning, TuningError> {
    check(lines, measured, settings)?;
    let measured: Vec<&MeasuredLine> = measured.iter().filter(|m| has_widths(m)).collect();
    let search = Search::new(lines, &measured, settings);
    let (tau_s, status) = (search.minimum(None), search.status);
    let minimum = |skip: Option<usize>| search.minimum(skip);
    let fits: Vec<LineFit> = (0..measured.len())
        .into_par_iter()
        .map(|l| {
            let m = measured[l];
            let line = &lines[m.line];
            let tau_without_s = minimum(Some(l));
            let (sse_at, level, n) = line_error(line, m, tau_s, settings);
            let (sse_out, _, _) = line_error(line, m, tau_without_s, settings);
            LineFit {
                line: m.line,
                advance_s: line.pressure_advance.advance_s,
                level,
                rmse_mm: (sse_at / n.max(1) as f64).sqrt(),
                tau_without_s,
                heldout_rmse_mm: (sse_out / n.max(1) as f64).sqrt(),
                positions: n,
                noise_mm: line_noise(m),
                spread: width_spread(m),
            }
        })
        .collect();
    let replicates_log: Vec<f64> = fits.iter().map(|f| f.tau_without_s.ln()).collect();
    let (lo, hi) = discrepancy::stats::jackknife_interval(tau_s.ln(), &replicates_log, settings.level);
    let measured_lines: Vec<&PrintedLine> = measured.iter().map(|m| &lines[m.line]).collect();
    let recommended_pa_s = flattest_advance(&measured_lines, tau_s, settings);
    let pa_replicates: Vec<f64> =
        fits.iter().map(|f| flattest_advance(&measured_lines, f.tau_without_s, settings)).collect();
    let pa_ci_s = discrepancy::stats::jackknife_interval(recommended_pa_s, &pa_replicates, settings.level);
    let pooled = |rmse: fn(&LineFit) -> f64| {
        let (ss, n) =
            fits.iter().fold((0.0, 0usize), |(ss, n), f| (ss + rmse(f).powi(2) * f.positions as f64, n + f.positions));
        (ss / n.max(1) as f64).sqrt()
    };
    Ok(Tuning {
        tau_s,
        tau_ci_s: (lo.exp(), hi.exp()),
        status,
        recommended_pa_s,
        pa_ci_s,
        heldout_rmse_mm: pooled(|f| f.heldout_rmse_mm),
        rmse_mm: pooled(|f| f.rmse_mm),
        noise_mm: finite_median(fits.iter().map(|f| f.noise_mm)),
        flattest_line_advance_s: fits
            .iter()
            .filter(|f| f.spread.is_finite())
            .min_by(|a, b| a.spread.total_cmp(&b.spread))
            .map_or(f64::NAN, |f| f.advance_s),
        lines: fits,
    })
}

/// The model's widths for `measured` under `tau_s`, with the line's level fitted.
pub fn predict(line: &PrintedLine, measured: &MeasuredLine, tau_s: f64, settings: &TuningSettings) -> LinePrediction {
    let parts = parts(line, tau_s, settings);
    let shapes: Vec<Vec<f64>> =
        measured.series.iter().map(|s| s.iter().map(|&(x, _)| deposit_at(&parts, line, x, tau_s)).collect()).collect();
    let level = level_of(measured, &shapes);
    LinePrediction { series: shapes.iter().map(|s| s.iter().map(|r| level * r).collect()).collect(), level }
}

/// The model's bead width at each of `positions_mm` under `tau_s` and the line's own
/// advance, before the line's level (mm; 0 in a gap).
pub fn modelled_widths(line: &PrintedLine, positions_mm: &[f64], tau_s: f64, settings: &TuningSettings) -> Vec<f64> {
    let parts = parts(line, tau_s, settings);
    positions_mm.iter().map(|&x| deposit_at(&parts, line, x, tau_s)).collect()
}

fn check(lines: &[PrintedLine], measured: &[MeasuredLine], s: &TuningSettings) -> Result<(), TuningError> {
    let (lo, hi) = s.tau_range_s;
    let positive = |x: f64| x.is_finite() && x > 0.0;
    if !(positive(lo) && positive(hi) && lo < hi && s.coarse_ratio > 1.0 && s.fine_ratio > 1.0 && positive(s.step_mm))
        || !(s.smoothing_mm >= 0.0 && s.level > 0.0 && s.level < 1.0)
    {
        return Err(TuningError::Settings(format!("{s:?}")));
    }
    if let Some(m) = measured.iter().find(|m| m.line >= lines.len()) {
        return Err(TuningError::UnknownLine { line: m.line, lines: lines.len() });
    }
    let with_widths = measured.iter().filter(|m| has_widths(m)).count();
    if with_widths < 2 {
        return Err(TuningError::TooFewLines(with_widths));
    }
    Ok(())
}

fn has_widths(m: &MeasuredLine) -> bool {
    m.series.iter().any(|s| !s.is_empty())
}

/// `τ_lo · ratio^k` up to `τ_hi` (its last point `τ_hi`).
fn log_grid((lo, hi): (f64, f64), ratio: f64) -> Vec<f64> {
    let n = ((hi / lo).ln() / ratio.ln()).ceil().max(2.0) as usize;
    (0..=n).map(|k| lo * (hi / lo).powf(k as f64 / n as f64)).collect()
}

/// The search for τ: a coarse grid over the range, a fine grid around its best point,
/// then a golden section between the fine points around the best.
struct Search<'a> {
    lines: &'a [PrintedLine],
    measured: &'a [&'a MeasuredLine],
    settings: &'a TuningSettings,
    coarse: Profile,
    fine: Profile,
    status: TauStatus,
}

impl<'a> Search<'a> {
    fn new(lines: &'a [PrintedLine], measured: &'a [&'a MeasuredLine], settings: &'a TuningSettings) -> Self {
        let coarse = Profile::new(lines, measured, log_grid(settings.tau_range_s, settings.coarse_ratio), settings);
        let best = coarse.best(None);
        let status = if coarse.interior(best) { TauStatus::Fitted } else { TauStatus::AtBound };
        let (lo, hi) = settings.tau_range_s;
        let window = settings.coarse_ratio.powi(2);
        let fine_range = ((coarse.grid[best] / window).max(lo), (coarse.grid[best] * window).min(hi));
        let fine = Profile::new(lines, measured, log_grid(fine_range, settings.fine_ratio), settings);
        Self { lines, measured, settings, coarse, fine, status }
    }

    /// The summed error of every line but `skip` at `tau_s`.
    fn error(&self, tau_s: f64, skip: Option<usize>) -> f64 {
        let others = self.measured.iter().enumerate().filter(|(l, _)| Some(*l) != skip);
        others.map(|(_, m)| line_error(&self.lines[m.line], m, tau_s, self.settings).0).sum()
    }

    /// The τ of every line but `skip`: the parabola (in log τ) through the fine grid's
    /// best point and its neighbours; where the fine grid's ends hold the best, a golden
    /// section between the coarse grid's points around its best; an end of the range
    /// where the coarse grid's ends hold it.
    fn minimum(&self, skip: Option<usize>) -> f64 {
        let (f, c) = (self.fine.best(skip), self.coarse.best(skip));
        if self.fine.interior(f) {
            let totals = self.fine.totals(skip);
            let xs = [f - 1, f, f + 1].map(|i| self.fine.grid[i].ln());
            return parabola_vertex(xs, [totals[f - 1], totals[f], totals[f + 1]]).exp();
        }
        if !self.coarse.interior(c) {
            return self.coarse.grid[c];
        }
        let error = |log_tau: f64| self.error(log_tau.exp(), skip);
        golden_minimum(error, self.coarse.grid[c - 1].ln(), self.coarse.grid[c + 1].ln(), LOG_TAU_TOLERANCE).exp()
    }
}

/// The vertex of the parabola through three points (x ascending, the middle one lowest),
/// clamped to the outer two.
fn parabola_vertex([x0, x1, x2]: [f64; 3], [y0, y1, y2]: [f64; 3]) -> f64 {
    let denominator = (x0 - x1) * (y0 - y2) - (x0 - x2) * (y0 - y1);
    let numerator = (x0 - x1).powi(2) * (y0 - y2) - (x0 - x2).powi(2) * (y0 - y1);
    let vertex = if denominator.abs() > 0.0 { x0 - 0.5 * numerator / denominator } else { x1 };
    vertex.clamp(x0, x2)
}

/// Each line's squared error (level profiled out) on a grid of τ.
struct Profile {
    grid: Vec<f64>,
    /// `sse[g][l]`.
    sse: Vec<Vec<f64>>,
}

impl Profile {
    fn new(lines: &[PrintedLine], measured: &[&MeasuredLine], grid: Vec<f64>, s: &TuningSettings) -> Self {
        let sse = grid
            .par_iter()
            .map(|&tau| measured.iter().map(|m| line_error(&lines[m.line], m, tau, s).0).collect())
            .collect();
        Self { grid, sse }
    }

    /// The summed error of every line but `skip` at each grid point.
    fn totals(&self, skip: Option<usize>) -> Vec<f64> {
        let others =
            |per: &Vec<f64>| -> f64 { per.iter().enumerate().filter(|(l, _)| Some(*l) != skip).map(|(_, e)| e).sum() };
        self.sse.iter().map(others).collect()
    }

    /// The grid index where the summed error of every line but `skip` is least.
    fn best(&self, skip: Option<usize>) -> usize {
        let totals = self.totals(skip);
        (0..totals.len()).min_by(|&a, &b| totals[a].total_cmp(&totals[b])).unwrap_or(0)
    }

    /// Whether `index` has a grid point on either side.
    fn interior(&self, index: usize) -> bool {
        index > 0 && index + 1 < self.grid.len()
    }
}

/// Golden-section search for a minimum of `f` on `[a, b]` down to `tolerance`. The error
/// is a staircase as well as a curve (a cell turns into a gap at a τ), so no parabola.
fn golden_minimum(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64, tolerance: f64) -> f64 {
    let ratio = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - ratio * (b - a), a + ratio * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    while b - a > tolerance {
        if fc <= fd {
            (b, d, fd) = (d, c, fc);
            c = b - ratio * (b - a);
            fc = f(c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + ratio * (b - a);
            fd = f(d);
        }
    }
    if fc <= fd {
        c
    } else {
        d
    }
}

fn parts(line: &PrintedLine, tau_s: f64, s: &TuningSettings) -> DepositParts {
    let settings = DepositSettings {
        tau_s,
        pressure_advance: line.pressure_advance,
        step_mm: s.step_mm,
        smoothing_mm: s.smoothing_mm,
        gap_fraction: s.gap_fraction,
    };
    deposit_parts(line, &settings)
}

/// The modelled deposit per mm of path at `x_mm` (mm; linear between model positions, 0 in a gap).
fn deposit_at(parts: &DepositParts, line: &PrintedLine, x_mm: f64, tau_s: f64) -> f64 {
    let k = line.pressure_advance.advance_s;
    let step = parts.positions_mm.get(1).copied().unwrap_or(1.0);
    let last = parts.positions_mm.len() - 1;
    let f = (x_mm / step).clamp(0.0, last as f64);
    let j = (f.floor() as usize).min(last.saturating_sub(1));
    let frac = f - j as f64;
    let w = |i: usize| parts.bead_width_mm(i, k, tau_s);
    if last == 0 {
        w(0)
    } else {
        w(j) * (1.0 - frac) + w(j + 1) * frac
    }
}

/// The line's level: least squares of the widths on the shapes.
fn level_of(measured: &MeasuredLine, shapes: &[Vec<f64>]) -> f64 {
    let (mut wr, mut rr) = (0.0, 0.0);
    for (series, shape) in measured.series.iter().zip(shapes) {
        for (&(_, w), &r) in series.iter().zip(shape) {
            wr += w * r;
            rr += r * r;
        }
    }
    if rr > 0.0 {
        wr / rr
    } else {
        0.0
    }
}

/// (squared error with the level profiled out, level, positions) of one line at `tau_s`.
fn line_error(line: &PrintedLine, measured: &MeasuredLine, tau_s: f64, s: &TuningSettings) -> (f64, f64, usize) {
    let p = predict(line, measured, tau_s, s);
    let (mut sse, mut n) = (0.0, 0);
    for (series, model) in measured.series.iter().zip(&p.series) {
        for (&(_, w), &m) in series.iter().zip(model) {
            sse += (w - m).powi(2);
            n += 1;
        }
    }
    (sse, p.level, n)
}

/// The advance that makes the modelled width of `lines` flattest under `tau_s`: least
/// squares of `pushed + (K − τ)·lagged − commanded` over every model position.
pub fn flattest_advance(lines: &[&PrintedLine], tau_s: f64, s: &TuningSettings) -> f64 {
    let (mut ab, mut bb) = (0.0, 0.0);
    for line in lines {
        let p = parts(line, tau_s, s);
        for j in 0..p.positions_mm.len() {
            let excess = p.pushed_mm[j] - p.commanded_mm[j];
            ab += excess * p.lagged_mm_per_s[j];
            bb += p.lagged_mm_per_s[j].powi(2);
        }
    }
    if bb > 0.0 {
        tau_s - ab / bb
    } else {
        tau_s
    }
}

/// RMS over every position of every photo of `w / median − 1` (the median of the line's
/// widths; a gap counts as width 0).
fn width_spread(measured: &MeasuredLine) -> f64 {
    let widths = || measured.series.iter().flatten().map(|p| p.1);
    let median = finite_median(widths());
    let (ss, n) = widths().fold((0.0, 0usize), |(ss, n), w| (ss + (w / median - 1.0).powi(2), n + 1));
    (ss / n.max(1) as f64).sqrt()
}

/// `1.4826·median|Δw|/√2` over neighbouring positions within a bead, median over photos.
fn line_noise(measured: &MeasuredLine) -> f64 {
    finite_median(measured.series.iter().map(|series| {
        let steps = series.windows(2).filter(|p| p[0].1 > 0.0 && p[1].1 > 0.0).map(|p| (p[1].1 - p[0].1).abs());
        1.4826 * finite_median(steps) / std::f64::consts::SQRT_2
    }))
}

#[cfg(test)]
mod tests;
