//! Criterion benchmarks of the discrepancy engine on paper 000's lines (DESIGN §7): the
//! whole engine on both printers (7 candidates, 9 lines each, up to 3 rounds; target
//! ≤ 2 s on 2 cores), one power-study draw per effect on the Taz 5 (the study of
//! `specs/discrepancy_fdm.toml` is about a thousand such draws; target ≤ 5 min), and one
//! line through the forward model. The real data are read from `$AMREPRO_DATA` or the
//! repository's `data/`; without them the benchmarks run on lines drawn from the forward
//! model with pixel-like noise, and say so.

use std::path::PathBuf;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use discrepancy::{discover, Settings};
use models::fdm::discrepancy::forward::{widths, LineSetting, Scratch, Theta};
use models::fdm::discrepancy::inject::{Effect, InjectSettings};
use models::fdm::discrepancy::power::{run_draws, Base, Noise, PowerDesign};
use models::fdm::discrepancy::{FdmLine, FdmModel};
use models::fdm::synthetic::TABLE_I;
use models::fdm::{LineKinematics, MeasuredLine};

fn data_dir() -> PathBuf {
    std::env::var("AMREPRO_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data"))
        .join("fsu-linewidth")
}

/// The real lines of `printer`, or lines from the forward model when the data are absent.
fn lines(printer: &str) -> Vec<FdmLine> {
    let suffix = if printer == "taz5" { "xiao120" } else { "ino120" };
    TABLE_I
        .iter()
        .enumerate()
        .map(|(k, &(a, f))| {
            let label = format!("S{}F{}", a as u32, (f * 60.0) as u32);
            let nominal = LineKinematics::paper_line(a, f).unwrap();
            let file = data_dir().join(printer).join(format!("{label}_{suffix}.csv"));
            let (xs, ws) = match std::fs::read_to_string(&file) {
                Ok(text) => text
                    .lines()
                    .filter(|r| !r.trim().is_empty())
                    .map(|r| {
                        let mut it = r.split(',').map(|v| v.trim().parse::<f64>().unwrap());
                        (it.next().unwrap(), it.next().unwrap())
                    })
                    .unzip(),
                Err(_) => synthetic(&nominal, k),
            };
            FdmLine::new(label, MeasuredLine::new(nominal, xs, ws).unwrap())
        })
        .collect()
}

fn synthetic(nominal: &LineKinematics, k: usize) -> (Vec<f64>, Vec<f64>) {
    eprintln!("note: {} missing, benchmarking on synthetic lines", data_dir().display());
    let xs: Vec<f64> = (0..2500).map(|i| i as f64 * 0.048).collect();
    let mut ws = vec![0.0; xs.len()];
    let theta = Theta { max_excess_mm: 0.2, ..Theta::lag(0.09, 0.78, 12.0) };
    let setting = LineSetting { smoothing_mm: 0.5, v_ref_mm_s: 150.0 };
    widths(&theta, nominal, &setting, &xs, &mut Scratch::default(), &mut ws);
    for (i, w) in ws.iter_mut().enumerate() {
        *w += 0.048 * (((i * 31 + k * 7) as f64).sin() * 0.5).round();
    }
    (xs, ws)
}

fn bench_engine(c: &mut Criterion) {
    let printers = [(lines("taz5"), true), (lines("taz6"), false)];
    let settings = Settings::standard(1);
    let mut g = c.benchmark_group("discrepancy_engine");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    g.bench_function("both_printers_7_candidates_9_lines_3_rounds", |b| {
        b.iter(|| {
            for (l, blob) in &printers {
                let model = FdmModel::new(l, *blob, 0.5);
                std::hint::black_box(discover(&model, l, &[], &settings).unwrap());
            }
        })
    });
    g.finish();
}

fn bench_power_draw(c: &mut Criterion) {
    let taz5 = lines("taz5");
    let model = FdmModel::new(&taz5, true, 0.5);
    let engine = Settings { bootstrap_draws: 500, ..Settings::standard(1) };
    let base = Base::new("taz5", model, taz5, &engine).unwrap();
    let design = PowerDesign {
        cells: vec![(Effect::BedTilt, 0.05), (Effect::GearEccentricity, 0.05), (Effect::FlowSaturation, 0.1)],
        draws_per_cell: 1,
        null_draws: 1,
        seed: 3,
        engine,
        inject: InjectSettings::default(),
        noise: Noise::Measured,
    };
    let mut g = c.benchmark_group("discovery_power");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    g.bench_function("taz5_4_draws_null_tilt_gear_saturation", |b| {
        b.iter(|| std::hint::black_box(run_draws(&base, &design).unwrap()))
    });
    g.finish();
}

fn bench_forward(c: &mut Criterion) {
    let nominal = LineKinematics::paper_line(800.0, 150.0).unwrap();
    let xs: Vec<f64> = (0..200).map(|i| i as f64 * 0.6).collect();
    let setting = LineSetting { smoothing_mm: 0.5, v_ref_mm_s: 150.0 };
    let linear = Theta { max_excess_mm: 0.2, slow_fraction: 0.3, tau_slow_s: 0.5, ..Theta::lag(0.09, 0.78, 12.0) };
    let nonlinear = Theta { lag_offset_s: 0.2, lag_speed_mm_s: 30.0, ..linear };
    let mut out = vec![0.0; xs.len()];
    let mut g = c.benchmark_group("fdm_forward_line");
    for (name, theta) in [("two_stage_cap_200_samples", linear), ("nonlinear_lag_200_samples", nonlinear)] {
        g.bench_function(name, |b| {
            b.iter(|| {
                // A fresh state: every call integrates (no cached lag response).
                let mut scratch = Scratch::default();
                widths(&theta, &nominal, &setting, &xs, &mut scratch, &mut out)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_forward, bench_engine, bench_power_draw);
criterion_main!(benches);
