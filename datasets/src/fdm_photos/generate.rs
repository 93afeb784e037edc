//! A virtual printer and camera writing an `fdm-photos` dataset (issue 53, DESIGN §5 and
//! §10): a pressure-advance test pattern of our own G-code, printed with a known melt lag
//! τ under the pressure advance each line's `SET_PRESSURE_ADVANCE` sets
//! ([`models::fdm::pressure_advance`]), and photographed from above by a cheap camera
//! with the habits of real photos, each switchable with a strength.
//!
//! ```text
//! pattern    a frame of two perimeters (40 × 72 mm outside for 21 lines) and N lines 3 mm
//!            apart, each slow (10 mm/s) – fast (100 mm/s) – slow, pressure advance
//!            stepping from line to line (Klipper)
//! print      width along every line from the planned kinematics, the advance and the lag;
//!            a gap where the deposit falls below a fraction of the commanded; per line a
//!            height factor, a slow wander and edge roughness (seeded)
//! camera     bed mm → homography (scale, roll, tilt) → radial k1, k2 (vision::photo's
//!            PhotoCamera); each pixel mapped back (fixed-point inversion of the
//!            distortion, then the homography's inverse), 2 × 2 sub-pixels with box
//!            coverage of the signed distance to the nearest bead edge
//! habits     plate (black with bright specks, gold) with texture, filament colour, uneven
//!            light and vignetting, a specular spot, a stray string, PSF blur, noise, JPEG
//! ```
//!
//! The dataset holds what a lab would have (dataset.toml, print.gcode, photos.csv,
//! photos/); `truth/` (for evaluation stages only) holds `camera.toml` (per photo the
//! camera as `vision::photo::PhotoCamera` reads it), `widths.csv` (`line_index,
//! position_mm,width_mm`: every printed line of the G-code in the reader's order, every
//! 0.05 mm from its G-code start, 0 in a gap) and `print.toml` (τ, the pressure advance per
//! line, the habits).

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::Path;

use models::fdm::planner::plan;
use models::fdm::pressure_advance::{deposit_line, DepositSettings};
use models::fdm::printed_lines::{printed_lines, PrintedLine};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::gcode::{read_gcode, Firmware, StartSettings};
use super::{GCODE_FILE, KIND, PHOTOS_FILE, READABLE_VERSIONS};
use crate::error::DatasetError;
use crate::manifest::{DatasetManifest, Provenance, MANIFEST_FILE};
use crate::output::{write_file, OutputDir, Ownership};
use crate::stream;

/// Generator name recorded in the provenance.
pub const GENERATOR: &str = "amrepro-fdm-photos";
/// Spacing of the truth's positions along a line (mm).
pub const TRUTH_STEP_MM: f64 = 0.05;

/// Which folders the generator may replace.
pub const OUTPUT: Ownership = Ownership {
    kind: KIND,
    versions: READABLE_VERSIONS,
    writer: "datasets generate fdm-photos",
    written_by_us: |p| matches!(p, Provenance::Virtual { generator, .. } if generator == GENERATOR),
};

/// The plate's colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plate {
    /// Black textured PEI with bright specks.
    Black,
    /// Gold textured PEI.
    Gold,
}

/// The filament's colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filament {
    /// White.
    White,
    /// Grey.
    Grey,
}

/// The camera's habits; a strength of 0 switches one off, 1 is typical of a cheap
/// endoscope (the shared photos), a value in between scales it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Habits {
    /// Radial distortion: k1 = 0.13·s, k2 = −0.15·s, each ±20 % per photo.
    pub distortion: f64,
    /// Perspective: the camera tilted so the scale changes by up to ±10·s % across the pattern.
    pub perspective: f64,
    /// The plate.
    pub plate: Plate,
    /// Plate texture and specks (relative strength).
    pub texture: f64,
    /// The filament.
    pub filament: Filament,
    /// A light gradient of ±30·s % across the photo and 30·s % vignetting in the corners.
    pub uneven_light: f64,
    /// A coloured specular spot (an LED's reflection) of brightness 0.5·s.
    pub specular: f64,
    /// A stray string across the frame (drawn when > 0, its width 0.15·s mm).
    pub string: f64,
    /// Gaussian PSF standard deviation (px).
    pub blur_px: f64,
    /// Sensor noise standard deviation (of the 0..1 range).
    pub noise: f64,
    /// JPEG quality (1-100); `None` writes PNG.
    pub jpeg_quality: Option<u8>,
}

impl Habits {
    /// Every habit on at its typical strength: black plate, white filament, JPEG 85.
    pub fn all_on() -> Self {
        Self {
            distortion: 1.0,
            perspective: 1.0,
            plate: Plate::Black,
            texture: 1.0,
            filament: Filament::White,
            uneven_light: 1.0,
            specular: 1.0,
            string: 1.0,
            blur_px: 1.0,
            noise: 0.02,
            jpeg_quality: Some(85),
        }
    }

    /// No habit: an ideal camera looking straight down (black plate, white filament, PNG).
    pub fn none() -> Self {
        Self {
            distortion: 0.0,
            perspective: 0.0,
            plate: Plate::Black,
            texture: 0.0,
            filament: Filament::White,
            uneven_light: 0.0,
            specular: 0.0,
            string: 0.0,
            blur_px: 0.0,
            noise: 0.0,
            jpeg_quality: None,
        }
    }
}

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct GenerateConfig {
    /// Seed of every random stream.
    pub seed: u64,
    /// Test lines (the frame grows with them: 3 mm per line).
    pub lines: usize,
    /// Pressure advance of the first line (s).
    pub advance_start_s: f64,
    /// Pressure advance step from line to line (s).
    pub advance_step_s: f64,
    /// Klipper's smooth time (s).
    pub smooth_time_s: f64,
    /// The melt's first-order lag τ (s).
    pub tau_s: f64,
    /// A deposit below this fraction of the commanded width breaks the bead.
    pub gap_fraction: f64,
    /// Per line: relative sd of its height factor (its width scales by 1/factor).
    pub line_height_sd: f64,
    /// Relative sd of the slow width wander (5 mm correlation length).
    pub wander_sd: f64,
    /// Each edge's roughness (mm, 0.5 mm correlation length).
    pub edge_sd_mm: f64,
    /// Photos of the print.
    pub photos: usize,
    /// Image scale at the pattern's centre (px/mm).
    pub px_per_mm: f64,
    /// Image size (px): width, height.
    pub size_px: [usize; 2],
    /// The camera's habits.
    pub habits: Habits,
}

