//! Paper 000's piecewise model (eqs 1-3, [`crate::fdm::fit`]: the five-phase width
//! model with the `r_a × r_F` grid search) as the engine's baseline instead of the lag
//! model: what the paper's own model gets wrong.
//!
//! The piecewise model is a fitted curve per phase, not a flow simulation, so only the
//! candidates that act on the width it predicts extend it; they are the lag model's
//! mechanisms of the same names, as factors:
//!
//! ```text
//! w = p(x)·(1 − S·(v_cmd(x)/v_ref)²) / (1 + k(x/L − ½))·(1 + g·A·sin(2πx/P + φ))
//!     flow_saturation                 bed_tilt              gear_eccentricity
//! ```
//!
//! The lag-specific candidates (nonlinear and two-stage lag, the width cap) have no
//! counterpart in a curve fit, and the kinematics deviation is already the paper's
//! grid search. Simplification, stated: the curve and the factors are fitted by
//! backfitting, not jointly, because the curve's grid search is far too costly to
//! repeat inside a least-squares loop. Each of [`BACKFIT_ROUNDS`] rounds fits the curve
//! to the training widths divided by the current factors, then the factors with the
//! curve held: tilt and saturation by bounded least squares, then the gear's period
//! search on the lag model's grid, refined by a golden-section search within one grid
//! step, with each line's phase and the shared amplitude profiled out.

use ::discrepancy::least_squares::{minimize, LmSettings};
use ::discrepancy::{Mechanism, Model, ModelError, Parameter, Scale, Variable};

use super::forward::width_factor;
use super::gear::{self, attenuation};
use super::mechanisms::{BedTilt, FlowSaturation, GearEccentricity};
use super::{FdmLine, FdmModel};
use crate::fdm::line::MeasuredLine;
use crate::fdm::{FittedPiecewise, PiecewiseValidParams};

/// The candidates that extend the piecewise model, in index order.
pub static PIECEWISE_CANDIDATES: [&dyn Mechanism; 3] = [&BedTilt, &GearEccentricity, &FlowSaturation];
/// Rounds of curve-then-factors backfitting (a curve fitted to data with a trend
/// takes part of the trend; each round hands the curve less of it).
pub const BACKFIT_ROUNDS: usize = 3;
/// Index of `bed_tilt` among [`PIECEWISE_CANDIDATES`].
pub const TILT: usize = 0;
/// Index of `gear_eccentricity`.
pub const GEAR: usize = 1;
/// Index of `flow_saturation`.
pub const SATURATION: usize = 2;

/// The baseline's own reported parameters: the kinematics scales its grid search chose.
static PARAMS: [Parameter; 2] = [
    Parameter {
        name: "r_a",
        unit: "1",
        lo: 0.5,
        hi: 1.5,
        meaning: "actual over commanded acceleration (paper 000 eq. 1), from the grid search",
        scale: Scale::Linear,
    },
    Parameter {
        name: "r_f",
        unit: "1",
        lo: 0.5,
        hi: 1.5,
        meaning: "actual over commanded feed (paper 000 eq. 1), from the grid search",
        scale: Scale::Linear,
    },
];

/// The piecewise model as the engine's baseline.
#[derive(Debug, Clone)]
pub struct PiecewiseModel {
    /// The piecewise fit's settings (the `r` grid, the start blob).
    pub params: PiecewiseValidParams,
    /// The same data's lag model: its setting (smoothing, the saturation's reference
    /// speed) and the variables the residuals are shown against.
    pub lag: FdmModel,
}

/// A fitted piecewise model with its active factors.
#[derive(Debug, Clone)]
pub struct PiecewiseFit {
    /// Active candidates, in the order added.
    pub active: Vec<usize>,
    /// The curve.
    pub piecewise: FittedPiecewise,
    /// `bed_tilt`'s width change from start to end (0 when off).
    pub tilt_width_change: f64,
    /// `flow_saturation`'s loss at the reference speed (0 when off).
    pub saturation_loss: f64,
    /// `gear_eccentricity`'s period (mm; NaN when off).
    pub gear_period_mm: f64,
    /// Its shared amplitude (0 when off).
    pub gear_amplitude: f64,
}

