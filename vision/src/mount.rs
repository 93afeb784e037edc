//! Rigid-mount localisation: our extension of paper 003 Sec. 2.3 (eqs 27 and 29).
//!
//! **What the paper does.** Every frame i gets its own homography H(i) (undistorted
//! pixel → plane), estimated from at least four corner pairs by DLT (eq. 27, see
//! [`crate::homography`]); the nozzle is P_N,i = H(i)·P_N⁽⁰⁾ (eq. 29), with the nozzle
//! pixel P_N⁽⁰⁾ marked once. A frame with fewer than four corners is not localised, and a
//! general 8-parameter H(i) from four to six corners on one side of the image
//! extrapolates their noise onto the nozzle.
//!
//! **What we add, and why.** The camera is rigid on the nozzle and the head only
//! translates, so every frame sees the plane through the same mount:
//! H(i) = T(n_i)·H_m, with T(n) the translation by the nozzle position n_i (world mm)
//! and H_m the mount homography (undistorted pixel → plane mm relative to the nozzle).
//! Per frame only n_i is unknown, two numbers, so a single corner pair places the
//! nozzle; H_m is estimated once from the pairs of all frames (a self-calibration of the
//! mount from the sequence, in the spirit of the paper marking P_N⁽⁰⁾ once). The fixed
//! mounting error is absorbed by H_m; per-frame vibration of the mount is not modelled
//! and shows as noise in n_i, as it does in the paper's H(i).
//!
//! Parametrisation: H_m = K·T(−P_N⁽⁰⁾) with K = [[a, b, 0], [c, d, 0], [g, h, 1]], so
//! H_m maps P_N⁽⁰⁾ to the origin by construction and n_i = H(i)·P_N⁽⁰⁾ is eq. 29. This
//! also fixes the gauge (a translation of H_m would otherwise trade against every n_i):
//! six unknowns, the eight of a homography less the two that eq. 29 pins.
//!
//! Fit ([`fit_mount`]): minimise Σ_i Σ_k ‖c_ik − n_i − H_m(x_ik)‖² over H_m and all n_i
//! (x_ik: image point, c_ik: its CAD vertex). For a given H_m the best n_i is the mean of
//! c_ik − H_m(x_ik) over frame i, so the n_i are eliminated (variable projection: the
//! residuals and Jacobian rows are centred per frame) and Levenberg-Marquardt runs on the
//! six mount parameters, starting from the nominal H0. Frames with one pair say nothing
//! about H_m and are left out of the fit. Robustness: after each fit every frame's
//! translation is re-estimated robustly ([`locate_nozzle`]'s rule), pairs farther than
//! max(gate, 3 × the median residual) from it are dropped, and the fit is repeated until
//! the set of pairs no longer changes.

use faer::prelude::Solve;
use faer::{Mat, Side};

use crate::homography::Homography;

/// Unknowns of the mount: a homography's eight less the two fixed by H_m(P_N⁽⁰⁾) = 0.
pub const MOUNT_UNKNOWNS: usize = 6;

/// Settings of [`fit_mount`] and [`locate_nozzle`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountParams {
    /// A pair is an inlier when it lies within this distance of its frame's translation (mm).
    pub inlier_gate_mm: f64,
    /// Levenberg-Marquardt iterations per fit.
    pub max_iters: usize,
    /// Fit / reject rounds.
    pub max_rounds: usize,
    /// Equations (two per pair beyond the first of each frame) the fit needs at least.
    pub min_equations: usize,
}

impl MountParams {
    /// Sized for corner vertices good to a few hundredths of a millimetre: a 0.15 mm gate
    /// (one pixel near the nozzle) keeps them and drops a wrong pairing, which is off by a
    /// bead width or more; 24 equations are four times the unknowns.
    pub fn defaults() -> Self {
        Self { inlier_gate_mm: 0.15, max_iters: 100, max_rounds: 10, min_equations: 4 * MOUNT_UNKNOWNS }
    }
}

/// One frame's corner pairs: undistorted image points and their CAD vertices (world mm).
#[derive(Debug, Clone, Copy)]
pub struct FramePairs<'a> {
    /// Undistorted pixels.
    pub image_px: &'a [[f64; 2]],
    /// Plane points (world mm), one per image point.
    pub plane_mm: &'a [[f64; 2]],
}

