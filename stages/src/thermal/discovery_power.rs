//! `thermal.discovery_power`: the thermal power study (DESIGN §7). Each draw prints and
//! films the corner test part on the virtual printer (`thermal.generate_sequence`'s
//! generator, the Lepton's habits on) with one effect hidden at a given strength, or
//! none; the monitor (`thermal.monitor`'s code, with this stage's monitor parameters)
//! measures it, and the engine (`thermal.discrepancy`'s model), told nothing, is scored
//! against what the printer did. An evaluation stage: it knows the truth because it
//! printed it. Draws run in parallel; each one's dataset lives in a scratch folder of
//! the stage's output and is removed once measured.
//!
//! The corner effects (`heat_diffusion_widening`, `melt_squeeze_out`) have no candidate
//! (`models::thermal::discrepancy`): their draws can only come out *none* or *wrong*,
//! and the study reports how often the engine stays silent.
//!
//! Outputs (docs/OUTPUTS.md): `power.parquet` (the columns of `fdm.discovery_power`'s)
//! and `power_draws.parquet` (one row per draw, with each candidate's first-round
//! p-value).

use std::path::{Path, PathBuf};

use datasets::thermal::Effects;
use discrepancy::power::{DrawScore, DrawVerdict, Outcome};
use discrepancy::stats::mix_seed;
use discrepancy::Mechanism;
use models::thermal::discrepancy::{candidate_index, CANDIDATES};
use pipeline::params::{ParamError, StageParams};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::units::run_split;
use pipeline::{Params, Split, StageContext, StageError, Unit};
use rayon::prelude::*;
use tables::discrepancy::power;
use tables::discrepancy::thermal::{power_draws, power_part};

use super::filmed_print::{named_list, FilmedPrint, Filming, FilmingParams};
use crate::discrepancy_tables::{draws_frame, DrawRow};
use crate::effects::strength_list;
use crate::parts::{merge_study, study_unit_draws, study_units, write_study_part, StudySize, UnitSize};

/// The `thermal.discovery_power` stage kind.
pub struct DiscoveryPowerStage;

/// The effects the study can hide, each with its strengths' parameter, largest
/// strength and unit (the printer's ranges, `datasets::thermal::effects`).
const STUDIED: [(&str, f64, &str); 5] = [
    ("camera_latency", 0.5, "s"),
    ("layer_heat_accumulation", 1.0, "fraction"),
    ("tau_mismatch", 10.0, "relative"),
    ("heat_diffusion_widening", 20.0, "relative"),
    ("melt_squeeze_out", 1.0, "fraction"),
];

pipeline::params! {
    /// The parameters of `thermal.discovery_power`.
    pub struct DiscoveryPowerParams {
        /// Strengths of camera_latency (capture delay, s), comma-separated; empty for none.
        pub camera_latency: String = "0.005, 0.01",
        /// Strengths of layer_heat_accumulation (fraction of a layer's residual heat carried into the next layer's substrate), comma-separated.
        pub layer_heat_accumulation: String = "0.3, 0.6",
        /// Strengths of tau_mismatch (relative error of the flow's τ: actual τ = nominal·(1 + strength)), comma-separated.
        pub tau_mismatch: String = "0.3",
        /// Strengths of heat_diffusion_widening (relative increase of the lateral diffusivity; no candidate), comma-separated.
        pub heat_diffusion_widening: String = "1",
        /// Strengths of melt_squeeze_out (fraction of the volume squeezed out; no candidate), comma-separated.
        pub melt_squeeze_out: String = "0.2",
        /// Prints per effect and strength.
        pub draws: i64 [1, 100_000] = 4,
        /// Prints with no effect.
        pub null_draws: i64 [0, 100_000] = 8,
        /// Filmed layers per print (each is a group: 8 or more before anything can be named at α = 0.05 over 5 candidates).
        pub layers: i64 [2, 20] = 8,
        /// Most causes named: after each, the extended model is the baseline and the search repeats.
        pub max_rounds: i64 [1, 5] = 2,
    }
    groups {
        /// How the prints are filmed and read.
        pub filming: FilmingParams,
        /// How the draws are cut into work units.
        pub unit_size: UnitSize,
    }
}

impl DiscoveryPowerParams {
    /// Each studied effect's list of strengths, in [`STUDIED`] order.
    fn lists(&self) -> [&str; 5] {
        [
            &self.camera_latency,
            &self.layer_heat_accumulation,
            &self.tau_mismatch,
            &self.heat_diffusion_widening,
            &self.melt_squeeze_out,
        ]
    }

    /// The study's cells (effect, strength), each strength checked against its effect's range.
    fn cells(&self) -> Result<Vec<(&'static str, f64)>, ParamError> {
        let mut cells = Vec::new();
        for ((effect, top, unit), list) in STUDIED.into_iter().zip(self.lists()) {
            cells.extend(strength_list(effect, list, top, &format!(" ({unit})"))?.into_iter().map(|s| (effect, s)));
        }
        Ok(cells)
    }
}

