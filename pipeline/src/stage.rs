//! The one trait every stage kind implements ([`Stage`]: its [`StageInfo`] with the named
//! roles of its inputs, and its parameters as one typed struct), the context a stage
//! runs in, and the registry from which the planner, `amrepro stages` and the docs are
//! generated.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use polars::prelude::DataFrame;

use crate::artifact;
use crate::error::StageError;
use crate::params::{ParamError, ParamSpec, Params, StageParams};
use crate::schema::{Reads, Table};

/// What the registry, the planner, `amrepro stages` and the docs know of a stage kind,
/// declared once beside it (its parameters are its [`Stage::Params`]).
#[derive(Debug)]
pub struct StageInfo {
    /// The registry name, `domain.step` (`fdm.line_summary`).
    pub name: &'static str,
    /// Bump when the outputs for the same inputs change; invalidates the cache.
    pub version: u32,
    /// One sentence: what the stage computes.
    pub summary: &'static str,
    /// The paper section or equation it implements (or the design section).
    pub implements: &'static str,
    /// Its inputs, as named roles in the order a spec lists them.
    pub inputs: &'static [Input],
    /// What its output folder is, for the roles of stages downstream.
    pub output: Output,
}

/// One named input role of a stage kind: what it accepts and how many.
#[derive(Debug, Clone, Copy)]
pub struct Input {
    /// The role's name (`sequence`, `monitor`), used in errors and docs.
    pub role: &'static str,
    /// What a spec may wire to it.
    pub takes: &'static [Source],
    /// How many inputs fill it.
    pub count: Count,
    /// One sentence: what the stage reads from it.
    pub doc: &'static str,
    /// The declared tables (and their columns) the stage reads from it; the planner
    /// checks that an upstream stage writes them ([`Stage::WRITES`]).
    pub reads: &'static [Reads],
    /// For a role that takes several kinds and reads different tables from each: per
    /// upstream kind, what the stage reads from an input of that kind (checked as
    /// `reads` is, on the inputs of that kind only).
    pub reads_by_kind: &'static [(&'static str, &'static [Reads])],
}

impl Input {
    /// One input of this role.
    pub const fn one(role: &'static str, takes: &'static [Source], doc: &'static str) -> Self {
        Self { role, takes, count: Count::One, doc, reads: &[], reads_by_kind: &[] }
    }

    /// At most one input of this role.
    pub const fn optional(role: &'static str, takes: &'static [Source], doc: &'static str) -> Self {
        Self { role, takes, count: Count::Optional, doc, reads: &[], reads_by_kind: &[] }
    }

    /// At least `min` inputs of this role.
    pub const fn many(role: &'static str, min: usize, takes: &'static [Source], doc: &'static str) -> Self {
        Self { role, takes, count: Count::Many { min }, doc, reads: &[], reads_by_kind: &[] }
    }

    /// The same role, reading these columns of these declared tables.
    pub const fn reading(self, reads: &'static [Reads]) -> Self {
        Self { reads, ..self }
    }

    /// The same role, reading from an input of each listed upstream kind what is listed
    /// beside it.
    pub const fn reading_by_kind(self, reads_by_kind: &'static [(&'static str, &'static [Reads])]) -> Self {
        Self { reads_by_kind, ..self }
    }
}

/// What an input role accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// A dataset of this kind (its `dataset.toml` says `kind = "…"`), given in the spec
    /// or written by a stage whose [`Output`] is that dataset.
    Dataset(&'static str),
    /// A folder of raw data without a `dataset.toml` (an importer's input).
    RawFolder,
    /// The output of a stage of this kind.
    Stage(&'static str),
    /// The output of any stage.
    AnyStage,
}

/// How many inputs fill a role.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Count {
    /// Exactly one.
    One,
    /// None or one.
    Optional,
    /// At least `min`.
    Many {
        /// Fewest inputs.
        min: usize,
    },
}

/// What a stage's output folder holds, as the planner matches it against roles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// Tables (and files) of its own kind.
    Tables,
    /// A dataset of this kind.
    Dataset(&'static str),
    /// The same kinds of tables as its inputs (`table.concat`): accepted wherever all its
    /// inputs would be.
    LikeInputs,
}

