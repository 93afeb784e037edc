//! `figure.fdm_loo_predictions`: predicted against measured width along the held-out
//! lines of a leave-one-out, in the style of paper 000 Fig. 6 (Case A, §III-A): the
//! line with the lowest RMSE on the left, the one with the highest on the right, and
//! the physics (lag) baseline dashed on the same lines when its predictions are in the
//! table. Reads `loo.parquet` and `loo_predictions.parquet` of one input folder.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{loo, loo_predictions};

use crate::read::{f64s, no_rows, read_parquet, strs};
use crate::style::{draw_house_legend, draw_png_and_svg, text, PALETTE};

use super::draw_width_profile_mesh;

/// The `figure.fdm_loo_predictions` stage kind.
pub struct LooPredictionsFigure;

pipeline::params! {
    /// The parameters of `figure.fdm_loo_predictions`.
    pub struct LooPredictionsParams {
        /// Printer whose held-out lines are drawn.
        pub printer: String,
        /// Model whose predictions are drawn (default: the paper's piecewise model).
        pub model: String = "piecewise",
    }
}

/// The leave-one-out drawn: one model's or a `table.concat` of both models'.
const LOO: Input = Input::one(
    "loo",
    &[Source::Stage("fdm.piecewise_loo"), Source::Stage("fdm.lag_model")],
    "the held-out RMSEs and predictions (`loo.parquet`, `loo_predictions.parquet`)",
)
.reading(&[
    Reads {
        table: &loo::TABLE,
        columns: &[loo::printer, loo::condition, loo::model, loo::accel_mm_s2, loo::feed_mm_s, loo::rmse_mm],
    },
    SAMPLE_READS,
]);

/// What [`read_samples`] reads of `loo_predictions.parquet`.
pub(crate) const SAMPLE_READS: Reads = Reads {
    table: &loo_predictions::TABLE,
    columns: &[
        loo_predictions::printer,
        loo_predictions::condition,
        loo_predictions::model,
        loo_predictions::position_mm,
        loo_predictions::measured_width_mm,
        loo_predictions::predicted_width_mm,
    ],
};

/// The lag baseline's name in the `model` column.
const LAG_MODEL: &str = "lag";
/// Figure size in pixels (two panels side by side).
const SIZE_PX: (u32, u32) = (1400, 700);
/// Colour of the measured widths.
const MEASURED: RGBColor = RGBColor(70, 70, 70);

/// One row of `loo.parquet`: a held-out line's kinematics and RMSE under one model.
#[derive(Debug, Clone)]
pub struct FoldSummary {
    /// Condition name (`S800F9000`).
    pub condition: String,
    /// Model name.
    pub model: String,
    /// Commanded acceleration.
    pub accel_mm_s2: f64,
    /// Commanded feed.
    pub feed_mm_s: f64,
    /// RMSE of the prediction of the held-out line.
    pub rmse_mm: f64,
}

/// One held-out line as drawn: measured and predicted widths against position.
#[derive(Debug)]
pub struct HeldOutLine {
    /// The line's row of `loo.parquet` for the drawn model.
    pub fold: FoldSummary,
    /// (position, measured width) in mm, by position.
    pub measured_mm: Vec<(f64, f64)>,
    /// (position, predicted width) in mm, by position.
    pub predicted_mm: Vec<(f64, f64)>,
    /// The lag baseline's prediction of the same line, empty when absent.
    pub lag_mm: Vec<(f64, f64)>,
    /// The lag baseline's RMSE on the line, when in `loo.parquet`.
    pub lag_rmse_mm: Option<f64>,
}

/// Everything the figure draws.
#[derive(Debug)]
pub struct LooFigureData {
    /// Printer name.
    pub printer: String,
    /// Model drawn.
    pub model: String,
    /// The held-out line with the lowest RMSE.
    pub best: HeldOutLine,
    /// The held-out line with the highest RMSE.
    pub worst: HeldOutLine,
}

/// Samples of one (condition, model): (position, measured, predicted) in mm.
pub(crate) type Samples = BTreeMap<(String, String), Vec<[f64; 3]>>;

impl Stage for LooPredictionsFigure {
    type Params = LooPredictionsParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_loo_predictions",
        version: 1,
        summary: "Measured vs predicted width of the held-out lines with the lowest and highest leave-one-out RMSE → loo_predictions.png/.svg",
        implements: "paper 000 Fig. 6",
        inputs: &[LOO],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &LooPredictionsParams) -> Result<(), StageError> {
        let data = load(&ctx.input(&LOO).dir, &p.printer, &p.model)?;
        let stem = ctx.output_path("loo_predictions")?;
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, &data), |a| draw(a, &data))
    }
}

