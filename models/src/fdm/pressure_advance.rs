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
//! ends, so `E`, `u` and their second time integrals are closed forms at any time, and
//! the triangle (two boxes of width h) is the second difference of the second integral.
//! `D` is linear in K (`S[E] + (K − τ)·S[u]`, [`DepositParts`]). K = τ without
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
    let (k, tau) = (settings.pressure_advance.advance_s, settings.tau_s);
    let DepositParts { positions_mm, cells: [pushed, lagged, commanded_widths_mm], .. } = deposit_parts(line, settings);
    let flow_widths_mm: Vec<f64> = pushed.iter().zip(&lagged).map(|(p, l)| p + (k - tau) * l).collect();
    let gap: Vec<bool> = flow_widths_mm
        .iter()
        .zip(&commanded_widths_mm)
        .map(|(d, c)| d.is_nan() || *d < settings.gap_fraction * c)
        .collect();
    let smoothed = moving_average(&positions_mm, &flow_widths_mm, settings.smoothing_mm);
    let widths_mm = smoothed.iter().zip(&gap).map(|(w, g)| if *g { 0.0 } else { w.max(0.0) }).collect();
    let flow = CommandedFlow::new(line, tau);
    let half = settings.pressure_advance.smooth_time_s / 2.0;
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

/// A line's deposit split by its dependence on K (`D = S[E] + (K − τ)·S[u]`, linear in K):
/// per position the cell widths of each part, box-smoothed as [`deposit_line`] smooths
/// them, so that the unclipped width under any advance K is `pushed + (K − τ)·lagged`.
#[derive(Debug, Clone, PartialEq)]
pub struct DepositParts {
    /// Positions from the line's start, `0, step, …` (mm).
    pub positions_mm: Vec<f64>,
    /// Smoothed cell widths of `S[E]` (mm): the commanded flow under the smoothing alone.
    pub pushed_mm: Vec<f64>,
    /// Smoothed cell widths of `S[u]` per second of `K − τ` (mm/s).
    pub lagged_mm_per_s: Vec<f64>,
    /// Smoothed commanded cell widths (mm).
    pub commanded_mm: Vec<f64>,
    /// The three parts' cell widths before smoothing (pushed, lagged, commanded), which
    /// decide the gaps as [`deposit_line`] does.
    pub cells: [Vec<f64>; 3],
    /// A deposit below this fraction of the commanded width is a gap.
    pub gap_fraction: f64,
}

impl DepositParts {
    /// Smoothed width under advance `k_s` at position `j` (unclipped: negative where melt
    /// is pulled back).
    pub fn width_mm(&self, j: usize, k_s: f64, tau_s: f64) -> f64 {
        self.pushed_mm[j] + (k_s - tau_s) * self.lagged_mm_per_s[j]
    }

    /// The bead's width under advance `k_s` at position `j`: the smoothed width times the
    /// part of the cell `j ± step/2` that is bead, never negative. Where a gap begins or
    /// ends, the deposit's margin over the gap threshold is taken linear between
    /// neighbouring positions, so the width falls to 0 continuously as the gap's edge
    /// moves through the cell (a fit over τ sees no steps); a whole gap cell is 0 as in
    /// [`deposit_line`].
    pub fn bead_width_mm(&self, j: usize, k_s: f64, tau_s: f64) -> f64 {
        let margin = |i: usize| {
            let [pushed, lagged, commanded] = &self.cells;
            let m = pushed[i] + (k_s - tau_s) * lagged[i] - self.gap_fraction * commanded[i];
            if m.is_nan() {
                -1.0
            } else {
                m
            }
        };
        let here = margin(j);
        let half_bead = |other: Option<f64>| match other {
            None => f64::from(u8::from(here >= 0.0)) * 0.5,
            Some(o) => bead_part_of_half_cell(here, o),
        };
        let last = self.positions_mm.len() - 1;
        let before = half_bead((j > 0).then(|| margin(j - 1)));
        let after = half_bead((j < last).then(|| margin(j + 1)));
        (before + after) * self.width_mm(j, k_s, tau_s).max(0.0)
    }
}

/// The part of the half cell from a position (margin `here`) toward its neighbour (margin
/// `other`, a step away) where the margin, linear between them, is ≥ 0: from 0 to ½.
fn bead_part_of_half_cell(here: f64, other: f64) -> f64 {
    match (here >= 0.0, other >= 0.0) {
        (true, true) => 0.5,
        (false, false) => 0.0,
        // the margin crosses 0 at t = here / (here − other) steps from here
        (true, false) => (here / (here - other)).min(0.5),
        (false, true) => (0.5 - here / (here - other)).max(0.0),
    }
}

