//! Frame localisation over a whole filmed sequence, paper 003 Sec. 2.3 (eqs 27-30): the
//! paper's per-frame homography and our rigid-mount estimator, run on every frame; the
//! caller gets both and chooses the one it uses ([`Estimator`]); `thermal.monitor` writes
//! both capture times to its `frames.parquet` and reads the widths of Sec. 2.4 in the
//! frames placed by the chosen one.
//!
//! - [`Estimator::Dlt`], the paper's method: every frame on its own. Undistort, detect the
//!   hot corners in the band, pair them with the printed CAD corners predicted through
//!   the nominal mount from the recorded time, place each pair on the ridge intersection
//!   ([`crate::vertex`]), fit H(i) by RANSAC + DLT on at least four pairs (eq. 27), the
//!   nozzle P_N,i = H(i)·P_N⁽⁰⁾ (eq. 29) and the capture time (eq. 30, ±10 ms).
//! - [`Estimator::RigidMount`], ours ([`crate::mount`]): H(i) = T(n_i)·H_m, the camera
//!   being rigid on a head that only translates. Pass 1 takes the ridge-placed pairs of
//!   the detections above from every frame and fits the mount H_m once to all of them
//!   (P_N⁽⁰⁾ fixes its origin, as eq. 29 does). Then, in rounds until the mount moves no
//!   pixel's plane point by more than 0.002 mm (at most four), every printed corner whose
//!   arms are long enough to be read ([`VertexParams::arm_reach_mm`] plus half a
//!   millimetre, so the hot end of the bead is not mistaken for an arm) is predicted
//!   through the latest mount, from the frame's nozzle under it (or the commanded
//!   position at t_r when none is placed), with its arms oriented by the nominal mount
//!   ([`crate::rigid`] says why), its ridge vertex is searched from the prediction, in the
//!   band or not ([`crate::vertex`]), and the mount is fitted again. When it has settled,
//!   the rounds run once more with the arms oriented by the settled mount instead of the
//!   nominal one (whose error would otherwise move every nozzle of the sequence the same
//!   way, [`crate::rigid`]). Each frame's nozzle is then the robust mean of its pairs'
//!   offsets under the last mount — one pair suffices — and eq. 30 with the paper's
//!   window gives the capture time.
//!   Why: the per-frame DLT needs four corners in the band, which about three frames in
//!   four do not have, and its eight free parameters extrapolate the corners' errors
//!   onto the nozzle; the rigid model has two unknowns per frame.
//!   A frame with no readable corner at all (the first few of every layer: the layer
//!   starts mid-side, and the previous layer's corners are too old) is placed, when
//!   [`LocaliserParams::place_cornerless`] is set, by dead reckoning: the commanded
//!   position at its recorded time, shifted by the median capture offset t̂_c − t_r of the
//!   frames placed from their corners (a constant capture delay shows there), through the
//!   fitted mount ([`Placement::RecordedTime`]). It is not localised
//!   ([`FrameOutcome::localised`] is false, [`Located::estimated_time_s`] NaN, so
//!   `thermal.accuracy_evaluate` leaves it out of the capture-time and homography
//!   statistics), but its widths are read: the recorded time is good to a few
//!   milliseconds, a few hundredths of a millimetre along a straight bead, across which a
//!   width does not change.
//! - Both skip a frame whose image is bit for bit the one before it: a FLIR Lepton
//!   delivers its last image again (now and then, and through its ~0.9 s shutter freeze)
//!   under a new timestamp, and that image shows the part as it was before, so its
//!   corners would place the nozzle wrongly and, with no corner, dead reckoning would.
//! - A frame recorded after the layer's last move (the camera films on through the layer
//!   change) is placed as above, from its corners or at the end point, but not timed:
//!   the nozzle stands still, so every instant of eq. 30's window fits it equally
//!   ([`Placement::Parked`]). Its widths are read: they are the only view of the
//!   layer's last stretch, where the head stops while the lagging flow goes on.
//!
//! How well it does (capture time against the recorded time and the paper's DLT, the
//! nozzle against the floor the camera's vibration leaves, the mount, the frames placed
//! each way) is measured by `thermal.accuracy_evaluate` against the virtual printer's
//! truth and reported beside the paper. Ridge lines fitted from the arm gap alone put
//! the vertices of the sharp corners inside them; the mount fit absorbed that bias, which
//! is why the arm lines run through the ridges' centres.
//!
//! The localiser takes plain data, a [`Sequence`]: the frames with their layer, number,
//! recorded time and a way to read each one's PNG ([`FrameSource`]; a dataset reader
//! implements it), the closed CAD path, the commanded trajectory and the nozzle pixel.
//! One file per step: `outcome.rs` what each frame and each mount fit gets,
//! `observe.rs` pass 1 (decode, observe, the paper's DLT, repeats and disorder),
//! `rounds.rs` the rigid mount's fit-and-re-pair rounds and the placement of the frames.

