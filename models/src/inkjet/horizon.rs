//! The prediction of paper 002 eq. 8 over a horizon of `N` layers, and the cost of a
//! single flip of one decision variable, computed two ways:
//!
//! - [`HorizonState::evaluate`]: incremental. A droplet changes the next profile only on
//!   its 3 × 3 block, and a cell's increment reads only the 3 × 3 block of the previous
//!   profile, so a flip at layer `l` changes the predicted `H̄(k+N)` only within
//!   Chebyshev radius `N − l` of its cell. The evaluation re-simulates just these nested
//!   windows (radius 1, 2, …, `N − l`; at most `(2N+1)²` cells at the last layer) and
//!   updates the running sums of [`CostSums`]: the cost of a flip does not depend on the
//!   grid size.
//! - [`naive_objective_after_flip`]: reference. Toggles the variable, re-simulates all
//!   `N` layers on the whole grid and computes eq. 8 directly.
//!
//! **Horizon parametrisation** (Sec. IV-A, IV-C): the `N` future layers have `N`
//! independent patterns, `U_k, …, U_{k+N−1}`; the decision variables are the triples
//! `(i, j, k̄)` over the footprint cells and the `N` layers, as in the paper's search
//! space `{(i, j, k) | 1 ≤ k ≤ N}`. The model coefficients are held fixed over the
//! horizon (for two materials: the sets `I_A,k`, `I_B,k` from the measured profile).

use super::errors::InkjetError;
use super::grid::Grid;
use super::height_model::{deposit_layer_into, for_each_share, increment_at_um, DropletCoeffs};
use super::objective::{objective_direct, CostSums, Target, Weight};

/// One decision variable of eq. 8: the droplet at `cell` in future layer `layer`
/// (`0` = the layer printed next).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Flip {
    /// Row-major cell index.
    pub cell: usize,
    /// Layer within the horizon, `0 ≤ layer < N`.
    pub layer: usize,
}

/// The data of one control step: measured profile, target, model and weight.
#[derive(Debug, Clone, Copy)]
pub struct Problem<'a> {
    /// The grid.
    pub grid: Grid,
    /// Measured profile `H_k` (the prediction's initial condition), µm, row-major.
    pub measured_um: &'a [f64],
    /// Desired geometry.
    pub target: &'a Target,
    /// Model coefficients per cell, used for every layer of the horizon.
    pub coeffs: &'a [DropletCoeffs],
    /// The weighting `α` of eq. 8.
    pub weight: Weight,
}

impl<'a> Problem<'a> {
    /// A checked problem: every per-cell input matches the target's grid.
    pub fn new(
        measured_um: &'a [f64],
        target: &'a Target,
        coeffs: &'a [DropletCoeffs],
        weight: Weight,
    ) -> Result<Self, InkjetError> {
        let grid = target.grid();
        grid.check_len("measured profile", measured_um.len())?;
        grid.check_len("coefficients", coeffs.len())?;
        for c in coeffs {
            c.check()?;
        }
        Ok(Self { grid, measured_um, target, coeffs, weight })
    }

    /// The predicted profiles `H_k, …, H_{k+N}` for the `N` patterns of `plan`.
    pub fn simulate(&self, plan: &[Vec<bool>]) -> Vec<Vec<f64>> {
        let mut layers = vec![self.measured_um.to_vec()];
        for pattern in plan {
            let mut next = vec![0.0; self.grid.len()];
            let before = layers.last().expect("layers starts non-empty");
            deposit_layer_into(self.grid, before, pattern, self.coeffs, &mut next);
            layers.push(next);
        }
        layers
    }
}

/// Eq. 8 after toggling `flip` in `plan`, by full re-simulation (the reference).
pub fn naive_objective_after_flip(problem: &Problem<'_>, plan: &[Vec<bool>], flip: Flip) -> f64 {
    let mut flipped = plan.to_vec();
    flipped[flip.layer][flip.cell] ^= true;
    let layers = problem.simulate(&flipped);
    objective_direct(problem.target, problem.weight, layers.last().expect("N+1 layers"))
}

