//! The `thermal-sequence` dataset kind (DESIGN §4): radiometric frames of a
//! nozzle-mounted camera, their recorded times, the commanded trajectory, the camera
//! model and the nozzle pixel (paper 003 Sec. 2.3: P_N^(0), eqs 27-30).
//!
//! ```text
//! dataset.toml      kind = "thermal-sequence", format_version 1, printer, units, provenance
//! camera.toml       width/height, frame period, intrinsics, distortion, nominal mount, nozzle_px
//! process.toml      feed, acceleration, blend tolerance, layer height, nozzle, bead width, τ, temperatures, layers
//! path.csv          vertex,x_mm,y_mm                     the CAD polygon (closed)
//! trajectory.csv    t_s,x_mm,y_mm,e_mm3_s                commanded trajectory of one layer
//! frames.csv        layer,frame,recorded_time_s,file     file = frames/L{layer:02}_F{frame:04}.png
//! frames/*.png      16-bit grayscale, kelvin × 100, 0 = no reading
//! truth/            only evaluation stages read it (see [`ThermalTruth`])
//! ```
//!
//! [`ThermalSequence::open`] reads and checks everything but the PNGs (the analysis
//! decodes frames one at a time with [`read_png16`] and turns a bad one into a
//! diagnostic) and never reads `truth/`.

use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};

use serde::{de::DeserializeOwned, Deserialize, Serialize};

use super::camera::{Distortion, Intrinsics, Mount};
use crate::csv_table::CsvTable;
use crate::error::DatasetError;
use crate::manifest::DatasetManifest;
use models::thermal::DepositGrid;

/// The kind string in `dataset.toml`.
pub const KIND: &str = "thermal-sequence";
/// Current folder layout version.
pub const FORMAT_VERSION: u32 = 1;
/// Name of the ground-truth subfolder.
pub const TRUTH_DIR: &str = "truth";
/// Fill fraction stored as 65535 in `truth/deposit_L*.png`: a layer is at most three
/// layer heights thick (the nozzle face's headroom, reached where melt is squeezed over
/// the edge of the layer below; see `deposition`).
pub const DEPOSIT_PNG_FULL_FILL: f64 = 8.0;

/// `camera.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Image width (px).
    pub width_px: usize,
    /// Image height (px).
    pub height_px: usize,
    /// Nominal frame period (s).
    pub frame_period_s: f64,
    /// Pinhole intrinsics.
    pub intrinsics: Intrinsics,
    /// Lens distortion.
    pub distortion: Distortion,
    /// Nominal mount relative to the nozzle tip.
    pub mount: Mount,
    /// Nozzle tip in the raw (distorted) image, P_N^(0) (px).
    pub nozzle_px: [f64; 2],
}

/// `process.toml`: the print's commanded settings (paper Table 1 and Sec. 3.2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProcessFile {
    /// Programmed feed (mm/s).
    pub feed_mm_s: f64,
    /// Acceleration limit (mm/s²).
    pub accel_mm_s2: f64,
    /// Corner blending tolerance (mm).
    pub blend_tol_mm: f64,
    /// Layer height (mm).
    pub layer_height_mm: f64,
    /// Nozzle diameter (mm).
    pub nozzle_mm: f64,
    /// Nominal bead width (mm).
    pub bead_width_mm: f64,
    /// Nominal deposition time constant τ (s).
    pub tau_s: f64,
    /// Nozzle temperature (°C).
    pub nozzle_temp_c: f64,
    /// Bed temperature (°C).
    pub bed_temp_c: f64,
    /// Filament diameter (mm): E = A_fil·v_e for the deposition velocity v_e.
    pub filament_diameter_mm: f64,
    /// Layers printed (and filmed).
    pub layers_printed: usize,
    /// Trajectory sampling period (s).
    pub sample_period_s: f64,
}

