//! The baseline a lab writes first (step 4 of [`super`]): Otsu's threshold of the lightly
//! Gaussian-blurred photo (σ = 1 px, kornia-imgproc's `gaussian_blur`), then per sample
//! position the run of foreground pixels through the axis point counted in the image
//! column (or row, for a line closer to vertical), width = count × |cos θ| / px_per_mm
//! (|sin θ| for rows). A run that reaches the window's border (the bed crossed the
//! threshold too, e.g. in a vignetted corner) is skipped as [`SkipReason::NoForeground`].
//! The window is clipped to the frame less the blur's border ([`BORDER_PX`]), so the
//! baseline needs no more bed beside the line than the shared axis step does: a run
//! that ends inside the photo is counted, one that reaches the frame is
//! [`SkipReason::OutsideFrame`] (before, any column whose whole window did not fit was
//! skipped: 41 of 2401 positions on a 10 px/mm photo with 8 px of bed beside the line,
//! which the edge fit measured in full). It shares the axis and end refinement of [`super::segment_edge_fit`], so the
//! positions are the same and a comparison measures the width estimators alone.
//!
//! Otsu's method is hand-written (kornia-imgproc 0.2.0 has fixed thresholds only).

use kornia_image::{Image, ImageSize};
use kornia_imgproc::filter::gaussian_blur;

use super::axis::{self, FoundLine};
use super::errors::{LineError, SkipReason};
use super::image::GrayImage;
use super::{assemble, CheckedGeometry, Sample, Segmentation};

/// Blur applied before thresholding (px).
const BLUR_SIGMA_PX: f32 = 1.0;
/// Pixels this close to the frame border are not counted: the blur pads with zeros.
const BORDER_PX: usize = 4;
/// Histogram bins of Otsu's method.
const OTSU_BINS: usize = 256;

/// Widths every `step_mm` by counting Otsu-thresholded pixels per column (see the module doc).
pub fn segment_threshold_columns(
    img: &GrayImage,
    geom: &super::LineGeometry,
    step_mm: f64,
) -> Result<Segmentation, LineError> {
    let checked = CheckedGeometry::new(img, geom, step_mm)?;
    let line = axis::find_line(img, &checked)?;
    let blurred = blur(img)?;
    let threshold = otsu_threshold(&blurred.pixels);
    let counter = ColumnCounter { img: &blurred, geom: &checked, line: &line, threshold };
    let samples: Vec<Sample> = (0..checked.position_count).map(|k| counter.measure(k)).collect();
    assemble(&checked, &line, samples)
}

/// The photo blurred by a Gaussian of [`BLUR_SIGMA_PX`].
fn blur(img: &GrayImage) -> Result<GrayImage, LineError> {
    let size = ImageSize { width: img.width, height: img.height };
    let src = Image::<f32, 1>::new(size, img.pixels.clone()).map_err(|e| img.bad(&e.to_string()))?;
    let mut dst = Image::<f32, 1>::from_size_val(size, 0.0).map_err(|e| img.bad(&e.to_string()))?;
    gaussian_blur(&src, &mut dst, (0, 0), (BLUR_SIGMA_PX, BLUR_SIGMA_PX)).map_err(|e| img.bad(&e.to_string()))?;
    GrayImage::new(img.width, img.height, dst.as_slice().to_vec())
}

/// Otsu's threshold: the level maximising the between-class variance of a histogram.
pub fn otsu_threshold(pixels: &[f32]) -> f32 {
    let (lo, hi) = pixels.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if pixels.is_empty() || hi <= lo {
        return lo;
    }
    let scale = (OTSU_BINS as f32 - 1.0) / (hi - lo);
    let mut histogram = [0u64; OTSU_BINS];
    for &v in pixels {
        histogram[((v - lo) * scale) as usize] += 1;
    }
    let total = pixels.len() as f64;
    let sum_all: f64 = histogram.iter().enumerate().map(|(i, &c)| i as f64 * c as f64).sum();
    let (mut weight_low, mut sum_low, mut best) = (0.0, 0.0, (0.0, 0));
    for (i, &count) in histogram.iter().enumerate() {
        weight_low += count as f64;
        sum_low += i as f64 * count as f64;
        let weight_high = total - weight_low;
        if weight_low == 0.0 || weight_high == 0.0 {
            continue;
        }
        let mean_gap = sum_low / weight_low - (sum_all - sum_low) / weight_high;
        let between = weight_low * weight_high * mean_gap * mean_gap;
        if between > best.0 {
            best = (between, i);
        }
    }
    lo + (best.1 as f32 + 1.0) / scale
}

