//! The firmware's motion planner over a queue of G-code moves: per move a trapezoid
//! (accelerate at `a`, cruise, decelerate at `a`), with look-ahead so that the speed at
//! each joint between moves is as high as the corner and the moves around it allow. This
//! is what the nozzle was commanded to do along a printed line, which is what the photos'
//! widths answer to (issue 53).
//!
//! Per move `v² = v0² + 2·a·s` while accelerating, cruise `c = min(F, v_max,
//! √((v0² + v1²)/2 + a·L))`. The joint speeds come from the junction limits, then a
//! backward pass (every move can still stop by the end of the queue:
//! `v_i² ≤ v_{i+1}² + 2·a·L_i`) and a forward pass (`v_{i+1}² ≤ v_i² + 2·a·L_i`).
//! Junction limits:
//!
//! - Klipper (`square_corner_velocity`, learnt from its `toolhead.py`, not copied): a
//!   virtual junction deviation `δ = scv²·(√2 − 1)/a` and, for the angle θ between the
//!   moves' directions, `v² ≤ δ·a·sin(θ/2)/(1 − sin(θ/2))` (so `scv` at 90°, no limit
//!   when straight on), also `v² ≤ 2·a·L·tan(θ/2)/4` of either move (the arc stays
//!   within half a move). Its `minimum_cruise_ratio` (or `max_accel_to_decel`) caps a
//!   move's top speed at the triangle peak it would reach accelerating and decelerating
//!   at `a_d = a·(1 − ratio)`, found by the same passes at `a_d`. The extruder limits a
//!   joint where the filament per mm of path changes by Δr to `v ≤ icv/|Δr|`
//!   (`instantaneous_corner_velocity`, 1 mm/s by default). Klipper caps the peak once
//!   per accelerate–decelerate hill; here each move is capped by its own smoothed peak,
//!   the same for a move that has both ramps.
//! - Marlin junction deviation (`M205 J`): the same formula with the given `δ`.
//! - Marlin classic jerk (`M205 X Y Z`): each axis's velocity may jump by at most its
//!   jerk at a joint (at the joint speed `v`, axis k of unit vectors `p` then `u` jumps
//!   by `v·|u_k − p_k|`, or `v·max(|u_k|, |p_k|)` when it reverses, as Marlin's
//!   `planner.cpp` counts it), and a move may start from rest at its "safe speed",
//!   where no axis exceeds its jerk. The extruder's jerk is not modelled.
//!
//! A queue starts from rest (Marlin classic jerk: at the safe speed) and ends at rest.
//! A move with no XYZ length (E only: a retraction or a prime) is a stop: the queue
//! before it ends at rest and the one after starts from rest; it takes `|E|/F`.

use thiserror::Error;

/// How a firmware limits the speed through a joint between two moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cornering {
    /// Klipper's `square_corner_velocity` (mm/s) with its extruder's
    /// `instantaneous_corner_velocity` (mm/s of filament; Klipper's default 1).
    SquareCorner {
        /// Speed through a 90° corner (mm/s).
        velocity_mm_s: f64,
        /// Largest instantaneous change of filament speed at a joint (mm/s).
        extruder_corner_mm_s: f64,
    },
    /// Marlin's junction deviation (`M205 J`, mm).
    JunctionDeviation {
        /// The deviation δ (mm).
        deviation_mm: f64,
    },
    /// Marlin's classic jerk (`M205 X Y Z`, mm/s per axis).
    ClassicJerk {
        /// Largest instantaneous change of X speed (mm/s).
        jerk_x_mm_s: f64,
        /// Largest instantaneous change of Y speed (mm/s).
        jerk_y_mm_s: f64,
        /// Largest instantaneous change of Z speed (mm/s).
        jerk_z_mm_s: f64,
    },
}

/// The planner's limits in force for one move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionLimits {
    /// Acceleration and deceleration (mm/s²).
    pub accel_mm_s2: f64,
    /// Klipper's `max_accel_to_decel` = accel·(1 − minimum_cruise_ratio) (mm/s²); equal
    /// to the accel where there is no such cap (Marlin).
    pub accel_to_decel_mm_s2: f64,
    /// Speed cap over the feed (mm/s); `f64::INFINITY` for none.
    pub max_velocity_mm_s: f64,
    /// The junction rule.
    pub cornering: Cornering,
}

