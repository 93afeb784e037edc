//! Sub-pixel width of a single straight printed line in a top-view photo.
//!
//! Paper 000 (FDM line width) measured line widths from top-view camera photos of single
//! straight lines, 120 mm long and 0.4-2 mm wide (Sec. III). This module gives the width
//! along such a line every `step_mm` from one photo and its nominal geometry
//! ([`LineGeometry`]: start, direction, length, scale, nominal width).
//!
//! The main method, [`segment_edge_fit`], fits a physical edge model rather than counting
//! thresholded pixels, because a threshold count is biased by anything that moves the
//! threshold against the local contrast (uneven lighting, vignetting, the PSF) and is
//! quantised to whole pixels; the edge fit locates both edges to a fraction of a pixel:
//!
//! 1. **Axis** ([`axis`]): the metadata's start and direction may be off by ~10 px and
//!    ~1°, so coarse profiles across the nominal axis give edge midpoints (extrema of the
//!    smoothed derivative), a robust straight-line fit refines the axis, once more in a
//!    narrow window; the ends are found along the refined axis, the start becomes the
//!    origin of the positions, and the line's polarity (brighter or darker than the bed)
//!    and contrast are measured.
//! 2. **Profiles** ([`profile`]): at each position s_k = k · `step_mm` the photo is sampled
//!    bilinearly along the normal over t ∈ [−T, T], T = max(1.5 w, w/2 + 8 px) for the
//!    nominal width w, every 0.5 px, each sample averaged over a band of ±step/2 along
//!    the line to cut noise.
//! 3. **Edge model** ([`model`], [`fit`]): each profile is fitted by Levenberg–Marquardt
//!    with I(t) = b0 + b1·t + A·½[erf((t − a)/(σ√2)) − erf((t − b)/(σ√2))], a bar blurred by
//!    a Gaussian PSF on a linear background that absorbs the lighting gradient and the
//!    vignetting locally; the width is (b − a)/px_per_mm. Fits whose edges leave the
//!    window, whose |A| is low against the residual noise or the line's contrast, or that
//!    do not converge are [`SkippedColumn`]s; so are positions within the end blur.
//!
//! [`segment_threshold_columns`] is the baseline a lab writes first (Otsu threshold of the
//! lightly blurred photo, foreground pixels counted per image column); it shares step 1,
//! so comparing the two measures the width estimators alone.
//!
//! Whole-image problems are [`LineError`]s: no line, a line leaving the frame, a stated
//! scale that cannot be right. A px/mm that is 2× wrong is an error, not a set of skipped
//! columns: the line's ends are then not where the nominal length puts them
//! ([`LineError::LengthMismatch`]) or the line runs out of the frame
//! ([`LineError::LeavesFrame`]), and widths far from the nominal one are
//! [`LineError::WidthMismatch`].
//!
//! Accuracy on the virtual camera of `tests/lines.rs` (120 mm lines, 0.8 mm with a
//! 1.3 mm start blob, ripple and trend, rough edges, −3°/0°/+2.5°, metadata 6 px and 0.5°
//! off, lighting ramp, vignetting, 3 % bed texture, 1.5 % noise, both polarities, 8 and
//! 16 bit; worst of 12 lines): RMSE 0.0065 / 0.013 / 0.023 mm at 40 / 20 / 10 px/mm with
//! |bias| ≤ 0.004 mm, against 0.10 / 0.18 / 0.34 mm for the Otsu baseline, whose threshold
//! sits away from half contrast. Without texture and noise the fit is exact to 3·10⁻⁵ mm;
//! the bed texture dominates what is left.
//!
//! Library use: kornia-io decodes the PNG ([`GrayImage::from_png_bytes`]) and
//! kornia-imgproc's `gaussian_blur` smooths the photo for the baseline. Hand-written,
//! because kornia-imgproc 0.2.0 lacks them or works only on whole images: bilinear
//! sampling along arbitrary directions, the 1-D Gaussian-derivative filter, erf, the LM
//! solver with its 6 × 6 Cholesky, the robust line fit and Otsu's threshold.
//!
//! Speed: positions are measured in fixed chunks of 64 in parallel with rayon, inside
//! the caller's pool (run it in a one-thread pool to process one image per thread and
//! parallelise over images instead); within a chunk one set of buffers is reused and each
//! fit starts from its neighbour's result, which halves the LM iterations. The chunks do
//! not depend on the thread count, so neither do the widths. `benches/lines.rs` measures
//! one 120 mm photo at 40 px/mm (4883 × 262 px) on one thread and on all.