mod observe;
mod outcome;
mod rounds;

use std::path::PathBuf;

use models::progress::Progress;
use models::thermal::Trajectory;

use crate::camera::Undistorter;
use crate::corners::CornerError;
use crate::homography::Homography;
use crate::localize::{LocalizeError, TrajectoryView};
use crate::pipeline::{FrameContext, PathCorner, PipelineParams};
use crate::vertex::VertexParams;

pub use outcome::{DetectionRow, FrameOutcome, Located, MountRow, Placement};

/// Beyond `arm_reach_mm`, how far the nozzle must have moved on before a corner's ridges
/// are read (mm): the newest bead is hottest near the nozzle and would pull the ridge.
const READY_MARGIN_MM: f64 = 0.5;

/// Most re-pairing rounds per orientation of the arms (nominal, then settled).
const MAX_REPAIR_ROUNDS: usize = 4;

/// The mount has settled when a round moves no pixel's plane point farther than this (mm).
const MOUNT_SETTLED_MM: f64 = 0.002;

/// The estimator whose placement a caller uses ([`FrameOutcome::chosen`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Estimator {
    /// The paper's per-frame homography (eq. 27).
    Dlt,
    /// Our rigid-mount estimator.
    RigidMount,
}

/// One frame of a filmed sequence: a row of a `thermal-sequence` dataset's `frames.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceFrame {
    /// Layer index.
    pub layer: usize,
    /// Frame index within the layer.
    pub frame: usize,
    /// The camera's timestamp t_r (s from the layer start).
    pub recorded_time_s: f64,
    /// Its file, which a skip reason about the file names.
    pub file: PathBuf,
}

/// The frames of a sequence and their images.
pub trait FrameSource {
    /// The frames, in file order.
    fn frames(&self) -> &[SequenceFrame];

    /// The radiometric PNG (16-bit centi-kelvin, [`crate::frame`]) of frame `index` of
    /// [`Self::frames`], as stored.
    fn png_bytes(&self, index: usize) -> std::io::Result<Vec<u8>>;
}

impl<T: FrameSource + ?Sized> FrameSource for &T {
    fn frames(&self) -> &[SequenceFrame] {
        (**self).frames()
    }

    fn png_bytes(&self, index: usize) -> std::io::Result<Vec<u8>> {
        (**self).png_bytes(index)
    }
}

/// A filmed sequence as the localiser reads it.
#[derive(Debug, Clone)]
pub struct Sequence<'a, S> {
    /// Its frames and their images.
    pub frames: S,
    /// The closed CAD path (world mm); its vertices are the corners the frames show.
    pub path_mm: &'a [[f64; 2]],
    /// The commanded trajectory (eq. 1), uniformly sampled.
    pub trajectory: &'a Trajectory,
    /// The nozzle pixel P_N⁽⁰⁾ in the raw image (eq. 29).
    pub nozzle_px: [f64; 2],
}

/// The localiser's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocaliserParams {
    /// Settings of the frame pipeline (band, gates, RANSAC, window δt, mount fit).
    pub pipeline: PipelineParams,
    /// Rigid mount: corners printed longer ago than this (s, from the commanded
    /// trajectory) are not used; as a bead cools its heat spreads and the ridges of a
    /// corner's two arms pull each other inwards ([`crate::rigid`]).
    pub max_corner_age_s: f64,
    /// Rigid mount: place a frame with no readable corner by dead reckoning (module doc);
    /// false: skip it, as the paper's method must.
    pub place_cornerless: bool,
}

/// Why a sequence cannot be localised at all; a frame that cannot be is a skip reason in
/// its [`FrameOutcome`], never this.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LocaliserError {
    /// The commanded trajectory is not a uniformly sampled table.
    #[error(transparent)]
    Trajectory(#[from] LocalizeError),
    /// The corner detector's buffers could not be built for the camera's frame size.
    #[error(transparent)]
    Detector(#[from] CornerError),
}

/// Both estimators over one sequence, with its corners' passage and ready times
/// computed once.
pub struct Localiser<'a, S> {
    seq: Sequence<'a, S>,
    /// The camera's undistorter.
    pub undistorter: Undistorter,
    /// Nominal H0 of the undistorter's camera.
    h0: Homography,
    /// Settings of the frame pipeline.
    pub params: PipelineParams,
    path_corners: Vec<PathCorner>,
    /// When the trajectory passes each CAD vertex (s), by vertex index.
    passage_s: Vec<f64>,
    /// From when each CAD vertex's arms can be read (s), by vertex index (+∞ for a
    /// vertex that is no corner).
    ready_s: Vec<f64>,
    max_age_s: f64,
    place_cornerless: bool,
}

