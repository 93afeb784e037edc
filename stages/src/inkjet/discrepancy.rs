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
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::units::run_split;
use pipeline::{ParamSpec, ParamType, Params, Split, StageContext, StageError, StageKind, Unit};

use crate::discrepancy_tables::{
    draws_frame as shared_draws_frame, engine_settings, max_rounds, study_settings, DiscrepancyTables, Domain, DrawRow,
    ALPHA, BINS, BOOTSTRAP_DRAWS,
};
use crate::effects::strength_list;
use crate::parts::{
    data_set_units, merge_study, merge_tables, study_unit_draws, study_units, write_study_part, DRAWS_PER_UNIT,
};

/// The ink-jet tables' names: one discovery per dataset, heights in µm.
const INKJET: Domain = Domain { set_column: "dataset", unit: "um" };

pub(super) const LAYERS_PER_GROUP: ParamSpec = ParamSpec {
    name: "layers_per_group",
    ty: ParamType::Int { min: 1, max: 100 },
    default: ParamDefault::Int(4),
    doc: "Consecutive layers per group: blocks share only their boundary scan, so held-out blocks are close to independent (at least 3 groups are needed; 8 or more before anything can be named at α = 0.05 over 6 candidates).",
};
/// The most rounds over the six candidates.
pub(super) const MAX_ROUNDS: ParamSpec = max_rounds(6, 3);

/// The `inkjet.discrepancy` stage kind.
pub struct DiscrepancyStage;

const PARAMS: &[ParamSpec] = &[LAYERS_PER_GROUP, ALPHA, MAX_ROUNDS, BINS, BOOTSTRAP_DRAWS];

impl StageKind for DiscrepancyStage {
    fn name(&self) -> &'static str {
        "inkjet.discrepancy"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "What the layer-to-layer model gets wrong on a print's scans, the cause named by grouped cross-validation among 6 physical mechanisms, the extended model and its held-out gain → residuals, causes, extension, gain (.parquet)"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §7 on paper 002's layer-to-layer model (eqs 2-7) and the inkjet-scans format"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::at_least(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
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
        let settings = engine_settings(ctx)?;
        let per_group = ctx.params.i64("layers_per_group") as usize;
        let mut tables = DiscrepancyTables::new(INKJET, settings.alpha);
        let input = &ctx.inputs[index];
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
        merge_tables(ctx, parts, &DiscrepancyTables::NAMES)
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

const POWER_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "curing_shrinkage",
        ty: ParamType::Text,
        default: ParamDefault::Str("0.01, 0.02"),
        doc: "Strengths of curing_shrinkage (fraction of each fresh layer lost), comma-separated; empty for none.",
    },
    ParamSpec {
        name: "volume_drift",
        ty: ParamType::Text,
        default: ParamDefault::Str("0.0005, 0.001"),
        doc: "Strengths of volume_drift (relative droplet-volume change per layer, sign drawn per print), comma-separated.",
    },
    ParamSpec {
        name: "levelling_flow",
        ty: ParamType::Text,
        default: ParamDefault::Str("0.015, 0.03"),
        doc: "Strengths of levelling_flow (diffusion number of the fresh layer), comma-separated.",
    },
    ParamSpec {
        name: "nozzle_bias",
        ty: ParamType::Text,
        default: ParamDefault::Str("0.01, 0.02"),
        doc: "Strengths of nozzle_bias (std of the per-nozzle volume factor), comma-separated.",
    },
    ParamSpec {
        name: "substrate_tilt",
        ty: ParamType::Text,
        default: ParamDefault::Str("5"),
        doc: "Strengths of substrate_tilt (µm per mm, sign drawn; invisible layer to layer, no candidate), comma-separated.",
    },
    ParamSpec {
        name: "draws",
        ty: ParamType::Int { min: 1, max: 100_000 },
        default: ParamDefault::Int(10),
        doc: "Prints per effect and strength.",
    },
    ParamSpec {
        name: "null_draws",
        ty: ParamType::Int { min: 0, max: 100_000 },
        default: ParamDefault::Int(20),
        doc: "Prints with no effect.",
    },
    ParamSpec {
        name: "radius_cells",
        ty: ParamType::Int { min: 3, max: 40 },
        default: ParamDefault::Int(10),
        doc: "Radius of each print's cylinder, droplet spacings (paper 002's Sec. V-A part, smaller: the paper gives no diameter).",
    },
    ParamSpec {
        name: "layers",
        ty: ParamType::Int { min: 3, max: 1000 },
        default: ParamDefault::Int(40),
        doc: "Open-loop layers of each print.",
    },
    ParamSpec {
        name: "variation_pct",
        ty: ParamType::Float { min: 0.0, max: 100.0 },
        default: ParamDefault::Float(20.0),
        doc: "Largest droplet-volume shortfall p in percent (the paper's [0 20%]).",
    },
    LAYERS_PER_GROUP,
    ALPHA,
    MAX_ROUNDS,
    ParamSpec {
        name: "bootstrap_draws",
        ty: ParamType::Int { min: 100, max: 100_000 },
        default: ParamDefault::Int(200),
        doc: "Bootstrap draws of each gain interval inside a draw (the power table uses none of them).",
    },
    DRAWS_PER_UNIT,
];

impl StageKind for DiscoveryPowerStage {
    fn name(&self) -> &'static str {
        "inkjet.discovery_power"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Power study of the discrepancy engine on virtual ink-jet prints: each effect hidden at a grid of strengths, plus null prints, scored against the printer's truth → power.parquet, power_draws.parquet"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §7 (tests that hide an effect and require finding it), on paper 002's layer-to-layer model"
    }
    fn params(&self) -> &'static [ParamSpec] {
        POWER_PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(0)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

/// Work units: blocks of `draws_per_unit` consecutive draws ([`crate::parts`]).
impl Split for DiscoveryPowerStage {
    fn units(&self, params: &Params, _inputs: usize) -> Vec<Unit> {
        study_units(params, 1, STUDIED.map(|e| e.name()))
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let design = power_design(ctx)?;
        let (_, range) = study_unit_draws(&ctx.params, index, design.draw_count());
        let results = run_draw_range(&design, range).map_err(StageError::domain)?;
        let base = format!("cylinder r{} × {} layers", design.print.radius_cells, design.print.layers);
        let covered = results.iter().map(|d| d.score().covered).collect();
        write_study_part(ctx, draws_frame(&base, &results)?, covered)
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        merge_study(ctx, parts, &STUDIED.map(|e| e.name()))
    }
}

fn power_design(ctx: &StageContext) -> Result<PowerDesign, StageError> {
    let p = &ctx.params;
    let mut cells = Vec::new();
    for effect in STUDIED {
        for strength in strengths(ctx, effect)? {
            cells.push((effect, strength));
        }
    }
    Ok(PowerDesign {
        print: PrintDesign {
            radius_cells: p.i64("radius_cells") as usize,
            layers: p.i64("layers") as usize,
            max_shortfall: p.f64("variation_pct") / 100.0,
            layers_per_group: p.i64("layers_per_group") as usize,
        },
        cells,
        draws_per_cell: p.i64("draws") as usize,
        null_draws: p.i64("null_draws") as usize,
        seed: ctx.seed,
        engine: study_settings(ctx, p.i64("bootstrap_draws") as usize),
    })
}

/// The strengths listed for `effect`, each a magnitude within the effect's range.
pub(super) fn strengths(ctx: &StageContext, effect: Effect) -> Result<Vec<f64>, StageError> {
    let (lo, hi, unit) = effect.range();
    strength_list(ctx, effect.name(), hi.max(-lo), &format!(" ({unit})"))
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
