//! Line widths from a real photo of a printed pattern and the G-code that printed it,
//! measured in bed millimetres with nothing given by hand (no px/mm, no clicked points).
//!
//! 1. **Contrast** ([`contrast`]): the photo projected on the Fisher direction that
//!    separates its two colour classes, plate reading 0 and print 1.
//! 2. **Coarse pose** ([`search`]): rotation from the edge orientations, scale and
//!    position from normalised cross-correlation of the G-code's material with the photo.
//! 3. **Camera** ([`align`], [`camera`]): a homography and two radial distortion terms,
//!    fitted densely from coarse to fine blur; then the contrast is learnt again from the
//!    pixels the fitted G-code says are print and plate, and the finest levels are fitted
//!    again on it.
//! 4. **Orientation** ([`orient`]): poses a symmetric pattern leaves equally good are told
//!    apart by the print itself: its width changes where the G-code changes speed.
//! 5. **Widths** ([`measure`]): each path measured across its G-code axis every step along
//!    it, by the blurred-edge fit of [`crate::lines`] (and the threshold baseline), in bed
//!    mm through the camera; where other material lies within reach the position is not a
//!    single bead and is skipped; where the window holds no material it is a gap (width 0).
//!
//! Everything is in bed millimetres once the camera is known, so lens distortion and
//! perspective (the scale varying by ±8 % across a cheap endoscope's photo) do not enter
//! the widths.

pub mod align;
pub mod camera;
pub mod contrast;
pub mod image;
pub mod measure;
pub mod orient;
pub mod raster;
pub mod search;

pub use camera::PhotoCamera;
pub use contrast::ColourAxis;
pub use image::ColourImage;

use align::{align, LevelFit};
use raster::distance_to_segment;

/// Blur levels of the camera fit (mm on the bed), coarse to fine.
pub const ALIGN_SIGMAS_MM: [f64; 8] = [3.2, 2.3, 1.6, 1.1, 0.8, 0.4, 0.2, 0.1];
/// Levels fitted again on the learnt contrast.
const REFINE_SIGMAS_MM: [f64; 3] = [0.4, 0.2, 0.1];
/// Coarse poses scoring at least this fraction of the best are fitted too.
const CANDIDATE_FRACTION: f64 = 0.85;
/// Fitted poses whose finest decorrelation 1 − ρ is within this factor of the best are
/// told apart by the print ([`orient`]).
const TIE_FACTOR: f64 = 1.1;

/// One straight printed path as the G-code commanded it.
#[derive(Debug, Clone, PartialEq)]
pub struct PrintedPath {
    /// Start on the bed (mm).
    pub start_mm: [f64; 2],
    /// End on the bed (mm).
    pub end_mm: [f64; 2],
    /// Width the commanded flow gives (mm): the extruded volume per mm over the layer height.
    pub width_mm: f64,
    /// Positions along the path where the commanded speed changes (mm from its start).
    pub speed_changes_mm: Vec<f64>,
}

impl PrintedPath {
    /// A G-code line as the photo sees it: its axis, the width its commanded flow gives,
    /// and where along it the commanded speed changes (each move's start after the first).
    pub fn from_line(line: &models::fdm::printed_lines::PrintedLine) -> Self {
        Self {
            start_mm: line.start_mm,
            end_mm: line.end_mm,
            width_mm: line.nominal_width_mm,
            speed_changes_mm: line.moves.iter().skip(1).map(|m| m.start_along_mm).collect(),
        }
    }

    /// Length (mm).
    pub fn length_mm(&self) -> f64 {
        (self.end_mm[0] - self.start_mm[0]).hypot(self.end_mm[1] - self.start_mm[1])
    }

    /// Unit direction from start to end.
    pub fn direction(&self) -> [f64; 2] {
        let l = self.length_mm().max(1e-12);
        [(self.end_mm[0] - self.start_mm[0]) / l, (self.end_mm[1] - self.start_mm[1]) / l]
    }

    /// The bed point at `s_mm` along the path and `t_mm` to its left.
    pub fn point(&self, s_mm: f64, t_mm: f64) -> [f64; 2] {
        let d = self.direction();
        [self.start_mm[0] + d[0] * s_mm - d[1] * t_mm, self.start_mm[1] + d[1] * s_mm + d[0] * t_mm]
    }
}

/// Why a photo could not be measured at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhotoError {
    /// Not a decodable JPEG or PNG.
    #[error("unreadable image: {0}")]
    Unreadable(String),
    /// The header asks for more pixels than allowed (checked before decoding).
    #[error("image too large: {width}×{height} px exceeds the limit of {max_pixels} pixels")]
    TooLarge {
        /// Width (px).
        width: usize,
        /// Height (px).
        height: usize,
        /// The limit (pixels).
        max_pixels: usize,
    },
    /// The pixel buffer is unusable.
    #[error("unusable image: {0}")]
    BadImage(String),
    /// The G-code has no path to look for.
    #[error("the G-code has no printed path to find in the photo")]
    NoPaths,
    /// The photo has one colour: nothing separates print from plate.
    #[error("the photo has no contrast: its colours form one class, so print and plate cannot be told apart")]
    NoContrast,
    /// The pattern was not found.
    #[error("the G-code's pattern was not found in the photo: {0}")]
    NotFound(String),
}

