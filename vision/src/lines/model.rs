//! The blurred-bar edge model of a line cross-section (step 3 of [`super`]):
//!
//! I(t) = b0 + b1·t + A·½[erf((t − a)/(σ√2)) − erf((t − b)/(σ√2))]
//!
//! a bar of contrast A between the left edge `a` and the right edge `b`, blurred by a
//! Gaussian PSF of width σ, on a linear background b0 + b1·t that absorbs the lighting
//! gradient and the vignetting over the short profile. t, a, b, σ are in profile pixels.
//! `erf` is the Abramowitz–Stegun 7.1.26 approximation (|error| ≤ 1.5·10⁻⁷), hand-written
//! because std has none; it returns exp(−x²) as well, which the Jacobian reuses.

/// Parameter indices of [`EdgeParams::as_array`].
pub const N_PARAMS: usize = 6;

/// 1/√2.
const FRAC_1_SQRT_2: f64 = std::f64::consts::FRAC_1_SQRT_2;
/// 1/√(2π).
const FRAC_1_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// The six parameters of the edge model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeParams {
    /// Background level at t = 0.
    pub b0: f64,
    /// Background slope (per px).
    pub b1: f64,
    /// Contrast of the line against the background (negative for a dark line).
    pub contrast: f64,
    /// Left edge (px, t axis).
    pub left_px: f64,
    /// Right edge (px, t axis).
    pub right_px: f64,
    /// Gaussian PSF width (px).
    pub sigma_px: f64,
}

impl EdgeParams {
    /// The parameters in solver order (b0, b1, A, a, b, σ).
    pub fn as_array(&self) -> [f64; N_PARAMS] {
        [self.b0, self.b1, self.contrast, self.left_px, self.right_px, self.sigma_px]
    }

    /// The parameters from solver order.
    pub fn from_array(p: [f64; N_PARAMS]) -> Self {
        Self { b0: p[0], b1: p[1], contrast: p[2], left_px: p[3], right_px: p[4], sigma_px: p[5] }
    }

    /// The model's value at `t_px`.
    #[inline]
    pub fn value(&self, t_px: f64) -> f64 {
        let k = FRAC_1_SQRT_2 / self.sigma_px;
        let (ea, _) = erf_and_gauss((t_px - self.left_px) * k);
        let (eb, _) = erf_and_gauss((t_px - self.right_px) * k);
        self.b0 + self.b1 * t_px + self.contrast * 0.5 * (ea - eb)
    }

    /// The model's value at `t_px` and its gradient with respect to the six parameters.
    #[inline]
    pub fn value_and_gradient(&self, t_px: f64) -> (f64, [f64; N_PARAMS]) {
        let inv_sigma = 1.0 / self.sigma_px;
        let k = FRAC_1_SQRT_2 * inv_sigma;
        let (da, db) = (t_px - self.left_px, t_px - self.right_px);
        let (ea, xa) = erf_and_gauss(da * k);
        let (eb, xb) = erf_and_gauss(db * k);
        // g(x) = exp(−x²/2σ²)/(σ√2π), the PSF; exp(−(x k)²) is what erf_and_gauss returned.
        let (ga, gb) = (xa * FRAC_1_SQRT_2PI * inv_sigma, xb * FRAC_1_SQRT_2PI * inv_sigma);
        let bar = 0.5 * (ea - eb);
        let a = self.contrast;
        let gradient = [1.0, t_px, bar, -a * ga, a * gb, a * (db * gb - da * ga) * inv_sigma];
        (self.b0 + self.b1 * t_px + a * bar, gradient)
    }
}

