//! Step 1, **show**: held-out residuals binned against each candidate variable.
//!
//! Samples within a group are correlated (a printed line's widths along it), so a
//! bin's interval is cluster-robust over groups: with `S_g` the sum and `n_g` the
//! count of group `g`'s residuals in the bin, `m = ΣS_g/Σn_g` and
//! `Var(m) = G/(G−1) · Σ_g (S_g − n_g m)² / (Σ n_g)²`, with a t quantile on `G − 1`
//! degrees of freedom (no interval with fewer than two groups in the bin). The
//! structure a variable carries is the share of the residual sum of squares that its
//! bin means explain, `Σ_b n_b m_b² / Σ r²` (0: none, 1: the residual is a function
//! of the binned variable).

use crate::model::{Model, VariableKind};
use crate::stats::{quantile_sorted, t_quantile};

/// One bin of one variable.
#[derive(Debug, Clone, PartialEq)]
pub struct BinStat {
    /// Bin index, from 0.
    pub bin: usize,
    /// Lower edge (category code for a categorical variable).
    pub lo: f64,
    /// Upper edge.
    pub hi: f64,
    /// Mean residual in the bin.
    pub mean: f64,
    /// Lower end of its 95 % interval.
    pub ci_lo: f64,
    /// Upper end.
    pub ci_hi: f64,
    /// Samples in the bin.
    pub n: usize,
    /// Groups with samples in the bin.
    pub groups: usize,
}

/// The residual structure against one variable.
#[derive(Debug, Clone, PartialEq)]
pub struct VariableStructure {
    /// Index into [`Model::variables`].
    pub variable: usize,
    /// Its bins.
    pub bins: Vec<BinStat>,
    /// Share of the residual sum of squares explained by the bin means.
    pub structure: f64,
}

/// The residual structure of `residuals` (one vector per group, as the groups'
/// samples) against every variable of `model`, in at most `bins` bins each.
pub fn residual_structure<M: Model>(
    model: &M,
    groups: &[M::Group],
    residuals: &[Vec<f64>],
    bins: usize,
    level: f64,
) -> Vec<VariableStructure> {
    (0..model.variables().len())
        .map(|v| {
            let values: Vec<Vec<f64>> = groups.iter().map(|g| model.variable_values(g, v)).collect();
            let edges = bin_edges(model.variables()[v].kind, &values, bins);
            structure_of(v, &edges, &values, residuals, level)
        })
        .collect()
}

/// Bin edges `(lo, hi)`: one per category, one per distinct value when there are at
/// most `bins` of them, else equal-count bins of the pooled values.
fn bin_edges(kind: VariableKind, values: &[Vec<f64>], bins: usize) -> Vec<(f64, f64)> {
    if let VariableKind::Categorical(labels) = kind {
        return (0..labels.len()).map(|c| (c as f64, c as f64)).collect();
    }
    let mut pooled: Vec<f64> = values.iter().flatten().copied().filter(|x| x.is_finite()).collect();
    pooled.sort_by(f64::total_cmp);
    let mut distinct = pooled.clone();
    distinct.dedup();
    if distinct.len() <= bins.max(1) {
        return distinct.iter().map(|&x| (x, x)).collect();
    }
    let mut cuts: Vec<f64> = (0..=bins).map(|k| quantile_sorted(&pooled, k as f64 / bins as f64)).collect();
    cuts.dedup();
    cuts.windows(2).map(|w| (w[0], w[1])).collect()
}

/// The bin of `x`: exact match for point bins, else `[lo, hi)` with the last closed.
fn bin_of(edges: &[(f64, f64)], x: f64) -> Option<usize> {
    if !x.is_finite() || edges.is_empty() {
        return None;
    }
    if edges[0].0 == edges[0].1 {
        return edges.iter().position(|e| e.0 == x);
    }
    let last = edges.len() - 1;
    if x < edges[0].0 || x > edges[last].1 {
        return None;
    }
    Some(edges.partition_point(|e| e.1 <= x).min(last))
}

