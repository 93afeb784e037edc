//! Per-frame homography, paper 003 Sec. 2.3 eq. 27: P⁽¹⁾ = H·P⁽⁰⁾, from detected corners
//! P⁽⁰⁾ (undistorted image pixels) to the known corners of the printed path P⁽¹⁾ (plane mm).
//!
//! The paper solves H "with least square algorithms" from at least four corners. We add
//! robustness the paper does not describe: kornia-3d's RANSAC driver
//! (`kornia_3d::ransac::run`) with its `HomographyEstimator` (4-point minimal solver),
//! a threshold consensus on the squared plane-side transfer error (mm²) and a sampler of
//! our own drawing from the caller's seeded [`ChaCha8Rng`] (kornia's `UniformSampler`
//! needs rand 0.10, the workspace is on rand 0.9; SPRT is off, so the driver's own
//! thread-local RNG is never touched and the result is deterministic). The final model
//! is the least-squares DLT (`kornia_3d::pose::homography_dlt`, Hartley
//! normalised) refitted on all inliers, as the paper's least-squares step.

use kornia_3d::pose::homography_dlt;
use kornia_3d::ransac::{self, estimators::HomographyEstimator, Match2d2d, RansacConfig, Sampler, ThresholdConsensus};
use kornia_algebra::{Mat3F64, Vec2F64};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// Correspondences a homography needs (8 degrees of freedom, two equations per point).
pub const MIN_CORRESPONDENCES: usize = 4;

/// A 3 × 3 planar homography, row-major, acting on homogeneous points [x, y, 1].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography {
    /// Row-major matrix entries.
    pub m: [[f64; 3]; 3],
}

impl Homography {
    /// The identity map.
    pub const IDENTITY: Homography = Homography { m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] };

    /// Maps point `p`; NaN components when the point maps to infinity.
    #[inline]
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let m = &self.m;
        let w = m[2][0] * p[0] + m[2][1] * p[1] + m[2][2];
        if w.abs() < 1e-15 {
            return [f64::NAN, f64::NAN];
        }
        [(m[0][0] * p[0] + m[0][1] * p[1] + m[0][2]) / w, (m[1][0] * p[0] + m[1][1] * p[1] + m[1][2]) / w]
    }

    /// Determinant of the matrix.
    pub fn determinant(&self) -> f64 {
        let m = &self.m;
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    /// The inverse map, scaled so that its (3, 3) entry is 1 where possible; `None` when
    /// the matrix is singular.
    pub fn inverse(&self) -> Option<Homography> {
        let det = self.determinant();
        if !det.is_finite() || det.abs() < 1e-300 {
            return None;
        }
        let m = &self.m;
        let cof = |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
        let adj = [
            [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
            [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
            [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
        ];
        Some(Homography { m: adj.map(|row| row.map(|v| v / det)) }.normalized())
    }

    /// Matrix product `self · other` (apply `other` first).
    pub fn then_after(&self, other: &Homography) -> Homography {
        let mut out = [[0.0; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                out[r][c] = (0..3).map(|k| self.m[r][k] * other.m[k][c]).sum();
            }
        }
        Homography { m: out }.normalized()
    }

    /// The same projective map scaled so that `m[2][2]` = 1 (unchanged if `m[2][2]` ≈ 0).
    pub fn normalized(&self) -> Homography {
        let s = self.m[2][2];
        if s.abs() < 1e-15 || !s.is_finite() {
            return *self;
        }
        Homography { m: self.m.map(|row| row.map(|v| v / s)) }
    }

    fn from_kornia(h: &Mat3F64) -> Homography {
        // kornia/glam matrices are column-major: cols[c * 3 + r] = H[r][c].
        let cols = h.to_cols_array();
        let mut m = [[0.0; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] = cols[c * 3 + r];
            }
        }
        Homography { m }.normalized()
    }
}

/// RANSAC settings of [`estimate_homography`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HomographyParams {
    /// A correspondence is an inlier when its plane-side transfer error is below this (mm).
    pub inlier_threshold_mm: f64,
    /// RANSAC iteration cap (the driver stops earlier at 99.9 % confidence).
    pub max_iters: u32,
    /// Point sets whose spread (smallest principal standard deviation) is below this
    /// fraction of the largest are treated as collinear (degenerate).
    pub min_spread_ratio: f64,
}

impl HomographyParams {
    /// Defaults sized for a 160 × 120 thermal frame seeing ~0.15 mm per pixel: a 0.3 mm
    /// gate is about two pixels, above sub-pixel corner noise, well below a wrong match.
    pub fn paper_defaults() -> Self {
        Self { inlier_threshold_mm: 0.3, max_iters: 500, min_spread_ratio: 0.02 }
    }
}

/// A fitted homography with its quality measures.
#[derive(Debug, Clone, PartialEq)]
pub struct HomographyFit {
    /// Undistorted image pixel → plane mm.
    pub homography: Homography,
    /// One flag per correspondence: used in the final least-squares refit.
    pub inliers: Vec<bool>,
    /// RMS of the plane-side transfer error over the inliers (mm).
    pub rms_error_mm: f64,
}

impl HomographyFit {
    /// Number of inliers.
    pub fn inlier_count(&self) -> usize {
        self.inliers.iter().filter(|&&b| b).count()
    }
}

/// Why no homography could be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HomographyError {
    /// Fewer correspondences than the 4 a homography needs (paper Sec. 2.3).
    #[error("not enough corners: found {found}, needed {needed}")]
    NotEnoughCorners {
        /// Correspondences supplied (or inliers left).
        found: usize,
        /// Always 4.
        needed: usize,
    },
    /// The image or plane points are (nearly) collinear or coincident.
    #[error("degenerate configuration: {0}")]
    Degenerate(String),
    /// The two point slices differ in length.
    #[error("image and plane point counts differ: {image} vs {plane}")]
    LengthMismatch {
        /// Image points supplied.
        image: usize,
        /// Plane points supplied.
        plane: usize,
    },
}

