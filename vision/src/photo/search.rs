//! The coarse pose of the pattern in the photo, found with nothing but the photo and the
//! G-code: a similarity (rotation θ, scale s, translation) between the bed and the photo.
//!
//! 1. θ modulo 180°: the photo's edge orientations (gradient directions turned by 90°,
//!    weighted by the gradient's magnitude) are correlated circularly with the paths'
//!    directions weighted by their length; the peaks are the candidates, each with θ + 180°.
//! 2. s and the translation: for each θ and s on a logarithmic grid, the material drawn at
//!    that pose is correlated with the downsampled photo by FFT, normalised (zero-mean
//!    template, local image variance from integral images); the best position per (θ, s)
//!    is kept.
//!
//! The camera looks down on the bed, so the photo shows the bed unmirrored: bed y turns
//! against image y (det < 0). A camera that mirrors its image (some endoscope apps do) is
//! told by `mirrored`. Patterns with a symmetry (a frame with evenly spaced lines looks
//! alike turned by 180°) leave several candidates with close scores: all of them are
//! returned and told apart later by the fine fit and the print itself ([`super::orient`]).

use std::sync::Arc;

use rayon::prelude::*;
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

use super::camera::PhotoCamera;
use super::raster::{bounds, BedRaster, Raster};
use super::PrintedPath;
use crate::lines::GrayImage;

/// The downsampled photo's longer side (px).
const COARSE_SIDE_PX: usize = 160;
/// The drawn pattern's shorter side must span at least this many downsampled pixels: a
/// smaller template correlates with plate texture by chance as well as with the print
/// (measured on the shared photos: a 5 × 16 px template scored 0.85 on texture, above the
/// true pose's 0.80). So the pattern must span about an eighth of the photo's longer side.
const MIN_TEMPLATE_SIDE_PX: usize = 20;
/// Step of the logarithmic scale grid.
const LOG_SCALE_STEP: f64 = 0.06;
/// The smallest pattern searched for, as a fraction of the largest that fits.
const MIN_SCALE_FRACTION: f64 = 0.12;
/// Orientation histogram bins over 180°.
const ANGLE_BINS: usize = 180;
/// Most orientation peaks tried (each with θ + 180°).
const MAX_ANGLE_PEAKS: usize = 3;
/// A peak below this fraction of the highest is not tried.
const ANGLE_PEAK_FRACTION: f64 = 0.5;

/// A coarse pose and how well the drawn pattern correlates with the photo there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// The pose as a camera without distortion.
    pub camera: PhotoCamera,
    /// Magnitude of the normalised cross-correlation at the pose (0 … 1).
    pub score: f64,
    /// Rotation of the bed in the photo (rad).
    pub rotation_rad: f64,
    /// Scale (px/mm of the full photo).
    pub scale_px_mm: f64,
    /// +1 if the print reads higher than the plate in the contrast given, −1 if lower.
    pub polarity: f64,
}

/// The best pose per orientation hypothesis, best first.
pub fn coarse_candidates(contrast: &GrayImage, paths: &[PrintedPath], mirrored: bool) -> Vec<Candidate> {
    let factor = contrast.width.max(contrast.height).div_ceil(COARSE_SIDE_PX).max(1);
    let image = Raster {
        width: contrast.width,
        height: contrast.height,
        values: contrast.pixels.iter().map(|v| v.clamp(-0.5, 1.5)).collect(),
    }
    .downsampled(factor);
    let sign = if mirrored { 1.0 } else { -1.0 };
    let correlator = Correlator::new(&image);
    let (lo, hi) = bounds(paths);
    let extent_mm = (hi[0] - lo[0]).hypot(hi[1] - lo[1]).max(1.0);
    let s_max = image.width.max(image.height) as f64 / extent_mm;
    let bed = BedRaster::material(paths, (extent_mm / 400.0).max(0.05), 1.0);
    let scales = scale_grid(s_max);
    // the material blurred by half a coarse pixel at each scale, whatever the rotation
    let blurred: Vec<BedRaster> = scales
        .par_iter()
        .map(|&s| BedRaster { raster: bed.raster.blurred(0.5 / (s * bed.res_mm)), ..bed.clone() })
        .collect();
    let thetas = orientation_candidates(&image, paths, sign);
    let poses: Vec<(f64, f64)> = thetas.iter().flat_map(|&theta| scales.iter().map(move |&s| (theta, s))).collect();
    let peaks: Vec<Option<(f64, [f64; 2])>> = poses
        .par_iter()
        .enumerate()
        .map(|(k, &(theta, s))| correlator.best(&render(&blurred[k % scales.len()], theta, s, sign)))
        .collect();
    let mut out = Vec::new();
    for (per_theta, peaks) in poses.chunks(scales.len().max(1)).zip(peaks.chunks(scales.len().max(1))) {
        let mut best: Option<Candidate> = None;
        for (&(theta, s), peak) in per_theta.iter().zip(peaks) {
            let Some((ncc, t)) = *peak else { continue };
            if best.is_none_or(|b| ncc.abs() > b.score) {
                best = Some(Candidate {
                    camera: similarity_camera(theta, s, sign, t, factor as f64, contrast),
                    score: ncc.abs(),
                    rotation_rad: theta,
                    scale_px_mm: s * factor as f64,
                    polarity: ncc.signum(),
                });
            }
        }
        out.extend(best);
    }
    out.sort_by(|a, b| b.score.total_cmp(&a.score));
    out
}

