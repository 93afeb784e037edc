//! Frame localisation for `thermal.monitor` (paper 003 Sec. 2.3, eqs 27-30): the paper's
//! per-frame homography and our rigid-mount estimator, run on every frame of a sequence;
//! the `localisation` parameter chooses which one the widths and the tables use, and
//! `frames.parquet` carries both capture times.
//!
//! - `dlt`, the paper's method: every frame on its own. Undistort, detect the hot
//!   corners in the band, pair them with the printed CAD corners predicted through the
//!   nominal mount from the recorded time, place each pair on the ridge intersection
//!   (`vision::vertex`), fit H(i) by RANSAC + DLT on at least four pairs (eq. 27), the
//!   nozzle P_N,i = H(i)·P_N⁽⁰⁾ (eq. 29) and the capture time (eq. 30, ±10 ms).
//! - `rigid_mount`, ours (`vision::mount`): H(i) = T(n_i)·H_m, the camera being rigid on
//!   a head that only translates. Pass 1 takes the ridge-placed pairs of the detections
//!   above from every frame and fits the mount H_m once to all of them (P_N⁽⁰⁾ fixes its
//!   origin, as eq. 29 does). Then, in rounds until the mount moves no pixel's plane
//!   point by more than 0.002 mm (at most four), every printed corner whose arms are long
//!   enough to be read (`VertexParams::arm_reach_mm` plus half a millimetre, so the hot
//!   end of the bead is not mistaken for an arm) is predicted through the latest mount,
//!   from the frame's nozzle under it (or the commanded position at t_r when none is
//!   placed), with its arms oriented by the nominal mount (`vision::rigid` says why),
//!   its ridge vertex is searched from the prediction, in the band or not
//!   (`vision::vertex`), and the mount is fitted again. Each frame's nozzle is then the
//!   robust mean of its pairs' offsets under the last mount — one pair suffices — and
//!   eq. 30 with the paper's window gives the capture time.
//!   Why: the per-frame DLT needs four corners in the band, which about three frames in
//!   four do not have, and its eight free parameters extrapolate the corners' errors
//!   onto the nozzle; the rigid model has two unknowns per frame.
//!   A frame with no readable corner at all (the first few of every layer: the layer
//!   starts mid-side, and the previous layer's corners are too old) is placed, when
//!   `place_cornerless` is set, by dead reckoning: the commanded position at its recorded
//!   time, shifted by the median capture offset t̂_c − t_r of the frames placed from their
//!   corners (a constant capture delay shows there), through the fitted mount
//!   ([`Placement::RecordedTime`]). It is not localised (`used` is false, its
//!   `estimated_time_s` NaN, so `thermal.accuracy_evaluate` leaves it out of the
//!   capture-time and homography statistics), but its widths are read: the recorded time
//!   is good to a few milliseconds, a few hundredths of a millimetre along a straight
//!   bead, across which a width does not change.
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

use datasets::thermal::sequence::{FrameEntry, ThermalSequence};
use models::progress::Progress;
use models::stats::finite_median;
use models::thermal::Trajectory;
use pipeline::StageError;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use vision::camera::Undistorter;
use vision::frame::{FrameError, ThermalFrame};
use vision::homography::Homography;
use vision::localize::TrajectoryView;
use vision::matching::PredictedCorner;
use vision::mount::{fit_mount, frame_homography, locate_nozzle, FramePairs, MountError, MountFit};
use vision::pipeline::{
    check_plausible, localise_dlt, observe_frame, predict_path_corners_into, CornerPairs, FrameContext, FrameInput,
    FrameSkip, FrameWorkspace, PathCorner, PipelineParams,
};
use vision::rigid::{initial_mount, localise_rigid, predict_corners_with_arms_into, ridge_pairs_into};

use super::common::vertex_passage_times;

/// Beyond `arm_reach_mm`, how far the nozzle must have moved on before a corner's ridges
/// are read (mm): the newest bead is hottest near the nozzle and would pull the ridge.
const READY_MARGIN_MM: f64 = 0.5;

/// Most re-pairing rounds after the first mount fit.
const MAX_REPAIR_ROUNDS: usize = 4;

