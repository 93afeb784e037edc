//! Where a bed point appears in a photo: a plane-to-image homography followed by radial
//! lens distortion about the image centre (the Brown–Conrady model's two radial terms).
//!
//! u = H·(x, y, 1) (undistorted pixel), d = (u − c)/R, p = c + (u − c)·(1 + k1·|d|² + k2·|d|⁴)
//!
//! with c the image centre and R its half-diagonal, so k1 and k2 are dimensionless and a
//! cheap endoscope's barrel distortion (k1 ≈ −0.1 … −0.3) is of order one. A homography
//! holds every pose of a camera over a flat bed (tilt, roll, height, focal length); the
//! radial terms hold what no homography can, the scale changing with the distance from
//! the optical axis (about ±8 % across the shared photos). The principal point is taken
//! at the image centre: over a flat pattern a shift of it trades against the homography's
//! translation to first order, so fitting it would leave the fit ill-conditioned.

/// Parameters in solver order: the homography's h11 … h32 (h33 = 1), then k1, k2.
pub const N_CAMERA_PARAMS: usize = 10;

/// A photo's camera: bed millimetres to image pixels (x right, y down, the top-left
/// pixel's corner at 0, 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhotoCamera {
    /// Row-major homography from bed mm to undistorted pixels, h33 = 1.
    pub homography: [f64; 9],
    /// Radial distortion coefficient of |d|².
    pub k1: f64,
    /// Radial distortion coefficient of |d|⁴.
    pub k2: f64,
    /// The centre of distortion (px): the image centre.
    pub centre_px: [f64; 2],
    /// The radius normalising the distortion (px): the image's half-diagonal.
    pub radius_px: f64,
}

/// A projected point and its derivatives.
#[derive(Debug, Clone, Copy)]
pub struct Projection {
    /// The image point (px).
    pub point_px: [f64; 2],
    /// d(point)/d(parameters), rows u and v, in [`N_CAMERA_PARAMS`] order.
    pub d_params: [[f64; N_CAMERA_PARAMS]; 2],
    /// d(point)/d(bed x, bed y) (px per mm).
    pub d_bed: [[f64; 2]; 2],
}

impl PhotoCamera {
    /// A camera without distortion for an image of `width_px` × `height_px`.
    pub fn from_homography(homography: [f64; 9], width_px: usize, height_px: usize) -> Self {
        let centre_px = [width_px as f64 / 2.0, height_px as f64 / 2.0];
        Self { homography, k1: 0.0, k2: 0.0, centre_px, radius_px: centre_px[0].hypot(centre_px[1]) }
    }

