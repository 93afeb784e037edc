//! `fdm.transfer_cv`: between-printer transfer learning, paper 000 Case B (Algorithm 1,
//! eqs 4-6, Fig. 9). The source printer (first input, the Taz 5) gives the covariance
//! prior; on the target printer (second input, the Taz 6) every subset of n = 1..N−1
//! training lines is fitted with three methods and tested on the remaining lines:
//!
//! - `single`: the target's lines only;
//! - `transfer_zero_mean`: MAP with the paper's prior N(0, Σ) as written;
//! - `transfer_source_mean`: MAP with the prior centred on the source estimates (our
//!   extension: the zero-mean prior looks like a simplification worth testing).
//!
//! λ is chosen by inner leave-one-out on the training lines; with one training line,
//! by simulating single-line transfer on the source printer (see `models::fdm::transfer`).
//! Output `transfer_cv.parquet`: n_train, subset, test_condition, method, rmse_mm, lambda.
//!
//! Work units (`pipeline::units`, docs/SCALE.md): one per `r_a` of the target's grid
//! (`models::fdm::transfer_cv_blocks`, 21 with the paper's grid). A unit searches its
//! block of grid pairs for every training subset under every prior configuration and
//! writes the winners exactly (`part.parquet`, one row per subset and configuration;
//! `part_errors.parquet`, each subset's first failing pair); the merge joins the
//! blocks in grid order and finishes the study (`models::fdm::transfer_cv_from_parts`),
//! so the rows are those of one call bit for bit.

use std::path::{Path, PathBuf};

use models::fdm::{
    transfer_cv_blocks, transfer_cv_from_parts, transfer_cv_part, FitError, GridPart, GridWinner, PiecewiseParams,
    PiecewiseValidParams, TransferParams, TransferValidParams,
};
use pipeline::artifact::read_parquet;
use pipeline::params::NoParams;
use pipeline::schema::Table;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::units::run_split;
use pipeline::{Params, Split, StageContext, StageError, Unit};
use polars::prelude::DataFrame;
use tables::fdm::{transfer_cv, transfer_cv_errors, transfer_cv_part};

use crate::fdm::lines::{fit_failed, PrinterLines};
use crate::table::{f64_col, f64s, frame, i64_col, ints, str_col, strs};

/// The `fdm.transfer_cv` stage kind.
pub struct TransferCvStage;

/// The printer whose lines give the prior.
const SOURCE: Input = Input::one("source", &[Source::Dataset("fdm-widths")], "the source printer's lines (the prior)");
/// The printer learnt with few lines.
const TARGET: Input =
    Input::one("target", &[Source::Dataset("fdm-widths")], "the target printer's lines (trained and tested)");

impl Stage for TransferCvStage {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.transfer_cv",
        version: 1,
        summary: "Transfer CV: every subset of n = 1..N−1 target lines × {single, transfer_zero_mean, transfer_source_mean}, tested on the rest → transfer_cv.parquet",
        implements: "paper 000 Case B: Algorithm 1, eqs 4-6, Fig. 9",
        inputs: &[SOURCE, TARGET],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] =
        &[&transfer_cv::TABLE, &transfer_cv_part::TABLE, &transfer_cv_errors::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        run_split(self, ctx)
    }

    fn split(&self) -> Option<&dyn Split> {
        Some(self)
    }
}

/// Work units: one block of the target's grid pairs each (module docs).
impl Split for TransferCvStage {
    fn units(&self, _params: &Params, _inputs: usize) -> Vec<Unit> {
        let blocks = Study::target_params().map(|p| transfer_cv_blocks(&p)).unwrap_or_default();
        blocks.iter().map(|r| Unit { key: format!("grid pairs {}-{}", r.start, r.end - 1), cost: 1.0 }).collect()
    }

    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError> {
        let study = Study::read(ctx)?;
        let blocks = transfer_cv_blocks(&study.target_params);
        let pairs = blocks.get(index).cloned().ok_or_else(|| StageError::Params {
            stage: ctx.stage.clone(),
            message: format!("work unit {index} is past the grid's {} blocks", blocks.len()),
        })?;
        let part = transfer_cv_part(
            &study.source.lines,
            &study.target.lines,
            &study.source_params,
            &study.target_params,
            &study.transfer,
            pairs,
        )
        .map_err(|e| fit_failed(&study.what(), e))?;
        ctx.write_table(transfer_cv_part::TABLE.name, &mut winners_frame(&part)?)?;
        ctx.write_table(transfer_cv_errors::TABLE.name, &mut errors_frame(&part)?)?;
        Ok(())
    }

    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError> {
        let study = Study::read(ctx)?;
        let parts = parts.iter().map(|dir| read_part(dir)).collect::<Result<Vec<_>, _>>()?;
        let rows = transfer_cv_from_parts(
            &study.source.lines,
            &study.target.lines,
            &study.source_params,
            &study.target_params,
            &study.transfer,
            parts,
        )
        .map_err(|e| fit_failed(&study.what(), e))?;
        let target = &study.target;
        let mut table = frame(vec![
            i64_col(transfer_cv::n_train, rows.iter().map(|r| r.n_train as i64).collect()),
            str_col(transfer_cv::subset, rows.iter().map(|r| r.subset.clone()).collect()),
            str_col(
                transfer_cv::test_condition,
                rows.iter().map(|r| target.conditions[r.test_index].clone()).collect(),
            ),
            str_col(transfer_cv::method, rows.iter().map(|r| r.method.name().to_string()).collect()),
            f64_col(transfer_cv::rmse_mm, rows.iter().map(|r| r.rmse_mm).collect()),
            f64_col(transfer_cv::lambda, rows.iter().map(|r| r.lambda).collect()),
        ])?;
        ctx.write_table(transfer_cv::TABLE.name, &mut table)?;
        Ok(())
    }
}

