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
use pipeline::params::ParamError;
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::inkjet::{control_gain, control_trials};

use super::discrepancy::{LayerSearch, StrengthLists};
use crate::discrepancy_tables::NamingTest;
use crate::table::{f64_col, frame, i64_col, str_col};

/// The `inkjet.control_gain` stage kind.
pub struct ControlGainStage;

/// The effects whose fitted extension eq. 8's predictor can use.
const STUDIED: [Effect; 3] = [Effect::CuringShrinkage, Effect::VolumeDrift, Effect::NozzleBias];

pipeline::params! {
    /// The parameters of `inkjet.control_gain`.
    pub struct ControlGainParams {
        /// Strengths of curing_shrinkage (fraction of each fresh layer lost), comma-separated; empty for none.
        pub curing_shrinkage: String = "0.05",
        /// Strengths of volume_drift (relative droplet-volume change per layer, sign drawn per printer), comma-separated.
        pub volume_drift: String = "0.002",
        /// Strengths of nozzle_bias (std of the per-nozzle volume factor), comma-separated.
        pub nozzle_bias: String = "0.05",
        /// Printers (seeds) per effect and strength; each prints one calibration part and three production parts.
        pub printers: i64 [2, 10_000] = 8,
        /// Cylinder radius in droplet spacings, calibration and production alike.
        pub radius_cells: i64 [3, 40] = 10,
        /// Open-loop layers of the calibration print the engine reads.
        pub calibration_layers: i64 [3, 1000] = 40,
        /// Largest droplet-volume shortfall p in percent (the paper's [0 20%]).
        pub variation_pct: f64 [0.0, 100.0] = 20.0,
    }
    groups { pub search: LayerSearch, pub naming: NamingTest }
}

impl StrengthLists for ControlGainParams {
    fn list(&self, effect: Effect) -> &str {
        match effect {
            Effect::CuringShrinkage => &self.curing_shrinkage,
            Effect::VolumeDrift => &self.volume_drift,
            Effect::NozzleBias => &self.nozzle_bias,
            Effect::LevellingFlow | Effect::SubstrateTilt => "",
        }
    }
}

impl Stage for ControlGainStage {
    type Params = ControlGainParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "inkjet.control_gain",
        version: 1,
        summary: "Closed-loop prints of paper 002's cylinder controlled with the paper's model, the engine's baseline and the extended model fitted on a calibration print of the same printer → control_gain.parquet, control_trials.parquet",
        implements: "paper 002 eq. 8 (Sec. IV-A) with the discrepancy engine's extended model (DESIGN §7)",
        inputs: &[],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&control_gain::TABLE, &control_trials::TABLE];

    fn check(p: &ControlGainParams) -> Result<(), ParamError> {
        p.cells(&STUDIED).map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &ControlGainParams) -> Result<(), StageError> {
        let design = design(p, ctx.seed).map_err(|e| StageError::params(ctx, e))?;
        let rows = run_trials_observed(&design, &StageProgress::new(ctx)).map_err(StageError::domain)?;
        let mut gain = gain_frame(&summarize(&rows))?;
        ctx.write_table(control_gain::TABLE.name, &mut gain)?;
        let mut trials = trials_frame(&rows)?;
        ctx.write_table(control_trials::TABLE.name, &mut trials)?;
        Ok(())
    }
}

fn design(p: &ControlGainParams, seed: u64) -> Result<ControlDesign, ParamError> {
    Ok(ControlDesign {
        calibration: PrintDesign {
            radius_cells: p.radius_cells as usize,
            layers: p.calibration_layers as usize,
            max_shortfall: p.variation_pct / 100.0,
            layers_per_group: p.search.layers_per_group as usize,
        },
        cells: p.cells(&STUDIED)?,
        seeds: p.printers as usize,
        seed,
        engine: p.naming.study_settings(p.search.max_rounds, seed, 100),
    })
}

fn gain_frame(rows: &[ControlSummary]) -> Result<polars::prelude::DataFrame, StageError> {
    let col = |f: &dyn Fn(&ControlSummary) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    frame(vec![
        str_col(control_gain::effect, rows.iter().map(|r| r.effect.name().to_string()).collect()),
        f64_col(control_gain::strength, col(&|r| r.strength)),
        str_col(control_gain::controller, rows.iter().map(|r| r.predictor.name().to_string()).collect()),
        i64_col(control_gain::printers, rows.iter().map(|r| r.trials as i64).collect()),
        f64_col(control_gain::desired_um, col(&|r| r.desired_um)),
        f64_col(control_gain::mean_error_um, col(&|r| r.mean_error_um.mean.0)),
        f64_col(control_gain::mean_error_ci_lo, col(&|r| r.mean_error_um.mean.1)),
        f64_col(control_gain::mean_error_ci_hi, col(&|r| r.mean_error_um.mean.2)),
        f64_col(control_gain::rmsd_um, col(&|r| r.rmsd_um.mean.0)),
        f64_col(control_gain::rmsd_ci_lo, col(&|r| r.rmsd_um.mean.1)),
        f64_col(control_gain::rmsd_ci_hi, col(&|r| r.rmsd_um.mean.2)),
        f64_col(control_gain::average_height_um, col(&|r| r.average_height_um.mean.0)),
        f64_col(control_gain::average_height_ci_lo, col(&|r| r.average_height_um.mean.1)),
        f64_col(control_gain::average_height_ci_hi, col(&|r| r.average_height_um.mean.2)),
        f64_col(control_gain::mean_error_vs_paper_um, col(&|r| r.mean_error_um.vs_paper.0)),
        f64_col(control_gain::mean_error_vs_paper_ci_lo, col(&|r| r.mean_error_um.vs_paper.1)),
        f64_col(control_gain::mean_error_vs_paper_ci_hi, col(&|r| r.mean_error_um.vs_paper.2)),
        f64_col(control_gain::rmsd_vs_paper_um, col(&|r| r.rmsd_um.vs_paper.0)),
        f64_col(control_gain::rmsd_vs_paper_ci_lo, col(&|r| r.rmsd_um.vs_paper.1)),
        f64_col(control_gain::rmsd_vs_paper_ci_hi, col(&|r| r.rmsd_um.vs_paper.2)),
    ])
}

fn trials_frame(rows: &[ControlRow]) -> Result<polars::prelude::DataFrame, StageError> {
    let col = |f: &dyn Fn(&ControlRow) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    frame(vec![
        str_col(control_trials::effect, rows.iter().map(|r| r.effect.name().to_string()).collect()),
        f64_col(control_trials::strength, col(&|r| r.strength)),
        i64_col(control_trials::printer, rows.iter().map(|r| r.trial as i64).collect()),
        str_col(control_trials::seed, rows.iter().map(|r| format!("{:016x}", r.seed)).collect()),
        str_col(control_trials::named, rows.iter().map(|r| r.named.clone()).collect()),
        str_col(control_trials::controller, rows.iter().map(|r| r.predictor.name().to_string()).collect()),
        i64_col(control_trials::layers_printed, rows.iter().map(|r| r.layers_printed as i64).collect()),
        f64_col(control_trials::desired_um, col(&|r| r.desired_um)),
        f64_col(control_trials::mean_error_um, col(&|r| r.metrics.mean_error_um)),
        f64_col(control_trials::rmsd_um, col(&|r| r.metrics.rmsd_um)),
        f64_col(control_trials::std_um, col(&|r| r.metrics.std_um)),
        f64_col(control_trials::average_height_um, col(&|r| r.metrics.average_height_um)),
    ])
}
