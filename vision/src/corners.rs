//! Hot-spot corner detector for thermal frames, replacing the paper's Faster R-CNN
//! (paper 003 Sec. 2.3; DESIGN §5.3: no GPU, no weights).
//!
//! The paper notes that gradient detectors such as Harris suit blurry thermal edges
//! poorly, and that material piles up and stays hot at corners. So a corner of a freshly
//! printed path is found as a hot spot:
//! 1. NaN pixels are set to the frame's coolest valid value and the frame is smoothed
//!    with kornia's Gaussian blur (σ = `sigma_px`; the background is subtracted first so
//!    kornia's zero border acts as a background border);
//! 2. candidates are local maxima of the smoothed temperature over a
//!    (2·`nms_radius_px` + 1)² window (non-maximum suppression);
//! 3. only corners whose temperature T_p lies in the band 140 °C ≤ T_p ≤ 150 °C are kept
//!    (Sec. 3.2: "only thermal images with sufficient newly printed corners, whose
//!    temperature T_p satisfies 140 °C ≤ T_p ≤ 150 °C, are further processed");
//! 4. blob, not ridge: both Hessian eigenvalues must be negative and the smaller in
//!    magnitude at least `min_eigen_ratio` of the larger — a point on a straight bead has
//!    one eigenvalue near zero (the direction along the bead);
//! 5. points within 5 % of the image size from an edge are removed (Sec. 2.3);
//! 6. the smoothed maximum is snapped to the hottest unsmoothed pixel of its 3 × 3
//!    neighbourhood (smoothing pulls the maximum of a sharp corner towards its inside,
//!    where both arms add heat) and refined below the pixel by the vertex of the
//!    quadratic through the unsmoothed 3 × 3 neighbourhood (Newton step −H⁻¹∇T, clamped
//!    to half a pixel).
//!
//! T_p is that hottest unsmoothed pixel (smoothing would bias a small blob's peak low);
//! the score is the smaller Hessian eigenvalue magnitude of the smoothed frame (°C/px²).

use kornia_image::{Image, ImageSize};
use kornia_imgproc::filter::gaussian_blur;

use crate::frame::ThermalFrame;

/// Detector settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerParams {
    /// Lower end of the corner temperature band (°C).
    pub band_lo_c: f32,
    /// Upper end of the corner temperature band (°C).
    pub band_hi_c: f32,
    /// Gaussian smoothing σ (px).
    pub sigma_px: f32,
    /// Non-maximum suppression radius (px).
    pub nms_radius_px: usize,
    /// Minimum |λ_small| / |λ_large| of the Hessian (0 = accept ridges, 1 = only round blobs).
    pub min_eigen_ratio: f32,
    /// Minimum |λ_small| (°C/px²): rejects flat noise maxima.
    pub min_curvature_c_px2: f32,
    /// Fraction of the image size removed at every edge.
    pub edge_margin_frac: f32,
}

impl CornerParams {
    /// The paper's band (Sec. 3.2) and edge margin (Sec. 2.3); smoothing, suppression and
    /// curvature limits are ours, sized for a 160 × 120 frame at ~0.15 mm/px.
    pub fn paper_defaults() -> Self {
        Self {
            band_lo_c: 140.0,
            band_hi_c: 150.0,
            sigma_px: 1.0,
            nms_radius_px: 3,
            min_eigen_ratio: 0.05,
            min_curvature_c_px2: 0.05,
            edge_margin_frac: 0.05,
        }
    }
}

/// One detected corner, in undistorted pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerDetection {
    /// Column (px, sub-pixel).
    pub u_px: f64,
    /// Row (px, sub-pixel).
    pub v_px: f64,
    /// Temperature T_p at the corner (°C).
    pub temp_c: f32,
    /// Blob strength: smaller Hessian eigenvalue magnitude (°C/px²).
    pub score: f32,
}