/// A stage kind with its parameters as one typed struct: what every stage implements.
///
/// A stage reads only the files of the inputs it declared (dataset folders or the
/// output folders of upstream stages) and writes only into its own output folder,
/// through the [`StageContext`]. It must be deterministic given its parameters, the
/// seed and its inputs: the engine caches it on exactly those.
pub trait Stage: Send + Sync + 'static {
    /// Its parameters, declared with [`crate::params!`].
    type Params: StageParams;
    /// Its name, version, docs, input roles and output.
    const INFO: &'static StageInfo;
    /// The declared tables it writes: each written frame is checked against its
    /// declaration, and stages reading it are checked against it at plan time. (Kinds
    /// whose tables are not declared yet leave it empty.)
    const WRITES: &'static [&'static Table] = &[];
    /// Constraints across parameters, checked by the planner before anything runs.
    fn check(_params: &Self::Params) -> Result<(), ParamError> {
        Ok(())
    }
    /// Runs the stage with its checked parameters. A kind that splits
    /// ([`Stage::split`]) runs as [`crate::units::run_split`]: every unit, then the merge.
    fn run(&self, ctx: &mut StageContext, params: &Self::Params) -> Result<(), StageError>;
    /// How the kind's work splits into independent units (draws, subsets, re-prints),
    /// for runs spread over processes or machines ([`crate::units`]); `None`, the
    /// default, for a stage that is one unit.
    fn split(&self) -> Option<&dyn Split> {
        None
    }
}

/// A stage kind as the registry holds it: [`Stage`] with its parameter type erased.
pub trait StageKind: Send + Sync {
    /// Its name, version, docs, input roles and output.
    fn info(&self) -> &'static StageInfo;
    /// Its parameter declarations.
    fn params(&self) -> &'static [ParamSpec];
    /// The declared tables it writes ([`Stage::WRITES`]).
    fn writes(&self) -> &'static [&'static Table];
    /// The cross-parameter check of [`Stage::check`] on values checked against
    /// [`StageKind::params`].
    fn check(&self, params: &Params) -> Result<(), ParamError>;
    /// Runs the stage.
    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError>;
    /// See [`Stage::split`].
    fn split(&self) -> Option<&dyn Split>;
    /// The kind's type's full path (`std::any::type_name`), from which the registry
    /// finds its crate ([`StageKind::crate_name`]).
    fn type_name(&self) -> &'static str;
    /// The crate that defines the kind (the first segment of its type's path), whose
    /// code the kind's cache key holds ([`Registry::code`]).
    fn crate_name(&self) -> &'static str {
        crates_named(self.type_name()).next().unwrap_or("")
    }
}

/// The first segment of every path in a type's name (`a::X<b::Y>`: `a`, `b`).
fn crates_named(type_name: &str) -> impl Iterator<Item = &str> {
    type_name
        .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
        .filter(|path| path.contains("::"))
        .map(|path| &path[..path.find("::").unwrap_or(path.len())])
}

impl<S: Stage> StageKind for S {
    fn info(&self) -> &'static StageInfo {
        S::INFO
    }
    fn params(&self) -> &'static [ParamSpec] {
        S::Params::specs()
    }
    fn writes(&self) -> &'static [&'static Table] {
        S::WRITES
    }
    fn check(&self, params: &Params) -> Result<(), ParamError> {
        S::check(&S::Params::from_params(params))
    }
    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let params = S::Params::from_params(&ctx.params);
        Stage::run(self, ctx, &params)
    }
    fn split(&self) -> Option<&dyn Split> {
        Stage::split(self)
    }
    fn type_name(&self) -> &'static str {
        std::any::type_name::<S>()
    }
}

/// One independent piece of a split stage's work.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Unit {
    /// Says which part of the work it is (`base 1 draws 200-249`); stable for a spec.
    pub key: String,
    /// Its estimated cost, relative: 1 is a light stage run once.
    pub cost: f64,
}

/// A stage kind whose work is a list of independent units and a merge of their parts.
///
/// The contract that makes a run spread over workers give the same bytes as a run in
/// one process: the units depend only on the checked parameters and the number of
/// inputs (so they are known before anything runs); a unit's part depends only on the
/// stage's context and the unit's index (its randomness seeded from `ctx.seed` and the
/// work's own indices, never from the unit boundaries); and `merge` reads the parts in
/// unit order. A one-process run goes through the same three steps
/// ([`crate::units::run_split`]), parts on disk included.
pub trait Split: Send + Sync {
    /// The units, from the checked parameters and the number of inputs.
    fn units(&self, params: &Params, inputs: usize) -> Vec<Unit>;
    /// Runs unit `index`, writing its part into `ctx`'s output folder.
    fn run_unit(&self, ctx: &mut StageContext, index: usize) -> Result<(), StageError>;
    /// Writes the stage's outputs from the parts' folders, given in unit order.
    fn merge(&self, ctx: &mut StageContext, parts: &[PathBuf]) -> Result<(), StageError>;
}

