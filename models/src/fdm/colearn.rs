//! Transfer among several printers: a negative-transfer guard and co-learning from
//! more than one source, over any set of (sources → target) tasks. Built on paper 000's
//! MAP transfer (Ren et al. 2021, Sec. II-B, Algorithm 1, eqs 4-6) and on the held-out
//! table of [`super::transfer_cv`]: every training subset of the target's lines is fitted
//! once under every prior configuration, so every method here is a rule that *reads*
//! that table, and the methods are compared on the same fits. Where those fits take
//! `(r_a, r_F)` is the transfer settings' [`PriorKinematics`](super::transfer::PriorKinematics):
//! the guarantees below are tested under both rules.
//!
//! # Methods
//! - `single`, `transfer_zero_mean`, `transfer_source_mean`: as in
//!   [`super::transfer_cv`] (the paper's prior and ours), one source.
//! - `guarded` (one source): transfer only where the target's own data do not argue
//!   against it.
//!   1. **Conflict check.** Each target training line's single-line fit gives
//!      `θ_k = (β, γ, c, ρ)`, the same quantity as Algorithm 1's per-line source
//!      parameters. If the target printer were like the source, the mean `θ̄_T` of its
//!      `n` lines would differ from the source mean `θ̄_S` (over `K` lines) only by
//!      sampling: `T² = (θ̄_T − θ̄_S)ᵀ Σ̂_S⁻¹ (θ̄_T − θ̄_S) / (1/n + 1/K)` and
//!      `T²·(K − p)/(p·(K − 1)) ~ F(p, K − p)` (Hotelling, covariance from the source's
//!      `K − 1` degrees of freedom; `p` = the parameters under the prior; approximate, as
//!      per-line parameters are not exactly Gaussian and one outlying source line widens
//!      `Σ̂_S`, which makes the check more permissive, not less). A source whose
//!      `F` statistic exceeds its 95 % quantile is in conflict and is not used. A source
//!      with `K ≤ p` lines cannot be checked and is not used. The check is weak with
//!      few target lines: on virtual printers (the test with other families) it passes
//!      a printer whose nozzle is 1.6 times wider from two target lines, because
//!      single-line parameters scatter widely, and the guard then transfers from it
//!      and loses to single-printer learning, within its interval only. The check
//!      stands at every `n`: dropping it once the target has five lines (five folds
//!      for point 2) let the shipped spec's slower-melting Taz 6 learn from the Taz 6,
//!      but made virtual targets of other families worse than single-printer learning
//!      beyond their interval (the test with nine-line virtual targets).
//!   2. **Amount.** With two or more target lines, inner leave-one-out over the
//!      candidates "no transfer" and the source-centred prior at every grid `λ`
//!      (smallest mean held-out RMSE; ties go to "no transfer", which comes first).
//!   3. **One line: no transfer.** With one target line there is nothing on the target
//!      to validate a transfer on, and the source-simulation `λ` that
//!      `transfer_source_mean` uses validates only on the source: on the real Taz 6 →
//!      Taz 5 pair it makes a single line worse than learning from the line alone. So
//!      the guard does not transfer with one line, which makes its guarantee exact
//!      there (the same fit as `single`).
//! - `co_learning` (two or more sources): the same rule over several priors. Candidates
//!   are the sources that pass the conflict check and the *pooled* prior, Algorithm 1
//!   over the per-line parameters of all the task's sources together (its covariance
//!   holds the spread between printers as well as within them), if it passes the check
//!   too. With two or more target lines inner leave-one-out chooses among "no
//!   transfer" and every candidate at every grid `λ`; with one line, no transfer (as
//!   the guard). An unrelated printer among the sources
//!   either fails the check or loses the inner cross-validation, so adding it costs
//!   at most the selection noise.
//!
//! - `hindsight_bound` (every task): **not a method** but how far any choice of prior and
//!   `λ` could go. Per training subset, among "no transfer" and every prior of the task
//!   (each source's zero-mean and source-centred prior, and the pool of a task with
//!   several sources) at every grid `λ`, the configuration with the smallest mean RMSE on
//!   that subset's own held-out lines: chosen *with* the lines it is scored on. Every
//!   method above picks one of these configurations per subset from the training lines
//!   alone, so none has a lower mean held-out RMSE on any subset. The summary compares
//!   medians over all rows, which a method could in principle edge above the bound's,
//!   so it bounds the medians in practice, not by proof. Where even it stays below a
//!   wanted improvement, no rule for choosing `λ` among these priors reaches it on these
//!   lines; a different prior family would be needed.
//!
//! # The summary
//! [`summarise`] gives per (task, n, method) the median held-out RMSE over every
//! (subset, held-out line) row, its improvement over `single` in %, and a 95 %
//! percentile interval of the improvement from a paired bootstrap over the target's
//! held-out *lines* (the independent unit: a line is one printed experiment), with the
//! same resampled lines for the method and for `single`.

use std::collections::HashMap;

use discrepancy::stats::{mix_seed, quantile_sorted};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use super::errors::FitError;
use super::hyperparams::PiecewiseValidParams;
use super::line::MeasuredLine;
use super::transfer::{
    all_condition_subsets, estimate_covariance, prior_precision, segment_prior, ConditionSubset, ParameterCovariance,
    PriorMean, SourcePrior, TransferValidParams, TRANSFER_DIM,
};
use super::transfer_cv::{
    chosen_lambda, held_out_table, inner_cv_rmse, mask, subset_index, Configs, HeldOut, MAX_TARGET_LINES,
};

/// Level of the conflict check (its `F` quantile is `1 − CONFLICT_ALPHA`).
pub const CONFLICT_ALPHA: f64 = 0.05;

/// One printer of a transfer study: its lines and its piecewise-model settings.
#[derive(Debug, Clone, Copy)]
pub struct StudyPrinter<'a> {
    /// Printer name (from its dataset).
    pub name: &'a str,
    /// Its measured lines.
    pub lines: &'a [MeasuredLine],
    /// Its model settings (with or without the start blob).
    pub params: &'a PiecewiseValidParams,
}

