//! `report.discrepancy_fdm`: what the lag model gets wrong on paper 000's real lines,
//! the cause the discrepancy engine names, the extended model and its held-out gain,
//! and how strong a hidden effect must be before the engine names it (DESIGN §7).
//! Every number is read from the tables of `fdm.discrepancy` and `fdm.discovery_power`.
//!
//! Inputs: the `fdm.discrepancy` stage, then one or more `fdm.discovery_power` stages
//! (measured noise, and optionally measurement noise only).

use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::NoParams;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
// The columns every domain names alike are read through the FDM declarations (one
// template declares every domain's: `tables::discrepancy`), those carrying a domain's
// data-set column or unit through its `Engine` (`Names::engine`).
use tables::discrepancy::fdm::{causes, extension, gain, residuals};
use tables::discrepancy::{power, Engine};
use tables::report::comparison;

use super::{comparison_frame, Row};
use crate::html::{escape, format_sig};
use crate::read::{bools, f64s, ints, read_parquet, strs};

/// The `report.discrepancy_fdm` stage kind.
pub struct DiscrepancyFdmSection;

/// What [`Cause::read`], [`Param::read`] and [`GainRow::read`] read of a domain's
/// engine tables (`tables::discrepancy::<domain>`), then `extra` reads, for the input
/// role of its section.
macro_rules! engine_reads {
    ($domain:ident $(, $extra:expr)* $(,)?) => {{
        use tables::discrepancy::$domain::{causes, extension, gain, ENGINE};
        &[
            pipeline::schema::Reads {
                table: &causes::TABLE,
                columns: &[
                    ENGINE.set,
                    causes::base_model,
                    causes::mechanism,
                    causes::verdict,
                    causes::round,
                    causes::groups_helped,
                    causes::groups,
                    ENGINE.cv_rmse_before,
                    ENGINE.cv_rmse_after,
                    causes::gain_pct,
                    causes::gain_ci_lo_pct,
                    causes::gain_ci_hi_pct,
                    causes::p_value,
                    causes::p_adjusted,
                    causes::alpha,
                    causes::named,
                ],
            },
            pipeline::schema::Reads {
                table: &extension::TABLE,
                columns: &[
                    ENGINE.set,
                    extension::mechanism,
                    extension::parameter,
                    extension::unit,
                    extension::meaning,
                    extension::estimate,
                    extension::ci_lo,
                    extension::ci_hi,
                ],
            },
            pipeline::schema::Reads {
                table: &gain::TABLE,
                columns: &[
                    ENGINE.set,
                    gain::extended_model,
                    gain::groups,
                    ENGINE.rmse_before,
                    ENGINE.rmse_after,
                    gain::gain_pct,
                    gain::gain_ci_lo_pct,
                    gain::gain_ci_hi_pct,
                ],
            },
            $($extra,)*
        ]
    }};
}
pub(super) use engine_reads;

/// What [`Structure::read`] reads of a domain's `residuals.parquet`, as an extra
/// [`engine_reads!`] entry.
macro_rules! structure_reads {
    ($domain:ident) => {{
        use tables::discrepancy::$domain::{residuals, ENGINE};
        pipeline::schema::Reads {
            table: &residuals::TABLE,
            columns: &[ENGINE.set, residuals::model, residuals::variable, residuals::structure],
        }
    }};
}
pub(super) use structure_reads;

/// The engine run on the lag model.
const DISCREPANCY: Input = Input::one(
    "discrepancy",
    &[Source::Stage("fdm.discrepancy")],
    "the causes, extension, gain and residual structure of the lag model (`causes.parquet`, `extension.parquet`, `gain.parquet`, `residuals.parquet`)",
)
.reading(engine_reads!(fdm, structure_reads!(fdm)));

/// The power studies and the engine runs on other baselines, told apart by their tables
/// (a power study writes no `causes`, an engine run no `power`), each checked for what
/// is read from its kind.
const OTHERS: Input = Input::many(
    "others",
    1,
    &[Source::Stage("fdm.discovery_power"), Source::Stage("fdm.discrepancy")],
    "power studies (`power.parquet`) and engine runs on another baseline (`causes.parquet`), in any order",
)
.reading_by_kind(&[("fdm.discovery_power", POWER_READS), ("fdm.discrepancy", engine_reads!(fdm))]);

/// What [`PowerRow::read`] reads of a power study, any domain's.
pub(super) const POWER_READS: &[Reads] = &[Reads {
    table: &power::TABLE,
    columns: &[
        power::base,
        power::own_causes,
        power::effect,
        power::noise,
        power::strength,
        power::draws,
        power::wrong,
        power::covered,
        power::with_interval,
        power::correct_rate,
        power::correct_ci_lo,
        power::correct_ci_hi,
        power::false_alarm_rate,
        power::false_alarm_ci_lo,
        power::false_alarm_ci_hi,
    ],
}];

