//! Frame localization, paper 003 Sec. 2.3 eqs 28-30.
//!
//! Eq. 29: the nozzle's plane position in frame i is P_N,i = H(i)·P_N⁽⁰⁾, with P_N⁽⁰⁾ the
//! nozzle pixel marked once (here: the raw pixel of the dataset, undistorted).
//! Eq. 30: the capture time is t̂_c = argmin over t ∈ [t_r − δt, t_r + δt] of
//! ‖(x(t), y(t)) − P_N,i‖². The trajectory is a uniformly sampled table (t_s, x_mm, y_mm);
//! between samples it is taken as piecewise linear, so the argmin is refined below the
//! sample period by projecting P_N,i onto each segment inside the window. When the
//! minimum lies on the boundary of the window the estimate is flagged, since the true
//! capture time is then probably outside it (a repeated or frozen frame, DESIGN §5.3).

use crate::homography::Homography;

/// The paper's window half-width: "δt should be within 10 ms" (Sec. 2.3).
pub const PAPER_WINDOW_S: f64 = 0.010;

/// A uniformly sampled commanded trajectory (eq. 1's x(t), y(t)), borrowed.
#[derive(Debug, Clone, Copy)]
pub struct TrajectoryView<'a> {
    t_s: &'a [f64],
    x_mm: &'a [f64],
    y_mm: &'a [f64],
    dt_s: f64,
}

/// Why a trajectory table cannot be used for localization.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LocalizeError {
    /// t, x, y have different lengths.
    #[error("trajectory columns differ in length: t {t}, x {x}, y {y}")]
    LengthMismatch {
        /// Length of t_s.
        t: usize,
        /// Length of x_mm.
        x: usize,
        /// Length of y_mm.
        y: usize,
    },
    /// Fewer than two samples.
    #[error("trajectory needs at least 2 samples, has {0}")]
    TooShort(usize),
    /// The time column is not uniformly increasing.
    #[error("trajectory time is not uniformly sampled at sample {index}")]
    NotUniform {
        /// First sample whose spacing differs.
        index: usize,
    },
}

impl<'a> TrajectoryView<'a> {
    /// Checks the columns (equal lengths, ≥ 2 samples, uniform increasing time).
    pub fn new(t_s: &'a [f64], x_mm: &'a [f64], y_mm: &'a [f64]) -> Result<Self, LocalizeError> {
        if t_s.len() != x_mm.len() || t_s.len() != y_mm.len() {
            return Err(LocalizeError::LengthMismatch { t: t_s.len(), x: x_mm.len(), y: y_mm.len() });
        }
        if t_s.len() < 2 {
            return Err(LocalizeError::TooShort(t_s.len()));
        }
        let dt_s = (t_s[t_s.len() - 1] - t_s[0]) / (t_s.len() - 1) as f64;
        if dt_s.is_nan() || dt_s <= 0.0 {
            return Err(LocalizeError::NotUniform { index: 1 });
        }
        let tol = 1e-6 * dt_s;
        for (i, w) in t_s.windows(2).enumerate() {
            if ((w[1] - w[0]) - dt_s).abs() > tol.max(1e-9 * w[1].abs()) {
                return Err(LocalizeError::NotUniform { index: i + 1 });
            }
        }
        Ok(Self { t_s, x_mm, y_mm, dt_s })
    }

    /// Sample period (s).
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Time span covered [first, last] (s).
    pub fn span_s(&self) -> [f64; 2] {
        [self.t_s[0], self.t_s[self.t_s.len() - 1]]
    }

    /// Position at time `t_s` by linear interpolation (clamped to the ends).
    pub fn position_mm(&self, t_s: f64) -> [f64; 2] {
        let (k, s) = self.segment_at(t_s);
        lerp2([self.x_mm[k], self.y_mm[k]], [self.x_mm[k + 1], self.y_mm[k + 1]], s)
    }

    /// Segment index and fraction along it for time `t_s` (clamped).
    fn segment_at(&self, t_s: f64) -> (usize, f64) {
        let last = self.t_s.len() - 2;
        let f = ((t_s - self.t_s[0]) / self.dt_s).clamp(0.0, (last + 1) as f64);
        let k = (f.floor() as usize).min(last);
        (k, f - k as f64)
    }
}

/// Eq. 29: nozzle plane position P_N,i = H(i)·P_N⁽⁰⁾ (undistorted nozzle pixel).
pub fn nozzle_position_mm(h: &Homography, nozzle_undistorted_px: [f64; 2]) -> [f64; 2] {
    h.apply(nozzle_undistorted_px)
}

/// Result of eq. 30.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureTimeEstimate {
    /// Estimated capture time t̂_c (s).
    pub t_s: f64,
    /// Distance from the trajectory at t̂_c to the nozzle position (mm).
    pub distance_mm: f64,
    /// True when t̂_c sits on the boundary of [t_r − δt, t_r + δt] (trajectory ends included).
    pub at_window_edge: bool,
}

