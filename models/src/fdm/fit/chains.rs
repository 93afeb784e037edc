//! The chain solves of one training set at one grid pair, one per prior configuration
//! (paper 000, step 4 of the fitting procedure: eq. 3 fitted segment by segment, with
//! the prior of eq. 5 when there is one), several configurations advanced side by side.
//!
//! Each configuration's solve is the fixed point described at [`solve_chains`], and its
//! arithmetic is that of solving the configurations one after the other: the same
//! systems, the same LU solve ([`LuBatch`] does the one-system `lu_solve`'s operations
//! lane by lane), the same partition updates, cycle checks and SSEs, in the same
//! order. So every result is bit-identical to the one-at-a-time loop (a test keeps that
//! loop and checks it). What changes is only the order in which the CPU meets the work:
//! one configuration's iterations depend on each other (an LU solve is a chain of
//! divisions, the next partition needs its solution), while different configurations'
//! do not. So [`LANES`] configurations run at once, one per lane, their systems solved
//! together, and the CPU overlaps what one solve alone would leave it waiting for. A
//! lane whose configuration is done takes the next one, so lanes idle only at the end,
//! and only the lanes' states are live (a small working set).
//!
//! Where the iteration starts matters: the partition map has several fixed points, and
//! the one reached depends on the start. Every configuration starts from each line's
//! bp3 as the data place it (the paper's step 3). A configuration with a prior is also
//! solved from a second start, the partition at which the solve without a prior ends,
//! and keeps whichever of the two solutions has the lower penalised objective (training
//! SSE plus the prior's term, the objective both minimise). From the data's bp3 alone,
//! solves under a prior (above all a zero-mean one, which pulls every parameter far
//! from the data) could stop at a fixed point well above the one the second start
//! reaches, and the prior then looked worse than it is. Neither start is better
//! everywhere, so both are tried. Solving the configurations with a prior from the
//! second start alone would halve the iterations, but on the real Taz lines the first
//! start reaches the lower objective in a large share of the solves under the
//! strongest priors, often by far, so it stays (measured with
//! `examples/transfer_matrix_full.rs`).

use std::borrow::Borrow;

use super::super::small_linalg::LuBatch;
use super::{
    fixed_rows, load_lane, within_tolerance, ChainPrior, ChainProblem, Equations, FixedRow, LineAtPair, PartitionKey,
    WeightedPrior, C, EQUILIBRATED, NP,
};
use crate::fdm::hyperparams::PiecewiseValidParams;

/// Earlier solutions kept per configuration for the cycle check.
const HISTORY: usize = 8;

/// Configurations whose systems are solved side by side ([`LuBatch`] lanes).
pub(super) const LANES: usize = 4;

/// A configuration's result when its segment equations are singular: `(NaN, ∞)`, which
/// no grid pair selects.
pub(super) const SINGULAR: ([f64; NP], f64) = ([f64::NAN; NP], f64::INFINITY);

/// One configuration's solve between two iterations: which configuration, its rows that
/// no partition changes, its iteration, the current parameters (they pin the
/// unidentified ones) and the last [`HISTORY`] solutions.
#[derive(Debug, Clone, Copy)]
struct ChainState {
    config: usize,
    fixed: [FixedRow; 2],
    it: usize,
    theta: [f64; NP],
    history: [[f64; NP]; HISTORY],
    /// Whether it started from the initial partition (whose equations are `first`).
    initial: bool,
}

/// Reusable buffers of [`solve_chains`]: the batch, and per lane its solve (if any) and
/// its partition (`keys[lane · lines + line]`).
#[derive(Debug, Default)]
pub(crate) struct ChainScratch {
    batch: LuBatch<NP, LANES>,
    /// A lane's data part of the segment equations.
    data: Equations,
    lanes: [Option<ChainState>; LANES],
    keys: Vec<PartitionKey>,
    /// The second start of the configurations with a prior, and their solves from it.
    start: Vec<PartitionKey>,
    second: Vec<([f64; NP], f64)>,
}

/// What one solution does to a configuration's solve.
enum Outcome {
    /// The partition moved and no cycle closed: iterate again.
    Going,
    /// The parameters and the training SSE of p2-p5.
    Solved([f64; NP], f64),
    /// The segment equations were singular.
    Singular,
}

