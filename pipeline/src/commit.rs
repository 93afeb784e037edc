//! The run's commit: what readers see (stage folders under `runs/<run>/`, published
//! copies, the manifest) changes only when every stage of the run has succeeded, and
//! then all at once, as far as a file system allows.
//!
//! While a run executes, each stage that runs writes into a staging folder that
//! becomes `runs/<run>/.pending/<stage>/` when the stage succeeds; downstream stages
//! read it there. A run that fails or is killed leaves `.pending/` behind, and the
//! next run reuses each pending stage whose cache key is unchanged. When all stages
//! have succeeded, every byte of the new state is written first (published copies and
//! the manifest as synced temp files beside their destinations), then a journal of
//! the renames that remain ([`JOURNAL_FILE`]), then the renames, then the journal is
//! removed. A kill during the renames is completed by the next run before anything
//! else ([`roll_forward`]), so the published state is always one run's whole result
//! once any run has started again.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::artifact::{replace_dir, write_atomic};
use crate::error::RunError;

/// Folder under `runs/<run>/` holding the outputs of stages that finished in a run
/// that has not committed yet.
pub const PENDING_DIR: &str = ".pending";
/// The journal of renames of a commit in progress, inside [`PENDING_DIR`].
pub const JOURNAL_FILE: &str = "commit.json";

/// One rename of a commit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Move {
    /// The complete new file or folder.
    pub from: PathBuf,
    /// Where it goes.
    pub to: PathBuf,
    /// A folder (replaced whole) rather than a file.
    pub folder: bool,
}

/// Applies `moves` (in order: stage folders, published copies, the manifest last)
/// through a journal in `run_dir/.pending/`, then removes `.pending/`.
pub fn commit(run_dir: &Path, moves: &[Move]) -> Result<(), RunError> {
    let pending = run_dir.join(PENDING_DIR);
    let journal = pending.join(JOURNAL_FILE);
    let json = serde_json::to_vec_pretty(moves).expect("serialisable");
    write_atomic(&journal, &json).map_err(|e| RunError::bookkeeping(&journal, e))?;
    apply(&pending, moves)
}

/// Completes the commit that a killed run left half done in `run_dir`, if any;
/// returns whether there was one.
pub fn roll_forward(run_dir: &Path) -> Result<bool, RunError> {
    let pending = run_dir.join(PENDING_DIR);
    let journal = pending.join(JOURNAL_FILE);
    let text = match fs::read(&journal) {
        Ok(text) => text,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
        Err(source) => return Err(RunError::Io { path: journal, source }),
    };
    let moves: Vec<Move> = serde_json::from_slice(&text).map_err(|e| RunError::Io {
        path: journal.clone(),
        source: io::Error::other(format!("not a commit journal ({e}); remove the folder {}", pending.display())),
    })?;
    apply(&pending, &moves)?;
    Ok(true)
}

/// Every rename whose source still exists (a finished one has none), then the
/// pending folder goes.
fn apply(pending: &Path, moves: &[Move]) -> Result<(), RunError> {
    for mv in moves.iter().filter(|mv| mv.from.exists()) {
        let done = if mv.folder { replace_dir(&mv.from, &mv.to) } else { fs::rename(&mv.from, &mv.to) };
        done.map_err(|source| RunError::Io { path: mv.to.clone(), source })?;
    }
    fs::remove_dir_all(pending).map_err(|source| RunError::Io { path: pending.to_path_buf(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setup() -> (tempfile::TempDir, PathBuf, Vec<Move>) {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("runs/r");
        let pending = run.join(PENDING_DIR);
        fs::create_dir_all(pending.join("a")).unwrap();
        fs::write(pending.join("a/t.parquet"), "new").unwrap();
        fs::create_dir_all(run.join("a")).unwrap();
        fs::write(run.join("a/t.parquet"), "old").unwrap();
        fs::write(run.join(".manifest.json.tmp-1"), "manifest 2").unwrap();
        fs::write(run.join("manifest.json"), "manifest 1").unwrap();
        let moves = vec![
            Move { from: pending.join("a"), to: run.join("a"), folder: true },
            Move { from: run.join(".manifest.json.tmp-1"), to: run.join("manifest.json"), folder: false },
        ];
        (dir, run, moves)
    }

    #[test]
    fn commit_renames_everything_and_removes_pending() {
        let (_dir, run, moves) = setup();
        commit(&run, &moves).unwrap();
        assert_eq!(fs::read_to_string(run.join("a/t.parquet")).unwrap(), "new");
        assert_eq!(fs::read_to_string(run.join("manifest.json")).unwrap(), "manifest 2");
        assert!(!run.join(PENDING_DIR).exists());
        assert!(!roll_forward(&run).unwrap(), "nothing left to roll forward");
    }

    #[test]
    fn a_commit_killed_after_its_first_rename_is_completed_by_roll_forward() {
        let (_dir, run, moves) = setup();
        let journal = serde_json::to_vec(&moves).unwrap();
        fs::write(run.join(PENDING_DIR).join(JOURNAL_FILE), journal).unwrap();
        replace_dir(&moves[0].from, &moves[0].to).unwrap();
        assert_eq!(fs::read_to_string(run.join("manifest.json")).unwrap(), "manifest 1", "half done");
        assert!(roll_forward(&run).unwrap());
        assert_eq!(fs::read_to_string(run.join("a/t.parquet")).unwrap(), "new");
        assert_eq!(fs::read_to_string(run.join("manifest.json")).unwrap(), "manifest 2");
        assert!(!run.join(PENDING_DIR).exists());
    }
}
