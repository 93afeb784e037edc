//! The power study (DESIGN §7): how often the engine names an effect hidden in a
//! measured data set, how often it names something that is not there, and whether its
//! interval for the effect's strength covers the truth.
//!
//! First the engine runs on the base data as measured; the causes it names there are
//! the data's own, and every draw starts from the lag model extended by them, so a
//! draw's rounds are spent on what is new and the data's own causes are never counted
//! as false alarms. A draw is a surrogate of the base ([`super::surrogate`]: the
//! own-cause model's widths plus a phase-randomised copy of each line's residual), with
//! one effect of a given strength injected by [`super::inject`] (the tilt's sign and
//! the gear's period and phases drawn from the draw's seed). The engine is then run
//! without being told what was injected and scored: *correct* when it names the
//! injected mechanism and nothing else, *wrong* when it names anything else, *none*
//! when it names nothing. Null draws inject `none`. With [`Noise::White`] the residual is
//! replaced by independent noise of the lines' sample-to-sample scatter instead, which
//! separates what limits the engine from what limits the data.

use rayon::prelude::*;

use ::discrepancy::power::DrawScore;
use ::discrepancy::stats::mix_seed;
use ::discrepancy::{discover, discover_warm, EngineError, Model, Settings};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::inject::{inject, Effect, InjectError, InjectSettings};
use super::mechanisms::{candidate_index, CANDIDATES};
use super::surrogate::Surrogates;
use super::{FdmFit, FdmLine, FdmModel};

/// What to draw.
#[derive(Debug, Clone, PartialEq)]
pub struct PowerDesign {
    /// `(effect, strength)` cells; strengths are magnitudes (the tilt's sign is drawn).
    pub cells: Vec<(Effect, f64)>,
    /// Draws per cell.
    pub draws_per_cell: usize,
    /// Null draws (effect `none`).
    pub null_draws: usize,
    /// Seed of every draw.
    pub seed: u64,
    /// The engine's settings (its seed is replaced by the draw's).
    pub engine: Settings,
    /// How effects are injected.
    pub inject: InjectSettings,
    /// What noise a draw carries.
    pub noise: Noise,
}

impl PowerDesign {
    /// How many draws the design makes on one base.
    pub fn draw_count(&self) -> usize {
        self.null_draws + self.cells.len() * self.draws_per_cell
    }
}

/// The noise of a draw around the own-cause model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Noise {
    /// A phase-randomised copy of each line's measured residual: the data's own noise,
    /// slow swells included.
    Measured,
    /// Independent Gaussian noise with each line's sample-to-sample scatter
    /// (`σ² = mean((r_{i+1} − r_i)²)/2`): measurement noise only, no slow swells — what
    /// the engine could do on lines the model describes up to their measurement noise.
    White,
}

impl Noise {
    /// `measured` or `white`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Measured => "measured",
            Self::White => "white",
        }
    }
}

/// A base data set with the engine's verdict on it.
pub struct Base {
    /// Label (printer).
    pub label: String,
    /// The model of its lines.
    pub model: FdmModel,
    /// Its lines.
    pub lines: Vec<FdmLine>,
    /// Causes the engine names on it as measured.
    pub own: Vec<usize>,
    /// The own-cause model's widths of every line (fitted on all lines).
    pub fitted: Vec<Vec<f64>>,
    /// The own-cause model's fold fits on the measured lines: the draws' folds start
    /// from them (fold `k` never saw line `k`).
    pub folds: Vec<FdmFit>,
}

