//! `figure.fdm_transfer_cv`: the cross-validation of transfer learning to the
//! data-limited printer, in the style of paper 000 Fig. 9 (Case B, §III-B): (a) box
//! plots of the held-out RMSE against the number of target-printer training lines for
//! single-printer learning and the transfer methods, (b) the median RMSE improvement of
//! each transfer method over single-printer learning. Reads `transfer_cv.parquet`.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::transfer_cv;

use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_house_legend, draw_png_and_svg, house_mesh, text, PALETTE};

/// The `figure.fdm_transfer_cv` stage kind.
pub struct TransferCvFigure;

pipeline::params! {
    /// The parameters of `figure.fdm_transfer_cv`.
    pub struct TransferCvParams {
        /// Figure title (default: says what is compared and cites paper 000 Fig. 9).
        pub title: String = "",
    }
}

/// The cross-validation drawn.
const TRANSFER_CV: Input = Input::one(
    "transfer_cv",
    &[Source::Stage("fdm.transfer_cv")],
    "the held-out RMSE per training-set size and method (`transfer_cv.parquet`)",
)
.reading(&[Reads {
    table: &transfer_cv::TABLE,
    columns: &[transfer_cv::n_train, transfer_cv::method, transfer_cv::rmse_mm],
}]);

/// The baseline every transfer method is compared with.
const SINGLE: &str = "single";
/// Known methods in drawing order, with their legend labels and colours.
const METHODS: [(&str, &str, RGBColor); 3] = [
    (SINGLE, "single printer", PALETTE[6]),
    ("transfer_zero_mean", "transfer, zero-mean prior", PALETTE[0]),
    ("transfer_source_mean", "transfer, source-mean prior", PALETTE[1]),
];
/// Figure size in pixels (two panels side by side).
const SIZE_PX: (u32, u32) = (1400, 700);
/// Tukey's fence: whiskers reach the furthest point within this many IQRs of the box.
const WHISKER_IQR: f64 = 1.5;
/// Horizontal room of one n_train slot taken by the boxes of all methods.
const SLOT_WIDTH: f64 = 0.8;

/// The held-out RMSEs of every (n_train, method).
#[derive(Debug)]
pub struct TransferCv {
    /// Training-set sizes present, ascending.
    pub n_train: Vec<i64>,
    /// Methods present, known ones first in `METHODS` order.
    pub methods: Vec<String>,
    /// Held-out RMSEs in mm by (n_train, method).
    pub rmse_mm: BTreeMap<(i64, String), Vec<f64>>,
}

/// The five numbers a box plot draws, plus the points beyond the whiskers.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxStats {
    /// First quartile.
    pub q1: f64,
    /// Median.
    pub median: f64,
    /// Third quartile.
    pub q3: f64,
    /// Lowest value within 1.5 IQR below `q1`.
    pub whisker_lo: f64,
    /// Highest value within 1.5 IQR above `q3`.
    pub whisker_hi: f64,
    /// Values beyond the whiskers.
    pub outliers: Vec<f64>,
}

impl Stage for TransferCvFigure {
    type Params = TransferCvParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_transfer_cv",
        version: 1,
        summary: "Box plots of held-out RMSE vs target training lines per method, and median improvement over single-printer learning → transfer_cv.png/.svg",
        implements: "paper 000 Fig. 9",
        inputs: &[TRANSFER_CV],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &TransferCvParams) -> Result<(), StageError> {
        let cv = load(&ctx.input(&TRANSFER_CV).dir)?;
        let title = crate::figures::common::title_or(&p.title, || {
            "Transfer learning to the target printer: held-out RMSE vs training lines (paper 000 Fig. 9)".to_string()
        });
        let stem = ctx.output_path("transfer_cv")?;
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, &title, &cv), |a| draw(a, &title, &cv))
    }
}

