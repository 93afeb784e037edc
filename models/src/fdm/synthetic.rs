//! Synthetic ground truth for tests and benchmarks of the paper-000 models: the nine
//! Table I conditions and a plausible known piecewise model (eqs 2-3) from which
//! noiseless widths are drawn, so fits can be checked for parameter recovery; and a
//! pressure-advance pattern of slow–fast–slow lines with the widths a known lag lays.

use super::kinematics::LineKinematics;
use super::line::MeasuredLine;
use super::pa_tuning::MeasuredLine as PaMeasuredLine;
use super::piecewise::{Bp1PowerLaw, PiecewiseCoefficients};
use super::planner::{plan, Cornering, MotionLimits, Move, PressureAdvance};
use super::predict::FittedPiecewise;
use super::pressure_advance::deposit_line;
use super::printed_lines::{printed_lines, PrintedLine};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Table I conditions `(a mm/s², F mm/s)` in the paper's sample order 1-9.
pub const TABLE_I: [(f64, f64); 9] = [
    (800.0, 150.0),
    (800.0, 100.0),
    (800.0, 50.0),
    (600.0, 150.0),
    (600.0, 100.0),
    (600.0, 50.0),
    (400.0, 150.0),
    (400.0, 100.0),
    (400.0, 50.0),
];

/// A plausible Taz-5-like model (with blob) or Taz-6-like (without), at `r_a = 1.03`,
/// `r_F = 0.97` (both on the 0.01 grid).
pub fn synthetic_truth(blob: bool) -> FittedPiecewise {
    FittedPiecewise {
        r_a: 1.03,
        r_f: 0.97,
        coefficients: PiecewiseCoefficients {
            alpha1: 0.03,
            alpha2: 1.0,
            beta: 0.004,
            gamma: 0.02,
            c_mm: 0.8,
            rho: 0.12,
            w_start_mm: 0.5,
        },
        bp1_law: blob.then_some(Bp1PowerLaw { c0_s: 0.01, c1: 4.0, c2: -0.8 }),
        has_start_blob: blob,
        training_rmse_mm: 0.0,
        lambda: 0.0,
    }
}

/// The nine Table I lines of [`synthetic_truth`]`(blob)`, sampled every 0.048 mm (the
/// real data's step, 2500 samples), each width `w` turned into
/// `scale·(w + bump·sin(13 i + 5 k))` (sample `i` of line `k`): the perturbation keeps
/// fits from being exact, `scale` stands for another nozzle. The benchmarks' printers.
pub fn perturbed_lines(blob: bool, bump: f64, scale: f64) -> Vec<MeasuredLine> {
    let model = synthetic_truth(blob);
    TABLE_I
        .iter()
        .enumerate()
        .map(|(k, &(a, f))| {
            let nominal = LineKinematics::paper_line(a, f).expect("Table I conditions are valid");
            let xs: Vec<f64> = (0..2500).map(|i| i as f64 * 0.048).collect();
            let mut ws = model.predict(&nominal, &xs).expect("the synthetic model predicts its own conditions");
            for (i, w) in ws.iter_mut().enumerate() {
                *w = scale * (*w + bump * ((i * 13 + k * 5) as f64).sin());
            }
            MeasuredLine::new(nominal, xs, ws).expect("finite, sorted samples")
        })
        .collect()
}

/// A pressure-advance pattern: `advances.len()` slow–fast–slow lines (10, 100, 10 mm/s at
/// 2500 mm/s², 0.08 mm of filament per mm), each under its own K and Klipper's smooth time.
pub fn pressure_advance_pattern(advances: &[f64], smooth_time_s: f64) -> Vec<PrintedLine> {
    let limits = MotionLimits {
        accel_mm_s2: 2500.0,
        accel_to_decel_mm_s2: 2500.0,
        max_velocity_mm_s: f64::INFINITY,
        cornering: Cornering::SquareCorner { velocity_mm_s: 5.0, extruder_corner_mm_s: 1.0 },
    };
    let mut moves = Vec::new();
    for (i, &k) in advances.iter().enumerate() {
        let y = 8.0 + 3.0 * i as f64;
        let pressure_advance = PressureAdvance { advance_s: k, smooth_time_s };
        let mv = |a: [f64; 3], b: [f64; 3], feed: f64, e: f64| Move {
            start_mm: a,
            end_mm: b,
            filament_mm: e * (b[0] - a[0]).hypot(b[1] - a[1]),
            feed_mm_s: feed,
            limits,
            pressure_advance,
        };
        moves.push(mv([2.4, y, 0.3], [2.4, y, 0.2], 16.0, 0.0));
        // the shared pattern's segments: 3.88 mm slow, 23.28 mm fast, 11.64 mm slow
        let fast_start = 2.4 + 3.88;
        moves.push(mv([2.4, y, 0.2], [fast_start, y, 0.2], 10.0, 0.08));
        moves.push(mv([fast_start, y, 0.2], [29.56, y, 0.2], 100.0, 0.08));
        moves.push(mv([29.56, y, 0.2], [41.2, y, 0.2], 10.0, 0.08));
        moves.push(mv([41.2, y, 0.2], [41.2, y, 0.3], 16.0, 0.0));
    }
    printed_lines(&moves, &plan(&moves).expect("the pattern's moves plan"), 1.75)
}

/// Widths as a printer with lag `tau_s` lays them ([`deposit_line`], gaps at 0), line `i`
/// at level `1.25 + 0.02·(i mod 5)`, with Gaussian noise `noise_mm` (≥ 0) on the bead,
/// every 0.05 mm but the first and last millimetre.
pub fn pressure_advance_widths(lines: &[PrintedLine], tau_s: f64, noise_mm: f64, seed: u64) -> Vec<PaMeasuredLine> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_mm).expect("noise sd ≥ 0");
    lines
        .iter()
        .enumerate()
        .map(|(i, line)| {
            let deposit = deposit_line(line, &super::pressure_advance::DepositSettings::for_line(line, tau_s));
            let level = 1.25 + 0.02 * (i % 5) as f64;
            let series = deposit
                .positions_mm
                .iter()
                .zip(&deposit.widths_mm)
                .filter(|(x, _)| **x > 1.0 && **x < line.length_mm() - 1.0)
                .map(|(&x, &w)| (x, if w > 0.0 { level * w + noise.sample(&mut rng) } else { 0.0 }))
                .collect();
            PaMeasuredLine { line: i, series: vec![series] }
        })
        .collect()
}
