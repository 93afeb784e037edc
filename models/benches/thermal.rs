//! Benchmarks of the paper-003 models (Chen et al.): the filtered B-spline compensation
//! solve for one corner span (Sec. 2.4, eqs 36-39; the paper reports about 0.5 s per
//! corner including image processing on a laptop with a GPU, Sec. 3.3) and the deposition
//! direction allocation (Sec. 2.2) on the whole corner test trajectory.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use std::hint::black_box;

use models::thermal::compensation::{solve_fbs, FbsParams};
use models::thermal::dda::{allocate_directions, DdaParams};
use models::thermal::dynamics::first_order_lag;
use models::thermal::{PrintSetup, Trajectory};

/// A corner's desired output change: a 0.25 s bump extended by 0.1 s at both ends
/// (450 samples at 1 ms), tall enough (6 mm/s) that the ±bounds of eq. 39 bind.
fn corner_desired_mm_s(peak_mm_s: f64) -> Vec<f64> {
    (0..450).map(|k| peak_mm_s * (-((k as f64 - 225.0) / 50.0).powi(2)).exp()).collect()
}

fn compensation(c: &mut Criterion) {
    let params = FbsParams::paper_defaults();
    let mut group = c.benchmark_group("thermal_fbs_corner");
    for peak in [1.0, 6.0] {
        let desired = corner_desired_mm_s(peak);
        let id = BenchmarkId::new("450_samples_knots_20ms", format!("peak={peak}mm_s"));
        group.bench_function(id, |b| b.iter(|| solve_fbs(black_box(&desired), 0.001, &params).expect("solvable")));
    }
    group.finish();
}

fn direction_allocation(c: &mut Criterion) {
    let setup = PrintSetup::paper_defaults();
    let tr = Trajectory::corner_test(&setup).expect("corner test path plans");
    let commanded: Vec<f64> = tr.speed_mm_s().iter().map(|v| setup.nominal_flow_mm3_s(*v)).collect();
    let flow = first_order_lag(&commanded, tr.dt_s, setup.tau_s, 0.0);
    let mut group = c.benchmark_group("thermal_dda");
    group.sample_size(20);
    group.bench_function(BenchmarkId::new("corner_test", format!("{}_samples", tr.len())), |b| {
        b.iter(|| {
            allocate_directions(black_box(&tr), &flow, setup.layer_height_mm, &DdaParams::default()).expect("allocates")
        })
    });
    group.finish();
}

criterion_group!(benches, compensation, direction_allocation);
criterion_main!(benches);
