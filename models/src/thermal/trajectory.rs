//! The commanded motion of paper 003 (Sec. 2.1 eq. 1, Table 1): a closed polygon
//! printed at the programmed feed with every corner blended within a tolerance and
//! an acceleration-limited speed profile, sampled every `T_s`.
//!
//! Blending: each corner of turn angle δ is replaced by the circular arc tangent to
//! both edges that passes `tol` from the vertex, radius `r = tol / (1/cos(δ/2) − 1)`,
//! as a motion controller with a blending tolerance does. Speed: at most the feed on
//! lines and `sqrt(a·r)` on arcs (centripetal acceleration within the limit), tangential
//! acceleration within `a`, from rest at the start to rest at the end (forward and
//! backward passes over a fine arc-length grid). The path starts and ends at the middle
//! of the first edge so that no corner is printed from rest.

use super::errors::{positive, ThermalError};
use super::setup::PrintSetup;

/// Arc-length step of the speed-profile passes (mm).
const PROFILE_STEP_MM: f64 = 0.0005;

/// One blended corner of the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    /// Index of the vertex in the polygon given to [`Trajectory::plan`].
    pub vertex: usize,
    /// The sharp vertex (mm).
    pub vertex_mm: [f64; 2],
    /// Interior angle between the two edges (degrees).
    pub interior_angle_deg: f64,
    /// Signed turn angle of the direction of travel (radians, + counter-clockwise).
    pub turn_rad: f64,
    /// Blend radius (mm).
    pub radius_mm: f64,
    /// Time at which the nozzle enters and leaves the blend arc (s).
    pub arc_start_s: f64,
    /// See `arc_start_s`.
    pub arc_end_s: f64,
}

/// A commanded trajectory sampled every `dt_s` (paper eq. 1).
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Sampling period T_s (s).
    pub dt_s: f64,
    /// Sample times, `k·dt_s` (s).
    pub t_s: Vec<f64>,
    /// Nozzle position (mm).
    pub x_mm: Vec<f64>,
    /// See `x_mm`.
    pub y_mm: Vec<f64>,
    /// Velocity (mm/s), along the path tangent.
    pub vx_mm_s: Vec<f64>,
    /// See `vx_mm_s`.
    pub vy_mm_s: Vec<f64>,
    /// Arc length travelled (mm).
    pub s_mm: Vec<f64>,
    /// Curvature of the geometric path at each sample (1/mm, + counter-clockwise):
    /// 0 on edges, ±1/r on blend arcs. Eq. 4 estimates the same from the samples.
    pub path_curvature_per_mm: Vec<f64>,
    /// The blended corners in print order.
    pub corners: Vec<Corner>,
}

/// A piece of the blended path: a straight edge or a blend arc.
#[derive(Debug, Clone, Copy)]
enum Piece {
    Line { from: [f64; 2], dir: [f64; 2], length: f64 },
    Arc { center: [f64; 2], radius: f64, start_angle: f64, sweep: f64, corner: usize },
}

impl Piece {
    fn length(&self) -> f64 {
        match *self {
            Piece::Line { length, .. } => length,
            Piece::Arc { radius, sweep, .. } => radius * sweep.abs(),
        }
    }

    /// Position, unit tangent and curvature at arc length `u` into the piece.
    fn at(&self, u: f64) -> ([f64; 2], [f64; 2], f64) {
        match *self {
            Piece::Line { from, dir, .. } => ([from[0] + u * dir[0], from[1] + u * dir[1]], dir, 0.0),
            Piece::Arc { center, radius, start_angle, sweep, .. } => {
                let sign = sweep.signum();
                let angle = start_angle + sign * u / radius;
                let pos = [center[0] + radius * angle.cos(), center[1] + radius * angle.sin()];
                let tangent = [-sign * angle.sin(), sign * angle.cos()];
                (pos, tangent, sign / radius)
            }
        }
    }
}

impl Trajectory {
    /// Plans the closed polygon `vertices` (mm) with the feed, acceleration, blending
    /// tolerance and sampling period of `setup`.
    pub fn plan(vertices: &[[f64; 2]], setup: &PrintSetup) -> Result<Self, ThermalError> {
        let setup = setup.check()?;
        if vertices.len() < 3 {
            return Err(ThermalError::TooFewVertices { found: vertices.len() });
        }
        let (pieces, mut corners) = blended_pieces(vertices, setup.blend_tol_mm)?;
        let lengths: Vec<f64> = pieces.iter().map(Piece::length).collect();
        let total_mm: f64 = lengths.iter().sum();
        let limits = speed_limits(&pieces, &lengths, setup.feed_mm_s, setup.accel_mm_s2);
        let speeds = speed_profile(&limits, setup.accel_mm_s2);
        let times = passage_times(&speeds);
        let trajectory = sample_uniformly(&pieces, &lengths, &speeds, &times, total_mm, setup.sample_period_s);
        fill_corner_times(&mut corners, &pieces, &lengths, &times);
        Ok(Self { corners, ..trajectory })
    }

