//! `inkjet.recovery`: the exact-recovery check of paper 002 Sec. IV-C: a random droplet
//! pattern is applied to a random 20 × 20 profile with the nominal model, and the
//! stochastic greedy search (`α = 1`, one-layer horizon) must find it again from the
//! all-ones pattern (the paper: recovered in every trial).

use models::inkjet::experiments::{recovery_study, RecoverySetup, RecoveryTrial};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::{DataFrame, IntoColumn, NamedFrom, Series};
use tables::inkjet::recovery;

use crate::table::{f64_col, frame, i64_col};

/// The `inkjet.recovery` stage kind.
pub struct RecoveryStage;

pipeline::params! {
    /// The parameters of `inkjet.recovery`.
    pub struct RecoveryParams {
        /// Number of independent trials (trial t seeded with the stage seed + t); the paper reports 50.
        pub trials: i64 [1, 100_000] = 50,
    }
}

impl Stage for RecoveryStage {
    type Params = RecoveryParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "inkjet.recovery",
        version: 1,
        summary: "Exact-recovery trials of the greedy MPC search on random patterns → recovery.parquet",
        implements: "paper 002 Sec. IV-C (exact recovery of random patterns, α = 1)",
        inputs: &[],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&recovery::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &RecoveryParams) -> Result<(), StageError> {
        let results =
            recovery_study(&RecoverySetup::paper(), p.trials as usize, ctx.seed).map_err(StageError::domain)?;
        let mut table = recovery_frame(&results)?;
        ctx.write_table(recovery::TABLE.name, &mut table)?;
        Ok(())
    }
}

/// One row per trial: index, whether the applied pattern was found exactly, the number
/// of wrongly set cells, the final eq. 8 objective and the droplets applied.
pub fn recovery_frame(trials: &[RecoveryTrial]) -> Result<DataFrame, StageError> {
    let recovered: Vec<bool> = trials.iter().map(|t| t.flips_wrong == 0).collect();
    frame(vec![
        i64_col(recovery::trial, (0..trials.len() as i64).collect()),
        Series::new(recovery::recovered.into(), recovered).into_column(),
        i64_col(recovery::flips_wrong, trials.iter().map(|t| t.flips_wrong as i64).collect()),
        f64_col(recovery::objective_um, trials.iter().map(|t| t.objective_um).collect()),
        i64_col(recovery::droplets_applied, trials.iter().map(|t| t.droplets_applied as i64).collect()),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovered_means_no_wrong_flip() {
        let trials = [
            RecoveryTrial { flips_wrong: 0, objective_um: 0.0, droplets_applied: 200 },
            RecoveryTrial { flips_wrong: 3, objective_um: 1.2, droplets_applied: 190 },
        ];
        let table = recovery_frame(&trials).unwrap();
        assert_eq!(table.height(), 2);
        let recovered = table.column("recovered").unwrap().bool().unwrap();
        assert_eq!((recovered.get(0), recovered.get(1)), (Some(true), Some(false)));
        assert_eq!(table.column("trial").unwrap().i64().unwrap().get(1), Some(1));
        assert_eq!(table.column("flips_wrong").unwrap().i64().unwrap().get(1), Some(3));
    }
}
