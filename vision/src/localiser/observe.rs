//! Pass 1 of the localiser (paper 003 Sec. 2.3): every frame decoded at the camera's
//! size, undistorted, its hot corners detected in the band and paired with the printed
//! CAD corners predicted through the nominal mount from the recorded time, each pair
//! placed on its ridge vertex, and the frame localised by the paper's estimator (RANSAC +
//! DLT, eq. 27; the nozzle, eq. 29; the capture time, eq. 30). A frame recorded out of
//! order, or whose image repeats the one before it, is skipped (module doc of [`super`]);
//! a frame that cannot be read or observed is skipped with the reason.

use models::progress::Progress;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::outcome::{DetectionRow, FrameOutcome, Located};
use super::{FrameSource, Localiser, LocaliserError, SequenceFrame};
use crate::frame::{FrameError, ThermalFrame};
use crate::matching::PredictedCorner;
use crate::pipeline::{
    localise_dlt, observe_frame, predict_path_corners_into, FrameContext, FrameInput, FrameWorkspace, PathCorner,
};

impl<S: FrameSource> Localiser<'_, S> {
    /// Pass 1 over all frames: decode, observe, the paper's DLT, the ridge pairs; a frame
    /// whose image is the one before it again is skipped (module doc of [`super`]).
    pub(super) fn observe_all(
        &self,
        ctx: &FrameContext<'_>,
        seed: u64,
        progress: &dyn Progress,
    ) -> Result<Vec<FrameOutcome>, LocaliserError> {
        let mut workspace = FrameWorkspace::new(&self.undistorter, &self.params)?;
        let entries = self.seq.frames.frames();
        let mut last_time: Option<(usize, f64)> = None;
        let mut outcomes: Vec<FrameOutcome> = Vec::with_capacity(entries.len());
        progress.add(entries.len() as u64);
        for (index, entry) in entries.iter().enumerate() {
            let outcome = match last_time {
                Some((layer, t)) if layer == entry.layer && entry.recorded_time_s <= t => FrameOutcome::skipped(
                    entry,
                    format!(
                        "recorded time {:.4} s is not after the previous frame's {:.4} s (out of order)",
                        entry.recorded_time_s, t
                    ),
                ),
                _ => {
                    last_time = Some((entry.layer, entry.recorded_time_s));
                    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((entry.layer as u64) << 32 | entry.frame as u64));
                    let outcome = self.observe(ctx, index, entry, &mut workspace, &mut rng);
                    match repeated_image(&outcomes, &outcome) {
                        Some(previous) => FrameOutcome {
                            repeat_of: Some(previous),
                            ..FrameOutcome::skipped(
                                entry,
                                format!("same image as frame {previous}: a repeated or frozen camera frame, not its own time and place"),
                            )
                        },
                        None => outcome,
                    }
                }
            };
            outcomes.push(outcome);
            progress.done(1);
        }
        Ok(outcomes)
    }

    /// One frame of pass 1, `entry` the `index`-th of the sequence (a failure is a
    /// diagnostic, not an error).
    fn observe(
        &self,
        ctx: &FrameContext<'_>,
        index: usize,
        entry: &SequenceFrame,
        ws: &mut FrameWorkspace,
        rng: &mut ChaCha8Rng,
    ) -> FrameOutcome {
        let frame = match self.decode(index) {
            Ok(frame) => frame,
            Err(e) => return FrameOutcome::skipped(entry, format!("{}: {e}", entry.file.display())),
        };
        let t_r = entry.recorded_time_s;
        let printed: Vec<PathCorner> =
            self.path_corners.iter().copied().filter(|c| self.passage_s[c.id as usize] <= t_r).collect();
        let mut predicted: Vec<PredictedCorner> = Vec::new();
        predict_path_corners_into(&self.h0, ctx.trajectory.position_mm(t_r), &printed, &mut predicted);
        let input = FrameInput { frame: &frame, t_recorded_s: t_r, predicted: &predicted, width_queries: &[] };
        if let Err(skip) = observe_frame(ctx, &input, ws) {
            return FrameOutcome::skipped(entry, skip.to_string());
        }
        let detections = detection_rows(ws, &predicted);
        let (corners_found, matched) = (ws.detections().len(), detections.iter().filter(|d| d.0 >= 0).count());
        let dlt = localise_dlt(ctx, &input, ws, rng).map_err(|s| s.to_string()).and_then(|r| {
            let h = r.homography.homography;
            Located::new(r.capture, r.nozzle_mm, h, r.homography.rms_error_mm, r.homography.inlier_count())
        });
        let dlt = dlt.map(|l| self.unless_parked(l, t_r));
        FrameOutcome {
            entry: entry.clone(),
            corners_found,
            matched,
            detections,
            undistorted: Some(ws.undistorted().clone()),
            pairs: ws.ridge_pairs(&predicted),
            pair_used: Vec::new(),
            dlt,
            rigid: Err("not localised".into()),
            chosen: Err("not localised".into()),
            repeat_of: None,
        }
    }

    /// Frame `index`'s PNG decoded at the camera's size, checked against the PNG header
    /// before anything is allocated.
    fn decode(&self, index: usize) -> Result<ThermalFrame, FrameError> {
        let bytes = self.seq.frames.png_bytes(index).map_err(|e| FrameError::Unreadable(e.to_string()))?;
        let camera = self.undistorter.camera();
        ThermalFrame::from_png_bytes_sized(&bytes, camera.width_px, camera.height_px)
    }
}

