//! The bounds every size and count read from a dataset is checked against before
//! anything is allocated from it (docs/DATASETS.md, "Validation" of each kind). Each
//! bound says why it is where it is; a value outside is an error naming the file, the
//! field and the accepted range, never an attempt to allocate it.

use std::ops::RangeInclusive;
use std::path::Path;

use crate::error::DatasetError;

/// Camera image width and height (px). At least 2: the undistortion interpolates
/// between two neighbouring pixel centres along each axis. At most 2048: 1.6 × the
/// 1280 × 1024 of the largest radiometric thermal cameras, and a frame's correction
/// map then stays under 200 MB.
pub const IMAGE_SIDE_PX: RangeInclusive<usize> = 2..=2048;

/// Width and height of an `fdm-lines` photo (px). At least 8: a profile across the
/// line needs a few pixels on each side. At most 32 768: a 300 mm bed at 100 px/mm.
pub const LINE_IMAGE_SIDE_PX: RangeInclusive<usize> = 8..=32_768;

/// Pixels of an `fdm-lines` photo. At most 64 M: 6 × a 120 mm line at 40 px/mm with
/// its margins; decoded to 32-bit floats it takes 256 MB.
pub const LINE_IMAGE_PIXELS: RangeInclusive<usize> = 64..=64 * 1024 * 1024;

/// Ink-jet grid cells along x and along y (`m_x`, `m_y`). At most 2048: 20 × the
/// largest grid of paper 002 (the 100 × 100 pipe junction); one layer of heights is then
/// at most 32 MB.
pub const GRID_SIDE_CELLS: RangeInclusive<usize> = 1..=2048;

/// Layers of a `thermal-sequence` (`layers_printed`). At most 10 000: 1 m of 0.1 mm
/// layers; the monitor walks every layer the frames name.
pub const THERMAL_LAYERS: RangeInclusive<usize> = 1..=10_000;

/// Open-loop layers of a generated `inkjet-scans` print (`--layers`). At most 1000:
/// 250 × the cuboid of Sec. V-D-1 (4 layers); the pipe junction's 100 × 100 grid then
/// keeps its scans, truth and patterns in about 250 MB.
pub const INKJET_LAYERS: RangeInclusive<usize> = 1..=1000;

/// Longest line of an `fdm-widths` or `fdm-lines` dataset (`length_mm`): 10 m, above
/// the beds of large-format extrusion (a few metres). The models lay a line on a
/// 0.05 mm grid, so it then has 200 000 grid points; a longer one is a unit error
/// (a line of 1000 km would ask for terabytes).
pub const MAX_LINE_LENGTH_MM: f64 = 10_000.0;

/// Widest bead of an `fdm-widths` dataset (`width_mm`): 1 m, 20 × the beads of
/// large-format and construction extrusion (tens of mm). A wider one is a unit or parse
/// error, and would swamp every squared error the models sum over the line.
pub const MAX_BEAD_WIDTH_MM: f64 = 1000.0;

/// Largest height of an `inkjet-scans` dataset, measured or desired, in magnitude (µm):
/// 1 m, 100 × a print of the 1000 layers [`INKJET_LAYERS`] allows at paper 002's
/// droplet heights of about 10 µm. A larger value is a unit or parse error, and would
/// swamp every squared error the models sum over a layer.
pub const MAX_HEIGHT_UM: f64 = 1e6;

/// Largest distance of a `thermal-sequence` position (`path.csv`, `trajectory.csv`)
/// from the origin along x or y (mm): a 300 mm bed with the origin at its centre or a
/// corner (the paper's part spans 40 mm). It bounds the grids the analysis lays over
/// the part: the monitor's 0.1 mm mosaic stays under 40 M cells (300 MB).
pub const MAX_COORDINATE_MM: f64 = 300.0;

/// Longest time a camera may film after the trajectory's last sample and still belong
/// to the layer (s): the layer change (travel and z move; 1 s on the virtual printer)
/// during which the camera films the parked nozzle. A frame recorded later means the
/// trajectory does not cover the layer (e.g. a truncated `trajectory.csv`).
pub const MAX_FILMED_AFTER_END_S: f64 = 2.0;

