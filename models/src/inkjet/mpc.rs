//! The paper's "stochastic greedy-type search" for problem (8) (paper 002, Sec. IV-C).
//!
//! Starting from an initial plan (the open-loop pattern), repeat: pick a random subset
//! of `M` decision variables, test each single flip against the current plan, then
//! apply the flips that improved the cost. Stop when every single flip has been tested
//! against the current plan and none improves it (the paper's stopping rule), or after
//! `max_sweeps` passes.
//!
//! Choices the paper leaves open, and ours:
//! - The subsets are consecutive chunks of a fresh random permutation of all variables
//!   (a *sweep*), so every variable is tested once per sweep; a sweep with no applied
//!   flip proves the plan is a local minimum for single flips.
//! - "Flip all points marked Y" can raise the cost when two marked flips interact
//!   (neighbouring cells, or through the global mean and std). We apply the marked
//!   flips in subset order and keep each only if it still lowers the cost given the flips
//!   already applied, so the cost decreases monotonically, as the paper claims. A marked
//!   flip farther than `2N + 1` cells from every flip applied so far in its subset reads
//!   no changed cell, so its change of the running sums is reused and its cost is
//!   re-scored in O(1).
//! - Flips of a subset are evaluated in parallel (rayon) when the subset is large
//!   enough to pay for it (`M·(2N+1)² ≥ 8192` window cells, e.g. `M ≥ 1024` at `N = 1`);
//!   results are collected in subset order and applied sequentially, so the outcome does
//!   not depend on the number of threads.

use rand::seq::SliceRandom;
use rand::Rng;
use rayon::prelude::*;

use super::errors::InkjetError;
use super::horizon::{Flip, FlipDelta, FlipScratch, HorizonState, Problem};
use super::objective::Weight;

/// A flip must lower eq. 8 by more than this (µm) to count as an improvement; it only
/// guards against rounding noise (single-flip gains are ≥ 1e-5 µm on 10⁴-cell parts).
pub const IMPROVEMENT_TOL_UM: f64 = 1e-10;

/// Controller parameters as given (unchecked).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MpcParams {
    /// Weight `α` of the mean absolute error against the std in eq. 8.
    pub alpha: f64,
    /// Prediction horizon `N` (layers), at least 1.
    pub horizon_layers: usize,
    /// Subset size `M` of the stochastic greedy search, at least 1.
    pub subset_size: usize,
    /// Upper bound on the number of sweeps ("an upper bound for the highest number of
    /// iterations allowed", Sec. IV-C).
    pub max_sweeps: usize,
}

impl MpcParams {
    /// Our settings; the paper gives none of these values.
    ///
    /// - `α = 0.9`: mostly the mean absolute error. Near the desired height the std
    ///   term rewards a droplet on any cell lower than the mean even when it overshoots
    ///   `h_d`; with `α = 0.5` the simulated cylinder ends 2-3.5 µm too high, with
    ///   `α ≥ 0.8` within 1.6 µm (Figs 11-12 report 0.7 and 1.9 µm), and the std
    ///   (≈ 1.5 µm) does not depend on `α` in that range.
    /// - `N = 1`: the paper notes N "can be made as small as 1". `N = 2` lowers the
    ///   cylinder's mean error by about 0.2 µm at six times the cost.
    /// - `M = 64`: a "small subset" as in the paper, no larger than the smallest
    ///   footprint used (the 64-cell cuboid). Such subsets are evaluated on one thread;
    ///   on large grids `M = 1024` lets rayon pay and gives the same cost (see the
    ///   `inkjet` bench).
    /// - `max_sweeps = 200`: a safety cap, never reached in our scenarios.
    pub fn recommended() -> Self {
        Self { alpha: 0.9, horizon_layers: 1, subset_size: 64, max_sweeps: 200 }
    }

    /// Checks the ranges and returns the valid parameters.
    pub fn check(self) -> Result<ValidMpcParams, InkjetError> {
        let weight = Weight::new(self.alpha)?;
        positive("horizon_layers", self.horizon_layers)?;
        positive("subset_size", self.subset_size)?;
        positive("max_sweeps", self.max_sweeps)?;
        Ok(ValidMpcParams { params: self, weight })
    }
}

fn positive(name: &'static str, value: usize) -> Result<(), InkjetError> {
    if value == 0 {
        Err(InkjetError::InvalidParameter { name, value: 0.0, reason: "must be at least 1" })
    } else {
        Ok(())
    }
}

/// Checked controller parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValidMpcParams {
    params: MpcParams,
    weight: Weight,
}

impl ValidMpcParams {
    /// The parameters as given.
    pub fn params(&self) -> MpcParams {
        self.params
    }

    /// The checked weight `α`.
    pub fn weight(&self) -> Weight {
        self.weight
    }

