//! `fdm.discovery_power`: how strong an effect must be before the discrepancy engine
//! names it in a measured data set (DESIGN §7). For every input printer (a *base*),
//! effects are hidden by their physics in surrogate draws of the base at a grid of
//! strengths, plus null draws, and the engine — not told what was hidden — is scored
//! against what was injected (`models::fdm::discrepancy::power`). An evaluation stage:
//! it knows the truth because it made it.
//!
//! Outputs: `power.parquet` (per base, effect and strength: draws, correct, wrong and
//! none counts, the correct rate with its Clopper–Pearson interval, the false-alarm
//! rate, and how often the strength's interval covered the truth) and
//! `power_draws.parquet` (one row per draw).
//!
//! It splits into work units ([`pipeline::Split`], [`crate::parts`]): blocks of
//! `draws_per_unit` consecutive draws of one base. Each unit runs the engine once on
//! its base as measured (the own causes every draw starts from) and then its draws;
//! the merge stacks the units' rows and summarises them.

use std::path::PathBuf;

use discrepancy::power::{summarize, DrawScore, Outcome};
use discrepancy::stats::mix_seed;
use models::fdm::discrepancy::inject::{Effect, InjectSettings};
use models::fdm::discrepancy::power::{names, run_draw_range, Base, DrawResult, Noise, PowerDesign};
use models::fdm::discrepancy::FdmModel;
use pipeline::params::{ParamError, StageParams};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::units::run_split;
use pipeline::{Params, Split, StageContext, StageError, Unit};
use polars::prelude::{IntoColumn, NamedFrom, Series};
use tables::discrepancy::fdm::{power_draws, power_part};
use tables::discrepancy::power;

use crate::discrepancy_tables::{power_frame, NamingTest, PowerOf};
use crate::effects::strength_list;
use crate::fdm::discrepancy::{engine_failed, read_printers, LagBaseline, StartBlob};
use crate::parts::{read_parts, study_unit_draws, study_units, without, StudySize, UnitSize};
use crate::roles;
use crate::table::{f64_col, f64s, frame, i64_col, opt_bools, str_col, strs};

/// The `fdm.discovery_power` stage kind.
pub struct DiscoveryPowerStage;

pipeline::choice! {
    /// A draw's noise around the own-cause model.
    pub enum DrawNoise {
        /// A phase-randomised copy of each line's residual, slow swells included.
        Measured = "measured",
        /// Independent noise of the lines' sample-to-sample scatter: measurement noise only.
        White = "white",
    }
}

pipeline::params! {
    /// The parameters of `fdm.discovery_power`.
    pub struct DiscoveryPowerParams {
        /// Strengths of bed_tilt (relative width change end to end, its sign drawn per draw), comma-separated; empty for none.
        pub bed_tilt: String = "0.02, 0.05, 0.1, 0.2",
        /// Strengths of gear_eccentricity (relative flow ripple; period drawn in 4-40 mm, phase per line), comma-separated.
        pub gear_eccentricity: String = "0.02, 0.05, 0.1",
        /// Strengths of flow_saturation (relative width loss at the fastest line's cruise), comma-separated.
        pub flow_saturation: String = "0.05, 0.1, 0.2, 0.4",
        /// A draw's noise around the own-cause model: `measured` (a phase-randomised copy of each line's residual, slow swells included) or `white` (independent noise of the lines' sample-to-sample scatter: measurement noise only).
        pub noise: DrawNoise = DrawNoise::Measured,
        /// Draws per base, effect and strength.
        pub draws: i64 [1, 100_000] = 20,
        /// Draws per base with nothing injected.
        pub null_draws: i64 [0, 100_000] = 100,
        /// The engine's most rounds per draw (beyond the data's own causes).
        pub max_rounds: i64 [1, 7] = 3,
        /// Bootstrap draws of each gain interval inside a draw (the power table uses none of them).
        pub bootstrap_draws: i64 [100, 100_000] = 500,
    }
    groups { pub lag: LagBaseline, pub unit_size: UnitSize, pub naming: NamingTest }
}

impl DiscoveryPowerParams {
    /// The strength list of `effect` (none for the null).
    fn list(&self, effect: Effect) -> &str {
        match effect {
            Effect::None => "",
            Effect::BedTilt => &self.bed_tilt,
            Effect::GearEccentricity => &self.gear_eccentricity,
            Effect::FlowSaturation => &self.flow_saturation,
        }
    }

