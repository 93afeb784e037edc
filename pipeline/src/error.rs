//! Typed errors of the engine: spec errors (before anything runs) apart from stage
//! errors (while a stage runs).

use std::path::PathBuf;

/// A spec that cannot become a plan. Always names the spec file and, where there is
/// one, the line or the `stage.NAME.field` it is about.
#[derive(Debug, thiserror::Error)]
#[error("{}: {location}: {message}", file.display())]
pub struct SpecError {
    /// The spec file.
    pub file: PathBuf,
    /// Where in the spec: `line 12, column 3` or `stage.loo.params.step`.
    pub location: String,
    /// What was wrong and what was expected.
    pub message: String,
}

impl SpecError {
    /// Builds an error about `location` in `file`.
    pub fn new(file: &std::path::Path, location: impl Into<String>, message: impl Into<String>) -> Self {
        Self { file: file.to_path_buf(), location: location.into(), message: message.into() }
    }
}

/// A failure while a stage runs.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// An input file is malformed; names the file and, where known, the line or field.
    #[error("{}{}: {expected}", file.display(), location.as_ref().map(|l| format!(":{l}")).unwrap_or_default())]
    BadInput {
        /// The offending file.
        file: PathBuf,
        /// Line number or field, if known.
        location: Option<String>,
        /// What was expected there.
        expected: String,
    },
    /// Parameters that pass their one-by-one checks but not a check across them
    /// (e.g. a window's start after its end), found when the stage runs.
    #[error("stage `{stage}` params: {message}")]
    Params {
        /// The stage name in the spec.
        stage: String,
        /// What was wrong and what was expected.
        message: String,
    },
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A table could not be read or written.
    #[error("{}: {source}", path.display())]
    Table {
        /// The table file.
        path: PathBuf,
        /// The polars error.
        source: polars::error::PolarsError,
    },
    /// An error from a domain library (dataset reader, model fit), with its message.
    #[error(transparent)]
    Domain(Box<dyn std::error::Error + Send + Sync>),
    /// The stage wrote a table that breaks its declaration (`pipeline::schema`): a bug
    /// in amrepro, caught before the file is written.
    #[error("internal error, a bug in amrepro (please report it): {0}")]
    Declaration(String),
    /// The stage's code panicked: a bug in amrepro, caught so the run ends cleanly.
    #[error("internal error, a bug in amrepro (please report it with the input that caused it): {0}")]
    Panic(String),
}

impl StageError {
    /// Wraps a domain library error.
    pub fn domain<E: std::error::Error + Send + Sync + 'static>(err: E) -> Self {
        Self::Domain(Box::new(err))
    }

    /// A check across `ctx`'s parameters that failed when the stage ran.
    pub fn params(ctx: &crate::stage::StageContext, err: crate::params::ParamError) -> Self {
        Self::Params { stage: ctx.stage.clone(), message: format!("{}: {}", err.field, err.message) }
    }

    /// Wraps an I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io { path: path.into(), source }
    }
}

/// An error of a whole run: which stage failed and why.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A stage failed; what readers see (stage folders, published copies, manifest) is
    /// as the last complete run left it (see `commit`).
    #[error("stage `{stage}` ({kind}) failed: {source}")]
    Stage {
        /// The stage name in the spec.
        stage: String,
        /// Its kind.
        kind: String,
        /// Why it failed.
        source: StageError,
    },
    /// Bookkeeping I/O of the engine failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Another process holds the out folder's lock.
    #[error("out folder {} is in use by {holder}; wait for that run to finish (the lock frees itself when it ends)", out_dir.display())]
    Locked {
        /// The out folder.
        out_dir: PathBuf,
        /// Who holds it, as the lock file says.
        holder: String,
    },
    /// `--only` named a stage that is not in the spec.
    #[error("{0}")]
    Selection(String),
    /// Work units of a spread-out run are not in the shared out folder yet.
    #[error("{}: {for_what} needs work units that are not finished in the shared out folder: {}; run them with `amrepro run-unit {} --index N --out OUT` first", spec.display(), missing.join(", "), spec.display())]
    UnitsMissing {
        /// The spec.
        spec: PathBuf,
        /// What needs them (`collect`, `unit 3 (power: …)`).
        for_what: String,
        /// The missing units, `index (stage: unit)`.
        missing: Vec<String>,
    },
    /// A dataset folder named in the spec does not exist.
    #[error("dataset `{name}`: folder {} does not exist{}", dir.display(), if source_hint.is_empty() { String::new() } else { format!(". {source_hint}") })]
    MissingDataset {
        /// Dataset name in the spec.
        name: String,
        /// The resolved folder.
        dir: PathBuf,
        /// Where to get it.
        source_hint: String,
    },
}

impl RunError {
    /// The engine's own write of `path` (journal, manifest) failed with `e`.
    pub fn bookkeeping(path: &std::path::Path, e: StageError) -> Self {
        match e {
            StageError::Io { path, source } => Self::Io { path, source },
            other => Self::Io { path: path.to_path_buf(), source: std::io::Error::other(other.to_string()) },
        }
    }
}
