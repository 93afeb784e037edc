//! Phase p1 of eq. 3 (paper 000, step 3 of the fitting procedure): `w = 1/(α1 v + α2)`
//! on the pooled samples `t ≤ bp1` of a training set, fitted by linear least squares on
//! `1/w = α1 v + α2` and refined by Gauss-Newton on the widths (step halving, keeping
//! `α1 v + α2 > 0` on the data).
//!
//! It runs once per training set and grid pair, and its cost is divisions. A
//! Gauss-Newton step takes three per sample, so it first computes its per-sample terms
//! in a loop of their own, which the compiler vectorises (the terms are independent of
//! each other), and then sums them in sample order: the same terms, the same sums, as
//! one loop doing both. (The SSE takes one division per sample and one running sum,
//! whose additions are the slower chain: it stays one loop.) The reciprocal widths of
//! the linearised fit depend on the line only and come precomputed.

/// The pooled p1 samples of a training set: speeds, widths and `1/w`, with room for the
/// per-sample terms of a Gauss-Newton step.
#[derive(Debug, Default)]
pub(crate) struct P1Samples {
    v: Vec<f64>,
    w: Vec<f64>,
    inverse_w: Vec<f64>,
    terms: [Vec<f64>; 3],
}

impl P1Samples {
    pub(crate) fn clear(&mut self) {
        self.v.clear();
        self.w.clear();
        self.inverse_w.clear();
    }

    /// Appends samples: speeds `v`, widths `w` and their reciprocals `inverse_w`.
    pub(crate) fn extend(&mut self, v: &[f64], w: &[f64], inverse_w: &[f64]) {
        self.v.extend_from_slice(v);
        self.w.extend_from_slice(w);
        self.inverse_w.extend_from_slice(inverse_w);
    }

    /// Samples from `(v, w)` pairs.
    #[cfg(test)]
    pub(crate) fn from_pairs(pairs: &[(f64, f64)]) -> Self {
        let mut s = Self::default();
        for &(v, w) in pairs {
            s.extend(&[v], &[w], &[1.0 / w]);
        }
        s
    }

    fn len(&self) -> usize {
        self.v.len()
    }

    /// `Σ (w − 1/(α1 v + α2))²` in sample order. One division per sample and one
    /// running sum, whose additions are the slower chain: one loop.
    fn sse(&self, a: (f64, f64)) -> f64 {
        self.v.iter().zip(&self.w).map(|(&v, &w)| (w - 1.0 / (a.0 * v + a.1)).powi(2)).sum()
    }
}

/// Fits `w = 1/(α1 v + α2)` to the samples: linearised least squares on `1/w`, then
/// Gauss-Newton on the widths. Returns `((α1, α2), SSE)`, or `None` with fewer than
/// three samples.
pub(crate) fn fit_p1(samples: &mut P1Samples) -> Option<((f64, f64), f64)> {
    if samples.len() < 3 {
        return None;
    }
    let (v_min, v_max) =
        samples.v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let valid = |a: (f64, f64)| a.0 * v_min + a.1 > 0.0 && a.0 * v_max + a.1 > 0.0;
    let mut alpha = linearised_p1(samples).filter(|&a| valid(a)).unwrap_or_else(|| {
        let mean = samples.w.iter().sum::<f64>() / samples.len() as f64;
        (0.0, 1.0 / mean)
    });
    let mut current = samples.sse(alpha);
    for _ in 0..50 {
        let Some(step) = gauss_newton_step(samples, alpha) else {
            break;
        };
        let mut scale = 1.0;
        let mut improved = false;
        for _ in 0..30 {
            let cand = (alpha.0 + scale * step.0, alpha.1 + scale * step.1);
            if valid(cand) {
                let s = samples.sse(cand);
                if s <= current {
                    improved = current - s > 1e-15 * current.max(1e-300);
                    alpha = cand;
                    current = s;
                    break;
                }
            }
            scale *= 0.5;
        }
        if !improved {
            break;
        }
    }
    Some((alpha, current))
}

fn linearised_p1(samples: &P1Samples) -> Option<(f64, f64)> {
    let mut m = super::Moments::default();
    for (&v, &inverse_w) in samples.v.iter().zip(&samples.inverse_w) {
        m.add(v, inverse_w);
    }
    let det = m.n * m.sxx - m.sx * m.sx;
    if det.abs() <= 1e-12 * m.n * m.sxx {
        return None;
    }
    let a1 = (m.n * m.sxy - m.sx * m.sy) / det;
    Some((a1, (m.sy - a1 * m.sx) / m.n))
}

