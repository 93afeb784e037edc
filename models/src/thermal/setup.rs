//! The printing parameters of paper 003 (Table 1) and the corner test path (Fig. 7a).
//!
//! The paper does not give the test path's coordinates, only that it has "different
//! angles of corners" (Fig. 7a, "4 types of corners", Sec. 3.3) and prints in about
//! 10 s. Ours is a closed, counter-clockwise path 37 mm wide: 10 mm straight sides and
//! a zig-zag top and bottom, each of four teeth with apex angles of 45°, 60°, 90° and
//! 120°; the valleys between them add corners of 52.5°, 75° and 105°, the sides meet
//! the zig-zags at 120° and 157.5°, eighteen corners in all, about 8 s of printing.
//! Teeth 5 mm high put corners every 5-10 mm of path, so that four or more corners that
//! are still hot lie within the camera's field of view (about 20 mm at 14.5 mm and 45°)
//! in many frames, which the homography needs (eq. 27).

use super::errors::{positive, ThermalError};

/// The process parameters the planner, the deposition model and the virtual printer share.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrintSetup {
    /// Programmed feed (mm/s), Table 1: 20 mm/s.
    pub feed_mm_s: f64,
    /// Acceleration limit (mm/s²), Table 1: 500 mm/s².
    pub accel_mm_s2: f64,
    /// Corner blending tolerance (mm), Table 1: 0.05 mm.
    pub blend_tol_mm: f64,
    /// Layer height h (mm), Table 1: 0.25 mm.
    pub layer_height_mm: f64,
    /// Nozzle diameter (mm), Table 1: 0.4 mm.
    pub nozzle_mm: f64,
    /// Nominal bead width 2·w0 of a straight line (mm). Not in the paper, whose w0
    /// depends on its feed-to-deposition ratio (Sec. 3.2); 0.45 mm is the usual
    /// extrusion width for a 0.4 mm nozzle (1.125 × nozzle).
    pub bead_width_mm: f64,
    /// Deposition time constant τ of eq. 34 (s), Sec. 3.2: 0.0873 s.
    pub tau_s: f64,
    /// Nozzle temperature (°C), Table 1: 230 °C.
    pub nozzle_temp_c: f64,
    /// Bed temperature (°C), Table 1: 60 °C.
    pub bed_temp_c: f64,
    /// Number of layers of the test part (Fig. 7b): 20.
    pub layers: usize,
    /// Filament diameter (mm). Not in Table 1; the Flashforge Creator 3 takes 1.75 mm
    /// filament. It turns the extruder's (E-axis) velocity, the paper's "deposition
    /// velocity" v_e (Sec. 2.4, eqs 36-39), into a volumetric flow E = A_fil·v_e.
    pub filament_diameter_mm: f64,
    /// Sampling period T_s of the trajectory (s). The paper leaves it open (eq. 20);
    /// 1 ms resolves a 20 mm/s path to 0.02 mm, a tenth of the blend radius of a 90° corner.
    pub sample_period_s: f64,
}

impl PrintSetup {
    /// Table 1 of the paper, with the choices above where it is silent.
    pub fn paper_defaults() -> Self {
        Self {
            feed_mm_s: 20.0,
            accel_mm_s2: 500.0,
            blend_tol_mm: 0.05,
            layer_height_mm: 0.25,
            nozzle_mm: 0.4,
            bead_width_mm: 0.45,
            tau_s: 0.0873,
            nozzle_temp_c: 230.0,
            bed_temp_c: 60.0,
            layers: 20,
            filament_diameter_mm: 1.75,
            sample_period_s: 0.001,
        }
    }

    /// Checks that every quantity is positive and finite.
    pub fn check(self) -> Result<Self, ThermalError> {
        positive("feed_mm_s", self.feed_mm_s)?;
        positive("accel_mm_s2", self.accel_mm_s2)?;
        positive("blend_tol_mm", self.blend_tol_mm)?;
        positive("layer_height_mm", self.layer_height_mm)?;
        positive("nozzle_mm", self.nozzle_mm)?;
        positive("bead_width_mm", self.bead_width_mm)?;
        positive("tau_s", self.tau_s)?;
        positive("filament_diameter_mm", self.filament_diameter_mm)?;
        positive("sample_period_s", self.sample_period_s)?;
        if self.layers == 0 {
            return Err(ThermalError::NotPositive { name: "layers", value: 0.0 });
        }
        Ok(self)
    }

    /// Steady commanded flow E for a straight line at speed `speed_mm_s` (mm³/s):
    /// the bead cross-section (width × layer height) times the speed, paper eq. 3
    /// with w = w0 (E = 2·h·|v|·w0).
    pub fn nominal_flow_mm3_s(&self, speed_mm_s: f64) -> f64 {
        self.bead_width_mm * self.layer_height_mm * speed_mm_s
    }

    /// Cross-section of the filament (mm²).
    pub fn filament_area_mm2(&self) -> f64 {
        std::f64::consts::PI * self.filament_diameter_mm * self.filament_diameter_mm / 4.0
    }

