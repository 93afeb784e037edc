//! `table.concat`: stacks same-named Parquet tables of several input stages into one
//! (e.g. the per-printer, per-model leave-one-out tables into `loo.parquet`). Tables
//! must have the same columns in the same order; rows keep input order.

use pipeline::artifact::read_parquet;
use pipeline::params::ParamError;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;

/// The `table.concat` stage kind.
pub struct ConcatStage;

pipeline::params! {
    /// The parameters of `table.concat`.
    pub struct ConcatParams {
        /// Comma-separated table names (without .parquet); a table missing from an input is skipped for that input.
        pub tables: String,
    }
}

/// The stages whose tables are stacked.
const PARTS: Input = Input::many("parts", 1, &[Source::AnyStage], "stages writing the named tables");

impl Stage for ConcatStage {
    type Params = ConcatParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "table.concat",
        version: 1,
        summary: "Stacks same-named Parquet tables of its inputs into one table each",
        implements: "DESIGN §3 (stages meet only through Parquet)",
        inputs: &[PARTS],
        output: Output::LikeInputs,
    };

    fn check(p: &ConcatParams) -> Result<(), ParamError> {
        if table_names(&p.tables).next().is_none() {
            return Err(ParamError::new("tables", "name at least one table"));
        }
        Ok(())
    }

    fn run(&self, ctx: &mut StageContext, p: &ConcatParams) -> Result<(), StageError> {
        for name in table_names(&p.tables) {
            let mut stacked = stack(ctx, name)?;
            ctx.write_table(name, &mut stacked)?;
        }
        Ok(())
    }
}

/// The non-empty names of a comma-separated list.
fn table_names(list: &str) -> impl Iterator<Item = &str> {
    list.split(',').map(str::trim).filter(|n| !n.is_empty())
}

fn stack(ctx: &StageContext, name: &str) -> Result<DataFrame, StageError> {
    let mut stacked: Option<DataFrame> = None;
    for input in ctx.inputs_of(&PARTS) {
        let path = input.dir.join(format!("{name}.parquet"));
        if !path.exists() {
            continue;
        }
        let df = read_parquet(&path)?;
        stacked = Some(match stacked {
            None => df,
            Some(mut acc) => {
                acc.vstack_mut(&df).map_err(|source| StageError::Table { path: path.clone(), source })?;
                acc
            }
        });
    }
    stacked.ok_or_else(|| StageError::BadInput {
        file: format!("{name}.parquet").into(),
        location: None,
        expected: format!("expected at least one input holding {name}.parquet"),
    })
}
