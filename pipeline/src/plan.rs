//! Spec → validated, resolved plan. Nothing executes an unchecked spec: every name,
//! input (each filling a named role of its stage's kind that accepts what it is given),
//! parameter (types, ranges and the kind's constraints across parameters), publish path
//! and the absence of cycles is checked here, and each error names the spec file, the
//! stage and the field.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

use crate::error::SpecError;
use crate::params::Params;
use crate::schema::{Reads, Table};
use crate::spec::{apply_overrides, expand_path, read_spec, Override, RawSpec, RawStage};
use crate::stage::{Count, Input, Output, Registry, Source};

/// A checked, ordered plan.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The spec file it came from.
    pub spec_file: PathBuf,
    /// Run name (folder under `out/runs/`).
    pub run_name: String,
    /// Title shown in the report.
    pub title: String,
    /// Run seed.
    pub seed: u64,
    /// External datasets.
    pub datasets: Vec<PlannedDataset>,
    /// Stages in a topological order.
    pub stages: Vec<PlannedStage>,
    /// Groups of stage indices that can run in parallel, in dependency order.
    pub waves: Vec<Vec<usize>>,
    /// Parameters set on the command line in place of the spec's
    /// (`STAGE.PARAM=VALUE`, [`Plan::from_file_with`]), as the manifest records them.
    pub overrides: Vec<String>,
}

/// A dataset folder the plan reads.
#[derive(Debug, Clone)]
pub struct PlannedDataset {
    /// Name in the spec.
    pub name: String,
    /// Resolved folder.
    pub dir: PathBuf,
    /// Where to get it if it is missing.
    pub source: String,
    /// What its `dataset.toml` says it is, as far as the planner can tell.
    pub kind: DatasetKind,
}

/// The kind of a dataset folder, read from its `dataset.toml` at planning time.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DatasetKind {
    /// `dataset.toml` names this kind.
    Declared(String),
    /// The folder has no `dataset.toml`: raw data for an importer.
    Raw,
    /// Not known before the run: the folder is missing or its `dataset.toml` unreadable
    /// (the stage reading it names the problem).
    Unknown,
}

impl DatasetKind {
    /// The kind of the folder `dir`.
    pub fn of(dir: &Path) -> Self {
        if !dir.is_dir() {
            return Self::Unknown;
        }
        let Ok(text) = std::fs::read_to_string(dir.join("dataset.toml")) else {
            return if dir.join("dataset.toml").exists() { Self::Unknown } else { Self::Raw };
        };
        match text.parse::<toml::Table>().ok().and_then(|t| t.get("kind")?.as_str().map(str::to_string)) {
            Some(kind) => Self::Declared(kind),
            None => Self::Unknown,
        }
    }
}

/// Where a stage input comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputRef {
    /// Index into [`Plan::datasets`].
    Dataset(usize),
    /// Index into [`Plan::stages`].
    Stage(usize),
}

/// A checked stage.
#[derive(Debug, Clone)]
pub struct PlannedStage {
    /// Name in the spec.
    pub name: String,
    /// Registered kind.
    pub kind: &'static str,
    /// Kind version at planning time.
    pub kind_version: u32,
    /// Complete, checked parameters.
    pub params: Params,
    /// Inputs in spec order.
    pub inputs: Vec<InputRef>,
    /// The role of the kind each input fills, parallel to `inputs`.
    pub input_roles: Vec<&'static str>,
    /// Output file → stable path relative to the out folder.
    pub publish: Vec<(String, PathBuf)>,
}

impl Plan {
    /// Reads `spec_file` and checks it against `registry`; `${VAR}` in dataset paths
    /// are read from the process environment.
    pub fn from_file(spec_file: &Path, registry: &Registry) -> Result<Self, SpecError> {
        Self::from_file_with(spec_file, &[], registry)
    }

    /// [`Self::from_file`] with parameters set on the command line
    /// ([`Override`], `amrepro run --set`), checked as the spec's own values are; an
    /// error about one of them says it was set so.
    pub fn from_file_with(spec_file: &Path, overrides: &[Override], registry: &Registry) -> Result<Self, SpecError> {
        let mut raw = read_spec(spec_file)?;
        apply_overrides(&mut raw, overrides).map_err(|(l, m)| SpecError::new(spec_file, l, m))?;
        let mut plan = Self::check(spec_file, raw, registry, |v| std::env::var(v).ok()).map_err(|mut e| {
            if let Some(o) = overrides.iter().rev().find(|o| e.location == o.location()) {
                e.message += &format!(" (set by --set {o})");
            }
            e
        })?;
        plan.overrides = overrides.iter().map(Override::to_string).collect();
        Ok(plan)
    }