impl ProcessFile {
    /// The print settings as the models take them.
    pub fn print_setup(&self) -> models::thermal::PrintSetup {
        models::thermal::PrintSetup {
            feed_mm_s: self.feed_mm_s,
            accel_mm_s2: self.accel_mm_s2,
            blend_tol_mm: self.blend_tol_mm,
            layer_height_mm: self.layer_height_mm,
            nozzle_mm: self.nozzle_mm,
            bead_width_mm: self.bead_width_mm,
            tau_s: self.tau_s,
            nozzle_temp_c: self.nozzle_temp_c,
            bed_temp_c: self.bed_temp_c,
            layers: self.layers_printed,
            filament_diameter_mm: self.filament_diameter_mm,
            sample_period_s: self.sample_period_s,
        }
    }
}

/// `truth/truth.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthFile {
    /// The camera's true mount (nominal + mounting error, before per-frame vibration).
    pub mount: Mount,
    /// The printer's true deposition time constant (s).
    pub tau_s: f64,
    /// Lower-left corner of deposit cell (0, 0) (mm).
    pub deposit_origin_mm: [f64; 2],
    /// Deposit cell edge (mm).
    pub deposit_cell_mm: f64,
    /// Deposit grid columns.
    pub deposit_nx: usize,
    /// Deposit grid rows (PNG row r is grid row r: y grows downwards in the PNG).
    pub deposit_ny: usize,
    /// Substrate temperature of each layer (°C).
    pub substrate_c: Vec<f64>,
    /// Per-layer flow factor (filament tolerance).
    pub flow_factor: Vec<f64>,
}

/// One row of `frames.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameEntry {
    /// Layer index.
    pub layer: usize,
    /// Frame index within the layer.
    pub frame: usize,
    /// The camera's timestamp t_r (s from the layer start).
    pub recorded_time_s: f64,
    /// The PNG, relative to the dataset folder.
    pub file: PathBuf,
}

/// The commanded trajectory of one layer (`trajectory.csv`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TrajectoryTable {
    /// Sample times (s).
    pub t_s: Vec<f64>,
    /// Nozzle x (mm).
    pub x_mm: Vec<f64>,
    /// Nozzle y (mm).
    pub y_mm: Vec<f64>,
    /// Commanded flow E_cmd (mm³/s).
    pub e_mm3_s: Vec<f64>,
}

/// A `thermal-sequence` dataset as the analysis sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalSequence {
    /// The folder.
    pub dir: PathBuf,
    /// `dataset.toml`.
    pub manifest: DatasetManifest,
    /// `camera.toml`.
    pub camera: CameraFile,
    /// `process.toml`.
    pub process: ProcessFile,
    /// CAD polygon vertices (mm).
    pub path_mm: Vec<[f64; 2]>,
    /// Commanded trajectory.
    pub trajectory: TrajectoryTable,
    /// Frames in file order.
    pub frames: Vec<FrameEntry>,
}

/// One row of `truth/frames.csv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthFrame {
    /// Layer index.
    pub layer: usize,
    /// Frame index.
    pub frame: usize,
    /// True capture time of the image content (s from the layer start).
    pub capture_time_s: f64,
    /// Nozzle tip at that time (mm).
    pub nozzle_mm: [f64; 2],
}

/// One row of `truth/corners.csv`: a printed corner in view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthCorner {
    /// Layer index.
    pub layer: usize,
    /// Frame index.
    pub frame: usize,
    /// Polygon vertex index.
    pub vertex: usize,
    /// Raw (distorted) pixel of the vertex (px).
    pub pixel: [f64; 2],
    /// True temperature at the vertex (°C).
    pub temp_c: f64,
    /// Time since the nozzle passed the corner (s).
    pub age_s: f64,
}

/// One row of `truth/widths.csv`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthWidth {
    /// Layer index.
    pub layer: usize,
    /// Trajectory sample index.
    pub sample: usize,
    /// Sample time (s).
    pub t_s: f64,
    /// Left half width along the path normal (mm).
    pub w_left_mm: f64,
    /// Right half width (mm).
    pub w_right_mm: f64,
}

/// The ground truth of a virtual `thermal-sequence` (evaluation stages only).
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalTruth {
    /// The dataset folder.
    pub dir: PathBuf,
    /// `truth/truth.toml`.
    pub truth: TruthFile,
    /// `truth/frames.csv`.
    pub frames: Vec<TruthFrame>,
    /// `truth/corners.csv`.
    pub corners: Vec<TruthCorner>,
    /// `truth/widths.csv`.
    pub widths: Vec<TruthWidth>,
}