    /// A trajectory from a commanded table (t, x, y) sampled every `dt_s`, as a dataset
    /// gives it (DESIGN §4): velocity by central differences (eq. 1), curvature by eq. 4,
    /// arc length by summing the steps. The table carries no corner list, so `corners`
    /// is empty; errors if the columns differ in length or the times are not `k·dt_s`.
    pub fn from_samples(t_s: &[f64], x_mm: &[f64], y_mm: &[f64]) -> Result<Self, ThermalError> {
        let bad = |message: String| ThermalError::BadTrajectory { message };
        if t_s.len() != x_mm.len() || t_s.len() != y_mm.len() || t_s.len() < 3 {
            return Err(bad(format!(
                "{} times, {} x, {} y: need equal lengths of 3 or more",
                t_s.len(),
                x_mm.len(),
                y_mm.len()
            )));
        }
        let dt_s = t_s[1] - t_s[0];
        if let Some(k) =
            (1..t_s.len()).find(|&k| ((t_s[k] - t_s[0]) - k as f64 * dt_s).abs() > 1e-6 * dt_s.max(1e-9) + 1e-9)
        {
            return Err(bad(format!("sample {k} at t = {} s breaks the uniform period {dt_s} s", t_s[k])));
        }
        positive("sample period", dt_s)?;
        let (vx_mm_s, vy_mm_s) = super::geometry::velocity_mm_s(x_mm, y_mm, dt_s);
        let mut s_mm = vec![0.0; t_s.len()];
        for k in 1..t_s.len() {
            s_mm[k] = s_mm[k - 1] + (x_mm[k] - x_mm[k - 1]).hypot(y_mm[k] - y_mm[k - 1]);
        }
        Ok(Self {
            dt_s,
            t_s: t_s.to_vec(),
            x_mm: x_mm.to_vec(),
            y_mm: y_mm.to_vec(),
            vx_mm_s,
            vy_mm_s,
            s_mm,
            path_curvature_per_mm: super::geometry::curvature_per_mm(x_mm, y_mm, dt_s),
            corners: Vec::new(),
        })
    }

