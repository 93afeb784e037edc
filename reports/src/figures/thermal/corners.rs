//! `figure.thermal_corners`: per compensated corner, what the monitor saw and what the
//! compensation commands, in the style of paper 003 (Chen et al.) Figs 5 and 8
//! (Sec. 2.4, eqs 31-39): (a) the temperature at the path around the corner against
//! time, with the 140-150 °C band of Sec. 3.2; (b) the extracted width w_l + w_r
//! against the desired width (eqs 31-32), both as the compensation used them (the
//! measured width combined over the monitored layers, the desired width of the
//! stage's `desired_width` choice), over the extended window; (c) the compensation sequence: the
//! desired output change Δv_e (eq. 33), the input Δv_er (eq. 36) and the filtered
//! B-spline output (eq. 38), with the bounds of eq. 39 (−2 / +4 mm/s) dashed. The
//! compensation span is shaded and its extensions (0.1 s each side, Sec. 3.2) lighter.
//!
//! The paper's Fig. 5(a) is a map of temperature over time and position along the
//! deposition direction; the monitor publishes the temperature at the path only, so
//! (a) is its trace. Time is drawn from the span start Δt_0 (s).
//!
//! Inputs: a `thermal.monitor` stage (`widths.parquet`), then a `thermal.compensate`
//! stage (`spans.parquet`, `compensation.parquet`).

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::params::ParamError;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::thermal::{compensation, spans, widths};

use crate::figures::thermal::common::finite_range;
use crate::figures::thermal::directions::parse_vertices;
use crate::read::{f64s, ints, no_rows, read_parquet};
use crate::style::{draw_house_legend, draw_png_and_svg, house_mesh, text, PALETTE};

/// The `figure.thermal_corners` stage kind.
pub struct ThermalCornersFigure;

/// Figure width and height of one corner row, in pixels.
const WIDTH_PX: u32 = 1650;
const ROW_PX: u32 = 330;
/// Height of the title band, in pixels.
const TITLE_PX: u32 = 50;
/// The 140-150 °C band of freshly printed material (paper 003 Sec. 3.2).
const BAND_C: (f64, f64) = (140.0, 150.0);

pipeline::params! {
    /// The parameters of `figure.thermal_corners`.
    pub struct CornersParams {
        /// Comma-separated span ids to draw, one row each (default: every span).
        pub spans: String = "",
        /// Layer of widths.parquet to draw; −1: the lowest layer with samples in each span's window.
        pub layer: i64 [-1, 100_000] = -1,
        /// Time shown before the extended span and after it (s).
        pub pad_s: f64 [0.0, 10.0] = 0.1,
        /// Lower bound ΔV_min of eq. 39 drawn dashed (mm/s); paper 003 Sec. 3.2: −2 mm/s.
        pub dv_min_mm_s: f64 [-1000.0, 0.0] = -2.0,
        /// Upper bound ΔV_max of eq. 39 drawn dashed (mm/s); paper 003 Sec. 3.2: 4 mm/s.
        pub dv_max_mm_s: f64 [0.0, 1000.0] = 4.0,
        /// Figure title (default: a generic description).
        pub title: String = "",
    }
}

/// The monitor whose temperatures are drawn.
const MONITOR: Input = Input::one(
    "monitor",
    &[Source::Stage("thermal.monitor")],
    "the temperature at the path per sample (`widths.parquet`)",
)
.reading(&[Reads { table: &widths::TABLE, columns: &[widths::layer, widths::t_s, widths::temp_c] }]);

/// The compensation drawn.
const COMPENSATE: Input = Input::one(
    "compensate",
    &[Source::Stage("thermal.compensate")],
    "the compensated spans and their sequences (`spans.parquet`, `compensation.parquet`)",
)
.reading(&[
    Reads {
        table: &spans::TABLE,
        columns: &[
            spans::span,
            spans::vertex,
            spans::angle_deg,
            spans::t_start_s,
            spans::t_end_s,
            spans::t_ext_start_s,
            spans::t_ext_end_s,
            spans::corner_temp_c,
            spans::gain_ke,
            spans::max_dw_mm,
        ],
    },
    Reads {
        table: &compensation::TABLE,
        columns: &[
            compensation::span,
            compensation::t_s,
            compensation::dv_desired_mm_s,
            compensation::w_measured_mm,
            compensation::w_desired_mm,
            compensation::dv_input_mm_s,
            compensation::dv_output_mm_s,
        ],
    },
]);