/// Foreground counting along image columns or rows.
struct ColumnCounter<'a> {
    img: &'a GrayImage,
    geom: &'a CheckedGeometry,
    line: &'a FoundLine,
    threshold: f32,
}

impl ColumnCounter<'_> {
    /// The width (mm) at position `k` from the foreground count of its column or row.
    fn measure(&self, k: usize) -> Sample {
        let s_px = self.geom.position_px(k);
        if self.geom.near_end(s_px, self.line.length_px) {
            return Err(SkipReason::NearLineEnd);
        }
        let [u, v] = self.line.axis.point(s_px, 0.0);
        let [dx, dy] = self.line.axis.dir;
        let by_columns = dx.abs() >= dy.abs();
        let (across, along, cos) = if by_columns { (v, u, dx.abs()) } else { (u, v, dy.abs()) };
        let reach = self.geom.half_window_px / cos;
        let count = self.count(by_columns, along, across, [across - reach, across + reach])?;
        Ok(count as f64 * cos / self.geom.px_per_mm)
    }

    /// Length of the foreground run through the axis point `across` in column (or row)
    /// `along`, which must end inside the window [from, to] (pixel centres). The window
    /// is clipped to the frame less [`BORDER_PX`]: a run that ends inside the photo is
    /// counted however close the photo is cropped, one that reaches the frame is
    /// [`SkipReason::OutsideFrame`], one that reaches the window's own border
    /// [`SkipReason::NoForeground`].
    fn count(&self, by_columns: bool, along: f64, across: f64, [from, to]: [f64; 2]) -> Result<usize, SkipReason> {
        let (extent_along, extent_across) =
            if by_columns { (self.img.width, self.img.height) } else { (self.img.height, self.img.width) };
        let line_index = along.floor();
        let (first, last) = ((from - 0.5).ceil(), (to - 0.5).floor());
        let inside = |x: f64, extent: usize| x >= BORDER_PX as f64 && x < (extent - BORDER_PX) as f64;
        if !(inside(line_index, extent_along) && inside(across.floor(), extent_across)) {
            return Err(SkipReason::OutsideFrame);
        }
        let (frame_first, frame_last) = (BORDER_PX as f64, (extent_across - BORDER_PX - 1) as f64);
        let bright = self.line.polarity > 0.0;
        let is_foreground = |x: usize| {
            let (i, j) = if by_columns { (line_index as usize, x) } else { (x, line_index as usize) };
            (self.img.at(i, j) > self.threshold) == bright
        };
        let centre = across.floor() as usize;
        if !is_foreground(centre) {
            return Err(SkipReason::NoForeground);
        }
        let edge = |clipped: bool| if clipped { SkipReason::OutsideFrame } else { SkipReason::NoForeground };
        let (low_end, high_end) = (first.max(frame_first) as usize, last.min(frame_last) as usize);
        let low = (low_end..centre).rev().find(|&x| !is_foreground(x)).ok_or(edge(first < frame_first))?;
        let high = (centre + 1..=high_end).find(|&x| !is_foreground(x)).ok_or(edge(last > frame_last))?;
        Ok(high - low - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn otsu_splits_two_clusters_between_them() {
        let mut pixels = vec![0.2f32; 900];
        pixels.extend(std::iter::repeat_n(0.7f32, 100));
        pixels[3] = 0.22;
        let t = otsu_threshold(&pixels);
        assert!(t > 0.22 && t < 0.7, "threshold {t}");
    }
}
