//! The print as a state-space model: eqs 2-7 propagate the surface from layer to
//! layer, the profiler observes it with noise, and a per-cell Kalman filter carries
//! the estimate of the surface a layer lands on.
//!
//! Why not the measured scan itself: the increment a droplet gives its neighbours
//! depends on height *differences* through `sat` (eq. 5, a few µm wide), and the
//! profiler's noise (1 µm per cell, Sec. V-B) is of that size. Fed the raw scan, the
//! model shares material by noise; the next scan then shows the noise regress, and any
//! candidate that changes how shares respond to height differences "explains" that
//! regression, on prints with nothing wrong. Predicting scan `k` by the filter's
//! one-step prediction instead makes the residual the filter's innovation, which is
//! unpredictable from the past scans when the model is right: only a real discrepancy
//! remains to be found. The filter runs with the model being scored (baseline or
//! extended), so an extension's prediction is not biased by the baseline's errors.
//!
//! The state is the *true* surface, not the scan: the printer's `sat` acts on true
//! height differences, and the profiler's spot smooths a rim's step, so shares computed
//! on the scan would differ at every rim in a way that looks like levelling flow.
//! Per cell `c` and layer `k`: `Ĥ⁻ = Ĥ_k + Δ_k(Ĥ_k)`, the predicted scan `B·Ĥ⁻` (`B` the
//! spot), `P⁻ = P + q_{k,c}`; update with scan `k + 1`: `K = P⁻/(P⁻ + r)`,
//! `Ĥ_{k+1} = Ĥ⁻ + K(scan − B·Ĥ⁻)`, `P = (1 − K)P⁻`; start `Ĥ_0 = scan_0`, `P_0 = r`. The
//! gain treats `B` as the identity (its centre weight is 0.97 for the paper's spot):
//! each layer's update is one Van Cittert step of deconvolving the spot, so a rim's
//! estimate sharpens towards the true step over the layers. `r` is the profiler's noise variance (`noise_um²` of the dataset; 0 makes
//! the filter the raw scan), `q` the variance the droplets add: each share of a
//! droplet printed at cell `p` varies by the droplet's relative volume std
//! (`(p_var/√12)/(1 − p_var/2)` for the shortfall `U[0, p_var]`), plus an allowance for
//! model error of [`MODEL_ERROR_FRACTION`] of a droplet's volume per layer at every
//! cell a droplet reaches. Cross-cell covariances are left out (a per-cell filter):
//! the gain is then a little off where droplets overlap, never biased.

use super::forward::{levelling_stencil, ColumnMaps, LayerInput, Scalars, Spot};
use crate::inkjet::grid::{Grid, CORNER_OFFSETS, SIDE_OFFSETS};
use crate::inkjet::height_model::DropletCoeffs;

/// The model error the filter allows per layer, as a fraction of a droplet's volume.
pub const MODEL_ERROR_FRACTION: f64 = 0.02;

/// What the filter needs of a print besides its layers.
#[derive(Debug, Clone, PartialEq)]
pub struct Noise {
    /// Profiler noise variance `r`, µm².
    pub measurement_var: f64,
    /// Per layer and cell, the variance the layer's droplets add, µm².
    pub process_var: Vec<Vec<f64>>,
}

impl Noise {
    /// `q` of every layer from its droplets and `r` from the profiler.
    pub fn new(grid: Grid, droplets: &[Vec<bool>], coeffs: &[Vec<DropletCoeffs>], rel_sd: f64, noise_um: f64) -> Self {
        let process_var = droplets
            .iter()
            .zip(coeffs)
            .map(|(droplet, coeffs)| {
                let mut q = vec![0.0; grid.len()];
                for p in (0..grid.len()).filter(|&p| droplet[p]) {
                    let c = coeffs[p];
                    let allowance = (MODEL_ERROR_FRACTION * c.droplet_volume_um()).powi(2);
                    let (i, j) = grid.coords(p);
                    let mut add = |cell: usize, share: f64| q[cell] += (rel_sd * share).powi(2) + allowance / 9.0;
                    add(p, c.h1_um);
                    for (offsets, share) in [(&SIDE_OFFSETS, c.h2_um), (&CORNER_OFFSETS, c.h3_um)] {
                        for &(di, dj) in offsets {
                            if let Some((a, b)) = grid.offset(i, j, di, dj) {
                                add(grid.index(a, b), share);
                            }
                        }
                    }
                }
                q
            })
            .collect();
        Self { measurement_var: noise_um * noise_um, process_var }
    }
}

/// The filter's run through a print under one model.
#[derive(Debug, Clone, Default)]
pub struct Track {
    /// Per layer, the shares of its droplets on the filtered surface.
    pub maps: Vec<ColumnMaps>,
    /// `surface[k]`: the filtered estimate of the true surface layer `k` lands on
    /// (`[0]` the substrate scan).
    pub surface: Vec<Vec<f64>>,
    /// `prior[k]`: the one-step prediction of scan `k + 1`.
    pub prior: Vec<Vec<f64>>,
    /// With sensitivities: `sensitivity[k][c·w + o]` is `∂prior[k][c]/∂b` for the
    /// column `col(c) − reach + o`, `w = 2·reach + 1` ([`Track::reach`]): through the
    /// layer's own shares and through the filtered surface of the layers before
    /// (shares and `sat` widths held at the run's factors).
    pub sensitivity: Vec<Vec<f64>>,
    /// Columns on each side of a cell that its prediction depends on.
    pub reach: usize,
    variance: Vec<f64>,
    gain: Vec<f64>,
    surface_sensitivity: Vec<f64>,
    pre: Vec<f64>,
    after: Vec<f64>,
}

