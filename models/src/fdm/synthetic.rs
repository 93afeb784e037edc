//! Synthetic ground truth for tests and benchmarks of the paper-000 models: the nine
//! Table I conditions and a plausible known piecewise model (eqs 2-3) from which
//! noiseless widths are drawn, so fits can be checked for parameter recovery.

use super::kinematics::LineKinematics;
use super::line::MeasuredLine;
use super::piecewise::{Bp1PowerLaw, PiecewiseCoefficients};
use super::predict::FittedPiecewise;

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
