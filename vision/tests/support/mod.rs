//! A test-only virtual camera for single printed lines (the model of `vision::lines`'s
//! brief, written independently of the segmenter): pixel (i, j) has its centre at
//! (i + 0.5, j + 0.5) px; the line occupies s ∈ [0, L], t ∈ [−w_l(s), w_r(s)] around its
//! axis; coverage is the indicator blurred by a Gaussian PSF of σ px, which for a locally
//! straight edge is ½[erf((t + w_l)/σ√2) − erf((t − w_r)/σ√2)] times the same factor
//! along s at both ends; intensity I = V·(B + A·c) + noise with a linear lighting ramp and
//! a smooth random texture in the bed B, vignetting V = 1 − k·r², Gaussian noise; then
//! quantised to 8 or 16 bits and written as a PNG through kornia-io.
//!
//! erf here is Numerical Recipes' `erfcc` (Chebyshev, |error| ≤ 1.2·10⁻⁷), not the
//! segmenter's Abramowitz–Stegun formula, so that the two do not share an error.
#![allow(dead_code)]

use kornia_image::ImageSize;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use vision::lines::{GrayImage, LineGeometry};

/// A smooth random function of s (mm): a sum of cosines with Gaussian-spectrum
/// frequencies, i.e. a stationary field of standard deviation `amplitude_mm` and
/// Gaussian correlation of length `correlation_mm`.
#[derive(Debug, Clone)]
pub struct RoughEdge {
    waves: Vec<(f64, f64)>,
    amplitude_mm: f64,
}

impl RoughEdge {
    /// A new random edge.
    pub fn new(rng: &mut ChaCha8Rng, amplitude_mm: f64, correlation_mm: f64) -> Self {
        let waves = (0..32)
            .map(|_| {
                let omega: f64 = StandardNormal.sample(rng);
                (omega / correlation_mm, rng.random_range(0.0..std::f64::consts::TAU))
            })
            .collect();
        Self { waves, amplitude_mm }
    }

    /// The edge's deviation at `s_mm` (mm).
    pub fn at(&self, s_mm: f64) -> f64 {
        let scale = self.amplitude_mm * (2.0 / self.waves.len() as f64).sqrt();
        scale * self.waves.iter().map(|(omega, phase)| (omega * s_mm + phase).cos()).sum::<f64>()
    }
}

/// The paper-000-like width profile: 0.8 mm mean, a start blob up to 1.3 mm over the
/// first 5 mm, a 0.05 mm ripple of 10 mm period and a slow trend, with two rough edges.
#[derive(Debug, Clone)]
pub struct WidthProfile {
    pub length_mm: f64,
    pub mean_mm: f64,
    pub left: RoughEdge,
    pub right: RoughEdge,
}

impl WidthProfile {
    pub fn paper000(rng: &mut ChaCha8Rng) -> Self {
        let left = RoughEdge::new(rng, 0.007, 0.3);
        let right = RoughEdge::new(rng, 0.008, 0.45);
        Self { length_mm: 120.0, mean_mm: 0.8, left, right }
    }

    /// The smooth part of the width (mm).
    pub fn smooth_width_mm(&self, s_mm: f64) -> f64 {
        let blob = 0.5 * (-(s_mm / 1.8).powi(2)).exp();
        let ripple = 0.05 * (std::f64::consts::TAU * s_mm / 10.0).sin();
        let trend = 0.04 * (s_mm / self.length_mm - 0.5);
        self.mean_mm + blob + ripple + trend
    }

    /// Left half-width w_l (mm); the line is 0.01 mm off its axis.
    pub fn left_mm(&self, s_mm: f64) -> f64 {
        0.5 * self.smooth_width_mm(s_mm) + 0.01 + self.left.at(s_mm)
    }

    /// Right half-width w_r (mm).
    pub fn right_mm(&self, s_mm: f64) -> f64 {
        0.5 * self.smooth_width_mm(s_mm) - 0.01 + self.right.at(s_mm)
    }

    /// The true width w_l + w_r (mm).
    pub fn width_mm(&self, s_mm: f64) -> f64 {
        self.left_mm(s_mm) + self.right_mm(s_mm)
    }
}