impl ThermalSequence {
    /// Reads and checks a `thermal-sequence` folder (not the PNGs, not `truth/`).
    pub fn open(dir: &Path) -> Result<Self, DatasetError> {
        let manifest = DatasetManifest::read(dir, KIND)?;
        let camera: CameraFile = read_toml(&dir.join("camera.toml"))?;
        let process: ProcessFile = read_toml(&dir.join("process.toml"))?;
        let path = CsvTable::read(&dir.join("path.csv"))?;
        let path_mm = columns(&path, &["x_mm", "y_mm"])?.into_iter().map(|r| [r[0], r[1]]).collect();
        let table = CsvTable::read(&dir.join("trajectory.csv"))?;
        let rows = columns(&table, &["t_s", "x_mm", "y_mm", "e_mm3_s"])?;
        let mut trajectory = TrajectoryTable::default();
        for r in rows {
            trajectory.t_s.push(r[0]);
            trajectory.x_mm.push(r[1]);
            trajectory.y_mm.push(r[2]);
            trajectory.e_mm3_s.push(r[3]);
        }
        let frames = read_frames(dir)?;
        Ok(Self { dir: dir.to_path_buf(), manifest, camera, process, path_mm, trajectory, frames })
    }

    /// Absolute path of a frame's PNG.
    pub fn frame_path(&self, frame: &FrameEntry) -> PathBuf {
        self.dir.join(&frame.file)
    }
}

impl ThermalTruth {
    /// Reads `dir/truth/`.
    pub fn open(dir: &Path) -> Result<Self, DatasetError> {
        let truth_dir = dir.join(TRUTH_DIR);
        let truth: TruthFile = read_toml(&truth_dir.join("truth.toml"))?;
        let table = CsvTable::read(&truth_dir.join("frames.csv"))?;
        let frames = integer_led(&table, &["layer", "frame"], &["capture_time_s", "nozzle_x_mm", "nozzle_y_mm"])?
            .into_iter()
            .map(|(i, r)| TruthFrame { layer: i[0], frame: i[1], capture_time_s: r[0], nozzle_mm: [r[1], r[2]] })
            .collect();
        let table = CsvTable::read(&truth_dir.join("corners.csv"))?;
        let corners = integer_led(&table, &["layer", "frame", "vertex"], &["u_px", "v_px", "temp_c", "age_s"])?
            .into_iter()
            .map(|(i, r)| TruthCorner {
                layer: i[0],
                frame: i[1],
                vertex: i[2],
                pixel: [r[0], r[1]],
                temp_c: r[2],
                age_s: r[3],
            })
            .collect();
        let table = CsvTable::read(&truth_dir.join("widths.csv"))?;
        let widths = integer_led(&table, &["layer", "sample"], &["t_s", "w_left_mm", "w_right_mm"])?
            .into_iter()
            .map(|(i, r)| TruthWidth { layer: i[0], sample: i[1], t_s: r[0], w_left_mm: r[1], w_right_mm: r[2] })
            .collect();
        Ok(Self { dir: dir.to_path_buf(), truth, frames, corners, widths })
    }

    /// The true deposit of `layer`, decoded from `truth/deposit_L{layer:02}.png`.
    pub fn deposit(&self, layer: usize) -> Result<DepositGrid, DatasetError> {
        let file = self.dir.join(TRUTH_DIR).join(deposit_file_name(layer));
        let (w, h, data) = read_png16(&file)?;
        let t = &self.truth;
        if (w, h) != (t.deposit_nx, t.deposit_ny) {
            let expected = format!("expected {}×{} px (truth.toml), got {w}×{h}", t.deposit_nx, t.deposit_ny);
            return Err(DatasetError::Malformed { file, location: None, expected });
        }
        let fill = data.iter().map(|v| (f64::from(*v) / 65535.0 * DEPOSIT_PNG_FULL_FILL) as f32).collect();
        Ok(DepositGrid { origin_mm: t.deposit_origin_mm, cell_mm: t.deposit_cell_mm, nx: w, ny: h, fill })
    }
}

/// `frames/L{layer:02}_F{frame:04}.png`.
pub fn frame_file_name(layer: usize, frame: usize) -> PathBuf {
    Path::new("frames").join(format!("L{layer:02}_F{frame:04}.png"))
}

