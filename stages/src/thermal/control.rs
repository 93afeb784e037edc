//! `thermal.control_gain`: does the extended model print better? For each print (one
//! seed, the flow lagging with a τ off the nominal by a given strength), the virtual
//! printer prints and films the corner test part; the monitor (`thermal.monitor`'s
//! code) measures it and the discrepancy engine (`thermal.discrepancy`'s model), told
//! nothing, names what is wrong. The part is then re-printed three times on the same
//! printer with the same flow draws (paper 003 Sec. 3.3):
//!
//! - `conventional`: the nominal command, no compensation;
//! - `paper`: the filtered-B-spline compensation of eqs 31-39 (`thermal.compensate`,
//!   its defaults) from the first layer's widths, with the nominal τ in G(s) (eq. 34);
//! - `extended`: the same compensation from the same widths, with the τ the engine
//!   fitted, `τ0·(1 + m̂)`, when it named `tau_mismatch` (otherwise the nominal: then it
//!   is the paper's command).
//!
//! Each print is scored as Sec. 3.3 scores it (`models::thermal::metrics::print_quality`):
//! the first layer's mean O_E over the corners (eq. 40) and the contour error's max and
//! RMS over every layer (eq. 41, Table 3). What changes between `paper` and `extended`
//! is the deposition model only; the monitor, its widths and the desired widths are the
//! same. An evaluation stage: it prints on the virtual printer and knows what it printed.
//!
//! Outputs (docs/OUTPUTS.md): `control_gain.parquet` (per strength and controller: each
//! metric's mean over prints with a 95 % Student-t interval, and the mean paired
//! difference to the paper's controller with its interval) and `control_trials.parquet`
//! (one row per print and controller, with what the engine named and fitted).
//!
//! Work units (`pipeline::units`, docs/SCALE.md): one per print. A print's seed comes
//! from its strength's place in the list and its own index, never from the unit it runs
//! in, and its part is its three rows of `control_trials.parquet`, from which the merge
//! rebuilds every trial exactly (Parquet keeps each `f64` bit for bit).

use std::path::{Path, PathBuf};

use datasets::thermal::deposition::print_part;
use datasets::thermal::Effects;
use discrepancy::stats::{mix_seed, t_interval};
use models::thermal::discrepancy::TAU_MISMATCH;
use models::thermal::metrics::{print_quality, IdealBead, PrintQuality};
use pipeline::params::{ParamError, StageParams};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::units::run_split;
use pipeline::{Params, Split, StageContext, StageError, Unit};
use polars::prelude::DataFrame;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use tables::thermal::{control_gain, control_part, control_trials};

use super::common::trajectory_of;
use super::compensate::{compensate, CompensateParams, MonitorInputs};
use super::filmed_print::{named_list, FilmedPrint, Filming, FilmingParams};
use crate::effects::strength_list;
use crate::parts::{listed, read_parts};
use crate::table::{f64_col, f64s, frame, i64_col, ints, str_col, strs};

/// The `thermal.control_gain` stage kind.
pub struct ControlGainStage;

/// The controllers, in table order.
const CONTROLLERS: [&str; 3] = ["conventional", "paper", "extended"];

/// The effect the compensation's model can take up: G(s)'s τ.
const EFFECT: &str = "tau_mismatch";

/// Mixed into a print's seed for the re-prints' flow draws (all three the same).
const REPRINT_SALT: u64 = 0x4354_524c_5245_5052;

