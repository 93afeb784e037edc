//! Surrogate data sets for the power study: new draws of a measured data set's noise
//! around the model the data's own causes give.
//!
//! Each line's residual about that model (fitted on all lines) keeps its Fourier
//! amplitudes and gets random phases (Theiler et al. 1992, "phase-randomised
//! surrogates"): the surrogate residual has exactly the measured residual's power
//! spectrum, so its autocorrelation, including the slow swells that make a trend or a
//! ripple hard to see, while its realisation is new and independent from line to line.
//! What it does not keep: the residual's non-stationarity along the line (the misfit
//! near the ends is spread along it) and its alignment across lines. A draw is the
//! model's widths plus the surrogate residual.

use std::collections::HashMap;
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

/// A forward and an inverse transform of one length.
type Plan = (Arc<dyn Fft<f64>>, Arc<dyn Fft<f64>>);

/// Planned transforms, one pair per line length.
pub struct Surrogates {
    plans: HashMap<usize, Plan>,
}

impl Surrogates {
    /// Plans for residuals of the given lengths.
    pub fn new(lengths: impl IntoIterator<Item = usize>) -> Self {
        let mut planner = FftPlanner::new();
        let plans =
            lengths.into_iter().map(|n| (n, (planner.plan_fft_forward(n), planner.plan_fft_inverse(n)))).collect();
        Self { plans }
    }

    /// A phase-randomised copy of `residual`, seeded. Its mean (the zero frequency)
    /// and, for an even length, the Nyquist term are kept as they are.
    pub fn draw(&self, residual: &[f64], seed: u64) -> Vec<f64> {
        let n = residual.len();
        let Some((forward, inverse)) = self.plans.get(&n) else {
            return residual.to_vec();
        };
        let mut spectrum: Vec<Complex<f64>> = residual.iter().map(|&r| Complex::new(r, 0.0)).collect();
        forward.process(&mut spectrum);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        for k in 1..n.div_ceil(2) {
            let phase = Complex::from_polar(1.0, rng.random::<f64>() * std::f64::consts::TAU);
            spectrum[k] = Complex::new(spectrum[k].norm(), 0.0) * phase;
            spectrum[n - k] = spectrum[k].conj();
        }
        inverse.process(&mut spectrum);
        spectrum.iter().map(|c| c.re / n as f64).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_power_spectrum_and_the_mean_with_new_phases() {
        // Parseval: equal spectra give equal sums of squares; the zero frequency is the
        // sum. The realisation differs and depends only on the seed.
        let r: Vec<f64> =
            (0..501).map(|i| ((i as f64) * 0.37).sin() * 0.02 + ((i * 7919) % 13) as f64 * 1e-3).collect();
        let s = Surrogates::new([501]);
        let a = s.draw(&r, 1);
        let ss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        assert!((ss(&a) - ss(&r)).abs() < 1e-9 * ss(&r));
        assert!((a.iter().sum::<f64>() - r.iter().sum::<f64>()).abs() < 1e-9);
        assert_ne!(a, r);
        assert_eq!(a, s.draw(&r, 1));
        assert_ne!(a, s.draw(&r, 2));
    }
}
