//! `report.discrepancy_inkjet`: what paper 002's layer-to-layer model gets wrong on
//! ink-jet scans, the cause the discrepancy engine names, the extended model and its
//! held-out gain, and, when a power study is an input, how often a hidden effect is
//! named (DESIGN §7). Every number is read from the tables of `inkjet.discrepancy` and
//! `inkjet.discovery_power`.
//!
//! Inputs: the `inkjet.discrepancy` stage, then optionally `inkjet.discovery_power`
//! and `inkjet.control_gain` (recognised by their tables), in any order.

use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::NoParams;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::inkjet::control_gain;
use tables::report::comparison;

use super::discrepancy_fdm::{
    causes_table, engine_reads, parameter_table, percent, structure_reads, Cause, GainRow, Names, Param, PowerRow,
    Structure, POWER_READS,
};
use super::{comparison_frame, Row};
use crate::html::{escape, format_sig};
use crate::read::{f64_triples, f64s, ints, read_parquet, strs};

/// The ink-jet tables: one discovery per dataset, heights in µm, a group is a block of
/// consecutive layers.
const INKJET: DatasetText = DatasetText {
    names: Names {
        engine: &tables::discrepancy::inkjet::ENGINE, unit: "um", unit_label: "µm", groups: "layer blocks"
    },
    section: "discrepancy_inkjet",
    kind: "inkjet.discrepancy",
    power_kind: "inkjet.discovery",
    prefix: "inkjet",
    rmse_over: "",
};

/// What a domain's per-dataset parts call things: its tables' names, its report section,
/// its stage kind, the prefix of its published tables (`out/discrepancy/{prefix}_gain.parquet`).
pub(super) struct DatasetText {
    pub(super) names: Names,
    pub(super) section: &'static str,
    pub(super) kind: &'static str,
    /// The power study's stage kind without its `_power` suffix.
    pub(super) power_kind: &'static str,
    pub(super) prefix: &'static str,
    /// What the data set's held-out RMSE is over, when its observations are of several
    /// kinds (empty: one kind).
    pub(super) rmse_over: &'static str,
}

/// The `report.discrepancy_inkjet` stage kind.
pub struct DiscrepancyInkjetSection;

/// The engine run on the layer-to-layer model.
const DISCREPANCY: Input = Input::one(
    "discrepancy",
    &[Source::Stage("inkjet.discrepancy")],
    "the causes, extension, gain and residual structure per dataset (`causes.parquet`, `extension.parquet`, `gain.parquet`, `residuals.parquet`)",
)
.reading(engine_reads!(inkjet, structure_reads!(inkjet)));

/// The optional studies, told apart by their tables.
const STUDIES: Input = Input::many(
    "studies",
    0,
    &[Source::Stage("inkjet.discovery_power"), Source::Stage("inkjet.control_gain")],
    "a power study (`power.parquet`) and a control study (`control_gain.parquet`), in any order",
)
.reading_by_kind(&[("inkjet.discovery_power", POWER_READS), ("inkjet.control_gain", CONTROL_READS)]);

/// What [`ControlRow::read`] reads of a control study.
const CONTROL_READS: &[Reads] = &[Reads {
    table: &control_gain::TABLE,
    columns: &{
        use control_gain as c;
        [
            c::effect,
            c::controller,
            c::strength,
            c::desired_um,
            c::printers,
            c::mean_error_um,
            c::mean_error_ci_lo,
            c::mean_error_ci_hi,
            c::rmsd_um,
            c::rmsd_ci_lo,
            c::rmsd_ci_hi,
            c::average_height_um,
            c::average_height_ci_lo,
            c::average_height_ci_hi,
            c::rmsd_vs_paper_um,
            c::rmsd_vs_paper_ci_lo,
            c::rmsd_vs_paper_ci_hi,
        ]
    },
}];