pipeline::params! {
    /// The parameters of `thermal.control_gain`.
    pub struct ControlGainParams {
        /// Strengths of tau_mismatch (actual τ = nominal·(1 + strength)), comma-separated.
        pub tau_mismatch: String = "0.3",
        /// Prints (seeds) per strength; each is filmed, then re-printed three times.
        pub prints: i64 [2, 10_000] = 4,
        /// Filmed layers of each print (the engine's groups).
        pub layers: i64 [2, 20] = 8,
        /// Layers of each re-print scored by eq. 41 (Table 3: 20).
        pub reprint_layers: i64 [1, 50] = 20,
        /// Radius of the corner window of eq. 40 (mm), as `thermal.reprint_evaluate`'s.
        pub corner_radius_mm: f64 [0.1, 5.0] = 1.0,
        /// Spacing of the CAD contour points of eq. 41 (mm), as `thermal.reprint_evaluate`'s.
        pub contour_spacing_mm: f64 [0.005, 1.0] = 0.05,
        /// Most causes named: after each, the extended model is the baseline and the search repeats.
        pub max_rounds: i64 [1, 5] = 2,
    }
    groups {
        /// How the prints are filmed and read.
        pub filming: FilmingParams,
    }
}

impl ControlGainParams {
    /// The strengths of `tau_mismatch`, each checked against the printer's range.
    fn strengths(&self) -> Result<Vec<f64>, ParamError> {
        strength_list(EFFECT, &self.tau_mismatch, 10.0, " (relative)")
    }
}

impl Stage for ControlGainStage {
    type Params = ControlGainParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.control_gain",
        // 2: the engine's noise scales use models::stats' median.
        // 3: layer_heat_accumulation is fitted with a weak prior on the first carried excess.
        // 4: the contour map knows the bead's age and the seam is no straight run.
        // 5: the contour map has a level per straight run.
        // 6: the contour map has a quadratic in the age per straight run and a gain growing with the age.
        version: 6,
        summary: "Prints with a flow τ off the nominal, compensated (eqs 31-39) with the paper's τ and with the τ the discrepancy engine fitted, re-printed and scored (eqs 40-41) → control_gain.parquet, control_trials.parquet",
        implements: "paper 003 eqs 31-41 (Secs 2.4, 3.3) with the discrepancy engine's extended model (DESIGN §7; evaluation)",
        inputs: &[],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&control_gain::TABLE, &control_trials::TABLE, &control_part::TABLE];

    fn check(p: &ControlGainParams) -> Result<(), ParamError> {
        p.strengths()?;
        p.filming.check()
    }

    fn run(&self, ctx: &mut StageContext, _: &ControlGainParams) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

/// Work units: one per print, strength-major (the order of the tables' rows).
impl Split for ControlGainStage {
    fn units(&self, params: &Params, _inputs: usize) -> Vec<Unit> {
        let study = ControlGainParams::from_params(params);
        let prints = study.prints as usize;
        (0..listed(&study.tau_mismatch))
            .flat_map(|c| (0..prints).map(move |p| Unit { key: format!("strength {c} print {p}"), cost: 1.0 }))
            .collect()
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let p = ControlGainParams::from_params(&ctx.params);
        let design = Design::new(&p, ctx.seed).map_err(|e| StageError::params(ctx, e))?;
        let (cell, print) = (index / design.prints, index % design.prints);
        let strength = *design.strengths.get(cell).ok_or_else(|| StageError::Params {
            stage: ctx.stage.clone(),
            message: format!("work unit {index} is past the study's {} strengths", design.strengths.len()),
        })?;
        let scratch = ctx.output_dir().join("scratch");
        let trial = design.trial(cell, strength, print, &scratch)?;
        std::fs::remove_dir_all(&scratch).ok();
        ctx.write_table(control_part::TABLE.name, &mut trials_frame(&[trial])?)?;
        Ok(())
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        let trials = trials_from_frame(&read_parts(parts)?, &ctx.output_dir().join("parts"))?;
        ctx.write_table(control_gain::TABLE.name, &mut gain_frame(&trials)?)?;
        ctx.write_table(control_trials::TABLE.name, &mut trials_frame(&trials)?)?;
        Ok(())
    }
}

/// The checked study.
struct Design {
    strengths: Vec<f64>,
    prints: usize,
    reprint_layers: usize,
    corner_radius_mm: f64,
    contour_spacing_mm: f64,
    seed: u64,
    filming: Filming,
    compensation: CompensateParams,
}

