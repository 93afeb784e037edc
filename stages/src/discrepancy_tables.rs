//! The tables every domain's discrepancy stage writes from a [`Discovery`]
//! (`fdm.discrepancy`, `inkjet.discrepancy`; docs/OUTPUTS.md lists the columns):
//! `residuals.parquet` (held-out residuals binned per candidate variable, baseline and
//! extended), `causes.parquet` (every candidate of every round with its cross-validated
//! gain, p-values and the verdict), `extension.parquet` (the final model's parameters
//! with jackknife intervals) and `gain.parquet` (held-out RMSE before and after). The
//! columns are declared once, below, with the domain's set column and unit filled in.

use discrepancy::power::{Outcome, PowerRow};
use discrepancy::{Discovery, Model, Settings, VariableKind, Verdict};
use pipeline::params::ParamError;
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;

use crate::table::{bool_col, f64_col, frame, i64_col, str_col};

pipeline::params! {
    /// The family-wise false-alarm rate, as every discrepancy stage and study declares it.
    pub struct FalseAlarm {
        /// Family-wise false-alarm rate of each round, over its candidates (Holm).
        pub alpha: f64 [0.001, 0.5] = 0.05,
    }
}

pipeline::params! {
    /// The engine's parameters every discrepancy stage declares (beyond `max_rounds`,
    /// whose range is the domain's number of candidates).
    pub struct EngineParams {
        /// Most bins per variable in residuals.parquet (equal-count bins, one per value when fewer).
        pub bins: i64 [2, 60] = 12,
        /// Bootstrap draws over groups of every gain interval.
        pub bootstrap_draws: i64 [100, 100_000] = 2000,
    }
    groups { pub false_alarm: FalseAlarm }
}

impl EngineParams {
    /// The engine's settings with `max_rounds` rounds and seed `seed`, checked.
    pub(crate) fn settings(&self, max_rounds: i64, seed: u64) -> Result<Settings, ParamError> {
        let settings = Settings {
            alpha: self.false_alarm.alpha,
            max_rounds: max_rounds as usize,
            bins: self.bins as usize,
            bootstrap_draws: self.bootstrap_draws as usize,
            level: 0.95,
            seed,
        };
        settings.check().map_err(|e| ParamError::new("alpha", e.to_string()))?;
        Ok(settings)
    }
}

/// The engine's settings for a study stage (a power or control study) from its `alpha`
/// and `max_rounds` and seed, with `bootstrap_draws` draws of each gain interval (the
/// studies use the fits, not those intervals) and the default bins.
pub(crate) fn study_settings(alpha: f64, max_rounds: i64, seed: u64, bootstrap_draws: usize) -> Settings {
    Settings { alpha, max_rounds: max_rounds as usize, bootstrap_draws, ..Settings::standard(seed) }
}

/// The name of a mechanism of the model (`None`: the baseline).
fn mechanism_name<M: Model>(model: &M, mechanism: Option<usize>) -> String {
    mechanism.map_or(model.name(), |c| model.candidates()[c].name()).to_string()
}

/// A column's type.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(crate) enum Kind {
    /// f64.
    F,
    /// i64.
    I,
    /// String.
    S,
    /// bool.
    B,
}

/// One value of a row.
#[derive(Clone)]
pub(crate) enum Value {
    /// f64.
    F(f64),
    /// i64.
    I(i64),
    /// String.
    S(String),
    /// bool.
    B(bool),
}

impl Value {
    fn kind(&self) -> Kind {
        match self {
            Self::F(_) => Kind::F,
            Self::I(_) => Kind::I,
            Self::S(_) => Kind::S,
            Self::B(_) => Kind::B,
        }
    }
}

