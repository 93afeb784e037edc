//! Speed of the virtual thermal printer (DESIGN §5.3, paper 003 eqs 5-11 and 13-26):
//! one layer of the corner test path (7.1 s of printing, 7120 samples at 1 ms) laid by
//! the deposition direction allocation and the area-uniform spreading of each
//! millisecond's volume, and a five-layer part, whose layers are squeezed into the gap
//! over the part below (sequential: each layer needs the one beneath). The re-print
//! stage of `specs/chen2024.toml` prints 2 × 20 layers.

use criterion::{criterion_group, criterion_main, Criterion};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;

use datasets::thermal::deposition::print_part;
use datasets::thermal::Effects;
use models::thermal::{PrintSetup, Trajectory};

fn printer(c: &mut Criterion) {
    let setup = PrintSetup::paper_defaults();
    let trajectory = Trajectory::corner_test(&setup).expect("corner test path");
    let command = setup.conventional_command(&trajectory);
    let mut group = c.benchmark_group("thermal_printer");
    group.sample_size(10);
    for layers in [1, 5] {
        group.bench_function(format!("corner_test_{layers}_layers"), |b| {
            b.iter(|| {
                let mut rng = ChaCha8Rng::seed_from_u64(3);
                let printed = print_part(&setup, &trajectory, &command, layers, &Effects::none(), &mut rng);
                black_box(printed.expect("prints").len())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, printer);
criterion_main!(benches);