/// The mount has settled when a round moves no pixel's plane point farther than this (mm).
const MOUNT_SETTLED_MM: f64 = 0.002;

/// The estimator whose result the monitor uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Localisation {
    /// The paper's per-frame homography (eq. 27).
    Dlt,
    /// Our rigid-mount estimator.
    RigidMount,
}

impl Localisation {
    /// The parameter values, in this order.
    pub const NAMES: &'static [&'static str] = &["dlt", "rigid_mount"];

    /// From a checked parameter value.
    pub fn from_name(name: &str) -> Self {
        if name == "dlt" {
            Self::Dlt
        } else {
            Self::RigidMount
        }
    }

    /// The parameter value.
    pub fn name(self) -> &'static str {
        match self {
            Self::Dlt => "dlt",
            Self::RigidMount => "rigid_mount",
        }
    }
}

/// The skip reason of a frame placed by its recorded time.
const PLACED_BY_RECORDED_TIME: &str = "rigid mount: no corner pairs; placed by its recorded time, for its widths only";
/// The skip reason of a frame filmed after the layer's last move.
const PARKED: &str =
    "filmed after the layer's last move: placed, but eq. 30 cannot time a nozzle at rest; for its widths only";

/// How a frame was placed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placement {
    /// From its corners (eqs 27-30).
    Corners,
    /// No corner: the commanded position at the recorded time, through the fitted mount.
    RecordedTime,
    /// Filmed after the layer's last move (the camera keeps filming through the layer
    /// change), placed from its corners or, with none, at the end point where the nozzle
    /// stands: eq. 30 cannot time it, every instant of its window putting the nozzle at
    /// the same place, so its time is the recorded time.
    Parked,
}

impl Placement {
    /// The `placed_by` value of `frames.parquet`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Corners => "corners",
            Self::RecordedTime => "recorded_time",
            Self::Parked => "parked",
        }
    }
}

/// One estimator's placement of a frame.
#[derive(Debug, Clone, Copy)]
pub struct Located {
    /// Capture time t̂_c (eq. 30, s); for [`Placement::RecordedTime`] the recorded time
    /// plus the sequence's median capture offset.
    pub t_s: f64,
    /// How the frame was placed.
    pub placed_by: Placement,
    /// t̂_c lies on the edge of the search window.
    pub at_window_edge: bool,
    /// Nozzle position P_N,i (eq. 29, world mm).
    pub nozzle_mm: [f64; 2],
    /// H(i): undistorted pixel → world plane mm.
    pub px_to_plane: Homography,
    /// Its inverse.
    pub plane_to_px: Homography,
    /// RMS error of the fit over the pairs it used (mm).
    pub fit_err_mm: f64,
    /// Pairs it used.
    pub pairs: usize,
}

impl Located {
    fn new(
        t: vision::localize::CaptureTimeEstimate,
        nozzle_mm: [f64; 2],
        h: Homography,
        err: f64,
        pairs: usize,
    ) -> Result<Self, String> {
        let plane_to_px = h.inverse().ok_or_else(|| "singular homography".to_string())?;
        Ok(Self {
            t_s: t.t_s,
            placed_by: Placement::Corners,
            at_window_edge: t.at_window_edge,
            nozzle_mm,
            px_to_plane: h,
            plane_to_px,
            fit_err_mm: err,
            pairs,
        })
    }

    /// A frame without corners, placed by dead reckoning at `t_s` (module doc).
    fn by_recorded_time(t_s: f64, nozzle_mm: [f64; 2], h: Homography) -> Result<Self, String> {
        let time = vision::localize::CaptureTimeEstimate { t_s, distance_mm: 0.0, at_window_edge: false };
        Ok(Self { placed_by: Placement::RecordedTime, ..Self::new(time, nozzle_mm, h, f64::NAN, 0)? })
    }

    /// Eq. 30's capture-time estimate; NaN for a frame placed by its recorded time or parked.
    pub fn estimated_time_s(&self) -> f64 {
        match self.placed_by {
            Placement::Corners => self.t_s,
            Placement::RecordedTime | Placement::Parked => f64::NAN,
        }
    }