/// The columns of each output table, declared once (docs/OUTPUTS.md lists them).
const RESIDUALS: &[(&str, Kind)] = &[
    ("{set}", Kind::S),
    ("model", Kind::S),
    ("variable", Kind::S),
    ("unit", Kind::S),
    ("bin", Kind::I),
    ("label", Kind::S),
    ("bin_lo", Kind::F),
    ("bin_hi", Kind::F),
    ("mean_residual_{unit}", Kind::F),
    ("ci_lo_{unit}", Kind::F),
    ("ci_hi_{unit}", Kind::F),
    ("n", Kind::I),
    ("groups", Kind::I),
    ("structure", Kind::F),
];
const CAUSES: &[(&str, Kind)] = &[
    ("{set}", Kind::S),
    ("round", Kind::I),
    ("base_model", Kind::S),
    ("mechanism", Kind::S),
    ("cv_rmse_before_{unit}", Kind::F),
    ("cv_rmse_after_{unit}", Kind::F),
    ("gain_pct", Kind::F),
    ("gain_ci_lo_pct", Kind::F),
    ("gain_ci_hi_pct", Kind::F),
    ("groups_helped", Kind::I),
    ("groups", Kind::I),
    ("p_value", Kind::F),
    ("p_adjusted", Kind::F),
    ("alpha", Kind::F),
    ("named", Kind::B),
    ("verdict", Kind::S),
    ("failure", Kind::S),
];
const EXTENSION: &[(&str, Kind)] = &[
    ("{set}", Kind::S),
    ("round", Kind::I),
    ("mechanism", Kind::S),
    ("parameter", Kind::S),
    ("unit", Kind::S),
    ("estimate", Kind::F),
    ("ci_lo", Kind::F),
    ("ci_hi", Kind::F),
    ("meaning", Kind::S),
];
const GAIN: &[(&str, Kind)] = &[
    ("{set}", Kind::S),
    ("baseline", Kind::S),
    ("extended_model", Kind::S),
    ("groups", Kind::I),
    ("rmse_before_{unit}", Kind::F),
    ("rmse_after_{unit}", Kind::F),
    ("gain_pct", Kind::F),
    ("gain_ci_lo_pct", Kind::F),
    ("gain_ci_hi_pct", Kind::F),
];

/// A table being filled row by row against its declared columns.
pub(crate) struct Table {
    name: &'static str,
    schema: Vec<(String, Kind)>,
    columns: Vec<Vec<Value>>,
}

impl Table {
    /// A table of these columns; `{set}` and `{unit}` in a name are replaced by the
    /// domain's set column and residual unit.
    pub(crate) fn new(name: &'static str, schema: &[(&str, Kind)], domain: Domain) -> Self {
        let schema: Vec<(String, Kind)> = schema
            .iter()
            .map(|(n, k)| (n.replace("{set}", domain.set_column).replace("{unit}", domain.unit), *k))
            .collect();
        Self { name, columns: vec![Vec::new(); schema.len()], schema }
    }

    /// Appends a row, one value per column in order.
    pub(crate) fn push(&mut self, row: Vec<Value>) {
        debug_assert_eq!(row.len(), self.schema.len(), "{}: row length", self.name);
        for ((column, value), (name, kind)) in self.columns.iter_mut().zip(row).zip(&self.schema) {
            debug_assert_eq!(value.kind(), *kind, "{}.{name}", self.name);
            column.push(value);
        }
    }

    /// Writes the table as `NAME.parquet` through the context.
    pub(crate) fn write(self, ctx: &mut StageContext) -> Result<(), StageError> {
        let columns =
            self.schema.iter().zip(&self.columns).map(|((name, kind), values)| to_column(name, *kind, values));
        let mut df = frame(columns.collect())?;
        ctx.write_table(self.name, &mut df)?;
        Ok(())
    }
}

fn to_column(name: &str, kind: Kind, values: &[Value]) -> polars::prelude::Column {
    match kind {
        Kind::I => i64_col(name, values.iter().map(|v| if let Value::I(x) = v { *x } else { 0 }).collect()),
        Kind::S => {
            str_col(name, values.iter().map(|v| if let Value::S(x) = v { x.clone() } else { String::new() }).collect())
        }
        Kind::B => bool_col(name, values.iter().map(|v| matches!(v, Value::B(true))).collect()),
        Kind::F => f64_col(name, values.iter().map(|v| if let Value::F(x) = v { *x } else { f64::NAN }).collect()),
    }
}

/// Which column names a domain's discrepancy tables carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Domain {
    /// The column naming the data set a discovery ran on (`printer`, `dataset`).
    pub(crate) set_column: &'static str,
    /// The unit of residuals and RMSEs in column names (`mm`, `um`).
    pub(crate) unit: &'static str,
}

/// Rows of the four tables every domain's discrepancy stage writes.
pub(crate) struct DiscrepancyTables {
    alpha: f64,
    residuals: Table,
    causes: Table,
    extension: Table,
    gain: Table,
}

fn s(text: &str) -> Value {
    Value::S(text.to_string())
}