/// One input of a running stage: a folder of files.
#[derive(Debug, Clone)]
pub struct InputArtifact {
    /// The dataset or stage name in the spec.
    pub name: String,
    /// The role of the stage's kind it fills.
    pub role: &'static str,
    /// The folder holding its files.
    pub dir: PathBuf,
}

/// What a running stage sees: its parameters, inputs, seed and an output folder.
pub struct StageContext {
    /// The stage name in the spec.
    pub stage: String,
    /// The checked parameters.
    pub params: Params,
    /// The inputs in the order the spec lists them (each role's inputs together, roles
    /// in their declared order); read them by role with [`StageContext::input`].
    pub inputs: Vec<InputArtifact>,
    /// A seed derived from the spec's run seed and the stage name.
    pub seed: u64,
    /// Hash of the stage's cache key, written into table metadata.
    pub stage_hash: String,
    /// Hash of the checked parameters alone, written into table metadata.
    pub params_hash: String,
    pub(crate) out_dir: PathBuf,
    pub(crate) rows: u64,
    pub(crate) progress: Option<indicatif::MultiProgress>,
    pub(crate) writes: &'static [&'static Table],
}

impl StageContext {
    /// The path of an output file `rel` (creating its parent folders). Files written
    /// here become visible only if the whole stage succeeds.
    pub fn output_path(&self, rel: &str) -> Result<PathBuf, StageError> {
        let path = self.out_dir.join(rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| StageError::io(parent, e))?;
        }
        Ok(path)
    }

    /// The one input of role `role` (a role counted [`Count::One`]).
    ///
    /// # Panics
    /// When the kind does not declare `role` as one input: a bug in the stage, not a
    /// spec error (the planner fills every declared role).
    pub fn input(&self, role: &Input) -> &InputArtifact {
        self.optional_input(role)
            .unwrap_or_else(|| panic!("stage `{}` has no input of role `{}`", self.stage, role.role))
    }

    /// The input of role `role`, if the spec gave one.
    pub fn optional_input(&self, role: &Input) -> Option<&InputArtifact> {
        self.inputs.iter().find(|i| i.role == role.role)
    }

    /// Every input of role `role`, in spec order.
    pub fn inputs_of(&self, role: &Input) -> Vec<&InputArtifact> {
        self.inputs.iter().filter(|i| i.role == role.role).collect()
    }

    /// The stage's output folder (not yet visible to anyone else).
    pub fn output_dir(&self) -> &Path {
        &self.out_dir
    }

    /// Writes `df` as Parquet `name.parquet` with the run's key/value metadata. A kind
    /// that declares its tables ([`Stage::WRITES`]) declares every table it writes, and
    /// each must match its declaration exactly.
    pub fn write_table(&mut self, name: &str, df: &mut DataFrame) -> Result<PathBuf, StageError> {
        match self.writes.iter().find(|t| t.name == name) {
            Some(table) => table.check_frame(df).map_err(StageError::Declaration)?,
            None if !self.writes.is_empty() => {
                return Err(StageError::Declaration(format!(
                    "{name}.parquet is not among the tables the kind declares ({})",
                    self.writes.iter().map(|t| t.file()).collect::<Vec<_>>().join(", ")
                )))
            }
            None => {}
        }
        let path = self.output_path(&format!("{name}.parquet"))?;
        let meta = artifact::TableMeta {
            stage: self.stage.clone(),
            stage_hash: self.stage_hash.clone(),
            params_hash: self.params_hash.clone(),
            schema_version: 1,
        };
        artifact::write_parquet(&path, df, &meta)?;
        self.rows += df.height() as u64;
        Ok(path)
    }

    /// The same context writing into `out_dir` instead, with no progress bars: what
    /// one unit of a split stage runs in.
    pub(crate) fn for_unit(&self, out_dir: PathBuf) -> Self {
        Self {
            stage: self.stage.clone(),
            params: self.params.clone(),
            inputs: self.inputs.clone(),
            seed: self.seed,
            stage_hash: self.stage_hash.clone(),
            params_hash: self.params_hash.clone(),
            out_dir,
            rows: 0,
            progress: None,
            writes: self.writes,
        }
    }

    /// A progress bar for `len` steps of work, drawn while the stage is running for
    /// more than a second (hidden when output is not a terminal or with `--quiet`).
    /// With `len` 0 it says the work is being counted until it is given
    /// [`bar_style`] (the length of work known so far is then set on it).
    pub fn progress(&self, len: u64) -> indicatif::ProgressBar {
        let bar = indicatif::ProgressBar::new(len);
        let Some(multi) = &self.progress else {
            return indicatif::ProgressBar::hidden();
        };
        bar.set_style(if len == 0 { counting_style() } else { bar_style() });
        bar.set_prefix(self.stage.clone());
        multi.add(bar)
    }
}

