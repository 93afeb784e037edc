//! Writing a dataset folder without losing anything: the one helper every writer
//! (`datasets generate thermal|inkjet`, `datasets import`, `datasets inject`) uses.
//!
//! [`OutputDir::begin`] refuses a destination that is not ours to replace — ours means
//! absent, an empty folder, or a dataset this tool wrote (a `dataset.toml` of the
//! expected kind whose provenance the writer recognises) — and creates a staging folder
//! beside it. The writer fills [`OutputDir::path`]; [`OutputDir::commit`] swaps the
//! staging folder into place (the old folder is renamed aside first and removed last).
//! Dropping an `OutputDir` that was not committed removes the staging folder, so an
//! error leaves the destination as it was and nothing behind.

use std::path::{Component, Path, PathBuf};

use crate::error::DatasetError;
use crate::manifest::{DatasetManifest, Provenance};

/// Which existing folders a writer may replace.
#[derive(Debug, Clone, Copy)]
pub struct Ownership {
    /// The dataset kind the writer writes.
    pub kind: &'static str,
    /// The format versions of that kind this build reads.
    pub versions: &'static [u32],
    /// The writer, as the refusal names it (`datasets generate thermal`).
    pub writer: &'static str,
    /// Whether a dataset of that kind with this provenance was written by the writer.
    pub written_by_us: fn(&Provenance) -> bool,
}

/// A staging folder beside the destination, swapped in by [`Self::commit`].
#[derive(Debug)]
pub struct OutputDir {
    target: PathBuf,
    staging: PathBuf,
    /// The first missing ancestor of the target that `begin` created, removed again on failure.
    created: Option<PathBuf>,
    committed: bool,
}

impl OutputDir {
    /// Checks that `target` may be replaced under `rule` and creates the staging folder.
    pub fn begin(target: &Path, rule: &Ownership) -> Result<Self, DatasetError> {
        let refuse = |reason: String| DatasetError::Output { path: target.to_path_buf(), reason };
        let Some(Component::Normal(name)) = target.components().next_back() else {
            return Err(refuse(
                "expected a folder name (not `.`, `..` or `/`): the dataset is written as that folder".into(),
            ));
        };
        check_replaceable(target, rule).map_err(refuse)?;
        let parent = target.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let created = first_missing(parent);
        std::fs::create_dir_all(parent).map_err(|e| DatasetError::io(parent, e))?;
        let name = name.to_string_lossy();
        remove_stale_staging(parent, &name);
        let staging = parent.join(format!(".{name}.staging-{}", std::process::id()));
        let out = Self { target: target.to_path_buf(), staging, created, committed: false };
        let _ = std::fs::remove_dir_all(&out.staging);
        std::fs::create_dir(&out.staging).map_err(|e| DatasetError::io(&out.staging, e))?;
        Ok(out)
    }

    /// The staging folder to write the dataset into.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Replaces the destination by the staging folder.
    pub fn commit(mut self) -> Result<PathBuf, DatasetError> {
        let old = self.staging.with_extension("old");
        let had_target = self.target.exists();
        if had_target {
            let _ = std::fs::remove_dir_all(&old);
            std::fs::rename(&self.target, &old).map_err(|e| DatasetError::io(&self.target, e))?;
        }
        if let Err(e) = std::fs::rename(&self.staging, &self.target) {
            if had_target {
                let _ = std::fs::rename(&old, &self.target);
            }
            return Err(DatasetError::io(&self.target, e));
        }
        self.committed = true;
        let _ = std::fs::remove_dir_all(&old);
        Ok(self.target.clone())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if self.committed {
            return;
        }
        let _ = std::fs::remove_dir_all(&self.staging);
        if let Some(created) = &self.created {
            let _ = std::fs::remove_dir_all(created);
        }
    }
}

/// Writes `bytes` to `relative` inside `dir` (creating subfolders).
pub fn write_file(dir: &Path, relative: impl AsRef<Path>, bytes: &[u8]) -> Result<(), DatasetError> {
    let file = dir.join(relative);
    if let Some(parent) = file.parent() {
        std::fs::create_dir_all(parent).map_err(|e| DatasetError::io(parent, e))?;
    }
    std::fs::write(&file, bytes).map_err(|e| DatasetError::io(&file, e))
}

/// `Ok` when `target` is absent, an empty folder, or a dataset the writer of `rule`
/// wrote; otherwise why not.
fn check_replaceable(target: &Path, rule: &Ownership) -> Result<(), String> {
    let Ok(meta) = std::fs::symlink_metadata(target) else { return Ok(()) };
    if !meta.is_dir() {
        return Err("exists and is not a folder; refusing to replace it".into());
    }
    let empty = std::fs::read_dir(target).map(|mut d| d.next().is_none()).unwrap_or(false);
    let ours =
        DatasetManifest::read(target, rule.kind, rule.versions).is_ok_and(|m| (rule.written_by_us)(&m.provenance));
    if empty || ours {
        return Ok(());
    }
    Err(format!(
        "exists and is not an earlier output of `{}` (an empty folder or a `{}` dataset it wrote); refusing to replace it: choose a new folder or remove this one yourself",
        rule.writer, rule.kind
    ))
}