impl DiscrepancyTables {
    /// The tables' names, as written.
    pub(crate) const NAMES: [&'static str; 4] = ["residuals", "causes", "extension", "gain"];

    /// Empty tables with the domain's column names.
    pub(crate) fn new(domain: Domain, alpha: f64) -> Self {
        Self {
            alpha,
            residuals: Table::new(Self::NAMES[0], RESIDUALS, domain),
            causes: Table::new(Self::NAMES[1], CAUSES, domain),
            extension: Table::new(Self::NAMES[2], EXTENSION, domain),
            gain: Table::new(Self::NAMES[3], GAIN, domain),
        }
    }

    /// The rows of one discovery on the set `label` of `groups` groups.
    pub(crate) fn add<M: Model>(&mut self, label: &str, model: &M, groups: usize, found: &Discovery<M::Fit>) {
        self.add_residuals(label, model, found);
        self.add_causes(label, model, groups, found);
        self.add_extension(label, model, found);
        self.add_gain(label, model, groups, found);
    }

    fn add_residuals<M: Model>(&mut self, label: &str, model: &M, found: &Discovery<M::Fit>) {
        for (which, structure) in [("baseline", &found.structure_before), ("extended", &found.structure_after)] {
            for v in structure {
                let variable = model.variables()[v.variable];
                for b in &v.bins {
                    let bin_label = match variable.kind {
                        VariableKind::Categorical(labels) => labels[b.bin].to_string(),
                        VariableKind::Continuous if b.lo == b.hi => format!("{}", b.lo),
                        VariableKind::Continuous => format!("[{:.4}, {:.4}]", b.lo, b.hi),
                    };
                    self.residuals.push(vec![
                        s(label),
                        s(which),
                        s(variable.name),
                        s(variable.unit),
                        Value::I(b.bin as i64),
                        Value::S(bin_label),
                        Value::F(b.lo),
                        Value::F(b.hi),
                        Value::F(b.mean),
                        Value::F(b.ci_lo),
                        Value::F(b.ci_hi),
                        Value::I(b.n as i64),
                        Value::I(b.groups as i64),
                        Value::F(v.structure),
                    ]);
                }
            }
        }
    }

    fn add_causes<M: Model>(&mut self, label: &str, model: &M, groups: usize, found: &Discovery<M::Fit>) {
        let alpha = self.alpha;
        for round in &found.rounds {
            let base: Vec<String> = round.base.iter().map(|&c| mechanism_name(model, Some(c))).collect();
            for c in &round.candidates {
                self.causes.push(vec![
                    s(label),
                    Value::I(round.index as i64),
                    Value::S(base_label(model, &base)),
                    Value::S(mechanism_name(model, Some(c.mechanism))),
                    Value::F(c.rmse_before),
                    Value::F(c.rmse_after),
                    Value::F(c.gain_pct),
                    Value::F(c.gain_ci_pct.0),
                    Value::F(c.gain_ci_pct.1),
                    Value::I(c.log_gains.iter().filter(|&&d| d > 0.0).count() as i64),
                    Value::I(groups as i64),
                    Value::F(c.p_value),
                    Value::F(c.p_adjusted),
                    Value::F(alpha),
                    Value::B(c.named),
                    s(round.verdict.label()),
                    Value::S(c.failure.clone().unwrap_or_default()),
                ]);
            }
        }
    }

    fn add_extension<M: Model>(&mut self, label: &str, model: &M, found: &Discovery<M::Fit>) {
        let round_of = |c: Option<usize>| -> i64 {
            let named_in = |r: &&discrepancy::Round| c.is_some_and(|c| r.verdict == Verdict::Named(c));
            found.rounds.iter().find(named_in).map_or(0, |r| r.index as i64)
        };
        for e in &found.extension {
            self.extension.push(vec![
                s(label),
                Value::I(round_of(e.mechanism)),
                Value::S(mechanism_name(model, e.mechanism)),
                s(e.parameter.name),
                s(e.parameter.unit),
                Value::F(e.estimate),
                Value::F(e.ci_lo),
                Value::F(e.ci_hi),
                s(e.parameter.meaning),
            ]);
        }
    }

    fn add_gain<M: Model>(&mut self, label: &str, model: &M, groups: usize, found: &Discovery<M::Fit>) {
        let named: Vec<String> = found.named.iter().map(|&c| mechanism_name(model, Some(c))).collect();
        let g = &found.gain;
        self.gain.push(vec![
            s(label),
            s(model.name()),
            Value::S(base_label(model, &named)),
            Value::I(groups as i64),
            Value::F(g.rmse_before),
            Value::F(g.rmse_after),
            Value::F(g.gain_pct),
            Value::F(g.ci_pct.0),
            Value::F(g.ci_pct.1),
        ]);
    }

    /// Writes the four tables.
    pub(crate) fn write(self, ctx: &mut StageContext) -> Result<(), StageError> {
        for table in [self.residuals, self.causes, self.extension, self.gain] {
            table.write(ctx)?;
        }
        Ok(())
    }
}

/// `lag_model` or `lag_model + width_cap + …`.
fn base_label<M: Model>(model: &M, extensions: &[String]) -> String {
    std::iter::once(model.name().to_string()).chain(extensions.iter().cloned()).collect::<Vec<_>>().join(" + ")
}

/// A power study's summary (`power.parquet`): one row per effect and strength.
pub(crate) fn power_frame(base: &str, rows: &[PowerRow]) -> Result<DataFrame, StageError> {
    let n = rows.len();
    let col = |f: &dyn Fn(&PowerRow) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
    let int = |f: &dyn Fn(&PowerRow) -> usize| rows.iter().map(|r| f(r) as i64).collect::<Vec<i64>>();
    frame(vec![
        str_col("base", vec![base.to_string(); n]),
        str_col("noise", vec!["virtual".to_string(); n]),
        str_col("own_causes", vec!["none".to_string(); n]),
        str_col("effect", rows.iter().map(|r| r.effect.to_string()).collect()),
        f64_col("strength", col(&|r| r.strength)),
        i64_col("draws", int(&|r| r.draws)),
        i64_col("correct", int(&|r| r.correct)),
        i64_col("wrong", int(&|r| r.wrong)),
        i64_col("none", int(&|r| r.none)),
        f64_col("correct_rate", col(&|r| r.correct_rate.0)),
        f64_col("correct_ci_lo", col(&|r| r.correct_rate.1)),
        f64_col("correct_ci_hi", col(&|r| r.correct_rate.2)),
        f64_col("false_alarm_rate", col(&|r| r.false_alarm_rate.0)),
        f64_col("false_alarm_ci_lo", col(&|r| r.false_alarm_rate.1)),
        f64_col("false_alarm_ci_hi", col(&|r| r.false_alarm_rate.2)),
        i64_col("covered", int(&|r| r.covered.0)),
        i64_col("with_interval", int(&|r| r.covered.1)),
        f64_col("coverage_rate", col(&|r| r.coverage_rate().0)),
        f64_col("coverage_ci_lo", col(&|r| r.coverage_rate().1)),
        f64_col("coverage_ci_hi", col(&|r| r.coverage_rate().2)),
    ])
}

/// One draw of a power study, as `power_draws.parquet` stores it.
pub(crate) struct DrawRow<'a> {
    pub(crate) effect: &'a str,
    pub(crate) strength: f64,
    pub(crate) draw: usize,
    pub(crate) seed: u64,
    /// The strength the draw carries (signed).
    pub(crate) injected: f64,
    /// Mechanisms named, `+`-joined (`none`).
    pub(crate) named: String,
    pub(crate) outcome: Outcome,
    /// Fitted strength with its interval, when correct.
    pub(crate) fitted: Option<(f64, f64, f64)>,
    /// Each candidate's first-round p-value, in `candidates` order.
    pub(crate) first_round_p: &'a [f64],
}