/// Where the photo sits on the bed and how its colours read.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The fitted camera.
    pub camera: PhotoCamera,
    /// The learnt contrast (plate 0, print 1).
    pub contrast_axis: ColourAxis,
    /// Each level of the final camera fit.
    pub levels: Vec<LevelFit>,
    /// The coarse pose's normalised correlation.
    pub coarse_score: f64,
    /// How the orientation was chosen among equally good poses.
    pub orientation: orient::Choice,
}

/// Places the photo on the bed from the G-code's paths. `mirrored`: the camera mirrors its
/// image (an unmirrored top view turns bed y against image y).
pub fn calibrate(img: &ColourImage, paths: &[PrintedPath], mirrored: bool) -> Result<Calibration, PhotoError> {
    if paths.is_empty() {
        return Err(PhotoError::NoPaths);
    }
    let first_axis = ColourAxis::from_clusters(img).ok_or(PhotoError::NoContrast)?;
    let first_contrast = first_axis.apply(img);
    let candidates = search::coarse_candidates(&first_contrast, paths, mirrored);
    let best_score = candidates.first().map_or(0.0, |c| c.score);
    let mut fitted = Vec::new();
    for c in candidates.iter().filter(|c| c.score >= CANDIDATE_FRACTION * best_score) {
        let axis = if c.polarity < 0.0 { negated(&first_axis) } else { first_axis };
        if let Some(cal) = refine(img, paths, c.camera, axis, c.score) {
            fitted.push(cal);
        }
    }
    let best_rms = fitted.iter().map(final_decorrelation).fold(f64::INFINITY, f64::min);
    let tied: Vec<Calibration> =
        fitted.into_iter().filter(|c| final_decorrelation(c) <= TIE_FACTOR * best_rms).collect();
    orient::choose(img, paths, tied).ok_or_else(|| {
        PhotoError::NotFound(format!(
            "no pose fitted ({} coarse candidates, best correlation {best_score:.2})",
            candidates.len()
        ))
    })
}

/// 1 − ρ of the finest level (lower is better).
fn final_decorrelation(c: &Calibration) -> f64 {
    c.levels.last().map_or(f64::INFINITY, |l| 1.0 - l.correlation)
}

fn negated(axis: &ColourAxis) -> ColourAxis {
    ColourAxis { direction: axis.direction.map(|v| -v), ..*axis }
}

/// The dense fit from a coarse pose, the contrast learnt from the fitted G-code, and the
/// finest levels again on it.
fn refine(
    img: &ColourImage,
    paths: &[PrintedPath],
    start: PhotoCamera,
    axis: ColourAxis,
    coarse_score: f64,
) -> Option<Calibration> {
    let first = align(&axis.apply(img), paths, start, &ALIGN_SIGMAS_MM)?;
    let learnt = learn_contrast(img, paths, &first.camera).unwrap_or(axis);
    let second = align(&learnt.apply(img), paths, first.camera, &REFINE_SIGMAS_MM)?;
    let orientation = orient::Choice::Only;
    Some(Calibration { camera: second.camera, contrast_axis: learnt, levels: second.levels, coarse_score, orientation })
}

/// The Fisher axis from pixels the G-code says are surely print (within a third of the
/// commanded half-width of an axis) or surely plate (beyond twice it plus 0.5 mm from
/// every path, within 3 mm of the pattern).
fn learn_contrast(img: &ColourImage, paths: &[PrintedPath], camera: &PhotoCamera) -> Option<ColourAxis> {
    let (lo, hi) = raster::bounds(paths);
    let scale = camera.mean_scale([(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0])?;
    let step = 1.0 / scale;
    let mut labelled = Vec::new();
    let mut y = lo[1] - 3.0;
    while y <= hi[1] + 3.0 {
        let mut x = lo[0] - 3.0;
        while x <= hi[0] + 3.0 {
            if let Some(label) = surely(paths, [x, y]) {
                if let Some(p) = camera.project([x, y]) {
                    let (i, j) = (p[0].floor(), p[1].floor());
                    if i >= 0.0 && j >= 0.0 && (i as usize) < img.width && (j as usize) < img.height {
                        labelled.push((img.at(i as usize, j as usize), label));
                    }
                }
            }
            x += step;
        }
        y += step;
    }
    ColourAxis::from_labels(labelled)
}

fn surely(paths: &[PrintedPath], p: [f64; 2]) -> Option<bool> {
    let mut plate = true;
    for path in paths {
        let d = distance_to_segment(p, path.start_mm, path.end_mm);
        if d <= path.width_mm / 6.0 {
            return Some(true);
        }
        plate &= d > path.width_mm + 0.5;
    }
    plate.then_some(false)
}
