//! Deposition direction allocation (DDA), paper 003 Sec. 2.2, eqs 13-26 and Fig. 2.
//!
//! Where the slender condition fails (S_c > 1, eq. 15) the deposition direction is
//! rotated away from the path normal by an added curvature κ_φ (eqs 13-14), and the
//! rotation taken out of the violating span is handed to its neighbours so that the
//! total turn between samples far from the span is unchanged (eq. 16). The loop is the
//! paper's: find the first continuous violating span t_v, set κ_φ there by eq. 17, take
//! ΔΦ = ∫κ_φ|v|dt (eq. 18), split it equally into past and future (eq. 19), and hand
//! the opposite rotation sample by sample forward from t_v,1 and backward from t_v,0
//! (eqs 20-25): each sample takes the whole remainder if that keeps it slender (eq. 24)
//! and otherwise its maximum allowance (eq. 23). Repeat until no span violates.
//!
//! Deviations from the paper, each for a stated reason:
//! - **Rotated-frame bound** ([`SlenderBound::RotatedFrame`], the default). The paper
//!   bounds |κ_eff|·q ≤ 1 (q = E/(|v|h)) whatever the rotation ψ of the deposition
//!   direction. A deposition segment of length w rotating at κ_eff|v| while its foot moves
//!   at |v|cos ψ across it sweeps backwards beyond w = cos ψ/κ_eff, so consecutive
//!   segments cross wherever ψ ≠ 0 and S_c → 1; on the corner test path the literal
//!   bound gives hundreds of crossing segment pairs, up to 1 mm deep (the unit test
//!   checks this). Mass conservation in the rotated frame, (κ_eff/2)w² − cos ψ·w + q/2 = 0,
//!   has a real root exactly when |κ_eff|q ≤ cos²ψ, so we bound |κ_eff|q ≤ cos²ψ in eqs
//!   15, 17 and 23; it equals the paper's bound where ψ = 0. [`SlenderBound::Paper`]
//!   keeps the literal bound. With the rotated-frame bound the ψ of a sample depends on
//!   the rotation allocated at it, so eq. 17 on the span is iterated to its fixed point
//!   and the forward pass refines its allowance a few times (a contraction: the
//!   allocated angle per sample is small).
//! - **ψ as φ_eff.** Eq. 26 defines φ_eff = κ_eff·|v|·T_s, a one-sample increment of
//!   heading; used in eq. 31 (w_d = w0/cos φ_eff) it would make w_d = w0 to within
//!   (κ|v|T_s)²/2, i.e. a no-op. We report the angle between the deposition direction and
//!   the path normal, ψ = θ_dep − θ, with θ_dep(t) = θ(t0) + ∫κ_eff|v|dt (rectangle rule
//!   per sample) and θ the heading of the commanded velocity; ψ is what eq. 31 needs.
//!   Because eq. 4's central differences smear a sharp arc's turn over neighbouring
//!   samples, ψ without any allocation is not exactly 0 inside tight arcs (≤ 0.07 rad
//!   on the corner test path, back to < 0.01 rad after the arc).
//! - A pass that runs off the end of the trajectory hands its remainder to the other
//!   side; if that cannot place it either, [`ThermalError::DirectionAllocation`].
//!
//! The deposition direction (left) is n_dep = (−sin θ_dep, cos θ_dep).

use super::errors::ThermalError;
use super::geometry::{bead_reach_mm, curvature_per_mm, half_widths_from_reach};
use super::trajectory::Trajectory;

/// Relative tolerance on S_c ≤ 1 before a sample counts as violating.
const SLENDER_TOL: f64 = 1e-9;
/// Fixed-point iterations of eq. 17 on a span and of the forward allowance.
const FIXED_POINT_ITERATIONS: usize = 100;

/// Which slender bound the allocation enforces (see the module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlenderBound {
    /// |κ_eff|·q ≤ 1, eq. 15 as printed.
    Paper,
    /// |κ_eff|·q ≤ cos²ψ: mass conservation along the rotated deposition direction.
    RotatedFrame,
}

/// Parameters of the allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DdaParams {
    /// The bound enforced.
    pub bound: SlenderBound,
    /// Most violating spans handled before giving up (each iteration of Fig. 2 is one).
    pub max_spans: usize,
}