    /// Horizon `N`.
    pub fn horizon(&self) -> usize {
        self.params.horizon_layers
    }
}

/// What the search did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SearchStats {
    /// Eq. 8 of the initial plan.
    pub objective_start: f64,
    /// Eq. 8 of the returned plan.
    pub objective_end: f64,
    /// Number of sweeps (full passes over the variables).
    pub sweeps: usize,
    /// Number of single-flip evaluations.
    pub flips_evaluated: usize,
    /// Number of flips applied.
    pub flips_applied: usize,
    /// Whether the last sweep found no improving flip (a single-flip local minimum).
    pub converged: bool,
}

/// The optimised plan: `N` row-major patterns, the first one to be printed next.
#[derive(Debug, Clone, PartialEq)]
pub struct MpcSolution {
    /// The `N` patterns of the horizon.
    pub plan: Vec<Vec<bool>>,
    /// Search statistics.
    pub stats: SearchStats,
}

/// Minimises eq. 8 from `initial` (one pattern per horizon layer) over the footprint
/// cells of every layer. Deterministic for a given `rng` state, whatever the number of
/// rayon threads.
pub fn optimise(
    problem: Problem<'_>,
    params: &ValidMpcParams,
    initial: Vec<Vec<bool>>,
    rng: &mut impl Rng,
) -> MpcSolution {
    let horizon = initial.len();
    let mut state = HorizonState::new(problem, initial);
    let mut stats = SearchStats { objective_start: state.objective(), ..SearchStats::default() };
    let mut variables = decision_variables(&problem, horizon);
    let mut scratch = FlipScratch::new(horizon);
    while stats.sweeps < params.params.max_sweeps && !stats.converged {
        variables.shuffle(rng);
        let applied_before = stats.flips_applied;
        for subset in variables.chunks(params.params.subset_size) {
            search_subset(&mut state, subset, &mut scratch, &mut stats);
        }
        state.resync();
        stats.sweeps += 1;
        stats.converged = stats.flips_applied == applied_before;
    }
    stats.objective_end = state.objective();
    MpcSolution { plan: state.plan().to_vec(), stats }
}

/// All `(cell, layer)` pairs over the footprint and the horizon, layer-major.
fn decision_variables(problem: &Problem<'_>, horizon: usize) -> Vec<Flip> {
    (0..horizon).flat_map(|layer| problem.target.cells().iter().map(move |&cell| Flip { cell, layer })).collect()
}

/// One iteration: evaluate every flip of `subset` (in parallel), then apply the
/// improving ones that still improve, in subset order.
fn search_subset(state: &mut HorizonState<'_>, subset: &[Flip], scratch: &mut FlipScratch, stats: &mut SearchStats) {
    let horizon = state.horizon();
    let current = state.objective();
    let deltas = evaluate_subset(state, subset, scratch);
    stats.flips_evaluated += subset.len();
    let reach = 2 * horizon + 1;
    let grid = state.grid();
    let mut applied: Vec<(usize, usize)> = Vec::new();
    for (&flip, delta) in subset.iter().zip(&deltas) {
        if delta.objective >= current - IMPROVEMENT_TOL_UM {
            continue;
        }
        let (i, j) = grid.coords(flip.cell);
        let interacts = applied.iter().any(|&(a, b)| a.abs_diff(i) <= reach && b.abs_diff(j) <= reach);
        let now = if interacts {
            stats.flips_evaluated += 1;
            state.evaluate(flip, scratch).objective
        } else {
            state.objective_with(delta.sums)
        };
        if now < state.objective() - IMPROVEMENT_TOL_UM {
            state.commit(flip, scratch);
            applied.push((i, j));
            stats.flips_applied += 1;
        }
    }
}

/// Evaluates every flip of `subset` against the current state, in subset order: in
/// parallel when the subset holds at least [`PARALLEL_MIN_CELLS`] window cells, on the
/// calling thread otherwise (handing a few microseconds of work to the pool costs more
/// than it saves). Both paths give identical results.
fn evaluate_subset(state: &HorizonState<'_>, subset: &[Flip], scratch: &mut FlipScratch) -> Vec<FlipDelta> {
    let horizon = state.horizon();
    let window_cells = (2 * horizon + 1).pow(2);
    if subset.len() * window_cells < PARALLEL_MIN_CELLS {
        return subset.iter().map(|&f| state.evaluate(f, scratch)).collect();
    }
    subset
        .par_iter()
        .with_min_len((PARALLEL_MIN_CELLS / window_cells).max(1))
        .map_init(|| FlipScratch::new(horizon), |scratch, &flip| state.evaluate(flip, scratch))
        .collect()
}