/// The pressure (linear) advance in force: Klipper's `pressure_advance` and
/// `pressure_advance_smooth_time`, Marlin's `M900 K` (smooth time 0: Marlin has none).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PressureAdvance {
    /// Filament advance per filament speed (s).
    pub advance_s: f64,
    /// Klipper's smoothing window (s).
    pub smooth_time_s: f64,
}

/// One commanded move as the G-code gives it, with what is in force for it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Move {
    /// Start (x, y, z) on the bed (mm).
    pub start_mm: [f64; 3],
    /// End (x, y, z) (mm).
    pub end_mm: [f64; 3],
    /// Filament pushed (mm; negative for a retraction).
    pub filament_mm: f64,
    /// Commanded feed (mm/s).
    pub feed_mm_s: f64,
    /// The planner's limits.
    pub limits: MotionLimits,
    /// The pressure advance in force (the planner ignores it).
    pub pressure_advance: PressureAdvance,
}

impl Move {
    /// XYZ length (mm).
    pub fn length_mm(&self) -> f64 {
        norm(sub(self.end_mm, self.start_mm))
    }

    /// Unit direction of the XYZ motion (zero for a move without length).
    fn direction(&self) -> [f64; 3] {
        let d = sub(self.end_mm, self.start_mm);
        let n = norm(d);
        if n > MIN_LENGTH_MM {
            [d[0] / n, d[1] / n, d[2] / n]
        } else {
            [0.0; 3]
        }
    }

    /// Filament per mm of path.
    pub fn filament_per_mm(&self) -> f64 {
        let n = self.length_mm();
        if n > MIN_LENGTH_MM {
            self.filament_mm / n
        } else {
            0.0
        }
    }

    fn is_kinematic(&self) -> bool {
        self.length_mm() > MIN_LENGTH_MM
    }

    fn cruise_cap_v2(&self) -> f64 {
        self.feed_mm_s.min(self.limits.max_velocity_mm_s).powi(2)
    }
}

/// Shorter moves have no direction (mm); Klipper's threshold.
pub const MIN_LENGTH_MM: f64 = 1e-9;

/// One planned move: its trapezoid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlannedMove {
    /// XYZ length (mm; 0 for an E-only move).
    pub length_mm: f64,
    /// Speed at the start (mm/s).
    pub entry_mm_s: f64,
    /// Top speed (mm/s).
    pub cruise_mm_s: f64,
    /// Speed at the end (mm/s).
    pub exit_mm_s: f64,
    /// Acceleration and deceleration (mm/s²).
    pub accel_mm_s2: f64,
    /// Time the move takes (s).
    pub duration_s: f64,
}

impl PlannedMove {
    fn trapezoid(length_mm: f64, v0: f64, c: f64, v1: f64, accel_mm_s2: f64) -> Self {
        let mut m = Self { length_mm, entry_mm_s: v0, cruise_mm_s: c, exit_mm_s: v1, accel_mm_s2, duration_s: 0.0 };
        m.duration_s = m.time_at_mm(length_mm);
        m
    }

    /// Distance over which the move accelerates (mm).
    pub fn accel_length_mm(&self) -> f64 {
        ((self.cruise_mm_s.powi(2) - self.entry_mm_s.powi(2)) / (2.0 * self.accel_mm_s2)).clamp(0.0, self.length_mm)
    }

    /// Distance over which the move decelerates (mm).
    pub fn decel_length_mm(&self) -> f64 {
        let d = (self.cruise_mm_s.powi(2) - self.exit_mm_s.powi(2)) / (2.0 * self.accel_mm_s2);
        d.clamp(0.0, self.length_mm - self.accel_length_mm())
    }

    /// Commanded speed at `s_mm` from the move's start (clamped to the move; mm/s).
    pub fn speed_at_mm(&self, s_mm: f64) -> f64 {
        let s = s_mm.clamp(0.0, self.length_mm);
        let (d_acc, d_dec) = (self.accel_length_mm(), self.decel_length_mm());
        if s < d_acc {
            (self.entry_mm_s.powi(2) + 2.0 * self.accel_mm_s2 * s).sqrt().min(self.cruise_mm_s)
        } else if s <= self.length_mm - d_dec {
            self.cruise_mm_s
        } else {
            let left = self.length_mm - s;
            (self.exit_mm_s.powi(2) + 2.0 * self.accel_mm_s2 * left).sqrt().min(self.cruise_mm_s)
        }
    }