impl Stage for DiscrepancyFdmSection {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.discrepancy_fdm",
        version: 2,
        summary: "What the lag model gets wrong on the measured lines, the cause named, the extension and its gain, and the engine's power → section.html, comparison.parquet",
        implements: "DESIGN §7 on paper 000's Taz 5 / Taz 6 data",
        inputs: &[DISCREPANCY, OTHERS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let discrepancy = ctx.input(&DISCREPANCY);
        let dir = &discrepancy.dir;
        let causes = Cause::read(dir, &FDM)?;
        let params = Param::read(dir, &FDM)?;
        let gains = GainRow::read(dir, &FDM)?;
        let structure = Structure::read(dir, &FDM)?;
        // The other inputs: power studies (power.parquet), and engine runs on another
        // baseline (causes.parquet without power.parquet).
        let (mut power_rows, mut power_stages, mut other_baselines) = (Vec::new(), Vec::new(), Vec::new());
        for input in ctx.inputs_of(&OTHERS) {
            if input.dir.join(power::TABLE.file()).exists() || !input.dir.join(causes::TABLE.file()).exists() {
                power_rows.extend(PowerRow::read(&input.dir)?);
                power_stages.push(input.name.as_str());
            } else {
                other_baselines.push(input);
            }
        }
        let stage = discrepancy.name.clone();
        let power_stage = power_stages.join(", ");
        let mut html = String::from("<h3>What the lag model gets wrong, and why</h3>\n");
        html += &method(&causes);
        let mut rows = Vec::new();
        for g in &gains {
            html += &printer_part(g, &causes, &params, &structure, &stage, &mut rows);
        }
        for input in other_baselines {
            html += &other_baseline_part(&input.dir, &input.name, &mut rows)?;
        }
        html += &power_part(&power_rows, &power_stage, &mut rows);
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

/// A domain's discrepancy tables and the words its section uses.
pub(super) struct Names {
    /// Its engine tables (`tables::discrepancy::<domain>::ENGINE`).
    pub(super) engine: &'static Engine,
    /// The unit of residuals and RMSEs in the comparison table (`mm`, `um`, `sd`).
    pub(super) unit: &'static str,
    /// The same as printed (`mm`, `µm`).
    pub(super) unit_label: &'static str,
    /// What a group is, plural (`lines`, `layer blocks`).
    pub(super) groups: &'static str,
}

/// The FDM tables: one discovery per printer, widths in mm, a group is a line.
const FDM: Names = Names { engine: &tables::discrepancy::fdm::ENGINE, unit: "mm", unit_label: "mm", groups: "lines" };

/// A row of `causes.parquet`.
pub(super) struct Cause {
    pub(super) printer: String,
    pub(super) round: i64,
    pub(super) base_model: String,
    pub(super) mechanism: String,
    pub(super) before: f64,
    pub(super) after: f64,
    pub(super) gain: (f64, f64, f64),
    pub(super) helped: i64,
    pub(super) groups: i64,
    pub(super) p: f64,
    pub(super) p_adjusted: f64,
    pub(super) alpha: f64,
    /// The smallest held-out gain worth naming the test asked for, %.
    pub(super) min_gain_pct: f64,
    pub(super) named: bool,
    pub(super) verdict: String,
}

impl Cause {
    /// The rows of `causes.parquet` in `dir`, a stage of the domain of `names`.
    pub(super) fn read(dir: &Path, names: &Names) -> Result<Vec<Self>, StageError> {
        use causes as c;
        let engine = names.engine;
        let path = &dir.join(engine.causes.file());
        let df = read_parquet(path)?;
        let (printer, base, mechanism, verdict) = (
            strs(&df, engine.set, path)?,
            strs(&df, c::base_model, path)?,
            strs(&df, c::mechanism, path)?,
            strs(&df, c::verdict, path)?,
        );
        let (round, helped, groups) =
            (ints(&df, c::round, path)?, ints(&df, c::groups_helped, path)?, ints(&df, c::groups, path)?);
        let (before, after) = (f64s(&df, engine.cv_rmse_before, path)?, f64s(&df, engine.cv_rmse_after, path)?);
        let (gain, lo, hi) =
            (f64s(&df, c::gain_pct, path)?, f64s(&df, c::gain_ci_lo_pct, path)?, f64s(&df, c::gain_ci_hi_pct, path)?);
        let (p, padj, alpha) =
            (f64s(&df, c::p_value, path)?, f64s(&df, c::p_adjusted, path)?, f64s(&df, c::alpha, path)?);
        let (min_gain_pct, named) = (f64s(&df, c::min_gain_pct, path)?, bools(&df, c::named, path)?);
        Ok((0..df.height())
            .map(|i| Self {
                printer: printer[i].clone(),
                round: round[i],
                base_model: base[i].clone(),
                mechanism: mechanism[i].clone(),
                before: before[i],
                after: after[i],
                gain: (gain[i], lo[i], hi[i]),
                helped: helped[i],
                groups: groups[i],
                p: p[i],
                p_adjusted: padj[i],
                alpha: alpha[i],
                min_gain_pct: min_gain_pct[i],
                named: named[i],
                verdict: verdict[i].clone(),
            })
            .collect())
    }
}

/// A row of `extension.parquet`.
pub(super) struct Param {
    pub(super) printer: String,
    pub(super) mechanism: String,
    pub(super) parameter: String,
    pub(super) unit: String,
    pub(super) estimate: f64,
    pub(super) ci: (f64, f64),
    pub(super) meaning: String,
}

impl Param {
    /// The rows of `extension.parquet` in `dir`, a stage of the domain of `names`.
    pub(super) fn read(dir: &Path, names: &Names) -> Result<Vec<Self>, StageError> {
        use extension as e;
        let engine = names.engine;
        let path = &dir.join(engine.extension.file());
        let df = read_parquet(path)?;
        let (printer, mechanism, parameter, unit, meaning) = (
            strs(&df, engine.set, path)?,
            strs(&df, e::mechanism, path)?,
            strs(&df, e::parameter, path)?,
            strs(&df, e::unit, path)?,
            strs(&df, e::meaning, path)?,
        );
        let (estimate, lo, hi) =
            (f64s(&df, e::estimate, path)?, f64s(&df, e::ci_lo, path)?, f64s(&df, e::ci_hi, path)?);
        Ok((0..df.height())
            .map(|i| Self {
                printer: printer[i].clone(),
                mechanism: mechanism[i].clone(),
                parameter: parameter[i].clone(),
                unit: unit[i].clone(),
                estimate: estimate[i],
                ci: (lo[i], hi[i]),
                meaning: meaning[i].clone(),
            })
            .collect())
    }
}

/// A row of `gain.parquet`.
pub(super) struct GainRow {
    pub(super) printer: String,
    pub(super) extended: String,
    pub(super) groups: i64,
    pub(super) before: f64,
    pub(super) after: f64,
    pub(super) gain: (f64, f64, f64),
}

impl GainRow {
    /// The rows of `gain.parquet` in `dir`, a stage of the domain of `names`.
    pub(super) fn read(dir: &Path, names: &Names) -> Result<Vec<Self>, StageError> {
        use gain as g;
        let engine = names.engine;
        let path = &dir.join(engine.gain.file());
        let df = read_parquet(path)?;
        let (printer, extended) = (strs(&df, engine.set, path)?, strs(&df, g::extended_model, path)?);
        let groups = ints(&df, g::groups, path)?;
        let (before, after) = (f64s(&df, engine.rmse_before, path)?, f64s(&df, engine.rmse_after, path)?);
        let (gain, lo, hi) =
            (f64s(&df, g::gain_pct, path)?, f64s(&df, g::gain_ci_lo_pct, path)?, f64s(&df, g::gain_ci_hi_pct, path)?);
        Ok((0..df.height())
            .map(|i| Self {
                printer: printer[i].clone(),
                extended: extended[i].clone(),
                groups: groups[i],
                before: before[i],
                after: after[i],
                gain: (gain[i], lo[i], hi[i]),
            })
            .collect())
    }
}

/// One variable's structure share per (data set, model) of a domain's `residuals.parquet`.
pub(super) struct Structure {
    set: String,
    model: String,
    variable: String,
    share: f64,
}

impl Structure {
    /// Reads `names`' residual table in `dir`, one row per (data set, model, variable).
    /// The columns other than the data set's are named alike in every domain.
    pub(super) fn read(dir: &Path, names: &Names) -> Result<Vec<Self>, StageError> {
        use residuals as r;
        let path = dir.join(names.engine.residuals.file());
        let df = read_parquet(&path)?;
        let (set, model, variable) =
            (strs(&df, names.engine.set, &path)?, strs(&df, r::model, &path)?, strs(&df, r::variable, &path)?);
        let share = f64s(&df, r::structure, &path)?;
        let mut out: Vec<Self> = Vec::new();
        for i in 0..df.height() {
            let seen = out.iter().any(|s| s.set == set[i] && s.model == model[i] && s.variable == variable[i]);
            if !seen {
                out.push(Self {
                    set: set[i].clone(),
                    model: model[i].clone(),
                    variable: variable[i].clone(),
                    share: share[i],
                });
            }
        }
        Ok(out)
    }

    /// The sentence naming the variable the baseline's held-out residuals of `set` carry
    /// the most structure against, with its share after the extension when `extended`
    /// (empty when the table has no row of `set`); `whose` names the baseline (`Its`).
    pub(super) fn strongest(structure: &[Self], set: &str, extended: bool, whose: &str) -> String {
        let strongest = structure
            .iter()
            .filter(|s| s.set == set && s.model == "baseline")
            .max_by(|a, b| a.share.total_cmp(&b.share));
        strongest.map_or(String::new(), |s| {
            let after = structure
                .iter()
                .find(|t| t.set == set && t.model == "extended" && t.variable == s.variable)
                .map_or(f64::NAN, |t| t.share);
            let after = if extended { format!(" ({:.0} % after the extension)", 100.0 * after) } else { String::new() };
            if (100.0 * s.share).round() == 0.0 {
                return format!(
                    " {whose} held-out residuals carry no structure against any variable: the largest share of their sum of squares that a variable's bin means explain, against <code>{}</code>, is under 0.5 %.",
                    escape(&s.variable)
                );
            }
            format!(
                " {whose} held-out residuals carry the most structure against <code>{}</code>: the bin means there explain {:.0} % of the residual sum of squares{after}.",
                escape(&s.variable),
                100.0 * s.share,
            )
        })
    }
}

/// A row of `power.parquet`.
pub(super) struct PowerRow {
    pub(super) base: String,
    pub(super) noise: String,
    pub(super) own: String,
    pub(super) effect: String,
    pub(super) strength: f64,
    pub(super) draws: i64,
    pub(super) correct: (f64, f64, f64),
    pub(super) wrong: i64,
    pub(super) false_alarm: (f64, f64, f64),
    pub(super) covered: i64,
    pub(super) with_interval: i64,
}

impl PowerRow {
    /// The rows of `power.parquet` in `dir`, any domain's power study.
    pub(super) fn read(dir: &Path) -> Result<Vec<Self>, StageError> {
        use power as p;
        let path = &dir.join(p::TABLE.file());
        let df = read_parquet(path)?;
        let (base, own, effect) =
            (strs(&df, p::base, path)?, strs(&df, p::own_causes, path)?, strs(&df, p::effect, path)?);
        let noise = strs(&df, p::noise, path)?;
        let strength = f64s(&df, p::strength, path)?;
        let (draws, wrong, covered, with) = (
            ints(&df, p::draws, path)?,
            ints(&df, p::wrong, path)?,
            ints(&df, p::covered, path)?,
            ints(&df, p::with_interval, path)?,
        );
        let (rate, lo, hi) =
            (f64s(&df, p::correct_rate, path)?, f64s(&df, p::correct_ci_lo, path)?, f64s(&df, p::correct_ci_hi, path)?);
        let (fa, fa_lo, fa_hi) = (
            f64s(&df, p::false_alarm_rate, path)?,
            f64s(&df, p::false_alarm_ci_lo, path)?,
            f64s(&df, p::false_alarm_ci_hi, path)?,
        );
        Ok((0..df.height())
            .map(|i| Self {
                base: base[i].clone(),
                noise: noise[i].clone(),
                own: own[i].clone(),
                effect: effect[i].clone(),
                strength: strength[i],
                draws: draws[i],
                correct: (rate[i], lo[i], hi[i]),
                wrong: wrong[i],
                false_alarm: (fa[i], fa_lo[i], fa_hi[i]),
                covered: covered[i],
                with_interval: with[i],
            })
            .collect())
    }
}

fn method(causes: &[Cause]) -> String {
    let alpha = causes.first().map_or(f64::NAN, |c| c.alpha);
    let groups = causes.first().map_or(0, |c| c.groups);
    format!(
        "<p>The lag model of the paper-000 reproduction (mass conservation with a first-order extrusion lag and a start blob) is extended in turn by each of seven \
named physical mechanisms — a tilted bed, a drive gear's runout ripple, flow lost at high flow, a flow-dependent lag, a second slower lag path, a cap on the extra width \
the bead takes, and actual acceleration and feed off the G-code's — and every candidate is scored by leave-one-line-out cross-validation on the {groups} printed lines \
of a printer. Each held-out line contributes the log ratio of its squared error before and after; a one-sided sign-flip test over lines gives each candidate a p-value, \
Holm's step-down holds the family-wise false-alarm rate of a round at α = {alpha}, and the cause named is the significant candidate with the largest held-out gain. \
The extended model then becomes the baseline and the search repeats. A gear's phase belongs to one line only: it is estimated on one half of the held-out line and \
scored on the other. Parameter intervals are delete-one-line jackknife intervals of the cross-validation's own fits; gain intervals are a bootstrap over lines.</p>\n"
    )
}

fn printer_part(
    g: &GainRow,
    causes: &[Cause],
    params: &[Param],
    structure: &[Structure],
    stage: &str,
    rows: &mut Vec<Row>,
) -> String {
    let printer = &g.printer;
    let mine: Vec<&Cause> = causes.iter().filter(|c| &c.printer == printer).collect();
    let source = format!("out/discrepancy/causes.parquet (stage {stage}, fdm.discrepancy)");
    let mut html = format!("<h4>{}</h4>\n", escape(&printer_name(printer)));
    html += &finding(g, &mine, structure);
    html += &causes_table(&mine, &FDM);
    html += &parameter_table(params.iter().filter(|p| &p.printer == printer));
    let _ = writeln!(
        html,
        "<p class=\"run\">Run discrepancy_fdm, stage {stage} (fdm.discrepancy): tables out/discrepancy/causes.parquet, extension.parquet, gain.parquet, residuals.parquet.</p>"
    );
    for (item, value, unit) in [
        ("held-out rmse, lag model", g.before, "mm"),
        ("held-out rmse, extended model", g.after, "mm"),
        ("held-out gain", g.gain.0, "%"),
        ("held-out gain, 95 % lower bound", g.gain.1, "%"),
        ("held-out gain, 95 % upper bound", g.gain.2, "%"),
    ] {
        rows.push(Row {
            section: "discrepancy_fdm",
            item: format!("{printer} {item} ({})", g.extended),
            paper: None,
            ours: value,
            unit,
            source: source.replace("causes.parquet", "gain.parquet"),
        });
    }
    html
}

fn printer_name(printer: &str) -> String {
    match printer {
        "taz5" => "LulzBot Taz 5 (source printer of paper 000)".into(),
        "taz6" => "LulzBot Taz 6 (target printer of paper 000)".into(),
        other => other.into(),
    }
}

/// The paragraph that says what was found, in computed numbers.
fn finding(g: &GainRow, causes: &[&Cause], structure: &[Structure]) -> String {
    let shows = Structure::strongest(structure, &g.printer, causes.iter().any(|c| c.named), "Its");
    let first = causes.iter().find(|c| c.round == 1);
    let rmse = first.map_or(g.before, |c| c.before);
    let mut text = format!(
        "<p>Predicted from the commanded kinematics only, the lag model misses the {} measured lines by a held-out RMSE of {rmse:.4} mm.{shows}",
        g.groups
    );
    let named: Vec<&&Cause> = causes.iter().filter(|c| c.named).collect();
    for c in &named {
        let _ = write!(
            text,
            " In round {}, <b>{}</b> lowers the held-out RMSE of {} from {:.4} to {:.4} mm ({:+.1} %, 95 % interval {:+.1} to {:+.1} %), helping {} of {} lines; \
its Holm-adjusted p-value is {:.4}.",
            c.round,
            escape(&c.mechanism),
            escape(&c.base_model),
            c.before,
            c.after,
            c.gain.0,
            c.gain.1,
            c.gain.2,
            c.helped,
            c.groups,
            c.p_adjusted
        );
    }
    let last_round = causes.iter().map(|c| c.round).max().unwrap_or(0);
    let last: Vec<&&Cause> = causes.iter().filter(|c| c.round == last_round).collect();
    if let Some(verdict) = last.first().map(|c| c.verdict.as_str()).filter(|v| *v != "named") {
        let best = last.iter().max_by(|a, b| a.gain.0.total_cmp(&b.gain.0));
        let reason = match verdict {
            "too_few_groups" => "there are too few lines for any candidate to reach the corrected level".to_string(),
            _ => best.map_or("no candidate is significant".into(), |b| {
                format!(
                    "no {}candidate is significant (the best, {}, changes the held-out RMSE by {:+.1} % with adjusted p = {:.3})",
                    if last_round > 1 { "further " } else { "" },
                    escape(&b.mechanism),
                    b.gain.0,
                    b.p_adjusted
                )
            }),
        };
        let _ = write!(text, " In round {last_round} {reason}.");
    }
    if named.is_empty() {
        text += " <b>No significant discrepancy</b> is named: what the lag model gets wrong here is not one of the candidate mechanisms.";
    } else {
        let _ = write!(
            text,
            " Over all rounds the held-out RMSE falls from {:.4} to {:.4} mm, a gain of {:.1} % (95 % interval {:.1} to {:.1} %, bootstrap over lines).",
            g.before, g.after, g.gain.0, g.gain.1, g.gain.2
        );
    }
    text + "</p>\n"
}

pub(super) fn causes_table(causes: &[&Cause], names: &Names) -> String {
    let (unit, groups) = (names.unit_label, names.groups);
    let mut html = format!(
        "<table><tr><th>round</th><th class=\"t\">candidate</th><th>held-out RMSE before ({unit})</th><th>after ({unit})</th><th>gain (%)</th><th>95 % interval (%)</th><th>{groups} helped</th><th>p</th><th>p, Holm</th><th class=\"t\">outcome</th></tr>\n",
    );
    for c in causes {
        let verdict = if c.named {
            "named"
        } else if c.p_adjusted <= c.alpha {
            "significant, smaller gain"
        } else {
            "not significant"
        };
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td class=\"t\">{}{}</td><td>{:.4}</td><td>{:.4}</td><td>{:+.2}</td><td>{:+.1} to {:+.1}</td><td>{} / {}</td><td>{:.4}</td><td>{:.4}</td><td class=\"t\">{}</td></tr>",
            c.round,
            if c.named { "<b>" } else { "" },
            escape(&c.mechanism) + if c.named { "</b>" } else { "" },
            c.before,
            c.after,
            c.gain.0,
            c.gain.1,
            c.gain.2,
            c.helped,
            c.groups,
            c.p,
            c.p_adjusted,
            verdict
        );
    }
    html + "</table>\n"
}

pub(super) fn parameter_table<'a>(params: impl Iterator<Item = &'a Param>) -> String {
    let mut html = String::from(
        "<table><tr><th class=\"t\">model part</th><th class=\"t\">parameter</th><th>estimate</th><th>95 % interval</th><th class=\"t\">unit</th><th class=\"t\">meaning</th></tr>\n",
    );
    for p in params {
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{}</td><td>{}</td><td>{} to {}</td><td class=\"t\">{}</td><td class=\"t\">{}</td></tr>",
            escape(&p.mechanism),
            escape(&p.parameter),
            format_sig(p.estimate),
            format_sig(p.ci.0),
            format_sig(p.ci.1),
            escape(&p.unit),
            escape(&p.meaning)
        );
    }
    html + "</table>\n"
}

