//! Layer pattern laws of paper 002 (Sec. II, IV-A): the open-loop law (print the whole
//! footprint every layer, for a layer count fixed in advance) and the closed-loop law
//! `U_k = f_c(h_d, Y_k)` that solves eq. 8 on the measured profile before each layer.

use rand::Rng;

use super::errors::InkjetError;
use super::grid::{HeightMap, Pattern};
use super::height_model::DropletCoeffs;
use super::horizon::Problem;
use super::mpc::{optimise, MpcParams, SearchStats, ValidMpcParams};
use super::objective::Target;

/// Open-loop layer count: the desired height over the nominal layer height
/// `h1 + 4h2 + 4h3` (a uniform layer on a flat surface, eq. 2), rounded to the nearest
/// whole layer and at least one. Table I: 400 µm / 7.6 µm → 53 layers.
pub fn open_loop_layer_count(desired_um: f64, nominal: DropletCoeffs) -> usize {
    ((desired_um / nominal.droplet_volume_um()).round() as usize).max(1)
}

/// The open-loop pattern: a droplet at every footprint cell (`U_ijk = 1`, Sec. III-C).
pub fn open_loop_pattern(target: &Target) -> Pattern {
    target.footprint.clone()
}

/// The pattern chosen for the next layer and how the search went.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerDecision {
    /// Pattern to print next (the first layer of the optimised horizon).
    pub pattern: Pattern,
    /// Statistics of the search.
    pub stats: SearchStats,
}

impl LayerDecision {
    /// Whether the controller deposits nothing: the print is finished.
    ///
    /// With a horizon `N > 1` only the first layer's pattern is ever printed, so the
    /// print also stops when the optimiser postpones every droplet: re-planning on an
    /// unchanged profile would give the same empty first layer.
    pub fn is_finished(&self) -> bool {
        self.pattern.count() == 0
    }
}

/// The closed-loop law: eq. 8 solved by the stochastic greedy search, started from the
/// open-loop pattern repeated over the horizon.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosedLoopController {
    params: ValidMpcParams,
}

impl ClosedLoopController {
    /// A controller with checked parameters.
    pub fn new(params: MpcParams) -> Result<Self, InkjetError> {
        Ok(Self { params: params.check()? })
    }

    /// The checked parameters.
    pub fn params(&self) -> &ValidMpcParams {
        &self.params
    }

    /// The next layer's pattern for the measured profile `measured`, predicted with the
    /// per-cell model coefficients `coeffs`.
    pub fn next_pattern(
        &self,
        measured: &HeightMap,
        target: &Target,
        coeffs: &[DropletCoeffs],
        rng: &mut impl Rng,
    ) -> Result<LayerDecision, InkjetError> {
        if measured.grid != target.grid() {
            return Err(InkjetError::GridMismatch {
                what: "measured profile",
                found: measured.grid.len(),
                expected: target.grid().len(),
            });
        }
        let problem = Problem::new(&measured.height_um, target, coeffs, self.params.weight())?;
        let initial = vec![target.footprint.droplet.clone(); self.params.horizon()];
        let solution = optimise(problem, &self.params, initial, rng);
        let first = solution.plan.into_iter().next().expect("horizon >= 1");
        Ok(LayerDecision { pattern: Pattern::from_vec(measured.grid, first)?, stats: solution.stats })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inkjet::grid::Grid;
    use crate::inkjet::height_model::uniform_coeffs;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn open_loop_layer_counts_follow_the_nominal_layer_height() {
        let table1 = DropletCoeffs::paper_table1();
        // 7.6 µm per layer: 400 µm → 52.6 → 53 layers; 22.8 µm → exactly 3 layers.
        assert_eq!(open_loop_layer_count(400.0, table1), 53);
        assert_eq!(open_loop_layer_count(22.8, table1), 3);
        assert_eq!(open_loop_layer_count(1.0, table1), 1);
    }

    #[test]
    fn the_controller_stops_at_the_desired_height() {
        // A flat part already at the target: any droplet overshoots, so nothing is printed.
        let grid = Grid::new(8, 8, 1.0).unwrap();
        let footprint = Pattern::from_fn(grid, |x, y| (2.0..=5.0).contains(&x) && (2.0..=5.0).contains(&y));
        let target = Target::uniform(grid, footprint, 50.0).unwrap();
        let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        let controller = ClosedLoopController::new(MpcParams::recommended()).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let done = controller.next_pattern(&HeightMap::flat(grid, 50.0), &target, &coeffs, &mut rng).unwrap();
        assert!(done.is_finished());
        // Far below the target, the open-loop pattern is kept.
        let start = controller.next_pattern(&HeightMap::flat(grid, 0.0), &target, &coeffs, &mut rng).unwrap();
        assert_eq!(start.pattern, target.footprint);
    }
}