    /// Time from the move's start to `s_mm` along it (clamped to the move; s).
    pub fn time_at_mm(&self, s_mm: f64) -> f64 {
        if self.length_mm <= MIN_LENGTH_MM {
            return self.duration_s;
        }
        let s = s_mm.clamp(0.0, self.length_mm);
        let (a, c) = (self.accel_mm_s2, self.cruise_mm_s);
        let (d_acc, d_dec) = (self.accel_length_mm(), self.decel_length_mm());
        let t_acc = (c - self.entry_mm_s) / a;
        if s < d_acc {
            return (self.speed_at_mm(s) - self.entry_mm_s) / a;
        }
        let cruise_end = self.length_mm - d_dec;
        if s <= cruise_end {
            return t_acc + (s - d_acc) / c;
        }
        t_acc + (cruise_end - d_acc) / c + (c - self.speed_at_mm(s)) / a
    }
}

/// A move the planner cannot plan.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PlanError {
    /// A quantity is zero, negative or not finite.
    #[error("move {index}: {name} must be positive and finite, got {value}")]
    NotPositive {
        /// Index of the move in the queue.
        index: usize,
        /// Which quantity.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// A position or the filament is not finite.
    #[error("move {index}: positions and filament must be finite")]
    NotFinite {
        /// Index of the move in the queue.
        index: usize,
    },
}

/// Plans every move of `moves` (in G-code order) as the firmware's look-ahead does over
/// the whole queue, from rest to rest.
pub fn plan(moves: &[Move]) -> Result<Vec<PlannedMove>, PlanError> {
    for (index, m) in moves.iter().enumerate() {
        check_move(index, m)?;
    }
    let mut planned = Vec::with_capacity(moves.len());
    let mut chain_start = 0;
    for (i, m) in moves.iter().enumerate() {
        if !m.is_kinematic() {
            planned.extend(plan_chain(&moves[chain_start..i]));
            planned.push(extrude_only(m));
            chain_start = i + 1;
        }
    }
    planned.extend(plan_chain(&moves[chain_start..]));
    Ok(planned)
}

fn check_move(index: usize, m: &Move) -> Result<(), PlanError> {
    let finite = m.start_mm.iter().chain(&m.end_mm).all(|x| x.is_finite()) && m.filament_mm.is_finite();
    if !finite {
        return Err(PlanError::NotFinite { index });
    }
    let l = &m.limits;
    let mut checks = vec![
        ("feed_mm_s", m.feed_mm_s),
        ("accel_mm_s2", l.accel_mm_s2),
        ("accel_to_decel_mm_s2", l.accel_to_decel_mm_s2),
    ];
    match l.cornering {
        Cornering::SquareCorner { velocity_mm_s, extruder_corner_mm_s } => {
            checks.push(("square_corner_velocity_mm_s", velocity_mm_s));
            checks.push(("extruder_corner_mm_s", extruder_corner_mm_s));
        }
        Cornering::JunctionDeviation { deviation_mm } => checks.push(("junction_deviation_mm", deviation_mm)),
        Cornering::ClassicJerk { jerk_x_mm_s, jerk_y_mm_s, jerk_z_mm_s } => {
            checks.extend([("jerk_x_mm_s", jerk_x_mm_s), ("jerk_y_mm_s", jerk_y_mm_s), ("jerk_z_mm_s", jerk_z_mm_s)]);
        }
    }
    if let Some(&(name, value)) = checks.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
        return Err(PlanError::NotPositive { index, name, value });
    }
    if l.max_velocity_mm_s.is_nan() || l.max_velocity_mm_s <= 0.0 {
        return Err(PlanError::NotPositive { index, name: "max_velocity_mm_s", value: l.max_velocity_mm_s });
    }
    Ok(())
}