/// Why a detector could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CornerError {
    /// The image buffers could not be created or smoothed.
    #[error("image buffer: {0}")]
    Image(String),
}

/// A detector with its image buffers, reused across frames of one size.
pub struct CornerDetector {
    params: CornerParams,
    size: ImageSize,
    filled: Image<f32, 1>,
    smooth: Image<f32, 1>,
}

impl CornerDetector {
    /// Allocates the buffers for `width` × `height` frames.
    pub fn new(width: usize, height: usize, params: CornerParams) -> Result<Self, CornerError> {
        let size = ImageSize { width, height };
        let alloc = || Image::<f32, 1>::from_size_val(size, 0.0).map_err(|e| CornerError::Image(e.to_string()));
        Ok(Self { params, size, filled: alloc()?, smooth: alloc()? })
    }

    /// The detector's settings.
    pub fn params(&self) -> &CornerParams {
        &self.params
    }

    /// Detects corners in an undistorted frame, strongest first, into `out` (cleared).
    /// A frame of another size or without valid pixels yields no corners.
    pub fn detect_into(&mut self, frame: &ThermalFrame, out: &mut Vec<CornerDetection>) {
        out.clear();
        if frame.width != self.size.width || frame.height != self.size.height {
            return;
        }
        let Some(background_c) = self.smooth_frame(frame) else { return };
        let (w, h) = (self.size.width, self.size.height);
        let (u0, u1, v0, v1) = self.search_box();
        for v in v0..=v1 {
            for u in u0..=u1 {
                if let Some(det) = self.candidate(frame, u, v, background_c) {
                    out.push(det);
                }
            }
        }
        debug_assert!(out.iter().all(|d| d.u_px >= 0.0 && d.u_px < w as f64 && d.v_px < h as f64));
        out.sort_by(|a, b| b.score.total_cmp(&a.score));
    }

    /// Convenience wrapper returning a new vector.
    pub fn detect(&mut self, frame: &ThermalFrame) -> Vec<CornerDetection> {
        let mut out = Vec::new();
        self.detect_into(frame, &mut out);
        out
    }

    /// Fills NaN, subtracts the background, smooths; returns the background (°C).
    fn smooth_frame(&mut self, frame: &ThermalFrame) -> Option<f32> {
        let background_c = frame.temp_c.iter().copied().filter(|t| t.is_finite()).reduce(f32::min)?;
        for (dst, &t) in self.filled.as_slice_mut().iter_mut().zip(&frame.temp_c) {
            *dst = if t.is_finite() { t - background_c } else { 0.0 };
        }
        let sigma = self.params.sigma_px;
        if sigma > 0.0 {
            gaussian_blur(&self.filled, &mut self.smooth, (0, 0), (sigma, sigma)).ok()?;
        } else {
            self.smooth.as_slice_mut().copy_from_slice(self.filled.as_slice());
        }
        Some(background_c)
    }

    /// Inclusive pixel box outside the edge margin (and one pixel in, for the stencils).
    fn search_box(&self) -> (usize, usize, usize, usize) {
        let (w, h) = (self.size.width as f32, self.size.height as f32);
        let mu = (self.params.edge_margin_frac * w).ceil().max(1.0) as usize;
        let mv = (self.params.edge_margin_frac * h).ceil().max(1.0) as usize;
        let (wu, hu) = (self.size.width, self.size.height);
        (mu, wu.saturating_sub(mu + 1), mv, hu.saturating_sub(mv + 1))
    }

