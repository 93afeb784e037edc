//! `inkjet.discrepancy`: what paper 002's layer-to-layer model (eqs 2-7, the dataset's
//! nominal droplets) gets wrong on an `inkjet-scans` print, which physical cause
//! explains it, the extended model and its held-out gain — the ink-jet domain of the
//! `discrepancy` engine (`models::inkjet::discrepancy`). One discovery per input
//! dataset; a group is a block of consecutive layers. Reads datasets only through the
//! documented format, never `truth/`.
//!
//! `inkjet.discovery_power`: the power study. Prints on the virtual printer with one
//! effect hidden at a given strength (sign drawn for tilt and drift), plus null prints,
//! each scored against what the printer did. An evaluation stage: it knows the truth
//! because it printed it.
//!
//! Outputs (docs/OUTPUTS.md): `residuals`, `causes`, `extension`, `gain` (the columns of
//! `fdm.discrepancy` with `dataset` for `printer` and µm for mm); `power.parquet` (the
//! columns of `fdm.discovery_power`'s) and `power_draws.parquet` (one row per draw,
//! with each candidate's first-round p-value).

use std::path::PathBuf;

use datasets::inkjet::InkjetScans;
use discrepancy::discover;
use models::inkjet::discrepancy::mechanisms::CANDIDATES;
use models::inkjet::discrepancy::power::{names, run_draw_range, DrawResult, PowerDesign, PrintDesign};
use models::inkjet::discrepancy::{InkjetModel, InkjetPrint, PrintParts};
use models::inkjet::printer::Effect;
use models::inkjet::{DropletCoeffs, Grid};
use pipeline::params::{ParamError, StageParams};
use pipeline::schema::Table;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::units::run_split;
use pipeline::{Params, Split, StageContext, StageError, Unit};
use tables::discrepancy::inkjet::{causes, extension, gain, power_draws, power_part, residuals, ENGINE};
use tables::discrepancy::power;

use crate::discrepancy_tables::{
    draws_frame as shared_draws_frame, DiscrepancyTables, DrawRow, EngineParams, NamingTest,
};
use crate::effects::strength_list;
use crate::parts::{
    data_set_units, merge_study, merge_tables, study_unit_draws, study_units, write_study_part, StudySize, UnitSize,
};

pipeline::params! {
    /// How the ink-jet discrepancy search groups a print's layers and how many causes it
    /// names, as the discrepancy stage and both studies declare it.
    pub struct LayerSearch {
        /// Consecutive layers per group: blocks share only their boundary scan, so held-out blocks are close to independent (at least 3 groups are needed; 8 or more before anything can be named at α = 0.05 over 6 candidates).
        pub layers_per_group: i64 [1, 100] = 4,
        /// Most causes named: after each, the extended model is the baseline and the search repeats.
        pub max_rounds: i64 [1, 6] = 3,
    }
}

pipeline::params! {
    /// The parameters of `inkjet.discrepancy`.
    pub struct DiscrepancyParams {}
    groups { pub search: LayerSearch, pub engine: EngineParams }
}

/// The prints searched, one discovery each.
const SCANS: Input = Input::many(
    "scans",
    1,
    &[Source::Dataset("inkjet-scans")],
    "printed parts' layer scans (`inkjet-scans`), one discovery each",
);

/// The `inkjet.discrepancy` stage kind.
pub struct DiscrepancyStage;

impl Stage for DiscrepancyStage {
    type Params = DiscrepancyParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "inkjet.discrepancy",
        // 2: causes.parquet has the test's min_gain_pct.
        version: 2,
        summary: "What the layer-to-layer model gets wrong on a print's scans, the cause named by grouped cross-validation among 6 physical mechanisms, the extended model and its held-out gain → residuals, causes, extension, gain (.parquet)",
        implements: "DESIGN §7 on paper 002's layer-to-layer model (eqs 2-7) and the inkjet-scans format",
        inputs: &[SCANS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&residuals::TABLE, &causes::TABLE, &extension::TABLE, &gain::TABLE];

