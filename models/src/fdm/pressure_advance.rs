//! Pressure advance in the extrusion physics (DESIGN §10, issue 55 item 1): the firmware
//! advances the extruder ahead of the commanded flow, and the melt then lags what the
//! extruder pushes by a first-order τ (the lag of [`super::lag`]). Along one straight
//! printed line ([`super::printed_lines::PrintedLine`]) with flow per layer height
//! (mm²/s, the layer height cancels as in [`super::lag`]):
//!
//! ```text
//! q(t)   = w_i · v(t)                     commanded flow (w_i: move i's nominal width)
//! E(t)   = ∫ q dt                         commanded extruder position (mm²)
//! P(t)   = S[E + K·q](t)                  the extruder's position under pressure advance
//! S[f](t) = ∫ f(t + s)·(h − |s|)/h² ds,  |s| ≤ h = smooth_time/2   (Klipper's triangle)
//! τ·dQ/dt + Q = dP/dt                     the melt's first-order lag
//! D(t)   = ∫ Q dt                         deposited (mm²);  width w(x) = dD/dx
//! ```
//!
//! Klipper smooths the whole advanced position (its `extruder.c` integrates position plus
//! K times velocity against the triangle); Marlin's linear advance is K·de/dt without
//! smoothing (smooth time 0). Integrating the lag once, `τ·dD/dt + D = P`, and with `u`
//! the lag of the commanded flow (`τu' + u = q`, [`super::lag::first_order_response`])
//! the lag of `E` is `E − τu`, so (S commutes with the lag)
//!
//! ```text
//! D = S[E + (K − τ)·u]
//! ```
//!
//! exact for the planner's trapezoids: `q` is linear in time between the moves' ramp
//! ends, so `E` and `u` are exact at any time (first-order hold from the last
//! breakpoint), and only the triangle's integral is numerical (Simpson). K = τ without
//! smoothing gives `D = E`: the deposited width is the commanded width whatever the speed
//! does. K = 0 gives `Q = u`, the plain lag. `D(∞) = E(∞)`: what the extruder pushed is
//! deposited (mass conservation).
//!
//! Width on the line (mass conservation, as [`super::lag`] and the virtual printer):
//! the deposited area per mm of path over a cell of `step_mm` around each position, then
//! box-smoothed over about a nozzle diameter. Where the deposit falls below a fraction of
//! the commanded (pressure advance overshooting as the nozzle slows, the extruder pulling
//! back), the bead breaks: a gap, width 0. Modelling choices (ours): material deposited
//! before the nozzle leaves the line's start (the smoothing window reaches earlier) or
//! after it reaches the end (the lag's tail) is reported, not laid on the line; each line
//! starts from a melt at rest (the moves around a line of a pressure-advance pattern do
//! not extrude).

use super::fit::moving_average;
use super::planner::PressureAdvance;
use super::printed_lines::PrintedLine;

/// Simpson intervals over the smoothing triangle (even).
const SMOOTHING_INTERVALS: usize = 64;
/// The lag's tail is followed for this many τ after the line ends (e^-40: nothing left).
const TAIL_TAUS: f64 = 40.0;

/// How a line's deposit is computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepositSettings {
    /// The melt's first-order time constant τ (s), > 0.
    pub tau_s: f64,
    /// The pressure advance in force (K, smooth time).
    pub pressure_advance: PressureAdvance,
    /// Spacing of the positions along the line, and the cell each width is averaged over (mm).
    pub step_mm: f64,
    /// Box smoothing of the width along the path (mm): about a nozzle diameter; 0 for none.
    pub smoothing_mm: f64,
    /// A deposit below this fraction of the commanded width is a gap (bead broken).
    pub gap_fraction: f64,
}

impl DepositSettings {
    /// τ with the line's own pressure advance, widths every 0.05 mm smoothed over a
    /// 0.4 mm nozzle, a gap below a quarter of the commanded width.
    pub fn for_line(line: &PrintedLine, tau_s: f64) -> Self {
        Self { tau_s, pressure_advance: line.pressure_advance, step_mm: 0.05, smoothing_mm: 0.4, gap_fraction: 0.25 }
    }
}