fn gauss_newton_step(samples: &mut P1Samples, a: (f64, f64)) -> Option<(f64, f64)> {
    // r = w − 1/d, d = α1 v + α2; ∂r/∂α = (v, 1)/d².
    let n = samples.len();
    let [r, d1, d2] = &mut samples.terms;
    for terms in [&mut *r, &mut *d1, &mut *d2] {
        terms.resize(n, 0.0);
    }
    let per_sample = r.iter_mut().zip(d1.iter_mut()).zip(d2.iter_mut()).zip(&samples.v).zip(&samples.w);
    for ((((r, d1), d2), &v), &w) in per_sample {
        let d = a.0 * v + a.1;
        *r = w - 1.0 / d;
        (*d1, *d2) = (v / (d * d), 1.0 / (d * d));
    }
    let (mut j11, mut j12, mut j22, mut g1, mut g2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for ((&r, &d1), &d2) in r.iter().zip(d1.iter()).zip(d2.iter()) {
        j11 += d1 * d1;
        j12 += d1 * d2;
        j22 += d2 * d2;
        g1 += d1 * r;
        g2 += d2 * r;
    }
    let x = super::spd_solve(&[[j11, j12], [j12, j22]], &[-g1, -g2])?;
    Some((x[0], x[1]))
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;

    /// The p1 fit as it was, one loop per pass over `(v, w)` pairs dividing as it sums:
    /// the definition `fit_p1` must match bit for bit.
    fn reference(samples: &[(f64, f64)]) -> Option<((f64, f64), f64)> {
        if samples.len() < 3 {
            return None;
        }
        let (v_min, v_max) =
            samples.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(v, _)| (lo.min(v), hi.max(v)));
        let valid = |a: (f64, f64)| a.0 * v_min + a.1 > 0.0 && a.0 * v_max + a.1 > 0.0;
        let sse = |a: (f64, f64)| -> f64 { samples.iter().map(|&(v, w)| (w - 1.0 / (a.0 * v + a.1)).powi(2)).sum() };
        let mut alpha = reference_linearised(samples).filter(|&a| valid(a)).unwrap_or_else(|| {
            let mean = samples.iter().map(|s| s.1).sum::<f64>() / samples.len() as f64;
            (0.0, 1.0 / mean)
        });
        let mut current = sse(alpha);
        for _ in 0..50 {
            let Some(step) = reference_step(samples, alpha) else {
                break;
            };
            let mut scale = 1.0;
            let mut improved = false;
            for _ in 0..30 {
                let cand = (alpha.0 + scale * step.0, alpha.1 + scale * step.1);
                if valid(cand) {
                    let s = sse(cand);
                    if s <= current {
                        improved = current - s > 1e-15 * current.max(1e-300);
                        alpha = cand;
                        current = s;
                        break;
                    }
                }
                scale *= 0.5;
            }
            if !improved {
                break;
            }
        }
        Some((alpha, current))
    }

    fn reference_linearised(samples: &[(f64, f64)]) -> Option<(f64, f64)> {
        let mut m = super::super::Moments::default();
        for &(v, w) in samples {
            m.add(v, 1.0 / w);
        }
        let det = m.n * m.sxx - m.sx * m.sx;
        if det.abs() <= 1e-12 * m.n * m.sxx {
            return None;
        }
        let a1 = (m.n * m.sxy - m.sx * m.sy) / det;
        Some((a1, (m.sy - a1 * m.sx) / m.n))
    }

    fn reference_step(samples: &[(f64, f64)], a: (f64, f64)) -> Option<(f64, f64)> {
        // r = w − 1/d, d = α1 v + α2; ∂r/∂α = (v, 1)/d².
        let (mut j11, mut j12, mut j22, mut g1, mut g2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(v, w) in samples {
            let d = a.0 * v + a.1;
            let r = w - 1.0 / d;
            let (d1, d2) = (v / (d * d), 1.0 / (d * d));
            j11 += d1 * d1;
            j12 += d1 * d2;
            j22 += d2 * d2;
            g1 += d1 * r;
            g2 += d2 * r;
        }
        let x = super::super::spd_solve(&[[j11, j12], [j12, j22]], &[-g1, -g2])?;
        Some((x[0], x[1]))
    }

    #[test]
    fn split_passes_equal_the_one_loop_fit_bit_for_bit() {
        // Pooled p1 samples like a training set's (speeds rising from rest, widths of a
        // blob narrowing with speed, noise), from 2 to 400 samples, and a few with a
        // width law the linearised fit cannot start from.
        let mut rng = ChaCha8Rng::seed_from_u64(2021);
        for case in 0..300 {
            let n = rng.random_range(2..400);
            let (a1, a2) = (rng.random_range(0.005..0.05), rng.random_range(0.8..1.5));
            let pairs: Vec<(f64, f64)> = (0..n)
                .map(|i| {
                    let v = 1.0 + 60.0 * i as f64 / n as f64 + rng.random_range(0.0..0.5);
                    let noise =
                        if case % 10 == 0 { rng.random_range(-0.5..0.5) } else { rng.random_range(-0.02..0.02) };
                    (v, 1.0 / (a1 * v + a2) + noise)
                })
                .collect();
            let bits = |r: Option<((f64, f64), f64)>| r.map(|((a, b), s)| (a.to_bits(), b.to_bits(), s.to_bits()));
            assert_eq!(bits(fit_p1(&mut P1Samples::from_pairs(&pairs))), bits(reference(&pairs)), "case {case}");
        }
    }
}