impl<'a, S: FrameSource> Localiser<'a, S> {
    /// The localiser of `seq` filmed through the camera of `undistorter` (its nominal
    /// mount gives H0): precomputes the corners' passage and ready times.
    pub fn new(seq: Sequence<'a, S>, undistorter: Undistorter, params: LocaliserParams) -> Self {
        let trajectory = seq.trajectory;
        let path_corners = PathCorner::of_closed_path(seq.path_mm);
        let passage_s = passage_times_s(seq.path_mm, trajectory);
        let vertex = params.pipeline.vertex.unwrap_or_else(VertexParams::defaults);
        let ready_s = ready_times_s(trajectory, seq.path_mm.len(), &path_corners, &passage_s, vertex);
        let h0 = undistorter.camera().nominal_homography();
        Self {
            seq,
            undistorter,
            h0,
            params: params.pipeline,
            path_corners,
            passage_s,
            ready_s,
            max_age_s: params.max_corner_age_s,
            place_cornerless: params.place_cornerless,
        }
    }

    /// Both estimators on every frame, in file order, and the mount fits (one row per
    /// pass); each frame's `chosen` set by `estimator`. `seed` seeds the RANSAC of each
    /// frame (with its layer and number); `progress` is told of each frame observed.
    pub fn run(
        &self,
        seed: u64,
        estimator: Estimator,
        progress: &dyn Progress,
    ) -> Result<(Vec<FrameOutcome>, Vec<MountRow>), LocaliserError> {
        let trajectory = self.seq.trajectory;
        let view = TrajectoryView::new(&trajectory.t_s, &trajectory.x_mm, &trajectory.y_mm)?;
        let ctx = FrameContext {
            undistorter: &self.undistorter,
            h0: self.h0,
            nozzle_px: self.seq.nozzle_px,
            trajectory: view,
            params: self.params,
        };
        let mut frames = self.observe_all(&ctx, seed, progress)?;
        let mounts = self.localise_rigid_all(&ctx, &mut frames);
        for f in &mut frames {
            f.chosen = match estimator {
                Estimator::Dlt => f.dlt.clone(),
                Estimator::RigidMount => f.rigid.clone(),
            };
        }
        Ok((frames, mounts))
    }
}

impl<S> Localiser<'_, S> {
    /// `located` as it stands, or parked at `t_r` if the frame was recorded after the
    /// layer's last move ([`Placement::Parked`]).
    fn unless_parked(&self, located: Located, t_r: f64) -> Located {
        if t_r >= self.seq.trajectory.duration_s() {
            located.parked(t_r)
        } else {
            located
        }
    }

    /// Both arms of corner `id` are readable at `t_r` and it is at most `max_age_s` old.
    fn is_young_and_ready(&self, id: u32, t_r: f64) -> bool {
        let i = id as usize;
        self.ready_s[i] <= t_r && t_r - self.passage_s[i] <= self.max_age_s
    }
}

/// Time at which the trajectory passes closest to each CAD vertex (s).
fn passage_times_s(path_mm: &[[f64; 2]], trajectory: &Trajectory) -> Vec<f64> {
    path_mm.iter().map(|v| trajectory.t_s[trajectory.nearest_sample(*v)]).collect()
}

/// From when each corner's arms can be read (s), by vertex index like `passage_s`: a
/// vertex [`PathCorner::of_closed_path`] skips (a repeated point has no arm) is never
/// ready, and the corners after it keep their own times.
fn ready_times_s(
    trajectory: &Trajectory,
    vertices: usize,
    path_corners: &[PathCorner],
    passage_s: &[f64],
    vertex: VertexParams,
) -> Vec<f64> {
    let mut ready_s = vec![f64::INFINITY; vertices];
    for c in path_corners {
        let cos = c.arm_dirs[0][0] * c.arm_dirs[1][0] + c.arm_dirs[0][1] * c.arm_dirs[1][1];
        let id = c.id as usize;
        ready_s[id] = ready_time_s(trajectory, c.vertex_mm, passage_s[id], vertex.arm_reach_mm(cos) + READY_MARGIN_MM);
    }
    ready_s
}

/// First time after `passage_s` at which the trajectory is `reach_mm` from `vertex_mm`
/// (+∞ if never): from then on both arms of the corner are printed that far.
fn ready_time_s(trajectory: &Trajectory, vertex_mm: [f64; 2], passage_s: f64, reach_mm: f64) -> f64 {
    (0..trajectory.len())
        .filter(|&k| trajectory.t_s[k] >= passage_s)
        .find(|&k| (trajectory.x_mm[k] - vertex_mm[0]).hypot(trajectory.y_mm[k] - vertex_mm[1]) >= reach_mm)
        .map_or(f64::INFINITY, |k| trajectory.t_s[k])
}

#[cfg(test)]
mod tests;