/// `power_draws.parquet`: one row per draw, with each candidate's first-round p-value
/// as `p_<candidate>`.
pub(crate) fn draws_frame(base: &str, draws: &[DrawRow<'_>], candidates: &[&str]) -> Result<DataFrame, StageError> {
    let n = draws.len();
    let fitted = |k: usize| draws.iter().map(|d| d.fitted.map_or(f64::NAN, |f| [f.0, f.1, f.2][k])).collect();
    let mut columns = vec![
        str_col("base", vec![base.to_string(); n]),
        str_col("effect", draws.iter().map(|d| d.effect.to_string()).collect()),
        f64_col("strength", draws.iter().map(|d| d.strength).collect()),
        i64_col("draw", draws.iter().map(|d| d.draw as i64).collect()),
        str_col("seed", draws.iter().map(|d| format!("{:016x}", d.seed)).collect()),
        f64_col("injected", draws.iter().map(|d| d.injected).collect()),
        str_col("named", draws.iter().map(|d| d.named.clone()).collect()),
        str_col("outcome", draws.iter().map(|d| d.outcome.label().to_string()).collect()),
        f64_col("estimate", fitted(0)),
        f64_col("ci_lo", fitted(1)),
        f64_col("ci_hi", fitted(2)),
    ];
    for (c, candidate) in candidates.iter().enumerate() {
        columns.push(f64_col(&format!("p_{candidate}"), draws.iter().map(|d| d.first_round_p[c]).collect()));
    }
    frame(columns)
}