/// A fitted mount.
#[derive(Debug, Clone, PartialEq)]
pub struct MountFit {
    /// H_m: undistorted pixel → plane mm relative to the nozzle; maps P_N⁽⁰⁾ to the origin.
    pub mount: Homography,
    /// Per frame, per pair: kept by the last round.
    pub inliers: Vec<Vec<bool>>,
    /// RMS distance of the kept pairs from their frame's translation (mm).
    pub rms_mm: f64,
    /// Kept pairs in frames with at least two kept pairs (those that shape H_m).
    pub pairs_used: usize,
    /// Frames with at least two kept pairs.
    pub frames_used: usize,
}

/// A frame's nozzle position under a known mount.
#[derive(Debug, Clone, PartialEq)]
pub struct NozzleFix {
    /// n_i = H(i)·P_N⁽⁰⁾ (world mm).
    pub nozzle_mm: [f64; 2],
    /// Per pair: used in the mean.
    pub inliers: Vec<bool>,
    /// RMS distance of the used pairs from n_i (mm); 0 for a single pair.
    pub rms_mm: f64,
}

impl NozzleFix {
    /// Number of pairs used.
    pub fn inlier_count(&self) -> usize {
        self.inliers.iter().filter(|&&k| k).count()
    }
}

/// Why the mount or a nozzle position could not be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MountError {
    /// A frame's two point slices differ in length.
    #[error("frame {frame}: {image} image points but {plane} plane points")]
    LengthMismatch {
        /// Frame index in the caller's slice.
        frame: usize,
        /// Image points.
        image: usize,
        /// Plane points.
        plane: usize,
    },
    /// Too few pairs in frames with at least two of them.
    #[error("too few corner pairs to fit the mount: {found} equations, {needed} needed")]
    TooFewPairs {
        /// Equations available (two per pair beyond the first of each frame).
        found: usize,
        /// Equations needed.
        needed: usize,
    },
    /// The starting homography sends the nozzle pixel to infinity.
    #[error("the homography does not map the nozzle pixel onto the plane")]
    NozzleOffPlane,
    /// The normal equations could not be solved (the pairs do not determine the mount).
    #[error("the mount is not determined by the pairs (singular normal equations)")]
    Singular,
    /// No finite pair.
    #[error("no corner pairs")]
    NoPairs,
    /// The pairs disagree on the nozzle position by more than the gate.
    #[error("corner pairs disagree on the nozzle position: the nearest is {spread_mm:.3} mm from their centre")]
    Inconsistent {
        /// Distance of the nearest pair's position from the central estimate (mm).
        spread_mm: f64,
    },
}