impl GenerateConfig {
    /// The shared pattern's layout (21 lines, PA 0 to 0.1 s by 0.005 s, smooth time 0.04 s),
    /// τ = 0.04 s, three 1080 × 1920 photos at 20 px/mm with every habit on.
    pub fn new(seed: u64) -> Self {
        Self {
            seed,
            lines: 21,
            advance_start_s: 0.0,
            advance_step_s: 0.005,
            smooth_time_s: 0.04,
            tau_s: 0.04,
            gap_fraction: 0.3,
            line_height_sd: 0.02,
            wander_sd: 0.01,
            edge_sd_mm: 0.003,
            photos: 3,
            px_per_mm: 20.0,
            size_px: [1080, 1920],
            habits: Habits::all_on(),
        }
    }

    fn check(&self) -> Result<(), String> {
        let ok = (1..=60).contains(&self.lines)
            && (1..=50).contains(&self.photos)
            && (0.001..=2.0).contains(&self.tau_s)
            && (0.0..=0.2).contains(&self.smooth_time_s)
            && self.advance_start_s >= 0.0
            && self.advance_step_s >= 0.0
            && self.advance_start_s + self.advance_step_s * (self.lines - 1) as f64 <= 2.0
            && (2.0..=200.0).contains(&self.px_per_mm)
            && self.size_px.iter().all(|s| (64..=8000).contains(s));
        if ok {
            Ok(())
        } else {
            Err(format!("expected 1-60 lines, 1-50 photos, τ in [0.001, 2] s, smooth time in [0, 0.2] s, pressure advance in [0, 2] s, 2-200 px/mm, 64-8000 px per side; got {self:?}"))
        }
    }
}

/// Generates into `out` (absent, empty or an earlier output of this generator),
/// atomically; returns the number of photos.
pub fn generate(config: &GenerateConfig, out: &Path) -> Result<usize, DatasetError> {
    let output = OutputDir::begin(out, &OUTPUT)?;
    let n = generate_into(config, output.path())?;
    output.commit()?;
    Ok(n)
}

/// [`generate`] into the empty folder `out_dir`.
pub fn generate_into(config: &GenerateConfig, out_dir: &Path) -> Result<usize, DatasetError> {
    let bad = |expected: String| DatasetError::Malformed { file: out_dir.to_path_buf(), location: None, expected };
    config.check().map_err(bad)?;
    let gcode = pattern_gcode(config);
    let lines = plan_pattern(config, &gcode, out_dir).map_err(bad)?;
    let beads: Vec<Bead> =
        lines.iter().map(|l| print_bead(config, l, &mut stream(config.seed, l.index as u64))).collect();
    let mut photos_csv = String::from("photo_id,image\n");
    let mut cameras = String::new();
    for k in 0..config.photos {
        let id = format!("p{}", k + 1);
        let mut rng = stream(config.seed, 1_000_000 + k as u64);
        let camera = draw_camera(config, &lines, &mut rng);
        let (bytes, ext) = photograph(config, &beads, &camera, &mut rng).map_err(bad)?;
        let image = format!("photos/{id}.{ext}");
        write_file(out_dir, &image, &bytes)?;
        writeln!(photos_csv, "{id},{image}").expect("string");
        cameras += &camera_toml(&id, &camera);
    }
    write_file(out_dir, GCODE_FILE, gcode.as_bytes())?;
    write_file(out_dir, PHOTOS_FILE, photos_csv.as_bytes())?;
    write_file(out_dir, "truth/camera.toml", cameras.as_bytes())?;
    write_file(out_dir, "truth/widths.csv", widths_csv(&beads).as_bytes())?;
    write_file(out_dir, "truth/print.toml", print_toml(config, &lines).as_bytes())?;
    write_file(out_dir, MANIFEST_FILE, manifest_toml(config).as_bytes())?;
    Ok(config.photos)
}

/// The printer the pattern is planned for (Klipper; all written to `[printer_settings]`).
pub fn start_settings(config: &GenerateConfig) -> StartSettings {
    StartSettings {
        firmware: Firmware::Klipper,
        accel_mm_s2: ACCEL_MM_S2,
        square_corner_velocity_mm_s: 5.0,
        minimum_cruise_ratio: 0.5,
        max_velocity_mm_s: 300.0,
        extruder_corner_mm_s: 1.0,
        jerk_mm_s: 10.0,
        jerk_z_mm_s: 0.3,
        pressure_advance_s: 0.0,
        smooth_time_s: config.smooth_time_s,
    }
}

const ACCEL_MM_S2: f64 = 2500.0;
const FILAMENT_MM: f64 = 1.75;
const NOZZLE_MM: f64 = 0.4;
/// Filament per mm of path (the shared pattern's 0.08: a bead of 0.96 mm at 0.2 mm layers).
const E_PER_MM: f64 = 0.08;
const LAYER_MM: f64 = 0.2;
const FRAME_WIDTH_MM: f64 = 40.0;
/// Segments of a test line: slow, fast, slow (mm).
const SEGMENTS_MM: [(f64, f64); 3] = [(3.88, 10.0), (23.28, 100.0), (11.64, 10.0)];

