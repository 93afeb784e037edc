//! The nozzle-mounted thermal camera, paper 003 Sec. 2.3: intrinsics with radial and
//! tangential (Brown/OpenCV polynomial) distortion, the tilted mount, the nominal
//! plane ↔ image homography H0 and an [`Undistorter`] for whole frames.
//!
//! The paper removes radial distortion with Zhang's calibration and the tilt with a
//! homography (eq. 27). Here the distortion coefficients are given (the dataset carries
//! them), undistortion uses kornia's correction map
//! (`generate_correction_map_polynomial`) and point inversion
//! (`undistort_normalized_point_iter`), and the tilt is the homography H0 computed from
//! the nominal mount — the per-frame H of `homography.rs` corrects what the mount gets
//! wrong (mounting error, vibration).
//!
//! Contract (shared with the virtual camera): pixel (0, 0) is the centre of the top-left
//! pixel; normalized coordinates x = (u − cx)/fx, y = (v − cy)/fy; distortion
//! x_d = x(1 + k1 r² + k2 r⁴) + 2 p1 x y + p2 (r² + 2x²),
//! y_d = y(1 + k1 r² + k2 r⁴) + p1 (r² + 2y²) + 2 p2 x y (kornia's `PolynomialDistortion`
//! with k3..k6 = 0). The camera centre sits `height_mm` above the plane, its optical axis
//! tilted `tilt_deg` from vertical meets the plane at `look_at_mm` relative to the nozzle,
//! image u runs along world +x, image v (down) runs towards the camera (world −y).

use kornia_image::ImageSize;
use kornia_imgproc::calibration::distortion::{
    generate_correction_map_polynomial, undistort_normalized_point_iter, PolynomialDistortion, TermCriteria,
};
use kornia_imgproc::calibration::{CameraExtrinsic, CameraIntrinsic};

use crate::frame::{ThermalFrame, LEPTON_HEIGHT_PX, LEPTON_WIDTH_PX};
use crate::homography::Homography;

/// Pinhole intrinsics in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Focal length along u (px).
    pub fx_px: f64,
    /// Focal length along v (px).
    pub fy_px: f64,
    /// Principal point u (px).
    pub cx_px: f64,
    /// Principal point v (px).
    pub cy_px: f64,
}

impl Intrinsics {
    /// FLIR Lepton 3.5: 160 × 120 px, 57° horizontal field of view, so
    /// fx = 80 / tan(28.5°) ≈ 147.3 px, square pixels, principal point at the centre.
    pub fn lepton35() -> Self {
        let fx = 80.0 / 28.5_f64.to_radians().tan();
        Self { fx_px: fx, fy_px: fx, cx_px: 79.5, cy_px: 59.5 }
    }

    fn kornia(&self) -> CameraIntrinsic {
        CameraIntrinsic { fx: self.fx_px, fy: self.fy_px, cx: self.cx_px, cy: self.cy_px }
    }
}

/// Brown/OpenCV polynomial distortion coefficients (normalized coordinates).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
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

impl Distortion {
    fn kornia(&self) -> PolynomialDistortion {
        PolynomialDistortion { k1: self.k1, k2: self.k2, p1: self.p1, p2: self.p2, ..Default::default() }
    }
}

/// How the camera is mounted on the nozzle (moves with it, no rotation about z).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mount {
    /// Angle of the optical axis from vertical (degrees).
    pub tilt_deg: f64,
    /// Height of the camera centre above the plane of the layer being printed (mm).
    pub height_mm: f64,
    /// Where the optical axis meets the plane, relative to the nozzle tip (mm).
    pub look_at_mm: [f64; 2],
}

impl Mount {
    /// Paper 003 setup (DESIGN §5.3): 45° tilt, 14.5 mm above the plane, aimed at the nozzle.
    pub fn paper_nominal() -> Self {
        Self { tilt_deg: 45.0, height_mm: 14.5, look_at_mm: [0.0, 0.0] }
    }
}