/// An E-only move: no XYZ motion; the filament moves at the feed.
fn extrude_only(m: &Move) -> PlannedMove {
    PlannedMove {
        length_mm: 0.0,
        entry_mm_s: 0.0,
        cruise_mm_s: 0.0,
        exit_mm_s: 0.0,
        accel_mm_s2: m.limits.accel_mm_s2,
        duration_s: m.filament_mm.abs() / m.feed_mm_s,
    }
}

/// Plans a queue of moves that all have XYZ length, from rest to rest.
fn plan_chain(moves: &[Move]) -> Vec<PlannedMove> {
    let n = moves.len();
    if n == 0 {
        return Vec::new();
    }
    // Joint i is the start of move i; joint n the end of the last move.
    let mut joint_max_v2 = vec![0.0; n + 1];
    joint_max_v2[0] = start_from_rest_mm_s(&moves[0]).powi(2);
    for i in 1..n {
        joint_max_v2[i] = junction_v2(&moves[i - 1], &moves[i]);
    }
    let accel: Vec<f64> = moves.iter().map(|m| m.limits.accel_mm_s2).collect();
    let smooth_accel: Vec<f64> =
        moves.iter().map(|m| m.limits.accel_to_decel_mm_s2.min(m.limits.accel_mm_s2)).collect();
    let lengths: Vec<f64> = moves.iter().map(Move::length_mm).collect();
    let smoothed = reachable_joints_v2(&joint_max_v2, &lengths, &smooth_accel);
    let caps: Vec<f64> = (0..n)
        .map(|i| moves[i].cruise_cap_v2().min(peak_v2(smoothed[i], smoothed[i + 1], smooth_accel[i], lengths[i])))
        .collect();
    for i in 0..=n {
        let before = if i > 0 { caps[i - 1] } else { f64::INFINITY };
        let after = if i < n { caps[i] } else { f64::INFINITY };
        joint_max_v2[i] = joint_max_v2[i].min(before).min(after);
    }
    let joints = reachable_joints_v2(&joint_max_v2, &lengths, &accel);
    (0..n)
        .map(|i| {
            let cruise_v2 = caps[i].min(peak_v2(joints[i], joints[i + 1], accel[i], lengths[i]));
            PlannedMove::trapezoid(lengths[i], joints[i].sqrt(), cruise_v2.sqrt(), joints[i + 1].sqrt(), accel[i])
        })
        .collect()
}

/// Joint speeds² within the joints' limits that every move can reach from the one
/// before and stop from by the end: the backward then the forward pass.
fn reachable_joints_v2(max_v2: &[f64], lengths: &[f64], accel: &[f64]) -> Vec<f64> {
    let mut v2 = max_v2.to_vec();
    for i in (0..lengths.len()).rev() {
        v2[i] = v2[i].min(v2[i + 1] + 2.0 * accel[i] * lengths[i]);
    }
    for i in 0..lengths.len() {
        v2[i + 1] = v2[i + 1].min(v2[i] + 2.0 * accel[i] * lengths[i]);
    }
    v2
}

/// The top speed² of a triangle from `v0²` to `v1²` over `length_mm` at `accel`.
fn peak_v2(v0_2: f64, v1_2: f64, accel: f64, length_mm: f64) -> f64 {
    0.5 * (v0_2 + v1_2) + accel * length_mm
}

/// The speed a move may start at from rest (mm/s).
pub fn start_from_rest_mm_s(m: &Move) -> f64 {
    match m.limits.cornering {
        Cornering::ClassicJerk { .. } => safe_speed_mm_s(m),
        _ => 0.0,
    }
}

/// Marlin's safe speed: no axis's speed above its jerk (mm/s).
fn safe_speed_mm_s(m: &Move) -> f64 {
    let Cornering::ClassicJerk { jerk_x_mm_s, jerk_y_mm_s, jerk_z_mm_s } = m.limits.cornering else {
        return 0.0;
    };
    let u = m.direction();
    let jerks = [jerk_x_mm_s, jerk_y_mm_s, jerk_z_mm_s];
    let mut v = m.cruise_cap_v2().sqrt();
    for k in 0..3 {
        if u[k].abs() > 0.0 {
            v = v.min(jerks[k] / u[k].abs());
        }
    }
    v
}