    /// Checks a parsed spec.
    pub fn check(
        spec_file: &Path,
        raw: RawSpec,
        registry: &Registry,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Self, SpecError> {
        let err = |loc: String, msg: String| SpecError::new(spec_file, loc, msg);
        check_name(&raw.run.name).map_err(|m| err("run.name".into(), m))?;
        let base = spec_file.parent().unwrap_or(Path::new("."));
        let datasets = plan_datasets(&raw, base, &env).map_err(|(l, m)| err(l, m))?;
        let order = topological_order(&raw, &datasets).map_err(|(l, m)| err(l, m))?;
        let mut stages = Vec::with_capacity(order.len());
        for name in &order {
            let planned = plan_stage(name, &raw.stage[name], registry, &datasets, &order, &stages)
                .map_err(|(field, m)| err(format!("stage.{name}.{field}"), m))?;
            stages.push(planned);
        }
        check_publish_unique(&stages).map_err(|(l, m)| err(l, m))?;
        let waves = waves(&stages);
        Ok(Self {
            spec_file: spec_file.to_path_buf(),
            run_name: raw.run.name,
            title: raw.run.title,
            seed: raw.run.seed,
            datasets,
            stages,
            waves,
            overrides: Vec::new(),
        })
    }

    /// Index of the stage called `name`.
    pub fn stage_index(&self, name: &str) -> Option<usize> {
        self.stages.iter().position(|s| s.name == name)
    }

    /// The declaration of the table `name` (`name.parquet`) stage `stage` writes: its
    /// kind's own ([`crate::stage::Stage::WRITES`]), or for a kind that writes what its
    /// inputs write (`table.concat`), the first input stage's. `None` when no
    /// declaration covers it.
    pub fn declared_table(&self, stage: usize, name: &str, registry: &Registry) -> Option<&'static Table> {
        let planned = &self.stages[stage];
        let kind = registry.get(planned.kind)?;
        if kind.info().output != Output::LikeInputs {
            return kind.writes().iter().copied().find(|t| t.name == name);
        }
        planned.inputs.iter().find_map(|input| match *input {
            InputRef::Stage(i) => self.declared_table(i, name, registry),
            InputRef::Dataset(_) => None,
        })
    }

    /// Human name of an input.
    pub fn input_name(&self, input: InputRef) -> &str {
        match input {
            InputRef::Dataset(i) => &self.datasets[i].name,
            InputRef::Stage(i) => &self.stages[i].name,
        }
    }
}

type Located = (String, String);

fn check_name(name: &str) -> Result<(), String> {
    let ok =
        !name.is_empty() && name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(format!("`{name}` is not a valid name: use lowercase letters, digits, `_` and `-`"))
    }
}

fn plan_datasets(
    raw: &RawSpec,
    base: &Path,
    env: &impl Fn(&str) -> Option<String>,
) -> Result<Vec<PlannedDataset>, Located> {
    raw.dataset
        .iter()
        .map(|(name, ds)| {
            check_name(name).map_err(|m| (format!("dataset.{name}"), m))?;
            if raw.stage.contains_key(name) {
                return Err((format!("dataset.{name}"), "a stage has the same name".into()));
            }
            let dir = expand_path(&ds.path, base, env).map_err(|m| (format!("dataset.{name}.path"), m))?;
            if dir.is_file() {
                return Err((
                    format!("dataset.{name}.path"),
                    format!("{} is a file, expected a dataset folder", dir.display()),
                ));
            }
            let kind = DatasetKind::of(&dir);
            Ok(PlannedDataset { name: name.clone(), dir, source: ds.source.clone(), kind })
        })
        .collect()
}

/// Orders stages so every stage follows its stage inputs (Kahn's algorithm, ties by
/// name); an unknown input or a cycle is an error naming the stage.
fn topological_order(raw: &RawSpec, datasets: &[PlannedDataset]) -> Result<Vec<String>, Located> {
    let is_dataset = |n: &str| datasets.iter().any(|d| d.name == n);
    for (name, stage) in &raw.stage {
        check_name(name).map_err(|m| (format!("stage.{name}"), m))?;
        for input in &stage.inputs {
            if !is_dataset(input) && !raw.stage.contains_key(input) {
                return Err((
                    format!("stage.{name}.inputs"),
                    format!("`{input}` is neither a dataset nor a stage of this spec"),
                ));
            }
        }
    }
    let mut pending: BTreeMap<&str, BTreeSet<&str>> = raw
        .stage
        .iter()
        .map(|(n, s)| (n.as_str(), s.inputs.iter().map(String::as_str).filter(|i| !is_dataset(i)).collect()))
        .collect();
    let mut order = Vec::new();
    while !pending.is_empty() {
        let ready: Vec<&str> = pending.iter().filter(|(_, deps)| deps.is_empty()).map(|(n, _)| *n).collect();
        if ready.is_empty() {
            let cycle: Vec<&str> = pending.keys().copied().collect();
            return Err((format!("stage.{}.inputs", cycle[0]), format!("cycle among stages: {}", cycle.join(" → "))));
        }
        for name in ready {
            pending.remove(name);
            pending.values_mut().for_each(|deps| {
                deps.remove(name);
            });
            order.push(name.to_string());
        }
    }
    Ok(order)
}