/// Our G-code of the pattern: the frame's outer and inner perimeter at 20 mm/s, then each
/// line after a lift, a travel and `SET_PRESSURE_ADVANCE`.
pub fn pattern_gcode(config: &GenerateConfig) -> String {
    let height = 3.0 * (config.lines as f64 - 1.0) + 12.0;
    let mut g = String::new();
    let _ = writeln!(g, "; amrepro virtual pressure-advance pattern: {} lines, seed {}", config.lines, config.seed);
    g += "G21 ; mm\nG90 ; absolute XYZ\nM83 ; relative E\n";
    let _ = writeln!(g, "SET_VELOCITY_LIMIT ACCEL={ACCEL_MM_S2}");
    let _ = writeln!(g, "SET_PRESSURE_ADVANCE ADVANCE=0 SMOOTH_TIME={}", config.smooth_time_s);
    let travel = |g: &mut String, x: f64, y: f64| {
        let _ = writeln!(g, "G1 Z{:.2} F900\nG1 X{x:.3} Y{y:.3} F9000\nG1 Z{LAYER_MM:.2} F900", LAYER_MM + 0.2);
    };
    for inset in [0.0, 0.4] {
        let (x0, y0, x1, y1) = (2.0 + inset, 2.0 + inset, 2.0 + FRAME_WIDTH_MM - inset, 2.0 + height - inset);
        travel(&mut g, x0, y0);
        for (x, y, len) in [(x1, y0, x1 - x0), (x1, y1, y1 - y0), (x0, y1, x1 - x0), (x0, y0, y1 - y0)] {
            let _ = writeln!(g, "G1 X{x:.3} Y{y:.3} E{:.5} F1200", E_PER_MM * len);
        }
    }
    for i in 0..config.lines {
        let y = 8.0 + 3.0 * i as f64;
        let mut x = 2.4;
        travel(&mut g, x, y);
        let k = config.advance_start_s + config.advance_step_s * i as f64;
        let _ = writeln!(g, "SET_PRESSURE_ADVANCE ADVANCE={k:.4}");
        for (len, speed) in SEGMENTS_MM {
            x += len;
            let _ = writeln!(g, "G1 X{x:.3} Y{y:.3} E{:.5} F{:.0}", E_PER_MM * len, speed * 60.0);
        }
    }
    g += "G1 Z10 F900\n";
    g
}

fn plan_pattern(config: &GenerateConfig, gcode: &str, dir: &Path) -> Result<Vec<PrintedLine>, String> {
    let start = start_settings(config);
    let program = read_gcode(&dir.join(GCODE_FILE), gcode, start).map_err(|e| format!("our own G-code: {e}"))?;
    let planned = plan(&program.moves).map_err(|e| format!("planning our own G-code: {e}"))?;
    Ok(printed_lines(&program.moves, &planned, FILAMENT_MM))
}

/// One printed bead: its axis and its half-widths every [`TRUTH_STEP_MM`].
#[derive(Debug, Clone)]
struct Bead {
    index: usize,
    start_mm: [f64; 2],
    direction: [f64; 2],
    length_mm: f64,
    /// Left and right half-widths (mm; 0 in a gap).
    left_mm: Vec<f64>,
    right_mm: Vec<f64>,
}

impl Bead {
    fn widths(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.left_mm.iter().zip(&self.right_mm).enumerate().map(|(j, (l, r))| (j as f64 * TRUTH_STEP_MM, l + r))
    }

    /// Half-widths at `s_mm` (linear between samples; the end's beyond).
    fn half_at(&self, s_mm: f64) -> (f64, f64) {
        let last = self.left_mm.len() - 1;
        let u = (s_mm / TRUTH_STEP_MM).clamp(0.0, last as f64);
        let i = (u.floor() as usize).min(last.saturating_sub(1));
        let j = (i + 1).min(last);
        let f = u - i as f64;
        if self.left_mm[i] + self.right_mm[i] == 0.0 || self.left_mm[j] + self.right_mm[j] == 0.0 {
            // a gap's edge: no material until both neighbours have it
            return (0.0, 0.0);
        }
        (
            self.left_mm[i] + f * (self.left_mm[j] - self.left_mm[i]),
            self.right_mm[i] + f * (self.right_mm[j] - self.right_mm[i]),
        )
    }
}

/// The printed bead of `line`: the pressure-advance physics, then per line a height
/// factor, a wander and edge roughness.
fn print_bead(config: &GenerateConfig, line: &PrintedLine, rng: &mut ChaCha8Rng) -> Bead {
    let settings = DepositSettings {
        smoothing_mm: NOZZLE_MM,
        gap_fraction: config.gap_fraction,
        step_mm: TRUTH_STEP_MM,
        ..DepositSettings::for_line(line, config.tau_s)
    };
    let deposit = deposit_line(line, &settings);
    let n = deposit.widths_mm.len();
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let height = 1.0 + config.line_height_sd * normal.sample(rng);
    let wander = ornstein_uhlenbeck(n, config.wander_sd, 5.0, rng);
    let (el, er) =
        (ornstein_uhlenbeck(n, config.edge_sd_mm, 0.5, rng), ornstein_uhlenbeck(n, config.edge_sd_mm, 0.5, rng));
    let (mut left_mm, mut right_mm) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for j in 0..n {
        let half = 0.5 * deposit.widths_mm[j] * (1.0 + wander[j]) / height;
        let (l, r) = (half + el[j], half + er[j]);
        let broken = deposit.gap[j] || l <= 0.0 || r <= 0.0;
        left_mm.push(if broken { 0.0 } else { l });
        right_mm.push(if broken { 0.0 } else { r });
    }
    Bead {
        index: line.index,
        start_mm: line.start_mm,
        direction: line.direction(),
        length_mm: line.length_mm(),
        left_mm,
        right_mm,
    }
}

/// `n` samples [`TRUTH_STEP_MM`] apart of a stationary Ornstein–Uhlenbeck process.
fn ornstein_uhlenbeck(n: usize, sd: f64, length_mm: f64, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let normal = Normal::new(0.0, 1.0).expect("unit normal");
    let rho = (-TRUTH_STEP_MM / length_mm).exp();
    let mut x = sd * normal.sample(rng);
    (0..n)
        .map(|_| {
            let now = x;
            x = rho * x + sd * (1.0 - rho * rho).sqrt() * normal.sample(rng);
            now
        })
        .collect()
}