/// What a line deposits.
#[derive(Debug, Clone, PartialEq)]
pub struct LineDeposit {
    /// Positions from the line's start, `0, step, …` up to its length (mm).
    pub positions_mm: Vec<f64>,
    /// Width of the bead (mm): smoothed, 0 in a gap.
    pub widths_mm: Vec<f64>,
    /// Deposited area per mm over each position's cell, unsmoothed (mm; negative where
    /// the advance pulls melt back).
    pub flow_widths_mm: Vec<f64>,
    /// Commanded area per mm over each position's cell (mm).
    pub commanded_widths_mm: Vec<f64>,
    /// Whether the bead is broken at each position.
    pub gap: Vec<bool>,
    /// Area deposited before the nozzle leaves the start (mm², volume / layer height).
    pub before_start_mm2: f64,
    /// Area deposited after the nozzle reaches the end (mm²).
    pub after_end_mm2: f64,
    /// Area the extruder was commanded to push along the line (mm²).
    pub commanded_mm2: f64,
}

/// The deposit of `line` under `settings`.
pub fn deposit_line(line: &PrintedLine, settings: &DepositSettings) -> LineDeposit {
    let flow = CommandedFlow::new(line, settings.tau_s);
    let k = settings.pressure_advance.advance_s;
    let half = settings.pressure_advance.smooth_time_s / 2.0;
    let length = line.length_mm();
    let n = (length / settings.step_mm + 1e-9).floor() as usize + 1;
    let positions_mm: Vec<f64> = (0..n).map(|j| j as f64 * settings.step_mm).collect();
    let deposited = |x: f64| flow.deposited_mm2(line.time_at_mm(x), k, half);
    let commanded = |x: f64| flow.commanded_mm2(line.time_at_mm(x));
    let (mut flow_widths_mm, mut commanded_widths_mm) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for &x in &positions_mm {
        let (a, b) = ((x - settings.step_mm / 2.0).max(0.0), (x + settings.step_mm / 2.0).min(length));
        let cell = (b - a).max(1e-12);
        flow_widths_mm.push((deposited(b) - deposited(a)) / cell);
        commanded_widths_mm.push((commanded(b) - commanded(a)) / cell);
    }
    let gap: Vec<bool> = flow_widths_mm
        .iter()
        .zip(&commanded_widths_mm)
        .map(|(d, c)| d.is_nan() || *d < settings.gap_fraction * c)
        .collect();
    let smoothed = moving_average(&positions_mm, &flow_widths_mm, settings.smoothing_mm);
    let widths_mm = smoothed.iter().zip(&gap).map(|(w, g)| if *g { 0.0 } else { w.max(0.0) }).collect();
    let end = flow.deposited_mm2(line.duration_s(), k, half);
    LineDeposit {
        positions_mm,
        widths_mm,
        flow_widths_mm,
        commanded_widths_mm,
        gap,
        before_start_mm2: flow.deposited_mm2(0.0, k, half),
        after_end_mm2: flow.deposited_mm2(flow.tail_end_s(half), k, half) - end,
        commanded_mm2: flow.commanded_mm2(line.duration_s()),
    }
}

/// The commanded flow of a line as exact piecewise-linear nodes, with `E` and the lag `u`
/// at each node.
#[derive(Debug, Clone)]
pub struct CommandedFlow {
    tau_s: f64,
    /// Node times (s); a jump in q is two nodes at one time.
    times_s: Vec<f64>,
    /// q at each node (mm²/s).
    flows: Vec<f64>,
    /// E at each node (mm²).
    pushed: Vec<f64>,
    /// u at each node (mm²/s).
    lagged: Vec<f64>,
}