/// The scales searched (coarse px/mm), from `s_max` down to [`MIN_SCALE_FRACTION`] of
/// it by [`LOG_SCALE_STEP`].
fn scale_grid(s_max: f64) -> Vec<f64> {
    let mut scales = Vec::new();
    let mut s = s_max;
    while s >= s_max * MIN_SCALE_FRACTION {
        scales.push(s);
        s *= (-LOG_SCALE_STEP).exp();
    }
    scales
}

/// The pose image = factor·(s·R(θ)·diag(1, sign)·bed + t) as a camera.
fn similarity_camera(theta: f64, s: f64, sign: f64, t: [f64; 2], factor: f64, contrast: &GrayImage) -> PhotoCamera {
    let (c, sn) = (theta.cos() * s * factor, theta.sin() * s * factor);
    let h = [c, -sn * sign, t[0] * factor, sn, c * sign, t[1] * factor, 0.0, 0.0, 1.0];
    PhotoCamera::from_homography(h, contrast.width, contrast.height)
}

/// A template drawn at a pose, and where its top-left corner sits relative to the pose's
/// image of the bed origin (coarse px).
struct Template {
    raster: Raster,
    corner: [f64; 2],
}

fn render(bed: &BedRaster, theta: f64, s: f64, sign: f64) -> Template {
    let (c, sn) = (theta.cos() * s, theta.sin() * s);
    let forward = |x: f64, y: f64| [c * x - sn * sign * y, sn * x + c * sign * y];
    let (w_mm, h_mm) = (bed.raster.width as f64 * bed.res_mm, bed.raster.height as f64 * bed.res_mm);
    let o = bed.origin_mm;
    let corners = [
        forward(o[0], o[1]),
        forward(o[0] + w_mm, o[1]),
        forward(o[0], o[1] + h_mm),
        forward(o[0] + w_mm, o[1] + h_mm),
    ];
    let umin = corners.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min).floor();
    let vmin = corners.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min).floor();
    let umax = corners.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max).ceil();
    let vmax = corners.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max).ceil();
    let (tw, th) = ((umax - umin) as usize, (vmax - vmin) as usize);
    // inverse of the similarity: bed = (1/s)·diag(1, sign)·R(−θ)·image
    let inverse = |u: f64, v: f64| {
        let (x, y) = ((c * u + sn * v) / (s * s), (-sn * u + c * v) / (s * s));
        [x, y * sign]
    };
    let mut values = vec![0.0f32; tw * th];
    for b in 0..th {
        for a in 0..tw {
            let p = inverse(umin + a as f64 + 0.5, vmin + b as f64 + 0.5);
            let (x, y) = ((p[0] - o[0]) / bed.res_mm, (p[1] - o[1]) / bed.res_mm);
            values[b * tw + a] = bed.raster.sample(x, y).map_or(0.0, |(v, _)| v as f32);
        }
    }
    Template { raster: Raster { width: tw, height: th, values }, corner: [umin, vmin] }
}