/// Everything the virtual camera needs for one photo.
#[derive(Debug, Clone)]
pub struct Scene {
    pub width_px: usize,
    pub height_px: usize,
    pub px_per_mm: f64,
    pub start_px: [f64; 2],
    pub angle_rad: f64,
    pub profile: WidthProfile,
    pub sigma_psf_px: f64,
    pub bed_level: f64,
    /// Line contrast A (negative: darker than the bed).
    pub contrast: f64,
    /// Lighting ramp: relative change of B from the centre to the right / bottom border.
    pub ramp: [f64; 2],
    /// Texture std as a fraction of |A|, and its correlation (px).
    pub texture: (f64, f64),
    /// Vignetting k of V = 1 − k·r² (r = 1 in the corners).
    pub vignetting: f64,
    /// Noise std as a fraction of |A|.
    pub noise: f64,
    /// 8 or 16.
    pub bits: u8,
    /// Whether the line is drawn at all (false: bed and noise only).
    pub with_line: bool,
    pub seed: u64,
}

impl Scene {
    /// The test scene: a 120 mm line at `angle_deg`, bright or dark, framed with a
    /// margin of `lateral_margin_px` beyond the segmenter's window and 40 px at the ends.
    pub fn paper000(px_per_mm: f64, angle_deg: f64, dark: bool, bits: u8, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let profile = WidthProfile::paper000(&mut rng);
        let angle_rad = angle_deg.to_radians();
        let window_px = (1.5 * 0.8 * px_per_mm).max(0.4 * px_per_mm + 8.0);
        let (half_lat, half_along) = (window_px + 40.0, 0.5 * profile.length_mm * px_per_mm + 40.0);
        let (cos, sin) = (angle_rad.cos().abs(), angle_rad.sin().abs());
        let width_px = (2.0 * (half_along * cos + half_lat * sin)).ceil() as usize;
        let height_px = (2.0 * (half_along * sin + half_lat * cos)).ceil() as usize;
        let centre = [width_px as f64 / 2.0, height_px as f64 / 2.0];
        let half_len_px = 0.5 * profile.length_mm * px_per_mm;
        let start_px = [centre[0] - half_len_px * angle_rad.cos(), centre[1] - half_len_px * angle_rad.sin()];
        let (bed_level, contrast) = if dark { (0.72, -0.45) } else { (0.25, 0.5) };
        Self {
            width_px,
            height_px,
            px_per_mm,
            start_px,
            angle_rad,
            profile,
            sigma_psf_px: [1.2, 1.5, 1.8][(seed % 3) as usize],
            bed_level,
            contrast,
            ramp: [0.15, 0.05],
            texture: (0.03, 2.0),
            vignetting: 0.2,
            noise: 0.015,
            bits,
            with_line: true,
            seed,
        }
    }

    /// The metadata with the start 6 px and the direction 0.5° off.
    pub fn nominal_geometry(&self) -> LineGeometry {
        LineGeometry {
            start_px: [self.start_px[0] + 3.6, self.start_px[1] - 4.8],
            direction_rad: self.angle_rad + 0.5f64.to_radians(),
            length_mm: self.profile.length_mm,
            px_per_mm: self.px_per_mm,
            nominal_width_mm: self.profile.mean_mm,
        }
    }