/// One compensated span (a row of `spans.parquet`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// Span id.
    pub span: i64,
    /// CAD vertex of the corner.
    pub vertex: i64,
    /// Corner angle (degrees).
    pub angle_deg: f64,
    /// Span start and end Δt_0, Δt_1 (s).
    pub t_s: (f64, f64),
    /// Extended span start and end (s).
    pub t_ext_s: (f64, f64),
    /// Corner temperature T_p (°C).
    pub corner_temp_c: f64,
    /// Correction gain K_e.
    pub gain_ke: f64,
    /// Largest |Δw| in the span (mm).
    pub max_dw_mm: f64,
}

impl Span {
    /// The row caption.
    pub fn caption(&self) -> String {
        format!(
            "span {}: vertex {} ({:.0}° corner), T_p = {:.1} °C, K_e = {:.2}, max Δw = {:.3} mm",
            self.span, self.vertex, self.angle_deg, self.corner_temp_c, self.gain_ke, self.max_dw_mm
        )
    }
}

/// The monitored samples (a few columns of `widths.parquet`).
#[derive(Debug, Clone, Default)]
pub struct Widths {
    /// Layer of each sample.
    pub layer: Vec<i64>,
    /// Time (s).
    pub t_s: Vec<f64>,
    /// Temperature at the path (°C).
    pub temp_c: Vec<f64>,
}

/// The compensation sequence of one span.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Sequence {
    /// Time (s).
    pub t_s: Vec<f64>,
    /// Measured width w_l + w_r the compensation used (mm; NaN where not measured).
    pub measured_mm: Vec<f64>,
    /// Desired width the compensation aimed at (mm).
    pub wanted_mm: Vec<f64>,
    /// Desired output change Δv_e (mm/s).
    pub desired_mm_s: Vec<f64>,
    /// Input Δv_er (mm/s).
    pub input_mm_s: Vec<f64>,
    /// Filtered B-spline output (mm/s).
    pub output_mm_s: Vec<f64>,
}

/// Everything a drawing needs: one row per span.
#[derive(Debug, Clone)]
pub struct Plot {
    /// The spans drawn, in order.
    pub rows: Vec<(Span, Sequence)>,
    /// The monitored samples.
    pub widths: Widths,
    /// Layer to draw (None: the lowest in each window).
    pub layer: Option<i64>,
    /// Padding around the extended span (s).
    pub pad_s: f64,
    /// Bounds of eq. 39 (mm/s).
    pub dv_bounds_mm_s: (f64, f64),
}

impl Stage for ThermalCornersFigure {
    type Params = CornersParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.thermal_corners",
        version: 2,
        summary: "Per compensated corner: temperature at the path, extracted vs desired width, and the compensation sequence with its bounds → thermal_corners.png/.svg",
        implements: "paper 003 Figs 5 and 8 (Sec. 2.4, eqs 31-39)",
        inputs: &[MONITOR, COMPENSATE],
        output: Output::Tables,
    };

    fn check(p: &CornersParams) -> Result<(), ParamError> {
        parse_vertices(&p.spans, "spans").map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &CornersParams) -> Result<(), StageError> {
        let widths = load_widths(&ctx.input(&MONITOR).dir.join(widths::TABLE.file()))?;
        let wanted = parse_vertices(&p.spans, "spans").map_err(|e| StageError::params(ctx, e))?;
        let rows = load_spans(&ctx.input(&COMPENSATE).dir, &wanted)?;
        let plot = Plot {
            rows,
            widths,
            layer: (p.layer >= 0).then_some(p.layer),
            pad_s: p.pad_s,
            dv_bounds_mm_s: (p.dv_min_mm_s, p.dv_max_mm_s),
        };
        let title = crate::figures::common::title_or(&p.title, || {
            "Compensated corners: temperature, extracted vs desired width, compensation sequence".to_string()
        });
        let stem = ctx.output_path("thermal_corners")?;
        let size = figure_size_px(plot.rows.len());
        draw_png_and_svg(&stem, size, |a| draw(a, &title, &plot), |a| draw(a, &title, &plot))
    }
}

