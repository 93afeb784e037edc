//! Dataset errors: each names the file and, where there is one, the line and field,
//! and says what was expected.

use std::path::PathBuf;

/// Why a dataset could not be read, imported or written.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A value in a file is not what the format requires.
    #[error("{}{}: {expected}", file.display(), location.as_ref().map(|l| format!(":{l}")).unwrap_or_default())]
    Malformed {
        /// The file.
        file: PathBuf,
        /// `line 12`, `line 12, field feed_mm_s`, or a TOML key.
        location: Option<String>,
        /// What was expected (and what was found).
        expected: String,
    },
    /// A file the dataset needs is missing.
    #[error("{}: missing{}", file.display(), hint.as_ref().map(|h| format!(". {h}")).unwrap_or_default())]
    Missing {
        /// The missing file or folder.
        file: PathBuf,
        /// Where to get it.
        hint: Option<String>,
    },
    /// A file's checksum does not match the published data.
    #[error("{}: sha256 {actual} does not match the published file ({expected}); the data was modified or is another release", file.display())]
    Checksum {
        /// The file.
        file: PathBuf,
        /// Expected hex SHA-256.
        expected: String,
        /// Actual hex SHA-256.
        actual: String,
    },
    /// An output folder that is not ours to replace, or no folder name.
    #[error("{}: {reason}", path.display())]
    Output {
        /// The destination.
        path: PathBuf,
        /// Why it is refused.
        reason: String,
    },
    /// An I/O error.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

impl DatasetError {
    /// A malformed value at `line` (1-based) of `file`.
    pub fn at_line(file: impl Into<PathBuf>, line: usize, expected: impl Into<String>) -> Self {
        Self::Malformed { file: file.into(), location: Some(format!("line {line}")), expected: expected.into() }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io { path: path.into(), source }
    }
}