/// Estimates H (undistorted pixel → plane mm, eq. 27) robustly: RANSAC on kornia-3d's
/// 4-point estimator, then a least-squares DLT refit on the inliers.
pub fn estimate_homography(
    image_px: &[[f64; 2]],
    plane_mm: &[[f64; 2]],
    params: &HomographyParams,
    rng: &mut ChaCha8Rng,
) -> Result<HomographyFit, HomographyError> {
    check_input(image_px, plane_mm, params)?;
    let samples: Vec<Match2d2d> = image_px
        .iter()
        .zip(plane_mm)
        .map(|(a, b)| Match2d2d::new(Vec2F64::new(a[0], a[1]), Vec2F64::new(b[0], b[1])))
        .collect();
    let cfg = RansacConfig {
        max_iters: params.max_iters,
        inlier_threshold: params.inlier_threshold_mm.powi(2),
        ..RansacConfig::default()
    };
    let consensus = ThresholdConsensus { threshold: cfg.inlier_threshold };
    let mut sampler = ChaChaSampler { rng };
    let result = ransac::run(&HomographyEstimator, &consensus, &mut sampler, &samples, &cfg);
    let found = result.inlier_count();
    if result.model.is_none() || found < MIN_CORRESPONDENCES {
        return Err(HomographyError::NotEnoughCorners { found, needed: MIN_CORRESPONDENCES });
    }
    refit_on_inliers(image_px, plane_mm, result.inliers, params)
}

/// Least-squares DLT on all correspondences (no outlier rejection), as in the paper.
pub fn fit_homography_least_squares(
    image_px: &[[f64; 2]],
    plane_mm: &[[f64; 2]],
) -> Result<Homography, HomographyError> {
    if image_px.len() != plane_mm.len() {
        return Err(HomographyError::LengthMismatch { image: image_px.len(), plane: plane_mm.len() });
    }
    if image_px.len() < MIN_CORRESPONDENCES {
        return Err(HomographyError::NotEnoughCorners { found: image_px.len(), needed: MIN_CORRESPONDENCES });
    }
    let x1: Vec<Vec2F64> = image_px.iter().map(|p| Vec2F64::new(p[0], p[1])).collect();
    let x2: Vec<Vec2F64> = plane_mm.iter().map(|p| Vec2F64::new(p[0], p[1])).collect();
    let h = homography_dlt(&x1, &x2).map_err(|e| HomographyError::Degenerate(e.to_string()))?;
    let h = Homography::from_kornia(&h);
    if h.m.iter().flatten().all(|v| v.is_finite()) {
        Ok(h)
    } else {
        Err(HomographyError::Degenerate("non-finite homography".into()))
    }
}

