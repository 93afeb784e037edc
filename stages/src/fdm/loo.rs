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
use models::fdm::{fit_at, fit_lag, rmse, LagParams, MeasuredLine, PiecewiseParams, PiecewiseValidParams};
use models::progress::Progress;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};
use polars::prelude::{Column, IntoColumn, NamedFrom, Series};
use rayon::prelude::*;

use crate::fdm::lines::{fit_failed, PrinterLines};
use crate::progress::StageProgress;
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

const R: ParamType = ParamType::Float { min: 0.5, max: 1.5 };

const PIECEWISE_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "start_blob",
        ty: ParamType::Bool,
        default: ParamDefault::Required,
        doc: "Lines start with a blob (phase p1): true for the Taz 5, false for the Taz 6 (paper Fig. 8).",
    },
    ParamSpec { name: "r_min", ty: R, default: ParamDefault::Float(0.9), doc: "Lower end of the r_a, r_F grid (eq. 1)." },
    ParamSpec { name: "r_max", ty: R, default: ParamDefault::Float(1.1), doc: "Upper end of the r_a, r_F grid (eq. 1)." },
    ParamSpec {
        name: "r_step",
        ty: ParamType::Float { min: 0.001, max: 0.2 },
        default: ParamDefault::Float(0.01),
        doc: "Grid step: 0.01 gives the paper's 21 × 21 = 441 pairs.",
    },
    ParamSpec {
        name: "smoothing_mm",
        ty: ParamType::Float { min: 0.0, max: 10.0 },
        default: ParamDefault::Float(1.0),
        doc: "Moving average before locating the width minimum (bp1) and the first reach of c (bp3); ours, the paper does not say.",
    },
];

const LAG_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "start_blob",
        ty: ParamType::Bool,
        default: ParamDefault::Required,
        doc: "Fit an initial flow excess from dwell pressure (the start blob).",
    },
    ParamSpec {
        name: "tau_min_s",
        ty: ParamType::Float { min: 1e-4, max: 10.0 },
        default: ParamDefault::Float(0.005),
        doc: "Smallest extrusion time constant searched (s).",
    },
    ParamSpec {
        name: "tau_max_s",
        ty: ParamType::Float { min: 1e-3, max: 30.0 },
        default: ParamDefault::Float(3.0),
        doc: "Largest time constant searched (s); Bowden extruders reach ≈ 1 s (DESIGN §5.1).",
    },
    ParamSpec {
        name: "smoothing_mm",
        ty: ParamType::Float { min: 0.0, max: 10.0 },
        default: ParamDefault::Float(0.5),
        doc: "Width smoothing along the path: about one nozzle diameter (0.5 mm, Table I).",
    },
];

impl StageKind for PiecewiseLooStage {
    fn name(&self) -> &'static str {
        "fdm.piecewise_loo"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Leave-one-out of the piecewise width model with r_a × r_F grid search → loo.parquet, loo_predictions.parquet, r_surface.parquet"
    }
    fn implements(&self) -> &'static str {
        "paper 000 eqs 1-3, 8-step procedure, Case A (Table II, Fig. 6)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PIECEWISE_PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let params = piecewise_params(ctx)?;
        let printer = PrinterLines::read(&ctx.inputs[0].dir)?;
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
        ctx.write_table("r_surface", &mut surface)?;
        Ok(())
    }
}

impl StageKind for LagLooStage {
    fn name(&self) -> &'static str {
        "fdm.lag_model"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Leave-one-out of the physics baseline: mass conservation + first-order extrusion lag + start blob → loo.parquet, loo_predictions.parquet"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §5.1 (w = Q/(h·v), τ·dQ/dt = Q_cmd − Q); compared with paper 000 Table II"
    }
    fn params(&self) -> &'static [ParamSpec] {
        LAG_PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let p = &ctx.params;
        let params = LagParams {
            tau_min_s: p.f64("tau_min_s"),
            tau_max_s: p.f64("tau_max_s"),
            smoothing_mm: p.f64("smoothing_mm"),
            has_start_blob: p.bool("start_blob"),
            ..LagParams::paper_defaults()
        }
        .check()
        .map_err(|e| StageError::Params { stage: ctx.stage.clone(), message: e.to_string() })?;
        let printer = PrinterLines::read(&ctx.inputs[0].dir)?;
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

fn piecewise_params(ctx: &StageContext) -> Result<PiecewiseValidParams, StageError> {
    let p = &ctx.params;
    PiecewiseParams {
        r_min: p.f64("r_min"),
        r_max: p.f64("r_max"),
        r_step: p.f64("r_step"),
        has_start_blob: p.bool("start_blob"),
        smoothing_mm: p.f64("smoothing_mm"),
        ..PiecewiseParams::paper_defaults()
    }
    .check()
    .map_err(|e| StageError::Params { stage: ctx.stage.clone(), message: e.to_string() })
}

fn write_loo(ctx: &mut StageContext, printer: &PrinterLines, model: &str, folds: &[Fold]) -> Result<(), StageError> {
    let n = folds.len();
    let lines = &printer.lines;
    let mut summary = frame(vec![
        str_col("printer", vec![printer.printer.clone(); n]),
        str_col("condition", printer.conditions.clone()),
        f64_col("accel_mm_s2", lines.iter().map(|l| l.nominal.accel_mm_s2).collect()),
        f64_col("feed_mm_s", lines.iter().map(|l| l.nominal.feed_mm_s).collect()),
        str_col("model", vec![model.to_string(); n]),
        f64_col("rmse_mm", folds.iter().map(|f| f.rmse_mm).collect()),
        f64_col("r_a", folds.iter().map(|f| f.r_a).collect()),
        f64_col("r_f", folds.iter().map(|f| f.r_f).collect()),
        optional_col("tau_s", folds.iter().map(|f| f.tau_s).collect()),
    ])?;
    ctx.write_table("loo", &mut summary)?;
    let mut predictions = predictions_frame(printer, model, folds)?;
    ctx.write_table("loo_predictions", &mut predictions)?;
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
        str_col("printer", vec![printer.printer.clone(); total]),
        str_col("condition", condition),
        str_col("model", vec![model.to_string(); total]),
        f64_col("position_mm", position),
        f64_col("measured_width_mm", measured),
        f64_col("predicted_width_mm", predicted),
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
        str_col("printer", vec![printer.printer.clone(); grid.len()]),
        f64_col("r_a", grid.iter().map(|g| g.0).collect()),
        f64_col("r_f", grid.iter().map(|g| g.1).collect()),
        f64_col("training_rmse_mm", rmse_mm),
    ])
}

fn optional_col(name: &str, values: Vec<Option<f64>>) -> Column {
    Series::new(name.into(), values).into_column()
}
