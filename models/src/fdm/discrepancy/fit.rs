//! Fitting the lag model with any set of active mechanisms to training lines, and
//! predicting a held-out one.
//!
//! Every active shared parameter is fitted jointly by bounded least squares
//! ([`discrepancy::least_squares::minimize`]) on the training lines' fit samples, the
//! parameters declared on a log scale (time constants, the cap) on their logarithm.
//! Starting points: the plain lag model from three time constants (20 ms, 80 ms,
//! 300 ms: direct drive to Bowden, DESIGN §5.1); a model with one more mechanism from
//! the fit without it (on the same training lines) and one or two physically
//! different starts of the new mechanism; the gear's period from the grid search of
//! [`super::gear`] on the residuals of the fit without it. The gear's per-line phase
//! and amplitude are profiled out of the residuals by their 2 × 2 least squares.

use ::discrepancy::least_squares::{minimize, LmSettings};
use ::discrepancy::{ModelError, Parameter, Scale};

use super::forward::{widths, Scratch, Theta};
use super::gear::{self, attenuation};
use super::mechanisms::*;
use super::{has_gear, middle_widths, FdmFit, FdmLine, FdmModel};

/// Starting time constants of the plain lag model (s).
const START_TAU_S: [f64; 3] = [0.02, 0.08, 0.3];

/// Fits `active` on `train`; see the module doc.
pub fn fit(
    model: &FdmModel,
    active: &[usize],
    train: &[&FdmLine],
    warm: Option<&FdmFit>,
) -> Result<FdmFit, ModelError> {
    if train.is_empty() {
        return Err(ModelError::Fit("no training lines".into()));
    }
    let start = match warm {
        Some(w) if w.active.iter().all(|c| active.contains(c)) => Some(w.clone()),
        _ if active.is_empty() => None,
        _ => Some(fit(model, &active[..active.len() - 1], train, None)?),
    };
    let Some(start) = start else {
        let w0 = crate::stats::finite_median(train.iter().flat_map(|l| middle_widths(&l.line)));
        let starts: Vec<Theta> = START_TAU_S.iter().map(|&tau| Theta::lag(tau, w0, 0.0)).collect();
        return best_of(model, &[], train, starts);
    };
    let new: Vec<usize> = active.iter().copied().filter(|c| !start.active.contains(c)).collect();
    let mut order = start.active.clone();
    order.extend(&new);
    let mut starts = vec![start.theta];
    for &c in &new {
        starts = starts.iter().flat_map(|t| starts_of(model, c, t, train)).collect();
    }
    best_of(model, &order, train, starts)
}

/// Starting values of mechanism `c` added to `theta`.
fn starts_of(model: &FdmModel, c: usize, theta: &Theta, train: &[&FdmLine]) -> Vec<Theta> {
    let t = *theta;
    match c {
        BED_TILT => vec![t],
        GEAR_ECCENTRICITY => vec![Theta { gear_period_mm: searched_period(model, &t, train), ..t }],
        FLOW_SATURATION => vec![Theta { saturation_loss: 0.02, ..t }],
        NONLINEAR_LAG => vec![
            Theta { lag_offset_s: 0.05, lag_speed_mm_s: 20.0, ..t },
            Theta { lag_offset_s: 0.3, lag_speed_mm_s: 60.0, ..t },
        ],
        TWO_STAGE_LAG => {
            vec![Theta { tau_slow_s: 0.3, slow_fraction: 0.2, ..t }, Theta { tau_slow_s: 1.5, slow_fraction: 0.2, ..t }]
        }
        WIDTH_CAP => vec![Theta { max_excess_mm: 0.3, ..t }, Theta { max_excess_mm: 1.0, ..t }],
        _ => vec![t],
    }
}