/// RMS plane-side transfer error ‖H·x − y‖ over the flagged correspondences (mm).
pub fn rms_transfer_error_mm(h: &Homography, image_px: &[[f64; 2]], plane_mm: &[[f64; 2]], mask: &[bool]) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for ((p, q), &keep) in image_px.iter().zip(plane_mm).zip(mask) {
        if keep {
            let r = h.apply(*p);
            sum += (r[0] - q[0]).powi(2) + (r[1] - q[1]).powi(2);
            n += 1;
        }
    }
    if n == 0 {
        f64::NAN
    } else {
        (sum / n as f64).sqrt()
    }
}

fn check_input(image_px: &[[f64; 2]], plane_mm: &[[f64; 2]], params: &HomographyParams) -> Result<(), HomographyError> {
    if image_px.len() != plane_mm.len() {
        return Err(HomographyError::LengthMismatch { image: image_px.len(), plane: plane_mm.len() });
    }
    if image_px.len() < MIN_CORRESPONDENCES {
        return Err(HomographyError::NotEnoughCorners { found: image_px.len(), needed: MIN_CORRESPONDENCES });
    }
    if image_px.iter().chain(plane_mm).any(|p| !p[0].is_finite() || !p[1].is_finite()) {
        return Err(HomographyError::Degenerate("non-finite point".into()));
    }
    for (name, pts) in [("image", image_px), ("plane", plane_mm)] {
        let ratio = spread_ratio(pts);
        if ratio.is_nan() || ratio < params.min_spread_ratio {
            return Err(HomographyError::Degenerate(format!("{name} points are collinear or coincident")));
        }
    }
    Ok(())
}

/// sqrt(λ_min / λ_max) of the 2 × 2 covariance: 0 for collinear points, 1 for isotropic.
fn spread_ratio(pts: &[[f64; 2]]) -> f64 {
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p[0]).sum::<f64>() / n, pts.iter().map(|p| p[1]).sum::<f64>() / n);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for p in pts {
        let (dx, dy) = (p[0] - mx, p[1] - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    let half_tr = 0.5 * (sxx + syy);
    let disc = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
    let (l_max, l_min) = (half_tr + disc, (half_tr - disc).max(0.0));
    if l_max <= 0.0 {
        return f64::NAN;
    }
    (l_min / l_max).sqrt()
}

fn refit_on_inliers(
    image_px: &[[f64; 2]],
    plane_mm: &[[f64; 2]],
    inliers: Vec<bool>,
    params: &HomographyParams,
) -> Result<HomographyFit, HomographyError> {
    let pick =
        |pts: &[[f64; 2]]| -> Vec<[f64; 2]> { pts.iter().zip(&inliers).filter(|(_, &k)| k).map(|(p, _)| *p).collect() };
    let (img_in, plane_in) = (pick(image_px), pick(plane_mm));
    check_input(&img_in, &plane_in, params)?;
    let homography = fit_homography_least_squares(&img_in, &plane_in)?;
    let rms_error_mm = rms_transfer_error_mm(&homography, image_px, plane_mm, &inliers);
    Ok(HomographyFit { homography, inliers, rms_error_mm })
}

/// kornia's [`Sampler`] drawing distinct indices from the caller's seeded ChaCha8 stream.
struct ChaChaSampler<'a> {
    rng: &'a mut ChaCha8Rng,
}

