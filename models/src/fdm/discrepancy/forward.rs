//! The forward model of one printed line with any set of the candidate mechanisms
//! switched on (DESIGN §5.1 and §7). With `q = Q/h` (flow per layer height, mm²/s):
//!
//! ```text
//! motion     a = r_a·a0, F = r_F·F0                      (kinematics_deviation; else 1, 1)
//! command    c(t) = w0·v(t)
//! lag        τ dq₁/dt = (1 − f)c − q₁,  q₁(0) = (1 − f)w0·v0 + b     (b: start blob)
//!            τ is τ + τ_off·sech²(q₁/((1 − f)w0·v_lin))             (nonlinear_lag)
//!            τ₂ dq₂/dt = f·c − q₂,      q₂(0) = f·w0·v0             (two_stage_lag; else f = 0)
//! width      w = (q₁ + q₂)/v                                        (mass conservation)
//!            w ← w0 + E·tanh((w − w0)/E) where w > w0               (width_cap)
//! smoothing  box average over `smoothing_mm` along the path (about a nozzle diameter)
//! factors    w ← w / (1 + k(x/L − ½)),  k = −c_t/(1 + c_t/2)         (bed_tilt: c_t end to end)
//!            w ← w·(1 − S·(v_cmd(x)/v_ref)²)                        (flow_saturation)
//! ```
//!
//! The gear's ripple is applied by the caller, because its phase is per line. The lag
//! is integrated on a time grid that has nodes at the ends of the ramps, where the speed
//! is exactly linear in time, with the exact first-order-hold step (as in
//! [`crate::fdm::lag`]): `u₊ = φu + (1 − φ)v₀ + (v₁ − v₀)(1 − τ(1 − φ)/Δt)`, so the
//! linear lag is exact at the nodes and `φ` is one `exp` per segment. The nonlinear lag
//! freezes its time constant over a step (1 ms on the ramps). The box smoothing is the
//! difference of the running integral of `w` over the nonuniform grid.

use crate::fdm::kinematics::LineKinematics;

/// Time step on the ramps (s): 2 ms is 16 µm of path at the jerk speed.
const RAMP_STEP_S: f64 = 0.002;
/// Time step in the cruise (s), where the width relaxes smoothly.
const CRUISE_STEP_S: f64 = 0.01;

/// Physical parameters of the forward model; a mechanism that is off keeps its
/// neutral value (the plain lag model).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Theta {
    /// Lag time constant τ (s).
    pub tau_s: f64,
    /// Steady-state width w0 (mm).
    pub w0_mm: f64,
    /// Initial flow excess b per layer height (mm²/s).
    pub blob_mm2_s: f64,
    /// Bed tilt: relative width change from start to end, `w(L)/w(0) − 1`.
    pub tilt_width_change: f64,
    /// Flow saturation: relative width loss at `v_ref`.
    pub saturation_loss: f64,
    /// Nonlinear lag: extra time constant at low flow (s).
    pub lag_offset_s: f64,
    /// Nonlinear lag: speed scale of the extra lag (mm/s).
    pub lag_speed_mm_s: f64,
    /// Two-stage lag: slow time constant τ₂ (s).
    pub tau_slow_s: f64,
    /// Two-stage lag: share f of the flow through the slow path.
    pub slow_fraction: f64,
    /// Width cap: largest extra width E (mm); infinite when off.
    pub max_excess_mm: f64,
    /// Kinematics deviation: r_a of eq. 1.
    pub r_a: f64,
    /// Kinematics deviation: r_F of eq. 1.
    pub r_f: f64,
    /// Gear eccentricity: ripple period in path length (mm); NaN when off.
    pub gear_period_mm: f64,
}

impl Theta {
    /// The plain lag model with `τ`, `w0`, `b`.
    pub fn lag(tau_s: f64, w0_mm: f64, blob_mm2_s: f64) -> Self {
        Self {
            tau_s,
            w0_mm,
            blob_mm2_s,
            tilt_width_change: 0.0,
            saturation_loss: 0.0,
            lag_offset_s: 0.0,
            lag_speed_mm_s: 10.0,
            tau_slow_s: 1.0,
            slow_fraction: 0.0,
            max_excess_mm: f64::INFINITY,
            r_a: 1.0,
            r_f: 1.0,
            gear_period_mm: f64::NAN,
        }
    }
}

