//! The discrepancy engine's figures (DESIGN §7) on paper 000's lines (the held-out
//! residuals against each candidate variable are `figure.discrepancy_residuals`, which
//! every domain draws):
//!
//! - `figure.fdm_discrepancy_lines`: measured, baseline and extended-model widths
//!   along the lines the baseline predicts worst (`predictions.parquet`).
//! - `figure.fdm_discovery_power`: the power curves — the share of draws in which the
//!   engine names a hidden effect, against its strength, per base printer, with the
//!   null draws' false-alarm rate (`power.parquet`).

use std::collections::BTreeMap;
use std::path::Path;

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use pipeline::params::NoParams;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::discrepancy::fdm::{self, gain, predictions};
use tables::discrepancy::power;

use crate::figures::discrepancy_residuals::{Models, BASELINE, EXTENDED};
use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_house_legend, draw_png_and_svg, house_mesh, text, PALETTE};

use super::draw_width_profile_mesh;
use super::loo_predictions::step_points;

/// Colour of measured widths.
const MEASURED: RGBColor = RGBColor(70, 70, 70);

pipeline::params! {
    /// The parameters of `figure.fdm_discrepancy_lines`.
    pub struct LinesParams {
        /// Printer whose results are drawn.
        pub printer: String,
        /// How many lines to draw: those the baseline predicts worst (held-out RMSE).
        pub lines: usize [1, 9] = 3,
    }
}

/// What the lines figure reads of the engine run besides its predictions: the names of
/// the baseline and of the extended model.
const MODEL_NAMES: Reads =
    Reads { table: &gain::TABLE, columns: &[gain::printer, gain::baseline, gain::extended_model] };

/// The engine run whose held-out predictions the lines figure draws.
const DISCREPANCY_LINES: Input = Input::one(
    "discrepancy",
    &[Source::Stage("fdm.discrepancy")],
    "the engine's held-out predictions and gain (`predictions.parquet`, `gain.parquet`)",
)
.reading(&[
    Reads {
        table: &predictions::TABLE,
        columns: &[
            predictions::printer,
            predictions::condition,
            predictions::accel_mm_s2,
            predictions::feed_mm_s,
            predictions::position_mm,
            predictions::measured_width_mm,
            predictions::baseline_width_mm,
            predictions::extended_width_mm,
        ],
    },
    MODEL_NAMES,
]);

/// The power studies drawn together.
const POWER: Input = Input::many(
    "power",
    1,
    &[Source::Stage("fdm.discovery_power")],
    "power studies (`power.parquet`), their bases drawn side by side",
)
.reading(&[Reads {
    table: &power::TABLE,
    columns: &[
        power::base,
        power::own_causes,
        power::effect,
        power::noise,
        power::strength,
        power::correct_rate,
        power::correct_ci_lo,
        power::correct_ci_hi,
        power::false_alarm_rate,
        power::false_alarm_ci_hi,
        power::draws,
    ],
}]);

/// The `figure.fdm_discrepancy_lines` stage kind.
pub struct DiscrepancyLinesFigure;

/// The `figure.fdm_discovery_power` stage kind.
pub struct DiscoveryPowerFigure;

impl Stage for DiscrepancyLinesFigure {
    type Params = LinesParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_discrepancy_lines",
        version: 2,
        summary: "Measured vs baseline (the lag model, or paper 000's piecewise model) vs extended model along the lines the baseline predicts worst (held out) → discrepancy_lines.png/.svg",
        implements: "DESIGN §7 steps 3-4 (extend, gain), in the style of paper 000 Fig. 6",
        inputs: &[DISCREPANCY_LINES],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &LinesParams) -> Result<(), StageError> {
        let printer = &p.printer;
        let dir = &ctx.input(&DISCREPANCY_LINES).dir;
        let lines = read_lines(&dir.join(predictions::TABLE.file()), printer)?;
        let models = Models::read(&dir.join(gain::TABLE.file()), &fdm::ENGINE, printer)?;
        let worst = worst_lines(lines, p.lines);
        let baseline = models.baseline_words();
        let title = if models.unchanged() {
            format!("{printer}: the lines the {baseline} predicts worst, held out (no cause named)")
        } else {
            format!("{printer}: the lines the {baseline} predicts worst, held out, and {}", models.extended)
        };
        let stem = ctx.output_path("discrepancy_lines")?;
        let height = 420 * worst.len().max(1) as u32 + 60;
        draw_png_and_svg(
            &stem,
            (1400, height),
            |a| draw_lines(a, &title, &models, &worst),
            |a| draw_lines(a, &title, &models, &worst),
        )
    }
}