    /// The parameters in solver order.
    pub fn params(&self) -> [f64; N_CAMERA_PARAMS] {
        let h = &self.homography;
        [h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], self.k1, self.k2]
    }

    /// The same camera with the parameters `p` (solver order).
    pub fn with_params(&self, p: &[f64; N_CAMERA_PARAMS]) -> Self {
        Self { homography: [p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], 1.0], k1: p[8], k2: p[9], ..*self }
    }

    /// Where the bed point `xy_mm` appears (px); `None` behind the camera or at the
    /// horizon (the homography's w ≤ 0).
    #[inline]
    pub fn project(&self, xy_mm: [f64; 2]) -> Option<[f64; 2]> {
        let (u, _) = self.undistorted(xy_mm)?;
        Some(self.distort(u).0)
    }

    /// [`Self::project`] with its derivatives.
    pub fn project_with_derivatives(&self, xy_mm: [f64; 2]) -> Option<Projection> {
        let j = self.param_jacobian(xy_mm)?;
        let h = &self.homography;
        let (u, w, dp_du) = (j.u, j.w, j.dp_du);
        // du/d(x, y) of the homography
        let du_dbed = [
            [(h[0] - u[0] * h[6]) / w, (h[1] - u[0] * h[7]) / w],
            [(h[3] - u[1] * h[6]) / w, (h[4] - u[1] * h[7]) / w],
        ];
        let mut d_bed = [[0.0; 2]; 2];
        for row in 0..2 {
            for col in 0..2 {
                d_bed[row][col] = dp_du[row][0] * du_dbed[0][col] + dp_du[row][1] * du_dbed[1][col];
            }
        }
        let d_params = [j.gradient([1.0, 0.0]), j.gradient([0.0, 1.0])];
        Some(Projection { point_px: j.point_px, d_params, d_bed })
    }

    /// [`Self::project`] with what its derivatives in the parameters are made of (see
    /// [`ParamJacobian`]); `None` where [`Self::project`] has none.
    #[inline]
    pub fn param_jacobian(&self, xy_mm: [f64; 2]) -> Option<ParamJacobian> {
        let [x, y] = xy_mm;
        let (u, w) = self.undistorted(xy_mm)?;
        let (p, f, fp_r2, r2, d) = self.distort_terms(u);
        // dp/du = f·I + 2 f'(r²) d dᵀ
        let dp_du = [
            [f + 2.0 * fp_r2 * d[0] * d[0], 2.0 * fp_r2 * d[0] * d[1]],
            [2.0 * fp_r2 * d[1] * d[0], f + 2.0 * fp_r2 * d[1] * d[1]],
        ];
        let radial = [(u[0] - self.centre_px[0]) * r2, (u[1] - self.centre_px[1]) * r2];
        let iw = 1.0 / w;
        Some(ParamJacobian { point_px: p, dp_du, xyw: [x * iw, y * iw, iw], u, w, radial, r2 })
    }

    /// The image scale along the bed direction `dir` (unit vector) at `xy_mm` (px/mm).
    pub fn scale_along(&self, xy_mm: [f64; 2], dir: [f64; 2]) -> Option<f64> {
        let j = self.project_with_derivatives(xy_mm)?.d_bed;
        Some((j[0][0] * dir[0] + j[0][1] * dir[1]).hypot(j[1][0] * dir[0] + j[1][1] * dir[1]))
    }

    /// Mean image scale (px/mm) at `xy_mm`: the square root of the Jacobian's determinant.
    pub fn mean_scale(&self, xy_mm: [f64; 2]) -> Option<f64> {
        let j = self.project_with_derivatives(xy_mm)?.d_bed;
        Some((j[0][0] * j[1][1] - j[0][1] * j[1][0]).abs().sqrt())
    }

    fn undistorted(&self, [x, y]: [f64; 2]) -> Option<([f64; 2], f64)> {
        let h = &self.homography;
        let w = h[6] * x + h[7] * y + h[8];
        if w.is_nan() || w <= 1e-9 {
            return None;
        }
        // one division per point: the fit projects every point at every iteration
        let iw = 1.0 / w;
        Some(([(h[0] * x + h[1] * y + h[2]) * iw, (h[3] * x + h[4] * y + h[5]) * iw], w))
    }

    fn distort(&self, u: [f64; 2]) -> ([f64; 2], f64) {
        let (p, f, ..) = self.distort_terms(u);
        (p, f)
    }

    /// The distorted point, f, f'(r²) divided by R² folded into d, r² and d = (u − c)/R.
    #[inline]
    fn distort_terms(&self, u: [f64; 2]) -> ([f64; 2], f64, f64, f64, [f64; 2]) {
        let inv_radius = 1.0 / self.radius_px;
        let d = [(u[0] - self.centre_px[0]) * inv_radius, (u[1] - self.centre_px[1]) * inv_radius];
        let r2 = d[0] * d[0] + d[1] * d[1];
        let f = 1.0 + self.k1 * r2 + self.k2 * r2 * r2;
        let fp = self.k1 + 2.0 * self.k2 * r2;
        let p =
            [self.centre_px[0] + (u[0] - self.centre_px[0]) * f, self.centre_px[1] + (u[1] - self.centre_px[1]) * f];
        (p, f, fp, r2, d)
    }
}

