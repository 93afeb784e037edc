//! The nozzle-mounted thermal camera of the virtual printer (DESIGN §5.3 "Camera";
//! paper 003 Sec. 2.3, Table 2): a FLIR Lepton 3.5 (160 × 120, 57° horizontal field of
//! view, < 50 mK) 14.5 mm above the layer, tilted 45°, moving with the nozzle.
//!
//! Frame contract (shared with the vision code): 16-bit grayscale, pixel = kelvin × 100,
//! 0 = no reading; pinhole intrinsics with the pixel origin at the centre of the top-left
//! pixel; Brown/OpenCV distortion on normalised coordinates (kornia's
//! `PolynomialDistortion` with k3..k6 = 0); mount: the optical axis meets the layer plane
//! at `look_at_mm` from the nozzle tip, the camera centre `height_mm` above the plane and
//! `height·tan(tilt)` towards −y, image columns along world +x, image rows towards −y.
//!
//! The true camera differs from the nominal one by a fixed mounting error (tilt ±0.5°,
//! height ±0.2 mm, look-at ±0.3 mm, roll ±0.3°, uniform, seeded) and per-frame vibration
//! (Gaussian: tilt and roll 0.05°, look-at 0.02 mm, height 0.01 mm), which is why the
//! paper re-estimates the homography of every frame from its corners (eq. 27).
//! Rendering: each pixel is sampled at 2 × 2 sub-positions, each a ray through the
//! distortion model onto the layer plane reading the temperature field; then a Gaussian
//! PSF (σ = 0.7 px), 50 mK white noise and quantisation to centi-kelvin.
//! Capture schedule (eq. 28): recorded times every 0.125 s from the layer start
//! (Sec. 3.2) through the layer change that follows it (the camera films on while the
//! nozzle stands at the layer's end point), true capture time = recorded + jitter (N(0, 3 ms) clipped at ±8 ms) +
//! `camera_latency`. Lepton habits (off by default): repeated frames (probability 5 %:
//! the previous image is delivered again) and one ~0.9 s shutter freeze per layer (the
//! last image before it is repeated).
//!
//! Simplifications, stated: the nozzle and the heater block, which a real camera sees,
//! are not rendered; the layer below is seen at the substrate temperature; the emissivity
//! is 1 and the optics are radiometrically perfect.

use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use super::heat::TemperatureField;

/// Image width (px).
pub const WIDTH_PX: usize = 160;
/// Image height (px).
pub const HEIGHT_PX: usize = 120;
/// Nominal frame period (s), paper Sec. 3.2.
pub const FRAME_PERIOD_S: f64 = 0.125;
/// Kelvin at 0 °C.
pub const KELVIN_AT_ZERO_C: f64 = 273.15;

/// Pinhole intrinsics (px), origin at the top-left pixel's centre.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length along x (px).
    pub fx_px: f64,
    /// Focal length along y (px).
    pub fy_px: f64,
    /// Principal point x (px).
    pub cx_px: f64,
    /// Principal point y (px).
    pub cy_px: f64,
}

/// Brown/OpenCV polynomial distortion on normalised coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Distortion {
    /// Radial r² coefficient.
    pub k1: f64,
    /// Radial r⁴ coefficient.
    pub k2: f64,
    /// Tangential coefficient p1.
    pub p1: f64,
    /// Tangential coefficient p2.
    pub p2: f64,
}

/// How the camera sits relative to the nozzle tip.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Mount {
    /// Camera centre height above the layer plane (mm).
    pub height_mm: f64,
    /// Tilt of the optical axis from vertical (degrees).
    pub tilt_deg: f64,
    /// Where the optical axis meets the plane, relative to the nozzle tip (mm).
    pub look_at_mm: [f64; 2],
    /// Rotation about the optical axis (degrees; nominal 0).
    pub roll_deg: f64,
}

/// The camera's position and orientation for one frame: centre and world→camera rows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Camera centre (mm; z above the layer plane).
    pub centre_mm: [f64; 3],
    /// Rows: image x axis, image y axis, optical axis, in world coordinates.
    pub rows: [[f64; 3]; 3],
}

