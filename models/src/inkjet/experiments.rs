//! The simulation studies of paper 002 as pure functions: the cylinder of Figs 11-12
//! (Sec. V-A), the cuboid of Table II (Sec. V-D) and the exact-recovery check of
//! Sec. IV-C.
//!
//! A "truth" printer stands in for the machine (DESIGN §5.2): it follows the same height
//! model, but every droplet deposited has its `(h1, h2, h3)` scaled by `(1 − u)`,
//! `u ~ U[0, p]` drawn independently per droplet and layer (our reading of the paper's
//! "[0 20%] / [0 40%] variation on h1, h2 and h3": a droplet-volume shortfall). The
//! profiler returns the true profile plus 1 µm Gaussian noise (Sec. V-B: 1 µm
//! repeatability); its lateral resolution is the droplet grid. The controller predicts
//! with the nominal Table I coefficients.
//!
//! Metrics over the footprint (Figs 11-12 report "mean error" and "std"): the mean error
//! is `|mean(h_d − H)|`, the error of the average height. The paper's closed-loop pair
//! (0.7 µm mean error with a 4.1 µm std) rules out the mean absolute error, which for
//! that spread would be about 3 µm. Table II's "Z-axis RMSD" is read as
//! `sqrt(mean((H − h_d)²))`, the RMS deviation from the desired height.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::controller::{open_loop_layer_count, ClosedLoopController};
use super::errors::InkjetError;
use super::grid::{Grid, HeightMap, Pattern};
use super::height_model::{deposit_layer_into, uniform_coeffs, DropletCoeffs};
use super::horizon::Problem;
use super::mpc::{optimise, MpcParams};
use super::objective::Target;

/// The simulated machine: nominal droplets with a random volume shortfall, and a noisy
/// profiler.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthPrinter {
    /// Nominal droplet coefficients (Table I).
    pub nominal: DropletCoeffs,
    /// Largest shortfall `p`: each droplet is scaled by `1 − u`, `u ~ U[0, p]`.
    pub max_shortfall: f64,
    /// Standard deviation of the profiler noise, µm.
    pub noise_um: f64,
}

impl TruthPrinter {
    /// Table I droplets, shortfall `U[0, p]`, 1 µm profiler noise (Sec. V-B).
    pub fn paper(max_shortfall: f64) -> Self {
        Self { nominal: DropletCoeffs::paper_table1(), max_shortfall, noise_um: 1.0 }
    }

    /// Prints `pattern` on the true profile `heights` (in place), drawing one shortfall
    /// per droplet in row-major order.
    pub fn print_layer(&self, heights: &mut HeightMap, pattern: &Pattern, rng: &mut impl Rng) {
        let coeffs: Vec<DropletCoeffs> = pattern
            .droplet
            .iter()
            .map(|&d| {
                let u = if d { rng.random_range(0.0..=self.max_shortfall) } else { 0.0 };
                self.nominal.scaled(1.0 - u)
            })
            .collect();
        let before = heights.height_um.clone();
        deposit_layer_into(heights.grid, &before, &pattern.droplet, &coeffs, &mut heights.height_um);
    }

    /// What the profiler reports for the true profile `heights`.
    pub fn measure(&self, heights: &HeightMap, rng: &mut impl Rng) -> HeightMap {
        let noise = Normal::new(0.0, self.noise_um).expect("finite, non-negative noise");
        let height_um = heights.height_um.iter().map(|h| h + noise.sample(rng)).collect();
        HeightMap { grid: heights.grid, height_um }
    }
}

/// A print job: part, machine, and both control laws' settings.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// The desired part.
    pub target: Target,
    /// The coefficients the controller predicts with (nominal Table I).
    pub model: DropletCoeffs,
    /// The simulated machine.
    pub truth: TruthPrinter,
    /// Layers printed by the open-loop law.
    pub open_loop_layers: usize,
    /// Closed-loop controller parameters.
    pub mpc: MpcParams,
    /// Safety cap on the closed-loop layer count (never reached in our scenarios).
    pub max_layers: usize,
}