impl CommandedFlow {
    /// The line's commanded flow (each move's nominal width times its speed) and its lag τ,
    /// from rest before the line to rest after it.
    pub fn new(line: &PrintedLine, tau_s: f64) -> Self {
        let mean_filament = line.moves.iter().map(|m| m.filament_per_mm * m.planned.length_mm).sum::<f64>()
            / line.length_mm().max(1e-12);
        let mut nodes: Vec<(f64, f64)> = vec![(0.0, 0.0)];
        for m in &line.moves {
            let w = line.nominal_width_mm * m.filament_per_mm / mean_filament;
            let p = &m.planned;
            let t_acc = (p.speed_at_mm(p.accel_length_mm()) - p.entry_mm_s) / p.accel_mm_s2;
            let t_dec_start = p.time_at_mm(p.length_mm - p.decel_length_mm());
            for t in [0.0, t_acc, t_dec_start, p.duration_s] {
                nodes.push((m.start_time_s + t, w * speed_at_time(p, t)));
            }
        }
        nodes.push((line.duration_s(), 0.0));
        let mut flow = Self { tau_s, times_s: Vec::new(), flows: Vec::new(), pushed: Vec::new(), lagged: Vec::new() };
        let (mut e, mut u) = (0.0, 0.0);
        let (mut t_prev, mut q_prev) = (0.0, 0.0);
        for (t, q) in nodes {
            e += 0.5 * (q_prev + q) * (t - t_prev);
            u = hold_step(u, q_prev, q, t - t_prev, tau_s);
            flow.times_s.push(t);
            flow.flows.push(q);
            flow.pushed.push(e);
            flow.lagged.push(u);
            (t_prev, q_prev) = (t, q);
        }
        flow
    }

    /// `(q, E, u)` at time `t_s` (before the line all 0; after it q = 0, E its total, u decaying).
    pub fn state(&self, t_s: f64) -> (f64, f64, f64) {
        if t_s <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        let k = self.times_s.partition_point(|&t| t <= t_s) - 1;
        let (t0, q0) = (self.times_s[k], self.flows[k]);
        let q = match self.times_s.get(k + 1) {
            Some(&t1) if t1 > t0 => q0 + (self.flows[k + 1] - q0) * (t_s - t0) / (t1 - t0),
            _ => q0,
        };
        let dt = t_s - t0;
        (q, self.pushed[k] + 0.5 * (q0 + q) * dt, hold_step(self.lagged[k], q0, q, dt, self.tau_s))
    }

    /// Commanded area pushed by `t_s` (mm²).
    pub fn commanded_mm2(&self, t_s: f64) -> f64 {
        self.state(t_s).1
    }

    /// Deposited area by `t_s` (mm²) under advance `k_s` and the smoothing triangle's half
    /// width `half_s`: `S[E + (K − τ)u]`.
    pub fn deposited_mm2(&self, t_s: f64, k_s: f64, half_s: f64) -> f64 {
        let f = |t: f64| {
            let (_, e, u) = self.state(t);
            e + (k_s - self.tau_s) * u
        };
        if half_s <= 0.0 {
            return f(t_s);
        }
        // Composite Simpson over [−h, h] against (h − |s|)/h²; s = 0 is a node.
        let m = SMOOTHING_INTERVALS;
        let ds = 2.0 * half_s / m as f64;
        let mut sum = 0.0;
        for i in 0..=m {
            let s = -half_s + i as f64 * ds;
            let simpson = if i == 0 || i == m {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            sum += simpson * (half_s - s.abs()) / (half_s * half_s) * f(t_s + s);
        }
        sum * ds / 3.0
    }

    /// A time by which the lag's tail has died out (s).
    pub fn tail_end_s(&self, half_s: f64) -> f64 {
        self.times_s.last().copied().unwrap_or(0.0) + half_s + TAIL_TAUS * self.tau_s
    }
}

/// Speed of a planned trapezoid `t_s` after its start (clamped to the move; mm/s).
pub fn speed_at_time(p: &super::planner::PlannedMove, t_s: f64) -> f64 {
    let t = t_s.clamp(0.0, p.duration_s);
    let t_acc = (p.speed_at_mm(p.accel_length_mm()) - p.entry_mm_s) / p.accel_mm_s2;
    let t_dec = p.time_at_mm(p.length_mm - p.decel_length_mm());
    if t < t_acc {
        p.entry_mm_s + p.accel_mm_s2 * t
    } else if t <= t_dec {
        p.speed_at_mm(p.accel_length_mm())
    } else {
        (p.speed_at_mm(p.length_mm - p.decel_length_mm()) - p.accel_mm_s2 * (t - t_dec)).max(p.exit_mm_s)
    }
}

/// Exact first-order-hold step of `τu' = q − u` over `dt` with q linear from `q0` to `q1`
/// (the step of [`super::lag::first_order_response`]).
fn hold_step(u: f64, q0: f64, q1: f64, dt: f64, tau_s: f64) -> f64 {
    if dt <= 0.0 {
        return u;
    }
    let phi = (-dt / tau_s).exp();
    let one_minus = -(-dt / tau_s).exp_m1();
    phi * u + one_minus * q0 + (q1 - q0) * (1.0 - tau_s * one_minus / dt)
}

#[cfg(test)]
mod tests {
    use super::super::lag::first_order_response;
    use super::super::planner::{plan, Cornering, MotionLimits, Move};
    use super::super::printed_lines::printed_lines;
    use super::*;

