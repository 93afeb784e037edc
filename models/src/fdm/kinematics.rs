//! Nozzle kinematics of one straight printed line (paper 000, Sec. II-A and eq. 1).
//!
//! The data's authors assume a single straight line of length `L`: the nozzle starts at
//! the jerk speed `v0` (8 mm/s), accelerates at a constant `a` to the target feed `F`,
//! cruises, and decelerates at `a` back to `v0` exactly at `x = L`. When the line is too
//! short to reach `F` the profile is triangular with peak speed `sqrt(v0² + a·L)` (the
//! paper's first special case). Actual values are `a = r_a·a0`, `F = r_F·F0` (eq. 1).
//!
//! Breakpoints in the paper's notation: `bp2` is where acceleration ends, `bp4` where
//! deceleration starts (equal in the triangular case). All closed forms follow from
//! `v² = v0² + 2·a·x` and `v = v0 + a·t`.

use super::errors::KinematicsError;

/// The motion phase of the nozzle at a point of the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MotionPhase {
    /// Speeding up from the jerk speed (before `bp2`).
    Accelerating,
    /// Constant speed at the target feed (between `bp2` and `bp4`).
    Cruise,
    /// Slowing down to the jerk speed (after `bp4`).
    Decelerating,
}

/// Trapezoidal (or triangular) speed profile of one straight line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineKinematics {
    /// Acceleration and deceleration magnitude (mm/s²).
    pub accel_mm_s2: f64,
    /// Target feed (mm/s).
    pub feed_mm_s: f64,
    /// Start and end speed, the planner's jerk (mm/s).
    pub jerk_mm_s: f64,
    /// Line length (mm).
    pub length_mm: f64,
}

/// Kinematic state at the given sample positions (see [`LineKinematics::sample`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct KinematicSamples {
    /// Positions along the line (mm), as given.
    pub positions_mm: Vec<f64>,
    /// Nominal time at which the nozzle passes each position (s).
    pub time_s: Vec<f64>,
    /// Nozzle speed (mm/s).
    pub speed_mm_s: Vec<f64>,
    /// Signed acceleration (mm/s²): `+a`, `0` or `-a`.
    pub accel_mm_s2: Vec<f64>,
    /// Motion phase.
    pub phase: Vec<MotionPhase>,
}

impl LineKinematics {
    /// The paper's jerk (start/end speed) in mm/s (Sec. II-A, "the jerk is a fixed value of 8 mm/s").
    pub const PAPER_JERK_MM_S: f64 = 8.0;
    /// The paper's line length in mm (the data's 120 mm lines).
    pub const PAPER_LENGTH_MM: f64 = 120.0;

    /// A checked profile. Errors if a value is not positive or the feed does not exceed
    /// the jerk speed.
    pub fn new(accel_mm_s2: f64, feed_mm_s: f64, jerk_mm_s: f64, length_mm: f64) -> Result<Self, KinematicsError> {
        for (name, value) in
            [("accel_mm_s2", accel_mm_s2), ("feed_mm_s", feed_mm_s), ("jerk_mm_s", jerk_mm_s), ("length_mm", length_mm)]
        {
            if !(value.is_finite() && value > 0.0) {
                return Err(KinematicsError::NotPositive { name, value });
            }
        }
        if feed_mm_s <= jerk_mm_s {
            return Err(KinematicsError::FeedNotAboveJerk { feed_mm_s, jerk_mm_s });
        }
        Ok(Self { accel_mm_s2, feed_mm_s, jerk_mm_s, length_mm })
    }

    /// A paper line (jerk 8 mm/s, 120 mm) with the given nominal acceleration and feed.
    pub fn paper_line(accel_mm_s2: f64, feed_mm_s: f64) -> Result<Self, KinematicsError> {
        Self::new(accel_mm_s2, feed_mm_s, Self::PAPER_JERK_MM_S, Self::PAPER_LENGTH_MM)
    }

    /// The actual profile `a = r_a·a0`, `F = r_F·F0` of eq. 1 from this nominal one.
    pub fn scaled(&self, r_a: f64, r_f: f64) -> Result<Self, KinematicsError> {
        Self::new(r_a * self.accel_mm_s2, r_f * self.feed_mm_s, self.jerk_mm_s, self.length_mm)
    }

    /// Whether the line is long enough to reach the target feed (a cruise phase exists,
    /// possibly of zero length).
    pub fn has_cruise(&self) -> bool {
        2.0 * self.ramp_length_to_feed_mm() <= self.length_mm
    }