/// Cylinder of Figs 11-12: `h_d = 400 µm` on the Table I grid, open loop 53 layers
/// (400 / 7.6 µm).
///
/// The paper gives neither the grid nor the cylinder's diameter. We use a 37 × 37 grid
/// (9.7 mm square) and a footprint of radius 15.5 spacings (4.1 mm, 749 cells), with 3
/// unprinted cells between the part and the grid boundary so that the boundary rule
/// never acts. The radius sets the share of edge loss in the open-loop mean error; 15
/// cells gives 44.4 / 84.0 µm against the paper's 44.1 / 84.7 µm (radius 10: 47.6 /
/// 86.9, radius 25: 41.7 / 81.6). The open-loop std is not as large as the paper's for
/// any radius: the corrected model's dome after 53 layers is about 20 µm deep at the
/// rim, which gives a std of at most 7 µm (paper: 15.0 / 16.6 µm).
pub fn cylinder(max_shortfall: f64) -> Scenario {
    cylinder_with_radius(max_shortfall, 15)
}

/// The cylinder scenario with a footprint radius of `radius_cells` droplet spacings and
/// a 3-cell margin.
pub fn cylinder_with_radius(max_shortfall: f64, radius_cells: usize) -> Scenario {
    let m = 2 * radius_cells + 1 + 6;
    let grid = Grid::new(m, m, Grid::paper_spacing_um()).expect("valid grid");
    let (centre_um, radius_um) = ((m / 2) as f64 * grid.spacing_um, (radius_cells as f64 + 0.5) * grid.spacing_um);
    let footprint =
        Pattern::from_fn(grid, |x, y| (x - centre_um).powi(2) + (y - centre_um).powi(2) <= radius_um * radius_um);
    paper_scenario(grid, footprint, 400.0, max_shortfall, None)
}

/// Cuboid of Table II (Sec. V-D-2): 2106 × 2106 µm, i.e. 8 × 8 droplets at the Table I
/// spacing, `h_d = 22.8 µm`, on a 14 × 14 grid (3 unprinted cells around).
///
/// The open-loop cuboid gets the nominal layer count, 22.8 / 7.6 = 3 layers: Table II's
/// "ideal model" average of 22.8 µm is exactly three additive layers. (The four-layer
/// cuboid of Sec. V-D-1 and Figs 21-22 is the separate model-verification print; use
/// [`cuboid_with_layers`] for it.) Table II's open-loop average of 18.5 µm is closest to
/// the `[0 20%]` shortfall (our average: 19.2 µm).
pub fn cuboid(max_shortfall: f64) -> Scenario {
    cuboid_with_layers(max_shortfall, None)
}

/// The cuboid scenario with `open_loop_layers` open-loop layers (`None`: the nominal
/// count, 3).
pub fn cuboid_with_layers(max_shortfall: f64, open_loop_layers: Option<usize>) -> Scenario {
    let grid = Grid::new(14, 14, Grid::paper_spacing_um()).expect("valid grid");
    let (lo, hi) = (3.0 * grid.spacing_um, 10.5 * grid.spacing_um);
    let footprint = Pattern::from_fn(grid, |x, y| x >= lo && x <= hi && y >= lo && y <= hi);
    paper_scenario(grid, footprint, 22.8, max_shortfall, open_loop_layers)
}

fn paper_scenario(
    grid: Grid,
    footprint: Pattern,
    desired_um: f64,
    max_shortfall: f64,
    open_loop_layers: Option<usize>,
) -> Scenario {
    let model = DropletCoeffs::paper_table1();
    let open_loop_layers = open_loop_layers.unwrap_or(open_loop_layer_count(desired_um, model));
    Scenario {
        target: Target::uniform(grid, footprint, desired_um).expect("non-empty footprint"),
        model,
        truth: TruthPrinter::paper(max_shortfall),
        open_loop_layers,
        mpc: MpcParams::recommended(),
        max_layers: 4 * open_loop_layers + 10,
    }
}

/// Quality of a printed part over its footprint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrintMetrics {
    /// `|mean(h_d − H)|`, the "mean error" of Figs 11-12, µm.
    pub mean_error_um: f64,
    /// `mean |h_d − H|`, µm (reported alongside).
    pub mean_abs_error_um: f64,
    /// Population std of `H`, µm.
    pub std_um: f64,
    /// `sqrt(mean((H − h_d)²))`, Table II's "Z-axis RMSD", µm.
    pub rmsd_um: f64,
    /// Average height `mean(H)`, µm.
    pub average_height_um: f64,
}