/// A photo's camera as `vision::photo::PhotoCamera` holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthCamera {
    /// Row-major homography bed mm → undistorted px, h33 = 1.
    pub homography: [f64; 9],
    /// Radial coefficient of |d|².
    pub k1: f64,
    /// Radial coefficient of |d|⁴.
    pub k2: f64,
    /// Centre of distortion (px): the image centre.
    pub centre_px: [f64; 2],
    /// Normalising radius (px): the half-diagonal.
    pub radius_px: f64,
}

impl TruthCamera {
    /// Where the bed point appears (px).
    pub fn project(&self, [x, y]: [f64; 2]) -> [f64; 2] {
        let h = &self.homography;
        let w = h[6] * x + h[7] * y + h[8];
        let u = [(h[0] * x + h[1] * y + h[2]) / w, (h[3] * x + h[4] * y + h[5]) / w];
        let d = [(u[0] - self.centre_px[0]) / self.radius_px, (u[1] - self.centre_px[1]) / self.radius_px];
        let r2 = d[0] * d[0] + d[1] * d[1];
        let f = 1.0 + self.k1 * r2 + self.k2 * r2 * r2;
        [self.centre_px[0] + (u[0] - self.centre_px[0]) * f, self.centre_px[1] + (u[1] - self.centre_px[1]) * f]
    }

    /// The bed point seen at pixel `p`: the distortion inverted by fixed-point iteration,
    /// then the homography's inverse (`inverse`, row-major).
    fn unproject(&self, p: [f64; 2], inverse: &[f64; 9]) -> [f64; 2] {
        let c = self.centre_px;
        let mut u = p;
        for _ in 0..20 {
            let d = [(u[0] - c[0]) / self.radius_px, (u[1] - c[1]) / self.radius_px];
            let r2 = d[0] * d[0] + d[1] * d[1];
            let f = 1.0 + self.k1 * r2 + self.k2 * r2 * r2;
            let next = [c[0] + (p[0] - c[0]) / f, c[1] + (p[1] - c[1]) / f];
            let moved = (next[0] - u[0]).abs() + (next[1] - u[1]).abs();
            u = next;
            if moved < 1e-9 {
                break;
            }
        }
        let g = inverse;
        let w = g[6] * u[0] + g[7] * u[1] + g[8];
        [(g[0] * u[0] + g[1] * u[1] + g[2]) / w, (g[3] * u[0] + g[4] * u[1] + g[5]) / w]
    }
}

/// A camera over the pattern's centre: scale, a roll of up to ±3°, a tilt and the radial
/// terms as the habits ask; an unmirrored top view (image y runs against bed y).
fn draw_camera(config: &GenerateConfig, lines: &[PrintedLine], rng: &mut ChaCha8Rng) -> TruthCamera {
    let (lo, hi) = lines
        .iter()
        .flat_map(|l| [l.start_mm, l.end_mm])
        .fold(([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]), |(lo, hi), p| {
            ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
        });
    let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    let half_extent = 0.5 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let h = config.habits;
    let roll = rng.random_range(-3.0..3.0) * PI / 180.0;
    let s = config.px_per_mm * rng.random_range(0.97..1.03);
    // tilt: w = 1 + p·(x, y) changes by ±0.1·strength over the pattern's half extent
    let tilt_angle = rng.random_range(0.0..2.0 * PI);
    let p = 0.1 * h.perspective / half_extent;
    let (px, py) = (p * tilt_angle.cos(), p * tilt_angle.sin());
    let [w_px, h_px] = config.size_px.map(|v| v as f64);
    let image_centre = [w_px / 2.0 + rng.random_range(-10.0..10.0), h_px / 2.0 + rng.random_range(-10.0..10.0)];
    // u = image_centre + s·R·(x', −y') / (1 + px x' + py y'), x' = x − centre
    let (c, sn) = (roll.cos(), roll.sin());
    let a = [[s * c, s * sn], [s * sn, -s * c]];
    let m = [
        [a[0][0] + image_centre[0] * px, a[0][1] + image_centre[0] * py],
        [a[1][0] + image_centre[1] * px, a[1][1] + image_centre[1] * py],
    ];
    let t = [
        image_centre[0] - m[0][0] * centre[0] - m[0][1] * centre[1],
        image_centre[1] - m[1][0] * centre[0] - m[1][1] * centre[1],
    ];
    let w0 = 1.0 - px * centre[0] - py * centre[1];
    let homography =
        [m[0][0] / w0, m[0][1] / w0, t[0] / w0, m[1][0] / w0, m[1][1] / w0, t[1] / w0, px / w0, py / w0, 1.0];
    let k1 = 0.13 * h.distortion * rng.random_range(0.8..1.2);
    let k2 = -0.15 * h.distortion * rng.random_range(0.8..1.2);
    let centre_px = [w_px / 2.0, h_px / 2.0];
    TruthCamera { homography, k1, k2, centre_px, radius_px: centre_px[0].hypot(centre_px[1]) }
}

fn invert3(m: &[f64; 9]) -> [f64; 9] {
    let det =
        m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6]);
    let inv = [
        m[4] * m[8] - m[5] * m[7],
        m[2] * m[7] - m[1] * m[8],
        m[1] * m[5] - m[2] * m[4],
        m[5] * m[6] - m[3] * m[8],
        m[0] * m[8] - m[2] * m[6],
        m[2] * m[3] - m[0] * m[5],
        m[3] * m[7] - m[4] * m[6],
        m[1] * m[6] - m[0] * m[7],
        m[0] * m[4] - m[1] * m[3],
    ];
    inv.map(|v| v / det)
}