fn plan_stage(
    name: &str,
    raw: &RawStage,
    registry: &Registry,
    datasets: &[PlannedDataset],
    order: &[String],
    planned: &[PlannedStage],
) -> Result<PlannedStage, Located> {
    let kind = registry.get(&raw.kind).ok_or_else(|| ("kind".to_string(), unknown_kind(&raw.kind, registry)))?;
    let info = kind.info();
    let roles = assign_roles(info.inputs, raw.inputs.len())
        .map_err(|()| ("inputs".to_string(), roles_text(info.name, info.inputs, raw.inputs.len())))?;
    let params = Params::check(kind.params(), &raw.params).map_err(|(f, m)| (format!("params.{f}"), m))?;
    kind.check(&params).map_err(|e| (format!("params.{}", e.field), e.message))?;
    let inputs: Vec<InputRef> = raw
        .inputs
        .iter()
        .map(|i| match datasets.iter().position(|d| &d.name == i) {
            Some(d) => InputRef::Dataset(d),
            None => InputRef::Stage(order.iter().position(|s| s == i).expect("checked in ordering")),
        })
        .collect();
    let wiring = Wiring { registry, datasets, stages: planned };
    for ((input, role), given) in inputs.iter().zip(&roles).zip(&raw.inputs) {
        if let Err(why) = wiring.check_reads(role.reads, *input).and_then(|()| wiring.check_kind_reads(role, *input)) {
            return Err((
                "inputs".into(),
                format!(
                    "role `{}` of `{}` reads {why}; got `{given}`, {}",
                    role.role,
                    info.name,
                    wiring.describe(*input)
                ),
            ));
        }
        if !wiring.accepts(role.takes, *input) {
            return Err((
                "inputs".into(),
                format!(
                    "role `{}` of `{}` takes {}; got `{given}`, {}",
                    role.role,
                    info.name,
                    sources_text(role.takes),
                    wiring.describe(*input)
                ),
            ));
        }
    }
    let publish = raw
        .publish
        .iter()
        .map(|(from, to)| {
            check_publish_path(to).map(|p| (from.clone(), p)).map_err(|m| (format!("publish.\"{from}\""), m))
        })
        .collect::<Result<_, _>>()?;
    Ok(PlannedStage {
        name: name.to_string(),
        kind: info.name,
        kind_version: info.version,
        params,
        input_roles: roles.iter().map(|r| r.role).collect(),
        inputs,
        publish,
    })
}

/// The role each of `n` inputs fills, in spec order: roles take inputs in their declared
/// order, one each, an optional role one when more are left than the roles after it
/// need, a many-role all but what the roles after it need.
fn assign_roles(roles: &'static [Input], n: usize) -> Result<Vec<&'static Input>, ()> {
    let min_of = |r: &Input| match r.count {
        Count::One => 1,
        Count::Optional => 0,
        Count::Many { min } => min,
    };
    let mut assigned = Vec::with_capacity(n);
    let mut left = n;
    for (i, role) in roles.iter().enumerate() {
        let needed_after: usize = roles[i + 1..].iter().map(min_of).sum();
        let spare = left.checked_sub(needed_after).ok_or(())?;
        let take = match role.count {
            Count::One => 1,
            Count::Optional => spare.min(1),
            Count::Many { .. } => spare,
        };
        if take < min_of(role) || take > left {
            return Err(());
        }
        assigned.extend(std::iter::repeat_n(role, take));
        left -= take;
    }
    if left == 0 {
        Ok(assigned)
    } else {
        Err(())
    }
}

/// "`kind` takes its inputs as: …; got N", listing each role and its count.
fn roles_text(kind: &str, roles: &[Input], n: usize) -> String {
    if roles.is_empty() {
        return format!("`{kind}` takes no inputs, got {n}");
    }
    let each: Vec<String> = roles
        .iter()
        .map(|r| {
            let count = match r.count {
                Count::One => "one".to_string(),
                Count::Optional => "optional".to_string(),
                Count::Many { min } => format!("at least {min}"),
            };
            format!("{} ({count}: {})", r.role, sources_text(r.takes))
        })
        .collect();
    format!("`{kind}` takes its inputs in this order: {}; got {n} input(s)", each.join(", "))
}

/// What a role accepts, in words.
pub fn sources_text(takes: &[Source]) -> String {
    let each: Vec<String> = takes
        .iter()
        .map(|s| match s {
            Source::Dataset(kind) => format!("a `{kind}` dataset (or a stage writing one)"),
            Source::RawFolder => "a folder of raw data (no dataset.toml)".to_string(),
            Source::Stage(kind) => format!("a `{kind}` stage"),
            Source::AnyStage => "any stage".to_string(),
        })
        .collect();
    each.join(" or ")
}

/// Whether an upstream stage writes a table a role reads, as far as the declarations
/// tell (ordered: one input that writes it, or might, is enough for a concatenation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Written {
    /// Its kind declares its tables, and this is not one of them.
    No,
    /// Its kind declares no tables yet.
    Unknown,
    /// It writes the table with the columns read.
    Yes,
}

