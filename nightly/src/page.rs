//! `report/nightly.html`: the history as a reader wants it the next morning. One
//! self-contained file (inline CSS and SVG figures): what regressed, every run's and
//! stage's time over the nights, and a trend figure per compared number — ours over
//! the nights, the paper's value as a dashed line, the band the latest night was held
//! to shaded.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use pipeline::artifact::write_atomic;
use pipeline::StageError;
use plotters::prelude::*;
use reports::html::{escape, format_sig};
use reports::style::{text, PALETTE};

use crate::history::History;
use crate::regress::{band, Band, Change, Finding, Rules};
use crate::{Night, NumberRow, SeriesKey};

const CSS: &str = "body{font-family:DejaVu Sans,Helvetica,Arial,sans-serif;max-width:1250px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}\
h1{border-bottom:2px solid #0072b2}h2{margin-top:2em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;margin:1em 0;font-size:13px}td,th{border:1px solid #ddd;padding:3px 8px;text-align:right}\
th{background:#f2f6fa}td.t,th.t{text-align:left}.note{color:#555;font-size:13px}\
.grid{display:flex;flex-wrap:wrap;gap:6px}.grid figure{margin:0;width:320px}figcaption{font-size:12px;color:#444;word-break:break-all}\
.bad{color:#b00020;font-weight:bold}.good{color:#007a4d}";

/// Stages drawn per run in the timing figure (the slowest; the table lists them all).
const STAGES_DRAWN: usize = 8;

/// Writes `out_dir/report/nightly.html`.
pub fn write(out_dir: &Path, history: &History, found: &[Finding], rules: &Rules) -> Result<PathBuf, StageError> {
    let mut html = format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>amrepro nightly benchmark</title><style>{CSS}</style></head><body>\n<h1>Nightly benchmark</h1>\n<p><a href=\"index.html\">← the report of the latest run</a></p>\n"
    );
    html += &header(history);
    html += &findings_section(found);
    html += &rules_note(rules);
    html += &runs_section(history);
    html += &stages_section(history);
    html += &numbers_section(history, rules);
    html += "</body></html>\n";
    let path = out_dir.join("report").join("nightly.html");
    write_atomic(&path, html.as_bytes())?;
    Ok(path)
}

fn header(history: &History) -> String {
    let (Some(first), Some(latest)) = (history.nights.first(), history.nights.last()) else {
        return "<p>The history holds no night yet.</p>\n".into();
    };
    let i = &latest.info;
    format!(
        "<p>{} night(s), {} to {}. Latest: <code>{}</code>, commit <code>{}</code>, host {}, {} cores, amrepro {}, {} s from start to finish. Every number comes from the history's <code>numbers</code> table (run, stage, table and metric named under each figure); timings from its <code>stages</code> table (docs/NIGHTLY.md).</p>\n",
        history.nights.len(),
        escape(&first.info.date),
        escape(&i.date),
        escape(&i.night),
        escape(&i.commit),
        escape(&i.host),
        i.cores,
        escape(&i.tool_version),
        i.finished_unix_s - i.started_unix_s
    )
}

fn findings_section(found: &[Finding]) -> String {
    let (bad, good): (Vec<&Finding>, Vec<&Finding>) = found.iter().partition(|f| f.regression);
    let mut s = format!("<h2 id=\"regressions\">Regressions ({})</h2>\n", bad.len());
    if bad.is_empty() {
        s += "<p class=\"good\">None: every number within its band, every verdict as before, every run complete, no stage slower.</p>\n";
    } else {
        s += &findings_table(&bad);
    }
    if !good.is_empty() {
        let _ = writeln!(s, "<h3>Moved towards the paper ({})</h3>", good.len());
        s += &findings_table(&good);
    }
    s
}