/// The study: the source (first input) and target (second) lines and the paper's
/// settings.
struct Study {
    source: PrinterLines,
    target: PrinterLines,
    source_params: PiecewiseValidParams,
    target_params: PiecewiseValidParams,
    transfer: TransferValidParams,
}

impl Study {
    fn read(ctx: &StageContext) -> Result<Self, StageError> {
        Ok(Self {
            source: PrinterLines::read(&ctx.input(&SOURCE).dir)?,
            target: PrinterLines::read(&ctx.input(&TARGET).dir)?,
            source_params: PiecewiseParams::paper_defaults()
                .check()
                .map_err(|e| fit_failed("piecewise parameters", e))?,
            target_params: Self::target_params()?,
            transfer: TransferParams::paper_defaults().check().map_err(|e| fit_failed("transfer parameters", e))?,
        })
    }

    /// What the study fits, for its errors: which printer is which, and which one the
    /// model fits with the start blob.
    fn what(&self) -> String {
        format!(
            "transfer cross-validation from source `{}` (fitted with the start blob, phase p1, as the Taz 5) to target `{}` (without it, as the Taz 6)",
            self.source.printer, self.target.printer
        )
    }

    /// The target's model settings: the paper's, without the start blob (the Taz 6).
    fn target_params() -> Result<PiecewiseValidParams, StageError> {
        PiecewiseParams::paper_defaults_without_blob().check().map_err(|e| fit_failed("piecewise parameters", e))
    }
}

/// A unit's winners, exactly: one row per (subset, configuration) in that order; `pair`
/// is −1 where no pair of the block gave a finite SSE.
fn winners_frame(part: &GridPart) -> Result<DataFrame, StageError> {
    let w = &part.winners;
    let mut columns = vec![
        i64_col(transfer_cv_part::configurations, vec![part.n_configs as i64; w.len()]),
        f64_col(transfer_cv_part::sse, w.iter().map(|w| w.sse).collect()),
        i64_col(transfer_cv_part::pair, w.iter().map(|w| w.pair.map_or(-1, |p| p as i64)).collect()),
        f64_col(transfer_cv_part::alpha_1, w.iter().map(|w| w.alpha.0).collect()),
        f64_col(transfer_cv_part::alpha_2, w.iter().map(|w| w.alpha.1).collect()),
    ];
    columns.extend(THETA.iter().enumerate().map(|(k, name)| f64_col(name, w.iter().map(|w| w.theta[k]).collect())));
    frame(columns)
}

/// The part's columns of a winner's `θ = (β, γ, c, ρ, w_start)`, one per entry (a θ of
/// another length does not build).
const THETA: [&str; GridWinner::NONE.theta.len()] = [
    transfer_cv_part::theta_0,
    transfer_cv_part::theta_1,
    transfer_cv_part::theta_2,
    transfer_cv_part::theta_3,
    transfer_cv_part::theta_4,
];

/// A unit's failures: each subset's first failing pair and the failure's text.
fn errors_frame(part: &GridPart) -> Result<DataFrame, StageError> {
    let failed: Vec<(usize, &(usize, FitError))> =
        part.first_error.iter().enumerate().filter_map(|(s, e)| e.as_ref().map(|e| (s, e))).collect();
    frame(vec![
        i64_col(transfer_cv_errors::subset, failed.iter().map(|(s, _)| *s as i64).collect()),
        i64_col(transfer_cv_errors::pair, failed.iter().map(|(_, (p, _))| *p as i64).collect()),
        str_col(transfer_cv_errors::error, failed.iter().map(|(_, (_, e))| e.to_string()).collect()),
    ])
}

/// A unit's [`GridPart`] back from its two tables.
fn read_part(dir: &Path) -> Result<GridPart, StageError> {
    use transfer_cv_part as part;
    let file = dir.join(part::TABLE.file());
    let winners = read_parquet(&file)?;
    let n_configs = ints(&winners, part::configurations, &file)?.first().copied().unwrap_or(1).max(1) as usize;
    let (sse, pair) = (f64s(&winners, part::sse, &file)?, ints(&winners, part::pair, &file)?);
    let (a1, a2) = (f64s(&winners, part::alpha_1, &file)?, f64s(&winners, part::alpha_2, &file)?);
    let theta: Vec<Vec<f64>> = THETA.iter().map(|name| f64s(&winners, name, &file)).collect::<Result<_, _>>()?;
    let winners = (0..winners.height())
        .map(|i| GridWinner {
            sse: sse[i],
            pair: usize::try_from(pair[i]).ok(),
            alpha: (a1[i], a2[i]),
            theta: std::array::from_fn(|k| theta[k][i]),
        })
        .collect::<Vec<_>>();
    use transfer_cv_errors as errors_part;
    let file = dir.join(errors_part::TABLE.file());
    let errors = read_parquet(&file)?;
    let n_subsets = winners.len() / n_configs;
    let mut first_error = vec![None; n_subsets];
    let (subset, pair) = (ints(&errors, errors_part::subset, &file)?, ints(&errors, errors_part::pair, &file)?);
    for (i, text) in strs(&errors, errors_part::error, &file)?.into_iter().enumerate() {
        let slot = usize::try_from(subset[i]).ok().and_then(|s| first_error.get_mut(s)).ok_or_else(|| {
            StageError::BadInput {
                file: file.clone(),
                location: Some(format!("row {i}, column `{}`", errors_part::subset)),
                expected: format!("a subset index below {n_subsets}, got {}", subset[i]),
            }
        })?;
        *slot = Some((pair[i].max(0) as usize, FitError::Recorded(text)));
    }
    Ok(GridPart { n_configs, winners, first_error })
}
