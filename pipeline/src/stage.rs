//! The one trait every stage kind implements, the context a stage runs in, and the
//! registry from which the planner, `amrepro stages` and the docs are generated.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use polars::prelude::DataFrame;

use crate::artifact;
use crate::error::StageError;
use crate::params::{ParamSpec, Params};

/// How many inputs a stage kind takes.
#[derive(Debug, Clone, Copy)]
pub struct Arity {
    /// Fewest inputs.
    pub min: usize,
    /// Most inputs.
    pub max: usize,
}

impl Arity {
    /// Exactly `n` inputs.
    pub const fn exactly(n: usize) -> Self {
        Self { min: n, max: n }
    }

    /// At least `n` inputs.
    pub const fn at_least(n: usize) -> Self {
        Self { min: n, max: usize::MAX }
    }
}

/// A stage kind: a small struct that turns input folders into output files.
///
/// A stage reads only the files of the inputs it declared (dataset folders or the
/// output folders of upstream stages) and writes only into its own output folder,
/// through the [`StageContext`]. It must be deterministic given its parameters, the
/// seed and its inputs: the engine caches it on exactly those.
pub trait StageKind: Send + Sync {
    /// The registry name, `domain.step` (`fdm.line_summary`).
    fn name(&self) -> &'static str;
    /// Bump when the outputs for the same inputs change; invalidates the cache.
    fn version(&self) -> u32;
    /// One sentence: what the stage computes.
    fn summary(&self) -> &'static str;
    /// The paper section or equation it implements (or the design section).
    fn implements(&self) -> &'static str;
    /// Its parameters.
    fn params(&self) -> &'static [ParamSpec];
    /// How many inputs it takes.
    fn arity(&self) -> Arity;
    /// Runs the stage. A kind that splits ([`StageKind::split`]) runs as
    /// [`crate::units::run_split`]: every unit, then the merge.
    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError>;
    /// How the kind's work splits into independent units (draws, subsets, re-prints),
    /// for runs spread over processes or machines ([`crate::units`]); `None`, the
    /// default, for a stage that is one unit.
    fn split(&self) -> Option<&dyn Split> {
        None
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
    /// The folder holding its files.
    pub dir: PathBuf,
}

/// What a running stage sees: its parameters, inputs, seed and an output folder.
pub struct StageContext {
    /// The stage name in the spec.
    pub stage: String,
    /// The checked parameters.
    pub params: Params,
    /// The inputs in the order the spec lists them.
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

    /// The stage's output folder (not yet visible to anyone else).
    pub fn output_dir(&self) -> &Path {
        &self.out_dir
    }

    /// Writes `df` as Parquet `name.parquet` with the run's key/value metadata.
    pub fn write_table(&mut self, name: &str, df: &mut DataFrame) -> Result<PathBuf, StageError> {
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

/// All registered stage kinds, by name.
#[derive(Default)]
pub struct Registry {
    kinds: BTreeMap<&'static str, Box<dyn StageKind>>,
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a kind. Panics on a duplicate name: that is a programming error.
    pub fn register(&mut self, kind: Box<dyn StageKind>) {
        let name = kind.name();
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