/// One print: what the engine made of it and its three re-prints.
struct Trial {
    strength: f64,
    print: usize,
    seed: u64,
    named: String,
    /// The engine's τ excess with its interval, when it named `tau_mismatch`.
    fitted: Option<(f64, f64, f64)>,
    /// Per controller, in [`CONTROLLERS`] order.
    quality: [PrintQuality; 3],
}

impl Design {
    /// The study of `p`, its prints seeded from the stage's `seed`; the compensation
    /// runs with `thermal.compensate`'s defaults.
    fn new(p: &ControlGainParams, seed: u64) -> Result<Self, ParamError> {
        Ok(Self {
            strengths: p.strengths()?,
            prints: p.prints as usize,
            reprint_layers: p.reprint_layers as usize,
            corner_radius_mm: p.corner_radius_mm,
            contour_spacing_mm: p.contour_spacing_mm,
            seed,
            filming: Filming::new(&p.filming, p.layers, p.max_rounds, seed)?,
            compensation: CompensateParams::stage_defaults(),
        })
    }

    /// Prints and films one part in `scratch`, lets the engine read it, compensates
    /// with both models, re-prints and scores.
    fn trial(&self, cell: usize, strength: f64, print: usize, scratch: &Path) -> Result<Trial, StageError> {
        let seed = mix_seed(self.seed, cell as u64, print as u64);
        let effects = Effects::from_pairs([(EFFECT, strength)]).map_err(StageError::domain)?;
        let FilmedPrint { sequence: seq, tables, found } =
            self.filming.film(effects, seed, scratch, &format!("control print {print}"))?;
        let fitted =
            found.extension.iter().find(|e| e.mechanism == Some(TAU_MISMATCH)).map(|e| (e.estimate, e.ci_lo, e.ci_hi));
        let named = named_list(&found.named);
        let setup = seq.process.print_setup();
        let inputs = MonitorInputs {
            dir: scratch,
            widths_dir: scratch,
            widths: &tables.widths,
            directions: &tables.directions,
            detections: &tables.detections,
        };
        let paper = compensate(&seq, &inputs, &self.compensation, setup.tau_s)?;
        let tau_extended_s = setup.tau_s * (1.0 + fitted.map_or(0.0, |f| f.0));
        let extended = compensate(&seq, &inputs, &self.compensation, tau_extended_s)?;
        let commands = [&paper.nominal_mm_s, &paper.command_mm_s, &extended.command_mm_s];
        let quality = self.reprint(&seq, &effects, seed, commands)?;
        Ok(Trial { strength, print, seed, named, fitted, quality })
    }

    /// Re-prints the part with each command on the same printer and flow draws, scored.
    fn reprint(
        &self,
        seq: &datasets::thermal::ThermalSequence,
        effects: &Effects,
        seed: u64,
        commands: [&Vec<f64>; 3],
    ) -> Result<[PrintQuality; 3], StageError> {
        let setup = seq.process.print_setup();
        let trajectory = trajectory_of(seq)?;
        let bead = IdealBead::new(&seq.path_mm, setup.bead_width_mm / 2.0).map_err(StageError::domain)?;
        let cad = bead.contour_points(self.contour_spacing_mm, false);
        let score = |command: &Vec<f64>| -> Result<PrintQuality, StageError> {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ REPRINT_SALT);
            let printed = print_part(&setup, &trajectory, command, self.reprint_layers, effects, &mut rng)
                .map_err(StageError::domain)?;
            let grids: Vec<_> = printed.into_iter().map(|l| l.grid).collect();
            Ok(print_quality(&grids, &bead, &seq.path_mm, setup.bead_width_mm, self.corner_radius_mm, &cad))
        };
        let scored: Vec<PrintQuality> = commands.par_iter().map(|c| score(c)).collect::<Result<_, _>>()?;
        Ok([scored[0], scored[1], scored[2]])
    }
}

