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

use serde::{Deserialize, Serialize};

use super::camera::{Distortion, Intrinsics, Mount};
use crate::csv_table::CsvTable;
use crate::error::DatasetError;
use crate::limits::{
    check_numbers, check_size, NumberRule, NumberRule::*, DEPOSIT_SIDE_CELLS, IMAGE_SIDE_PX, MAX_COORDINATE_MM,
    MAX_FILMED_AFTER_END_S, SAMPLE_PERIOD_TOLERANCE, THERMAL_LAYERS,
};
use crate::manifest::DatasetManifest;
use crate::paths::{file_in, referenced_file};
use crate::text::read_toml;
use models::thermal::DepositGrid;

/// The kind string in `dataset.toml`.
pub const KIND: &str = "thermal-sequence";
/// Current folder layout version.
pub const FORMAT_VERSION: u32 = 1;
/// The folder layout versions this build reads.
pub const READABLE_VERSIONS: &[u32] = &[FORMAT_VERSION];
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
        let manifest = DatasetManifest::read(dir, KIND, READABLE_VERSIONS)?;
        let camera = read_camera(&file_in(dir, "camera.toml")?)?;
        let process = read_process(&file_in(dir, "process.toml")?)?;
        let path = CsvTable::read(&file_in(dir, "path.csv")?)?;
        let path_mm = positions(&path, &columns(&path, &["x_mm", "y_mm"])?)?;
        let trajectory = read_trajectory(&file_in(dir, "trajectory.csv")?, process.sample_period_s)?;
        let frames = read_frames(dir, &process, &camera, &trajectory)?;
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
        let truth = read_truth_file(&file_in(dir, "truth/truth.toml")?)?;
        let table = CsvTable::read(&file_in(dir, "truth/frames.csv")?)?;
        let frames = integer_led(&table, &["layer", "frame"], &["capture_time_s", "nozzle_x_mm", "nozzle_y_mm"])?
            .into_iter()
            .map(|(i, r)| TruthFrame { layer: i[0], frame: i[1], capture_time_s: r[0], nozzle_mm: [r[1], r[2]] })
            .collect();
        let table = CsvTable::read(&file_in(dir, "truth/corners.csv")?)?;
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
        let table = CsvTable::read(&file_in(dir, "truth/widths.csv")?)?;
        let widths = integer_led(&table, &["layer", "sample"], &["t_s", "w_left_mm", "w_right_mm"])?
            .into_iter()
            .map(|(i, r)| TruthWidth { layer: i[0], sample: i[1], t_s: r[0], w_left_mm: r[1], w_right_mm: r[2] })
            .collect();
        Ok(Self { dir: dir.to_path_buf(), truth, frames, corners, widths })
    }

    /// The true deposit of `layer`, decoded from `truth/deposit_L{layer:02}.png`.
    pub fn deposit(&self, layer: usize) -> Result<DepositGrid, DatasetError> {
        let file = file_in(&self.dir, &format!("{TRUTH_DIR}/{}", deposit_file_name(layer)))?;
        let t = &self.truth;
        let (w, h, data) = read_png16(&file, t.deposit_nx, t.deposit_ny)?;
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

/// Decodes a 16-bit grayscale PNG that must be `width` × `height` into
/// `(width, height, values)`; the header's size is checked before anything is allocated.
pub fn read_png16(file: &Path, width: usize, height: usize) -> Result<(usize, usize, Vec<u16>), DatasetError> {
    let bad = |e: String| DatasetError::Malformed { file: file.to_path_buf(), location: None, expected: e };
    let handle = std::fs::File::open(file).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => DatasetError::Missing { file: file.to_path_buf(), hint: None },
        _ => DatasetError::io(file, e),
    })?;
    // Room for the image and the decoder's row buffers; more is a lie in the header.
    let limits = png::Limits { bytes: 4 * width * height + (1 << 16) };
    let mut reader = png::Decoder::new_with_limits(BufReader::new(handle), limits)
        .read_info()
        .map_err(|e| bad(format!("not a PNG: {e}")))?;
    let (w, h) = (reader.info().width as usize, reader.info().height as usize);
    if (w, h) != (width, height) {
        return Err(bad(format!("expected {width}×{height} px, the PNG header says {w}×{h}")));
    }
    let size = reader.output_buffer_size().ok_or_else(|| bad("PNG too large".into()))?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf).map_err(|e| bad(format!("corrupt PNG: {e}")))?;
    if info.color_type != png::ColorType::Grayscale || info.bit_depth != png::BitDepth::Sixteen {
        return Err(bad(format!("expected 16-bit grayscale, got {:?} {:?}", info.color_type, info.bit_depth)));
    }
    let values = buf[..info.buffer_size()].chunks_exact(2).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
    Ok((w, h, values))
}