/// The parts of `line`'s deposit under lag `settings.tau_s` and the smoothing of
/// `settings.pressure_advance` (its K is not used: the parts hold every K).
pub fn deposit_parts(line: &PrintedLine, settings: &DepositSettings) -> DepositParts {
    let flow = CommandedFlow::new(line, settings.tau_s);
    let half = settings.pressure_advance.smooth_time_s / 2.0;
    let length = line.length_mm();
    let step = settings.step_mm;
    let n = (length / step + 1e-9).floor() as usize + 1;
    let positions_mm: Vec<f64> = (0..n).map(|j| j as f64 * step).collect();
    // cell edges: (j ± ½)·step clamped to the line, evaluated once each
    let edges: Vec<f64> = (0..=n).map(|j| ((j as f64 - 0.5) * step).clamp(0.0, length)).collect();
    let at_edges: Vec<[f64; 3]> = edges
        .iter()
        .map(|&x| {
            let t = line.time_at_mm(x);
            let (pushed, lagged) = flow.smoothed_parts(t, half);
            [pushed, lagged, flow.commanded_mm2(t)]
        })
        .collect();
    let mut cells = [Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n)];
    for j in 0..n {
        let width = (edges[j + 1] - edges[j]).max(1e-12);
        for (k, cell) in cells.iter_mut().enumerate() {
            cell.push((at_edges[j + 1][k] - at_edges[j][k]) / width);
        }
    }
    let [pushed, lagged, commanded] = cells.each_ref().map(|c| moving_average(&positions_mm, c, settings.smoothing_mm));
    DepositParts {
        positions_mm,
        pushed_mm: pushed,
        lagged_mm_per_s: lagged,
        commanded_mm: commanded,
        cells,
        gap_fraction: settings.gap_fraction,
    }
}

/// The commanded flow of a line as exact piecewise-linear nodes, with at each node `E`,
/// the lag `u` and their first and second time integrals (for the smoothing triangle).
#[derive(Debug, Clone)]
pub struct CommandedFlow {
    tau_s: f64,
    /// Node times (s); a jump in q is two nodes at one time.
    times_s: Vec<f64>,
    /// The state at each node.
    nodes: Vec<NodeState>,
}

/// `q` and, from the line's start, `E = ∫q`, `E1 = ∫E`, `E2 = ∫E1`, `u` (the lag of q),
/// `U1 = ∫u`, `U2 = ∫U1` at one time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct NodeState {
    q: f64,
    e: [f64; 3],
    u: [f64; 3],
}

impl NodeState {
    /// The state `d` seconds after this one while q runs linearly at `slope` (exact: q is
    /// a polynomial, u is `q − slope·τ` plus a decaying exponential).
    fn advance(&self, d: f64, slope: f64, tau: f64) -> Self {
        if d <= 0.0 {
            return *self;
        }
        let (q0, m) = (self.q, slope);
        let [e0, e1, e2] = self.e;
        let [u0, u1, u2] = self.u;
        let (d2, d3, d4) = (d * d, d * d * d, d * d * d * d);
        let e = [
            e0 + q0 * d + m * d2 / 2.0,
            e1 + e0 * d + q0 * d2 / 2.0 + m * d3 / 6.0,
            e2 + e1 * d + e0 * d2 / 2.0 + q0 * d3 / 6.0 + m * d4 / 24.0,
        ];
        // u(s) = p(s) + c·e^(−s/τ) with p(s) = q0 − m·τ + m·s
        let (p0, c, x) = (q0 - m * tau, u0 - q0 + m * tau, d / tau);
        let one_minus = -(-x).exp_m1();
        let u = [
            p0 + m * d + c * (1.0 - one_minus),
            u1 + p0 * d + m * d2 / 2.0 + c * tau * one_minus,
            u2 + u1 * d + p0 * d2 / 2.0 + m * d3 / 6.0 + c * tau * tau * (x + (-x).exp_m1()),
        ];
        Self { q: q0 + m * d, e, u }
    }
}