impl PiecewiseModel {
    /// The curve times the active tilt and saturation factors at `positions_mm`.
    fn factored(&self, fit: &PiecewiseFit, line: &MeasuredLine, positions_mm: &[f64]) -> Result<Vec<f64>, String> {
        let mut w = fit.piecewise.predict(&line.nominal, positions_mm).map_err(|e| e.to_string())?;
        apply_factors(
            &mut w,
            positions_mm,
            line,
            fit.tilt_width_change,
            fit.saturation_loss,
            self.lag.setting.v_ref_mm_s,
        );
        Ok(w)
    }

    fn smoothing_mm(&self) -> f64 {
        self.lag.setting.smoothing_mm
    }
}

fn apply_factors(w: &mut [f64], positions_mm: &[f64], line: &MeasuredLine, tilt: f64, saturation: f64, v_ref: f64) {
    if tilt == 0.0 && saturation == 0.0 {
        return;
    }
    let length = line.nominal.length_mm;
    for (w, &x) in w.iter_mut().zip(positions_mm) {
        *w *= width_factor(tilt, saturation, line.nominal.speed_at_position(x) / v_ref, x.clamp(0.0, length) / length);
    }
}

impl Model for PiecewiseModel {
    type Group = FdmLine;
    type Fit = PiecewiseFit;

    fn name(&self) -> &'static str {
        "piecewise_model"
    }

    fn params(&self) -> &'static [Parameter] {
        &PARAMS
    }

    fn candidates(&self) -> &[&'static dyn Mechanism] {
        &PIECEWISE_CANDIDATES
    }

    fn variables(&self) -> &[Variable] {
        self.lag.variables()
    }

    fn variable_values(&self, group: &FdmLine, variable: usize) -> Vec<f64> {
        self.lag.variable_values(group, variable)
    }

    fn fit(
        &self,
        active: &[usize],
        train: &[&FdmLine],
        _warm: Option<&PiecewiseFit>,
    ) -> Result<PiecewiseFit, ModelError> {
        let fit_error = |e: crate::fdm::FitError| ModelError::Fit(e.to_string());
        let mut lines: Vec<MeasuredLine> = train.iter().map(|g| g.line.clone()).collect();
        let rounds = if active.is_empty() { 1 } else { BACKFIT_ROUNDS };
        let mut fit = PiecewiseFit {
            active: active.to_vec(),
            piecewise: crate::fdm::fit(&lines, &self.params).map_err(fit_error)?,
            tilt_width_change: 0.0,
            saturation_loss: 0.0,
            gear_period_mm: f64::NAN,
            gear_amplitude: 0.0,
        };
        for round in 0..rounds {
            if round > 0 {
                self.divide_out_factors(&fit, train, &mut lines)?;
                fit.piecewise = crate::fdm::fit(&lines, &self.params).map_err(fit_error)?;
            }
            let curves: Vec<Vec<f64>> = train
                .iter()
                .map(|g| fit.piecewise.predict(&g.line.nominal, g.fit_positions_mm()))
                .collect::<Result<_, _>>()
                .map_err(fit_error)?;
            self.fit_factors(&mut fit, train, &curves)?;
            if active.contains(&GEAR) {
                self.fit_gear(&mut fit, train, &curves);
            }
        }
        Ok(fit)
    }

    fn predict(&self, fit: &PiecewiseFit, group: &FdmLine, calibrate: Option<&[bool]>) -> Result<Vec<f64>, ModelError> {
        let line = &group.line;
        let mut w = self.factored(fit, line, &line.positions_mm).map_err(ModelError::Predict)?;
        if fit.active.contains(&GEAR) {
            let mask =
                calibrate.ok_or_else(|| ModelError::Predict("the gear's phase needs calibration samples".into()))?;
            let g = attenuation(fit.gear_period_mm, self.smoothing_mm());
            let phase = gear::line_phase(&line.positions_mm, &w, &line.widths_mm, fit.gear_period_mm, |i| mask[i]);
            gear::apply(&line.positions_mm, &mut w, fit.gear_period_mm, g, fit.gear_amplitude, phase);
        }
        Ok(w)
    }

    fn estimates(&self, fit: &PiecewiseFit) -> Vec<f64> {
        let mut out = vec![fit.piecewise.r_a, fit.piecewise.r_f];
        for &c in &fit.active {
            match c {
                TILT => out.push(fit.tilt_width_change),
                GEAR => out.extend([fit.gear_period_mm, fit.gear_amplitude]),
                _ => out.push(fit.saturation_loss),
            }
        }
        out
    }
}

