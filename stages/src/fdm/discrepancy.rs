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

use discrepancy::{discover, Discovery, Settings};
use models::fdm::discrepancy::piecewise_baseline::PiecewiseModel;
use models::fdm::discrepancy::{FdmLine, FdmModel};
use models::fdm::PiecewiseParams;
use models::progress::Progress;
use pipeline::params::ParamError;
use pipeline::schema::Table as Declared;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{InputArtifact, StageContext, StageError};
use tables::discrepancy::fdm::{causes, extension, gain, predictions, residuals, ENGINE};

use crate::discrepancy_tables::{DiscrepancyTables, EngineParams, Table, Value};
use crate::fdm::lines::{model_param_error, PrinterLines};
use crate::progress::StageProgress;
use crate::roles;

/// The `fdm.discrepancy` stage kind.
pub struct DiscrepancyStage;

pipeline::choice! {
    /// The model whose errors the engine searches.
    pub enum Baseline {
        /// The lag model (DESIGN §5.1).
        LagModel = "lag_model",
        /// Paper 000's piecewise model (eqs 1-3 with the r_a × r_F grid search).
        PiecewiseModel = "piecewise_model",
    }
}

pipeline::params! {
    /// The lag model as the FDM discrepancy stages fit it: which printers' lines start
    /// with a blob, and the smoothing along the path.
    pub struct LagBaseline {
        /// Printers whose lines start with a blob (the lag's initial flow excess is fitted): `all`, `none` or a comma-separated list of printer names (paper 000: `taz5`; the Taz 6 has none, Fig. 8).
        pub start_blob: String = "all",
        /// Width smoothing along the path: about one nozzle diameter (0.5 mm, paper 000 Table I), as fdm.lag_model.
        pub smoothing_mm: f64 [0.0, 10.0] = 0.5,
    }
}

pipeline::params! {
    /// The parameters of `fdm.discrepancy`.
    pub struct DiscrepancyParams {
        /// The model whose errors are searched: the lag model (DESIGN §5.1; seven candidates) or paper 000's piecewise model (eqs 1-3 with the r_a × r_F grid search; the three candidates that act on its widths: bed_tilt, gear_eccentricity, flow_saturation).
        pub baseline: Baseline = Baseline::LagModel,
        /// With the piecewise baseline: step of its r_a, r_F grid over [0.9, 1.1] (paper 000: 0.01; every fold and candidate fits it again, so the default is coarser).
        pub r_step: f64 [0.005, 0.1] = 0.02,
        /// Most causes named: after each, the extended model is the baseline and the search repeats.
        pub max_rounds: i64 [0, 7] = 3,
    }
    groups { pub lag: LagBaseline, pub engine: EngineParams }
}

impl Stage for DiscrepancyStage {
    type Params = DiscrepancyParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.discrepancy",
        // 3: causes.parquet has the test's min_gain_pct.
        version: 3,
        summary: "What the lag model gets wrong, the cause named by grouped cross-validation among 7 physical mechanisms, the extended model and its held-out gain → residuals, causes, extension, gain, predictions (.parquet)",
        implements: "DESIGN §7 on paper 000's lines (the lag model of DESIGN §5.1, or paper 000's piecewise model eqs 1-3, as the baseline)",
        inputs: &[roles::FDM_WIDTHS_MANY],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Declared] =
        &[&residuals::TABLE, &causes::TABLE, &extension::TABLE, &gain::TABLE, &predictions::TABLE];

    fn check(p: &DiscrepancyParams) -> Result<(), ParamError> {
        p.engine.settings(p.max_rounds, 0)?;
        piecewise_params(p.r_step, true).map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &DiscrepancyParams) -> Result<(), StageError> {
        let printers = read_printers(ctx.inputs_of(&roles::FDM_WIDTHS_MANY))?;
        let blob = StartBlob::parse(&p.lag.start_blob, &printers).map_err(|e| StageError::params(ctx, e))?;
        let settings = p.engine.settings(p.max_rounds, ctx.seed).map_err(|e| StageError::params(ctx, e))?;
        let mut tables = Tables::new(&settings);
        let progress = StageProgress::with_steps(ctx, printers.len() as u64);
        for (printer, lines) in &printers {
            let lag = FdmModel::new(lines, blob.has(printer), p.lag.smoothing_mm);
            match p.baseline {
                Baseline::PiecewiseModel => {
                    let params =
                        piecewise_params(p.r_step, blob.has(printer)).map_err(|e| StageError::params(ctx, e))?;
                    let model = PiecewiseModel { params, lag };
                    let found = discover(&model, lines, &[], &settings).map_err(|e| engine_failed(printer, e))?;
                    tables.add(printer, &model, lines, &found);
                }
                Baseline::LagModel => {
                    let found = discover(&lag, lines, &[], &settings).map_err(|e| engine_failed(printer, e))?;
                    tables.add(printer, &lag, lines, &found);
                }
            }
            progress.done(1);
        }
        tables.write(ctx)
    }
}