    /// Highest speed reached (mm/s): `F`, or `sqrt(v0² + a·L)` for a triangular profile.
    pub fn peak_speed_mm_s(&self) -> f64 {
        if self.has_cruise() {
            self.feed_mm_s
        } else {
            (self.jerk_mm_s.powi(2) + self.accel_mm_s2 * self.length_mm).sqrt()
        }
    }

    /// Position where acceleration ends (bp2, mm): `(v_peak² − v0²) / (2a)`.
    pub fn accel_end_mm(&self) -> f64 {
        (self.peak_speed_mm_s().powi(2) - self.jerk_mm_s.powi(2)) / (2.0 * self.accel_mm_s2)
    }

    /// Time when acceleration ends (bp2, s): `(v_peak − v0) / a`.
    pub fn accel_end_s(&self) -> f64 {
        (self.peak_speed_mm_s() - self.jerk_mm_s) / self.accel_mm_s2
    }

    /// Position where deceleration starts (bp4, mm): `L − x_acc`.
    pub fn decel_start_mm(&self) -> f64 {
        if self.has_cruise() {
            self.length_mm - self.accel_end_mm()
        } else {
            self.accel_end_mm()
        }
    }

    /// Time when deceleration starts (bp4, s): `t_acc + (x_dec − x_acc) / v_peak`.
    pub fn decel_start_s(&self) -> f64 {
        if self.has_cruise() {
            self.accel_end_s() + (self.decel_start_mm() - self.accel_end_mm()) / self.peak_speed_mm_s()
        } else {
            self.accel_end_s()
        }
    }

    /// Total time of the move (s): `bp4 + t_acc` (the ramps are symmetric).
    pub fn total_time_s(&self) -> f64 {
        self.decel_start_s() + self.accel_end_s()
    }

    /// Motion phase at a position (clamped to `[0, L]`). The boundaries `x_acc` and
    /// `x_dec` belong to the cruise phase.
    pub fn phase_at_position(&self, x_mm: f64) -> MotionPhase {
        let x = self.clamp_position(x_mm);
        if x < self.accel_end_mm() {
            MotionPhase::Accelerating
        } else if x <= self.decel_start_mm() {
            MotionPhase::Cruise
        } else {
            MotionPhase::Decelerating
        }
    }

    /// Nozzle speed at a position (mm/s), from `v² = v0² + 2·a·x` on the ramps.
    pub fn speed_at_position(&self, x_mm: f64) -> f64 {
        let x = self.clamp_position(x_mm);
        let v0_sq = self.jerk_mm_s.powi(2);
        match self.phase_at_position(x) {
            MotionPhase::Accelerating => (v0_sq + 2.0 * self.accel_mm_s2 * x).sqrt(),
            MotionPhase::Cruise => self.peak_speed_mm_s(),
            MotionPhase::Decelerating => {
                let remaining = self.length_mm - x;
                (v0_sq + 2.0 * self.accel_mm_s2 * remaining).sqrt()
            }
        }
    }

    /// Nominal time at which the nozzle passes a position (s).
    pub fn time_at_position(&self, x_mm: f64) -> f64 {
        let x = self.clamp_position(x_mm);
        let v = self.speed_at_position(x);
        match self.phase_at_position(x) {
            MotionPhase::Accelerating => (v - self.jerk_mm_s) / self.accel_mm_s2,
            MotionPhase::Cruise => self.accel_end_s() + (x - self.accel_end_mm()) / self.peak_speed_mm_s(),
            MotionPhase::Decelerating => self.decel_start_s() + (self.peak_speed_mm_s() - v) / self.accel_mm_s2,
        }
    }

    /// Signed acceleration at a position (mm/s²).
    pub fn accel_at_position(&self, x_mm: f64) -> f64 {
        match self.phase_at_position(x_mm) {
            MotionPhase::Accelerating => self.accel_mm_s2,
            MotionPhase::Cruise => 0.0,
            MotionPhase::Decelerating => -self.accel_mm_s2,
        }
    }

    /// Nozzle speed at a time (mm/s), clamped to `[0, total_time]`.
    pub fn speed_at_time(&self, t_s: f64) -> f64 {
        let t = t_s.clamp(0.0, self.total_time_s());
        if t < self.accel_end_s() {
            self.jerk_mm_s + self.accel_mm_s2 * t
        } else if t <= self.decel_start_s() {
            self.peak_speed_mm_s()
        } else {
            self.peak_speed_mm_s() - self.accel_mm_s2 * (t - self.decel_start_s())
        }
    }

