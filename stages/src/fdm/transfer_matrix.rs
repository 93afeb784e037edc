//! `fdm.transfer_matrix`: transfer learning among several printers (paper 000 Sec. II-B
//! and III-B, Algorithm 1, eqs 4-6, carried to many printers): every ordered
//! (source → target) pair of the input printers and, with `co_learning`, every printer
//! as the target of all the others. Per task every subset of the target's lines is
//! fitted with the methods of `models::fdm::colearn` (single, the paper's zero-mean
//! prior, the source-centred prior, the negative-transfer guard, co-learning) and tested
//! on the target's other lines; beside them, not a method, the bound in hindsight (per
//! subset the prior and λ best on its own held-out lines: how far any choice could go).
//!
//! Outputs:
//! - `transfer_matrix.parquet`: sources, target, n_train, method, median_rmse_mm,
//!   improvement_pct, ci_lo_pct, ci_hi_pct, rows (a paired bootstrap over the held-out
//!   lines gives the interval).
//! - `transfer_matrix_rows.parquet`: sources, target, n_train, subset, test_condition,
//!   method, rmse_mm, lambda, prior (one row per prediction).
//!
//! It splits into one work unit per target printer ([`pipeline::Split`]): each unit
//! fits its target's tasks (building the priors of their sources: one more build per
//! source and target than the whole study in one go, too cheap to measure on the
//! shipped spec), and the merge stacks the units' rows in task order and summarises
//! them. The rows are those of the whole study (`models::fdm::transfer_matrix_for_target`).

use std::path::PathBuf;

use models::fdm::{
    default_tasks, summarise, transfer_matrix_for_target, MatrixMethod, MatrixRow, PiecewiseParams,
    PiecewiseValidParams, PriorKinematics, StudyPrinter, TransferParams, TransferTask, TransferValidParams,
};
use pipeline::params::{ParamError, StageParams};
use pipeline::schema::Table;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::units::run_split;
use pipeline::{Params, Split, StageContext, StageError, Unit};
use tables::fdm::{transfer_matrix, transfer_matrix_part, transfer_matrix_rows};

use crate::fdm::lines::{fit_failed, PrinterLines};
use crate::parts::read_parts;
use crate::table::{f64_col, f64s, frame, i64_col, ints, str_col, strs};

/// The `fdm.transfer_matrix` stage kind.
pub struct TransferMatrixStage;

pipeline::params! {
    /// The parameters of `fdm.transfer_matrix`.
    pub struct TransferMatrixParams {
        /// Comma-separated printer names (dataset.toml `printer`) whose lines start with a dwell blob (phase p1 of eq. 3); the others are fitted without it.
        pub blob_printers: String = "",
        /// Also learn each printer from all the others together (needs three or more printers).
        pub co_learning: bool = true,
        /// Spacing of the λ grid from 1e-6 to 1e4 (decades; fdm.transfer_cv uses 0.5). Every method's λ is chosen on this grid.
        pub lambda_step_decades: f64 [0.1, 2.0] = 1.0,
        /// Where a fit under a prior takes the kinematic scales (r_a, r_F) of eq. 1: `grid` repeats the grid search under every prior and λ (as fdm.transfer_cv, Fig. 9); `target_pair` takes the training lines' own pair without prior and fits every prior there.
        pub kinematics: String = "grid",
        /// Bootstrap resamples of the target's held-out lines for each improvement's 95 % interval.
        pub bootstrap_draws: i64 [100, 100_000] = 2000,
    }
}

/// Every printer of the study, each learnt from the others.
const PRINTERS: Input =
    Input::many("printers", 2, &[Source::Dataset("fdm-widths")], "each printer's lines (`fdm-widths`), two or more");

impl Stage for TransferMatrixStage {
    type Params = TransferMatrixParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.transfer_matrix",
        version: 3,
        summary: "Transfer among several printers: every ordered pair and every printer from all the others × {single, zero-mean, source-mean, guarded, co-learning, bound in hindsight} → transfer_matrix.parquet, transfer_matrix_rows.parquet",
        implements: "paper 000 Sec. II-B / III-B (Algorithm 1, eqs 4-6) over many printers, with a negative-transfer guard",
        inputs: &[PRINTERS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] =
        &[&transfer_matrix::TABLE, &transfer_matrix_rows::TABLE, &transfer_matrix_part::TABLE];