/// Settings shared by every line of a data set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineSetting {
    /// Box smoothing length along the path (mm).
    pub smoothing_mm: f64,
    /// Reference speed of the flow saturation (mm/s): the data set's fastest feed.
    pub v_ref_mm_s: f64,
}

/// One line's simulation state, reused between calls: the time grid of the current
/// kinematics and, because the linear lags are linear in their input, the unit
/// responses `u_τ` (to `v`, from `u(0) = v0`) and the blob's decay `e^{−t/τ}` of the last
/// time constants seen. A fit's difference steps in `w0`, `b`, `f`, the cap and the
/// factors then reuse them; only a new `τ`, `τ₂` or `(r_a, r_F)` integrates again.
#[derive(Debug, Clone)]
pub struct Scratch {
    grid_key: (f64, f64),
    t: Vec<f64>,
    x: Vec<f64>,
    v: Vec<f64>,
    fast_key: f64,
    unit_fast: Vec<f64>,
    blob: Vec<f64>,
    slow_key: f64,
    unit_slow: Vec<f64>,
    w: Vec<f64>,
    cumulative: Vec<f64>,
}

impl Default for Scratch {
    fn default() -> Self {
        Self {
            grid_key: (f64::NAN, f64::NAN),
            t: Vec::new(),
            x: Vec::new(),
            v: Vec::new(),
            fast_key: f64::NAN,
            unit_fast: Vec::new(),
            blob: Vec::new(),
            slow_key: f64::NAN,
            unit_slow: Vec::new(),
            w: Vec::new(),
            cumulative: Vec::new(),
        }
    }
}

/// One segment of constant acceleration.
#[derive(Clone, Copy)]
struct Segment {
    x0: f64,
    v0: f64,
    accel: f64,
    duration: f64,
    step: f64,
}

fn segments(kin: &LineKinematics) -> [Segment; 3] {
    let (t_acc, t_dec, t_end) = (kin.accel_end_s(), kin.decel_start_s(), kin.total_time_s());
    let (x_acc, x_dec, v_peak) = (kin.accel_end_mm(), kin.decel_start_mm(), kin.peak_speed_mm_s());
    [
        Segment { x0: 0.0, v0: kin.jerk_mm_s, accel: kin.accel_mm_s2, duration: t_acc, step: RAMP_STEP_S },
        Segment { x0: x_acc, v0: v_peak, accel: 0.0, duration: t_dec - t_acc, step: CRUISE_STEP_S },
        Segment { x0: x_dec, v0: v_peak, accel: -kin.accel_mm_s2, duration: t_end - t_dec, step: RAMP_STEP_S },
    ]
}

/// `1/n!` for `n ≤ 17`, the coefficients of the hold's series.
const INVERSE_FACTORIAL: [f64; 18] = {
    let mut t = [1.0; 18];
    let mut n = 1;
    while n < 18 {
        t[n] = t[n - 1] / n as f64;
        n += 1;
    }
    t
};

/// The first-order-hold step of `τ u' = c − u` over a fixed `dt`:
/// `u₊ = φu + (1 − φ)c₀ + (c₁ − c₀)(1 − τ(1 − φ)/Δt)`.
#[derive(Clone, Copy)]
struct Hold {
    phi: f64,
    one_minus: f64,
    ramp: f64,
}

impl Hold {
    /// The step for `z = Δt/τ`; below `z = ½` by the series of `1 − e^{−z}` and of
    /// `1 − (1 − e^{−z})/z` (the second would lose digits to cancellation, and the
    /// nonlinear lag builds a hold every step), exact to rounding.
    fn new(dt: f64, tau: f64) -> Self {
        let z = dt / tau;
        let (one_minus, ramp) = if z < 0.5 {
            // 1 − e^{−z} = Σ_{n≥1} (−1)^{n+1} zⁿ/n!, 1 − (1 − e^{−z})/z = Σ_{n≥1} (−1)^{n+1} zⁿ/(n+1)!,
            // by Horner to the 16th power (the remainder is below z¹⁷/17! < 3e-20).
            let (mut one_minus, mut ramp) = (0.0, 0.0);
            for n in (1..=16).rev() {
                one_minus = z * (INVERSE_FACTORIAL[n] - one_minus);
                ramp = z * (INVERSE_FACTORIAL[n + 1] - ramp);
            }
            (one_minus, ramp)
        } else {
            let one_minus = -(-z).exp_m1();
            (one_minus, 1.0 - one_minus / z)
        };
        Self { phi: 1.0 - one_minus, one_minus, ramp }
    }