/// The gear's grid period on the residuals of `theta` (gear off); the middle of the
/// range when `theta` gives no valid widths.
fn searched_period(model: &FdmModel, theta: &Theta, train: &[&FdmLine]) -> f64 {
    let layout = Layout::new(model, &[]);
    let mut problem = Problem::new(model, &layout, train);
    if problem.simulate(theta).is_none() {
        return 0.5 * (gear::PERIOD_MIN_MM + gear::PERIOD_MAX_MM);
    }
    let lines: Vec<gear::SearchLine> = train
        .iter()
        .zip(&problem.simulated)
        .map(|(l, w)| (l.gear_table(), w.as_slice(), l.fit_widths_mm(), l.fit_positions_mm()))
        .collect();
    gear::best_period(&lines, model.setting.smoothing_mm)
}

/// The lowest-SSE least-squares fit of `active` over the starts.
fn best_of(model: &FdmModel, active: &[usize], train: &[&FdmLine], starts: Vec<Theta>) -> Result<FdmFit, ModelError> {
    let layout = Layout::new(model, active);
    let (lo, hi) = layout.bounds();
    let m: usize = train.iter().map(|l| l.fit_positions_mm().len()).sum();
    let settings = LmSettings { max_iterations: 40, relative_tolerance: 1e-6, ..LmSettings::default() };
    let mut problem = Problem::new(model, &layout, train);
    let start = screen(&mut problem, &layout, &starts, m)
        .ok_or_else(|| ModelError::Fit("no start point gives a valid width profile".into()))?;
    let solution = minimize(|u, r| problem.residuals(u, r), &start, &lo, &hi, m, &settings)
        .ok_or_else(|| ModelError::Fit("the least squares left the valid parameters".into()))?;
    let theta = layout.decode(&solution.x);
    let gear_amplitude = if has_gear(active) { fitted_gear_amplitude(model, &theta, train) } else { 0.0 };
    Ok(FdmFit { active: active.to_vec(), theta, gear_amplitude, training_rmse_mm: (solution.sse / m as f64).sqrt() })
}

/// The start with the lowest sum of squares (the least squares then runs from it
/// alone, as a grid search is refined from its best point).
fn screen(problem: &mut Problem, layout: &Layout, starts: &[Theta], m: usize) -> Option<Vec<f64>> {
    let mut r = vec![0.0; m];
    let mut best: Option<(f64, Vec<f64>)> = None;
    for start in starts {
        let u = layout.encode(start);
        if !problem.residuals(&u, &mut r) {
            continue;
        }
        let sse: f64 = r.iter().map(|v| v * v).sum();
        if sse.is_finite() && best.as_ref().is_none_or(|b| sse < b.0) {
            best = Some((sse, u));
        }
    }
    best.map(|b| b.1)
}

/// The gear ripple's shared amplitude on the training lines at `theta`.
fn fitted_gear_amplitude(model: &FdmModel, theta: &Theta, train: &[&FdmLine]) -> f64 {
    let layout = Layout::new(model, &[GEAR_ECCENTRICITY]);
    let mut problem = Problem::new(model, &layout, train);
    problem.simulate(theta).map_or(0.0, |_| problem.ripple(theta).0)
}

/// Predicts every measurement of `group`; the gear's phase from the `calibrate` samples.
pub fn predict(
    model: &FdmModel,
    fit: &FdmFit,
    group: &FdmLine,
    calibrate: Option<&[bool]>,
) -> Result<Vec<f64>, ModelError> {
    let line = &group.line;
    let mut w = vec![0.0; line.len()];
    if !widths(&fit.theta, &line.nominal, &model.setting, &line.positions_mm, &mut Scratch::default(), &mut w) {
        return Err(ModelError::Predict(format!("no valid width profile for line {}", group.label)));
    }
    if has_gear(&fit.active) {
        let mask = calibrate.ok_or_else(|| ModelError::Predict("the gear's phase needs calibration samples".into()))?;
        let (p, g) = (fit.theta.gear_period_mm, attenuation(fit.theta.gear_period_mm, model.setting.smoothing_mm));
        let phase = gear::line_phase(&line.positions_mm, &w, &line.widths_mm, p, |i| mask[i]);
        gear::apply(&line.positions_mm, &mut w, p, g, fit.gear_amplitude, phase);
    }
    Ok(w)
}