impl PiecewiseModel {
    /// `lines` = the training lines' measured widths divided by the factors of `fit`
    /// (the gear's ripple with each line's phase from the whole line).
    fn divide_out_factors(
        &self,
        fit: &PiecewiseFit,
        train: &[&FdmLine],
        lines: &mut [MeasuredLine],
    ) -> Result<(), ModelError> {
        let v_ref = self.lag.setting.v_ref_mm_s;
        for (g, line) in train.iter().zip(lines.iter_mut()) {
            let x = &g.line.positions_mm;
            let mut factor = vec![1.0; x.len()];
            apply_factors(&mut factor, x, &g.line, fit.tilt_width_change, fit.saturation_loss, v_ref);
            if fit.active.contains(&GEAR) {
                let model = self.factored(fit, &g.line, x).map_err(ModelError::Fit)?;
                let phase = gear::line_phase(x, &model, &g.line.widths_mm, fit.gear_period_mm, |_| true);
                let gain = attenuation(fit.gear_period_mm, self.smoothing_mm());
                gear::apply(x, &mut factor, fit.gear_period_mm, gain, fit.gear_amplitude, phase);
            }
            for ((w, measured), f) in line.widths_mm.iter_mut().zip(&g.line.widths_mm).zip(&factor) {
                *w = measured / f;
            }
        }
        Ok(())
    }

    /// Tilt and saturation (those active) by bounded least squares on the training
    /// lines' fit samples, the curve held.
    fn fit_factors(&self, fit: &mut PiecewiseFit, train: &[&FdmLine], curves: &[Vec<f64>]) -> Result<(), ModelError> {
        let (tilt, saturation) = (fit.active.contains(&TILT), fit.active.contains(&SATURATION));
        if !tilt && !saturation {
            return Ok(());
        }
        let bounds = |c: usize| {
            let p = PIECEWISE_CANDIDATES[c].params()[0];
            (p.lo, p.hi)
        };
        let which: Vec<usize> = [(TILT, tilt), (SATURATION, saturation)].iter().filter(|w| w.1).map(|w| w.0).collect();
        let (lo, hi): (Vec<f64>, Vec<f64>) = which.iter().map(|&c| bounds(c)).unzip();
        // Each fit sample's curve width, observation and where it lies (speed ratio,
        // fraction of the line), computed once: the residuals are then arithmetic.
        let v_ref = self.lag.setting.v_ref_mm_s;
        let samples: Vec<FactorSample> = train
            .iter()
            .zip(curves)
            .flat_map(|(g, curve)| {
                let (nominal, length) = (&g.line.nominal, g.line.nominal.length_mm);
                g.fit_positions_mm().iter().zip(curve).zip(g.fit_widths_mm()).map(
                    move |((&x, &curve_mm), &observed_mm)| FactorSample {
                        curve_mm,
                        observed_mm,
                        speed_ratio: nominal.speed_at_position(x) / v_ref,
                        fraction: x.clamp(0.0, length) / length,
                    },
                )
            })
            .collect();
        let residuals = |x: &[f64], r: &mut [f64]| {
            let value = |c: usize| which.iter().position(|&w| w == c).map_or(0.0, |k| x[k]);
            let (t, s) = (value(TILT), value(SATURATION));
            for (r, p) in r.iter_mut().zip(&samples) {
                *r = p.observed_mm - p.curve_mm * width_factor(t, s, p.speed_ratio, p.fraction);
            }
            r.iter().all(|v| v.is_finite())
        };
        let x0 = vec![0.0; which.len()];
        let solution = minimize(residuals, &x0, &lo, &hi, samples.len(), &LmSettings::default())
            .ok_or_else(|| ModelError::Fit("the factors' least squares could not start".into()))?;
        for (k, &c) in which.iter().enumerate() {
            match c {
                TILT => fit.tilt_width_change = solution.x[k],
                _ => fit.saturation_loss = solution.x[k],
            }
        }
        Ok(())
    }

