//! The rigid-mount estimator over a sequence, our extension of paper 003 Sec. 2.3
//! ([`crate::mount`]: H(i) = T(n_i)·H_m): the mount fitted to the pass-1 pairs of every
//! frame, then rounds that re-pair every young, readable corner from the latest mount's
//! predictions and fit again until the mount settles, the corners' arms oriented by the
//! nominal mount and then once by the settled one; each frame's nozzle is then placed
//! from its pairs under the last mount (eq. 29) and timed by eq. 30, or, with no pair,
//! by dead reckoning (module doc of [`super`]).

use models::stats::finite_median;

use super::outcome::{FrameOutcome, Located, MountRow};
use super::{Localiser, MAX_REPAIR_ROUNDS, MOUNT_SETTLED_MM};
use crate::camera::CameraModel;
use crate::homography::Homography;
use crate::mount::{fit_mount, frame_homography, locate_nozzle, FramePairs, MountError, MountFit};
use crate::pipeline::{check_plausible, CornerPairs, FrameContext, FrameSkip, PathCorner};
use crate::rigid::{initial_mount, localise_rigid, predict_corners_with_arms_into, ridge_pairs_into};
use crate::vertex::VertexParams;

impl<S> Localiser<'_, S> {
    /// The rigid-mount estimator over the sequence: fit on pass-1 pairs, then re-pair
    /// every ready corner from the mount's predictions and fit again until the mount
    /// settles (arms nominal, then settled), and place each frame's nozzle.
    pub(super) fn localise_rigid_all(&self, ctx: &FrameContext<'_>, frames: &mut [FrameOutcome]) -> Vec<MountRow> {
        let nozzle_px = self.undistorter.undistort_px(ctx.nozzle_px);
        let start = match initial_mount(ctx) {
            Ok(h) => h,
            Err(e) => {
                let reason = format!("rigid mount: {e}");
                frames.iter_mut().for_each(|f| f.rigid = Err(reason.clone()));
                return vec![MountRow { pass: 0, fit: Err(e.to_string()), applied: false }];
            }
        };
        self.keep_young(frames);
        let nominal = MountFit { mount: start, inliers: Vec::new(), rms_mm: f64::NAN, pairs_used: 0, frames_used: 0 };
        let first = self.fit(frames, nozzle_px, &start);
        let mut mount = first.as_ref().map_or(start, |f| f.mount);
        let mut fits = vec![Ok(nominal), first];
        // Rounds with the arms oriented by the nominal mount, then once more by the mount
        // they settle on ([`crate::rigid`] says why once).
        self.settle(ctx, frames, nozzle_px, &mut mount, &start, &mut fits);
        let settled = mount;
        self.settle(ctx, frames, nozzle_px, &mut mount, &settled, &mut fits);
        // The last mount that could be fitted places each frame (the nominal mount
        // anchored at P_N⁽⁰⁾ when none could); the rows say which.
        let cornerless: Vec<usize> = (0..frames.len()).filter(|&i| self.place(ctx, &mut frames[i], &mount)).collect();
        if self.place_cornerless {
            self.place_by_recorded_time(ctx, frames, &cornerless, &mount);
        }
        let applied = fits.iter().rposition(|f| f.is_ok()).unwrap_or(0);
        fits.into_iter()
            .enumerate()
            .map(|(pass, fit)| MountRow { pass: pass as i64, fit, applied: pass == applied })
            .collect()
    }

    /// Re-pairs every frame from the latest `mount` (its ridge searches start from the
    /// mount's predictions, their arms oriented by `arms`) and fits again (the mount
    /// anchored at the undistorted nozzle pixel `nozzle_px`), until the
    /// mount settles or [`MAX_REPAIR_ROUNDS`] have run; each fit joins `fits`.
    fn settle(
        &self,
        ctx: &FrameContext<'_>,
        frames: &mut [FrameOutcome],
        nozzle_px: [f64; 2],
        mount: &mut Homography,
        arms: &Homography,
        fits: &mut Vec<Result<MountFit, String>>,
    ) {
        for _ in 0..MAX_REPAIR_ROUNDS {
            self.repair_all(ctx, frames, mount, arms);
            let next = self.fit(frames, nozzle_px, mount);
            let moved_mm = next.as_ref().map_or(0.0, |f| largest_gap_mm(&f.mount, mount, self.undistorter.camera()));
            if let Ok(f) = &next {
                *mount = f.mount;
            }
            fits.push(next);
            if moved_mm <= MOUNT_SETTLED_MM {
                break;
            }
        }
    }

    /// The mount fitted to the current pairs of every frame.
    fn fit(&self, frames: &[FrameOutcome], nozzle_px: [f64; 2], start: &Homography) -> Result<MountFit, String> {
        let pairs: Vec<FramePairs<'_>> =
            frames.iter().map(|f| FramePairs { image_px: &f.pairs.image_px, plane_mm: &f.pairs.plane_mm }).collect();
        fit_mount(&pairs, nozzle_px, start, &self.params.mount).map_err(|e| e.to_string())
    }

    /// One re-pairing round: every frame's pairs searched from the predictions of
    /// `mount`, the arms oriented as the fixed mount `arms` sees them.
    fn repair_all(&self, ctx: &FrameContext<'_>, frames: &mut [FrameOutcome], mount: &Homography, arms: &Homography) {
        let vertex = self.params.vertex.unwrap_or_else(VertexParams::defaults);
        let (mut predicted, mut found) = (Vec::new(), CornerPairs::default());
        for f in frames.iter_mut() {
            let Some(image) = &f.undistorted else { continue };
            let t_r = f.entry.recorded_time_s;
            let nozzle = locate_nozzle(mount, &f.pairs.image_px, &f.pairs.plane_mm, self.params.mount.inlier_gate_mm)
                .ok()
                .map(|fix| fix.nozzle_mm)
                .filter(|n| check_plausible(ctx, *n, t_r).is_ok())
                .unwrap_or_else(|| ctx.trajectory.position_mm(t_r));
            let ready: Vec<PathCorner> =
                self.path_corners.iter().copied().filter(|c| self.is_young_and_ready(c.id, t_r)).collect();
            predict_corners_with_arms_into(mount, arms, nozzle, &ready, &mut predicted);
            ridge_pairs_into(image, &predicted, &vertex, self.params.predicted_shift_px, &mut found);
            f.pairs = merged(&found, &f.pairs);
        }
    }

    /// Drops the pass-1 pairs of corners that are too old or not yet readable.
    fn keep_young(&self, frames: &mut [FrameOutcome]) {
        for f in frames.iter_mut() {
            let t_r = f.entry.recorded_time_s;
            let mut kept = CornerPairs::default();
            for k in (0..f.pairs.len()).filter(|&k| self.is_young_and_ready(f.pairs.ids[k], t_r)) {
                kept.push(f.pairs.ids[k], f.pairs.image_px[k], f.pairs.plane_mm[k]);
            }
            f.pairs = kept;
        }
    }

    /// The rigid estimator's placement of one frame from its corners; true when it has
    /// none (it is then skipped, unless [`Self::place_by_recorded_time`] places it).
    fn place(&self, ctx: &FrameContext<'_>, f: &mut FrameOutcome, mount: &Homography) -> bool {
        if f.undistorted.is_none() {
            f.rigid = f.dlt.clone();
            return false;
        }
        let t_r = f.entry.recorded_time_s;
        match localise_rigid(ctx, mount, &f.pairs, t_r) {
            Ok(r) => {
                f.pair_used = r.fix.inliers.clone();
                let located =
                    Located::new(r.capture, r.fix.nozzle_mm, r.homography, r.fix.rms_mm, r.fix.inlier_count());
                f.rigid = located.map(|l| self.unless_parked(l, t_r));
                false
            }
            Err(skip) => {
                f.rigid = Err(skip.to_string());
                skip == FrameSkip::Mount(MountError::NoPairs)
            }
        }
    }

    /// Places the frames `cornerless` (no corner pair) by dead reckoning (module doc of
    /// [`super`]): the commanded position at the recorded time plus the median capture
    /// offset t̂_c − t_r of the frames placed from their corners, through the fitted
    /// mount, so that a constant capture delay the corners reveal is not left in.
    fn place_by_recorded_time(
        &self,
        ctx: &FrameContext<'_>,
        frames: &mut [FrameOutcome],
        cornerless: &[usize],
        mount: &Homography,
    ) {
        let offset_s = finite_median(
            frames.iter().filter_map(|f| f.rigid.as_ref().ok().map(|l| l.estimated_time_s() - f.entry.recorded_time_s)),
        );
        let offset_s = if offset_s.is_finite() { offset_s } else { 0.0 };
        for &i in cornerless {
            let t_r = frames[i].entry.recorded_time_s;
            let t_s = t_r + offset_s;
            let nozzle_mm = ctx.trajectory.position_mm(t_s);
            let located = Located::by_recorded_time(t_s, nozzle_mm, frame_homography(mount, nozzle_mm));
            frames[i].rigid = located.map(|l| self.unless_parked(l, t_r));
        }
    }
}