    /// The strengths listed for `effect`, each checked against the effect's range.
    fn strengths(&self, effect: Effect) -> Result<Vec<f64>, ParamError> {
        let (lo, hi) = effect.strength_range();
        strength_list(effect.name(), self.list(effect), hi.max(-lo), "")
    }

    fn noise(&self) -> Noise {
        match self.noise {
            DrawNoise::Measured => Noise::Measured,
            DrawNoise::White => Noise::White,
        }
    }
}

/// The effects the study hides, in the order of its cells.
const STUDIED: [Effect; 3] = [Effect::BedTilt, Effect::GearEccentricity, Effect::FlowSaturation];

/// The part's bookkeeping columns, beyond those of `power_draws.parquet`.
const PART_ONLY: [&str; 2] = [power_part::own_causes, power_part::covered];

impl Stage for DiscoveryPowerStage {
    type Params = DiscoveryPowerParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.discovery_power",
        version: 2,
        summary: "Power study of the discrepancy engine: effects hidden in surrogate draws of each measured base at a grid of strengths, plus null draws, scored against the injection → power.parquet, power_draws.parquet",
        implements: "DESIGN §7 (tests that hide an effect and require finding it), on paper 000's lines",
        inputs: &[roles::FDM_WIDTHS_MANY],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&power::TABLE, &power_draws::TABLE, &power_part::TABLE];

    fn check(p: &DiscoveryPowerParams) -> Result<(), ParamError> {
        STUDIED.iter().try_for_each(|e| p.strengths(*e).map(|_| ()))
    }

    fn run(&self, ctx: &mut StageContext, _: &DiscoveryPowerParams) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

impl Split for DiscoveryPowerStage {
    fn units(&self, params: &Params, inputs: usize) -> Vec<Unit> {
        let p = DiscoveryPowerParams::from_params(params);
        let size = StudySize {
            null_draws: p.null_draws,
            draws: p.draws,
            strength_lists: STUDIED.map(|e| p.list(e)).to_vec(),
            unit_size: &p.unit_size,
        };
        study_units(&size, inputs)
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let p = DiscoveryPowerParams::from_params(&ctx.params);
        let printers = read_printers(ctx.inputs_of(&roles::FDM_WIDTHS_MANY))?;
        let blob = StartBlob::parse(&p.lag.start_blob, &printers).map_err(|e| StageError::params(ctx, e))?;
        let design = design(&p, ctx.seed).map_err(|e| StageError::params(ctx, e))?;
        let (b, range) = study_unit_draws(&p.unit_size, index, design.draw_count());
        let mut rows = DrawRows::default();
        if let Some((printer, lines)) = printers.into_iter().nth(b) {
            let model = FdmModel::new(&lines, blob.has(&printer), p.lag.smoothing_mm);
            let base =
                Base::new(printer.clone(), model, lines, &design.engine).map_err(|e| engine_failed(&printer, e))?;
            let base_design = PowerDesign { seed: mix_seed(design.seed, b as u64, 0), ..design };
            let results = run_draw_range(&base, &base_design, range).map_err(|e| engine_failed(&printer, e))?;
            rows.add(&base, &results);
        }
        let mut part = rows.into_frame()?;
        ctx.write_table(power_part::TABLE.name, &mut part)?;
        Ok(())
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        let p = DiscoveryPowerParams::from_params(&ctx.params);
        let all = read_parts(parts)?;
        let mut power = power_table(ctx, p.noise(), &all)?;
        ctx.write_table(power::TABLE.name, &mut power)?;
        let mut per_draw = without(&all, &PART_ONLY)?;
        ctx.write_table(power_draws::TABLE.name, &mut per_draw)?;
        Ok(())
    }
}