/// A transfer task: learn `target` from `sources` (indices into the printers).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TransferTask {
    /// Source printers (one or more, none equal to the target).
    pub sources: Vec<usize>,
    /// Target printer.
    pub target: usize,
}

/// The methods compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MatrixMethod {
    /// Target lines only.
    Single,
    /// The paper's zero-mean prior (one source).
    TransferZeroMean,
    /// The source-centred prior (one source).
    TransferSourceMean,
    /// The source-centred prior behind the negative-transfer guard (one source).
    Guarded,
    /// Several sources: guarded choice among the compatible sources and their pool.
    CoLearning,
    /// Not a method: the bound in hindsight (module docs).
    Hindsight,
}

impl MatrixMethod {
    /// Stable snake_case name.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Single => "single",
            Self::TransferZeroMean => "transfer_zero_mean",
            Self::TransferSourceMean => "transfer_source_mean",
            Self::Guarded => "guarded",
            Self::CoLearning => "co_learning",
            Self::Hindsight => "hindsight_bound",
        }
    }

    /// The method called `name` ([`MatrixMethod::name`]).
    pub fn parse(name: &str) -> Option<Self> {
        [
            Self::Single,
            Self::TransferZeroMean,
            Self::TransferSourceMean,
            Self::Guarded,
            Self::CoLearning,
            Self::Hindsight,
        ]
        .into_iter()
        .find(|m| m.name() == name)
    }

    /// The methods of a task with `n_sources` sources, in row order.
    pub fn for_sources(n_sources: usize) -> &'static [MatrixMethod] {
        if n_sources == 1 {
            &[Self::Single, Self::TransferZeroMean, Self::TransferSourceMean, Self::Guarded, Self::Hindsight]
        } else {
            &[Self::Single, Self::CoLearning, Self::Hindsight]
        }
    }
}

/// One prediction: a method fitted on a subset of the target's lines, tested on one of
/// its other lines.
#[derive(Debug, Clone, PartialEq)]
pub struct MatrixRow {
    /// Index of the task.
    pub task: usize,
    /// Number of target training lines.
    pub n_train: usize,
    /// Subset id ([`ConditionSubset::id`]).
    pub subset: String,
    /// Held-out target line.
    pub test_index: usize,
    /// The method.
    pub method: MatrixMethod,
    /// RMSE over the held-out line (mm).
    pub rmse_mm: f64,
    /// The `λ` used (0 without transfer).
    pub lambda: f64,
    /// The prior used: `none`, a source printer's name, or `pooled`.
    pub prior: String,
}

/// Every task's rows (see the module docs). Errors on a task with no source, a source
/// equal to its target, an index out of range, a target with fewer than two or more than
/// [`MAX_TARGET_LINES`] lines, a source with fewer than three lines, or a failed fit.
pub fn transfer_matrix(
    printers: &[StudyPrinter],
    tasks: &[TransferTask],
    transfer: &TransferValidParams,
) -> Result<Vec<MatrixRow>, FitError> {
    check_tasks(printers, tasks)?;
    let sources = source_priors(printers, tasks.iter(), transfer)?;
    let mut targets: Vec<usize> = tasks.iter().map(|t| t.target).collect();
    targets.sort_unstable();
    targets.dedup();
    let mut rows = Vec::new();
    for target in targets {
        rows.extend(target_rows(printers, tasks, target, &sources, transfer)?);
    }
    rows.sort_by_key(|r| r.task);
    Ok(rows)
}

/// The rows of the tasks whose target is printer `target`, as [`transfer_matrix`]
/// gives them: the study split by target printer. The rows of every target,
/// concatenated in target order and stably sorted by task, are [`transfer_matrix`]'s
/// (each target's rows depend only on its own tasks and their sources' priors).
pub fn transfer_matrix_for_target(
    printers: &[StudyPrinter],
    tasks: &[TransferTask],
    transfer: &TransferValidParams,
    target: usize,
) -> Result<Vec<MatrixRow>, FitError> {
    check_tasks(printers, tasks)?;
    let sources = source_priors(printers, tasks.iter().filter(|t| t.target == target), transfer)?;
    let mut rows = target_rows(printers, tasks, target, &sources, transfer)?;
    rows.sort_by_key(|r| r.task);
    Ok(rows)
}

/// The prior of every source printer of `tasks`.
fn source_priors<'t>(
    printers: &[StudyPrinter],
    tasks: impl Iterator<Item = &'t TransferTask>,
    transfer: &TransferValidParams,
) -> Result<HashMap<usize, SourcePrior>, FitError> {
    let mut used: Vec<usize> = tasks.flat_map(|t| t.sources.iter().copied()).collect();
    used.sort_unstable();
    used.dedup();
    let prior = |s: usize| {
        SourcePrior::build(printers[s].lines, printers[s].params, transfer)
            .map_err(|e| FitError::Source { printer: printers[s].name.to_string(), error: Box::new(e) })
    };
    used.iter().map(|&s| Ok((s, prior(s)?))).collect()
}

fn check_tasks(printers: &[StudyPrinter], tasks: &[TransferTask]) -> Result<(), FitError> {
    for (i, t) in tasks.iter().enumerate() {
        let bad = |why: String| Err(FitError::Dimension(format!("transfer task {i}: {why}")));
        if t.sources.is_empty() {
            return bad("no source printer".into());
        }
        if let Some(&s) = t.sources.iter().chain([&t.target]).find(|&&s| s >= printers.len()) {
            return bad(format!("printer index {s} of {}", printers.len()));
        }
        if t.sources.contains(&t.target) {
            return bad(format!("{} is both source and target", printers[t.target].name));
        }
        let n = printers[t.target].lines.len();
        if !(2..=MAX_TARGET_LINES).contains(&n) {
            return bad(format!("target {} has {n} lines (2 to {MAX_TARGET_LINES})", printers[t.target].name));
        }
    }
    Ok(())
}