/// The outcome of evaluating one flip against the current state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlipDelta {
    /// Change of the running sums of the final predicted layer.
    pub sums: CostSums,
    /// Eq. 8 after the flip.
    pub objective: f64,
}

/// Reusable buffers of one flip evaluation (one per worker thread).
#[derive(Debug, Clone, Default)]
pub struct FlipScratch {
    patches: Vec<Patch>,
}

impl FlipScratch {
    /// Buffers for a horizon of `horizon` layers.
    pub fn new(horizon: usize) -> Self {
        let patches = (1..=horizon)
            .map(|r| Patch { window: Window::default(), values: Vec::with_capacity((2 * r + 1).pow(2)) })
            .collect();
        Self { patches }
    }
}

/// A plan, its predicted profiles and the running sums of its final profile.
#[derive(Debug, Clone)]
pub struct HorizonState<'a> {
    problem: Problem<'a>,
    plan: Vec<Vec<bool>>,
    layers_um: Vec<Vec<f64>>,
    sums: CostSums,
}

impl<'a> HorizonState<'a> {
    /// The state of `plan` (one row-major pattern per horizon layer, `N ≥ 1`).
    pub fn new(problem: Problem<'a>, plan: Vec<Vec<bool>>) -> Self {
        assert!(!plan.is_empty(), "the horizon has at least one layer");
        let layers_um = problem.simulate(&plan);
        let sums = CostSums::of(problem.target, layers_um.last().expect("N+1 layers"));
        Self { problem, plan, layers_um, sums }
    }

    /// The grid.
    pub fn grid(&self) -> Grid {
        self.problem.grid
    }

    /// Horizon length `N`.
    pub fn horizon(&self) -> usize {
        self.plan.len()
    }

    /// The current patterns.
    pub fn plan(&self) -> &[Vec<bool>] {
        &self.plan
    }

    /// The predicted final profile `H̄(k+N)`.
    pub fn final_layer_um(&self) -> &[f64] {
        self.layers_um.last().expect("N+1 layers")
    }

    /// Eq. 8 of the current plan.
    pub fn objective(&self) -> f64 {
        self.objective_with(CostSums::default())
    }

    /// Eq. 8 if the running sums changed by `delta`.
    pub fn objective_with(&self, delta: CostSums) -> f64 {
        let n = self.problem.target.cells().len();
        self.sums.plus(delta).objective(self.problem.weight, n)
    }

    /// Recomputes the running sums from the final profile (removes rounding drift).
    pub fn resync(&mut self) {
        self.sums = CostSums::of(self.problem.target, self.final_layer_um());
    }

    /// Incremental eq. 8 after toggling `flip`, touching only the cells it can change.
    pub fn evaluate(&self, flip: Flip, scratch: &mut FlipScratch) -> FlipDelta {
        self.propagate(flip, scratch);
        let last = &scratch.patches[self.horizon() - flip.layer - 1];
        let sums = self.final_delta(last);
        FlipDelta { sums, objective: self.objective_with(sums) }
    }

    /// Applies `flip`: toggles the variable and writes the changed cells of every
    /// predicted layer. Returns the delta it applied.
    pub fn commit(&mut self, flip: Flip, scratch: &mut FlipScratch) -> FlipDelta {
        let delta = self.evaluate(flip, scratch);
        let grid = self.problem.grid;
        for (k, patch) in scratch.patches[..self.horizon() - flip.layer].iter().enumerate() {
            let layer = &mut self.layers_um[flip.layer + 1 + k];
            patch.window.for_each(|i, j, local| {
                layer[grid.index(i, j)] = patch.values[local];
            });
        }
        self.plan[flip.layer][flip.cell] ^= true;
        self.sums = self.sums.plus(delta.sums);
        delta
    }

