//! What the paper-003 stages share: opening a `thermal-sequence` input, the commanded
//! trajectory rebuilt from its table (eq. 1, eq. 4), the deposition directions the
//! analysis assumes (eqs 13-26 with the nominal lagged flow), and the camera model
//! and the filmed frames converted from `camera.toml` and `frames.csv` to the vision
//! crate's types.

use std::path::Path;

use datasets::thermal::sequence::{CameraFile, ThermalSequence};
use models::thermal::dda::{allocate_directions, without_allocation, DdaParams, DepositionDirections};
use models::thermal::dynamics::first_order_lag;
use models::thermal::{PrintSetup, Trajectory};
use pipeline::StageError;
use polars::prelude::DataFrame;
use vision::camera::{CameraModel, Distortion, Intrinsics, Mount};
use vision::localiser::{FrameSource, Sequence, SequenceFrame};

/// Opens the `thermal-sequence` dataset in `dir`.
pub fn open_sequence(dir: &Path) -> Result<ThermalSequence, StageError> {
    ThermalSequence::open(dir).map_err(StageError::domain)
}

/// The commanded trajectory of one layer, from `trajectory.csv`.
pub fn trajectory_of(seq: &ThermalSequence) -> Result<Trajectory, StageError> {
    let table = &seq.trajectory;
    Trajectory::from_samples(&table.t_s, &table.x_mm, &table.y_mm).map_err(|e| bad_input(seq, "trajectory.csv", e))
}

/// The deposition the analysis expects: the commanded flow of `trajectory.csv`
/// through the nominal first-order dynamics (eq. 34), what actually leaves the nozzle.
pub fn expected_flow_mm3_s(seq: &ThermalSequence, setup: &PrintSetup) -> Vec<f64> {
    first_order_lag(&seq.trajectory.e_mm3_s, setup.sample_period_s, setup.tau_s, 0.0)
}

/// Deposition directions with and without the allocation of Sec. 2.2.
pub fn deposition_directions(
    seq: &ThermalSequence,
    trajectory: &Trajectory,
    setup: &PrintSetup,
) -> Result<(DepositionDirections, DepositionDirections), StageError> {
    let flow = expected_flow_mm3_s(seq, setup);
    let with = allocate_directions(trajectory, &flow, setup.layer_height_mm, &DdaParams::default())
        .map_err(|e| bad_input(seq, "trajectory.csv", e))?;
    let without = without_allocation(trajectory, &flow, setup.layer_height_mm)
        .map_err(|e| bad_input(seq, "trajectory.csv", e))?;
    Ok((with, without))
}

/// The left deposition direction (unit) at each sample: the normal of the deposition heading.
pub fn left_directions(directions: &DepositionDirections) -> Vec<[f64; 2]> {
    directions.deposition_heading_rad.iter().map(|th| [-th.sin(), th.cos()]).collect()
}

/// The nominal camera of `camera.toml` in the vision crate's types.
pub fn camera_model(camera: &CameraFile) -> CameraModel {
    let (i, d, m) = (&camera.intrinsics, &camera.distortion, &camera.mount);
    CameraModel {
        intrinsics: Intrinsics { fx_px: i.fx_px, fy_px: i.fy_px, cx_px: i.cx_px, cy_px: i.cy_px },
        distortion: Distortion { k1: d.k1, k2: d.k2, p1: d.p1, p2: d.p2 },
        mount: Mount { tilt_deg: m.tilt_deg, height_mm: m.height_mm, look_at_mm: m.look_at_mm },
        width_px: camera.width_px,
        height_px: camera.height_px,
    }
}

/// A `thermal-sequence` dataset's frames (`frames.csv`) and their PNG files, as the
/// frame localiser reads them (`vision::localiser`).
pub struct DatasetFrames<'a> {
    seq: &'a ThermalSequence,
    frames: Vec<SequenceFrame>,
}

impl<'a> DatasetFrames<'a> {
    /// The frames of `seq`, in file order.
    pub fn new(seq: &'a ThermalSequence) -> Self {
        let frames = seq
            .frames
            .iter()
            .map(|f| SequenceFrame {
                layer: f.layer,
                frame: f.frame,
                recorded_time_s: f.recorded_time_s,
                file: f.file.clone(),
            })
            .collect();
        Self { seq, frames }
    }
}

impl FrameSource for DatasetFrames<'_> {
    fn frames(&self) -> &[SequenceFrame] {
        &self.frames
    }

    fn png_bytes(&self, index: usize) -> std::io::Result<Vec<u8>> {
        std::fs::read(self.seq.frame_path(&self.seq.frames[index]))
    }
}

/// `seq` as the frame localiser reads it, with its commanded `trajectory`.
pub fn filmed_sequence<'a>(seq: &'a ThermalSequence, trajectory: &'a Trajectory) -> Sequence<'a, DatasetFrames<'a>> {
    Sequence { frames: DatasetFrames::new(seq), path_mm: &seq.path_mm, trajectory, nozzle_px: seq.camera.nozzle_px }
}

/// Row `row`'s trajectory sample index (column `sample` of `file`), checked below `samples`.
pub fn sample_index(file: &Path, row: usize, sample: i64, samples: usize) -> Result<usize, StageError> {
    usize::try_from(sample).ok().filter(|&k| k < samples).ok_or_else(|| StageError::BadInput {
        file: file.to_path_buf(),
        location: Some(format!("row {row}, column sample")),
        expected: format!("a trajectory sample index below {samples}, found {sample}"),
    })
}

/// Reads a Parquet table an upstream stage wrote into `dir`.
pub fn read_table(dir: &Path, file: &str) -> Result<DataFrame, StageError> {
    pipeline::artifact::read_parquet(&dir.join(file))
}

pub use crate::table::{bools, f64s, ints};

/// A domain error about one file of the sequence.
pub fn bad_input(seq: &ThermalSequence, file: &str, err: impl std::fmt::Display) -> StageError {
    StageError::BadInput { file: seq.dir.join(file), location: None, expected: err.to_string() }
}
