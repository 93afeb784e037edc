//! Line widths from a real photo of a printed pattern and the G-code that printed it,
//! measured in bed millimetres with nothing given by hand (no px/mm, no clicked points).
//!
//! 1. **Contrast** ([`contrast`]): the photo projected on the Fisher direction that
//!    separates its two colour classes, plate reading 0 and print 1.
//! 2. **Coarse pose** ([`search`]): rotation from the edge orientations, scale and
//!    position from normalised cross-correlation of the G-code's material with the photo.
//! 3. **Camera** ([`mod@align`], [`camera`]): a homography and two radial distortion terms,
//!    fitted densely from coarse to fine blur, every coarse pose down to 0.4 mm of blur
//!    ([`PLACE_SIGMAS_MM`]); then the contrast is learnt again from the pixels each fitted
//!    G-code says are print and plate.
//! 4. **Orientation** ([`orient`]): poses a symmetric pattern leaves equally good are told
//!    apart by the print itself: its width changes where the G-code changes speed. Where
//!    the best pose is placed well at 0.4 mm and each other is as good or clearly worse,
//!    the choice is made there and only the chosen pose is fitted through the finest
//!    levels ([`FINE_SIGMAS_MM`]) on its learnt contrast: they are most of the fit's time.
//!    At 0.4 mm a pose lies within 0.36 mm of its final place on the shared photos (RMS
//!    0.11 mm along the axes), close enough for the orientation's width proxy (± the
//!    commanded width) and the contrast's labels: the same choice (21 of 21 lines on each
//!    photo), and a contrast that separates print from plate as well as one learnt after
//!    the finest levels (Fisher separation 6.03–6.45 against 5.96–6.38). Otherwise every
//!    pose goes the long way: on through 0.2 and 0.1 mm ([`LONG_WAY_SIGMAS_MM`]), its
//!    contrast learnt there, the finest levels fitted on it, and the poses told apart at
//!    the end; a virtual photo tilted by ±10 % is placed only so.
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

use std::borrow::Cow;

use crate::lines::GrayImage;
use align::{align, LevelFit};
use contrast::LabelSums;
use rayon::prelude::*;

/// Blur levels (mm on the bed) fitted from every coarse pose on the clusters' contrast,
/// coarse to fine; where they can be, the poses are told apart after the last of them.
pub const PLACE_SIGMAS_MM: [f64; 6] = [3.2, 2.3, 1.6, 1.1, 0.8, 0.4];
/// Blur levels (mm on the bed) fitted for the chosen pose on the contrast learnt from it.
pub const FINE_SIGMAS_MM: [f64; 3] = [0.4, 0.2, 0.1];
/// Blur levels (mm on the bed) that poses not told apart after [`PLACE_SIGMAS_MM`] are
/// fitted on through, on the clusters' contrast, before their contrast is learnt again.
pub const LONG_WAY_SIGMAS_MM: [f64; 2] = [0.2, 0.1];
/// Coarse poses scoring at least this fraction of the best are fitted too.
const CANDIDATE_FRACTION: f64 = 0.85;
/// Fitted poses whose finest decorrelation 1 − ρ is within this factor of the best are
/// told apart by the print ([`orient`]).
const TIE_FACTOR: f64 = 1.1;
/// A placed pose whose decorrelation after [`PLACE_SIGMAS_MM`] is beyond this factor of the
/// best's is clearly worse; one between [`TIE_FACTOR`] and it might still overtake the best
/// on the finer levels, so the poses are not told apart there. On the well placed photos
/// measured, the other pose was tied (within 1.01 times) or 15 times worse (a coarse pose
/// at a quarter of the scale).
const CONTENDER_FACTOR: f64 = 2.0;
/// The best placed pose's correlation after [`PLACE_SIGMAS_MM`] for the poses to be told
/// apart there. Measured at 0.4 mm: 0.90-0.91 on the shared photos, 0.94-0.95 on the
/// virtual photos placed this way; 0.41-0.62 on the virtual photos tilted by ±10 % that
/// end on a wrong pose or are placed only the long way (one: the finer levels on the
/// clusters' contrast and a restart on the contrast learnt after them found its pose).
const WELL_PLACED_CORRELATION: f64 = 0.8;

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
        self.axis().point(s_mm, t_mm)
    }

    /// The path's axis with its direction worked out once, for many points along it.
    pub fn axis(&self) -> PathAxis {
        PathAxis { start_mm: self.start_mm, direction: self.direction() }
    }
}