    /// The same placement of a frame filmed after the layer's last move, at its recorded time.
    fn parked(self, recorded_time_s: f64) -> Self {
        Self { t_s: recorded_time_s, placed_by: Placement::Parked, at_window_edge: false, ..self }
    }
}

/// A detection: (matched vertex or −1, undistorted pixel, temperature °C).
pub type DetectionRow = (i64, [f64; 2], f64);

/// One frame's outcome under both estimators.
pub struct FrameOutcome {
    /// Its row of `frames.csv`.
    pub entry: FrameEntry,
    /// Corners detected in the band.
    pub corners_found: usize,
    /// Detections paired with printed CAD corners.
    pub matched: usize,
    /// Every detection with the vertex it was paired with.
    pub detections: Vec<DetectionRow>,
    /// The undistorted frame (None when it could not be read).
    pub undistorted: Option<ThermalFrame>,
    /// The rigid estimator's pairs (after the last round) and which of them placed the nozzle.
    pub pairs: CornerPairs,
    /// Per pair of `pairs`: used for the nozzle.
    pub pair_used: Vec<bool>,
    /// The paper's estimator, or why it skipped the frame.
    pub dlt: Result<Located, String>,
    /// Ours, or why it skipped the frame.
    pub rigid: Result<Located, String>,
    /// The one `localisation` chose.
    pub chosen: Result<Located, String>,
    /// The frame number whose image this one repeats (skipped, see `observe_all`).
    pub repeat_of: Option<usize>,
}

impl FrameOutcome {
    fn skipped(entry: &FrameEntry, reason: String) -> Self {
        Self {
            entry: entry.clone(),
            corners_found: 0,
            matched: 0,
            detections: Vec::new(),
            undistorted: None,
            pairs: CornerPairs::default(),
            pair_used: Vec::new(),
            dlt: Err(reason.clone()),
            rigid: Err(reason.clone()),
            chosen: Err(reason),
            repeat_of: None,
        }
    }

    /// The chosen placement, if the frame was localised.
    pub fn located(&self) -> Option<&Located> {
        self.chosen.as_ref().ok()
    }

    /// Placed from its corners (eqs 27-30), with a capture-time estimate: `used` in
    /// `frames.parquet`.
    pub fn localised(&self) -> bool {
        self.located().is_some_and(|l| l.placed_by == Placement::Corners)
    }

    /// [`Self::skip_reason`] without the frame's own file name, so that frames skipped
    /// for one reason group together.
    pub fn shared_skip_reason(&self) -> Option<&str> {
        let reason = self.skip_reason()?;
        let own = format!("{}: ", self.entry.file.display());
        Some(reason.strip_prefix(own.as_str()).unwrap_or(reason))
    }

    /// Why the frame is not localised: the chosen estimator's skip reason, or that it was
    /// placed by its recorded time for its widths only.
    pub fn skip_reason(&self) -> Option<&str> {
        match &self.chosen {
            Err(reason) => Some(reason),
            Ok(l) if l.placed_by == Placement::RecordedTime => Some(PLACED_BY_RECORDED_TIME),
            Ok(l) if l.placed_by == Placement::Parked => Some(PARKED),
            Ok(_) => None,
        }
    }
}

/// One mount for `mount.parquet`: the start (pass 0, the nominal mount anchored at
/// P_N⁽⁰⁾), the fit to the detections' pairs (pass 1) and the fit of each re-pairing
/// round (passes 2, 3, …).
pub struct MountRow {
    /// 0 the start, 1 the first fit, 2 and up the rounds.
    pub pass: i64,
    /// The fit or why it failed.
    pub fit: Result<MountFit, String>,
    /// This mount placed the frames (the last one that could be fitted).
    pub applied: bool,
}

/// What localisation needs, built once per sequence.
pub struct Localiser<'a> {
    seq: &'a ThermalSequence,
    trajectory: &'a Trajectory,
    /// The camera's undistorter.
    pub undistorter: Undistorter,
    h0: Homography,
    /// Settings of the frame pipeline.
    pub params: PipelineParams,
    path_corners: Vec<PathCorner>,
    passage_s: Vec<f64>,
    ready_s: Vec<f64>,
    max_age_s: f64,
    place_cornerless: bool,
}

