//! Leave-one-out of paper 000 (Case A, Table II): for each printer, fit on all lines
//! but one, predict the held-out line from its commanded kinematics only, RMSE over the
//! whole line. Two models share one output layout so the tables stack:
//!
//! - `fdm.piecewise_loo`: the five-phase piecewise model (eqs 2-3) with the 8-step fit
//!   and the r_a × r_F grid search (eq. 1); also writes the training-RMSE surface over
//!   the grid on all lines (not in the paper: shows whether the optimum is sharp).
//! - `fdm.lag_model`: the physics baseline of DESIGN §5.1 (mass conservation and a
//!   first-order extrusion lag with a start-blob state), fitted per printer on the same
//!   splits. It is reported as fitted, not tuned to hide its failures.
//!
//! Outputs: `loo.parquet` (printer, condition, accel_mm_s2, feed_mm_s, model, rmse_mm,
//! r_a, r_f, tau_s) and `loo_predictions.parquet` (printer, condition, model,
//! position_mm, measured_width_mm, predicted_width_mm).

use models::fdm::loo::run_folds;
use models::fdm::{
    fit_at, fit_lag, rmse, LagParams, LagValidParams, MeasuredLine, PiecewiseParams, PiecewiseValidParams,
};
use models::progress::Progress;
use pipeline::params::ParamError;
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::{Column, IntoColumn, NamedFrom, Series};
use rayon::prelude::*;
use tables::fdm::{loo, loo_predictions, r_surface};

use crate::fdm::lines::{fit_failed, model_param_error, PrinterLines};
use crate::progress::StageProgress;
use crate::roles;
use crate::table::{f64_col, frame, str_col};

/// One held-out line's result.
struct Fold {
    rmse_mm: f64,
    r_a: f64,
    r_f: f64,
    tau_s: Option<f64>,
    predicted_mm: Vec<f64>,
}

/// The `fdm.piecewise_loo` stage kind.
pub struct PiecewiseLooStage;

/// The `fdm.lag_model` stage kind.
pub struct LagLooStage;

pipeline::params! {
    /// The parameters of `fdm.piecewise_loo`.
    pub struct PiecewiseLooParams {
        /// Lines start with a blob (phase p1): true for the Taz 5, false for the Taz 6 (paper Fig. 8).
        pub start_blob: bool,
        /// Lower end of the r_a, r_F grid (eq. 1).
        pub r_min: f64 [0.5, 1.5] = 0.9,
        /// Upper end of the r_a, r_F grid (eq. 1).
        pub r_max: f64 [0.5, 1.5] = 1.1,
        /// Grid step: 0.01 gives the paper's 21 × 21 = 441 pairs.
        pub r_step: f64 [0.001, 0.2] = 0.01,
        /// Moving average before locating the width minimum (bp1) and the first reach of c (bp3); ours, the paper does not say.
        pub smoothing_mm: f64 [0.0, 10.0] = 1.0,
    }
}

pipeline::params! {
    /// The parameters of `fdm.lag_model`.
    pub struct LagLooParams {
        /// Fit an initial flow excess from dwell pressure (the start blob).
        pub start_blob: bool,
        /// Smallest extrusion time constant searched (s).
        pub tau_min_s: f64 [1e-4, 10.0] = 0.005,
        /// Largest time constant searched (s); Bowden extruders reach ≈ 1 s (DESIGN §5.1).
        pub tau_max_s: f64 [1e-3, 30.0] = 3.0,
        /// Width smoothing along the path: about one nozzle diameter (0.5 mm, Table I).
        pub smoothing_mm: f64 [0.0, 10.0] = 0.5,
    }
}

impl PiecewiseLooParams {
    /// The model's checked hyper-parameters.
    fn checked(&self) -> Result<PiecewiseValidParams, ParamError> {
        PiecewiseParams {
            r_min: self.r_min,
            r_max: self.r_max,
            r_step: self.r_step,
            has_start_blob: self.start_blob,
            smoothing_mm: self.smoothing_mm,
            ..PiecewiseParams::paper_defaults()
        }
        .check()
        .map_err(model_param_error)
    }
}

impl LagLooParams {
    /// The model's checked hyper-parameters.
    fn checked(&self) -> Result<LagValidParams, ParamError> {
        LagParams {
            tau_min_s: self.tau_min_s,
            tau_max_s: self.tau_max_s,
            smoothing_mm: self.smoothing_mm,
            has_start_blob: self.start_blob,
            ..LagParams::paper_defaults()
        }
        .check()
        .map_err(model_param_error)
    }
}

impl Stage for PiecewiseLooStage {
    type Params = PiecewiseLooParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.piecewise_loo",
        version: 1,
        summary: "Leave-one-out of the piecewise width model with r_a × r_F grid search → loo.parquet, loo_predictions.parquet, r_surface.parquet",
        implements: "paper 000 eqs 1-3, 8-step procedure, Case A (Table II, Fig. 6)",
        inputs: &[roles::FDM_WIDTHS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&loo::TABLE, &loo_predictions::TABLE, &r_surface::TABLE];

    fn check(p: &PiecewiseLooParams) -> Result<(), ParamError> {
        p.checked().map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &PiecewiseLooParams) -> Result<(), StageError> {
        let params = p.checked().map_err(|e| StageError::params(ctx, e))?;
        let printer = PrinterLines::read(&ctx.input(&roles::FDM_WIDTHS).dir)?;
        let progress = StageProgress::with_steps(ctx, printer.lines.len() as u64);
        let folds = run_folds(&printer.lines, |train, test, _| {
            let model = models::fdm::fit(train, &params)?;
            let predicted_mm = model.predict(&test.nominal, &test.positions_mm)?;
            let rmse_mm = rmse(&predicted_mm, &test.widths_mm);
            progress.done(1);
            Ok(Fold { rmse_mm, r_a: model.r_a, r_f: model.r_f, tau_s: None, predicted_mm })
        })
        .map_err(|e| fit_failed("piecewise leave-one-out", e))?;
        write_loo(ctx, &printer, "piecewise", &folds)?;
        let mut surface = r_surface(&printer, &params)?;
        ctx.write_table(r_surface::TABLE.name, &mut surface)?;
        Ok(())
    }
}