/// A path's start and unit direction ([`PrintedPath::axis`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathAxis {
    /// Start on the bed (mm).
    pub start_mm: [f64; 2],
    /// Unit direction from start to end.
    pub direction: [f64; 2],
}

impl PathAxis {
    /// The bed point at `s_mm` along the path and `t_mm` to its left.
    #[inline]
    pub fn point(&self, s_mm: f64, t_mm: f64) -> [f64; 2] {
        let (a, d) = (self.start_mm, self.direction);
        [a[0] + d[0] * s_mm - d[1] * t_mm, a[1] + d[1] * s_mm + d[0] * t_mm]
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
    let placed: Vec<Placed> = candidates
        .par_iter()
        .filter(|c| c.score >= CANDIDATE_FRACTION * best_score)
        .filter_map(|c| place(img, &first_contrast, paths, c, &first_axis))
        .collect();
    let chosen = if told_apart(&placed) {
        let tied = within(placed.into_iter().map(|p| p.calibration).collect(), TIE_FACTOR);
        choose_then_refine(img, paths, tied)
    } else {
        let fitted: Vec<Calibration> =
            placed.par_iter().filter_map(|p| the_long_way(img, &first_contrast, paths, p)).collect();
        orient::choose(img, paths, within(fitted, TIE_FACTOR))
    };
    chosen.ok_or_else(|| {
        PhotoError::NotFound(format!(
            "no pose fitted ({} coarse candidates, best correlation {best_score:.2})",
            candidates.len()
        ))
    })
}

/// A coarse pose fitted through [`PLACE_SIGMAS_MM`]: its calibration there, with the
/// contrast learnt from it, and whether the print reads darker than the plate in the
/// clusters' contrast.
struct Placed {
    calibration: Calibration,
    clusters_axis: ColourAxis,
    negative: bool,
}

/// Whether the placed poses can be told apart where they stand: the best is placed well
/// ([`WELL_PLACED_CORRELATION`]) and each other is as good ([`TIE_FACTOR`]) or clearly
/// worse ([`CONTENDER_FACTOR`]).
fn told_apart(placed: &[Placed]) -> bool {
    let decorrelation: Vec<f64> = placed.iter().map(|p| final_decorrelation(&p.calibration)).collect();
    let best = decorrelation.iter().copied().fold(f64::INFINITY, f64::min);
    1.0 - best >= WELL_PLACED_CORRELATION
        && decorrelation.iter().all(|&d| d <= TIE_FACTOR * best || d > CONTENDER_FACTOR * best)
}

/// Equally good poses: the print chooses among them as they stand and only the chosen one
/// is fitted through the finest levels (if that fails, its points leaving the photo, the
/// print chooses among the others).
fn choose_then_refine(img: &ColourImage, paths: &[PrintedPath], mut tied: Vec<Calibration>) -> Option<Calibration> {
    for _ in 0..tied.len() {
        let chosen = orient::choose(img, paths, tied.clone())?;
        if let Some(fine) = refine(img, paths, &chosen) {
            return Some(fine);
        }
        tied.retain(|c| c.camera != chosen.camera);
    }
    None
}

/// The poses whose last level's decorrelation is within `factor` of the best's.
fn within(poses: Vec<Calibration>, factor: f64) -> Vec<Calibration> {
    let best = poses.iter().map(final_decorrelation).fold(f64::INFINITY, f64::min);
    poses.into_iter().filter(|c| final_decorrelation(c) <= factor * best).collect()
}

/// 1 − ρ of the last level fitted (lower is better).
fn final_decorrelation(c: &Calibration) -> f64 {
    c.levels.last().map_or(f64::INFINITY, |l| 1.0 - l.correlation)
}

fn negated(axis: &ColourAxis) -> ColourAxis {
    ColourAxis { direction: axis.direction.map(|v| -v), ..*axis }
}

/// The clusters' contrast, negated where the print reads darker than the plate.
fn with_polarity(contrast: &GrayImage, negative: bool) -> Cow<'_, GrayImage> {
    if negative {
        Cow::Owned(GrayImage { pixels: contrast.pixels.iter().map(|v| -v).collect(), ..*contrast })
    } else {
        Cow::Borrowed(contrast)
    }
}