/// One metric of a print: its column of `control_trials` (and of the parts), its six
/// columns of `control_gain` (the mean and its interval, the paired difference to
/// `paper` and its interval) and how to read it.
type Metric = (&'static str, [&'static str; 6], fn(&PrintQuality) -> f64);

/// The three metrics of Sec. 3.3, in table order.
const METRICS: [Metric; 3] = {
    use control_gain as g;
    [
        (
            control_trials::mean_oe_pct,
            [
                g::mean_oe_pct,
                g::mean_oe_pct_ci_lo,
                g::mean_oe_pct_ci_hi,
                g::mean_oe_pct_vs_paper,
                g::mean_oe_pct_vs_paper_ci_lo,
                g::mean_oe_pct_vs_paper_ci_hi,
            ],
            |q| q.mean_oe_pct,
        ),
        (
            control_trials::contour_rms_mm,
            [
                g::contour_rms_mm,
                g::contour_rms_mm_ci_lo,
                g::contour_rms_mm_ci_hi,
                g::contour_rms_mm_vs_paper,
                g::contour_rms_mm_vs_paper_ci_lo,
                g::contour_rms_mm_vs_paper_ci_hi,
            ],
            |q| q.contour_rms_mm,
        ),
        (
            control_trials::contour_max_mm,
            [
                g::contour_max_mm,
                g::contour_max_mm_ci_lo,
                g::contour_max_mm_ci_hi,
                g::contour_max_mm_vs_paper,
                g::contour_max_mm_vs_paper_ci_lo,
                g::contour_max_mm_vs_paper_ci_hi,
            ],
            |q| q.contour_max_mm,
        ),
    ]
};

/// `control_gain.parquet`: per strength and controller, each metric's mean over prints
/// with its 95 % Student-t interval, and the paired difference to `paper`.
fn gain_frame(trials: &[Trial]) -> Result<polars::prelude::DataFrame, StageError> {
    let mut strengths: Vec<f64> = trials.iter().map(|t| t.strength).collect();
    strengths.dedup();
    let (mut strength, mut controller, mut prints, mut named) = (vec![], vec![], vec![], vec![]);
    let mut columns: Vec<(&str, Vec<f64>)> =
        METRICS.iter().flat_map(|(_, gain, _)| gain.map(|name| (name, Vec::new()))).collect();
    for s in strengths {
        let these: Vec<&Trial> = trials.iter().filter(|t| t.strength == s).collect();
        for (c, name) in CONTROLLERS.iter().enumerate() {
            strength.push(s);
            controller.push(name.to_string());
            prints.push(these.len() as i64);
            named.push(these.iter().filter(|t| t.fitted.is_some()).count() as i64);
            for (m, (_, _, metric)) in METRICS.iter().enumerate() {
                let values: Vec<f64> = these.iter().map(|t| metric(&t.quality[c])).collect();
                let paired: Vec<f64> = these.iter().map(|t| metric(&t.quality[c]) - metric(&t.quality[1])).collect();
                let (mean, diff) = (t_interval(&values), t_interval(&paired));
                for (k, v) in [mean.0, mean.1, mean.2, diff.0, diff.1, diff.2].into_iter().enumerate() {
                    columns[6 * m + k].1.push(v);
                }
            }
        }
    }
    let mut cols = vec![
        str_col(control_gain::effect, vec![EFFECT.to_string(); strength.len()]),
        f64_col(control_gain::strength, strength),
        str_col(control_gain::controller, controller),
        i64_col(control_gain::prints, prints),
        i64_col(control_gain::tau_named, named),
    ];
    cols.extend(columns.into_iter().map(|(name, values)| f64_col(name, values)));
    frame(cols)
}

