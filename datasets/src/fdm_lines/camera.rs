//! The virtual top-view camera over a printed line (DESIGN §5.1): a gray photo of the
//! bed with the line on it, as a lab's fixed camera would take it.
//!
//! ```text
//! geometry   pixel centre p = (i + ½, j + ½); s = (p − P0)·d / k, t = (p − P0)·n / k
//!            (k the true px/mm, d the print direction rotated by a random ±3°, n its normal)
//! coverage   c = [Φ((t + l(s))/σ) − Φ((t − r(s))/σ)]·[Φ(s/σ) − Φ((s − L)/σ)]
//!            (the line's indicator blurred by a Gaussian PSF of σ, separably in the
//!            line's own frame: the edges' slopes are under 0.05, so the error is of
//!            their square)
//! intensity  I = V·(B + A·c) + ε,  B = b·(1 + g·(u, v)·ĝ) + texture,  V = 1 − ν·r²/r²_corner
//! sensor     ε ~ N(0, (η·A)²), quantised to 8 or 16 bits
//! ```
//!
//! `l(s)`, `r(s)` are the printed edges, linear between the printer's 0.05 mm truth
//! samples. The bed texture is a smooth random field (Gaussian noise on a coarse grid,
//! bilinearly interpolated). A camera scale error renders at `(1 + e)` times the
//! recorded px/mm. The recorded start point and direction are the true ones off by a
//! marking error, as a person clicking the line's ends would leave them.

use std::f64::consts::{FRAC_1_SQRT_2, PI};
use std::io::BufWriter;

use models::fdm::printer::{truth_grid_weights, PrintedLine};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use statrs::function::erf::erf;

use super::ImagePlacement;

/// The camera's settings (defaults: [`CameraSettings::default`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraSettings {
    /// Recorded pixel scale (px/mm).
    pub px_per_mm: f64,
    /// 8 or 16.
    pub bit_depth: u8,
    /// Gaussian PSF standard deviation (px).
    pub psf_sigma_px: f64,
    /// Largest rotation of the line in the frame (degrees).
    pub max_rotation_deg: f64,
    /// Bed shown around the line on every side (mm).
    pub margin_mm: f64,
    /// Largest extra random offset of the line in the frame (px).
    pub max_offset_px: f64,
    /// Bed brightness (0-1).
    pub bed_level: f64,
    /// Line brightness over the bed, `A` (signed: a dark line on a light bed is < 0).
    pub contrast: f64,
    /// Lighting gradient: relative change of the bed's brightness across the frame.
    pub lighting_gradient: f64,
    /// Vignetting: relative dimming in the corners.
    pub vignetting: f64,
    /// Bed texture standard deviation, relative to `|A|`.
    pub texture: f64,
    /// Bed texture correlation length (px).
    pub texture_px: f64,
    /// Sensor noise standard deviation, relative to `|A|`.
    pub noise: f64,
    /// Standard deviation of the marked start point (px).
    pub marking_error_px: f64,
    /// Standard deviation of the marked direction (degrees).
    pub marking_error_deg: f64,
}

impl Default for CameraSettings {
    /// 40 px/mm, 8 bits, a PSF of 1.2 px, ±3°, a light line on a dark bed with a 15 %
    /// lighting gradient, 15 % vignetting, 3 % texture and 1.5 % noise.
    fn default() -> Self {
        Self {
            px_per_mm: 40.0,
            bit_depth: 8,
            psf_sigma_px: 1.2,
            max_rotation_deg: 3.0,
            margin_mm: 3.0,
            max_offset_px: 16.0,
            bed_level: 0.2,
            contrast: 0.55,
            lighting_gradient: 0.15,
            vignetting: 0.15,
            texture: 0.03,
            texture_px: 4.0,
            noise: 0.015,
            marking_error_px: 2.0,
            marking_error_deg: 0.2,
        }
    }
}

/// A rendered photo.
#[derive(Debug, Clone, PartialEq)]
pub struct Photo {
    /// PNG bytes.
    pub png: Vec<u8>,
    /// Width and height (px).
    pub size_px: (usize, usize),
    /// The start point and direction as recorded (marked), at the recorded scale.
    pub recorded: ImagePlacement,
    /// The true start point (px) and direction (degrees) and the true px/mm.
    pub truth: ImagePlacement,
}

/// Why a photo could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// A setting outside physics.
    #[error("camera setting {0}")]
    Setting(String),
    /// The PNG encoder failed.
    #[error("encoding the photo: {0}")]
    Encode(String),
}