impl Stage for DiscoveryPowerStage {
    type Params = DiscoveryPowerParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.discovery_power",
        // 3: the engine's noise scales use models::stats' median.
        // 4: layer_heat_accumulation is fitted with a weak prior on the first carried excess.
        // 5: the contour map knows the bead's age and the seam is no straight run.
        // 6: the contour map has a level per straight run.
        // 7: the contour map has a quadratic in the age per straight run and a gain growing with the age.
        version: 7,
        summary: "Power study of the discrepancy engine on virtual thermal sequences: each effect hidden at a grid of strengths, plus null prints, monitored and scored against the printer's truth → power.parquet, power_draws.parquet",
        implements: "DESIGN §7 (tests that hide an effect and require finding it), on paper 003's capture-time and layer models",
        inputs: &[],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&power::TABLE, &power_draws::TABLE, &power_part::TABLE];

    fn check(p: &DiscoveryPowerParams) -> Result<(), ParamError> {
        p.cells()?;
        p.filming.check()
    }

    fn run(&self, ctx: &mut StageContext, _: &DiscoveryPowerParams) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

/// Work units: blocks of `draws_per_unit` consecutive prints ([`crate::parts`]).
impl Split for DiscoveryPowerStage {
    fn units(&self, params: &Params, _inputs: usize) -> Vec<Unit> {
        let p = DiscoveryPowerParams::from_params(params);
        let size = StudySize {
            null_draws: p.null_draws,
            draws: p.draws,
            strength_lists: p.lists().to_vec(),
            unit_size: &p.unit_size,
        };
        study_units(&size, 1)
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let p = DiscoveryPowerParams::from_params(&ctx.params);
        let design = Design::new(&p, ctx.seed).map_err(|e| StageError::params(ctx, e))?;
        let jobs = design.jobs();
        let (_, range) = study_unit_draws(&p.unit_size, index, jobs.len());
        let scratch = ctx.output_dir().join("scratch");
        let draws: Vec<Draw> = jobs[range]
            .par_iter()
            .map(|job| design.draw(job, &scratch.join(format!("draw_{}_{}", job.cell, job.draw))))
            .collect::<Result<_, _>>()?;
        std::fs::remove_dir_all(&scratch).ok();
        let base = format!("corner test part × {} layers", design.filming.layers);
        let rows: Vec<DrawRow<'_>> = draws.iter().map(Draw::row).collect();
        let candidates: Vec<&str> = CANDIDATES.iter().map(Mechanism::name).collect();
        let covered = draws.iter().map(|d| d.score().covered).collect();
        write_study_part(ctx, draws_frame(&base, &rows, &candidates)?, covered)
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        merge_study(ctx, parts, &STUDIED.map(|(effect, _, _)| effect))
    }
}

/// The checked study.
struct Design {
    cells: Vec<(&'static str, f64)>,
    draws: usize,
    null_draws: usize,
    seed: u64,
    filming: Filming,
}

/// One print to make.
struct Job {
    cell: usize,
    effect: Option<&'static str>,
    strength: f64,
    draw: usize,
}

/// One print and what the engine made of it.
struct Draw {
    effect: Option<&'static str>,
    strength: f64,
    draw: usize,
    seed: u64,
    named: Vec<usize>,
    outcome: Outcome,
    fitted: Option<(f64, f64, f64)>,
    first_round_p: Vec<f64>,
}

impl Design {
    /// The study of `p`, its prints seeded from the stage's `seed`.
    fn new(p: &DiscoveryPowerParams, seed: u64) -> Result<Self, ParamError> {
        Ok(Self {
            cells: p.cells()?,
            draws: p.draws as usize,
            null_draws: p.null_draws as usize,
            seed,
            filming: Filming::new(&p.filming, p.layers, p.max_rounds, seed)?,
        })
    }

    /// Null draws first (cell 0), then each cell's draws.
    fn jobs(&self) -> Vec<Job> {
        let mut jobs: Vec<Job> =
            (0..self.null_draws).map(|draw| Job { cell: 0, effect: None, strength: 0.0, draw }).collect();
        for (c, &(effect, strength)) in self.cells.iter().enumerate() {
            jobs.extend((0..self.draws).map(|draw| Job { cell: c + 1, effect: Some(effect), strength, draw }));
        }
        jobs
    }

    /// Prints, films and monitors one job in `scratch`, runs the engine, scores it.
    fn draw(&self, job: &Job, scratch: &Path) -> Result<Draw, StageError> {
        let seed = mix_seed(self.seed, job.cell as u64, job.draw as u64);
        let effects = match job.effect {
            Some(name) => Effects::from_pairs([(name, job.strength)]).map_err(StageError::domain)?,
            None => Effects::none(),
        };
        let FilmedPrint { found, .. } =
            self.filming.film(effects, seed, scratch, &format!("power draw {}", job.draw))?;
        let DrawVerdict { outcome, fitted, first_round_p } =
            DrawVerdict::of(&found, job.effect.and_then(candidate_index), CANDIDATES.len());
        Ok(Draw {
            effect: job.effect,
            strength: job.strength,
            draw: job.draw,
            seed,
            named: found.named,
            outcome,
            fitted,
            first_round_p,
        })
    }
}

impl Draw {
    fn effect_name(&self) -> &'static str {
        self.effect.unwrap_or("none")
    }

    fn score(&self) -> DrawScore {
        let covered = self.fitted.map(|(_, lo, hi)| lo <= self.strength && self.strength <= hi);
        DrawScore { effect: self.effect_name(), strength: self.strength, outcome: self.outcome, covered }
    }

    fn row(&self) -> DrawRow<'_> {
        let named = named_list(&self.named);
        DrawRow {
            effect: self.effect_name(),
            strength: self.strength,
            draw: self.draw,
            seed: self.seed,
            injected: self.strength,
            named,
            outcome: self.outcome,
            fitted: self.fitted,
            first_round_p: &self.first_round_p,
        }
    }
}