impl Stage for DiscrepancyInkjetSection {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.discrepancy_inkjet",
        version: 3,
        summary: "What the layer-to-layer model gets wrong on ink-jet scans, the cause named, the extension and its gain, and (with a power study) how often hidden effects are named → section.html, comparison.parquet",
        implements: "DESIGN §7 on paper 002's layer-to-layer model",
        inputs: &[DISCREPANCY, STUDIES],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let discrepancy = ctx.input(&DISCREPANCY);
        let (dir, stage) = (&discrepancy.dir, discrepancy.name.clone());
        let causes = Cause::read(dir, &INKJET.names)?;
        let params = Param::read(dir, &INKJET.names)?;
        let gains = GainRow::read(dir, &INKJET.names)?;
        let structure = Structure::read(dir, &INKJET.names)?;
        let mut rows = Vec::new();
        let mut html = String::from("<h3>What the layer-to-layer model gets wrong, and why</h3>\n");
        html += &method(&causes);
        for g in &gains {
            html += &dataset_part(g, &causes, &params, &structure, &stage, &mut rows, &INKJET);
        }
        for input in ctx.inputs_of(&STUDIES) {
            let control = input.dir.join(control_gain::TABLE.file());
            if control.is_file() {
                html += &control_part(&ControlRow::read(&control)?, &input.name, &mut rows);
            } else {
                let power = PowerRow::read(&input.dir)?;
                html += &power_part(&power, &input.name, &mut rows);
            }
        }
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

fn method(causes: &[Cause]) -> String {
    let alpha = causes.first().map_or(f64::NAN, |c| c.alpha);
    format!(
        "<p>Paper 002 predicts each layer from the surface it is printed on: a droplet adds h1 to its cell and shares h2 and h3 with its side and corner neighbours, \
the shares saturating where the neighbour is higher (eqs 2-7). Here that model, with each dataset's nominal droplets at the mean of its recorded volume variation and its \
profiler's spot, predicts every scan from the layers before. It is run as a Kalman filter on the true surface (the profiler's noise variance from the dataset, the droplets' \
volume variance as process noise), because fed the raw scan the model would share material by measurement noise and the next scan's regression would look like a physical \
cause. Six named mechanisms extend it in turn — curing shrinkage (equally, droplets below their nominal volume), a droplet volume drifting with the layer, levelling flow of \
the fresh layer, a volume factor per nozzle, and two the virtual printer does not have: a miscalibrated split of h1, h2, h3 and an anisotropic spread — and each is scored by \
cross-validation holding out blocks of consecutive layers. Each held-out block contributes the log ratio of its squared error before and after; a one-sided sign-flip test \
over blocks gives each candidate a p-value, Holm's step-down holds the family-wise false-alarm rate of a round at α = {alpha}, and the cause named is the significant \
candidate with the largest held-out gain; the extended model then becomes the baseline and the search repeats. A tilted substrate has no candidate: the model predicts from \
the measured surface, which already contains the tilt. Parameter intervals are delete-one-block jackknife intervals; gain intervals are a bootstrap over blocks.</p>\n"
    )
}

/// One dataset's verdict, causes, parameters and gain, with its comparison rows.
pub(super) fn dataset_part(
    g: &GainRow,
    causes: &[Cause],
    params: &[Param],
    structure: &[Structure],
    stage: &str,
    rows: &mut Vec<Row>,
    text: &DatasetText,
) -> String {
    let (names, prefix) = (&text.names, text.prefix);
    let dataset = &g.printer;
    let mine: Vec<&Cause> = causes.iter().filter(|c| &c.printer == dataset).collect();
    let named: Vec<String> = mine.iter().filter(|c| c.named).map(|c| c.mechanism.replace('_', " ")).collect();
    let mut html = format!("<h4>{}</h4>\n", escape(&dataset.replace('_', " ")));
    let verdict = if named.is_empty() {
        let too_few = mine.iter().any(|c| c.verdict == "too_few_groups");
        if too_few {
            format!("there are too few {} for any candidate to reach significance, so nothing is named", names.groups)
        } else {
            "no candidate is significant: the model stays as it is".to_string()
        }
    } else {
        format!(
            "named: <b>{}</b>; the held-out RMSE{} falls from {} to {} {}, a gain of {} % (95 % interval {} to {} %)",
            named.join("</b>, then <b>"),
            text.rmse_over,
            format_sig(g.before),
            format_sig(g.after),
            names.unit_label,
            percent(g.gain.0 / 100.0),
            percent(g.gain.1 / 100.0),
            percent(g.gain.2 / 100.0)
        )
    };
    let shows = Structure::strongest(structure, dataset, !named.is_empty(), "The baseline's");
    let _ = writeln!(html, "<p>{} {}; {verdict}.{shows}</p>", g.groups, names.groups);
    html += &causes_table(&mine, names);
    let fitted: Vec<&Param> = params.iter().filter(|p| &p.printer == dataset).collect();
    if !fitted.is_empty() {
        html += &parameter_table(fitted.into_iter());
    }
    let _ = writeln!(
        html,
        "<p class=\"run\">Run {section}, stage {stage} ({kind}): tables out/discrepancy/{prefix}_causes.parquet, {prefix}_extension.parquet, {prefix}_gain.parquet, {prefix}_residuals.parquet.</p>",
        section = text.section,
        kind = text.kind,
    );
    let source = format!("out/discrepancy/{prefix}_gain.parquet (stage {stage}, {})", text.kind);
    for (item, value, unit) in [
        ("held-out rmse, baseline", g.before, names.unit),
        ("held-out rmse, extended model", g.after, names.unit),
        ("held-out gain", g.gain.0, "%"),
    ] {
        rows.push(Row {
            section: text.section,
            item: format!("{dataset} {item} ({})", g.extended),
            paper: None,
            ours: value,
            unit,
            source: source.clone(),
        });
    }
    html
}

fn power_part(power: &[PowerRow], stage: &str, rows: &mut Vec<Row>) -> String {
    let mut html = String::from(
        "<h4>How often is a hidden effect named?</h4>\n<p>Each draw prints a cylinder open loop on the virtual printer (the paper's droplet variation and profiler) \
with one effect at the given strength (the sign drawn for the tilt and the drift) or none, and the engine, told nothing, is scored: correct when it names the printed effect \
and nothing else, wrong when it names anything else. A nozzle bias's truth is the spread of the nozzle factors the print actually drew. A tilted substrate has no candidate \
(see above): its draws show how often the engine stays silent when the model has nothing to learn.</p>\n",
    );
    html += &power_table(power, stage, rows, &INKJET);
    html
}

/// The power table of a study, its comparison rows and where it came from.
pub(super) fn power_table(power: &[PowerRow], stage: &str, rows: &mut Vec<Row>, text: &DatasetText) -> String {
    let source = format!("out/discrepancy/{}_power.parquet (stage {stage}, {}_power)", text.prefix, text.power_kind);
    let mut html = String::from("<table><tr><th class=\"t\">print</th><th class=\"t\">hidden effect</th><th>strength</th><th>draws</th><th>named (%)</th><th>95 % interval (%)</th><th>wrong cause (%)</th><th>strength interval covers the truth</th></tr>\n");
    for r in power {
        let null = r.effect == "none";
        let named = if null { "—".to_string() } else { format!("{:.0}", 100.0 * r.correct.0) };
        let ci =
            if null { "—".to_string() } else { format!("{:.0} to {:.0}", 100.0 * r.correct.1, 100.0 * r.correct.2) };
        let wrong = format!("{:.1} (up to {:.1})", 100.0 * r.false_alarm.0, 100.0 * r.false_alarm.2);
        let coverage =
            if r.with_interval > 0 { format!("{} of {}", r.covered, r.with_interval) } else { "—".to_string() };
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{}</td><td>{}</td><td>{}</td><td>{named}</td><td>{ci}</td><td>{wrong}</td><td>{coverage}</td></tr>",
            escape(&r.base),
            escape(&r.effect),
            if null { "—".to_string() } else { format_sig(r.strength) },
            r.draws
        );
        let (item, value) = if null {
            (format!("{} null false-alarm rate", r.base), r.false_alarm.0)
        } else {
            (format!("{} {} {} correct rate", r.base, r.effect, r.strength), r.correct.0)
        };
        rows.push(Row { section: text.section, item, paper: None, ours: value, unit: "1", source: source.clone() });
    }
    html += "</table>\n";
    let _ = writeln!(
        html,
        "<p class=\"run\">Stage {stage} ({}_power): tables out/discrepancy/{prefix}_power.parquet and {prefix}_power_draws.parquet (one row per print, with each candidate's first-round p-value). Intervals of rates are Clopper–Pearson.</p>",
        text.power_kind,
        prefix = text.prefix,
    );
    html
}