/// Serialises a TOML file's contents.
pub fn to_toml<T: Serialize>(value: &T) -> String {
    toml::to_string_pretty(value).expect("plain structs serialise to TOML")
}

/// `camera.toml`, every size within [`IMAGE_SIDE_PX`] and every number finite.
fn read_camera(file: &Path) -> Result<CameraFile, DatasetError> {
    let c: CameraFile = read_toml(file)?;
    check_size(file, "width_px", c.width_px, &IMAGE_SIDE_PX)?;
    check_size(file, "height_px", c.height_px, &IMAGE_SIDE_PX)?;
    let (i, d, m) = (&c.intrinsics, &c.distortion, &c.mount);
    check_numbers(
        file,
        &[
            ("frame_period_s", c.frame_period_s, Positive),
            ("intrinsics.fx_px", i.fx_px, Positive),
            ("intrinsics.fy_px", i.fy_px, Positive),
            ("intrinsics.cx_px", i.cx_px, Finite),
            ("intrinsics.cy_px", i.cy_px, Finite),
            ("distortion.k1", d.k1, Finite),
            ("distortion.k2", d.k2, Finite),
            ("distortion.p1", d.p1, Finite),
            ("distortion.p2", d.p2, Finite),
            ("mount.height_mm", m.height_mm, Positive),
            ("mount.tilt_deg", m.tilt_deg, Below(0.0, 90.0)),
            ("mount.look_at_mm", m.look_at_mm[0], Finite),
            ("mount.look_at_mm", m.look_at_mm[1], Finite),
            ("mount.roll_deg", m.roll_deg, Finite),
            ("nozzle_px", c.nozzle_px[0], Finite),
            ("nozzle_px", c.nozzle_px[1], Finite),
        ],
    )?;
    Ok(c)
}

/// The sizes of a bead (layer height, nozzle, bead width), mm: from 1 µm, far below any
/// extruded bead (a layer height of 1e-300 mm left the monitor's direction allocation
/// with NaN angles), to 100 mm, beyond the layers of construction-scale extrusion.
const BEAD_SIZE_MM: NumberRule = Within(1e-3, 100.0);

/// `process.toml`: physical quantities positive (bead sizes within [`BEAD_SIZE_MM`]),
/// `layers_printed` within [`THERMAL_LAYERS`].
fn read_process(file: &Path) -> Result<ProcessFile, DatasetError> {
    let p: ProcessFile = read_toml(file)?;
    check_size(file, "layers_printed", p.layers_printed, &THERMAL_LAYERS)?;
    check_numbers(
        file,
        &[
            ("feed_mm_s", p.feed_mm_s, Positive),
            ("accel_mm_s2", p.accel_mm_s2, Positive),
            ("blend_tol_mm", p.blend_tol_mm, NonNegative),
            ("layer_height_mm", p.layer_height_mm, BEAD_SIZE_MM),
            ("nozzle_mm", p.nozzle_mm, BEAD_SIZE_MM),
            ("bead_width_mm", p.bead_width_mm, BEAD_SIZE_MM),
            ("tau_s", p.tau_s, NonNegative),
            ("bed_temp_c", p.bed_temp_c, Finite),
            ("nozzle_temp_c", p.nozzle_temp_c, Within(p.bed_temp_c + 1.0, f64::MAX)),
            ("filament_diameter_mm", p.filament_diameter_mm, Positive),
            ("sample_period_s", p.sample_period_s, Positive),
        ],
    )?;
    Ok(p)
}

/// `truth/truth.toml`, the deposit grid within [`DEPOSIT_SIDE_CELLS`].
fn read_truth_file(file: &Path) -> Result<TruthFile, DatasetError> {
    let t: TruthFile = read_toml(file)?;
    check_size(file, "deposit_nx", t.deposit_nx, &DEPOSIT_SIDE_CELLS)?;
    check_size(file, "deposit_ny", t.deposit_ny, &DEPOSIT_SIDE_CELLS)?;
    check_numbers(file, &[("deposit_cell_mm", t.deposit_cell_mm, Positive)])?;
    Ok(t)
}

