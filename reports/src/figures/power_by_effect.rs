//! `figure.discovery_power_by_effect`: a power study's curves, one panel per hidden
//! effect on its own strength axis (strengths of different effects are in different
//! units and cannot share one): the share of draws in which the engine names the effect
//! (its Clopper–Pearson 95 % interval as bars), the share naming a wrong cause, and the
//! upper 95 % bound of the null draws' false-alarm rate as a line. Reads any
//! `*.discovery_power` stage's `power.parquet` (DESIGN §7).

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::discrepancy::power;

use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_png_and_svg, house_mesh, text, PALETTE};

/// The `figure.discovery_power_by_effect` stage kind.
pub struct DiscoveryPowerByEffectFigure;

pipeline::params! {
    /// The parameters of `figure.discovery_power_by_effect`.
    pub struct PowerByEffectParams {
        /// Figure title.
        pub title: String = "How strong a hidden effect must be before the engine names it",
    }
}

/// The power study drawn: any domain's (their `power.parquet` share its columns).
const POWER: Input = Input::one(
    "power",
    &[
        Source::Stage("inkjet.discovery_power"),
        Source::Stage("thermal.discovery_power"),
        Source::Stage("fdm.discovery_power"),
    ],
    "a power study's rates per effect and strength (`power.parquet`)",
)
.reading(&[Reads {
    table: &power::TABLE,
    columns: &[
        power::base,
        power::effect,
        power::strength,
        power::draws,
        power::correct_rate,
        power::correct_ci_lo,
        power::correct_ci_hi,
        power::false_alarm_rate,
        power::false_alarm_ci_hi,
    ],
}]);

impl Stage for DiscoveryPowerByEffectFigure {
    type Params = PowerByEffectParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.discovery_power_by_effect",
        version: 1,
        summary: "A power study's curves, one panel per hidden effect on its own strength axis, with the null draws' false-alarm bound → discovery_power.png/.svg",
        implements: "DESIGN §7 (tests that hide an effect and require finding it)",
        inputs: &[POWER],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &PowerByEffectParams) -> Result<(), StageError> {
        let study = Study::read(&ctx.input(&POWER).dir.join(power::TABLE.file()))?;
        let title = p.title.clone();
        let columns = study.curves.len().clamp(1, 4);
        let rows = study.curves.len().div_ceil(columns).max(1);
        let size = (420 * columns as u32 + 40, 360 * rows as u32 + 120);
        let stem = ctx.output_path("discovery_power")?;
        draw_png_and_svg(&stem, size, |a| draw(a, &title, &study, columns), |a| draw(a, &title, &study, columns))
    }
}

/// One effect's points: `(strength, named, named_lo, named_hi, wrong)` per strength.
struct Curve {
    effect: String,
    points: Vec<[f64; 5]>,
    draws: i64,
}

/// A study: its base, its null draws and a curve per effect.
struct Study {
    base: String,
    null: Option<(i64, f64, f64)>,
    curves: Vec<Curve>,
}

impl Study {
    fn read(path: &std::path::Path) -> Result<Self, StageError> {
        let df = read_parquet(path)?;
        let (base, effect) = (strs(&df, power::base, path)?, strs(&df, power::effect, path)?);
        let (strength, draws) = (f64s(&df, power::strength, path)?, ints(&df, power::draws, path)?);
        let (rate, lo, hi) = (
            f64s(&df, power::correct_rate, path)?,
            f64s(&df, power::correct_ci_lo, path)?,
            f64s(&df, power::correct_ci_hi, path)?,
        );
        let (fa, fa_hi) = (f64s(&df, power::false_alarm_rate, path)?, f64s(&df, power::false_alarm_ci_hi, path)?);
        if df.height() == 0 {
            return Err(no_rows(path, power::effect, "any effect"));
        }
        let mut study = Study { base: base[0].clone(), null: None, curves: Vec::new() };
        for i in 0..df.height() {
            if effect[i] == "none" {
                study.null = Some((draws[i], fa[i], fa_hi[i]));
                continue;
            }
            let point = [strength[i], rate[i], lo[i], hi[i], fa[i]];
            match study.curves.iter_mut().find(|c| c.effect == effect[i]) {
                Some(c) => {
                    c.points.push(point);
                    c.draws += draws[i];
                }
                None => study.curves.push(Curve { effect: effect[i].clone(), points: vec![point], draws: draws[i] }),
            }
        }
        Ok(study)
    }
}

fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    study: &Study,
    columns: usize,
) -> Result<(), String> {
    let area = area.margin(10, 6, 6, 10).titled(title, text(21.0)).map_err(|e| e.to_string())?;
    let (plots, key) = area.split_vertically(area.dim_in_pixel().1.saturating_sub(64));
    let rows = study.curves.len().div_ceil(columns).max(1);
    let panels = plots.split_evenly((rows, columns));
    for (curve, panel) in study.curves.iter().zip(&panels) {
        draw_panel(panel, curve, study.null).map_err(|e| e.to_string())?;
    }
    draw_key(&key, study).map_err(|e| e.to_string())
}

const NAMED: RGBColor = PALETTE[0];
const WRONG: RGBColor = PALETTE[1];

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    curve: &Curve,
    null: Option<(i64, f64, f64)>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let x_max = curve.points.iter().map(|p| p[0]).fold(0.0f64, f64::max) * 1.15;
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{} ({} draws)", curve.effect.replace('_', " "), curve.draws), text(16.0))
        .margin(8)
        .margin_right(16)
        .x_label_area_size(38)
        .y_label_area_size(48)
        .build_cartesian_2d(0.0..x_max.max(1e-9), 0.0..1.02)?;
    house_mesh(&mut chart)
        .x_desc("strength")
        .y_desc("share of draws")
        .x_labels(5)
        .x_label_formatter(&|x| format_strength(*x))
        .y_label_formatter(&|y| format!("{y:.1}"))
        .draw()?;
    if let Some((_, _, bound)) = null {
        chart.draw_series(DashedLineSeries::new(
            [(0.0, bound), (x_max, bound)],
            5,
            4,
            BLACK.mix(0.6).stroke_width(1),
        ))?;
    }
    let named = NAMED.stroke_width(2);
    chart.draw_series(curve.points.iter().map(|p| PathElement::new([(p[0], p[2]), (p[0], p[3])], named)))?;
    chart.draw_series(LineSeries::new(curve.points.iter().map(|p| (p[0], p[1])), named))?;
    chart.draw_series(curve.points.iter().map(|p| Circle::new((p[0], p[1]), 4, NAMED.filled())))?;
    let wrong = WRONG.stroke_width(2);
    chart.draw_series(DashedLineSeries::new(curve.points.iter().map(|p| (p[0], p[4])), 6, 4, wrong))?;
    chart.draw_series(curve.points.iter().map(|p| TriangleMarker::new((p[0], p[4]), 5, WRONG.filled())))?;
    Ok(())
}

/// Strengths span µs to tens: three significant digits, no trailing zeros.
fn format_strength(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let digits = (2 - x.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{x:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

fn draw_key<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    study: &Study,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = text(14.0);
    area.draw(&PathElement::new([(50, 14), (80, 14)], NAMED.stroke_width(2)))?;
    area.draw(&Text::new("effect named (bars: 95 % interval)", (88, 6), style.clone()))?;
    area.draw(&PathElement::new([(360, 14), (390, 14)], WRONG.stroke_width(2)))?;
    area.draw(&Text::new("a wrong cause named", (398, 6), style.clone()))?;
    let null = match study.null {
        Some((n, rate, bound)) => format!(
            "{}: a cause named in {:.1} % of {n} null draws (dashed grey: its upper 95 % bound, {:.1} %)",
            study.base,
            100.0 * rate,
            100.0 * bound
        ),
        None => format!("{}: no null draws", study.base),
    };
    area.draw(&Text::new(null, (50, 34), style))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::format_strength;

    #[test]
    fn strengths_print_with_three_significant_digits() {
        assert_eq!(format_strength(0.005), "0.005");
        assert_eq!(format_strength(0.0125), "0.0125");
        assert_eq!(format_strength(0.3), "0.3");
        assert_eq!(format_strength(12.5), "12.5");
        assert_eq!(format_strength(0.0), "0");
    }
}