/// Reads `<dir>/transfer_cv.parquet`, dropping non-finite RMSEs.
pub fn load(dir: &Path) -> Result<TransferCv, StageError> {
    let path = dir.join(transfer_cv::TABLE.file());
    let df = read_parquet(&path)?;
    let (n_train, methods) = (ints(&df, transfer_cv::n_train, &path)?, strs(&df, transfer_cv::method, &path)?);
    let rmse = f64s(&df, transfer_cv::rmse_mm, &path)?;
    let mut rmse_mm: BTreeMap<(i64, String), Vec<f64>> = BTreeMap::new();
    for i in (0..df.height()).filter(|&i| rmse[i].is_finite()) {
        rmse_mm.entry((n_train[i], methods[i].clone())).or_default().push(rmse[i]);
    }
    if rmse_mm.is_empty() {
        return Err(no_rows(&path, transfer_cv::rmse_mm, "a finite RMSE"));
    }
    let mut n: Vec<i64> = rmse_mm.keys().map(|k| k.0).collect();
    n.dedup();
    let mut methods: Vec<String> = rmse_mm.keys().map(|k| k.1.clone()).collect();
    methods.sort_by_key(|m| (METHODS.iter().position(|k| k.0 == m).unwrap_or(METHODS.len()), m.clone()));
    methods.dedup();
    Ok(TransferCv { n_train: n, methods, rmse_mm })
}

/// The `p`-quantile of ascending `sorted` by linear interpolation between order
/// statistics (Hyndman & Fan type 7, the default of R and NumPy): position
/// h = (n − 1)·p, value x⌊h⌋ + (h − ⌊h⌋)(x⌊h⌋+1 − x⌊h⌋). NaN for an empty slice.
pub fn quantile_type7(sorted: &[f64], p: f64) -> f64 {
    let Some(last) = sorted.len().checked_sub(1) else {
        return f64::NAN;
    };
    let h = last as f64 * p.clamp(0.0, 1.0);
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(last);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

impl BoxStats {
    /// Quartiles by [`quantile_type7`], whiskers to the furthest values within 1.5 IQR
    /// of the box (Tukey); `None` without finite values.
    pub fn of(values: &[f64]) -> Option<Self> {
        let mut sorted: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        if sorted.is_empty() {
            return None;
        }
        sorted.sort_by(f64::total_cmp);
        let (q1, median, q3) =
            (quantile_type7(&sorted, 0.25), quantile_type7(&sorted, 0.5), quantile_type7(&sorted, 0.75));
        let (fence_lo, fence_hi) = (q1 - WHISKER_IQR * (q3 - q1), q3 + WHISKER_IQR * (q3 - q1));
        let inside = || sorted.iter().copied().filter(|v| (fence_lo..=fence_hi).contains(v));
        Some(Self {
            q1,
            median,
            q3,
            whisker_lo: inside().fold(f64::INFINITY, f64::min),
            whisker_hi: inside().fold(f64::NEG_INFINITY, f64::max),
            outliers: sorted.iter().copied().filter(|v| !(fence_lo..=fence_hi).contains(v)).collect(),
        })
    }
}

/// Improvement of a method over the baseline in percent of the baseline:
/// 100·(median_single − median_method)/median_single (positive = lower RMSE).
pub fn improvement_pct(median_single_mm: f64, median_method_mm: f64) -> f64 {
    100.0 * (median_single_mm - median_method_mm) / median_single_mm
}

impl TransferCv {
    fn stats(&self, n: i64, method: &str) -> Option<BoxStats> {
        self.rmse_mm.get(&(n, method.to_string())).and_then(|v| BoxStats::of(v))
    }

    /// (n_train, median improvement %) of `method` over single-printer learning.
    fn improvements(&self, method: &str) -> Vec<(f64, f64)> {
        let median = |n, m| self.stats(n, m).map(|s| s.median);
        let pct = |n| Some(improvement_pct(median(n, SINGLE)?, median(n, method)?));
        self.n_train.iter().filter_map(|&n| pct(n).map(|p| (n as f64, p))).collect()
    }

    fn x_range(&self) -> std::ops::Range<f64> {
        let (first, last) = (self.n_train[0] as f64, self.n_train[self.n_train.len() - 1] as f64);
        (first - 0.6)..(last + 0.6)
    }
}

fn method_label(method: &str) -> (String, RGBColor, usize) {
    match METHODS.iter().position(|k| k.0 == method) {
        Some(i) => (METHODS[i].1.to_string(), METHODS[i].2, i),
        None => (method.to_string(), PALETTE[4], METHODS.len()),
    }
}

/// Draws (a) the box plots and (b) the median improvement side by side.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, cv: &TransferCv) -> Result<(), String> {
    let area = area.margin(12, 6, 6, 14).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    let panels = area.split_evenly((1, 2));
    draw_boxes(&panels[0], cv).map_err(|e| e.to_string())?;
    draw_improvement(&panels[1], cv).map_err(|e| e.to_string())
}