/// One line's held-out predictions: `(position, measured, baseline, extended)`.
struct LinePredictions {
    condition: String,
    accel_mm_s2: f64,
    feed_mm_s: f64,
    samples: Vec<[f64; 4]>,
}

impl LinePredictions {
    fn rmse(&self, column: usize) -> f64 {
        let n = self.samples.len().max(1) as f64;
        (self.samples.iter().map(|s| (s[column] - s[1]).powi(2)).sum::<f64>() / n).sqrt()
    }
}

fn read_lines(path: &Path, printer: &str) -> Result<Vec<LinePredictions>, StageError> {
    use predictions as p;
    let df = read_parquet(path)?;
    let (printers, conditions) = (strs(&df, p::printer, path)?, strs(&df, p::condition, path)?);
    let (accel, feed, pos) =
        (f64s(&df, p::accel_mm_s2, path)?, f64s(&df, p::feed_mm_s, path)?, f64s(&df, p::position_mm, path)?);
    let (meas, base, ext) = (
        f64s(&df, p::measured_width_mm, path)?,
        f64s(&df, p::baseline_width_mm, path)?,
        f64s(&df, p::extended_width_mm, path)?,
    );
    let mut lines: Vec<LinePredictions> = Vec::new();
    for i in (0..df.height()).filter(|&i| printers[i] == printer) {
        if lines.last().is_none_or(|l| l.condition != conditions[i]) {
            lines.push(LinePredictions {
                condition: conditions[i].clone(),
                accel_mm_s2: accel[i],
                feed_mm_s: feed[i],
                samples: Vec::new(),
            });
        }
        if let Some(l) = lines.last_mut() {
            l.samples.push([pos[i], meas[i], base[i], ext[i]]);
        }
    }
    if lines.is_empty() {
        return Err(no_rows(path, p::printer, &format!("printer `{printer}`")));
    }
    Ok(lines)
}

/// The `count` lines with the highest baseline RMSE, worst first.
fn worst_lines(mut lines: Vec<LinePredictions>, count: usize) -> Vec<LinePredictions> {
    lines.sort_by(|a, b| b.rmse(2).total_cmp(&a.rmse(2)));
    lines.truncate(count);
    lines
}

fn draw_lines<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    models: &Models,
    lines: &[LinePredictions],
) -> Result<(), String> {
    let area = area.margin(12, 6, 6, 14).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    let panels = area.split_evenly((lines.len().max(1), 1));
    let y_max = lines
        .iter()
        .flat_map(|l| l.samples.iter().flat_map(|s| [s[1], s[2], s[3]]))
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        * 1.06;
    for (line, panel) in lines.iter().zip(&panels) {
        draw_line_panel(panel, line, models, y_max).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn draw_line_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    line: &LinePredictions,
    models: &Models,
    y_max: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let head = format!("{}: a = {} mm/s², F = {} mm/s", line.condition, line.accel_mm_s2, line.feed_mm_s);
    let baseline = models.baseline_words();
    let caption = if models.unchanged() {
        format!("{head}; held-out RMSE {:.3} mm ({baseline})", line.rmse(2))
    } else {
        format!("{head}; held-out RMSE {:.3} mm ({baseline}) → {:.3} mm", line.rmse(2), line.rmse(3))
    };
    let x_max = line.samples.last().map_or(1.0, |s| s[0]);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(17.0))
        .margin(8)
        .margin_right(20)
        .x_label_area_size(38)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..x_max, 0.0..y_max)?;
    draw_width_profile_mesh(&mut chart)?;
    let measured: Vec<(f64, f64)> = line.samples.iter().map(|s| (s[0], s[1])).collect();
    let mut series = vec![(2, BASELINE, format!("{} (held out)", models.baseline))];
    if !models.unchanged() {
        series.push((3, EXTENDED, format!("{} (held out)", models.extended)));
    }
    let grey = MEASURED.stroke_width(1);
    chart
        .draw_series(LineSeries::new(step_points(&measured), grey))?
        .label("measured")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], grey));
    for (column, colour, label) in series {
        let style = colour.stroke_width(2);
        chart
            .draw_series(LineSeries::new(line.samples.iter().map(|s| (s[0], s[column])), style))?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], style));
    }
    draw_house_legend(&mut chart, SeriesLabelPosition::UpperLeft)
}