/// A stroke of material: a bead of the print or the stray string (straight pieces).
enum Stroke<'a> {
    Bead(&'a Bead),
    String { a: [f64; 2], b: [f64; 2], half_mm: f64 },
}

impl Stroke<'_> {
    /// Signed distance (mm) of `p` to the stroke's edge, positive inside.
    fn inside_mm(&self, p: [f64; 2]) -> f64 {
        match self {
            Stroke::Bead(b) => {
                let d = [p[0] - b.start_mm[0], p[1] - b.start_mm[1]];
                let s = d[0] * b.direction[0] + d[1] * b.direction[1];
                let t = -d[0] * b.direction[1] + d[1] * b.direction[0];
                let (l, r) = b.half_at(s);
                if l + r == 0.0 {
                    return -1.0;
                }
                let lateral = if t >= 0.0 { l - t } else { r + t };
                let beyond = if s < 0.0 {
                    -s
                } else if s > b.length_mm {
                    s - b.length_mm
                } else {
                    return lateral;
                };
                // a round end of the end's half-width
                0.5 * (l + r) - beyond.hypot(t)
            }
            Stroke::String { a, b, half_mm } => {
                let ab = [b[0] - a[0], b[1] - a[1]];
                let len2 = ab[0] * ab[0] + ab[1] * ab[1];
                let f = (((p[0] - a[0]) * ab[0] + (p[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0);
                half_mm - (p[0] - a[0] - f * ab[0]).hypot(p[1] - a[1] - f * ab[1])
            }
        }
    }

    fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let (a, b, reach) = match self {
            Stroke::Bead(b) => {
                let end = [b.start_mm[0] + b.direction[0] * b.length_mm, b.start_mm[1] + b.direction[1] * b.length_mm];
                let widest = b.left_mm.iter().chain(&b.right_mm).copied().fold(0.0, f64::max);
                (b.start_mm, end, widest + 0.2)
            }
            Stroke::String { a, b, half_mm } => (*a, *b, half_mm + 0.2),
        };
        ([a[0].min(b[0]) - reach, a[1].min(b[1]) - reach], [a[0].max(b[0]) + reach, a[1].max(b[1]) + reach])
    }
}

/// Strokes by 1 mm bed cell.
struct Buckets<'a> {
    strokes: Vec<Stroke<'a>>,
    origin: [f64; 2],
    cols: usize,
    rows: usize,
    cells: Vec<Vec<u32>>,
}

impl<'a> Buckets<'a> {
    fn new(strokes: Vec<Stroke<'a>>) -> Self {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for s in &strokes {
            let (a, b) = s.bounds();
            lo = [lo[0].min(a[0]), lo[1].min(a[1])];
            hi = [hi[0].max(b[0]), hi[1].max(b[1])];
        }
        let (cols, rows) = ((hi[0] - lo[0]).ceil() as usize + 1, (hi[1] - lo[1]).ceil() as usize + 1);
        let mut cells = vec![Vec::new(); cols * rows];
        for (k, s) in strokes.iter().enumerate() {
            let (a, b) = s.bounds();
            for j in (a[1] - lo[1]).floor() as usize..=((b[1] - lo[1]).floor() as usize).min(rows - 1) {
                for i in (a[0] - lo[0]).floor() as usize..=((b[0] - lo[0]).floor() as usize).min(cols - 1) {
                    cells[j * cols + i].push(k as u32);
                }
            }
        }
        Self { strokes, origin: lo, cols, rows, cells }
    }

    /// The largest signed distance to an edge over the strokes near `p` (mm), and whether
    /// the stroke is the string.
    fn inside_mm(&self, p: [f64; 2]) -> f64 {
        let (i, j) = ((p[0] - self.origin[0]).floor(), (p[1] - self.origin[1]).floor());
        if i < 0.0 || j < 0.0 || i as usize >= self.cols || j as usize >= self.rows {
            return -1.0;
        }
        self.cells[j as usize * self.cols + i as usize]
            .iter()
            .map(|&k| self.strokes[k as usize].inside_mm(p))
            .fold(-1.0, f64::max)
    }
}

/// Renders one photo: bytes and file extension.
fn photograph(
    config: &GenerateConfig,
    beads: &[Bead],
    camera: &TruthCamera,
    rng: &mut ChaCha8Rng,
) -> Result<(Vec<u8>, &'static str), String> {
    let h = config.habits;
    let mut strokes: Vec<Stroke> = beads.iter().map(Stroke::Bead).collect();
    if h.string > 0.0 {
        strokes.extend(stray_string(beads, 0.075 * h.string, rng));
    }
    let buckets = Buckets::new(strokes);
    let inverse = invert3(&camera.homography);
    let [width, height] = config.size_px;
    let plate = PlateLook::new(h, rng);
    let filament = match h.filament {
        Filament::White => [0.9, 0.9, 0.88],
        Filament::Grey => [0.5, 0.5, 0.52],
    };
    let mut pixels = vec![[0f32; 3]; width * height];
    pixels.par_chunks_mut(width).enumerate().for_each(|(j, row)| {
        for (i, px) in row.iter_mut().enumerate() {
            let mut sum = [0.0; 3];
            for (di, dj) in [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)] {
                let p = [i as f64 + di, j as f64 + dj];
                let bed = camera.unproject(p, &inverse);
                // box coverage of a sub-pixel half a pixel wide across a straight edge
                let scale = config.px_per_mm;
                let cover = (0.5 + buckets.inside_mm(bed) * scale / 0.5).clamp(0.0, 1.0);
                let under = plate.colour(bed);
                for c in 0..3 {
                    sum[c] += cover * filament[c] + (1.0 - cover) * under[c];
                }
            }
            *px = sum.map(|v| (v / 4.0) as f32);
        }
    });
    let pixels = blur(&pixels, width, height, h.blur_px);
    let light = Lighting::new(h, config.size_px, rng);
    let noise = Normal::new(0.0, h.noise.max(1e-12)).expect("noise sd");
    let mut bytes = vec![0u8; width * height * 3];
    for (k, px) in pixels.iter().enumerate() {
        let (i, j) = ((k % width) as f64 + 0.5, (k / width) as f64 + 0.5);
        let (gain, spot) = light.at([i, j]);
        for c in 0..3 {
            let v = px[c] as f64 * gain + spot[c] + if h.noise > 0.0 { noise.sample(rng) } else { 0.0 };
            bytes[3 * k + c] = (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        }
    }
    encode(bytes, width, height, h.jpeg_quality)
}