/// The style of a stage's progress bar: count, elapsed time and ETA.
pub fn bar_style() -> indicatif::ProgressStyle {
    indicatif::ProgressStyle::with_template("{prefix:>18} [{bar:30}] {pos}/{len} {elapsed}, about {eta} left")
        .expect("valid template")
        .progress_chars("=> ")
}

/// The style of a bar whose work is not known yet (not an empty bar drawn full).
fn counting_style() -> indicatif::ProgressStyle {
    indicatif::ProgressStyle::with_template("{prefix:>18} counting the work, {elapsed}").expect("valid template")
}

/// Checks a kind's declaration: parameter names unique (a group may not repeat a field
/// of its struct), every default admissible for its type, input roles uniquely named and
/// at most one of them taking many inputs, with no optional role after it (roles are
/// filled in order, so inputs after a many-role could only go to required roles).
pub fn check_declaration(kind: &dyn StageKind) -> Result<(), String> {
    let params = kind.params();
    for (i, p) in params.iter().enumerate() {
        if params[..i].iter().any(|q| q.name == p.name) {
            return Err(format!("parameter `{}` is declared twice", p.name));
        }
    }
    for p in params {
        p.check_default().map_err(|why| format!("default of `{}` is not admissible: {why}", p.name))?;
    }
    let roles = kind.info().inputs;
    for (i, r) in roles.iter().enumerate() {
        if roles[..i].iter().any(|q| q.role == r.role) {
            return Err(format!("input role `{}` is declared twice", r.role));
        }
    }
    if let Some(many) = roles.iter().position(|r| matches!(r.count, Count::Many { .. })) {
        if roles[many + 1..].iter().any(|r| r.count != Count::One) {
            return Err(format!("only single roles may follow the many-role `{}`", roles[many].role));
        }
    }
    Ok(())
}

/// The code a stage kind runs, as its cache key holds it: a fingerprint and the parts it
/// is taken over, by name (for `amrepro`: the kind's crate and every workspace crate it
/// depends on, each with the hash of its sources, the lock file, the workspace manifest
/// and the toolchain), so that the cache can say which part changed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Code {
    /// The fingerprint over the parts.
    pub fingerprint: String,
    /// Part name → its hash (empty when the program names no parts).
    pub parts: BTreeMap<String, String>,
}

/// All registered stage kinds, by name, and the code each runs: the code of the crate
/// that defines it, or the whole program's.
#[derive(Default)]
pub struct Registry {
    kinds: BTreeMap<&'static str, Box<dyn StageKind>>,
    program: Code,
    by_crate: BTreeMap<String, Code>,
}

impl Registry {
    /// An empty registry with no code fingerprint (the cache then tells builds apart by
    /// the kinds' versions only).
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty registry of a program whose code hashes to `fingerprint`, which every
    /// kind's cache key holds, so a stage cached by another build runs again: a change
    /// nobody marked with a version bump is never served stale.
    pub fn with_code_fingerprint(fingerprint: &str) -> Self {
        Self { program: Code { fingerprint: fingerprint.to_string(), parts: BTreeMap::new() }, ..Self::default() }
    }