impl Stage for DiscoveryPowerFigure {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_discovery_power",
        version: 2,
        summary: "Power curves of the discrepancy engine: share of draws naming a hidden effect against its strength, per base, with the null false-alarm rate → discovery_power.png/.svg",
        implements: "DESIGN §7 (tests that hide an effect and require finding it)",
        inputs: &[POWER],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let mut bases: Vec<PowerBase> = Vec::new();
        for input in ctx.inputs_of(&POWER) {
            for b in read_power(&input.dir.join(power::TABLE.file()))? {
                match bases.iter_mut().find(|x| x.base == b.base) {
                    Some(x) => {
                        x.curves.extend(b.curves);
                        x.null.extend(b.null);
                    }
                    None => bases.push(b),
                }
            }
        }
        let stem = ctx.output_path("discovery_power")?;
        let title =
            "How strong a hidden effect must be before the engine names it (surrogate draws of the measured lines)";
        draw_png_and_svg(&stem, (1500, 700), |a| draw_power(a, title, &bases), |a| draw_power(a, title, &bases))
    }
}

/// One base's curves.
struct PowerBase {
    base: String,
    own: String,
    /// Per (effect, noise): `(strength, rate, lo, hi)`.
    curves: BTreeMap<(String, String), Vec<[f64; 4]>>,
    /// Null draws per noise: noise, count, false-alarm rate and its upper bound.
    null: Vec<(String, i64, f64, f64)>,
}

fn read_power(path: &Path) -> Result<Vec<PowerBase>, StageError> {
    let df = read_parquet(path)?;
    let (bases, own, effects) =
        (strs(&df, power::base, path)?, strs(&df, power::own_causes, path)?, strs(&df, power::effect, path)?);
    let noise = strs(&df, power::noise, path)?;
    let (strength, rate) = (f64s(&df, power::strength, path)?, f64s(&df, power::correct_rate, path)?);
    let (lo, hi) = (f64s(&df, power::correct_ci_lo, path)?, f64s(&df, power::correct_ci_hi, path)?);
    let (fa, fa_hi, draws) = (
        f64s(&df, power::false_alarm_rate, path)?,
        f64s(&df, power::false_alarm_ci_hi, path)?,
        ints(&df, power::draws, path)?,
    );
    let mut out: Vec<PowerBase> = Vec::new();
    for i in 0..df.height() {
        if out.last().is_none_or(|b| b.base != bases[i]) {
            out.push(PowerBase {
                base: bases[i].clone(),
                own: own[i].clone(),
                curves: BTreeMap::new(),
                null: Vec::new(),
            });
        }
        let b = out.last_mut().expect("pushed");
        if effects[i] == "none" {
            b.null.push((noise[i].clone(), draws[i], fa[i], fa_hi[i]));
        } else {
            b.curves.entry((effects[i].clone(), noise[i].clone())).or_default().push([
                strength[i],
                rate[i],
                lo[i],
                hi[i],
            ]);
        }
    }
    if out.is_empty() {
        return Err(no_rows(path, power::base, "any base"));
    }
    Ok(out)
}

fn draw_power<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    bases: &[PowerBase],
) -> Result<(), String> {
    let area = area.margin(12, 6, 6, 14).titled(title, text(22.0)).map_err(|e| e.to_string())?;
    let (plots, key) = area.split_vertically(area.dim_in_pixel().1.saturating_sub(POWER_KEY_PX));
    let panels = plots.split_evenly((1, bases.len().max(1)));
    let x_max = bases.iter().flat_map(|b| b.curves.values().flatten().map(|p| p[0])).fold(0.0f64, f64::max) * 1.05;
    let effects: Vec<&String> = effect_names(bases);
    for (base, panel) in bases.iter().zip(&panels) {
        draw_power_panel(panel, base, &effects, x_max.max(1e-3)).map_err(|e| e.to_string())?;
    }
    draw_power_key(&key, &effects, bases).map_err(|e| e.to_string())
}

/// Height of the key below the panels (px).
const POWER_KEY_PX: u32 = 110;

/// The effects drawn, in colour order (sorted by name).
fn effect_names(bases: &[PowerBase]) -> Vec<&String> {
    let mut e: Vec<&String> = bases.iter().flat_map(|b| b.curves.keys().map(|k| &k.0)).collect();
    e.sort();
    e.dedup();
    e
}