/// Eq. 30: the time in [t_r − δt, t_r + δt] (clipped to the trajectory) whose position is
/// nearest to `nozzle_mm`, refined within each sample interval by projection.
pub fn estimate_capture_time(
    traj: &TrajectoryView<'_>,
    nozzle_mm: [f64; 2],
    t_recorded_s: f64,
    window_s: f64,
) -> CaptureTimeEstimate {
    let span = traj.span_s();
    let t_lo = (t_recorded_s - window_s).clamp(span[0], span[1]);
    let t_hi = (t_recorded_s + window_s).clamp(span[0], span[1]);
    let (k_lo, _) = traj.segment_at(t_lo);
    let (k_hi, _) = traj.segment_at(t_hi);
    let mut best = CaptureTimeEstimate { t_s: t_lo, distance_mm: f64::INFINITY, at_window_edge: true };
    for k in k_lo..=k_hi {
        let t = best_time_on_segment(traj, k, nozzle_mm).clamp(t_lo, t_hi);
        let p = traj.position_mm(t);
        let d = (p[0] - nozzle_mm[0]).hypot(p[1] - nozzle_mm[1]);
        if d < best.distance_mm {
            best = CaptureTimeEstimate { t_s: t, distance_mm: d, at_window_edge: false };
        }
    }
    let edge_tol = 1e-9 * traj.dt_s.max(1.0);
    best.at_window_edge = (best.t_s - t_lo).abs() <= edge_tol || (t_hi - best.t_s).abs() <= edge_tol;
    best
}

/// Time of the point of segment k (samples k, k+1) nearest to `p`.
fn best_time_on_segment(traj: &TrajectoryView<'_>, k: usize, p: [f64; 2]) -> f64 {
    let a = [traj.x_mm[k], traj.y_mm[k]];
    let b = [traj.x_mm[k + 1], traj.y_mm[k + 1]];
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let s = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    traj.t_s[k] + s * traj.dt_s
}

fn lerp2(a: [f64; 2], b: [f64; 2], s: f64) -> [f64; 2] {
    [a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])]
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Table {
        t: Vec<f64>,
        x: Vec<f64>,
        y: Vec<f64>,
    }

    fn table(n: usize, dt: f64, f: impl Fn(f64) -> [f64; 2]) -> Table {
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let (x, y) = t.iter().map(|&t| f(t)).map(|p| (p[0], p[1])).unzip();
        Table { t, x, y }
    }

    #[test]
    fn straight_line_time_is_recovered_exactly_between_samples() {
        // x = 20 t (20 mm/s, paper feed), sampled every 1 ms: the segment projection of the
        // exact position returns t* exactly, far below the sample period.
        let tab = table(3000, 0.001, |t| [20.0 * t, 5.0]);
        let traj = TrajectoryView::new(&tab.t, &tab.x, &tab.y).unwrap();
        let t_true = 1.234_567;
        let est = estimate_capture_time(&traj, [20.0 * t_true, 5.0], 1.2375, PAPER_WINDOW_S);
        assert!((est.t_s - t_true).abs() < 1e-12, "{}", est.t_s);
        assert!(est.distance_mm < 1e-12 && !est.at_window_edge);
    }

    #[test]
    fn curved_trajectory_time_is_recovered() {
        // A circle of radius 10 mm at 20 mm/s (ω = 2 rad/s), sampled every 1 ms.
        let circle = |t: f64| [10.0 * (2.0 * t).cos(), 10.0 * (2.0 * t).sin()];
        let tab = table(2000, 0.001, circle);
        let traj = TrajectoryView::new(&tab.t, &tab.x, &tab.y).unwrap();
        let t_true = 0.777_3;
        // A position on the sampled (piecewise linear) trajectory is recovered exactly.
        let on_table = traj.position_mm(t_true);
        let est = estimate_capture_time(&traj, on_table, 0.780, PAPER_WINDOW_S);
        assert!((est.t_s - t_true).abs() < 1e-12);
        // The true arc point lies 0.5 µm off the chords (sagitta r(ωdt)²/8); the time
        // error this causes is far below a microsecond.
        let est = estimate_capture_time(&traj, circle(t_true), 0.780, PAPER_WINDOW_S);
        assert!((est.t_s - t_true).abs() < 1e-6, "{}", est.t_s);
    }

    #[test]
    fn position_outside_the_window_returns_the_flagged_edge() {
        let tab = table(3000, 0.001, |t| [20.0 * t, 0.0]);
        let traj = TrajectoryView::new(&tab.t, &tab.x, &tab.y).unwrap();
        // The nozzle was at t = 1.5 s but the recorded time says 1.0 s: the window's upper
        // edge 1.010 s is the best the search may return, and it says so.
        let est = estimate_capture_time(&traj, [30.0, 0.0], 1.0, PAPER_WINDOW_S);
        assert!((est.t_s - 1.010).abs() < 1e-12 && est.at_window_edge);
        assert!((est.distance_mm - (30.0 - 20.2)).abs() < 1e-9);
    }

    #[test]
    fn nozzle_position_is_the_homography_image_of_the_nozzle_pixel() {
        let h = Homography { m: [[0.1, 0.0, -8.0], [0.0, 0.2, -12.0], [0.0, 0.0, 1.0]] };
        assert_eq!(nozzle_position_mm(&h, [80.0, 60.0]), [0.0, 0.0]);
    }

    #[test]
    fn bad_tables_are_rejected() {
        assert!(matches!(
            TrajectoryView::new(&[0.0, 1.0], &[0.0], &[0.0, 1.0]),
            Err(LocalizeError::LengthMismatch { .. })
        ));
        assert_eq!(TrajectoryView::new(&[0.0], &[0.0], &[0.0]).unwrap_err(), LocalizeError::TooShort(1));
        let t = [0.0, 0.1, 0.25, 0.3];
        assert!(matches!(TrajectoryView::new(&t, &[0.0; 4], &[0.0; 4]), Err(LocalizeError::NotUniform { .. })));
    }
}
