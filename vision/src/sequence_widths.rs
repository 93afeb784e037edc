//! Widths over a localised filmed sequence (paper 003 Sec. 2.4): every trajectory
//! sample of a layer is read in one placed frame, along its deposition direction, at a
//! threshold temperature T_t that is given or calibrated per layer.
//!
//! - **Which frame.** A sample is read in the placed frame of its layer in which its bead
//!   is closest to `measure_age_s` old, and only if that is within half a frame period:
//!   the thermal contour drifts as the bead cools, so every sample is read at one age.
//! - **Which threshold.** The paper does not give T_t. It identifies the nominal width
//!   w0 experimentally on straight lines (Sec. 3.2); we calibrate T_t the same way, per
//!   layer: the T_t at which the median width of the layer's straight samples equals
//!   the nominal bead width, by bisection between the bed and the nozzle temperature
//!   (the contour narrows as the threshold rises). Which samples are straight is the
//!   caller's (e.g. clear of every corner, and where the flow has settled:
//!   `models::thermal::PrintSetup::settled_samples`).

use models::stats::finite_median;

use crate::frame::ThermalFrame;
use crate::homography::Homography;
use crate::widths::{bilinear, extract_widths_into, WidthParams, WidthQuery};

/// Bisection steps of the T_t calibration: 30 halvings shrink a bed-to-nozzle bracket
/// of a few hundred kelvin below a millikelvin.
const CALIBRATION_STEPS: usize = 30;

/// One frame of the sequence as the width reading sees it.
#[derive(Debug, Clone, Copy)]
pub struct FrameView<'a> {
    /// Its layer.
    pub layer: usize,
    /// Where it was placed: capture time (s) and the undistorted-pixel ← plane map;
    /// `None` for a frame that was not placed.
    pub placed: Option<(f64, &'a Homography)>,
    /// The undistorted image, when it could be read.
    pub image: Option<&'a ThermalFrame>,
}

/// How T_t is found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    /// This T_t (°C) on every layer.
    Fixed(f64),
    /// Per layer, the T_t in `[low_c, high_c]` at which the median width of the straight
    /// samples is `nominal_width_mm`.
    Calibrated {
        /// Lower end of the bracket (°C), e.g. just above the bed temperature.
        low_c: f64,
        /// Upper end (°C), e.g. the nozzle temperature.
        high_c: f64,
        /// The nominal bead width 2·w0 (mm).
        nominal_width_mm: f64,
    },
}

/// The settings of the reading.
#[derive(Debug, Clone, Copy)]
pub struct Reading {
    /// Age of the bead at which each sample is read (s).
    pub measure_age_s: f64,
    /// The camera's frame period (s): a sample is read only in a frame within half of
    /// it from the measuring age.
    pub frame_period_s: f64,
    /// The half-width search (its threshold is replaced by the layer's T_t).
    pub widths: WidthParams,
    /// How T_t is found.
    pub threshold: Threshold,
}

/// One sample's reading; NaN where it could not be read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleWidth {
    /// Left half width (mm).
    pub left_mm: f64,
    /// Right half width (mm).
    pub right_mm: f64,
    /// Temperature on the path there (°C).
    pub temp_c: f64,
}

impl Default for SampleWidth {
    fn default() -> Self {
        Self { left_mm: f64::NAN, right_mm: f64::NAN, temp_c: f64::NAN }
    }
}

/// The widths read on one layer.
#[derive(Debug, Clone)]
pub struct LayerWidths {
    /// The layer.
    pub layer: usize,
    /// The T_t used (°C).
    pub threshold_c: f64,
    /// Per sample, the index of the frame it was read in.
    pub owner: Vec<Option<usize>>,
    /// Per sample, the reading.
    pub measured: Vec<SampleWidth>,
}

/// The samples of a layer's path and how to read them.
#[derive(Debug, Clone, Copy)]
pub struct SequenceWidths<'a> {
    /// Time of each trajectory sample (s).
    pub t_s: &'a [f64],
    /// Each sample's point and left deposition direction.
    pub queries: &'a [WidthQuery],
    /// Per sample: straight, i.e. fit to calibrate T_t on.
    pub straight: &'a [bool],
    /// The settings.
    pub reading: Reading,
}