/// `deposit_L{layer:02}.png` (inside `truth/`).
pub fn deposit_file_name(layer: usize) -> String {
    format!("deposit_L{layer:02}.png")
}

/// Encodes a 16-bit grayscale PNG (row-major, `width × height` values).
pub fn encode_png16(width: usize, height: usize, data: &[u16]) -> Vec<u8> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(BufWriter::new(&mut out), width as u32, height as u32);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Sixteen);
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder.write_header().expect("PNG header to memory");
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_be_bytes()).collect();
        writer.write_image_data(&bytes).expect("PNG data to memory");
    }
    out
}

/// Decodes a 16-bit grayscale PNG into `(width, height, values)`.
pub fn read_png16(file: &Path) -> Result<(usize, usize, Vec<u16>), DatasetError> {
    let bad = |e: String| DatasetError::Malformed { file: file.to_path_buf(), location: None, expected: e };
    let handle = std::fs::File::open(file).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DatasetError::Missing { file: file.to_path_buf(), hint: None },
        _ => DatasetError::io(file, e),
    })?;
    let mut reader =
        png::Decoder::new(BufReader::new(handle)).read_info().map_err(|e| bad(format!("not a PNG: {e}")))?;
    let size = reader.output_buffer_size().ok_or_else(|| bad("PNG too large".into()))?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf).map_err(|e| bad(format!("corrupt PNG: {e}")))?;
    if info.color_type != png::ColorType::Grayscale || info.bit_depth != png::BitDepth::Sixteen {
        return Err(bad(format!("expected 16-bit grayscale, got {:?} {:?}", info.color_type, info.bit_depth)));
    }
    let values = buf[..info.buffer_size()].chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
    Ok((info.width as usize, info.height as usize, values))
}

/// Writes a dataset into a staging folder beside `out_dir` and swaps it into place.
#[derive(Debug)]
pub struct StagedDir {
    staging: PathBuf,
    target: PathBuf,
}

impl StagedDir {
    /// A fresh staging folder `.{name}.staging` next to `out_dir`.
    pub fn new(out_dir: &Path) -> Result<Self, DatasetError> {
        let name = out_dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "dataset".into());
        let staging = out_dir.with_file_name(format!(".{name}.staging"));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| DatasetError::io(&staging, e))?;
        }
        std::fs::create_dir_all(&staging).map_err(|e| DatasetError::io(&staging, e))?;
        Ok(Self { staging, target: out_dir.to_path_buf() })
    }

    /// Writes `bytes` to `relative` inside the staging folder (creating subfolders).
    pub fn write(&self, relative: impl AsRef<Path>, bytes: &[u8]) -> Result<(), DatasetError> {
        let file = self.staging.join(relative);
        if let Some(parent) = file.parent() {
            std::fs::create_dir_all(parent).map_err(|e| DatasetError::io(parent, e))?;
        }
        std::fs::write(&file, bytes).map_err(|e| DatasetError::io(&file, e))
    }

    /// Replaces `out_dir` by the staging folder (an existing `out_dir` is removed last).
    pub fn commit(self) -> Result<(), DatasetError> {
        let old = self.target.with_file_name(format!(
            ".{}.old",
            self.target.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
        ));
        if self.target.exists() {
            if old.exists() {
                std::fs::remove_dir_all(&old).map_err(|e| DatasetError::io(&old, e))?;
            }
            std::fs::rename(&self.target, &old).map_err(|e| DatasetError::io(&self.target, e))?;
        }
        std::fs::rename(&self.staging, &self.target).map_err(|e| DatasetError::io(&self.target, e))?;
        if old.exists() {
            std::fs::remove_dir_all(&old).map_err(|e| DatasetError::io(&old, e))?;
        }
        Ok(())
    }
}

/// Serialises a TOML file's contents.
pub fn to_toml<T: Serialize>(value: &T) -> String {
    toml::to_string_pretty(value).expect("plain structs serialise to TOML")
}