/// The frame number of the last decoded frame before `current`, if it is of the same
/// layer and its image is bit for bit `current`'s.
fn repeated_image(earlier: &[FrameOutcome], current: &FrameOutcome) -> Option<usize> {
    let image = current.undistorted.as_ref()?;
    let previous = earlier.iter().rev().find(|f| f.undistorted.is_some())?;
    let same = previous.entry.layer == current.entry.layer
        && previous.undistorted.as_ref().is_some_and(|p| {
            p.width == image.width
                && p.temp_c.len() == image.temp_c.len()
                && p.temp_c.iter().zip(&image.temp_c).all(|(a, b)| a.to_bits() == b.to_bits())
        });
    same.then_some(previous.entry.frame)
}

/// The detections of the last observed frame with the vertex each was paired with.
fn detection_rows(ws: &FrameWorkspace, predicted: &[PredictedCorner]) -> Vec<DetectionRow> {
    ws.detections()
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let vertex =
                ws.matches().iter().find(|m| m.detection == i).map_or(-1, |m| i64::from(predicted[m.predicted].id));
            (vertex, [d.u_px, d.v_px], f64::from(d.temp_c))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A decoded frame of `layer`, `frame` whose every pixel reads `temp_c`.
    fn decoded(layer: usize, frame: usize, temp_c: f32) -> FrameOutcome {
        let entry = SequenceFrame { layer, frame, recorded_time_s: 0.125 * frame as f64, file: "f.png".into() };
        let image = ThermalFrame { width: 4, height: 3, temp_c: vec![temp_c; 12] };
        FrameOutcome { undistorted: Some(image), ..FrameOutcome::skipped(&entry, String::new()) }
    }

    #[test]
    fn a_frame_repeats_the_last_decoded_one_of_its_layer_only_bit_for_bit() {
        let unreadable = FrameOutcome::skipped(&decoded(0, 1, 0.0).entry, "wrong size".into());
        let earlier = vec![decoded(0, 0, 80.0), unreadable];
        assert_eq!(repeated_image(&earlier, &decoded(0, 2, 80.0)), Some(0), "the unreadable frame is passed over");
        assert_eq!(repeated_image(&earlier, &decoded(0, 2, 80.001)), None);
        assert_eq!(repeated_image(&earlier, &decoded(1, 0, 80.0)), None, "a new layer starts afresh");
        assert_eq!(repeated_image(&[], &decoded(0, 0, 80.0)), None);
    }
}
