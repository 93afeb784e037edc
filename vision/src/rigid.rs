//! One frame under a fitted rigid mount, our extension of paper 003 Sec. 2.3 (see
//! [`crate::mount`] for the model H(i) = T(n_i)·H_m and why).
//!
//! The paper pairs only the corners its detector finds in the 140-150 °C band and needs
//! four of them per frame. With the mount known, the pixel of every printed path corner
//! is predicted from the recorded time to about a pixel (3 ms of capture jitter is
//! 0.06 mm at 20 mm/s), so the vertex is searched directly from that prediction by
//! intersecting the two bead ridges ([`crate::vertex`]), for every corner whose arms are
//! still warmer than their surroundings, in the band or not; the search may move
//! `predicted_shift_px` at most. One such pair places the nozzle ([`locate_nozzle`]),
//! several are averaged after dropping those that disagree; the nozzle must lie within
//! `max_nozzle_offset_mm` of the commanded position at the recorded time, as for the
//! paper's H(i); the capture time is then eq. 30 with the paper's window.
//!
//! Which corners to search is the caller's choice. As a bead cools its heat spreads, and
//! near the vertex each arm's ridge is pulled towards the other arm: on the virtual
//! printer the vertex moves inwards by ~0.01 mm in the first half second and ~0.1 mm
//! after 2 s, so `thermal.monitor` searches only corners younger than `max_corner_age_s`.
//!
//! The ridge vertex holds the arm directions it is given ([`crate::vertex`]), so where
//! they come from matters. Taken from the fitted mount, they would close a loop: a mount
//! turned by δ turns the predicted arms by δ, which moves each vertex sideways by
//! s̄·δ/cos(θ/2) ≈ 2.6δ mm for a 45° corner, while the mount moves the predicted
//! vertices of two neighbouring zigzag corners (5 mm apart across the part) relative to
//! each other by about 5δ mm, the same way: the two corners of a frame then confirm the
//! turned mount: re-pairing from the fitted mount's arms and fitting again keeps
//! turning the mount (each time a little less) instead of settling.
//! [`predict_corners_with_arms_into`] therefore takes the positions from the fitted
//! mount and the arm directions from a fixed one, and the fit-and-re-pair rounds then
//! settle.
//!
//! Which fixed mount: first the nominal one, then, once, the mount those rounds settle
//! on (`thermal.monitor`'s localiser runs the rounds twice). The nominal mount's error,
//! up to ±0.5° of tilt and ±0.3° of roll, turns every arm of a print by up to
//! ~0.005 rad, which moves every vertex the same way by ~0.01 mm and the nozzles with
//! them: a capture-time error shared by every frame of the print, which follows the
//! true mount's tilt and roll, and which no interval computed within one print can see
//! (the thermal discrepancy engine's delay interval was too narrow across prints
//! because of it). Arms oriented by the settled mount, which is off by far less, remove
//! it. Only once: every further re-orientation moves the rotation the corners hardly
//! constrain a little further (the loop above), and against the virtual
//! printer's truth it carried the capture times past the true ones.

use crate::frame::ThermalFrame;
use crate::homography::Homography;
use crate::localize::{estimate_capture_time, CaptureTimeEstimate};
use crate::matching::{PredictedCorner, ARM_PROBE_MM};
use crate::mount::{frame_homography, locate_nozzle, MountError, NozzleFix};
use crate::pipeline::{check_plausible, CornerPairs, FrameContext, FrameSkip, PathCorner};
use crate::vertex::{vertex_from_ridges, CornerArms, VertexParams};

/// A frame localised under the rigid mount.
#[derive(Debug, Clone, PartialEq)]
pub struct RigidResult {
    /// The nozzle position n_i and the pairs it rests on.
    pub fix: NozzleFix,
    /// H(i) = T(n_i)·H_m: undistorted pixel → world plane mm.
    pub homography: Homography,
    /// Capture time (eq. 30).
    pub capture: CaptureTimeEstimate,
}