/// Everything needed to map between the plane and the raw image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    /// Pinhole intrinsics.
    pub intrinsics: Intrinsics,
    /// Lens distortion.
    pub distortion: Distortion,
    /// Mount geometry.
    pub mount: Mount,
    /// Image width (px).
    pub width_px: usize,
    /// Image height (px).
    pub height_px: usize,
}

impl CameraModel {
    /// Lepton 3.5 on the paper's nominal mount with the given distortion.
    pub fn lepton35(distortion: Distortion) -> Self {
        Self {
            intrinsics: Intrinsics::lepton35(),
            distortion,
            mount: Mount::paper_nominal(),
            width_px: LEPTON_WIDTH_PX,
            height_px: LEPTON_HEIGHT_PX,
        }
    }

    /// World → camera rotation, rows = camera x (u), y (v, down) and z (optical axis).
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        let (s, c) = self.mount.tilt_deg.to_radians().sin_cos();
        [[1.0, 0.0, 0.0], [0.0, -c, -s], [0.0, s, -c]]
    }

    /// Camera centre relative to the nozzle tip (mm, z up from the plane).
    pub fn centre_mm(&self) -> [f64; 3] {
        let m = &self.mount;
        let back = m.height_mm * m.tilt_deg.to_radians().tan();
        [m.look_at_mm[0], m.look_at_mm[1] - back, m.height_mm]
    }

    /// Projects a plane point (mm relative to the nozzle) to an undistorted pixel;
    /// `None` behind the camera.
    pub fn plane_to_undistorted_px(&self, p_mm: [f64; 2]) -> Option<[f64; 2]> {
        let (r, c) = (self.rotation(), self.centre_mm());
        let d = [p_mm[0] - c[0], p_mm[1] - c[1], -c[2]];
        let cam = r.map(|row| row[0] * d[0] + row[1] * d[1] + row[2] * d[2]);
        if cam[2] <= 1e-9 {
            return None;
        }
        let k = &self.intrinsics;
        Some([k.fx_px * cam[0] / cam[2] + k.cx_px, k.fy_px * cam[1] / cam[2] + k.cy_px])
    }

    /// Projects a plane point (mm relative to the nozzle) to a raw (distorted) pixel.
    pub fn plane_to_raw_px(&self, p_mm: [f64; 2]) -> Option<[f64; 2]> {
        self.plane_to_undistorted_px(p_mm).map(|px| self.distort_px(px))
    }

    /// Applies the lens distortion: undistorted pixel → raw pixel (the contract's formula).
    pub fn distort_px(&self, px: [f64; 2]) -> [f64; 2] {
        let (k, d) = (&self.intrinsics, &self.distortion);
        let x = (px[0] - k.cx_px) / k.fx_px;
        let y = (px[1] - k.cy_px) / k.fy_px;
        let r2 = x * x + y * y;
        let radial = 1.0 + d.k1 * r2 + d.k2 * r2 * r2;
        let xd = x * radial + 2.0 * d.p1 * x * y + d.p2 * (r2 + 2.0 * x * x);
        let yd = y * radial + d.p1 * (r2 + 2.0 * y * y) + 2.0 * d.p2 * x * y;
        [k.fx_px * xd + k.cx_px, k.fy_px * yd + k.cy_px]
    }

    /// Removes the lens distortion: raw pixel → undistorted pixel (kornia's iterative
    /// inversion, converged to 1e-12 px²).
    pub fn undistort_px(&self, raw: [f64; 2]) -> [f64; 2] {
        let k = &self.intrinsics;
        let (x0, y0) = ((raw[0] - k.cx_px) / k.fx_px, (raw[1] - k.cy_px) / k.fy_px);
        let criteria = TermCriteria { max_iter: 100, eps: 1e-12 };
        let r =
            undistort_normalized_point_iter(x0, y0, raw[0], raw[1], &k.kornia(), &self.distortion.kornia(), criteria);
        [k.fx_px * r.x + k.cx_px, k.fy_px * r.y + k.cy_px]
    }

    /// Nominal homography H0: undistorted pixel → plane mm relative to the nozzle, from
    /// the intrinsics and the mount (the inverse of K·[r1 r2 t]).
    pub fn nominal_homography(&self) -> Homography {
        let (r, c) = (self.rotation(), self.centre_mm());
        let t = r.map(|row| -(row[0] * c[0] + row[1] * c[1] + row[2] * c[2]));
        let k = &self.intrinsics;
        let kmat = [[k.fx_px, 0.0, k.cx_px], [0.0, k.fy_px, k.cy_px], [0.0, 0.0, 1.0]];
        let rt = [[r[0][0], r[0][1], t[0]], [r[1][0], r[1][1], t[1]], [r[2][0], r[2][1], t[2]]];
        let plane_to_px = Homography { m: kmat }.then_after(&Homography { m: rt });
        plane_to_px.inverse().unwrap_or(Homography::IDENTITY)
    }
}

