//! The amrepro engine: declarative spec → validated plan → execution.
//!
//! This crate knows nothing about additive manufacturing. It parses a TOML spec
//! ([`spec`]), checks it against the registry of stage kinds into a [`plan::Plan`]
//! (names, inputs, cycles, parameter types and ranges), and executes the plan
//! ([`execute`]): independent stages in parallel with rayon, each cached by a content
//! hash of (kind, kind version, the code it runs, parameters, seed, input hashes), every artifact
//! written atomically, one run per out folder at a time ([`lock`]), and what readers
//! see changed only when the whole run succeeded ([`commit`]), the manifest last
//! (DESIGN §3).
#![deny(missing_docs)]

pub mod artifact;
pub mod cache;
pub mod columns;
pub mod commit;
pub mod diff;
pub mod error;
pub mod execute;
pub mod graph;
pub mod hash;
pub mod lock;
pub mod manifest;
pub mod panic;
pub mod params;
pub mod plan;
pub mod schema;
pub mod snakefile;
pub mod spec;
pub mod stage;
pub mod testing;
pub mod units;
pub mod usage;

pub use error::{SpecError, StageError};
pub use execute::{open_out_dir, run_plan, run_plan_locked, RunOptions, RunSummary};
pub use lock::OutLock;
pub use manifest::{Manifest, StageRecord};
pub use params::{ParamSpec, ParamType, ParamValue, Params};
pub use plan::Plan;
pub use stage::{Code, InputArtifact, Registry, Split, StageContext, StageKind, Unit};

/// The version of this tool, written into every artifact and manifest.
pub const TOOL_VERSION: &str = env!("CARGO_PKG_VERSION");
