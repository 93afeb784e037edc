//! Reading the text files of a dataset (CSV tables, TOML files): one place that maps
//! I/O errors to [`DatasetError`]s naming the file, refuses bytes that are not UTF-8,
//! and strips the UTF-8 byte-order mark that spreadsheet exports put at the start.

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::DatasetError;

/// The UTF-8 byte-order mark (U+FEFF) as it starts a file.
pub const BYTE_ORDER_MARK: char = '\u{feff}';

/// The text of `file` without a leading byte-order mark.
pub fn read_text(file: &Path) -> Result<String, DatasetError> {
    let bytes = std::fs::read(file).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DatasetError::Missing { file: file.to_path_buf(), hint: None },
        _ => DatasetError::io(file, e),
    })?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let offset = e.utf8_error().valid_up_to();
        let line = 1 + e.as_bytes()[..offset].iter().filter(|&&b| b == b'\n').count();
        DatasetError::at_line(file, line, format!("expected UTF-8 text, found invalid bytes at byte {offset}"))
    })?;
    Ok(strip_byte_order_mark(text))
}

/// Reads and parses a TOML file; a parse error names the file and TOML's location.
pub fn read_toml<T: DeserializeOwned>(file: &Path) -> Result<T, DatasetError> {
    let text = read_text(file)?;
    toml::from_str(&text).map_err(|e| DatasetError::Malformed {
        file: file.to_path_buf(),
        location: None,
        expected: e.to_string().trim().replace('\n', " "),
    })
}

fn strip_byte_order_mark(text: String) -> String {
    match text.strip_prefix(BYTE_ORDER_MARK) {
        Some(rest) => rest.to_string(),
        None => text,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_byte_order_mark_is_stripped_and_invalid_utf8_named() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a.csv");
        std::fs::write(&file, "\u{feff}x,y\n1,2\n").unwrap();
        assert_eq!(read_text(&file).unwrap(), "x,y\n1,2\n");
        std::fs::write(&file, b"x,y\n1,\xff\n").unwrap();
        let err = read_text(&file).unwrap_err().to_string();
        assert!(err.contains("a.csv:line 2: expected UTF-8 text"), "{err}");
        let err = read_text(&dir.path().join("b.csv")).unwrap_err();
        assert!(matches!(err, DatasetError::Missing { .. }), "{err}");
    }
}