impl SequenceWidths<'_> {
    /// The widths of every layer the frames show (layers 0 to the largest).
    pub fn layers(&self, frames: &[FrameView]) -> Vec<LayerWidths> {
        let layers = frames.iter().map(|f| f.layer).max().map_or(0, |l| l + 1);
        (0..layers)
            .map(|layer| {
                let owner = self.frame_of_samples(frames, layer);
                let threshold_c = match self.reading.threshold {
                    Threshold::Fixed(t) => t,
                    Threshold::Calibrated { low_c, high_c, nominal_width_mm } => {
                        self.calibrated_threshold(frames, &owner, (low_c, high_c), nominal_width_mm)
                    }
                };
                let measured = self.read(frames, &owner, threshold_c);
                LayerWidths { layer, threshold_c, owner, measured }
            })
            .collect()
    }

    /// For each sample, the placed frame of `layer` in which its bead is closest to the
    /// measuring age (within half a frame period); the earliest such frame on a tie.
    pub fn frame_of_samples(&self, frames: &[FrameView], layer: usize) -> Vec<Option<usize>> {
        let half_period = 0.5 * self.reading.frame_period_s;
        let mut best: Vec<Option<(usize, f64)>> = vec![None; self.t_s.len()];
        for (i, t_frame) in frames.iter().enumerate().filter_map(|(i, f)| f.placed.map(|(t, _)| (i, t))) {
            if frames[i].layer != layer {
                continue;
            }
            for (slot, t_sample) in best.iter_mut().zip(self.t_s) {
                let miss = (t_frame - t_sample - self.reading.measure_age_s).abs();
                if miss <= half_period && slot.is_none_or(|(_, m)| miss < m) {
                    *slot = Some((i, miss));
                }
            }
        }
        best.into_iter().map(|b| b.map(|(i, _)| i)).collect()
    }

    /// Half widths and path temperature of every sample at `threshold_c`, each in its
    /// `owner` frame.
    pub fn read(&self, frames: &[FrameView], owner: &[Option<usize>], threshold_c: f64) -> Vec<SampleWidth> {
        let params = WidthParams { threshold_c, ..self.reading.widths };
        let mut out = Vec::with_capacity(1);
        owner
            .iter()
            .zip(self.queries)
            .map(|(frame, query)| {
                let Some(f) = frame.map(|i| &frames[i]) else { return SampleWidth::default() };
                let (Some(image), Some((_, h))) = (f.image, f.placed) else { return SampleWidth::default() };
                extract_widths_into(image, h, std::slice::from_ref(query), &params, &mut out);
                let px = h.apply(query.p_mm);
                let temp_c = bilinear(image, px[0], px[1]).unwrap_or(f64::NAN);
                let (left_mm, right_mm) = out[0].unwrap_or((f64::NAN, f64::NAN));
                SampleWidth { left_mm, right_mm, temp_c }
            })
            .collect()
    }

    /// The T_t in `(low_c, high_c)` at which the median width of the straight samples is
    /// `nominal_width_mm` (bisection: the contour narrows as the threshold rises; a
    /// threshold at which nothing is read counts as too high).
    pub fn calibrated_threshold(
        &self,
        frames: &[FrameView],
        owner: &[Option<usize>],
        (low_c, high_c): (f64, f64),
        nominal_width_mm: f64,
    ) -> f64 {
        let straight_owner: Vec<Option<usize>> =
            owner.iter().zip(self.straight).map(|(o, s)| if *s { *o } else { None }).collect();
        let median_width =
            |t: f64| finite_median(self.read(frames, &straight_owner, t).iter().map(|m| m.left_mm + m.right_mm));
        let (mut lo, mut hi) = (low_c, high_c);
        for _ in 0..CALIBRATION_STEPS {
            let mid = 0.5 * (lo + hi);
            let w = median_width(mid);
            if !w.is_finite() || w < nominal_width_mm {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

#[cfg(test)]
mod tests;
