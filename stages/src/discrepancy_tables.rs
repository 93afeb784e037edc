//! The tables every domain's discrepancy stage writes from a [`Discovery`]
//! (`fdm.discrepancy`, `inkjet.discrepancy`, `thermal.discrepancy`):
//! `residuals.parquet` (held-out residuals binned per candidate variable, baseline and
//! extended), `causes.parquet` (every candidate of every round with its cross-validated
//! gain, p-values and the verdict), `extension.parquet` (the final model's parameters
//! with jackknife intervals) and `gain.parquet` (held-out RMSE before and after), and
//! the power studies' `power.parquet` and `power_draws.parquet`. The columns are declared
//! once, per domain, in `tables::discrepancy`: a row is pushed in declared order and
//! written under the declared names, and the power tables name the columns every domain
//! shares through the FDM declarations.

use discrepancy::power::{Outcome, PowerRow};
use discrepancy::{Discovery, Model, Settings, VariableKind, Verdict};
use pipeline::params::ParamError;
use pipeline::schema::{Column, Dtype, Table as Declared};
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;
use tables::discrepancy::fdm::power_draws;
use tables::discrepancy::{power, Engine};

use crate::table::{bool_col, f64_col, frame, i64_col, str_col};

pipeline::params! {
    /// What the engine's test asks, as every discrepancy stage and study declares it.
    pub struct NamingTest {
        /// Family-wise false-alarm rate of each round, over its candidates (Holm).
        pub alpha: f64 [0.001, 0.5] = 0.05,
        /// Smallest held-out RMSE gain worth naming (%): each candidate is tested against "its gain is at most this" (a minimum-effect test; 0 tests for any gain).
        pub min_gain_pct: f64 [0.0, 50.0] = 0.0,
    }
}

impl NamingTest {
    /// The engine's settings of a study stage (a power or control study) with
    /// `max_rounds` rounds, seed `seed`, `bootstrap_draws` draws of each gain interval
    /// (the studies use the fits, not those intervals) and the default bins.
    pub(crate) fn study_settings(&self, max_rounds: i64, seed: u64, bootstrap_draws: usize) -> Settings {
        Settings {
            alpha: self.alpha,
            min_gain_pct: self.min_gain_pct,
            max_rounds: max_rounds as usize,
            bootstrap_draws,
            ..Settings::standard(seed)
        }
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
    groups { pub naming: NamingTest }
}

impl EngineParams {
    /// The engine's settings with `max_rounds` rounds and seed `seed`, checked.
    pub(crate) fn settings(&self, max_rounds: i64, seed: u64) -> Result<Settings, ParamError> {
        let settings = Settings {
            alpha: self.naming.alpha,
            max_rounds: max_rounds as usize,
            bins: self.bins as usize,
            bootstrap_draws: self.bootstrap_draws as usize,
            level: 0.95,
            seed,
            min_gain_pct: self.naming.min_gain_pct,
        };
        settings.check().map_err(|e| ParamError::new("alpha", e.to_string()))?;
        Ok(settings)
    }
}

/// The name of a mechanism of the model (`None`: the baseline).
fn mechanism_name<M: Model>(model: &M, mechanism: Option<usize>) -> String {
    mechanism.map_or(model.name(), |c| model.candidates()[c].name()).to_string()
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
    fn dtype(&self) -> Dtype {
        match self {
            Self::F(_) => Dtype::Float64,
            Self::I(_) => Dtype::Int64,
            Self::S(_) => Dtype::Str,
            Self::B(_) => Dtype::Bool,
        }
    }
}

/// A declared table being filled row by row, one value per declared column in order.
pub(crate) struct Table {
    declared: &'static Declared,
    columns: Vec<Vec<Value>>,
}

impl Table {
    /// An empty table of `declared`'s columns.
    pub(crate) fn new(declared: &'static Declared) -> Self {
        Self { declared, columns: vec![Vec::new(); declared.columns.len()] }
    }

