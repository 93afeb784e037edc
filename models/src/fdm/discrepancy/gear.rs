//! The gear ripple's period search and its per-line phase (DESIGN §7, a nuisance).
//!
//! The ripple is `ŵ·(1 + g·A·sin(2πx/P + φ))`: one gear, so one amplitude `A` and one
//! period `P` for all lines, and a phase `φ` per line. With the rest of the model
//! fixed, `A sin(2πx/P + φ) = α sin 2πx/P + β cos 2πx/P` is linear in `(α, β)`, so a
//! line's phase is `atan2(β, α)` of its 2 × 2 least squares, and for every period on a
//! grid the explained sum of squares of all training lines is a periodogram weighted by
//! the model width. Measured residuals are red (slow swells carry most of their power),
//! so the raw periodogram peaks at the longest period whatever the gear does; a gear is
//! a narrow line in the spectrum, so the period chosen is the one whose power stands
//! highest above a red-noise continuum, a power law `P ∝ f^b` fitted to the log
//! periodogram (least squares, then again without the bins more than two median
//! absolute deviations above the first fit, so that the line itself does not lift its
//! background). Real widths also swell slowly by several per cent with no fixed period
//! and phase, and such a swell can stand as high; a gear's phase, however, is fixed
//! along a line. So the `CANDIDATE_PEAKS` highest peaks are tried by cross-fitting on
//! the training lines themselves — each line's phase from one half predicting its
//! other half — and the period whose ripple predicts best is chosen. Given the phases, the shared amplitude is a one-parameter least
//! squares. A held-out line gets only its phase from its calibration half: its
//! amplitude is the training lines', so a calibration half whose residual is not a
//! ripple cannot blow the ripple up on the other half. The grid spans 2-60 mm in frequency steps of a quarter
//! cycle over 120 mm, so no peak falls between two grid points by more than an eighth
//! of a cycle; the least squares that follows refines the period. Searching the grid is
//! part of every fit, so a held-out line's score pays for the look-elsewhere effect.

use std::f64::consts::PI;

/// Shortest period searched (mm).
pub const PERIOD_MIN_MM: f64 = 2.0;
/// Longest period searched (mm).
pub const PERIOD_MAX_MM: f64 = 60.0;
/// Frequency step of the grid (1/mm): a quarter cycle over 120 mm.
pub const FREQUENCY_STEP_PER_MM: f64 = 1.0 / 480.0;

/// The grid's frequencies (1/mm), from `1/PERIOD_MAX` to `1/PERIOD_MIN`.
pub fn frequencies() -> Vec<f64> {
    let (lo, hi) = (1.0 / PERIOD_MAX_MM, 1.0 / PERIOD_MIN_MM);
    let n = ((hi - lo) / FREQUENCY_STEP_PER_MM).floor() as usize;
    (0..=n).map(|j| lo + j as f64 * FREQUENCY_STEP_PER_MM).collect()
}

/// `sin`, `cos` of every grid frequency at one line's sample positions.
#[derive(Debug, Clone)]
pub struct GearTable {
    sin: Vec<f64>,
    cos: Vec<f64>,
    samples: usize,
}

impl GearTable {
    /// The table at `positions_mm`.
    pub fn new(positions_mm: &[f64]) -> Self {
        let freqs = frequencies();
        let n = positions_mm.len();
        let (mut sin, mut cos) = (Vec::with_capacity(freqs.len() * n), Vec::with_capacity(freqs.len() * n));
        for f in &freqs {
            for x in positions_mm {
                let (s, c) = (2.0 * PI * f * x).sin_cos();
                sin.push(s);
                cos.push(c);
            }
        }
        Self { sin, cos, samples: n }
    }
}

/// Smoothing attenuation of a ripple of period `period_mm` under a box of `window_mm`.
pub fn attenuation(period_mm: f64, window_mm: f64) -> f64 {
    let z = PI * window_mm / period_mm;
    if z.abs() < 1e-9 {
        1.0
    } else {
        z.sin() / z
    }
}