/// Lepton habits the virtual camera can imitate (off by default).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct LeptonHabits {
    /// Sometimes deliver the previous image again.
    pub repeated_frames: bool,
    /// Freeze for ~0.9 s once per layer (flat-field shutter).
    pub shutter_freeze: bool,
}

/// One delivered frame of the schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameCapture {
    /// Frame index within the layer.
    pub frame: usize,
    /// The camera's timestamp t_r (s from the layer start).
    pub recorded_time_s: f64,
    /// True capture time t_c of the image content (s from the layer start).
    pub capture_time_s: f64,
    /// Index of the frame whose image is delivered (itself unless repeated or frozen).
    pub source: usize,
}

impl Intrinsics {
    /// Lepton 3.5: fx = fy = 80 / tan(28.5°) ≈ 147.3 px, principal point at the image centre.
    pub fn lepton35() -> Self {
        let f = (WIDTH_PX as f64 / 2.0) / 28.5f64.to_radians().tan();
        Self { fx_px: f, fy_px: f, cx_px: (WIDTH_PX as f64 - 1.0) / 2.0, cy_px: (HEIGHT_PX as f64 - 1.0) / 2.0 }
    }
}

impl Distortion {
    /// Mild barrel distortion of a small wide-angle lens (plus a little decentring).
    pub fn lepton35() -> Self {
        Self { k1: -0.12, k2: 0.02, p1: 0.0008, p2: -0.0005 }
    }

    /// Distorts normalised coordinates (the contract's formula).
    pub fn distort(&self, x: f64, y: f64) -> [f64; 2] {
        let r2 = x * x + y * y;
        let radial = 1.0 + self.k1 * r2 + self.k2 * r2 * r2;
        [
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        ]
    }

    /// Inverts [`Self::distort`] by fixed-point iteration (converges for this mild lens).
    pub fn undistort(&self, xd: f64, yd: f64) -> [f64; 2] {
        let (mut x, mut y) = (xd, yd);
        for _ in 0..30 {
            let r2 = x * x + y * y;
            let radial = 1.0 + self.k1 * r2 + self.k2 * r2 * r2;
            let tx = 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
            let ty = self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
            x = (xd - tx) / radial;
            y = (yd - ty) / radial;
        }
        [x, y]
    }
}

impl Mount {
    /// Paper Table 2: 14.5 mm above the plane, 45° tilt, looking at the nozzle tip.
    pub fn nominal() -> Self {
        Self { height_mm: 14.5, tilt_deg: 45.0, look_at_mm: [0.0, 0.0], roll_deg: 0.0 }
    }

    /// The nominal mount with a fixed mounting error (uniform within the module doc's bounds).
    pub fn with_mounting_error<R: Rng>(&self, rng: &mut R) -> Self {
        let mut u = |half: f64| rng.random_range(-half..=half);
        Self {
            height_mm: self.height_mm + u(0.2),
            tilt_deg: self.tilt_deg + u(0.5),
            look_at_mm: [self.look_at_mm[0] + u(0.3), self.look_at_mm[1] + u(0.3)],
            roll_deg: self.roll_deg + u(0.3),
        }
    }

    /// This mount shaken by one frame's vibration (Gaussian, module doc).
    pub fn vibrated<R: Rng>(&self, rng: &mut R) -> Self {
        let mut n = |sd: f64| Normal::new(0.0, sd).expect("valid sd").sample(rng);
        Self {
            height_mm: self.height_mm + n(0.01),
            tilt_deg: self.tilt_deg + n(0.05),
            look_at_mm: [self.look_at_mm[0] + n(0.02), self.look_at_mm[1] + n(0.02)],
            roll_deg: self.roll_deg + n(0.05),
        }
    }

    /// The pose when the nozzle tip is at `nozzle_mm` on the plane.
    pub fn pose(&self, nozzle_mm: [f64; 2]) -> Pose {
        let (s, c) = self.tilt_deg.to_radians().sin_cos();
        let (sr, cr) = self.roll_deg.to_radians().sin_cos();
        let axis = [0.0, s, -c];
        let (x0, y0) = ([1.0, 0.0, 0.0], [0.0, -c, -s]);
        let x = [cr * x0[0] + sr * y0[0], cr * x0[1] + sr * y0[1], cr * x0[2] + sr * y0[2]];
        let y = [-sr * x0[0] + cr * y0[0], -sr * x0[1] + cr * y0[1], -sr * x0[2] + cr * y0[2]];
        let target = [nozzle_mm[0] + self.look_at_mm[0], nozzle_mm[1] + self.look_at_mm[1]];
        let back = self.height_mm / c; // distance from the centre to the target along the axis
        let centre_mm = [target[0] - back * axis[0], target[1] - back * axis[1], -back * axis[2]];
        Pose { centre_mm, rows: [x, y, axis] }
    }
}

