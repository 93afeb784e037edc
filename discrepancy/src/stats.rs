//! The statistics of the engine, each chosen for groups that are few and whose
//! samples are correlated within a group:
//!
//! - [`sign_flip_p_value`]: a one-sided sign-flip permutation test of "the per-group
//!   gains are centred at zero" against "they are positive". Exact (all `2^G` sign
//!   patterns) up to [`EXACT_SIGN_FLIP_GROUPS`] groups, Monte Carlo beyond. It assumes
//!   only that, with no effect, each group's gain is as likely positive as negative —
//!   no normality, no independence of samples within a group — and it is exact, so its
//!   smallest p-value is `2^-G`: with too few groups nothing can be named.
//! - [`holm`]: Holm's step-down adjustment, which holds the family-wise error rate at
//!   α for any dependence between the candidates' tests.
//! - [`jackknife_interval`]: delete-one-group jackknife with a Student-t quantile on
//!   `G − 1` degrees of freedom; the replicates are the cross-validation's own fold fits.
//! - [`bootstrap_ratio_interval`]: percentile bootstrap over groups of a pooled RMSE ratio.
//! - [`clopper_pearson`]: exact binomial interval for the power study's rates.
//! - [`ks_uniform`]: Kolmogorov–Smirnov test of uniformity (the tests' own tests).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use statrs::distribution::{Beta, ContinuousCDF, StudentsT};

/// Largest number of groups for which the sign-flip test enumerates every pattern.
pub const EXACT_SIGN_FLIP_GROUPS: usize = 20;

/// Random sign patterns drawn when there are more groups than [`EXACT_SIGN_FLIP_GROUPS`].
pub const MONTE_CARLO_SIGN_FLIPS: usize = 100_000;

/// One-sided sign-flip p-value of the mean of `gains` (H1: mean > 0). Evidence that is
/// not finite (a score that failed) is no evidence: p = 1, as for no groups at all.
pub fn sign_flip_p_value(gains: &[f64], seed: u64) -> f64 {
    let g = gains.len();
    if g == 0 || gains.iter().any(|x| !x.is_finite()) {
        return 1.0;
    }
    let observed: f64 = gains.iter().sum();
    // A pattern counts when its sum is at least the observed one; the tolerance keeps
    // the identity pattern counted whatever the rounding of the sum.
    let tol = 1e-12 * gains.iter().map(|x| x.abs()).sum::<f64>();
    if g <= EXACT_SIGN_FLIP_GROUPS {
        let mut count = 0u64;
        for pattern in 0u64..(1u64 << g) {
            let s: f64 = gains.iter().enumerate().map(|(i, x)| if pattern >> i & 1 == 1 { -x } else { *x }).sum();
            if s >= observed - tol {
                count += 1;
            }
        }
        return count as f64 / (1u64 << g) as f64;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut count = 0usize;
    for _ in 0..MONTE_CARLO_SIGN_FLIPS {
        let s: f64 = gains.iter().map(|x| if rng.random::<bool>() { -x } else { *x }).sum();
        if s >= observed - tol {
            count += 1;
        }
    }
    (1 + count) as f64 / (1 + MONTE_CARLO_SIGN_FLIPS) as f64
}

/// The smallest p-value the sign-flip test can give with `groups` groups.
pub fn sign_flip_floor(groups: usize) -> f64 {
    if groups <= EXACT_SIGN_FLIP_GROUPS {
        0.5f64.powi(groups as i32)
    } else {
        1.0 / (1 + MONTE_CARLO_SIGN_FLIPS) as f64
    }
}

/// Holm step-down adjusted p-values, in the input order.
pub fn holm(p_values: &[f64]) -> Vec<f64> {
    let m = p_values.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| p_values[a].total_cmp(&p_values[b]));
    let mut adjusted = vec![1.0; m];
    let mut running = 0.0f64;
    for (rank, &i) in order.iter().enumerate() {
        running = running.max(((m - rank) as f64 * p_values[i]).min(1.0));
        adjusted[i] = running;
    }
    adjusted
}

/// The `q` quantile of Student's t with `dof` degrees of freedom.
pub fn t_quantile(q: f64, dof: f64) -> f64 {
    StudentsT::new(0.0, 1.0, dof).map_or(f64::NAN, |t| t.inverse_cdf(q))
}