/// The RMSE axis top: the highest whisker, or outliers up to twice that; outliers
/// beyond are drawn as triangles on the top edge so one bad fold cannot flatten the boxes.
fn rmse_axis_top_mm(all: &[BoxStats]) -> f64 {
    let whiskers = all.iter().map(|s| s.whisker_hi).fold(0.0, f64::max);
    let outliers = all.iter().flat_map(|s| s.outliers.iter().copied()).fold(0.0, f64::max);
    whiskers.max(outliers.min(2.0 * whiskers)) * 1.08
}

fn draw_boxes<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    cv: &TransferCv,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let boxes = positioned_boxes(cv);
    let all: Vec<BoxStats> = boxes.iter().map(|b| b.2.clone()).collect();
    let top_mm = rmse_axis_top_mm(&all);
    let clipped = all.iter().flat_map(|s| &s.outliers).filter(|o| **o > top_mm).count();
    let caption = match clipped {
        0 => "(a) held-out RMSE per number of training lines".to_string(),
        k => format!("(a) held-out RMSE per number of training lines (▲ {k} beyond axis)"),
    };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(18.0))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(cv.x_range(), 0.0..top_mm)?;
    draw_n_mesh(&mut chart, cv, "held-out RMSE (mm)", &|y| format!("{y:.3}"))?;
    let half_width = SLOT_WIDTH / cv.methods.len() as f64 * 0.4;
    for method in &cv.methods {
        let (label, colour, _) = method_label(method);
        let mine = boxes.iter().filter(|b| b.1 == method);
        let rects = mine.clone().map(|(x, _, s)| {
            Rectangle::new([(x - half_width, s.q1), (x + half_width, s.q3)], colour.mix(0.35).filled())
        });
        chart
            .draw_series(rects)?
            .label(label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 18, y + 6)], colour.mix(0.6).filled()));
        for (x, _, s) in mine {
            draw_box_lines(&mut chart, *x, half_width, s, colour, top_mm)?;
        }
    }
    draw_house_legend(&mut chart, SeriesLabelPosition::UpperRight)
}

/// Every (box centre x, method, stats) to draw, methods in legend order.
fn positioned_boxes(cv: &TransferCv) -> Vec<(f64, &str, BoxStats)> {
    let mut boxes = Vec::new();
    for (j, method) in cv.methods.iter().enumerate() {
        for &n in &cv.n_train {
            if let Some(stats) = cv.stats(n, method) {
                boxes.push((box_x(cv, n, j), method.as_str(), stats));
            }
        }
    }
    boxes
}

/// The centre of method `j`'s box in the slot of `n`.
fn box_x(cv: &TransferCv, n: i64, j: usize) -> f64 {
    let m = cv.methods.len() as f64;
    n as f64 + (j as f64 + 0.5 - m / 2.0) * SLOT_WIDTH / m
}

type BoxChart<'a, DB> =
    ChartContext<'a, DB, Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>>;