/// One row of `control_gain.parquet`: an effect, a strength and a controller model.
struct ControlRow {
    effect: String,
    strength: f64,
    controller: String,
    printers: i64,
    desired_um: f64,
    mean_error: (f64, f64, f64),
    rmsd: (f64, f64, f64),
    height: (f64, f64, f64),
    rmsd_vs_paper: (f64, f64, f64),
}

impl ControlRow {
    fn read(path: &Path) -> Result<Vec<Self>, StageError> {
        use control_gain as c;
        let df = read_parquet(path)?;
        let triple = |name: &str, lo: &str, hi: &str| f64_triples(&df, [name, lo, hi], path);
        let (effect, controller) = (strs(&df, c::effect, path)?, strs(&df, c::controller, path)?);
        let (strength, desired, printers) =
            (f64s(&df, c::strength, path)?, f64s(&df, c::desired_um, path)?, ints(&df, c::printers, path)?);
        let mean_error = triple(c::mean_error_um, c::mean_error_ci_lo, c::mean_error_ci_hi)?;
        let rmsd = triple(c::rmsd_um, c::rmsd_ci_lo, c::rmsd_ci_hi)?;
        let height = triple(c::average_height_um, c::average_height_ci_lo, c::average_height_ci_hi)?;
        let vs_paper = triple(c::rmsd_vs_paper_um, c::rmsd_vs_paper_ci_lo, c::rmsd_vs_paper_ci_hi)?;
        Ok((0..df.height())
            .map(|i| Self {
                effect: effect[i].clone(),
                strength: strength[i],
                controller: controller[i].clone(),
                printers: printers[i],
                desired_um: desired[i],
                mean_error: mean_error[i],
                rmsd: rmsd[i],
                height: height[i],
                rmsd_vs_paper: vs_paper[i],
            })
            .collect())
    }
}