impl PrintMetrics {
    /// Metrics of `heights` against `target`.
    pub fn of(target: &Target, heights: &HeightMap) -> Self {
        let cells = target.cells();
        let n = cells.len() as f64;
        let h = |c: usize| heights.height_um[c];
        let error = |c: usize| target.desired.height_um[c] - h(c);
        let mean_error: f64 = cells.iter().map(|&c| error(c)).sum::<f64>() / n;
        let average = cells.iter().map(|&c| h(c)).sum::<f64>() / n;
        let variance = cells.iter().map(|&c| (h(c) - average).powi(2)).sum::<f64>() / n;
        let mse = cells.iter().map(|&c| error(c).powi(2)).sum::<f64>() / n;
        Self {
            mean_error_um: mean_error.abs(),
            mean_abs_error_um: cells.iter().map(|&c| error(c).abs()).sum::<f64>() / n,
            std_um: variance.sqrt(),
            rmsd_um: mse.sqrt(),
            average_height_um: average,
        }
    }
}

/// The result of one simulated print.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintOutcome {
    /// True final profile.
    pub final_heights: HeightMap,
    /// Metrics over the footprint.
    pub metrics: PrintMetrics,
    /// Number of layers printed.
    pub layers_printed: usize,
    /// Number of droplets printed.
    pub droplets_printed: usize,
}

/// Open-loop print: the whole footprint, `scenario.open_loop_layers` times, on a flat
/// substrate at height 0.
pub fn run_open_loop(scenario: &Scenario, rng: &mut impl Rng) -> PrintOutcome {
    let grid = scenario.target.grid();
    let mut heights = HeightMap::flat(grid, 0.0);
    let pattern = &scenario.target.footprint;
    for _ in 0..scenario.open_loop_layers {
        scenario.truth.print_layer(&mut heights, pattern, rng);
    }
    outcome(scenario, heights, scenario.open_loop_layers, pattern.count() * scenario.open_loop_layers)
}

/// Closed-loop print: before each layer, measure, solve eq. 8 and print the first
/// pattern of the plan; stop when the controller deposits nothing.
pub fn run_closed_loop(scenario: &Scenario, rng: &mut impl Rng) -> Result<PrintOutcome, InkjetError> {
    let grid = scenario.target.grid();
    let controller = ClosedLoopController::new(scenario.mpc)?;
    let coeffs = uniform_coeffs(grid, scenario.model.check()?);
    let mut heights = HeightMap::flat(grid, 0.0);
    let (mut layers, mut droplets) = (0, 0);
    while layers < scenario.max_layers {
        let measured = scenario.truth.measure(&heights, rng);
        let decision = controller.next_pattern(&measured, &scenario.target, &coeffs, rng)?;
        if decision.is_finished() {
            break;
        }
        scenario.truth.print_layer(&mut heights, &decision.pattern, rng);
        layers += 1;
        droplets += decision.pattern.count();
    }
    Ok(outcome(scenario, heights, layers, droplets))
}

fn outcome(scenario: &Scenario, heights: HeightMap, layers: usize, droplets: usize) -> PrintOutcome {
    PrintOutcome {
        metrics: PrintMetrics::of(&scenario.target, &heights),
        final_heights: heights,
        layers_printed: layers,
        droplets_printed: droplets,
    }
}

/// One trial of the Sec. IV-C check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecoveryTrial {
    /// Cells where the found pattern differs from the applied one.
    pub flips_wrong: usize,
    /// Eq. 8 (`α = 1`) of the found pattern, µm (0 for an exact recovery).
    pub objective_um: f64,
    /// Number of droplets in the applied pattern.
    pub droplets_applied: usize,
}