/// A prior of one target's configurations, with what the rules need to know of it.
struct PriorSlot {
    /// Which source (or the pool of a task's sources) it comes from.
    origin: Origin,
    mean: PriorMean,
    covariance: ParameterCovariance,
}

#[derive(Debug, Clone, PartialEq)]
enum Origin {
    Source(usize),
    Pool(Vec<usize>),
}

/// Rows of every task with this target: one held-out table for all of them.
fn target_rows(
    printers: &[StudyPrinter],
    tasks: &[TransferTask],
    target: usize,
    sources: &HashMap<usize, SourcePrior>,
    transfer: &TransferValidParams,
) -> Result<Vec<MatrixRow>, FitError> {
    let mine: Vec<(usize, &TransferTask)> = tasks.iter().enumerate().filter(|(_, t)| t.target == target).collect();
    let slots = prior_slots(&mine, sources)?;
    let priors = slots.iter().map(|s| segment_prior(&s.covariance, s.mean, transfer)).collect::<Result<Vec<_>, _>>()?;
    let lambdas = &transfer.get().lambda_grid;
    let configs = Configs::new(&priors, lambdas);
    let tp = printers[target];
    let subsets = all_condition_subsets(tp.lines.len());
    let table = held_out_table(tp.lines, tp.params, &subsets, &configs, transfer.get().kinematics)?;
    let study = TargetStudy::new(&subsets, &configs, &table, &slots, sources, transfer)?;
    let mut rows = Vec::new();
    for &(task, t) in &mine {
        for (s, sub) in subsets.iter().enumerate() {
            for &method in MatrixMethod::for_sources(t.sources.len()) {
                let choice = study.choose(sub, t, method)?;
                for k in (0..tp.lines.len()).filter(|k| !sub.indices.contains(k)) {
                    rows.push(MatrixRow {
                        task,
                        n_train: sub.indices.len(),
                        subset: sub.id.clone(),
                        test_index: k,
                        method,
                        rmse_mm: table.at(s, choice.config, k),
                        lambda: configs.lambda(choice.config),
                        prior: choice.prior_name(printers),
                    });
                }
            }
        }
    }
    Ok(rows)
}

/// Per source: zero-mean and source-mean priors; per task with several sources: the pool.
fn prior_slots(
    mine: &[(usize, &TransferTask)],
    sources: &HashMap<usize, SourcePrior>,
) -> Result<Vec<PriorSlot>, FitError> {
    let mut ids: Vec<usize> = mine.iter().flat_map(|(_, t)| t.sources.iter().copied()).collect();
    ids.sort_unstable();
    ids.dedup();
    let mut slots = Vec::new();
    for s in ids {
        for mean in [PriorMean::Zero, PriorMean::SourceMean] {
            slots.push(PriorSlot { origin: Origin::Source(s), mean, covariance: sources[&s].covariance.clone() });
        }
    }
    for (_, t) in mine.iter().filter(|(_, t)| t.sources.len() > 1) {
        let mut pool = t.sources.clone();
        pool.sort_unstable();
        if slots.iter().any(|s| s.origin == Origin::Pool(pool.clone())) {
            continue;
        }
        let per_line: Vec<[f64; TRANSFER_DIM]> =
            pool.iter().flat_map(|s| sources[s].covariance.per_line.iter().copied()).collect();
        slots.push(PriorSlot {
            origin: Origin::Pool(pool),
            mean: PriorMean::SourceMean,
            covariance: estimate_covariance(&per_line)?,
        });
    }
    Ok(slots)
}

/// A method's choice for one subset: a configuration and the prior it uses.
struct Choice {
    config: usize,
    origin: Option<Origin>,
    mean: PriorMean,
}

impl Choice {
    const NONE: Choice = Choice { config: 0, origin: None, mean: PriorMean::SourceMean };

    fn prior_name(&self, printers: &[StudyPrinter]) -> String {
        match &self.origin {
            None => "none".into(),
            Some(Origin::Source(s)) if self.mean == PriorMean::Zero => format!("{} (zero mean)", printers[*s].name),
            Some(Origin::Source(s)) => printers[*s].name.to_string(),
            Some(Origin::Pool(_)) => "pooled".into(),
        }
    }
}

/// What the rules read for one target: the held-out table, the priors, the single-line
/// parameters of every target line, and each subset's index by line mask.
struct TargetStudy<'a> {
    configs: &'a Configs<'a>,
    table: &'a HeldOut,
    slots: &'a [PriorSlot],
    sources: &'a HashMap<usize, SourcePrior>,
    transfer: &'a TransferValidParams,
    index: HashMap<u64, usize>,
    line_theta: Vec<[f64; TRANSFER_DIM]>,
}

impl<'a> TargetStudy<'a> {
    fn new(
        subsets: &[ConditionSubset],
        configs: &'a Configs<'a>,
        table: &'a HeldOut,
        slots: &'a [PriorSlot],
        sources: &'a HashMap<usize, SourcePrior>,
        transfer: &'a TransferValidParams,
    ) -> Result<Self, FitError> {
        let index = subset_index(subsets);
        let line_theta = (0..table.n_lines)
            .map(|k| {
                let s =
                    index.get(&(1u64 << k)).ok_or_else(|| FitError::Dimension(format!("no subset for line {k}")))?;
                Ok(table.model(*s, 0).coefficients.transfer_vector())
            })
            .collect::<Result<_, FitError>>()?;
        Ok(Self { configs, table, slots, sources, transfer, index, line_theta })
    }

    fn slot(&self, origin: &Origin, mean: PriorMean) -> usize {
        self.slots.iter().position(|s| &s.origin == origin && s.mean == mean).expect("every task's priors are slotted")
    }