/// The per-segment (MAP) least squares with consistent continuity offsets under every
/// configuration of `configs`: `out[c]` receives `(β, γ, c, ρ, w_start)` and the
/// training SSE of p2-p5 plus `sse_p1`, or [`SINGULAR`].
///
/// For a fixed partition (bp3 of every line, as a sample index, and whether the plateau
/// is reached before bp4), the offsets `w(bp2) = w(bp1) + β·g(bp2)` and `w(bp4) = c` or
/// `w(bp2) + γ·s(bp4)` are linear in the parameters. The parameters are then the fixed
/// point "θ minimises the segment sums of squares (plus prior) with the offsets held at
/// their values under θ" (eq. 3 fitted segment by segment, eq. 6's constant offsets),
/// which is one non-symmetric linear system (data part, prior added, unidentified
/// parameters pinned, LU). Without a prior it is exactly the paper's sequential
/// per-segment fit. The partition is then updated from the new bp3 and the solve
/// repeated until the partition no longer changes. Because bp3 moves in whole samples
/// this can end in a short cycle between neighbouring partitions; a cycle of up to
/// `HISTORY` steps is detected and its member with the smallest training SSE is
/// returned (likewise among the last `HISTORY` states if `max_iterations` is reached,
/// which happens only with a strong prior). Every configuration starts from the initial
/// partition (every line's initial bp3); one with a prior is solved again from the
/// partition of the first no-prior configuration's solution (where there is one, it is
/// not singular and it is not the initial partition) and keeps the solution of lower
/// [`penalised`] objective, the first on a tie (see the module docs).
pub(super) fn solve_chains<'p, L: Borrow<LineAtPair<'p>>>(
    pb: &ChainProblem<L>,
    configs: &[ChainPrior],
    params: &PiecewiseValidParams,
    sse_p1: f64,
    scratch: &mut ChainScratch,
    out: &mut [([f64; NP], f64)],
) {
    let ChainScratch { batch, data, lanes, keys, start, second } = scratch;
    let n = pb.data.len();
    let p = params.get();
    keys.resize(LANES * n, (0, false));
    let with_prior = |c: &usize| configs[*c].is_some();
    let run = Run { pb, configs, tolerance: p.tolerance, max_iterations: p.max_iterations, sse_p1 };
    run.lanes(0..configs.len(), None, (batch, data, lanes, keys), out);
    // The second start: the partition of the first solution without a prior, unless it
    // is the first start (which gives the same solves).
    let Some(anchor) = (0..configs.len()).find(|c| !with_prior(c)).filter(|&c| out[c].1.is_finite()) else {
        return;
    };
    let theta = out[anchor].0;
    start.clear();
    start.extend((0..n).map(|k| pb.model_key(k, &theta)));
    if start[..] == *pb.initial {
        return;
    }
    second.clear();
    second.extend_from_slice(out);
    run.lanes((0..configs.len()).filter(with_prior), Some(start), (batch, data, lanes, keys), second);
    for (c, (first, second)) in out.iter_mut().zip(second.iter()).enumerate() {
        if let Some(prior) = &configs[c] {
            if penalised(prior, second) < penalised(prior, first) {
                *first = *second;
            }
        }
    }
}

/// The objective a solve with `prior` minimises for its partition: the training SSE
/// plus `λ(θ−μ)ᵀΣ⁻¹(θ−μ)` (eq. 5), up to the constant `λμᵀΣ⁻¹μ`; `+∞` for a singular
/// solve (or any whose objective is not a number), so that every solution beats it.
fn penalised(prior: &WeightedPrior, (theta, sse): &([f64; NP], f64)) -> f64 {
    let mut penalty = 0.0;
    for i in 0..NP {
        for j in 0..NP {
            penalty += theta[i] * prior.matrix[i][j] * theta[j] - 2.0 * theta[i] * prior.rhs_terms[i][j];
        }
    }
    let objective = sse + penalty;
    if objective.is_nan() {
        f64::INFINITY
    } else {
        objective
    }
}

