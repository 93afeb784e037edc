//! Confining a dataset's files to its folder (docs/DATASETS.md, "Files and paths").
//!
//! The pipeline caches a stage on the hash of its dataset folder's files, so a file the
//! dataset reads from elsewhere could change without the cache noticing, and a path in
//! a table could make a reader open (and quote) any file. So every file a reader opens
//! is inside the folder: a path a table names is relative, without `..`, and neither it
//! nor a fixed file name (`lines.csv`, …) may resolve through a symbolic link to a place
//! outside the folder. Links that stay inside the folder are fine.

use std::path::{Component, Path, PathBuf};

use crate::error::DatasetError;

/// The rule a path field must follow, quoted in errors.
pub const PATH_RULE: &str =
    "a path relative to the dataset folder that stays inside it (no absolute path, no `..`, no link leading out)";

/// Checks that `dir` is a folder: a missing folder or a file is named as such.
pub fn check_dataset_folder(dir: &Path) -> Result<(), DatasetError> {
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => Ok(()),
        Ok(_) => Err(DatasetError::Malformed {
            file: dir.to_path_buf(),
            location: None,
            expected: "is a file, expected a dataset folder".into(),
        }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(DatasetError::Missing {
            file: dir.to_path_buf(),
            hint: Some("expected a dataset folder holding a dataset.toml (docs/DATASETS.md)".into()),
        }),
        Err(e) => Err(DatasetError::io(dir, e)),
    }
}

/// The file `name` (a fixed name of the format) of the dataset in `dir`, refused if a
/// symbolic link takes it outside the folder.
pub fn file_in(dir: &Path, name: &str) -> Result<PathBuf, DatasetError> {
    let file = dir.join(name);
    stays_inside(dir, &file).map_err(|expected| DatasetError::Malformed {
        file: file.clone(),
        location: None,
        expected,
    })?;
    Ok(file)
}

/// The file that a path field of a dataset table names (`raw`, relative to `dir`), or
/// the rule it breaks.
pub fn referenced_file(dir: &Path, raw: &str) -> Result<PathBuf, String> {
    let path = Path::new(raw);
    if raw.is_empty() {
        return Err(format!("expected {PATH_RULE}, got an empty path"));
    }
    if path.has_root() || path.components().any(|c| matches!(c, Component::Prefix(_))) {
        return Err(format!("expected {PATH_RULE}, got the absolute path `{raw}`"));
    }
    if path.components().any(|c| c == Component::ParentDir) {
        return Err(format!("expected {PATH_RULE}, got `{raw}`, which climbs out with `..`"));
    }
    let file = dir.join(path);
    stays_inside(dir, &file)?;
    Ok(file)
}

/// `file` (under `dir`), once symbolic links are followed, lies inside `dir`; a file
/// that does not exist passes (its reader reports it missing).
fn stays_inside(dir: &Path, file: &Path) -> Result<(), String> {
    let (Ok(root), Ok(real)) = (dir.canonicalize(), file.canonicalize()) else { return Ok(()) };
    if real.starts_with(&root) {
        Ok(())
    } else {
        Err(format!(
            "resolves through a symbolic link to {}, outside the dataset folder; expected {PATH_RULE}: copy the file into the folder",
            real.display()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_that_leave_the_folder_are_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let (dir, outside) = (tmp.path().join("ds"), tmp.path().join("secret.csv"));
        std::fs::create_dir_all(dir.join("widths")).unwrap();
        std::fs::write(&outside, "x").unwrap();
        std::fs::write(dir.join("widths/a.csv"), "x").unwrap();
        assert_eq!(referenced_file(&dir, "widths/a.csv").unwrap(), dir.join("widths/a.csv"));
        let absolute = outside.display().to_string();
        assert!(referenced_file(&dir, &absolute).unwrap_err().contains("absolute path"));
        assert!(referenced_file(&dir, "widths/../../secret.csv").unwrap_err().contains("`..`"));
        assert!(referenced_file(&dir, "").unwrap_err().contains("empty"));
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(&outside, dir.join("widths/link.csv")).unwrap();
            std::os::unix::fs::symlink(dir.join("widths/a.csv"), dir.join("inner.csv")).unwrap();
            let err = referenced_file(&dir, "widths/link.csv").unwrap_err();
            assert!(err.contains("symbolic link") && err.contains("secret.csv"), "{err}");
            assert!(file_in(&dir, "inner.csv").is_ok(), "a link inside the folder is fine");
            let err = file_in(&dir, "widths/link.csv").unwrap_err().to_string();
            assert!(err.contains("outside the dataset folder"), "{err}");
        }
    }

    #[test]
    fn a_file_is_not_a_dataset_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("ds");
        std::fs::write(&file, "x").unwrap();
        let err = check_dataset_folder(&file).unwrap_err().to_string();
        assert!(err.ends_with("ds: is a file, expected a dataset folder"), "{err}");
        assert!(check_dataset_folder(&tmp.path().join("none")).unwrap_err().to_string().contains("missing"));
        assert!(check_dataset_folder(tmp.path()).is_ok());
    }
}