fn read_toml<T: DeserializeOwned>(file: &Path) -> Result<T, DatasetError> {
    let text = std::fs::read_to_string(file).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DatasetError::Missing { file: file.to_path_buf(), hint: None },
        _ => DatasetError::io(file, e),
    })?;
    toml::from_str(&text).map_err(|e| DatasetError::Malformed {
        file: file.to_path_buf(),
        location: None,
        expected: e.to_string().trim().replace('\n', " "),
    })
}

/// The named numeric columns of every row.
fn columns(table: &CsvTable, names: &[&str]) -> Result<Vec<Vec<f64>>, DatasetError> {
    let cols: Vec<usize> = names.iter().map(|n| table.column(n)).collect::<Result<_, _>>()?;
    table.rows.iter().map(|row| cols.iter().map(|&c| table.number(row, c)).collect()).collect()
}

/// A row as (non-negative integer fields, numeric fields).
type MixedRow = (Vec<usize>, Vec<f64>);

/// Rows as (non-negative integer columns, numeric columns).
fn integer_led(table: &CsvTable, ints: &[&str], nums: &[&str]) -> Result<Vec<MixedRow>, DatasetError> {
    let int_cols: Vec<usize> = ints.iter().map(|n| table.column(n)).collect::<Result<_, _>>()?;
    let num_cols: Vec<usize> = nums.iter().map(|n| table.column(n)).collect::<Result<_, _>>()?;
    table
        .rows
        .iter()
        .map(|row| {
            let i = int_cols.iter().map(|&c| index_field(table, row, c)).collect::<Result<Vec<_>, _>>()?;
            let n = num_cols.iter().map(|&c| table.number(row, c)).collect::<Result<Vec<_>, _>>()?;
            Ok((i, n))
        })
        .collect()
}

fn index_field(table: &CsvTable, row: &(usize, Vec<String>), col: usize) -> Result<usize, DatasetError> {
    row.1[col]
        .parse::<usize>()
        .map_err(|_| table.field_error(row.0, col, format!("expected a non-negative integer, got `{}`", row.1[col])))
}

fn read_frames(dir: &Path) -> Result<Vec<FrameEntry>, DatasetError> {
    let table = CsvTable::read(&dir.join("frames.csv"))?;
    let file_col = table.column("file")?;
    let time_col = table.column("recorded_time_s")?;
    let (layer_col, frame_col) = (table.column("layer")?, table.column("frame")?);
    table
        .rows
        .iter()
        .map(|row| {
            let file = PathBuf::from(&row.1[file_col]);
            if file.is_absolute() || file.components().any(|c| matches!(c, std::path::Component::ParentDir)) {
                return Err(table.field_error(row.0, file_col, "expected a path inside the dataset folder"));
            }
            Ok(FrameEntry {
                layer: index_field(&table, row, layer_col)?,
                frame: index_field(&table, row, frame_col)?,
                recorded_time_s: table.number(row, time_col)?,
                file,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png16_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let data: Vec<u16> = (0..12u16).map(|i| i * 5000 + 7).collect();
        let file = dir.path().join("a.png");
        std::fs::write(&file, encode_png16(4, 3, &data)).unwrap();
        assert_eq!(read_png16(&file).unwrap(), (4, 3, data));
        std::fs::write(&file, b"not a png").unwrap();
        assert!(read_png16(&file).unwrap_err().to_string().contains("not a PNG"));
    }

    #[test]
    fn frames_csv_errors_name_line_and_field() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("frames.csv"), "layer,frame,recorded_time_s,file\n0,x,0.0,frames/a.png\n")
            .unwrap();
        let err = read_frames(dir.path()).unwrap_err().to_string();
        assert!(err.contains("frames.csv:line 2, field frame: expected a non-negative integer"), "{err}");
    }

    #[test]
    fn staged_dir_replaces_the_target_atomically() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("ds");
        std::fs::create_dir_all(&out).unwrap();
        std::fs::write(out.join("old.txt"), b"old").unwrap();
        let staged = StagedDir::new(&out).unwrap();
        staged.write("sub/new.txt", b"new").unwrap();
        assert!(out.join("old.txt").exists(), "nothing changes before commit");
        staged.commit().unwrap();
        assert!(!out.join("old.txt").exists() && out.join("sub/new.txt").exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no staging leftovers");
    }
}