pub mod axis;
pub mod errors;
pub mod fit;
pub mod image;
pub mod model;
pub mod profile;
pub mod threshold;

use rayon::prelude::*;

pub use errors::{EndSearch, LineError, SkipReason, SkippedColumn};
pub use image::GrayImage;
pub use threshold::segment_threshold_columns;

use axis::FoundLine;
use fit::{fit_edges, with_linear_parameters, Profile};
use model::EdgeParams;
use profile::{band_offsets, mean, median, peak, sample_across, AxisFrame, DerivativeKernel, SampleGrid};

/// The default spacing of the width samples along the line (mm).
pub const DEFAULT_STEP_MM: f64 = 0.05;
/// Positions measured in sequence by one worker, each fit starting from its neighbour's
/// result. Fixed, so that the results do not depend on the number of threads.
const CHUNK_POSITIONS: usize = 64;
/// Lateral sample spacing of a profile (px).
const PROFILE_DT_PX: f64 = 0.5;
/// Positions closer than this to a found end are skipped (px): two PSF widths for the
/// 1-2 px PSFs of our cameras, where the end blur changes the cross-section.
const END_MARGIN_PX: f64 = 4.0;
/// |A| must exceed this many times the fit's rms residual.
const CONTRAST_SNR: f64 = 5.0;
/// |A| must exceed this fraction of the line's contrast found by the axis step.
const CONTRAST_FRACTION: f64 = 0.25;
/// Accepted range of the median width as a multiple of the nominal width.
const WIDTH_RATIO_RANGE: (f64, f64) = (0.3, 3.0);
/// Most sample positions per image (a 10 m line at 0.01 mm); more is a unit mix-up.
const MAX_POSITIONS: usize = 1_000_000;
/// Positions are reported on a grid of this many points per mm (a picometre apart):
/// far below any pixel or step, coarse enough that k · step comes out as its decimal
/// ([`CheckedGeometry::position_mm`]).
pub const POSITION_GRID_PER_MM: f64 = 1e9;
/// Smallest nominal width that can be measured (px).
const MIN_WIDTH_PX: f64 = 2.0;

/// The nominal geometry of the photographed line, as the print's metadata states it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LineGeometry {
    /// Start point of the line (px, image coordinates: column + 0.5 at a pixel centre).
    pub start_px: [f64; 2],
    /// Direction from the start to the end (rad, image coordinates with v down).
    pub direction_rad: f64,
    /// Length of the line (mm).
    pub length_mm: f64,
    /// Image scale (px per mm).
    pub px_per_mm: f64,
    /// Width the line was printed for (mm); sets the sampling window.
    pub nominal_width_mm: f64,
}

/// The refined axis the widths are measured along.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefinedAxis {
    /// The found start of the line (px), the origin of [`Segmentation::positions_mm`].
    pub start_px: [f64; 2],
    /// The refined direction (rad).
    pub direction_rad: f64,
    /// Distance between the found ends (mm).
    pub found_length_mm: f64,
    /// True when the line is darker than the bed.
    pub dark_line: bool,
    /// Intensity step across the line (median over the axis profiles, signed: negative
    /// for a dark line; units of [`GrayImage::pixels`]).
    pub contrast: f64,
}

/// Widths along the line.
#[derive(Debug, Clone, PartialEq)]
pub struct Segmentation {
    /// Path coordinate of each width (mm from the found start), increasing.
    pub positions_mm: Vec<f64>,
    /// Width at each position (mm).
    pub widths_mm: Vec<f64>,
    /// Positions without a width, and why.
    pub skipped: Vec<SkippedColumn>,
    /// The axis the positions are measured along.
    pub axis: RefinedAxis,
}

/// What one sample position gave.
pub(crate) type Sample = Result<f64, SkipReason>;

