//! `report.discrepancy_thermal`: what paper 003's capture-time model (eq. 28), its
//! assumption that every layer prints alike and its flow dynamics (eq. 34) get wrong
//! about what the thermal monitor measures, the cause the discrepancy engine names, the
//! extended model and its held-out gain, with a power study how often hidden effects are
//! named, and with a control study whether the compensation prints better with the
//! extended model (DESIGN §7). Every number is read from the tables of
//! `thermal.discrepancy`, `thermal.discovery_power` and `thermal.control_gain`.
//!
//! Inputs: the `thermal.discrepancy` stage, then optionally `thermal.discovery_power`
//! and `thermal.control_gain` (recognised by their tables), in any order.

use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::NoParams;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::report::comparison;
use tables::thermal::control_gain;

use super::discrepancy_fdm::{
    engine_reads, structure_reads, Cause, GainRow, Names, Param, PowerRow, Structure, POWER_READS,
};
use super::discrepancy_inkjet::{dataset_part, difference_words, power_table, with_interval, DatasetText};
use super::{comparison_frame, Row};
use crate::html::escape;
use crate::read::{f64_triples, f64s, ints, read_parquet, strs};

/// The thermal tables: one discovery per filmed print, residuals in noise standard
/// deviations, a group is a filmed layer.
const THERMAL: DatasetText = DatasetText {
    names: Names {
        engine: &tables::discrepancy::thermal::ENGINE,
        unit: "sd",
        unit_label: "noise sd",
        groups: "layers",
    },
    section: "discrepancy_thermal",
    kind: "thermal.discrepancy",
    power_kind: "thermal.discovery",
    prefix: "thermal",
    rmse_over: " over the kinds of observation its named causes move, on which the table below scores each candidate,",
};

/// The `report.discrepancy_thermal` stage kind.
pub struct DiscrepancyThermalSection;

/// The engine run on the capture-time, layer and flow models.
const DISCREPANCY: Input = Input::one(
    "discrepancy",
    &[Source::Stage("thermal.discrepancy")],
    "the causes, extension, gain and residual structure per filmed print (`causes.parquet`, `extension.parquet`, `gain.parquet`, `residuals.parquet`)",
)
.reading(engine_reads!(thermal, structure_reads!(thermal)));

/// The optional studies, told apart by their tables.
const STUDIES: Input = Input::many(
    "studies",
    0,
    &[Source::Stage("thermal.discovery_power"), Source::Stage("thermal.control_gain")],
    "a power study (`power.parquet`) and a control study (`control_gain.parquet`), in any order",
)
.reading_by_kind(&[("thermal.discovery_power", POWER_READS), ("thermal.control_gain", CONTROL_READS)]);

/// The `(mean, low, high)` columns of each score [`ControlRow::read`] reads.
const CONTROL_TRIPLES: [[&str; 3]; 5] = {
    use control_gain as c;
    [
        [c::mean_oe_pct, c::mean_oe_pct_ci_lo, c::mean_oe_pct_ci_hi],
        [c::contour_rms_mm, c::contour_rms_mm_ci_lo, c::contour_rms_mm_ci_hi],
        [c::contour_max_mm, c::contour_max_mm_ci_lo, c::contour_max_mm_ci_hi],
        [c::mean_oe_pct_vs_paper, c::mean_oe_pct_vs_paper_ci_lo, c::mean_oe_pct_vs_paper_ci_hi],
        [c::contour_rms_mm_vs_paper, c::contour_rms_mm_vs_paper_ci_lo, c::contour_rms_mm_vs_paper_ci_hi],
    ]
};

/// What [`ControlRow::read`] reads of a control study: its five describing columns,
/// then every score's triple of [`CONTROL_TRIPLES`] in order.
const CONTROL_READS: &[Reads] = &[Reads { table: &control_gain::TABLE, columns: &control_columns() }];