/// The print's data the filter reads.
#[derive(Debug, Clone, Copy)]
pub struct TrackInput<'a> {
    /// The grid.
    pub grid: Grid,
    /// Scans, `[0]` the substrate.
    pub scans: &'a [Vec<f64>],
    /// Droplets per layer.
    pub droplets: &'a [Vec<bool>],
    /// Mean droplets per layer and cell.
    pub coeffs: &'a [Vec<DropletCoeffs>],
    /// The profiler's spot.
    pub spot: &'a Spot,
    /// The noise model.
    pub noise: &'a Noise,
}

impl Track {
    /// Runs the filter through every layer under `scalars`, column factors `bias` and
    /// `sat` widths of the factors `width_bias`; with `sensitivity`, also the
    /// predictions' derivatives by the column factors.
    pub fn run(
        &mut self,
        input: &TrackInput<'_>,
        scalars: &Scalars,
        bias: Option<&[f64]>,
        width_bias: Option<&[f64]>,
        sensitivity: bool,
    ) {
        let grid = input.grid;
        let layers = input.droplets.len();
        // The shares reach one column, levelling one more, the spot its own reach.
        self.reach = input.spot.reach() + 2;
        let width = 2 * self.reach + 1;
        if sensitivity {
            self.sensitivity.resize_with(layers, Vec::new);
            self.surface_sensitivity.clear();
            self.surface_sensitivity.resize(grid.len() * width, 0.0);
        }
        self.maps.resize_with(layers, ColumnMaps::default);
        self.surface.resize_with(layers + 1, Vec::new);
        self.prior.resize_with(layers, Vec::new);
        self.surface[0].clone_from(&input.scans[0]);
        self.variance.clear();
        self.variance.resize(grid.len(), input.noise.measurement_var);
        let r = input.noise.measurement_var;
        for k in 0..layers {
            let layer = LayerInput {
                grid,
                before_um: &self.surface[k],
                droplet: &input.droplets[k],
                coeffs: &input.coeffs[k],
                layer_index: k,
            };
            self.maps[k].fill(&layer, scalars, width_bias);
            self.pre.clear();
            self.pre.extend((0..grid.len()).map(|c| self.maps[k].increment_at(grid, c, bias)));
            // The true surface after the layer, then as the profiler would see it.
            self.after.clear();
            for c in 0..grid.len() {
                let mut delta = 0.0;
                levelling_stencil(grid, c, scalars, |n, w| delta += w * self.pre[n]);
                self.after.push(self.surface[k][c] + delta);
            }
            let mut prior = std::mem::take(&mut self.prior[k]);
            prior.clear();
            for c in 0..grid.len() {
                let mut seen = 0.0;
                input.spot.for_each_cell(grid, c, |n, w| seen += w * self.after[n]);
                prior.push(seen);
            }
            self.gain.clear();
            for c in 0..grid.len() {
                let predicted_var = self.variance[c] + input.noise.process_var[k][c];
                let gain = if predicted_var + r > 0.0 { predicted_var / (predicted_var + r) } else { 1.0 };
                self.variance[c] = (1.0 - gain) * predicted_var;
                self.gain.push(gain);
            }
            if sensitivity {
                self.propagate_sensitivity(input, scalars, k, width);
            }
            let mut next = std::mem::take(&mut self.surface[k + 1]);
            next.clear();
            next.extend((0..grid.len()).map(|c| self.after[c] + self.gain[c] * (input.scans[k + 1][c] - prior[c])));
            self.prior[k] = prior;
            self.surface[k + 1] = next;
        }
    }

    /// `∂prior[k]/∂b` (the spot over the true surface's sensitivity after the layer)
    /// and the next surface's sensitivity `∂after/∂b − K·∂prior/∂b`, each per cell over
    /// the columns within [`Track::reach`] of the cell's own (farther ones, which enter
    /// only through repeated spot blurs, are left out).
    fn propagate_sensitivity(&mut self, input: &TrackInput<'_>, scalars: &Scalars, k: usize, width: usize) {
        let grid = input.grid;
        let reach = self.reach as isize;
        // ∂after/∂b: the surface's, plus the layer's own shares through levelling.
        let mut after = std::mem::take(&mut self.surface_sensitivity);
        let maps = &self.maps[k];
        for c in 0..grid.len() {
            let col = grid.coords(c).0 as isize;
            let row = &mut after[c * width..(c + 1) * width];
            levelling_stencil(grid, c, scalars, |n, w| {
                maps.for_each_column(grid, n, w, |column, v| row[(column as isize - col + reach) as usize] += v)
            });
        }
        let mut prior = std::mem::take(&mut self.sensitivity[k]);
        prior.clear();
        prior.resize(grid.len() * width, 0.0);
        for c in 0..grid.len() {
            let col = grid.coords(c).0 as isize;
            let row = &mut prior[c * width..(c + 1) * width];
            input.spot.for_each_cell(grid, c, |n, w| {
                let shift = grid.coords(n).0 as isize - col;
                for (o, &d) in after[n * width..(n + 1) * width].iter().enumerate() {
                    let o = o as isize + shift;
                    if d != 0.0 && (0..width as isize).contains(&o) {
                        row[o as usize] += w * d;
                    }
                }
            });
        }
        for c in 0..grid.len() {
            let gain = self.gain[c];
            for o in c * width..(c + 1) * width {
                after[o] -= gain * prior[o];
            }
        }
        self.surface_sensitivity = after;
        self.sensitivity[k] = prior;
    }
}