/// A coarse pose fitted through [`PLACE_SIGMAS_MM`] on the clusters' contrast (`clusters`
/// applied: `contrast`, negated where the coarse search found the print darker), with the
/// contrast learnt from the pixels the fitted G-code says are print and plate: what the
/// orientation is chosen on.
fn place(
    img: &ColourImage,
    contrast: &GrayImage,
    paths: &[PrintedPath],
    candidate: &search::Candidate,
    clusters: &ColourAxis,
) -> Option<Placed> {
    let negative = candidate.polarity < 0.0;
    let clusters_axis = if negative { negated(clusters) } else { *clusters };
    let placed = align(&with_polarity(contrast, negative), paths, candidate.camera, &PLACE_SIGMAS_MM)?;
    let learnt = learn_contrast(img, paths, &placed.camera).unwrap_or(clusters_axis);
    let calibration = Calibration {
        camera: placed.camera,
        contrast_axis: learnt,
        levels: placed.levels,
        coarse_score: candidate.score,
        orientation: orient::Choice::Only,
    };
    Some(Placed { calibration, clusters_axis, negative })
}

/// A pose not told apart after [`PLACE_SIGMAS_MM`], fitted on through
/// [`LONG_WAY_SIGMAS_MM`] on the clusters' contrast, its contrast learnt again there and
/// [`FINE_SIGMAS_MM`] fitted on that: what every pose went through before the poses were
/// told apart early.
fn the_long_way(
    img: &ColourImage,
    contrast: &GrayImage,
    paths: &[PrintedPath],
    placed: &Placed,
) -> Option<Calibration> {
    let start = placed.calibration.camera;
    let first = align(&with_polarity(contrast, placed.negative), paths, start, &LONG_WAY_SIGMAS_MM)?;
    let learnt = learn_contrast(img, paths, &first.camera).unwrap_or(placed.clusters_axis);
    let calibration = Calibration { camera: first.camera, contrast_axis: learnt, ..placed.calibration.clone() };
    refine(img, paths, &calibration)
}

/// A pose fitted through [`FINE_SIGMAS_MM`] on its learnt contrast.
fn refine(img: &ColourImage, paths: &[PrintedPath], placed: &Calibration) -> Option<Calibration> {
    let fine = align(&placed.contrast_axis.apply(img), paths, placed.camera, &FINE_SIGMAS_MM)?;
    Some(Calibration { camera: fine.camera, levels: fine.levels, ..placed.clone() })
}

