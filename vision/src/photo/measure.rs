//! Widths of every printed path in a placed photo, measured across the path's G-code axis
//! in bed millimetres (step 5 of [`super`]).
//!
//! At each position s = k·step along a path the contrast is sampled across the axis every
//! half pixel, each sample averaged over a band of ±step/2 along the path, and fitted by
//! the blurred-bar edge model of [`crate::lines::model`] (sub-pixel edges); the plain
//! baseline beside it is the width of the run of samples above half contrast (0.5: the
//! contrast reads 0 on plate and 1 on print) around the axis, interpolated at its ends.
//!
//! A position is measured only where the path is a single bead: the window stops short of
//! other paths' material (each taken as [`SPREAD`] × its commanded width, the beads of a
//! real print run wider than the commanded flow gives), and a position whose own bead
//! would touch it — a frame the line runs into, a second pass beside it — is skipped with
//! the path it touches. Where the window holds less than a quarter of the commanded width
//! of material, the bead is broken: a gap, width 0, not a narrow bead fitted to specks.

use rayon::prelude::*;

use super::camera::PhotoCamera;
use super::raster::distance_to_segment;
use super::PrintedPath;
use crate::lines::fit::{fit_edges, with_linear_parameters, Profile};
use crate::lines::model::EdgeParams;
use crate::lines::profile::bilinear;
use crate::lines::GrayImage;

/// A bead's half-width is taken as this many times half its commanded width when deciding
/// what another path's material reaches (the shared print's beads run 1.35 × wider).
pub const SPREAD: f64 = 1.5;
/// Plate kept beyond a bead's expected edge for the fit (mm).
const MIN_MARGIN_MM: f64 = 0.3;
/// The window's half-width: this many commanded widths, at least the bead and 0.5 mm.
const WINDOW_WIDTHS: f64 = 1.5;
/// Lateral sample spacing (px of the photo).
const SAMPLE_PX: f64 = 0.5;
/// Samples averaged along the path per lateral sample.
const BAND_SAMPLES: usize = 3;
/// Less material than this fraction of the commanded width in the window is a gap.
const GAP_FRACTION: f64 = 0.25;
/// The fitted bar's contrast must lie in this range (the contrast reads 1 on print).
const CONTRAST_RANGE: (f64, f64) = (0.35, 3.0);

/// One measured position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WidthSample {
    /// Position along the path from its G-code start (mm).
    pub position_mm: f64,
    /// Edge-fit width (mm); 0 in a gap.
    pub width_mm: f64,
    /// The left edge's distance to the left of the G-code axis (mm); NaN in a gap.
    pub left_mm: f64,
    /// The right edge's distance to the right of the G-code axis (mm); NaN in a gap.
    pub right_mm: f64,
    /// The half-contrast baseline's width (mm); 0 in a gap.
    pub threshold_width_mm: f64,
}

/// Why a position was not measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Skip {
    /// Another path's material lies within the bead's reach (path index).
    Touches(usize),
    /// The window leaves the photo.
    OutsidePhoto,
    /// The edge model did not converge to a bar of print contrast.
    NoFit,
}

impl Skip {
    /// A short reason in words.
    pub fn reason(&self) -> String {
        match self {
            Skip::Touches(j) => format!("touches line {j}"),
            Skip::OutsidePhoto => "outside the photo".into(),
            Skip::NoFit => "no edge fit".into(),
        }
    }
}

/// One path's measurement.
#[derive(Debug, Clone, PartialEq)]
pub struct PathMeasurement {
    /// Measured positions, in order.
    pub samples: Vec<WidthSample>,
    /// Skipped positions and why.
    pub skipped: Vec<(f64, Skip)>,
    /// The path's G-code start and end in the photo (px); `None` behind the camera.
    pub start_px: Option<[f64; 2]>,
    /// See `start_px`.
    pub end_px: Option<[f64; 2]>,
}

/// The reprojection error of a placed photo: the RMS over measured bead positions of the
/// bead's centre ((left − right)/2 from the G-code axis, mm), and the number of positions
/// (NaN and 0 without any).
pub fn reprojection_error(paths: &[PathMeasurement]) -> (f64, usize) {
    let offsets: Vec<f64> = paths
        .iter()
        .flat_map(|p| &p.samples)
        .filter(|s| s.width_mm > 0.0)
        .map(|s| (s.left_mm - s.right_mm) / 2.0)
        .collect();
    if offsets.is_empty() {
        return (f64::NAN, 0);
    }
    ((offsets.iter().map(|o| o * o).sum::<f64>() / offsets.len() as f64).sqrt(), offsets.len())
}

