//! Throughput of `vision::lines` (paper 000 Sec. III line widths) on one photo of a
//! 120 mm line at 40 px/mm (about 5000 × 260 px, rotated 1°, from the test renderer
//! `tests/support`), widths every 0.05 mm (2401 positions): the edge fit and the Otsu
//! baseline, each on one thread (a one-thread rayon pool, the setting for parallelism over
//! images) and on all threads. Throughput is in pixels of the photo.

#[path = "../tests/support/mod.rs"]
mod support;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::hint::black_box;
use vision::lines::{segment_edge_fit, segment_threshold_columns, DEFAULT_STEP_MM};

fn lines(c: &mut Criterion) {
    let scene = support::Scene::paper000(40.0, 1.0, false, 8, 11);
    let img = scene.render();
    let geom = scene.nominal_geometry();
    let pixels = (img.width * img.height) as u64;
    let all = rayon::current_num_threads();
    let mut group = c.benchmark_group("lines");
    group.throughput(Throughput::Elements(pixels));
    group.sample_size(20);
    for threads in [1, all] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool");
        let size = format!("{}x{}px_{threads}thr", img.width, img.height);
        group.bench_with_input(BenchmarkId::new("edge_fit", &size), &img, |b, img| {
            b.iter(|| pool.install(|| segment_edge_fit(black_box(img), &geom, DEFAULT_STEP_MM).expect("segments")))
        });
        group.bench_with_input(BenchmarkId::new("otsu_columns", &size), &img, |b, img| {
            b.iter(|| {
                pool.install(|| segment_threshold_columns(black_box(img), &geom, DEFAULT_STEP_MM).expect("segments"))
            })
        });
    }
    group.finish();
}

criterion_group!(benches, lines);
criterion_main!(benches);