/// Moments of the 2 × 2 least squares of `r` on `(ŵ sin, ŵ cos)`.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    ss: f64,
    sc: f64,
    cc: f64,
    sr: f64,
    cr: f64,
}

impl Moments {
    fn add(&mut self, w: f64, s: f64, c: f64, r: f64) {
        let (a, b) = (w * s, w * c);
        self.ss += a * a;
        self.sc += a * b;
        self.cc += b * b;
        self.sr += a * r;
        self.cr += b * r;
    }

    /// `(α, β)` and the explained sum of squares.
    fn solve(&self) -> (f64, f64, f64) {
        let det = self.ss * self.cc - self.sc * self.sc;
        if det.is_nan() || det <= 1e-12 * (self.ss * self.cc).max(f64::MIN_POSITIVE) {
            return (0.0, 0.0, 0.0);
        }
        let alpha = (self.cc * self.sr - self.sc * self.cr) / det;
        let beta = (self.ss * self.cr - self.sc * self.sr) / det;
        (alpha, beta, alpha * self.sr + beta * self.cr)
    }
}

/// Peaks of the periodogram tried by cross-fitting.
pub const CANDIDATE_PEAKS: usize = 8;

/// One training line for the period search: its table, model widths `ŵ` and
/// observations at the table's samples, and the sample positions.
pub type SearchLine<'a> = (&'a GearTable, &'a [f64], &'a [f64], &'a [f64]);

/// The period (mm) of the ripple that best predicts each training line's half from its
/// other half, among the highest peaks above the red-noise continuum; `g` is the
/// smoothing attenuation model.
pub fn best_period(lines: &[SearchLine], smoothing_mm: f64) -> f64 {
    let freqs = frequencies();
    let table_lines: Vec<(&GearTable, &[f64], &[f64])> = lines.iter().map(|l| (l.0, l.1, l.2)).collect();
    let power = periodogram(&table_lines, freqs.len());
    let excess = excess_over_continuum(&freqs, &power);
    let peaks = highest_peaks(&excess, CANDIDATE_PEAKS);
    let score = |j: usize| cross_half_gain(lines, 1.0 / freqs[j], smoothing_mm);
    let best = peaks.iter().copied().max_by(|&a, &b| score(a).total_cmp(&score(b))).unwrap_or(0);
    1.0 / freqs[best]
}

/// `ln P − ln P_continuum` at each frequency, the continuum a power law fitted twice.
fn excess_over_continuum(freqs: &[f64], power: &[f64]) -> Vec<f64> {
    let x: Vec<f64> = freqs.iter().map(|f| f.ln()).collect();
    let y: Vec<f64> = power.iter().map(|p| p.max(f64::MIN_POSITIVE).ln()).collect();
    let first = line_fit(&x, &y, |_| true);
    let excess: Vec<f64> = x.iter().zip(&y).map(|(xi, yi)| yi - first.0 - first.1 * xi).collect();
    let mut sorted = excess.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let mut deviations: Vec<f64> = excess.iter().map(|e| (e - median).abs()).collect();
    deviations.sort_by(f64::total_cmp);
    let cut = median + 2.0 * deviations[deviations.len() / 2];
    let (a, b) = line_fit(&x, &y, |j| excess[j] <= cut);
    x.iter().zip(&y).map(|(xi, yi)| yi - a - b * xi).collect()
}

/// Indices of the `count` highest local maxima of `values`, highest first.
fn highest_peaks(values: &[f64], count: usize) -> Vec<usize> {
    let n = values.len();
    let mut peaks: Vec<usize> = (0..n)
        .filter(|&j| (j == 0 || values[j] >= values[j - 1]) && (j + 1 == n || values[j] >= values[j + 1]))
        .collect();
    peaks.sort_by(|&a, &b| values[b].total_cmp(&values[a]));
    peaks.truncate(count);
    peaks
}

