//! `report.discrepancy_thermal`: what paper 003's capture-time model (eq. 28) and its
//! assumption that every layer prints alike get wrong about what the thermal monitor
//! measures, the cause the discrepancy engine names, the extended model and its held-out
//! gain, and with a power study how often hidden effects are named (DESIGN §7). Every
//! number is read from the tables of `thermal.discrepancy` and `thermal.discovery_power`.
//!
//! Inputs: the `thermal.discrepancy` stage, then optionally `thermal.discovery_power`.

use pipeline::stage::Arity;
use pipeline::{ParamSpec, StageContext, StageError, StageKind};

use super::comparison_frame;
use super::discrepancy_fdm::{Cause, GainRow, Names, Param, PowerRow};
use super::discrepancy_inkjet::{dataset_part, power_table, DatasetText};

/// The thermal tables: one discovery per filmed print, residuals in noise standard
/// deviations, a group is a filmed layer.
const THERMAL: DatasetText = DatasetText {
    names: Names { set: "dataset", unit: "sd", unit_label: "noise sd", groups: "layers" },
    section: "discrepancy_thermal",
    kind: "thermal.discrepancy",
    power_kind: "thermal.discovery",
    prefix: "thermal",
};

/// The `report.discrepancy_thermal` stage kind.
pub struct DiscrepancyThermalSection;

impl StageKind for DiscrepancyThermalSection {
    fn name(&self) -> &'static str {
        "report.discrepancy_thermal"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "What the capture-time and layer models get wrong about the thermal monitor's measurements, the cause named, the extension and its gain → section.html, comparison.parquet"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §7 on paper 003's eq. 28 and layer model"
    }
    fn params(&self) -> &'static [ParamSpec] {
        &[]
    }
    fn arity(&self) -> Arity {
        Arity { min: 1, max: 2 }
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let dir = &ctx.inputs[0].dir;
        let stage = ctx.inputs[0].name.clone();
        let causes = Cause::read(&dir.join("causes.parquet"), &THERMAL.names)?;
        let params = Param::read(&dir.join("extension.parquet"), &THERMAL.names)?;
        let gains = GainRow::read(&dir.join("gain.parquet"), &THERMAL.names)?;
        let mut rows = Vec::new();
        let mut html = String::from("<h3>What the thermal monitor's models get wrong, and why</h3>\n");
        html += &method(&causes);
        for g in &gains {
            html += &dataset_part(g, &causes, &params, &stage, &mut rows, &THERMAL);
        }
        if let Some(input) = ctx.inputs.get(1) {
            let power = PowerRow::read(&input.dir.join("power.parquet"))?;
            html += POWER_INTRO;
            html += &power_table(&power, &input.name, &mut rows, &THERMAL);
        }
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table("comparison", &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

const POWER_INTRO: &str = "<h4>How often is a hidden effect named?</h4>\n<p>Each draw prints and films the corner test part on the virtual printer \
(the Lepton's habits on) with one effect at the given strength or none; the monitor measures it as above and the engine, told nothing, is scored: correct when it names \
the printed effect and nothing else, wrong when it names anything else. The three width effects have no candidate (see above): their draws show how often the engine \
stays silent when its model has nothing to learn.</p>\n";

fn method(causes: &[Cause]) -> String {
    let alpha = causes.first().map_or(f64::NAN, |c| c.alpha);
    format!(
        "<p>Paper 003 localises every frame by the time it was recorded (eq. 28: the true capture time is the recorded one plus a small, zero-mean \
fluctuation) and prints and measures every layer the same way, on a substrate at the bed temperature. Two of the monitor's measurements test that: each \
localised frame's capture offset, its capture time estimated by eq. 30 minus its recorded time (eq. 30's search window widened so that a delay is not \
cut off; frames at its edge and repeated images are left out), and each trajectory sample's centre temperature, the bead's temperature on the path at the \
measuring age. The baseline predicts a zero offset and, for every layer, the centre temperatures the other layers read at the same sample. Four named \
mechanisms extend it — a constant camera latency, a camera clock running at another rate, a fraction of each layer's residual heat carried into the next \
layer's substrate (read through the bead's excess over its substrate, which decays alike whatever the substrate's temperature), and a substrate warming by \
a fixed amount per layer; the second and the last are not in the virtual printer. Residuals are in noise standard deviations: each observation is divided \
by its kind's noise scale, estimated from differences no candidate explains. A group is a whole filmed layer with its frames (a layer carries its own \
random state, which blocks of it would share); each held-out layer contributes the log ratio of its squared error before and after, a one-sided sign-flip \
test over layers gives each candidate a p-value, Holm's step-down holds the family-wise false-alarm rate of a round at α = {alpha}, and the significant candidate with the largest \
held-out gain is named. The printer's effects that change the deposited width (a τ other than the nominal, wider heat diffusion, melt squeezed out) have no \
candidate: even on a print without any of them, the threshold contour of a cooling bead differs near every corner from the widths eqs 5-11 give with the \
nominal τ by more than they change it, so a width discrepancy needs a model of the contour first. Parameter intervals are delete-one-layer jackknife intervals; gain intervals are a \
bootstrap over layers.</p>\n"
    )
}