    fn choose(&self, sub: &ConditionSubset, task: &TransferTask, method: MatrixMethod) -> Result<Choice, FitError> {
        match method {
            MatrixMethod::Single => Ok(Choice::NONE),
            MatrixMethod::TransferZeroMean | MatrixMethod::TransferSourceMean => {
                let mean =
                    if method == MatrixMethod::TransferZeroMean { PriorMean::Zero } else { PriorMean::SourceMean };
                let origin = Origin::Source(task.sources[0]);
                let slot = self.slot(&origin, mean);
                let source = &self.sources[&task.sources[0]];
                let j = chosen_lambda(sub, mean, slot, self.configs, source, self.table, &self.index)?;
                Ok(Choice { config: self.configs.index(Some(slot), j), origin: Some(origin), mean })
            }
            MatrixMethod::Guarded | MatrixMethod::CoLearning => self.guarded(sub, task, method),
            MatrixMethod::Hindsight => Ok(self.hindsight(sub, task)),
        }
    }

    /// The bound in hindsight (module docs): among "no transfer" and every prior of the
    /// task at every grid `λ`, the configuration with the smallest mean RMSE on the
    /// subset's own held-out lines (the first on a tie, "no transfer" first).
    fn hindsight(&self, sub: &ConditionSubset, task: &TransferTask) -> Choice {
        let s = self.index[&mask(&sub.indices)];
        let held_out: Vec<usize> = (0..self.table.n_lines).filter(|k| !sub.indices.contains(k)).collect();
        let mean_rmse = |config: usize| -> f64 {
            held_out.iter().map(|&k| self.table.at(s, config, k)).sum::<f64>() / held_out.len() as f64
        };
        let mut pool = task.sources.clone();
        pool.sort_unstable();
        let mut best = (mean_rmse(0), Choice::NONE);
        for (slot, prior) in self.slots.iter().enumerate() {
            let of_task = match &prior.origin {
                Origin::Source(src) => task.sources.contains(src),
                Origin::Pool(members) => *members == pool,
            };
            if !of_task {
                continue;
            }
            for j in 0..self.configs.lambdas().len() {
                let config = self.configs.index(Some(slot), j);
                let score = mean_rmse(config);
                if score < best.0 {
                    best = (score, Choice { config, origin: Some(prior.origin.clone()), mean: prior.mean });
                }
            }
        }
        best.1
    }

    /// The guard's rule over the candidates of a task (module docs).
    fn guarded(&self, sub: &ConditionSubset, task: &TransferTask, method: MatrixMethod) -> Result<Choice, FitError> {
        let mut candidates: Vec<(Origin, f64)> = task
            .sources
            .iter()
            .map(|&src| (Origin::Source(src), self.conflict(sub, &self.sources[&src].covariance)))
            .collect();
        if method == MatrixMethod::CoLearning {
            let mut pool = task.sources.clone();
            pool.sort_unstable();
            let slot = self.slot(&Origin::Pool(pool.clone()), PriorMean::SourceMean);
            candidates.push((Origin::Pool(pool), self.conflict(sub, &self.slots[slot].covariance)));
        }
        candidates.retain(|(_, ratio)| *ratio <= 1.0);
        if sub.indices.len() == 1 {
            return Ok(Choice::NONE);
        }
        let mut best = (self.inner_cv(sub, 0), Choice::NONE);
        for (origin, _) in candidates {
            let slot = self.slot(&origin, PriorMean::SourceMean);
            for j in 0..self.configs.lambdas().len() {
                let config = self.configs.index(Some(slot), j);
                let score = self.inner_cv(sub, config);
                if score < best.0 {
                    best = (score, Choice { config, origin: Some(origin.clone()), mean: PriorMean::SourceMean });
                }
            }
        }
        Ok(best.1)
    }

    /// The conflict statistic over its 95 % quantile (≤ 1: compatible; `∞` when the
    /// source has too few lines to check).
    fn conflict(&self, sub: &ConditionSubset, source: &ParameterCovariance) -> f64 {
        let on = &self.transfer.get().prior_on;
        let p = on.iter().filter(|&&b| b).count();
        let k = source.per_line.len();
        if k <= p {
            return f64::INFINITY;
        }
        let Ok(precision) = prior_precision(source, self.transfer) else { return f64::INFINITY };
        let n = sub.indices.len() as f64;
        let mut mean_t = [0.0; TRANSFER_DIM];
        for &i in &sub.indices {
            for (m, t) in mean_t.iter_mut().zip(&self.line_theta[i]) {
                *m += t / n;
            }
        }
        let d: Vec<f64> = (0..TRANSFER_DIM).map(|i| mean_t[i] - source.mean[i]).collect();
        let quad: f64 =
            (0..TRANSFER_DIM).map(|i| (0..TRANSFER_DIM).map(|j| d[i] * precision[i][j] * d[j]).sum::<f64>()).sum();
        let t2 = quad / (1.0 / n + 1.0 / k as f64);
        conflict_ratio(t2, p, k)
    }

    fn inner_cv(&self, sub: &ConditionSubset, config: usize) -> f64 {
        inner_cv_rmse(sub, config, self.table, &self.index)
    }
}

/// Hotelling's `T²` of a target mean against a source of `k` lines with `p` parameters,
/// as a ratio to its `1 − CONFLICT_ALPHA` critical value (`∞` if it cannot be formed).
pub fn conflict_ratio(t2: f64, p: usize, k: usize) -> f64 {
    if k <= p || p == 0 {
        return f64::INFINITY;
    }
    let (p, k) = (p as f64, k as f64);
    let Ok(f) = FisherSnedecor::new(p, k - p) else { return f64::INFINITY };
    let critical = f.inverse_cdf(1.0 - CONFLICT_ALPHA) * p * (k - 1.0) / (k - p);
    t2 / critical
}