    /// The gear's period by the lag model's search, each training line's phase and the
    /// shared amplitude, on the factored curve.
    fn fit_gear(&self, fit: &mut PiecewiseFit, train: &[&FdmLine], curves: &[Vec<f64>]) {
        let v_ref = self.lag.setting.v_ref_mm_s;
        let models: Vec<Vec<f64>> = train
            .iter()
            .zip(curves)
            .map(|(g, curve)| {
                let mut w = curve.clone();
                apply_factors(&mut w, g.fit_positions_mm(), &g.line, fit.tilt_width_change, fit.saturation_loss, v_ref);
                w
            })
            .collect();
        let search: Vec<gear::SearchLine> = train
            .iter()
            .zip(&models)
            .map(|(g, m)| (g.gear_table(), m.as_slice(), g.fit_widths_mm(), g.fit_positions_mm()))
            .collect();
        let grid_period = gear::best_period(&search, self.smoothing_mm());
        let ripple = |period: f64| self.ripple_at(train, &models, period);
        let period = refine_period(grid_period, |p| ripple(p).1);
        fit.gear_period_mm = period;
        fit.gear_amplitude = ripple(period).0;
    }

    /// The shared amplitude and the training sum of squares of a ripple of `period_mm`
    /// on `models`, each line's phase profiled out.
    fn ripple_at(&self, train: &[&FdmLine], models: &[Vec<f64>], period_mm: f64) -> (f64, f64) {
        let phases: Vec<f64> = train
            .iter()
            .zip(models)
            .map(|(g, m)| gear::line_phase(g.fit_positions_mm(), m, g.fit_widths_mm(), period_mm, |_| true))
            .collect();
        let phased: Vec<gear::PhasedLine> = train
            .iter()
            .zip(models)
            .zip(&phases)
            .map(|((g, m), &p)| (g.fit_positions_mm(), m.as_slice(), g.fit_widths_mm(), p))
            .collect();
        let gain = attenuation(period_mm, self.smoothing_mm());
        let amplitude = gear::shared_amplitude(&phased, period_mm, gain);
        let sse = phased
            .iter()
            .map(|(x, m, y, phase)| {
                let ripple = |x: f64| gear::ripple_factor(x, period_mm, gain, amplitude, *phase);
                (0..x.len()).map(|i| (y[i] - m[i] * ripple(x[i])).powi(2)).sum::<f64>()
            })
            .sum();
        (amplitude, sse)
    }
}

/// One training sample of the factors' least squares.
struct FactorSample {
    curve_mm: f64,
    observed_mm: f64,
    /// Commanded speed over the reference speed.
    speed_ratio: f64,
    /// Position as a fraction of the line.
    fraction: f64,
}