/// Why an [`Undistorter`] could not be built or applied.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// The image is too small to interpolate in.
    #[error("image size {width}×{height} px: the undistortion needs at least {MIN_SIDE_PX} px along each axis")]
    TooSmall {
        /// Width (px).
        width: usize,
        /// Height (px).
        height: usize,
    },
    /// kornia could not build the correction map.
    #[error("correction map: {0}")]
    CorrectionMap(String),
    /// The frame does not have the camera's size.
    #[error("frame is {found_width}×{found_height}, camera is {width}×{height}")]
    FrameSize {
        /// Camera width (px).
        width: usize,
        /// Camera height (px).
        height: usize,
        /// Frame width (px).
        found_width: usize,
        /// Frame height (px).
        found_height: usize,
    },
}

/// Fewest pixels along each axis of an image the undistorter takes: bilinear sampling
/// interpolates between two neighbouring pixel centres.
pub const MIN_SIDE_PX: usize = 2;

/// Four bilinear taps into the raw frame for one undistorted pixel.
#[derive(Debug, Clone, Copy)]
struct Taps {
    idx: [u32; 4],
    weight: [f32; 4],
}

/// Undistorts whole frames with a correction map computed once (kornia), sampling the
/// raw frame bilinearly. NaN-aware: NaN taps are dropped and the remaining weights
/// renormalised; a pixel whose source lies outside the raw frame, or whose valid taps
/// carry less than a quarter of the weight, is NaN.
#[derive(Debug, Clone)]
pub struct Undistorter {
    camera: CameraModel,
    taps: Vec<Option<Taps>>,
}

impl Undistorter {
    /// Precomputes the correction map for `camera`.
    pub fn new(camera: &CameraModel) -> Result<Self, CameraError> {
        let (width, height) = (camera.width_px, camera.height_px);
        if width < MIN_SIDE_PX || height < MIN_SIDE_PX {
            return Err(CameraError::TooSmall { width, height });
        }
        let size = ImageSize { width: camera.width_px, height: camera.height_px };
        let identity =
            CameraExtrinsic { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3] };
        let k = camera.intrinsics.kornia();
        let (map_x, map_y) = generate_correction_map_polynomial(&k, &identity, &k, &camera.distortion.kornia(), &size)
            .map_err(|e| CameraError::CorrectionMap(e.to_string()))?;
        let taps = map_x
            .as_slice()
            .iter()
            .zip(map_y.as_slice())
            .map(|(&x, &y)| bilinear_taps(x, y, camera.width_px, camera.height_px))
            .collect();
        Ok(Self { camera: *camera, taps })
    }

    /// The camera this undistorter was built for.
    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// Undistorts `raw` into `out` (resized if needed; no allocation when it fits).
    pub fn undistort_into(&self, raw: &ThermalFrame, out: &mut ThermalFrame) -> Result<(), CameraError> {
        let (w, h) = (self.camera.width_px, self.camera.height_px);
        if raw.width != w || raw.height != h {
            return Err(CameraError::FrameSize {
                width: w,
                height: h,
                found_width: raw.width,
                found_height: raw.height,
            });
        }
        out.width = w;
        out.height = h;
        out.temp_c.resize(w * h, f32::NAN);
        for (dst, taps) in out.temp_c.iter_mut().zip(&self.taps) {
            *dst = taps.map_or(f32::NAN, |t| sample_taps(&raw.temp_c, &t));
        }
        Ok(())
    }

    /// Undistorts `raw` into a new frame.
    pub fn undistort(&self, raw: &ThermalFrame) -> Result<ThermalFrame, CameraError> {
        let mut out = ThermalFrame::filled(self.camera.width_px, self.camera.height_px, f32::NAN);
        self.undistort_into(raw, &mut out)?;
        Ok(out)
    }

    /// Raw (distorted) pixel → undistorted pixel.
    pub fn undistort_px(&self, raw: [f64; 2]) -> [f64; 2] {
        self.camera.undistort_px(raw)
    }

    /// Undistorted pixel → raw (distorted) pixel.
    pub fn distort_px(&self, px: [f64; 2]) -> [f64; 2] {
        self.camera.distort_px(px)
    }
}

