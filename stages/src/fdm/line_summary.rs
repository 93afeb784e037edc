//! `fdm.line_summary`: per measured line, the quantities paper 000 reads off its width
//! profiles (Sec. II-III, Figs 3-4): the steady width (phase p4), the start dip (the
//! minimum of phases p1-p2 and where it lies), the end bulge (phase p5) and the
//! largest width.

use datasets::fdm_widths::{FdmWidthsDataset, WidthLine};
use pipeline::params::{ParamError, StageParams};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::line_summary;

use crate::roles;
use crate::table::{f64_col, frame, read_fdm_widths, str_col};

/// The `fdm.line_summary` stage kind.
pub struct LineSummaryStage;

pipeline::params! {
    /// Windows of the summary: the parameters of `fdm.line_summary`.
    #[derive(Copy)]
    pub struct SummaryWindows {
        /// Start of the steady window (mm); 50-80 mm is past the acceleration of every Table I condition.
        pub steady_from_mm: f64 [0.0, 10_000.0] = 50.0,
        /// End of the steady window (mm).
        pub steady_to_mm: f64 [0.0, 10_000.0] = 80.0,
        /// The start dip is the minimum over [0, this] mm; 40 mm covers the longest acceleration of Table I (28 mm at 150 mm/s, 400 mm/s²).
        pub start_window_mm: f64 [0.0, 10_000.0] = 40.0,
        /// The end bulge is the maximum over the last this many mm of the line.
        pub end_window_mm: f64 [0.0, 10_000.0] = 20.0,
    }
}

impl SummaryWindows {
    /// The declared defaults.
    pub fn paper_defaults() -> Self {
        Self::defaults().expect("every window has a default")
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

impl Stage for LineSummaryStage {
    type Params = SummaryWindows;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.line_summary",
        version: 1,
        summary:
            "Per line: steady width, start dip (minimum and position), end bulge, maximum width → line_summary.parquet",
        implements: "paper 000 Sec. II, Figs 3-4 (phases p1-p5 of a printed line)",
        inputs: &[roles::FDM_WIDTHS_MANY],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&line_summary::TABLE];

    fn check(w: &SummaryWindows) -> Result<(), ParamError> {
        if w.steady_from_mm >= w.steady_to_mm {
            return Err(ParamError::new(
                "steady_to_mm",
                format!("expected steady_from_mm < steady_to_mm, got {} and {}", w.steady_from_mm, w.steady_to_mm),
            ));
        }
        Ok(())
    }

    fn run(&self, ctx: &mut StageContext, windows: &SummaryWindows) -> Result<(), StageError> {
        let mut rows = SummaryRows::default();
        for input in ctx.inputs_of(&roles::FDM_WIDTHS_MANY) {
            let dataset = read_fdm_widths(&input.dir)?;
            rows.push_dataset(&dataset, *windows, &input.dir)?;
        }
        let mut table = rows.into_frame()?;
        ctx.write_table(line_summary::TABLE.name, &mut table)?;
        Ok(())
    }
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
            str_col(line_summary::printer, self.printer.clone()),
            str_col(line_summary::condition, self.condition.clone()),
            f64_col(line_summary::accel_mm_s2, self.accel.clone()),
            f64_col(line_summary::feed_mm_s, self.feed.clone()),
            col(line_summary::steady_width_mm, |s| s.steady_width_mm),
            col(line_summary::start_min_width_mm, |s| s.start_min_width_mm),
            col(line_summary::start_min_position_mm, |s| s.start_min_position_mm),
            col(line_summary::start_dip_pct, |s| s.start_dip_pct),
            col(line_summary::end_bulge_pct, |s| s.end_bulge_pct),
            col(line_summary::max_width_mm, |s| s.max_width_mm),
            col(line_summary::max_width_position_mm, |s| s.max_width_position_mm),
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
