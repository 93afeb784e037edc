//! Criterion benchmarks of the thermal discrepancy domain (DESIGN §7): the whole engine
//! (5 candidates, 8 filmed layers as groups, up to 5 rounds) on a record the size of one
//! filmed corner test part (7120 trajectory samples per layer at 1 ms, a frame every
//! 1/8.7 s, a centre temperature per sample, straight-run widths), without and with a
//! flow τ 30 % above the nominal — the unit of `thermal.discrepancy`, of every draw of
//! `thermal.discovery_power` (the study of `specs/studies/discrepancy_thermal_power.toml`
//! is about 520 of them) and of every print of `thermal.control_gain`; and the τ fit
//! alone (Levenberg–Marquardt over eq. 34's lag of the whole layer).
//!
//! The record is built here in the model's own terms (speed ramps at a corner every
//! 0.4 s, deterministic pseudo-noise), not filmed: the virtual printer and the monitor
//! live in `datasets` and `stages`, which `models` does not depend on.

use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use discrepancy::{discover, Model, Settings};
use models::thermal::discrepancy::{
    Deposition, FrameObservation, RecordParts, TemperatureObservation, ThermalModel, ThermalRecord, WidthObservation,
    TAU_MISMATCH,
};
use models::thermal::dynamics::first_order_lag;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SAMPLES: usize = 7120;
const LAYERS: usize = 8;
const DT_S: f64 = 0.001;
const H_MM: f64 = 0.25;
const W0_MM: f64 = 0.45;
const TAU_S: f64 = 0.0873;

/// A layer's speed (a 0.04 s ramp to 20 mm/s after a corner every 0.4 s) and its
/// commanded flow w0·h·v.
fn flow_and_speed() -> (Vec<f64>, Vec<f64>) {
    let speed: Vec<f64> = (0..SAMPLES).map(|k| 20.0 * (0.05 + (k % 400) as f64 / 40.0).min(1.0)).collect();
    (speed.iter().map(|v| W0_MM * H_MM * v).collect(), speed)
}

/// A record of `LAYERS` layers whose flow lags with τ0·(1 + `tau_excess`).
fn record(tau_excess: f64) -> ThermalRecord {
    let (flow, speed) = flow_and_speed();
    let lagged = first_order_lag(&flow, DT_S, TAU_S * (1.0 + tau_excess), 0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (mut frames, mut temps, mut widths) = (vec![], vec![], vec![]);
    let duration_s = SAMPLES as f64 * DT_S;
    for layer in 0..LAYERS {
        for i in 0..62 {
            let recorded_time_s = i as f64 / 8.7;
            frames.push(FrameObservation { layer, recorded_time_s, offset_s: rng.random_range(-0.005..0.005) });
        }
        for k in 0..SAMPLES {
            let temp_c = 180.0 + 10.0 * (k as f64 * 0.003).sin() + rng.random_range(-1.0..1.0);
            temps.push(TemperatureObservation { layer, sample: k, t_s: k as f64 * DT_S, temp_c });
            if speed[k] >= 19.0 && k % 400 > 120 {
                let excess_mm = lagged[k] / (H_MM * speed[k]) - W0_MM;
                let width_mm = W0_MM + 0.002 + 1.2 * excess_mm + rng.random_range(-0.003..0.003);
                widths.push(WidthObservation { layer, sample: k, width_mm, age_s: 0.1 });
            }
        }
    }
    let deposition = Deposition {
        commanded_flow_mm3_s: &flow,
        speed_mm_s: &speed,
        dt_s: DT_S,
        layer_height_mm: H_MM,
        tau_s: TAU_S,
        bead_width_mm: W0_MM,
    };
    ThermalRecord::new(RecordParts {
        frames: &frames,
        temps: &temps,
        widths: &widths,
        deposition,
        samples: SAMPLES,
        layer_duration_s: duration_s,
        nozzle_temp_c: 230.0,
        bed_temp_c: 60.0,
    })
    .expect("a valid record")
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("thermal_discrepancy");
    group.sample_size(10).measurement_time(Duration::from_secs(20));
    let engine = Settings { max_rounds: 5, ..Settings::standard(1) };
    for (label, tau_excess, named) in
        [("engine_null_print", 0.0, vec![]), ("engine_tau_30pct_print", 0.3, vec![TAU_MISMATCH])]
    {
        let model = ThermalModel::new(record(tau_excess));
        let groups = model.record().layer_groups();
        let found = discover(&model, &groups, &[], &engine).unwrap();
        assert_eq!(found.named, named, "{label}: the engine should name what the record holds");
        group.bench_function(label, |b| b.iter(|| discover(&model, &groups, &[], &engine).unwrap()));
    }
    let model = ThermalModel::new(record(0.3));
    let groups = model.record().layer_groups();
    let train: Vec<_> = groups.iter().collect();
    group.bench_function("tau_fit_all_layers", |b| b.iter(|| model.fit(&[TAU_MISMATCH], &train, None).unwrap()));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