/// Measures every path, in parallel over paths (each path's result does not depend on
/// the thread count).
pub fn measure_paths(
    contrast: &GrayImage,
    paths: &[PrintedPath],
    camera: &PhotoCamera,
    step_mm: f64,
) -> Vec<PathMeasurement> {
    (0..paths.len()).into_par_iter().map(|i| measure_path(contrast, paths, i, camera, step_mm)).collect()
}

/// Measures path `index` every `step_mm` from its start.
pub fn measure_path(
    contrast: &GrayImage,
    paths: &[PrintedPath],
    index: usize,
    camera: &PhotoCamera,
    step_mm: f64,
) -> PathMeasurement {
    let path = &paths[index];
    let neighbours = neighbours(paths, index);
    let count = (path.length_mm() / step_mm).floor() as usize + 1;
    let mut out = PathMeasurement {
        samples: Vec::new(),
        skipped: Vec::new(),
        start_px: camera.project(path.start_mm),
        end_px: camera.project(path.end_mm),
    };
    let mut buffers = Buffers::default();
    for k in 0..count {
        let s_mm = ((k as f64 * step_mm) * 1e9).round() / 1e9;
        match measure_position(contrast, paths, path, &neighbours, camera, s_mm, step_mm, &mut buffers) {
            Ok(sample) => out.samples.push(sample),
            Err(skip) => out.skipped.push((s_mm, skip)),
        }
    }
    out
}

/// Paths whose material could come within a window of this one.
fn neighbours(paths: &[PrintedPath], index: usize) -> Vec<usize> {
    let path = &paths[index];
    let reach = window_half_mm(path) + paths.iter().map(|p| SPREAD * p.width_mm / 2.0).fold(0.0, f64::max);
    (0..paths.len()).filter(|&j| j != index).filter(|&j| segment_distance(path, &paths[j]) <= reach).collect()
}

fn segment_distance(a: &PrintedPath, b: &PrintedPath) -> f64 {
    let d1 =
        distance_to_segment(a.start_mm, b.start_mm, b.end_mm).min(distance_to_segment(a.end_mm, b.start_mm, b.end_mm));
    let d2 =
        distance_to_segment(b.start_mm, a.start_mm, a.end_mm).min(distance_to_segment(b.end_mm, a.start_mm, a.end_mm));
    // segments that cross have distance 0; the endpoint distances bound it otherwise
    if crosses(a, b) {
        0.0
    } else {
        d1.min(d2)
    }
}

fn crosses(a: &PrintedPath, b: &PrintedPath) -> bool {
    let side = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]);
    let (d1, d2) = (side(a.start_mm, a.end_mm, b.start_mm), side(a.start_mm, a.end_mm, b.end_mm));
    let (d3, d4) = (side(b.start_mm, b.end_mm, a.start_mm), side(b.start_mm, b.end_mm, a.end_mm));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

fn window_half_mm(path: &PrintedPath) -> f64 {
    (WINDOW_WIDTHS * path.width_mm).max(SPREAD * path.width_mm / 2.0 + 0.5)
}

#[derive(Default)]
struct Buffers {
    values: Vec<f64>,
}