    fn check(p: &TransferMatrixParams) -> Result<(), ParamError> {
        transfer_params(p).map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, _: &TransferMatrixParams) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

/// Work units: one per target printer (every task learning it, from each source and
/// from all the others); the merge stacks their rows and summarises them.
impl Split for TransferMatrixStage {
    fn units(&self, _params: &Params, inputs: usize) -> Vec<Unit> {
        (0..inputs).map(|t| Unit { key: format!("target printer {t}"), cost: inputs as f64 }).collect()
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let study = Study::read(ctx)?;
        let printers = study.printers();
        let rows = transfer_matrix_for_target(&printers, &study.tasks, &study.transfer, index)
            .map_err(|e| fit_failed("transfer matrix", e))?;
        ctx.write_table(transfer_matrix_part::TABLE.name, &mut part_table(&rows)?)?;
        Ok(())
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        let study = Study::read(ctx)?;
        let mut rows = part_rows(ctx, &read_parts(parts)?)?;
        rows.sort_by_key(|r| r.task);
        write_tables(ctx, &study, &rows)
    }
}

/// `transfer_matrix.parquet` (the rows summarised) and `transfer_matrix_rows.parquet`.
fn write_tables(ctx: &mut StageContext, study: &Study, rows: &[MatrixRow]) -> Result<(), StageError> {
    let draws = TransferMatrixParams::from_params(&ctx.params).bootstrap_draws as usize;
    let summary = summarise(rows, draws, ctx.seed);
    let names = task_names(&study.tasks, &study.lines);
    let (s_src, s_tgt): (Vec<String>, Vec<String>) = summary.iter().map(|s| names[s.task].clone()).unzip();
    let mut table = frame(vec![
        str_col(transfer_matrix::sources, s_src),
        str_col(transfer_matrix::target, s_tgt),
        i64_col(transfer_matrix::n_train, summary.iter().map(|s| s.n_train as i64).collect()),
        str_col(transfer_matrix::method, summary.iter().map(|s| s.method.name().to_string()).collect()),
        f64_col(transfer_matrix::median_rmse_mm, summary.iter().map(|s| s.median_rmse_mm).collect()),
        f64_col(transfer_matrix::improvement_pct, summary.iter().map(|s| s.improvement_pct).collect()),
        f64_col(transfer_matrix::ci_lo_pct, summary.iter().map(|s| s.ci_lo_pct).collect()),
        f64_col(transfer_matrix::ci_hi_pct, summary.iter().map(|s| s.ci_hi_pct).collect()),
        i64_col(transfer_matrix::rows, summary.iter().map(|s| s.rows as i64).collect()),
        str_col(transfer_matrix::kinematics, vec![study.transfer.get().kinematics.name().to_string(); summary.len()]),
    ])?;
    ctx.write_table(transfer_matrix::TABLE.name, &mut table)?;
    let mut rows = rows_table(rows, &study.tasks, &study.lines, &names)?;
    ctx.write_table(transfer_matrix_rows::TABLE.name, &mut rows)?;
    Ok(())
}

/// The study as the spec sets it: every input printer's lines and model settings, the
/// transfer settings and the tasks.
struct Study {
    lines: Vec<PrinterLines>,
    params: Vec<PiecewiseValidParams>,
    transfer: TransferValidParams,
    tasks: Vec<TransferTask>,
}

impl Study {
    fn read(ctx: &StageContext) -> Result<Self, StageError> {
        let p = TransferMatrixParams::from_params(&ctx.params);
        let inputs = ctx.inputs_of(&PRINTERS);
        let lines = (inputs.iter().map(|i| PrinterLines::read(&i.dir))).collect::<Result<Vec<PrinterLines>, _>>()?;
        for (b, later) in lines.iter().enumerate() {
            if let Some(a) = lines[..b].iter().position(|p| p.printer == later.printer) {
                return Err(StageError::BadInput {
                    file: inputs[b].dir.join("dataset.toml"),
                    location: Some("field printer".into()),
                    expected: format!(
                        "expected a printer other than input `{}`'s, `{}` (the matrix tells printers apart by name)",
                        inputs[a].name, later.printer
                    ),
                });
            }
        }
        let params = model_params(&lines, &p.blob_printers)
            .map_err(|message| StageError::Params { stage: ctx.stage.clone(), message })?;
        let transfer = transfer_params(&p).map_err(|e| StageError::params(ctx, e))?;
        let tasks = default_tasks(lines.len(), p.co_learning);
        Ok(Self { lines, params, transfer, tasks })
    }

    fn printers(&self) -> Vec<StudyPrinter<'_>> {
        self.lines
            .iter()
            .zip(&self.params)
            .map(|(p, params)| StudyPrinter { name: &p.printer, lines: &p.lines, params })
            .collect()
    }
}

/// A unit's rows, exactly (indices, not names: the merge needs them back).
fn part_table(rows: &[MatrixRow]) -> Result<polars::prelude::DataFrame, StageError> {
    use transfer_matrix_part as part;
    frame(vec![
        i64_col(part::task, rows.iter().map(|r| r.task as i64).collect()),
        i64_col(part::n_train, rows.iter().map(|r| r.n_train as i64).collect()),
        str_col(part::subset, rows.iter().map(|r| r.subset.clone()).collect()),
        i64_col(part::test_index, rows.iter().map(|r| r.test_index as i64).collect()),
        str_col(part::method, rows.iter().map(|r| r.method.name().to_string()).collect()),
        f64_col(part::rmse_mm, rows.iter().map(|r| r.rmse_mm).collect()),
        f64_col(part::lambda, rows.iter().map(|r| r.lambda).collect()),
        str_col(part::prior, rows.iter().map(|r| r.prior.clone()).collect()),
    ])
}

