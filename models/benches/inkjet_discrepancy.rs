//! Criterion benchmarks of the ink-jet discrepancy domain (DESIGN §7): one filter run
//! of the layer-to-layer model through a print, and the whole engine (6 candidates,
//! 10 layer blocks, up to 3 rounds) on a print without and with a hidden effect — the
//! unit of `inkjet.discrepancy` and of every draw of `inkjet.discovery_power` (the study
//! of `specs/studies/discrepancy_inkjet_power.toml` is about 560 of them).

use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use discrepancy::{discover, Settings};
use models::inkjet::discrepancy::power::{print_of, PrintDesign};
use models::inkjet::discrepancy::{InkjetModel, LayerBlock};
use models::inkjet::experiments::{run_print, ControlLaw};
use models::inkjet::printer::{Effect, Effects};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const DESIGN: PrintDesign = PrintDesign { radius_cells: 10, layers: 40, max_shortfall: 0.2, layers_per_group: 4 };

fn print(effects: Effects) -> (InkjetModel, Vec<LayerBlock>) {
    let scenario = DESIGN.scenario(effects);
    let (_, recording) = run_print(&scenario, ControlLaw::OpenLoop, &mut ChaCha8Rng::seed_from_u64(7), true).unwrap();
    let model = InkjetModel::new(print_of(&scenario, &recording.unwrap()).unwrap());
    let blocks = model.print().blocks(DESIGN.layers_per_group);
    (model, blocks)
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("inkjet_discrepancy");
    group.sample_size(10).measurement_time(Duration::from_secs(20));
    let engine = Settings { bootstrap_draws: 200, ..Settings::standard(1) };
    for (label, effects) in [
        ("engine_null_print", Effects::none()),
        ("engine_nozzle_bias_print", Effects::none().with(Effect::NozzleBias, 0.02).unwrap()),
    ] {
        let (model, blocks) = print(effects);
        group.bench_function(label, |b| b.iter(|| discover(&model, &blocks, &[], &engine).unwrap()));
    }
    let (model, blocks) = print(Effects::none());
    let all: Vec<&LayerBlock> = blocks.iter().collect();
    group.bench_function("baseline_fit_and_predict", |b| {
        b.iter(|| {
            use discrepancy::Model;
            let fit = model.fit(&[], &all, None).unwrap();
            model.predict(&fit, &blocks[0], None).unwrap()
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