    fn check(p: &DiscrepancyParams) -> Result<(), ParamError> {
        p.engine.settings(p.search.max_rounds, 0).map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, _: &DiscrepancyParams) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

/// Work units: one per dataset, each discovery independent of the others.
impl Split for DiscrepancyStage {
    fn units(&self, _params: &Params, inputs: usize) -> Vec<Unit> {
        data_set_units(inputs, 1)
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let p = DiscrepancyParams::from_params(&ctx.params);
        let settings = p.engine.settings(p.search.max_rounds, ctx.seed).map_err(|e| StageError::params(ctx, e))?;
        let per_group = p.search.layers_per_group as usize;
        let mut tables = DiscrepancyTables::new(&ENGINE, &settings);
        let input = ctx.inputs_of(&SCANS)[index].clone();
        let dataset = InkjetScans::read(&input.dir).map_err(StageError::domain)?;
        let model = InkjetModel::new(print_of(&dataset).map_err(StageError::domain)?);
        let blocks = model.print().blocks(per_group);
        let found = discover(&model, &blocks, &[], &settings).map_err(|e| {
            let groups = blocks.len();
            StageError::Domain(
                format!("discrepancy engine on dataset `{}` ({groups} groups of {per_group} layers): {e}", input.name)
                    .into(),
            )
        })?;
        tables.add(&input.name, &model, blocks.len(), &found);
        tables.write(ctx)
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        merge_tables(ctx, parts, &ENGINE.tables())
    }
}

/// The model's view of a dataset: its scans, patterns, nominal droplets and profiler.
pub fn print_of(dataset: &InkjetScans) -> Result<InkjetPrint, models::inkjet::InkjetError> {
    let g = &dataset.grid;
    let footprint: Vec<bool> = dataset.target.iter().map(Option::is_some).collect();
    InkjetPrint::new(PrintParts {
        grid: Grid::new(g.m_x, g.m_y, g.spacing_um)?,
        scans: &dataset.scans,
        patterns: &dataset.patterns,
        part: DropletCoeffs::from(g.part),
        support: g.support.map(DropletCoeffs::from),
        max_shortfall: g.variation_pct / 100.0,
        footprint: &footprint,
        spot_sigma_um: g.profiler.spot_sigma_um,
        noise_um: g.profiler.noise_um,
    })
}

/// The `inkjet.discovery_power` stage kind.
pub struct DiscoveryPowerStage;

/// The effects the study can hide, with the parameter naming their strengths.
const STUDIED: [Effect; 5] =
    [Effect::CuringShrinkage, Effect::VolumeDrift, Effect::LevellingFlow, Effect::NozzleBias, Effect::SubstrateTilt];

pipeline::params! {
    /// The parameters of `inkjet.discovery_power`.
    pub struct DiscoveryPowerParams {
        /// Strengths of curing_shrinkage (fraction of each fresh layer lost), comma-separated; empty for none.
        pub curing_shrinkage: String = "0.01, 0.02",
        /// Strengths of volume_drift (relative droplet-volume change per layer, sign drawn per print), comma-separated.
        pub volume_drift: String = "0.0005, 0.001",
        /// Strengths of levelling_flow (diffusion number of the fresh layer), comma-separated.
        pub levelling_flow: String = "0.015, 0.03",
        /// Strengths of nozzle_bias (std of the per-nozzle volume factor), comma-separated.
        pub nozzle_bias: String = "0.01, 0.02",
        /// Strengths of substrate_tilt (µm per mm, sign drawn; invisible layer to layer, no candidate), comma-separated.
        pub substrate_tilt: String = "5",
        /// Prints per effect and strength.
        pub draws: i64 [1, 100_000] = 10,
        /// Prints with no effect.
        pub null_draws: i64 [0, 100_000] = 20,
        /// Radius of each print's cylinder, droplet spacings (paper 002's Sec. V-A part, smaller: the paper gives no diameter).
        pub radius_cells: i64 [3, 40] = 10,
        /// Open-loop layers of each print.
        pub layers: i64 [3, 1000] = 40,
        /// Largest droplet-volume shortfall p in percent (the paper's [0 20%]).
        pub variation_pct: f64 [0.0, 100.0] = 20.0,
        /// Bootstrap draws of each gain interval inside a draw (the power table uses none of them).
        pub bootstrap_draws: i64 [100, 100_000] = 200,
    }
    groups { pub search: LayerSearch, pub naming: NamingTest, pub unit_size: UnitSize }
}

impl StrengthLists for DiscoveryPowerParams {
    fn list(&self, effect: Effect) -> &str {
        match effect {
            Effect::CuringShrinkage => &self.curing_shrinkage,
            Effect::VolumeDrift => &self.volume_drift,
            Effect::LevellingFlow => &self.levelling_flow,
            Effect::NozzleBias => &self.nozzle_bias,
            Effect::SubstrateTilt => &self.substrate_tilt,
        }
    }
}

impl Stage for DiscoveryPowerStage {
    type Params = DiscoveryPowerParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "inkjet.discovery_power",
        version: 1,
        summary: "Power study of the discrepancy engine on virtual ink-jet prints: each effect hidden at a grid of strengths, plus null prints, scored against the printer's truth → power.parquet, power_draws.parquet",
        implements: "DESIGN §7 (tests that hide an effect and require finding it), on paper 002's layer-to-layer model",
        inputs: &[],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&power::TABLE, &power_draws::TABLE, &power_part::TABLE];

