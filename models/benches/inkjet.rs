//! Benchmarks of the paper-002 controller (Lu, Zheng, Mishra 2015, Sec. IV-C): one
//! closed-loop layer (eq. 8 solved by the stochastic greedy search) on a 100 × 100 grid,
//! and single-flip evaluations per second, incremental (local window + running sums)
//! against naive (full re-simulation of the horizon), at horizons N = 1 and 2.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

use models::inkjet::controller::ClosedLoopController;
use models::inkjet::experiments::TruthPrinter;
use models::inkjet::height_model::uniform_coeffs;
use models::inkjet::horizon::{naive_objective_after_flip, Flip, FlipScratch, HorizonState, Problem};
use models::inkjet::mpc::MpcParams;
use models::inkjet::objective::{Target, Weight};
use models::inkjet::{DropletCoeffs, Grid, HeightMap, Pattern};

const SIZE: usize = 100;

/// A disk-shaped part (radius 45 cells) printed open loop for 50 layers by a [0 20%]
/// truth printer, measured with 1 µm noise; the target is 4 µm above its mean height,
/// so the next layer needs roughly half the droplets: a late, busy control step.
struct Setup {
    measured: HeightMap,
    target: Target,
    coeffs: Vec<DropletCoeffs>,
}

fn setup() -> Setup {
    let grid = Grid::new(SIZE, SIZE, Grid::paper_spacing_um()).expect("valid grid");
    let centre = 49.5 * grid.spacing_um;
    let radius = 45.0 * grid.spacing_um;
    let footprint = Pattern::from_fn(grid, |x, y| (x - centre).powi(2) + (y - centre).powi(2) <= radius * radius);
    let truth = TruthPrinter::paper(0.2);
    let mut run = truth.start(grid, &mut ChaCha8Rng::seed_from_u64(42));
    let nominal = uniform_coeffs(grid, DropletCoeffs::paper_table1());
    for _ in 0..50 {
        run.print_layer(&footprint, &nominal).expect("pattern fits the grid");
    }
    let measured = run.measure();
    let heights = run.truth();
    let cells = footprint.cells();
    let mean = cells.iter().map(|&c| heights.height_um[c]).sum::<f64>() / cells.len() as f64;
    let target = Target::uniform(grid, footprint, mean + 4.0).expect("non-empty footprint");
    let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
    Setup { measured, target, coeffs }
}

fn closed_loop_layer(c: &mut Criterion) {
    let s = setup();
    let mut group = c.benchmark_group("inkjet_closed_loop_layer");
    group.sample_size(10);
    // M = 64 (the default) runs each subset on one thread; M = 1024 takes the
    // parallel path.
    for (horizon, subset_size) in [(1, 64), (1, 1024), (2, 64), (2, 1024)] {
        let params = MpcParams { horizon_layers: horizon, subset_size, ..MpcParams::recommended() };
        let controller = ClosedLoopController::new(params).expect("valid parameters");
        let id = BenchmarkId::new(format!("{SIZE}x{SIZE}"), format!("N={horizon}/M={subset_size}"));
        group.bench_function(id, |b| {
            b.iter(|| {
                let mut rng = ChaCha8Rng::seed_from_u64(7);
                let decision =
                    controller.next_pattern(&s.measured, &s.target, &s.coeffs, &mut rng).expect("valid problem");
                black_box(decision.pattern.count())
            })
        });
    }
    group.finish();
}

fn random_flips(target: &Target, horizon: usize, count: usize) -> Vec<Flip> {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let cells = target.cells();
    (0..count)
        .map(|_| Flip { cell: cells[rng.random_range(0..cells.len())], layer: rng.random_range(0..horizon) })
        .collect()
}

fn flip_evaluation(c: &mut Criterion) {
    let s = setup();
    let weight = Weight::new(MpcParams::recommended().alpha).expect("valid alpha");
    let problem = Problem::new(&s.measured.height_um, &s.target, &s.coeffs, weight).expect("valid problem");
    let mut group = c.benchmark_group("inkjet_flip_eval");
    group.sample_size(10);
    for horizon in [1, 2] {
        let plan = vec![s.target.footprint.droplet.clone(); horizon];
        let state = HorizonState::new(problem, plan.clone());
        let incremental = random_flips(&s.target, horizon, 10_000);
        group.throughput(Throughput::Elements(incremental.len() as u64));
        let id = BenchmarkId::new(format!("incremental/{SIZE}x{SIZE}"), format!("N={horizon}"));
        group.bench_function(id, |b| {
            let mut scratch = FlipScratch::new(horizon);
            b.iter(|| {
                let total: f64 = incremental.iter().map(|&flip| state.evaluate(flip, &mut scratch).objective).sum();
                black_box(total)
            })
        });
        let naive = random_flips(&s.target, horizon, 20);
        group.throughput(Throughput::Elements(naive.len() as u64));
        let id = BenchmarkId::new(format!("naive/{SIZE}x{SIZE}"), format!("N={horizon}"));
        group.bench_function(id, |b| {
            b.iter(|| {
                let total: f64 = naive.iter().map(|&flip| naive_objective_after_flip(&problem, &plan, flip)).sum();
                black_box(total)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, closed_loop_layer, flip_evaluation);
criterion_main!(benches);
