//! The `fdm-lines` dataset kind (DESIGN §4): one top-view photo per printed straight
//! line, with the line's commanded kinematics and where it lies in the image — what a
//! lab that photographs its lines has, and what paper 000 measured its widths from
//! (Sec. III).
//!
//! ```text
//! dataset.toml           kind = "fdm-lines", printer, units, provenance
//! lines.csv              line_id,condition,image,px_per_mm,accel_mm_s2,feed_mm_s,jerk_mm_s,
//!                        length_mm,layer_height_mm,nominal_width_mm,start_x_px,start_y_px,direction_deg
//! images/<line_id>.png   8- or 16-bit gray (or RGB) top view
//! truth/                 virtual datasets only: the true edges (evaluation stages only)
//! ```
//!
//! `start_x_px, start_y_px` is where the line starts (pixel coordinates, x to the right,
//! y down, the top-left pixel's corner at 0, 0) and `direction_deg` the direction it was
//! printed in (0 = +x, 90 = +y), both as marked by hand or read from a fixture: the
//! segmentation refines them, so a few pixels and half a degree off is fine.
//!
//! - [`camera`]: the virtual top-view camera that renders a printed line.
//! - [`generate`](mod@generate): the virtual FDM printer writing an `fdm-lines` dataset.

pub mod camera;
pub mod generate;

use std::path::{Path, PathBuf};

use crate::csv_table::CsvTable;
use crate::error::DatasetError;
use crate::fdm_widths::{check_length, LineMotion};
use crate::limits::{check_size, LINE_IMAGE_PIXELS, LINE_IMAGE_SIDE_PX};
use crate::manifest::DatasetManifest;
use crate::paths::{file_in, referenced_file};

/// The kind string in `dataset.toml`.
pub const KIND: &str = "fdm-lines";
/// Current folder layout version.
pub const FORMAT_VERSION: u32 = 1;
/// The folder layout versions this build reads.
pub const READABLE_VERSIONS: &[u32] = &[FORMAT_VERSION];
/// Columns of `lines.csv`, in order.
pub const LINE_COLUMNS: [&str; 13] = [
    "line_id",
    "condition",
    "image",
    "px_per_mm",
    "accel_mm_s2",
    "feed_mm_s",
    "jerk_mm_s",
    "length_mm",
    "layer_height_mm",
    "nominal_width_mm",
    "start_x_px",
    "start_y_px",
    "direction_deg",
];

/// Where a line lies in its photo and at what scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImagePlacement {
    /// Pixel scale (px/mm) as calibrated.
    pub px_per_mm: f64,
    /// Start point, x (px).
    pub start_x_px: f64,
    /// Start point, y (px).
    pub start_y_px: f64,
    /// Print direction (degrees, 0 = +x, 90 = +y).
    pub direction_deg: f64,
}

/// One photographed line.
#[derive(Debug, Clone, PartialEq)]
pub struct PhotoLine {
    /// Unique id within the dataset (a file-name-safe string).
    pub line_id: String,
    /// Experimental condition label (`S800F9000`).
    pub condition: String,
    /// The photo: as read, its path (inside the dataset folder); as written by
    /// [`lines_csv`], relative to the folder (`images/<line_id>.png`).
    pub image: PathBuf,
    /// Its width and height (px) from the PNG header, or what is wrong with the file
    /// (not a PNG, too large): one bad photo does not stop the others being read.
    pub image_size_px: Result<(usize, usize), String>,
    /// Commanded motion (G-code).
    pub motion: LineMotion,
    /// Layer height (mm).
    pub layer_height_mm: f64,
    /// Nominal (sliced) line width (mm).
    pub nominal_width_mm: f64,
    /// Where the line lies in the photo.
    pub placement: ImagePlacement,
}

/// A whole `fdm-lines` dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct FdmLinesDataset {
    /// Its `dataset.toml`.
    pub manifest: DatasetManifest,
    /// Its lines, in `lines.csv` order.
    pub lines: Vec<PhotoLine>,
}

impl FdmLinesDataset {
    /// Reads and checks a dataset folder: every field, and every photo's PNG header
    /// (size within [`LINE_IMAGE_SIDE_PX`] and [`LINE_IMAGE_PIXELS`]; a bad photo is
    /// recorded in its line's [`PhotoLine::image_size_px`]); the pixels are not decoded
    /// here.
    pub fn read(dir: &Path) -> Result<Self, DatasetError> {
        let manifest = DatasetManifest::read(dir, KIND, READABLE_VERSIONS)?;
        let table = CsvTable::read(&file_in(dir, "lines.csv")?)?;
        let cols: Vec<usize> = LINE_COLUMNS.iter().map(|c| table.column(c)).collect::<Result<_, _>>()?;
        let lines = table.rows_with_unique_ids(
            cols[0],
            |l: &PhotoLine| &l.line_id,
            |row| read_line(dir, &table, row, &cols),
        )?;
        Ok(Self { manifest, lines })
    }
}