/// Largest distance between the plane points two pixel → plane maps give the pixels of
/// a 10-pixel grid over the image (mm).
fn largest_gap_mm(a: &Homography, b: &Homography, camera: &CameraModel) -> f64 {
    let mut worst: f64 = 0.0;
    for v in (0..camera.height_px).step_by(10) {
        for u in (0..camera.width_px).step_by(10) {
            let (p, q) = (a.apply([u as f64, v as f64]), b.apply([u as f64, v as f64]));
            worst = worst.max((p[0] - q[0]).hypot(p[1] - q[1]));
        }
    }
    worst
}

/// `primary` plus the pairs of `extra` whose corner it lacks.
fn merged(primary: &CornerPairs, extra: &CornerPairs) -> CornerPairs {
    let mut out = primary.clone();
    for k in (0..extra.len()).filter(|&k| !primary.ids.contains(&extra.ids[k])) {
        out.push(extra.ids[k], extra.image_px[k], extra.plane_mm[k]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Distortion;

    #[test]
    fn the_largest_gap_of_a_shifted_map_is_the_shift() {
        let camera = CameraModel::lepton35(Distortion::default());
        let h = camera.nominal_homography();
        let shifted = Homography { m: [[1.0, 0.0, 0.003], [0.0, 1.0, -0.004], [0.0, 0.0, 1.0]] }.then_after(&h);
        assert!((largest_gap_mm(&shifted, &h, &camera) - 0.005).abs() < 1e-12);
        assert_eq!(largest_gap_mm(&h, &h, &camera), 0.0);
    }

    #[test]
    fn merging_keeps_the_primary_pair_of_a_corner() {
        let mut a = CornerPairs::default();
        a.push(3, [1.0, 1.0], [0.0, 0.0]);
        let mut b = CornerPairs::default();
        b.push(3, [9.0, 9.0], [0.0, 0.0]);
        b.push(5, [2.0, 2.0], [1.0, 1.0]);
        let m = merged(&a, &b);
        assert_eq!(m.ids, [3, 5]);
        assert_eq!(m.image_px[0], [1.0, 1.0]);
    }
}
