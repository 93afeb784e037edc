//! The `fdm-widths` dataset kind (DESIGN §4): widths already measured along printed
//! straight lines, with each line's commanded kinematics, no images.
//!
//! ```text
//! dataset.toml           kind = "fdm-widths", printer, units, provenance
//! lines.csv              line_id,condition,accel_mm_s2,feed_mm_s,jerk_mm_s,length_mm,widths_file
//! widths/<line_id>.csv   position_mm,width_mm   (header, one row per measurement)
//! ```
//!
//! The kinematics are the G-code values (paper 000 eq. 1 calls them a0, F0); the line
//! starts and ends at the jerk speed.

use std::path::Path;

use crate::csv_table::CsvTable;
use crate::error::DatasetError;
use crate::limits::{MAX_BEAD_WIDTH_MM, MAX_LINE_LENGTH_MM};
use crate::manifest::{DatasetManifest, MANIFEST_FILE};
use crate::paths::{file_in, referenced_file};

/// The kind string in `dataset.toml`.
pub const KIND: &str = "fdm-widths";
/// Current folder layout version.
pub const FORMAT_VERSION: u32 = 1;
/// The folder layout versions this build reads.
pub const READABLE_VERSIONS: &[u32] = &[FORMAT_VERSION];
/// Columns of `lines.csv`, in order.
pub const LINE_COLUMNS: [&str; 7] =
    ["line_id", "condition", "accel_mm_s2", "feed_mm_s", "jerk_mm_s", "length_mm", "widths_file"];

/// The units of an `fdm-widths` dataset's quantities (`[units]` of `dataset.toml`).
pub const UNITS: [(&str, &str); 6] =
    [("position", "mm"), ("width", "mm"), ("accel", "mm/s^2"), ("feed", "mm/s"), ("jerk", "mm/s"), ("length", "mm")];

/// The `[units]` table of `dataset.toml` for `units`.
pub fn units_table(units: &[(&str, &str)]) -> std::collections::BTreeMap<String, String> {
    units.iter().map(|(q, u)| (q.to_string(), u.to_string())).collect()
}

/// Commanded motion of one straight line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineMotion {
    /// Commanded acceleration a0 (mm/s²).
    pub accel_mm_s2: f64,
    /// Commanded feed F0 (mm/s).
    pub feed_mm_s: f64,
    /// Jerk speed = start and end speed (mm/s).
    pub jerk_mm_s: f64,
    /// Line length (mm).
    pub length_mm: f64,
}

/// One measured line.
#[derive(Debug, Clone, PartialEq)]
pub struct WidthLine {
    /// Unique id within the dataset (a file-name-safe string).
    pub line_id: String,
    /// Experimental condition label (`S800F9000`).
    pub condition: String,
    /// Commanded motion.
    pub motion: LineMotion,
    /// Positions along the line (mm), strictly increasing.
    pub positions_mm: Vec<f64>,
    /// Measured widths (mm), one per position.
    pub widths_mm: Vec<f64>,
}

/// A whole `fdm-widths` dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct FdmWidthsDataset {
    /// Its `dataset.toml`.
    pub manifest: DatasetManifest,
    /// Its lines, in `lines.csv` order.
    pub lines: Vec<WidthLine>,
}

impl FdmWidthsDataset {
    /// Reads and checks a dataset folder.
    pub fn read(dir: &Path) -> Result<Self, DatasetError> {
        let manifest = DatasetManifest::read(dir, KIND, READABLE_VERSIONS)?;
        let table = CsvTable::read(&file_in(dir, "lines.csv")?)?;
        let cols: Vec<usize> = LINE_COLUMNS.iter().map(|c| table.column(c)).collect::<Result<_, _>>()?;
        let lines = table.rows_with_unique_ids(
            cols[0],
            |l: &WidthLine| &l.line_id,
            |row| read_line(dir, &table, row, &cols),
        )?;
        Ok(Self { manifest, lines })
    }

    /// Writes the dataset into `dir` (which should be a fresh staging folder).
    pub fn write(&self, dir: &Path) -> Result<(), DatasetError> {
        let widths_dir = dir.join("widths");
        std::fs::create_dir_all(&widths_dir).map_err(|e| DatasetError::io(&widths_dir, e))?;
        write_file(&dir.join(MANIFEST_FILE), &self.manifest.to_toml())?;
        let mut table = LINE_COLUMNS.join(",") + "\n";
        for line in &self.lines {
            let m = &line.motion;
            table += &format!(
                "{},{},{},{},{},{},widths/{}.csv\n",
                line.line_id, line.condition, m.accel_mm_s2, m.feed_mm_s, m.jerk_mm_s, m.length_mm, line.line_id
            );
            write_file(&widths_dir.join(format!("{}.csv", line.line_id)), &widths_csv(line))?;
        }
        write_file(&dir.join("lines.csv"), &table)
    }
}

fn widths_csv(line: &WidthLine) -> String {
    let mut text = String::from("position_mm,width_mm\n");
    for (x, w) in line.positions_mm.iter().zip(&line.widths_mm) {
        text += &format!("{x},{w}\n");
    }
    text
}