impl Default for DdaParams {
    fn default() -> Self {
        Self { bound: SlenderBound::RotatedFrame, max_spans: 10_000 }
    }
}

/// Per-sample result of the allocation.
#[derive(Debug, Clone, PartialEq)]
pub struct DepositionDirections {
    /// Curvature κ of eq. 4 (1/mm).
    pub curvature_per_mm: Vec<f64>,
    /// Added curvature κ_φ (1/mm), eq. 13.
    pub added_curvature_per_mm: Vec<f64>,
    /// Effective curvature κ_eff = κ + κ_φ (1/mm), eq. 14.
    pub effective_curvature_per_mm: Vec<f64>,
    /// Bead reach q = E/(|v|h) (mm).
    pub reach_mm: Vec<f64>,
    /// S_c of eq. 12 (with κ) before the allocation.
    pub slender_before: Vec<f64>,
    /// S_c of eq. 15 (with κ_eff) after the allocation.
    pub slender_after: Vec<f64>,
    /// Heading θ of the printing direction e(t), unwrapped (rad).
    pub heading_rad: Vec<f64>,
    /// Heading θ_dep of the deposition frame (rad).
    pub deposition_heading_rad: Vec<f64>,
    /// ψ = θ_dep − θ, the angle between deposition direction and path normal (rad).
    pub psi_rad: Vec<f64>,
    /// Number of violating spans handled (iterations of Fig. 2).
    pub spans: usize,
}

/// Left and right boundary points p ± w·n_dep of the bead at every sample (Fig. 3).
#[derive(Debug, Clone, PartialEq)]
pub struct BeadBoundary {
    /// Left boundary points (mm).
    pub left_mm: Vec<[f64; 2]>,
    /// Right boundary points (mm).
    pub right_mm: Vec<[f64; 2]>,
    /// Left half width along n_dep (mm), eq. 10 with κ_eff.
    pub left_half_width_mm: Vec<f64>,
    /// Right half width along −n_dep (mm), eq. 11 with κ_eff.
    pub right_half_width_mm: Vec<f64>,
}

/// Runs the allocation of Sec. 2.2 on `trajectory` with the deposited flow
/// `flow_mm3_s` (one value per sample; the stage passes the commanded flow filtered
/// through G(s), what is actually deposited) and layer height `layer_height_mm`.
pub fn allocate_directions(
    trajectory: &Trajectory,
    flow_mm3_s: &[f64],
    layer_height_mm: f64,
    params: &DdaParams,
) -> Result<DepositionDirections, ThermalError> {
    let mut state = Allocation::new(trajectory, flow_mm3_s, layer_height_mm, params.bound)?;
    let mut spans = 0;
    while let Some((first, last)) = state.first_violating_span() {
        spans += 1;
        if spans > params.max_spans {
            return Err(ThermalError::TooManySpans { t_s: trajectory.t_s[first], max_spans: params.max_spans });
        }
        state
            .resolve_span(first, last)
            .map_err(|residual_rad| ThermalError::DirectionAllocation { t_s: trajectory.t_s[first], residual_rad })?;
    }
    Ok(state.finish(trajectory, spans))
}

/// The directions without allocation (κ_φ = 0): the deposition direction is the path
/// normal up to the discretisation of eq. 4 (Fig. 3a).
pub fn without_allocation(
    trajectory: &Trajectory,
    flow_mm3_s: &[f64],
    layer_height_mm: f64,
) -> Result<DepositionDirections, ThermalError> {
    let state = Allocation::new(trajectory, flow_mm3_s, layer_height_mm, SlenderBound::Paper)?;
    Ok(state.finish(trajectory, 0))
}

/// Boundary points p ± w·n_dep with w from eqs 10-11 evaluated with κ_eff.
pub fn boundary_points(trajectory: &Trajectory, directions: &DepositionDirections) -> BeadBoundary {
    let n = trajectory.len();
    let mut out = BeadBoundary {
        left_mm: Vec::with_capacity(n),
        right_mm: Vec::with_capacity(n),
        left_half_width_mm: Vec::with_capacity(n),
        right_half_width_mm: Vec::with_capacity(n),
    };
    for k in 0..n {
        let widths = half_widths_from_reach(directions.reach_mm[k], directions.effective_curvature_per_mm[k]);
        let (sin, cos) = directions.deposition_heading_rad[k].sin_cos();
        let (x, y) = (trajectory.x_mm[k], trajectory.y_mm[k]);
        out.left_mm.push([x - widths.left_mm * sin, y + widths.left_mm * cos]);
        out.right_mm.push([x + widths.right_mm * sin, y - widths.right_mm * cos]);
        out.left_half_width_mm.push(widths.left_mm);
        out.right_half_width_mm.push(widths.right_mm);
    }
    out
}