/// A fraction as a percentage with at most one decimal (`0.05` → `5`, `0.025` → `2.5`).
/// The engine on another baseline (paper 000's piecewise model): per printer, the
/// baseline's held-out RMSE, what was named and the candidates' scores.
fn other_baseline_part(dir: &Path, stage: &str, rows: &mut Vec<Row>) -> Result<String, StageError> {
    let causes = Cause::read(dir, &FDM)?;
    let gains = GainRow::read(dir, &FDM)?;
    let baseline = causes.first().map_or("piecewise_model".to_string(), |c| c.base_model.clone());
    let mut html = format!(
        "<h4>The paper's own model as the baseline ({})</h4>\n<p>The same engine with paper 000's piecewise model (eqs 1-3, its r_a × r_F grid search in every fold) in place of the lag model. A curve fitted per phase has no flow to extend, so the candidates are the three that act on the width it predicts: a tilted bed, a gear's ripple and flow lost at high flow.</p>\n",
        escape(&baseline.replace('_', " "))
    );
    for g in &gains {
        let mine: Vec<&Cause> = causes.iter().filter(|c| c.printer == g.printer).collect();
        let named: Vec<String> = mine.iter().filter(|c| c.named).map(|c| c.mechanism.replace('_', " ")).collect();
        let verdict = if named.is_empty() {
            "no candidate is significant, so the model stays as it is".to_string()
        } else {
            format!(
                "named: {}; the extended model's held-out RMSE is {:.4} mm, a gain of {} % (95 % interval {} to {} %)",
                named.join(", "),
                g.after,
                percent(g.gain.0),
                percent(g.gain.1),
                percent(g.gain.2)
            )
        };
        let _ = writeln!(
            html,
            "<p><b>{}</b>: held-out RMSE of the piecewise model {:.4} mm; {verdict}.</p>",
            escape(&printer_name(&g.printer)),
            g.before
        );
        html += &causes_table(&mine, &FDM);
        let source = format!("gain.parquet of stage {stage} (fdm.discrepancy, baseline {baseline})");
        rows.push(Row {
            section: "piecewise_baseline",
            item: format!("{} piecewise model held-out rmse", g.printer),
            paper: None,
            ours: g.before,
            unit: "mm",
            source,
        });
    }
    Ok(html)
}