/// Widths every `step_mm` by fitting the blurred-bar edge model to each cross-section
/// (see the module doc); in parallel over chunks of positions within the current rayon
/// pool, with results independent of its size.
pub fn segment_edge_fit(img: &GrayImage, geom: &LineGeometry, step_mm: f64) -> Result<Segmentation, LineError> {
    let checked = CheckedGeometry::new(img, geom, step_mm)?;
    let line = axis::find_line(img, &checked)?;
    let fitter = EdgeFitter::new(&checked, &line);
    let chunks = checked.position_count.div_ceil(CHUNK_POSITIONS);
    let samples: Vec<Sample> =
        (0..chunks).into_par_iter().flat_map_iter(|chunk| fitter.measure_chunk(img, chunk)).collect();
    assemble(&checked, &line, samples)
}

/// The geometry checked and converted to pixels.
#[derive(Debug, Clone, Copy)]
pub struct CheckedGeometry {
    /// Stated start (px).
    pub start_px: [f64; 2],
    /// Stated direction (rad).
    pub direction_rad: f64,
    /// Scale (px per mm).
    pub px_per_mm: f64,
    /// Nominal length (px).
    pub length_px: f64,
    /// Nominal width (px).
    pub nominal_width_px: f64,
    /// Half-width T of the profile window (px).
    pub half_window_px: f64,
    /// Spacing of the positions (mm).
    pub step_mm: f64,
    /// Spacing of the positions (px).
    pub step_px: f64,
    /// Number of positions k·step ≤ length.
    pub position_count: usize,
}

impl CheckedGeometry {
    /// Checks the image, the geometry and the step.
    pub fn new(img: &GrayImage, geom: &LineGeometry, step_mm: f64) -> Result<Self, LineError> {
        img.check_buffer()?;
        if img.width < 8 || img.height < 8 {
            return Err(img.bad("a line photo must be at least 8 × 8 px"));
        }
        let positive = |name: &str, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(value)
            } else {
                Err(LineError::BadGeometry(format!("{name} must be a positive finite number, got {value}")))
            }
        };
        let px_per_mm = positive("px_per_mm", geom.px_per_mm)?;
        let length_mm = positive("length_mm", geom.length_mm)?;
        let width_mm = positive("nominal_width_mm", geom.nominal_width_mm)?;
        let step_mm = positive("step_mm", step_mm)?;
        if !(geom.start_px.iter().all(|v| v.is_finite()) && geom.direction_rad.is_finite()) {
            return Err(LineError::BadGeometry("start_px and direction_rad must be finite".into()));
        }
        let position_count = (length_mm / step_mm + 1e-9).floor() + 1.0;
        if position_count > MAX_POSITIONS as f64 {
            return Err(LineError::BadGeometry(format!(
                "{position_count} positions (length_mm / step_mm) exceed {MAX_POSITIONS}: check the units"
            )));
        }
        let nominal_width_px = width_mm * px_per_mm;
        if nominal_width_px < MIN_WIDTH_PX {
            return Err(LineError::BadGeometry(format!(
                "the nominal width is {nominal_width_px:.2} px, below the {MIN_WIDTH_PX} px that can be measured"
            )));
        }
        let half_window_px = (1.5 * nominal_width_px).max(0.5 * nominal_width_px + 8.0);
        check_fits(img, geom, length_mm * px_per_mm, half_window_px)?;
        Ok(Self {
            start_px: geom.start_px,
            direction_rad: geom.direction_rad,
            px_per_mm,
            length_px: length_mm * px_per_mm,
            nominal_width_px,
            half_window_px,
            step_mm,
            step_px: step_mm * px_per_mm,
            position_count: position_count as usize,
        })
    }

    /// Path coordinate of position `k` (px).
    pub fn position_px(&self, k: usize) -> f64 {
        k as f64 * self.step_px
    }

    /// Path coordinate of position `k` as it is reported (mm): k · `step_mm` rounded to
    /// the nearest 10⁻⁹ mm ([`POSITION_GRID_PER_MM`]), so that the sixth position at
    /// 0.05 mm is written 0.3, the decimal a reader expects, and not 0.30000000000000004
    /// (the binary rounding of the product). Dividing the whole number of grid points,
    /// rather than multiplying by 10⁻⁹, gives the double nearest that decimal. It differs
    /// from the measured place, [`Self::position_px`], by at most 5·10⁻¹⁰ mm.
    pub fn position_mm(&self, k: usize) -> f64 {
        (k as f64 * self.step_mm * POSITION_GRID_PER_MM).round() / POSITION_GRID_PER_MM
    }

    /// Whether position `s_px` lies within the end blur of a line of `length_px`.
    pub fn near_end(&self, s_px: f64, length_px: f64) -> bool {
        let margin = END_MARGIN_PX + 0.5 * self.step_px;
        s_px < margin || s_px > length_px - margin
    }
}