    /// The step of the nonlinear lag, whose time constant is frozen over the step (an
    /// error of order Δt·dτ/dt already): below `z = ½` the series to the eighth power
    /// (remainder below z⁹/9! < 6e-9), else exact.
    fn frozen(dt: f64, tau: f64) -> Self {
        let z = dt / tau;
        if z >= 0.5 {
            return Self::new(dt, tau);
        }
        let (mut one_minus, mut ramp) = (0.0, 0.0);
        for n in (1..=8).rev() {
            one_minus = z * (INVERSE_FACTORIAL[n] - one_minus);
            ramp = z * (INVERSE_FACTORIAL[n + 1] - ramp);
        }
        Self { phi: 1.0 - one_minus, one_minus, ramp }
    }

    fn step(&self, u: f64, c0: f64, c1: f64) -> f64 {
        self.phi * u + self.one_minus * c0 + (c1 - c0) * self.ramp
    }
}

/// Simulated widths (mm) at `positions_mm` (ascending) into `out`, without the gear
/// ripple. Returns false when the parameters give no valid motion or width.
pub fn widths(
    theta: &Theta,
    nominal: &LineKinematics,
    setting: &LineSetting,
    positions_mm: &[f64],
    scratch: &mut Scratch,
    out: &mut [f64],
) -> bool {
    let Ok(kin) = nominal.scaled(theta.r_a, theta.r_f) else {
        return false;
    };
    scratch.prepare(theta, &kin);
    scratch.fill_widths(theta);
    let length = kin.length_mm;
    smooth_into(scratch, positions_mm, setting.smoothing_mm, length, out);
    if theta.saturation_loss == 0.0 && theta.tilt_width_change == 0.0 {
        return out.iter().all(|w| w.is_finite());
    }
    for (w, &x) in out.iter_mut().zip(positions_mm) {
        let speed_ratio = nominal.speed_at_position(x) / setting.v_ref_mm_s;
        *w *= width_factor(theta.tilt_width_change, theta.saturation_loss, speed_ratio, x.clamp(0.0, length) / length);
    }
    out.iter().all(|w| w.is_finite())
}

/// The width factor of a bed tilt `c_t` (width change end to end) and a flow
/// saturation `S` at the fraction `u = x/L` of the line, where the commanded speed is
/// `speed_ratio` times the reference: `(1 − S·speed_ratio²) / (1 + k(u − ½))`,
/// `k = −c_t/(1 + c_t/2)`.
pub fn width_factor(tilt_width_change: f64, saturation_loss: f64, speed_ratio: f64, u: f64) -> f64 {
    let k_tilt = -tilt_width_change / (1.0 + tilt_width_change / 2.0);
    (1.0 - saturation_loss * speed_ratio.powi(2)) / (1.0 + k_tilt * (u - 0.5))
}

impl Scratch {
    /// Brings the grid and the cached unit responses up to `theta` and `kin`.
    fn prepare(&mut self, theta: &Theta, kin: &LineKinematics) {
        if self.grid_key != (theta.r_a, theta.r_f) {
            self.build_grid(kin);
            self.grid_key = (theta.r_a, theta.r_f);
            self.fast_key = f64::NAN;
            self.slow_key = f64::NAN;
        }
        if theta.lag_offset_s == 0.0 && self.fast_key != theta.tau_s {
            unit_response(&self.t, &self.v, theta.tau_s, &mut self.unit_fast, Some(&mut self.blob));
            self.fast_key = theta.tau_s;
        }
        if theta.slow_fraction > 0.0 && self.slow_key != theta.tau_slow_s {
            unit_response(&self.t, &self.v, theta.tau_slow_s, &mut self.unit_slow, None);
            self.slow_key = theta.tau_slow_s;
        }
    }

