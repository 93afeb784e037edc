//! What paper 002's layer-to-layer model gets wrong on a print's scans, and why: the
//! ink-jet domain of the discrepancy engine (DESIGN §7).
//!
//! **Baseline.** Eqs 2-7 (corrected, [`crate::inkjet::height_model`]) with the dataset's
//! nominal coefficients, each droplet at the mean of the recorded volume variation
//! (`1 − p/2` for the shortfall `U[0, p]`; measured data record `p = 0`), predicting
//! every scan `k` from the *measured* scan `k − 1` and the pattern printed in layer `k`.
//! It has no fitted parameter. A sample is one cell of one layer within two cells of a
//! droplet of that layer (where the model or a flow of the fresh layer can change the
//! height); its observation is the measured increment `scan_k − scan_{k−1}`.
//!
//! **Groups** are blocks of `layers_per_group` consecutive layers of one print. Why
//! blocks and not single layers: layer `k`'s residual contains the profiler noise of
//! scans `k − 1` and `k`, so neighbouring layers share a scan and their residuals are
//! correlated; in blocks only the one scan at each boundary is shared, a small part of
//! a block's evidence, and the sign-flip test's exchangeability holds closely enough
//! that its p-values on null prints are valid: nowhere significantly below the uniform
//! (a one-sided KS test over null prints in [`power`]'s tests; they lean towards 1,
//! since a candidate fitted to noise loses on held-out blocks). Parameters are shared by all blocks of the print (the printhead's
//! nozzle factors included), none belongs to one block, so no cross-fitting is needed.
//!
//! **Candidates** ([`mechanisms`]): curing shrinkage, volume drift, levelling flow and
//! nozzle bias (the virtual printer's effects a scan can show), a miscalibrated split of
//! `h1, h2, h3` and an anisotropic spread (which it does not have). The forward model is
//! in [`forward`]; nozzle factors are solved exactly by least squares per column
//! (variable projection), the scalar parameters by the engine's bounded
//! Levenberg–Marquardt solver.

pub mod control;
pub mod filter;
pub mod forward;
pub mod mechanisms;
pub mod power;

use ::discrepancy::least_squares::{minimize, LmSettings};
use ::discrepancy::{Group, Mechanism, Model, ModelError, Parameter, Variable, VariableKind};
use faer::prelude::Solve;
use faer::{Mat, Side};

use self::filter::{Noise, Track, TrackInput};
use self::forward::{Scalars, Spot};
use self::mechanisms::*;
use super::errors::InkjetError;
use super::grid::Grid;
use super::height_model::{DropletCoeffs, Material};

/// One print as the model sees it: scans, patterns and the mean droplets per cell.
#[derive(Debug, Clone, PartialEq)]
pub struct InkjetPrint {
    grid: Grid,
    scans: Vec<Vec<f64>>,
    droplets: Vec<Vec<bool>>,
    coeffs: Vec<Vec<DropletCoeffs>>,
    edge_mm: Vec<f64>,
    spot: Spot,
    noise: Noise,
}

/// What a print is made of, in the `inkjet-scans` layout.
#[derive(Debug, Clone, Copy)]
pub struct PrintParts<'a> {
    /// The grid.
    pub grid: Grid,
    /// `scans[0]` the substrate, `scans[k]` after layer `k`, row-major.
    pub scans: &'a [Vec<f64>],
    /// `patterns[k − 1]`: the material printed at each cell in layer `k`.
    pub patterns: &'a [Vec<Option<Material>>],
    /// Nominal part droplets.
    pub part: DropletCoeffs,
    /// Nominal support droplets (two-material prints).
    pub support: Option<DropletCoeffs>,
    /// Largest droplet-volume shortfall `p` (fraction): droplets average `1 − p/2`.
    pub max_shortfall: f64,
    /// The part's footprint (the desired cells).
    pub footprint: &'a [bool],
    /// The profiler's Gaussian spot std, µm.
    pub spot_sigma_um: f64,
    /// The profiler's noise std, µm.
    pub noise_um: f64,
}