/// Reads the lines with the lowest and highest RMSE of `printer` under `model`.
pub fn load(dir: &Path, printer: &str, model: &str) -> Result<LooFigureData, StageError> {
    let summary_path = dir.join(loo::TABLE.file());
    let folds = read_folds(&summary_path, printer)?;
    let (best, worst) = extremes(&folds, model).ok_or_else(|| {
        no_rows(&summary_path, loo::model, &format!("printer `{printer}`, model `{model}`, finite RMSE"))
    })?;
    let samples_path = dir.join(loo_predictions::TABLE.file());
    let samples = read_samples(&samples_path, printer)?;
    let line = |fold: &FoldSummary| held_out_line(fold, &folds, &samples, &samples_path);
    Ok(LooFigureData { printer: printer.into(), model: model.into(), best: line(best)?, worst: line(worst)? })
}

/// The folds of `model` with the lowest and highest finite RMSE (first on ties).
pub fn extremes<'a>(folds: &'a [FoldSummary], model: &str) -> Option<(&'a FoldSummary, &'a FoldSummary)> {
    let mut of_model = folds.iter().filter(|f| f.model == model && f.rmse_mm.is_finite());
    let first = of_model.next()?;
    Some(of_model.fold((first, first), |(lo, hi), f| {
        (if f.rmse_mm < lo.rmse_mm { f } else { lo }, if f.rmse_mm > hi.rmse_mm { f } else { hi })
    }))
}

/// The vertices of a step line through `points` (sorted by x): each value holds until
/// the next sample, so the plot shows the measurement's sampling honestly.
pub fn step_points(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(2 * points.len());
    for (i, &(x, y)) in points.iter().enumerate() {
        out.push((x, y));
        if let Some(&(x_next, _)) = points.get(i + 1) {
            out.push((x_next, y));
        }
    }
    out
}

fn read_folds(path: &Path, printer: &str) -> Result<Vec<FoldSummary>, StageError> {
    let df = read_parquet(path)?;
    let (printers, conditions, models) =
        (strs(&df, loo::printer, path)?, strs(&df, loo::condition, path)?, strs(&df, loo::model, path)?);
    let (accel, feed, rmse) =
        (f64s(&df, loo::accel_mm_s2, path)?, f64s(&df, loo::feed_mm_s, path)?, f64s(&df, loo::rmse_mm, path)?);
    Ok((0..df.height())
        .filter(|&i| printers[i] == printer)
        .map(|i| FoldSummary {
            condition: conditions[i].clone(),
            model: models[i].clone(),
            accel_mm_s2: accel[i],
            feed_mm_s: feed[i],
            rmse_mm: rmse[i],
        })
        .collect())
}

/// Every held-out line of `printer` in `loo_predictions.parquet` ([`SAMPLE_READS`]), by
/// (condition, model), its samples in position order.
pub(crate) fn read_samples(path: &Path, printer: &str) -> Result<Samples, StageError> {
    let df = read_parquet(path)?;
    use loo_predictions as p;
    let (printers, conditions, models) =
        (strs(&df, p::printer, path)?, strs(&df, p::condition, path)?, strs(&df, p::model, path)?);
    let position = f64s(&df, p::position_mm, path)?;
    let (measured, predicted) = (f64s(&df, p::measured_width_mm, path)?, f64s(&df, p::predicted_width_mm, path)?);
    let mut samples = Samples::new();
    for i in (0..df.height()).filter(|&i| printers[i] == printer) {
        let key = (conditions[i].clone(), models[i].clone());
        samples.entry(key).or_default().push([position[i], measured[i], predicted[i]]);
    }
    for line in samples.values_mut() {
        line.sort_by(|a, b| a[0].total_cmp(&b[0]));
    }
    Ok(samples)
}