/// One line of the summary: a method on a task at one training size.
#[derive(Debug, Clone, PartialEq)]
pub struct MatrixSummary {
    /// Index of the task.
    pub task: usize,
    /// Number of target training lines.
    pub n_train: usize,
    /// The method.
    pub method: MatrixMethod,
    /// Median held-out RMSE over every (subset, held-out line) (mm).
    pub median_rmse_mm: f64,
    /// `100·(single − method)/single` of the medians (%; > 0 is better than single).
    pub improvement_pct: f64,
    /// 95 % bootstrap interval of the improvement (%).
    pub ci_lo_pct: f64,
    /// Upper end of that interval (%).
    pub ci_hi_pct: f64,
    /// Rows behind the median.
    pub rows: usize,
}

/// Per (task, n, method) medians, improvements and bootstrap intervals (module docs);
/// `draws` resamples of the held-out lines from `seed`. Rows come in task, n, method
/// order.
pub fn summarise(rows: &[MatrixRow], draws: usize, seed: u64) -> Vec<MatrixSummary> {
    let mut groups: HashMap<(usize, usize), Vec<&MatrixRow>> = HashMap::new();
    for r in rows {
        groups.entry((r.task, r.n_train)).or_default().push(r);
    }
    let mut keys: Vec<(usize, usize)> = groups.keys().copied().collect();
    keys.sort_unstable();
    keys.par_iter()
        .flat_map_iter(|key| {
            let rng_seed = mix_seed(seed, key.0 as u64, key.1 as u64);
            summarise_group(*key, &groups[key], draws, rng_seed)
        })
        .collect()
}

fn summarise_group(
    (task, n_train): (usize, usize),
    rows: &[&MatrixRow],
    draws: usize,
    seed: u64,
) -> Vec<MatrixSummary> {
    let mut methods: Vec<MatrixMethod> = rows.iter().map(|r| r.method).collect();
    methods.sort_unstable();
    methods.dedup();
    let n_lines = rows.iter().map(|r| r.test_index).max().map_or(0, |m| m + 1);
    let by_method = |m: MatrixMethod| -> Vec<(usize, f64)> {
        rows.iter().filter(|r| r.method == m).map(|r| (r.test_index, r.rmse_mm)).collect()
    };
    let single = by_method(MatrixMethod::Single);
    let ones = vec![1usize; n_lines];
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let tested: Vec<usize> = {
        let mut t: Vec<usize> = single.iter().map(|r| r.0).collect();
        t.sort_unstable();
        t.dedup();
        t
    };
    let weights: Vec<Vec<usize>> = (0..draws)
        .map(|_| {
            let mut w = vec![0usize; n_lines];
            for _ in 0..tested.len() {
                w[tested[rng.random_range(0..tested.len())]] += 1;
            }
            w
        })
        .collect();
    let single = SortedRows::new(&single);
    let base = single.weighted_median(&ones);
    let single_boot: Vec<f64> = weights.iter().map(|w| single.weighted_median(w)).collect();
    methods
        .into_iter()
        .map(|m| {
            let own = SortedRows::new(&by_method(m));
            let median = own.weighted_median(&ones);
            let mut boot: Vec<f64> = weights
                .iter()
                .zip(&single_boot)
                .map(|(w, &single_mm)| improvement_pct(single_mm, own.weighted_median(w)))
                .filter(|v| v.is_finite())
                .collect();
            boot.sort_by(f64::total_cmp);
            MatrixSummary {
                task,
                n_train,
                method: m,
                median_rmse_mm: median,
                improvement_pct: improvement_pct(base, median),
                ci_lo_pct: quantile_sorted(&boot, 0.025),
                ci_hi_pct: quantile_sorted(&boot, 0.975),
                rows: own.rows.len(),
            }
        })
        .collect()
}

/// `100·(single − method)/single` (%).
pub fn improvement_pct(single_mm: f64, method_mm: f64) -> f64 {
    100.0 * (single_mm - method_mm) / single_mm
}

/// The median of the values `(group, value)` with each row repeated `weights[group]`
/// times (the usual median, the mean of the two middle values for an even count; NaN
/// when the total weight is 0).
pub fn weighted_median(values: &[(usize, f64)], weights: &[usize]) -> f64 {
    SortedRows::new(values).weighted_median(weights)
}

/// Rows `(group, value)` sorted by value once, so that the bootstrap's medians under
/// thousands of reweightings each cost one pass and no sort (the median depends only on
/// the multiset of weighted values, so it is that of sorting under each weighting).
struct SortedRows {
    rows: Vec<(usize, f64)>,
}

impl SortedRows {
    fn new(values: &[(usize, f64)]) -> Self {
        let mut rows = values.to_vec();
        rows.sort_by(|a, b| a.1.total_cmp(&b.1));
        Self { rows }
    }

    /// [`weighted_median`] of the rows under `weights` (indexed by group).
    fn weighted_median(&self, weights: &[usize]) -> f64 {
        let total: usize = self.rows.iter().map(|&(g, _)| weights[g]).sum();
        if total == 0 {
            return f64::NAN;
        }
        let (lower, upper) = ((total - 1) / 2, total / 2);
        let (mut seen, mut low) = (0, None);
        for &(g, x) in &self.rows {
            seen += weights[g];
            if low.is_none() && seen > lower {
                low = Some(x);
            }
            if let (Some(low), true) = (low, seen > upper) {
                return 0.5 * (low + x);
            }
        }
        unreachable!("the running weight reaches the total")
    }
}

/// Every ordered pair `(source → target)` of `n` printers, then, when `co_learning` and
/// `n ≥ 3`, every printer as target of all the others.
pub fn default_tasks(n: usize, co_learning: bool) -> Vec<TransferTask> {
    let mut tasks: Vec<TransferTask> = (0..n)
        .flat_map(|t| (0..n).filter(move |&s| s != t).map(move |s| TransferTask { sources: vec![s], target: t }))
        .collect();
    if co_learning && n >= 3 {
        tasks.extend((0..n).map(|t| TransferTask { sources: (0..n).filter(|&s| s != t).collect(), target: t }));
    }
    tasks
}