/// Sum over lines of the squared error removed from each half by the ripple whose
/// phase was fitted on the other half, with the amplitude shared by the full lines.
fn cross_half_gain(lines: &[SearchLine], period_mm: f64, smoothing_mm: f64) -> f64 {
    let g = attenuation(period_mm, smoothing_mm);
    let phases: Vec<f64> = lines.iter().map(|l| line_phase(l.3, l.1, l.2, period_mm, |_| true)).collect();
    let full: Vec<_> = lines.iter().zip(&phases).map(|(l, &ph)| (l.3, l.1, l.2, ph)).collect();
    let amplitude = shared_amplitude(&full, period_mm, g);
    lines
        .iter()
        .map(|&(_, w, y, x)| {
            let half = x.len() / 2;
            let first = line_phase(x, w, y, period_mm, |i| i < half);
            let second = line_phase(x, w, y, period_mm, |i| i >= half);
            (0..x.len())
                .map(|i| {
                    let phase = if i < half { second } else { first };
                    let r = y[i] - w[i];
                    let ripple = w[i] * g * amplitude * (2.0 * PI * x[i] / period_mm + phase).sin();
                    r * r - (r - ripple).powi(2)
                })
                .sum::<f64>()
        })
        .sum()
}

/// Least-squares line `y = a + b x` through the points where `keep` holds.
fn line_fit(x: &[f64], y: &[f64], keep: impl Fn(usize) -> bool) -> (f64, f64) {
    let idx: Vec<usize> = (0..x.len()).filter(|&j| keep(j)).collect();
    let n = idx.len().max(1) as f64;
    let (mx, my) = (idx.iter().map(|&j| x[j]).sum::<f64>() / n, idx.iter().map(|&j| y[j]).sum::<f64>() / n);
    let sxx: f64 = idx.iter().map(|&j| (x[j] - mx).powi(2)).sum();
    let sxy: f64 = idx.iter().map(|&j| (x[j] - mx) * (y[j] - my)).sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - b * mx, b)
}

/// Explained sum of squares at each of the first `count` grid frequencies.
fn periodogram(lines: &[(&GearTable, &[f64], &[f64])], count: usize) -> Vec<f64> {
    (0..count)
        .map(|j| {
            lines
                .iter()
                .map(|(table, model, observed)| {
                    let mut m = Moments::default();
                    let base = j * table.samples;
                    for i in 0..table.samples {
                        m.add(model[i], table.sin[base + i], table.cos[base + i], observed[i] - model[i]);
                    }
                    m.solve().2
                })
                .sum()
        })
        .collect()
}

/// `sin` and `cos` of `2πx/P` at the positions, into the buffers.
pub fn basis_into(positions_mm: &[f64], period_mm: f64, sin: &mut Vec<f64>, cos: &mut Vec<f64>) {
    sin.clear();
    cos.clear();
    for x in positions_mm {
        let (s, c) = (2.0 * PI * x / period_mm).sin_cos();
        sin.push(s);
        cos.push(c);
    }
}

/// The ripple of one line on a precomputed basis: its phase, and the sums
/// `(Σ u·r, Σ u²)` of `u = ŵ·sin(2πx/P + φ)` that give the shared amplitude.
pub fn phase_and_moments(sin: &[f64], cos: &[f64], model: &[f64], observed: &[f64]) -> (f64, f64, f64) {
    let mut m = Moments::default();
    for i in 0..sin.len() {
        m.add(model[i], sin[i], cos[i], observed[i] - model[i]);
    }
    let (alpha, beta, _) = m.solve();
    let phase = beta.atan2(alpha);
    let (cp, sp) = (phase.cos(), phase.sin());
    let (mut ur, mut uu) = (0.0, 0.0);
    for i in 0..sin.len() {
        let u = model[i] * (sin[i] * cp + cos[i] * sp);
        ur += u * (observed[i] - model[i]);
        uu += u * u;
    }
    (phase, ur, uu)
}

/// Applies a ripple on a precomputed basis.
pub fn apply_on_basis(sin: &[f64], cos: &[f64], widths: &mut [f64], g: f64, amplitude: f64, phase: f64) {
    let (cp, sp) = (phase.cos(), phase.sin());
    for (i, w) in widths.iter_mut().enumerate() {
        *w *= 1.0 + g * amplitude * (sin[i] * cp + cos[i] * sp);
    }
}