    /// Appends a row, one value per column in order.
    pub(crate) fn push(&mut self, row: Vec<Value>) {
        let name = self.declared.name;
        debug_assert_eq!(row.len(), self.columns.len(), "{name}: row length");
        for ((column, value), declared) in self.columns.iter_mut().zip(row).zip(self.declared.columns) {
            debug_assert_eq!(value.dtype(), declared.dtype, "{name}.{}", declared.name);
            column.push(value);
        }
    }

    /// Writes the table as its declared file through the context.
    pub(crate) fn write(self, ctx: &mut StageContext) -> Result<(), StageError> {
        let columns = self.declared.columns.iter().zip(&self.columns).map(|(c, values)| to_column(c, values));
        let mut df = frame(columns.collect())?;
        ctx.write_table(self.declared.name, &mut df)?;
        Ok(())
    }
}

fn to_column(declared: &Column, values: &[Value]) -> polars::prelude::Column {
    let name = declared.name;
    match declared.dtype {
        Dtype::Int64 => i64_col(name, values.iter().map(|v| if let Value::I(x) = v { *x } else { 0 }).collect()),
        Dtype::Str => {
            str_col(name, values.iter().map(|v| if let Value::S(x) = v { x.clone() } else { String::new() }).collect())
        }
        Dtype::Bool => bool_col(name, values.iter().map(|v| matches!(v, Value::B(true))).collect()),
        Dtype::Float64 => {
            f64_col(name, values.iter().map(|v| if let Value::F(x) = v { *x } else { f64::NAN }).collect())
        }
    }
}

/// Rows of the four tables every domain's discrepancy stage writes.
pub(crate) struct DiscrepancyTables {
    /// The test's α and smallest gain worth naming, %.
    test: (f64, f64),
    residuals: Table,
    causes: Table,
    extension: Table,
    gain: Table,
}

fn s(text: &str) -> Value {
    Value::S(text.to_string())
}

impl DiscrepancyTables {
    /// Empty tables of the domain's declarations.
    pub(crate) fn new(engine: &Engine, settings: &Settings) -> Self {
        Self {
            test: (settings.alpha, settings.min_gain_pct),
            residuals: Table::new(engine.residuals),
            causes: Table::new(engine.causes),
            extension: Table::new(engine.extension),
            gain: Table::new(engine.gain),
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
        let (alpha, min_gain_pct) = self.test;
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
                    Value::F(min_gain_pct),
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

/// Whose draws a power summary's rows count: the base, the draws' noise and the causes
/// the engine names on the base as measured (`none`).
pub(crate) struct PowerOf<'a> {
    pub(crate) base: &'a str,
    pub(crate) noise: &'a str,
    pub(crate) own_causes: &'a str,
}

/// A power study's summary (`power.parquet`): per base, in order, one row per effect
/// and strength.
pub(crate) fn power_frame(summaries: &[(PowerOf<'_>, Vec<PowerRow>)]) -> Result<DataFrame, StageError> {
    let rows: Vec<(&PowerOf, &PowerRow)> =
        summaries.iter().flat_map(|(of, rows)| rows.iter().map(move |r| (of, r))).collect();
    let text = |f: &dyn Fn(&PowerOf) -> String| rows.iter().map(|(of, _)| f(of)).collect::<Vec<String>>();
    let col = |f: &dyn Fn(&PowerRow) -> f64| rows.iter().map(|(_, r)| f(r)).collect::<Vec<f64>>();
    let int = |f: &dyn Fn(&PowerRow) -> usize| rows.iter().map(|(_, r)| f(r) as i64).collect::<Vec<i64>>();
    frame(vec![
        str_col(power::base, text(&|of| of.base.to_string())),
        str_col(power::noise, text(&|of| of.noise.to_string())),
        str_col(power::own_causes, text(&|of| of.own_causes.to_string())),
        str_col(power::effect, rows.iter().map(|(_, r)| r.effect.to_string()).collect()),
        f64_col(power::strength, col(&|r| r.strength)),
        i64_col(power::draws, int(&|r| r.draws)),
        i64_col(power::correct, int(&|r| r.correct)),
        i64_col(power::wrong, int(&|r| r.wrong)),
        i64_col(power::none, int(&|r| r.none)),
        f64_col(power::correct_rate, col(&|r| r.correct_rate.0)),
        f64_col(power::correct_ci_lo, col(&|r| r.correct_rate.1)),
        f64_col(power::correct_ci_hi, col(&|r| r.correct_rate.2)),
        f64_col(power::false_alarm_rate, col(&|r| r.false_alarm_rate.0)),
        f64_col(power::false_alarm_ci_lo, col(&|r| r.false_alarm_rate.1)),
        f64_col(power::false_alarm_ci_hi, col(&|r| r.false_alarm_rate.2)),
        i64_col(power::covered, int(&|r| r.covered.0)),
        i64_col(power::with_interval, int(&|r| r.covered.1)),
        f64_col(power::coverage_rate, col(&|r| r.coverage_rate().0)),
        f64_col(power::coverage_ci_lo, col(&|r| r.coverage_rate().1)),
        f64_col(power::coverage_ci_hi, col(&|r| r.coverage_rate().2)),
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
/// as `p_<candidate>` (the domain's declaration names those columns, and the write
/// checks the frame against it).
pub(crate) fn draws_frame(base: &str, draws: &[DrawRow<'_>], candidates: &[&str]) -> Result<DataFrame, StageError> {
    let n = draws.len();
    let fitted = |k: usize| draws.iter().map(|d| d.fitted.map_or(f64::NAN, |f| [f.0, f.1, f.2][k])).collect();
    let mut columns = vec![
        str_col(power_draws::base, vec![base.to_string(); n]),
        str_col(power_draws::effect, draws.iter().map(|d| d.effect.to_string()).collect()),
        f64_col(power_draws::strength, draws.iter().map(|d| d.strength).collect()),
        i64_col(power_draws::draw, draws.iter().map(|d| d.draw as i64).collect()),
        str_col(power_draws::seed, draws.iter().map(|d| format!("{:016x}", d.seed)).collect()),
        f64_col(power_draws::injected, draws.iter().map(|d| d.injected).collect()),
        str_col(power_draws::named, draws.iter().map(|d| d.named.clone()).collect()),
        str_col(power_draws::outcome, draws.iter().map(|d| d.outcome.label().to_string()).collect()),
        f64_col(power_draws::estimate, fitted(0)),
        f64_col(power_draws::ci_lo, fitted(1)),
        f64_col(power_draws::ci_hi, fitted(2)),
    ];
    for (c, candidate) in candidates.iter().enumerate() {
        columns.push(f64_col(&format!("p_{candidate}"), draws.iter().map(|d| d.first_round_p[c]).collect()));
    }
    frame(columns)
}

#[cfg(test)]
mod tests {
    use discrepancy::Mechanism;
    use tables::discrepancy::{inkjet, thermal};

    use super::*;

    /// The `p_<candidate>` columns a study's declaration names after the FDM draws'.
    fn p_columns(draws: &Declared) -> Vec<&'static str> {
        draws.columns[power_draws::TABLE.columns.len()..].iter().map(|c| c.name).collect()
    }

    /// What [`draws_frame`] writes after the fixed columns: one per candidate, in order.
    fn written(candidates: &[&dyn Mechanism]) -> Vec<String> {
        candidates.iter().map(|c| format!("p_{}", c.name())).collect()
    }

    #[test]
    fn each_study_declares_a_p_value_column_per_candidate_of_its_model_in_order() {
        let inkjet_candidates: Vec<&dyn Mechanism> =
            models::inkjet::discrepancy::mechanisms::CANDIDATES.iter().map(|c| c as &dyn Mechanism).collect();
        assert_eq!(p_columns(&inkjet::power_draws::TABLE), written(&inkjet_candidates));
        let thermal_candidates: Vec<&dyn Mechanism> =
            models::thermal::discrepancy::CANDIDATES.iter().map(|c| c as &dyn Mechanism).collect();
        assert_eq!(p_columns(&thermal::power_draws::TABLE), written(&thermal_candidates));
    }
}