    /// A slow–fast–slow line (10, 100, 10 mm/s at 2500 mm/s², 0.08 mm filament per mm:
    /// nominal width 0.962 mm at 0.2 mm layers) entered and left at 5 mm/s corners.
    fn slow_fast_slow() -> PrintedLine {
        let limits = MotionLimits {
            accel_mm_s2: 2500.0,
            accel_to_decel_mm_s2: 2500.0,
            max_velocity_mm_s: f64::INFINITY,
            cornering: Cornering::SquareCorner { velocity_mm_s: 5.0, extruder_corner_mm_s: 1.0 },
        };
        let pa = PressureAdvance::default();
        let mv = |a: [f64; 3], b: [f64; 3], feed: f64, e: f64| Move {
            start_mm: a,
            end_mm: b,
            filament_mm: e * (b[0] - a[0]).hypot(b[1] - a[1]),
            feed_mm_s: feed,
            limits,
            pressure_advance: pa,
        };
        let moves = [
            mv([2.0, 8.0, 0.3], [2.0, 8.0, 0.2], 16.0, 0.0),
            mv([2.0, 8.0, 0.2], [5.88, 8.0, 0.2], 10.0, 0.08),
            mv([5.88, 8.0, 0.2], [29.16, 8.0, 0.2], 100.0, 0.08),
            mv([29.16, 8.0, 0.2], [40.8, 8.0, 0.2], 10.0, 0.08),
            mv([40.8, 8.0, 0.2], [40.8, 8.0, 0.3], 16.0, 0.0),
        ];
        printed_lines(&moves, &plan(&moves).unwrap(), 1.75).remove(0)
    }

    fn settings(tau_s: f64, advance_s: f64, smooth_time_s: f64) -> DepositSettings {
        DepositSettings {
            tau_s,
            pressure_advance: PressureAdvance { advance_s, smooth_time_s },
            step_mm: 0.05,
            smoothing_mm: 0.0,
            gap_fraction: 0.25,
        }
    }

    #[test]
    fn advance_equal_to_tau_cancels_the_lag_through_every_speed_step() {
        // D = E + (K − τ)u = E: the deposit is the commanded width everywhere, through the
        // start from 5 mm/s, both accelerations and both decelerations.
        let line = slow_fast_slow();
        let d = deposit_line(&line, &settings(0.05, 0.05, 0.0));
        let w = line.nominal_width_mm;
        let worst = d.flow_widths_mm.iter().map(|x| (x - w).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-9 * w, "worst deviation {worst}");
        assert!(d.gap.iter().all(|g| !g));
        assert!(d.before_start_mm2.abs() < 1e-12 && d.after_end_mm2.abs() < 1e-9);
    }