const fn control_columns() -> [&'static str; 5 + 3 * CONTROL_TRIPLES.len()] {
    use control_gain as c;
    let head = [c::effect, c::controller, c::strength, c::prints, c::tau_named];
    let mut columns = [""; 5 + 3 * CONTROL_TRIPLES.len()];
    let mut k = 0;
    while k < columns.len() {
        columns[k] = if k < head.len() { head[k] } else { CONTROL_TRIPLES[(k - head.len()) / 3][(k - head.len()) % 3] };
        k += 1;
    }
    columns
}

impl Stage for DiscrepancyThermalSection {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.discrepancy_thermal",
        // 11: the method paragraph says the contour map has a level per straight run, and
        //     why the test asks for a gain worth naming without the τ-like departure.
        // 12: the contour map's quadratic in the age per straight run and gain growing with the age.
        // 13: the method told in paragraphs and lists (the measurements, the contour map,
        //     the candidates, the test, what has no candidate, the intervals).
        version: 13,
        summary: "What the capture-time, layer and flow models get wrong about the thermal monitor's measurements, the cause named, the extension, its gain and the compensation it gives → section.html, comparison.parquet",
        implements: "DESIGN §7 on paper 003's eq. 28, layer model and eq. 34; eqs 31-41 with the extended model",
        inputs: &[DISCREPANCY, STUDIES],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let discrepancy = ctx.input(&DISCREPANCY);
        let (dir, stage) = (&discrepancy.dir, discrepancy.name.clone());
        let causes = Cause::read(dir, &THERMAL.names)?;
        let params = Param::read(dir, &THERMAL.names)?;
        let gains = GainRow::read(dir, &THERMAL.names)?;
        let structure = Structure::read(dir, &THERMAL.names)?;
        let mut rows = Vec::new();
        let mut html = String::from("<h3>What the thermal monitor's models get wrong, and why</h3>\n");
        html += &method(&causes);
        for g in &gains {
            html += &dataset_part(g, &causes, &params, &structure, &stage, &mut rows, &THERMAL);
        }
        for input in ctx.inputs_of(&STUDIES) {
            let control = input.dir.join("control_gain.parquet");
            if control.is_file() {
                html += &control_part(&ControlRow::read(&control)?, &input.name, &mut rows);
            } else {
                let power = PowerRow::read(&input.dir)?;
                html += POWER_INTRO;
                html += &power_table(&power, &input.name, &mut rows, &THERMAL);
            }
        }
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

const POWER_INTRO: &str = "<h4>How often is a hidden effect named?</h4>\n<p>Each draw prints and films the corner test part on the virtual printer \
(the Lepton's habits on) with one effect at the given strength or none; the monitor measures it as above and the engine, told nothing, is scored: correct when it names \
the printed effect and nothing else, wrong when it names anything else. The two corner effects have no candidate (see above): their draws show how often the engine \
stays silent when its model has nothing to learn.</p>\n";

fn method(causes: &[Cause]) -> String {
    let (alpha, min_gain_pct) = causes.first().map_or((f64::NAN, f64::NAN), |c| (c.alpha, c.min_gain_pct));
    let worth_naming = if min_gain_pct > 0.0 {
        format!(
            " Each test asks for a gain worth naming: its null hypothesis is that the candidate lowers the held-out RMSE of what it moves by at most \
{min_gain_pct} % (a minimum-effect test), because with thousands of widths in every layer all layers agree on differences far too small to matter, \
and a real printer always has some (the virtual printer's own bead recovers from a corner slightly faster than eq. 34's lag, by far less than a pixel)."
        )
    } else {
        String::new()
    };
    format!(
        "<p>Paper 003 localises every frame by the time it was recorded (eq. 28: the true capture time is the recorded one plus a small, zero-mean \
fluctuation), prints and measures every layer the same way, on a substrate at the bed temperature, and models the flow that reaches the nozzle as the command \
through a first-order lag with its identified τ (eq. 34). Three of the monitor's measurements test that:</p>\n<ul>\n\
<li><em>capture offsets</em>: each localised frame's capture time estimated by eq. 30 minus its recorded time (eq. 30's search window widened so that a delay \
is not cut off; frames at its edge and repeated images are left out); the baseline predicts zero;</li>\n\
<li><em>centre temperatures</em>: each trajectory sample's temperature on the path at the measuring age; the baseline predicts, for every layer, what the \
other layers read at the same sample;</li>\n\
<li><em>bead widths</em> on the straight runs, read at the feed speed, away from every corner and from the seam where each layer starts on the previous \
one's stop, in frames with a capture-time estimate; the baseline predicts the width of the lagged flow spread over the path, read through a contour map \
fitted to the training layers.</li>\n</ul>\n\
<p>The contour map is linear in the bead's width, with a gain that grows linearly with the bead's age when its frame is taken: a thinner bead holds less \
heat, so its threshold contour shrinks more than its deposit, the more so the older the bead (its heat spreads as it ages). On each straight run it has a \
level of its own and a quadratic curve in that age. The camera rides on the head without turning with it, so each run's bead lies at its own place and \
direction in the image, where the image's blur, its pixels' footprint and the small errors of the fitted mount read a straight bead a little wider or \
narrower, the same in every layer; and a cooling bead's contour contracts with its age, which varies along every run with where the frames fall (the \
camera trails the nozzle), while an older bead lies farther behind the nozzle along the run's own direction in the image, where the tilted camera's blur \
and footprint change across the field.</p>\n\
<p>Five named mechanisms extend the baseline (the second and the fourth are not in the virtual printer):</p>\n<ul>\n\
<li>a constant camera latency;</li>\n<li>a camera clock running at another rate;</li>\n\
<li>a fraction of each layer's residual heat carried into the next layer's substrate, read through the bead's excess over its substrate, which decays \
alike whatever the substrate's temperature (with a weak prior on the first carried excess, because without layer 0 the other layers hardly say how much \
warmer than the bed they all are);</li>\n\
<li>a substrate warming by a fixed amount per layer;</li>\n<li>a flow time constant other than the nominal.</li>\n</ul>\n\
<p>Residuals are in noise standard deviations: each observation is divided by its kind's noise scale, estimated from differences no candidate explains, \
and each candidate is scored on the kind of observation it moves. The residual figures and the structure shares below show each kind against its own \
variables: the capture offsets against the layer and the recorded time, the centre temperatures against the layer and the time, the widths against the \
layer, the time since the head last left a corner's slow-down and the bead's age when its frame was taken.</p>\n\
<p>A group is a whole filmed layer with its frames (a layer carries its own random state, which blocks of it would share). Each held-out layer \
contributes the log ratio of its squared error before and after, a one-sided sign-flip test over layers gives each candidate a p-value, Holm's step-down \
holds the family-wise false-alarm rate of a round at α = {alpha}, and the significant candidate with the largest held-out gain is named.{}</p>\n\
<p>The printer's effects at the corners (wider heat diffusion, melt squeezed out) have no candidate: near a corner the threshold contour of the hot bulge \
differs from the widths of eqs 5-11 by far more than they change it, even on a print without them, so they need a model of the contour first.</p>\n\
<p>Parameter intervals are delete-one-layer jackknife intervals: they measure how the layers disagree, and the power study's coverage column checks them \
against what the printer did. The camera delay's interval assumes that the monitor's capture-time estimates (eq. 30) share no part of their error across \
the layers of a print, which a jackknife over the print's layers could not see; the same column checks it across prints. A print's gain is over the kinds \
of observation its named causes move, its interval a bootstrap over layers.</p>\n",
        worth_naming
    )
}

/// One row of `control_gain.parquet`: a strength and a controller.
struct ControlRow {
    effect: String,
    strength: f64,
    controller: String,
    prints: i64,
    tau_named: i64,
    oe_pct: (f64, f64, f64),
    rms_mm: (f64, f64, f64),
    max_mm: (f64, f64, f64),
    oe_vs_paper: (f64, f64, f64),
    rms_vs_paper: (f64, f64, f64),
}

impl ControlRow {
    fn read(path: &Path) -> Result<Vec<Self>, StageError> {
        let df = read_parquet(path)?;
        use control_gain as c;
        let (effect, controller) = (strs(&df, c::effect, path)?, strs(&df, c::controller, path)?);
        let (strength, prints, named) =
            (f64s(&df, c::strength, path)?, ints(&df, c::prints, path)?, ints(&df, c::tau_named, path)?);
        let [oe, rms, max, oe_vs, rms_vs] = CONTROL_TRIPLES.map(|names| f64_triples(&df, names, path));
        let (oe, rms, max, oe_vs, rms_vs) = (oe?, rms?, max?, oe_vs?, rms_vs?);
        Ok((0..df.height())
            .map(|i| Self {
                effect: effect[i].clone(),
                strength: strength[i],
                controller: controller[i].clone(),
                prints: prints[i],
                tau_named: named[i],
                oe_pct: oe[i],
                rms_mm: rms[i],
                max_mm: max[i],
                oe_vs_paper: oe_vs[i],
                rms_vs_paper: rms_vs[i],
            })
            .collect())
    }
}

fn control_part(control: &[ControlRow], stage: &str, rows: &mut Vec<Row>) -> String {
    let mut html = String::from(
        "<h4>Does the extended model compensate better?</h4>\n<p>Each print (one seed) lags its flow with a τ above the nominal by the given \
fraction. The virtual printer prints and films it, the monitor measures it as above and the engine, told nothing, names and fits what is wrong. The part is \
then printed again three times on the same printer with the same flow draws (Sec. 3.3): with the conventional command, with the filtered-B-spline compensation \
of eqs 31-39 from the first layer's widths and the nominal τ in G(s) (<i>paper</i>), and with the same compensation from the same widths and the τ the engine \
fitted (<i>extended</i>; the nominal τ when it named no τ error). Mean O_E is over the first layer's corners (eq. 40); the contour error is eq. 41 over every \
layer (Table 3); intervals are 95 % Student-t over prints, and differences to the paper's compensation are paired by print.</p>\n",
    );
    html += "<table><tr><th class=\"t\">printers' effect</th><th>strength</th><th class=\"t\">command</th><th>prints</th><th>τ named on</th><th>mean O_E (%)</th><th>contour RMS (mm)</th><th>contour max (mm)</th><th>O_E minus the paper's (points)</th><th>RMS minus the paper's (mm)</th></tr>\n";
    for r in control {
        let paired = |d| if r.controller == "paper" { "—".to_string() } else { with_interval(d) };
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td>{}</td><td class=\"t\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&r.effect.replace('_', " ")),
            r.strength,
            escape(&r.controller),
            r.prints,
            r.tau_named,
            with_interval(r.oe_pct),
            with_interval(r.rms_mm),
            with_interval(r.max_mm),
            paired(r.oe_vs_paper),
            paired(r.rms_vs_paper),
        );
        for (item, value, unit) in [("mean O_E", r.oe_pct.0, "%"), ("contour RMS", r.rms_mm.0, "mm")] {
            rows.push(Row {
                section: "discrepancy_thermal",
                item: format!("re-print {item}, {} {}, {} command", r.effect, r.strength, r.controller),
                paper: None,
                ours: value,
                unit,
                source: format!("out/discrepancy/thermal_control_gain.parquet (stage {stage}, thermal.control_gain)"),
            });
        }
    }
    html += "</table>\n<p>";
    for r in control.iter().filter(|r| r.controller == "extended") {
        let _ = write!(
            html,
            "With the flow's τ at {} times the nominal, the engine named the τ error on {} of {} prints; the extended compensation's mean O_E is {}, and its RMS contour error is {}. ",
            1.0 + r.strength,
            r.tau_named,
            r.prints,
            difference_words(r.oe_vs_paper, " points", "the paper compensation's"),
            difference_words(r.rms_vs_paper, " mm", "the paper compensation's"),
        );
    }
    html += "</p>\n";
    let _ = writeln!(
        html,
        "<p class=\"run\">Stage {stage} (thermal.control_gain): tables out/discrepancy/thermal_control_gain.parquet and thermal_control_trials.parquet (one row per print and command, with what the engine named and fitted).</p>"
    );
    html
}