fn write_file(path: &Path, text: &str) -> Result<(), DatasetError> {
    std::fs::write(path, text).map_err(|e| DatasetError::io(path, e))
}

fn read_line(
    dir: &Path,
    table: &CsvTable,
    row: &(usize, Vec<String>),
    cols: &[usize],
) -> Result<WidthLine, DatasetError> {
    let positive = |i: usize| -> Result<f64, DatasetError> {
        let x = table.number(row, cols[i])?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(table.field_error(row.0, cols[i], format!("expected a positive number, got {x}")))
        }
    };
    let motion = LineMotion {
        accel_mm_s2: positive(2)?,
        feed_mm_s: positive(3)?,
        jerk_mm_s: positive(4)?,
        length_mm: positive(5)?,
    };
    check_length(motion.length_mm).map_err(|e| table.field_error(row.0, cols[5], e))?;
    if motion.jerk_mm_s > motion.feed_mm_s {
        return Err(table.field_error(row.0, cols[4], "expected a jerk (start) speed no larger than the feed"));
    }
    let line_id = row.1[cols[0]].clone();
    if line_id.is_empty() || !line_id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        return Err(table.field_error(row.0, cols[0], "expected a non-empty id of letters, digits, `_`, `-`"));
    }
    let widths_file = referenced_file(dir, &row.1[cols[6]]).map_err(|rule| table.field_error(row.0, cols[6], rule))?;
    let (positions_mm, widths_mm) = read_widths(&widths_file, motion.length_mm)?;
    Ok(WidthLine { line_id, condition: row.1[cols[1]].clone(), motion, positions_mm, widths_mm })
}

/// What is wrong with one measurement of a widths profile.
#[derive(Debug, Clone, PartialEq)]
pub enum SampleProblem {
    /// The position is outside the line or not after the previous one.
    Position(String),
    /// The width is not positive.
    Width(String),
}

/// Checks one `(position, width)` measurement of a line of `length_mm`, `previous_mm`
/// the position before it: positions strictly increase within `[0, length_mm]`
/// (0.1 % slack at the end), widths are positive. Shared by the reader and the importer.
pub fn check_sample(previous_mm: Option<f64>, x_mm: f64, w_mm: f64, length_mm: f64) -> Result<(), SampleProblem> {
    if previous_mm.is_some_and(|prev| x_mm <= prev) || x_mm < 0.0 || x_mm > length_mm * 1.001 {
        return Err(SampleProblem::Position(format!(
            "expected increasing positions within [0, {length_mm}] mm, got {x_mm}"
        )));
    }
    if w_mm <= 0.0 {
        return Err(SampleProblem::Width(format!("expected a positive width, got {w_mm}")));
    }
    if w_mm > MAX_BEAD_WIDTH_MM {
        return Err(SampleProblem::Width(format!("expected a width of at most {MAX_BEAD_WIDTH_MM} mm, got {w_mm:e}")));
    }
    Ok(())
}

/// Checks a line's `length_mm` against [`MAX_LINE_LENGTH_MM`] (its sign is checked
/// where it is read).
pub(crate) fn check_length(length_mm: f64) -> Result<(), String> {
    if length_mm <= MAX_LINE_LENGTH_MM {
        Ok(())
    } else {
        Err(format!("expected a line length of at most {MAX_LINE_LENGTH_MM} mm, got {length_mm:e}"))
    }
}