    /// Position at a time (mm), clamped to `[0, total_time]`; the inverse of
    /// [`Self::time_at_position`].
    pub fn position_at_time(&self, t_s: f64) -> f64 {
        let t = t_s.clamp(0.0, self.total_time_s());
        let (v0, a) = (self.jerk_mm_s, self.accel_mm_s2);
        if t < self.accel_end_s() {
            v0 * t + 0.5 * a * t * t
        } else if t <= self.decel_start_s() {
            self.accel_end_mm() + self.peak_speed_mm_s() * (t - self.accel_end_s())
        } else {
            let dt = t - self.decel_start_s();
            self.decel_start_mm() + self.peak_speed_mm_s() * dt - 0.5 * a * dt * dt
        }
    }

    /// Kinematic state at each of the given positions.
    pub fn sample(&self, positions_mm: &[f64]) -> KinematicSamples {
        KinematicSamples {
            positions_mm: positions_mm.to_vec(),
            time_s: positions_mm.iter().map(|&x| self.time_at_position(x)).collect(),
            speed_mm_s: positions_mm.iter().map(|&x| self.speed_at_position(x)).collect(),
            accel_mm_s2: positions_mm.iter().map(|&x| self.accel_at_position(x)).collect(),
            phase: positions_mm.iter().map(|&x| self.phase_at_position(x)).collect(),
        }
    }

    /// Writes the time and speed at each position into the given buffers (no allocation;
    /// the hot-loop form of [`Self::sample`], with the breakpoints computed once).
    pub fn time_and_speed_into(&self, positions_mm: &[f64], time_s: &mut [f64], speed: &mut [f64]) {
        let (v0, a, top) = (self.jerk_mm_s, self.accel_mm_s2, self.peak_speed_mm_s());
        let (x_acc, x_dec) = (self.accel_end_mm(), self.decel_start_mm());
        let (t_acc, t_dec) = (self.accel_end_s(), self.decel_start_s());
        let v0_sq = v0 * v0;
        for ((x, t), v) in positions_mm.iter().zip(time_s).zip(speed) {
            let x = self.clamp_position(*x);
            if x < x_acc {
                *v = (v0_sq + 2.0 * a * x).sqrt();
                *t = (*v - v0) / a;
            } else if x <= x_dec {
                *v = top;
                *t = t_acc + (x - x_acc) / top;
            } else {
                *v = (v0_sq + 2.0 * a * (self.length_mm - x)).sqrt();
                *t = t_dec + (top - *v) / a;
            }
        }
    }

    /// Length of one ramp from the jerk speed to the target feed (mm).
    fn ramp_length_to_feed_mm(&self) -> f64 {
        (self.feed_mm_s.powi(2) - self.jerk_mm_s.powi(2)) / (2.0 * self.accel_mm_s2)
    }