fn held_out_line(
    fold: &FoldSummary,
    folds: &[FoldSummary],
    samples: &Samples,
    path: &Path,
) -> Result<HeldOutLine, StageError> {
    let key = |model: &str| (fold.condition.clone(), model.to_string());
    let Some(line) = samples.get(&key(&fold.model)) else {
        let wanted = format!("condition `{}`, model `{}`", fold.condition, fold.model);
        return Err(no_rows(path, loo_predictions::condition, &wanted));
    };
    let lag = if fold.model == LAG_MODEL { None } else { samples.get(&key(LAG_MODEL)) };
    let lag_rmse_mm = lag.and_then(|_| folds.iter().find(|f| f.model == LAG_MODEL && f.condition == fold.condition));
    Ok(HeldOutLine {
        fold: fold.clone(),
        measured_mm: line.iter().map(|s| (s[0], s[1])).collect(),
        predicted_mm: line.iter().map(|s| (s[0], s[2])).collect(),
        lag_mm: lag.map(|l| l.iter().map(|s| (s[0], s[2])).collect()).unwrap_or_default(),
        lag_rmse_mm: lag_rmse_mm.map(|f| f.rmse_mm),
    })
}

/// Draws both panels with a shared width axis.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, data: &LooFigureData) -> Result<(), String> {
    let title = format!(
        "Leave-one-out: held-out lines of {} predicted by the {} model (paper 000 Fig. 6)",
        data.printer, data.model
    );
    let area = area.margin(12, 6, 6, 14).titled(&title, text(26.0)).map_err(|e| e.to_string())?;
    let panels = area.split_evenly((1, 2));
    let width_max_mm = [&data.best, &data.worst].iter().map(|l| max_width_mm(l)).fold(0.0, f64::max) * 1.08;
    draw_panel(&panels[0], "(a) lowest", &data.best, &data.model, width_max_mm).map_err(|e| e.to_string())?;
    draw_panel(&panels[1], "(b) highest", &data.worst, &data.model, width_max_mm).map_err(|e| e.to_string())
}

fn max_width_mm(line: &HeldOutLine) -> f64 {
    let all = line.measured_mm.iter().chain(&line.predicted_mm).chain(&line.lag_mm);
    all.map(|p| p.1).filter(|w| w.is_finite()).fold(0.0, f64::max)
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    which: &str,
    line: &HeldOutLine,
    model: &str,
    width_max_mm: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let f = &line.fold;
    let caption = format!(
        "{which} RMSE {:.3} mm: {}, a = {} mm/s², F = {} mm/s",
        f.rmse_mm, f.condition, f.accel_mm_s2, f.feed_mm_s
    );
    let x_min = line.measured_mm.first().map_or(0.0, |p| p.0.min(0.0));
    let x_max = line.measured_mm.last().map_or(1.0, |p| p.0);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(18.0))
        .margin(10)
        .margin_right(22)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(x_min..x_max, 0.0..width_max_mm)?;
    draw_width_profile_mesh(&mut chart)?;
    draw_lines(&mut chart, line, model)?;
    draw_house_legend(&mut chart, SeriesLabelPosition::LowerRight)
}