/// erf(x) and exp(−x²) (Abramowitz & Stegun 7.1.26, |erf error| ≤ 1.5·10⁻⁷).
#[inline]
pub fn erf_and_gauss(x: f64) -> (f64, f64) {
    // Beyond 4 erf is ±1 within 2·10⁻⁸ and exp(−x²) below 1.2·10⁻⁷: skip the exp (most samples of a profile).
    if x.abs() > 4.0 {
        return (1.0f64.copysign(x), 0.0);
    }
    const P: f64 = 0.327_591_1;
    const A: [f64; 5] = [0.254_829_592, -0.284_496_736, 1.421_413_741, -1.453_152_027, 1.061_405_429];
    let z = x.abs();
    let t = 1.0 / (1.0 + P * z);
    let poly = t * (A[0] + t * (A[1] + t * (A[2] + t * (A[3] + t * A[4]))));
    let gauss = exp_neg(z * z);
    let erf_abs = 1.0 - poly * gauss;
    (erf_abs.copysign(x), gauss)
}

/// e^(−y) for 0 ≤ y ≤ 16 to a relative 10⁻⁸: 2^(−y·log₂e) split into the nearest integer
/// power, set in the exponent bits, and a fractional one in [−½, ½] by its Taylor
/// polynomial of degree 7 (remainder (½ ln 2)⁸/8! < 5·10⁻⁹). Cheaper than `f64::exp`,
/// which dominated the fit's cost.
#[inline]
fn exp_neg(y: f64) -> f64 {
    const C: [f64; 8] = [
        1.0,
        std::f64::consts::LN_2,
        0.240_226_506_959_100_7,
        0.055_504_108_664_821_58,
        0.009_618_129_107_628_477,
        0.001_333_355_814_642_844_3,
        0.000_154_035_303_933_816_1,
        0.000_015_252_733_804_059_84,
    ];
    let x = -y * std::f64::consts::LOG2_E;
    let n = x.round();
    let f = x - n;
    let p = C[0] + f * (C[1] + f * (C[2] + f * (C[3] + f * (C[4] + f * (C[5] + f * (C[6] + f * C[7]))))));
    p * f64::from_bits(((1023 + n as i64) as u64) << 52)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erf_matches_reference_values() {
        // erf(0.5), erf(1), erf(2) from tables (Abramowitz & Stegun Table 7.1).
        for (x, want) in [(0.0, 0.0), (0.5, 0.520_499_877_8), (1.0, 0.842_700_792_9), (2.0, 0.995_322_265_0)] {
            assert!((erf_and_gauss(x).0 - want).abs() < 2e-7, "erf({x})");
            assert!((erf_and_gauss(-x).0 + want).abs() < 2e-7, "erf is odd");
        }
        assert!((erf_and_gauss(1.5).1 - (-2.25f64).exp()).abs() < 1e-9);
        assert_eq!(erf_and_gauss(-6.0), (-1.0, 0.0));
    }

    #[test]
    fn fast_exponential_is_accurate_on_its_range() {
        for k in 0..=1600 {
            let y = k as f64 * 0.01;
            let rel = (exp_neg(y) - (-y).exp()).abs() / (-y).exp();
            assert!(rel < 3e-8, "e^-{y}: relative error {rel}");
        }
    }

    #[test]
    fn the_bar_integrates_to_its_width() {
        // ∫ ½[erf((t−a)/σ√2) − erf((t−b)/σ√2)] dt = b − a: blurring keeps the area.
        let bar = EdgeParams { b0: 0.0, b1: 0.0, contrast: 1.0, left_px: -7.3, right_px: 11.1, sigma_px: 1.7 };
        let area: f64 = (-4000..4000).map(|i| bar.value(i as f64 * 0.01) * 0.01).sum();
        assert!((area - 18.4).abs() < 1e-5, "area {area}");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let p = EdgeParams { b0: 0.3, b1: 0.01, contrast: -0.4, left_px: -5.0, right_px: 6.5, sigma_px: 1.4 };
        for t in [-7.0, -5.2, 0.0, 6.0, 8.0] {
            let (_, grad) = p.value_and_gradient(t);
            for k in 0..N_PARAMS {
                let (mut up, mut down) = (p.as_array(), p.as_array());
                up[k] += 1e-6;
                down[k] -= 1e-6;
                let fd = (EdgeParams::from_array(up).value(t) - EdgeParams::from_array(down).value(t)) / 2e-6;
                assert!((fd - grad[k]).abs() < 1e-5, "t {t} param {k}: {fd} vs {}", grad[k]);
            }
        }
    }
}
