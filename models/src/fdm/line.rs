//! The measured-line input of the paper-000 fits (Ren et al. 2021, Sec. III): the
//! nominal G-code kinematics of one printed straight line and its width profile.

use super::errors::FitError;
use super::kinematics::LineKinematics;

/// One printed straight line: its nominal kinematics (as set in the G-code, before the
/// `r_a`, `r_F` scaling of eq. 1) and the widths measured along it.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredLine {
    /// Nominal (G-code) kinematics.
    pub nominal: LineKinematics,
    /// Positions along the line (mm), strictly increasing, within `[0, length_mm]`.
    pub positions_mm: Vec<f64>,
    /// Measured widths at those positions (mm).
    pub widths_mm: Vec<f64>,
}

impl MeasuredLine {
    /// A checked line (see [`Self::validate`]).
    pub fn new(nominal: LineKinematics, positions_mm: Vec<f64>, widths_mm: Vec<f64>) -> Result<Self, FitError> {
        let line = Self { nominal, positions_mm, widths_mm };
        line.check(None)?;
        Ok(line)
    }

    /// Checks lengths agree, there are at least 10 samples, positions are finite, strictly
    /// increasing and inside the line, and widths are finite and positive. `index` (its
    /// position in the input slice) names the line in the error.
    pub fn validate(&self, index: usize) -> Result<(), FitError> {
        self.check(Some(index))
    }

    fn check(&self, index: Option<usize>) -> Result<(), FitError> {
        let bad = |reason: String| FitError::BadLine { line: index, reason };
        if self.positions_mm.len() != self.widths_mm.len() {
            return Err(bad(format!("{} positions but {} widths", self.positions_mm.len(), self.widths_mm.len())));
        }
        if self.positions_mm.len() < 10 {
            return Err(bad("fewer than 10 samples".into()));
        }
        let length = self.nominal.length_mm;
        let in_range = |x: f64| x.is_finite() && (-1e-9..=length + 1e-9).contains(&x);
        if !self.positions_mm.iter().all(|&x| in_range(x)) {
            return Err(bad(format!("a position is outside [0, {length}] mm")));
        }
        if self.positions_mm.windows(2).any(|w| w[1] <= w[0]) {
            return Err(bad("positions are not strictly increasing".into()));
        }
        if !self.widths_mm.iter().all(|w| w.is_finite() && *w > 0.0) {
            return Err(bad("a width is not finite and positive".into()));
        }
        Ok(())
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.positions_mm.len()
    }

    /// Whether the line has no samples.
    pub fn is_empty(&self) -> bool {
        self.positions_mm.is_empty()
    }
}

/// Root-mean-square difference of two equally long width profiles (mm). Returns NaN for
/// empty or unequal inputs.
pub fn rmse(predicted_mm: &[f64], measured_mm: &[f64]) -> f64 {
    if predicted_mm.is_empty() || predicted_mm.len() != measured_mm.len() {
        return f64::NAN;
    }
    let sse: f64 = predicted_mm.iter().zip(measured_mm).map(|(p, m)| (p - m).powi(2)).sum();
    (sse / predicted_mm.len() as f64).sqrt()
}

/// The widths a printer of another family would lay down along the same path: every
/// width times `width_scale` (a nozzle `width_scale` times wider at the same kinematics:
/// mass conservation scales the bead), then a first-order lag of length `lag_mm` in path
/// length, `w' (x) = w'(x⁻) + (w(x) − w'(x⁻))·(1 − e^{−Δx/lag_mm})`, started at the first
/// width (a slower melt response that stretches the start dip and the end bulge).
/// `lag_mm = 0` leaves the profile's shape as it is.
pub fn other_family_widths(positions_mm: &[f64], widths_mm: &[f64], width_scale: f64, lag_mm: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(widths_mm.len());
    let mut state = widths_mm.first().map_or(0.0, |w| w * width_scale);
    for (i, (&x, &w)) in positions_mm.iter().zip(widths_mm).enumerate() {
        let target = w * width_scale;
        state = if i == 0 || lag_mm <= 0.0 {
            target
        } else {
            let dx = x - positions_mm[i - 1];
            state + (target - state) * (1.0 - (-dx / lag_mm).exp())
        };
        out.push(state);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_rejects_malformed_lines() {
        let k = LineKinematics::paper_line(400.0, 50.0).unwrap();
        let xs: Vec<f64> = (0..20).map(|i| i as f64).collect();
        let ws = vec![0.8; 20];
        assert!(MeasuredLine::new(k, xs.clone(), ws.clone()).is_ok());
        assert!(matches!(MeasuredLine::new(k, xs.clone(), vec![0.8; 19]), Err(FitError::BadLine { .. })));
        // A line checked alone has no index to name (it used to print usize::MAX).
        let alone = MeasuredLine::new(k, xs[..5].to_vec(), vec![0.8; 5]).unwrap_err().to_string();
        assert_eq!(alone, "measured line: fewer than 10 samples");
        let err = MeasuredLine { nominal: k, positions_mm: xs[..5].to_vec(), widths_mm: vec![0.8; 5] }.validate(3);
        assert_eq!(err.unwrap_err().to_string(), "measured line 3: fewer than 10 samples");
        let mut unsorted = xs.clone();
        unsorted.swap(3, 4);
        assert!(MeasuredLine::new(k, unsorted, ws.clone()).is_err());
        let mut outside = xs.clone();
        outside[19] = 121.0;
        assert!(MeasuredLine::new(k, outside, ws).is_err());
    }

    #[test]
    fn rmse_matches_definition() {
        // Differences 0.3 and 0.4: sqrt((0.09 + 0.16)/2).
        let r = rmse(&[1.0, 2.0], &[1.3, 1.6]);
        assert!((r - (0.125f64).sqrt()).abs() < 1e-15);
        assert!(rmse(&[], &[]).is_nan());
    }
}