/// The least-squares residuals of one layout on the training lines.
struct Problem<'a> {
    model: &'a FdmModel,
    layout: &'a Layout,
    train: &'a [&'a FdmLine],
    /// Each training line's simulation state (its cached lag responses).
    scratch: Vec<Scratch>,
    /// Model widths of each training line at its fit samples.
    simulated: Vec<Vec<f64>>,
    /// The gear ripple's `sin`, `cos` basis of each training line.
    basis: Vec<(Vec<f64>, Vec<f64>)>,
}

impl<'a> Problem<'a> {
    fn new(model: &'a FdmModel, layout: &'a Layout, train: &'a [&'a FdmLine]) -> Self {
        let simulated = train.iter().map(|l| vec![0.0; l.fit_positions_mm().len()]).collect();
        let basis = vec![(Vec::new(), Vec::new()); train.len()];
        let scratch = vec![Scratch::default(); train.len()];
        Self { model, layout, train, scratch, simulated, basis }
    }

    /// Simulates every training line at `theta` (no ripple); `None` when invalid.
    fn simulate(&mut self, theta: &Theta) -> Option<()> {
        for ((line, w), scratch) in self.train.iter().zip(self.simulated.iter_mut()).zip(self.scratch.iter_mut()) {
            let ok = widths(theta, &line.line.nominal, &self.model.setting, line.fit_positions_mm(), scratch, w);
            ok.then_some(())?;
        }
        Some(())
    }

    /// The ripple's shared amplitude and each line's phase on the simulated widths,
    /// leaving each line's `sin`, `cos` basis in `self.basis`.
    fn ripple(&mut self, theta: &Theta) -> (f64, Vec<f64>) {
        let p = theta.gear_period_mm;
        let g = attenuation(p, self.model.setting.smoothing_mm);
        let (mut num, mut den) = (0.0, 0.0);
        let mut phases = Vec::with_capacity(self.train.len());
        for (k, (l, w)) in self.train.iter().zip(&self.simulated).enumerate() {
            let (sin, cos) = &mut self.basis[k];
            gear::basis_into(l.fit_positions_mm(), p, sin, cos);
            let (phase, ur, uu) = gear::phase_and_moments(sin, cos, w, l.fit_widths_mm());
            phases.push(phase);
            num += g * ur;
            den += g * g * uu;
        }
        let amplitude = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
        (amplitude, phases)
    }

    fn residuals(&mut self, u: &[f64], out: &mut [f64]) -> bool {
        let theta = self.layout.decode(u);
        if self.simulate(&theta).is_none() {
            return false;
        }
        let ripple = has_gear(&self.layout.active).then(|| self.ripple(&theta));
        let g = attenuation(theta.gear_period_mm, self.model.setting.smoothing_mm);
        let mut k = 0;
        for (i, (line, w)) in self.train.iter().zip(self.simulated.iter_mut()).enumerate() {
            let y = line.fit_widths_mm();
            if let Some((amplitude, phases)) = &ripple {
                let (sin, cos) = &self.basis[i];
                gear::apply_on_basis(sin, cos, w, g, *amplitude, phases[i]);
            }
            for (j, (wi, yi)) in w.iter().zip(y).enumerate() {
                out[k + j] = wi - yi;
            }
            k += y.len();
        }
        true
    }
}

/// Where each fitted parameter sits in the least-squares vector (the gear's amplitude
/// is profiled, not fitted), each on its declared scale. The parameters that leave the
/// lag's cached responses valid come first, so that the difference steps of a
/// Jacobian reuse them and only the last columns integrate again.
struct Layout {
    active: Vec<usize>,
    params: Vec<(Option<usize>, usize, Parameter)>,
}