    /// Deposition (extruder, E-axis) velocity that gives the nominal bead at path speed
    /// `speed_mm_s` (mm/s of filament): the nominal flow over the filament area.
    pub fn nominal_deposition_velocity_mm_s(&self, speed_mm_s: f64) -> f64 {
        self.nominal_flow_mm3_s(speed_mm_s) / self.filament_area_mm2()
    }

    /// The conventional print's command: at every sample of `trajectory` the deposition
    /// velocity that gives the nominal bead at the commanded path speed (flow ∝ speed,
    /// as a slicer commands it; paper 003 compensates away from this, eqs 31-39).
    pub fn conventional_command(&self, trajectory: &super::Trajectory) -> Vec<f64> {
        trajectory.speed_mm_s().iter().map(|v| self.nominal_deposition_velocity_mm_s(*v)).collect()
    }

    /// The samples of `trajectory` where the nominal deposition dynamics (eq. 34 with
    /// this setup's τ) have settled: the conventional command through G(s) is within
    /// `tolerance` × the steady command at the feed. After each corner the head
    /// accelerates while the flow still lags, so a short leg is thinner than the nominal
    /// bead along most of its length; only settled samples show the nominal bead.
    pub fn settled_samples(&self, trajectory: &super::Trajectory, tolerance: f64) -> Vec<bool> {
        let command = self.conventional_command(trajectory);
        let steady = self.nominal_deposition_velocity_mm_s(self.feed_mm_s);
        let excess = super::dynamics::lag_excess(&command, trajectory.dt_s, self.tau_s);
        excess.iter().map(|e| e.abs() <= tolerance * steady).collect()
    }
}

/// Height of each tooth of the test path's zig-zags (mm).
pub const TOOTH_HEIGHT_MM: f64 = 5.0;
/// Length of the straight sides between the two zig-zags (mm).
pub const BASE_HEIGHT_MM: f64 = 10.0;
/// Apex angles of the four teeth of the top zig-zag, right to left in print order;
/// the bottom zig-zag has the same teeth below them, printed left to right (degrees).
pub const TOOTH_APEX_DEG: [f64; 4] = [120.0, 90.0, 60.0, 45.0];

/// Vertices of the corner test path (mm), counter-clockwise, starting at the
/// bottom-right end of the right side: up the right side, the top zig-zag right to
/// left, down the left side, the bottom zig-zag left to right. The path is closed:
/// the last vertex joins the first. Print starts in the middle of the right side.
pub fn corner_test_path() -> Vec<[f64; 2]> {
    let half_bases: Vec<f64> =
        TOOTH_APEX_DEG.iter().map(|deg| TOOTH_HEIGHT_MM * (deg.to_radians() / 2.0).tan()).collect();
    let width_mm: f64 = 2.0 * half_bases.iter().sum::<f64>();
    let mut vertices = vec![[width_mm, 0.0], [width_mm, BASE_HEIGHT_MM]];
    let mut x = width_mm;
    for half in &half_bases {
        vertices.push([x - half, BASE_HEIGHT_MM + TOOTH_HEIGHT_MM]);
        x -= 2.0 * half;
        vertices.push([x, BASE_HEIGHT_MM]);
    }
    // The last top valley is the top-left corner (0, BASE_HEIGHT_MM); then down the left side.
    vertices.push([0.0, 0.0]);
    for half in half_bases.iter().rev() {
        vertices.push([x + half, -TOOTH_HEIGHT_MM]);
        x += 2.0 * half;
        vertices.push([x, 0.0]);
    }
    // The last bottom valley is the first vertex.
    vertices.pop();
    vertices
}

/// A point in the middle of the left side, the longest straight run between two
/// gentle corners, where the flow has settled (mm), and the side's direction of travel.
pub fn straight_test_point() -> ([f64; 2], [f64; 2]) {
    ([0.0, BASE_HEIGHT_MM / 2.0], [0.0, -1.0])
}

/// Interior angle of a closed polygon at each vertex (degrees), between its two edges.
pub fn interior_angles_deg(polygon_mm: &[[f64; 2]]) -> Vec<f64> {
    let n = polygon_mm.len();
    (0..n)
        .map(|i| {
            let (prev, at, next) = (polygon_mm[(i + n - 1) % n], polygon_mm[i], polygon_mm[(i + 1) % n]);
            let a = [prev[0] - at[0], prev[1] - at[1]];
            let b = [next[0] - at[0], next[1] - at[1]];
            let cos = (a[0] * b[0] + a[1] * b[1]) / (a[0].hypot(a[1]) * b[0].hypot(b[1]));
            cos.clamp(-1.0, 1.0).acos().to_degrees()
        })
        .collect()
}