/// The rows of [`part_table`]s, stacked.
fn part_rows(ctx: &StageContext, all: &polars::prelude::DataFrame) -> Result<Vec<MatrixRow>, StageError> {
    use transfer_matrix_part as part;
    let file = ctx.output_dir().join("parts");
    let index = |name: &str| -> Result<Vec<usize>, StageError> {
        Ok(ints(all, name, &file)?.into_iter().map(|v| v as usize).collect())
    };
    let (task, n_train, test_index) = (index(part::task)?, index(part::n_train)?, index(part::test_index)?);
    let (subset, method, prior) =
        (strs(all, part::subset, &file)?, strs(all, part::method, &file)?, strs(all, part::prior, &file)?);
    let (rmse_mm, lambda) = (f64s(all, part::rmse_mm, &file)?, f64s(all, part::lambda, &file)?);
    (0..all.height())
        .map(|i| {
            let method = MatrixMethod::parse(&method[i]).ok_or_else(|| StageError::BadInput {
                file: file.clone(),
                location: None,
                expected: format!("a transfer method, got `{}`", method[i]),
            })?;
            Ok(MatrixRow {
                task: task[i],
                n_train: n_train[i],
                subset: subset[i].clone(),
                test_index: test_index[i],
                method,
                rmse_mm: rmse_mm[i],
                lambda: lambda[i],
                prior: prior[i].clone(),
            })
        })
        .collect()
}

/// Each printer's model settings: the paper's, with the start blob where named.
fn model_params(printers: &[PrinterLines], blob_printers: &str) -> Result<Vec<PiecewiseValidParams>, String> {
    let blob: Vec<&str> = blob_printers.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
    if let Some(unknown) = blob.iter().find(|b| !printers.iter().any(|p| p.printer == **b)) {
        let known: Vec<&str> = printers.iter().map(|p| p.printer.as_str()).collect();
        return Err(format!("blob_printers names `{unknown}`, which is not an input printer ({})", known.join(", ")));
    }
    printers
        .iter()
        .map(|p| {
            let params = if blob.contains(&p.printer.as_str()) {
                PiecewiseParams::paper_defaults()
            } else {
                PiecewiseParams::paper_defaults_without_blob()
            };
            params.check().map_err(|e| format!("piecewise parameters: {e}"))
        })
        .collect()
}

/// The paper's transfer settings on a λ grid from 1e-6 to 1e4 in steps of
/// `lambda_step_decades`, with the stage's kinematics rule.
fn transfer_params(p: &TransferMatrixParams) -> Result<TransferValidParams, ParamError> {
    let kinematics = PriorKinematics::parse(&p.kinematics).ok_or_else(|| {
        let names = PriorKinematics::ALL.map(|k| k.name());
        ParamError::new("kinematics", format!("`{}` is not one of {}", p.kinematics, names.join(", ")))
    })?;
    let lambda_grid = TransferParams::log_lambda_grid(p.lambda_step_decades);
    TransferParams { lambda_grid, kinematics, ..TransferParams::paper_defaults() }
        .check()
        .map_err(|e| ParamError::new("lambda_step_decades", e.to_string()))
}

/// Each task's `+`-joined source names and its target's name.
fn task_names(tasks: &[TransferTask], printers: &[PrinterLines]) -> Vec<(String, String)> {
    let name = |i: usize| printers[i].printer.as_str();
    tasks
        .iter()
        .map(|t| (t.sources.iter().map(|&s| name(s)).collect::<Vec<_>>().join("+"), name(t.target).into()))
        .collect()
}

fn rows_table(
    rows: &[MatrixRow],
    tasks: &[TransferTask],
    printers: &[PrinterLines],
    names: &[(String, String)],
) -> Result<polars::prelude::DataFrame, StageError> {
    let (src, tgt): (Vec<String>, Vec<String>) = rows.iter().map(|r| names[r.task].clone()).unzip();
    let condition = |r: &MatrixRow| printers[tasks[r.task].target].conditions[r.test_index].clone();
    use transfer_matrix_rows as t;
    frame(vec![
        str_col(t::sources, src),
        str_col(t::target, tgt),
        i64_col(t::n_train, rows.iter().map(|r| r.n_train as i64).collect()),
        str_col(t::subset, rows.iter().map(|r| r.subset.clone()).collect()),
        str_col(t::test_condition, rows.iter().map(condition).collect()),
        str_col(t::method, rows.iter().map(|r| r.method.name().to_string()).collect()),
        f64_col(t::rmse_mm, rows.iter().map(|r| r.rmse_mm).collect()),
        f64_col(t::lambda, rows.iter().map(|r| r.lambda).collect()),
        str_col(t::prior, rows.iter().map(|r| r.prior.clone()).collect()),
    ])
}