/// The piecewise fit's settings: paper 000's, with the stage's `r_step`.
fn piecewise_params(r_step: f64, start_blob: bool) -> Result<models::fdm::PiecewiseValidParams, ParamError> {
    let defaults =
        if start_blob { PiecewiseParams::paper_defaults() } else { PiecewiseParams::paper_defaults_without_blob() };
    PiecewiseParams { r_step, ..defaults }.check().map_err(model_param_error)
}

/// Every input's lines as groups, pooled by printer in the order first seen.
pub(crate) fn read_printers(inputs: Vec<&InputArtifact>) -> Result<Vec<(String, Vec<FdmLine>)>, StageError> {
    let mut printers: Vec<(String, Vec<FdmLine>)> = Vec::new();
    for input in inputs {
        let read = PrinterLines::read(&input.dir)?;
        let groups = read.lines.into_iter().zip(read.conditions).map(|(l, c)| FdmLine::new(c, l));
        match printers.iter_mut().find(|(p, _)| *p == read.printer) {
            Some((_, lines)) => lines.extend(groups),
            None => printers.push((read.printer, groups.collect())),
        }
    }
    Ok(printers)
}

/// An engine failure as a stage error naming the printer and what the engine's groups are.
pub(crate) fn engine_failed(printer: &str, err: impl std::fmt::Display) -> StageError {
    StageError::Domain(
        format!(
            "discrepancy engine on printer `{printer}` (its groups are its lines, in the order of lines.csv): {err}"
        )
        .into(),
    )
}

/// The `start_blob` parameter, checked against the printers present.
pub(crate) enum StartBlob {
    All,
    None,
    Only(Vec<String>),
}

impl StartBlob {
    pub(crate) fn parse(raw: &str, printers: &[(String, Vec<FdmLine>)]) -> Result<Self, ParamError> {
        let raw = raw.trim();
        let parsed = match raw {
            "all" => Self::All,
            "none" => Self::None,
            list => Self::Only(list.split(',').map(|s| s.trim().to_string()).filter(|s| !s.is_empty()).collect()),
        };
        if let Self::Only(names) = &parsed {
            if let Some(unknown) = names.iter().find(|n| !printers.iter().any(|(p, _)| p == *n)) {
                let known: Vec<&str> = printers.iter().map(|(p, _)| p.as_str()).collect();
                return Err(ParamError::new(
                    "start_blob",
                    format!(
                        "names printer `{unknown}`, which no input has (inputs: {}); use `all`, `none` or a list of these",
                        known.join(", ")
                    ),
                ));
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

/// The four discrepancy tables and each line's held-out predictions.
struct Tables {
    tables: DiscrepancyTables,
    predictions: Table,
}

impl Tables {
    fn new(settings: &Settings) -> Self {
        Self { tables: DiscrepancyTables::new(&ENGINE, settings), predictions: Table::new(&predictions::TABLE) }
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
                // In `predictions`' declared order.
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