#[allow(clippy::too_many_arguments)]
fn measure_position(
    contrast: &GrayImage,
    paths: &[PrintedPath],
    path: &PrintedPath,
    neighbours: &[usize],
    camera: &PhotoCamera,
    s_mm: f64,
    step_mm: f64,
    buffers: &mut Buffers,
) -> Result<WidthSample, Skip> {
    let own_half = SPREAD * path.width_mm / 2.0;
    let (t_lo, t_hi) = clear_window(paths, path, neighbours, s_mm, own_half)?;
    let normal = {
        let d = path.direction();
        [-d[1], d[0]]
    };
    let axis = path.axis();
    let scale = camera.scale_along(axis.point(s_mm, 0.0), normal).ok_or(Skip::OutsidePhoto)?;
    let dt_mm = SAMPLE_PX / scale;
    let n = ((t_hi - t_lo) / dt_mm).floor() as usize + 1;
    let values = &mut buffers.values;
    values.clear();
    for j in 0..n {
        let t = t_lo + j as f64 * dt_mm;
        let mut sum = 0.0;
        for b in 0..BAND_SAMPLES {
            let ds = (b as f64 / (BAND_SAMPLES - 1) as f64 - 0.5) * step_mm;
            let p = camera.project(axis.point(s_mm + ds, t)).ok_or(Skip::OutsidePhoto)?;
            sum += bilinear(contrast, p[0], p[1]).ok_or(Skip::OutsidePhoto)?;
        }
        values.push(sum / BAND_SAMPLES as f64);
    }
    let material_mm: f64 = (0..n)
        .filter(|&j| (t_lo + j as f64 * dt_mm).abs() <= own_half)
        .map(|j| values[j].clamp(0.0, 1.0) * dt_mm)
        .sum();
    if material_mm < GAP_FRACTION * path.width_mm {
        return Ok(WidthSample {
            position_mm: s_mm,
            width_mm: 0.0,
            left_mm: f64::NAN,
            right_mm: f64::NAN,
            threshold_width_mm: 0.0,
        });
    }
    let threshold = half_contrast_run(values, t_lo, dt_mm);
    let (lo, hi) = threshold.unwrap_or((-path.width_mm / 2.0, path.width_mm / 2.0));
    // the fit runs in photo pixels across the path (t_px = t_mm · scale)
    let profile = Profile { t0_px: t_lo * scale, dt_px: SAMPLE_PX, values };
    let init = EdgeParams { b0: 0.0, b1: 0.0, contrast: 1.0, left_px: lo * scale, right_px: hi * scale, sigma_px: 1.0 };
    let fit = fit_edges(profile, with_linear_parameters(profile, init)).ok_or(Skip::NoFit)?;
    let p = fit.params;
    let inside = p.left_px > t_lo * scale && p.right_px < t_hi * scale;
    if !inside || p.contrast < CONTRAST_RANGE.0 || p.contrast > CONTRAST_RANGE.1 {
        return Err(Skip::NoFit);
    }
    Ok(WidthSample {
        position_mm: s_mm,
        width_mm: (p.right_px - p.left_px) / scale,
        left_mm: p.right_px / scale,
        right_mm: -p.left_px / scale,
        threshold_width_mm: threshold.map_or(0.0, |(lo, hi)| hi - lo),
    })
}

/// The lateral window [t_lo, t_hi] (mm, positive to the path's left) clear of other
/// paths' material; a skip if that material lies within the own bead's reach.
fn clear_window(
    paths: &[PrintedPath],
    path: &PrintedPath,
    neighbours: &[usize],
    s_mm: f64,
    own_half: f64,
) -> Result<(f64, f64), Skip> {
    let half = window_half_mm(path);
    let (mut t_lo, mut t_hi) = (-half, half);
    let needed = own_half + MIN_MARGIN_MM;
    let axis = path.axis();
    for &j in neighbours {
        let other = &paths[j];
        let reach = SPREAD * other.width_mm / 2.0;
        let centre = distance_to_segment(axis.point(s_mm, 0.0), other.start_mm, other.end_mm);
        if centre <= reach + needed {
            return Err(Skip::Touches(j));
        }
        // walk out from the axis on each side to where the other's material begins
        for side in [-1.0, 1.0] {
            let limit = if side < 0.0 { -t_lo } else { t_hi };
            let mut t = needed;
            while t < limit {
                if distance_to_segment(axis.point(s_mm, side * t), other.start_mm, other.end_mm) <= reach {
                    if side < 0.0 {
                        t_lo = -t
                    } else {
                        t_hi = t
                    }
                    break;
                }
                t += 0.05;
            }
        }
    }
    Ok((t_lo, t_hi))
}

/// The run of samples at or above half contrast that contains the one nearest the axis
/// at or above it, its ends interpolated linearly (mm); `None` if no sample reaches 0.5.
fn half_contrast_run(values: &[f64], t_lo: f64, dt_mm: f64) -> Option<(f64, f64)> {
    let centre = (-t_lo / dt_mm).round() as isize;
    let above = |j: isize| j >= 0 && (j as usize) < values.len() && values[j as usize] >= 0.5;
    let seed = (0..values.len() as isize).filter(|&j| above(j)).min_by_key(|&j| (j - centre).abs())?;
    let (mut a, mut b) = (seed, seed);
    while above(a - 1) {
        a -= 1;
    }
    while above(b + 1) {
        b += 1;
    }
    let cross = |inside: isize, outside: isize| {
        if outside < 0 || outside as usize >= values.len() {
            return inside as f64;
        }
        let (vi, vo) = (values[inside as usize], values[outside as usize]);
        inside as f64 + (outside - inside) as f64 * (vi - 0.5) / (vi - vo)
    };
    Some((t_lo + cross(a, a - 1) * dt_mm, t_lo + cross(b, b + 1) * dt_mm))
}
