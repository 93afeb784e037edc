//! `table.concat`: stacks same-named Parquet tables of several input stages into one
//! (e.g. the per-printer, per-model leave-one-out tables into `loo.parquet`). Tables
//! must have the same columns in the same order; rows keep input order.

use pipeline::artifact::read_parquet;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};
use polars::prelude::DataFrame;

/// The `table.concat` stage kind.
pub struct ConcatStage;

const PARAMS: &[ParamSpec] = &[ParamSpec {
    name: "tables",
    ty: ParamType::Text,
    default: ParamDefault::Required,
    doc: "Comma-separated table names (without .parquet); a table missing from an input is skipped for that input.",
}];

impl StageKind for ConcatStage {
    fn name(&self) -> &'static str {
        "table.concat"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Stacks same-named Parquet tables of its inputs into one table each"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §3 (stages meet only through Parquet)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::at_least(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let names: Vec<String> = ctx.params.str("tables").split(',').map(|s| s.trim().to_string()).collect();
        for name in names.iter().filter(|n| !n.is_empty()) {
            let mut stacked = stack(ctx, name)?;
            ctx.write_table(name, &mut stacked)?;
        }
        Ok(())
    }
}

fn stack(ctx: &StageContext, name: &str) -> Result<DataFrame, StageError> {
    let mut stacked: Option<DataFrame> = None;
    for input in &ctx.inputs {
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