fn encode(bytes: Vec<u8>, width: usize, height: usize, quality: Option<u8>) -> Result<(Vec<u8>, &'static str), String> {
    let img = image::RgbImage::from_raw(width as u32, height as u32, bytes).ok_or("image buffer")?;
    let mut out = Vec::new();
    match quality {
        Some(q) => {
            let encoder = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, q.clamp(1, 100));
            img.write_with_encoder(encoder).map_err(|e| e.to_string())?;
            Ok((out, "jpg"))
        }
        None => {
            img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png).map_err(|e| e.to_string())?;
            Ok((out, "png"))
        }
    }
}

/// A string of filament across the frame's corner: from outside the frame into the plate
/// between the frame and the first line, as a few straight pieces of a gentle curve.
fn stray_string<'a>(beads: &[Bead], half_mm: f64, rng: &mut ChaCha8Rng) -> Vec<Stroke<'a>> {
    let frame = &beads[0];
    let corner = [frame.start_mm[0] + frame.direction[0] * frame.length_mm, frame.start_mm[1]];
    let a = [corner[0] + rng.random_range(4.0..8.0), corner[1] - rng.random_range(2.0..5.0)];
    let b = [corner[0] - rng.random_range(6.0..12.0), corner[1] + rng.random_range(2.5..3.5)];
    let bend = rng.random_range(-1.5..1.5);
    let point = |f: f64| {
        let n = [-(b[1] - a[1]), b[0] - a[0]];
        let l = n[0].hypot(n[1]);
        let o = bend * 4.0 * f * (1.0 - f);
        [a[0] + f * (b[0] - a[0]) + o * n[0] / l, a[1] + f * (b[1] - a[1]) + o * n[1] / l]
    };
    (0..12).map(|k| Stroke::String { a: point(k as f64 / 12.0), b: point((k + 1) as f64 / 12.0), half_mm }).collect()
}

/// The plate's colour at a bed point: base, a smooth texture and bright specks.
struct PlateLook {
    base: [f64; 3],
    texture: f64,
    specks: f64,
    salt: u64,
}

impl PlateLook {
    fn new(h: Habits, rng: &mut ChaCha8Rng) -> Self {
        let (base, specks) = match h.plate {
            Plate::Black => ([0.09, 0.09, 0.1], 0.5 * h.texture),
            Plate::Gold => ([0.62, 0.46, 0.2], 0.0),
        };
        Self { base, texture: 0.05 * h.texture, specks, salt: rng.random() }
    }

    fn colour(&self, p: [f64; 2]) -> [f64; 3] {
        if self.texture == 0.0 {
            return self.base;
        }
        let t = self.texture * (value_noise(p, 0.35, self.salt) + 0.6 * value_noise(p, 1.3, self.salt ^ 0x9e37));
        let mut speck = 0.0;
        if self.specks > 0.0 {
            // one candidate speck per 0.4 mm cell, present in 8 % of cells
            let cell = [(p[0] / 0.4).floor(), (p[1] / 0.4).floor()];
            let r = hash(cell[0] as i64, cell[1] as i64, self.salt ^ 0x5bd1);
            if r < 0.08 {
                let centre = [(cell[0] + 0.2 + 0.6 * hash(1, cell[0] as i64, self.salt)) * 0.4, (cell[1] + 0.5) * 0.4];
                let d = (p[0] - centre[0]).hypot(p[1] - centre[1]);
                speck = self.specks * (-(d * d) / (2.0 * 0.03f64.powi(2))).exp();
            }
        }
        self.base.map(|b| b * (1.0 + 4.0 * t) + t * 0.3 + speck)
    }
}

/// Smooth value noise in [−1, 1] with a cell of `cell_mm`.
fn value_noise(p: [f64; 2], cell_mm: f64, salt: u64) -> f64 {
    let (x, y) = (p[0] / cell_mm, p[1] / cell_mm);
    let (i, j) = (x.floor(), y.floor());
    let (fx, fy) = (x - i, y - j);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let v = |a: f64, b: f64| 2.0 * hash(a as i64, b as i64, salt) - 1.0;
    let top = v(i, j) + sx * (v(i + 1.0, j) - v(i, j));
    let bottom = v(i, j + 1.0) + sx * (v(i + 1.0, j + 1.0) - v(i, j + 1.0));
    top + sy * (bottom - top)
}

/// A hash of a lattice point in [0, 1).
fn hash(i: i64, j: i64, salt: u64) -> f64 {
    let mut h = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F) ^ salt;
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^= h >> 33;
    h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Uneven light, vignetting and a specular spot over the image.
struct Lighting {
    gradient: [f64; 2],
    vignetting: f64,
    centre: [f64; 2],
    radius: f64,
    spot: [f64; 3],
    spot_centre: [f64; 2],
    spot_radius: f64,
}

impl Lighting {
    fn new(h: Habits, size: [usize; 2], rng: &mut ChaCha8Rng) -> Self {
        let [w, hh] = size.map(|v| v as f64);
        let angle = rng.random_range(0.0..2.0 * PI);
        let g = 0.3 * h.uneven_light;
        let strength = 0.5 * h.specular;
        Self {
            gradient: [g * angle.cos(), g * angle.sin()],
            vignetting: 0.3 * h.uneven_light,
            centre: [w / 2.0, hh / 2.0],
            radius: (w / 2.0).hypot(hh / 2.0),
            spot: [strength, 0.25 * strength, 0.2 * strength],
            spot_centre: [rng.random_range(0.3..0.7) * w, rng.random_range(0.3..0.7) * hh],
            spot_radius: 0.04 * w.min(hh),
        }
    }

