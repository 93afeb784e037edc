//! Dense alignment of the G-code's material to the photo (the step after the coarse pose,
//! [`super::search`]): the camera's ten parameters q maximise the enhanced correlation
//! coefficient (ECC, Evangelidis & Psarakis 2008)
//!
//! ρ(q) = Σᵢ t̃ᵢ·C̃ᵢ(q) / (‖t̃‖·‖C̃(q)‖)
//!
//! over bed points xᵢ, with t the material drawn from the G-code and C(q) the photo's
//! contrast ([`super::contrast`]) at π(xᵢ; q), both blurred by σ (mm on the bed, σ times the
//! local scale in the photo) and made zero-mean over the points. Being normalised, ρ is
//! blind to the material's true width and the contrast's scale, and cannot be raised by
//! sliding the points onto flat plate (a least-squares fit with a free gain can, and did:
//! gain 0.03, pose off the pattern). Levenberg–Marquardt runs on the residuals
//! C̃ᵢ/‖C̃‖ − t̃ᵢ/‖t̃‖ (whose squares sum to 2 − 2ρ), its normal equations built from
//! running sums in one pass; where a level has many points, JᵀJ is summed over a regular
//! subset of them (`HESSIAN_POINTS`) while the cost and Jᵀr are summed over all, so the
//! optimum does not change (a subsampled Gauss–Newton). σ halves from level to level (coarse to fine); the first blur
//! is wider than a pattern's line spacing, so a comb of lines cannot lock a period off; the
//! image is box-downsampled where σ spans several pixels. Sums run over fixed chunks of
//! points, so they do not depend on the thread count.

use rayon::prelude::*;

use super::camera::{PhotoCamera, N_CAMERA_PARAMS};
use super::raster::{BedRaster, Raster};
use super::PrintedPath;
use crate::lines::fit::cholesky_solve;
use crate::lines::GrayImage;

/// Parameters fitted: the camera's.
const N: usize = N_CAMERA_PARAMS;
/// Points summed in sequence by one worker.
const CHUNK: usize = 4096;
/// Most LM iterations per level.
const MAX_ITERATIONS: usize = 40;
/// A step lowering the cost by less than this fraction ends the level.
const RELATIVE_TOLERANCE: f64 = 1e-5;
/// Levels blurred by at least this much (mm) fit an affine map only; the blur hides the
/// perspective and distortion they would otherwise trade against each other.
const AFFINE_ONLY_SIGMA_MM: f64 = 1.0;
/// Levels blurred by at least this much (mm) hold k2 at its value.
const NO_K2_SIGMA_MM: f64 = 0.5;
/// Contrast values are clamped to this range before blurring, so a specular speck or a
/// dark hole weighs no more than plate or print.
const CONTRAST_CLAMP: (f32, f32) = (-0.5, 1.5);
/// Finest cell of the bed grid (mm).
const MIN_RES_MM: f64 = 0.04;
/// Points whose blurred material lies in (ε, 1 − ε) carry the edges; of the others
/// (flat plate or flat print) only every `FLAT_STRIDE`-th cell is used.
const EDGE_EPSILON: f32 = 0.01;
const FLAT_STRIDE: usize = 3;
/// JᵀJ is summed over about this many of a level's points (every k-th) where it has more:
/// it only steers the steps, which end where the gradient Jᵀr, summed over every point,
/// vanishes; so the fit's optimum is the same while the finest level's 55 products per
/// point, half of its time, are spent on a ninth of its points.
const HESSIAN_POINTS: usize = 50_000;

/// The outcome of one level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelFit {
    /// Blur of the level (mm on the bed).
    pub sigma_mm: f64,
    /// The correlation ρ reached.
    pub correlation: f64,
    /// Points used.
    pub points: usize,
    /// LM iterations.
    pub iterations: usize,
}

/// The aligned camera and each level's fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Alignment {
    /// The camera after the finest level.
    pub camera: PhotoCamera,
    /// The levels, coarse to fine.
    pub levels: Vec<LevelFit>,
}