    /// Nodes at the ramps' ends and uniform steps within each segment.
    fn build_grid(&mut self, kin: &LineKinematics) {
        let (t, x, v) = (&mut self.t, &mut self.x, &mut self.v);
        t.clear();
        x.clear();
        v.clear();
        t.push(0.0);
        x.push(0.0);
        v.push(kin.jerk_mm_s);
        let mut t0 = 0.0;
        for seg in segments(kin) {
            if seg.duration <= 0.0 {
                continue;
            }
            let steps = (seg.duration / seg.step).ceil().max(1.0) as usize;
            let dt = seg.duration / steps as f64;
            for j in 1..=steps {
                let tau = j as f64 * dt;
                t.push(t0 + tau);
                v.push(seg.v0 + seg.accel * tau);
                x.push((seg.x0 + seg.v0 * tau + 0.5 * seg.accel * tau * tau).min(kin.length_mm));
            }
            t0 += seg.duration;
        }
    }

    /// Widths at the nodes (mass conservation, then the cap) and their running integral.
    fn fill_widths(&mut self, theta: &Theta) {
        let f = theta.slow_fraction;
        let w0 = theta.w0_mm;
        let n = self.t.len();
        self.w.clear();
        if theta.lag_offset_s > 0.0 {
            nonlinear_fast_flow(theta, &self.t, &self.v, &mut self.w);
        } else {
            let fast = (1.0 - f) * w0;
            self.w.extend((0..n).map(|k| fast * self.unit_fast[k] + theta.blob_mm2_s * self.blob[k]));
        }
        if f > 0.0 {
            for (q, u) in self.w.iter_mut().zip(&self.unit_slow) {
                *q += f * w0 * u;
            }
        }
        let capped = theta.max_excess_mm.is_finite();
        for (q, v) in self.w.iter_mut().zip(&self.v) {
            let w = *q / v;
            let excess = w - w0;
            *q = if capped && excess > 0.0 {
                w0 + theta.max_excess_mm * (excess / theta.max_excess_mm).tanh()
            } else {
                w
            };
        }
        self.cumulative.clear();
        self.cumulative.push(0.0);
        for k in 1..n {
            let c = self.cumulative[k - 1] + 0.5 * (self.w[k] + self.w[k - 1]) * (self.x[k] - self.x[k - 1]).max(0.0);
            self.cumulative.push(c);
        }
    }
}

/// Unit response `u` of `τ u' = v − u`, `u(0) = v(0)`, on the grid (exact first-order
/// hold), and optionally the free decay `e^{−t/τ}` (the blob's shape) by the same `φ`.
fn unit_response(t: &[f64], v: &[f64], tau: f64, u: &mut Vec<f64>, mut decay: Option<&mut Vec<f64>>) {
    u.clear();
    u.push(v[0]);
    if let Some(d) = decay.as_deref_mut() {
        d.clear();
        d.push(1.0);
    }
    let mut hold = Hold::new(1.0, tau);
    let mut last_dt = f64::NAN;
    for k in 1..t.len() {
        let dt = t[k] - t[k - 1];
        if dt != last_dt {
            hold = Hold::new(dt, tau);
            last_dt = dt;
        }
        let next = hold.step(u[k - 1], v[k - 1], v[k]);
        u.push(next);
        if let Some(d) = decay.as_deref_mut() {
            let prev = d[k - 1];
            d.push(prev * hold.phi);
        }
    }
}

/// The fast path's flow of the nonlinear lag, `τ(q) = τ + τ_off·sech²(q/((1−f)w0·v_lin))`,
/// with the time constant frozen over each step; the start blob is its initial excess.
fn nonlinear_fast_flow(theta: &Theta, t: &[f64], v: &[f64], q: &mut Vec<f64>) {
    let share = (1.0 - theta.slow_fraction) * theta.w0_mm;
    let scale = (share * theta.lag_speed_mm_s).max(1e-12);
    q.push(share * v[0] + theta.blob_mm2_s);
    for k in 1..t.len() {
        let prev = q[k - 1];
        let sech = 1.0 / (prev / scale).cosh();
        let hold = Hold::frozen(t[k] - t[k - 1], theta.tau_s + theta.lag_offset_s * sech * sech);
        q.push(hold.step(prev, share * v[k - 1], share * v[k]));
    }
}

/// Box average over `window` of the simulated width at each position (the window is
/// cut at the line's ends), or the width itself when `window` is 0. Between nodes the
/// width is linear, so its running integral is quadratic and the box is exact for it.
fn smooth_into(s: &Scratch, positions: &[f64], window: f64, length: f64, out: &mut [f64]) {
    let half = 0.5 * window;
    let (mut lo, mut hi) = (Pointer::default(), Pointer::default());
    for (o, &p) in out.iter_mut().zip(positions) {
        let (a, b) = ((p - half).max(0.0), (p + half).min(length));
        *o = if b - a > 1e-9 {
            (hi.integral(s, b) - lo.integral(s, a)) / (b - a)
        } else {
            hi.width(s, p.clamp(0.0, length))
        };
    }
}