impl InkjetPrint {
    /// Checks the parts' sizes and prepares the mean droplets and the edge distances.
    pub fn new(parts: PrintParts<'_>) -> Result<Self, InkjetError> {
        let grid = parts.grid;
        if parts.scans.len() != parts.patterns.len() + 1 {
            return Err(InkjetError::InvalidParameter {
                name: "scans",
                value: parts.scans.len() as f64,
                reason: "one scan more than printed layers is needed (the substrate first)",
            });
        }
        for scan in parts.scans {
            grid.check_len("scan", scan.len())?;
        }
        grid.check_len("footprint", parts.footprint.len())?;
        let mean = 1.0 - parts.max_shortfall / 2.0;
        let part = parts.part.check()?.scaled(mean);
        let support = parts.support.map(DropletCoeffs::check).transpose()?.map(|s| s.scaled(mean)).unwrap_or(part);
        let mut droplets = Vec::with_capacity(parts.patterns.len());
        let mut coeffs = Vec::with_capacity(parts.patterns.len());
        for pattern in parts.patterns {
            grid.check_len("pattern", pattern.len())?;
            droplets.push(pattern.iter().map(Option::is_some).collect());
            coeffs.push(pattern.iter().map(|m| if *m == Some(Material::Support) { support } else { part }).collect());
        }
        let edge_mm = edge_distances_mm(grid, parts.footprint);
        let spot = Spot::new(grid, parts.spot_sigma_um);
        let rel_sd = parts.max_shortfall / 12f64.sqrt() / mean;
        let noise = Noise::new(grid, &droplets, &coeffs, rel_sd, parts.noise_um);
        Ok(Self { grid, scans: parts.scans.to_vec(), droplets, coeffs, edge_mm, spot, noise })
    }

    /// Printed layers.
    pub fn layers(&self) -> usize {
        self.droplets.len()
    }

    /// The grid.
    pub fn grid(&self) -> Grid {
        self.grid
    }

    /// The print cut into blocks of `layers_per_group` consecutive layers (the last
    /// block takes the remainder).
    pub fn blocks(&self, layers_per_group: usize) -> Vec<LayerBlock> {
        let per = layers_per_group.max(1);
        let count = (self.layers() / per).max(1);
        (0..count)
            .map(|b| {
                let end = if b + 1 == count { self.layers() } else { (b + 1) * per };
                self.block(b, b * per..end)
            })
            .collect()
    }

    fn block(&self, index: usize, layers: std::ops::Range<usize>) -> LayerBlock {
        let (mut samples, mut observed) = (Vec::new(), Vec::new());
        for k in layers.clone() {
            for cell in self.sample_cells(k) {
                samples.push(Sample { layer: k as u32, cell: cell as u32 });
                observed.push(self.scans[k + 1][cell]);
            }
        }
        LayerBlock { index, layers, samples, observed }
    }

    /// Cells within two cells (Chebyshev) of a droplet of layer `k`.
    fn sample_cells(&self, k: usize) -> Vec<usize> {
        let grid = self.grid;
        let droplet = &self.droplets[k];
        (0..grid.len())
            .filter(|&c| {
                let (i, j) = grid.coords(c);
                (-2..=2).any(|dj| {
                    (-2..=2).any(|di| grid.offset(i, j, di, dj).is_some_and(|(a, b)| droplet[grid.index(a, b)]))
                })
            })
            .collect()
    }

    fn track_input(&self) -> TrackInput<'_> {
        TrackInput {
            grid: self.grid,
            scans: &self.scans,
            droplets: &self.droplets,
            coeffs: &self.coeffs,
            spot: &self.spot,
            noise: &self.noise,
        }
    }
}

