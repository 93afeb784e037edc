//! `fdm.line_summary`: per measured line, the quantities paper 000 reads off its width
//! profiles (Sec. II-III, Figs 3-4): the steady width (phase p4), the start dip (the
//! minimum of phases p1-p2 and where it lies), the end bulge (phase p5) and the
//! largest width.

use datasets::fdm_widths::{FdmWidthsDataset, WidthLine};
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use crate::table::{f64_col, frame, read_fdm_widths, str_col};

/// The `fdm.line_summary` stage kind.
pub struct LineSummaryStage;

const LENGTH: ParamType = ParamType::Float { min: 0.0, max: 10_000.0 };

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "steady_from_mm",
        ty: LENGTH,
        default: ParamDefault::Float(50.0),
        doc: "Start of the steady window (mm); 50-80 mm is past the acceleration of every Table I condition.",
    },
    ParamSpec { name: "steady_to_mm", ty: LENGTH, default: ParamDefault::Float(80.0), doc: "End of the steady window (mm)." },
    ParamSpec {
        name: "start_window_mm",
        ty: LENGTH,
        default: ParamDefault::Float(40.0),
        doc: "The start dip is the minimum over [0, this] mm; 40 mm covers the longest acceleration of Table I (28 mm at 150 mm/s, 400 mm/s²).",
    },
    ParamSpec {
        name: "end_window_mm",
        ty: LENGTH,
        default: ParamDefault::Float(20.0),
        doc: "The end bulge is the maximum over the last this many mm of the line.",
    },
];

/// Windows of the summary, checked (`steady_from < steady_to`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SummaryWindows {
    /// Steady window start (mm).
    pub steady_from_mm: f64,
    /// Steady window end (mm).
    pub steady_to_mm: f64,
    /// Start dip window length (mm).
    pub start_window_mm: f64,
    /// End bulge window length (mm).
    pub end_window_mm: f64,
}

impl SummaryWindows {
    /// The defaults above.
    pub fn paper_defaults() -> Self {
        Self { steady_from_mm: 50.0, steady_to_mm: 80.0, start_window_mm: 40.0, end_window_mm: 20.0 }
    }
}

/// The summary of one line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineSummary {
    /// Mean width over the steady window (mm).
    pub steady_width_mm: f64,
    /// Smallest width in the start window (mm).
    pub start_min_width_mm: f64,
    /// Where it lies (mm).
    pub start_min_position_mm: f64,
    /// (steady − start minimum) / steady, in %.
    pub start_dip_pct: f64,
    /// (end maximum − steady) / steady, in %.
    pub end_bulge_pct: f64,
    /// Largest width anywhere (mm).
    pub max_width_mm: f64,
    /// Where it lies (mm).
    pub max_width_position_mm: f64,
}

/// Summarises one line; `None` when a window holds no measurement.
pub fn summarize_line(
    positions_mm: &[f64],
    widths_mm: &[f64],
    length_mm: f64,
    w: SummaryWindows,
) -> Option<LineSummary> {
    let points = || positions_mm.iter().copied().zip(widths_mm.iter().copied());
    let steady: Vec<f64> =
        points().filter(|(x, _)| (w.steady_from_mm..=w.steady_to_mm).contains(x)).map(|(_, y)| y).collect();
    if steady.is_empty() {
        return None;
    }
    let steady_width_mm = steady.iter().sum::<f64>() / steady.len() as f64;
    let (start_min_position_mm, start_min_width_mm) =
        extreme(points().filter(|(x, _)| *x <= w.start_window_mm), |a, b| a < b)?;
    let (_, end_max) = extreme(points().filter(|(x, _)| *x >= length_mm - w.end_window_mm), |a, b| a > b)?;
    let (max_width_position_mm, max_width_mm) = extreme(points(), |a, b| a > b)?;
    Some(LineSummary {
        steady_width_mm,
        start_min_width_mm,
        start_min_position_mm,
        start_dip_pct: 100.0 * (steady_width_mm - start_min_width_mm) / steady_width_mm,
        end_bulge_pct: 100.0 * (end_max - steady_width_mm) / steady_width_mm,
        max_width_mm,
        max_width_position_mm,
    })
}

/// The first point whose width beats all others by `better`.
fn extreme(points: impl Iterator<Item = (f64, f64)>, better: impl Fn(f64, f64) -> bool) -> Option<(f64, f64)> {
    points.fold(None, |best, p| match best {
        Some(b) if !better(p.1, b.1) => Some(b),
        _ => Some(p),
    })
}