/// Working state of the allocation loop.
struct Allocation {
    kappa: Vec<f64>,
    added: Vec<f64>,
    /// |v|h/E (1/mm): the largest |κ_eff| of eq. 15 (∞ without flow).
    limit: Vec<f64>,
    /// |v|·T_s (mm): the arc length of one sample.
    step_mm: Vec<f64>,
    reach_mm: Vec<f64>,
    /// Cumulative added rotation Σ κ_φ|v|T_s up to each sample (rad).
    cumulative: Vec<f64>,
    bound: SlenderBound,
}

impl Allocation {
    fn new(tr: &Trajectory, flow: &[f64], h: f64, bound: SlenderBound) -> Result<Self, ThermalError> {
        if flow.len() != tr.len() {
            return Err(ThermalError::BadTrajectory {
                message: format!("{} flow samples for {} trajectory samples", flow.len(), tr.len()),
            });
        }
        super::errors::positive("layer_height_mm", h)?;
        let speed = tr.speed_mm_s();
        let reach_mm: Vec<f64> = flow.iter().zip(&speed).map(|(e, v)| bead_reach_mm(*e, *v, h)).collect();
        Ok(Self {
            kappa: curvature_per_mm(&tr.x_mm, &tr.y_mm, tr.dt_s),
            added: vec![0.0; tr.len()],
            limit: reach_mm.iter().map(|q| 1.0 / q).collect(),
            step_mm: speed.iter().map(|v| v * tr.dt_s).collect(),
            reach_mm,
            cumulative: vec![0.0; tr.len()],
            bound,
        })
    }

    /// Largest |κ_eff| at sample `k` when the deposition direction is rotated by `psi`.
    fn bound_at(&self, k: usize, psi: f64) -> f64 {
        match self.bound {
            SlenderBound::Paper => self.limit[k],
            SlenderBound::RotatedFrame if self.limit[k].is_infinite() => f64::INFINITY,
            SlenderBound::RotatedFrame => self.limit[k] * psi.cos().powi(2),
        }
    }

    fn effective(&self, k: usize) -> f64 {
        self.kappa[k] + self.added[k]
    }

    fn violates(&self, k: usize) -> bool {
        let kappa_eff = self.effective(k);
        kappa_eff != 0.0 && kappa_eff.abs() > self.bound_at(k, self.cumulative[k]) * (1.0 + SLENDER_TOL)
    }

    fn update_cumulative(&mut self) {
        let mut sum = 0.0;
        for k in 0..self.added.len() {
            sum += self.added[k] * self.step_mm[k];
            self.cumulative[k] = sum;
        }
    }

    /// The first continuous span t_v of samples that violate eq. 15 (inclusive indices).
    fn first_violating_span(&mut self) -> Option<(usize, usize)> {
        self.update_cumulative();
        let first = (0..self.kappa.len()).find(|&k| self.violates(k))?;
        let last = (first..self.kappa.len()).take_while(|&k| self.violates(k)).last().unwrap_or(first);
        Some((first, last))
    }

    /// Eqs 17-25 for one span; `Err` carries the rotation that could not be placed.
    fn resolve_span(&mut self, first: usize, last: usize) -> Result<(), f64> {
        let delta_phi = self.clamp_span(first, last);
        let n = self.kappa.len();
        let rest = self.hand_out(last + 1..n, -0.5 * delta_phi, true);
        let rest = self.hand_out((0..first).rev(), -0.5 * delta_phi + rest, false);
        let rest = if rest != 0.0 { self.hand_out(last + 1..n, rest, true) } else { rest };
        if rest != 0.0 {
            return Err(rest);
        }
        Ok(())
    }