/// `trajectory.csv`: times strictly increasing at `sample_period_s` (first step within
/// [`SAMPLE_PERIOD_TOLERANCE`]), positions within [`MAX_COORDINATE_MM`].
fn read_trajectory(file: &Path, sample_period_s: f64) -> Result<TrajectoryTable, DatasetError> {
    let table = CsvTable::read(file)?;
    let rows = columns(&table, &["t_s", "x_mm", "y_mm", "e_mm3_s"])?;
    let xy: Vec<Vec<f64>> = rows.iter().map(|r| r[1..3].to_vec()).collect();
    positions(&table, &xy)?;
    let t_col = table.column("t_s")?;
    for (k, pair) in rows.windows(2).enumerate() {
        let (line, step_s) = (table.rows[k + 1].0, pair[1][0] - pair[0][0]);
        if step_s <= 0.0 {
            return Err(table.field_error(
                line,
                t_col,
                format!("expected times increasing, got {} after {}", pair[1][0], pair[0][0]),
            ));
        }
        if k == 0 && (step_s - sample_period_s).abs() > SAMPLE_PERIOD_TOLERANCE * sample_period_s {
            let expected =
                format!("expected the step of sample_period_s = {sample_period_s} s (process.toml), got {step_s} s");
            return Err(table.field_error(line, t_col, expected));
        }
    }
    let mut trajectory = TrajectoryTable::default();
    for r in rows {
        trajectory.t_s.push(r[0]);
        trajectory.x_mm.push(r[1]);
        trajectory.y_mm.push(r[2]);
        trajectory.e_mm3_s.push(r[3]);
    }
    Ok(trajectory)
}

