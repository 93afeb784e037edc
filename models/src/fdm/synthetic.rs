//! Synthetic ground truth for tests and benchmarks of the paper-000 models: the nine
//! Table I conditions and a plausible known piecewise model (eqs 2-3) from which
//! noiseless widths are drawn, so fits can be checked for parameter recovery.

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