/// What the planner knows of a stage's possible inputs, to match them against roles.
struct Wiring<'a> {
    registry: &'a Registry,
    datasets: &'a [PlannedDataset],
    stages: &'a [PlannedStage],
}

impl Wiring<'_> {
    /// Whether `input` is something `takes` accepts.
    fn accepts(&self, takes: &[Source], input: InputRef) -> bool {
        match input {
            InputRef::Dataset(d) => takes.iter().any(|s| match (&self.datasets[d].kind, s) {
                (DatasetKind::Declared(kind), Source::Dataset(want)) => kind == want,
                (DatasetKind::Raw, Source::RawFolder) => true,
                (DatasetKind::Unknown, Source::Dataset(_) | Source::RawFolder) => true,
                _ => false,
            }),
            InputRef::Stage(i) => {
                let stage = &self.stages[i];
                let output = self.output_of(stage);
                let direct = takes.iter().any(|s| match s {
                    Source::Stage(kind) => *kind == stage.kind,
                    Source::Dataset(kind) => output == Output::Dataset(kind),
                    Source::AnyStage => true,
                    Source::RawFolder => false,
                });
                let through = output == Output::LikeInputs
                    && !stage.inputs.is_empty()
                    && stage.inputs.iter().all(|i| self.accepts(takes, *i));
                direct || through
            }
        }
    }

    /// Whether `input` writes the declared tables and columns `reads`. A stage whose
    /// output is its inputs' (`table.concat`) writes a table when one of its inputs does,
    /// and every input that does must write the columns read (the concatenation skips an
    /// input without the table); a kind that declares no tables is not checked.
    fn check_reads(&self, reads: &[Reads], input: InputRef) -> Result<(), String> {
        let InputRef::Stage(i) = input else { return Ok(()) };
        for read in reads {
            if self.written(read, i)? == Written::No {
                let stage = &self.stages[i];
                return Err(match self.output_of(stage) {
                    Output::LikeInputs => {
                        format!("`{}`, which no input of the `{}` stage writes", read.table.file(), stage.kind)
                    }
                    _ => format!("`{}`, which a `{}` stage does not write", read.table.file(), stage.kind),
                });
            }
        }
        Ok(())
    }

    /// [`Wiring::check_reads`] of what `role` reads from an upstream of `input`'s kind.
    fn check_kind_reads(&self, role: &Input, input: InputRef) -> Result<(), String> {
        let InputRef::Stage(i) = input else { return Ok(()) };
        let kind = self.stages[i].kind;
        match role.reads_by_kind.iter().find(|(k, _)| *k == kind) {
            Some((_, reads)) => self.check_reads(reads, input),
            None => Ok(()),
        }
    }

    /// Whether stage `i` writes the table `read` reads, with its columns (an error
    /// names a column it lacks or writes as another type).
    fn written(&self, read: &Reads, i: usize) -> Result<Written, String> {
        let stage = &self.stages[i];
        if self.output_of(stage) == Output::LikeInputs {
            let mut found = Written::No;
            for input in &stage.inputs {
                let part = match *input {
                    InputRef::Stage(j) => self.written(read, j)?,
                    InputRef::Dataset(_) => Written::Unknown,
                };
                found = found.max(part);
            }
            return Ok(found);
        }
        let writes = self.registry.get(stage.kind).map_or(&[][..], |k| k.writes());
        if writes.is_empty() {
            return Ok(Written::Unknown);
        }
        let Some(written) = writes.iter().find(|t| t.name == read.table.name) else { return Ok(Written::No) };
        for column in read.columns {
            let wanted = read.table.column(column).map(|c| c.dtype);
            match written.column(column) {
                Some(c) if Some(c.dtype) == wanted => {}
                Some(c) => {
                    return Err(format!(
                        "column `{column}` of `{}` as {}, which a `{}` stage writes as {}",
                        read.table.file(),
                        wanted.map_or("an undeclared type".into(), |d| d.to_string()),
                        stage.kind,
                        c.dtype
                    ))
                }
                None => {
                    return Err(format!(
                        "column `{column}` of `{}`, which a `{}` stage does not write",
                        read.table.file(),
                        stage.kind
                    ))
                }
            }
        }
        Ok(Written::Yes)
    }

    fn output_of(&self, stage: &PlannedStage) -> Output {
        self.registry.get(stage.kind).map_or(Output::Tables, |k| k.info().output)
    }

    /// What `input` is, in words.
    fn describe(&self, input: InputRef) -> String {
        match input {
            InputRef::Dataset(d) => match &self.datasets[d].kind {
                DatasetKind::Declared(kind) => format!("a `{kind}` dataset"),
                DatasetKind::Raw => "a folder without dataset.toml".to_string(),
                DatasetKind::Unknown => "a dataset of unknown kind".to_string(),
            },
            InputRef::Stage(i) => match self.output_of(&self.stages[i]) {
                Output::Dataset(kind) => format!("a `{}` stage (writing a `{kind}` dataset)", self.stages[i].kind),
                _ => format!("a `{}` stage", self.stages[i].kind),
            },
        }
    }
}