impl Layout {
    fn new(model: &FdmModel, active: &[usize]) -> Self {
        let base = ::discrepancy::Model::params(model).iter().enumerate().map(|(i, p)| (None, i, *p));
        let extensions = active.iter().flat_map(|&c| {
            let fitted = if c == GEAR_ECCENTRICITY { 1 } else { CANDIDATES[c].params().len() };
            CANDIDATES[c].params()[..fitted].iter().enumerate().map(move |(i, p)| (Some(c), i, *p))
        });
        let mut params: Vec<_> = base.chain(extensions).collect();
        params.sort_by_key(|&(c, i, _)| integration_cost(c, i));
        Self { active: active.to_vec(), params }
    }

    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        self.params.iter().map(|(_, _, p)| (to_internal(p, p.lo), to_internal(p, p.hi))).unzip()
    }

    fn encode(&self, theta: &Theta) -> Vec<f64> {
        let mut t = *theta;
        self.params.iter().map(|&(c, i, p)| to_internal(&p, *slot(&mut t, c, i))).collect()
    }

    fn decode(&self, u: &[f64]) -> Theta {
        let mut theta = Theta::lag(0.0, 0.0, 0.0);
        for (&(c, i, p), &v) in self.params.iter().zip(u) {
            *slot(&mut theta, c, i) = if p.scale == Scale::Log { v.exp() } else { v };
        }
        theta
    }
}

/// 0: acts after the lag (reuses every cached response); 1: the slow path's τ₂; 2: the
/// fast path's τ; 3: the nonlinear lag (integrated in full); 4: the kinematics (a new
/// time grid).
fn integration_cost(c: Option<usize>, i: usize) -> u8 {
    match (c, i) {
        (None, 0) => 2,
        (Some(TWO_STAGE_LAG), 0) => 1,
        (Some(NONLINEAR_LAG), _) => 3,
        (Some(KINEMATICS_DEVIATION), _) => 4,
        _ => 0,
    }
}

fn to_internal(p: &Parameter, v: f64) -> f64 {
    if p.scale == Scale::Log {
        v.ln()
    } else {
        v
    }
}

/// The `Theta` field of parameter `i` of mechanism `c` (`None`: the baseline).
fn slot(theta: &mut Theta, c: Option<usize>, i: usize) -> &mut f64 {
    match (c, i) {
        (None, 0) => &mut theta.tau_s,
        (None, 1) => &mut theta.w0_mm,
        (None, _) => &mut theta.blob_mm2_s,
        (Some(BED_TILT), _) => &mut theta.tilt_width_change,
        (Some(GEAR_ECCENTRICITY), _) => &mut theta.gear_period_mm,
        (Some(FLOW_SATURATION), _) => &mut theta.saturation_loss,
        (Some(NONLINEAR_LAG), 0) => &mut theta.lag_offset_s,
        (Some(NONLINEAR_LAG), _) => &mut theta.lag_speed_mm_s,
        (Some(TWO_STAGE_LAG), 0) => &mut theta.tau_slow_s,
        (Some(TWO_STAGE_LAG), _) => &mut theta.slow_fraction,
        (Some(WIDTH_CAP), _) => &mut theta.max_excess_mm,
        (Some(_), 0) => &mut theta.r_a,
        (Some(_), _) => &mut theta.r_f,
    }
}

#[cfg(test)]
mod tests {
    use ::discrepancy::Model;

    use super::super::forward::LineSetting;
    use super::super::gear;
    use super::*;
    use crate::fdm::kinematics::LineKinematics;
    use crate::fdm::line::MeasuredLine;
    use crate::fdm::synthetic::TABLE_I;