/// Relative tolerance between `sample_period_s` and the spacing of `trajectory.csv`'s
/// `t_s` (the generator writes `t_s` to 1 µs).
pub const SAMPLE_PERIOD_TOLERANCE: f64 = 0.01;

/// An error unless `value` (of `field` in `file`) lies in `range`.
pub fn check_size(file: &Path, field: &str, value: usize, range: &RangeInclusive<usize>) -> Result<(), DatasetError> {
    if range.contains(&value) {
        return Ok(());
    }
    Err(DatasetError::Malformed {
        file: file.to_path_buf(),
        location: Some(field.into()),
        expected: format!("expected {} to {}, got {value}", range.start(), range.end()),
    })
}

/// Cells along each side of a deposit grid: the virtual printer's (0.02 mm cells) and
/// `truth/deposit_L*.png`. At most 8192 (164 mm, 4 × the paper's corner test part):
/// the printer keeps about 16 bytes per cell, 1 GB at this size.
pub const DEPOSIT_SIDE_CELLS: RangeInclusive<usize> = 1..=8192;

/// An error unless the command-line option `name` (`--layers`) lies in `range`.
pub fn check_option(name: &str, value: usize, range: &RangeInclusive<usize>) -> Result<(), DatasetError> {
    if range.contains(&value) {
        return Ok(());
    }
    Err(DatasetError::Malformed {
        file: name.into(),
        location: None,
        expected: format!("expected {} to {}, got {value}", range.start(), range.end()),
    })
}

/// What a number read from a TOML file must be (TOML also spells `nan` and `inf`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum NumberRule {
    /// Any finite number.
    Finite,
    /// Finite and > 0.
    Positive,
    /// Finite and ≥ 0.
    NonNegative,
    /// Finite, in `[lo, hi)`.
    Below(f64, f64),
    /// Finite, in `[lo, hi]`.
    Within(f64, f64),
}

impl NumberRule {
    fn holds(self, x: f64) -> bool {
        x.is_finite()
            && match self {
                Self::Finite => true,
                Self::Positive => x > 0.0,
                Self::NonNegative => x >= 0.0,
                Self::Below(lo, hi) => lo <= x && x < hi,
                Self::Within(lo, hi) => lo <= x && x <= hi,
            }
    }

    fn describe(self) -> String {
        match self {
            Self::Finite => "a finite number".into(),
            Self::Positive => "a finite number > 0".into(),
            Self::NonNegative => "a finite number ≥ 0".into(),
            Self::Below(lo, hi) => format!("a number in [{lo}, {hi})"),
            Self::Within(lo, hi) => format!("a number in [{lo}, {hi}]"),
        }
    }
}

/// An error naming the first `(field, value, rule)` of `file` whose value breaks its rule.
pub fn check_numbers(file: &Path, checks: &[(&str, f64, NumberRule)]) -> Result<(), DatasetError> {
    match checks.iter().find(|(_, value, rule)| !rule.holds(*value)) {
        None => Ok(()),
        Some((field, value, rule)) => Err(DatasetError::Malformed {
            file: file.to_path_buf(),
            location: Some((*field).into()),
            expected: format!("expected {}, got {value}", rule.describe()),
        }),
    }
}

/// Largest `print.gcode` of an `fdm-photos` dataset (bytes): 200 MB, several times the
/// G-code of a full-bed print with fine layers (tens of MB). The reader holds the text
/// while it reads it; a larger file is not the G-code of a photographed test print.
pub const MAX_GCODE_BYTES: usize = 200 * 1024 * 1024;

/// Most moves of an `fdm-photos` G-code: 5 M, what 200 MB of 40-byte move lines hold.
/// A move and its plan take about 200 bytes, so the planned print stays under 1 GB.
pub const MAX_GCODE_MOVES: usize = 5_000_000;

/// Largest distance of a G-code position from the origin along any axis (mm): 10 m,
/// as [`MAX_LINE_LENGTH_MM`]; beyond it a coordinate is a unit or parse error.
pub const MAX_GCODE_COORDINATE_MM: f64 = 10_000.0;