/// Reads a `position_mm,width_mm` file and checks every measurement ([`check_sample`]).
fn read_widths(file: &Path, length_mm: f64) -> Result<(Vec<f64>, Vec<f64>), DatasetError> {
    let table = CsvTable::read(file)?;
    let (xc, wc) = (table.column("position_mm")?, table.column("width_mm")?);
    let mut positions: Vec<f64> = Vec::with_capacity(table.rows.len());
    let mut widths = Vec::with_capacity(table.rows.len());
    for row in &table.rows {
        let (x, w) = (table.number(row, xc)?, table.number(row, wc)?);
        check_sample(positions.last().copied(), x, w, length_mm).map_err(|problem| match problem {
            SampleProblem::Position(e) => table.field_error(row.0, xc, e),
            SampleProblem::Width(e) => table.field_error(row.0, wc, e),
        })?;
        positions.push(x);
        widths.push(w);
    }
    Ok((positions, widths))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::manifest::Provenance;

    fn example() -> FdmWidthsDataset {
        let manifest = DatasetManifest {
            kind: KIND.into(),
            format_version: FORMAT_VERSION,
            printer: "demo".into(),
            description: String::new(),
            units: [("position".to_string(), "mm".to_string())].into(),
            provenance: Provenance::Measured {
                source: "hand".into(),
                license: "CC0".into(),
                imported_by: "test".into(),
            },
        };
        let line = WidthLine {
            line_id: "S400F3000".into(),
            condition: "S400F3000".into(),
            motion: LineMotion { accel_mm_s2: 400.0, feed_mm_s: 50.0, jerk_mm_s: 8.0, length_mm: 120.0 },
            positions_mm: vec![0.0, 60.0, 120.0],
            widths_mm: vec![0.7, 0.8, 0.9],
        };
        FdmWidthsDataset { manifest, lines: vec![line] }
    }

    #[test]
    fn write_then_read_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        example().write(dir.path()).unwrap();
        assert_eq!(FdmWidthsDataset::read(dir.path()).unwrap(), example());
    }

    #[test]
    fn negative_feed_names_line_and_field() {
        let dir = tempfile::tempdir().unwrap();
        example().write(dir.path()).unwrap();
        let lines = dir.path().join("lines.csv");
        let text = std::fs::read_to_string(&lines).unwrap().replace(",50,", ",-50,");
        std::fs::write(&lines, text).unwrap();
        let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
        assert!(err.contains("lines.csv:line 2, field feed_mm_s: expected a positive number, got -50"), "{err}");
    }

    /// `example()` written into a fresh folder, with `edit(lines.csv text)` applied.
    fn edited(edit: impl Fn(String) -> String) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        example().write(dir.path()).unwrap();
        let lines = dir.path().join("lines.csv");
        std::fs::write(&lines, edit(std::fs::read_to_string(&lines).unwrap())).unwrap();
        dir
    }

    #[test]
    fn a_line_longer_than_the_limit_or_a_bead_wider_is_refused() {
        // 1000 km: the models would lay it on a grid of 2·10¹⁰ points.
        let dir = edited(|text| text.replace(",8,120,", ",8,1e9,"));
        let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("lines.csv:line 2, field length_mm: expected a line length of at most 10000 mm, got 1e9"),
            "{err}"
        );
        let dir = edited(|text| text);
        let widths = dir.path().join("widths/S400F3000.csv");
        let text = std::fs::read_to_string(&widths).unwrap().replace(",0.8", ",1e300");
        std::fs::write(&widths, text).unwrap();
        let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("S400F3000.csv:line 3, field width_mm: expected a width of at most 1000 mm, got 1e300"),
            "{err}"
        );
    }

    #[test]
    fn a_line_id_given_twice_is_refused() {
        let dir = edited(|text| {
            let row = text.lines().nth(1).unwrap().to_string();
            format!("{text}{row}\n")
        });
        let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("lines.csv:line 3, field line_id: expected a unique id, `S400F3000` is also on line 2"),
            "{err}"
        );
    }

    #[test]
    fn widths_files_outside_the_folder_are_refused_before_they_are_read() {
        let outside = tempfile::tempdir().unwrap();
        let secret = outside.path().join("secret.csv");
        std::fs::write(&secret, "position_mm,width_mm\nTOP SECRET,1\n").unwrap();
        for path in [secret.display().to_string(), "../secret.csv".to_string(), "widths/../../secret.csv".into()] {
            let dir = edited(|text| text.replace("widths/S400F3000.csv", &path));
            let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
            assert!(
                err.contains("lines.csv:line 2, field widths_file: expected a path relative to the dataset folder"),
                "{err}"
            );
            assert!(!err.contains("TOP SECRET"), "{err}");
        }
    }

    #[test]
    fn an_unknown_format_version_names_the_versions_this_build_reads() {
        let dir = tempfile::tempdir().unwrap();
        example().write(dir.path()).unwrap();
        let toml = dir.path().join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&toml).unwrap().replace("format_version = 1", "format_version = 7");
        std::fs::write(&toml, text).unwrap();
        let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains(
                "dataset.toml:format_version: this build of amrepro reads `fdm-widths` format_version 1, got 7"
            ),
            "{err}"
        );
    }

    #[test]
    fn files_with_a_byte_order_mark_read() {
        let dir = tempfile::tempdir().unwrap();
        example().write(dir.path()).unwrap();
        for name in [MANIFEST_FILE, "lines.csv", "widths/S400F3000.csv"] {
            let file = dir.path().join(name);
            let text = std::fs::read_to_string(&file).unwrap();
            std::fs::write(&file, format!("\u{feff}{text}")).unwrap();
        }
        assert_eq!(FdmWidthsDataset::read(dir.path()).unwrap(), example());
    }

    #[test]
    fn missing_widths_file_and_wrong_kind_are_named() {
        let dir = tempfile::tempdir().unwrap();
        example().write(dir.path()).unwrap();
        std::fs::remove_file(dir.path().join("widths/S400F3000.csv")).unwrap();
        let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
        assert!(err.contains("S400F3000.csv: missing"), "{err}");
        let toml = dir.path().join(MANIFEST_FILE);
        let text = std::fs::read_to_string(&toml).unwrap().replace("fdm-widths", "inkjet-scans");
        std::fs::write(&toml, text).unwrap();
        let err = FdmWidthsDataset::read(dir.path()).unwrap_err().to_string();
        assert!(err.contains("expected kind `fdm-widths`"), "{err}");
    }
}