/// Rotation candidates θ (rad), each with θ + π.
fn orientation_candidates(image: &Raster, paths: &[PrintedPath], sign: f64) -> Vec<f64> {
    let photo = smooth_circular(&edge_histogram(image));
    let mut pattern = vec![0.0; ANGLE_BINS];
    for p in paths {
        let (dx, dy) = (p.end_mm[0] - p.start_mm[0], p.end_mm[1] - p.start_mm[1]);
        pattern[angle_bin(dy.atan2(dx))] += dx.hypot(dy);
    }
    let pattern = smooth_circular(&pattern);
    // the bed direction φ appears in the photo at θ + sign·φ (a proper view turns it back)
    let n = ANGLE_BINS as isize;
    let step = sign.signum() as isize;
    let score: Vec<f64> = (0..n)
        .map(|t| (0..n).map(|f| pattern[f as usize] * photo[(t + step * f).rem_euclid(n) as usize]).sum())
        .collect();
    let top = score.iter().cloned().fold(0.0, f64::max);
    let mut peaks: Vec<(usize, f64)> = (0..ANGLE_BINS)
        .filter(|&t| {
            let (prev, next) = (score[(t + ANGLE_BINS - 1) % ANGLE_BINS], score[(t + 1) % ANGLE_BINS]);
            score[t] >= prev && score[t] > next && score[t] >= ANGLE_PEAK_FRACTION * top
        })
        .map(|t| (t, score[t]))
        .collect();
    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    peaks.truncate(MAX_ANGLE_PEAKS);
    let bin = std::f64::consts::PI / ANGLE_BINS as f64;
    peaks.iter().flat_map(|&(t, _)| [t as f64 * bin, t as f64 * bin + std::f64::consts::PI]).collect()
}

fn angle_bin(angle_rad: f64) -> usize {
    let a = angle_rad.rem_euclid(std::f64::consts::PI);
    ((a / std::f64::consts::PI * ANGLE_BINS as f64).round() as usize) % ANGLE_BINS
}

/// Edge directions (gradient turned by 90°) weighted by the gradient's magnitude.
fn edge_histogram(image: &Raster) -> Vec<f64> {
    let mut h = vec![0.0; ANGLE_BINS];
    let at = |i: usize, j: usize| f64::from(image.values[j * image.width + i]);
    for j in 1..image.height.saturating_sub(1) {
        for i in 1..image.width.saturating_sub(1) {
            let gx = at(i + 1, j) - at(i - 1, j);
            let gy = at(i, j + 1) - at(i, j - 1);
            let m = gx.hypot(gy);
            if m > 0.0 {
                h[angle_bin(gy.atan2(gx) + std::f64::consts::FRAC_PI_2)] += m;
            }
        }
    }
    h
}

fn smooth_circular(h: &[f64]) -> Vec<f64> {
    let n = h.len() as isize;
    (0..n).map(|i| (-4..=4).map(|k| (-(k * k) as f64 / 8.0).exp() * h[(i + k).rem_euclid(n) as usize]).sum()).collect()
}

/// Normalised cross-correlation of templates with one image by FFT.
struct Correlator {
    image: Raster,
    size: [usize; 2],
    plans: Plans,
    spectrum: Vec<Complex32>,
    sum: Vec<f64>,
    sum_sq: Vec<f64>,
}

impl Correlator {
    fn new(image: &Raster) -> Self {
        let size = [2 * image.width, 2 * image.height];
        let plans = Plans::new(size);
        let mut spectrum = vec![Complex32::new(0.0, 0.0); size[0] * size[1]];
        for j in 0..image.height {
            for i in 0..image.width {
                spectrum[j * size[0] + i].re = image.values[j * image.width + i];
            }
        }
        plans.forward(&mut spectrum);
        let (sum, sum_sq) = integral_images(image);
        Self { image: image.clone(), size, plans, spectrum, sum, sum_sq }
    }