/// The figure size for `rows` corners.
pub fn figure_size_px(rows: usize) -> (u32, u32) {
    (WIDTH_PX, TITLE_PX + ROW_PX * rows.max(1) as u32)
}

/// Reads `widths.parquet`.
pub fn load_widths(path: &Path) -> Result<Widths, StageError> {
    let df = read_parquet(path)?;
    let widths = Widths {
        layer: ints(&df, widths::layer, path)?,
        t_s: f64s(&df, widths::t_s, path)?,
        temp_c: f64s(&df, widths::temp_c, path)?,
    };
    if widths.t_s.is_empty() {
        return Err(no_rows(path, widths::t_s, "one row per monitored sample"));
    }
    Ok(widths)
}

/// Reads `spans.parquet` and `compensation.parquet`; keeps the spans in `wanted`
/// (all when empty). A wanted span that is absent is an error.
pub fn load_spans(dir: &Path, wanted: &[i64]) -> Result<Vec<(Span, Sequence)>, StageError> {
    let path = dir.join(spans::TABLE.file());
    let df = read_parquet(&path)?;
    let f = |name: &str| f64s(&df, name, &path);
    let (span, vertex) = (ints(&df, spans::span, &path)?, ints(&df, spans::vertex, &path)?);
    let (angle, t0, t1, e0, e1) = (
        f(spans::angle_deg)?,
        f(spans::t_start_s)?,
        f(spans::t_end_s)?,
        f(spans::t_ext_start_s)?,
        f(spans::t_ext_end_s)?,
    );
    let (temp, gain, dw) = (f(spans::corner_temp_c)?, f(spans::gain_ke)?, f(spans::max_dw_mm)?);
    let spans: Vec<Span> = (0..df.height())
        .map(|i| Span {
            span: span[i],
            vertex: vertex[i],
            angle_deg: angle[i],
            t_s: (t0[i], t1[i]),
            t_ext_s: (e0[i], e1[i]),
            corner_temp_c: temp[i],
            gain_ke: gain[i],
            max_dw_mm: dw[i],
        })
        .filter(|s| wanted.is_empty() || wanted.contains(&s.span))
        .collect();
    if let Some(missing) = wanted.iter().find(|w| !spans.iter().any(|s| s.span == **w)) {
        return Err(no_rows(&path, spans::span, &format!("span {missing}")));
    }
    if spans.is_empty() {
        return Err(no_rows(&path, spans::span, "one row per compensated span"));
    }
    let sequences = load_sequences(&dir.join(compensation::TABLE.file()), &spans)?;
    Ok(spans.into_iter().zip(sequences).collect())
}

fn load_sequences(path: &Path, spans: &[Span]) -> Result<Vec<Sequence>, StageError> {
    let df = read_parquet(path)?;
    let id = ints(&df, compensation::span, path)?;
    let (t, want) = (f64s(&df, compensation::t_s, path)?, f64s(&df, compensation::dv_desired_mm_s, path)?);
    let (measured, wanted) =
        (f64s(&df, compensation::w_measured_mm, path)?, f64s(&df, compensation::w_desired_mm, path)?);
    let (input, output) =
        (f64s(&df, compensation::dv_input_mm_s, path)?, f64s(&df, compensation::dv_output_mm_s, path)?);
    let mut sequences = vec![Sequence::default(); spans.len()];
    for i in 0..df.height() {
        if let Some(k) = spans.iter().position(|s| s.span == id[i]) {
            let q = &mut sequences[k];
            q.t_s.push(t[i]);
            q.measured_mm.push(measured[i]);
            q.wanted_mm.push(wanted[i]);
            q.desired_mm_s.push(want[i]);
            q.input_mm_s.push(input[i]);
            q.output_mm_s.push(output[i]);
        }
    }
    if let Some(k) = sequences.iter().position(|q| q.t_s.is_empty()) {
        return Err(no_rows(path, compensation::span, &format!("the sequence of span {}", spans[k].span)));
    }
    Ok(sequences)
}