/// The colour of the `k`-th effect.
fn effect_colour(k: usize) -> RGBColor {
    PALETTE[(k + 2) % PALETTE.len()]
}

/// One key for every panel: the effects' colours, the marker of the draws with
/// measurement noise only, the null draws' false-alarm bounds, and per base its null
/// draws' false-alarm rates.
fn draw_power_key<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    effects: &[&String],
    bases: &[PowerBase],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = text(15.0);
    let mut x = 60;
    for (k, e) in effects.iter().enumerate() {
        area.draw(&PathElement::new([(x, 18), (x + 30, 18)], effect_colour(k).stroke_width(3)))?;
        area.draw(&Text::new(e.to_string(), (x + 38, 10), style.clone()))?;
        x += 60 + 9 * e.len() as i32;
    }
    area.draw(&DashedPathElement::new([(x, 18), (x + 30, 18)], 6, 4, BLACK.stroke_width(2)))?;
    area.draw(&TriangleMarker::new((x + 15, 18), 6, BLACK.filled()))?;
    area.draw(&Text::new("measurement noise only (triangles, dashed between strengths)", (x + 38, 10), style.clone()))?;
    let y = 44;
    area.draw(&DashedPathElement::new([(60, y), (90, y)], 6, 4, BLACK.stroke_width(1)))?;
    area.draw(&DashedPathElement::new([(96, y), (126, y)], 6, 4, BLACK.mix(0.45).stroke_width(1)))?;
    let bound = "upper 95 % bound of the null draws' false-alarm rate (grey: measurement noise only)";
    area.draw(&Text::new(bound, (134, y - 8), style.clone()))?;
    for (k, b) in bases.iter().enumerate() {
        let nulls: Vec<String> = b
            .null
            .iter()
            .map(|(noise, n, rate, upper)| {
                let which = if noise == "white" { " with measurement noise only" } else { "" };
                format!("{:.1} % of {n} null draws{which} (≤ {:.1} %)", 100.0 * rate, 100.0 * upper)
            })
            .collect();
        let line = format!("{}: a cause beyond its own named in {}", b.base, nulls.join("; "));
        area.draw(&Text::new(line, (60, y + 16 + 22 * k as i32), style.clone()))?;
    }
    Ok(())
}

