//! Printed-path geometry of paper 003, Sec. 2.1: velocity and printing direction
//! (eq. 1), curvature from the samples (eq. 4), the left and right half widths that
//! conserve material on a curved path (eqs 5-11) and the slender deposition condition
//! (eqs 12/15).
//!
//! Units: flow E in mm³/s, speed in mm/s, layer height h in mm, so that the straight-line
//! half width w = E/(2h|v|) (eq. 3) is in mm. The quantity `q = E/(|v|h) = 2w` (mm) appears
//! in every formula and is called the bead reach here.
//!
//! Eq. 4 is written with derivatives along the curve; we evaluate it with time
//! derivatives (central differences of x(t), y(t)), which gives the same κ because the
//! numerator scales with ṡ³ and the denominator with ṡ³. Eqs 10-11 are evaluated in the
//! algebraically equivalent forms `w_l = q/(1 + sqrt(1 − κq))`, `w_r = q/(1 + sqrt(1 + κq))`,
//! which stay accurate as κ → 0 (no cancellation) and give w = q/2 on straight lines.
//! Where the slender condition fails there is no real root; we return the limit value at
//! S_c = 1 (the inner width equals q) and let the caller check [`slender_condition`].
//! At |v| = 0 with flow the reach is infinite: S_c = ∞ unless κ = 0 (then 0: a straight
//! path has no side to cross).

/// Speeds below this (mm/s) count as standing still for eq. 4 (curvature undefined, set to 0).
const STANDSTILL_MM_S: f64 = 1e-9;

/// Left and right half widths of the printed path at one sample (mm), eqs 10-11.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HalfWidths {
    /// Half width to the left of the path (mm).
    pub left_mm: f64,
    /// Half width to the right of the path (mm).
    pub right_mm: f64,
}

/// Velocity by central differences of the samples (eq. 1), one-sided at the ends (mm/s).
pub fn velocity_mm_s(x_mm: &[f64], y_mm: &[f64], dt_s: f64) -> (Vec<f64>, Vec<f64>) {
    let n = x_mm.len();
    let diff = |v: &[f64], k: usize| -> f64 {
        match (k, n) {
            (_, 0 | 1) => 0.0,
            (0, _) => (v[1] - v[0]) / dt_s,
            (k, n) if k == n - 1 => (v[k] - v[k - 1]) / dt_s,
            (k, _) => (v[k + 1] - v[k - 1]) / (2.0 * dt_s),
        }
    };
    ((0..n).map(|k| diff(x_mm, k)).collect(), (0..n).map(|k| diff(y_mm, k)).collect())
}

/// Unit printing direction e = v/|v| (eq. 1); `None` when standing still.
pub fn unit_direction(vx_mm_s: f64, vy_mm_s: f64) -> Option<[f64; 2]> {
    let speed = vx_mm_s.hypot(vy_mm_s);
    (speed > STANDSTILL_MM_S).then(|| [vx_mm_s / speed, vy_mm_s / speed])
}

/// Curvature κ (1/mm, + counter-clockwise) of eq. 4 from central differences of the
/// samples; the end samples copy their neighbours, samples at rest get 0.
pub fn curvature_per_mm(x_mm: &[f64], y_mm: &[f64], dt_s: f64) -> Vec<f64> {
    let n = x_mm.len();
    let mut kappa = vec![0.0; n];
    if n < 3 {
        return kappa;
    }
    for k in 1..n - 1 {
        let xd = (x_mm[k + 1] - x_mm[k - 1]) / (2.0 * dt_s);
        let yd = (y_mm[k + 1] - y_mm[k - 1]) / (2.0 * dt_s);
        let xdd = (x_mm[k + 1] - 2.0 * x_mm[k] + x_mm[k - 1]) / (dt_s * dt_s);
        let ydd = (y_mm[k + 1] - 2.0 * y_mm[k] + y_mm[k - 1]) / (dt_s * dt_s);
        let speed = xd.hypot(yd);
        if speed > STANDSTILL_MM_S {
            kappa[k] = (xd * ydd - xdd * yd) / (speed * speed * speed);
        }
    }
    kappa[0] = kappa[1];
    kappa[n - 1] = kappa[n - 2];
    kappa
}

/// Bead reach q = E/(|v|h) = 2w (mm): 0 without flow, ∞ at rest with flow.
pub fn bead_reach_mm(flow_mm3_s: f64, speed_mm_s: f64, layer_height_mm: f64) -> f64 {
    if flow_mm3_s <= 0.0 {
        0.0
    } else if speed_mm_s <= 0.0 {
        f64::INFINITY
    } else {
        flow_mm3_s / (speed_mm_s * layer_height_mm)
    }
}

/// Straight-line half width w = E/(2h|v|) (mm), eq. 3.
pub fn straight_half_width_mm(flow_mm3_s: f64, speed_mm_s: f64, layer_height_mm: f64) -> f64 {
    0.5 * bead_reach_mm(flow_mm3_s, speed_mm_s, layer_height_mm)
}

/// Slender deposition condition S_c = |κ E/(|v|h)| of eq. 12 (eq. 15 with κ = κ_eff);
/// the deposit is slender where S_c ≤ 1.
pub fn slender_condition(flow_mm3_s: f64, speed_mm_s: f64, layer_height_mm: f64, curvature_per_mm: f64) -> f64 {
    let reach = bead_reach_mm(flow_mm3_s, speed_mm_s, layer_height_mm);
    if curvature_per_mm == 0.0 || reach == 0.0 {
        0.0
    } else {
        curvature_per_mm.abs() * reach
    }
}