fn draw_lines<DB: DrawingBackend>(
    chart: &mut ChartContext<
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    line: &HeldOutLine,
    model: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let measured = MEASURED.stroke_width(1);
    chart
        .draw_series(LineSeries::new(step_points(&line.measured_mm), measured))?
        .label("measured")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], measured));
    let predicted = PALETTE[0].stroke_width(2);
    chart
        .draw_series(LineSeries::new(line.predicted_mm.iter().copied(), predicted))?
        .label(format!("predicted, {model}"))
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], predicted));
    if line.lag_mm.is_empty() {
        return Ok(());
    }
    let lag = PALETTE[1].stroke_width(2);
    let label = match line.lag_rmse_mm {
        Some(rmse) => format!("predicted, lag baseline (RMSE {rmse:.3} mm)"),
        None => "predicted, lag baseline".to_string(),
    };
    chart
        .draw_series(DashedLineSeries::new(line.lag_mm.iter().copied(), 8, 5, lag))?
        .label(label)
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], lag));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, noise, synthetic_width_mm, write_declared};
    use polars::df;

    const CONDITIONS: [(&str, f64, f64); 3] =
        [("S500F3000", 500.0, 50.0), ("S800F6000", 800.0, 100.0), ("S1000F9000", 1000.0, 150.0)];
    const LENGTH_MM: f64 = 60.0;

    fn fold(condition: &str, model: &str, rmse_mm: f64) -> FoldSummary {
        FoldSummary { condition: condition.into(), model: model.into(), accel_mm_s2: 500.0, feed_mm_s: 50.0, rmse_mm }
    }

    #[test]
    fn extremes_pick_lowest_and_highest_rmse_of_the_model_only() {
        let folds = [
            fold("a", "piecewise", 0.05),
            fold("b", "piecewise", 0.03),
            fold("c", "lag", 0.01),
            fold("d", "piecewise", f64::NAN),
            fold("e", "piecewise", 0.07),
        ];
        let (best, worst) = extremes(&folds, "piecewise").expect("rows of the model");
        assert_eq!((best.condition.as_str(), worst.condition.as_str()), ("b", "e"));
        assert!(extremes(&folds, "other").is_none());
    }

    #[test]
    fn step_points_hold_each_value_until_the_next_sample() {
        let steps = step_points(&[(0.0, 1.0), (1.0, 2.0), (3.0, 0.5)]);
        assert_eq!(steps, vec![(0.0, 1.0), (1.0, 1.0), (1.0, 2.0), (3.0, 2.0), (3.0, 0.5)]);
        assert!(step_points(&[]).is_empty());
    }

    /// loo.parquet and loo_predictions.parquet for printer taz5: three lines, both
    /// models; the piecewise model errs more on faster lines, the lag model everywhere.
    fn write_inputs(dir: &Path) {
        let (mut cond, mut model, mut rmse) = (vec![], vec![], vec![]);
        let (mut p_cond, mut p_model, mut pos, mut meas, mut pred) = (vec![], vec![], vec![], vec![], vec![]);
        for (k, &(name, _, feed)) in CONDITIONS.iter().enumerate() {
            for (m, bias_mm) in [("piecewise", 0.01 * (k as f64 + 1.0)), ("lag", 0.06)] {
                let mut sq_sum = 0.0;
                for i in 0..=240 {
                    let x = i as f64 * LENGTH_MM / 240.0;
                    let truth = synthetic_width_mm(x, LENGTH_MM, feed);
                    let measured = truth + 0.03 * noise(i + 1000 * k);
                    let predicted = truth + bias_mm * (x / 7.0).sin();
                    sq_sum += (measured - predicted).powi(2);
                    p_cond.push(name);
                    p_model.push(m);
                    pos.push(x);
                    meas.push(measured);
                    pred.push(predicted);
                }
                cond.push(name);
                model.push(m);
                rmse.push((sq_sum / 241.0).sqrt());
            }
        }
        let n = cond.len();
        let accel: Vec<f64> = CONDITIONS.iter().flat_map(|c| [c.1, c.1]).collect();
        let feed: Vec<f64> = CONDITIONS.iter().flat_map(|c| [c.2, c.2]).collect();
        let tau_s: Vec<f64> = model.iter().map(|m| if *m == LAG_MODEL { 0.05 } else { f64::NAN }).collect();
        let folds = df!(loo::printer => vec!["taz5"; n], loo::condition => cond, loo::accel_mm_s2 => accel,
            loo::feed_mm_s => feed, loo::model => model, loo::rmse_mm => rmse,
            loo::r_a => vec![1.0; n], loo::r_f => vec![1.0; n], loo::tau_s => tau_s)
        .expect("frame");
        write_declared(dir, &loo::TABLE, folds);
        let m = p_cond.len();
        use loo_predictions as p;
        let predictions = df!(p::printer => vec!["taz5"; m], p::condition => p_cond, p::model => p_model,
            p::position_mm => pos, p::measured_width_mm => meas, p::predicted_width_mm => pred)
        .expect("frame");
        write_declared(dir, &p::TABLE, predictions);
    }

    #[test]
    fn draws_lowest_and_highest_rmse_lines_with_lag_baseline() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_inputs(dir.path());
        let data = load(dir.path(), "taz5", "piecewise").expect("loads");
        assert_eq!(data.best.fold.condition, "S500F3000");
        assert_eq!(data.worst.fold.condition, "S1000F9000");
        assert_eq!(data.best.measured_mm.len(), 241);
        assert_eq!(data.best.lag_mm.len(), 241);
        assert!(data.worst.lag_rmse_mm.is_some());
        let stem = dir.path().join("loo_predictions");
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, &data), |a| draw(a, &data)).expect("draws");
        assert_drawn(&stem);
    }

    #[test]
    fn unknown_printer_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_inputs(dir.path());
        let err = load(dir.path(), "taz9", "piecewise").expect_err("no rows for taz9");
        assert!(err.to_string().contains(&loo::TABLE.file()), "{err}");
    }
}