    /// Noiseless lines of Table I from the forward model at `truth` (with a gear ripple
    /// of `gear_amplitude` at phases 0.7·k when its period is set), every 0.1 mm.
    fn lines_from(truth: &Theta, gear_amplitude: f64) -> (FdmModel, Vec<FdmLine>) {
        let setting = LineSetting { smoothing_mm: 0.5, v_ref_mm_s: 150.0 };
        let xs: Vec<f64> = (0..=1200).map(|i| i as f64 * 0.1).collect();
        let lines: Vec<FdmLine> = TABLE_I
            .iter()
            .enumerate()
            .map(|(k, &(a, f))| {
                let nominal = LineKinematics::paper_line(a, f).unwrap();
                let mut w = vec![0.0; xs.len()];
                assert!(widths(truth, &nominal, &setting, &xs, &mut Scratch::default(), &mut w));
                if truth.gear_period_mm.is_finite() {
                    let g = attenuation(truth.gear_period_mm, 0.5);
                    gear::apply(&xs, &mut w, truth.gear_period_mm, g, gear_amplitude, 0.7 * k as f64);
                }
                FdmLine::new(format!("line{k}"), MeasuredLine::new(nominal, xs.clone(), w).unwrap())
            })
            .collect();
        let model = FdmModel::new(&lines, truth.blob_mm2_s != 0.0, 0.5);
        assert_eq!(model.setting, setting);
        (model, lines)
    }

    /// Fits `[c]` to lines drawn with `truth` and checks every estimate against it.
    fn recovers(c: usize, truth: Theta, gear_amplitude: f64, tolerance: f64) {
        let (model, lines) = lines_from(&truth, gear_amplitude);
        let train: Vec<&FdmLine> = lines.iter().collect();
        let fit = model.fit(&[c], &train, None).unwrap();
        let expected =
            model.estimates(&FdmFit { active: vec![c], theta: truth, gear_amplitude, training_rmse_mm: 0.0 });
        let got = model.estimates(&fit);
        for (i, (g, e)) in got.iter().zip(&expected).enumerate() {
            assert!(
                (g - e).abs() <= tolerance * e.abs().max(1e-3),
                "{} parameter {i}: {g} vs {e}",
                CANDIDATES[c].name()
            );
        }
        assert!(fit.training_rmse_mm < 1e-4, "{}: rmse {}", CANDIDATES[c].name(), fit.training_rmse_mm);
    }

    fn lag() -> Theta {
        Theta::lag(0.06, 0.78, 5.0)
    }

    #[test]
    fn each_mechanism_recovers_its_parameters_from_noiseless_lines() {
        // The data are the model itself, so the least squares must return the truth up
        // to the optimiser's tolerance (1e-6 relative fall of the sum of squares).
        recovers(BED_TILT, Theta { tilt_width_change: 0.03, ..lag() }, 0.0, 1e-2);
        recovers(GEAR_ECCENTRICITY, Theta { gear_period_mm: 13.7, ..lag() }, 0.03, 1e-2);
        recovers(FLOW_SATURATION, Theta { saturation_loss: 0.06, ..lag() }, 0.0, 1e-2);
        recovers(NONLINEAR_LAG, Theta { lag_offset_s: 0.12, lag_speed_mm_s: 25.0, ..lag() }, 0.0, 5e-2);
        recovers(TWO_STAGE_LAG, Theta { tau_slow_s: 0.6, slow_fraction: 0.25, ..lag() }, 0.0, 2e-2);
        recovers(WIDTH_CAP, Theta { max_excess_mm: 0.35, ..lag() }, 0.0, 1e-2);
        recovers(KINEMATICS_DEVIATION, Theta { r_a: 1.05, r_f: 0.96, ..lag() }, 0.0, 1e-2);
    }

    #[test]
    fn the_plain_lag_is_recovered_and_predicts_a_held_out_line_exactly() {
        let truth = lag();
        let (model, lines) = lines_from(&truth, 0.0);
        let train: Vec<&FdmLine> = lines[1..].iter().collect();
        let fit = model.fit(&[], &train, None).unwrap();
        assert!((fit.theta.tau_s - 0.06).abs() < 1e-4 && (fit.theta.w0_mm - 0.78).abs() < 1e-5);
        let predicted = model.predict(&fit, &lines[0], None).unwrap();
        let worst = predicted.iter().zip(&lines[0].line.widths_mm).map(|(p, y)| (p - y).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-4, "{worst}");
        // The gear's phase needs calibration samples.
        let gear_fit = FdmFit { active: vec![GEAR_ECCENTRICITY], ..fit };
        assert!(model.predict(&gear_fit, &lines[0], None).is_err());
    }
}