/// The largest speed² through the joint from `prev` into `next` (both with length).
pub fn junction_v2(prev: &Move, next: &Move) -> f64 {
    let cap = prev.cruise_cap_v2().min(next.cruise_cap_v2());
    let (p, u) = (prev.direction(), next.direction());
    match next.limits.cornering {
        Cornering::SquareCorner { velocity_mm_s, extruder_corner_mm_s } => {
            let deviation_mm = velocity_mm_s.powi(2) * (2f64.sqrt() - 1.0) / next.limits.accel_mm_s2;
            let extruder = extruder_junction_v2(prev, next, extruder_corner_mm_s);
            cap.min(deviation_junction_v2(prev, next, deviation_mm, true)).min(extruder)
        }
        Cornering::JunctionDeviation { deviation_mm } => {
            cap.min(deviation_junction_v2(prev, next, deviation_mm, false))
        }
        Cornering::ClassicJerk { jerk_x_mm_s, jerk_y_mm_s, jerk_z_mm_s } => {
            let jerks = [jerk_x_mm_s, jerk_y_mm_s, jerk_z_mm_s];
            let mut v = cap.sqrt();
            for k in 0..3 {
                let jump = axis_jump(p[k], u[k]);
                if jump > 0.0 {
                    v = v.min(jerks[k] / jump);
                }
            }
            // Marlin: when both moves could start from rest faster, the joint may too.
            let (safe_prev, safe_next) = (safe_speed_mm_s(prev), safe_speed_mm_s(next));
            if safe_prev > 0.99 * v && safe_next > 0.99 * v {
                v = safe_next;
            }
            v * v
        }
    }
}

/// The jump of one axis's speed per unit joint speed, from direction component `p` to
/// `u`: the difference when it keeps its sense, the larger magnitude when it reverses.
fn axis_jump(p: f64, u: f64) -> f64 {
    if p * u >= 0.0 && !(p == 0.0 || u == 0.0) {
        (u - p).abs()
    } else {
        p.abs().max(u.abs())
    }
}

/// Junction deviation's limit for the angle between the moves; with `arc_within_half`
/// also Klipper's limit that the virtual arc touch each move within its first half.
fn deviation_junction_v2(prev: &Move, next: &Move, deviation_mm: f64, arc_within_half: bool) -> f64 {
    let (p, u) = (prev.direction(), next.direction());
    let cos_theta = -(p[0] * u[0] + p[1] * u[1] + p[2] * u[2]);
    let sin_half = (0.5 * (1.0 - cos_theta)).max(0.0).sqrt();
    let cos_half = (0.5 * (1.0 + cos_theta)).max(0.0).sqrt();
    if 1.0 - sin_half <= 0.0 || cos_half <= 0.0 {
        return f64::INFINITY;
    }
    let r = sin_half / (1.0 - sin_half);
    let mut v2 = r * deviation_mm * next.limits.accel_mm_s2;
    if arc_within_half {
        let quarter_tan = 0.25 * sin_half / cos_half;
        let delta = |m: &Move| 2.0 * m.length_mm() * m.limits.accel_mm_s2;
        v2 = v2.min(delta(next) * quarter_tan).min(delta(prev) * quarter_tan);
    }
    v2
}

