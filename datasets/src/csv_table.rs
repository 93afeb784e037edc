//! A small reader for the CSV tables of the dataset formats: a header row, then rows
//! of plain fields (no quoting). Every error names the file, the line and the column.
//! Hand-written because the formats need exact line/field diagnostics and nothing
//! more; quoted fields are not part of any of our formats.

use std::path::{Path, PathBuf};

use crate::error::DatasetError;

/// A parsed table: header and rows of raw fields, with their 1-based line numbers.
#[derive(Debug, Clone)]
pub struct CsvTable {
    /// The file it was read from.
    pub file: PathBuf,
    /// Column names.
    pub header: Vec<String>,
    /// `(line number, fields)` per data row.
    pub rows: Vec<(usize, Vec<String>)>,
}

impl CsvTable {
    /// Reads `file`; it must have a header and at least one row, every row with as
    /// many fields as the header. Blank lines are skipped.
    pub fn read(file: &Path) -> Result<Self, DatasetError> {
        let text = read_text(file)?;
        let mut lines = numbered_lines(&text);
        let (_, header_line) =
            lines.next().ok_or_else(|| DatasetError::at_line(file, 1, "expected a header row, the file is empty"))?;
        let header: Vec<String> = header_line.split(',').map(|h| h.trim().to_string()).collect();
        let mut rows = Vec::new();
        for (n, line) in lines {
            let fields: Vec<String> = line.split(',').map(|f| f.trim().to_string()).collect();
            if fields.len() != header.len() {
                let expected = format!("expected {} fields ({}), got {}", header.len(), header.join(","), fields.len());
                return Err(DatasetError::at_line(file, n, expected));
            }
            rows.push((n, fields));
        }
        if rows.is_empty() {
            return Err(DatasetError::at_line(file, 2, "expected at least one data row after the header"));
        }
        Ok(Self { file: file.to_path_buf(), header, rows })
    }

    /// Index of column `name`, or an error naming the file and the missing column.
    pub fn column(&self, name: &str) -> Result<usize, DatasetError> {
        self.header.iter().position(|h| h == name).ok_or_else(|| DatasetError::Malformed {
            file: self.file.clone(),
            location: Some("line 1".into()),
            expected: format!("expected a column `{name}` in the header ({})", self.header.join(",")),
        })
    }

    /// Field `col` of a row as a finite number.
    pub fn number(&self, row: &(usize, Vec<String>), col: usize) -> Result<f64, DatasetError> {
        let raw = &row.1[col];
        raw.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| self.field_error(row.0, col, format!("expected a finite number, got `{raw}`")))
    }

    /// An error about field `col` at `line`.
    pub fn field_error(&self, line: usize, col: usize, expected: impl Into<String>) -> DatasetError {
        DatasetError::Malformed {
            file: self.file.clone(),
            location: Some(format!("line {line}, field {}", self.header[col])),
            expected: expected.into(),
        }
    }
}

/// Reads a headerless two-column numeric file (`x,y` per line) into two vectors;
/// `what` names the columns in errors (`"position_mm,width_mm"`).
pub fn read_xy(file: &Path, what: &str) -> Result<(Vec<f64>, Vec<f64>), DatasetError> {
    let text = read_text(file)?;
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for (n, line) in numbered_lines(&text) {
        let (x, y) = parse_pair(line).ok_or_else(|| {
            DatasetError::at_line(file, n, format!("expected two numbers `{what}`, got `{}`", line.trim()))
        })?;
        xs.push(x);
        ys.push(y);
    }
    if xs.is_empty() {
        return Err(DatasetError::at_line(file, 1, format!("expected rows of `{what}`, the file is empty")));
    }
    Ok((xs, ys))
}

fn parse_pair(line: &str) -> Option<(f64, f64)> {
    let mut parts = line.split(',');
    let x = parts.next()?.trim().parse::<f64>().ok()?;
    let y = parts.next()?.trim().parse::<f64>().ok()?;
    (parts.next().is_none() && x.is_finite() && y.is_finite()).then_some((x, y))
}

fn read_text(file: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(file).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DatasetError::Missing { file: file.to_path_buf(), hint: None },
        _ => DatasetError::io(file, e),
    })
}

/// Non-blank lines with their 1-based numbers.
fn numbered_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().map(|(i, l)| (i + 1, l)).filter(|(_, l)| !l.trim().is_empty())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn xy_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "a.csv", "0,1.0\n0.5,1.1\n1.0,abc\n");
        let err = read_xy(&path, "position_mm,width_mm").unwrap_err().to_string();
        assert!(err.ends_with("a.csv:line 3: expected two numbers `position_mm,width_mm`, got `1.0,abc`"), "{err}");
        let path = write(dir.path(), "b.csv", "0,1.0,2.0\n");
        assert!(read_xy(&path, "x,y").unwrap_err().to_string().contains("line 1"));
        let path = write(dir.path(), "c.csv", "\n");
        assert!(read_xy(&path, "x,y").unwrap_err().to_string().contains("empty"));
        let path = write(dir.path(), "d.csv", "0,NaN\n");
        assert!(read_xy(&path, "x,y").is_err(), "NaN is not a measurement");
    }

    #[test]
    fn table_errors_name_line_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "t.csv", "id,feed_mm_s\na,50\nb,fast\n");
        let table = CsvTable::read(&path).unwrap();
        let col = table.column("feed_mm_s").unwrap();
        assert_eq!(table.number(&table.rows[0], col).unwrap(), 50.0);
        let err = table.number(&table.rows[1], col).unwrap_err().to_string();
        assert!(err.contains("t.csv:line 3, field feed_mm_s: expected a finite number, got `fast`"), "{err}");
        assert!(table.column("accel").is_err());
    }
}