/// The settings of the Sec. IV-C check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecoverySetup {
    /// Grid side (20 in the paper).
    pub size: usize,
    /// Initial heights are drawn from `U[0, max_initial_um]` (the paper: "certain random
    /// initial height"; we take one to two layers of roughness).
    pub max_initial_um: f64,
    /// Probability of a droplet in the applied random pattern ("random 0 and 1").
    pub droplet_probability: f64,
    /// Search parameters: the paper sets `α = 1`; horizon 1 (one layer is applied).
    pub mpc: MpcParams,
}

impl RecoverySetup {
    /// The paper's setting: 20 × 20 grid, `α = 1`, `N = 1`, Table I model; our choices:
    /// initial heights `U[0, 10 µm]`, droplets with probability 1/2, `M = 64`.
    pub fn paper() -> Self {
        Self {
            size: 20,
            max_initial_um: 10.0,
            droplet_probability: 0.5,
            mpc: MpcParams { alpha: 1.0, horizon_layers: 1, ..MpcParams::recommended() },
        }
    }
}

/// One recovery trial: apply a random pattern to a random profile with the nominal
/// model, then search for it from the all-ones pattern with `α = 1` and
/// `h_d = H_new`.
pub fn recovery_trial(setup: &RecoverySetup, rng: &mut impl Rng) -> Result<RecoveryTrial, InkjetError> {
    let grid = Grid::new(setup.size, setup.size, Grid::paper_spacing_um())?;
    let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
    let initial_um: Vec<f64> = (0..grid.len()).map(|_| rng.random_range(0.0..=setup.max_initial_um)).collect();
    let applied: Vec<bool> = (0..grid.len()).map(|_| rng.random_bool(setup.droplet_probability)).collect();
    let mut new_um = vec![0.0; grid.len()];
    deposit_layer_into(grid, &initial_um, &applied, &coeffs, &mut new_um);
    let everywhere = Pattern::from_vec(grid, vec![true; grid.len()])?;
    let target = Target::new(everywhere, HeightMap::from_vec(grid, new_um)?)?;
    let params = setup.mpc.check()?;
    let problem = Problem::new(&initial_um, &target, &coeffs, params.weight())?;
    let start = vec![vec![true; grid.len()]; params.horizon()];
    let solution = optimise(problem, &params, start, rng);
    let found = &solution.plan[0];
    Ok(RecoveryTrial {
        flips_wrong: found.iter().zip(&applied).filter(|(a, b)| a != b).count(),
        objective_um: solution.stats.objective_end,
        droplets_applied: applied.iter().filter(|&&d| d).count(),
    })
}