/// A projected point and the parts of its derivatives in the camera's parameters. The
/// homography's part is sparse: with a = (dp/du)ᵀ·∇ (the image gradient ∇ pulled back to
/// the undistorted point), d/dh1· = a_u·(x, y, 1)/w, d/dh2· = a_v·(x, y, 1)/w and
/// d/dh3· = −(a·u)·(x, y)/w; the radial terms' are ∇·(u − c)·r² and that times r². So the
/// gradient of an image value in the ten parameters costs a dozen products, not a 2 × 10
/// matrix and its product: the dense camera fit ([`mod@super::align`]) needs it at every point
/// of every iteration.
#[derive(Debug, Clone, Copy)]
pub struct ParamJacobian {
    /// The image point (px).
    pub point_px: [f64; 2],
    dp_du: [[f64; 2]; 2],
    xyw: [f64; 3],
    u: [f64; 2],
    w: f64,
    radial: [f64; 2],
    r2: f64,
}

impl ParamJacobian {
    /// d(value)/d(parameters), in [`N_CAMERA_PARAMS`] order, of an image value whose
    /// gradient at the point is `grad_px` (per px).
    #[inline]
    pub fn gradient(&self, grad_px: [f64; 2]) -> [f64; N_CAMERA_PARAMS] {
        let [gx, gy] = grad_px;
        let a = [gx * self.dp_du[0][0] + gy * self.dp_du[1][0], gx * self.dp_du[0][1] + gy * self.dp_du[1][1]];
        let [xw, yw, iw] = self.xyw;
        let perspective = -(a[0] * self.u[0] + a[1] * self.u[1]);
        let radial = gx * self.radial[0] + gy * self.radial[1];
        [
            a[0] * xw,
            a[0] * yw,
            a[0] * iw,
            a[1] * xw,
            a[1] * yw,
            a[1] * iw,
            perspective * xw,
            perspective * yw,
            radial,
            radial * self.r2,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> PhotoCamera {
        let mut c = PhotoCamera::from_homography([20.5, 1.2, 300.0, -0.8, -19.0, 1500.0, 2e-4, -3e-4, 1.0], 1080, 1920);
        c.k1 = -0.2;
        c.k2 = 0.05;
        c
    }

    #[test]
    fn parameter_derivatives_match_finite_differences() {
        let cam = camera();
        let xy = [12.0, 40.0];
        let analytic = cam.project_with_derivatives(xy).unwrap();
        let p0 = cam.params();
        for k in 0..N_CAMERA_PARAMS {
            let h = 1e-6 * p0[k].abs().max(1e-3);
            let mut p = p0;
            p[k] += h;
            let plus = cam.with_params(&p).project(xy).unwrap();
            p[k] = p0[k] - h;
            let minus = cam.with_params(&p).project(xy).unwrap();
            for row in 0..2 {
                let numeric = (plus[row] - minus[row]) / (2.0 * h);
                let scale = numeric.abs().max(1.0);
                assert!(
                    (numeric - analytic.d_params[row][k]).abs() < 1e-5 * scale,
                    "param {k} row {row}: {numeric} vs {}",
                    analytic.d_params[row][k]
                );
            }
        }
    }

    #[test]
    fn bed_derivatives_match_finite_differences() {
        let cam = camera();
        let xy = [30.0, 5.0];
        let analytic = cam.project_with_derivatives(xy).unwrap().d_bed;
        for col in 0..2 {
            let mut a = xy;
            let mut b = xy;
            a[col] += 1e-5;
            b[col] -= 1e-5;
            let (pa, pb) = (cam.project(a).unwrap(), cam.project(b).unwrap());
            for row in 0..2 {
                let numeric = (pa[row] - pb[row]) / 2e-5;
                assert!((numeric - analytic[row][col]).abs() < 1e-5 * numeric.abs().max(1.0));
            }
        }
    }

    #[test]
    fn without_distortion_the_centre_maps_as_the_homography() {
        let cam = PhotoCamera::from_homography([2.0, 0.0, 540.0, 0.0, -2.0, 960.0, 0.0, 0.0, 1.0], 1080, 1920);
        assert_eq!(cam.project([0.0, 0.0]), Some([540.0, 960.0]));
        assert_eq!(cam.project([10.0, 10.0]), Some([560.0, 940.0]));
        assert!((cam.mean_scale([3.0, 4.0]).unwrap() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn a_point_behind_the_camera_has_no_image() {
        let cam = PhotoCamera::from_homography([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, -0.1, 0.0, 1.0], 100, 100);
        assert!(cam.project([20.0, 0.0]).is_none());
    }
}
