//! What the localiser gives each frame and each mount fit (paper 003 Sec. 2.3): a
//! frame's placement by either estimator — capture time (eq. 30), nozzle (eq. 29), H(i)
//! (eq. 27 or the rigid mount's T(n_i)·H_m) and how it was placed — or the reason it was
//! skipped, with its detections and corner pairs; and the rigid mount of every pass.

use crate::frame::ThermalFrame;
use crate::homography::Homography;
use crate::localize::CaptureTimeEstimate;
use crate::mount::MountFit;
use crate::pipeline::CornerPairs;

use super::SequenceFrame;

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
    /// Its name (the `placed_by` column of `thermal.monitor`'s `frames.parquet`).
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
    /// A placement from corners: capture time `t`, the nozzle, H(i) = `h`, the RMS error
    /// `err` (mm) over the `pairs` it used; an error when `h` cannot be inverted.
    pub(super) fn new(
        t: CaptureTimeEstimate,
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
    pub(super) fn by_recorded_time(t_s: f64, nozzle_mm: [f64; 2], h: Homography) -> Result<Self, String> {
        let time = CaptureTimeEstimate { t_s, distance_mm: 0.0, at_window_edge: false };
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
    pub(super) fn parked(self, recorded_time_s: f64) -> Self {
        Self { t_s: recorded_time_s, placed_by: Placement::Parked, at_window_edge: false, ..self }
    }
}

/// A detection: (matched vertex or −1, undistorted pixel, temperature °C).
pub type DetectionRow = (i64, [f64; 2], f64);

/// One frame's outcome under both estimators.
pub struct FrameOutcome {
    /// The frame.
    pub entry: SequenceFrame,
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
    /// The frame number whose image this one repeats (skipped, see the module doc of
    /// [`super`]).
    pub repeat_of: Option<usize>,
}

impl FrameOutcome {
    pub(super) fn skipped(entry: &SequenceFrame, reason: String) -> Self {
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

    /// Placed from its corners (eqs 27-30), with a capture-time estimate (`used` in
    /// `thermal.monitor`'s `frames.parquet`).
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

/// One rigid mount (a row of `thermal.monitor`'s `mount.parquet`): the start (pass 0, the nominal mount anchored at
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shared_skip_reason_leaves_out_the_frame_s_own_file() {
        let entry = SequenceFrame { layer: 0, frame: 3, recorded_time_s: 0.375, file: "f.png".into() };
        let f = FrameOutcome::skipped(&entry, "f.png: all pixels invalid (all-NaN)".into());
        assert_eq!(f.shared_skip_reason(), Some("all pixels invalid (all-NaN)"));
        assert_eq!(f.skip_reason(), Some("f.png: all pixels invalid (all-NaN)"));
        assert!(f.located().is_none() && !f.localised());
    }

    #[test]
    fn a_frame_placed_by_its_recorded_time_or_parked_is_not_timed() {
        let h = Homography { m: [[0.1, 0.0, -8.0], [0.0, 0.1, -6.0], [0.0, 0.0, 1.0]] };
        let by_time = Located::by_recorded_time(1.25, [1.0, 2.0], h).unwrap();
        assert_eq!((by_time.placed_by, by_time.t_s, by_time.pairs), (Placement::RecordedTime, 1.25, 0));
        assert!(by_time.estimated_time_s().is_nan() && by_time.fit_err_mm.is_nan());
        let capture = CaptureTimeEstimate { t_s: 2.003, distance_mm: 0.01, at_window_edge: true };
        let timed = Located::new(capture, [1.0, 2.0], h, 0.02, 3).unwrap();
        assert_eq!(timed.estimated_time_s(), 2.003);
        let parked = timed.parked(2.5);
        assert_eq!((parked.placed_by, parked.t_s, parked.at_window_edge), (Placement::Parked, 2.5, false));
        assert!(parked.estimated_time_s().is_nan());
        let singular = Homography { m: [[0.0; 3]; 3] };
        assert_eq!(Located::new(capture, [0.0; 2], singular, 0.0, 4).unwrap_err(), "singular homography");
    }
}