fn draw_power_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    base: &PowerBase,
    effects: &[&String],
    x_max: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let caption = if base.own == "none" {
        format!("{}, starting from lag_model (no cause of its own)", base.base)
    } else {
        format!("{}, starting from lag_model + {} (its own cause)", base.base, base.own)
    };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(17.0))
        .margin(10)
        .margin_right(20)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..x_max * 100.0, 0.0..1.02)?;
    house_mesh(&mut chart)
        .x_desc("strength of the hidden effect (%)")
        .y_desc("share of draws naming it")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.1}"))
        .draw()?;
    for ((effect, noise), points) in &base.curves {
        let k = effects.iter().position(|e| **e == *effect).unwrap_or(0);
        let colour = effect_colour(k);
        let style = colour.stroke_width(2);
        // Draws with measurement noise only sit beside their effect's colour, shifted a
        // little per effect so that coinciding rates stay visible.
        let shift = if noise == "white" { 0.006 * x_max * 100.0 * (k as f64 + 1.0) } else { 0.0 };
        chart.draw_series(
            points
                .iter()
                .map(move |p| PathElement::new([(100.0 * p[0] + shift, p[2]), (100.0 * p[0] + shift, p[3])], style)),
        )?;
        let curve = points.iter().map(move |p| (100.0 * p[0] + shift, p[1]));
        if noise == "white" {
            chart.draw_series(DashedLineSeries::new(curve, 6, 4, style))?;
            chart.draw_series(
                points.iter().map(move |p| TriangleMarker::new((100.0 * p[0] + shift, p[1]), 6, colour.filled())),
            )?;
        } else {
            chart.draw_series(LineSeries::new(curve, style).point_size(4))?;
        }
    }
    for (noise, _, _, upper) in &base.null {
        let dashed = if noise == "white" { BLACK.mix(0.45).stroke_width(1) } else { BLACK.stroke_width(1) };
        chart.draw_series(DashedLineSeries::new([(0.0, *upper), (x_max * 100.0, *upper)], 6, 4, dashed))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, declared, noise, write_declared};
    use polars::df;

    #[test]
    fn worst_lines_are_ordered_by_baseline_rmse() {
        let line = |c: &str, err: f64| LinePredictions {
            condition: c.into(),
            accel_mm_s2: 1.0,
            feed_mm_s: 1.0,
            samples: vec![[0.0, 1.0, 1.0 + err, 1.0]],
        };
        let worst = worst_lines(vec![line("a", 0.1), line("b", 0.3), line("c", 0.2)], 2);
        let names: Vec<&str> = worst.iter().map(|l| l.condition.as_str()).collect();
        assert_eq!(names, ["b", "c"]);
        assert!((worst[0].rmse(2) - 0.3).abs() < 1e-12 && worst[0].rmse(3) == 0.0);
    }

    #[test]
    fn draws_the_lines_and_power_figures_from_their_tables() {
        let dir = tempfile::tempdir().unwrap();
        let (mut pos, mut meas, mut base, mut ext, mut cond) = (vec![], vec![], vec![], vec![], vec![]);
        for (k, c) in ["S400F3000", "S800F9000"].iter().enumerate() {
            for i in 0..=600 {
                let x = i as f64 * 0.2;
                let w = 0.8 + 0.3 * (-(120.0 - x) / 3.0).exp() + 0.01 * noise(i + 1000 * k);
                pos.push(x);
                meas.push(w);
                base.push(0.8 + 0.9 * (-(120.0 - x) / 2.0).exp());
                ext.push(0.8 + 0.3 * (-(120.0 - x) / 3.0).exp());
                cond.push(c.to_string());
            }
        }
        let n = pos.len();
        use predictions as pred;
        let lines = df!(
            pred::printer => vec!["taz5"; n], pred::condition => cond, pred::accel_mm_s2 => vec![400.0; n],
            pred::feed_mm_s => vec![50.0; n], pred::position_mm => pos, pred::measured_width_mm => meas,
            pred::baseline_width_mm => base, pred::extended_width_mm => ext)
        .unwrap();
        write_declared(dir.path(), &pred::TABLE, lines);
        let gains = df!(gain::printer => ["taz5"], gain::baseline => ["piecewise_model"],
            gain::extended_model => ["piecewise_model + bed_tilt"])
        .unwrap();
        write_declared(dir.path(), &gain::TABLE, declared(&gain::TABLE, gains));
        let study = df!(
            power::base => ["taz5"; 4], power::noise => ["measured", "measured", "measured", "white"],
            power::own_causes => ["width_cap"; 4], power::effect => ["none", "bed_tilt", "bed_tilt", "gear_eccentricity"],
            power::strength => [0.0, 0.02, 0.1, 0.05], power::draws => [100i64, 20, 20, 20],
            power::correct_rate => [0.0, 0.1, 0.9, 0.6], power::correct_ci_lo => [0.0, 0.01, 0.7, 0.4],
            power::correct_ci_hi => [0.04, 0.3, 0.99, 0.8], power::false_alarm_rate => [0.01, 0.0, 0.0, 0.05],
            power::false_alarm_ci_hi => [0.05, 0.17, 0.17, 0.25])
        .unwrap();
        write_declared(dir.path(), &power::TABLE, declared(&power::TABLE, study));
        let out = tempfile::tempdir().unwrap();
        let lines = worst_lines(read_lines(&dir.path().join(predictions::TABLE.file()), "taz5").unwrap(), 2);
        let models = Models::read(&dir.path().join(gain::TABLE.file()), &fdm::ENGINE, "taz5").unwrap();
        assert_eq!((models.baseline_words().as_str(), models.unchanged()), ("piecewise model", false));
        let stem = out.path().join("l");
        draw_png_and_svg(
            &stem,
            (1400, 900),
            |a| draw_lines(a, "t", &models, &lines),
            |a| draw_lines(a, "t", &models, &lines),
        )
        .unwrap();
        assert_drawn(&stem);
        let bases = read_power(&dir.path().join(power::TABLE.file())).unwrap();
        assert_eq!(bases[0].null, vec![("measured".to_string(), 100, 0.01, 0.05)]);
        let stem = out.path().join("p");
        draw_png_and_svg(&stem, (1500, 620), |a| draw_power(a, "t", &bases), |a| draw_power(a, "t", &bases)).unwrap();
        assert_drawn(&stem);
        assert!(read_lines(&dir.path().join(predictions::TABLE.file()), "taz6").is_err());
    }
}