/// One [`solve_chains`] call's problem, configurations and iteration rules.
struct Run<'r, L> {
    pb: &'r ChainProblem<'r, L>,
    configs: &'r [ChainPrior],
    tolerance: f64,
    max_iterations: usize,
    sse_p1: f64,
}

impl<'p, L: Borrow<LineAtPair<'p>>> Run<'_, L> {
    /// Solves the configurations `waiting`, [`LANES`] side by side, each from the
    /// partition `start` (`None`: the initial one) into `out`.
    fn lanes(
        &self,
        mut waiting: impl Iterator<Item = usize>,
        start: Option<&[PartitionKey]>,
        (batch, data, lanes, keys): (
            &mut LuBatch<NP, LANES>,
            &mut Equations,
            &mut [Option<ChainState>; LANES],
            &mut [PartitionKey],
        ),
        out: &mut [([f64; NP], f64)],
    ) {
        let (pb, configs) = (self.pb, self.configs);
        let n = pb.data.len();
        for (lane, state) in lanes.iter_mut().enumerate() {
            *state = ChainState::next((&mut waiting, configs), pb, start, &mut keys[lane * n..(lane + 1) * n], out);
        }
        while lanes.iter().any(Option::is_some) {
            let mut solved = [None; LANES];
            solve_batch(pb, configs, (lanes, keys), (batch, data), &mut solved);
            for (lane, (state, solution)) in lanes.iter_mut().zip(solved).enumerate() {
                let Some(st) = state else { continue };
                let keys = &mut keys[lane * n..(lane + 1) * n];
                out[st.config] = match advance(pb, st, keys, solution, self.tolerance) {
                    Outcome::Going if st.it < self.max_iterations => continue,
                    Outcome::Going => with_p1(budget_spent(pb, st), self.sse_p1),
                    Outcome::Solved(theta, sse) => with_p1((theta, sse), self.sse_p1),
                    Outcome::Singular => SINGULAR,
                };
                *state = ChainState::next((&mut waiting, configs), pb, start, keys, out);
            }
        }
    }
}

/// A solve's result with the p1 SSE added to its training SSE.
fn with_p1((theta, sse): ([f64; NP], f64), sse_p1: f64) -> ([f64; NP], f64) {
    (theta, sse + sse_p1)
}

impl ChainState {
    /// The next of the `waiting` configurations before its first iteration (`c` at its
    /// initial value, the partition `start` in `keys`, the initial one if `None`), if any
    /// is left. A configuration whose fixed rows already make the LU solve fail is
    /// [`SINGULAR`] in `out` at once.
    fn next<L>(
        (waiting, configs): (&mut impl Iterator<Item = usize>, &[ChainPrior]),
        pb: &ChainProblem<L>,
        start: Option<&[PartitionKey]>,
        keys: &mut [PartitionKey],
        out: &mut [([f64; NP], f64)],
    ) -> Option<Self> {
        let (config, fixed) = loop {
            let config = waiting.next()?;
            match fixed_rows(&pb.first, &configs[config]) {
                Some(fixed) => break (config, fixed),
                None => out[config] = SINGULAR,
            }
        };
        keys.copy_from_slice(start.unwrap_or(pb.initial));
        let mut theta = [0.0; NP];
        theta[C] = pb.c_init;
        Some(Self { config, fixed, it: 0, theta, history: [[f64::NAN; NP]; HISTORY], initial: start.is_none() })
    }
}

/// The lanes' current systems, solved side by side: the data part of each one's
/// partition (the shared first one at its first iteration), its prior added and its
/// unidentified parameters pinned at their current values.
fn solve_batch<'p, L: Borrow<LineAtPair<'p>>>(
    pb: &ChainProblem<L>,
    configs: &[ChainPrior],
    (lanes, keys): (&[Option<ChainState>; LANES], &[PartitionKey]),
    (batch, data): (&mut LuBatch<NP, LANES>, &mut Equations),
    out: &mut [Option<[f64; NP]>; LANES],
) {
    let n = pb.data.len();
    for (lane, state) in lanes.iter().enumerate() {
        let Some(st) = state else {
            batch.clear(lane);
            continue;
        };
        let equations = if st.it == 0 && st.initial {
            &pb.first
        } else {
            pb.partition_rows_into(&keys[lane * n..(lane + 1) * n], data);
            &*data
        };
        load_lane((batch, lane), equations, &configs[st.config], &st.theta, &st.fixed);
    }
    batch.solve(&EQUILIBRATED, out);
}