    /// Multiplicative gain and additive spot at pixel `p`.
    fn at(&self, p: [f64; 2]) -> (f64, [f64; 3]) {
        let d = [(p[0] - self.centre[0]) / self.radius, (p[1] - self.centre[1]) / self.radius];
        let gain = (1.0 + self.gradient[0] * d[0] + self.gradient[1] * d[1])
            * (1.0 - self.vignetting * (d[0] * d[0] + d[1] * d[1]));
        let r2 =
            ((p[0] - self.spot_centre[0]).powi(2) + (p[1] - self.spot_centre[1]).powi(2)) / self.spot_radius.powi(2);
        let spot = (-0.5 * r2).exp();
        (gain, self.spot.map(|s| s * spot))
    }
}

/// Separable Gaussian blur of `sigma_px` (none at 0), edges clamped.
fn blur(pixels: &[[f32; 3]], width: usize, height: usize, sigma_px: f64) -> Vec<[f32; 3]> {
    if sigma_px <= 0.0 {
        return pixels.to_vec();
    }
    let r = (3.0 * sigma_px).ceil() as isize;
    let kernel: Vec<f32> = (-r..=r).map(|k| (-(k * k) as f64 / (2.0 * sigma_px * sigma_px)).exp() as f32).collect();
    let total: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / total).collect();
    let pass = |src: &[[f32; 3]], horizontal: bool| -> Vec<[f32; 3]> {
        let mut out = vec![[0f32; 3]; width * height];
        out.par_chunks_mut(width).enumerate().for_each(|(j, row)| {
            for (i, px) in row.iter_mut().enumerate() {
                let mut acc = [0f32; 3];
                for (k, w) in kernel.iter().enumerate() {
                    let o = k as isize - r;
                    let (ii, jj) = if horizontal {
                        ((i as isize + o).clamp(0, width as isize - 1) as usize, j)
                    } else {
                        (i, (j as isize + o).clamp(0, height as isize - 1) as usize)
                    };
                    let v = src[jj * width + ii];
                    for c in 0..3 {
                        acc[c] += w * v[c];
                    }
                }
                *px = acc;
            }
        });
        out
    };
    pass(&pass(pixels, true), false)
}

fn camera_toml(id: &str, c: &TruthCamera) -> String {
    let list = |v: &[f64]| v.iter().map(|x| format!("{x:e}")).collect::<Vec<_>>().join(", ");
    format!(
        "[{id}]\nhomography = [{}]\nk1 = {:e}\nk2 = {:e}\ncentre_px = [{}]\nradius_px = {:e}\n\n",
        list(&c.homography),
        c.k1,
        c.k2,
        list(&c.centre_px),
        c.radius_px
    )
}

fn widths_csv(beads: &[Bead]) -> String {
    let mut text = String::from("line_index,position_mm,width_mm\n");
    for b in beads {
        for (x, w) in b.widths() {
            let _ = writeln!(text, "{},{x:.2},{w:.6}", b.index);
        }
    }
    text
}

fn print_toml(config: &GenerateConfig, lines: &[PrintedLine]) -> String {
    let h = config.habits;
    let advances: Vec<String> = lines.iter().map(|l| format!("{}", l.pressure_advance.advance_s)).collect();
    format!(
        "tau_s = {}\nsmooth_time_s = {}\ngap_fraction = {}\nline_height_sd = {}\nwander_sd = {}\nedge_sd_mm = {}\n\
         # per printed line (reader's order): the pressure advance in force (s)\npressure_advance_s = [{}]\n\n\
         [habits]\ndistortion = {}\nperspective = {}\nplate = \"{:?}\"\ntexture = {}\nfilament = \"{:?}\"\n\
         uneven_light = {}\nspecular = {}\nstring = {}\nblur_px = {}\nnoise = {}\njpeg_quality = {}\npx_per_mm = {}\n",
        config.tau_s,
        config.smooth_time_s,
        config.gap_fraction,
        config.line_height_sd,
        config.wander_sd,
        config.edge_sd_mm,
        advances.join(", "),
        h.distortion,
        h.perspective,
        h.plate,
        h.texture,
        h.filament,
        h.uneven_light,
        h.specular,
        h.string,
        h.blur_px,
        h.noise,
        h.jpeg_quality.map_or(0, i64::from),
        config.px_per_mm,
    )
}

fn manifest_toml(config: &GenerateConfig) -> String {
    let effects = BTreeMap::from([("tau_s".to_string(), config.tau_s)]);
    let manifest = DatasetManifest {
        kind: KIND.into(),
        format_version: super::FORMAT_VERSION,
        printer: "virtual-klipper".into(),
        description: format!(
            "Virtual pressure-advance pattern: {} slow-fast-slow lines in a frame, τ = {} s, {} photo(s) at about {} px/mm.",
            config.lines, config.tau_s, config.photos, config.px_per_mm
        ),
        units: BTreeMap::from([("length".to_string(), "mm".to_string()), ("time".to_string(), "s".to_string())]),
        provenance: Provenance::Virtual {
            generator: GENERATOR.into(),
            version: env!("CARGO_PKG_VERSION").into(),
            seed: config.seed,
            effects,
        },
    };
    let s = start_settings(config);
    format!(
        "{}\n[printer_settings]\nfirmware = \"klipper\"\nfilament_diameter_mm = {FILAMENT_MM}\nnozzle_diameter_mm = {NOZZLE_MM}\n\
         accel_mm_s2 = {}\nsquare_corner_velocity_mm_s = {}\nminimum_cruise_ratio = {}\nmax_velocity_mm_s = {}\n\
         pressure_advance_s = 0.0\nsmooth_time_s = {}\n",
        manifest.to_toml(),
        s.accel_mm_s2,
        s.square_corner_velocity_mm_s,
        s.minimum_cruise_ratio,
        s.max_velocity_mm_s,
        s.smooth_time_s
    )
}