fn structure_of(
    variable: usize,
    edges: &[(f64, f64)],
    values: &[Vec<f64>],
    residuals: &[Vec<f64>],
    level: f64,
) -> VariableStructure {
    let nb = edges.len();
    // Per bin and group: (count, sum).
    let mut acc = vec![vec![(0usize, 0.0f64); residuals.len()]; nb];
    let mut total_ss = 0.0;
    for (g, (vals, res)) in values.iter().zip(residuals).enumerate() {
        for (&x, &r) in vals.iter().zip(res) {
            if let (Some(b), true) = (bin_of(edges, x), r.is_finite()) {
                acc[b][g].0 += 1;
                acc[b][g].1 += r;
                total_ss += r * r;
            }
        }
    }
    let bins: Vec<BinStat> =
        acc.iter().enumerate().map(|(b, per_group)| bin_stat(b, edges[b], per_group, level)).collect();
    let explained: f64 = bins.iter().filter(|b| b.n > 0).map(|b| b.n as f64 * b.mean * b.mean).sum();
    let structure = if total_ss > 0.0 { explained / total_ss } else { 0.0 };
    VariableStructure { variable, bins, structure }
}

fn bin_stat(bin: usize, (lo, hi): (f64, f64), per_group: &[(usize, f64)], level: f64) -> BinStat {
    let n: usize = per_group.iter().map(|p| p.0).sum();
    let groups = per_group.iter().filter(|p| p.0 > 0).count();
    if n == 0 {
        return BinStat { bin, lo, hi, mean: f64::NAN, ci_lo: f64::NAN, ci_hi: f64::NAN, n, groups };
    }
    let mean = per_group.iter().map(|p| p.1).sum::<f64>() / n as f64;
    let (ci_lo, ci_hi) = if groups >= 2 {
        let ss: f64 = per_group.iter().filter(|p| p.0 > 0).map(|p| (p.1 - p.0 as f64 * mean).powi(2)).sum();
        let var = groups as f64 / (groups - 1) as f64 * ss / (n as f64).powi(2);
        let half = t_quantile(0.5 + level / 2.0, (groups - 1) as f64) * var.sqrt();
        (mean - half, mean + half)
    } else {
        (f64::NAN, f64::NAN)
    };
    BinStat { bin, lo, hi, mean, ci_lo, ci_hi, n, groups }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn few_values_get_one_bin_each_and_quantile_bins_hold_all() {
        let values = vec![vec![50.0, 50.0], vec![100.0, 150.0]];
        assert_eq!(
            bin_edges(VariableKind::Continuous, &values, 12),
            vec![(50.0, 50.0), (100.0, 100.0), (150.0, 150.0)]
        );
        let many = vec![(0..100).map(f64::from).collect::<Vec<_>>()];
        let edges = bin_edges(VariableKind::Continuous, &many, 4);
        assert_eq!(edges.len(), 4);
        let counts: Vec<usize> =
            (0..4).map(|b| many[0].iter().filter(|&&x| bin_of(&edges, x) == Some(b)).count()).collect();
        assert_eq!(counts.iter().sum::<usize>(), 100);
        assert!(counts.iter().all(|&c| (24..=26).contains(&c)), "{counts:?}");
    }

    #[test]
    fn cluster_interval_and_structure_share() {
        // Residual = +1 in bin 0 and −1 in bin 1 for both groups: the bin means explain
        // all of Σr² (structure 1), and the groups agree, so the interval has width 0.
        let edges = vec![(0.0, 0.0), (1.0, 1.0)];
        let values = vec![vec![0.0, 1.0, 0.0], vec![1.0, 0.0]];
        let residuals = vec![vec![1.0, -1.0, 1.0], vec![-1.0, 1.0]];
        let s = structure_of(0, &edges, &values, &residuals, 0.95);
        assert!((s.structure - 1.0).abs() < 1e-15);
        assert_eq!((s.bins[0].n, s.bins[0].groups), (3, 2));
        assert!((s.bins[0].ci_lo - 1.0).abs() < 1e-12 && (s.bins[0].ci_hi - 1.0).abs() < 1e-12);
    }
}