/// Rows of `(x_mm, y_mm)` as points, each coordinate within ±[`MAX_COORDINATE_MM`].
fn positions(table: &CsvTable, rows: &[Vec<f64>]) -> Result<Vec<[f64; 2]>, DatasetError> {
    let cols = [table.column("x_mm")?, table.column("y_mm")?];
    for (row, r) in table.rows.iter().zip(rows) {
        if let Some(axis) = (0..2).find(|&a| r[a].abs() > MAX_COORDINATE_MM) {
            let expected = format!("expected a position within ±{MAX_COORDINATE_MM} mm of the origin, got {}", r[axis]);
            return Err(table.field_error(row.0, cols[axis], expected));
        }
    }
    Ok(rows.iter().map(|r| [r[0], r[1]]).collect())
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

/// `frames.csv`: each file inside the folder, each `(layer, frame)` once, layers the
/// dataset has, recorded times the trajectory covers (see [`recorded_time`]).
fn read_frames(
    dir: &Path,
    process: &ProcessFile,
    camera: &CameraFile,
    trajectory: &TrajectoryTable,
) -> Result<Vec<FrameEntry>, DatasetError> {
    let table = CsvTable::read(&file_in(dir, "frames.csv")?)?;
    let file_col = table.column("file")?;
    let (layer_col, frame_col) = (table.column("layer")?, table.column("frame")?);
    let mut seen: std::collections::HashMap<(usize, usize), usize> = std::collections::HashMap::new();
    let mut frames = Vec::with_capacity(table.rows.len());
    for row in &table.rows {
        let file = referenced_file(dir, &row.1[file_col]).map_err(|rule| table.field_error(row.0, file_col, rule))?;
        let layer = index_field(&table, row, layer_col)?;
        if layer >= process.layers_printed {
            let expected = format!(
                "expected a layer below layers_printed = {} (process.toml), got {layer}",
                process.layers_printed
            );
            return Err(table.field_error(row.0, layer_col, expected));
        }
        let frame = index_field(&table, row, frame_col)?;
        if let Some(first) = seen.insert((layer, frame), row.0) {
            return Err(table.field_error(
                row.0,
                frame_col,
                format!("expected each frame once, layer {layer} frame {frame} is also on line {first}"),
            ));
        }
        let recorded_time_s = recorded_time(&table, row, camera, trajectory)?;
        let file = file.strip_prefix(dir).map(Path::to_path_buf).unwrap_or(file);
        frames.push(FrameEntry { layer, frame, recorded_time_s, file });
    }
    Ok(frames)
}

/// A frame's `recorded_time_s`: from one frame period before the trajectory's first
/// sample to [`MAX_FILMED_AFTER_END_S`] after its last, else the trajectory does not
/// cover the frames (a truncated `trajectory.csv`, or another clock).
fn recorded_time(
    table: &CsvTable,
    row: &(usize, Vec<String>),
    camera: &CameraFile,
    trajectory: &TrajectoryTable,
) -> Result<f64, DatasetError> {
    let col = table.column("recorded_time_s")?;
    let t_s = table.number(row, col)?;
    let (first, last) = (trajectory.t_s[0], trajectory.t_s[trajectory.t_s.len() - 1]);
    let (lo, hi) = (first - camera.frame_period_s, last + MAX_FILMED_AFTER_END_S);
    if (lo..=hi).contains(&t_s) {
        return Ok(t_s);
    }
    Err(table.field_error(
        row.0,
        col,
        format!(
            "expected a time the trajectory covers: trajectory.csv runs from {first} s to {last} s, so frames from {lo} s to {hi} s ({MAX_FILMED_AFTER_END_S} s of layer change after its end), got {t_s} s"
        ),
    ))
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
        assert_eq!(read_png16(&file, 4, 3).unwrap(), (4, 3, data));
        std::fs::write(&file, b"not a png").unwrap();
        assert!(read_png16(&file, 4, 3).unwrap_err().to_string().contains("not a PNG"));
    }

    /// The seed sequence of the fuzz tests (`tests/seeds/thermal-sequence`), copied,
    /// with each `(file, from, to)` replacement applied.
    fn seed(edits: &[(&str, &str, &str)]) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        copy_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/seeds/thermal-sequence"), dir.path());
        for (name, from, to) in edits {
            let file = dir.path().join(name);
            let text = std::fs::read_to_string(&file).unwrap();
            assert!(text.contains(from), "{name} has no `{from}`");
            std::fs::write(&file, text.replacen(from, to, 1)).unwrap();
        }
        dir
    }

    fn copy_dir(src: &Path, dst: &Path) {
        std::fs::create_dir_all(dst).unwrap();
        for entry in std::fs::read_dir(src).unwrap() {
            let path = entry.unwrap().path();
            let to = dst.join(path.file_name().unwrap());
            if path.is_dir() {
                copy_dir(&path, &to);
            } else {
                std::fs::copy(&path, &to).unwrap();
            }
        }
    }

    /// The error of opening the seed with `edits`.
    fn open_error(edits: &[(&str, &str, &str)]) -> String {
        ThermalSequence::open(seed(edits).path()).unwrap_err().to_string()
    }

    #[test]
    fn the_seed_sequence_and_its_truth_read() {
        let dir = seed(&[]);
        let seq = ThermalSequence::open(dir.path()).unwrap();
        assert_eq!((seq.frames.len(), seq.trajectory.t_s.len(), seq.path_mm.len()), (3, 21, 4));
        assert_eq!(seq.frames[1].file, Path::new("frames/L00_F0001.png"));
        let truth = ThermalTruth::open(dir.path()).unwrap();
        assert_eq!((truth.deposit(0).unwrap().nx, truth.frames.len()), (4, 2));
    }

    #[test]
    fn image_sizes_outside_the_bounds_are_refused_before_anything_is_allocated() {
        // 10⁹ × 10⁹ px used to reach the undistortion's correction map (SIGABRT); 0 px
        // panicked inside kornia.
        for (from, to, field) in
            [("width_px = 160", "width_px = 1000000000", "width_px"), ("height_px = 120", "height_px = 0", "height_px")]
        {
            let err = open_error(&[("camera.toml", from, to)]);
            assert!(err.contains(&format!("camera.toml:{field}: expected 2 to 2048, got")), "{err}");
        }
        let err = open_error(&[("process.toml", "layers_printed = 1", "layers_printed = 0")]);
        assert!(err.contains("process.toml:layers_printed: expected 1 to 10000, got 0"), "{err}");
        let truth = seed(&[("truth/truth.toml", "deposit_nx = 4", "deposit_nx = 4000000000")]);
        let err = ThermalTruth::open(truth.path()).unwrap_err().to_string();
        assert!(err.contains("truth.toml:deposit_nx: expected 1 to 8192"), "{err}");
        let truth = seed(&[("truth/truth.toml", "deposit_nx = 4", "deposit_nx = 5")]);
        let err = ThermalTruth::open(truth.path()).unwrap().deposit(0).unwrap_err().to_string();
        assert!(err.contains("deposit_L00.png: expected 5×3 px, the PNG header says 4×3"), "{err}");
    }

    #[test]
    fn periods_and_camera_numbers_must_be_physical() {
        let cases = [
            (
                "process.toml",
                "sample_period_s = 0.01",
                "sample_period_s = 0.0",
                "process.toml:sample_period_s: expected a finite number > 0, got 0",
            ),
            (
                "camera.toml",
                "frame_period_s = 0.125",
                "frame_period_s = -0.125",
                "camera.toml:frame_period_s: expected a finite number > 0",
            ),
            (
                "camera.toml",
                "fx_px = 147.34",
                "fx_px = nan",
                "camera.toml:intrinsics.fx_px: expected a finite number > 0, got NaN",
            ),
            ("camera.toml", "k1 = -0.12", "k1 = inf", "camera.toml:distortion.k1: expected a finite number, got inf"),
            (
                "process.toml",
                "nozzle_temp_c = 230.0",
                "nozzle_temp_c = 50.0",
                "process.toml:nozzle_temp_c: expected a number in [61",
            ),
            (
                "trajectory.csv",
                "0.010,0.2",
                "0.000,0.2",
                "trajectory.csv:line 3, field t_s: expected times increasing, got 0 after 0",
            ),
            (
                "trajectory.csv",
                "0.010,0.2",
                "0.005,0.2",
                "trajectory.csv:line 3, field t_s: expected the step of sample_period_s = 0.01 s",
            ),
            ("path.csv", "1,4,0", "1,4e6,0", "path.csv:line 3, field x_mm: expected a position within ±300 mm"),
            (
                "process.toml",
                "layer_height_mm = 0.25",
                "layer_height_mm = 1e-300",
                "process.toml:layer_height_mm: expected a number in [0.001, 100]",
            ),
        ];
        for (file, from, to, expected) in cases {
            let err = open_error(&[(file, from, to)]);
            assert!(err.contains(expected), "{to}: {err}");
        }
    }

    #[test]
    fn frames_must_be_unique_of_known_layers_and_covered_by_the_trajectory() {
        let err = open_error(&[("frames.csv", "0,2,0.250000", "0,1,0.250000")]);
        assert!(
            err.contains("frames.csv:line 4, field frame: expected each frame once, layer 0 frame 1 is also on line 3"),
            "{err}"
        );
        let err = open_error(&[("frames.csv", "0,2,0.250000", "3,2,0.250000")]);
        assert!(
            err.contains(
                "frames.csv:line 4, field layer: expected a layer below layers_printed = 1 (process.toml), got 3"
            ),
            "{err}"
        );
        // A truncated trajectory (0.2 s here) does not cover a frame recorded at 2.5 s:
        // it used to run with nearly every frame parked and exit 0.
        let err = open_error(&[("frames.csv", "0,2,0.250000", "0,2,2.500000")]);
        assert!(err.contains("frames.csv:line 4, field recorded_time_s: expected a time the trajectory covers: trajectory.csv runs from 0 s to 0.2 s"), "{err}");
    }

    #[test]
    fn frame_files_stay_inside_the_folder() {
        for path in ["/etc/passwd", "../frames/L00_F0000.png", "frames/../../x.png", ""] {
            let err = open_error(&[("frames.csv", "frames/L00_F0002.png", path)]);
            assert!(
                err.contains("frames.csv:line 4, field file: expected a path relative to the dataset folder"),
                "{path}: {err}"
            );
        }
        #[cfg(unix)]
        {
            // A frames/ folder that is a link to another place is refused, by name.
            let (dir, elsewhere) = (seed(&[]), tempfile::tempdir().unwrap());
            std::fs::rename(dir.path().join("frames"), elsewhere.path().join("frames")).unwrap();
            std::os::unix::fs::symlink(elsewhere.path().join("frames"), dir.path().join("frames")).unwrap();
            let err = ThermalSequence::open(dir.path()).unwrap_err().to_string();
            assert!(err.contains("frames.csv:line 2, field file: resolves through a symbolic link"), "{err}");
        }
    }

    #[test]
    fn toml_files_with_a_byte_order_mark_read() {
        let dir = seed(&[]);
        for name in ["dataset.toml", "camera.toml", "process.toml", "frames.csv"] {
            let file = dir.path().join(name);
            let text = std::fs::read_to_string(&file).unwrap();
            std::fs::write(&file, format!("\u{feff}{text}")).unwrap();
        }
        assert_eq!(ThermalSequence::open(dir.path()).unwrap().frames.len(), 3);
    }

    #[test]
    fn an_unknown_format_version_is_refused() {
        let err = open_error(&[("dataset.toml", "format_version = 1", "format_version = 2")]);
        assert!(
            err.contains(
                "dataset.toml:format_version: this build of amrepro reads `thermal-sequence` format_version 1, got 2"
            ),
            "{err}"
        );
    }
}