fn bilinear_taps(x: f32, y: f32, width: usize, height: usize) -> Option<Taps> {
    // Sources up to half a pixel outside the outermost pixel centres are clamped onto them.
    let (xmax, ymax) = ((width - 1) as f32, (height - 1) as f32);
    if !(x >= -0.5 && y >= -0.5 && x <= xmax + 0.5 && y <= ymax + 0.5) {
        return None;
    }
    let (x, y) = (x.clamp(0.0, xmax), y.clamp(0.0, ymax));
    let (x0, y0) =
        ((x.floor() as usize).min(width.saturating_sub(2)), (y.floor() as usize).min(height.saturating_sub(2)));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let i00 = (y0 * width + x0) as u32;
    let w = width as u32;
    Some(Taps {
        idx: [i00, i00 + 1, i00 + w, i00 + w + 1],
        weight: [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy],
    })
}

#[inline]
fn sample_taps(src: &[f32], t: &Taps) -> f32 {
    let (mut acc, mut wsum) = (0.0f32, 0.0f32);
    for k in 0..4 {
        let v = src[t.idx[k] as usize];
        if v.is_finite() {
            acc += t.weight[k] * v;
            wsum += t.weight[k];
        }
    }
    if wsum >= 0.25 {
        acc / wsum
    } else {
        f32::NAN
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> CameraModel {
        CameraModel::lepton35(Distortion { k1: -0.12, k2: 0.03, p1: 0.001, p2: -0.0015 })
    }

    #[test]
    fn images_too_small_to_interpolate_are_an_error_not_a_panic() {
        // A 0 × 0 camera used to panic inside kornia; 1 px wide indexed past the frame.
        for (width, height) in [(0, 0), (0, 120), (1, 120), (160, 1)] {
            let err = Undistorter::new(&CameraModel { width_px: width, height_px: height, ..camera() }).unwrap_err();
            assert_eq!(err, CameraError::TooSmall { width, height });
        }
        assert!(Undistorter::new(&CameraModel { width_px: 2, height_px: 2, ..camera() }).is_ok());
    }

    #[test]
    fn lepton_focal_length_follows_from_the_field_of_view() {
        // 57° horizontal FOV over 160 px: fx = 80 / tan(28.5°) = 147.34 px.
        assert!((Intrinsics::lepton35().fx_px - 147.34).abs() < 0.01);
    }

    #[test]
    fn nominal_camera_centre_is_behind_and_above_the_nozzle() {
        let c = CameraModel::lepton35(Distortion::default()).centre_mm();
        assert!((c[0]).abs() < 1e-12 && (c[1] + 14.5).abs() < 1e-9 && (c[2] - 14.5).abs() < 1e-12);
    }

    #[test]
    fn h0_maps_the_principal_point_to_look_at() {
        let mut cam = camera();
        cam.mount.look_at_mm = [0.7, -1.3];
        cam.mount.tilt_deg = 40.0;
        let p = cam.nominal_homography().apply([cam.intrinsics.cx_px, cam.intrinsics.cy_px]);
        assert!((p[0] - 0.7).abs() < 1e-9 && (p[1] + 1.3).abs() < 1e-9, "{p:?}");
    }

    #[test]
    fn h0_inverts_the_forward_projection_and_keeps_the_axis_convention() {
        let cam = camera();
        let h0 = cam.nominal_homography();
        for p in [[0.0, 0.0], [3.0, 1.0], [-4.0, -2.5], [2.0, 5.0]] {
            let px = cam.plane_to_undistorted_px(p).unwrap();
            let back = h0.apply(px);
            assert!((back[0] - p[0]).abs() < 1e-9 && (back[1] - p[1]).abs() < 1e-9);
        }
        // u increases with world +x; v increases towards the camera (world −y).
        let o = cam.plane_to_undistorted_px([0.0, 0.0]).unwrap();
        assert!(cam.plane_to_undistorted_px([1.0, 0.0]).unwrap()[0] > o[0]);
        assert!(cam.plane_to_undistorted_px([0.0, -1.0]).unwrap()[1] > o[1]);
    }

    #[test]
    fn distort_then_undistort_recovers_plane_points_below_0_05_px() {
        let cam = camera();
        let und = Undistorter::new(&cam).unwrap();
        let h0 = cam.nominal_homography();
        for i in 0..40 {
            let p = [-5.0 + 0.25 * i as f64, -4.0 + 0.2 * (i % 17) as f64];
            let Some(raw) = cam.plane_to_raw_px(p) else { continue };
            let px = und.undistort_px(raw);
            let truth = cam.plane_to_undistorted_px(p).unwrap();
            assert!((px[0] - truth[0]).hypot(px[1] - truth[1]) < 0.05, "{p:?}: {px:?} vs {truth:?}");
            let back = h0.apply(px);
            assert!((back[0] - p[0]).hypot(back[1] - p[1]) < 0.01);
        }
    }

    #[test]
    fn undistorting_a_frame_moves_a_feature_to_its_undistorted_position() {
        // A smooth radial temperature bump drawn at a raw (distorted) position must peak
        // at the corresponding undistorted position after remapping.
        let cam = camera();
        let und = Undistorter::new(&cam).unwrap();
        let target = [30.0, 25.0];
        let raw_centre = cam.distort_px(target);
        let mut raw = ThermalFrame::filled(160, 120, 60.0);
        for v in 0..120 {
            for u in 0..160 {
                let d2 = (u as f64 - raw_centre[0]).powi(2) + (v as f64 - raw_centre[1]).powi(2);
                raw.temp_c[v * 160 + u] = 60.0 + 100.0 * (-d2 / 18.0).exp() as f32;
            }
        }
        let out = und.undistort(&raw).unwrap();
        let (imax, _) = out
            .temp_c
            .iter()
            .enumerate()
            .filter(|(_, t)| t.is_finite())
            .fold((0, f32::MIN), |a, (i, &t)| if t > a.1 { (i, t) } else { a });
        let (u, v) = ((imax % 160) as f64, (imax / 160) as f64);
        assert!((u - target[0]).abs() <= 1.0 && (v - target[1]).abs() <= 1.0, "peak at {u},{v}");
    }

    #[test]
    fn nan_pixels_do_not_spread_and_uniform_frames_stay_uniform() {
        let und = Undistorter::new(&camera()).unwrap();
        let mut raw = ThermalFrame::filled(160, 120, 75.0);
        raw.temp_c[60 * 160 + 80] = f32::NAN;
        let out = und.undistort(&raw).unwrap();
        let finite: Vec<f32> = out.temp_c.iter().copied().filter(|t| t.is_finite()).collect();
        assert!(finite.len() > 150 * 110);
        assert!(finite.iter().all(|&t| (t - 75.0).abs() < 1e-4));
    }

    #[test]
    fn wrong_frame_size_is_an_error() {
        let und = Undistorter::new(&camera()).unwrap();
        let err = und.undistort(&ThermalFrame::filled(80, 60, 20.0)).unwrap_err();
        assert!(matches!(err, CameraError::FrameSize { found_width: 80, .. }));
    }
}