impl Sampler for ChaChaSampler<'_> {
    fn sample(&mut self, n: usize, out: &mut [usize]) {
        // Partial Fisher-Yates over a small stack of candidates: k ≤ 4 draws, no allocation.
        for i in 0..out.len() {
            loop {
                let idx = self.rng.random_range(0..n);
                if !out[..i].contains(&idx) {
                    out[i] = idx;
                    break;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn known_h() -> Homography {
        // A tilted-camera-like map: ~0.15 mm/px with perspective foreshortening along v.
        Homography { m: [[0.15, 0.01, -12.0], [0.002, 0.21, -13.0], [0.0001, 0.0012, 1.0]] }
    }

    fn grid_points(n: usize) -> Vec<[f64; 2]> {
        (0..n).map(|i| [10.0 + (i % 5) as f64 * 33.0 + (i / 5) as f64 * 3.0, 8.0 + (i / 5) as f64 * 25.0]).collect()
    }

    #[test]
    fn noiseless_points_recover_the_known_homography_exactly() {
        let h = known_h();
        let img = grid_points(12);
        let plane: Vec<[f64; 2]> = img.iter().map(|p| h.apply(*p)).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let fit = estimate_homography(&img, &plane, &HomographyParams::paper_defaults(), &mut rng).unwrap();
        assert_eq!(fit.inlier_count(), 12);
        assert!(fit.rms_error_mm < 1e-9, "rms {}", fit.rms_error_mm);
        for (a, b) in fit.homography.m.iter().flatten().zip(h.m.iter().flatten()) {
            assert!((a - b).abs() < 1e-9 * (1.0 + b.abs()), "{a} vs {b}");
        }
    }

    #[test]
    fn thirty_percent_gross_outliers_are_rejected() {
        let h = known_h();
        let img = grid_points(20);
        let mut plane: Vec<[f64; 2]> = img.iter().map(|p| h.apply(*p)).collect();
        let outliers = [1, 4, 7, 10, 13, 16];
        for (k, &i) in outliers.iter().enumerate() {
            plane[i][0] += 3.0 + k as f64;
            plane[i][1] -= 2.0 * k as f64 + 1.5;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let fit = estimate_homography(&img, &plane, &HomographyParams::paper_defaults(), &mut rng).unwrap();
        for i in 0..20 {
            assert_eq!(fit.inliers[i], !outliers.contains(&i), "point {i}");
        }
        assert!(fit.rms_error_mm < 1e-9);
        let probe = h.apply([80.0, 60.0]);
        let got = fit.homography.apply([80.0, 60.0]);
        assert!((probe[0] - got[0]).abs() < 1e-9 && (probe[1] - got[1]).abs() < 1e-9);
    }

    #[test]
    fn three_points_are_not_enough() {
        let img = grid_points(3);
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let err = estimate_homography(&img, &img, &HomographyParams::paper_defaults(), &mut rng).unwrap_err();
        assert_eq!(err, HomographyError::NotEnoughCorners { found: 3, needed: 4 });
    }

    #[test]
    fn collinear_points_are_degenerate() {
        let img: Vec<[f64; 2]> = (0..6).map(|i| [10.0 * i as f64, 5.0 * i as f64 + 1.0]).collect();
        let plane: Vec<[f64; 2]> = img.iter().map(|p| known_h().apply(*p)).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let err = estimate_homography(&img, &plane, &HomographyParams::paper_defaults(), &mut rng).unwrap_err();
        assert!(matches!(err, HomographyError::Degenerate(_)), "{err:?}");
    }

    #[test]
    fn inverse_composes_to_identity() {
        let h = known_h();
        let id = h.then_after(&h.inverse().unwrap());
        for r in 0..3 {
            for c in 0..3 {
                let expect = if r == c { 1.0 } else { 0.0 };
                assert!((id.m[r][c] - expect).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn same_seed_gives_the_same_fit() {
        let h = known_h();
        let img = grid_points(15);
        let mut plane: Vec<[f64; 2]> = img.iter().map(|p| h.apply(*p)).collect();
        plane[3][0] += 5.0;
        let params = HomographyParams::paper_defaults();
        let a = estimate_homography(&img, &plane, &params, &mut ChaCha8Rng::seed_from_u64(9)).unwrap();
        let b = estimate_homography(&img, &plane, &params, &mut ChaCha8Rng::seed_from_u64(9)).unwrap();
        assert_eq!(a, b);
    }
}