/// Work (flips × window cells) below which a subset is evaluated on one thread:
/// about 50 µs of evaluation.
pub const PARALLEL_MIN_CELLS: usize = 8192;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inkjet::grid::{Grid, HeightMap, Pattern};
    use crate::inkjet::height_model::{deposit_layer_into, uniform_coeffs, DropletCoeffs};
    use crate::inkjet::objective::Target;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn invalid_parameters_are_errors() {
        let base = MpcParams::recommended();
        assert!(base.check().is_ok());
        assert!(MpcParams { alpha: 2.0, ..base }.check().is_err());
        assert!(MpcParams { horizon_layers: 0, ..base }.check().is_err());
        assert!(MpcParams { subset_size: 0, ..base }.check().is_err());
    }

    #[test]
    fn the_search_never_raises_the_cost_and_is_deterministic() {
        let grid = Grid::new(12, 12, 1.0).unwrap();
        let footprint = Pattern::from_fn(grid, |x, y| (2.0..=9.0).contains(&x) && (2.0..=9.0).contains(&y));
        // Rough profile at 10-20 µm, target 18 µm: printing everything overshoots in places.
        let target = Target::uniform(grid, footprint.clone(), 18.0).unwrap();
        let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let measured: Vec<f64> = (0..grid.len()).map(|_| rng.random_range(10.0..20.0)).collect();
        for horizon in [1, 2] {
            let params =
                MpcParams { horizon_layers: horizon, subset_size: 7, ..MpcParams::recommended() }.check().unwrap();
            let problem = Problem::new(&measured, &target, &coeffs, params.weight()).unwrap();
            let initial = vec![footprint.droplet.clone(); horizon];
            let a = optimise(problem, &params, initial.clone(), &mut ChaCha8Rng::seed_from_u64(9));
            let b = optimise(problem, &params, initial, &mut ChaCha8Rng::seed_from_u64(9));
            assert_eq!(a, b);
            assert!(a.stats.converged);
            assert!(a.stats.objective_end < a.stats.objective_start);
            // The returned cost is the plan's true cost.
            let check = HorizonState::new(problem, a.plan.clone()).objective();
            assert!((check - a.stats.objective_end).abs() < 1e-9);
            // Droplets only ever land on the footprint.
            for pattern in &a.plan {
                assert!((0..grid.len()).all(|c| !pattern[c] || footprint.droplet[c]));
            }
        }
    }

    #[test]
    fn the_result_does_not_depend_on_the_thread_count() {
        // Subsets of 2048 flips at N = 2 take the parallel path.
        let grid = Grid::new(60, 60, 1.0).unwrap();
        let footprint = Pattern::from_fn(grid, |x, y| (3.0..=56.0).contains(&x) && (3.0..=56.0).contains(&y));
        let target = Target::uniform(grid, footprint.clone(), 18.0).unwrap();
        let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let measured: Vec<f64> = (0..grid.len()).map(|_| rng.random_range(8.0..14.0)).collect();
        let params = MpcParams { horizon_layers: 2, subset_size: 2048, ..MpcParams::recommended() }.check().unwrap();
        assert!(params.params().subset_size * 25 >= PARALLEL_MIN_CELLS);
        let problem = Problem::new(&measured, &target, &coeffs, params.weight()).unwrap();
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let initial = vec![footprint.droplet.clone(); 2];
                optimise(problem, &params, initial, &mut ChaCha8Rng::seed_from_u64(1))
            })
        };
        let one = run(1);
        assert!(one.stats.flips_applied > 0);
        assert_eq!(one, run(3));
    }

    #[test]
    fn the_result_is_a_local_minimum_for_single_flips() {
        let grid = Grid::new(10, 10, 1.0).unwrap();
        let footprint = Pattern::from_fn(grid, |_, _| true);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let measured: Vec<f64> = (0..grid.len()).map(|_| rng.random_range(0.0..10.0)).collect();
        let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        let mut desired = vec![0.0; grid.len()];
        let truth: Vec<bool> = (0..grid.len()).map(|_| rng.random_bool(0.5)).collect();
        deposit_layer_into(grid, &measured, &truth, &coeffs, &mut desired);
        let target = Target::new(footprint.clone(), HeightMap::from_vec(grid, desired).unwrap()).unwrap();
        let params = MpcParams { alpha: 1.0, ..MpcParams::recommended() }.check().unwrap();
        let problem = Problem::new(&measured, &target, &coeffs, params.weight()).unwrap();
        let solution = optimise(problem, &params, vec![footprint.droplet.clone()], &mut rng);
        let state = HorizonState::new(problem, solution.plan.clone());
        let mut scratch = FlipScratch::new(1);
        for cell in 0..grid.len() {
            let after = state.evaluate(Flip { cell, layer: 0 }, &mut scratch).objective;
            assert!(after >= state.objective() - IMPROVEMENT_TOL_UM);
        }
    }
}