impl Widths {
    /// Indices of the samples in `window` (s) of `layer`, or of the lowest layer with
    /// samples in the window when `layer` is None, sorted by time.
    pub fn in_window(&self, window: &Range<f64>, layer: Option<i64>) -> Vec<usize> {
        let inside = |i: &usize| window.contains(&self.t_s[*i]);
        let layer = layer.or_else(|| (0..self.t_s.len()).filter(inside).map(|i| self.layer[i]).min());
        let mut picked: Vec<usize> =
            (0..self.t_s.len()).filter(|i| inside(i) && Some(self.layer[*i]) == layer).collect();
        picked.sort_by(|a, b| self.t_s[*a].total_cmp(&self.t_s[*b]));
        picked
    }
}

/// Splits a series at its non-finite values into the pieces a line can join.
pub fn finite_pieces(points: impl Iterator<Item = (f64, f64)>) -> Vec<Vec<(f64, f64)>> {
    let mut pieces: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (x, y) in points {
        match (x.is_finite() && y.is_finite(), pieces.last_mut()) {
            (true, Some(p)) => p.push((x, y)),
            (false, Some(p)) if !p.is_empty() => pieces.push(Vec::new()),
            _ => {}
        }
    }
    pieces.retain(|p| !p.is_empty());
    pieces
}

/// Draws one row of three panels per span.
pub fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, title: &str, plot: &Plot) -> Result<(), String> {
    let area = area.margin(10, 6, 6, 10).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    let rows = area.split_evenly((plot.rows.len().max(1), 1));
    for (k, ((span, sequence), row)) in plot.rows.iter().zip(&rows).enumerate() {
        let row = row.titled(&span.caption(), text(17.0)).map_err(|e| e.to_string())?;
        let panels = row.split_evenly((1, 3));
        let t0 = span.t_s.0;
        let window = (span.t_ext_s.0 - plot.pad_s)..(span.t_ext_s.1 + plot.pad_s);
        let xs = (window.start - t0)..(window.end - t0);
        let picked = plot.widths.in_window(&window, plot.layer);
        let series =
            |v: &[f64]| -> Vec<(f64, f64)> { picked.iter().map(|&i| (plot.widths.t_s[i] - t0, v[i])).collect() };
        let legend = k == 0;
        let temp = series(&plot.widths.temp_c);
        let along = |v: &[f64]| -> Vec<(f64, f64)> { sequence.t_s.iter().zip(v).map(|(t, w)| (t - t0, *w)).collect() };
        let (width, desired) = (along(&sequence.measured_mm), along(&sequence.wanted_mm));
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        draw_temperature(&panels[0], span, xs.clone(), &temp, legend).map_err(e)?;
        draw_width(&panels[1], span, xs.clone(), &width, &desired, legend).map_err(e)?;
        draw_sequence(&panels[2], span, sequence, xs, plot.dv_bounds_mm_s, legend).map_err(e)?;
    }
    Ok(())
}

type Chart<'a, DB> = crate::figures::thermal::common::PlaneChart<'a, DB>;