/// Removes the staging folders `.NAME.staging-PID` beside the target that processes
/// which no longer run left behind (killed writers). Whether a process runs is read
/// from `/proc`; where there is none, nothing is removed.
fn remove_stale_staging(parent: &Path, name: &str) {
    let prefix = format!(".{name}.staging-");
    let Ok(entries) = std::fs::read_dir(parent) else { return };
    for entry in entries.flatten() {
        let file_name = entry.file_name();
        let Some(pid) = file_name.to_str().and_then(|n| n.strip_prefix(&prefix)) else { continue };
        let is_pid = !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit());
        let proc = Path::new("/proc");
        if is_pid && proc.join("self").exists() && !proc.join(pid).exists() {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// The topmost ancestor of `dir` (itself included) that does not exist yet.
fn first_missing(dir: &Path) -> Option<PathBuf> {
    dir.ancestors().take_while(|a| !a.as_os_str().is_empty() && !a.exists()).last().map(Path::to_path_buf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fdm_widths::{FORMAT_VERSION, KIND};

    const RULE: Ownership = Ownership {
        kind: KIND,
        versions: &[FORMAT_VERSION],
        writer: "test writer",
        written_by_us: |p| matches!(p, Provenance::Virtual { generator, .. } if generator == "test"),
    };

    fn ours(dir: &Path) {
        let manifest = DatasetManifest {
            kind: KIND.into(),
            format_version: FORMAT_VERSION,
            printer: "p".into(),
            description: String::new(),
            units: Default::default(),
            provenance: Provenance::Virtual {
                generator: "test".into(),
                version: "0".into(),
                seed: 1,
                effects: Default::default(),
            },
        };
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(dir.join("dataset.toml"), manifest.to_toml()).unwrap();
    }

    /// Every entry of `dir`, sorted.
    fn entries(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> =
            std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
        names.sort();
        names
    }

    #[test]
    fn replaces_only_absent_empty_or_own_folders_and_leaves_nothing_behind() {
        let tmp = tempfile::tempdir().unwrap();
        let target = tmp.path().join("ds");
        for prepare in [|_: &Path| {}, |d: &Path| std::fs::create_dir_all(d).unwrap(), ours] {
            prepare(&target);
            let out = OutputDir::begin(&target, &RULE).unwrap();
            write_file(out.path(), "sub/new.txt", b"new").unwrap();
            assert_eq!(out.commit().unwrap(), target);
            assert!(target.join("sub/new.txt").is_file());
            assert_eq!(entries(tmp.path()), ["ds"], "no staging or old folder left");
            std::fs::remove_dir_all(&target).unwrap();
        }
        // A folder holding something else, or a dataset someone else wrote: refused, untouched.
        std::fs::create_dir_all(&target).unwrap();
        std::fs::write(target.join("notes.txt"), "mine").unwrap();
        let err = OutputDir::begin(&target, &RULE).unwrap_err().to_string();
        assert!(err.contains("refusing to replace it") && err.contains("test writer"), "{err}");
        assert_eq!(entries(&target), ["notes.txt"]);
        for dot in [".", "..", "/"] {
            let err = OutputDir::begin(Path::new(dot), &RULE).unwrap_err().to_string();
            assert!(err.contains("expected a folder name"), "{dot}: {err}");
        }
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn staging_left_by_a_dead_writer_is_removed_and_a_live_one_kept() {
        let tmp = tempfile::tempdir().unwrap();
        let dead = tmp.path().join(format!(".ds.staging-{}", u32::MAX));
        let live = tmp.path().join(".ds.staging-1");
        for dir in [&dead, &live] {
            std::fs::create_dir_all(dir.join("frames")).unwrap();
        }
        let out = OutputDir::begin(&tmp.path().join("ds"), &RULE).unwrap();
        out.commit().unwrap();
        assert!(!dead.exists(), "a killed writer's staging folder is cleaned");
        assert!(live.exists(), "pid 1 runs: its staging folder is not ours to remove");
    }

    #[test]
    fn an_uncommitted_output_removes_its_staging_and_the_folders_it_created() {
        let tmp = tempfile::tempdir().unwrap();
        let out = OutputDir::begin(&tmp.path().join("a/b/ds"), &RULE).unwrap();
        write_file(out.path(), "big.bin", &[0; 1000]).unwrap();
        assert!(out.path().is_dir());
        drop(out);
        assert!(entries(tmp.path()).is_empty(), "{:?}", entries(tmp.path()));
    }
}