/// One iteration's solution applied to a configuration: the new partition; done if it
/// did not move or a cycle closed, else the solution joins the history.
fn advance<'p, L: Borrow<LineAtPair<'p>>>(
    pb: &ChainProblem<L>,
    state: &mut ChainState,
    keys: &mut [PartitionKey],
    solved: Option<[f64; NP]>,
    tolerance: f64,
) -> Outcome {
    let Some(solved) = solved else { return Outcome::Singular };
    let it = state.it;
    state.it += 1;
    let mut moved = false;
    for (k, key) in keys.iter_mut().enumerate() {
        let new = pb.model_key(k, &solved);
        moved |= new != *key;
        *key = new;
    }
    if !moved {
        return Outcome::Solved(solved, pb.sse_at(keys, &solved));
    }
    let history = &state.history;
    let repeat = (1..HISTORY).find(|&k| it >= k && within_tolerance(&solved, &history[(it - k) % HISTORY], tolerance));
    if let Some(k) = repeat {
        // `keys` is the model's partition for `solved`, so its SSE is `sse_at(keys)`.
        let solved = (solved, pb.sse_at(keys, &solved));
        let (best, sse) = smallest_sse(pb, solved, (1..k).map(|j| history[(it - j) % HISTORY]));
        return Outcome::Solved(best, sse);
    }
    state.history[it % HISTORY] = solved;
    state.theta = solved;
    Outcome::Going
}

/// No fixed point within the iteration budget: the best of the last states visited.
fn budget_spent<'p, L: Borrow<LineAtPair<'p>>>(pb: &ChainProblem<L>, state: &ChainState) -> ([f64; NP], f64) {
    let recent = state.history.iter().copied().filter(|t| t.iter().all(|v| v.is_finite()));
    smallest_sse(pb, (state.theta, pb.sse(&state.theta)), recent)
}

/// The state of smallest SSE (bp3 from the model) among `first` (given with its SSE)
/// and `others`, the earliest on ties, with its SSE: `fold(first, |b, t| if sse(t) <
/// sse(b) { t } else { b })`, each state's SSE computed once instead of at every
/// comparison.
fn smallest_sse<'p, L: Borrow<LineAtPair<'p>>>(
    pb: &ChainProblem<L>,
    first: ([f64; NP], f64),
    others: impl Iterator<Item = [f64; NP]>,
) -> ([f64; NP], f64) {
    others.fold(first, |best, t| {
        let sse = pb.sse(&t);
        if sse < best.1 {
            (t, sse)
        } else {
            best
        }
    })
}

#[cfg(test)]
mod tests {
    use super::super::super::small_linalg::lu_solve;
    use super::super::super::test_support::{synthetic_lines, synthetic_truth};
    use super::super::{
        accumulate_line, add_prior, pin_unidentified, prepare_lines, set_up, SegmentPrior, SetScratch, WeightedPrior,
        FIXED_ROWS, RHO,
    };
    use super::*;
    use crate::fdm::hyperparams::PiecewiseParams;
    use crate::fdm::line::MeasuredLine;