/// Left and right half widths of eqs 10-11 (mm) in their cancellation-free forms; where
/// S_c > 1 the inner side takes its limit value q (see the module doc).
pub fn half_widths_mm(flow_mm3_s: f64, speed_mm_s: f64, layer_height_mm: f64, curvature_per_mm: f64) -> HalfWidths {
    let reach = bead_reach_mm(flow_mm3_s, speed_mm_s, layer_height_mm);
    half_widths_from_reach(reach, curvature_per_mm)
}

/// Eqs 10-11 for a given bead reach q (mm) and curvature κ (1/mm).
pub fn half_widths_from_reach(reach_mm: f64, curvature_per_mm: f64) -> HalfWidths {
    if reach_mm.is_infinite() {
        return HalfWidths { left_mm: f64::INFINITY, right_mm: f64::INFINITY };
    }
    let kq = curvature_per_mm * reach_mm;
    HalfWidths {
        left_mm: reach_mm / (1.0 + (1.0 - kq).max(0.0).sqrt()),
        right_mm: reach_mm / (1.0 + (1.0 + kq).max(0.0).sqrt()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thermal::{PrintSetup, Trajectory};

    #[test]
    fn straight_line_has_the_constant_width_of_eq_3() {
        // On a line κ = 0, so both half widths are E/(2h|v|).
        let (flow, speed, h) = (2.25, 20.0, 0.25);
        let w = half_widths_mm(flow, speed, h, 0.0);
        let expected = flow / (2.0 * h * speed);
        assert!((w.left_mm - expected).abs() < 1e-15 && (w.right_mm - expected).abs() < 1e-15);
        assert_eq!(slender_condition(flow, speed, h, 0.0), 0.0);
        assert_eq!(slender_condition(flow, 0.0, h, 0.0), 0.0);
        assert_eq!(slender_condition(flow, 0.0, h, 0.1), f64::INFINITY);
    }

    #[test]
    fn circular_arc_widths_match_eqs_8_to_11() {
        let (flow, speed, h) = (1.5, 8.0, 0.25);
        for kappa in [-1.2, -0.3, 1e-9, 0.4, 1.3] {
            let q = flow / (speed * h);
            let w = half_widths_mm(flow, speed, h, kappa);
            // Closed forms of eqs 10-11 (no cancellation at these κ).
            let wl = (1.0 - (1.0 - kappa * q).sqrt()) / kappa;
            let wr = (-1.0 + (1.0 + kappa * q).sqrt()) / kappa;
            assert!((w.left_mm - wl).abs() < 1e-6 * wl && (w.right_mm - wr).abs() < 1e-6 * wr, "κ {kappa}");
            // Eqs 8-9.
            assert!((kappa / 2.0 * w.left_mm.powi(2) - w.left_mm + q / 2.0).abs() < 1e-14);
            assert!((kappa / 2.0 * w.right_mm.powi(2) + w.right_mm - q / 2.0).abs() < 1e-14);
            // Eqs 5-7: both sides receive S = E ds/(2|v|h) per unit ds.
            let s_left = w.left_mm * (1.0 - w.left_mm * kappa / 2.0);
            let s_right = w.right_mm * (1.0 + w.right_mm * kappa / 2.0);
            assert!((s_left - q / 2.0).abs() < 1e-14 && (s_right - q / 2.0).abs() < 1e-14);
        }
    }

    #[test]
    fn eq_4_on_a_sampled_circle_gives_one_over_r() {
        // Uniform motion on a circle sampled at dt: the central-difference κ is
        // (1/R)·2/(1 + cos ωdt), within (ωdt)²/4 of 1/R. Clockwise gives −1/R.
        let (radius, omega, dt) = (2.0, 10.0, 1e-3);
        for sign in [1.0, -1.0] {
            let t: Vec<f64> = (0..200).map(|k| k as f64 * dt).collect();
            let x: Vec<f64> = t.iter().map(|t| radius * (sign * omega * t).cos()).collect();
            let y: Vec<f64> = t.iter().map(|t| radius * (sign * omega * t).sin()).collect();
            let kappa = curvature_per_mm(&x, &y, dt);
            let exact = sign / radius * 2.0 / (1.0 + (omega * dt).cos());
            assert!(kappa.iter().all(|k| (k - exact).abs() < 1e-9), "{}", kappa[5]);
            assert!((exact - sign / radius).abs() < 1e-4);
        }
    }

    #[test]
    fn eq_4_matches_the_planned_path_curvature_away_from_arc_ends() {
        let tr = Trajectory::corner_test(&PrintSetup::paper_defaults()).unwrap();
        let kappa = curvature_per_mm(&tr.x_mm, &tr.y_mm, tr.dt_s);
        let near_end = |t: f64| {
            tr.corners
                .iter()
                .any(|c| (t - c.arc_start_s).abs() < 3.0 * tr.dt_s || (t - c.arc_end_s).abs() < 3.0 * tr.dt_s)
        };
        let mut checked = 0;
        for k in 1..tr.len() - 1 {
            if near_end(tr.t_s[k]) {
                continue;
            }
            let path = tr.path_curvature_per_mm[k];
            // On the tightest arc (r = 0.031 mm at 3.9 mm/s) ωdt = 0.13: 0.5 % of 1/r.
            assert!((kappa[k] - path).abs() < 0.01 * path.abs() + 1e-3, "sample {k}: {} vs {path}", kappa[k]);
            checked += 1;
        }
        // Up to seven samples around each of the two arc ends are skipped, nothing else.
        assert!(checked > tr.len() - 16 * tr.corners.len());
    }
}