    /// Fills `scratch.patches[k]` with the flipped profile of layer `flip.layer + 1 + k`
    /// on the window of radius `k + 1` around the flipped cell.
    fn propagate(&self, flip: Flip, scratch: &mut FlipScratch) {
        let grid = self.problem.grid;
        let (pi, pj) = grid.coords(flip.cell);
        let sign = if self.plan[flip.layer][flip.cell] { -1.0 } else { 1.0 };
        // First changed layer: the old profile plus or minus this droplet's shares.
        let first = &mut scratch.patches[0];
        first.load(Window::around(grid, pi, pj, 1), grid, &self.layers_um[flip.layer + 1]);
        let before = &self.layers_um[flip.layer];
        let coeffs = self.problem.coeffs[flip.cell];
        for_each_share(grid, before, flip.cell, coeffs, |q, amount| {
            let (qi, qj) = grid.coords(q);
            let local = first.window.local(qi, qj);
            first.values[local] += sign * amount;
        });
        // Later layers: re-simulate the growing window from the changed profile.
        for k in 1..self.horizon() - flip.layer {
            let (done, rest) = scratch.patches.split_at_mut(k);
            self.advance(&done[k - 1], flip.layer + k, (pi, pj, k + 1), &mut rest[0]);
        }
    }

    /// Computes layer `layer + 1` on the window of radius `r` around `(pi, pj)` from
    /// `prev` (the changed part of layer `layer`) and the stored profile elsewhere.
    fn advance(&self, prev: &Patch, layer: usize, (pi, pj, r): (usize, usize, usize), out: &mut Patch) {
        let grid = self.problem.grid;
        let base = &self.layers_um[layer];
        let height_at = |i: usize, j: usize, c: usize| {
            if prev.window.contains(i, j) {
                prev.values[prev.window.local(i, j)]
            } else {
                base[c]
            }
        };
        out.window = Window::around(grid, pi, pj, r);
        out.values.clear();
        let (pattern, coeffs) = (&self.plan[layer], self.problem.coeffs);
        out.window.for_each(|i, j, _| {
            let inc = increment_at_um(grid, i, j, height_at, pattern, coeffs);
            out.values.push(height_at(i, j, grid.index(i, j)) + inc);
        });
    }

    /// Change of the running sums when the final layer takes the values of `last`.
    fn final_delta(&self, last: &Patch) -> CostSums {
        let grid = self.problem.grid;
        let target = self.problem.target;
        let old = self.final_layer_um();
        let mut delta = CostSums::default();
        last.window.for_each(|i, j, local| {
            let c = grid.index(i, j);
            if target.footprint.droplet[c] {
                delta.add_cell(target, c, last.values[local], 1.0);
                delta.add_cell(target, c, old[c], -1.0);
            }
        });
        delta
    }
}

/// The changed values of one predicted layer on a window.
#[derive(Debug, Clone, Default)]
struct Patch {
    window: Window,
    values: Vec<f64>,
}

impl Patch {
    /// Copies `layer` on `window` into the patch.
    fn load(&mut self, window: Window, grid: Grid, layer: &[f64]) {
        self.window = window;
        self.values.clear();
        window.for_each(|i, j, _| self.values.push(layer[grid.index(i, j)]));
    }
}

/// An inclusive, grid-clipped box of cells.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Window {
    i0: usize,
    j0: usize,
    i1: usize,
    j1: usize,
}

impl Window {
    /// The cells within Chebyshev radius `r` of `(i, j)`, clipped to the grid.
    fn around(grid: Grid, i: usize, j: usize, r: usize) -> Self {
        Self {
            i0: i.saturating_sub(r),
            j0: j.saturating_sub(r),
            i1: (i + r).min(grid.m_x - 1),
            j1: (j + r).min(grid.m_y - 1),
        }
    }

    #[inline]
    fn contains(&self, i: usize, j: usize) -> bool {
        i >= self.i0 && i <= self.i1 && j >= self.j0 && j <= self.j1
    }

    #[inline]
    fn local(&self, i: usize, j: usize) -> usize {
        (j - self.j0) * (self.i1 - self.i0 + 1) + (i - self.i0)
    }