    /// How a one-at-a-time solve ended.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum End {
        Fixed,
        Cycle,
        Budget,
        Singular,
    }

    /// The chain solve of one configuration on its own from the partition `start` (the
    /// initial one if `None`), as it was before the configurations were advanced
    /// together: the definition `solve_chains` must match.
    fn one_at_a_time<'p, L: Borrow<LineAtPair<'p>>>(
        pb: &ChainProblem<L>,
        prior: &ChainPrior,
        params: &PiecewiseValidParams,
        start: Option<&[PartitionKey]>,
    ) -> (([f64; NP], f64), End) {
        let mut theta = [0.0; NP];
        theta[C] = pb.c_init;
        let mut history = [[f64::NAN; NP]; HISTORY];
        let mut keys = start.unwrap_or(pb.initial).to_vec();
        let p = params.get();
        for it in 0..p.max_iterations {
            let (mut a, mut b) = pb.first;
            if it > 0 || start.is_some() {
                (a, b) = ([[0.0; NP]; NP], [0.0; NP]);
                for (k, (lf, &key)) in pb.data.iter().zip(&keys).enumerate() {
                    accumulate_line(lf, pb.line(k), pb.blob, key, &mut a, &mut b);
                }
            }
            if let Some(pr) = prior {
                add_prior(&mut a, &mut b, pr);
            }
            pin_unidentified(&mut a, &mut b, &theta);
            let Some(solved) = lu_solve(&a, &b) else { return (SINGULAR, End::Singular) };
            let mut moved = false;
            for (k, key) in keys.iter_mut().enumerate() {
                let new = pb.model_key(k, &solved);
                moved |= new != *key;
                *key = new;
            }
            if !moved {
                return ((solved, pb.sse_at(&keys, &solved)), End::Fixed);
            }
            let repeat =
                (1..HISTORY).find(|&k| it >= k && within_tolerance(&solved, &history[(it - k) % HISTORY], p.tolerance));
            if let Some(k) = repeat {
                let cycle = (1..k).map(|j| history[(it - j) % HISTORY]);
                let best = cycle.fold(solved, |b, t| if pb.sse(&t) < pb.sse(&b) { t } else { b });
                return ((best, pb.sse(&best)), End::Cycle);
            }
            history[it % HISTORY] = solved;
            theta = solved;
        }
        let recent = history.iter().filter(|t| t.iter().all(|v| v.is_finite()));
        let best = recent.fold(theta, |b, t| if pb.sse(t) < pb.sse(&b) { *t } else { b });
        ((best, pb.sse(&best)), End::Budget)
    }

    /// Nine Table I lines of the synthetic printer with a ripple the model cannot fit.
    fn rippled_lines(blob: bool) -> Vec<MeasuredLine> {
        let mut lines = synthetic_lines(&synthetic_truth(blob), 0.1);
        for (k, l) in lines.iter_mut().enumerate() {
            for (i, w) in l.widths_mm.iter_mut().enumerate() {
                *w += 0.02 * ((i * 7 + k * 3) as f64).sin();
            }
        }
        lines
    }

    /// No prior, then a prior centred on the truth and one centred on zero, each at
    /// `λ` from 1e-6 (nearly no prior) to 1e6 (strong enough to exhaust a small budget).
    fn configs(blob: bool) -> Vec<ChainPrior> {
        let t = synthetic_truth(blob).coefficients;
        let centre = [t.beta, t.gamma, t.c_mm, t.rho, 0.0];
        let mut precision = [[0.0; NP]; NP];
        for k in 0..=RHO {
            precision[k][k] = 1.0 / (0.1 * centre[k]).powi(2);
        }
        precision[0][1] = 0.3 * (precision[0][0] * precision[1][1]).sqrt();
        precision[1][0] = precision[0][1];
        let priors = [SegmentPrior { precision, mean: centre }, SegmentPrior { precision, mean: [0.0; NP] }];
        let lambdas = (-6..=6).map(|e| 10f64.powi(e));
        let weighted = priors.iter().flat_map(|p| lambdas.clone().map(move |l| Some(WeightedPrior::new(p, l))));
        std::iter::once(None).chain(weighted).collect()
    }

    /// The rows of β and w_start of the equations are the same, bit for bit, whatever
    /// the partition: every line's bp3 at the start of its region or at its end, with
    /// and without the plateau, or at the initial partition.
    fn assert_fixed_rows_do_not_move<'p>(pb: &ChainProblem<&LineAtPair<'p>>) {
        for (at_end, plateau) in [(false, false), (false, true), (true, false), (true, true)] {
            let keys: Vec<PartitionKey> =
                pb.data.iter().map(|lf| (if at_end { lf.i4 } else { lf.i3 }, plateau)).collect();
            let (mut a, mut b) = ([[0.0; NP]; NP], [0.0; NP]);
            for (k, (lf, &key)) in pb.data.iter().zip(&keys).enumerate() {
                accumulate_line(lf, pb.line(k), pb.blob, key, &mut a, &mut b);
            }
            for i in FIXED_ROWS {
                assert_eq!(a[i].map(f64::to_bits), pb.first.0[i].map(f64::to_bits), "row {i}");
                assert_eq!(b[i].to_bits(), pb.first.1[i].to_bits(), "row {i}");
            }
        }
    }

    #[test]
    fn configurations_together_equal_one_at_a_time_bit_for_bit() {
        // Training sets of 1, 2, 4 and 9 lines at three grid pairs, with and without the
        // start blob, under 27 configurations, with the paper's iteration budget and
        // with a budget of 3: every result of solve_chains must have the bits of the
        // one-at-a-time solve, and between them the cases must reach a fixed point, close
        // a cycle and exhaust the budget.
        let (mut ends, mut from_second) = (Vec::new(), 0);
        for blob in [true, false] {
            let lines = rippled_lines(blob);
            let configs = configs(blob);
            for budget in [60, 3] {
                let params = PiecewiseParams {
                    max_iterations: budget,
                    has_start_blob: blob,
                    ..PiecewiseParams::paper_defaults()
                }
                .check()
                .unwrap();
                let prepared = prepare_lines(&lines, &params).unwrap();
                for (r_a, r_f) in [(1.0, 1.0), (0.9, 1.1), (1.1, 0.95)] {
                    let mut at_pair: Vec<LineAtPair> = prepared.iter().map(LineAtPair::indexed).collect();
                    at_pair.iter_mut().for_each(|l| l.update(r_a, r_f).unwrap());
                    for subset in [&[4][..], &[1, 5], &[0, 2, 4, 8], &[0, 1, 2, 3, 4, 5, 6, 7, 8]] {
                        let set_lines: Vec<&LineAtPair> = subset.iter().map(|&i| &at_pair[i]).collect();
                        let mut set = SetScratch::default();
                        let start = set_up(&set_lines, &params, &mut set, &mut None).unwrap();
                        let pb = ChainProblem {
                            data: &set.data,
                            lines: &set_lines[..],
                            blob,
                            c_init: start.c_init,
                            initial: &set.initial,
                            first: start.first,
                        };
                        assert_fixed_rows_do_not_move(&pb);
                        let mut out = vec![SINGULAR; configs.len()];
                        solve_chains(&pb, &configs, &params, start.sse_p1, &mut ChainScratch::default(), &mut out);
                        // Without a prior from the initial partition; with one from
                        // where the solve without ends.
                        let (unweighted, _) = one_at_a_time(&pb, &None, &params, None);
                        let anchor: Option<Vec<PartitionKey>> = unweighted
                            .1
                            .is_finite()
                            .then(|| (0..pb.data.len()).map(|k| pb.model_key(k, &unweighted.0)).collect());
                        let anchor = anchor.filter(|a| a[..] != *pb.initial);
                        for (prior, got) in configs.iter().zip(&out) {
                            let (mut solved, mut end) = one_at_a_time(&pb, prior, &params, None);
                            if let (Some(w), Some(from)) = (prior, anchor.as_deref()) {
                                let (second, second_end) = one_at_a_time(&pb, prior, &params, Some(from));
                                let with_p1 = |(t, sse): ([f64; NP], f64)| (t, sse + start.sse_p1);
                                if penalised(w, &with_p1(second)) < penalised(w, &with_p1(solved)) {
                                    (solved, end) = (second, second_end);
                                    from_second += 1;
                                }
                            }
                            let (theta, sse) = solved;
                            let expected = (theta.map(f64::to_bits), (sse + start.sse_p1).to_bits());
                            let got_bits = (got.0.map(f64::to_bits), got.1.to_bits());
                            let sse_bits = if end == End::Singular { SINGULAR.1.to_bits() } else { expected.1 };
                            assert_eq!(got_bits, (expected.0, sse_bits), "{blob} {r_a} {r_f} {subset:?} {end:?}");
                            ends.push(end);
                        }
                    }
                }
            }
        }
        for end in [End::Fixed, End::Cycle, End::Budget] {
            assert!(ends.contains(&end), "no {end:?} among {} solves", ends.len());
        }
        assert!(from_second > 0, "no solve kept its second start's solution");
    }
}