fn unknown_kind(kind: &str, registry: &Registry) -> String {
    let names = registry.names();
    let closest = names.iter().min_by_key(|n| edit_distance(kind, n));
    match closest {
        Some(c) if edit_distance(kind, c) <= 3 => format!("unknown stage kind `{kind}`; did you mean `{c}`?"),
        _ => format!("unknown stage kind `{kind}`; known kinds: {}", names.join(", ")),
    }
}

/// Levenshtein distance, for "did you mean" hints.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

fn check_publish_path(to: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(to);
    let plain = path.components().all(|c| matches!(c, Component::Normal(_)));
    if to.is_empty() || !plain || to.starts_with("runs/") || to.starts_with("report/") {
        return Err(format!(
            "`{to}` must be a relative path inside the out folder, without `..`, outside runs/ and report/"
        ));
    }
    Ok(path)
}

fn check_publish_unique(stages: &[PlannedStage]) -> Result<(), Located> {
    let mut seen = BTreeMap::new();
    for stage in stages {
        for (from, to) in &stage.publish {
            if let Some(other) = seen.insert(to.clone(), stage.name.clone()) {
                return Err((
                    format!("stage.{}.publish.\"{from}\"", stage.name),
                    format!("`{}` is also published by stage `{other}`", to.display()),
                ));
            }
        }
    }
    Ok(())
}