/// The power table of the stacked parts: per base, in order, its draws summarised.
fn power_table(
    ctx: &StageContext,
    noise: Noise,
    all: &polars::prelude::DataFrame,
) -> Result<polars::prelude::DataFrame, StageError> {
    let bad = |what: &str, value: &str| StageError::BadInput {
        file: ctx.output_dir().join("parts"),
        location: None,
        expected: format!("a known {what}, got `{value}`"),
    };
    let file = ctx.output_dir().join("parts");
    let text = |name: &str| strs(all, name, &file);
    let (base, own) = (text(power_part::base)?, text(power_part::own_causes)?);
    let (effect, outcome) = (text(power_part::effect)?, text(power_part::outcome)?);
    let (strength, covered) = (f64s(all, power_part::strength, &file)?, opt_bools(all, power_part::covered, &file)?);
    let mut labels: Vec<&str> = Vec::new();
    for b in &base {
        if !labels.contains(&b.as_str()) {
            labels.push(b);
        }
    }
    let mut summaries = Vec::new();
    for label in labels {
        let mut scores = Vec::new();
        for i in (0..base.len()).filter(|&i| base[i] == label) {
            scores.push(DrawScore {
                effect: Effect::parse(&effect[i]).ok_or_else(|| bad("effect", &effect[i]))?.name(),
                strength: strength[i],
                outcome: Outcome::parse(&outcome[i]).ok_or_else(|| bad("outcome", &outcome[i]))?,
                covered: covered[i],
            });
        }
        let own_causes = &own[base.iter().position(|b| b == label).expect("a label of the rows")];
        summaries.push((PowerOf { base: label, noise: noise.name(), own_causes }, summarize(&scores)));
    }
    power_frame(&summaries)
}

/// The study's design from the parameters.
fn design(p: &DiscoveryPowerParams, seed: u64) -> Result<PowerDesign, ParamError> {
    let mut cells = Vec::new();
    for effect in STUDIED {
        for strength in p.strengths(effect)? {
            cells.push((effect, strength));
        }
    }
    let engine = p.naming.study_settings(p.max_rounds, seed, p.bootstrap_draws as usize);
    Ok(PowerDesign {
        cells,
        draws_per_cell: p.draws as usize,
        null_draws: p.null_draws as usize,
        seed,
        engine,
        inject: InjectSettings { smoothing_mm: p.lag.smoothing_mm, gear_period_mm: None },
        noise: p.noise(),
    })
}

fn push3(columns: &mut [Vec<f64>; 3], (a, b, c): (f64, f64, f64)) {
    columns[0].push(a);
    columns[1].push(b);
    columns[2].push(c);
}

/// Columns of a unit's `part.parquet`: `power_draws.parquet`'s and the bookkeeping
/// (`tables::discrepancy::fdm::power_part`).
#[derive(Default)]
struct DrawRows {
    base: Vec<String>,
    effect: Vec<String>,
    strength: Vec<f64>,
    draw: Vec<i64>,
    seed: Vec<String>,
    injected: Vec<f64>,
    named: Vec<String>,
    outcome: Vec<String>,
    fitted: [Vec<f64>; 3],
    own: Vec<String>,
    covered: Vec<Option<bool>>,
}

impl DrawRows {
    fn add(&mut self, base: &Base, results: &[DrawResult]) {
        for d in results {
            self.base.push(base.label.clone());
            self.own.push(names(&base.own));
            self.covered.push(d.covered());
            self.effect.push(d.effect.name().into());
            self.strength.push(d.strength);
            self.draw.push(d.draw as i64);
            self.seed.push(format!("{:016x}", d.seed));
            self.injected.push(d.injected);
            self.named.push(names(&d.named));
            self.outcome.push(d.outcome.label().into());
            push3(&mut self.fitted, d.fitted.unwrap_or((f64::NAN, f64::NAN, f64::NAN)));
        }
    }

    fn into_frame(self) -> Result<polars::prelude::DataFrame, StageError> {
        let [estimate, lo, hi] = self.fitted;
        frame(vec![
            str_col(power_part::base, self.base),
            str_col(power_part::effect, self.effect),
            f64_col(power_part::strength, self.strength),
            i64_col(power_part::draw, self.draw),
            str_col(power_part::seed, self.seed),
            f64_col(power_part::injected, self.injected),
            str_col(power_part::named, self.named),
            str_col(power_part::outcome, self.outcome),
            f64_col(power_part::estimate, estimate),
            f64_col(power_part::ci_lo, lo),
            f64_col(power_part::ci_hi, hi),
            str_col(power_part::own_causes, self.own),
            Series::new(power_part::covered.into(), self.covered).into_column(),
        ])
    }
}