pub(super) fn percent(x: f64) -> String {
    let p = (1000.0 * x).round() / 10.0;
    if p.fract() == 0.0 {
        format!("{p:.0}")
    } else {
        format!("{p:.1}")
    }
}

fn power_part(power: &[PowerRow], stage: &str, rows: &mut Vec<Row>) -> String {
    let mut html = String::from(
        "<h4>How strong must a hidden effect be?</h4>\n<p>Each draw keeps a printer's lines and kinematics, replaces the measured widths by the model its own causes give plus a new, \
phase-randomised copy of each line's residual (the same power spectrum, so the same slow swells and the same scatter, in a new realisation), and hides one effect by its physics: \
a bed tilt of the given relative width change from the start of the line to its end (sign drawn), a gear ripple of the given relative flow amplitude (period and each line's phase drawn \
from the draw's seed), or a flow loss of the given size at the fastest line's cruise. The engine, starting from the lag model extended by the printer's own causes and not told \
what was hidden, is correct when it names the hidden mechanism and nothing else; wrong when it names anything else. Draws marked <i>measurement noise only</i> carry, \
instead of the residual's copy, independent noise of each line's sample-to-sample scatter: they show what the engine could find on lines the model describes up to their \
measurement noise, and so what in the measured lines limits it.</p>\n",
    );
    html += "<table><tr><th class=\"t\">base</th><th class=\"t\">noise</th><th class=\"t\">its own causes</th><th class=\"t\">hidden effect</th><th>strength (%)</th><th>draws</th><th>named (%)</th><th>95 % interval (%)</th><th>wrong cause (%)</th><th>strength interval covers the truth</th></tr>\n";
    for r in power {
        let named = if r.effect == "none" { "—".to_string() } else { format!("{:.0}", 100.0 * r.correct.0) };
        let ci = if r.effect == "none" {
            "—".to_string()
        } else {
            format!("{:.0} to {:.0}", 100.0 * r.correct.1, 100.0 * r.correct.2)
        };
        let wrong = format!("{:.1} (up to {:.1})", 100.0 * r.false_alarm.0, 100.0 * r.false_alarm.2);
        let coverage =
            if r.with_interval > 0 { format!("{} of {}", r.covered, r.with_interval) } else { "—".to_string() };
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{}</td><td class=\"t\">{}</td><td class=\"t\">{}</td><td>{}</td><td>{}</td><td>{named}</td><td>{ci}</td><td>{wrong}</td><td>{coverage}</td></tr>",
            escape(&r.base),
            noise_label(&r.noise),
            escape(&r.own),
            escape(&r.effect),
            percent(r.strength),
            r.draws
        );
        let item = if r.effect == "none" {
            format!("{} {} noise null false-alarm rate", r.base, r.noise)
        } else {
            format!("{} {} noise {} {} correct rate", r.base, r.noise, r.effect, r.strength)
        };
        let value = if r.effect == "none" { r.false_alarm.0 } else { r.correct.0 };
        rows.push(Row {
            section: "discrepancy_fdm",
            item,
            paper: None,
            ours: value,
            unit: "1",
            source: format!("out/discrepancy/power.parquet (stage {stage}, fdm.discovery_power)"),
        });
    }
    html += "</table>\n";
    html += &power_summary(power);
    let _ = writeln!(
        html,
        "<p class=\"run\">Run discrepancy_fdm, stage {stage} (fdm.discovery_power): tables out/discrepancy/power.parquet and power_draws.parquet (one row per draw). \
Intervals of rates are Clopper–Pearson.</p>"
    );
    html
}