/// The predicted pixels of `corners` for a nozzle at `nozzle_mm` (world) through `mount`
/// (px = H_m⁻¹(corner − nozzle)), with each corner's arm probes
/// ([`PredictedCorner::arm_px`]) oriented and scaled as `arms_mount` images them (its
/// probes moved onto `mount`'s vertex pixel). The ridge vertex holds the arm directions
/// it is given, so taking them from a fixed mount (the nominal one) keeps the vertices
/// from following the fitted mount's rotation, which the corners of a zigzag hardly
/// constrain (see the module doc). Corners behind either camera are left out.
pub fn predict_corners_with_arms_into(
    mount: &Homography,
    arms_mount: &Homography,
    nozzle_mm: [f64; 2],
    corners: &[PathCorner],
    out: &mut Vec<PredictedCorner>,
) {
    out.clear();
    let (Some(inv), Some(arms_inv)) = (mount.inverse(), arms_mount.inverse()) else { return };
    let rel = |p: [f64; 2]| [p[0] - nozzle_mm[0], p[1] - nozzle_mm[1]];
    let finite = |p: [f64; 2]| p[0].is_finite() && p[1].is_finite();
    for c in corners {
        let (px, at) = (inv.apply(rel(c.vertex_mm)), arms_inv.apply(rel(c.vertex_mm)));
        if !finite(px) || !finite(at) {
            continue;
        }
        let probe = |d: [f64; 2]| {
            let q = arms_inv.apply(rel([c.vertex_mm[0] + ARM_PROBE_MM * d[0], c.vertex_mm[1] + ARM_PROBE_MM * d[1]]));
            [q[0] - at[0] + px[0], q[1] - at[1] + px[1]]
        };
        let arms = [probe(c.arm_dirs[0]), probe(c.arm_dirs[1])];
        let arm_px = (finite(arms[0]) && finite(arms[1])).then_some(arms);
        out.push(PredictedCorner { id: c.id, plane_mm: c.vertex_mm, px, arm_px });
    }
}

/// The ridge vertex of every predicted corner that has both arm probes, searched from its
/// predicted pixel with the shift limited to `max_shift_px`, appended to `out` (cleared).
pub fn ridge_pairs_into(
    image: &ThermalFrame,
    predicted: &[PredictedCorner],
    vertex: &VertexParams,
    max_shift_px: f64,
    out: &mut CornerPairs,
) {
    out.clear();
    let params = VertexParams { max_shift_px, ..*vertex };
    for pred in predicted {
        let Some(arm_px) = pred.arm_px else { continue };
        let Some(arms) = CornerArms::from_points(pred.px, arm_px, ARM_PROBE_MM) else { continue };
        if let Some(px) = vertex_from_ridges(image, pred.px, &arms, &params) {
            out.push(pred.id, px, pred.plane_mm);
        }
    }
}

/// Places the nozzle of one frame from its pairs under the mount H_m (`mount`), checks it
/// against the commanded position at `t_recorded_s` and estimates the capture time (eq. 30).
pub fn localise_rigid(
    ctx: &FrameContext<'_>,
    mount: &Homography,
    pairs: &CornerPairs,
    t_recorded_s: f64,
) -> Result<RigidResult, FrameSkip> {
    let p = &ctx.params;
    let fix =
        locate_nozzle(mount, &pairs.image_px, &pairs.plane_mm, p.mount.inlier_gate_mm).map_err(FrameSkip::Mount)?;
    check_plausible(ctx, fix.nozzle_mm, t_recorded_s)?;
    let capture = estimate_capture_time(&ctx.trajectory, fix.nozzle_mm, t_recorded_s, p.window_s);
    let homography = frame_homography(mount, fix.nozzle_mm);
    Ok(RigidResult { fix, homography, capture })
}