#[cfg(test)]
mod tests {
    use super::super::discrepancy::forward::Theta;
    use super::super::hyperparams::PiecewiseParams;
    use super::super::kinematics::LineKinematics;
    use super::super::line::other_family_widths;
    use super::super::printer::{print_line, Effects, PrinterProfile};
    use super::super::synthetic::TABLE_I;
    use super::super::test_support::real_lines;
    use super::super::transfer::{PriorKinematics, TransferParams};
    use super::*;

    #[test]
    fn weighted_median_is_the_median_of_the_repeated_rows() {
        let v = [(0, 3.0), (1, 1.0), (2, 2.0), (2, 10.0)];
        assert_eq!(weighted_median(&v, &[1, 1, 1]), 2.5, "1, 2, 3, 10");
        assert_eq!(weighted_median(&v, &[0, 1, 1]), 2.0, "1, 2, 10");
        assert_eq!(weighted_median(&v, &[3, 0, 0]), 3.0);
        assert_eq!(weighted_median(&v, &[0, 2, 1]), 1.5, "1, 1, 2, 10");
        assert!(weighted_median(&v, &[0, 0, 0]).is_nan());
    }

    #[test]
    fn weighted_median_equals_sorting_the_repeated_rows_under_random_weights() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let groups = rng.random_range(1..6);
            let values: Vec<(usize, f64)> = (0..rng.random_range(1..12))
                .map(|_| (rng.random_range(0..groups), rng.random_range(0..5) as f64))
                .collect();
            let weights: Vec<usize> = (0..groups).map(|_| rng.random_range(0..4)).collect();
            let mut repeated: Vec<f64> = values.iter().flat_map(|&(g, x)| std::iter::repeat_n(x, weights[g])).collect();
            repeated.sort_by(f64::total_cmp);
            let expected = match repeated.len() {
                0 => f64::NAN,
                n => 0.5 * (repeated[(n - 1) / 2] + repeated[n / 2]),
            };
            let got = weighted_median(&values, &weights);
            assert!(got == expected || (got.is_nan() && expected.is_nan()), "{values:?} {weights:?}");
        }
    }

    #[test]
    fn conflict_ratio_is_hotelling_against_its_f_quantile() {
        // F(4, 5) at 0.95 is 5.1922; T² critical = 5.1922 · 4 · 8 / 5 = 33.23 for K = 9.
        let critical = 5.192_167_7 * 4.0 * 8.0 / 5.0;
        assert!((conflict_ratio(critical, 4, 9) - 1.0).abs() < 1e-6);
        assert!(conflict_ratio(0.5 * critical, 4, 9) < 1.0);
        assert_eq!(conflict_ratio(1.0, 4, 4), f64::INFINITY, "K ≤ p cannot be checked");
    }

    #[test]
    fn default_tasks_are_every_ordered_pair_then_all_others() {
        let tasks = default_tasks(4, true);
        assert_eq!(tasks.len(), 12 + 4);
        assert!(tasks[..12].iter().all(|t| t.sources.len() == 1 && t.sources[0] != t.target));
        assert_eq!(tasks[12], TransferTask { sources: vec![1, 2, 3], target: 0 });
        assert_eq!(default_tasks(2, true).len(), 2, "co-learning needs three printers");
        assert_eq!(default_tasks(3, false).len(), 6);
    }

    #[test]
    fn other_family_widths_scale_and_lag_in_closed_form() {
        let xs: Vec<f64> = (0..=100).map(|i| i as f64 * 0.1).collect();
        let step: Vec<f64> = xs.iter().map(|&x| if x < 1.0 { 0.5 } else { 1.0 }).collect();
        let scaled = other_family_widths(&xs, &step, 1.6, 0.0);
        assert!(scaled.iter().zip(&step).all(|(a, b)| (a - 1.6 * b).abs() < 1e-12));
        // A first-order lag of L = 2 mm, discretised exactly for an input that changes at
        // a sample: the step reaches the lag in the interval after x = 0.9 mm, so
        // w'(x) = 1 − 0.5·e^{−(x − 0.9)/L} from x = 1 mm on.
        let lagged = other_family_widths(&xs, &step, 1.0, 2.0);
        for (&x, &w) in xs.iter().zip(&lagged).filter(|(x, _)| **x >= 1.0) {
            let expected = 1.0 - 0.5 * (-(x - 0.9) / 2.0).exp();
            assert!((w - expected).abs() < 1e-9, "x = {x}: {w} vs {expected}");
        }
    }

    fn real_study() -> Option<(Vec<MeasuredLine>, Vec<MeasuredLine>, Vec<MeasuredLine>)> {
        let (t5, t6) = (real_lines("taz5")?, real_lines("taz6")?);
        let wide = t5
            .iter()
            .map(|l| {
                let w = other_family_widths(&l.positions_mm, &l.widths_mm, 1.6, 0.0);
                MeasuredLine::new(l.nominal, l.positions_mm.clone(), w).unwrap()
            })
            .collect();
        Some((t5, t6, wide))
    }

    #[test]
    fn real_lines_the_guard_never_hurts_beyond_its_interval_and_rejects_another_family() {
        // Taz 5 ↔ Taz 6 and a 0.8 mm-nozzle Taz 5 as sources; as targets, four lines of
        // the Taz 6 and of the Taz 5 (14 subsets each, so the test stays short; the
        // shipped spec runs all nine). On every (task, n) the guard's interval must reach
        // 0 or above, and with the other family as the only source it must fit exactly
        // what single-printer learning fits.
        let Some((t5, t6, wide)) = real_study() else { return };
        let (t5_four, t6_four) = (four_lines(&t5), four_lines(&t6));
        let p5 = PiecewiseParams::paper_defaults().check().unwrap();
        let p6 = PiecewiseParams::paper_defaults_without_blob().check().unwrap();
        let printers = [
            StudyPrinter { name: "taz5", lines: &t5, params: &p5 },
            StudyPrinter { name: "taz6", lines: &t6, params: &p6 },
            StudyPrinter { name: "wide", lines: &wide, params: &p5 },
            StudyPrinter { name: "taz5-four", lines: &t5_four, params: &p5 },
            StudyPrinter { name: "taz6-four", lines: &t6_four, params: &p6 },
        ];
        let tasks = [
            TransferTask { sources: vec![0], target: 4 },
            TransferTask { sources: vec![2], target: 4 },
            TransferTask { sources: vec![1], target: 3 },
            TransferTask { sources: vec![0, 2], target: 4 },
        ];
        // The guarantees must hold under both kinematics rules, here and in the tests below.
        for kinematics in PriorKinematics::ALL {
            real_lines_under(&printers, &tasks, &decade_grid(kinematics));
        }
    }

    /// The assertions of the real-lines test under one transfer setting.
    fn real_lines_under(printers: &[StudyPrinter], tasks: &[TransferTask], transfer: &TransferValidParams) {
        let rows = transfer_matrix(printers, tasks, transfer).unwrap();
        let mut by_target: Vec<MatrixRow> =
            [3, 4].iter().flat_map(|&t| transfer_matrix_for_target(printers, tasks, transfer, t).unwrap()).collect();
        by_target.sort_by_key(|r| r.task);
        assert_eq!(by_target, rows, "the study split by target printer gives the same rows");
        let summary = summarise(&rows, 500, 7);
        assert_guarded_never_below_single(&summary);
        let of = |task: usize, m: MatrixMethod| -> Vec<f64> {
            rows.iter().filter(|r| r.task == task && r.method == m).map(|r| r.rmse_mm).collect()
        };
        assert_eq!(of(1, MatrixMethod::Guarded), of(1, MatrixMethod::Single), "the other family is rejected");
        assert!(
            of(1, MatrixMethod::TransferSourceMean).iter().sum::<f64>()
                > of(1, MatrixMethod::Single).iter().sum::<f64>()
        );
        let one_line = rows.iter().filter(|r| r.n_train == 1 && r.method == MatrixMethod::Guarded);
        assert!(one_line.clone().count() > 0 && one_line.clone().all(|r| r.lambda == 0.0 && r.prior == "none"));
        // Co-learning with the related and the unrelated source never uses the other
        // family alone, and the same seed gives the same summary.
        let co_learning = rows.iter().filter(|r| r.task == 3 && r.method == MatrixMethod::CoLearning);
        assert!(co_learning.clone().all(|r| r.prior != "wide"));
        assert_eq!(summarise(&rows, 500, 7), summary);
        assert_hindsight_bounds_every_method(&rows);
    }

    /// The guard and co-learning are never worse than single-printer learning beyond
    /// their interval, on every (task, n) of the summary.
    fn assert_guarded_never_below_single(summary: &[MatrixSummary]) {
        for s in summary.iter().filter(|s| matches!(s.method, MatrixMethod::Guarded | MatrixMethod::CoLearning)) {
            assert!(s.ci_hi_pct >= 0.0, "task {} n = {}: {s:?}", s.task, s.n_train);
        }
    }

    /// A Bowden-extruder variant of `taz6`: half of the flow through a second lag of
    /// 1.5 s (the tube's compliance).
    fn bowden_profile(taz6: &PrinterProfile) -> PrinterProfile {
        PrinterProfile { theta: Theta { slow_fraction: 0.5, tau_slow_s: 1.5, ..taz6.theta }, ..*taz6 }
    }

    /// On every (task, training subset) the bound in hindsight's mean RMSE over the
    /// subset's held-out lines is at most every method's, as its definition requires
    /// (every method of a task chooses among the configurations it searches).
    fn assert_hindsight_bounds_every_method(rows: &[MatrixRow]) {
        let mut means: HashMap<(usize, &str, MatrixMethod), (f64, usize)> = HashMap::new();
        for r in rows {
            let m = means.entry((r.task, r.subset.as_str(), r.method)).or_default();
            *m = (m.0 + r.rmse_mm, m.1 + 1);
        }
        let mut checked = 0;
        for (&(task, subset, method), &(sum, n)) in &means {
            let (bound, n_bound) = means[&(task, subset, MatrixMethod::Hindsight)];
            assert_eq!(n, n_bound, "task {task} {subset}: the same held-out lines");
            assert!(bound <= sum * (1.0 + 1e-12), "task {task} {subset}: {method:?} {sum} below the bound {bound}");
            checked += usize::from(method != MatrixMethod::Hindsight);
        }
        assert!(checked > 100, "{checked} comparisons");
    }

    /// Four of nine Table I lines (14 training subsets: the tests stay short).
    fn four_lines(lines: &[MeasuredLine]) -> Vec<MeasuredLine> {
        [0, 3, 5, 8].iter().map(|&k| lines[k].clone()).collect()
    }

    /// The shipped spec's λ grid, 1e-6 to 1e4 in whole decades, with the kinematics rule
    /// `kinematics`.
    fn decade_grid(kinematics: PriorKinematics) -> TransferValidParams {
        let lambda_grid = TransferParams::log_lambda_grid(1.0);
        TransferParams { lambda_grid, kinematics, ..TransferParams::paper_defaults() }.check().unwrap()
    }

    /// Nine Table I lines of the virtual printer `profile`, sampled every 0.5 mm (the
    /// truth grid's every tenth point), each line from its own seeded stream.
    fn virtual_lines(profile: &PrinterProfile, seed: u64) -> Vec<MeasuredLine> {
        let kins: Vec<LineKinematics> =
            TABLE_I.iter().map(|&(a, f)| LineKinematics::paper_line(a, f).unwrap()).collect();
        let v_ref = kins.iter().map(LineKinematics::peak_speed_mm_s).fold(0.0, f64::max);
        kins.iter()
            .enumerate()
            .map(|(k, kin)| {
                let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, k as u64, 0));
                let line = print_line(profile, &Effects::default(), kin, v_ref, &mut rng).unwrap();
                let widths = line.widths_mm();
                let keep = |v: &[f64]| -> Vec<f64> { v.iter().step_by(10).copied().collect() };
                MeasuredLine::new(*kin, keep(&line.positions_mm), keep(&widths)).unwrap()
            })
            .collect()
    }

    #[test]
    fn virtual_printers_of_other_families_the_guard_and_co_learning_never_hurt_beyond_their_interval() {
        // Virtual printers (models::fdm::printer, DESIGN §5.1): a target of the Taz 6's
        // calibrated physics, a twin of it (same physics, its own lines), and two
        // printers of other families made by changing the physics: a 0.8 mm nozzle (w0
        // × 1.6) and a Bowden extruder (half of the flow through a second lag of 1.5 s,
        // the tube's compliance). As targets: four lines of the Taz 6 and of the
        // Bowden printer (14 subsets each, as the real-lines test). The guard and
        // co-learning must never be worse than single beyond their interval, and the
        // twin's prior must help two target lines, alone and among the other families.
        // Not asserted, because it does not hold: that the guard rejects the other
        // families. From two target lines the conflict check passes the wide nozzle
        // (its per-line parameters scatter too widely for the check to see the
        // difference), inner leave-one-out over one-line folds then picks its prior,
        // and at n = 2 the guard loses to single-printer learning, within its interval
        // only; co-learning picks that prior for some subsets too.
        let taz6 = PrinterProfile::taz6();
        let wide = PrinterProfile { theta: Theta { w0_mm: 1.6 * taz6.theta.w0_mm, ..taz6.theta }, ..taz6 };
        let bowden = bowden_profile(&taz6);
        let (target, twin) = (four_lines(&virtual_lines(&taz6, 1)), virtual_lines(&taz6, 2));
        let (wide, bowden_all) = (virtual_lines(&wide, 3), virtual_lines(&bowden, 4));
        let bowden_target = four_lines(&virtual_lines(&bowden, 5));
        let p = PiecewiseParams::paper_defaults_without_blob().check().unwrap();
        let printers = [
            StudyPrinter { name: "taz6-four", lines: &target, params: &p },
            StudyPrinter { name: "twin", lines: &twin, params: &p },
            StudyPrinter { name: "wide", lines: &wide, params: &p },
            StudyPrinter { name: "bowden", lines: &bowden_all, params: &p },
            StudyPrinter { name: "bowden-four", lines: &bowden_target, params: &p },
        ];
        let tasks = [
            TransferTask { sources: vec![1], target: 0 },
            TransferTask { sources: vec![2], target: 0 },
            TransferTask { sources: vec![3], target: 0 },
            TransferTask { sources: vec![1, 2, 3], target: 0 },
            TransferTask { sources: vec![1], target: 4 },
        ];
        for kinematics in PriorKinematics::ALL {
            let rows = transfer_matrix(&printers, &tasks, &decade_grid(kinematics)).unwrap();
            let summary = summarise(&rows, 500, 7);
            assert_guarded_never_below_single(&summary);
            let of = |task: usize, n: usize, m: MatrixMethod| {
                summary.iter().find(|s| s.task == task && s.n_train == n && s.method == m).unwrap().improvement_pct
            };
            assert!(of(0, 2, MatrixMethod::Guarded) > 10.0, "{kinematics:?}: the twin's prior helps two lines");
            assert!(of(3, 2, MatrixMethod::CoLearning) > 10.0, "{kinematics:?}: so it does among other families");
            assert_hindsight_bounds_every_method(&rows);
        }
    }

    #[test]
    fn nine_line_virtual_targets_of_other_families_the_guard_never_hurts_beyond_its_interval() {
        // All nine lines of a virtual Taz 6 learnt from the Bowden printer, and of the
        // Bowden printer learnt from the Taz 6's twin (one source each, every subset up
        // to eight lines): from five target lines on the inner leave-one-out has five
        // folds or more, and the conflict check must still stand beside it. Without the
        // check from five lines on (tried: it helped the shipped spec's slower-melting
        // Taz 6), both tasks fall below single-printer learning beyond their interval
        // at n = 5. The likely reason: leave-one-out picks the best of a dozen noisy
        // configurations, so its pick looks better than it is, by more than a prior
        // from another family gives.
        let taz6 = PrinterProfile::taz6();
        let bowden = bowden_profile(&taz6);
        let (target, twin) = (virtual_lines(&taz6, 1), virtual_lines(&taz6, 2));
        let (bowden_source, bowden_target) = (virtual_lines(&bowden, 4), virtual_lines(&bowden, 5));
        let p = PiecewiseParams::paper_defaults_without_blob().check().unwrap();
        let printers = [
            StudyPrinter { name: "taz6", lines: &target, params: &p },
            StudyPrinter { name: "twin", lines: &twin, params: &p },
            StudyPrinter { name: "bowden", lines: &bowden_source, params: &p },
            StudyPrinter { name: "bowden-target", lines: &bowden_target, params: &p },
        ];
        let tasks = [TransferTask { sources: vec![2], target: 0 }, TransferTask { sources: vec![1], target: 3 }];
        for kinematics in PriorKinematics::ALL {
            let rows = transfer_matrix(&printers, &tasks, &decade_grid(kinematics)).unwrap();
            assert_guarded_never_below_single(&summarise(&rows, 500, 7));
        }
    }

    #[test]
    fn bad_tasks_are_errors() {
        let Some((t5, t6, _)) = real_study() else { return };
        let p = PiecewiseParams::paper_defaults_without_blob().check().unwrap();
        let printers =
            [StudyPrinter { name: "a", lines: &t5, params: &p }, StudyPrinter { name: "b", lines: &t6, params: &p }];
        let transfer = TransferParams::paper_defaults().check().unwrap();
        for task in [
            TransferTask { sources: vec![], target: 0 },
            TransferTask { sources: vec![0], target: 0 },
            TransferTask { sources: vec![5], target: 0 },
        ] {
            assert!(matches!(transfer_matrix(&printers, &[task], &transfer), Err(FitError::Dimension(_))));
        }
    }
}