    #[test]
    fn no_advance_is_the_plain_lag() {
        // K = 0: Q = u, the first-order response of the commanded flow; width = u/v. Checked
        // on fine cells against lag.rs's own response on a fine time grid.
        let line = slow_fast_slow();
        let tau = 0.04;
        let s = DepositSettings { step_mm: 0.002, ..settings(tau, 0.0, 0.0) };
        let d = deposit_line(&line, &s);
        let flow = CommandedFlow::new(&line, tau);
        let ts: Vec<f64> = (0..=200_000).map(|i| i as f64 * line.duration_s() / 200_000.0).collect();
        // u(0) = 0: the melt is at rest before the line (lag.rs starts at q(0), so a zero
        // sample goes just before the start, where q jumps to w·v0).
        let mut ts0 = vec![-1e-12];
        ts0.extend(&ts);
        let mut qs0 = vec![0.0];
        qs0.extend(ts.iter().map(|&t| flow.state(t).0));
        let u = first_order_response(&ts0, &qs0, tau);
        for x in [1.0, 5.0, 8.0, 15.0, 28.0, 29.5, 31.0, 35.0] {
            let t = line.time_at_mm(x);
            let i = ((t / line.duration_s()) * 200_000.0).round() as usize + 1;
            let expected = u[i] / line.speed_at_mm(x);
            let j = (x / 0.002).round() as usize;
            assert!(
                (d.flow_widths_mm[j] - expected).abs() < 2e-3 * expected,
                "{x}: {} vs {expected}",
                d.flow_widths_mm[j]
            );
        }
        // the lag thins the fast segment's start and widens the slow segment after it
        let at = |x: f64| d.flow_widths_mm[(x / 0.002).round() as usize];
        assert!(at(6.5) < 0.8 * line.nominal_width_mm && at(28.0) > 1.5 * line.nominal_width_mm);
    }

    #[test]
    fn smoothing_rounds_a_ramp_end_by_its_closed_form() {
        // K = τ: D = S[E], the deposited flow is the triangle-smoothed commanded flow. Mid
        // ramp q is linear over the window, so the width is nominal; where the ramp from
        // 10 to 100 mm/s ends (q's slope m = w·a stops), S[q] = q_c − m·h/6, so the width
        // is w·(1 − a·h/(6·v_c)) with h = smooth_time/2.
        let line = slow_fast_slow();
        let (a, h, v_c) = (2500.0, 0.02, 100.0);
        let d = deposit_line(&line, &DepositSettings { step_mm: 0.001, ..settings(0.05, 0.05, 2.0 * h) });
        let w = line.nominal_width_mm;
        let ramp_end = line.moves[1].start_along_mm + line.moves[1].planned.accel_length_mm();
        let at = |x: f64| d.flow_widths_mm[(x / 0.001).round() as usize];
        let expected = w * (1.0 - a * h / (6.0 * v_c));
        assert!((at(ramp_end) - expected).abs() < 2e-3 * w, "{} vs {expected}", at(ramp_end));
        // mid ramp: t_acc = 36 ms > 2h, at 18 ms the window sees only the ramp
        let mid = line.moves[1].start_along_mm + 10.0 * 0.018 + 0.5 * a * 0.018f64.powi(2);
        assert!((at(mid) - w).abs() < 2e-3 * w, "{}", at(mid));
        // and the smoothing moves material ahead of the start
        assert!(d.before_start_mm2 > 0.0);
    }

