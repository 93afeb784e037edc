//! Content hashes (SHA-256, hex) of files, folders and cache keys.

use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// Hex SHA-256 of a byte string.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// Hex SHA-256 of a file's contents.
pub fn file_sha256(path: &Path) -> io::Result<String> {
    let mut hasher = Sha256::new();
    let mut file = fs::File::open(path)?;
    io::copy(&mut file, &mut hasher)?;
    Ok(hex(&hasher.finalize()))
}

/// All regular files under `dir`, as sorted paths relative to `dir`, skipping hidden
/// files and folders (engine bookkeeping and temp files start with a dot).
pub fn list_files(dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    walk(dir, Path::new(""), &mut files)?;
    files.sort();
    Ok(files)
}

fn walk(root: &Path, rel: &Path, files: &mut Vec<PathBuf>) -> io::Result<()> {
    for entry in fs::read_dir(root.join(rel))? {
        let entry = entry?;
        let name = entry.file_name();
        if name.to_string_lossy().starts_with('.') {
            continue;
        }
        let rel_path = rel.join(&name);
        let file_type = entry.file_type()?;
        if file_type.is_symlink() && fs::metadata(root.join(&rel_path)).is_ok_and(|m| m.is_dir()) {
            let message = format!(
                "{}: a symbolic link to a folder; a dataset folder holds its own files, which the cache hashes one by one (docs/DATASETS.md): copy the folder in instead",
                rel_path.display()
            );
            return Err(io::Error::new(io::ErrorKind::InvalidInput, message));
        }
        if file_type.is_dir() {
            walk(root, &rel_path, files)?;
        } else {
            files.push(rel_path);
        }
    }
    Ok(())
}

/// Hash of a folder: of the sorted (relative path, file hash) pairs of its files.
/// Returns the hash and the per-file hashes.
pub fn dir_hash(dir: &Path) -> io::Result<(String, Vec<(PathBuf, String)>)> {
    let files: Vec<(PathBuf, String)> = list_files(dir)?
        .into_iter()
        .map(|rel| file_sha256(&dir.join(&rel)).map(|h| (rel, h)))
        .collect::<io::Result<_>>()?;
    let mut hasher = Sha256::new();
    for (rel, h) in &files {
        hasher.update(rel.to_string_lossy().as_bytes());
        hasher.update([0]);
        hasher.update(h.as_bytes());
        hasher.update([b'\n']);
    }
    Ok((hex(&hasher.finalize()), files))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_sha256_of_abc() {
        // FIPS 180-2, appendix B.1.
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
    }

    #[cfg(unix)]
    #[test]
    fn a_linked_folder_is_named_not_read_as_a_file() {
        // It used to fail with `Is a directory (os error 21)` and no name.
        let (dir, elsewhere) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        fs::write(elsewhere.path().join("f.png"), b"x").unwrap();
        std::os::unix::fs::symlink(elsewhere.path(), dir.path().join("frames")).unwrap();
        let err = dir_hash(dir.path()).unwrap_err().to_string();
        assert!(err.starts_with("frames: a symbolic link to a folder"), "{err}");
    }

    #[test]
    fn dir_hash_changes_with_content_and_ignores_hidden_files() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(dir.path().join("a.csv"), "1,2\n").unwrap();
        let (h1, files) = dir_hash(dir.path()).unwrap();
        assert_eq!(files.len(), 1);
        fs::write(dir.path().join(".stage.json"), "{}").unwrap();
        assert_eq!(dir_hash(dir.path()).unwrap().0, h1);
        fs::write(dir.path().join("a.csv"), "1,3\n").unwrap();
        assert_ne!(dir_hash(dir.path()).unwrap().0, h1);
    }
}