    /// The normalised correlation of largest magnitude (either polarity) of `template`
    /// over the positions where it lies wholly inside the image, and the pose's
    /// translation there (coarse px).
    fn best(&self, template: &Template) -> Option<(f64, [f64; 2])> {
        let (tw, th) = (template.raster.width, template.raster.height);
        let (w, h) = (self.image.width, self.image.height);
        if tw.min(th) < MIN_TEMPLATE_SIDE_PX || tw > w || th > h {
            return None;
        }
        let n = (tw * th) as f64;
        let mean = template.raster.values.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let norm = template.raster.values.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum::<f64>().sqrt();
        if norm.is_nan() || norm <= 0.0 {
            return None;
        }
        let mut buf = vec![Complex32::new(0.0, 0.0); self.size[0] * self.size[1]];
        for b in 0..th {
            for a in 0..tw {
                buf[b * self.size[0] + a].re = template.raster.values[b * tw + a] - mean as f32;
            }
        }
        self.plans.forward(&mut buf);
        for (x, s) in buf.iter_mut().zip(&self.spectrum) {
            *x = s * x.conj();
        }
        self.plans.inverse(&mut buf);
        let scale = 1.0 / (self.size[0] * self.size[1]) as f64;
        let mut best: Option<(f64, [f64; 2])> = None;
        for y in 0..=h - th {
            for x in 0..=w - tw {
                let c = f64::from(buf[y * self.size[0] + x].re) * scale;
                let (s1, s2) = (self.window(&self.sum, x, y, tw, th), self.window(&self.sum_sq, x, y, tw, th));
                let var = (s2 - s1 * s1 / n).max(1e-9);
                let ncc = c / (var.sqrt() * norm);
                if best.is_none_or(|b| ncc.abs() > b.0.abs()) {
                    best = Some((ncc, [x as f64 - template.corner[0], y as f64 - template.corner[1]]));
                }
            }
        }
        best
    }

    fn window(&self, table: &[f64], x: usize, y: usize, tw: usize, th: usize) -> f64 {
        let stride = self.image.width + 1;
        table[(y + th) * stride + x + tw] - table[y * stride + x + tw] - table[(y + th) * stride + x]
            + table[y * stride + x]
    }
}

fn integral_images(image: &Raster) -> (Vec<f64>, Vec<f64>) {
    let stride = image.width + 1;
    let mut sum = vec![0.0; stride * (image.height + 1)];
    let mut sum_sq = sum.clone();
    for j in 0..image.height {
        let (mut row, mut row_sq) = (0.0, 0.0);
        for i in 0..image.width {
            let v = f64::from(image.values[j * image.width + i]);
            row += v;
            row_sq += v * v;
            sum[(j + 1) * stride + i + 1] = sum[j * stride + i + 1] + row;
            sum_sq[(j + 1) * stride + i + 1] = sum_sq[j * stride + i + 1] + row_sq;
        }
    }
    (sum, sum_sq)
}

/// The row and column FFTs of one padded size, planned once per photo and reused by every
/// template's correlation.
struct Plans {
    size: [usize; 2],
    forward: [Arc<dyn Fft<f32>>; 2],
    inverse: [Arc<dyn Fft<f32>>; 2],
}

impl Plans {
    fn new(size: [usize; 2]) -> Self {
        let mut planner = FftPlanner::new();
        let forward = [planner.plan_fft_forward(size[0]), planner.plan_fft_forward(size[1])];
        let inverse = [planner.plan_fft_inverse(size[0]), planner.plan_fft_inverse(size[1])];
        Self { size, forward, inverse }
    }

    fn forward(&self, buf: &mut [Complex32]) {
        fft2(buf, self.size, &self.forward);
    }

    /// Unnormalised inverse.
    fn inverse(&self, buf: &mut [Complex32]) {
        fft2(buf, self.size, &self.inverse);
    }
}

/// In-place 2-D FFT of a row-major `size[0]` × `size[1]` buffer with the row and column
/// plans `fft`.
fn fft2(buf: &mut [Complex32], size: [usize; 2], fft: &[Arc<dyn Fft<f32>>; 2]) {
    fft[0].process(buf);
    let mut column = vec![Complex32::new(0.0, 0.0); size[1]];
    for i in 0..size[0] {
        for j in 0..size[1] {
            column[j] = buf[j * size[0] + i];
        }
        fft[1].process(&mut column);
        for j in 0..size[1] {
            buf[j * size[0] + i] = column[j];
        }
    }
}