    /// Eq. 17 on the span (iterated with ψ for the rotated-frame bound); returns ΔΦ (eq. 18).
    fn clamp_span(&mut self, first: usize, last: usize) -> f64 {
        let base: Vec<f64> = self.added[first..=last].to_vec();
        let signs: Vec<f64> = (first..=last).map(|k| self.effective(k).signum()).collect();
        let mut psi: Vec<f64> = self.cumulative[first..=last].to_vec();
        let mut delta_phi = 0.0;
        for _ in 0..FIXED_POINT_ITERATIONS {
            let mut partial = Vec::with_capacity(psi.len());
            delta_phi = 0.0;
            for (i, k) in (first..=last).enumerate() {
                self.added[k] = signs[i] * self.bound_at(k, psi[i]) - self.kappa[k];
                delta_phi += (self.added[k] - base[i]) * self.step_mm[k];
                partial.push(delta_phi);
            }
            // The past receives −ΔΦ/2 before the span; ψ inside follows the span's own rotation.
            let mut change: f64 = 0.0;
            for (i, k) in (first..=last).enumerate() {
                let next = self.cumulative[k] - 0.5 * delta_phi + partial[i];
                change = change.max((next - psi[i]).abs());
                psi[i] = next;
            }
            if change < 1e-14 || self.bound == SlenderBound::Paper {
                break;
            }
        }
        delta_phi
    }

    /// Eqs 20-25: hands `phi` out over `indices`, forward in time or backward; returns
    /// what could not be placed.
    fn hand_out(&mut self, indices: impl Iterator<Item = usize>, mut phi: f64, forward: bool) -> f64 {
        for k in indices {
            if phi == 0.0 {
                break;
            }
            let step = self.step_mm[k];
            if step <= 0.0 {
                continue;
            }
            let candidate = phi / step; // eq. 24
            let added = self.allowed_addition(k, phi, candidate, forward);
            if added == 0.0 {
                continue;
            }
            self.added[k] += added;
            phi = if added == candidate { 0.0 } else { phi - added * step }; // eqs 21-22
        }
        phi
    }

    /// Eqs 23 and 25: the candidate, or the allowance if the candidate exceeds it.
    /// ψ at sample k after the span is resolved: backward, the cumulative so far plus all
    /// rotation still to place at or before k; forward, minus what remains after k.
    fn allowed_addition(&self, k: usize, phi: f64, candidate: f64, forward: bool) -> f64 {
        let sign = phi.signum();
        let kappa_eff = self.effective(k);
        let allowance = |psi: f64| sign * self.bound_at(k, psi) - kappa_eff;
        let choose = |allow: f64| if candidate.abs() <= allow.abs() { candidate } else { allow };
        if !forward {
            let allow = allowance(self.cumulative[k] + phi);
            return if allow * sign > 0.0 { choose(allow) } else { 0.0 };
        }
        let mut allow = allowance(self.cumulative[k] - phi);
        let mut added = 0.0;
        for _ in 0..4 {
            if allow * sign <= 0.0 {
                return 0.0;
            }
            added = choose(allow);
            allow = allowance(self.cumulative[k] - (phi - added * self.step_mm[k]));
        }
        if allow * sign <= 0.0 {
            0.0
        } else {
            added
        }
    }

    fn finish(mut self, tr: &Trajectory, spans: usize) -> DepositionDirections {
        self.update_cumulative();
        let n = tr.len();
        let effective: Vec<f64> = (0..n).map(|k| self.effective(k)).collect();
        let heading = unwrapped_heading(tr);
        let mut deposition = vec![0.0; n];
        for k in 0..n {
            deposition[k] = if k == 0 { heading[0] } else { deposition[k - 1] + effective[k] * self.step_mm[k] };
        }
        let sc = |kappa: f64, q: f64| if kappa == 0.0 || q == 0.0 { 0.0 } else { kappa.abs() * q };
        DepositionDirections {
            slender_before: (0..n).map(|k| sc(self.kappa[k], self.reach_mm[k])).collect(),
            slender_after: (0..n).map(|k| sc(effective[k], self.reach_mm[k])).collect(),
            psi_rad: deposition.iter().zip(&heading).map(|(d, h)| d - h).collect(),
            curvature_per_mm: self.kappa,
            added_curvature_per_mm: self.added,
            effective_curvature_per_mm: effective,
            reach_mm: self.reach_mm,
            heading_rad: heading,
            deposition_heading_rad: deposition,
            spans,
        }
    }
}