    fn candidate(&self, frame: &ThermalFrame, u: usize, v: usize, background_c: f32) -> Option<CornerDetection> {
        let p = &self.params;
        let s = self.smooth.as_slice();
        let w = self.size.width;
        let centre = s[v * w + u];
        if centre + background_c > p.band_hi_c || !self.is_local_max(u, v, centre) {
            return None;
        }
        let (_, _, hxx, hyy, hxy) = derivatives(s, w, u, v);
        let (l_small, l_large) = eigen_magnitudes(hxx, hyy, hxy)?;
        if l_small < p.min_curvature_c_px2 || l_small < p.min_eigen_ratio * l_large {
            return None;
        }
        let (u_px, v_px, temp_c) = refine_on_raw(frame, u, v)?;
        if temp_c < p.band_lo_c || temp_c > p.band_hi_c {
            return None;
        }
        Some(CornerDetection { u_px, v_px, temp_c, score: l_small })
    }

    /// Strict maximum over the NMS window (ties go to the first pixel in raster order).
    fn is_local_max(&self, u: usize, v: usize, centre: f32) -> bool {
        let r = self.params.nms_radius_px;
        let (w, h) = (self.size.width, self.size.height);
        let s = self.smooth.as_slice();
        for vv in v.saturating_sub(r)..=(v + r).min(h - 1) {
            for uu in u.saturating_sub(r)..=(u + r).min(w - 1) {
                let other = s[vv * w + uu];
                let before = (vv, uu) < (v, u);
                if other > centre || (before && other == centre) {
                    return false;
                }
            }
        }
        true
    }
}

/// One-shot detection with default buffers.
pub fn detect_corners(frame: &ThermalFrame, params: &CornerParams) -> Vec<CornerDetection> {
    CornerDetector::new(frame.width, frame.height, *params).map(|mut d| d.detect(frame)).unwrap_or_default()
}

/// Snaps a smoothed maximum to the hottest raw pixel of its 3 × 3 neighbourhood (the
/// smoothing pulls the maximum of a sharp corner towards the inside of the corner) and
/// refines it there by the quadratic vertex on the raw frame. Returns (u, v, T_p).
fn refine_on_raw(frame: &ThermalFrame, u: usize, v: usize) -> Option<(f64, f64, f32)> {
    let w = frame.width;
    let (mut best_u, mut best_v, mut best_t) = (u, v, f32::NEG_INFINITY);
    for vv in v - 1..=v + 1 {
        for uu in u - 1..=u + 1 {
            let t = frame.temp_c[vv * w + uu];
            if t > best_t {
                (best_u, best_v, best_t) = (uu, vv, t);
            }
        }
    }
    if !best_t.is_finite() {
        return None;
    }
    let inside = best_u >= 1 && best_v >= 1 && best_u + 1 < w && best_v + 1 < frame.height;
    let (gx, gy, hxx, hyy, hxy) =
        if inside { derivatives(&frame.temp_c, w, best_u, best_v) } else { (0.0, 0.0, 0.0, 0.0, 0.0) };
    let (du, dv) = if [gx, gy, hxx, hyy, hxy].iter().all(|d| d.is_finite()) && eigen_magnitudes(hxx, hyy, hxy).is_some()
    {
        newton_offset(gx, gy, hxx, hyy, hxy)
    } else {
        (0.0, 0.0)
    };
    Some((best_u as f64 + du, best_v as f64 + dv, best_t))
}

/// Central differences at (u, v): gradient and Hessian of the smoothed image.
fn derivatives(s: &[f32], w: usize, u: usize, v: usize) -> (f32, f32, f32, f32, f32) {
    let at = |du: isize, dv: isize| s[(v as isize + dv) as usize * w + (u as isize + du) as usize];
    let c = at(0, 0);
    let gx = 0.5 * (at(1, 0) - at(-1, 0));
    let gy = 0.5 * (at(0, 1) - at(0, -1));
    let hxx = at(1, 0) - 2.0 * c + at(-1, 0);
    let hyy = at(0, 1) - 2.0 * c + at(0, -1);
    let hxy = 0.25 * (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1));
    (gx, gy, hxx, hyy, hxy)
}