    fn check(p: &DiscoveryPowerParams) -> Result<(), ParamError> {
        p.cells(&STUDIED).map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, _: &DiscoveryPowerParams) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

/// Work units: blocks of `draws_per_unit` consecutive draws ([`crate::parts`]).
impl Split for DiscoveryPowerStage {
    fn units(&self, params: &Params, _inputs: usize) -> Vec<Unit> {
        let p = DiscoveryPowerParams::from_params(params);
        let size = StudySize {
            null_draws: p.null_draws,
            draws: p.draws,
            strength_lists: STUDIED.map(|e| p.list(e)).to_vec(),
            unit_size: &p.unit_size,
        };
        study_units(&size, 1)
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let p = DiscoveryPowerParams::from_params(&ctx.params);
        let design = power_design(&p, ctx.seed).map_err(|e| StageError::params(ctx, e))?;
        let (_, range) = study_unit_draws(&p.unit_size, index, design.draw_count());
        let results = run_draw_range(&design, range).map_err(StageError::domain)?;
        let base = format!("cylinder r{} × {} layers", design.print.radius_cells, design.print.layers);
        let covered = results.iter().map(|d| d.score().covered).collect();
        write_study_part(ctx, draws_frame(&base, &results)?, covered)
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        merge_study(ctx, parts, &STUDIED.map(|e| e.name()))
    }
}

fn power_design(p: &DiscoveryPowerParams, seed: u64) -> Result<PowerDesign, ParamError> {
    Ok(PowerDesign {
        print: PrintDesign {
            radius_cells: p.radius_cells as usize,
            layers: p.layers as usize,
            max_shortfall: p.variation_pct / 100.0,
            layers_per_group: p.search.layers_per_group as usize,
        },
        cells: p.cells(&STUDIED)?,
        draws_per_cell: p.draws as usize,
        null_draws: p.null_draws as usize,
        seed,
        engine: p.naming.study_settings(p.search.max_rounds, seed, p.bootstrap_draws as usize),
    })
}

/// A study's comma-separated strength list per effect.
pub(super) trait StrengthLists {
    /// The list of `effect` (a study lists only the effects it studies).
    fn list(&self, effect: Effect) -> &str;

    /// Every (effect, strength) cell of `studied`, each strength a magnitude within the
    /// effect's range.
    fn cells(&self, studied: &[Effect]) -> Result<Vec<(Effect, f64)>, ParamError> {
        let mut cells = Vec::new();
        for &effect in studied {
            let (lo, hi, unit) = effect.range();
            let listed = strength_list(effect.name(), self.list(effect), hi.max(-lo), &format!(" ({unit})"))?;
            cells.extend(listed.into_iter().map(|s| (effect, s)));
        }
        Ok(cells)
    }
}

fn draws_frame(base: &str, draws: &[DrawResult]) -> Result<polars::prelude::DataFrame, StageError> {
    let rows: Vec<DrawRow<'_>> = draws
        .iter()
        .map(|d| DrawRow {
            effect: d.effect_name(),
            strength: d.strength,
            draw: d.draw,
            seed: d.seed,
            injected: d.truth,
            named: names(&d.named),
            outcome: d.outcome,
            fitted: d.fitted,
            first_round_p: &d.first_round_p,
        })
        .collect();
    let candidates: Vec<&str> = CANDIDATES.iter().map(discrepancy::Mechanism::name).collect();
    shared_draws_frame(base, &rows, &candidates)
}