impl<'a> Localiser<'a> {
    /// Precomputes the corners' passage and ready times.
    pub fn new(
        seq: &'a ThermalSequence,
        trajectory: &'a Trajectory,
        undistorter: Undistorter,
        h0: Homography,
        params: PipelineParams,
        max_age_s: f64,
        place_cornerless: bool,
    ) -> Self {
        let path_corners = PathCorner::of_closed_path(&seq.path_mm);
        let passage_s = vertex_passage_times(seq, trajectory);
        let vertex = params.vertex.unwrap_or_else(vision::vertex::VertexParams::defaults);
        let ready_s = path_corners
            .iter()
            .map(|c| {
                let cos = c.arm_dirs[0][0] * c.arm_dirs[1][0] + c.arm_dirs[0][1] * c.arm_dirs[1][1];
                ready_time_s(
                    trajectory,
                    c.vertex_mm,
                    passage_s[c.id as usize],
                    vertex.arm_reach_mm(cos) + READY_MARGIN_MM,
                )
            })
            .collect();
        Self { seq, trajectory, undistorter, h0, params, path_corners, passage_s, ready_s, max_age_s, place_cornerless }
    }

    /// Both estimators on every frame, in file order, and the mount fits; `chosen` set by
    /// `method`. `progress` is told of each frame observed.
    pub fn run(
        &self,
        seed: u64,
        method: Localisation,
        progress: &dyn Progress,
    ) -> Result<(Vec<FrameOutcome>, Vec<MountRow>), StageError> {
        let view = TrajectoryView::new(&self.trajectory.t_s, &self.trajectory.x_mm, &self.trajectory.y_mm)
            .map_err(StageError::domain)?;
        let ctx = FrameContext {
            undistorter: &self.undistorter,
            h0: self.h0,
            nozzle_px: self.seq.camera.nozzle_px,
            trajectory: view,
            params: self.params,
        };
        let mut frames = self.observe_all(&ctx, seed, progress)?;
        let mounts = self.localise_rigid_all(&ctx, &mut frames);
        for f in &mut frames {
            f.chosen = match method {
                Localisation::Dlt => f.dlt.clone(),
                Localisation::RigidMount => f.rigid.clone(),
            };
        }
        Ok((frames, mounts))
    }