/// Signed distance of each cell centre to the footprint's edge, mm (inside positive,
/// the edge half a spacing beyond the last cell): a two-pass chamfer distance
/// transform with steps 1 and √2 (within 8 % of Euclidean, linear in the grid), so
/// that the largest grids of the format cost milliseconds, not hours.
fn edge_distances_mm(grid: Grid, footprint: &[bool]) -> Vec<f64> {
    let inside = chamfer_cells(grid, footprint, false);
    let outside = chamfer_cells(grid, footprint, true);
    let spacing_mm = grid.spacing_um / 1000.0;
    (0..grid.len())
        .map(|c| {
            let (cells, sign) = if footprint[c] { (inside[c], 1.0) } else { (outside[c], -1.0) };
            if cells.is_finite() {
                sign * (cells - 0.5) * spacing_mm
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// Chamfer distance, in spacings, from each cell to the nearest cell whose footprint
/// flag is `target` (0 on such cells); with no such cell, to the ring just outside the
/// grid (a footprint filling the grid has its edge at the grid's).
fn chamfer_cells(grid: Grid, footprint: &[bool], target: bool) -> Vec<f64> {
    let any = footprint.contains(&target);
    let on_border = |c: usize| {
        let (i, j) = grid.coords(c);
        i == 0 || j == 0 || i + 1 == grid.m_x || j + 1 == grid.m_y
    };
    let mut d: Vec<f64> = (0..grid.len())
        .map(|c| match (footprint[c] == target, any) {
            (true, _) => 0.0,
            (false, false) if on_border(c) => 1.0,
            _ => f64::INFINITY,
        })
        .collect();
    let diagonal = std::f64::consts::SQRT_2;
    let forward = [(-1, 0, 1.0), (0, -1, 1.0), (-1, -1, diagonal), (1, -1, diagonal)];
    let backward = [(1, 0, 1.0), (0, 1, 1.0), (1, 1, diagonal), (-1, 1, diagonal)];
    let mut relax = |c: usize, steps: &[(isize, isize, f64)]| {
        let (i, j) = grid.coords(c);
        for &(di, dj, w) in steps {
            if let Some((a, b)) = grid.offset(i, j, di, dj) {
                d[c] = d[c].min(d[grid.index(a, b)] + w);
            }
        }
    };
    for c in 0..grid.len() {
        relax(c, &forward);
    }
    for c in (0..grid.len()).rev() {
        relax(c, &backward);
    }
    d
}

/// One sample: a cell of a layer (0-based layer index).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sample {
    /// 0-based layer index (the layer printed on scan `layer`).
    pub layer: u32,
    /// Cell, row-major.
    pub cell: u32,
}

/// A group: consecutive layers of one print.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerBlock {
    /// Block number in the print.
    pub index: usize,
    /// Its 0-based layer indices.
    pub layers: std::ops::Range<usize>,
    /// Its samples in layer order.
    pub samples: Vec<Sample>,
    observed: Vec<f64>,
}

impl Group for LayerBlock {
    fn observed(&self) -> &[f64] {
        &self.observed
    }
}

/// The variables the residuals are shown against.
pub static VARIABLES: [Variable; 7] = [
    Variable { name: "layer", unit: "", kind: VariableKind::Continuous },
    Variable { name: "height_gradient_um_per_mm", unit: "µm/mm", kind: VariableKind::Continuous },
    Variable { name: "edge_distance_mm", unit: "mm", kind: VariableKind::Continuous },
    Variable { name: "x_mm", unit: "mm", kind: VariableKind::Continuous },
    Variable { name: "y_mm", unit: "mm", kind: VariableKind::Continuous },
    Variable { name: "nozzle", unit: "", kind: VariableKind::Continuous },
    Variable { name: "neighbour_droplets", unit: "", kind: VariableKind::Continuous },
];

/// The paper's model of one print, extendable by the candidates.
#[derive(Debug, Clone)]
pub struct InkjetModel {
    print: InkjetPrint,
}

/// A fitted model: scalar parameters and, with the nozzle bias, the column factors.
#[derive(Debug, Clone, PartialEq)]
pub struct InkjetFit {
    /// Active mechanisms.
    pub active: Vec<usize>,
    /// Scalar parameters.
    pub scalars: Scalars,
    /// Column factors (nozzle bias active).
    pub bias: Option<Vec<f64>>,
    /// Their spread over the printed columns, estimation noise removed.
    pub nozzle_std: f64,
}

impl InkjetModel {
    /// The model of `print`.
    pub fn new(print: InkjetPrint) -> Self {
        Self { print }
    }

    /// The print.
    pub fn print(&self) -> &InkjetPrint {
        &self.print
    }
}

/// Where a scalar mechanism's parameter lives in [`Scalars`].
fn scalar_slot(c: usize) -> Option<fn(&mut Scalars) -> &mut f64> {
    match c {
        CURING_SHRINKAGE => Some(|s| &mut s.shrinkage),
        VOLUME_DRIFT => Some(|s| &mut s.drift_per_layer),
        LEVELLING_FLOW => Some(|s| &mut s.levelling),
        COEFFICIENT_SPLIT => Some(|s| &mut s.split),
        ANISOTROPIC_SPREAD => Some(|s| &mut s.anisotropy),
        _ => None,
    }
}

impl Model for InkjetModel {
    type Group = LayerBlock;
    type Fit = InkjetFit;

    fn name(&self) -> &'static str {
        "layer_model"
    }
    fn params(&self) -> &'static [Parameter] {
        &[]
    }
    fn candidates(&self) -> &[&'static dyn Mechanism] {
        &MECHANISMS
    }
    fn variables(&self) -> &[Variable] {
        &VARIABLES
    }

    fn variable_values(&self, group: &LayerBlock, variable: usize) -> Vec<f64> {
        let p = &self.print;
        let grid = p.grid;
        group
            .samples
            .iter()
            .map(|s| {
                let (k, c) = (s.layer as usize, s.cell as usize);
                let (i, j) = grid.coords(c);
                match variable {
                    0 => (k + 1) as f64,
                    1 => gradient_um_per_mm(grid, &p.scans[k], i, j),
                    2 => p.edge_mm[c],
                    3 => grid.position_um(i, j).0 / 1000.0,
                    4 => grid.position_um(i, j).1 / 1000.0,
                    5 => i as f64,
                    _ => neighbour_droplets(grid, &p.droplets[k], i, j),
                }
            })
            .collect()
    }

    fn fit(&self, active: &[usize], train: &[&LayerBlock], warm: Option<&InkjetFit>) -> Result<InkjetFit, ModelError> {
        let mut fitter = Fitter::new(&self.print, active, train);
        if let Some(bias) = warm.and_then(|w| w.bias.as_ref()) {
            fitter.start_bias.clone_from(bias);
        }
        fitter.fit(warm)
    }

    fn predict(
        &self,
        fit: &InkjetFit,
        group: &LayerBlock,
        _calibrate: Option<&[bool]>,
    ) -> Result<Vec<f64>, ModelError> {
        let mut track = Track::default();
        let bias = fit.bias.as_deref();
        track.run(&self.print.track_input(), &fit.scalars, bias, bias, false);
        Ok(group.samples.iter().map(|s| track.prior[s.layer as usize][s.cell as usize]).collect())
    }

    fn estimates(&self, fit: &InkjetFit) -> Vec<f64> {
        fit.active
            .iter()
            .map(|&c| match scalar_slot(c) {
                Some(slot) => *slot(&mut fit.scalars.clone()),
                None => fit.nozzle_std,
            })
            .collect()
    }
}