/// Labels whole numbers only: n_train is a count, ticks between counts stay unlabelled.
/// The mesh both panels share: n on x (whole numbers only), `y_desc` and `y_format`
/// on y, faint major grid lines across.
fn draw_n_mesh<DB: DrawingBackend>(
    chart: &mut ChartContext<DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    cv: &TransferCv,
    y_desc: &str,
    y_format: &dyn Fn(&f64) -> String,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    house_mesh(chart)
        .disable_x_mesh()
        .x_desc("target-printer lines in training (n)")
        .y_desc(y_desc)
        .x_labels(cv.n_train.len() + 2)
        .x_label_formatter(&integer_label)
        .y_label_formatter(y_format)
        .bold_line_style(BLACK.mix(0.08))
        .draw()
}

fn integer_label(x: &f64) -> String {
    if (x - x.round()).abs() < 1e-9 {
        format!("{x:.0}")
    } else {
        String::new()
    }
}

fn draw_box_lines<DB: DrawingBackend>(
    chart: &mut BoxChart<'_, DB>,
    x: f64,
    half_width: f64,
    s: &BoxStats,
    colour: RGBColor,
    top_mm: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let line = colour.stroke_width(2);
    let cap = half_width * 0.5;
    let segments = [
        vec![
            (x - half_width, s.q1),
            (x + half_width, s.q1),
            (x + half_width, s.q3),
            (x - half_width, s.q3),
            (x - half_width, s.q1),
        ],
        vec![(x, s.q3), (x, s.whisker_hi)],
        vec![(x, s.q1), (x, s.whisker_lo)],
        vec![(x - cap, s.whisker_hi), (x + cap, s.whisker_hi)],
        vec![(x - cap, s.whisker_lo), (x + cap, s.whisker_lo)],
    ];
    chart.draw_series(segments.into_iter().map(|points| PathElement::new(points, line)))?;
    chart.draw_series([PathElement::new(
        [(x - half_width, s.median), (x + half_width, s.median)],
        BLACK.stroke_width(3),
    )])?;
    let (shown, beyond): (Vec<f64>, Vec<f64>) = s.outliers.iter().partition(|o| **o <= top_mm);
    chart.draw_series(shown.into_iter().map(|o| Circle::new((x, o), 3, colour.stroke_width(1))))?;
    chart.draw_series(
        beyond.into_iter().take(1).map(|_| TriangleMarker::new((x, top_mm * 0.985), 6, colour.filled())),
    )?;
    Ok(())
}