impl Pose {
    /// Normalised (undistorted) image coordinates of the plane point `p_mm`, if in front.
    pub fn project(&self, p_mm: [f64; 2]) -> Option<[f64; 2]> {
        let d = [p_mm[0] - self.centre_mm[0], p_mm[1] - self.centre_mm[1], -self.centre_mm[2]];
        let cam: Vec<f64> = self.rows.iter().map(|r| r[0] * d[0] + r[1] * d[1] + r[2] * d[2]).collect();
        (cam[2] > 1e-9).then(|| [cam[0] / cam[2], cam[1] / cam[2]])
    }

    /// Where the ray of normalised coordinates (x, y) meets the plane, if it does.
    pub fn ray_to_plane(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        let r = &self.rows;
        let dir = [0, 1, 2].map(|a| x * r[0][a] + y * r[1][a] + r[2][a]);
        (dir[2] < -1e-9).then(|| {
            let s = -self.centre_mm[2] / dir[2];
            [self.centre_mm[0] + s * dir[0], self.centre_mm[1] + s * dir[1]]
        })
    }

    /// Plane → undistorted pixel homography K·[r1 r2 −R·C] (row-major, h33 = 1).
    pub fn plane_to_pixel(&self, intrinsics: &Intrinsics) -> [[f64; 3]; 3] {
        let r = &self.rows;
        let t = [0, 1, 2]
            .map(|i| -(r[i][0] * self.centre_mm[0] + r[i][1] * self.centre_mm[1] + r[i][2] * self.centre_mm[2]));
        let m = [0, 1, 2].map(|i| [r[i][0], r[i][1], t[i]]);
        let k = [[intrinsics.fx_px, 0.0, intrinsics.cx_px], [0.0, intrinsics.fy_px, intrinsics.cy_px], [0.0, 0.0, 1.0]];
        normalized(mat_mul(&k, &m))
    }
}

/// The nominal homography H0: undistorted pixel → plane mm relative to the nozzle tip.
pub fn nominal_homography(intrinsics: &Intrinsics, mount: &Mount) -> [[f64; 3]; 3] {
    normalized(invert3(&mount.pose([0.0, 0.0]).plane_to_pixel(intrinsics)))
}

/// Raw (distorted) pixel of the plane point `p_mm` seen from `pose`, if in front.
pub fn project_px(pose: &Pose, intrinsics: &Intrinsics, distortion: &Distortion, p_mm: [f64; 2]) -> Option<[f64; 2]> {
    let [x, y] = pose.project(p_mm)?;
    let [xd, yd] = distortion.distort(x, y);
    Some([intrinsics.fx_px * xd + intrinsics.cx_px, intrinsics.fy_px * yd + intrinsics.cy_px])
}

/// Undistorted normalised ray coordinates of every pixel's 2 × 2 sub-samples, row-major
/// by pixel, four per pixel (computed once per camera).
pub fn pixel_rays(intrinsics: &Intrinsics, distortion: &Distortion) -> Vec<[f64; 2]> {
    let mut rays = Vec::with_capacity(WIDTH_PX * HEIGHT_PX * 4);
    for v in 0..HEIGHT_PX {
        for u in 0..WIDTH_PX {
            for (du, dv) in [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)] {
                let xd = (u as f64 + du - intrinsics.cx_px) / intrinsics.fx_px;
                let yd = (v as f64 + dv - intrinsics.cy_px) / intrinsics.fy_px;
                rays.push(distortion.undistort(xd, yd));
            }
        }
    }
    rays
}