/// Heading of the commanded velocity, unwrapped; samples at rest take the nearest
/// defined heading (the first moving sample's for leading ones).
fn unwrapped_heading(tr: &Trajectory) -> Vec<f64> {
    let raw: Vec<Option<f64>> =
        tr.vx_mm_s.iter().zip(&tr.vy_mm_s).map(|(vx, vy)| (vx.hypot(*vy) > 0.0).then(|| vy.atan2(*vx))).collect();
    let first = raw.iter().flatten().next().copied().unwrap_or(0.0);
    let mut out = Vec::with_capacity(raw.len());
    let mut prev = first;
    for angle in raw {
        let a = angle.unwrap_or(prev);
        let step = (a - prev + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        prev += step;
        out.push(prev);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thermal::dynamics::first_order_lag;
    use crate::thermal::PrintSetup;

    fn corner_test_with_lagged_flow() -> (Trajectory, Vec<f64>, f64) {
        let setup = PrintSetup::paper_defaults();
        let tr = Trajectory::corner_test(&setup).unwrap();
        let commanded: Vec<f64> = tr.speed_mm_s().iter().map(|v| setup.nominal_flow_mm3_s(*v)).collect();
        let flow = first_order_lag(&commanded, tr.dt_s, setup.tau_s, 0.0);
        (tr, flow, setup.layer_height_mm)
    }

    /// Deepest crossing (mm from the outer end) of consecutive deposition segments
    /// p_k → b_k on either side; 0 when none cross.
    fn deepest_crossing_mm(tr: &Trajectory, boundary: &BeadBoundary) -> f64 {
        let mut deepest: f64 = 0.0;
        for k in 0..tr.len() - 1 {
            let (p, q) = ([tr.x_mm[k], tr.y_mm[k]], [tr.x_mm[k + 1], tr.y_mm[k + 1]]);
            for (ends, widths) in
                [(&boundary.left_mm, &boundary.left_half_width_mm), (&boundary.right_mm, &boundary.right_half_width_mm)]
            {
                if let Some((a, b)) = segment_intersection(p, ends[k], q, ends[k + 1]) {
                    deepest = deepest.max(((1.0 - a) * widths[k]).min((1.0 - b) * widths[k + 1]));
                }
            }
        }
        deepest
    }

    /// Parameters (along each segment, 0..1) of the proper intersection of p1→p2 and p3→p4.
    fn segment_intersection(p1: [f64; 2], p2: [f64; 2], p3: [f64; 2], p4: [f64; 2]) -> Option<(f64, f64)> {
        let r = [p2[0] - p1[0], p2[1] - p1[1]];
        let s = [p4[0] - p3[0], p4[1] - p3[1]];
        let den = r[0] * s[1] - r[1] * s[0];
        if den == 0.0 || !den.is_finite() {
            return None;
        }
        let d = [p3[0] - p1[0], p3[1] - p1[1]];
        let a = (d[0] * s[1] - d[1] * s[0]) / den;
        let b = (d[0] * r[1] - d[1] * r[0]) / den;
        (a > 0.0 && a < 1.0 && b > 0.0 && b < 1.0).then_some((a, b))
    }

    #[test]
    fn straight_line_is_left_unchanged() {
        let (dt, speed, n) = (1e-3, 20.0, 500);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let tr = Trajectory {
            dt_s: dt,
            x_mm: t.iter().map(|t| 1.0 + speed * t * 0.6).collect(),
            y_mm: t.iter().map(|t| 2.0 + speed * t * 0.8).collect(),
            vx_mm_s: vec![speed * 0.6; n],
            vy_mm_s: vec![speed * 0.8; n],
            s_mm: t.iter().map(|t| speed * t).collect(),
            path_curvature_per_mm: vec![0.0; n],
            corners: Vec::new(),
            t_s: t,
        };
        let flow = vec![PrintSetup::paper_defaults().nominal_flow_mm3_s(speed); n];
        let dirs = allocate_directions(&tr, &flow, 0.25, &DdaParams::default()).unwrap();
        assert_eq!(dirs.spans, 0);
        assert!(dirs.added_curvature_per_mm.iter().all(|k| *k == 0.0));
        assert!(dirs.psi_rad.iter().all(|p| p.abs() < 1e-12));
        assert!(dirs.curvature_per_mm.iter().all(|k| k.abs() < 1e-9));
    }

    #[test]
    fn allocation_makes_every_sample_slender() {
        let (tr, flow, h) = corner_test_with_lagged_flow();
        let dirs = allocate_directions(&tr, &flow, h, &DdaParams::default()).unwrap();
        // Every corner violates eq. 12 before: the head slows while the lagged flow does not.
        assert!(dirs.slender_before.iter().cloned().fold(0.0, f64::max) > 10.0);
        assert!(dirs.spans >= tr.corners.len());
        let worst = dirs.slender_after.iter().cloned().fold(0.0, f64::max);
        assert!(worst <= 1.0 + 1e-6, "max S_c after DDA {worst}");
        // The rotated-frame bound holds too: |κ_eff| q ≤ cos²ψ (ψ from the added rotation).
        let mut psi_added = 0.0;
        for k in 0..tr.len() {
            psi_added += dirs.added_curvature_per_mm[k] * tr.speed_mm_s()[k] * tr.dt_s;
            assert!(dirs.slender_after[k] <= psi_added.cos().powi(2) * (1.0 + 1e-6), "sample {k}");
        }
    }

    #[test]
    fn a_bead_far_wider_than_the_corners_allow_is_named_as_such() {
        // The same flow through a layer 250 times thinner: half-widths no allocation can fit.
        let (tr, flow, h) = corner_test_with_lagged_flow();
        let err =
            allocate_directions(&tr, &flow, h / 250.0, &DdaParams { max_spans: 50, ..Default::default() }).unwrap_err();
        assert!(matches!(err, ThermalError::TooManySpans { max_spans: 50, .. }), "{err}");
        assert!(err.to_string().contains("far wider than the path's corners allow"), "{err}");
    }

    #[test]
    fn allocated_rotation_integrates_back_between_corners() {
        // Eq. 16: ∫κ_eff|v|dt = ∫κ|v|dt between mid-edge samples far from any corner.
        let (tr, flow, h) = corner_test_with_lagged_flow();
        let dirs = allocate_directions(&tr, &flow, h, &DdaParams::default()).unwrap();
        let speed = tr.speed_mm_s();
        let mut cuts = vec![0];
        for w in tr.corners.windows(2) {
            cuts.push(((w[0].arc_end_s + w[1].arc_start_s) / 2.0 / tr.dt_s) as usize);
        }
        cuts.push(tr.len());
        for w in cuts.windows(2) {
            let turn: f64 = (w[0]..w[1]).map(|k| dirs.curvature_per_mm[k] * speed[k] * tr.dt_s).sum();
            let turn_eff: f64 = (w[0]..w[1]).map(|k| dirs.effective_curvature_per_mm[k] * speed[k] * tr.dt_s).sum();
            assert!(turn.abs() > 0.3, "each window holds one corner: {turn}");
            assert!((turn_eff - turn).abs() < 1e-9 * turn.abs(), "{}..{}: {turn_eff} vs {turn}", w[0], w[1]);
        }
    }

    #[test]
    fn boundaries_cross_without_allocation_and_not_with_it() {
        let (tr, flow, h) = corner_test_with_lagged_flow();
        let with = allocate_directions(&tr, &flow, h, &DdaParams::default()).unwrap();
        let without = without_allocation(&tr, &flow, h).unwrap();
        let paper = allocate_directions(&tr, &flow, h, &DdaParams { bound: SlenderBound::Paper, ..Default::default() })
            .unwrap();
        let depth_with = deepest_crossing_mm(&tr, &boundary_points(&tr, &with));
        let depth_without = deepest_crossing_mm(&tr, &boundary_points(&tr, &without));
        let depth_paper = deepest_crossing_mm(&tr, &boundary_points(&tr, &paper));
        // Touching at the outer ends (segments rotating about their tip where S_c = 1)
        // is allowed to within 5 µm, far below a grid cell.
        assert!(depth_with < 0.005, "with DDA: {depth_with} mm");
        assert!(depth_without > 0.1, "without DDA: {depth_without} mm");
        assert!(depth_paper > 0.1, "paper's literal bound: {depth_paper} mm");
        // The allocation has handed back all rotation by the end of the path.
        assert!(with.psi_rad.last().unwrap().abs() < 0.02);
    }
}