/// `value (lo to hi)` with three significant digits.
pub(super) fn with_interval((value, lo, hi): (f64, f64, f64)) -> String {
    format!("{} ({} to {})", format_sig(value), format_sig(lo), format_sig(hi))
}

/// What the paired interval `(d, lo, hi)` of a difference to `reference` says, in
/// words, with the unit `unit` (`µm`, ` percentage points`).
pub(super) fn difference_words((d, lo, hi): (f64, f64, f64), unit: &str, reference: &str) -> String {
    let interval = format!("95 % interval {} to {}{unit}", format_sig(lo), format_sig(hi));
    if lo > 0.0 {
        format!("higher than {reference} by {}{unit} ({interval})", format_sig(d))
    } else if hi < 0.0 {
        format!("lower than {reference} by {}{unit} ({interval})", format_sig(-d))
    } else {
        format!("not resolved from {reference} (a difference of {}{unit}, {interval})", format_sig(d))
    }
}

fn control_part(control: &[ControlRow], stage: &str, rows: &mut Vec<Row>) -> String {
    let desired = control.first().map_or(f64::NAN, |r| r.desired_um);
    let mut html = format!(
        "<h4>Does the extended model print better?</h4>\n<p>Each printer (one seed, one effect at the given strength) first prints an open-loop calibration \
cylinder; the engine reads its scans, told nothing, and names and fits an extension. The same printer — the same printhead and droplets — then prints the {} µm \
cylinder of Figs 11-12 in closed loop three times, the controller solving eq. 8 before every layer with a different height model: the paper's nominal droplets \
(<i>paper</i>), the engine's baseline, the nominal droplets at the mean of the recorded variation (<i>mean_droplet</i>), and that baseline extended by what the engine \
named (<i>extended</i>). An extension enters eq. 8 as per-cell droplet coefficients for the next layer (shrinkage as a volume factor on the coefficients rather than on the \
cured layer; levelling flow and an anisotropic spread, which eq. 8's predictor cannot express, would be left out). Mean error and RMSD are of the true top surface over \
the footprint, as in Figs 11-12 and Table II; intervals are 95 % Student-t over printers, and the difference to the paper's controller is paired by printer.</p>\n",
        format_sig(desired)
    );
    html += "<table><tr><th class=\"t\">printers' effect</th><th>strength</th><th class=\"t\">controller's model</th><th>printers</th><th>mean error (µm)</th><th>RMSD (µm)</th><th>average height (µm)</th><th>RMSD minus the paper controller's (µm)</th></tr>\n";
    for r in control {
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td>{}</td><td class=\"t\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&r.effect.replace('_', " ")),
            format_sig(r.strength),
            escape(&r.controller.replace('_', " ")),
            r.printers,
            with_interval(r.mean_error),
            with_interval(r.rmsd),
            with_interval(r.height),
            if r.controller == "paper" { "—".to_string() } else { with_interval(r.rmsd_vs_paper) },
        );
        rows.push(Row {
            section: "discrepancy_inkjet",
            item: format!("closed-loop rmsd, {} {}, {} controller", r.effect, r.strength, r.controller),
            paper: None,
            ours: r.rmsd.0,
            unit: "um",
            source: format!("out/discrepancy/inkjet_control_gain.parquet (stage {stage}, inkjet.control_gain)"),
        });
    }
    html += "</table>\n<p>";
    for r in control.iter().filter(|r| r.controller == "extended") {
        let _ = write!(
            html,
            "With a {} of {}, the extended controller's RMSD is {}. ",
            escape(&r.effect.replace('_', " ")),
            format_sig(r.strength),
            difference_words(r.rmsd_vs_paper, " µm", "the paper controller's")
        );
    }
    let lowest = control.iter().map(|r| r.height.1).fold(f64::INFINITY, f64::min);
    if lowest > desired {
        let highest = control.iter().map(|r| r.height.0).fold(f64::NEG_INFINITY, f64::max);
        let _ = write!(
            html,
            "Every controller's part ends above the desired {} µm: its average height's interval lies above it in every row (means up to {} µm).",
            format_sig(desired),
            format_sig(highest)
        );
    }
    html += "</p>\n";
    let _ = writeln!(
        html,
        "<p class=\"run\">Stage {stage} (inkjet.control_gain): tables out/discrepancy/inkjet_control_gain.parquet and inkjet_control_trials.parquet (one row per production print, with what the engine named).</p>"
    );
    html
}