/// The plane rectangle the frame's rays reach (mm).
pub fn footprint_mm(pose: &Pose, rays: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut min = [f64::INFINITY; 2];
    let mut max = [f64::NEG_INFINITY; 2];
    for p in rays.iter().filter_map(|r| pose.ray_to_plane(r[0], r[1])) {
        min = [min[0].min(p[0]), min[1].min(p[1])];
        max = [max[0].max(p[0]), max[1].max(p[1])];
    }
    (min, max)
}

/// Renders one frame: temperatures (°C) through the optics, before noise.
pub fn render_temperatures_c(field: &TemperatureField, pose: &Pose, rays: &[[f64; 2]]) -> Vec<f64> {
    let sharp: Vec<f64> = rays
        .chunks_exact(4)
        .map(|sub| {
            let sum: f64 = sub
                .iter()
                .map(|r| pose.ray_to_plane(r[0], r[1]).map_or(field.substrate_c(), |p| field.temp_c(p)))
                .sum();
            sum / 4.0
        })
        .collect();
    psf_blur(&sharp, 0.7)
}

/// Adds 50 mK white noise and quantises to centi-kelvin (1..=65535; 0 means no reading).
pub fn to_radiometric<R: Rng>(temps_c: &[f64], rng: &mut R) -> Vec<u16> {
    let noise = Normal::new(0.0, 0.05).expect("valid sd");
    temps_c.iter().map(|t| to_centikelvin(t + noise.sample(rng))).collect()
}

/// One temperature (°C) as the Lepton's radiometric value.
pub fn to_centikelvin(temp_c: f64) -> u16 {
    ((temp_c + KELVIN_AT_ZERO_C) * 100.0).round().clamp(1.0, 65535.0) as u16
}

/// The capture schedule of a layer filmed for `duration_s` (its moves and the layer
/// change after them).
pub fn schedule<R: Rng>(duration_s: f64, latency_s: f64, habits: &LeptonHabits, rng: &mut R) -> Vec<FrameCapture> {
    let jitter: Normal<f64> = Normal::new(0.0, 0.003).expect("valid sd");
    let count = (duration_s / FRAME_PERIOD_S).floor() as usize + 1;
    let freeze_start = habits.shutter_freeze.then(|| rng.random_range(0.5..(duration_s - 1.0).max(0.6)));
    let mut frames: Vec<FrameCapture> = Vec::with_capacity(count);
    for frame in 0..count {
        let recorded_time_s = frame as f64 * FRAME_PERIOD_S;
        let capture_time_s = recorded_time_s + jitter.sample(rng).clamp(-0.008, 0.008) + latency_s;
        let repeated = habits.repeated_frames && frame > 0 && rng.random::<f64>() < 0.05;
        let frozen = freeze_start.is_some_and(|s| recorded_time_s >= s && recorded_time_s < s + 0.9) && frame > 0;
        let source = if repeated || frozen { frames[frame - 1].source } else { frame };
        let capture_time_s = if source == frame { capture_time_s } else { frames[source].capture_time_s };
        frames.push(FrameCapture { frame, recorded_time_s, capture_time_s, source });
    }
    frames
}

/// Separable Gaussian blur of a WIDTH × HEIGHT image (edges clamped).
fn psf_blur(image: &[f64], sigma_px: f64) -> Vec<f64> {
    let radius = (3.0 * sigma_px).ceil() as i64;
    let taps: Vec<f64> = (-radius..=radius).map(|i| (-(i * i) as f64 / (2.0 * sigma_px * sigma_px)).exp()).collect();
    let sum: f64 = taps.iter().sum();
    let taps: Vec<f64> = taps.iter().map(|t| t / sum).collect();
    let (w, h) = (WIDTH_PX as i64, HEIGHT_PX as i64);
    let pass = |src: &[f64], dx: i64, dy: i64| -> Vec<f64> {
        let mut out = vec![0.0; src.len()];
        for y in 0..h {
            for x in 0..w {
                out[(y * w + x) as usize] = taps
                    .iter()
                    .enumerate()
                    .map(|(k, t)| {
                        let o = k as i64 - radius;
                        let (sx, sy) = ((x + o * dx).clamp(0, w - 1), (y + o * dy).clamp(0, h - 1));
                        t * src[(sy * w + sx) as usize]
                    })
                    .sum();
            }
        }
        out
    };
    pass(&pass(image, 1, 0), 0, 1)
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

fn invert3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let cof = |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    let det = m[0][0] * adj[0][0] + m[0][1] * adj[1][0] + m[0][2] * adj[2][0];
    adj.map(|row| row.map(|v| v / det))
}