/// A forward-only position in the node list (the positions asked for are ascending).
#[derive(Default)]
struct Pointer(usize);

impl Pointer {
    /// Moves to the node interval holding `x`; returns `(k, s)` with `x = x_k + s`,
    /// `s` clamped to the interval.
    fn locate(&mut self, xs: &[f64], x: f64) -> (usize, f64) {
        let n = xs.len();
        while self.0 + 2 < n && xs[self.0 + 1] < x {
            self.0 += 1;
        }
        let k = self.0.min(n.saturating_sub(2));
        (k, (x - xs[k]).clamp(0.0, (xs[k + 1] - xs[k]).max(0.0)))
    }

    /// `∫₀ˣ w`, with `w` linear between nodes.
    fn integral(&mut self, s: &Scratch, x: f64) -> f64 {
        if s.x.len() < 2 {
            return 0.0;
        }
        let (k, d) = self.locate(&s.x, x);
        let dx = s.x[k + 1] - s.x[k];
        let slope = if dx > 0.0 { (s.w[k + 1] - s.w[k]) / dx } else { 0.0 };
        s.cumulative[k] + s.w[k] * d + 0.5 * slope * d * d
    }

    /// `w(x)`, linear between nodes.
    fn width(&mut self, s: &Scratch, x: f64) -> f64 {
        if s.x.len() < 2 {
            return s.w.first().copied().unwrap_or(f64::NAN);
        }
        let (k, d) = self.locate(&s.x, x);
        let dx = s.x[k + 1] - s.x[k];
        if dx > 0.0 {
            s.w[k] + d / dx * (s.w[k + 1] - s.w[k])
        } else {
            s.w[k + 1]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fdm::lag::FittedLag;

    fn setting(smoothing_mm: f64) -> LineSetting {
        LineSetting { smoothing_mm, v_ref_mm_s: 150.0 }
    }

    #[test]
    fn plain_lag_matches_the_lag_baseline() {
        // With every mechanism off the forward model is fdm::lag's model (another grid,
        // the same exact discretisation): agreement to well below a pixel (0.048 mm).
        let k = LineKinematics::paper_line(600.0, 100.0).unwrap();
        let xs: Vec<f64> = (0..=240).map(|i| i as f64 * 0.5).collect();
        let lag = FittedLag {
            tau_s: 0.05,
            w0_mm: 0.78,
            blob_flow_mm2_s: 4.0,
            smoothing_mm: 0.5,
            grid_step_mm: 0.01,
            training_rmse_mm: 0.0,
        };
        let reference = lag.predict(&k, &xs).unwrap();
        let mut out = vec![0.0; xs.len()];
        assert!(widths(&Theta::lag(0.05, 0.78, 4.0), &k, &setting(0.5), &xs, &mut Scratch::default(), &mut out));
        // The two end samples are left out: there the box is cut to half a window, which
        // fdm::lag averages over its grid points and this model integrates exactly.
        let n = xs.len();
        let worst = out[1..n - 1].iter().zip(&reference[1..n - 1]).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 2e-3, "largest difference {worst} mm");
    }

    #[test]
    fn hold_series_matches_the_exponential() {
        for z in [1e-6, 1e-3, 0.05, 0.3, 0.4999, 0.5001, 2.0] {
            let h = Hold::new(z, 1.0);
            let one_minus = -(-z).exp_m1();
            assert!((h.one_minus - one_minus).abs() < 1e-13 * one_minus.max(1e-300) + 1e-16, "{z}");
            // ramp = 1 − (1 − e^{−z})/z, to 1e-12 relative where it is computable directly.
            let ramp = 1.0 - one_minus / z;
            assert!((h.ramp - ramp).abs() < 1e-9 * ramp.abs() + 1e-12, "{z}: {} vs {ramp}", h.ramp);
        }
    }

    #[test]
    fn mass_is_conserved_without_cap_and_factors() {
        // ∫ w dx over the line equals ∫ q dt: a lag moves material, it does not make it.
        // With b = 0 and q(0) = c(0), ∫q dt = ∫c dt − τ(q_end − c_end) for each path, so
        // ∫w dx = w0·L − τ(q₁,end − (1−f)w0·v_end) − τ₂(q₂,end − f·w0·v_end).
        let k = LineKinematics::paper_line(800.0, 150.0).unwrap();
        let theta = Theta { slow_fraction: 0.4, tau_slow_s: 0.3, ..Theta::lag(0.04, 0.8, 0.0) };
        let mut s = Scratch::default();
        s.prepare(&theta, &k);
        s.fill_widths(&theta);
        let integral = *s.cumulative.last().unwrap();
        let (u1, u2) = (*s.unit_fast.last().unwrap(), *s.unit_slow.last().unwrap());
        let expected = 0.8 * 120.0 - 0.04 * 0.6 * 0.8 * (u1 - 8.0) - 0.3 * 0.4 * 0.8 * (u2 - 8.0);
        // The trapezoid in x of q/v is the time integral of q up to the grid's quadrature.
        assert!((integral - expected).abs() < 2e-3 * expected, "{integral} vs {expected}");
    }

    #[test]
    fn cached_responses_give_the_same_widths_as_a_fresh_simulation() {
        // A scratch that last saw other parameters must give exactly what a new one gives.
        let k = LineKinematics::paper_line(600.0, 100.0).unwrap();
        let xs: Vec<f64> = (0..=120).map(|i| i as f64).collect();
        let a = Theta { slow_fraction: 0.3, tau_slow_s: 0.5, max_excess_mm: 0.4, ..Theta::lag(0.05, 0.8, 3.0) };
        let b = Theta { w0_mm: 0.7, slow_fraction: 0.2, ..a };
        let (mut used, mut fresh) = (Scratch::default(), Scratch::default());
        let (mut wa, mut wb) = (vec![0.0; xs.len()], vec![0.0; xs.len()]);
        widths(&a, &k, &setting(0.5), &xs, &mut used, &mut wa);
        widths(&b, &k, &setting(0.5), &xs, &mut used, &mut wa);
        widths(&b, &k, &setting(0.5), &xs, &mut fresh, &mut wb);
        assert_eq!(wa, wb);
        let nonlinear = Theta { lag_offset_s: 0.2, lag_speed_mm_s: 30.0, ..b };
        widths(&nonlinear, &k, &setting(0.5), &xs, &mut used, &mut wa);
        widths(&nonlinear, &k, &setting(0.5), &xs, &mut Scratch::default(), &mut wb);
        assert_eq!(wa, wb);
        // With no offset the nonlinear lag is the linear one.
        let linear = Theta { lag_offset_s: 1e-300, ..b };
        widths(&linear, &k, &setting(0.5), &xs, &mut used, &mut wa);
        widths(&b, &k, &setting(0.5), &xs, &mut used, &mut wb);
        assert!(wa.iter().zip(&wb).all(|(p, q)| (p - q).abs() < 1e-9));
    }

    #[test]
    fn tilt_saturation_and_cap_do_what_they_say() {
        let k = LineKinematics::paper_line(400.0, 150.0).unwrap();
        let xs = [0.0, 60.0, 120.0];
        let mut base = [0.0; 3];
        let mut s = Scratch::default();
        let plain = Theta::lag(0.03, 0.8, 0.0);
        widths(&plain, &k, &setting(0.0), &xs, &mut s, &mut base);
        let mut tilted = [0.0; 3];
        widths(&Theta { tilt_width_change: 0.02, ..plain }, &k, &setting(0.0), &xs, &mut s, &mut tilted);
        let change = (tilted[2] / base[2]) / (tilted[0] / base[0]) - 1.0;
        assert!((change - 0.02).abs() < 1e-12, "{change}");
        let mut sat = [0.0; 3];
        widths(&Theta { saturation_loss: 0.05, ..plain }, &k, &setting(0.0), &xs, &mut s, &mut sat);
        assert!((sat[1] / base[1] - 0.95).abs() < 1e-12);
        let mut capped = [0.0; 3];
        widths(&Theta { max_excess_mm: 0.3, ..plain }, &k, &setting(0.0), &xs, &mut s, &mut capped);
        assert!(base[2] - 0.8 > 0.3 && capped[2] < 0.8 + 0.3 && capped[2] > 0.8);
        assert!((capped[1] - base[1]).abs() < 1e-9);
    }
}
