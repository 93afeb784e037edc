//! Issue 53's speed target for `vision::photo`: one 2 MP photo of a 21-line
//! pressure-advance pattern (1080 × 1920 px at 20 px/mm, every habit of a cheap camera on:
//! distortion, tilt, textured plate, uneven light, a specular spot, a stray string, blur,
//! noise, JPEG) placed on the bed from its G-code alone and every path measured every
//! 0.05 mm, in at most 1 s on 2 cores. The photo comes from the virtual generator
//! (`datasets::fdm_photos::generate`, seeded), so the benchmark runs from a fresh clone
//! without the shared GPL photos; generating and decoding it happen outside the timed
//! work, and the setup checks that the photo is placed (every test line measured,
//! reprojection error below 0.1 mm), so a failed placement is never what is timed. Also
//! timed apart: the calibration alone and the measurement alone (on the calibration made
//! once beforehand).
//!
//! The virtual photo is an easier fit than the shared real ones: its finest level settles
//! in 2-3 iterations at a correlation of 0.91, theirs in 12-15 at 0.69
//! (docs/notes/2026-12-07-photos.md, Speed).

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use datasets::fdm_photos::generate::{generate, GenerateConfig};
use datasets::fdm_photos::FdmPhotos;
use vision::photo::measure::{measure_paths, reprojection_error, PathMeasurement};
use vision::photo::{calibrate, ColourImage, PrintedPath};

/// Positions along each path (mm), as `fdm.measure_photos` measures by default.
const STEP_MM: f64 = 0.05;
/// The generator's seed, one whose photo is placed the short way (its two 180° poses
/// equally good at 0.4 mm of blur, told apart by the print there), as the shared photos
/// are. Of seeds 1-8 only the photos of 4, 5 and 7 are placed at all at the generator's
/// default tilt (the scale changing by up to ±10 % across the pattern); the others lock
/// a wrong pose: an open problem (docs/notes/2026-12-07-photos.md).
const SEED: u64 = 4;
/// The setup's check that the photo was placed: the reprojection error (mm) below this,
/// as `fdm.measure_photos` reports it.
const PLACED_REPROJECTION_MM: f64 = 0.1;

/// One virtual photo of the shared pattern's layout and its G-code's paths.
fn virtual_photo() -> (ColourImage, Vec<PrintedPath>) {
    let tmp = tempfile::tempdir().expect("temporary folder");
    let dir = tmp.path().join("photos");
    generate(&GenerateConfig { photos: 1, ..GenerateConfig::new(SEED) }, &dir).expect("virtual photo");
    let data = FdmPhotos::read(&dir).expect("virtual dataset");
    let paths = data.lines.iter().map(PrintedPath::from_line).collect();
    let bytes = std::fs::read(&data.photos[0].image).expect("photo file");
    (ColourImage::decode(&bytes, 64 << 20).expect("decodes"), paths)
}

/// Panics unless every test line (one with speed changes) has widths and the bead centres
/// lie within [`PLACED_REPROJECTION_MM`] of their axes.
fn check_placed(measured: &[PathMeasurement], paths: &[PrintedPath]) {
    let unmeasured = measured
        .iter()
        .zip(paths)
        .filter(|(m, p)| p.speed_changes_mm.len() >= 2 && !m.samples.iter().any(|s| s.width_mm > 0.0))
        .count();
    let (rms, _) = reprojection_error(measured);
    assert!(
        unmeasured == 0 && rms < PLACED_REPROJECTION_MM,
        "seed {SEED}'s photo is not placed ({unmeasured} test lines unmeasured, reprojection {rms:.3} mm): the benchmark would time a failed calibration"
    );
}

fn photo(c: &mut Criterion) {
    let (img, paths) = virtual_photo();
    let lines = paths.iter().filter(|p| p.speed_changes_mm.len() >= 2).count();
    let cal = calibrate(&img, &paths, false).expect("placed");
    let contrast = cal.contrast_axis.apply(&img);
    check_placed(&measure_paths(&contrast, &paths, &cal.camera, STEP_MM), &paths);
    let size = format!("{}x{}px_{lines}_lines", img.width, img.height);
    let mut group = c.benchmark_group("photo");
    group.sample_size(10).measurement_time(Duration::from_secs(20));
    group.bench_with_input(BenchmarkId::new("calibrate_and_measure", &size), &img, |b, img| {
        b.iter(|| {
            let cal = calibrate(black_box(img), &paths, false).expect("placed");
            measure_paths(&cal.contrast_axis.apply(img), &paths, &cal.camera, STEP_MM)
        })
    });
    group.bench_with_input(BenchmarkId::new("calibrate", &size), &img, |b, img| {
        b.iter(|| calibrate(black_box(img), &paths, false).expect("placed"))
    });
    group.bench_with_input(BenchmarkId::new("measure", &size), &contrast, |b, contrast| {
        b.iter(|| measure_paths(black_box(contrast), &paths, &cal.camera, STEP_MM))
    });
    group.finish();
}

criterion_group!(benches, photo);
criterion_main!(benches);