/// The Fisher axis from pixels the G-code says are surely print (within a third of the
/// commanded half-width of an axis) or surely plate (beyond twice it plus 0.5 mm from
/// every path, within 3 mm of the pattern), on a bed grid of about one photo pixel.
fn learn_contrast(img: &ColourImage, paths: &[PrintedPath], camera: &PhotoCamera) -> Option<ColourAxis> {
    let (lo, hi) = raster::bounds(paths);
    let scale = camera.mean_scale([(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0])?;
    let xs = grid_steps(lo[0] - 3.0, hi[0] + 3.0, 1.0 / scale);
    let ys = grid_steps(lo[1] - 3.0, hi[1] + 3.0, 1.0 / scale);
    let labels = surely_labels(paths, &xs, &ys);
    // per row in parallel, the rows' sums merged in order
    let rows: Vec<LabelSums> = labels
        .par_chunks(xs.len().max(1))
        .zip(&ys)
        .map(|(row, &y)| {
            let mut sums = LabelSums::default();
            for (&x, &label) in xs.iter().zip(row) {
                let is_print = match label {
                    Surely::Plate => false,
                    Surely::Print => true,
                    Surely::Neither => continue,
                };
                let Some(p) = camera.project([x, y]) else { continue };
                let (i, j) = (p[0].floor(), p[1].floor());
                if i >= 0.0 && j >= 0.0 && (i as usize) < img.width && (j as usize) < img.height {
                    sums.add(img.at(i as usize, j as usize), is_print);
                }
            }
            sums
        })
        .collect();
    let mut total = LabelSums::default();
    rows.iter().for_each(|row| total.merge(row));
    ColourAxis::from_label_sums(&total)
}

/// `from`, `from + step`, … up to `to` (accumulated, as a walk over the grid would).
fn grid_steps(from: f64, to: f64, step: f64) -> Vec<f64> {
    let mut steps = Vec::new();
    let mut x = from;
    while x <= to {
        steps.push(x);
        x += step;
    }
    steps
}

/// Squared distances to one segment, its direction and length prepared once
/// ([`raster::distance_to_segment`] for many points).
struct SegmentDistance {
    start: [f64; 2],
    d: [f64; 2],
    inv_len2: f64,
}

impl SegmentDistance {
    fn new(a: [f64; 2], b: [f64; 2]) -> Self {
        let d = [b[0] - a[0], b[1] - a[1]];
        let len2 = d[0] * d[0] + d[1] * d[1];
        Self { start: a, d, inv_len2: if len2 > 0.0 { 1.0 / len2 } else { 0.0 } }
    }

    #[inline]
    fn squared(&self, p: [f64; 2]) -> f64 {
        let (a, d) = (self.start, self.d);
        let t = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) * self.inv_len2).clamp(0.0, 1.0);
        let (dx, dy) = (p[0] - a[0] - t * d[0], p[1] - a[1] - t * d[1]);
        dx * dx + dy * dy
    }
}

/// What a bed point surely is, ordered so that the strongest claim any path makes wins.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Surely {
    Plate,
    Neither,
    Print,
}

/// Per grid point (row-major over `ys`, `xs`): print within a third of the commanded
/// half-width of any path's axis; else plate beyond the commanded width plus 0.5 mm of
/// every path; else neither. Each row visits only the paths within reach of it, and each
/// path only the columns within reach.
fn surely_labels(paths: &[PrintedPath], xs: &[f64], ys: &[f64]) -> Vec<Surely> {
    let mut labels = vec![Surely::Plate; xs.len() * ys.len()];
    labels.par_chunks_mut(xs.len().max(1)).zip(ys).for_each(|(row, &y)| {
        for path in paths {
            let reach = path.width_mm + 0.5;
            let (a, b) = (path.start_mm, path.end_mm);
            if y < a[1].min(b[1]) - reach || y > a[1].max(b[1]) + reach {
                continue;
            }
            let first = xs.partition_point(|&x| x < a[0].min(b[0]) - reach);
            let last = xs.partition_point(|&x| x <= a[0].max(b[0]) + reach);
            let axis = SegmentDistance::new(a, b);
            let (print2, reach2) = ((path.width_mm / 6.0).powi(2), reach * reach);
            for (label, &x) in row[first..last].iter_mut().zip(&xs[first..last]) {
                let d2 = axis.squared([x, y]);
                let here = if d2 <= print2 {
                    Surely::Print
                } else if d2 <= reach2 {
                    Surely::Neither
                } else {
                    Surely::Plate
                };
                *label = (*label).max(here);
            }
        }
    });
    labels
}