/// Groups stages into waves: a stage's wave is one more than its latest stage input's.
fn waves(stages: &[PlannedStage]) -> Vec<Vec<usize>> {
    let mut level = vec![0usize; stages.len()];
    for (i, stage) in stages.iter().enumerate() {
        level[i] = stage
            .inputs
            .iter()
            .filter_map(|inp| match inp {
                InputRef::Stage(j) => Some(level[*j] + 1),
                InputRef::Dataset(_) => None,
            })
            .max()
            .unwrap_or(0);
    }
    let depth = level.iter().max().map_or(0, |m| m + 1);
    (0..depth).map(|d| (0..stages.len()).filter(|i| level[*i] == d).collect()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::StageError;
    use crate::params::ParamError;
    use crate::spec::parse_spec;
    use crate::stage::{Stage, StageContext, StageInfo};

    struct Noop;

    crate::params! {
        struct NoopParams {
            /// A knob.
            k: i64 [0, 9] = 1,
            /// Must not be below `k`.
            k_max: i64 [0, 9] = 5,
        }
    }

    const ANY: Input = Input::many("any", 0, &[Source::AnyStage, Source::RawFolder, Source::Dataset("d")], "anything");

    impl Stage for Noop {
        type Params = NoopParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.noop",
            version: 1,
            summary: "does nothing",
            implements: "tests",
            inputs: &[ANY],
            output: Output::Tables,
        };
        fn check(p: &NoopParams) -> Result<(), ParamError> {
            if p.k_max < p.k {
                return Err(ParamError::new("k_max", format!("must be at least k = {}, got {}", p.k, p.k_max)));
            }
            Ok(())
        }
        fn run(&self, _: &mut StageContext, _: &NoopParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    struct Picky;

    const WIDTHS: Input = Input::one("widths", &[Source::Dataset("w")], "the widths");
    const MODEL: Input = Input::optional("model", &[Source::Stage("test.noop")], "a model");
    const EXTRA: Input = Input::many("extra", 1, &[Source::AnyStage], "more");

    impl Stage for Picky {
        type Params = crate::params::NoParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.picky",
            version: 1,
            summary: "takes roles",
            implements: "tests",
            inputs: &[WIDTHS, MODEL, EXTRA],
            output: Output::Dataset("w"),
        };
        fn run(&self, _: &mut StageContext, _: &crate::params::NoParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    crate::table! {
        /// What the writer writes.
        mod written = "w" {
            /// A.
            a: Float64 "mm",
        }
    }

    crate::table! {
        /// What the reader expects of the same file.
        mod expected = "w" {
            /// A.
            a: Float64 "mm",
            /// B.
            b: Int64 "1",
        }
    }

    struct Writer;

    impl Stage for Writer {
        type Params = crate::params::NoParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.writer",
            version: 1,
            summary: "writes w",
            implements: "tests",
            inputs: &[],
            output: Output::Tables,
        };
        const WRITES: &'static [&'static crate::schema::Table] = &[&written::TABLE];
        fn run(&self, _: &mut StageContext, _: &crate::params::NoParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    struct Reader;

    const W: Input = Input::one("w", &[Source::Stage("test.writer"), Source::Stage("test.noop")], "w")
        .reading(&[Reads { table: &expected::TABLE, columns: &[expected::a, expected::b] }]);

    impl Stage for Reader {
        type Params = crate::params::NoParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.reader",
            version: 1,
            summary: "reads w",
            implements: "tests",
            inputs: &[W],
            output: Output::Tables,
        };
        fn run(&self, _: &mut StageContext, _: &crate::params::NoParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    crate::table! {
        /// Another table.
        mod other = "other" {
            /// C.
            c: Str "",
        }
    }

    /// A kind declaring only `other`, and a concatenation passing its inputs' tables on.
    struct OtherWriter;
    struct Concat;

    impl Stage for OtherWriter {
        type Params = crate::params::NoParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.other",
            version: 1,
            summary: "writes other",
            implements: "tests",
            inputs: &[],
            output: Output::Tables,
        };
        const WRITES: &'static [&'static crate::schema::Table] = &[&other::TABLE];
        fn run(&self, _: &mut StageContext, _: &crate::params::NoParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    const PARTS: Input = Input::many("parts", 1, &[Source::AnyStage], "parts");

    impl Stage for Concat {
        type Params = crate::params::NoParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.concat",
            version: 1,
            summary: "stacks",
            implements: "tests",
            inputs: &[PARTS],
            output: Output::LikeInputs,
        };
        fn run(&self, _: &mut StageContext, _: &crate::params::NoParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    struct ReaderOfA;

    const WA: Input = Input::one("w", &[Source::Stage("test.writer"), Source::Stage("test.other")], "w")
        .reading(&[Reads { table: &expected::TABLE, columns: &[expected::a] }]);

    impl Stage for ReaderOfA {
        type Params = crate::params::NoParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.reader_a",
            version: 1,
            summary: "reads a of w",
            implements: "tests",
            inputs: &[WA],
            output: Output::Tables,
        };
        fn run(&self, _: &mut StageContext, _: &crate::params::NoParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    /// A role taking two kinds, reading `w` (with `b`) from the writer and `other` from the other.
    struct KindReader;

    const MIXED: Input = Input::many("mixed", 1, &[Source::Stage("test.writer"), Source::Stage("test.other")], "mixed")
        .reading_by_kind(&[
            ("test.writer", &[Reads { table: &expected::TABLE, columns: &[expected::a, expected::b] }]),
            ("test.other", &[Reads { table: &other::TABLE, columns: &[other::c] }]),
        ]);

    impl Stage for KindReader {
        type Params = crate::params::NoParams;
        const INFO: &'static StageInfo = &StageInfo {
            name: "test.kind_reader",
            version: 1,
            summary: "reads per kind",
            implements: "tests",
            inputs: &[MIXED],
            output: Output::Tables,
        };
        fn run(&self, _: &mut StageContext, _: &crate::params::NoParams) -> Result<(), StageError> {
            Ok(())
        }
    }

    fn plan(text: &str) -> Result<Plan, SpecError> {
        let mut registry = Registry::new();
        registry.register(Box::new(OtherWriter));
        registry.register(Box::new(Concat));
        registry.register(Box::new(ReaderOfA));
        registry.register(Box::new(Noop));
        registry.register(Box::new(Picky));
        registry.register(Box::new(Writer));
        registry.register(Box::new(Reader));
        registry.register(Box::new(KindReader));
        let file = Path::new("t.toml");
        Plan::check(file, parse_spec(file, text)?, &registry, |_| None)
    }

    #[test]
    fn diamond_orders_into_three_waves_with_the_middle_in_parallel() {
        let p = plan(
            "[run]\nname = \"d\"\n[dataset.raw]\npath = \"x\"\n\
             [stage.top]\nkind = \"test.noop\"\ninputs = [\"raw\"]\n\
             [stage.left]\nkind = \"test.noop\"\ninputs = [\"top\"]\n\
             [stage.right]\nkind = \"test.noop\"\ninputs = [\"top\"]\n\
             [stage.bottom]\nkind = \"test.noop\"\ninputs = [\"left\", \"right\"]\n",
        )
        .unwrap();
        let names = |w: &Vec<usize>| w.iter().map(|i| p.stages[*i].name.clone()).collect::<Vec<_>>();
        let waves: Vec<Vec<String>> = p.waves.iter().map(names).collect();
        assert_eq!(waves, vec![vec!["top"], vec!["left", "right"], vec!["bottom"]]);
        assert_eq!(p.datasets[0].dir, Path::new("x"), "relative to the spec's folder (here: none)");
    }

    #[test]
    fn publish_paths_must_stay_inside_out_and_be_unique() {
        let base = "[run]\nname = \"d\"\n[stage.a]\nkind = \"test.noop\"\n";
        let err = plan(&format!("{base}publish = {{ \"t.parquet\" = \"../t.parquet\" }}\n")).unwrap_err();
        assert_eq!(err.location, "stage.a.publish.\"t.parquet\"");
        let two = format!("{base}publish = {{ \"t.parquet\" = \"x/t.parquet\" }}\n[stage.b]\nkind = \"test.noop\"\npublish = {{ \"u.parquet\" = \"x/t.parquet\" }}\n");
        assert!(plan(&two).unwrap_err().message.contains("also published by stage `a`"));
    }

    #[test]
    fn a_dataset_path_that_is_a_file_is_named_so() {
        // It used to pass the plan and fail the run with "folder … does not exist".
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("lines.csv");
        std::fs::write(&file, "x").unwrap();
        let text = format!("[run]\nname = \"d\"\n[dataset.raw]\npath = \"{}\"\n", file.display());
        let err = plan(&text).unwrap_err();
        assert_eq!(err.location, "dataset.raw.path");
        assert!(err.message.ends_with("lines.csv is a file, expected a dataset folder"), "{}", err.message);
    }

    #[test]
    fn edit_distance_suggests_close_kinds() {
        assert_eq!(edit_distance("fdm.line_sumary", "fdm.line_summary"), 1);
        assert_eq!(edit_distance("", "abc"), 3);
    }

    #[test]
    fn a_constraint_across_parameters_is_checked_at_plan_time() {
        let err =
            plan("[run]\nname = \"d\"\n[stage.a]\nkind = \"test.noop\"\nparams = { k = 4, k_max = 2 }\n").unwrap_err();
        assert_eq!(err.location, "stage.a.params.k_max");
        assert_eq!(err.message, "must be at least k = 4, got 2");
    }

    #[test]
    fn inputs_fill_roles_in_order_and_wrong_wiring_names_the_role_and_what_it_got() {
        let dir = tempfile::tempdir().unwrap();
        for (name, kind) in [("w", "w"), ("v", "v")] {
            std::fs::create_dir(dir.path().join(name)).unwrap();
            std::fs::write(dir.path().join(name).join("dataset.toml"), format!("kind = \"{kind}\"\n")).unwrap();
        }
        std::fs::create_dir(dir.path().join("raw")).unwrap();
        let head = format!(
            "[run]\nname = \"d\"\n[dataset.w]\npath = \"{0}/w\"\n[dataset.v]\npath = \"{0}/v\"\n\
             [dataset.raw]\npath = \"{0}/raw\"\n[stage.n]\nkind = \"test.noop\"\ninputs = [\"raw\"]\n",
            dir.path().display()
        );
        let picky = |inputs: &str| plan(&format!("{head}[stage.p]\nkind = \"test.picky\"\ninputs = [{inputs}]\n"));
        let p = picky("\"w\", \"n\", \"n\"").unwrap();
        assert_eq!(p.stages[p.stage_index("p").unwrap()].input_roles, ["widths", "model", "extra"]);
        let p = picky("\"w\", \"n\"").unwrap();
        assert_eq!(
            p.stages[p.stage_index("p").unwrap()].input_roles,
            ["widths", "extra"],
            "the optional role is skipped"
        );
        let err = picky("\"v\", \"n\"").unwrap_err();
        assert_eq!(err.location, "stage.p.inputs");
        assert_eq!(
            err.message,
            "role `widths` of `test.picky` takes a `w` dataset (or a stage writing one); got `v`, a `v` dataset"
        );
        let err = picky("\"raw\", \"n\"").unwrap_err();
        assert!(err.message.ends_with("got `raw`, a folder without dataset.toml"), "{}", err.message);
        let err = picky("\"w\"").unwrap_err();
        assert!(err.message.starts_with("`test.picky` takes its inputs in this order: widths (one"), "{}", err.message);
        assert!(err.message.ends_with("got 1 input(s)"), "{}", err.message);
    }

    #[test]
    fn a_stage_writing_a_dataset_fills_a_role_that_takes_that_dataset() {
        let text = "[run]\nname = \"d\"\n[stage.n]\nkind = \"test.noop\"\n\
                    [stage.p]\nkind = \"test.picky\"\ninputs = [\"n\", \"n\"]\n";
        let err = plan(text).unwrap_err();
        assert!(err.message.contains("got `n`, a `test.noop` stage"), "{}", err.message);
        let chained = "[run]\nname = \"d\"\n[stage.n]\nkind = \"test.noop\"\n\
                       [stage.p]\nkind = \"test.picky\"\ninputs = [\"missing_dataset\", \"n\"]\n\
                       [dataset.missing_dataset]\npath = \"/nonexistent/amrepro\"\n\
                       [stage.q]\nkind = \"test.picky\"\ninputs = [\"p\", \"p\"]\n";
        let p = plan(chained).unwrap();
        assert_eq!(p.stages[p.stage_index("q").unwrap()].input_roles, ["widths", "extra"]);
    }

    #[test]
    fn a_column_the_upstream_kind_does_not_write_is_refused_at_plan_time() {
        let text = "[run]\nname = \"d\"\n[stage.a]\nkind = \"test.writer\"\n\
                    [stage.r]\nkind = \"test.reader\"\ninputs = [\"a\"]\n";
        let err = plan(text).unwrap_err();
        assert_eq!(err.location, "stage.r.inputs");
        assert_eq!(
            err.message,
            "role `w` of `test.reader` reads column `b` of `w.parquet`, which a `test.writer` stage does not write; \
             got `a`, a `test.writer` stage"
        );
        let undeclared = "[run]\nname = \"d\"\n[stage.a]\nkind = \"test.noop\"\n\
                          [stage.r]\nkind = \"test.reader\"\ninputs = [\"a\"]\n";
        assert!(plan(undeclared).is_ok(), "a kind that declares no tables is not checked");
    }

    #[test]
    fn a_concatenation_writes_a_table_when_one_of_its_inputs_does() {
        let head = "[run]\nname = \"d\"\n[stage.w]\nkind = \"test.writer\"\n[stage.o]\nkind = \"test.other\"\n";
        let read = |parts: &str| {
            plan(&format!(
                "{head}[stage.c]\nkind = \"test.concat\"\ninputs = [{parts}]\n\
                 [stage.r]\nkind = \"test.reader_a\"\ninputs = [\"c\"]\n"
            ))
        };
        assert!(read("\"w\", \"o\"").is_ok(), "the writer's part has the table; the other part is skipped");
        let err = read("\"o\"").unwrap_err();
        assert_eq!(
            err.message,
            "role `w` of `test.reader_a` reads `w.parquet`, which no input of the `test.concat` stage writes; \
             got `c`, a `test.concat` stage"
        );
    }

    #[test]
    fn a_role_taking_several_kinds_checks_what_it_reads_from_each_kind() {
        let head = "[run]\nname = \"d\"\n[stage.w]\nkind = \"test.writer\"\n[stage.o]\nkind = \"test.other\"\n";
        let read = |inputs: &str| plan(&format!("{head}[stage.r]\nkind = \"test.kind_reader\"\ninputs = [{inputs}]\n"));
        assert!(read("\"o\"").is_ok(), "the other kind writes what is read from it");
        let err = read("\"o\", \"w\"").unwrap_err();
        assert_eq!(err.location, "stage.r.inputs");
        assert_eq!(
            err.message,
            "role `mixed` of `test.kind_reader` reads column `b` of `w.parquet`, which a `test.writer` stage does not \
             write; got `w`, a `test.writer` stage"
        );
    }
}