/// The mount's starting point: the nominal H0 anchored at the undistorted nozzle pixel
/// P_N⁽⁰⁾ (H0 maps it a mounting error away from the origin).
pub fn initial_mount(ctx: &FrameContext<'_>) -> Result<Homography, MountError> {
    let nozzle_px = ctx.undistorter.undistort_px(ctx.nozzle_px);
    crate::mount::anchored_at_nozzle(&ctx.h0, nozzle_px).ok_or(MountError::NozzleOffPlane)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraModel, Distortion, Undistorter};
    use crate::localize::TrajectoryView;
    use crate::pipeline::{predict_path_corners_into, PathCorner, PipelineParams};
    use crate::synth::{add_noise, render_raw_frame, HotPolyline};

    /// A zigzag fixed in the world with four interior corners of 68°-76°, a lukewarm bead
    /// (the ridges of corners outside the paper's band still show), no hot spot at the
    /// corners; the nozzle moves along +x at 20 mm/s; the true mount is off by 0.4° of
    /// tilt and 0.3 mm of aim, and H_m is that true mount (as [`crate::mount::fit_mount`]
    /// returns it from a sequence).
    struct Case {
        truth: CameraModel,
        nominal: CameraModel,
        t: Vec<f64>,
        x: Vec<f64>,
        y: Vec<f64>,
        scene: HotPolyline,
        t_capture_s: f64,
    }

    impl Case {
        /// The frame context of this case: nominal mount, the true nozzle pixel.
        fn context<'a>(&self, undistorter: &'a Undistorter, trajectory: TrajectoryView<'a>) -> FrameContext<'a> {
            FrameContext {
                undistorter,
                h0: self.nominal.nominal_homography(),
                nozzle_px: self.truth.plane_to_raw_px([0.0, 0.0]).unwrap(),
                trajectory,
                params: PipelineParams::paper_defaults(80.0),
            }
        }
    }

    fn case() -> Case {
        let distortion = Distortion { k1: -0.1, k2: 0.02, p1: 0.0005, p2: -0.0005 };
        let nominal = CameraModel::lepton35(distortion);
        let mut truth = nominal;
        truth.mount.tilt_deg = 45.4;
        truth.mount.look_at_mm = [0.3, -0.2];
        let t: Vec<f64> = (0..4000).map(|i| i as f64 * 0.001).collect();
        let (x, y) = t.iter().map(|&t| (-30.0 + 20.0 * t, 10.0)).unzip();
        let t_capture_s = 1.5043;
        let nozzle = [-30.0 + 20.0 * t_capture_s, 10.0];
        let rel = [[-10.0, 3.0], [-7.0, -1.5], [-4.0, 3.0], [-1.0, -1.5], [2.0, 3.0], [5.0, -1.0]];
        let scene = HotPolyline {
            vertices_mm: rel.iter().map(|p| [p[0] + nozzle[0] + 0.21, p[1] + nozzle[1]]).collect(),
            background_c: 60.0,
            bead_c: 95.0,
            bead_sigma_mm: 0.3,
            corner_excess_c: 0.0,
            corner_sigma_mm: 0.45,
        };
        Case { truth, nominal, t, x, y, scene, t_capture_s }
    }

    fn path_corners(v: &[[f64; 2]]) -> Vec<PathCorner> {
        let unit = |a: [f64; 2], b: [f64; 2]| {
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let l = dx.hypot(dy);
            [dx / l, dy / l]
        };
        (1..v.len() - 1)
            .map(|i| PathCorner {
                id: i as u32,
                vertex_mm: v[i],
                arm_dirs: [unit(v[i], v[i - 1]), unit(v[i], v[i + 1])],
            })
            .collect()
    }

    #[test]
    fn a_frame_with_known_translation_is_placed_from_all_or_one_of_its_corners() {
        let c = case();
        let traj = TrajectoryView::new(&c.t, &c.x, &c.y).unwrap();
        let nozzle_true = traj.position_mm(c.t_capture_s);
        let mut raw = render_raw_frame(&c.truth, nozzle_true, |p| c.scene.temp_c(p));
        add_noise(&mut raw, 0.05, 3);
        let undistorter = Undistorter::new(&c.nominal).unwrap();
        let image = undistorter.undistort(&raw).unwrap();
        let ctx = c.context(&undistorter, traj);
        let mount = c.truth.nominal_homography();
        // Recorded 4.3 ms early: predictions are 0.09 mm (0.6 px) off, the ridges fix that.
        let t_recorded_s = 1.5;
        let mut predicted = Vec::new();
        predict_path_corners_into(
            &mount,
            traj.position_mm(t_recorded_s),
            &path_corners(&c.scene.vertices_mm),
            &mut predicted,
        );
        assert_eq!(predicted.len(), 4);
        let mut pairs = CornerPairs::default();
        ridge_pairs_into(&image, &predicted, &VertexParams::defaults(), 3.0, &mut pairs);
        assert_eq!(pairs.len(), 4, "every corner in view is placed on its ridges");
        let res = localise_rigid(&ctx, &mount, &pairs, t_recorded_s).unwrap();
        let err_mm = (res.fix.nozzle_mm[0] - nozzle_true[0]).hypot(res.fix.nozzle_mm[1] - nozzle_true[1]);
        // The ridges of a symmetric synthetic bead are centred on the path, so the
        // vertices are good to a few micrometres (0.003 mm here): 0.01 mm is 0.07 px.
        assert!(err_mm < 0.01, "nozzle off by {err_mm} mm");
        // 0.01 mm along a 20 mm/s path is 0.5 ms.
        assert!((res.capture.t_s - c.t_capture_s).abs() < 0.0005, "t {}", res.capture.t_s);
        let back = res.homography.apply(undistorter.undistort_px(ctx.nozzle_px));
        assert!((back[0] - res.fix.nozzle_mm[0]).hypot(back[1] - res.fix.nozzle_mm[1]) < 1e-9, "eq. 29");
        // One corner alone places the nozzle too (the paper's DLT needs four).
        for k in 0..pairs.len() {
            let one = CornerPairs {
                ids: vec![pairs.ids[k]],
                image_px: vec![pairs.image_px[k]],
                plane_mm: vec![pairs.plane_mm[k]],
            };
            let res = localise_rigid(&ctx, &mount, &one, t_recorded_s).unwrap();
            let err_mm = (res.fix.nozzle_mm[0] - nozzle_true[0]).hypot(res.fix.nozzle_mm[1] - nozzle_true[1]);
            assert!(err_mm < 0.01, "corner {}: nozzle off by {err_mm} mm", pairs.ids[k]);
        }
    }

    #[test]
    fn corners_are_placed_by_the_mount_and_oriented_by_the_arms_mount() {
        let c = case();
        let corners = path_corners(&c.scene.vertices_mm);
        let nozzle = [-1.0, 10.0];
        let (mount, nominal) = (c.truth.nominal_homography(), c.nominal.nominal_homography());
        let (mut same, mut plain, mut mixed, mut by_nominal) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        // With one mount for both it is the plain prediction.
        predict_corners_with_arms_into(&mount, &mount, nozzle, &corners, &mut same);
        predict_path_corners_into(&mount, nozzle, &corners, &mut plain);
        assert_eq!(same.len(), corners.len());
        for (a, b) in same.iter().zip(&plain) {
            assert_eq!(a.id, b.id);
            assert!((a.px[0] - b.px[0]).hypot(a.px[1] - b.px[1]) < 1e-9);
            for k in 0..2 {
                let (p, q) = (a.arm_px.unwrap()[k], b.arm_px.unwrap()[k]);
                assert!((p[0] - q[0]).hypot(p[1] - q[1]) < 1e-9);
            }
        }
        // Mixed: the vertex pixel of `mount`, the arm probes of `nominal` moved onto it.
        predict_corners_with_arms_into(&mount, &nominal, nozzle, &corners, &mut mixed);
        predict_path_corners_into(&nominal, nozzle, &corners, &mut by_nominal);
        for ((m, p), n) in mixed.iter().zip(&plain).zip(&by_nominal) {
            assert!((m.px[0] - p.px[0]).hypot(m.px[1] - p.px[1]) < 1e-9);
            for k in 0..2 {
                let (a, b) = (m.arm_px.unwrap()[k], n.arm_px.unwrap()[k]);
                let (da, db) = ([a[0] - m.px[0], a[1] - m.px[1]], [b[0] - n.px[0], b[1] - n.px[1]]);
                assert!((da[0] - db[0]).hypot(da[1] - db[1]) < 1e-9, "corner {} arm {k}", m.id);
            }
        }
        assert!(mixed.iter().zip(&by_nominal).any(|(m, n)| (m.px[0] - n.px[0]).abs() > 0.5), "the mounts differ");
    }

    #[test]
    fn a_frame_without_pairs_or_far_from_the_commanded_path_is_skipped() {
        let c = case();
        let traj = TrajectoryView::new(&c.t, &c.x, &c.y).unwrap();
        let undistorter = Undistorter::new(&c.nominal).unwrap();
        let ctx = c.context(&undistorter, traj);
        let mount = c.truth.nominal_homography();
        let none = localise_rigid(&ctx, &mount, &CornerPairs::default(), 1.5).unwrap_err();
        assert_eq!(none, FrameSkip::Mount(MountError::NoPairs));
        // A corner paired with a vertex 3 mm away puts the nozzle 3 mm off: implausible.
        let nozzle = traj.position_mm(1.5);
        let px = c.truth.plane_to_undistorted_px([2.0, 1.0]).unwrap();
        let mut pairs = CornerPairs::default();
        pairs.push(0, px, [nozzle[0] + 5.0, nozzle[1] + 1.0]);
        let far = localise_rigid(&ctx, &mount, &pairs, 1.5).unwrap_err();
        assert!(matches!(far, FrameSkip::Implausible { offset_mm } if (offset_mm - 3.0).abs() < 1e-6), "{far:?}");
    }
}