    /// Pass 1 over all frames: decode, observe, the paper's DLT, the ridge pairs; a frame
    /// whose image is the one before it again is skipped (module doc).
    fn observe_all(
        &self,
        ctx: &FrameContext<'_>,
        seed: u64,
        progress: &dyn Progress,
    ) -> Result<Vec<FrameOutcome>, StageError> {
        let mut workspace = FrameWorkspace::new(&self.undistorter, &self.params).map_err(StageError::domain)?;
        let mut last_time: Option<(usize, f64)> = None;
        let mut outcomes: Vec<FrameOutcome> = Vec::with_capacity(self.seq.frames.len());
        progress.add(self.seq.frames.len() as u64);
        for entry in &self.seq.frames {
            let outcome = match last_time {
                Some((layer, t)) if layer == entry.layer && entry.recorded_time_s <= t => FrameOutcome::skipped(
                    entry,
                    format!(
                        "recorded time {:.4} s is not after the previous frame's {:.4} s (out of order)",
                        entry.recorded_time_s, t
                    ),
                ),
                _ => {
                    last_time = Some((entry.layer, entry.recorded_time_s));
                    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((entry.layer as u64) << 32 | entry.frame as u64));
                    let outcome = self.observe(ctx, entry, &mut workspace, &mut rng);
                    match repeated_image(&outcomes, &outcome) {
                        Some(previous) => FrameOutcome {
                            repeat_of: Some(previous),
                            ..FrameOutcome::skipped(
                                entry,
                                format!("same image as frame {previous}: a repeated or frozen camera frame, not its own time and place"),
                            )
                        },
                        None => outcome,
                    }
                }
            };
            outcomes.push(outcome);
            progress.done(1);
        }
        Ok(outcomes)
    }

    /// One frame of pass 1 (a failure is a diagnostic, not an error).
    fn observe(
        &self,
        ctx: &FrameContext<'_>,
        entry: &FrameEntry,
        ws: &mut FrameWorkspace,
        rng: &mut ChaCha8Rng,
    ) -> FrameOutcome {
        let frame = match self.decode(entry) {
            Ok(frame) => frame,
            Err(e) => return FrameOutcome::skipped(entry, format!("{}: {e}", entry.file.display())),
        };
        let t_r = entry.recorded_time_s;
        let printed: Vec<PathCorner> =
            self.path_corners.iter().copied().filter(|c| self.passage_s[c.id as usize] <= t_r).collect();
        let mut predicted: Vec<PredictedCorner> = Vec::new();
        predict_path_corners_into(&self.h0, ctx.trajectory.position_mm(t_r), &printed, &mut predicted);
        let input = FrameInput { frame: &frame, t_recorded_s: t_r, predicted: &predicted, width_queries: &[] };
        if let Err(skip) = observe_frame(ctx, &input, ws) {
            return FrameOutcome::skipped(entry, skip.to_string());
        }
        let detections = detection_rows(ws, &predicted);
        let (corners_found, matched) = (ws.detections().len(), detections.iter().filter(|d| d.0 >= 0).count());
        let dlt = localise_dlt(ctx, &input, ws, rng).map_err(|s| s.to_string()).and_then(|r| {
            let h = r.homography.homography;
            Located::new(r.capture, r.nozzle_mm, h, r.homography.rms_error_mm, r.homography.inlier_count())
        });
        let dlt = dlt.map(|l| self.unless_parked(l, t_r));
        FrameOutcome {
            entry: entry.clone(),
            corners_found,
            matched,
            detections,
            undistorted: Some(ws.undistorted().clone()),
            pairs: ws.ridge_pairs(&predicted),
            pair_used: Vec::new(),
            dlt,
            rigid: Err("not localised".into()),
            chosen: Err("not localised".into()),
            repeat_of: None,
        }
    }

    /// A frame's PNG decoded at the camera's size (`camera.toml`), checked against the
    /// PNG header before anything is allocated.
    fn decode(&self, entry: &FrameEntry) -> Result<ThermalFrame, FrameError> {
        let bytes = std::fs::read(self.seq.frame_path(entry)).map_err(|e| FrameError::Unreadable(e.to_string()))?;
        let camera = &self.seq.camera;
        ThermalFrame::from_png_bytes_sized(&bytes, camera.width_px, camera.height_px)
    }

    /// The rigid-mount estimator over the sequence: fit on pass-1 pairs, then re-pair
    /// every ready corner from the mount's predictions and fit again until the mount
    /// settles, and place each frame's nozzle.
    fn localise_rigid_all(&self, ctx: &FrameContext<'_>, frames: &mut [FrameOutcome]) -> Vec<MountRow> {
        let nozzle_px = self.undistorter.undistort_px(ctx.nozzle_px);
        let start = match initial_mount(ctx) {
            Ok(h) => h,
            Err(e) => {
                let reason = format!("rigid mount: {e}");
                frames.iter_mut().for_each(|f| f.rigid = Err(reason.clone()));
                return vec![MountRow { pass: 0, fit: Err(e.to_string()), applied: false }];
            }
        };
        self.keep_young(frames);
        let nominal = MountFit { mount: start, inliers: Vec::new(), rms_mm: f64::NAN, pairs_used: 0, frames_used: 0 };
        let first = self.fit(frames, nozzle_px, &start);
        let mut mount = first.as_ref().map_or(start, |f| f.mount);
        let mut fits = vec![Ok(nominal), first];
        // Re-pair from the latest mount and fit again until the mount settles: the ridge
        // searches start from its predictions (their arms keep the nominal directions).
        for _ in 0..MAX_REPAIR_ROUNDS {
            self.repair_all(ctx, frames, &mount, &start);
            let next = self.fit(frames, nozzle_px, &mount);
            let moved_mm = next.as_ref().map_or(0.0, |f| largest_gap_mm(&f.mount, &mount, self.undistorter.camera()));
            if let Ok(f) = &next {
                mount = f.mount;
            }
            fits.push(next);
            if moved_mm <= MOUNT_SETTLED_MM {
                break;
            }
        }
        // The last mount that could be fitted places each frame (the nominal mount
        // anchored at P_N⁽⁰⁾ when none could); mount.parquet says which.
        let cornerless: Vec<usize> = (0..frames.len()).filter(|&i| self.place(ctx, &mut frames[i], &mount)).collect();
        if self.place_cornerless {
            self.place_by_recorded_time(ctx, frames, &cornerless, &mount);
        }
        let applied = fits.iter().rposition(|f| f.is_ok()).unwrap_or(0);
        fits.into_iter()
            .enumerate()
            .map(|(pass, fit)| MountRow { pass: pass as i64, fit, applied: pass == applied })
            .collect()
    }

    /// The mount fitted to the current pairs of every frame.
    fn fit(&self, frames: &[FrameOutcome], nozzle_px: [f64; 2], start: &Homography) -> Result<MountFit, String> {
        let pairs: Vec<FramePairs<'_>> =
            frames.iter().map(|f| FramePairs { image_px: &f.pairs.image_px, plane_mm: &f.pairs.plane_mm }).collect();
        fit_mount(&pairs, nozzle_px, start, &self.params.mount).map_err(|e| e.to_string())
    }

    /// One re-pairing round: every frame's pairs searched from the predictions of
    /// `mount`, the arms oriented as the nominal mount `nominal` sees them.
    fn repair_all(
        &self,
        ctx: &FrameContext<'_>,
        frames: &mut [FrameOutcome],
        mount: &Homography,
        nominal: &Homography,
    ) {
        let vertex = self.params.vertex.unwrap_or_else(vision::vertex::VertexParams::defaults);
        let (mut predicted, mut found) = (Vec::new(), CornerPairs::default());
        for f in frames.iter_mut() {
            let Some(image) = &f.undistorted else { continue };
            let t_r = f.entry.recorded_time_s;
            let nozzle = locate_nozzle(mount, &f.pairs.image_px, &f.pairs.plane_mm, self.params.mount.inlier_gate_mm)
                .ok()
                .map(|fix| fix.nozzle_mm)
                .filter(|n| check_plausible(ctx, *n, t_r).is_ok())
                .unwrap_or_else(|| ctx.trajectory.position_mm(t_r));
            let ready: Vec<PathCorner> =
                self.path_corners.iter().copied().filter(|c| self.is_young_and_ready(c.id, t_r)).collect();
            predict_corners_with_arms_into(mount, nominal, nozzle, &ready, &mut predicted);
            ridge_pairs_into(image, &predicted, &vertex, self.params.predicted_shift_px, &mut found);
            f.pairs = merged(&found, &f.pairs);
        }
    }

    /// `located` as it stands, or parked at `t_r` if the frame was recorded after the
    /// layer's last move ([`Placement::Parked`]).
    fn unless_parked(&self, located: Located, t_r: f64) -> Located {
        if t_r >= self.trajectory.duration_s() {
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

    /// Drops the pass-1 pairs of corners that are too old or not yet readable.
    fn keep_young(&self, frames: &mut [FrameOutcome]) {
        for f in frames.iter_mut() {
            let t_r = f.entry.recorded_time_s;
            let mut kept = CornerPairs::default();
            for k in (0..f.pairs.len()).filter(|&k| self.is_young_and_ready(f.pairs.ids[k], t_r)) {
                kept.push(f.pairs.ids[k], f.pairs.image_px[k], f.pairs.plane_mm[k]);
            }
            f.pairs = kept;
        }
    }

    /// The rigid estimator's placement of one frame from its corners; true when it has
    /// none (it is then skipped, unless [`Self::place_by_recorded_time`] places it).
    fn place(&self, ctx: &FrameContext<'_>, f: &mut FrameOutcome, mount: &Homography) -> bool {
        if f.undistorted.is_none() {
            f.rigid = f.dlt.clone();
            return false;
        }
        let t_r = f.entry.recorded_time_s;
        match localise_rigid(ctx, mount, &f.pairs, t_r) {
            Ok(r) => {
                f.pair_used = r.fix.inliers.clone();
                let located =
                    Located::new(r.capture, r.fix.nozzle_mm, r.homography, r.fix.rms_mm, r.fix.inlier_count());
                f.rigid = located.map(|l| self.unless_parked(l, t_r));
                false
            }
            Err(skip) => {
                f.rigid = Err(skip.to_string());
                skip == FrameSkip::Mount(MountError::NoPairs)
            }
        }
    }

    /// Places the frames `cornerless` (no corner pair) by dead reckoning (module doc): the
    /// commanded position at the recorded time plus the median capture offset t̂_c − t_r
    /// of the frames placed from their corners, through the fitted mount, so that a
    /// constant capture delay the corners reveal is not left in.
    fn place_by_recorded_time(
        &self,
        ctx: &FrameContext<'_>,
        frames: &mut [FrameOutcome],
        cornerless: &[usize],
        mount: &Homography,
    ) {
        let offset_s = finite_median(
            frames.iter().filter_map(|f| f.rigid.as_ref().ok().map(|l| l.estimated_time_s() - f.entry.recorded_time_s)),
        );
        let offset_s = if offset_s.is_finite() { offset_s } else { 0.0 };
        for &i in cornerless {
            let t_r = frames[i].entry.recorded_time_s;
            let t_s = t_r + offset_s;
            let nozzle_mm = ctx.trajectory.position_mm(t_s);
            let located = Located::by_recorded_time(t_s, nozzle_mm, frame_homography(mount, nozzle_mm));
            frames[i].rigid = located.map(|l| self.unless_parked(l, t_r));
        }
    }
}

/// The frame number of the last decoded frame before `current`, if it is of the same
/// layer and its image is bit for bit `current`'s.
fn repeated_image(earlier: &[FrameOutcome], current: &FrameOutcome) -> Option<usize> {
    let image = current.undistorted.as_ref()?;
    let previous = earlier.iter().rev().find(|f| f.undistorted.is_some())?;
    let same = previous.entry.layer == current.entry.layer
        && previous.undistorted.as_ref().is_some_and(|p| {
            p.width == image.width
                && p.temp_c.len() == image.temp_c.len()
                && p.temp_c.iter().zip(&image.temp_c).all(|(a, b)| a.to_bits() == b.to_bits())
        });
    same.then_some(previous.entry.frame)
}

/// Largest distance between the plane points two pixel → plane maps give the pixels of
/// a 10-pixel grid over the image (mm).
fn largest_gap_mm(a: &Homography, b: &Homography, camera: &vision::camera::CameraModel) -> f64 {
    let mut worst: f64 = 0.0;
    for v in (0..camera.height_px).step_by(10) {
        for u in (0..camera.width_px).step_by(10) {
            let (p, q) = (a.apply([u as f64, v as f64]), b.apply([u as f64, v as f64]));
            worst = worst.max((p[0] - q[0]).hypot(p[1] - q[1]));
        }
    }
    worst
}

/// `primary` plus the pairs of `extra` whose corner it lacks.
fn merged(primary: &CornerPairs, extra: &CornerPairs) -> CornerPairs {
    let mut out = primary.clone();
    for k in (0..extra.len()).filter(|&k| !primary.ids.contains(&extra.ids[k])) {
        out.push(extra.ids[k], extra.image_px[k], extra.plane_mm[k]);
    }
    out
}

/// First time after `passage_s` at which the trajectory is `reach_mm` from `vertex_mm`
/// (+∞ if never): from then on both arms of the corner are printed that far.
fn ready_time_s(trajectory: &Trajectory, vertex_mm: [f64; 2], passage_s: f64, reach_mm: f64) -> f64 {
    (0..trajectory.len())
        .filter(|&k| trajectory.t_s[k] >= passage_s)
        .find(|&k| (trajectory.x_mm[k] - vertex_mm[0]).hypot(trajectory.y_mm[k] - vertex_mm[1]) >= reach_mm)
        .map_or(f64::INFINITY, |k| trajectory.t_s[k])
}

/// The detections of the last observed frame with the vertex each was paired with.
fn detection_rows(ws: &FrameWorkspace, predicted: &[PredictedCorner]) -> Vec<DetectionRow> {
    ws.detections()
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let vertex =
                ws.matches().iter().find(|m| m.detection == i).map_or(-1, |m| i64::from(predicted[m.predicted].id));
            (vertex, [d.u_px, d.v_px], f64::from(d.temp_c))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A decoded frame of `layer`, `frame` whose every pixel reads `temp_c`.
    fn decoded(layer: usize, frame: usize, temp_c: f32) -> FrameOutcome {
        let entry = FrameEntry { layer, frame, recorded_time_s: 0.125 * frame as f64, file: "f.png".into() };
        let image = ThermalFrame { width: 4, height: 3, temp_c: vec![temp_c; 12] };
        FrameOutcome { undistorted: Some(image), ..FrameOutcome::skipped(&entry, String::new()) }
    }

    #[test]
    fn a_frame_repeats_the_last_decoded_one_of_its_layer_only_bit_for_bit() {
        let unreadable = FrameOutcome::skipped(&decoded(0, 1, 0.0).entry, "wrong size".into());
        let earlier = vec![decoded(0, 0, 80.0), unreadable];
        assert_eq!(repeated_image(&earlier, &decoded(0, 2, 80.0)), Some(0), "the unreadable frame is passed over");
        assert_eq!(repeated_image(&earlier, &decoded(0, 2, 80.001)), None);
        assert_eq!(repeated_image(&earlier, &decoded(1, 0, 80.0)), None, "a new layer starts afresh");
        assert_eq!(repeated_image(&[], &decoded(0, 0, 80.0)), None);
    }

    #[test]
    fn a_corner_is_ready_once_the_nozzle_is_its_reach_away() {
        // Along +x at 20 mm/s through a vertex at x = 2 mm (t = 0.1 s): 1.5 mm further on
        // is reached at t = 0.175 s.
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 0.001).collect();
        let x: Vec<f64> = t.iter().map(|t| 20.0 * t).collect();
        let y = vec![0.0; t.len()];
        let traj = Trajectory::from_samples(&t, &x, &y).unwrap();
        let ready = ready_time_s(&traj, [2.0, 0.0], 0.1, 1.5);
        assert!((ready - 0.175).abs() < 1e-9, "{ready}");
        assert_eq!(ready_time_s(&traj, [2.0, 0.0], 0.1, 100.0), f64::INFINITY);
    }

    #[test]
    fn the_largest_gap_of_a_shifted_map_is_the_shift() {
        let camera = vision::camera::CameraModel::lepton35(vision::camera::Distortion::default());
        let h = camera.nominal_homography();
        let shifted = Homography { m: [[1.0, 0.0, 0.003], [0.0, 1.0, -0.004], [0.0, 0.0, 1.0]] }.then_after(&h);
        assert!((largest_gap_mm(&shifted, &h, &camera) - 0.005).abs() < 1e-12);
        assert_eq!(largest_gap_mm(&h, &h, &camera), 0.0);
    }

    #[test]
    fn merging_keeps_the_primary_pair_of_a_corner() {
        let mut a = CornerPairs::default();
        a.push(3, [1.0, 1.0], [0.0, 0.0]);
        let mut b = CornerPairs::default();
        b.push(3, [9.0, 9.0], [0.0, 0.0]);
        b.push(5, [2.0, 2.0], [1.0, 1.0]);
        let m = merged(&a, &b);
        assert_eq!(m.ids, [3, 5]);
        assert_eq!(m.image_px[0], [1.0, 1.0]);
    }

    #[test]
    fn a_shared_skip_reason_leaves_out_the_frame_s_own_file() {
        let f = FrameOutcome::skipped(&decoded(0, 3, 0.0).entry, "f.png: all pixels invalid (all-NaN)".into());
        assert_eq!(f.shared_skip_reason(), Some("all pixels invalid (all-NaN)"));
        assert_eq!(f.skip_reason(), Some("f.png: all pixels invalid (all-NaN)"));
    }

    #[test]
    fn localisation_names_round_trip() {
        for name in Localisation::NAMES {
            assert_eq!(Localisation::from_name(name).name(), *name);
        }
    }
}