/// Klipper's extruder joint limit: the filament speed may jump by at most
/// `extruder_corner_mm_s`.
fn extruder_junction_v2(prev: &Move, next: &Move, extruder_corner_mm_s: f64) -> f64 {
    let diff = (next.filament_per_mm() - prev.filament_per_mm()).abs();
    if diff > 0.0 {
        (extruder_corner_mm_s / diff).powi(2)
    } else {
        f64::INFINITY
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(d: [f64; 3]) -> f64 {
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    const A: f64 = 1000.0;

    fn klipper(scv_mm_s: f64, min_cruise_ratio: f64) -> MotionLimits {
        MotionLimits {
            accel_mm_s2: A,
            accel_to_decel_mm_s2: A * (1.0 - min_cruise_ratio),
            max_velocity_mm_s: f64::INFINITY,
            cornering: Cornering::SquareCorner { velocity_mm_s: scv_mm_s, extruder_corner_mm_s: 1.0 },
        }
    }

    fn marlin_jerk(jerk_mm_s: f64) -> MotionLimits {
        MotionLimits {
            accel_mm_s2: A,
            accel_to_decel_mm_s2: A,
            max_velocity_mm_s: f64::INFINITY,
            cornering: Cornering::ClassicJerk { jerk_x_mm_s: jerk_mm_s, jerk_y_mm_s: jerk_mm_s, jerk_z_mm_s: 0.3 },
        }
    }

    /// Moves through `points` (x, y at z 0.2), each at its feed, extruding 0.05 mm/mm.
    fn path(points: &[[f64; 2]], feeds_mm_s: &[f64], limits: MotionLimits) -> Vec<Move> {
        points
            .windows(2)
            .zip(feeds_mm_s)
            .map(|(w, &feed_mm_s)| {
                let (start_mm, end_mm) = ([w[0][0], w[0][1], 0.2], [w[1][0], w[1][1], 0.2]);
                let filament_mm = 0.05 * norm(sub(end_mm, start_mm));
                Move { start_mm, end_mm, filament_mm, feed_mm_s, limits, pressure_advance: PressureAdvance::default() }
            })
            .collect()
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn a_long_move_reaches_the_feed_with_v_over_a_ramps() {
        let p = plan(&path(&[[0.0, 0.0], [100.0, 0.0]], &[50.0], klipper(5.0, 0.0))).unwrap();
        let m = p[0];
        assert_eq!((m.entry_mm_s, m.cruise_mm_s, m.exit_mm_s), (0.0, 50.0, 0.0));
        assert!(close(m.time_at_mm(m.accel_length_mm()), 50.0 / A, 1e-12));
        assert!(close(m.accel_length_mm(), 50.0 * 50.0 / (2.0 * A), 1e-12));
        // 2 ramps of v/a each, the rest at the feed.
        let expected_s = 2.0 * 50.0 / A + (100.0 - 2.0 * 1.25) / 50.0;
        assert!(close(m.duration_s, expected_s, 1e-12), "{}", m.duration_s);
    }

    #[test]
    fn a_short_move_is_a_triangle_with_peak_root_a_l() {
        let p = plan(&path(&[[0.0, 0.0], [2.0, 0.0]], &[200.0], klipper(5.0, 0.0))).unwrap();
        assert!(close(p[0].cruise_mm_s, (A * 2.0f64).sqrt(), 1e-9), "{:?}", p[0]);
        assert!(close(p[0].speed_at_mm(1.0), (A * 2.0f64).sqrt(), 1e-9));
        // Marlin starts and stops at the jerk: v0 = 10, peak² = v0² + a·L at the middle
        // only when v1 = v0; Marlin ends at rest, so peak² = v0²/2 + a·L.
        let p = plan(&path(&[[0.0, 0.0], [2.0, 0.0]], &[200.0], marlin_jerk(10.0))).unwrap();
        assert_eq!(p[0].entry_mm_s, 10.0);
        assert!(close(p[0].cruise_mm_s, (50.0 + A * 2.0f64).sqrt(), 1e-9), "{:?}", p[0]);
    }

    #[test]
    fn minimum_cruise_ratio_caps_the_peak_of_a_short_move() {
        let p = plan(&path(&[[0.0, 0.0], [2.0, 0.0]], &[200.0], klipper(5.0, 0.5))).unwrap();
        assert!(close(p[0].cruise_mm_s, (0.5 * A * 2.0f64).sqrt(), 1e-9), "{:?}", p[0]);
        // Half the move cruises.
        let cruise_mm = p[0].length_mm - p[0].accel_length_mm() - p[0].decel_length_mm();
        assert!(close(cruise_mm, 1.0, 1e-9), "{cruise_mm}");
    }

    #[test]
    fn collinear_moves_keep_their_speed_across_the_joint() {
        let moves = path(&[[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]], &[50.0, 50.0], klipper(5.0, 0.5));
        let p = plan(&moves).unwrap();
        assert_eq!(p[0].exit_mm_s, 50.0);
        assert_eq!(p[1].entry_mm_s, 50.0);
        // Straight on, only the feed limits the joint (Klipper: no limit at 180°).
        assert_eq!(junction_v2(&moves[0], &moves[1]), 2500.0);
    }

    #[test]
    fn a_right_angle_with_klipper_passes_at_the_square_corner_velocity() {
        let moves = path(&[[0.0, 0.0], [50.0, 0.0], [50.0, 50.0]], &[100.0, 100.0], klipper(5.0, 0.0));
        assert!(close(junction_v2(&moves[0], &moves[1]).sqrt(), 5.0, 1e-9));
        let p = plan(&moves).unwrap();
        assert!(close(p[0].exit_mm_s, 5.0, 1e-9) && close(p[1].entry_mm_s, 5.0, 1e-9), "{p:?}");
        // 135° of turn (45° between the lines) is slower, straight on faster.
        let sharp = path(&[[0.0, 0.0], [50.0, 0.0], [0.0, 50.0]], &[100.0, 100.0], klipper(5.0, 0.0));
        assert!(junction_v2(&sharp[0], &sharp[1]).sqrt() < 5.0);
    }

    #[test]
    fn a_right_angle_with_marlin_jerk_passes_at_the_jerk() {
        let moves = path(&[[0.0, 0.0], [50.0, 0.0], [50.0, 50.0]], &[100.0, 100.0], marlin_jerk(8.0));
        assert!(close(junction_v2(&moves[0], &moves[1]).sqrt(), 8.0, 1e-9));
        // A 45° move from rest starts where each axis runs at the jerk: 8·√2.
        let diagonal = path(&[[0.0, 0.0], [50.0, 50.0]], &[100.0], marlin_jerk(8.0));
        assert!(close(plan(&diagonal).unwrap()[0].entry_mm_s, 8.0 * 2f64.sqrt(), 1e-9));
    }

    #[test]
    fn time_integrates_to_length() {
        let moves = path(
            &[[0.0, 0.0], [3.88, 0.0], [27.16, 0.0], [38.8, 0.0], [38.8, 10.0]],
            &[10.0, 100.0, 10.0, 30.0],
            klipper(5.0, 0.5),
        );
        for m in plan(&moves).unwrap() {
            // ∫ v dt by the midpoint rule over time: step in s, dt = ds / v.
            let steps = 20_000;
            let mut length = 0.0;
            for k in 0..steps {
                let (t0, t1) = (k as f64 / steps as f64, (k + 1) as f64 / steps as f64);
                let (s0, s1) = (t0 * m.length_mm, t1 * m.length_mm);
                let dt = m.time_at_mm(s1) - m.time_at_mm(s0);
                length += m.speed_at_mm(0.5 * (s0 + s1)) * dt;
            }
            assert!(close(length, m.length_mm, 1e-4 * m.length_mm), "{length} vs {m:?}");
        }
    }

    #[test]
    fn an_extrude_only_move_is_a_stop() {
        let mut moves = path(&[[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]], &[50.0, 50.0], klipper(5.0, 0.0));
        let retract =
            Move { start_mm: moves[0].end_mm, end_mm: moves[0].end_mm, filament_mm: -0.8, feed_mm_s: 40.0, ..moves[0] };
        moves.insert(1, retract);
        let p = plan(&moves).unwrap();
        assert_eq!((p[0].exit_mm_s, p[2].entry_mm_s), (0.0, 0.0));
        assert!(close(p[1].duration_s, 0.02, 1e-12));
    }

    #[test]
    fn the_extruder_limits_a_joint_where_the_flow_changes() {
        let mut moves = path(&[[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]], &[100.0, 100.0], klipper(5.0, 0.0));
        moves[1].filament_mm = 0.0;
        // 0.05 mm of filament per mm stops: 1 mm/s / 0.05 = 20 mm/s.
        assert!(close(plan(&moves).unwrap()[0].exit_mm_s, 20.0, 1e-9));
    }

    #[test]
    fn bad_numbers_are_refused_by_move() {
        let mut moves = path(&[[0.0, 0.0], [50.0, 0.0]], &[0.0], klipper(5.0, 0.0));
        let err = plan(&moves).unwrap_err().to_string();
        assert!(err.contains("move 0: feed_mm_s"), "{err}");
        moves[0].feed_mm_s = 10.0;
        moves[0].end_mm[0] = f64::NAN;
        assert_eq!(plan(&moves).unwrap_err(), PlanError::NotFinite { index: 0 });
    }
}
