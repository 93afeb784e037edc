//! Checked hyper-parameters of the five-phase piecewise width model (paper 000, Sec. II-A:
//! the `r_a`, `r_F` grid of eq. 1, the bp1 power law of eq. 2, the phases of eq. 3).
//!
//! Unchecked [`PiecewiseParams`] → `.check()` → [`PiecewiseValidParams`] (linfa style);
//! the fit only accepts the valid type.

use super::errors::ParamError;

/// Unchecked settings of the piecewise fit. Start from [`Self::paper_defaults`].
#[derive(Debug, Clone, PartialEq)]
pub struct PiecewiseParams {
    /// Lower end of the `r_a`, `r_F` grid (eq. 1: 0.9).
    pub r_min: f64,
    /// Upper end of the grid (eq. 1: 1.1).
    pub r_max: f64,
    /// Grid step (0.01, giving the 21 × 21 = 441 pairs of the brief).
    pub r_step: f64,
    /// Whether lines start with a blob whose width falls as the head accelerates
    /// (phase p1). The Taz 5 has it; the Taz 6 has not (paper Fig. 8): without it p1 and
    /// bp1 are dropped and phase p2 starts at `t = 0` from a fitted width `w_start`.
    pub has_start_blob: bool,
    /// Width of the centred moving average applied to the measured widths before the
    /// width minimum (bp1) and the first crossing of the nominal width (initial bp3) are
    /// located (mm). Our choice: the data are quantised to one pixel (≈ 0.048 mm) and
    /// the minimum is a plateau; 0 disables smoothing.
    pub smoothing_mm: f64,
    /// The width minimum (bp1) is searched for in `[0, min(bp4, max · L)]` with this
    /// fraction `max` of the line length (our choice: 0.5).
    pub bp1_search_fraction: f64,
    /// Lowest exponent `c2` of the bp1 power law (eq. 2) in its grid search.
    pub bp1_c2_min: f64,
    /// Highest exponent `c2` in the grid search.
    pub bp1_c2_max: f64,
    /// Step of the `c2` grid.
    pub bp1_c2_step: f64,
    /// Exponent used when the training lines have only two distinct accelerations, so that
    /// `c0, c1, c2` are not identifiable (our choice: −1, bp1 time ∝ 1/a).
    pub bp1_c2_fallback: f64,
    /// Most fixed-point iterations of the per-segment least squares (continuity offsets
    /// and bp3 are updated between iterations).
    pub max_iterations: usize,
    /// Convergence tolerance on the largest parameter change between iterations.
    pub tolerance: f64,
}

/// Checked settings of the piecewise fit (build with [`PiecewiseParams::check`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PiecewiseValidParams(PiecewiseParams);

impl PiecewiseParams {
    /// The paper's settings for a printer with a start blob (Taz 5): `r ∈ [0.9, 1.1]` in
    /// steps of 0.01 (eq. 1), bp1 from eq. 2. The smoothing, search window, `c2` grid
    /// and iteration settings are ours (the paper does not state them).
    pub fn paper_defaults() -> Self {
        Self {
            r_min: 0.9,
            r_max: 1.1,
            r_step: 0.01,
            has_start_blob: true,
            smoothing_mm: 1.0,
            bp1_search_fraction: 0.5,
            bp1_c2_min: -3.0,
            bp1_c2_max: 3.0,
            bp1_c2_step: 0.01,
            bp1_c2_fallback: -1.0,
            max_iterations: 60,
            tolerance: 1e-10,
        }
    }

    /// Paper defaults for a printer without the start blob (the Taz 6, paper Fig. 8).
    pub fn paper_defaults_without_blob() -> Self {
        Self { has_start_blob: false, ..Self::paper_defaults() }
    }

    /// Checks every field and returns the valid type.
    pub fn check(self) -> Result<PiecewiseValidParams, ParamError> {
        let positive = |name, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(ParamError::OutOfRange { name, value, reason: "must be positive and finite" })
            }
        };
        positive("r_min", self.r_min)?;
        positive("r_step", self.r_step)?;
        if !(self.r_max.is_finite() && self.r_max >= self.r_min) {
            return Err(ParamError::OutOfRange {
                name: "r_max",
                value: self.r_max,
                reason: "must be finite and at least r_min",
            });
        }
        if self.smoothing_mm.is_nan() || self.smoothing_mm < 0.0 {
            return Err(ParamError::OutOfRange {
                name: "smoothing_mm",
                value: self.smoothing_mm,
                reason: "must be non-negative",
            });
        }
        if !(self.bp1_search_fraction > 0.0 && self.bp1_search_fraction <= 1.0) {
            return Err(ParamError::OutOfRange {
                name: "bp1_search_fraction",
                value: self.bp1_search_fraction,
                reason: "must be in (0, 1]",
            });
        }
        positive("bp1_c2_step", self.bp1_c2_step)?;
        if !(self.bp1_c2_max.is_finite() && self.bp1_c2_min.is_finite()) || self.bp1_c2_max < self.bp1_c2_min {
            return Err(ParamError::OutOfRange {
                name: "bp1_c2_max",
                value: self.bp1_c2_max,
                reason: "must be finite and at least bp1_c2_min",
            });
        }
        if !self.bp1_c2_fallback.is_finite() || self.bp1_c2_fallback == 0.0 {
            return Err(ParamError::OutOfRange {
                name: "bp1_c2_fallback",
                value: self.bp1_c2_fallback,
                reason: "must be finite and non-zero",
            });
        }
        if self.max_iterations == 0 {
            return Err(ParamError::OutOfRange { name: "max_iterations", value: 0.0, reason: "must be at least 1" });
        }
        positive("tolerance", self.tolerance)?;
        if self.r_values().len() > 10_000 {
            return Err(ParamError::OutOfRange {
                name: "r_step",
                value: self.r_step,
                reason: "gives more than 10 000 values per axis",
            });
        }
        Ok(PiecewiseValidParams(self))
    }

    /// The grid values `r_min, r_min + step, …, r_max` of one axis.
    fn r_values(&self) -> Vec<f64> {
        let n = ((self.r_max - self.r_min) / self.r_step + 1e-9).floor() as usize + 1;
        (0..n.min(10_001)).map(|k| self.r_min + k as f64 * self.r_step).collect()
    }
}

impl PiecewiseValidParams {
    /// The checked settings.
    pub fn get(&self) -> &PiecewiseParams {
        &self.0
    }

    /// Values of one axis of the `r_a`, `r_F` grid (eq. 1), ascending.
    pub fn r_values(&self) -> Vec<f64> {
        self.0.r_values()
    }

    /// Whether the printer has the start blob (phase p1).
    pub fn has_start_blob(&self) -> bool {
        self.0.has_start_blob
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_grid_has_441_pairs() {
        let p = PiecewiseParams::paper_defaults().check().unwrap();
        let r = p.r_values();
        assert_eq!(r.len(), 21);
        assert_eq!(r.len() * r.len(), 441);
        assert!((r[0] - 0.9).abs() < 1e-12 && (r[20] - 1.1).abs() < 1e-12);
    }

    #[test]
    fn invalid_settings_are_rejected() {
        let p = PiecewiseParams { r_step: 0.0, ..PiecewiseParams::paper_defaults() };
        assert!(matches!(p.check(), Err(ParamError::OutOfRange { name: "r_step", .. })));
        let p = PiecewiseParams { r_max: 0.8, ..PiecewiseParams::paper_defaults() };
        assert!(p.check().is_err());
        let p = PiecewiseParams { bp1_c2_fallback: 0.0, ..PiecewiseParams::paper_defaults() };
        assert!(p.check().is_err());
    }
}