    /// The photo as PNG bytes.
    pub fn render_png(&self) -> Vec<u8> {
        let intensity = self.render_intensity();
        let size = ImageSize { width: self.width_px, height: self.height_px };
        let mut png = Vec::new();
        if self.bits == 8 {
            let pixels: Vec<u8> = intensity.iter().map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8).collect();
            let img = kornia_image::Image::<u8, 1>::new(size, pixels).unwrap();
            kornia_io::png::encode_image_png_gray8(&img, &mut png, Some(1)).unwrap();
        } else {
            let pixels: Vec<u16> = intensity.iter().map(|&v| (v.clamp(0.0, 1.0) * 65535.0).round() as u16).collect();
            kornia_io::png::encode_image_png_gray16_slice(&pixels, size, &mut png, Some(1)).unwrap();
        }
        png
    }

    /// The photo decoded as the segmenter sees it.
    pub fn render(&self) -> GrayImage {
        GrayImage::from_png_bytes(&self.render_png(), 1 << 26).unwrap()
    }

    /// Intensity before quantisation, row-major.
    pub fn render_intensity(&self) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x5EED);
        let texture = smooth_field(&mut rng, self.width_px, self.height_px, self.texture.1);
        let coverage = self.coverage();
        let (w, h) = (self.width_px as f64, self.height_px as f64);
        let half_diag2 = 0.25 * (w * w + h * h);
        let texture_std = self.texture.0 * self.contrast.abs();
        let noise_std = self.noise * self.contrast.abs();
        let mut out = Vec::with_capacity(self.width_px * self.height_px);
        for j in 0..self.height_px {
            for i in 0..self.width_px {
                let (u, v) = (i as f64 + 0.5, j as f64 + 0.5);
                let (x, y) = (u - 0.5 * w, v - 0.5 * h);
                let ramp = 1.0 + self.ramp[0] * x / (0.5 * w) + self.ramp[1] * y / (0.5 * h);
                let bed = self.bed_level * ramp + texture_std * texture[j * self.width_px + i];
                let vignette = 1.0 - self.vignetting * (x * x + y * y) / half_diag2;
                let k = j * self.width_px + i;
                let noise: f64 = StandardNormal.sample(&mut rng);
                out.push(vignette * (bed + self.contrast * coverage[k]) + noise_std * noise);
            }
        }
        out
    }

    /// PSF-blurred coverage of the line per pixel.
    fn coverage(&self) -> Vec<f64> {
        let mut out = vec![0.0; self.width_px * self.height_px];
        if !self.with_line {
            return out;
        }
        let ppm = self.px_per_mm;
        let length_px = self.profile.length_mm * ppm;
        let grid_step_px = 0.25;
        let n_grid = (length_px / grid_step_px).ceil() as usize + 1;
        let half_widths: Vec<(f64, f64)> = (0..n_grid)
            .map(|g| {
                let s_mm = (g as f64 * grid_step_px / ppm).min(self.profile.length_mm);
                (self.profile.left_mm(s_mm) * ppm, self.profile.right_mm(s_mm) * ppm)
            })
            .collect();
        let (d, n) = ([self.angle_rad.cos(), self.angle_rad.sin()], [-self.angle_rad.sin(), self.angle_rad.cos()]);
        let reach = 6.0 * self.sigma_psf_px;
        let max_half = 1.0 * ppm + reach;
        let k = 1.0 / (self.sigma_psf_px * std::f64::consts::SQRT_2);
        for j in 0..self.height_px {
            for i in 0..self.width_px {
                let (du, dv) = (i as f64 + 0.5 - self.start_px[0], j as f64 + 0.5 - self.start_px[1]);
                let (s, t) = (du * d[0] + dv * d[1], du * n[0] + dv * n[1]);
                if t.abs() > max_half || s < -reach || s > length_px + reach {
                    continue;
                }
                let g = (s.clamp(0.0, length_px) / grid_step_px).min((n_grid - 1) as f64);
                let (g0, f) = (g.floor() as usize, g.fract());
                let g1 = (g0 + 1).min(n_grid - 1);
                let wl = half_widths[g0].0 * (1.0 - f) + half_widths[g1].0 * f;
                let wr = half_widths[g0].1 * (1.0 - f) + half_widths[g1].1 * f;
                let across = 0.5 * (erf((t + wl) * k) - erf((t - wr) * k));
                let along = 0.5 * (erf(s * k) - erf((s - length_px) * k));
                out[j * self.width_px + i] = across * along;
            }
        }
        out
    }
}

/// White noise blurred by a Gaussian of `sigma_px`, rescaled to unit standard deviation.
fn smooth_field(rng: &mut ChaCha8Rng, width: usize, height: usize, sigma_px: f64) -> Vec<f64> {
    let white: Vec<f64> = (0..width * height).map(|_| StandardNormal.sample(&mut *rng)).collect();
    let radius = (3.0 * sigma_px).ceil() as isize;
    let kernel: Vec<f64> = (-radius..=radius).map(|x| (-(x * x) as f64 / (2.0 * sigma_px * sigma_px)).exp()).collect();
    let norm: f64 = kernel.iter().map(|k| k * k).sum::<f64>();
    let blur = |src: &[f64], stride: usize, len: usize, count: usize, step: usize| {
        let mut out = vec![0.0; src.len()];
        for line in 0..count {
            for x in 0..len as isize {
                let sum: f64 = (-radius..=radius)
                    .map(|r| {
                        let xi = (x + r).clamp(0, len as isize - 1) as usize;
                        kernel[(r + radius) as usize] * src[line * step + xi * stride]
                    })
                    .sum();
                out[line * step + x as usize * stride] = sum;
            }
        }
        out
    };
    let rows = blur(&white, 1, width, height, width);
    let both = blur(&rows, width, height, width, 1);
    // Each pass scales the std by √Σk²: undo both.
    both.iter().map(|v| v / norm).collect()
}

/// erf(x) by Numerical Recipes' erfcc (|error| ≤ 1.2·10⁻⁷).
pub fn erf(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98 + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let erfc = t * poly.exp();
    (1.0 - erfc).copysign(x)
}