fn normalized(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let s = m[2][2];
    m.map(|row| row.map(|v| v / s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn nominal_camera_sits_as_the_contract_says() {
        // Centre at nozzle + (0, −14.5, 14.5); the nozzle tip projects to the principal point.
        let pose = Mount::nominal().pose([3.0, 4.0]);
        let c = pose.centre_mm;
        assert!((c[0] - 3.0).abs() < 1e-12 && (c[1] - (4.0 - 14.5)).abs() < 1e-9 && (c[2] - 14.5).abs() < 1e-9);
        let px = project_px(&pose, &Intrinsics::lepton35(), &Distortion::lepton35(), [3.0, 4.0]).unwrap();
        assert!((px[0] - 79.5).abs() < 1e-9 && (px[1] - 59.5).abs() < 1e-9, "{px:?}");
        // Image u grows with world +x; image v grows towards the camera (world −y).
        let right = project_px(&pose, &Intrinsics::lepton35(), &Distortion::lepton35(), [4.0, 4.0]).unwrap();
        let near = project_px(&pose, &Intrinsics::lepton35(), &Distortion::lepton35(), [3.0, 3.0]).unwrap();
        assert!(right[0] > px[0] && near[1] > px[1]);
    }

    #[test]
    fn rays_and_projection_are_inverse() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let pose = Mount::nominal().with_mounting_error(&mut rng).pose([10.0, 2.0]);
        for p in [[10.0, 2.0], [5.0, 8.0], [14.0, -3.0]] {
            let [x, y] = pose.project(p).unwrap();
            let back = pose.ray_to_plane(x, y).unwrap();
            assert!((back[0] - p[0]).abs() < 1e-9 && (back[1] - p[1]).abs() < 1e-9);
        }
    }

    #[test]
    fn undistort_inverts_distort() {
        let d = Distortion::lepton35();
        for (x, y) in [(0.5, 0.4), (-0.6, 0.3), (0.0, -0.45)] {
            let [xd, yd] = d.distort(x, y);
            let [xu, yu] = d.undistort(xd, yd);
            assert!((xu - x).abs() < 1e-10 && (yu - y).abs() < 1e-10);
        }
    }

    #[test]
    fn nominal_homography_maps_pixels_to_the_plane() {
        // H0 · (undistorted pixel of a plane point) = that point relative to the nozzle.
        let (k, mount) = (Intrinsics::lepton35(), Mount::nominal());
        let h = nominal_homography(&k, &mount);
        let pose = mount.pose([0.0, 0.0]);
        for p in [[0.0, 0.0], [2.0, 5.0], [-4.0, -3.0]] {
            let [x, y] = pose.project(p).unwrap();
            let (u, v) = (k.fx_px * x + k.cx_px, k.fy_px * y + k.cy_px);
            let q = [0, 1, 2].map(|i| h[i][0] * u + h[i][1] * v + h[i][2]);
            assert!((q[0] / q[2] - p[0]).abs() < 1e-9 && (q[1] / q[2] - p[1]).abs() < 1e-9);
        }
    }

    #[test]
    fn schedule_keeps_jitter_small_and_repeats_when_asked() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let plain = schedule(5.8, 0.0, &LeptonHabits::default(), &mut rng);
        assert_eq!(plain.len(), 47);
        assert!(plain
            .iter()
            .all(|f| (f.capture_time_s - f.recorded_time_s).abs() <= 0.008 + 1e-12 && f.source == f.frame));
        let habits = LeptonHabits { repeated_frames: false, shutter_freeze: true };
        let frozen = schedule(5.8, 0.02, &habits, &mut rng);
        let repeats = frozen.iter().filter(|f| f.source != f.frame).count();
        assert!((6..=8).contains(&repeats), "a 0.9 s freeze repeats 7 frames, got {repeats}");
    }

    #[test]
    fn quantisation_is_centikelvin() {
        assert_eq!(to_centikelvin(26.85), 30000);
        assert_eq!(to_centikelvin(-400.0), 1);
    }
}
