//! Errors and per-position diagnostics of the line-width segmenter ([`super`]).
//!
//! Whole-image problems (the file is unreadable, no line is found, the line leaves the
//! frame, the stated scale cannot be right) make every width of the image meaningless and
//! are a [`LineError`] that says what to check. A single unusable sample position is a
//! [`SkippedColumn`] with a [`SkipReason`], and the other positions go on.

use std::fmt;

/// Why an image could not be segmented at all.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LineError {
    /// The bytes are not a decodable PNG of a supported kind (truncated, corrupt, palette…).
    #[error("unreadable PNG: {0}")]
    Unreadable(String),
    /// The PNG header asks for more pixels than the caller allows (checked before allocating).
    #[error("image too large: {width}×{height} px exceeds the limit of {max_pixels} pixels")]
    TooLarge {
        /// Width stated in the header (px).
        width: usize,
        /// Height stated in the header (px).
        height: usize,
        /// The caller's limit (pixels).
        max_pixels: usize,
    },
    /// The image is too small to hold a line profile, or its buffer does not match its size.
    #[error("unusable image of {width}×{height} px with {pixels} values: {reason}")]
    BadImage {
        /// Width (px).
        width: usize,
        /// Height (px).
        height: usize,
        /// Number of pixel values held.
        pixels: usize,
        /// What is wrong.
        reason: String,
    },
    /// The line geometry or the step is not usable (not finite, not positive, too fine).
    #[error("bad line geometry: {0}")]
    BadGeometry(String),
    /// No line with two clear edges was found near the nominal axis.
    #[error(
        "no line found near the nominal axis: {found} of {tried} profiles show two edges \
         ({reason}); check start_px, direction_rad and that the photo shows the line"
    )]
    NoLine {
        /// Profiles in which a pair of edges was found.
        found: usize,
        /// Profiles tried.
        tried: usize,
        /// Why the found ones are not enough.
        reason: String,
    },
    /// The refined line, with its lateral margin, is not inside the image.
    #[error(
        "the line leaves the frame: its point at s = {s_mm:.2} mm (lateral margin {margin_px:.0} px) \
         lies at ({u_px:.0}, {v_px:.0}) px outside the {width}×{height} px image; check length_mm, \
         px_per_mm and start_px"
    )]
    LeavesFrame {
        /// Path coordinate of the offending point (mm).
        s_mm: f64,
        /// Lateral margin that must fit in the frame (px).
        margin_px: f64,
        /// Image column coordinate of the point (px).
        u_px: f64,
        /// Image row coordinate of the point (px).
        v_px: f64,
        /// Image width (px).
        width: usize,
        /// Image height (px).
        height: usize,
    },
    /// A line end was not found where the nominal length puts it.
    #[error(
        "the line's {which} was not found within ±{window_mm:.2} mm of its nominal place: {found}; \
         the found length does not match length_mm = {length_mm} mm: check length_mm and px_per_mm"
    )]
    LengthMismatch {
        /// "start" or "end".
        which: &'static str,
        /// Half-width of the search window (mm).
        window_mm: f64,
        /// What the search found instead of an end.
        found: EndSearch,
        /// The nominal length (mm).
        length_mm: f64,
    },
    /// The measured widths are far from the nominal width: the scale is probably wrong.
    #[error(
        "median width {median_width_mm:.3} mm is outside [{min_ratio}, {max_ratio}] × the nominal \
         {nominal_width_mm} mm; check px_per_mm and nominal_width_mm"
    )]
    WidthMismatch {
        /// Median of the measured widths (mm).
        median_width_mm: f64,
        /// The nominal width (mm).
        nominal_width_mm: f64,
        /// Lowest accepted ratio.
        min_ratio: f64,
        /// Highest accepted ratio.
        max_ratio: f64,
    },
    /// Every sample position was skipped.
    #[error("no sample position could be measured: {skipped} skipped ({})", reason_counts(.by_reason))]
    NothingMeasured {
        /// Number of skipped positions.
        skipped: usize,
        /// How many positions were skipped for each reason, the most frequent first.
        by_reason: Vec<(SkipReason, usize)>,
    },
}

/// What the search for a line end found in its window along the axis, when it found no
/// end: the reason of a [`LineError::LengthMismatch`], in words that say what was
/// expected (an intensity step across the end of at least half the line's contrast).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EndSearch {
    /// The strongest change of the right sign is too small to be the line's end.
    WeakStep {
        /// The intensity step across the best candidate (units of the image).
        step: f64,
        /// The line's contrast measured across it (units of the image).
        contrast: f64,
    },
    /// The intensity changes most at the window's border: there is no end inside it, the
    /// line (or the bed's shading) goes on beyond the window.
    AtWindowBorder {
        /// The line's contrast measured across it (units of the image).
        contrast: f64,
    },
    /// The window holds too little of the photo to show an end (the photo ends there).
    WindowClipped {
        /// The length of the window inside the photo (px).
        inside_px: f64,
        /// The length an end needs (px).
        needed_px: f64,
    },
}

impl fmt::Display for EndSearch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::WeakStep { step, contrast } => write!(
                f,
                "the strongest intensity step there, {step:.3}, is under half the line's contrast of {contrast:.3}"
            ),
            Self::AtWindowBorder { contrast } => write!(
                f,
                "no intensity step of half the line's contrast ({:.3}) inside the window: the intensity \
                 changes most at the window's border, so the line goes on beyond it or ends before it",
                0.5 * contrast
            ),
            Self::WindowClipped { inside_px, needed_px } => write!(
                f,
                "only {inside_px:.1} px of the window lie inside the photo, {needed_px:.0} px are needed to see an end"
            ),
        }
    }
}

/// "2380 × profile leaves the image, 21 × within the end blur of the line".
fn reason_counts(by_reason: &[(SkipReason, usize)]) -> String {
    by_reason.iter().map(|(r, n)| format!("{n} × {r}")).collect::<Vec<_>>().join(", ")
}

/// One sample position without a width, and why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkippedColumn {
    /// Path coordinate of the position (mm from the refined start).
    pub position_mm: f64,
    /// Why no width was measured there.
    pub reason: SkipReason,
}

/// Why one sample position has no width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SkipReason {
    /// Within the end blur of the line: the profile is not a full cross-section.
    NearLineEnd,
    /// Part of the profile lies outside the image.
    OutsideFrame,
    /// The fitted edge step is too weak against the residual noise or the line's contrast.
    LowContrast,
    /// The edge-model fit did not converge or gave an impossible shape.
    FitDidNotConverge,
    /// A fitted edge lies at or beyond the border of the sampling window.
    EdgeOutsideWindow,
    /// The threshold found no foreground in the column, or foreground touching the window border.
    NoForeground,
}

impl fmt::Display for SkipReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NearLineEnd => "within the end blur of the line",
            Self::OutsideFrame => "profile leaves the image",
            Self::LowContrast => "edge contrast too low against the noise",
            Self::FitDidNotConverge => "edge fit did not converge",
            Self::EdgeOutsideWindow => "an edge lies outside the sampling window",
            Self::NoForeground => "no foreground run inside the window",
        })
    }
}
