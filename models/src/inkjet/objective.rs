//! The cost of paper 002 eq. 8 and the target it is measured against:
//! `J = α·avg|h_d − H̄(k+N)| + (1 − α)·std(H̄(k+N))`.
//!
//! The paper averages over the whole `m_x × m_y` grid; here both terms run over the
//! target *footprint* (the cells of the part's cross-section), because cells outside
//! the part are never printed and their height is not part of the specification. For a
//! fully printable grid (the Sec. IV-C recovery check) the two readings coincide.
//! `std` is the population standard deviation (divide by the number of cells).
//!
//! [`CostSums`] keeps the running sums `Σ|h_d − H|`, `Σ(H − s)` and `Σ(H − s)²` from
//! which `J` follows in O(1), so that the controller can score a flip from the few cells
//! it changes. The shift `s` (the mean desired height) keeps `Σ(H − s)²` well
//! conditioned.

use super::errors::InkjetError;
use super::grid::{Grid, HeightMap, Pattern};

/// The desired geometry: which cells belong to the part, and their desired heights.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// Cells of the part's footprint: the decision cells of the controller and the cells
    /// eq. 8 averages over.
    pub footprint: Pattern,
    /// Desired height `h_d` of every cell in µm (only footprint cells are used).
    pub desired: HeightMap,
    cells: Vec<usize>,
    shift_um: f64,
}

impl Target {
    /// A target from a footprint and a desired-height map on the same grid.
    pub fn new(footprint: Pattern, desired: HeightMap) -> Result<Self, InkjetError> {
        desired.grid.check_pattern(&footprint)?;
        let cells = footprint.cells();
        if cells.is_empty() {
            return Err(InkjetError::EmptyFootprint);
        }
        let shift_um = cells.iter().map(|&c| desired.height_um[c]).sum::<f64>() / cells.len() as f64;
        Ok(Self { footprint, desired, cells, shift_um })
    }

    /// An extruded part: the same desired height `desired_um` over the whole footprint.
    pub fn uniform(grid: Grid, footprint: Pattern, desired_um: f64) -> Result<Self, InkjetError> {
        Self::new(footprint, HeightMap::flat(grid, desired_um))
    }

    /// The grid of the target.
    pub fn grid(&self) -> Grid {
        self.desired.grid
    }

    /// Row-major indices of the footprint cells.
    pub fn cells(&self) -> &[usize] {
        &self.cells
    }

    /// Mean desired height over the footprint, µm.
    pub fn mean_desired_um(&self) -> f64 {
        self.shift_um
    }
}

/// The weighting `α` of eq. 8 between mean absolute error and unevenness.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Weight {
    alpha: f64,
}

impl Weight {
    /// A checked weight, `0 ≤ α ≤ 1`.
    pub fn new(alpha: f64) -> Result<Self, InkjetError> {
        if (0.0..=1.0).contains(&alpha) {
            Ok(Self { alpha })
        } else {
            Err(InkjetError::InvalidParameter { name: "alpha", value: alpha, reason: "must lie in [0, 1]" })
        }
    }

    /// The value of `α`.
    pub fn alpha(self) -> f64 {
        self.alpha
    }
}

/// Running sums over the footprint from which eq. 8 follows in O(1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CostSums {
    /// `Σ |h_d − H|` in µm.
    pub abs_error_um: f64,
    /// `Σ (H − s)` in µm, `s` the target's mean desired height.
    pub dev_um: f64,
    /// `Σ (H − s)²` in µm².
    pub dev_sq_um2: f64,
}

impl CostSums {
    /// The sums for the heights `height_um` (one per grid cell).
    pub fn of(target: &Target, height_um: &[f64]) -> Self {
        let mut sums = Self::default();
        for &c in target.cells() {
            sums.add_cell(target, c, height_um[c], 1.0);
        }
        sums
    }

    /// Adds (`sign = 1`) or removes (`sign = −1`) the contribution of cell `c` at height
    /// `height_um`.
    #[inline]
    pub fn add_cell(&mut self, target: &Target, c: usize, height_um: f64, sign: f64) {
        let dev = height_um - target.shift_um;
        self.abs_error_um += sign * (target.desired.height_um[c] - height_um).abs();
        self.dev_um += sign * dev;
        self.dev_sq_um2 += sign * dev * dev;
    }

    /// Component-wise sum.
    pub fn plus(self, other: Self) -> Self {
        Self {
            abs_error_um: self.abs_error_um + other.abs_error_um,
            dev_um: self.dev_um + other.dev_um,
            dev_sq_um2: self.dev_sq_um2 + other.dev_sq_um2,
        }
    }

    /// Eq. 8 from the sums over `n` footprint cells.
    pub fn objective(self, weight: Weight, n: usize) -> f64 {
        let n = n as f64;
        let mean_dev = self.dev_um / n;
        let variance = (self.dev_sq_um2 / n - mean_dev * mean_dev).max(0.0);
        weight.alpha * self.abs_error_um / n + (1.0 - weight.alpha) * variance.sqrt()
    }
}

/// Eq. 8 computed directly (two passes, no running sums): the reference value.
pub fn objective_direct(target: &Target, weight: Weight, height_um: &[f64]) -> f64 {
    let cells = target.cells();
    let n = cells.len() as f64;
    let desired = &target.desired.height_um;
    let abs_error: f64 = cells.iter().map(|&c| (desired[c] - height_um[c]).abs()).sum();
    let mean: f64 = cells.iter().map(|&c| height_um[c]).sum::<f64>() / n;
    let variance: f64 = cells.iter().map(|&c| (height_um[c] - mean).powi(2)).sum::<f64>() / n;
    weight.alpha * abs_error / n + (1.0 - weight.alpha) * variance.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_sums_match_the_direct_objective() {
        let grid = Grid::new(4, 3, 1.0).unwrap();
        let footprint = Pattern::from_fn(grid, |x, _| x >= 1.0);
        let target = Target::uniform(grid, footprint, 400.0).unwrap();
        let heights: Vec<f64> = (0..12).map(|c| 380.0 + 3.7 * c as f64).collect();
        for alpha in [0.0, 0.3, 1.0] {
            let weight = Weight::new(alpha).unwrap();
            let sums = CostSums::of(&target, &heights);
            let fast = sums.objective(weight, target.cells().len());
            let slow = objective_direct(&target, weight, &heights);
            assert!((fast - slow).abs() < 1e-9, "{fast} vs {slow}");
        }
    }

    #[test]
    fn a_flat_part_at_the_desired_height_costs_nothing() {
        let grid = Grid::new(3, 3, 1.0).unwrap();
        let target = Target::uniform(grid, Pattern::from_fn(grid, |_, _| true), 22.8).unwrap();
        let weight = Weight::new(0.5).unwrap();
        assert!(objective_direct(&target, weight, &[22.8; 9]).abs() < 1e-12);
    }

    #[test]
    fn invalid_targets_and_weights_are_errors() {
        let grid = Grid::new(3, 3, 1.0).unwrap();
        assert_eq!(Target::uniform(grid, Pattern::empty(grid), 1.0), Err(InkjetError::EmptyFootprint));
        assert!(Weight::new(1.5).is_err());
        assert!(Weight::new(-0.1).is_err());
    }
}