/// A line longer than the image's diagonal, or a window wider than it, cannot be inside
/// the image whatever the start: a [`LineError::LeavesFrame`] at the nominal end (this
/// also bounds every buffer by the image size).
fn check_fits(img: &GrayImage, geom: &LineGeometry, length_px: f64, half_window_px: f64) -> Result<(), LineError> {
    let diagonal_px = (img.width as f64).hypot(img.height as f64);
    if length_px <= diagonal_px + 2.0 * axis::START_SLACK_PX && 2.0 * half_window_px <= diagonal_px {
        return Ok(());
    }
    let axis = AxisFrame::new(geom.start_px, geom.direction_rad);
    let [u_px, v_px] = axis.point(length_px, 0.0);
    Err(LineError::LeavesFrame {
        s_mm: geom.length_mm,
        margin_px: half_window_px,
        u_px,
        v_px,
        width: img.width,
        height: img.height,
    })
}

/// Splits per-position outcomes into widths and skips and applies the whole-image checks.
pub(crate) fn assemble(
    geom: &CheckedGeometry,
    line: &FoundLine,
    samples: Vec<Sample>,
) -> Result<Segmentation, LineError> {
    let mut segmentation = Segmentation {
        positions_mm: Vec::with_capacity(samples.len()),
        widths_mm: Vec::with_capacity(samples.len()),
        skipped: Vec::new(),
        axis: refined_axis(geom, line),
    };
    for (k, sample) in samples.into_iter().enumerate() {
        let position_mm = geom.position_mm(k);
        match sample {
            Ok(width_mm) => {
                segmentation.positions_mm.push(position_mm);
                segmentation.widths_mm.push(width_mm);
            }
            Err(reason) => segmentation.skipped.push(SkippedColumn { position_mm, reason }),
        }
    }
    check_widths(geom, &segmentation)?;
    Ok(segmentation)
}

/// The public form of the found line.
fn refined_axis(geom: &CheckedGeometry, line: &FoundLine) -> RefinedAxis {
    RefinedAxis {
        start_px: line.axis.origin_px,
        direction_rad: line.axis.direction_rad(),
        found_length_mm: line.length_px / geom.px_per_mm,
        dark_line: line.polarity < 0.0,
        contrast: line.contrast,
    }
}

/// Errors when nothing was measured or the median width is far from the nominal width.
fn check_widths(geom: &CheckedGeometry, segmentation: &Segmentation) -> Result<(), LineError> {
    if segmentation.widths_mm.is_empty() {
        return Err(LineError::NothingMeasured {
            skipped: segmentation.skipped.len(),
            by_reason: skip_counts(&segmentation.skipped),
        });
    }
    let median_width_mm = median(&mut segmentation.widths_mm.clone());
    let nominal_width_mm = geom.nominal_width_px / geom.px_per_mm;
    let (min_ratio, max_ratio) = WIDTH_RATIO_RANGE;
    let ratio = median_width_mm / nominal_width_mm;
    if !(min_ratio..=max_ratio).contains(&ratio) {
        return Err(LineError::WidthMismatch { median_width_mm, nominal_width_mm, min_ratio, max_ratio });
    }
    Ok(())
}

/// How many positions were skipped for each reason, the most frequent first (then in
/// the order the reasons first occur along the line).
pub fn skip_counts(skipped: &[SkippedColumn]) -> Vec<(SkipReason, usize)> {
    let mut counts: Vec<(SkipReason, usize)> = Vec::new();
    for s in skipped {
        match counts.iter_mut().find(|(r, _)| *r == s.reason) {
            Some((_, n)) => *n += 1,
            None => counts.push((s.reason, 1)),
        }
    }
    counts.sort_by_key(|c| std::cmp::Reverse(c.1));
    counts
}

