//! Speed of the virtual FDM printer and its camera (DESIGN §5.1): one line of paper
//! 000 printed (lag, blob, cap, wander, rough edges; 2401 truth samples) and one photo
//! of it rendered at 40 px/mm (about 2 MP, 8-bit PNG), the work per line of
//! `amrepro datasets generate fdm`; throughput in megapixels per second.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

use datasets::fdm_lines::camera::{photograph, CameraSettings};
use models::fdm::kinematics::LineKinematics;
use models::fdm::printer::{print_line, Effects, PrinterProfile};

fn photos(c: &mut Criterion) {
    let profile = PrinterProfile::taz5();
    let kin = LineKinematics::paper_line(800.0, 150.0).expect("paper line");
    let mut group = c.benchmark_group("fdm_photos");
    group.sample_size(10);
    group.bench_function("print_line", |b| {
        b.iter(|| {
            let line = print_line(&profile, &Effects::default(), &kin, 150.0, &mut ChaCha8Rng::seed_from_u64(1));
            black_box(line.expect("prints").positions_mm.len())
        })
    });
    let line =
        print_line(&profile, &Effects::default(), &kin, 150.0, &mut ChaCha8Rng::seed_from_u64(1)).expect("prints");
    let settings = CameraSettings::default();
    let size = photograph(&line, 120.0, &settings, 0.0, &mut ChaCha8Rng::seed_from_u64(2)).expect("renders").size_px;
    group.throughput(Throughput::Elements((size.0 * size.1) as u64));
    group.bench_function("photograph_40px_per_mm", |b| {
        b.iter(|| {
            let photo = photograph(&line, 120.0, &settings, 0.0, &mut ChaCha8Rng::seed_from_u64(2));
            black_box(photo.expect("renders").png.len())
        })
    });
    group.finish();
}

criterion_group!(benches, photos);
criterion_main!(benches);