/// Aligns `paths` to the contrast image from `camera`, one level per blur in `sigmas_mm`
/// (coarse first). `None` if the pattern leaves the photo or a level cannot be solved.
pub fn align(contrast: &GrayImage, paths: &[PrintedPath], camera: PhotoCamera, sigmas_mm: &[f64]) -> Option<Alignment> {
    let clamped = Raster {
        width: contrast.width,
        height: contrast.height,
        values: contrast.pixels.par_iter().map(|v| v.clamp(CONTRAST_CLAMP.0, CONTRAST_CLAMP.1)).collect(),
    };
    let mut camera = camera;
    let mut levels = Vec::with_capacity(sigmas_mm.len());
    let (lo, hi) = super::raster::bounds(paths);
    let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
    for &sigma_mm in sigmas_mm {
        let scale = camera.mean_scale(centre)?;
        let level = Level::new(&clamped, paths, sigma_mm, scale);
        let (fitted, fit) = level.fit(camera)?;
        camera = fitted;
        levels.push(fit);
    }
    Some(Alignment { camera, levels })
}

/// One level's image, template and points.
struct Level {
    image: Raster,
    factor: f64,
    points: Vec<([f64; 2], f64)>,
    sigma_mm: f64,
    /// JᵀJ is summed over the points whose index is a multiple of this.
    hessian_stride: usize,
}

impl Level {
    fn new(contrast: &Raster, paths: &[PrintedPath], sigma_mm: f64, scale_px_mm: f64) -> Self {
        let sigma_px = sigma_mm * scale_px_mm;
        let factor = ((sigma_px / 1.5).floor() as usize).max(1);
        let image = contrast.downsampled(factor).blurred(sigma_px / factor as f64);
        let res_mm = (sigma_mm / 2.0).max(MIN_RES_MM);
        let material = BedRaster::material(paths, res_mm, 3.0 * sigma_mm + 1.0);
        let template = material.raster.blurred(sigma_mm / res_mm);
        let mut points = Vec::new();
        for j in 0..template.height {
            for i in 0..template.width {
                let t = template.values[j * template.width + i];
                let edge = t > EDGE_EPSILON && t < 1.0 - EDGE_EPSILON;
                if edge || (i % FLAT_STRIDE == 0 && j % FLAT_STRIDE == 0) {
                    points.push((material.centre_mm(i, j), f64::from(t)));
                }
            }
        }
        // t̃ / ‖t̃‖: zero mean, unit norm over the points
        let mean = points.iter().map(|p| p.1).sum::<f64>() / points.len().max(1) as f64;
        let norm = points.iter().map(|p| (p.1 - mean).powi(2)).sum::<f64>().sqrt().max(1e-12);
        points.iter_mut().for_each(|p| p.1 = (p.1 - mean) / norm);
        let hessian_stride = (points.len() / HESSIAN_POINTS).max(1);
        Self { image, factor: factor as f64, points, sigma_mm, hessian_stride }
    }

    /// The parameters this level fits: the affine part always, perspective and k1 below
    /// [`AFFINE_ONLY_SIGMA_MM`], k2 below [`NO_K2_SIGMA_MM`].
    fn active(&self) -> [bool; N] {
        let mut active = [true; N];
        if self.sigma_mm >= AFFINE_ONLY_SIGMA_MM {
            active[6..=9].iter_mut().for_each(|a| *a = false);
        } else if self.sigma_mm >= NO_K2_SIGMA_MM {
            active[9] = false;
        }
        active
    }

    fn fit(&self, camera: PhotoCamera) -> Option<(PhotoCamera, LevelFit)> {
        let active = self.active();
        let mut q = camera.params();
        let mut eq = self.normal_equations(&camera)?;
        let mut lambda = 1e-3;
        let mut iterations = 0;
        for _ in 0..MAX_ITERATIONS {
            iterations += 1;
            let step = damped_solve(&eq.jtj, &eq.jtr, lambda, &active)?;
            let mut trial = q;
            for k in 0..N {
                trial[k] -= step[k];
            }
            match self.normal_equations(&camera.with_params(&trial)) {
                Some(next) if next.cost <= eq.cost => {
                    let settled = eq.cost - next.cost <= RELATIVE_TOLERANCE * eq.cost;
                    (q, eq) = (trial, next);
                    lambda = (lambda / 3.0).max(1e-12);
                    if settled {
                        break;
                    }
                }
                _ => lambda *= 5.0,
            }
            if lambda > 1e8 {
                break;
            }
        }
        let fitted = camera.with_params(&q);
        Some((
            fitted,
            LevelFit { sigma_mm: self.sigma_mm, correlation: 1.0 - eq.cost / 2.0, points: eq.used, iterations },
        ))
    }