fn draw_improvement<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    cv: &TransferCv,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let series: Vec<(&str, Vec<(f64, f64)>)> =
        cv.methods.iter().filter(|m| *m != SINGLE).map(|m| (m.as_str(), cv.improvements(m))).collect();
    let values = series.iter().flat_map(|s| s.1.iter().map(|p| p.1));
    let (lo, hi) = values.fold((0.0_f64, 0.0_f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = ((hi - lo) * 0.12).max(5.0);
    let mut chart = ChartBuilder::on(area)
        .caption("(b) median RMSE improvement over single-printer learning", text(18.0))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(cv.x_range(), (lo - pad)..(hi + pad))?;
    draw_n_mesh(&mut chart, cv, "median RMSE improvement (%)", &|y| format!("{y:.0}"))?;
    let (x_range, zero) = (cv.x_range(), BLACK.stroke_width(1));
    chart.draw_series(DashedLineSeries::new([(x_range.start, 0.0), (x_range.end, 0.0)], 6, 4, zero))?;
    for (method, points) in series {
        let (label, colour, _) = method_label(method);
        let style = colour.stroke_width(2);
        chart
            .draw_series(LineSeries::new(points.iter().copied(), style))?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], style));
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled())))?;
    }
    draw_house_legend(&mut chart, SeriesLabelPosition::UpperRight)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, noise, write_declared};
    use polars::df;

    #[test]
    fn quartiles_by_linear_interpolation_match_r_type_7() {
        // R: quantile(c(1, 2, 3, 4)) gives 1.75, 2.5, 3.25 at 0.25, 0.5, 0.75.
        let sorted = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(quantile_type7(&sorted, 0.25), 1.75);
        assert_eq!(quantile_type7(&sorted, 0.5), 2.5);
        assert_eq!(quantile_type7(&sorted, 0.75), 3.25);
        assert_eq!((quantile_type7(&sorted, 0.0), quantile_type7(&sorted, 1.0)), (1.0, 4.0));
        assert_eq!(quantile_type7(&[7.0], 0.3), 7.0);
        assert!(quantile_type7(&[], 0.5).is_nan());
    }

    #[test]
    fn whiskers_stop_at_the_last_point_inside_the_fences() {
        // Quartiles of 1..5 and 100 (type 7): 2.25 and 4.75, IQR 2.5, upper fence 8.5;
        // so the upper whisker ends at 5 and 100 is an outlier.
        let stats = BoxStats::of(&[100.0, 1.0, 2.0, 3.0, 4.0, 5.0]).expect("values");
        assert_eq!((stats.q1, stats.median, stats.q3), (2.25, 3.5, 4.75));
        assert_eq!((stats.whisker_lo, stats.whisker_hi), (1.0, 5.0));
        assert_eq!(stats.outliers, vec![100.0]);
        assert!(BoxStats::of(&[f64::NAN]).is_none());
    }

    #[test]
    fn improvement_is_percent_of_the_single_printer_median() {
        assert!((improvement_pct(0.08, 0.06) - 25.0).abs() < 1e-12);
        assert_eq!(improvement_pct(0.05, 0.05), 0.0);
        assert!(improvement_pct(0.04, 0.05) < 0.0, "worse than single is negative");
    }

    /// n = 1..8 with up to 12 subsets each, every held-out condition of a subset, three
    /// methods; transfer helps most at small n, as in the paper.
    fn cv_table() -> polars::prelude::DataFrame {
        let (mut n_train, mut subset, mut test, mut method, mut rmse) = (vec![], vec![], vec![], vec![], vec![]);
        let mut k = 0;
        for n in 1..=8_i64 {
            for s in 0..12.min(binomial(9, n)) {
                for t in 0..(9 - n) {
                    for (m, scale) in [("single", 1.0), ("transfer_zero_mean", 0.75), ("transfer_source_mean", 0.7)] {
                        let base_mm = 0.035 + 0.05 / n as f64 * scale + (1.0 - scale) * 0.01 * n as f64 / 8.0;
                        let outlier = if k % 97 == 0 { 3.0 } else { 1.0 };
                        n_train.push(n);
                        subset.push(format!("n{n}-{s}"));
                        test.push(format!("C{t}"));
                        method.push(m);
                        rmse.push(base_mm * (1.0 + 0.5 * noise(k)) * outlier);
                        k += 1;
                    }
                }
            }
        }
        let lambda = vec![1.0; rmse.len()];
        use transfer_cv as t;
        df!(t::n_train => n_train, t::subset => subset, t::test_condition => test, t::method => method,
            t::rmse_mm => rmse, t::lambda => lambda)
        .expect("frame")
    }

    fn binomial(n: i64, k: i64) -> i64 {
        (1..=k).fold(1, |acc, i| acc * (n - k + i) / i)
    }

    #[test]
    fn draws_box_plots_and_improvement() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_declared(dir.path(), &transfer_cv::TABLE, cv_table());
        let cv = load(dir.path()).expect("loads");
        assert_eq!(cv.n_train, (1..=8).collect::<Vec<_>>());
        assert_eq!(cv.methods, ["single", "transfer_zero_mean", "transfer_source_mean"]);
        assert!(cv.improvements("transfer_source_mean")[0].1 > 0.0, "transfer helps at n = 1");
        let stem = dir.path().join("transfer_cv");
        let title = "Transfer learning (test data)";
        draw_png_and_svg(&stem, SIZE_PX, |a| draw(a, title, &cv), |a| draw(a, title, &cv)).expect("draws");
        assert_drawn(&stem);
    }
}