fn findings_table(found: &[&Finding]) -> String {
    let mut s = "<table><tr><th class=\"t\">what</th><th class=\"t\">change</th><th>latest</th><th class=\"t\">before</th><th>paper</th></tr>\n".to_string();
    for f in found {
        let (change, now, before, paper) = match &f.change {
            Change::LeftBand { value, band, paper } => (
                "left its band",
                format_sig(*value),
                format!("{} ± {}", format_sig(band.median), format_sig(band.half_width)),
                paper.map(format_sig).unwrap_or_default(),
            ),
            Change::VerdictChanged { now, was } => ("verdict changed", escape(now), escape(was), String::new()),
            Change::Missing => ("missing or not finite", String::new(), "present".into(), String::new()),
            Change::RunFailed { error } => ("run failed", escape(error), "complete".into(), String::new()),
            Change::Slower { wall_time_s, median_s } => (
                "slower",
                format!("{} s", format_sig(*wall_time_s)),
                format!("median {} s", format_sig(*median_s)),
                String::new(),
            ),
        };
        let _ = writeln!(
            s,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{change}</td><td>{now}</td><td class=\"t\">{before}</td><td>{paper}</td></tr>",
            escape(&f.subject)
        );
    }
    s + "</table>\n"
}

fn rules_note(rules: &Rules) -> String {
    format!(
        "<p class=\"note\">Rules: a number regresses when it leaves the median of its last {} nights ± max({} × 1.4826 × MAD, {} % of the median) and does not move towards the paper's value; a verdict when it differs from the most frequent of those nights; a number when it disappears or stops being finite; a run when it fails; a stage when it is more than {} %, {} s and {} × 1.4826 × MAD of its own times slower than its median (with one earlier night its spread is not known yet, and a stage's time on a shared machine can vary by more than that percentage).</p>\n",
        rules.window_nights,
        rules.mad_k,
        100.0 * rules.relative_floor,
        (100.0 * (rules.slower_ratio - 1.0)).round(),
        rules.slower_min_s,
        rules.mad_k
    )
}

/// Each night's x-axis label: its UTC start, `MM-DD HH:MM`.
fn dates(history: &History) -> Vec<String> {
    let label = |n: &Night| {
        let at = chrono::DateTime::from_timestamp(n.info.started_unix_s, 0).unwrap_or_default();
        at.format("%m-%d %H:%M").to_string()
    };
    history.nights.iter().map(label).collect()
}

fn runs_section(history: &History) -> String {
    let mut walls: BTreeMap<&str, Vec<Option<f64>>> = BTreeMap::new();
    for (i, night) in history.nights.iter().enumerate() {
        for run in &night.runs {
            walls.entry(&run.run).or_insert_with(|| vec![None; history.nights.len()])[i] =
                run.ok.then_some(run.wall_time_s);
        }
    }
    let series: Vec<(String, Vec<Option<f64>>)> = walls.into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    let chart = Chart { title: "wall time per run (s)".into(), size: (900, 320), log_y: true, ..Chart::default() };
    format!("<h2 id=\"runs\">Runs</h2>\n{}\n", chart.svg(&dates(history), &series))
}

fn stages_section(history: &History) -> String {
    let Some(latest) = history.nights.last() else { return String::new() };
    let mut s = "<h2 id=\"stages\">Stage timings</h2>\n<p class=\"note\">Each stage ran alone (its CPU time and peak memory are its own); the figure of each run draws its slowest stages of the latest night.</p>\n".to_string();
    let runs: Vec<&str> = latest.runs.iter().filter(|r| r.ok).map(|r| r.run.as_str()).collect();
    for run in runs {
        let mut stages: Vec<&crate::StageRow> = latest.stages.iter().filter(|st| st.run == run).collect();
        stages.sort_by(|a, b| b.wall_time_s.total_cmp(&a.wall_time_s));
        let series: Vec<(String, Vec<Option<f64>>)> = stages
            .iter()
            .take(STAGES_DRAWN)
            .map(|st| (st.stage.clone(), stage_series(history, run, &st.stage)))
            .collect();
        let chart = Chart {
            title: format!("{run}: wall time per stage (s)"),
            size: (900, 300),
            log_y: true,
            ..Chart::default()
        };
        let _ = writeln!(s, "<h3>{}</h3>\n{}", escape(run), chart.svg(&dates(history), &series));
        s += &stage_table(history, &stages);
    }
    s
}

