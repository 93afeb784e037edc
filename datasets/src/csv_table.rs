//! A small reader for the CSV tables of the dataset formats: a header row, then rows
//! of plain fields (no quoting). Every error names the file, the line and the column.
//! Hand-written because the formats need exact line/field diagnostics and nothing
//! more; quoted fields are not part of any of our formats.

use std::path::{Path, PathBuf};

use crate::error::DatasetError;
use crate::text::read_text;

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
        check_header(file, &header)?;
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

    /// Every row read by `read_row`, refusing an id (column `id_col`, as `id_of`
    /// gives it back) that an earlier row already has.
    pub fn rows_with_unique_ids<T>(
        &self,
        id_col: usize,
        id_of: impl Fn(&T) -> &str,
        mut read_row: impl FnMut(&(usize, Vec<String>)) -> Result<T, DatasetError>,
    ) -> Result<Vec<T>, DatasetError> {
        let mut items: Vec<T> = Vec::with_capacity(self.rows.len());
        for row in &self.rows {
            let item = read_row(row)?;
            if let Some(k) = items.iter().position(|earlier| id_of(earlier) == id_of(&item)) {
                let (first, id) = (self.rows[k].0, id_of(&item));
                return Err(self.field_error(
                    row.0,
                    id_col,
                    format!("expected a unique id, `{id}` is also on line {first}"),
                ));
            }
            items.push(item);
        }
        Ok(items)
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

/// Reads a headerless two-column numeric file (`x,y` per line) into `(line, x, y)`
/// rows (1-based line numbers); `what` names the columns in errors (`"position_mm,width_mm"`).
pub fn read_xy(file: &Path, what: &str) -> Result<Vec<(usize, f64, f64)>, DatasetError> {
    let text = read_text(file)?;
    let rows: Vec<(usize, f64, f64)> = numbered_lines(&text)
        .map(|(n, line)| {
            parse_pair(line).map(|(x, y)| (n, x, y)).ok_or_else(|| {
                DatasetError::at_line(file, n, format!("expected two numbers `{what}`, got `{}`", line.trim()))
            })
        })
        .collect::<Result<_, _>>()?;
    if rows.is_empty() {
        return Err(DatasetError::at_line(file, 1, format!("expected rows of `{what}`, the file is empty")));
    }
    Ok(rows)
}

/// Column names are non-empty and unique (columns are found by name).
fn check_header(file: &Path, header: &[String]) -> Result<(), DatasetError> {
    for (i, name) in header.iter().enumerate() {
        if name.is_empty() || header[..i].contains(name) {
            let what = if name.is_empty() { "an empty column name".to_string() } else { format!("`{name}` twice") };
            return Err(DatasetError::at_line(file, 1, format!("expected unique column names, got {what}")));
        }
    }
    Ok(())
}

fn parse_pair(line: &str) -> Option<(f64, f64)> {
    let mut parts = line.split(',');
    let x = parts.next()?.trim().parse::<f64>().ok()?;
    let y = parts.next()?.trim().parse::<f64>().ok()?;
    (parts.next().is_none() && x.is_finite() && y.is_finite()).then_some((x, y))
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

    #[test]
    fn a_column_named_twice_or_unnamed_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "t.csv", "id,x,id\na,1,b\n");
        let err = CsvTable::read(&path).unwrap_err().to_string();
        assert!(err.contains("t.csv:line 1: expected unique column names, got `id` twice"), "{err}");
        let path = write(dir.path(), "u.csv", "id,,x\na,1,2\n");
        assert!(CsvTable::read(&path).unwrap_err().to_string().contains("an empty column name"));
    }

    #[test]
    fn a_byte_order_mark_before_the_header_is_not_part_of_the_first_column() {
        // Spreadsheet exports start with U+FEFF; it used to become part of the first
        // column's name, so `expected a column `id` in the header (id,…)` looked contradictory.
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "t.csv", "\u{feff}id,feed_mm_s\na,50\n");
        assert_eq!(CsvTable::read(&path).unwrap().column("id").unwrap(), 0);
        let path = write(dir.path(), "xy.csv", "\u{feff}0,1.0\n");
        assert_eq!(read_xy(&path, "x,y").unwrap(), vec![(1, 0.0, 1.0)]);
    }
}
