//! Prediction with a fitted piecewise model for a new line (paper 000, Sec. II-A, the
//! six prediction steps after the fitting procedure): actual kinematics from eq. 1 with
//! the fitted `r_a`, `r_F`; bp1 from the power law of eq. 2; bp2, bp4 from the
//! kinematics; eq. 3 evaluated piece by piece with bp3 where p3 reaches `c`.
//!
//! Architecture invariant (DESIGN §9): a prediction uses nothing of the predicted line
//! but its nominal kinematics and the positions at which widths are wanted.

use super::errors::FitError;
use super::kinematics::LineKinematics;
use super::piecewise::{Bp1PowerLaw, LineChain, PiecewiseCoefficients};

/// A fitted five-phase model (the output of [`crate::fdm::fit::fit`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedPiecewise {
    /// Selected acceleration scale `r_a` of eq. 1.
    pub r_a: f64,
    /// Selected feed scale `r_F` of eq. 1.
    pub r_f: f64,
    /// Coefficients of eq. 3.
    pub coefficients: PiecewiseCoefficients,
    /// bp1 power law of eq. 2 (`None` without a start blob).
    pub bp1_law: Option<Bp1PowerLaw>,
    /// Whether the model has phase p1.
    pub has_start_blob: bool,
    /// RMSE of the fitted curve on the training lines (mm), the grid criterion.
    pub training_rmse_mm: f64,
    /// Weight `λ` of the informative prior (0 for the single-printer fit).
    pub lambda: f64,
}

impl FittedPiecewise {
    /// Actual kinematics `a = r_a·a0`, `F = r_F·F0` of a nominal line (eq. 1).
    pub fn actual_kinematics(&self, nominal: &LineKinematics) -> Result<LineKinematics, FitError> {
        Ok(nominal.scaled(self.r_a, self.r_f)?)
    }

    /// Breakpoints and offsets of eq. 3 for a nominal line, bp1 from eq. 2.
    pub fn chain(&self, nominal: &LineKinematics) -> Result<LineChain, FitError> {
        let kin = self.actual_kinematics(nominal)?;
        let bp1 = self.bp1_law.map_or(0.0, |law| law.bp1_s(kin.accel_mm_s2));
        Ok(LineChain::new(&self.coefficients, &kin, self.has_start_blob, bp1))
    }

    /// Predicted widths (mm) at the given positions of a line with the given nominal
    /// kinematics.
    pub fn predict(&self, nominal: &LineKinematics, positions_mm: &[f64]) -> Result<Vec<f64>, FitError> {
        let mut out = vec![0.0; positions_mm.len()];
        self.predict_into(nominal, positions_mm, &mut out)?;
        Ok(out)
    }

    /// [`Self::predict`] into a caller's buffer (no allocation).
    pub fn predict_into(
        &self,
        nominal: &LineKinematics,
        positions_mm: &[f64],
        out_mm: &mut [f64],
    ) -> Result<(), FitError> {
        if out_mm.len() != positions_mm.len() {
            return Err(FitError::Dimension(format!(
                "{} positions but an output of {}",
                positions_mm.len(),
                out_mm.len()
            )));
        }
        let kin = self.actual_kinematics(nominal)?;
        let chain = self.chain(nominal)?;
        for (&x, w) in positions_mm.iter().zip(out_mm.iter_mut()) {
            let (t, v) = (kin.time_at_position(x), kin.speed_at_position(x));
            *w = chain.width_at(&self.coefficients, t, v);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{synthetic_lines, synthetic_truth};
    use super::*;
    use crate::fdm::line::rmse;

    #[test]
    fn prediction_reproduces_generating_model() {
        // synthetic_lines draws the widths from this very predictor, so predicting the
        // same positions again must give them back exactly.
        let truth = synthetic_truth(true);
        let lines = synthetic_lines(&truth, 0.5);
        for l in &lines {
            let p = truth.predict(&l.nominal, &l.positions_mm).unwrap();
            assert_eq!(rmse(&p, &l.widths_mm), 0.0);
        }
        let l = &lines[0];
        assert!(matches!(truth.predict_into(&l.nominal, &l.positions_mm, &mut [0.0; 3]), Err(FitError::Dimension(_))));
    }
}