    /// Calls `f(i, j, local)` for every cell, row by row.
    #[inline]
    fn for_each(&self, mut f: impl FnMut(usize, usize, usize)) {
        let mut local = 0;
        for j in self.j0..=self.j1 {
            for i in self.i0..=self.i1 {
                f(i, j, local);
                local += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inkjet::grid::Pattern;
    use crate::inkjet::height_model::{uniform_coeffs, DropletCoeffs};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    struct Case {
        measured: Vec<f64>,
        target: Target,
        coeffs: Vec<DropletCoeffs>,
        plan: Vec<Vec<bool>>,
    }

    /// A random control step: rough profile, part of the grid as footprint, varied
    /// droplet coefficients and a random plan of `horizon` layers.
    fn random_case(rng: &mut ChaCha8Rng, m_x: usize, m_y: usize, horizon: usize) -> Case {
        let grid = Grid::new(m_x, m_y, 1.0).unwrap();
        let measured = (0..grid.len()).map(|_| rng.random_range(0.0..15.0)).collect();
        let mut footprint: Vec<bool> = (0..grid.len()).map(|_| rng.random_bool(0.8)).collect();
        footprint[0] = true;
        let footprint = Pattern::from_vec(grid, footprint).unwrap();
        let desired = (0..grid.len()).map(|_| rng.random_range(5.0..25.0)).collect();
        let target = Target::new(footprint, crate::inkjet::grid::HeightMap::from_vec(grid, desired).unwrap()).unwrap();
        let coeffs =
            (0..grid.len()).map(|_| DropletCoeffs::paper_table1().scaled(rng.random_range(0.6..1.4))).collect();
        let plan = (0..horizon).map(|_| (0..grid.len()).map(|_| rng.random_bool(0.5)).collect()).collect();
        Case { measured, target, coeffs, plan }
    }

    #[test]
    fn incremental_flip_cost_equals_full_resimulation() {
        let mut rng = ChaCha8Rng::seed_from_u64(2015);
        for (m_x, m_y, horizon) in [(1, 1, 1), (9, 1, 2), (7, 6, 1), (11, 9, 2), (12, 10, 3), (4, 3, 4)] {
            let case = random_case(&mut rng, m_x, m_y, horizon);
            let alpha = rng.random_range(0.0..=1.0);
            let problem =
                Problem::new(&case.measured, &case.target, &case.coeffs, Weight::new(alpha).unwrap()).unwrap();
            let state = HorizonState::new(problem, case.plan.clone());
            let mut scratch = FlipScratch::new(horizon);
            for _ in 0..60 {
                let flip = Flip { cell: rng.random_range(0..problem.grid.len()), layer: rng.random_range(0..horizon) };
                let fast = state.evaluate(flip, &mut scratch).objective;
                let slow = naive_objective_after_flip(&problem, &case.plan, flip);
                assert!((fast - slow).abs() < 1e-9, "{m_x}x{m_y} N={horizon}: {fast} vs {slow}");
            }
        }
    }

    #[test]
    fn committed_flips_keep_the_state_equal_to_a_fresh_simulation() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let case = random_case(&mut rng, 10, 8, 3);
        let problem = Problem::new(&case.measured, &case.target, &case.coeffs, Weight::new(0.4).unwrap()).unwrap();
        let mut state = HorizonState::new(problem, case.plan.clone());
        let mut scratch = FlipScratch::new(3);
        for _ in 0..40 {
            let flip = Flip { cell: rng.random_range(0..problem.grid.len()), layer: rng.random_range(0..3) };
            state.commit(flip, &mut scratch);
        }
        let fresh = HorizonState::new(problem, state.plan().to_vec());
        for (a, b) in state.layers_um.iter().zip(&fresh.layers_um) {
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() < 1e-9);
            }
        }
        assert!((state.objective() - fresh.objective()).abs() < 1e-9);
    }

    #[test]
    fn mismatched_inputs_are_errors() {
        let grid = Grid::new(3, 3, 1.0).unwrap();
        let target = Target::uniform(grid, Pattern::from_fn(grid, |_, _| true), 10.0).unwrap();
        let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        let weight = Weight::new(0.5).unwrap();
        assert!(Problem::new(&[0.0; 8], &target, &coeffs, weight).is_err());
        assert!(Problem::new(&[0.0; 9], &target, &coeffs[..4], weight).is_err());
        assert!(Problem::new(&[0.0; 9], &target, &coeffs, weight).is_ok());
    }
}