    fn normal_equations(&self, camera: &PhotoCamera) -> Option<Normal> {
        let chunks: Vec<Sums> = self
            .points
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(k, chunk)| self.chunk_sums(camera, k * CHUNK, chunk))
            .collect();
        let mut total = Sums::default();
        for c in &chunks {
            total.add(c);
        }
        if total.n < (N * 10) as f64 || total.hessian.n < (N * 10) as f64 {
            return None;
        }
        total.normal()
    }

    /// The sums over `chunk`, the points from index `first` on.
    fn chunk_sums(&self, camera: &PhotoCamera, first: usize, chunk: &[([f64; 2], f64)]) -> Sums {
        let mut sums = Sums::default();
        let per_px = 1.0 / self.factor;
        for (k, &(xy, t)) in chunk.iter().enumerate() {
            let Some(proj) = camera.param_jacobian(xy) else { continue };
            let (c, grad) = self.image.sample_clamped(proj.point_px[0] * per_px, proj.point_px[1] * per_px);
            let g = proj.gradient([grad[0] * per_px, grad[1] * per_px]);
            sums.push(c, t, &g);
            if (first + k).is_multiple_of(self.hessian_stride) {
                sums.hessian.push(c, &g);
            }
        }
        sums
    }
}

/// One-pass sums over the points: n, ΣC, ΣC², Σt, Σt², ΣCt, Σg, ΣCg, Σtg, with g the
/// gradient of C(π(x; q)) in q; and over every k-th point what JᵀJ is made of.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    n: f64,
    c: f64,
    cc: f64,
    t: f64,
    tt: f64,
    ct: f64,
    g: [f64; N],
    cg: [f64; N],
    tg: [f64; N],
    hessian: HessianSums,
}

/// Sums over the points JᵀJ is summed on: their count, ΣC, ΣC², Σg, ΣCg and Σggᵀ (upper).
#[derive(Debug, Clone, Copy)]
struct HessianSums {
    n: f64,
    c: f64,
    cc: f64,
    g: [f64; N],
    cg: [f64; N],
    gg: [[f64; N]; N],
}

impl Default for HessianSums {
    fn default() -> Self {
        Self { n: 0.0, c: 0.0, cc: 0.0, g: [0.0; N], cg: [0.0; N], gg: [[0.0; N]; N] }
    }
}

/// JᵀJ, Jᵀr and the cost 2 − 2ρ of the normalised residuals.
struct Normal {
    jtj: [[f64; N]; N],
    jtr: [f64; N],
    cost: f64,
    used: usize,
}

impl Sums {
    #[inline]
    fn push(&mut self, c: f64, t: f64, g: &[f64; N]) {
        self.n += 1.0;
        self.c += c;
        self.cc += c * c;
        self.t += t;
        self.tt += t * t;
        self.ct += c * t;
        for a in 0..N {
            self.g[a] += g[a];
            self.cg[a] += c * g[a];
            self.tg[a] += t * g[a];
        }
    }

    fn add(&mut self, o: &Sums) {
        self.n += o.n;
        self.c += o.c;
        self.cc += o.cc;
        self.t += o.t;
        self.tt += o.tt;
        self.ct += o.ct;
        for a in 0..N {
            self.g[a] += o.g[a];
            self.cg[a] += o.cg[a];
            self.tg[a] += o.tg[a];
        }
        self.hessian.add(&o.hessian);
    }

