//! Artifacts on disk: atomic writes (temp file + rename, so a crash never leaves a
//! half-written file), Parquet tables with key/value metadata, atomic replacement of
//! a stage's whole output folder, and the synced copies the run's commit renames onto
//! the stable analyst paths.
//!
//! This is the one place that calls polars' Parquet writer and reader: their API moves
//! between releases, so it is wrapped here once.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use polars::prelude::{
    Column, DataFrame, KeyValueMetadata, ParquetCompression, ParquetReader, ParquetWriter, SerReader,
};

use crate::error::StageError;
use crate::TOOL_VERSION;

/// Key/value metadata written into every Parquet table.
#[derive(Debug, Clone)]
pub struct TableMeta {
    /// The stage that wrote the table.
    pub stage: String,
    /// The stage's cache key.
    pub stage_hash: String,
    /// Hash of the stage's checked parameters.
    pub params_hash: String,
    /// Version of the table's column contract.
    pub schema_version: u32,
}

/// Writes `df` to `path` as Parquet (zstd, statistics) with `meta`, atomically.
pub fn write_parquet(path: &Path, df: &mut DataFrame, meta: &TableMeta) -> Result<(), StageError> {
    let kv = KeyValueMetadata::from_static(vec![
        ("amrepro_tool_version".into(), TOOL_VERSION.into()),
        ("amrepro_stage".into(), meta.stage.clone()),
        ("amrepro_stage_hash".into(), meta.stage_hash.clone()),
        ("amrepro_params_hash".into(), meta.params_hash.clone()),
        ("amrepro_schema_version".into(), meta.schema_version.to_string()),
    ]);
    write_atomic_with(path, |file| {
        ParquetWriter::new(file)
            .with_compression(ParquetCompression::Zstd(None))
            .with_key_value_metadata(Some(kv))
            .set_parallel(false)
            .finish(df)
            .map(|_| ())
            .map_err(|source| StageError::Table { path: path.to_path_buf(), source })
    })
}

/// Reads a Parquet file; errors name the file.
pub fn read_parquet(path: &Path) -> Result<DataFrame, StageError> {
    let file = fs::File::open(path).map_err(|e| StageError::io(path, e))?;
    ParquetReader::new(file).finish().map_err(|source| StageError::Table { path: path.to_path_buf(), source })
}

/// Column `name` of `df`, read from `path`; a missing column is a `BadInput` naming the
/// file, the column and the columns the table has.
pub fn column<'a>(df: &'a DataFrame, name: &str, path: &Path) -> Result<&'a Column, StageError> {
    df.column(name).map_err(|_| {
        let present: Vec<&str> = df.get_column_names().iter().map(|c| c.as_str()).collect();
        StageError::BadInput {
            file: path.to_path_buf(),
            location: Some(name.to_string()),
            expected: format!("expected a column `{name}`; the table has {}", present.join(", ")),
        }
    })
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), StageError> {
    write_atomic_with(path, |file| file.write_all(bytes).map_err(|e| StageError::io(path, e)))
}

/// Creates a temp file beside `path`, lets `fill` write it, syncs and renames it onto
/// `path`. On any error the temp file is removed and `path` is untouched.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut fs::File) -> Result<(), StageError>,
) -> Result<(), StageError> {
    let tmp = temp_sibling(path);
    write_synced(&tmp, fill)?;
    fs::rename(&tmp, path).map_err(|e| {
        let _ = fs::remove_file(&tmp);
        StageError::io(path, e)
    })
}

/// Creates `path` (and its folder), lets `fill` write it and syncs it to disk; on any
/// error the file is removed. The first half of an atomic write, for callers that
/// rename later (the run's commit).
pub fn write_synced(path: &Path, fill: impl FnOnce(&mut fs::File) -> Result<(), StageError>) -> Result<(), StageError> {
    let dir = path.parent().unwrap_or(Path::new("."));
    fs::create_dir_all(dir).map_err(|e| StageError::io(dir, e))?;
    let result = fs::File::create(path).map_err(|e| StageError::io(path, e)).and_then(|mut file| {
        fill(&mut file)?;
        file.sync_all().map_err(|e| StageError::io(path, e))
    });
    if result.is_err() {
        let _ = fs::remove_file(path);
    }
    result
}

/// Copies `src` to a new, synced file `tmp` (renamed onto its destination later, by
/// the run's commit).
pub fn copy_synced(src: &Path, tmp: &Path) -> Result<(), StageError> {
    write_synced(tmp, |file| {
        let mut reader = fs::File::open(src).map_err(|e| StageError::io(src, e))?;
        std::io::copy(&mut reader, file).map(|_| ()).map_err(|e| StageError::io(tmp, e))
    })
}

/// Replaces folder `dst` by the fully written folder `staged`: the old folder stays
/// intact until the new one is complete, and is removed only after the swap.
pub fn replace_dir(staged: &Path, dst: &Path) -> std::io::Result<()> {
    let old = temp_sibling_named(dst, "old");
    let had_old = dst.exists();
    if had_old {
        fs::rename(dst, &old)?;
    }
    if let Err(e) = fs::rename(staged, dst) {
        if had_old {
            let _ = fs::rename(&old, dst);
        }
        return Err(e);
    }
    if had_old {
        fs::remove_dir_all(&old)?;
    }
    Ok(())
}

/// A fresh, empty staging folder beside `dst` for a stage to write into.
pub fn staging_dir(dst: &Path) -> std::io::Result<PathBuf> {
    let staged = temp_sibling(dst);
    if staged.exists() {
        fs::remove_dir_all(&staged)?;
    }
    fs::create_dir_all(&staged)?;
    Ok(staged)
}

/// `.NAME.tmp-PID` beside `path`: where an atomic write or a staging folder lives
/// until it is renamed onto `path` (see [`crate::lock::is_temp_name`]).
pub fn temp_sibling(path: &Path) -> PathBuf {
    temp_sibling_named(path, "tmp")
}

fn temp_sibling_named(path: &Path, marker: &str) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
    path.with_file_name(format!(".{name}.{marker}-{}", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_column_is_named_with_the_columns_there_are() {
        let df = polars::df!("x_mm" => [1.0], "y_mm" => [2.0]).unwrap();
        let path = Path::new("out/thermal/path.parquet");
        assert_eq!(column(&df, "y_mm", path).unwrap().len(), 1);
        let err = column(&df, "z_mm", path).unwrap_err().to_string();
        assert!(err.contains("out/thermal/path.parquet") && err.contains("`z_mm`"), "{err}");
        assert!(err.contains("the table has x_mm, y_mm"), "{err}");
        assert_eq!(err.matches("not found").count(), 0, "{err}");
    }

    #[test]
    fn failed_write_leaves_previous_file_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomic(&path, b"good").unwrap();
        let failed = write_atomic_with(&path, |f| {
            f.write_all(b"half").unwrap();
            Err(StageError::BadInput { file: path.clone(), location: None, expected: "x".into() })
        });
        assert!(failed.is_err());
        assert_eq!(fs::read(&path).unwrap(), b"good");
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1, "temp file removed");
    }

    #[test]
    fn replace_dir_swaps_whole_folders() {
        let dir = tempfile::tempdir().unwrap();
        let dst = dir.path().join("stage");
        fs::create_dir_all(&dst).unwrap();
        fs::write(dst.join("old.txt"), "old").unwrap();
        let staged = staging_dir(&dst).unwrap();
        fs::write(staged.join("new.txt"), "new").unwrap();
        replace_dir(&staged, &dst).unwrap();
        assert!(dst.join("new.txt").exists());
        assert!(!dst.join("old.txt").exists());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