impl StageKind for LineSummaryStage {
    fn name(&self) -> &'static str {
        "fdm.line_summary"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "Per line: steady width, start dip (minimum and position), end bulge, maximum width → line_summary.parquet"
    }
    fn implements(&self) -> &'static str {
        "paper 000 Sec. II, Figs 3-4 (phases p1-p5 of a printed line)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::at_least(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let windows = check_windows(ctx)?;
        let mut rows = SummaryRows::default();
        for input in &ctx.inputs {
            let dataset = read_fdm_widths(&input.dir)?;
            rows.push_dataset(&dataset, windows, &input.dir)?;
        }
        let mut table = rows.into_frame()?;
        ctx.write_table("line_summary", &mut table)?;
        Ok(())
    }
}

fn check_windows(ctx: &StageContext) -> Result<SummaryWindows, StageError> {
    let p = &ctx.params;
    let w = SummaryWindows {
        steady_from_mm: p.f64("steady_from_mm"),
        steady_to_mm: p.f64("steady_to_mm"),
        start_window_mm: p.f64("start_window_mm"),
        end_window_mm: p.f64("end_window_mm"),
    };
    if w.steady_from_mm >= w.steady_to_mm {
        return Err(StageError::Params {
            stage: ctx.stage.clone(),
            message: format!("expected steady_from_mm < steady_to_mm, got {} and {}", w.steady_from_mm, w.steady_to_mm),
        });
    }
    Ok(w)
}

#[derive(Default)]
struct SummaryRows {
    printer: Vec<String>,
    condition: Vec<String>,
    accel: Vec<f64>,
    feed: Vec<f64>,
    summaries: Vec<LineSummary>,
}

impl SummaryRows {
    fn push_dataset(
        &mut self,
        dataset: &FdmWidthsDataset,
        w: SummaryWindows,
        dir: &std::path::Path,
    ) -> Result<(), StageError> {
        for line in &dataset.lines {
            let summary = summarize(line, w).ok_or_else(|| StageError::BadInput {
                file: dir.join("widths").join(format!("{}.csv", line.line_id)),
                location: None,
                expected: "expected measurements inside the steady, start and end windows".into(),
            })?;
            self.printer.push(dataset.manifest.printer.clone());
            self.condition.push(line.condition.clone());
            self.accel.push(line.motion.accel_mm_s2);
            self.feed.push(line.motion.feed_mm_s);
            self.summaries.push(summary);
        }
        Ok(())
    }

    fn into_frame(self) -> Result<polars::prelude::DataFrame, StageError> {
        let col = |name: &str, f: fn(&LineSummary) -> f64| f64_col(name, self.summaries.iter().map(f).collect());
        frame(vec![
            str_col("printer", self.printer.clone()),
            str_col("condition", self.condition.clone()),
            f64_col("accel_mm_s2", self.accel.clone()),
            f64_col("feed_mm_s", self.feed.clone()),
            col("steady_width_mm", |s| s.steady_width_mm),
            col("start_min_width_mm", |s| s.start_min_width_mm),
            col("start_min_position_mm", |s| s.start_min_position_mm),
            col("start_dip_pct", |s| s.start_dip_pct),
            col("end_bulge_pct", |s| s.end_bulge_pct),
            col("max_width_mm", |s| s.max_width_mm),
            col("max_width_position_mm", |s| s.max_width_position_mm),
        ])
    }
}

fn summarize(line: &WidthLine, w: SummaryWindows) -> Option<LineSummary> {
    summarize_line(&line.positions_mm, &line.widths_mm, line.motion.length_mm, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic profile with known features: steady 0.8 mm, a dip to 0.5 at 10 mm,
    /// a bulge to 1.0 at 118 mm.
    fn profile() -> (Vec<f64>, Vec<f64>) {
        let xs: Vec<f64> = (0..=1200).map(|i| i as f64 * 0.1).collect();
        let ws = xs
            .iter()
            .map(|&x| match x {
                x if (x - 10.0).abs() < 1e-9 => 0.5,
                x if (x - 118.0).abs() < 1e-9 => 1.0,
                _ => 0.8,
            })
            .collect();
        (xs, ws)
    }

    #[test]
    fn recovers_known_features() {
        let (xs, ws) = profile();
        let s = summarize_line(&xs, &ws, 120.0, SummaryWindows::paper_defaults()).unwrap();
        assert!((s.steady_width_mm - 0.8).abs() < 1e-12);
        assert_eq!((s.start_min_position_mm, s.start_min_width_mm), (10.0, 0.5));
        assert!((s.start_dip_pct - 37.5).abs() < 1e-9, "(0.8 − 0.5)/0.8 = 37.5 %");
        assert!((s.end_bulge_pct - 25.0).abs() < 1e-9, "(1.0 − 0.8)/0.8 = 25 %");
        assert_eq!((s.max_width_position_mm, s.max_width_mm), (118.0, 1.0));
    }

    #[test]
    fn empty_window_is_none() {
        let (xs, ws) = profile();
        let w = SummaryWindows { steady_from_mm: 200.0, steady_to_mm: 300.0, ..SummaryWindows::paper_defaults() };
        assert!(summarize_line(&xs, &ws, 120.0, w).is_none());
    }
}