fn stage_series(history: &History, run: &str, stage: &str) -> Vec<Option<f64>> {
    history
        .nights
        .iter()
        .map(|n| n.stages.iter().find(|s| s.run == run && s.stage == stage).map(|s| s.wall_time_s))
        .collect()
}

fn stage_table(history: &History, stages: &[&crate::StageRow]) -> String {
    let mut s = "<table><tr><th class=\"t\">stage</th><th class=\"t\">kind</th><th>wall s</th><th>median s (earlier nights)</th><th>CPU s</th><th>peak MiB</th><th>rows</th></tr>\n".to_string();
    let earlier = &history.nights[..history.nights.len().saturating_sub(1)];
    for st in stages {
        let mut past: Vec<f64> = earlier
            .iter()
            .filter_map(|n| n.stages.iter().find(|x| x.run == st.run && x.stage == st.stage))
            .map(|x| x.wall_time_s)
            .collect();
        past.sort_by(f64::total_cmp);
        let median = past.get(past.len() / 2).map(|m| format_sig(*m)).unwrap_or_default();
        let _ = writeln!(
            s,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{}</td><td>{}</td><td>{median}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&st.stage),
            escape(&st.kind),
            format_sig(st.wall_time_s),
            st.cpu_time_s.map(format_sig).unwrap_or_default(),
            st.peak_rss_bytes.map(|b| format!("{:.0}", b as f64 / 1_048_576.0)).unwrap_or_default(),
            st.rows
        );
    }
    s + "</table>\n"
}

/// One compared number's value per night (`None` on nights that did not record it).
type NightValues<'h> = Vec<Option<&'h NumberRow>>;

/// Every series of the history, in key order, with its value per night.
fn all_series(history: &History) -> BTreeMap<SeriesKey, NightValues<'_>> {
    let mut series: BTreeMap<SeriesKey, NightValues<'_>> = BTreeMap::new();
    for (i, night) in history.nights.iter().enumerate() {
        for n in &night.numbers {
            series.entry(n.series()).or_insert_with(|| vec![None; history.nights.len()])[i] = Some(n);
        }
    }
    series
}