/// The `lines.csv` text of `lines` (image paths relative to the folder).
pub fn lines_csv(lines: &[PhotoLine]) -> String {
    let mut text = LINE_COLUMNS.join(",") + "\n";
    for l in lines {
        let (m, p) = (&l.motion, &l.placement);
        text += &format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
            l.line_id,
            l.condition,
            l.image.display(),
            p.px_per_mm,
            m.accel_mm_s2,
            m.feed_mm_s,
            m.jerk_mm_s,
            m.length_mm,
            l.layer_height_mm,
            l.nominal_width_mm,
            p.start_x_px,
            p.start_y_px,
            p.direction_deg
        );
    }
    text
}

fn read_line(
    dir: &Path,
    table: &CsvTable,
    row: &(usize, Vec<String>),
    cols: &[usize],
) -> Result<PhotoLine, DatasetError> {
    let number = |i: usize| table.number(row, cols[i]);
    let positive = |i: usize| -> Result<f64, DatasetError> {
        let x = number(i)?;
        if x > 0.0 {
            Ok(x)
        } else {
            Err(table.field_error(row.0, cols[i], format!("expected a positive number, got {x}")))
        }
    };
    let line_id = row.1[cols[0]].clone();
    if line_id.is_empty() || !line_id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        return Err(table.field_error(row.0, cols[0], "expected a non-empty id of letters, digits, `_`, `-`"));
    }
    let motion = LineMotion {
        accel_mm_s2: positive(4)?,
        feed_mm_s: positive(5)?,
        jerk_mm_s: positive(6)?,
        length_mm: positive(7)?,
    };
    check_length(motion.length_mm).map_err(|e| table.field_error(row.0, cols[7], e))?;
    if motion.jerk_mm_s > motion.feed_mm_s {
        return Err(table.field_error(row.0, cols[6], "expected a jerk (start) speed no larger than the feed"));
    }
    let placement = ImagePlacement {
        px_per_mm: positive(3)?,
        start_x_px: number(10)?,
        start_y_px: number(11)?,
        direction_deg: number(12)?,
    };
    let image = referenced_file(dir, &row.1[cols[2]]).map_err(|rule| table.field_error(row.0, cols[2], rule))?;
    let image_size_px = png_size(&image).map_err(|e| e.to_string());
    Ok(PhotoLine {
        line_id,
        condition: row.1[cols[1]].clone(),
        image,
        image_size_px,
        motion,
        layer_height_mm: positive(8)?,
        nominal_width_mm: positive(9)?,
        placement,
    })
}

/// The width and height in a PNG file's header, checked against the limits.
fn png_size(file: &Path) -> Result<(usize, usize), DatasetError> {
    let reader = std::fs::File::open(file).map_err(|e| DatasetError::io(file, e))?;
    let decoder = png::Decoder::new(std::io::BufReader::new(reader));
    let info = decoder.read_info().map_err(|e| DatasetError::Malformed {
        file: file.to_path_buf(),
        location: None,
        expected: format!("expected a PNG image: {e}"),
    })?;
    let (w, h) = (info.info().width as usize, info.info().height as usize);
    check_size(file, "width", w, &LINE_IMAGE_SIDE_PX)?;
    check_size(file, "height", h, &LINE_IMAGE_SIDE_PX)?;
    check_size(file, "width × height", w * h, &LINE_IMAGE_PIXELS)?;
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::generate::{generate, GenerateConfig};
    use super::*;

    fn small() -> GenerateConfig {
        let camera = super::camera::CameraSettings { px_per_mm: 10.0, ..Default::default() };
        GenerateConfig { camera, conditions: vec![(400.0, 50.0)], ..GenerateConfig::new("taz6", 3) }
    }

    #[test]
    fn a_generated_dataset_reads_back_with_its_placements() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("lines");
        generate(&small(), &dir).unwrap();
        let data = FdmLinesDataset::read(&dir).unwrap();
        assert_eq!(data.lines.len(), 1);
        let line = &data.lines[0];
        assert_eq!((line.motion.accel_mm_s2, line.motion.feed_mm_s, line.motion.length_mm), (400.0, 50.0, 120.0));
        assert!(line.placement.direction_deg.abs() <= 3.5);
        let (w, h) = line.image_size_px.clone().unwrap();
        assert!(w > 1200 && h > 20, "{w}×{h}");
    }

    #[test]
    fn bad_fields_and_bad_images_name_the_file_and_the_field() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("lines");
        generate(&small(), &dir).unwrap();
        let csv = dir.join("lines.csv");
        let good = std::fs::read_to_string(&csv).unwrap();
        std::fs::write(&csv, good.replace(",400,50,", ",400,-50,")).unwrap();
        let err = FdmLinesDataset::read(&dir).unwrap_err().to_string();
        assert!(err.contains("lines.csv") && err.contains("feed_mm_s") && err.contains("positive"), "{err}");
        std::fs::write(&csv, &good).unwrap();
        let image = std::fs::read_dir(dir.join("images")).unwrap().next().unwrap().unwrap().path();
        let bytes = std::fs::read(&image).unwrap();
        std::fs::write(&image, &bytes[..10]).unwrap();
        let err = FdmLinesDataset::read(&dir).unwrap().lines[0].image_size_px.clone().unwrap_err();
        assert!(err.contains(".png") && err.contains("PNG"), "{err}");
        std::fs::remove_file(&image).unwrap();
        let err = FdmLinesDataset::read(&dir).unwrap().lines[0].image_size_px.clone().unwrap_err();
        assert!(err.contains(".png"), "{err}");
    }
}