/// The period within one grid step (in frequency) of `grid_period_mm` that minimises
/// `sse`, by golden-section search on the frequency (the grid only brackets it).
fn refine_period(grid_period_mm: f64, sse: impl Fn(f64) -> f64) -> f64 {
    const GOLDEN: f64 = 0.618_033_988_749_895;
    let f0 = 1.0 / grid_period_mm;
    let lo = (f0 - gear::FREQUENCY_STEP_PER_MM).max(1.0 / gear::PERIOD_MAX_MM);
    let hi = (f0 + gear::FREQUENCY_STEP_PER_MM).min(1.0 / gear::PERIOD_MIN_MM);
    let (mut a, mut b) = (lo, hi);
    let (mut c, mut d) = (b - GOLDEN * (b - a), a + GOLDEN * (b - a));
    let (mut fc, mut fd) = (sse(1.0 / c), sse(1.0 / d));
    for _ in 0..30 {
        if fc < fd {
            (b, d, fd) = (d, c, fc);
            c = b - GOLDEN * (b - a);
            fc = sse(1.0 / c);
        } else {
            (a, c, fc) = (c, d, fd);
            d = a + GOLDEN * (b - a);
            fd = sse(1.0 / d);
        }
    }
    let best = 0.5 * (a + b);
    if sse(1.0 / best) <= sse(grid_period_mm) {
        1.0 / best
    } else {
        grid_period_mm
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;
    use crate::fdm::kinematics::LineKinematics;
    use crate::fdm::PiecewiseParams;

    /// The nine Table I lines of a piecewise model fitted to lag-model widths, times a
    /// tilt, a saturation and a gear ripple (phase per line), noiseless.
    fn lines(tilt: f64, saturation: f64, ripple: f64) -> Vec<FdmLine> {
        let mut out = Vec::new();
        for (k, (a, f)) in [400.0, 600.0, 800.0].iter().flat_map(|a| [50.0, 100.0, 150.0].map(|f| (*a, f))).enumerate()
        {
            let kin = LineKinematics::paper_line(a, f).unwrap();
            let x: Vec<f64> = (0..2400).map(|i| i as f64 * 0.05).collect();
            let mut w = vec![0.0; x.len()];
            let theta = super::super::forward::Theta::lag(0.05, 0.8, 0.0);
            let setting = super::super::forward::LineSetting { smoothing_mm: 0.5, v_ref_mm_s: 150.0 };
            assert!(super::super::forward::widths(&theta, &kin, &setting, &x, &mut Default::default(), &mut w));
            let line = MeasuredLine::new(kin, x.clone(), w.clone()).unwrap();
            apply_factors(&mut w, &x, &line, tilt, saturation, 150.0);
            let g = attenuation(9.0, 0.5);
            for (w, x) in w.iter_mut().zip(&x) {
                *w *= 1.0 + g * ripple * (2.0 * PI * x / 9.0 + k as f64).sin();
            }
            out.push(FdmLine::new(format!("line{k}"), MeasuredLine::new(kin, x, w).unwrap()));
        }
        out
    }

    fn model(lines: &[FdmLine]) -> PiecewiseModel {
        let params = PiecewiseParams { r_min: 1.0, r_max: 1.0, ..PiecewiseParams::paper_defaults_without_blob() };
        PiecewiseModel { params: params.check().unwrap(), lag: FdmModel::new(lines, false, 0.5) }
    }

    #[test]
    fn the_factors_recover_a_tilt_a_saturation_and_a_ripple_put_on_the_curve_data() {
        let data = lines(0.06, 0.08, 0.03);
        let m = model(&data);
        let train: Vec<&FdmLine> = data.iter().collect();
        let fit = m.fit(&[TILT, SATURATION, GEAR], &train, None).unwrap();
        let e = m.estimates(&fit);
        assert_eq!(e.len(), 2 + 1 + 1 + 2);
        assert!((fit.tilt_width_change - 0.06).abs() < 0.01, "tilt {}", fit.tilt_width_change);
        assert!((fit.saturation_loss - 0.08).abs() < 0.02, "saturation {}", fit.saturation_loss);
        assert!((fit.gear_period_mm - 9.0).abs() < 0.05, "refined period {}", fit.gear_period_mm);
        assert!((fit.gear_amplitude - 0.03).abs() < 0.006, "amplitude {}", fit.gear_amplitude);
        let plain = m.fit(&[], &train, None).unwrap();
        let rmse = |f: &PiecewiseFit| {
            let mask = vec![true; data[0].line.len()];
            let p = m.predict(f, &data[0], Some(&mask)).unwrap();
            crate::fdm::rmse(&p, &data[0].line.widths_mm)
        };
        // The curve cannot follow lag-model widths exactly (another model), so the rest is its own error.
        assert!(rmse(&fit) < 0.75 * rmse(&plain), "{} vs {}", rmse(&fit), rmse(&plain));
    }
}