fn time_chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    xs: Range<f64>,
    ys: (f64, f64),
    y_desc: &str,
    decimals: usize,
) -> Result<Chart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let pad = 0.08 * (ys.1 - ys.0);
    let mut chart = ChartBuilder::on(area)
        .margin(6)
        .margin_right(14)
        .x_label_area_size(40)
        .y_label_area_size(62)
        .build_cartesian_2d(xs, (ys.0 - pad)..(ys.1 + pad))?;
    house_mesh(&mut chart)
        .x_desc("Δt from span start (s)")
        .y_desc(y_desc)
        .x_label_formatter(&|x| format!("{:.2}", if x.abs() < 0.005 { 0.0 } else { *x }))
        .y_label_formatter(&|y| format!("{y:.decimals$}"))
        .draw()?;
    Ok(chart)
}

/// Shades the span (darker) and its extensions (lighter), times from the span start.
fn shade_span<DB: DrawingBackend>(
    chart: &mut Chart<DB>,
    span: &Span,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let y = chart.y_range();
    let t0 = span.t_s.0;
    let band = |a: f64, b: f64, alpha: f64| {
        Rectangle::new([(a - t0, y.start), (b - t0, y.end)], PALETTE[4].mix(alpha).filled())
    };
    chart.draw_series([band(span.t_ext_s.0, span.t_s.0, 0.12), band(span.t_s.1, span.t_ext_s.1, 0.12)])?;
    chart
        .draw_series([band(span.t_s.0, span.t_s.1, 0.3)])?
        .label("span (extensions lighter)")
        .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], PALETTE[4].mix(0.3).filled()));
    Ok(())
}

fn draw_temperature<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    span: &Span,
    xs: Range<f64>,
    temp: &[(f64, f64)],
    legend: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let ys = finite_range(temp.iter().map(|p| p.1).chain([BAND_C.0, BAND_C.1]));
    let mut chart = time_chart(area, xs.clone(), ys, "temperature at the path (°C)", 0)?;
    shade_span(&mut chart, span)?;
    let band = Rectangle::new([(xs.start, BAND_C.0), (xs.end, BAND_C.1)], PALETTE[1].mix(0.15).filled());
    chart
        .draw_series([band])?
        .label("140-150 °C band")
        .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], PALETTE[1].mix(0.15).filled()));
    let red = PALETTE[1].stroke_width(2);
    for piece in finite_pieces(temp.iter().copied()) {
        chart.draw_series(LineSeries::new(piece, red))?;
    }
    chart
        .draw_series([Circle::new((span_mid(span), span.corner_temp_c), 5, BLACK.filled())])?
        .label("T_p (corner)")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, BLACK.filled()));
    finish(&mut chart, legend)
}

fn span_mid(span: &Span) -> f64 {
    (span.t_s.1 - span.t_s.0) / 2.0
}

fn draw_width<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    span: &Span,
    xs: Range<f64>,
    width: &[(f64, f64)],
    desired: &[(f64, f64)],
    legend: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let ys = finite_range(width.iter().chain(desired).map(|p| p.1));
    let mut chart = time_chart(area, xs, ys, "width (mm)", 2)?;
    shade_span(&mut chart, span)?;
    let (blue, black) = (PALETTE[0].stroke_width(2), BLACK.stroke_width(2));
    for piece in finite_pieces(width.iter().copied()) {
        chart.draw_series(LineSeries::new(piece, blue))?;
    }
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
        .label("extracted w_l + w_r (used)")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], blue));
    for piece in finite_pieces(desired.iter().copied()) {
        chart.draw_series(DashedLineSeries::new(piece, 7, 4, black))?;
    }
    chart
        .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
        .label("desired width")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], black));
    finish(&mut chart, legend)
}