/// Why the study could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PowerError {
    /// The engine failed.
    #[error(transparent)]
    Engine(#[from] EngineError),
    /// An injection was refused.
    #[error(transparent)]
    Inject(#[from] InjectError),
}

impl Base {
    /// Runs the engine on the measured lines to find the data's own causes.
    pub fn new(
        label: impl Into<String>,
        model: FdmModel,
        lines: Vec<FdmLine>,
        engine: &Settings,
    ) -> Result<Self, PowerError> {
        let found = discover(&model, &lines, &[], engine)?;
        let all = vec![true; lines.iter().map(|l| l.line.len()).max().unwrap_or(0)];
        let fitted = lines
            .iter()
            .map(|l| model.predict(&found.final_fit, l, Some(&all[..l.line.len()])))
            .collect::<Result<_, _>>()
            .map_err(EngineError::from)?;
        Ok(Self { label: label.into(), model, lines, own: found.named, fitted, folds: found.extended.folds })
    }
}

pub use ::discrepancy::power::{Outcome, PowerRow};

/// One draw.
#[derive(Debug, Clone, PartialEq)]
pub struct DrawResult {
    /// The effect injected.
    pub effect: Effect,
    /// The cell's strength (a magnitude).
    pub strength: f64,
    /// Draw number within its cell.
    pub draw: usize,
    /// Its seed.
    pub seed: u64,
    /// The strength as injected (signed for the tilt).
    pub injected: f64,
    /// Mechanisms named (beyond the data's own).
    pub named: Vec<usize>,
    /// The verdict against the truth.
    pub outcome: Outcome,
    /// Fitted strength with its 95 % interval, when correct.
    pub fitted: Option<(f64, f64, f64)>,
}

impl DrawResult {
    /// Whether the interval covers the injected strength (when correct).
    pub fn covered(&self) -> Option<bool> {
        self.fitted.map(|(_, lo, hi)| lo <= self.injected && self.injected <= hi)
    }

    /// What the power table needs.
    pub fn score(&self) -> DrawScore {
        DrawScore {
            effect: self.effect.name(),
            strength: self.strength,
            outcome: self.outcome,
            covered: self.covered(),
        }
    }
}

/// Runs every draw of `design` on `base`, in parallel; the results are in design order
/// and do not depend on the number of threads.
pub fn run_draws(base: &Base, design: &PowerDesign) -> Result<Vec<DrawResult>, PowerError> {
    run_draw_range(base, design, 0..design.draw_count())
}

/// Draws `range` of [`run_draws`]' list (null draws first, then each cell's), in
/// parallel: a draw's result depends only on its place in the list, so a study split
/// into ranges gives the draws of the whole.
pub fn run_draw_range(
    base: &Base,
    design: &PowerDesign,
    range: std::ops::Range<usize>,
) -> Result<Vec<DrawResult>, PowerError> {
    let surrogates = Surrogates::new(base.lines.iter().map(|l| l.line.len()));
    let mut jobs: Vec<(usize, Effect, f64, usize)> =
        (0..design.null_draws).map(|d| (0, Effect::None, 0.0, d)).collect();
    for (c, &(effect, strength)) in design.cells.iter().enumerate() {
        jobs.extend((0..design.draws_per_cell).map(|d| (c + 1, effect, strength, d)));
    }
    jobs[range]
        .par_iter()
        .map(|&(cell, effect, strength, draw)| {
            let seed = mix_seed(design.seed, cell as u64, draw as u64);
            one_draw(base, design, &surrogates, effect, strength, draw, seed)
        })
        .collect()
}

fn one_draw(
    base: &Base,
    design: &PowerDesign,
    surrogates: &Surrogates,
    effect: Effect,
    strength: f64,
    draw: usize,
    seed: u64,
) -> Result<DrawResult, PowerError> {
    let measured: Vec<_> = base
        .lines
        .iter()
        .zip(&base.fitted)
        .enumerate()
        .map(|(i, (l, fitted))| {
            let residual: Vec<f64> = l.line.widths_mm.iter().zip(fitted).map(|(y, f)| y - f).collect();
            let line_seed = mix_seed(seed, 1_000 + i as u64, 0);
            let noise = match design.noise {
                Noise::Measured => surrogates.draw(&residual, line_seed),
                Noise::White => white_noise(&residual, line_seed),
            };
            let widths = fitted.iter().zip(&noise).map(|(f, e)| (f + e).max(1e-3)).collect();
            crate::fdm::line::MeasuredLine { widths_mm: widths, ..l.line.clone() }
        })
        .collect();
    let signed = if effect == Effect::BedTilt && seed & 1 == 1 { -strength } else { strength };
    let (injected, record) = inject(&measured, effect, signed, seed, &design.inject)?;
    let lines: Vec<FdmLine> = base.lines.iter().zip(injected).map(|(l, m)| FdmLine::new(l.label.clone(), m)).collect();
    let engine = Settings { seed, ..design.engine };
    let found = discover_warm(&base.model, &lines, &base.own, Some(&base.folds), &engine)?;
    let target = candidate_index(effect.name());
    let outcome = Outcome::of(&found.named, target);
    let fitted = (outcome == Outcome::Correct)
        .then(|| {
            let name = effect.strength_parameter()?;
            found
                .extension
                .iter()
                .find(|e| e.mechanism == target && e.parameter.name == name)
                .map(|e| (e.estimate, e.ci_lo, e.ci_hi))
        })
        .flatten();
    Ok(DrawResult { effect, strength, draw, seed, injected: record.strength, named: found.named, outcome, fitted })
}

/// Gaussian noise as long as `residual`, with its sample-to-sample scatter.
fn white_noise(residual: &[f64], seed: u64) -> Vec<f64> {
    let n = residual.len().max(2);
    let scatter = residual.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (2.0 * (n - 1) as f64);
    let normal = Normal::new(0.0, scatter.sqrt()).unwrap_or_else(|_| Normal::new(0.0, 0.0).expect("σ = 0 is valid"));
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    residual.iter().map(|_| normal.sample(&mut rng)).collect()
}

/// The draws summarised per (effect, strength), in the order first seen.
pub fn summarize(draws: &[DrawResult]) -> Vec<PowerRow> {
    ::discrepancy::power::summarize(&draws.iter().map(DrawResult::score).collect::<Vec<_>>())
}

/// The names of mechanisms, joined by `+` (`none` for none).
pub fn names(mechanisms: &[usize]) -> String {
    if mechanisms.is_empty() {
        return "none".into();
    }
    mechanisms.iter().map(|&m| CANDIDATES[m].name()).collect::<Vec<_>>().join("+")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fdm::test_support::real_lines;
    use ::discrepancy::stats::clopper_pearson;

    fn taz5() -> Option<Vec<FdmLine>> {
        let lines = real_lines("taz5")?;
        Some(lines.into_iter().enumerate().map(|(k, l)| FdmLine::new(format!("line{k}"), l)).collect())
    }

    #[test]
    fn small_fixed_seed_power_study_on_the_taz5() {
        // 60 null draws and 20 draws of each effect at a strength the full study
        // (`specs/discrepancy_fdm.toml`) names in at least 95 % of draws. Binomial slack:
        // a rate must not be significantly worse than its bar at 95 % (Clopper–Pearson).
        let Some(lines) = taz5() else { return };
        let model = FdmModel::new(&lines, true, 0.5);
        let engine = Settings { bootstrap_draws: 200, ..Settings::standard(1) };
        let base = Base::new("taz5", model, lines, &engine).unwrap();
        assert_eq!(names(&base.own), "width_cap", "the Taz 5's own cause");
        let design = PowerDesign {
            cells: vec![(Effect::GearEccentricity, 0.1), (Effect::FlowSaturation, 0.2)],
            draws_per_cell: 20,
            null_draws: 60,
            seed: 11,
            engine,
            inject: InjectSettings::default(),
            noise: Noise::Measured,
        };
        let rows = summarize(&run_draws(&base, &design).unwrap());
        for r in &rows {
            eprintln!(
                "{} {}: correct {} wrong {} none {} covered {:?}",
                r.effect, r.strength, r.correct, r.wrong, r.none, r.covered
            );
        }
        let null = &rows[0];
        assert_eq!((null.effect, null.draws), ("none", 60));
        assert!(null.false_alarm_rate.1 < 0.05, "null false alarms {} of 60", null.wrong);
        for r in &rows[1..] {
            assert!(r.correct_rate.2 >= 0.95, "{}: named {} of {}", r.effect, r.correct, r.draws);
            assert!(r.false_alarm_rate.1 < 0.02, "{}: wrong {} of {}", r.effect, r.wrong, r.draws);
        }
        // The strength intervals' coverage over all correct draws: not significantly
        // outside 90-98 %.
        let (covered, with): (usize, usize) =
            rows[1..].iter().fold((0, 0), |a, r| (a.0 + r.covered.0, a.1 + r.covered.1));
        let (lo, hi) = clopper_pearson(covered, with, 0.95);
        assert!(lo <= 0.98 && hi >= 0.90, "coverage {covered} of {with}");
    }
}