    /// The corner test path of [`super::setup::corner_test_path`] with `setup`.
    pub fn corner_test(setup: &PrintSetup) -> Result<Self, ThermalError> {
        Self::plan(&super::setup::corner_test_path(), setup)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// Speed |v| at each sample (mm/s).
    pub fn speed_mm_s(&self) -> Vec<f64> {
        self.vx_mm_s.iter().zip(&self.vy_mm_s).map(|(vx, vy)| vx.hypot(*vy)).collect()
    }

    /// Index of the sample nearest to `p_mm` (0 when there are no samples).
    pub fn nearest_sample(&self, p_mm: [f64; 2]) -> usize {
        let distance = |k: usize| (self.x_mm[k] - p_mm[0]).hypot(self.y_mm[k] - p_mm[1]);
        (0..self.len()).min_by(|&a, &b| distance(a).total_cmp(&distance(b))).unwrap_or(0)
    }

    /// Duration of the move (s).
    pub fn duration_s(&self) -> f64 {
        self.t_s.last().copied().unwrap_or(0.0)
    }
}

/// Edges shortened by the blend tangent lengths, with an arc at every vertex. The
/// first piece starts at the middle of edge 0 (vertex 0 → vertex 1).
fn blended_pieces(vertices: &[[f64; 2]], tol_mm: f64) -> Result<(Vec<Piece>, Vec<Corner>), ThermalError> {
    let n = vertices.len();
    let edge = |i: usize| -> ([f64; 2], f64) {
        let (a, b) = (vertices[i % n], vertices[(i + 1) % n]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = dx.hypot(dy);
        ([dx / len, dy / len], len)
    };
    // Corner k sits at vertex (k + 1) % n: print order from the middle of edge 0.
    let mut blends = Vec::with_capacity(n);
    for k in 0..n {
        let vertex = (k + 1) % n;
        let ((d_in, len_in), (d_out, len_out)) = (edge(k), edge(k + 1));
        let turn = (d_in[0] * d_out[1] - d_in[1] * d_out[0]).atan2(d_in[0] * d_out[0] + d_in[1] * d_out[1]);
        let radius = tol_mm / (1.0 / (turn.abs() / 2.0).cos() - 1.0);
        let tangent_mm = radius * (turn.abs() / 2.0).tan();
        let available_mm = 0.5 * len_in.min(len_out);
        if tangent_mm > available_mm {
            return Err(ThermalError::BlendDoesNotFit { corner: vertex, needed_mm: tangent_mm, available_mm });
        }
        blends.push((vertex, d_in, d_out, turn, radius, tangent_mm));
    }
    let mut pieces = Vec::with_capacity(2 * n + 1);
    let mut corners = Vec::with_capacity(n);
    let (d0, len0) = edge(0);
    let mut start = [vertices[0][0] + 0.5 * len0 * d0[0], vertices[0][1] + 0.5 * len0 * d0[1]];
    let mut prev_tangent_mm = 0.5 * len0; // the first line runs from the middle of edge 0
    for (k, &(vertex, d_in, d_out, turn, radius, tangent_mm)) in blends.iter().enumerate() {
        let v = vertices[vertex];
        let line_len = if k == 0 { prev_tangent_mm - tangent_mm } else { edge(k).1 - prev_tangent_mm - tangent_mm };
        pieces.push(Piece::Line { from: start, dir: d_in, length: line_len });
        let entry = [v[0] - tangent_mm * d_in[0], v[1] - tangent_mm * d_in[1]];
        let sign = turn.signum();
        let normal = [-sign * d_in[1], sign * d_in[0]]; // towards the arc centre
        let center = [entry[0] + radius * normal[0], entry[1] + radius * normal[1]];
        let start_angle = (entry[1] - center[1]).atan2(entry[0] - center[0]);
        pieces.push(Piece::Arc { center, radius, start_angle, sweep: turn, corner: k });
        let interior_angle_deg = 180.0 - turn.abs().to_degrees();
        corners.push(Corner {
            vertex,
            vertex_mm: v,
            interior_angle_deg,
            turn_rad: turn,
            radius_mm: radius,
            arc_start_s: 0.0,
            arc_end_s: 0.0,
        });
        start = [v[0] + tangent_mm * d_out[0], v[1] + tangent_mm * d_out[1]];
        prev_tangent_mm = tangent_mm;
    }
    // Back to the middle of edge 0.
    pieces.push(Piece::Line { from: start, dir: d0, length: 0.5 * len0 - prev_tangent_mm });
    Ok((pieces, corners))
}

/// Speed limit at each node of the arc-length grid: feed on lines, `sqrt(a·r)` on arcs.
fn speed_limits(pieces: &[Piece], lengths: &[f64], feed: f64, accel: f64) -> Vec<f64> {
    let total: f64 = lengths.iter().sum();
    let nodes = (total / PROFILE_STEP_MM).ceil() as usize + 1;
    let mut limits = vec![feed; nodes];
    let mut offset = 0.0;
    for (piece, len) in pieces.iter().zip(lengths) {
        if let Piece::Arc { radius, .. } = piece {
            let cap = feed.min((accel * radius).sqrt());
            let first = (offset / PROFILE_STEP_MM).floor() as usize;
            let last = (((offset + len) / PROFILE_STEP_MM).ceil() as usize).min(nodes - 1);
            limits[first..=last].iter_mut().for_each(|v| *v = v.min(cap));
        }
        offset += len;
    }
    limits
}

/// Forward and backward passes: speed within the limits, |dv²/ds| ≤ 2a, zero at both ends.
fn speed_profile(limits: &[f64], accel: f64) -> Vec<f64> {
    let mut speeds = limits.to_vec();
    let dv2 = 2.0 * accel * PROFILE_STEP_MM;
    let last = speeds.len() - 1;
    speeds[0] = 0.0;
    speeds[last] = 0.0;
    for i in 1..speeds.len() {
        speeds[i] = speeds[i].min((speeds[i - 1] * speeds[i - 1] + dv2).sqrt());
    }
    for i in (0..last).rev() {
        speeds[i] = speeds[i].min((speeds[i + 1] * speeds[i + 1] + dv2).sqrt());
    }
    speeds
}

/// Time at each arc-length node, trapezoidal in 1/v (exact for constant acceleration).
fn passage_times(speeds: &[f64]) -> Vec<f64> {
    let mut times = vec![0.0; speeds.len()];
    for i in 1..speeds.len() {
        times[i] = times[i - 1] + 2.0 * PROFILE_STEP_MM / (speeds[i - 1] + speeds[i]);
    }
    times
}

/// Samples position, velocity and curvature at `t = k·dt` by inverting s(t).
fn sample_uniformly(
    pieces: &[Piece],
    lengths: &[f64],
    speeds: &[f64],
    times: &[f64],
    total_mm: f64,
    dt_s: f64,
) -> Trajectory {
    let duration = *times.last().expect("profile has nodes");
    let samples = (duration / dt_s).floor() as usize + 1;
    let mut out = Trajectory {
        dt_s,
        t_s: Vec::with_capacity(samples),
        x_mm: Vec::with_capacity(samples),
        y_mm: Vec::with_capacity(samples),
        vx_mm_s: Vec::with_capacity(samples),
        vy_mm_s: Vec::with_capacity(samples),
        s_mm: Vec::with_capacity(samples),
        path_curvature_per_mm: Vec::with_capacity(samples),
        corners: Vec::new(),
    };
    let mut node = 0;
    let (mut piece, mut piece_start) = (0, 0.0);
    for k in 0..samples {
        let t = k as f64 * dt_s;
        while node + 1 < times.len() - 1 && times[node + 1] <= t {
            node += 1;
        }
        let (s, v) = position_in_step(node, t, speeds, times, total_mm);
        while piece + 1 < pieces.len() && s > piece_start + lengths[piece] {
            piece_start += lengths[piece];
            piece += 1;
        }
        let (pos, tangent, curvature) = pieces[piece].at((s - piece_start).clamp(0.0, lengths[piece]));
        out.t_s.push(t);
        out.x_mm.push(pos[0]);
        out.y_mm.push(pos[1]);
        out.vx_mm_s.push(v * tangent[0]);
        out.vy_mm_s.push(v * tangent[1]);
        out.s_mm.push(s);
        out.path_curvature_per_mm.push(curvature);
    }
    out
}

/// Arc length and speed at time `t` inside profile step `node` (constant acceleration).
fn position_in_step(node: usize, t: f64, speeds: &[f64], times: &[f64], total_mm: f64) -> (f64, f64) {
    let (v0, v1) = (speeds[node], speeds[node + 1]);
    let step_s = times[node + 1] - times[node];
    let tau = (t - times[node]).clamp(0.0, step_s);
    let accel = (v1 - v0) / step_s;
    let s = node as f64 * PROFILE_STEP_MM + v0 * tau + 0.5 * accel * tau * tau;
    (s.min(total_mm), v0 + accel * tau)
}

/// Entry and exit times of each blend arc, from the passage times of the profile grid.
fn fill_corner_times(corners: &mut [Corner], pieces: &[Piece], lengths: &[f64], times: &[f64]) {
    let time_at = |s: f64| {
        let x = s / PROFILE_STEP_MM;
        let i = (x.floor() as usize).min(times.len() - 2);
        let f = x - i as f64;
        times[i] + f * (times[i + 1] - times[i])
    };
    let mut offset = 0.0;
    for (piece, len) in pieces.iter().zip(lengths) {
        if let Piece::Arc { corner, .. } = piece {
            corners[*corner].arc_start_s = time_at(offset);
            corners[*corner].arc_end_s = time_at(offset + len);
        }
        offset += len;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thermal::setup::corner_test_path;

    fn test_trajectory() -> Trajectory {
        Trajectory::corner_test(&PrintSetup::paper_defaults()).unwrap()
    }

    #[test]
    fn path_is_closed_and_starts_and_ends_at_rest() {
        let tr = test_trajectory();
        let n = tr.len();
        assert!((tr.x_mm[0] - tr.x_mm[n - 1]).abs() < 1e-3 && (tr.y_mm[0] - tr.y_mm[n - 1]).abs() < 1e-3);
        let speed = tr.speed_mm_s();
        assert!(speed[0] < 1e-9 && speed[n - 1] < 0.5, "end speeds {} {}", speed[0], speed[n - 1]);
    }

    #[test]
    fn speed_and_acceleration_stay_within_the_limits() {
        let setup = PrintSetup::paper_defaults();
        let tr = test_trajectory();
        let speed = tr.speed_mm_s();
        assert!(speed.iter().all(|v| *v <= setup.feed_mm_s + 1e-9));
        assert!((speed.iter().cloned().fold(0.0, f64::max) - setup.feed_mm_s).abs() < 1e-9);
        for k in 1..tr.len() {
            let dv = (speed[k] - speed[k - 1]) / tr.dt_s;
            assert!(dv.abs() <= setup.accel_mm_s2 * 1.01, "sample {k}: tangential accel {dv}");
        }
    }

    #[test]
    fn blend_arcs_pass_the_tolerance_from_each_vertex() {
        // The arc's midpoint lies on the bisector at r/cos(δ/2) − r = tol from the vertex.
        let setup = PrintSetup::paper_defaults();
        let tr = test_trajectory();
        for c in &tr.corners {
            let closest = (0..tr.len())
                .map(|k| (tr.x_mm[k] - c.vertex_mm[0]).hypot(tr.y_mm[k] - c.vertex_mm[1]))
                .fold(f64::INFINITY, f64::min);
            assert!((closest - setup.blend_tol_mm).abs() < 0.002, "corner {}: {closest}", c.vertex);
            // On the arc, the centripetal acceleration v²/r stays within the limit.
            let speed = tr.speed_mm_s();
            let on_arc = (0..tr.len()).filter(|&k| tr.t_s[k] > c.arc_start_s && tr.t_s[k] < c.arc_end_s);
            for k in on_arc {
                assert!(speed[k] * speed[k] / c.radius_mm <= setup.accel_mm_s2 * 1.001, "corner {}", c.vertex);
            }
        }
    }

    #[test]
    fn corners_follow_the_polygon_in_print_order() {
        let tr = test_trajectory();
        let n = corner_test_path().len();
        assert_eq!(tr.corners.len(), n);
        let total_turn: f64 = tr.corners.iter().map(|c| c.turn_rad).sum();
        // A counter-clockwise simple polygon turns by +2π in all.
        assert!((total_turn - std::f64::consts::TAU).abs() < 1e-9, "{total_turn}");
        for w in tr.corners.windows(2) {
            assert!(w[0].arc_end_s <= w[1].arc_start_s);
        }
        // Printing starts in the middle of edge 0, so the first corner is vertex 1.
        assert_eq!(tr.corners[0].vertex, 1);
    }

    #[test]
    fn duration_is_length_over_feed_plus_corner_slowdowns() {
        // Never faster than the whole path at the feed; the paper prints its (larger) path in about 10 s.
        let tr = test_trajectory();
        let s_total = tr.s_mm.last().unwrap();
        assert!(tr.duration_s() > s_total / 20.0 && tr.duration_s() < 12.0, "{} s", tr.duration_s());
        for c in &tr.corners {
            eprintln!(
                "corner {} {:.1} deg r {:.3} mm arc {:.3}-{:.3} s",
                c.vertex, c.interior_angle_deg, c.radius_mm, c.arc_start_s, c.arc_end_s
            );
        }
    }

    #[test]
    fn a_trajectory_rebuilt_from_its_samples_agrees_with_the_plan() {
        // What a stage reads back from trajectory.csv: positions identical, velocities
        // within the central-difference error, curvature equal away from arc ends.
        let tr = test_trajectory();
        let back = Trajectory::from_samples(&tr.t_s, &tr.x_mm, &tr.y_mm).unwrap();
        assert_eq!(back.dt_s, tr.dt_s);
        for k in 1..tr.len() - 1 {
            assert!((back.vx_mm_s[k] - tr.vx_mm_s[k]).abs() < 0.3 && (back.vy_mm_s[k] - tr.vy_mm_s[k]).abs() < 0.3);
        }
        assert!((back.s_mm.last().unwrap() - tr.s_mm.last().unwrap()).abs() < 1e-3);
        assert!(Trajectory::from_samples(&[0.0, 0.001, 0.003], &[0.0; 3], &[0.0; 3]).is_err());
        assert!(Trajectory::from_samples(&[0.0, 0.001], &[0.0; 2], &[0.0; 2]).is_err());
    }

    #[test]
    fn samples_are_consistent_with_the_velocity() {
        // Central differences of position match the stored velocity to O(dt²·|v'|).
        let tr = test_trajectory();
        for k in 1..tr.len() - 1 {
            let vx = (tr.x_mm[k + 1] - tr.x_mm[k - 1]) / (2.0 * tr.dt_s);
            let vy = (tr.y_mm[k + 1] - tr.y_mm[k - 1]) / (2.0 * tr.dt_s);
            assert!((vx - tr.vx_mm_s[k]).abs() < 0.3 && (vy - tr.vy_mm_s[k]).abs() < 0.3, "sample {k}");
        }
    }
}
