//! `fdm.discrepancy`: what the lag model (`fdm.lag_model`, DESIGN §5.1) — or, with
//! `baseline = "piecewise_model"`, paper 000's piecewise model — gets wrong on
//! measured line widths, which physical cause explains it, the extended model and its
//! held-out gain (DESIGN §7) — the FDM domain of the `discrepancy` engine
//! (`models::fdm::discrepancy`). One run per printer over the lines of every input
//! of that printer; a group is one printed line.
//!
//! Outputs (documented in docs/OUTPUTS.md): `residuals.parquet` (held-out residuals
//! binned per candidate variable, baseline and extended), `causes.parquet` (every
//! candidate of every round with its cross-validated gain, p-values and the verdict),
//! `extension.parquet` (the final model's parameters with jackknife intervals),
//! `gain.parquet` (held-out RMSE before and after) and `predictions.parquet` (each
//! line's held-out predictions before and after, for the figures).

use discrepancy::{discover, Discovery};
use models::fdm::discrepancy::piecewise_baseline::PiecewiseModel;
use models::fdm::discrepancy::{FdmLine, FdmModel};
use models::fdm::PiecewiseParams;
use models::progress::Progress;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};

use crate::discrepancy_tables::{engine_settings, DiscrepancyTables, Domain, Kind, Table, Value, ALPHA, BINS};
use crate::fdm::lines::PrinterLines;
use crate::progress::StageProgress;

/// The `fdm.discrepancy` stage kind.
pub struct DiscrepancyStage;

const PARAMS: &[ParamSpec] = &[
    START_BLOB,
    ParamSpec {
        name: "baseline",
        ty: ParamType::Choice(&["lag_model", "piecewise_model"]),
        default: ParamDefault::Str("lag_model"),
        doc: "The model whose errors are searched: the lag model (DESIGN §5.1; seven candidates) or paper 000's piecewise model (eqs 1-3 with the r_a × r_F grid search; the three candidates that act on its widths: bed_tilt, gear_eccentricity, flow_saturation).",
    },
    ParamSpec {
        name: "r_step",
        ty: ParamType::Float { min: 0.005, max: 0.1 },
        default: ParamDefault::Float(0.02),
        doc: "With the piecewise baseline: step of its r_a, r_F grid over [0.9, 1.1] (paper 000: 0.01; every fold and candidate fits it again, so the default is coarser).",
    },
    ALPHA,
    ParamSpec {
        name: "max_rounds",
        ty: ParamType::Int { min: 0, max: 7 },
        default: ParamDefault::Int(3),
        doc: "Most causes named: after each, the extended model is the baseline and the search repeats.",
    },
    BINS,
    SMOOTHING,
    ParamSpec {
        name: "bootstrap_draws",
        ty: ParamType::Int { min: 100, max: 100_000 },
        default: ParamDefault::Int(2000),
        doc: "Bootstrap draws over lines of every gain interval.",
    },
];

/// Which printers' lines start with a blob.
pub(crate) const START_BLOB: ParamSpec = ParamSpec {
    name: "start_blob",
    ty: ParamType::Text,
    default: ParamDefault::Str("all"),
    doc: "Printers whose lines start with a blob (the lag's initial flow excess is fitted): `all`, `none` or a comma-separated list of printer names (paper 000: `taz5`; the Taz 6 has none, Fig. 8).",
};

/// The along-path smoothing of the lag model.
pub(crate) const SMOOTHING: ParamSpec = ParamSpec {
    name: "smoothing_mm",
    ty: ParamType::Float { min: 0.0, max: 10.0 },
    default: ParamDefault::Float(0.5),
    doc: "Width smoothing along the path: about one nozzle diameter (0.5 mm, paper 000 Table I), as fdm.lag_model.",
};

impl StageKind for DiscrepancyStage {
    fn name(&self) -> &'static str {
        "fdm.discrepancy"
    }
    fn version(&self) -> u32 {
        2
    }
    fn summary(&self) -> &'static str {
        "What the lag model gets wrong, the cause named by grouped cross-validation among 7 physical mechanisms, the extended model and its held-out gain → residuals, causes, extension, gain, predictions (.parquet)"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §7 on paper 000's lines (the lag model of DESIGN §5.1, or paper 000's piecewise model eqs 1-3, as the baseline)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::at_least(1)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let printers = read_printers(ctx)?;
        let blob = StartBlob::parse(ctx, &printers)?;
        let settings = engine_settings(ctx)?;
        let smoothing = ctx.params.f64("smoothing_mm");
        let mut tables = Tables::new(settings.alpha);
        let progress = StageProgress::with_steps(ctx, printers.len() as u64);
        for (printer, lines) in &printers {
            let lag = FdmModel::new(lines, blob.has(printer), smoothing);
            if ctx.params.str("baseline") == "piecewise_model" {
                let model = PiecewiseModel { params: piecewise_params(ctx, blob.has(printer))?, lag };
                let found = discover(&model, lines, &[], &settings).map_err(|e| engine_failed(printer, e))?;
                tables.add(printer, &model, lines, &found);
            } else {
                let found = discover(&lag, lines, &[], &settings).map_err(|e| engine_failed(printer, e))?;
                tables.add(printer, &lag, lines, &found);
            }
            progress.done(1);
        }
        tables.write(ctx)
    }
}