/// `|∇H|` of a scan at `(i, j)` by central differences (one-sided at the border).
fn gradient_um_per_mm(grid: Grid, scan: &[f64], i: usize, j: usize) -> f64 {
    let spacing_mm = grid.spacing_um / 1000.0;
    let diff = |a: Option<(usize, usize)>, b: Option<(usize, usize)>| match (a, b) {
        (Some(a), Some(b)) => {
            let span = if a.0.abs_diff(b.0) + a.1.abs_diff(b.1) == 2 { 2.0 } else { 1.0 };
            (scan[grid.index(a.0, a.1)] - scan[grid.index(b.0, b.1)]) / (span * spacing_mm)
        }
        _ => 0.0,
    };
    let here = Some((i, j));
    let gx = diff(grid.offset(i, j, 1, 0).or(here), grid.offset(i, j, -1, 0).or(here));
    let gy = diff(grid.offset(i, j, 0, 1).or(here), grid.offset(i, j, 0, -1).or(here));
    gx.hypot(gy)
}

/// Droplets of the layer in the 3 × 3 block around `(i, j)`.
fn neighbour_droplets(grid: Grid, droplet: &[bool], i: usize, j: usize) -> f64 {
    let mut n = 0;
    for dj in -1..=1 {
        for di in -1..=1 {
            if grid.offset(i, j, di, dj).is_some_and(|(a, b)| droplet[grid.index(a, b)]) {
                n += 1;
            }
        }
    }
    n as f64
}

/// Most linear solves of the column factors, each on the filter's run with the
/// factors (shares, `sat` widths, filtered surfaces) of the last solve. The solve
/// holds the shares at the last factors, and a factor also changes the filtered
/// surface its neighbours' `sat` sees, which it does not follow: measured on virtual
/// prints the solves approach the optimum by a factor ≈ 0.7 per pass.
const MAX_BIAS_PASSES: usize = 25;