/// The frame and pose of one photo.
struct Frame {
    width: usize,
    height: usize,
    start: [f64; 2],
    direction: [f64; 2],
    px_per_mm: f64,
}

/// Photographs `line` (of length `length_mm`) with `settings`; `scale_error` is the
/// camera scale error effect (true px/mm = recorded × (1 + e)); `rng` the photo's
/// stream (pose, texture, lighting, noise, marking).
pub fn photograph(
    line: &PrintedLine,
    length_mm: f64,
    settings: &CameraSettings,
    scale_error: f64,
    rng: &mut ChaCha8Rng,
) -> Result<Photo, CameraError> {
    check(settings)?;
    let frame = frame(line, length_mm, settings, scale_error, rng);
    let texture = Texture::new(&frame, settings, rng);
    let gradient_angle = rng.random_range(0.0..2.0 * PI);
    let full_scale = if settings.bit_depth == 8 { 255.0 } else { 65535.0 };
    let pixel_seed: u64 = rng.random();
    let mut gray_levels = vec![0u16; frame.width * frame.height];
    gray_levels.par_chunks_mut(frame.width).enumerate().for_each(|(j, row)| {
        let mut row_rng = ChaCha8Rng::seed_from_u64(pixel_seed ^ (j as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let normal = Normal::new(0.0, settings.noise * settings.contrast.abs()).expect("finite noise");
        for (i, out) in row.iter_mut().enumerate() {
            let (u, v) = (i as f64 + 0.5, j as f64 + 0.5);
            let clean = intensity(&frame, line, length_mm, settings, &texture, gradient_angle, u, v);
            *out = ((clean + normal.sample(&mut row_rng)).clamp(0.0, 1.0) * full_scale).round() as u16;
        }
    });
    let recorded = marked(&frame, settings, rng);
    let truth = ImagePlacement {
        px_per_mm: frame.px_per_mm,
        start_x_px: frame.start[0],
        start_y_px: frame.start[1],
        direction_deg: frame.direction[1].atan2(frame.direction[0]).to_degrees(),
    };
    let png = encode(&gray_levels, frame.width, frame.height, settings.bit_depth)?;
    Ok(Photo { png, size_px: (frame.width, frame.height), recorded, truth })
}

fn check(s: &CameraSettings) -> Result<(), CameraError> {
    let bad = |what: &str| Err(CameraError::Setting(what.into()));
    if !(s.px_per_mm.is_finite() && (1.0..=200.0).contains(&s.px_per_mm)) {
        return bad("px_per_mm: expected 1 to 200");
    }
    if s.bit_depth != 8 && s.bit_depth != 16 {
        return bad("bit_depth: expected 8 or 16");
    }
    let fractions = [s.bed_level, s.lighting_gradient, s.vignetting, s.texture, s.noise];
    if !fractions.iter().all(|f| f.is_finite() && (0.0..1.0).contains(f)) || s.contrast.abs() > 1.0 {
        return bad("levels: expected fractions in [0, 1)");
    }
    if !(s.psf_sigma_px > 0.0 && s.psf_sigma_px <= 10.0 && s.texture_px >= 1.0) {
        return bad("psf_sigma_px: expected (0, 10] px, texture_px ≥ 1 px");
    }
    Ok(())
}

/// Draws the rotation and offset and sizes the frame to hold the line and its margin.
fn frame(line: &PrintedLine, length_mm: f64, s: &CameraSettings, scale_error: f64, rng: &mut ChaCha8Rng) -> Frame {
    let k = s.px_per_mm * (1.0 + scale_error);
    let angle = rng.random_range(-s.max_rotation_deg..=s.max_rotation_deg).to_radians();
    let (d, n) = ([angle.cos(), angle.sin()], [-angle.sin(), angle.cos()]);
    let half_mm = line.left_mm.iter().chain(&line.right_mm).copied().fold(0.0, f64::max) + s.margin_mm;
    let corners = [
        (-s.margin_mm, -half_mm),
        (-s.margin_mm, half_mm),
        (length_mm + s.margin_mm, -half_mm),
        (length_mm + s.margin_mm, half_mm),
    ];
    let at = |(a, b): (f64, f64)| [k * (a * d[0] + b * n[0]), k * (a * d[1] + b * n[1])];
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in corners.map(at) {
        for c in 0..2 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    let offset = [rng.random_range(0.0..=s.max_offset_px), rng.random_range(0.0..=s.max_offset_px)];
    let extra = [rng.random_range(0.0..=s.max_offset_px), rng.random_range(0.0..=s.max_offset_px)];
    Frame {
        width: (hi[0] - lo[0] + offset[0] + extra[0]).ceil() as usize,
        height: (hi[1] - lo[1] + offset[1] + extra[1]).ceil() as usize,
        start: [offset[0] - lo[0], offset[1] - lo[1]],
        direction: d,
        px_per_mm: k,
    }
}

/// The clean intensity at pixel centre `(u, v)`.
#[allow(clippy::too_many_arguments)]
fn intensity(
    f: &Frame,
    line: &PrintedLine,
    length_mm: f64,
    s: &CameraSettings,
    texture: &Texture,
    gradient_angle: f64,
    u: f64,
    v: f64,
) -> f64 {
    let (du, dv) = (u - f.start[0], v - f.start[1]);
    let along_mm = (du * f.direction[0] + dv * f.direction[1]) / f.px_per_mm;
    let across_mm = (-du * f.direction[1] + dv * f.direction[0]) / f.px_per_mm;
    let coverage = coverage(line, length_mm, s.psf_sigma_px / f.px_per_mm, along_mm, across_mm);
    let (x, y) = (u / f.width as f64 - 0.5, v / f.height as f64 - 0.5);
    let bed = s.bed_level * (1.0 + s.lighting_gradient * (x * gradient_angle.cos() + y * gradient_angle.sin()))
        + s.texture * s.contrast.abs() * texture.at(u, v);
    let r2 = (x * x + y * y) / 0.5;
    (1.0 - s.vignetting * r2) * (bed + s.contrast * coverage)
}

/// The blurred line's coverage at `(s, t)` (mm), PSF `sigma_mm`.
fn coverage(line: &PrintedLine, length_mm: f64, sigma_mm: f64, s: f64, t: f64) -> f64 {
    let reach = 6.0 * sigma_mm;
    if s < -reach || s > length_mm + reach || t.abs() > 3.0 + reach {
        return 0.0;
    }
    let (left, right) = edges_at(line, s.clamp(0.0, length_mm));
    if t < -left - reach || t > right + reach {
        return 0.0;
    }
    let phi = |x: f64| 0.5 * (1.0 + erf(x / sigma_mm * FRAC_1_SQRT_2));
    (phi(t + left) - phi(t - right)) * (phi(s) - phi(s - length_mm))
}

/// The edges at `s` (mm), linear between the truth samples.
fn edges_at(line: &PrintedLine, s: f64) -> (f64, f64) {
    let (i, j, f) = truth_grid_weights(line.positions_mm.len(), s);
    let lerp = |a: &[f64]| a[i] + f * (a[j] - a[i]);
    (lerp(&line.left_mm), lerp(&line.right_mm))
}

/// The start point and direction a person marks, and the recorded scale.
fn marked(f: &Frame, s: &CameraSettings, rng: &mut ChaCha8Rng) -> ImagePlacement {
    let point = Normal::new(0.0, s.marking_error_px.max(1e-12)).expect("finite");
    let angle = Normal::new(0.0, s.marking_error_deg.max(1e-12)).expect("finite");
    let direction_deg = f.direction[1].atan2(f.direction[0]).to_degrees() + angle.sample(rng);
    ImagePlacement {
        px_per_mm: s.px_per_mm,
        start_x_px: round_to(f.start[0] + point.sample(rng), 100.0),
        start_y_px: round_to(f.start[1] + point.sample(rng), 100.0),
        direction_deg: round_to(direction_deg, 1000.0),
    }
}

fn round_to(x: f64, per_unit: f64) -> f64 {
    (x * per_unit).round() / per_unit
}

/// A smooth random field: standard normal values on a grid `texture_px` apart,
/// bilinearly interpolated (so its deviation is somewhat below 1 between nodes).
struct Texture {
    step_px: f64,
    columns: usize,
    nodes: Vec<f64>,
}

impl Texture {
    fn new(f: &Frame, s: &CameraSettings, rng: &mut ChaCha8Rng) -> Self {
        let columns = (f.width as f64 / s.texture_px).ceil() as usize + 2;
        let rows = (f.height as f64 / s.texture_px).ceil() as usize + 2;
        let normal = Normal::new(0.0, 1.0).expect("unit normal");
        let nodes = (0..columns * rows).map(|_| normal.sample(rng)).collect();
        Self { step_px: s.texture_px, columns, nodes }
    }

    fn at(&self, u: f64, v: f64) -> f64 {
        let (x, y) = (u / self.step_px, v / self.step_px);
        let (i, j) = (x.floor() as usize, y.floor() as usize);
        let (fx, fy) = (x - i as f64, y - j as f64);
        let n = |a: usize, b: usize| self.nodes[b * self.columns + a];
        (1.0 - fy) * ((1.0 - fx) * n(i, j) + fx * n(i + 1, j)) + fy * ((1.0 - fx) * n(i, j + 1) + fx * n(i + 1, j + 1))
    }
}

/// The gray levels as a PNG (8-bit: one byte a pixel; 16-bit: big-endian pairs).
fn encode(levels: &[u16], width: usize, height: usize, bit_depth: u8) -> Result<Vec<u8>, CameraError> {
    let data: Vec<u8> = if bit_depth == 8 {
        levels.iter().map(|&v| v as u8).collect()
    } else {
        levels.iter().flat_map(|v| v.to_be_bytes()).collect()
    };
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(BufWriter::new(&mut out), width as u32, height as u32);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(if bit_depth == 8 { png::BitDepth::Eight } else { png::BitDepth::Sixteen });
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder.write_header().map_err(|e| CameraError::Encode(e.to_string()))?;
        writer.write_image_data(&data).map_err(|e| CameraError::Encode(e.to_string()))?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use models::fdm::printer::TRUTH_STEP_MM;

    use super::*;

    fn straight(width_mm: f64, length_mm: f64) -> PrintedLine {
        let n = (length_mm / TRUTH_STEP_MM) as usize + 1;
        PrintedLine {
            positions_mm: (0..n).map(|i| i as f64 * TRUTH_STEP_MM).collect(),
            left_mm: vec![width_mm / 2.0; n],
            right_mm: vec![width_mm / 2.0; n],
        }
    }

    #[test]
    fn the_coverage_across_a_blurred_line_integrates_to_its_width() {
        // ∫ c dt over the line's cross-section is its width for any PSF.
        let line = straight(0.8, 10.0);
        let dt = 0.001;
        let area: f64 = (-2000..2000).map(|k| coverage(&line, 10.0, 0.03, 5.0, k as f64 * dt) * dt).sum();
        assert!((area - 0.8).abs() < 1e-6, "{area}");
        assert!((coverage(&line, 10.0, 0.03, 5.0, 0.4) - 0.5).abs() < 1e-3);
    }

    #[test]
    fn a_clean_photo_shows_the_line_where_its_placement_says() {
        let line = straight(0.8, 20.0);
        let settings = CameraSettings {
            px_per_mm: 20.0,
            noise: 0.0,
            texture: 0.0,
            vignetting: 0.0,
            lighting_gradient: 0.0,
            ..CameraSettings::default()
        };
        let photo = photograph(&line, 20.0, &settings, 0.0, &mut ChaCha8Rng::seed_from_u64(4)).unwrap();
        let (w, h) = photo.size_px;
        let mut decoder = png::Decoder::new(std::io::Cursor::new(&photo.png)).read_info().unwrap();
        let mut buf = vec![0; decoder.output_buffer_size().unwrap()];
        decoder.next_frame(&mut buf).unwrap();
        let t = photo.truth;
        let (c, sn) = (t.direction_deg.to_radians().cos(), t.direction_deg.to_radians().sin());
        let (u, v) = (t.start_x_px + 10.0 * 20.0 * c, t.start_y_px + 10.0 * 20.0 * sn);
        let on_line = buf[v as usize * w + u as usize] as f64 / 255.0;
        assert!((on_line - 0.75).abs() < 0.01, "{on_line}");
        assert!((buf[0] as f64 / 255.0 - 0.2).abs() < 0.01);
        assert!(w > 400 && h > 40 && (t.px_per_mm - 20.0).abs() < 1e-12);
        assert_eq!(photo, photograph(&line, 20.0, &settings, 0.0, &mut ChaCha8Rng::seed_from_u64(4)).unwrap());
        let scaled = photograph(&line, 20.0, &settings, 0.05, &mut ChaCha8Rng::seed_from_u64(4)).unwrap();
        assert!((scaled.truth.px_per_mm - 21.0).abs() < 1e-12 && scaled.recorded.px_per_mm == 20.0);
    }
}