/// For each vertex of a closed polygon, whether it is convex: the polygon turns there
/// the way it turns overall, so the outside of the turn is the outside of the part (an
/// apex); false at a reflex vertex (a valley, whose outside is the inside of the turn).
pub fn convex_vertices(polygon_mm: &[[f64; 2]]) -> Vec<bool> {
    let n = polygon_mm.len();
    let turn = |i: usize| {
        let (prev, at, next) = (polygon_mm[(i + n - 1) % n], polygon_mm[i], polygon_mm[(i + 1) % n]);
        (at[0] - prev[0]) * (next[1] - at[1]) - (at[1] - prev[1]) * (next[0] - at[0])
    };
    let area2: f64 = (0..n)
        .map(|i| polygon_mm[i][0] * polygon_mm[(i + 1) % n][1] - polygon_mm[(i + 1) % n][0] * polygon_mm[i][1])
        .sum();
    (0..n).map(|i| turn(i) * area2 > 0.0).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conventional_command_is_the_nominal_flow_over_the_filament_area_at_each_speed() {
        // v_e = w·h·v / (π d²/4) at every sample: proportional to the path speed.
        let setup = PrintSetup::paper_defaults();
        let trajectory = super::super::Trajectory::corner_test(&setup).unwrap();
        let command = setup.conventional_command(&trajectory);
        let speeds = trajectory.speed_mm_s();
        assert_eq!(command.len(), speeds.len());
        for (v_e, v) in command.iter().zip(&speeds) {
            let expected = setup.nominal_flow_mm3_s(*v) / setup.filament_area_mm2();
            assert_eq!(*v_e, expected);
        }
        assert!(command.iter().any(|v| *v > 0.0));
    }

    #[test]
    fn a_steady_feed_settles_once_the_lag_has_decayed_to_the_tolerance() {
        // Constant speed at the feed from rest: the excess is −exp(−t/τ) of the steady
        // command at t = (k+1)·dt, so a sample is settled from t = τ·ln(1/tolerance) on.
        let setup = PrintSetup::paper_defaults();
        let dt = setup.sample_period_s;
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * dt).collect();
        let x: Vec<f64> = t.iter().map(|t| setup.feed_mm_s * t).collect();
        let trajectory = super::super::Trajectory::from_samples(&t, &x, &vec![0.0; t.len()]).unwrap();
        let speeds = trajectory.speed_mm_s();
        let settled = setup.settled_samples(&trajectory, 0.02);
        let settle_s = setup.tau_s * (1.0_f64 / 0.02).ln();
        for (k, s) in settled.iter().enumerate().filter(|(k, _)| (speeds[*k] - setup.feed_mm_s).abs() < 1e-9) {
            let t_s = (k + 1) as f64 * dt;
            if (t_s - settle_s).abs() > 2.0 * dt {
                assert_eq!(*s, t_s > settle_s, "sample {k} at {t_s} s");
            }
        }
        assert!(settled[..10].iter().all(|s| !s) && settled[900..].iter().all(|s| *s));
    }

    #[test]
    fn test_path_has_the_stated_corner_angles() {
        let v = corner_test_path();
        let n = v.len();
        let angles = interior_angles_deg(&v);
        // Top apexes at vertices 2, 4, 6, 8 (valleys 3, 5, 7); bottom apexes at 11, 13, 15, 17
        // (valleys 12, 14, 16), the bottom teeth in reverse order.
        for (k, apex) in TOOTH_APEX_DEG.iter().enumerate() {
            assert!((angles[2 + 2 * k] - apex).abs() < 1e-9, "top apex {k}: {}", angles[2 + 2 * k]);
            assert!((angles[17 - 2 * k] - apex).abs() < 1e-9, "bottom apex {k}: {}", angles[17 - 2 * k]);
        }
        for (k, pair) in TOOTH_APEX_DEG.windows(2).enumerate() {
            let valley = (pair[0] + pair[1]) / 2.0;
            assert!((angles[3 + 2 * k] - valley).abs() < 1e-9, "top valley {k}: {}", angles[3 + 2 * k]);
            assert!((angles[16 - 2 * k] - valley).abs() < 1e-9, "bottom valley {k}: {}", angles[16 - 2 * k]);
        }
        assert_eq!(n, 18);
        // The straight test point is the middle of the left side, between vertices 9 and 10.
        let (p, _) = straight_test_point();
        assert!(v[9][0].abs() < 1e-9 && (v[9][1] - BASE_HEIGHT_MM).abs() < 1e-9 && v[10] == [0.0, 0.0]);
        assert!((p[0] - v[9][0]).abs() < 1e-9 && (p[1] - 0.5 * (v[9][1] + v[10][1])).abs() < 1e-9);
    }

    #[test]
    fn teeth_tips_and_sides_are_convex_and_valleys_are_not() {
        let convex = convex_vertices(&corner_test_path());
        let valleys = [3, 5, 7, 12, 14, 16];
        for (i, c) in convex.iter().enumerate() {
            assert_eq!(*c, !valleys.contains(&i), "vertex {i}");
        }
        let mut clockwise = corner_test_path();
        clockwise.reverse();
        assert_eq!(convex_vertices(&clockwise).iter().filter(|c| **c).count(), 12);
    }

    #[test]
    fn paper_defaults_are_valid() {
        assert!(PrintSetup::paper_defaults().check().is_ok());
    }
}