/// Magnitudes (small, large) of the Hessian eigenvalues when both are negative (a maximum).
fn eigen_magnitudes(hxx: f32, hyy: f32, hxy: f32) -> Option<(f32, f32)> {
    let half_tr = 0.5 * (hxx + hyy);
    let disc = (0.25 * (hxx - hyy).powi(2) + hxy * hxy).sqrt();
    let (l1, l2) = (half_tr - disc, half_tr + disc); // l1 ≤ l2
    if l2 >= 0.0 {
        return None;
    }
    Some((-l2, -l1))
}

/// Vertex of the fitted quadratic: −H⁻¹∇T, clamped to ±0.5 px.
fn newton_offset(gx: f32, gy: f32, hxx: f32, hyy: f32, hxy: f32) -> (f64, f64) {
    let det = hxx * hyy - hxy * hxy;
    if det.abs() < 1e-12 {
        return (0.0, 0.0);
    }
    let du = -(hyy * gx - hxy * gy) / det;
    let dv = -(hxx * gy - hxy * gx) / det;
    ((du as f64).clamp(-0.5, 0.5), (dv as f64).clamp(-0.5, 0.5))
}

/// Precision and recall of detections against ground-truth corner pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrecisionRecall {
    /// Detections matched one-to-one to a truth point within the radius.
    pub true_positives: usize,
    /// Number of detections.
    pub detections: usize,
    /// Number of truth points.
    pub truths: usize,
    /// true_positives / detections (1 when there are no detections).
    pub precision: f64,
    /// true_positives / truths (1 when there are no truth points).
    pub recall: f64,
}