/// Delete-one-group jackknife interval `(lo, hi)` at `level` around `estimate` from the
/// leave-one-group-out replicates: `SE² = (G−1)/G Σ (θ₍₋g₎ − θ̄)²`, half-width
/// `t_{(1+level)/2, G−1} · SE`. NaN when fewer than two replicates are finite.
pub fn jackknife_interval(estimate: f64, replicates: &[f64], level: f64) -> (f64, f64) {
    let finite: Vec<f64> = replicates.iter().copied().filter(|x| x.is_finite()).collect();
    let g = finite.len();
    if g < 2 || !estimate.is_finite() {
        return (f64::NAN, f64::NAN);
    }
    let mean = finite.iter().sum::<f64>() / g as f64;
    let ss: f64 = finite.iter().map(|x| (x - mean).powi(2)).sum();
    let se = ((g - 1) as f64 / g as f64 * ss).sqrt();
    let half = t_quantile(0.5 + level / 2.0, (g - 1) as f64) * se;
    (estimate - half, estimate + half)
}

/// Percentile bootstrap over groups of `1 − sqrt(Σ after / Σ before)` (the relative
/// fall of a pooled RMSE, as a fraction) at `level`: groups are drawn with replacement
/// `draws` times.
pub fn bootstrap_ratio_interval(before: &[f64], after: &[f64], draws: usize, level: f64, seed: u64) -> (f64, f64) {
    let g = before.len();
    if g == 0 || draws == 0 || after.len() != g {
        return (f64::NAN, f64::NAN);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut stats: Vec<f64> = (0..draws)
        .map(|_| {
            let (mut b, mut a) = (0.0, 0.0);
            for _ in 0..g {
                let k = rng.random_range(0..g);
                b += before[k];
                a += after[k];
            }
            if b > 0.0 {
                1.0 - (a / b).sqrt()
            } else {
                f64::NAN
            }
        })
        .filter(|x| x.is_finite())
        .collect();
    if stats.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    stats.sort_by(f64::total_cmp);
    (quantile_sorted(&stats, (1.0 - level) / 2.0), quantile_sorted(&stats, (1.0 + level) / 2.0))
}

/// A seed for the stream `(a, b)` derived from `seed` (SplitMix64's finaliser), so that
/// parallel work draws the same numbers whatever the order it runs in.
pub fn mix_seed(seed: u64, a: u64, b: u64) -> u64 {
    let mut z = seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Linear-interpolation quantile of sorted values.
pub fn quantile_sorted(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let pos = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (i, f) = (pos.floor() as usize, pos.fract());
    if i + 1 < sorted.len() {
        sorted[i] * (1.0 - f) + sorted[i + 1] * f
    } else {
        sorted[i]
    }
}

/// Clopper–Pearson interval `(lo, hi)` at `level` for `successes` out of `trials`.
pub fn clopper_pearson(successes: usize, trials: usize, level: f64) -> (f64, f64) {
    if trials == 0 {
        return (f64::NAN, f64::NAN);
    }
    let (k, n) = (successes as f64, trials as f64);
    let tail = (1.0 - level) / 2.0;
    let lo = if successes == 0 { 0.0 } else { Beta::new(k, n - k + 1.0).map_or(f64::NAN, |b| b.inverse_cdf(tail)) };
    let hi = if successes == trials {
        1.0
    } else {
        Beta::new(k + 1.0, n - k).map_or(f64::NAN, |b| b.inverse_cdf(1.0 - tail))
    };
    (lo, hi)
}

/// Kolmogorov–Smirnov test of `values` against the uniform distribution on [0, 1]:
/// `(D, p)` with the asymptotic Kolmogorov distribution (Stephens' small-sample
/// correction `√n + 0.12 + 0.11/√n`).
pub fn ks_uniform(values: &[f64]) -> (f64, f64) {
    let mut v: Vec<f64> = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len() as f64;
    let d = v.iter().enumerate().map(|(i, &x)| ((i + 1) as f64 / n - x).max(x - i as f64 / n)).fold(0.0f64, f64::max);
    let lambda = (n.sqrt() + 0.12 + 0.11 / n.sqrt()) * d;
    let p: f64 = (1..=100).map(|k| 2.0 * (-1f64).powi(k - 1) * (-2.0 * (k as f64 * lambda).powi(2)).exp()).sum();
    (d, p.clamp(0.0, 1.0))
}

/// Mean with a 95 % Student-t interval (NaN bounds for fewer than two values).
pub fn t_interval(values: &[f64]) -> (f64, f64, f64) {
    let n = values.len() as f64;
    if values.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mean = values.iter().sum::<f64>() / n;
    if values.len() < 2 {
        return (mean, f64::NAN, f64::NAN);
    }
    let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    let half = t_quantile(0.975, n - 1.0) * sd / n.sqrt();
    (mean, mean - half, mean + half)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn evidence_that_is_not_finite_gives_no_significance() {
        // Every pattern's sum would be NaN and none would count: p = 0 without the guard.
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert_eq!(sign_flip_p_value(&[1.0, 2.0, bad, 1.5], 1), 1.0);
        }
        assert_eq!(sign_flip_p_value(&[1.0, 2.0, 0.5, 1.5], 1), 1.0 / 16.0);
    }

    #[test]
    fn sign_flip_exact_counts() {
        // All of 4 gains positive: only the identity pattern reaches the sum → 1/16.
        assert_eq!(sign_flip_p_value(&[1.0, 2.0, 3.0, 4.0], 0), 1.0 / 16.0);
        // Gains (4, −1): patterns with sum ≥ 3 are (+4, −1) and (+4, +1) → 2/4.
        assert_eq!(sign_flip_p_value(&[4.0, -1.0], 0), 0.5);
        assert_eq!(sign_flip_floor(9), 1.0 / 512.0);
    }

    #[test]
    fn sign_flip_p_values_are_uniform_under_symmetric_null() {
        // Gains symmetric about zero: P(p ≤ u) = u up to the 2^-G grid, so a KS test
        // over 2000 draws of 14 groups (grid 1/16384) must not reject at 1 %.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let p: Vec<f64> = (0..2000)
            .map(|d| {
                let gains: Vec<f64> = (0..14).map(|_| rng.random::<f64>() - 0.5).collect();
                sign_flip_p_value(&gains, d)
            })
            .collect();
        let (d, ks_p) = ks_uniform(&p);
        assert!(ks_p > 0.01, "KS D = {d}, p = {ks_p}");
    }

    #[test]
    fn holm_matches_hand_computation() {
        // Sorted 0.01, 0.02, 0.04 → 3·0.01, max(0.03, 2·0.02), max(0.04, 0.04).
        let adj = holm(&[0.04, 0.01, 0.02]);
        assert!((adj[1] - 0.03).abs() < 1e-15 && (adj[2] - 0.04).abs() < 1e-15 && (adj[0] - 0.04).abs() < 1e-15);
    }

    #[test]
    fn clopper_pearson_known_values() {
        // 0 of 10: upper bound 1 − 0.025^(1/10) = 0.3085; 10 of 10: lower 0.025^(1/10).
        let (lo, hi) = clopper_pearson(0, 10, 0.95);
        assert!(lo == 0.0 && (hi - 0.308_50).abs() < 1e-4, "{hi}");
        let (lo, hi) = clopper_pearson(10, 10, 0.95);
        assert!((lo - 0.691_50).abs() < 1e-4 && hi == 1.0);
    }

    #[test]
    fn jackknife_of_a_mean_is_the_t_interval() {
        // For the mean, leave-one-out means give SE = s/√G exactly.
        let x = [1.0, 2.0, 4.0, 7.0];
        let mean = 3.5;
        let loo: Vec<f64> = (0..4).map(|k| (x.iter().sum::<f64>() - x[k]) / 3.0).collect();
        let (lo, hi) = jackknife_interval(mean, &loo, 0.95);
        let s = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / 3.0).sqrt();
        let half = t_quantile(0.975, 3.0) * s / 2.0;
        assert!((lo - (mean - half)).abs() < 1e-12 && (hi - (mean + half)).abs() < 1e-12);
    }

    #[test]
    fn ks_rejects_a_shifted_sample() {
        let shifted: Vec<f64> = (0..500).map(|i| (i as f64 / 500.0).powi(2)).collect();
        assert!(ks_uniform(&shifted).1 < 1e-6);
        let even: Vec<f64> = (0..500).map(|i| (i as f64 + 0.5) / 500.0).collect();
        assert!(ks_uniform(&even).1 > 0.99);
    }

    #[test]
    fn t_intervals_are_the_textbook_ones() {
        // Mean 2, sd 1, n = 4: half width t(0.975, 3)·1/2 = 3.1824/2.
        let values = [1.0, 2.0, 3.0, 2.0];
        let sd = (2.0f64 / 3.0).sqrt();
        let (m, lo, hi) = t_interval(&values);
        assert!((m - 2.0).abs() < 1e-12);
        assert!((hi - m - 3.182_446 * sd / 2.0).abs() < 1e-5 && (m - lo - (hi - m)).abs() < 1e-12);
        assert!(t_interval(&[1.0]).1.is_nan());
    }
}
