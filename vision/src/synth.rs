//! Synthetic thermal frames for tests and benches (not a physics model: the virtual
//! camera of the datasets crate is). A scene is a temperature field on the plane, in
//! world mm; [`render_raw_frame`] images it through the camera contract of `camera.rs`
//! (mount, pinhole, distortion) by mapping every raw pixel centre back to the plane,
//! so corners and edges land exactly where the forward camera code says they do.

use crate::camera::CameraModel;
use crate::frame::ThermalFrame;

/// A hot polyline: bead with a Gaussian cross-section over a uniform background, hotter
/// Gaussian blobs at its interior vertices (material piles up at corners, Sec. 2.3).
#[derive(Debug, Clone, PartialEq)]
pub struct HotPolyline {
    /// Polyline vertices in world mm.
    pub vertices_mm: Vec<[f64; 2]>,
    /// Background temperature (°C).
    pub background_c: f64,
    /// Bead centre-line temperature (°C).
    pub bead_c: f64,
    /// Standard deviation of the bead cross-section (mm).
    pub bead_sigma_mm: f64,
    /// Extra temperature at interior vertices (°C).
    pub corner_excess_c: f64,
    /// Standard deviation of the corner blobs (mm).
    pub corner_sigma_mm: f64,
}

impl HotPolyline {
    /// Temperature at plane point `p` (world mm).
    pub fn temp_c(&self, p: [f64; 2]) -> f64 {
        let d2 = self.vertices_mm.windows(2).map(|s| dist2_to_segment(p, s[0], s[1])).fold(f64::INFINITY, f64::min);
        let bead = (self.bead_c - self.background_c) * (-0.5 * d2 / self.bead_sigma_mm.powi(2)).exp();
        let n = self.vertices_mm.len();
        let corners: f64 = self.vertices_mm[1..n.saturating_sub(1).max(1)]
            .iter()
            .map(|c| {
                let r2 = (p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2);
                self.corner_excess_c * (-0.5 * r2 / self.corner_sigma_mm.powi(2)).exp()
            })
            .sum();
        self.background_c + bead + corners
    }

    /// Interior vertices (the corners a detector should find).
    pub fn corners_mm(&self) -> &[[f64; 2]] {
        let n = self.vertices_mm.len();
        if n < 3 {
            &[]
        } else {
            &self.vertices_mm[1..n - 1]
        }
    }
}

/// A straight bead with a flat top of half width `half_width_mm` and logistic edges of
/// scale `edge_mm`: T = bg + A / (1 + exp((d − w)/s)), so T crosses bg + A/2 exactly at
/// distance w from the centre line on both sides.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StraightBead {
    /// A point on the centre line (world mm).
    pub origin_mm: [f64; 2],
    /// Unit direction of the centre line.
    pub dir: [f64; 2],
    /// Half width at the mid-level (mm).
    pub half_width_mm: f64,
    /// Logistic edge scale (mm).
    pub edge_mm: f64,
    /// Background temperature (°C).
    pub background_c: f64,
    /// Bead excess over the background (°C).
    pub amplitude_c: f64,
}

impl StraightBead {
    /// Temperature at plane point `p` (world mm).
    pub fn temp_c(&self, p: [f64; 2]) -> f64 {
        let (dx, dy) = (p[0] - self.origin_mm[0], p[1] - self.origin_mm[1]);
        let d = (dx * self.dir[1] - dy * self.dir[0]).abs();
        self.background_c + self.amplitude_c / (1.0 + ((d - self.half_width_mm) / self.edge_mm).exp())
    }
}

/// Renders the raw (distorted) frame of `scene` seen with the nozzle at `nozzle_mm`
/// (world), in °C; pixels that see no plane point are NaN.
pub fn render_raw_frame(camera: &CameraModel, nozzle_mm: [f64; 2], scene: impl Fn([f64; 2]) -> f64) -> ThermalFrame {
    let h0 = camera.nominal_homography();
    let (w, h) = (camera.width_px, camera.height_px);
    let mut frame = ThermalFrame::filled(w, h, f32::NAN);
    for v in 0..h {
        for u in 0..w {
            let px = camera.undistort_px([u as f64, v as f64]);
            let rel = h0.apply(px);
            if rel[0].is_finite() && rel[1].is_finite() {
                frame.temp_c[v * w + u] = scene([rel[0] + nozzle_mm[0], rel[1] + nozzle_mm[1]]) as f32;
            }
        }
    }
    frame
}

/// Adds deterministic pseudo-noise of the given standard deviation (a fixed-seed
/// xorshift, uniform with matched variance) to every finite pixel.
pub fn add_noise(frame: &mut ThermalFrame, sigma_c: f32, seed: u64) {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let scale = sigma_c * 3f32.sqrt() * 2.0;
    for t in frame.temp_c.iter_mut().filter(|t| t.is_finite()) {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        let unit = (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
        *t += scale * unit;
    }
}

fn dist2_to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let s = if len2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
    let (ex, ey) = (a[0] + s * dx - p[0], a[1] + s * dy - p[1]);
    ex * ex + ey * ey
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_bead_crosses_mid_level_at_the_half_width() {
        let bead = StraightBead {
            origin_mm: [1.0, 2.0],
            dir: [0.6, 0.8],
            half_width_mm: 0.3,
            edge_mm: 0.05,
            background_c: 60.0,
            amplitude_c: 100.0,
        };
        // Left normal (−0.8, 0.6): the point 0.3 mm off the centre line is at mid level.
        assert!((bead.temp_c([1.0 - 0.24, 2.0 + 0.18]) - 110.0).abs() < 1e-9);
    }

    #[test]
    fn polyline_is_hottest_at_its_interior_corner() {
        let line = HotPolyline {
            vertices_mm: vec![[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]],
            background_c: 60.0,
            bead_c: 130.0,
            bead_sigma_mm: 0.2,
            corner_excess_c: 15.0,
            corner_sigma_mm: 0.3,
        };
        assert!((line.temp_c([2.0, 0.0]) - 145.0).abs() < 1e-9);
        assert!((line.temp_c([0.2, 0.0]) - 130.0).abs() < 1e-6);
        assert_eq!(line.corners_mm(), &[[2.0, 0.0]]);
    }
}