/// `trials` independent recovery trials, trial `t` seeded with `seed + t` (run in
/// parallel; the result does not depend on the thread count).
pub fn recovery_study(setup: &RecoverySetup, trials: usize, seed: u64) -> Result<Vec<RecoveryTrial>, InkjetError> {
    (0..trials as u64)
        .into_par_iter()
        .map(|t| recovery_trial(setup, &mut ChaCha8Rng::seed_from_u64(seed + t)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cylinder_matches_figs_11_and_12() {
        // Figs 11-12: open-loop mean error 44.1 µm ([0 20%]) and 84.7 µm ([0 40%]); we
        // require ±30 %. Closed loop: 0.7 / 1.9 µm mean error and 4.1 / 4.5 µm std in the
        // paper; we require < 2 µm and < 6 µm.
        for (p, paper_open_um, seed) in [(0.2, 44.1, 1), (0.4, 84.7, 2)] {
            let scenario = cylinder(p);
            assert_eq!(scenario.open_loop_layers, 53);
            let open = run_open_loop(&scenario, &mut ChaCha8Rng::seed_from_u64(seed));
            let closed = run_closed_loop(&scenario, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap();
            let ratio = open.metrics.mean_error_um / paper_open_um;
            assert!((0.7..=1.3).contains(&ratio), "p={p}: open-loop {:?}", open.metrics);
            assert!(closed.metrics.mean_error_um < 2.0, "p={p}: {:?}", closed.metrics);
            assert!(closed.metrics.std_um < 6.0, "p={p}: {:?}", closed.metrics);
            assert!(closed.metrics.std_um < open.metrics.std_um);
        }
    }

    #[test]
    fn cuboid_closed_loop_cuts_the_rmsd_as_in_table_2() {
        // Table II: open loop 18.5 µm average, RMSD 8.7; closed loop 22.3, RMSD 4.4
        // ("about half"). We require closed-loop RMSD <= 60 % of open loop, an open-loop
        // part lower than desired (edge shrink and shortfall) and a closed-loop average
        // within 1.5 µm of 22.8.
        for p in [0.2, 0.4] {
            for seed in 0..3 {
                let scenario = cuboid(p);
                assert_eq!(scenario.target.cells().len(), 64);
                let open = run_open_loop(&scenario, &mut ChaCha8Rng::seed_from_u64(seed));
                let closed = run_closed_loop(&scenario, &mut ChaCha8Rng::seed_from_u64(seed)).unwrap();
                assert!(
                    closed.metrics.rmsd_um <= 0.6 * open.metrics.rmsd_um,
                    "p={p} seed={seed}: {:?} vs {:?}",
                    closed.metrics,
                    open.metrics
                );
                assert!(open.metrics.average_height_um < 22.8 - 2.0);
                assert!((closed.metrics.average_height_um - 22.8).abs() < 1.5);
            }
        }
    }

    #[test]
    fn recovery_finds_the_applied_pattern_in_50_of_50_trials() {
        // Sec. IV-C: with alpha = 1 and h_d = H_new the applied pattern has zero cost; the
        // search from all ones found it in all 50 of the paper's random trials.
        let trials = recovery_study(&RecoverySetup::paper(), 50, 2015).unwrap();
        let wrong: Vec<usize> = trials.iter().map(|t| t.flips_wrong).collect();
        assert_eq!(wrong, vec![0; 50]);
        assert!(trials.iter().all(|t| t.objective_um < 1e-9));
        // The applied patterns are genuinely random (about half the 400 cells printed).
        assert!(trials.iter().all(|t| (140..260).contains(&t.droplets_applied)));
    }

    #[test]
    fn truth_printer_without_shortfall_or_noise_is_the_nominal_model() {
        let scenario = cuboid(0.0);
        let grid = scenario.target.grid();
        let truth = TruthPrinter { noise_um: 0.0, ..scenario.truth };
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut heights = HeightMap::flat(grid, 0.0);
        truth.print_layer(&mut heights, &scenario.target.footprint, &mut rng);
        let mut expected = vec![0.0; grid.len()];
        let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        deposit_layer_into(grid, &vec![0.0; grid.len()], &scenario.target.footprint.droplet, &coeffs, &mut expected);
        assert_eq!(heights.height_um, expected);
        assert_eq!(truth.measure(&heights, &mut rng), heights);
    }

    #[test]
    fn a_shortfall_only_ever_removes_volume() {
        // Each droplet adds between (1 - p)(h1 + 4h2 + 4h3) and h1 + 4h2 + 4h3.
        let scenario = cuboid(0.4);
        let mut heights = HeightMap::flat(scenario.target.grid(), 0.0);
        let pattern = &scenario.target.footprint;
        scenario.truth.print_layer(&mut heights, pattern, &mut ChaCha8Rng::seed_from_u64(3));
        let added: f64 = heights.height_um.iter().sum();
        let full = 7.6 * pattern.count() as f64;
        assert!(added < full && added > 0.6 * full);
    }

    #[test]
    fn metrics_of_a_known_profile() {
        let grid = Grid::new(2, 1, 1.0).unwrap();
        let target = Target::uniform(grid, Pattern::from_vec(grid, vec![true; 2]).unwrap(), 10.0).unwrap();
        let heights = HeightMap::from_vec(grid, vec![8.0, 14.0]).unwrap();
        let m = PrintMetrics::of(&target, &heights);
        // Errors -2 and +4 (H - h_d): mean error |1|, mean |error| 3, std 3, RMSD sqrt(10).
        assert!((m.mean_error_um - 1.0).abs() < 1e-12);
        assert!((m.mean_abs_error_um - 3.0).abs() < 1e-12);
        assert!((m.std_um - 3.0).abs() < 1e-12);
        assert!((m.rmsd_um - 10f64.sqrt()).abs() < 1e-12);
        assert!((m.average_height_um - 11.0).abs() < 1e-12);
    }
}