    /// With e = C̃/‖C̃‖, u = t̃/‖t̃‖, g̃ = g − ḡ, s = Σ e·g̃ and ρ = Σ e·u (the tildes
    /// centring over the points): J = (g̃ − e·sᵀ)/‖C̃‖, so JᵀJ = (Σ g̃g̃ᵀ − s sᵀ)/‖C̃‖² and
    /// Jᵀr = (ρ·s − Σ u·g)/‖C̃‖. JᵀJ is summed over the Hessian's points and scaled to all
    /// ([`HessianSums::jtj`]).
    fn normal(&self) -> Option<Normal> {
        let mean_c = self.c / self.n;
        let norm_c2 = self.cc - self.n * mean_c * mean_c;
        let mean_t = self.t / self.n;
        let norm_t = (self.tt - self.n * mean_t * mean_t).max(0.0).sqrt();
        if norm_c2.is_nan() || norm_c2 <= 1e-12 || norm_t.is_nan() || norm_t <= 1e-12 {
            return None;
        }
        let norm_c = norm_c2.sqrt();
        let rho = (self.ct - self.n * mean_c * mean_t) / (norm_c * norm_t);
        let mean_g = self.g.map(|v| v / self.n);
        let s: [f64; N] = std::array::from_fn(|a| (self.cg[a] - self.n * mean_c * mean_g[a]) / norm_c);
        let jtj = self.hessian.jtj(self.n, mean_c, norm_c, &mean_g, &s);
        let jtr = std::array::from_fn(|a| (rho * s[a] - (self.tg[a] - mean_t * self.g[a]) / norm_t) / norm_c);
        Some(Normal { jtj, jtr, cost: 2.0 - 2.0 * rho, used: self.n as usize })
    }
}

impl HessianSums {
    #[inline]
    fn push(&mut self, c: f64, g: &[f64; N]) {
        self.n += 1.0;
        self.c += c;
        self.cc += c * c;
        for a in 0..N {
            self.g[a] += g[a];
            self.cg[a] += c * g[a];
            for b in a..N {
                self.gg[a][b] += g[a] * g[b];
            }
        }
    }

    fn add(&mut self, o: &HessianSums) {
        self.n += o.n;
        self.c += o.c;
        self.cc += o.cc;
        for a in 0..N {
            self.g[a] += o.g[a];
            self.cg[a] += o.cg[a];
            for b in a..N {
                self.gg[a][b] += o.gg[a][b];
            }
        }
    }

    /// JᵀJ = Σ JᵢJᵢᵀ over all `n` points estimated from these: n/m times the sum over
    /// them of (g̃ − e·sᵀ)(g̃ − e·sᵀ)ᵀ/‖C̃‖², centred on the means of all points (`mean_c`,
    /// `mean_g`) with `s` from all of them, so it is positive semi-definite and, over every
    /// point, exactly (Σ g̃g̃ᵀ − s sᵀ)/‖C̃‖².
    fn jtj(&self, n: f64, mean_c: f64, norm_c: f64, mean_g: &[f64; N], s: &[f64; N]) -> [[f64; N]; N] {
        let m = self.n;
        // Σ e·g̃ and Σ e² over these points
        let es: [f64; N] = std::array::from_fn(|a| {
            (self.cg[a] - mean_c * self.g[a] - mean_g[a] * self.c + m * mean_c * mean_g[a]) / norm_c
        });
        let ee = (self.cc - 2.0 * mean_c * self.c + m * mean_c * mean_c) / (norm_c * norm_c);
        let scale = n / (m * norm_c * norm_c);
        let mut jtj = [[0.0; N]; N];
        for a in 0..N {
            for b in a..N {
                let gtgt = self.gg[a][b] - mean_g[a] * self.g[b] - self.g[a] * mean_g[b] + m * mean_g[a] * mean_g[b];
                jtj[a][b] = scale * (gtgt - s[a] * es[b] - es[a] * s[b] + ee * s[a] * s[b]);
                jtj[b][a] = jtj[a][b];
            }
        }
        jtj
    }
}

/// Solves (JᵀJ + λ·diag(JᵀJ))·δ = Jᵀr over the active parameters (Marquardt's scaling, so
/// the parameters' units do not matter) by Cholesky, δ = 0 for the others; `None` if it is
/// not positive definite.
fn damped_solve(jtj: &[[f64; N]; N], jtr: &[f64; N], lambda: f64, active: &[bool; N]) -> Option<[f64; N]> {
    let mut a = [[0.0; N]; N];
    let mut b = [0.0; N];
    for r in 0..N {
        if !active[r] {
            a[r][r] = 1.0;
            continue;
        }
        for c in 0..N {
            if active[c] {
                a[r][c] = jtj[r][c];
            }
        }
        a[r][r] += lambda * jtj[r][r].max(1e-12);
        b[r] = jtr[r];
    }
    cholesky_solve(a, b)
}
