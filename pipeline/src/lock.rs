//! One writer per out folder: an advisory lock on `out/.amrepro.lock`, held for a
//! whole run (or report build) and released by the operating system when the process
//! ends, however it ends, so a `kill -9` never leaves a stale lock. The file holds a
//! line naming the holder (PID, command, start time) for the message a second run
//! gets. Under the lock, the temp files and folders that killed runs left behind are
//! removed ([`remove_stale_temps`]): no other process can be writing them.

use std::fs;
use std::io::{self, Read, Seek, Write};
use std::path::{Path, PathBuf};

use crate::error::RunError;

/// File name of the lock inside the out folder.
pub const LOCK_FILE: &str = ".amrepro.lock";

/// The held lock; dropping it releases the lock.
#[derive(Debug)]
pub struct OutLock {
    file: fs::File,
    path: PathBuf,
}

impl OutLock {
    /// Takes the lock of `out_dir` (creating the folder), or refuses with
    /// [`RunError::Locked`] naming the process that holds it. `what` says what the
    /// holder is doing, for that message (`run specs/lu2015.toml`).
    pub fn acquire(out_dir: &Path, what: &str) -> Result<Self, RunError> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| RunError::Io { path, source }
        };
        fs::create_dir_all(out_dir).map_err(io(out_dir))?;
        let path = out_dir.join(LOCK_FILE);
        let mut file = fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(io(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(fs::TryLockError::WouldBlock) => {
                let mut holder = String::new();
                let _ = file.read_to_string(&mut holder);
                return Err(RunError::Locked { out_dir: out_dir.to_path_buf(), holder: describe_holder(&holder) });
            }
            Err(fs::TryLockError::Error(source)) => return Err(RunError::Io { path, source }),
        }
        let started = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
        let line = format!("pid {} (amrepro {what}), started at unix time {started}\n", std::process::id());
        file.set_len(0).and_then(|_| file.rewind()).and_then(|_| file.write_all(line.as_bytes())).map_err(io(&path))?;
        Ok(Self { file, path })
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for OutLock {
    fn drop(&mut self) {
        let _ = self.file.set_len(0);
        let _ = self.file.unlock();
    }
}

fn describe_holder(text: &str) -> String {
    match text.trim() {
        "" => "another amrepro process (it has not written its name yet)".into(),
        line => line.to_string(),
    }
}

/// Whether `name` is one of the engine's temp names: `.NAME.tmp-PID` (atomic writes,
/// staging folders) or `.NAME.old-PID` (a folder being replaced).
pub fn is_temp_name(name: &str) -> bool {
    let Some(rest) = name.strip_prefix('.') else {
        return false;
    };
    [".tmp-", ".old-"].iter().any(|marker| {
        rest.rfind(marker).is_some_and(|at| {
            let pid = &rest[at + marker.len()..];
            at > 0 && !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit())
        })
    })
}

/// Removes every temp file and folder ([`is_temp_name`]) under `out_dir`; call only
/// while holding its [`OutLock`]. Returns what was removed.
pub fn remove_stale_temps(out_dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut removed = Vec::new();
    if out_dir.is_dir() {
        sweep(out_dir, &mut removed)?;
    }
    Ok(removed)
}

fn sweep(dir: &Path, removed: &mut Vec<PathBuf>) -> io::Result<()> {
    for entry in fs::read_dir(dir)? {
        let entry = entry?;
        let path = entry.path();
        let is_dir = entry.file_type()?.is_dir();
        if is_temp_name(&entry.file_name().to_string_lossy()) {
            if is_dir {
                fs::remove_dir_all(&path)?;
            } else {
                fs::remove_file(&path)?;
            }
            removed.push(path);
        } else if is_dir {
            sweep(&path, removed)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_is_refused_naming_the_holder_and_freed_on_drop() {
        let dir = tempfile::tempdir().unwrap();
        let held = OutLock::acquire(dir.path(), "run a.toml").unwrap();
        let err = OutLock::acquire(dir.path(), "run b.toml").unwrap_err().to_string();
        assert!(err.contains(&format!("pid {}", std::process::id())), "{err}");
        assert!(err.contains("run a.toml") && err.contains(&dir.path().display().to_string()), "{err}");
        drop(held);
        OutLock::acquire(dir.path(), "run b.toml").unwrap();
    }

    #[test]
    fn temp_names_are_recognised_exactly() {
        for name in [".widths.parquet.tmp-123", ".import_taz5.tmp-9", ".manifest.json.tmp-42", ".fig.old-7"] {
            assert!(is_temp_name(name), "{name}");
        }
        for name in ["widths.parquet", ".stage.json", ".pending", ".a.tmp-", ".a.tmp-12x", "a.tmp-12", "..tmp-1"] {
            assert!(!is_temp_name(name), "{name}");
        }
    }

    #[test]
    fn stale_temps_are_swept_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let stage = dir.path().join("runs/r/stage");
        fs::create_dir_all(&stage).unwrap();
        fs::write(stage.join("keep.parquet"), "x").unwrap();
        fs::write(stage.join(".stage.json"), "{}").unwrap();
        fs::write(stage.join(".keep.parquet.tmp-77"), "half").unwrap();
        fs::create_dir_all(dir.path().join("runs/r/.other.tmp-78/deep")).unwrap();
        let removed = remove_stale_temps(dir.path()).unwrap();
        assert_eq!(removed.len(), 2, "{removed:?}");
        assert!(stage.join("keep.parquet").exists() && stage.join(".stage.json").exists());
        assert!(!dir.path().join("runs/r/.other.tmp-78").exists());
    }
}