fn numbers_section(history: &History, rules: &Rules) -> String {
    let series = all_series(history);
    let mut s = format!("<h2 id=\"numbers\">Compared numbers ({})</h2>\n<p class=\"note\">Ours over the nights (blue), the paper\'s value (orange, dashed) and the band the latest night was held to (shaded, from the nights before it).</p>\n", series.len());
    let mut by_run: BTreeMap<&str, Vec<(&SeriesKey, &NightValues<'_>)>> = BTreeMap::new();
    for (key, values) in &series {
        by_run.entry(&key.run).or_default().push((key, values));
    }
    for (run, list) in by_run {
        let _ = writeln!(s, "<h3>{}</h3>", escape(run));
        let (verdicts, numbers): (Vec<_>, Vec<_>) =
            list.into_iter().partition(|(_, v)| v.iter().flatten().any(|n| n.text.is_some()));
        s += "<div class=\"grid\">\n";
        for (key, values) in numbers {
            s += &number_figure(history, key, values, rules);
        }
        s += "</div>\n";
        s += &verdict_table(history, &verdicts);
    }
    s
}

fn number_figure(history: &History, key: &SeriesKey, values: &[Option<&NumberRow>], rules: &Rules) -> String {
    let ours: Vec<Option<f64>> = values.iter().map(|n| n.and_then(|n| n.value)).collect();
    let latest = values.iter().rev().flatten().next();
    let paper = latest.and_then(|n| n.paper_value);
    let earlier: Vec<f64> =
        ours[..ours.len().saturating_sub(1)].iter().rev().take(rules.window_nights).flatten().copied().collect();
    // A rate or a count has unit 1, which a caption does not print.
    let unit = latest.map(|n| n.unit.as_str()).filter(|u| *u != "1").unwrap_or_default();
    let chart =
        Chart { title: String::new(), size: (320, 170), paper, band: band(&earlier, rules), ..Chart::default() };
    let now = ours.last().copied().flatten().map(format_sig).unwrap_or_else(|| "—".into());
    let paper_text = paper.map(|p| format!(", paper {}", format_sig(p))).unwrap_or_default();
    format!(
        "<figure>{}<figcaption><b>{}</b> = {now} {}{paper_text}<br>{} / {} ({})</figcaption></figure>\n",
        chart.svg(&dates(history), &[("ours".into(), ours)]),
        escape(&key.metric),
        escape(unit),
        escape(&key.stage),
        escape(&key.table),
        escape(latest.map(|n| n.source.as_str()).unwrap_or_default())
    )
}

fn verdict_table(history: &History, verdicts: &[(&SeriesKey, &Vec<Option<&NumberRow>>)]) -> String {
    if verdicts.is_empty() {
        return String::new();
    }
    let mut s = "<table><tr><th class=\"t\">verdict</th><th class=\"t\">stage / table</th>".to_string();
    for night in &history.nights {
        let _ = write!(s, "<th class=\"t\">{}</th>", escape(&night_label(night)));
    }
    s += "</tr>\n";
    for (key, values) in verdicts {
        let _ = write!(
            s,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{} / {}</td>",
            escape(&key.metric),
            escape(&key.stage),
            escape(&key.table)
        );
        let mut previous: Option<&str> = None;
        for v in values.iter() {
            let text = v.and_then(|n| n.text.as_deref()).unwrap_or("");
            let class = if previous.is_some_and(|p| p != text) { " bad" } else { "" };
            let _ = write!(s, "<td class=\"t{class}\">{}</td>", escape(text));
            previous = Some(text);
        }
        s += "</tr>\n";
    }
    s + "</table>\n"
}

fn night_label(night: &Night) -> String {
    night.info.night.get(..15).unwrap_or(&night.info.night).to_string()
}

/// A small line chart over the nights, drawn as inline SVG.
#[derive(Debug, Clone, Default)]
struct Chart {
    title: String,
    size: (u32, u32),
    log_y: bool,
    paper: Option<f64>,
    band: Option<Band>,
}

impl Chart {
    /// The SVG text; a chart that cannot be drawn says so in place of the figure.
    fn svg(&self, x_labels: &[String], series: &[(String, Vec<Option<f64>>)]) -> String {
        let mut svg = String::new();
        let drawn = self.draw(&mut svg, x_labels, series);
        match drawn {
            Ok(()) => svg,
            Err(e) => format!("<p class=\"note\">(figure not drawn: {})</p>", escape(&e)),
        }
    }

    fn y_range(&self, series: &[(String, Vec<Option<f64>>)]) -> Option<(f64, f64)> {
        let mut ys: Vec<f64> = series.iter().flat_map(|(_, v)| v.iter().flatten().copied()).collect();
        ys.extend(self.paper);
        if let Some(b) = self.band {
            ys.extend([b.median - b.half_width, b.median + b.half_width]);
        }
        ys.retain(|y| y.is_finite() && (!self.log_y || *y > 0.0));
        let lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if !lo.is_finite() {
            return None;
        }
        if self.log_y {
            return Some((lo / 1.5, hi * 1.5));
        }
        // At least ±2 % of the values' size (±1 when they are all 0), so a number that
        // never moved is drawn as a level line, not magnified to its band's floor.
        let scale = series.iter().flat_map(|(_, v)| v.iter().flatten()).chain(&self.paper).map(|y| y.abs());
        let scale = scale.filter(|y| y.is_finite()).fold(0.0, f64::max);
        let min_half = if scale > 0.0 { 0.02 * scale } else { 1.0 };
        let (mid, half) = (0.5 * (lo + hi), (0.5 * (hi - lo)).max(min_half));
        Some((mid - 1.08 * half, mid + 1.08 * half))
    }

    fn draw(&self, svg: &mut String, x_labels: &[String], series: &[(String, Vec<Option<f64>>)]) -> Result<(), String> {
        let Some((y_lo, y_hi)) = self.y_range(series) else {
            return Err("no finite value".into());
        };
        let root = SVGBackend::with_string(svg, self.size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let n = x_labels.len().max(1) as f64;
        let mut builder = ChartBuilder::on(&root);
        builder.margin(6).x_label_area_size(22).y_label_area_size(58);
        if !self.title.is_empty() {
            builder.caption(&self.title, text(14.0));
        }
        let x_range = -0.5..(n - 0.5);
        let labels = |x: &f64| {
            let i = x.round();
            match (i - x).abs() < 1e-6 && i >= 0.0 {
                true => x_labels.get(i as usize).cloned().unwrap_or_default(),
                false => String::new(),
            }
        };
        let ticks = x_labels.len().clamp(1, 8);
        if self.log_y {
            let mut chart = builder.build_cartesian_2d(x_range, (y_lo..y_hi).log_scale()).map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .label_style(text(12.0))
                .light_line_style(WHITE)
                .x_labels(ticks)
                .y_labels(6)
                .x_label_formatter(&labels)
                .y_label_formatter(&|y| format_sig(*y))
                .draw()
                .map_err(|e| e.to_string())?;
            draw_series(&mut chart, series)?;
            if series.len() > 1 {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperLeft)
                    .label_font(text(12.0))
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK.mix(0.4))
                    .draw()
                    .map_err(|e| e.to_string())?;
            }
        } else {
            let mut chart = builder.build_cartesian_2d(x_range.clone(), y_lo..y_hi).map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .label_style(text(11.0))
                .light_line_style(WHITE)
                .x_labels(ticks.min(4))
                .y_labels(4)
                .x_label_formatter(&labels)
                .y_label_formatter(&|y| format_sig(*y))
                .draw()
                .map_err(|e| e.to_string())?;
            if let Some(b) = self.band {
                let rect = [(x_range.start, b.median - b.half_width), (x_range.end, b.median + b.half_width)];
                chart
                    .draw_series([Rectangle::new(rect, RGBColor(0, 114, 178).mix(0.12).filled())])
                    .map_err(|e| e.to_string())?;
            }
            if let Some(p) = self.paper {
                let dashes = (0..(2.0 * n) as i32).map(|k| {
                    let x0 = -0.5 + k as f64 * 0.5;
                    PathElement::new([(x0, p), (x0 + 0.3, p)], PALETTE[1].stroke_width(2))
                });
                chart.draw_series(dashes).map_err(|e| e.to_string())?;
            }
            draw_series(&mut chart, series)?;
        }
        root.present().map_err(|e| e.to_string())
    }
}

fn draw_series<DB: DrawingBackend, Y: plotters::coord::ranged1d::Ranged<ValueType = f64>>(
    chart: &mut ChartContext<DB, plotters::coord::cartesian::Cartesian2d<plotters::coord::types::RangedCoordf64, Y>>,
    series: &[(String, Vec<Option<f64>>)],
) -> Result<(), String> {
    for (k, (name, values)) in series.iter().enumerate() {
        let colour = PALETTE[k % PALETTE.len()];
        let points: Vec<(f64, f64)> = values.iter().enumerate().filter_map(|(i, v)| v.map(|y| (i as f64, y))).collect();
        chart
            .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label(name.clone())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], colour.stroke_width(2)));
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled()))).map_err(|e| e.to_string())?;
    }
    Ok(())
}