fn draw_sequence<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    span: &Span,
    q: &Sequence,
    xs: Range<f64>,
    (lo, hi): (f64, f64),
    legend: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let all = q.desired_mm_s.iter().chain(&q.input_mm_s).chain(&q.output_mm_s).copied();
    let ys = finite_range(all.chain([lo, hi]));
    let mut chart = time_chart(area, xs.clone(), ys, "Δv (mm/s)", 1)?;
    shade_span(&mut chart, span)?;
    let grey = PALETTE[6].stroke_width(2);
    chart
        .draw_series(
            [lo, hi].map(|b| DashedLineSeries::new([(xs.start, b), (xs.end, b)], 6, 4, grey)).into_iter().flatten(),
        )?
        .label(format!("bounds {lo} / +{hi} mm/s"))
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], grey));
    let t0 = span.t_s.0;
    let curves = [
        (&q.desired_mm_s, "desired output Δv_e", BLACK, 2),
        (&q.input_mm_s, "input Δv_er", PALETTE[1], 3),
        (&q.output_mm_s, "filtered output", PALETTE[0], 2),
    ];
    for (values, label, colour, width) in curves {
        let style = colour.stroke_width(width);
        let points = q.t_s.iter().zip(values.iter()).map(|(t, v)| (t - t0, *v));
        for piece in finite_pieces(points) {
            chart.draw_series(LineSeries::new(piece, style))?;
        }
        chart
            .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 24, y)], style));
    }
    finish(&mut chart, legend)
}

fn finish<'a, DB: DrawingBackend + 'a>(
    chart: &mut Chart<'a, DB>,
    legend: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    if legend {
        draw_house_legend(chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, write_declared, write_table};
    use crate::figures::thermal::test_data::{corner_path, widths, write_compensate};

    #[test]
    fn finite_pieces_break_at_nan() {
        let p = [(0.0, 1.0), (1.0, f64::NAN), (2.0, 3.0), (3.0, 4.0), (4.0, f64::NAN)];
        assert_eq!(finite_pieces(p.into_iter()), vec![vec![(0.0, 1.0)], vec![(2.0, 3.0), (3.0, 4.0)]]);
        assert!(finite_pieces([(0.0, f64::NAN)].into_iter()).is_empty());
    }

    #[test]
    fn window_takes_the_lowest_layer_unless_told() {
        let w = Widths { layer: vec![1, 0, 0, 1], t_s: vec![0.5, 0.6, 0.4, 0.55], temp_c: vec![0.0; 4] };
        assert_eq!(w.in_window(&(0.0..1.0), None), vec![2, 1], "layer 0, sorted by time");
        assert_eq!(w.in_window(&(0.0..1.0), Some(1)), vec![0, 3]);
        assert!(w.in_window(&(2.0..3.0), None).is_empty());
    }

    #[test]
    fn missing_span_or_column_is_an_error_naming_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_compensate(dir.path());
        let err = load_spans(dir.path(), &[7]).expect_err("no span 7").to_string();
        assert!(err.contains("spans.parquet") && err.contains("span 7"), "{err}");
        write_table(dir.path(), "widths", widths(&corner_path()).drop("temp_c").expect("drops"));
        let err = load_widths(&dir.path().join("widths.parquet")).expect_err("no temp_c").to_string();
        assert!(err.contains("widths.parquet") && err.contains("temp_c"), "{err}");
    }

    #[test]
    fn draws_one_row_per_span() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_compensate(dir.path());
        write_declared(dir.path(), &tables::thermal::widths::TABLE, widths(&corner_path()));
        let rows = load_spans(dir.path(), &[]).expect("loads");
        assert_eq!(rows.len(), 4);
        assert!(rows.iter().all(|(_, q)| q.t_s.len() == 361));
        let widths = load_widths(&dir.path().join("widths.parquet")).expect("loads");
        let plot = Plot { rows, widths, layer: None, pad_s: 0.1, dv_bounds_mm_s: (-2.0, 4.0) };
        let span = &plot.rows[0].0;
        let window = (span.t_ext_s.0 - 0.1)..(span.t_ext_s.1 + 0.1);
        assert!(plot.widths.in_window(&window, None).iter().all(|&i| plot.widths.layer[i] == 0));
        let stem = dir.path().join("thermal_corners");
        let title = "Synthetic compensated corners (cf. paper 003 Figs 5 and 8)";
        let size = figure_size_px(plot.rows.len());
        draw_png_and_svg(&stem, size, |a| draw(a, title, &plot), |a| draw(a, title, &plot)).expect("draws");
        assert_drawn(&stem);
    }
}
