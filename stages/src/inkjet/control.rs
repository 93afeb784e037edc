//! `inkjet.control_gain`: does the extended model print better? For each printer (one
//! seed, one effect at a given strength), the discrepancy engine runs on the scans of an
//! open-loop calibration cylinder, and the same printer then prints paper 002's 400 µm
//! cylinder in closed loop three times: with the paper's model, with the engine's
//! baseline (mean droplets) and with the extended model it fitted
//! (`models::inkjet::discrepancy::control`, which states how a fit enters eq. 8). An
//! evaluation stage: it prints on the virtual printer and scores the true surface.
//!
//! Outputs (docs/OUTPUTS.md): `control_gain.parquet` (per effect, strength and
//! controller model: mean error and RMSD of the top surface over the footprint, each
//! with a 95 % Student-t interval over printers and the paired difference to the
//! paper's controller with its interval) and `control_trials.parquet` (one row per
//! production print).

use crate::progress::StageProgress;
use models::inkjet::discrepancy::control::{run_trials_observed, summarize, ControlDesign, ControlRow, ControlSummary};
use models::inkjet::discrepancy::power::PrintDesign;
use models::inkjet::printer::Effect;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use super::discrepancy::{strengths, LAYERS_PER_GROUP, MAX_ROUNDS};
use crate::discrepancy_tables::{study_settings, ALPHA};
use crate::table::{f64_col, frame, i64_col, str_col};

/// The `inkjet.control_gain` stage kind.
pub struct ControlGainStage;

/// The effects whose fitted extension eq. 8's predictor can use.
const STUDIED: [Effect; 3] = [Effect::CuringShrinkage, Effect::VolumeDrift, Effect::NozzleBias];

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "curing_shrinkage",
        ty: ParamType::Text,
        default: ParamDefault::Str("0.05"),
        doc: "Strengths of curing_shrinkage (fraction of each fresh layer lost), comma-separated; empty for none.",
    },
    ParamSpec {
        name: "volume_drift",
        ty: ParamType::Text,
        default: ParamDefault::Str("0.002"),
        doc: "Strengths of volume_drift (relative droplet-volume change per layer, sign drawn per printer), comma-separated.",
    },
    ParamSpec {
        name: "nozzle_bias",
        ty: ParamType::Text,
        default: ParamDefault::Str("0.05"),
        doc: "Strengths of nozzle_bias (std of the per-nozzle volume factor), comma-separated.",
    },
    ParamSpec {
        name: "printers",
        ty: ParamType::Int { min: 2, max: 10_000 },
        default: ParamDefault::Int(8),
        doc: "Printers (seeds) per effect and strength; each prints one calibration part and three production parts.",
    },
    ParamSpec {
        name: "radius_cells",
        ty: ParamType::Int { min: 3, max: 40 },
        default: ParamDefault::Int(10),
        doc: "Cylinder radius in droplet spacings, calibration and production alike.",
    },
    ParamSpec {
        name: "calibration_layers",
        ty: ParamType::Int { min: 3, max: 1000 },
        default: ParamDefault::Int(40),
        doc: "Open-loop layers of the calibration print the engine reads.",
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
];

impl StageKind for ControlGainStage {
    fn name(&self) -> &'static str {
        "inkjet.control_gain"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Closed-loop prints of paper 002's cylinder controlled with the paper's model, the engine's baseline and the extended model fitted on a calibration print of the same printer → control_gain.parquet, control_trials.parquet"
    }
    fn implements(&self) -> &'static str {
        "paper 002 eq. 8 (Sec. IV-A) with the discrepancy engine's extended model (DESIGN §7)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(0)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let design = design(ctx)?;
        let rows = run_trials_observed(&design, &StageProgress::new(ctx)).map_err(StageError::domain)?;
        let mut gain = gain_frame(&summarize(&rows))?;
        ctx.write_table("control_gain", &mut gain)?;
        let mut trials = trials_frame(&rows)?;
        ctx.write_table("control_trials", &mut trials)?;
        Ok(())
    }
}