fn noise_label(noise: &str) -> &'static str {
    if noise == "white" {
        "measurement noise only"
    } else {
        "measured"
    }
}

/// Per base and noise: the null false alarms and, per effect, the weakest strength named
/// in at least 95 % of draws.
fn power_summary(power: &[PowerRow]) -> String {
    let mut bases: Vec<(&str, &str)> = power.iter().map(|r| (r.base.as_str(), r.noise.as_str())).collect();
    bases.dedup();
    let mut text = String::from("<p>");
    for (base, noise) in bases {
        let mine: Vec<&PowerRow> = power.iter().filter(|r| r.base == base && r.noise == noise).collect();
        let _ = write!(text, "<b>{base}, {}</b>: ", noise_label(noise));
        if let Some(null) = mine.iter().find(|r| r.effect == "none") {
            let _ = write!(
                text,
                "{} of {} null draws named a cause beyond the data's own ({:.1} %, at most {:.1} % at 95 % confidence). ",
                null.wrong, null.draws, 100.0 * null.false_alarm.0, 100.0 * null.false_alarm.2
            );
        }
        let mut effects: Vec<&str> = mine.iter().filter(|r| r.effect != "none").map(|r| r.effect.as_str()).collect();
        effects.dedup();
        let parts: Vec<String> = effects
            .iter()
            .map(|e| {
                let strengths: Vec<&&PowerRow> = mine.iter().filter(|r| r.effect == *e).collect();
                let weakest =
                    strengths.iter().filter(|r| r.correct.0 >= 0.95).min_by(|a, b| a.strength.total_cmp(&b.strength));
                let strongest = strengths.iter().max_by(|a, b| a.strength.total_cmp(&b.strength));
                match (weakest, strongest) {
                    (Some(w), _) => {
                        format!("{e} from {} % (named in {:.0} % of draws)", percent(w.strength), 100.0 * w.correct.0)
                    }
                    (None, Some(s)) => format!(
                        "{e} at none of the strengths tried (at {} %: {:.0} % of draws)",
                        percent(s.strength),
                        100.0 * s.correct.0
                    ),
                    _ => String::new(),
                }
            })
            .collect();
        if !parts.is_empty() {
            let _ = write!(text, "It names, in at least 95 % of draws, {}.<br>", parts.join("; "));
        }
    }
    text + "</p>\n"
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cause(round: i64, mechanism: &str, gain: f64, p_adjusted: f64, named: bool, verdict: &str) -> Cause {
        Cause {
            printer: "p".into(),
            round,
            base_model: "lag_model".into(),
            mechanism: mechanism.into(),
            before: 0.08,
            after: 0.08 * (1.0 - gain / 100.0),
            gain: (gain, gain - 5.0, gain + 5.0),
            helped: 9,
            groups: 9,
            p: p_adjusted / 6.0,
            p_adjusted,
            alpha: 0.05,
            min_gain_pct: 0.0,
            named,
            verdict: verdict.into(),
        }
    }

    #[test]
    fn the_finding_says_what_was_named_and_what_was_not_in_computed_numbers() {
        let g = GainRow {
            printer: "p".into(),
            extended: "lag_model + width_cap".into(),
            groups: 9,
            before: 0.08,
            after: 0.052,
            gain: (35.0, 28.0, 41.0),
        };
        let causes = [
            cause(1, "width_cap", 35.0, 0.0137, true, "named"),
            cause(1, "bed_tilt", 4.0, 0.15, false, "named"),
            cause(2, "bed_tilt", -1.0, 1.0, false, "none"),
        ];
        let refs: Vec<&Cause> = causes.iter().collect();
        let text = finding(&g, &refs, &[]);
        assert!(text.contains("In round 1, <b>width_cap</b>") && text.contains("+35.0 %"), "{text}");
        assert!(text.contains("no further candidate is significant"), "{text}");
        assert!(!text.contains("No significant discrepancy"), "{text}");
        let none = [cause(1, "bed_tilt", 1.0, 0.5, false, "none")];
        let refs: Vec<&Cause> = none.iter().collect();
        let text = finding(&GainRow { extended: "lag_model".into(), ..g }, &refs, &[]);
        assert!(text.contains("No significant discrepancy") && text.contains("no candidate is significant"), "{text}");
        assert!(!text.contains("NaN"), "{text}");
    }

    #[test]
    fn the_strongest_structure_is_named_with_its_share_after_the_extension() {
        let row = |set: &str, model: &str, variable: &str, share: f64| Structure {
            set: set.into(),
            model: model.into(),
            variable: variable.into(),
            share,
        };
        let table = [
            row("a", "baseline", "layer", 0.02),
            row("a", "baseline", "bead_width.age_s", 0.71),
            row("a", "extended", "bead_width.age_s", 0.64),
            row("b", "baseline", "layer", 0.004),
            row("b", "baseline", "nozzle", 0.001),
        ];
        let a = Structure::strongest(&table, "a", true, "Its");
        assert!(a.contains("<code>bead_width.age_s</code>") && a.contains("71 %") && a.contains("(64 % after"), "{a}");
        assert!(!Structure::strongest(&table, "a", false, "Its").contains("after the extension"));
        let b = Structure::strongest(&table, "b", false, "The baseline's");
        assert!(b.contains("no structure against any variable") && b.contains("<code>layer</code>"), "{b}");
        assert_eq!(Structure::strongest(&table, "c", true, "Its"), "");
    }

    #[test]
    fn percentages_drop_needless_decimals() {
        assert_eq!((percent(0.05), percent(0.025), percent(0.2)), ("5".into(), "2.5".into(), "20".into()));
    }
}