/// The solves stop when no factor moves by more than this.
const BIAS_TOLERANCE: f64 = 2e-5;

/// Rounds of scalar fit, then factor solves, when both are active.
const ALTERNATIONS: usize = 3;

/// One fit: the active mechanisms on the training blocks.
struct Fitter<'a> {
    print: &'a InkjetPrint,
    active: &'a [usize],
    train: &'a [&'a LayerBlock],
    scalars: Vec<usize>,
    nozzle: bool,
    samples: usize,
    start_bias: Vec<f64>,
}

/// The column factors' least-squares solution and what their spread needs.
struct BiasSolution {
    bias: Vec<f64>,
    /// Diagonal of the inverse normal matrix (0 for unprinted columns).
    inverse_diagonal: Vec<f64>,
}

impl<'a> Fitter<'a> {
    fn new(print: &'a InkjetPrint, active: &'a [usize], train: &'a [&'a LayerBlock]) -> Self {
        let scalars = active.iter().copied().filter(|&c| scalar_slot(c).is_some()).collect();
        let samples = train.iter().map(|b| b.samples.len()).sum();
        let start_bias = vec![1.0; print.grid.m_x];
        Self { print, active, train, scalars, nozzle: active.contains(&NOZZLE_BIAS), samples, start_bias }
    }

    fn scalars_of(&self, x: &[f64]) -> Scalars {
        let mut s = Scalars::default();
        for (&c, &v) in self.scalars.iter().zip(x) {
            *scalar_slot(c).expect("scalar mechanism")(&mut s) = v;
        }
        s
    }

    fn fit(&self, warm: Option<&InkjetFit>) -> Result<InkjetFit, ModelError> {
        let mut track = Track::default();
        let start = warm.map_or(Scalars::default(), |w| w.scalars);
        let mut x: Vec<f64> =
            self.scalars.iter().map(|&c| *scalar_slot(c).expect("scalar")(&mut start.clone())).collect();
        let mut bias = self.start_bias.clone();
        let mut solution = None;
        let rounds = if self.nozzle && !self.scalars.is_empty() { ALTERNATIONS } else { 1 };
        for _ in 0..rounds {
            if !self.scalars.is_empty() {
                x = self.fit_scalars(&x, self.nozzle.then_some(&bias[..]), &mut track)?;
            }
            if self.nozzle {
                solution = Some(self.fit_bias(&self.scalars_of(&x), &mut bias, &mut track)?);
            }
        }
        let scalars = self.scalars_of(&x);
        let factors = self.nozzle.then_some(&bias[..]);
        track.run(&self.print.track_input(), &scalars, factors, factors, false);
        let mut r = vec![0.0; self.samples];
        self.training_residuals(&track, &mut r);
        let nozzle_std = solution.as_ref().map_or(0.0, |s| spread_without_noise(s, &r, self.samples));
        Ok(InkjetFit { active: self.active.to_vec(), scalars, bias: self.nozzle.then_some(bias), nozzle_std })
    }

    /// The scalar parameters by bounded Levenberg–Marquardt from `x0`, the column
    /// factors held at `bias`.
    fn fit_scalars(&self, x0: &[f64], bias: Option<&[f64]>, track: &mut Track) -> Result<Vec<f64>, ModelError> {
        let bounds = |c: usize| MECHANISMS[c].params()[0];
        let lo: Vec<f64> = self.scalars.iter().map(|&c| bounds(c).lo).collect();
        let hi: Vec<f64> = self.scalars.iter().map(|&c| bounds(c).hi).collect();
        let input = self.print.track_input();
        let residuals = |x: &[f64], r: &mut [f64]| {
            track.run(&input, &self.scalars_of(x), bias, bias, false);
            self.training_residuals(track, r);
            r.iter().all(|v| v.is_finite())
        };
        let solution = minimize(residuals, x0, &lo, &hi, self.samples, &LmSettings::default())
            .ok_or_else(|| ModelError::Fit("the layer model cannot be evaluated at its start".into()))?;
        Ok(solution.x)
    }

    /// The column factors under `scalars`: linear solves alternating with the filter
    /// from the factors in `bias` (left there), until no factor moves by more than
    /// [`BIAS_TOLERANCE`] or [`MAX_BIAS_PASSES`] solves.
    fn fit_bias(&self, scalars: &Scalars, bias: &mut Vec<f64>, track: &mut Track) -> Result<BiasSolution, ModelError> {
        let input = self.print.track_input();
        let singular = || ModelError::Fit("nozzle factors: singular normal equations".into());
        track.run(&input, scalars, Some(bias), Some(bias), true);
        let mut solution = None;
        for _ in 0..MAX_BIAS_PASSES {
            let next = self.solve_bias(track, bias).ok_or_else(singular)?;
            let step = next.bias.iter().zip(bias.iter()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            bias.clone_from(&next.bias);
            solution = Some(next);
            if step < BIAS_TOLERANCE {
                break;
            }
            track.run(&input, scalars, Some(bias), Some(bias), true);
        }
        solution.ok_or_else(singular)
    }

    /// `observed − prior` of every training sample, in block and sample order.
    fn training_residuals(&self, track: &Track, r: &mut [f64]) {
        let mut i = 0;
        for block in self.train {
            for (s, y) in block.samples.iter().zip(&block.observed) {
                r[i] = y - track.prior[s.layer as usize][s.cell as usize];
                i += 1;
            }
        }
    }

    /// Least squares of the column factors on the filter's last run, linearised at
    /// its factors `last` (exact for the run's shares and `sat` widths): each training
    /// prediction is `prior + ∂prior/∂b·(b − last)`. A weak ridge towards 1 keeps the
    /// columns no droplet used at 1. The factors' mean is free: the head's nozzles
    /// together may print above or below the nominal volume (a volume scale that the
    /// shrinkage candidate, with one parameter, describes at less cost).
    fn solve_bias(&self, track: &Track, last: &[f64]) -> Option<BiasSolution> {
        let grid = self.print.grid;
        let m = grid.m_x;
        let reach = track.reach as isize;
        let width = 2 * track.reach + 1;
        let mut normal = Mat::<f64>::zeros(m, m);
        let mut rhs = vec![0.0; m];
        let mut row: Vec<(usize, f64)> = Vec::with_capacity(width);
        for block in self.train {
            for (s, y) in block.samples.iter().zip(&block.observed) {
                let (k, c) = (s.layer as usize, s.cell as usize);
                let col = grid.coords(c).0 as isize;
                row.clear();
                let derivatives = &track.sensitivity[k][c * width..(c + 1) * width];
                for (o, &d) in derivatives.iter().enumerate() {
                    let column = col - reach + o as isize;
                    if d != 0.0 && (0..m as isize).contains(&column) {
                        row.push((column as usize, d));
                    }
                }
                let z = y - track.prior[k][c] + row.iter().map(|&(a, d)| d * last[a]).sum::<f64>();
                for &(a, va) in &row {
                    rhs[a] += va * z;
                    for &(b, vb) in &row {
                        normal[(a, b)] += va * vb;
                    }
                }
            }
        }
        let trace: f64 = (0..m).map(|c| normal[(c, c)]).sum();
        let ridge = 1e-9 * trace.max(1e-300) / m as f64;
        let printed: Vec<bool> = (0..m).map(|c| normal[(c, c)] > ridge * 1e3).collect();
        for c in 0..m {
            normal[(c, c)] += ridge;
            rhs[c] += ridge;
        }
        let llt = normal.llt(Side::Lower).ok()?;
        let b = llt.solve(Mat::<f64>::from_fn(m, 1, |i, _| rhs[i]));
        let bias: Vec<f64> = (0..m).map(|i| b[(i, 0)]).collect();
        let inverse = llt.solve(Mat::<f64>::identity(m, m));
        let inverse_diagonal = (0..m).map(|c| if printed[c] { inverse[(c, c)] } else { 0.0 }).collect();
        bias.iter().all(|v| v.is_finite()).then_some(BiasSolution { bias, inverse_diagonal })
    }
}