fn design(ctx: &StageContext) -> Result<ControlDesign, StageError> {
    let p = &ctx.params;
    let mut cells = Vec::new();
    for effect in STUDIED {
        cells.extend(strengths(ctx, effect)?.into_iter().map(|s| (effect, s)));
    }
    Ok(ControlDesign {
        calibration: PrintDesign {
            radius_cells: p.i64("radius_cells") as usize,
            layers: p.i64("calibration_layers") as usize,
            max_shortfall: p.f64("variation_pct") / 100.0,
            layers_per_group: p.i64("layers_per_group") as usize,
        },
        cells,
        seeds: p.i64("printers") as usize,
        seed: ctx.seed,
        engine: study_settings(ctx, 100),
    })
}

fn gain_frame(rows: &[ControlSummary]) -> Result<polars::prelude::DataFrame, StageError> {
    let col = |f: &dyn Fn(&ControlSummary) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    frame(vec![
        str_col("effect", rows.iter().map(|r| r.effect.name().to_string()).collect()),
        f64_col("strength", col(&|r| r.strength)),
        str_col("controller", rows.iter().map(|r| r.predictor.name().to_string()).collect()),
        i64_col("printers", rows.iter().map(|r| r.trials as i64).collect()),
        f64_col("desired_um", col(&|r| r.desired_um)),
        f64_col("mean_error_um", col(&|r| r.mean_error_um.mean.0)),
        f64_col("mean_error_ci_lo", col(&|r| r.mean_error_um.mean.1)),
        f64_col("mean_error_ci_hi", col(&|r| r.mean_error_um.mean.2)),
        f64_col("rmsd_um", col(&|r| r.rmsd_um.mean.0)),
        f64_col("rmsd_ci_lo", col(&|r| r.rmsd_um.mean.1)),
        f64_col("rmsd_ci_hi", col(&|r| r.rmsd_um.mean.2)),
        f64_col("average_height_um", col(&|r| r.average_height_um.mean.0)),
        f64_col("average_height_ci_lo", col(&|r| r.average_height_um.mean.1)),
        f64_col("average_height_ci_hi", col(&|r| r.average_height_um.mean.2)),
        f64_col("mean_error_vs_paper_um", col(&|r| r.mean_error_um.vs_paper.0)),
        f64_col("mean_error_vs_paper_ci_lo", col(&|r| r.mean_error_um.vs_paper.1)),
        f64_col("mean_error_vs_paper_ci_hi", col(&|r| r.mean_error_um.vs_paper.2)),
        f64_col("rmsd_vs_paper_um", col(&|r| r.rmsd_um.vs_paper.0)),
        f64_col("rmsd_vs_paper_ci_lo", col(&|r| r.rmsd_um.vs_paper.1)),
        f64_col("rmsd_vs_paper_ci_hi", col(&|r| r.rmsd_um.vs_paper.2)),
    ])
}

fn trials_frame(rows: &[ControlRow]) -> Result<polars::prelude::DataFrame, StageError> {
    let col = |f: &dyn Fn(&ControlRow) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    frame(vec![
        str_col("effect", rows.iter().map(|r| r.effect.name().to_string()).collect()),
        f64_col("strength", col(&|r| r.strength)),
        i64_col("printer", rows.iter().map(|r| r.trial as i64).collect()),
        str_col("seed", rows.iter().map(|r| format!("{:016x}", r.seed)).collect()),
        str_col("named", rows.iter().map(|r| r.named.clone()).collect()),
        str_col("controller", rows.iter().map(|r| r.predictor.name().to_string()).collect()),
        i64_col("layers_printed", rows.iter().map(|r| r.layers_printed as i64).collect()),
        f64_col("desired_um", col(&|r| r.desired_um)),
        f64_col("mean_error_um", col(&|r| r.metrics.mean_error_um)),
        f64_col("rmsd_um", col(&|r| r.metrics.rmsd_um)),
        f64_col("std_um", col(&|r| r.metrics.std_um)),
        f64_col("average_height_um", col(&|r| r.metrics.average_height_um)),
    ])
}