    #[test]
    fn what_the_extruder_pushed_is_deposited() {
        // ∫Q dt = ∫q dt: before the start + on the line + after the end = commanded, for
        // any τ, K and smooth time (also where the advance pulls melt back).
        let line = slow_fast_slow();
        for (tau, k, st) in [(0.03, 0.0, 0.0), (0.05, 0.1, 0.0), (0.08, 0.02, 0.04), (0.02, 0.1, 0.04)] {
            let d = deposit_line(&line, &DepositSettings { step_mm: 0.01, ..settings(tau, k, st) });
            let on_line: f64 = d.flow_widths_mm.iter().map(|w| w * 0.01).sum::<f64>()
                - 0.5 * 0.01 * (d.flow_widths_mm[0] + d.flow_widths_mm[d.flow_widths_mm.len() - 1]);
            let total = d.before_start_mm2 + on_line + d.after_end_mm2;
            let expected = line.nominal_width_mm * line.length_mm();
            assert!((d.commanded_mm2 - expected).abs() < 1e-9 * expected);
            assert!((total - expected).abs() < 2e-3 * expected, "{tau} {k} {st}: {total} vs {expected}");
        }
    }

    #[test]
    fn an_advance_beyond_tau_breaks_the_bead_after_the_fast_segment() {
        // K = 0.1 s over τ = 0.03 s: decelerating from 100 mm/s the advance pulls melt
        // back (Q < 0) and the bead breaks just after the fast segment ends; K = τ never.
        let line = slow_fast_slow();
        let d = deposit_line(&line, &DepositSettings { smoothing_mm: 0.4, ..settings(0.03, 0.1, 0.04) });
        let fast_end = line.moves[2].start_along_mm;
        let gaps: Vec<f64> = d.positions_mm.iter().zip(&d.gap).filter(|(_, g)| **g).map(|(x, _)| *x).collect();
        assert!(!gaps.is_empty());
        // and where the nozzle slows into the corner at the line's very end
        let end = line.length_mm();
        let near = |x: &f64| (fast_end - 2.0..fast_end + 3.0).contains(x) || (end - 0.5..=end + 1e-9).contains(x);
        assert!(gaps.iter().any(|x| (fast_end..fast_end + 0.5).contains(x)), "{gaps:?}");
        assert!(gaps.iter().all(near), "{gaps:?}");
        assert!(d.flow_widths_mm.iter().any(|w| *w < 0.0));
        let even = deposit_line(&line, &DepositSettings { smoothing_mm: 0.4, ..settings(0.03, 0.03, 0.04) });
        assert!(even.gap.iter().all(|g| !g));
    }

    #[test]
    fn the_spec_integrated_by_brute_force_agrees() {
        // Independent of the closed form: advance then lag integrated as written, on a
        // 10 µs grid (P sampled, smoothed by a discrete triangle, q_adv = ΔP/Δt, the lag
        // stepped exactly for a held input, D summed).
        let line = slow_fast_slow();
        let (tau, k, st) = (0.04, 0.07, 0.04);
        let flow = CommandedFlow::new(&line, tau);
        let dt = 1e-5;
        let h = st / 2.0;
        let t0 = -h - 0.01;
        let n = ((line.duration_s() + 0.3 - t0) / dt) as usize;
        let p: Vec<f64> = (0..n)
            .map(|i| {
                let (q, e, _) = flow.state(t0 + i as f64 * dt);
                e + k * q
            })
            .collect();
        let hw = (h / dt).round() as isize;
        let weights: Vec<f64> = (-hw..=hw).map(|j| (hw - j.abs()) as f64).collect();
        let wsum: f64 = weights.iter().sum();
        let smooth = |i: usize| -> f64 {
            (-hw..=hw)
                .map(|j| weights[(j + hw) as usize] * p[(i as isize + j).clamp(0, n as isize - 1) as usize])
                .sum::<f64>()
                / wsum
        };
        let (mut q_dep, mut d, mut prev) = (0.0, 0.0, smooth(0));
        let phi = (-dt / tau).exp();
        for i in 1..n {
            let next = smooth(i);
            let u = (next - prev) / dt;
            d += u * dt + (q_dep - u) * tau * (1.0 - phi);
            q_dep = phi * q_dep + (1.0 - phi) * u;
            prev = next;
            let t = t0 + i as f64 * dt;
            if i % 20_000 == 0 {
                let exact = flow.deposited_mm2(t, k, h);
                assert!((d - exact).abs() < 2e-3, "t {t}: brute {d} vs {exact}");
            }
        }
    }
}