/// `control_trials.parquet` (and a unit's `part.parquet`, the same columns): one row
/// per print and controller.
fn trials_frame(trials: &[Trial]) -> Result<polars::prelude::DataFrame, StageError> {
    let rows: Vec<(&Trial, usize)> = trials.iter().flat_map(|t| (0..3).map(move |c| (t, c))).collect();
    let fitted = |k: usize| -> Vec<f64> {
        rows.iter().map(|(t, _)| t.fitted.map_or(f64::NAN, |f| [f.0, f.1, f.2][k])).collect()
    };
    let mut cols = vec![
        str_col(control_trials::effect, vec![EFFECT.to_string(); rows.len()]),
        f64_col(control_trials::strength, rows.iter().map(|(t, _)| t.strength).collect()),
        i64_col(control_trials::print, rows.iter().map(|(t, _)| t.print as i64).collect()),
        str_col(control_trials::seed, rows.iter().map(|(t, _)| format!("{:016x}", t.seed)).collect()),
        str_col(control_trials::named, rows.iter().map(|(t, _)| t.named.clone()).collect()),
        f64_col(control_trials::tau_excess, fitted(0)),
        f64_col(control_trials::tau_excess_ci_lo, fitted(1)),
        f64_col(control_trials::tau_excess_ci_hi, fitted(2)),
        str_col(control_trials::controller, rows.iter().map(|(_, c)| CONTROLLERS[*c].to_string()).collect()),
    ];
    for (name, _, metric) in METRICS {
        cols.push(f64_col(name, rows.iter().map(|(t, c)| metric(&t.quality[*c])).collect()));
    }
    frame(cols)
}

/// The trials of [`trials_frame`]'s rows (the merged parts: three per print, in
/// [`CONTROLLERS`] order), exactly: a `tau_excess` of NaN is a print on which the engine did not name τ.
fn trials_from_frame(all: &DataFrame, file: &Path) -> Result<Vec<Trial>, StageError> {
    let bad = |row: usize, expected: String| StageError::BadInput {
        file: file.to_path_buf(),
        location: Some(format!("row {row}")),
        expected,
    };
    use control_part as c;
    let (strength, print) = (f64s(all, c::strength, file)?, ints(all, c::print, file)?);
    let (seed, named, controller) =
        (strs(all, c::seed, file)?, strs(all, c::named, file)?, strs(all, c::controller, file)?);
    let [tau, tau_lo, tau_hi] = [c::tau_excess, c::tau_excess_ci_lo, c::tau_excess_ci_hi].map(|c| f64s(all, c, file));
    let (tau, tau_lo, tau_hi) = (tau?, tau_lo?, tau_hi?);
    let [oe, rms, max] = [c::mean_oe_pct, c::contour_rms_mm, c::contour_max_mm].map(|c| f64s(all, c, file));
    let (oe, rms, max) = (oe?, rms?, max?);
    if !all.height().is_multiple_of(CONTROLLERS.len()) {
        return Err(bad(all.height(), format!("{} rows per print", CONTROLLERS.len())));
    }
    (0..all.height())
        .step_by(CONTROLLERS.len())
        .map(|first| {
            for (c, name) in CONTROLLERS.iter().enumerate() {
                if controller[first + c] != *name {
                    return Err(bad(first + c, format!("controller `{name}`, got `{}`", controller[first + c])));
                }
            }
            let seed = u64::from_str_radix(&seed[first], 16)
                .map_err(|_| bad(first, format!("a seed in hexadecimal, got `{}`", seed[first])))?;
            let quality = [0, 1, 2].map(|c| PrintQuality {
                mean_oe_pct: oe[first + c],
                contour_max_mm: max[first + c],
                contour_rms_mm: rms[first + c],
            });
            Ok(Trial {
                strength: strength[first],
                print: print[first] as usize,
                seed,
                named: named[first].clone(),
                fitted: (!tau[first].is_nan()).then(|| (tau[first], tau_lo[first], tau_hi[first])),
                quality,
            })
        })
        .collect()
}