/// The spread of the fitted column factors over the printed columns, with the
/// estimation noise taken out: `sqrt(max(0, var(b̂) − s²·mean((NᵀN)⁻¹_ii)))`, `s²` the
/// residual variance (a method-of-moments random-effects estimate).
fn spread_without_noise(solution: &BiasSolution, residuals: &[f64], samples: usize) -> f64 {
    let printed: Vec<usize> = (0..solution.bias.len()).filter(|&c| solution.inverse_diagonal[c] > 0.0).collect();
    if printed.len() < 2 {
        return 0.0;
    }
    let n = printed.len() as f64;
    let mean = printed.iter().map(|&c| solution.bias[c]).sum::<f64>() / n;
    let var = printed.iter().map(|&c| (solution.bias[c] - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let dof = (samples as f64 - n).max(1.0);
    let s2 = residuals.iter().map(|r| r * r).sum::<f64>() / dof;
    let noise = s2 * printed.iter().map(|&c| solution.inverse_diagonal[c]).sum::<f64>() / n;
    (var - noise).max(0.0).sqrt()
}

#[cfg(test)]
mod tests {
    use super::power::{print_of, printed_column_spread, PrintDesign};
    use super::*;
    use crate::inkjet::experiments::{run_print, ControlLaw};
    use crate::inkjet::printer::{Effect, Effects, Profiler};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    const SMALL: PrintDesign = PrintDesign { radius_cells: 6, layers: 12, max_shortfall: 0.0, layers_per_group: 3 };

    /// A noiseless print (no droplet variation, a point profiler without noise).
    fn noiseless(effects: Effects) -> (InkjetModel, Vec<LayerBlock>, f64) {
        let mut scenario = SMALL.scenario(effects);
        scenario.truth.profiler = Profiler::ideal();
        let (_, rec) = run_print(&scenario, ControlLaw::OpenLoop, &mut ChaCha8Rng::seed_from_u64(4), true).unwrap();
        let rec = rec.unwrap();
        let spread = printed_column_spread(&scenario, &rec.nozzle_factors);
        let model = InkjetModel::new(print_of(&scenario, &rec).unwrap());
        let blocks = model.print().blocks(SMALL.layers_per_group);
        (model, blocks, spread)
    }

    #[test]
    fn edge_distances_are_signed_and_half_a_spacing_beyond_the_last_cell() {
        let grid = Grid::new(7, 5, 1000.0).unwrap();
        let footprint: Vec<bool> = (0..grid.len()).map(|c| (1..=5).contains(&grid.coords(c).0)).collect();
        let d = edge_distances_mm(grid, &footprint);
        let at = |i, j| d[grid.index(i, j)];
        assert_eq!((at(1, 2), at(3, 2), at(0, 2)), (0.5, 2.5, -0.5));
        // A footprint filling the grid has its edge at the grid's.
        let full = edge_distances_mm(grid, &vec![true; grid.len()]);
        assert_eq!((full[grid.index(0, 0)], full[grid.index(3, 2)]), (0.5, 2.5));
    }

    #[test]
    fn the_baseline_is_the_virtual_printer_without_effects() {
        let (model, blocks, _) = noiseless(Effects::none());
        assert_eq!(blocks.len(), 4);
        let fit = model.fit(&[], &blocks.iter().collect::<Vec<_>>(), None).unwrap();
        for b in &blocks {
            let predicted = model.predict(&fit, b, None).unwrap();
            let worst = b.observed().iter().zip(&predicted).map(|(y, p)| (y - p).abs()).fold(0.0, f64::max);
            assert!(worst < 1e-9, "block {}: {worst}", b.index);
        }
    }

    #[test]
    fn each_mechanism_recovers_its_own_parameter_from_noiseless_prints() {
        let cases = [
            (Effect::CuringShrinkage, 0.08, CURING_SHRINKAGE, 1e-6),
            (Effect::VolumeDrift, 0.004, VOLUME_DRIFT, 1e-3),
            (Effect::LevellingFlow, 0.06, LEVELLING_FLOW, 1e-3),
            (Effect::NozzleBias, 0.05, NOZZLE_BIAS, 1e-3),
        ];
        for (effect, strength, candidate, rel_tol) in cases {
            let (model, blocks, spread) = noiseless(Effects::none().with(effect, strength).unwrap());
            let fit = model.fit(&[candidate], &blocks.iter().collect::<Vec<_>>(), None).unwrap();
            let truth = if effect == Effect::NozzleBias { spread } else { strength };
            let got = model.estimates(&fit)[0];
            assert!((got - truth).abs() <= rel_tol * truth, "{}: {got} for {truth}", effect.name());
        }
    }
}