    /// An empty registry of a program whose code is `program` as a whole and
    /// `by_crate` per crate (the `amrepro` binary's, from its sources at build time): a
    /// kind's cache key holds the code of the crate defining it
    /// ([`StageKind::crate_name`]), or `program`'s when `by_crate` lacks that crate.
    /// A kind then reruns when the code it runs changes, and only then.
    pub fn with_code(program: Code, by_crate: BTreeMap<String, Code>) -> Self {
        Self { program, by_crate, ..Self::default() }
    }

    /// The whole program's code fingerprint (empty if none).
    pub fn code_fingerprint(&self) -> &str {
        &self.program.fingerprint
    }

    /// The code that kind `kind` runs ([`Self::with_code`]); the program's for a kind
    /// not registered.
    pub fn code(&self, kind: &str) -> &Code {
        let by_crate = self.get(kind).and_then(|k| self.by_crate.get(k.crate_name()));
        by_crate.unwrap_or(&self.program)
    }

    /// Adds a kind. Panics on a duplicate name, a malformed declaration
    /// ([`check_declaration`]), or a type naming a crate of the program outside the code
    /// of the crate defining it (a generic kind of one crate over a type of another,
    /// whose changes its cache key would miss): those are programming errors, caught by
    /// any test.
    pub fn register(&mut self, kind: Box<dyn StageKind>) {
        let name = kind.info().name;
        if let Err(why) = check_declaration(kind.as_ref()) {
            panic!("stage kind `{name}` is declared wrongly: {why}");
        }
        if let Some(code) = self.by_crate.get(kind.crate_name()) {
            let outside =
                crates_named(kind.type_name()).find(|c| self.by_crate.contains_key(*c) && !code.parts.contains_key(*c));
            if let Some(other) = outside {
                panic!(
                    "stage kind `{name}` ({}) runs code of crate `{other}`, which its crate's code does not hold",
                    kind.type_name()
                );
            }
        }
        assert!(self.kinds.insert(name, kind).is_none(), "stage kind `{name}` registered twice");
    }

    /// The kind called `name`.
    pub fn get(&self, name: &str) -> Option<&dyn StageKind> {
        self.kinds.get(name).map(|k| k.as_ref())
    }

    /// All kinds, sorted by name.
    pub fn kinds(&self) -> impl Iterator<Item = &dyn StageKind> {
        self.kinds.values().map(|k| k.as_ref())
    }

    /// All kind names, sorted.
    pub fn names(&self) -> Vec<&'static str> {
        self.kinds.keys().copied().collect()
    }
}

#[cfg(test)]
mod tests {
    use polars::prelude::df;

    use super::*;

    crate::table! {
        /// A test table.
        mod samples = "samples" {
            /// Where.
            x_mm: Float64 "mm",
        }
    }

    fn context(out_dir: &Path, writes: &'static [&'static Table]) -> StageContext {
        StageContext {
            stage: "s".into(),
            params: Params::default(),
            inputs: Vec::new(),
            seed: 0,
            stage_hash: "0".into(),
            params_hash: "0".into(),
            out_dir: out_dir.to_path_buf(),
            rows: 0,
            progress: None,
            writes,
        }
    }

    #[test]
    fn a_kind_is_of_the_crate_its_type_is_defined_in() {
        assert_eq!(crate::testing::FaultKind.crate_name(), "pipeline");
        let named: Vec<&str> = crates_named("stages::fdm::Fit<models::fdm::Lag, &[tables::X; 2]>").collect();
        assert_eq!(named, ["stages", "models", "tables"]);
    }

    #[test]
    fn a_kind_that_declares_its_tables_writes_only_those_and_as_declared() {
        let dir = tempfile::tempdir().unwrap();
        let mut declared = context(dir.path(), &[&samples::TABLE]);
        declared.write_table("samples", &mut df!("x_mm" => [1.0]).unwrap()).unwrap();
        let wrong = declared.write_table("samples", &mut df!("y_mm" => [1.0]).unwrap()).unwrap_err();
        assert!(wrong.to_string().contains("samples.parquet declares [x_mm: f64]"), "{wrong}");
        let undeclared = declared.write_table("other", &mut df!("x_mm" => [1.0]).unwrap()).unwrap_err();
        assert!(undeclared.to_string().contains("other.parquet is not among"), "{undeclared}");
        assert!(!dir.path().join("other.parquet").exists());
        let mut undeclaring = context(dir.path(), &[]);
        undeclaring.write_table("other", &mut df!("y_mm" => [1.0]).unwrap()).unwrap();
    }
}