/// Fits H_m to the pairs of all frames, starting from `initial` (e.g. the nominal H0;
/// its translation is irrelevant), with P_N⁽⁰⁾ = `nozzle_px` (undistorted).
pub fn fit_mount(
    frames: &[FramePairs<'_>],
    nozzle_px: [f64; 2],
    initial: &Homography,
    params: &MountParams,
) -> Result<MountFit, MountError> {
    for (frame, f) in frames.iter().enumerate() {
        if f.image_px.len() != f.plane_mm.len() {
            return Err(MountError::LengthMismatch { frame, image: f.image_px.len(), plane: f.plane_mm.len() });
        }
    }
    let mut model = MountModel::from_homography(initial, nozzle_px).ok_or(MountError::NozzleOffPlane)?;
    let mut inliers: Vec<Vec<bool>> = frames.iter().map(|f| finite_pairs(f)).collect();
    for _ in 0..params.max_rounds.max(1) {
        let found = equations(&inliers);
        if found < params.min_equations {
            return Err(MountError::TooFewPairs { found, needed: params.min_equations });
        }
        model = levenberg_marquardt(model, frames, &inliers, params.max_iters)?;
        let next = classify(&model, frames, &inliers, params.inlier_gate_mm);
        if next == inliers {
            break;
        }
        inliers = next;
    }
    Ok(summarise(&model, frames, inliers))
}

/// n_i for one frame under the mount H_m: the mean of c_k − H_m(x_k) over the pairs that
/// agree. One pair: its position. Two: their mean, unless they are more than twice the
/// gate apart. Three or more: pairs within the gate of the coordinate-wise median, then
/// within the gate of their mean.
pub fn locate_nozzle(
    mount: &Homography,
    image_px: &[[f64; 2]],
    plane_mm: &[[f64; 2]],
    gate_mm: f64,
) -> Result<NozzleFix, MountError> {
    if image_px.len() != plane_mm.len() {
        return Err(MountError::LengthMismatch { frame: 0, image: image_px.len(), plane: plane_mm.len() });
    }
    let offsets: Vec<[f64; 2]> = image_px.iter().zip(plane_mm).map(|(x, c)| sub(*c, mount.apply(*x))).collect();
    let (nozzle_mm, inliers) = robust_translation(&offsets, gate_mm)?;
    let rms_mm = rms_about(&offsets, &inliers, nozzle_mm);
    Ok(NozzleFix { nozzle_mm, inliers, rms_mm })
}

/// H(i) = T(n_i)·H_m: undistorted pixel → world plane mm for a nozzle at `nozzle_mm`.
pub fn frame_homography(mount: &Homography, nozzle_mm: [f64; 2]) -> Homography {
    translation(nozzle_mm).then_after(mount)
}

/// `h` shifted on the plane so that it maps `nozzle_px` to the origin (T(−h(P_N⁽⁰⁾))·h);
/// None when it maps it to infinity.
pub fn anchored_at_nozzle(h: &Homography, nozzle_px: [f64; 2]) -> Option<Homography> {
    let at = h.apply(nozzle_px);
    (at[0].is_finite() && at[1].is_finite()).then(|| translation([-at[0], -at[1]]).then_after(h))
}

/// The six mount parameters (a, b, c, d, g, h) and the nozzle pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
struct MountModel {
    p: [f64; MOUNT_UNKNOWNS],
    nozzle_px: [f64; 2],
}

impl MountModel {
    /// The parameters of `h` anchored at the nozzle: K = H_m·T(P_N⁽⁰⁾), scaled to K₃₃ = 1.
    fn from_homography(h: &Homography, nozzle_px: [f64; 2]) -> Option<Self> {
        let k = anchored_at_nozzle(h, nozzle_px)?.then_after(&translation(nozzle_px));
        let m = &k.m;
        let finite = m.iter().flatten().all(|v| v.is_finite());
        (finite && (m[2][2] - 1.0).abs() < 1e-9)
            .then_some(Self { p: [m[0][0], m[0][1], m[1][0], m[1][1], m[2][0], m[2][1]], nozzle_px })
    }

    /// H_m = K·T(−P_N⁽⁰⁾).
    fn homography(&self) -> Homography {
        let [a, b, c, d, g, h] = self.p;
        let k = Homography { m: [[a, b, 0.0], [c, d, 0.0], [g, h, 1.0]] };
        k.then_after(&translation([-self.nozzle_px[0], -self.nozzle_px[1]]))
    }

    /// H_m(x) and its derivatives by the six parameters (rows: plane x, plane y).
    #[inline]
    fn apply_with_jacobian(&self, x: [f64; 2]) -> ([f64; 2], [[f64; MOUNT_UNKNOWNS]; 2]) {
        let [a, b, c, d, g, h] = self.p;
        let q = [x[0] - self.nozzle_px[0], x[1] - self.nozzle_px[1]];
        let w = 1.0 + g * q[0] + h * q[1];
        let f = [(a * q[0] + b * q[1]) / w, (c * q[0] + d * q[1]) / w];
        let (qw0, qw1) = (q[0] / w, q[1] / w);
        let jx = [qw0, qw1, 0.0, 0.0, -f[0] * qw0, -f[0] * qw1];
        let jy = [0.0, 0.0, qw0, qw1, -f[1] * qw0, -f[1] * qw1];
        (f, [jx, jy])
    }

    fn stepped(&self, delta: &[f64; MOUNT_UNKNOWNS]) -> Self {
        let mut p = self.p;
        for (v, d) in p.iter_mut().zip(delta) {
            *v += d;
        }
        Self { p, ..*self }
    }
}

/// Normal equations of the centred residuals over the inlier pairs of frames with ≥ 2 of them.
struct Normal {
    jtj: [[f64; MOUNT_UNKNOWNS]; MOUNT_UNKNOWNS],
    jtr: [f64; MOUNT_UNKNOWNS],
    cost: f64,
}

/// Accumulates the normal equations: per frame, the residual c − H_m(x) and its
/// Jacobian, both minus their frame means (the eliminated translation).
fn normal_equations(model: &MountModel, frames: &[FramePairs<'_>], inliers: &[Vec<bool>]) -> Normal {
    let mut out = Normal { jtj: [[0.0; MOUNT_UNKNOWNS]; MOUNT_UNKNOWNS], jtr: [0.0; MOUNT_UNKNOWNS], cost: 0.0 };
    for (f, keep) in frames.iter().zip(inliers) {
        let m = keep.iter().filter(|&&k| k).count();
        if m < 2 {
            continue;
        }
        let (mut mean_r, mut mean_j) = ([0.0; 2], [[0.0; MOUNT_UNKNOWNS]; 2]);
        for k in (0..keep.len()).filter(|&k| keep[k]) {
            let (r, j) = residual(model, f, k);
            for a in 0..2 {
                mean_r[a] += r[a] / m as f64;
                for (s, v) in mean_j[a].iter_mut().zip(&j[a]) {
                    *s += v / m as f64;
                }
            }
        }
        for k in (0..keep.len()).filter(|&k| keep[k]) {
            let (r, j) = residual(model, f, k);
            for a in 0..2 {
                let rc = r[a] - mean_r[a];
                let mut jc = [0.0; MOUNT_UNKNOWNS];
                for u in 0..MOUNT_UNKNOWNS {
                    jc[u] = j[a][u] - mean_j[a][u];
                }
                out.cost += rc * rc;
                for u in 0..MOUNT_UNKNOWNS {
                    out.jtr[u] += jc[u] * rc;
                    for v in 0..MOUNT_UNKNOWNS {
                        out.jtj[u][v] += jc[u] * jc[v];
                    }
                }
            }
        }
    }
    out
}

/// Residual c_k − H_m(x_k) of pair k and the Jacobian of H_m(x_k) (the residual's is its negative).
#[inline]
fn residual(model: &MountModel, f: &FramePairs<'_>, k: usize) -> ([f64; 2], [[f64; MOUNT_UNKNOWNS]; 2]) {
    let (h, j) = model.apply_with_jacobian(f.image_px[k]);
    (sub(f.plane_mm[k], h), j)
}

/// Levenberg-Marquardt with Marquardt's diagonal scaling on the centred residuals.
/// Residual r = e − ē falls by J_c·δ for a step δ, so the step solves
/// (J_cᵀJ_c + λ·diag)·δ = J_cᵀ r.
fn levenberg_marquardt(
    mut model: MountModel,
    frames: &[FramePairs<'_>],
    inliers: &[Vec<bool>],
    max_iters: usize,
) -> Result<MountModel, MountError> {
    let mut normal = normal_equations(&model, frames, inliers);
    let mut lambda = 1e-3;
    for _ in 0..max_iters {
        let delta = solve_damped(&normal, lambda).ok_or(MountError::Singular)?;
        let trial = model.stepped(&delta);
        let next = normal_equations(&trial, frames, inliers);
        if next.cost.is_finite() && next.cost <= normal.cost {
            let converged = normal.cost - next.cost <= 1e-14 * normal.cost.max(1e-30)
                || delta.iter().zip(&model.p).all(|(d, p)| d.abs() <= 1e-12 * (p.abs() + 1e-9));
            (model, normal, lambda) = (trial, next, (lambda * 0.1).max(1e-12));
            if converged {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
        }
    }
    Ok(model)
}

/// Solves (JᵀJ + λ·diag(JᵀJ))·δ = Jᵀr by Cholesky; None when not positive definite.
fn solve_damped(normal: &Normal, lambda: f64) -> Option<[f64; MOUNT_UNKNOWNS]> {
    let n = MOUNT_UNKNOWNS;
    let a = Mat::from_fn(n, n, |r, c| normal.jtj[r][c] * if r == c { 1.0 + lambda } else { 1.0 });
    let b = Mat::from_fn(n, 1, |r, _| normal.jtr[r]);
    let x = a.llt(Side::Lower).ok()?.solve(&b);
    let mut out = [0.0f64; MOUNT_UNKNOWNS];
    for (r, v) in out.iter_mut().enumerate() {
        *v = x[(r, 0)];
    }
    out.iter().all(|v| v.is_finite()).then_some(out)
}

/// The next inlier sets: per frame a robust translation from the current inliers (all
/// pairs when none is left), then every pair within max(gate, 3 × median residual) of it.
fn classify(model: &MountModel, frames: &[FramePairs<'_>], inliers: &[Vec<bool>], gate_mm: f64) -> Vec<Vec<bool>> {
    let h = model.homography();
    let offsets: Vec<Vec<[f64; 2]>> =
        frames.iter().map(|f| f.image_px.iter().zip(f.plane_mm).map(|(x, c)| sub(*c, h.apply(*x))).collect()).collect();
    let centres: Vec<Option<[f64; 2]>> = offsets
        .iter()
        .zip(inliers)
        .map(|(o, keep)| {
            let kept: Vec<[f64; 2]> = o.iter().zip(keep).filter(|(_, &k)| k).map(|(p, _)| *p).collect();
            let pool = if kept.is_empty() { o.clone() } else { kept };
            robust_translation(&pool, gate_mm).ok().map(|(n, _)| n)
        })
        .collect();
    let mut residuals: Vec<f64> = Vec::new();
    for ((o, keep), centre) in offsets.iter().zip(inliers).zip(&centres) {
        if let Some(n) = centre.filter(|_| o.len() >= 2) {
            residuals.extend(o.iter().zip(keep).filter(|(_, &k)| k).map(|(p, _)| dist(*p, n)));
        }
    }
    let threshold = gate_mm.max(3.0 * median(&mut residuals).unwrap_or(0.0));
    offsets
        .iter()
        .zip(&centres)
        .map(|(o, centre)| {
            o.iter().map(|p| centre.is_some_and(|n| p[0].is_finite() && dist(*p, n) <= threshold)).collect()
        })
        .collect()
}

/// The fit's summary under the final inlier sets.
fn summarise(model: &MountModel, frames: &[FramePairs<'_>], inliers: Vec<Vec<bool>>) -> MountFit {
    let mount = model.homography();
    let (mut sum2, mut pairs_used, mut frames_used) = (0.0, 0usize, 0usize);
    for (f, keep) in frames.iter().zip(&inliers) {
        let m = keep.iter().filter(|&&k| k).count();
        if m < 2 {
            continue;
        }
        let offsets: Vec<[f64; 2]> = f.image_px.iter().zip(f.plane_mm).map(|(x, c)| sub(*c, mount.apply(*x))).collect();
        let mean = mean_of(&offsets, keep);
        sum2 += offsets.iter().zip(keep).filter(|(_, &k)| k).map(|(p, _)| dist(*p, mean).powi(2)).sum::<f64>();
        pairs_used += m;
        frames_used += 1;
    }
    let rms_mm = if pairs_used == 0 { f64::NAN } else { (sum2 / pairs_used as f64).sqrt() };
    MountFit { mount, inliers, rms_mm, pairs_used, frames_used }
}

/// The rule of [`locate_nozzle`] on plane offsets c − H_m(x).
fn robust_translation(offsets: &[[f64; 2]], gate_mm: f64) -> Result<([f64; 2], Vec<bool>), MountError> {
    let finite: Vec<bool> = offsets.iter().map(|p| p[0].is_finite() && p[1].is_finite()).collect();
    let count = finite.iter().filter(|&&k| k).count();
    match count {
        0 => Err(MountError::NoPairs),
        1 | 2 => {
            let n = mean_of(offsets, &finite);
            let spread_mm =
                offsets.iter().zip(&finite).filter(|(_, &k)| k).map(|(p, _)| dist(*p, n)).fold(0.0, f64::max);
            if spread_mm > gate_mm {
                return Err(MountError::Inconsistent { spread_mm });
            }
            Ok((n, finite))
        }
        _ => {
            let pick = |axis: usize| {
                let mut v: Vec<f64> = offsets.iter().zip(&finite).filter(|(_, &k)| k).map(|(p, _)| p[axis]).collect();
                median(&mut v).unwrap_or(f64::NAN)
            };
            let mut n = [pick(0), pick(1)];
            let mut keep = finite.clone();
            for _ in 0..2 {
                keep = offsets.iter().zip(&finite).map(|(p, &f)| f && dist(*p, n) <= gate_mm).collect();
                if !keep.iter().any(|&k| k) {
                    let spread_mm =
                        offsets.iter().filter(|p| p[0].is_finite()).map(|p| dist(*p, n)).fold(f64::INFINITY, f64::min);
                    return Err(MountError::Inconsistent { spread_mm });
                }
                n = mean_of(offsets, &keep);
            }
            Ok((n, keep))
        }
    }
}

/// Pairs whose four coordinates are finite.
fn finite_pairs(f: &FramePairs<'_>) -> Vec<bool> {
    f.image_px.iter().zip(f.plane_mm).map(|(x, c)| x.iter().chain(c).all(|v| v.is_finite())).collect()
}

/// Equations the inlier sets give: two per pair beyond the first in each frame.
fn equations(inliers: &[Vec<bool>]) -> usize {
    inliers.iter().map(|k| 2 * k.iter().filter(|&&x| x).count().saturating_sub(1)).sum()
}

fn translation(d: [f64; 2]) -> Homography {
    Homography { m: [[1.0, 0.0, d[0]], [0.0, 1.0, d[1]], [0.0, 0.0, 1.0]] }
}

fn mean_of(points: &[[f64; 2]], keep: &[bool]) -> [f64; 2] {
    let (mut s, mut n) = ([0.0; 2], 0usize);
    for (p, _) in points.iter().zip(keep).filter(|(_, &k)| k) {
        s = [s[0] + p[0], s[1] + p[1]];
        n += 1;
    }
    [s[0] / n as f64, s[1] / n as f64]
}

fn rms_about(points: &[[f64; 2]], keep: &[bool], centre: [f64; 2]) -> f64 {
    let d2: Vec<f64> = points.iter().zip(keep).filter(|(_, &k)| k).map(|(p, _)| dist(*p, centre).powi(2)).collect();
    (d2.iter().sum::<f64>() / d2.len().max(1) as f64).sqrt()
}

fn median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 { values[n / 2] } else { 0.5 * (values[n / 2 - 1] + values[n / 2]) })
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{CameraModel, Distortion};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// The nominal Lepton mount and a true one off by 0.4° of tilt, 0.2 mm of height and
    /// (0.25, −0.2) mm of aim: the mounting error the fit must absorb.
    fn cameras() -> (CameraModel, CameraModel) {
        let nominal = CameraModel::lepton35(Distortion::default());
        let mut truth = nominal;
        truth.mount.tilt_deg = 45.4;
        truth.mount.height_mm = 14.7;
        truth.mount.look_at_mm = [0.25, -0.2];
        (nominal, truth)
    }

    /// Frames of a nozzle sweeping over a 5 mm grid of corners (x 0-40, y −5-15 mm); frame
    /// i pairs up to `per_frame[i % len]` grid points that the true camera sees, with
    /// Gaussian pixel noise of `noise_px`.
    struct Synthetic {
        image: Vec<Vec<[f64; 2]>>,
        plane: Vec<Vec<[f64; 2]>>,
        nozzles: Vec<[f64; 2]>,
    }

    impl Synthetic {
        fn new(truth: &CameraModel, frames: usize, per_frame: &[usize], noise_px: f64) -> Self {
            let grid: Vec<[f64; 2]> =
                (0..9).flat_map(|i| (0..5).map(move |j| [5.0 * i as f64, 5.0 * j as f64 - 5.0])).collect();
            let noise = Normal::new(0.0, noise_px.max(1e-300)).unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(17);
            let mut out = Synthetic { image: Vec::new(), plane: Vec::new(), nozzles: Vec::new() };
            for i in 0..frames {
                let nozzle = [2.0 + 36.0 * i as f64 / (frames - 1) as f64, 5.0 + 6.0 * (i as f64).sin()];
                let visible: Vec<([f64; 2], [f64; 2])> = grid
                    .iter()
                    .filter_map(|c| truth.plane_to_undistorted_px(sub(*c, nozzle)).map(|px| (px, *c)))
                    .filter(|(px, _)| (8.0..152.0).contains(&px[0]) && (6.0..114.0).contains(&px[1]))
                    .collect();
                let take = per_frame[i % per_frame.len()].min(visible.len());
                let start = if visible.is_empty() { 0 } else { i % visible.len() };
                let chosen: Vec<_> = visible.iter().cycle().skip(start).take(take).collect();
                let jitter = |v: f64, rng: &mut ChaCha8Rng| if noise_px > 0.0 { v + noise.sample(rng) } else { v };
                out.image
                    .push(chosen.iter().map(|(px, _)| [jitter(px[0], &mut rng), jitter(px[1], &mut rng)]).collect());
                out.plane.push(chosen.iter().map(|(_, c)| *c).collect());
                out.nozzles.push(nozzle);
            }
            out
        }

        fn pairs(&self) -> Vec<FramePairs<'_>> {
            self.image.iter().zip(&self.plane).map(|(i, p)| FramePairs { image_px: i, plane_mm: p }).collect()
        }
    }

    /// Largest distance between two pixel → plane maps over the image (mm).
    fn max_gap_mm(a: &Homography, b: &Homography) -> f64 {
        let mut worst: f64 = 0.0;
        for u in (10..=150).step_by(20) {
            for v in (10..=110).step_by(20) {
                let (p, q) = (a.apply([u as f64, v as f64]), b.apply([u as f64, v as f64]));
                worst = worst.max(dist(p, q));
            }
        }
        worst
    }

    fn true_mount(truth: &CameraModel) -> (Homography, [f64; 2]) {
        let nozzle_px = truth.plane_to_undistorted_px([0.0, 0.0]).unwrap();
        (truth.nominal_homography(), nozzle_px)
    }

    #[test]
    fn the_parametrisation_maps_the_nozzle_pixel_to_the_origin_and_round_trips() {
        let (nominal, truth) = cameras();
        let (h_true, nozzle_px) = true_mount(&truth);
        let model = MountModel::from_homography(&nominal.nominal_homography(), nozzle_px).unwrap();
        let at = model.homography().apply(nozzle_px);
        assert!(at[0].abs() < 1e-12 && at[1].abs() < 1e-12, "{at:?}");
        // The true H0 already maps its nozzle pixel to 0: its parameters give it back.
        let back = MountModel::from_homography(&h_true, nozzle_px).unwrap().homography();
        assert!(max_gap_mm(&back, &h_true) < 1e-10);
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        let (nominal, truth) = cameras();
        let (_, nozzle_px) = true_mount(&truth);
        let model = MountModel::from_homography(&nominal.nominal_homography(), nozzle_px).unwrap();
        let x = [23.0, 91.0];
        let (f0, j) = model.apply_with_jacobian(x);
        for u in 0..MOUNT_UNKNOWNS {
            let step = 1e-7 * model.p[u].abs().max(1e-3);
            let mut delta = [0.0; MOUNT_UNKNOWNS];
            delta[u] = step;
            let (f1, _) = model.stepped(&delta).apply_with_jacobian(x);
            for a in 0..2 {
                let numeric = (f1[a] - f0[a]) / step;
                assert!(
                    (numeric - j[a][u]).abs() < 1e-5 * (1.0 + j[a][u].abs()),
                    "d{a}/dp{u}: {numeric} vs {}",
                    j[a][u]
                );
            }
        }
    }

    #[test]
    fn the_fit_recovers_a_known_mount_from_one_to_five_corners_per_frame() {
        // Noiseless pairs through the true (mis-mounted) camera; the fit starts from the
        // nominal mount, 0.4° and a few tenths of a millimetre off. Frames with one pair
        // add nothing to the fit, the others pin the six parameters exactly.
        let (nominal, truth) = cameras();
        let (h_true, nozzle_px) = true_mount(&truth);
        let data = Synthetic::new(&truth, 30, &[1, 2, 3, 5], 0.0);
        let params = MountParams::defaults();
        let fit = fit_mount(&data.pairs(), nozzle_px, &nominal.nominal_homography(), &params).unwrap();
        assert!(max_gap_mm(&nominal.nominal_homography(), &h_true) > 0.3, "the start is really off");
        assert!(max_gap_mm(&fit.mount, &h_true) < 1e-8, "gap {}", max_gap_mm(&fit.mount, &h_true));
        assert!(fit.rms_mm < 1e-9 && fit.inliers.iter().flatten().all(|&k| k));
        // Every frame, even one with a single corner, places the nozzle exactly (eq. 29).
        for i in 0..30 {
            let fix = locate_nozzle(&fit.mount, &data.image[i], &data.plane[i], params.inlier_gate_mm).unwrap();
            assert!(dist(fix.nozzle_mm, data.nozzles[i]) < 1e-8, "frame {i}");
            let h_i = frame_homography(&fit.mount, fix.nozzle_mm);
            let n = h_i.apply(nozzle_px);
            assert!(dist(n, fix.nozzle_mm) < 1e-9, "H(i)·P_N = n_i");
        }
    }

    #[test]
    fn wrong_pairings_are_dropped_and_the_mount_is_still_exact() {
        let (nominal, truth) = cameras();
        let (h_true, nozzle_px) = true_mount(&truth);
        let mut data = Synthetic::new(&truth, 30, &[3, 4, 5], 0.0);
        // One corner in every third frame paired with the wrong CAD vertex (5 mm off) and
        // one in every fifth moved by 0.8 mm.
        let mut corrupted = Vec::new();
        for i in (0..30).step_by(3) {
            data.plane[i][0][0] += 5.0;
            corrupted.push((i, 0));
        }
        for i in (1..30).step_by(5) {
            data.plane[i][1][1] -= 0.8;
            corrupted.push((i, 1));
        }
        let fit = fit_mount(&data.pairs(), nozzle_px, &nominal.nominal_homography(), &MountParams::defaults()).unwrap();
        assert!(max_gap_mm(&fit.mount, &h_true) < 1e-8, "gap {}", max_gap_mm(&fit.mount, &h_true));
        for (i, keep) in fit.inliers.iter().enumerate() {
            for (k, &kept) in keep.iter().enumerate() {
                assert_eq!(kept, !corrupted.contains(&(i, k)), "frame {i} pair {k}");
            }
        }
    }

    #[test]
    fn pixel_noise_averages_out_in_the_mount() {
        // 0.15 px of noise moves a single corner by ~0.02-0.05 mm on the plane. The mount,
        // fitted on 40 frames of 2-4 corners, must place every frame's nozzle better than
        // one corner would: RMS nozzle error below the RMS single-corner error.
        let (nominal, truth) = cameras();
        let (h_true, nozzle_px) = true_mount(&truth);
        let data = Synthetic::new(&truth, 40, &[2, 3, 4], 0.15);
        let params = MountParams::defaults();
        let fit = fit_mount(&data.pairs(), nozzle_px, &nominal.nominal_homography(), &params).unwrap();
        let (mut corner2, mut nozzle2, mut corners) = (0.0, 0.0, 0usize);
        for i in 0..40 {
            for (x, c) in data.image[i].iter().zip(&data.plane[i]) {
                corner2 += dist(sub(*c, h_true.apply(*x)), data.nozzles[i]).powi(2);
                corners += 1;
            }
            let fix = locate_nozzle(&fit.mount, &data.image[i], &data.plane[i], params.inlier_gate_mm).unwrap();
            nozzle2 += dist(fix.nozzle_mm, data.nozzles[i]).powi(2);
        }
        let (corner_rms, nozzle_rms) = ((corner2 / corners as f64).sqrt(), (nozzle2 / 40.0).sqrt());
        assert!(corner_rms > 0.015, "the noise is real: {corner_rms}");
        assert!(nozzle_rms < corner_rms, "nozzle {nozzle_rms} vs one corner {corner_rms}");
        assert!(fit.rms_mm < 2.0 * corner_rms, "rms {}", fit.rms_mm);
        let gap = max_gap_mm(&fit.mount, &h_true);
        assert!(gap < 0.1, "gap {gap}");
    }

    #[test]
    fn one_pair_places_the_nozzle_and_two_disagreeing_pairs_do_not() {
        let (_, truth) = cameras();
        let (h, nozzle_px) = true_mount(&truth);
        let nozzle = [12.0, 3.0];
        let c = [15.0, 7.0];
        let px = truth.plane_to_undistorted_px(sub(c, nozzle)).unwrap();
        let fix = locate_nozzle(&h, &[px], &[c], 0.15).unwrap();
        assert!(dist(fix.nozzle_mm, nozzle) < 1e-9 && fix.rms_mm == 0.0 && fix.inlier_count() == 1);
        let _ = nozzle_px;
        let c2 = [10.0, 7.0];
        let px2 = truth.plane_to_undistorted_px(sub(c2, nozzle)).unwrap();
        // Paired with a vertex 0.5 mm off: the two disagree by 0.5 mm > 2 × 0.15 mm.
        let err = locate_nozzle(&h, &[px, px2], &[c, [c2[0] + 0.5, c2[1]]], 0.15).unwrap_err();
        assert!(matches!(err, MountError::Inconsistent { spread_mm } if (spread_mm - 0.25).abs() < 1e-9), "{err:?}");
    }

    #[test]
    fn frames_with_single_pairs_cannot_fit_a_mount() {
        let (nominal, truth) = cameras();
        let (_, nozzle_px) = true_mount(&truth);
        let data = Synthetic::new(&truth, 30, &[1, 0], 0.0);
        let err =
            fit_mount(&data.pairs(), nozzle_px, &nominal.nominal_homography(), &MountParams::defaults()).unwrap_err();
        assert_eq!(err, MountError::TooFewPairs { found: 0, needed: 24 });
        let bad = [FramePairs { image_px: &[[1.0, 2.0]], plane_mm: &[] }];
        assert!(matches!(
            fit_mount(&bad, nozzle_px, &nominal.nominal_homography(), &MountParams::defaults()),
            Err(MountError::LengthMismatch { frame: 0, image: 1, plane: 0 })
        ));
    }
}