    fn clamp_position(&self, x_mm: f64) -> f64 {
        x_mm.clamp(0.0, self.length_mm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    #[test]
    fn trapezoid_closed_forms() {
        // a = 600, F = 100, v0 = 8: x_acc = (F² − v0²)/(2a), t_acc = (F − v0)/a,
        // cruise covers L − 2·x_acc at speed F.
        let k = LineKinematics::paper_line(600.0, 100.0).unwrap();
        let x_acc = (100.0f64.powi(2) - 64.0) / 1200.0;
        let t_acc = 92.0 / 600.0;
        assert!(k.has_cruise());
        assert!(close(k.accel_end_mm(), x_acc, 1e-14));
        assert!(close(k.accel_end_s(), t_acc, 1e-14));
        assert!(close(k.decel_start_mm(), 120.0 - x_acc, 1e-14));
        let t_cruise = (120.0 - 2.0 * x_acc) / 100.0;
        assert!(close(k.decel_start_s(), t_acc + t_cruise, 1e-14));
        assert!(close(k.total_time_s(), 2.0 * t_acc + t_cruise, 1e-14));
        assert!(close(k.time_at_position(120.0), k.total_time_s(), 1e-12));
        assert!(close(k.speed_at_position(120.0), 8.0, 1e-12));
        assert!(close(k.speed_at_position(0.0), 8.0, 1e-12));
    }

    #[test]
    fn triangular_profile_peaks_at_sqrt_v0sq_plus_al() {
        // L = 10 mm at a = 400, F = 150: 2·x_acc = 2·(150² − 64)/800 ≈ 56 mm > 10 mm, so
        // no cruise; symmetric ramps meet at L/2 with v² = v0² + 2a(L/2) = v0² + aL.
        let k = LineKinematics::new(400.0, 150.0, 8.0, 10.0).unwrap();
        assert!(!k.has_cruise());
        let v_peak = (64.0f64 + 400.0 * 10.0).sqrt();
        assert!(close(k.peak_speed_mm_s(), v_peak, 1e-14));
        assert!(close(k.accel_end_mm(), 5.0, 1e-12));
        assert!(close(k.decel_start_mm(), 5.0, 1e-12));
        assert!(close(k.accel_end_s(), k.decel_start_s(), 1e-12));
        assert!(close(k.speed_at_position(5.0), v_peak, 1e-12));
        assert!(close(k.speed_at_position(10.0), 8.0, 1e-12));
    }

    #[test]
    fn speed_and_time_are_continuous_and_monotone() {
        for (a, f) in [(400.0, 150.0), (800.0, 50.0), (600.0, 100.0)] {
            let k = LineKinematics::paper_line(a, f).unwrap();
            let mut prev_t = -1.0;
            for &x in &[k.accel_end_mm(), k.decel_start_mm()] {
                for eps in [1e-9, -1e-9] {
                    assert!((k.speed_at_position(x + eps) - k.speed_at_position(x)).abs() < 1e-5);
                    assert!((k.time_at_position(x + eps) - k.time_at_position(x)).abs() < 1e-8);
                }
            }
            for i in 0..=1200 {
                let t = k.time_at_position(i as f64 * 0.1);
                assert!(t > prev_t);
                prev_t = t;
            }
        }
    }

    #[test]
    fn time_integrates_position() {
        // x(t) = ∫ v dt: integrate the speed in time with Simpson's rule and compare with
        // the position, and check position_at_time inverts time_at_position.
        let k = LineKinematics::paper_line(800.0, 150.0).unwrap();
        let n = 20_000;
        let total = k.total_time_s();
        let h = total / n as f64;
        let mut integral = 0.0;
        for i in 0..n {
            let (t0, t1) = (i as f64 * h, (i + 1) as f64 * h);
            let tm = 0.5 * (t0 + t1);
            integral += h / 6.0 * (k.speed_at_time(t0) + 4.0 * k.speed_at_time(tm) + k.speed_at_time(t1));
        }
        assert!(close(integral, 120.0, 1e-9));
        for i in 0..=240 {
            let x = i as f64 * 0.5;
            assert!((k.position_at_time(k.time_at_position(x)) - x).abs() < 1e-9);
        }
    }

    #[test]
    fn sampler_reports_phases_and_signed_acceleration() {
        let k = LineKinematics::paper_line(400.0, 100.0).unwrap();
        let s = k.sample(&[0.0, 5.0, 60.0, 110.0, 120.0]);
        assert_eq!(s.phase[0], MotionPhase::Accelerating);
        assert_eq!(s.phase[2], MotionPhase::Cruise);
        assert_eq!(s.phase[3], MotionPhase::Decelerating);
        assert_eq!(s.accel_mm_s2[1], 400.0);
        assert_eq!(s.accel_mm_s2[2], 0.0);
        assert_eq!(s.accel_mm_s2[4], -400.0);
        assert!(close(s.speed_mm_s[1], (64.0f64 + 2.0 * 400.0 * 5.0).sqrt(), 1e-14));
        let mut t = vec![0.0; 5];
        let mut v = vec![0.0; 5];
        k.time_and_speed_into(&s.positions_mm, &mut t, &mut v);
        assert_eq!(t, s.time_s);
        assert_eq!(v, s.speed_mm_s);
    }

    #[test]
    fn invalid_profiles_are_rejected() {
        assert!(matches!(
            LineKinematics::new(0.0, 100.0, 8.0, 120.0),
            Err(KinematicsError::NotPositive { name: "accel_mm_s2", .. })
        ));
        assert!(matches!(LineKinematics::new(400.0, 8.0, 8.0, 120.0), Err(KinematicsError::FeedNotAboveJerk { .. })));
        let k = LineKinematics::paper_line(500.0, 100.0).unwrap();
        let s = k.scaled(1.1, 0.9).unwrap();
        assert!(close(s.accel_mm_s2, 550.0, 1e-14) && close(s.feed_mm_s, 90.0, 1e-14));
    }
}