/// Greedy one-to-one matching (closest pairs first) of detections to truth points within
/// `match_radius_px`, as object-detection benchmarks count hits.
pub fn precision_recall(
    detections: &[CornerDetection],
    truth_points: &[[f64; 2]],
    match_radius_px: f64,
) -> PrecisionRecall {
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, d) in detections.iter().enumerate() {
        for (j, t) in truth_points.iter().enumerate() {
            let dist = (d.u_px - t[0]).hypot(d.v_px - t[1]);
            if dist <= match_radius_px {
                pairs.push((dist, i, j));
            }
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut used_d, mut used_t) = (vec![false; detections.len()], vec![false; truth_points.len()]);
    let mut tp = 0;
    for (_, i, j) in pairs {
        if !used_d[i] && !used_t[j] {
            used_d[i] = true;
            used_t[j] = true;
            tp += 1;
        }
    }
    let ratio = |num: usize, den: usize| if den == 0 { 1.0 } else { num as f64 / den as f64 };
    PrecisionRecall {
        true_positives: tp,
        detections: detections.len(),
        truths: truth_points.len(),
        precision: ratio(tp, detections.len()),
        recall: ratio(tp, truth_points.len()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraModel, Distortion};
    use crate::synth::{add_noise, render_raw_frame, HotPolyline};

    fn zigzag() -> HotPolyline {
        HotPolyline {
            vertices_mm: vec![
                [-11.0, -2.0],
                [-8.0, 2.5],
                [-4.0, -2.0],
                [0.0, 2.5],
                [4.0, -2.0],
                [8.0, 2.5],
                [11.0, -1.0],
            ],
            background_c: 60.0,
            bead_c: 128.0,
            bead_sigma_mm: 0.25,
            corner_excess_c: 17.0,
            corner_sigma_mm: 0.45,
        }
    }

    fn undistorted_view(scene: &HotPolyline) -> (ThermalFrame, Vec<[f64; 2]>) {
        let cam = CameraModel::lepton35(Distortion::default());
        let mut frame = render_raw_frame(&cam, [0.0, 0.0], |p| scene.temp_c(p));
        add_noise(&mut frame, 0.05, 3);
        let truth = scene.corners_mm().iter().filter_map(|&c| cam.plane_to_undistorted_px(c)).collect();
        (frame, truth)
    }

    #[test]
    fn finds_every_hot_corner_of_a_zigzag_and_nothing_else() {
        let scene = zigzag();
        let (frame, truth) = undistorted_view(&scene);
        let dets = detect_corners(&frame, &CornerParams::paper_defaults());
        let pr = precision_recall(&dets, &truth, 1.0);
        assert_eq!((pr.precision, pr.recall), (1.0, 1.0), "{pr:?} {dets:?} {truth:?}");
        assert!(dets.iter().all(|d| (140.0..=150.0).contains(&d.temp_c)));
    }

    #[test]
    fn sub_pixel_refinement_lands_within_half_a_pixel() {
        let scene = zigzag();
        let (frame, truth) = undistorted_view(&scene);
        let dets = detect_corners(&frame, &CornerParams::paper_defaults());
        for t in &truth {
            let d = dets.iter().map(|d| (d.u_px - t[0]).hypot(d.v_px - t[1])).fold(f64::INFINITY, f64::min);
            // Measured: ≤ 0.38 px, biased towards the inside of the corner, where both
            // arms of the bead add heat (a 3 × 3 quadratic cannot remove that asymmetry).
            assert!(d < 0.5, "corner {t:?} off by {d} px");
        }
    }

    #[test]
    fn corners_outside_the_band_are_ignored() {
        // Same geometry, corners at 128 + 40 = 168 °C: too hot, not "newly printed" per Sec. 3.2.
        let mut scene = zigzag();
        scene.corner_excess_c = 40.0;
        let (frame, _) = undistorted_view(&scene);
        assert!(detect_corners(&frame, &CornerParams::paper_defaults()).is_empty());
    }

    #[test]
    fn a_straight_bead_in_the_band_has_no_corners() {
        // A ridge at 145 °C: in the band, local maxima from noise, but one flat eigenvalue.
        let scene = HotPolyline {
            vertices_mm: vec![[-9.0, 0.5], [9.0, 1.5]],
            background_c: 60.0,
            bead_c: 145.0,
            bead_sigma_mm: 0.2,
            corner_excess_c: 0.0,
            corner_sigma_mm: 0.3,
        };
        let (frame, _) = undistorted_view(&scene);
        let dets = detect_corners(&frame, &CornerParams::paper_defaults());
        assert!(dets.is_empty(), "{dets:?}");
    }

    #[test]
    fn corners_near_the_edge_are_removed() {
        let mut scene = zigzag();
        // Put the only corner within 5 % of the left edge (u < 8 px).
        let cam = CameraModel::lepton35(Distortion::default());
        let h0 = cam.nominal_homography();
        let c = h0.apply([5.0, 60.0]);
        scene.vertices_mm = vec![[c[0] + 0.5, c[1] - 3.0], c, [c[0] + 0.5, c[1] + 3.0]];
        let (frame, truth) = undistorted_view(&scene);
        assert!(truth[0][0] < 8.0);
        assert!(detect_corners(&frame, &CornerParams::paper_defaults()).is_empty());
    }

    #[test]
    fn precision_recall_counts_one_to_one_hits() {
        let det = |u, v| CornerDetection { u_px: u, v_px: v, temp_c: 145.0, score: 1.0 };
        let dets = [det(10.0, 10.0), det(10.5, 10.0), det(50.0, 50.0)];
        let pr = precision_recall(&dets, &[[10.2, 10.0], [80.0, 80.0]], 1.0);
        assert_eq!(pr.true_positives, 1);
        assert!((pr.precision - 1.0 / 3.0).abs() < 1e-12 && (pr.recall - 0.5).abs() < 1e-12);
    }

    #[test]
    fn all_nan_or_wrong_size_frames_give_no_corners() {
        let params = CornerParams::paper_defaults();
        assert!(detect_corners(&ThermalFrame::filled(160, 120, f32::NAN), &params).is_empty());
        let mut det = CornerDetector::new(160, 120, params).unwrap();
        assert!(det.detect(&ThermalFrame::filled(80, 60, 145.0)).is_empty());
    }
}