/// One line's ripple phase (rad) with the rest of the model `model` fixed, from the
/// samples where `use_sample` is true.
pub fn line_phase(
    positions_mm: &[f64],
    model: &[f64],
    observed: &[f64],
    period_mm: f64,
    use_sample: impl Fn(usize) -> bool,
) -> f64 {
    let mut m = Moments::default();
    for i in (0..positions_mm.len()).filter(|&i| use_sample(i)) {
        let (s, c) = (2.0 * PI * positions_mm[i] / period_mm).sin_cos();
        m.add(model[i], s, c, observed[i] - model[i]);
    }
    let (alpha, beta, _) = m.solve();
    beta.atan2(alpha)
}

/// One line with its ripple phase: `(positions, model widths, observed, phase)`.
pub type PhasedLine<'a> = (&'a [f64], &'a [f64], &'a [f64], f64);

/// The least-squares amplitude `A ≥ 0` shared by lines with the given phases; `g` is
/// the attenuation.
pub fn shared_amplitude(lines: &[PhasedLine], period_mm: f64, g: f64) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (x, w, y, phase) in lines {
        for i in 0..x.len() {
            let u = w[i] * g * (2.0 * PI * x[i] / period_mm + phase).sin();
            num += u * (y[i] - w[i]);
            den += u * u;
        }
    }
    if den > 0.0 {
        (num / den).max(0.0)
    } else {
        0.0
    }
}

/// Applies a ripple of amplitude `amplitude` and phase `phase` to the model widths.
pub fn apply(positions_mm: &[f64], widths: &mut [f64], period_mm: f64, g: f64, amplitude: f64, phase: f64) {
    for (w, &x) in widths.iter_mut().zip(positions_mm) {
        *w *= ripple_factor(x, period_mm, g, amplitude, phase);
    }
}

/// The ripple's width factor at `x_mm`: `1 + g·A·sin(2πx/P + φ)`.
pub fn ripple_factor(x_mm: f64, period_mm: f64, g: f64, amplitude: f64, phase: f64) -> f64 {
    1.0 + g * amplitude * (2.0 * PI * x_mm / period_mm + phase).sin()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_period_and_the_phase_of_a_clean_ripple() {
        // Two lines with a 7.3 mm ripple of 3 % at different phases: the grid's best
        // period is within one grid step of 7.3 mm, and at the true period the
        // phases (also from half a line) and the shared amplitude are the ripple's exactly.
        let xs: Vec<f64> = (0..1200).map(|i| i as f64 * 0.1).collect();
        let model = vec![0.8; xs.len()];
        let make = |phase: f64| -> Vec<f64> {
            xs.iter().map(|x| 0.8 * (1.0 + 0.03 * (2.0 * PI * x / 7.3 + phase).sin())).collect()
        };
        let (a, b) = (make(0.4), make(2.5));
        let table = GearTable::new(&xs);
        let p = best_period(&[(&table, &model, &a, &xs), (&table, &model, &b, &xs)], 0.5);
        assert!((1.0 / p - 1.0 / 7.3).abs() <= FREQUENCY_STEP_PER_MM, "{p}");
        let (pa, pb) = (line_phase(&xs, &model, &a, 7.3, |_| true), line_phase(&xs, &model, &b, 7.3, |i| i < 600));
        assert!((pa - 0.4).abs() < 1e-9 && (pb - 2.5).abs() < 1e-9, "{pa} {pb}");
        let amp = shared_amplitude(&[(&xs, &model, &a, pa), (&xs, &model, &b, pb)], 7.3, 1.0);
        assert!((amp - 0.03).abs() < 1e-12, "{amp}");
        let mut w = model.clone();
        apply(&xs, &mut w, 7.3, 1.0, amp, pa);
        assert!(w.iter().zip(&a).all(|(p, q)| (p - q).abs() < 1e-12));
        assert!((attenuation(2.0, 0.5) - (PI / 4.0).sin() / (PI / 4.0)).abs() < 1e-15);
    }
}