/// The truth of a virtual `fdm-photos` dataset, as evaluation reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct PhotosTruth {
    /// Per photo id its camera.
    pub cameras: BTreeMap<String, TruthCamera>,
    /// Per printed line index: (position mm, true width mm; 0 in a gap).
    pub widths: BTreeMap<usize, Vec<(f64, f64)>>,
    /// τ (s).
    pub tau_s: f64,
}

/// Reads `truth/` of a dataset this generator wrote.
pub fn read_truth(dir: &Path) -> Result<PhotosTruth, DatasetError> {
    let cameras_file = dir.join("truth/camera.toml");
    let table: toml::Table = crate::text::read_toml(&cameras_file)?;
    let bad = |file: &Path, what: String| DatasetError::Malformed {
        file: file.to_path_buf(),
        location: None,
        expected: what,
    };
    let numbers = |v: Option<&toml::Value>| -> Option<Vec<f64>> {
        v?.as_array()?.iter().map(|x| x.as_float().or_else(|| x.as_integer().map(|i| i as f64))).collect()
    };
    let mut cameras = BTreeMap::new();
    for (id, value) in &table {
        let t = value.as_table().ok_or_else(|| bad(&cameras_file, format!("expected a table [{id}]")))?;
        let h = numbers(t.get("homography")).filter(|h| h.len() == 9);
        let c = numbers(t.get("centre_px")).filter(|c| c.len() == 2);
        let f = |k: &str| t.get(k).and_then(|v| v.as_float());
        let (Some(h), Some(c), Some(k1), Some(k2), Some(r)) = (h, c, f("k1"), f("k2"), f("radius_px")) else {
            return Err(bad(&cameras_file, format!("expected homography, k1, k2, centre_px, radius_px in [{id}]")));
        };
        let homography: [f64; 9] = h.try_into().expect("nine");
        cameras.insert(id.clone(), TruthCamera { homography, k1, k2, centre_px: [c[0], c[1]], radius_px: r });
    }
    let widths_file = dir.join("truth/widths.csv");
    let csv = crate::csv_table::CsvTable::read(&widths_file)?;
    let (li, xi, wi) = (csv.column("line_index")?, csv.column("position_mm")?, csv.column("width_mm")?);
    let mut widths: BTreeMap<usize, Vec<(f64, f64)>> = BTreeMap::new();
    for row in &csv.rows {
        let line = csv.number(row, li)? as usize;
        widths.entry(line).or_default().push((csv.number(row, xi)?, csv.number(row, wi)?));
    }
    let print: toml::Table = crate::text::read_toml(&dir.join("truth/print.toml"))?;
    let tau_s = print.get("tau_s").and_then(|v| v.as_float()).unwrap_or(f64::NAN);
    Ok(PhotosTruth { cameras, widths, tau_s })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fdm_photos::FdmPhotos;

    fn small() -> GenerateConfig {
        GenerateConfig {
            lines: 4,
            advance_step_s: 0.03,
            photos: 1,
            px_per_mm: 8.0,
            size_px: [400, 400],
            ..GenerateConfig::new(5)
        }
    }

    #[test]
    fn the_dataset_reads_back_with_its_lines_and_truth() {
        let tmp = tempfile::tempdir().unwrap();
        let out = tmp.path().join("pa");
        generate(&small(), &out).unwrap();
        let data = FdmPhotos::read(&out).unwrap();
        // 8 frame edges and 4 test lines of three moves each
        assert_eq!(data.lines.len(), 12);
        assert!(data.assumed.is_empty(), "{:?}", data.assumed);
        let advances: Vec<f64> = data.lines[8..].iter().map(|l| l.pressure_advance.advance_s).collect();
        assert_eq!(advances, [0.0, 0.03, 0.06, 0.09]);
        assert!(data.lines[8..].iter().all(|l| l.moves.len() == 3));
        let truth = read_truth(&out).unwrap();
        assert_eq!(truth.widths.len(), 12);
        assert_eq!(truth.cameras.len(), 1);
        // an advance beyond τ = 0.04 s breaks the bead after the fast segment; none below it
        // (past the first half millimetre, where a lagging melt starts from rest)
        let gaps = |i: usize| truth.widths[&i].iter().filter(|(x, w)| *x > 0.5 && *w == 0.0).count();
        assert_eq!(gaps(8), 0);
        assert!(gaps(11) > 5, "{}", gaps(11));
        // and the same seed writes the same bytes
        let again = tmp.path().join("again");
        generate(&small(), &again).unwrap();
        for f in ["print.gcode", "photos/p1.jpg", "truth/widths.csv", "truth/camera.toml", "dataset.toml"] {
            assert_eq!(std::fs::read(out.join(f)).unwrap(), std::fs::read(again.join(f)).unwrap(), "{f}");
        }
    }

    #[test]
    fn the_camera_unprojects_what_it_projects() {
        let config = GenerateConfig::new(3);
        let lines = plan_pattern(&config, &pattern_gcode(&config), Path::new("x")).unwrap();
        let cam = draw_camera(&config, &lines, &mut stream(3, 9));
        let inverse = invert3(&cam.homography);
        for p in [[2.0, 2.0], [42.0, 74.0], [20.0, 40.0]] {
            let back = cam.unproject(cam.project(p), &inverse);
            assert!((back[0] - p[0]).abs() < 1e-6 && (back[1] - p[1]).abs() < 1e-6, "{p:?} {back:?}");
        }
        // the pattern lies in the photo at about 20 px/mm
        let (a, b) = (cam.project([2.0, 2.0]), cam.project([42.0, 74.0]));
        assert!([a, b].iter().all(|q| q[0] > 0.0 && q[0] < 1080.0 && q[1] > 0.0 && q[1] < 1920.0), "{a:?} {b:?}");
    }
}