/// Per-position edge fitting with shared settings.
struct EdgeFitter {
    axis: AxisFrame,
    length_px: f64,
    geom: CheckedGeometry,
    polarity: f64,
    contrast: f64,
    band_px: Vec<f64>,
    count: usize,
    derivative: DerivativeKernel,
}

/// Buffers one worker reuses for every position.
struct Scratch {
    values: Vec<f64>,
    derivative: Vec<f64>,
}

impl EdgeFitter {
    fn new(geom: &CheckedGeometry, line: &FoundLine) -> Self {
        let sub_samples = (geom.step_px.ceil() as usize).clamp(2, 5);
        let count = (2.0 * geom.half_window_px / PROFILE_DT_PX).floor() as usize + 1;
        Self {
            axis: line.axis,
            length_px: line.length_px,
            geom: *geom,
            polarity: line.polarity,
            contrast: line.contrast,
            band_px: band_offsets(0.5 * geom.step_px, sub_samples).collect(),
            count,
            derivative: DerivativeKernel::new(2.0),
        }
    }

    fn scratch(&self) -> Scratch {
        Scratch { values: vec![0.0; self.count], derivative: vec![0.0; self.count] }
    }

    fn grid(&self) -> SampleGrid<'_> {
        SampleGrid { t0_px: -self.geom.half_window_px, dt_px: PROFILE_DT_PX, count: self.count, band_px: &self.band_px }
    }

    /// The widths of the positions of chunk `chunk`, with one set of buffers; each fit
    /// starts from the previous position's fit (a couple of µm of roughness away), the
    /// first and any after a failure from the profile's own derivative extrema.
    fn measure_chunk(&self, img: &GrayImage, chunk: usize) -> Vec<Sample> {
        let mut scratch = self.scratch();
        let mut previous = None;
        let positions = chunk * CHUNK_POSITIONS..((chunk + 1) * CHUNK_POSITIONS).min(self.geom.position_count);
        positions
            .map(|k| {
                let fit = self.measure(img, k, previous, &mut scratch);
                previous = fit.as_ref().ok().map(|f| f.params);
                fit.map(|f| (f.params.right_px - f.params.left_px) / self.geom.px_per_mm)
            })
            .collect()
    }

    /// The accepted edge fit at position `k`, or why there is none.
    fn measure(
        &self,
        img: &GrayImage,
        k: usize,
        warm: Option<EdgeParams>,
        scratch: &mut Scratch,
    ) -> Result<fit::EdgeFit, SkipReason> {
        let s_px = self.geom.position_px(k);
        if self.geom.near_end(s_px, self.length_px) {
            return Err(SkipReason::NearLineEnd);
        }
        if !sample_across(img, &self.axis, s_px, self.grid(), &mut scratch.values) {
            return Err(SkipReason::OutsideFrame);
        }
        let profile = Profile { t0_px: -self.geom.half_window_px, dt_px: PROFILE_DT_PX, values: &scratch.values };
        let warm_fit = warm.and_then(|init| fit_edges(profile, init));
        let fit = match warm_fit {
            Some(fit) => fit,
            None => {
                let init = with_linear_parameters(profile, self.initial_guess(profile, &mut scratch.derivative));
                fit_edges(profile, init).ok_or(SkipReason::FitDidNotConverge)?
            }
        };
        self.accept(profile, &fit)?;
        Ok(fit)
    }

    /// Edges at the derivative extrema, background from the window's ends, σ = 1.5 px.
    fn initial_guess(&self, profile: Profile<'_>, derivative: &mut [f64]) -> EdgeParams {
        let values = profile.values;
        let n = values.len();
        self.derivative.apply(values, derivative);
        let half_nominal = 0.5 * self.geom.nominal_width_px;
        let (left_px, right_px) =
            match (peak(derivative, 4..n - 4, self.polarity), peak(derivative, 4..n - 4, -self.polarity)) {
                (Some((_, l)), Some((_, r))) if l < r => {
                    (profile.t_px(0) + l * profile.dt_px, profile.t_px(0) + r * profile.dt_px)
                }
                _ => (-half_nominal, half_nominal),
            };
        let flank = (n / 12).max(2);
        let (left_bg, right_bg) = (mean(values, 0, flank), mean(values, n - flank, n));
        let span_px = profile.t_px(n - flank / 2) - profile.t_px(flank / 2);
        let centre = ((0.5 * (left_px + right_px) - profile.t0_px) / profile.dt_px).round() as usize;
        let b0 = 0.5 * (left_bg + right_bg);
        let contrast = values[centre.min(n - 1)] - b0;
        EdgeParams { b0, b1: (right_bg - left_bg) / span_px, contrast, left_px, right_px, sigma_px: 1.5 }
    }

    /// Rejects fits with edges at the window border or too little contrast.
    fn accept(&self, profile: Profile<'_>, fit: &fit::EdgeFit) -> Result<(), SkipReason> {
        let p = &fit.params;
        let (t_min, t_max) = (profile.t0_px, profile.t_px(profile.values.len() - 1));
        if p.left_px < t_min + 2.0 * p.sigma_px || p.right_px > t_max - 2.0 * p.sigma_px {
            return Err(SkipReason::EdgeOutsideWindow);
        }
        if p.sigma_px > 0.5 * (p.right_px - p.left_px) {
            return Err(SkipReason::FitDidNotConverge);
        }
        let floor = (CONTRAST_SNR * fit.rms_residual).max(CONTRAST_FRACTION * self.contrast.abs());
        if p.contrast * self.polarity < floor {
            return Err(SkipReason::LowContrast);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn checked(step_mm: f64, length_mm: f64) -> CheckedGeometry {
        let img = GrayImage { width: 6000, height: 100, pixels: vec![0.5; 600_000] };
        let geom = LineGeometry {
            start_px: [50.0, 50.0],
            direction_rad: 0.0,
            length_mm,
            px_per_mm: 40.0,
            nominal_width_mm: 0.8,
        };
        CheckedGeometry::new(&img, &geom, step_mm).unwrap()
    }

    #[test]
    fn positions_are_the_decimals_k_times_the_step() {
        // 6 × 0.05 is 0.30000000000000004 in binary floating point; the positions are
        // written as the decimal (here 5·k hundredths, 48·k thousandths of a mm).
        assert_eq!(6.0 * 0.05, 0.30000000000000004);
        for (step_mm, per_mm) in [(0.05, 100), (0.048, 1000), (0.01, 100)] {
            let geom = checked(step_mm, 120.0);
            for k in 0..geom.position_count {
                let expected = format!("{}", (k as f64 * step_mm * per_mm as f64).round() / per_mm as f64);
                assert_eq!(format!("{}", geom.position_mm(k)), expected, "step {step_mm}, k {k}");
                // Never more than half the grid away from the measured place.
                assert!((geom.position_mm(k) - geom.position_px(k) / geom.px_per_mm).abs() <= 5e-10);
            }
        }
        assert_eq!(checked(0.05, 120.0).position_mm(6), 0.3);
    }

    #[test]
    fn skipped_positions_are_counted_by_reason_most_frequent_first() {
        let at = |reason| SkippedColumn { position_mm: 0.0, reason };
        let skipped = [
            at(SkipReason::NearLineEnd),
            at(SkipReason::OutsideFrame),
            at(SkipReason::OutsideFrame),
            at(SkipReason::NearLineEnd),
            at(SkipReason::OutsideFrame),
            at(SkipReason::LowContrast),
        ];
        let counts = skip_counts(&skipped);
        assert_eq!(counts, [(SkipReason::OutsideFrame, 3), (SkipReason::NearLineEnd, 2), (SkipReason::LowContrast, 1)]);
        let err = LineError::NothingMeasured { skipped: 6, by_reason: counts };
        assert_eq!(
            err.to_string(),
            "no sample position could be measured: 6 skipped (3 × profile leaves the image, 2 × within the \
             end blur of the line, 1 × edge contrast too low against the noise)"
        );
    }
}