impl Stage for LagLooStage {
    type Params = LagLooParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.lag_model",
        version: 1,
        summary: "Leave-one-out of the physics baseline: mass conservation + first-order extrusion lag + start blob → loo.parquet, loo_predictions.parquet",
        implements: "DESIGN §5.1 (w = Q/(h·v), τ·dQ/dt = Q_cmd − Q); compared with paper 000 Table II",
        inputs: &[roles::FDM_WIDTHS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&loo::TABLE, &loo_predictions::TABLE];

    fn check(p: &LagLooParams) -> Result<(), ParamError> {
        p.checked().map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &LagLooParams) -> Result<(), StageError> {
        let params = p.checked().map_err(|e| StageError::params(ctx, e))?;
        let printer = PrinterLines::read(&ctx.input(&roles::FDM_WIDTHS).dir)?;
        let progress = StageProgress::with_steps(ctx, printer.lines.len() as u64);
        let folds = run_folds(&printer.lines, |train, test, _| {
            let model = fit_lag(train, &params)?;
            let predicted_mm = model.predict(&test.nominal, &test.positions_mm)?;
            let rmse_mm = rmse(&predicted_mm, &test.widths_mm);
            progress.done(1);
            Ok(Fold { rmse_mm, r_a: 1.0, r_f: 1.0, tau_s: Some(model.tau_s), predicted_mm })
        })
        .map_err(|e| fit_failed("lag leave-one-out", e))?;
        write_loo(ctx, &printer, "lag", &folds)
    }
}

fn write_loo(ctx: &mut StageContext, printer: &PrinterLines, model: &str, folds: &[Fold]) -> Result<(), StageError> {
    let n = folds.len();
    let lines = &printer.lines;
    let mut summary = frame(vec![
        str_col(loo::printer, vec![printer.printer.clone(); n]),
        str_col(loo::condition, printer.conditions.clone()),
        f64_col(loo::accel_mm_s2, lines.iter().map(|l| l.nominal.accel_mm_s2).collect()),
        f64_col(loo::feed_mm_s, lines.iter().map(|l| l.nominal.feed_mm_s).collect()),
        str_col(loo::model, vec![model.to_string(); n]),
        f64_col(loo::rmse_mm, folds.iter().map(|f| f.rmse_mm).collect()),
        f64_col(loo::r_a, folds.iter().map(|f| f.r_a).collect()),
        f64_col(loo::r_f, folds.iter().map(|f| f.r_f).collect()),
        optional_col(loo::tau_s, folds.iter().map(|f| f.tau_s).collect()),
    ])?;
    ctx.write_table(loo::TABLE.name, &mut summary)?;
    let mut predictions = predictions_frame(printer, model, folds)?;
    ctx.write_table(loo_predictions::TABLE.name, &mut predictions)?;
    Ok(())
}

fn predictions_frame(
    printer: &PrinterLines,
    model: &str,
    folds: &[Fold],
) -> Result<polars::prelude::DataFrame, StageError> {
    let total: usize = printer.lines.iter().map(MeasuredLine::len).sum();
    let mut condition = Vec::with_capacity(total);
    let (mut position, mut measured, mut predicted) =
        (Vec::with_capacity(total), Vec::with_capacity(total), Vec::with_capacity(total));
    for ((line, cond), fold) in printer.lines.iter().zip(&printer.conditions).zip(folds) {
        condition.extend(std::iter::repeat_n(cond.clone(), line.len()));
        position.extend_from_slice(&line.positions_mm);
        measured.extend_from_slice(&line.widths_mm);
        predicted.extend_from_slice(&fold.predicted_mm);
    }
    frame(vec![
        str_col(loo_predictions::printer, vec![printer.printer.clone(); total]),
        str_col(loo_predictions::condition, condition),
        str_col(loo_predictions::model, vec![model.to_string(); total]),
        f64_col(loo_predictions::position_mm, position),
        f64_col(loo_predictions::measured_width_mm, measured),
        f64_col(loo_predictions::predicted_width_mm, predicted),
    ])
}

/// Training RMSE of the fit on all lines at every grid point (r_a major).
fn r_surface(printer: &PrinterLines, params: &PiecewiseValidParams) -> Result<polars::prelude::DataFrame, StageError> {
    let r = params.r_values();
    let grid: Vec<(f64, f64)> = r.iter().flat_map(|&a| r.iter().map(move |&f| (a, f))).collect();
    let rmse_mm: Vec<f64> = grid
        .par_iter()
        .map(|&(a, f)| fit_at(&printer.lines, params, a, f).map(|m| m.training_rmse_mm))
        .collect::<Result<_, _>>()
        .map_err(|e| fit_failed("r_a × r_F surface", e))?;
    frame(vec![
        str_col(r_surface::printer, vec![printer.printer.clone(); grid.len()]),
        f64_col(r_surface::r_a, grid.iter().map(|g| g.0).collect()),
        f64_col(r_surface::r_f, grid.iter().map(|g| g.1).collect()),
        f64_col(r_surface::training_rmse_mm, rmse_mm),
    ])
}

fn optional_col(name: &str, values: Vec<Option<f64>>) -> Column {
    Series::new(name.into(), values).into_column()
}