impl CommandedFlow {
    /// The line's commanded flow (each move's nominal width times its speed) and its lag τ,
    /// from rest before the line to rest after it.
    pub fn new(line: &PrintedLine, tau_s: f64) -> Self {
        let mean_filament = line.moves.iter().map(|m| m.filament_per_mm * m.planned.length_mm).sum::<f64>()
            / line.length_mm().max(1e-12);
        let mut points: Vec<(f64, f64)> = vec![(0.0, 0.0)];
        for m in &line.moves {
            let w = line.nominal_width_mm * m.filament_per_mm / mean_filament;
            let p = &m.planned;
            let t_acc = (p.speed_at_mm(p.accel_length_mm()) - p.entry_mm_s) / p.accel_mm_s2;
            let t_dec_start = p.time_at_mm(p.length_mm - p.decel_length_mm());
            for t in [0.0, t_acc, t_dec_start, p.duration_s] {
                points.push((m.start_time_s + t, w * speed_at_time(p, t)));
            }
        }
        points.push((line.duration_s(), 0.0));
        let mut times_s = Vec::with_capacity(points.len());
        let mut nodes = Vec::with_capacity(points.len());
        let mut state = NodeState::default();
        for (i, &(t, q)) in points.iter().enumerate() {
            if i > 0 {
                let (t_prev, q_prev) = points[i - 1];
                let dt = t - t_prev;
                let slope = if dt > 0.0 { (q - q_prev) / dt } else { 0.0 };
                state = state.advance(dt, slope, tau_s);
            }
            state.q = q;
            times_s.push(t);
            nodes.push(state);
        }
        Self { tau_s, times_s, nodes }
    }

    /// The full state at `t_s` (before the line all 0; after it q = 0, E its total, u decaying).
    fn full_state(&self, t_s: f64) -> NodeState {
        if t_s <= 0.0 {
            return NodeState::default();
        }
        let k = self.times_s.partition_point(|&t| t <= t_s) - 1;
        let slope = match self.times_s.get(k + 1) {
            Some(&t1) if t1 > self.times_s[k] => (self.nodes[k + 1].q - self.nodes[k].q) / (t1 - self.times_s[k]),
            _ => 0.0,
        };
        self.nodes[k].advance(t_s - self.times_s[k], slope, self.tau_s)
    }

    /// `(q, E, u)` at time `t_s` (before the line all 0; after it q = 0, E its total, u decaying).
    pub fn state(&self, t_s: f64) -> (f64, f64, f64) {
        let s = self.full_state(t_s);
        (s.q, s.e[0], s.u[0])
    }

    /// Commanded area pushed by `t_s` (mm²).
    pub fn commanded_mm2(&self, t_s: f64) -> f64 {
        self.full_state(t_s).e[0]
    }

    /// Deposited area by `t_s` (mm²) under advance `k_s` and the smoothing triangle's half
    /// width `half_s`: `S[E + (K − τ)u]`.
    pub fn deposited_mm2(&self, t_s: f64, k_s: f64, half_s: f64) -> f64 {
        let (pushed, lagged) = self.smoothed_parts(t_s, half_s);
        pushed + (k_s - self.tau_s) * lagged
    }

    /// `(S[E](t), S[u](t))`: the two parts of [`Self::deposited_mm2`], which is
    /// `S[E] + (K − τ)·S[u]`. The triangle `(h − |s|)/h²` is two boxes of width h, so
    /// `S[f](t) = (F₂(t+h) − 2F₂(t) + F₂(t−h))/h²` with `F₂` f's second integral: exact.
    pub fn smoothed_parts(&self, t_s: f64, half_s: f64) -> (f64, f64) {
        if half_s <= 0.0 {
            let s = self.full_state(t_s);
            return (s.e[0], s.u[0]);
        }
        let [before, at, after] = [t_s - half_s, t_s, t_s + half_s].map(|t| self.full_state(t));
        let h2 = half_s * half_s;
        ((after.e[2] - 2.0 * at.e[2] + before.e[2]) / h2, (after.u[2] - 2.0 * at.u[2] + before.u[2]) / h2)
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

#[cfg(test)]
mod tests {
    use super::super::lag::first_order_response;
    use super::super::synthetic::pressure_advance_pattern;
    use super::*;

    /// A slow–fast–slow line (10, 100, 10 mm/s at 2500 mm/s², 0.08 mm filament per mm:
    /// nominal width 0.962 mm at 0.2 mm layers) entered and left at 5 mm/s corners.
    fn slow_fast_slow() -> PrintedLine {
        pressure_advance_pattern(&[0.0], 0.0).remove(0)
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