/// The piecewise fit's settings: paper 000's, with the `r_step` of the stage.
fn piecewise_params(ctx: &StageContext, start_blob: bool) -> Result<models::fdm::PiecewiseValidParams, StageError> {
    let defaults =
        if start_blob { PiecewiseParams::paper_defaults() } else { PiecewiseParams::paper_defaults_without_blob() };
    PiecewiseParams { r_step: ctx.params.f64("r_step"), ..defaults }
        .check()
        .map_err(|e| StageError::Params { stage: ctx.stage.clone(), message: e.to_string() })
}

/// Every input's lines as groups, pooled by printer in the order first seen.
pub(crate) fn read_printers(ctx: &StageContext) -> Result<Vec<(String, Vec<FdmLine>)>, StageError> {
    let mut printers: Vec<(String, Vec<FdmLine>)> = Vec::new();
    for input in &ctx.inputs {
        let read = PrinterLines::read(&input.dir)?;
        let groups = read.lines.into_iter().zip(read.conditions).map(|(l, c)| FdmLine::new(c, l));
        match printers.iter_mut().find(|(p, _)| *p == read.printer) {
            Some((_, lines)) => lines.extend(groups),
            None => printers.push((read.printer, groups.collect())),
        }
    }
    Ok(printers)
}

/// An engine failure as a stage error naming the printer.
pub(crate) fn engine_failed(printer: &str, err: impl std::fmt::Display) -> StageError {
    StageError::Domain(format!("discrepancy engine on printer `{printer}`: {err}").into())
}

/// The `start_blob` parameter, checked against the printers present.
pub(crate) enum StartBlob {
    All,
    None,
    Only(Vec<String>),
}

impl StartBlob {
    pub(crate) fn parse(ctx: &StageContext, printers: &[(String, Vec<FdmLine>)]) -> Result<Self, StageError> {
        let raw = ctx.params.str("start_blob").trim();
        let parsed = match raw {
            "all" => Self::All,
            "none" => Self::None,
            list => Self::Only(list.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect()),
        };
        if let Self::Only(names) = &parsed {
            if let Some(unknown) = names.iter().find(|n| !printers.iter().any(|(p, _)| p == *n)) {
                let known: Vec<&str> = printers.iter().map(|(p, _)| p.as_str()).collect();
                return Err(StageError::Params {
                    stage: ctx.stage.clone(),
                    message: format!(
                        "start_blob names printer `{unknown}`, which no input has (inputs: {}); use `all`, `none` or a list of these",
                        known.join(", ")
                    ),
                });
            }
        }
        Ok(parsed)
    }

    pub(crate) fn has(&self, printer: &str) -> bool {
        match self {
            Self::All => true,
            Self::None => false,
            Self::Only(names) => names.iter().any(|n| n == printer),
        }
    }
}

/// The FDM tables' names: one discovery per printer, widths in mm.
const FDM: Domain = Domain { set_column: "printer", unit: "mm" };

const PREDICTIONS: &[(&str, Kind)] = &[
    ("printer", Kind::S),
    ("condition", Kind::S),
    ("accel_mm_s2", Kind::F),
    ("feed_mm_s", Kind::F),
    ("position_mm", Kind::F),
    ("measured_width_mm", Kind::F),
    ("baseline_width_mm", Kind::F),
    ("extended_width_mm", Kind::F),
];

/// The four discrepancy tables and each line's held-out predictions.
struct Tables {
    tables: DiscrepancyTables,
    predictions: Table,
}

impl Tables {
    fn new(alpha: f64) -> Self {
        Self { tables: DiscrepancyTables::new(FDM, alpha), predictions: Table::new("predictions", PREDICTIONS, FDM) }
    }

    fn add<M: discrepancy::Model<Group = FdmLine>>(
        &mut self,
        printer: &str,
        model: &M,
        lines: &[FdmLine],
        found: &Discovery<M::Fit>,
    ) {
        self.tables.add(printer, model, lines.len(), found);
        for (k, line) in lines.iter().enumerate() {
            let m = &line.line;
            for i in 0..m.len() {
                self.predictions.push(vec![
                    Value::S(printer.to_string()),
                    Value::S(line.label.clone()),
                    Value::F(m.nominal.accel_mm_s2),
                    Value::F(m.nominal.feed_mm_s),
                    Value::F(m.positions_mm[i]),
                    Value::F(m.widths_mm[i]),
                    Value::F(found.baseline.predictions[k][i]),
                    Value::F(found.extended.predictions[k][i]),
                ]);
            }
        }
    }

    fn write(self, ctx: &mut StageContext) -> Result<(), StageError> {
        self.tables.write(ctx)?;
        self.predictions.write(ctx)
    }
}
