//! The extended layer-to-layer model: paper 002's eqs 2-7 with the parameters of the
//! candidate mechanisms, for one layer predicted from the previous scan.
//!
//! A droplet at `p` (grid column `i_p`) on the previous scan `H`, with the cell's
//! nominal coefficients scaled by the dataset's mean droplet `1 − p_var/2` and by the
//! volume drift `1 + d·k` (`k` the 0-based layer index):
//! - **coefficient split** `ε`: `h2' = h2(1+ε)`, `h3' = h3(1+ε)`, `h1' = V − 4h2' − 4h3'`
//!   (the droplet's volume `V` unchanged: a miscalibrated split between its own cell and
//!   its neighbours);
//! - **anisotropic spread** `a`: the side share along x is `h2'(1+a)`, along y `h2'(1−a)`;
//! - the shares follow eq. 2 with `sat` of eq. 5 over the link's own width
//!   `h1' + share` (the paper's `h1 + h2`, `h1 + h3`);
//! - **nozzle bias**: every share of the droplet, and its `sat` width, is multiplied by
//!   its column's factor `b_i`. [`ColumnMaps`] keeps the shares apart by column with
//!   the widths of given factors, so that for fixed widths the increment is linear in
//!   the `b_i`; the fit alternates a linear solve of the factors with the widths of the
//!   last solve (the widths matter only where neighbours differ in height, at a rim, so
//!   two passes agree with the printer to well below the profiler's noise);
//! - the layer's increment `Δ` then flows once, `Δ + D·∇²Δ` over side neighbours with no
//!   flux across the grid boundary (**levelling**), and loses the fraction `s` on cure
//!   (**curing shrinkage**).
//!
//! - the profiler reads the surface through its spot ([`Spot`], the dataset's
//!   `spot_sigma_um`): the measured increment is the spot-weighted mean of the cells'
//!   increments (renormalised at the grid boundary, as the profiler does). This is part
//!   of the baseline, not a candidate: the dataset states how it was measured.
//!
//! With every parameter at its neutral value and a point spot this is exactly
//! [`crate::inkjet::height_model::deposit_layer_into`] on the mean droplets.

use crate::inkjet::grid::{Grid, CORNER_OFFSETS, SIDE_OFFSETS};
use crate::inkjet::height_model::{sat, DropletCoeffs};
use crate::inkjet::printer::Profiler;

/// The scalar parameters of the extensions (0 = the paper's model).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Scalars {
    /// Fraction of the fresh increment lost on cure.
    pub shrinkage: f64,
    /// Relative droplet-volume change per layer.
    pub drift_per_layer: f64,
    /// Diffusion number of the fresh increment.
    pub levelling: f64,
    /// Relative change of `h2`, `h3` at a fixed droplet volume.
    pub split: f64,
    /// Relative excess of the side share along x over y.
    pub anisotropy: f64,
}

/// One layer's droplets and the profile they land on.
#[derive(Debug, Clone, Copy)]
pub struct LayerInput<'a> {
    /// The grid.
    pub grid: Grid,
    /// The previous scan.
    pub before_um: &'a [f64],
    /// Where droplets are printed.
    pub droplet: &'a [bool],
    /// Each cell's mean droplet coefficients (nominal × `1 − p_var/2`).
    pub coeffs: &'a [DropletCoeffs],
    /// 0-based layer index (for the drift).
    pub layer_index: usize,
}

/// The pre-levelling increment of a layer resolved by the droplet's column:
/// `maps[o][q]` is what cell `q` receives from droplets in column `col(q) + o − 1`.
#[derive(Debug, Clone, Default)]
pub struct ColumnMaps {
    /// Three maps over the grid, offsets −1, 0, +1.
    pub maps: [Vec<f64>; 3],
}

impl ColumnMaps {
    /// Fills the maps for `layer` under `scalars`, the `sat` widths of each droplet
    /// scaled by its column's factor in `width_bias` (`None`: 1), reusing the buffers.
    pub fn fill(&mut self, layer: &LayerInput<'_>, scalars: &Scalars, width_bias: Option<&[f64]>) {
        let grid = layer.grid;
        for map in &mut self.maps {
            map.clear();
            map.resize(grid.len(), 0.0);
        }
        let drift = (1.0 + scalars.drift_per_layer * layer.layer_index as f64).max(0.0);
        for p in (0..grid.len()).filter(|&p| layer.droplet[p]) {
            let widen = width_bias.map_or(1.0, |b| b[grid.coords(p).0]);
            self.add_droplet(layer, p, layer.coeffs[p].scaled(drift), widen, scalars);
        }
    }

    fn add_droplet(&mut self, layer: &LayerInput<'_>, p: usize, c: DropletCoeffs, widen: f64, scalars: &Scalars) {
        let grid = layer.grid;
        let (i, j) = grid.coords(p);
        let h_p = layer.before_um[p];
        let (h2, h3) = (c.h2_um * (1.0 + scalars.split), c.h3_um * (1.0 + scalars.split));
        let h1 = if scalars.split == 0.0 { c.h1_um } else { c.droplet_volume_um() - 4.0 * (h2 + h3) };
        let mut kept_um = h1;
        let links = SIDE_OFFSETS.iter().map(|&(di, dj)| {
            let along_x = if di != 0 { 1.0 } else { -1.0 };
            (di, dj, h2 * (1.0 + scalars.anisotropy * along_x))
        });
        for (di, dj, share) in links.chain(CORNER_OFFSETS.iter().map(|&(di, dj)| (di, dj, h3))) {
            match grid.offset(i, j, di, dj) {
                Some((ni, nj)) => {
                    let q = grid.index(ni, nj);
                    let given = share * sat(widen * (h1 + share), h_p - layer.before_um[q]);
                    // The droplet's column is q's column minus di: offset index 1 − di.
                    self.maps[(1 - di) as usize][q] += given;
                    kept_um += share - given;
                }
                None => kept_um += share,
            }
        }
        self.maps[1][p] += kept_um;
    }

    /// The pre-levelling increment at `q` with column factors `bias` (`None`: all 1).
    #[inline]
    pub fn increment_at(&self, grid: Grid, q: usize, bias: Option<&[f64]>) -> f64 {
        match bias {
            None => self.maps[0][q] + self.maps[1][q] + self.maps[2][q],
            Some(b) => {
                let col = grid.coords(q).0;
                (0..3)
                    .filter_map(|o| (col + o).checked_sub(1).filter(|&c| c < grid.m_x).map(|c| b[c] * self.maps[o][q]))
                    .sum()
            }
        }
    }

    /// Calls `emit(column, coefficient)` for each column factor `b_column` the
    /// pre-levelling increment at `q` is linear in.
    #[inline]
    pub fn for_each_column(&self, grid: Grid, q: usize, weight: f64, mut emit: impl FnMut(usize, f64)) {
        let col = grid.coords(q).0;
        for o in 0..3 {
            if let Some(c) = (col + o).checked_sub(1).filter(|&c| c < grid.m_x) {
                let m = self.maps[o][q];
                if m != 0.0 {
                    emit(c, weight * m);
                }
            }
        }
    }
}

/// Calls `emit(neighbour, weight)` for the cells whose pre-levelling increment makes up
/// the final increment at `q`: `q` itself with `(1 − s)(1 − D·n_q)` and each in-grid
/// side neighbour with `(1 − s)·D`.
#[inline]
pub fn levelling_stencil(grid: Grid, q: usize, scalars: &Scalars, mut emit: impl FnMut(usize, f64)) {
    let keep = 1.0 - scalars.shrinkage;
    if scalars.levelling == 0.0 {
        emit(q, keep);
        return;
    }
    let (i, j) = grid.coords(q);
    let mut neighbours = 0.0;
    for &(di, dj) in &SIDE_OFFSETS {
        if let Some((ni, nj)) = grid.offset(i, j, di, dj) {
            emit(grid.index(ni, nj), keep * scalars.levelling);
            neighbours += 1.0;
        }
    }
    emit(q, keep * (1.0 - scalars.levelling * neighbours));
}

/// The profiler's spot on the grid: weights `(di, dj, w)`, centre included.
#[derive(Debug, Clone, PartialEq)]
pub struct Spot {
    kernel: Vec<(isize, isize, f64)>,
}

impl Spot {
    /// The spot of a profiler with Gaussian spot std `sigma_um` (0: a point).
    pub fn new(grid: Grid, sigma_um: f64) -> Self {
        Self { kernel: Profiler { noise_um: 0.0, spot_sigma_um: sigma_um }.kernel(grid) }
    }

    /// The largest column offset of the spot's cells.
    pub fn reach(&self) -> usize {
        self.kernel.iter().map(|&(di, _, _)| di.unsigned_abs()).max().unwrap_or(0)
    }

    /// Calls `emit(cell, weight)` for the cells the profiler averages at `q`, weights
    /// renormalised over the cells inside the grid.
    #[inline]
    pub fn for_each_cell(&self, grid: Grid, q: usize, mut emit: impl FnMut(usize, f64)) {
        let (i, j) = grid.coords(q);
        let inside = |&(di, dj, w): &(isize, isize, f64)| grid.offset(i, j, di, dj).map(|(a, b)| (grid.index(a, b), w));
        let total: f64 = self.kernel.iter().filter_map(inside).map(|(_, w)| w).sum();
        for (n, w) in self.kernel.iter().filter_map(inside) {
            emit(n, w / total);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inkjet::height_model::{deposit_layer_into, uniform_coeffs};
    use crate::inkjet::printer::diffuse_once;

    /// The composition [`super::filter::Track`] evaluates over whole fields, one cell at a
    /// time: the reference its tests compare against.
    /// Calls `emit(cell, weight)` for the cells whose pre-levelling increment makes up the
    /// measured increment at `q`: the spot over the levelling stencil.
    fn for_each_source(grid: Grid, q: usize, scalars: &Scalars, spot: &Spot, mut emit: impl FnMut(usize, f64)) {
        spot.for_each_cell(grid, q, |n, ws| levelling_stencil(grid, n, scalars, |m, wl| emit(m, ws * wl)));
    }

    /// The measured increment at `q`: the spot over levelling and shrinkage of the
    /// pre-levelling increments of `maps` with column factors `bias`.
    fn increment_um(
        maps: &ColumnMaps,
        grid: Grid,
        q: usize,
        scalars: &Scalars,
        spot: &Spot,
        bias: Option<&[f64]>,
    ) -> f64 {
        let mut sum = 0.0;
        for_each_source(grid, q, scalars, spot, |n, w| sum += w * maps.increment_at(grid, n, bias));
        sum
    }

    fn setup() -> (Grid, Vec<f64>, Vec<bool>, Vec<DropletCoeffs>) {
        let grid = Grid::new(9, 8, 263.0).unwrap();
        let before: Vec<f64> = (0..grid.len()).map(|c| ((c * 7) % 5) as f64 * 0.8).collect();
        let droplet: Vec<bool> = (0..grid.len()).map(|c| (c * 3) % 4 != 0).collect();
        (grid, before, droplet, uniform_coeffs(grid, DropletCoeffs::paper_table1()))
    }

    #[test]
    fn neutral_parameters_are_the_papers_model_and_levelling_is_the_printers() {
        let (grid, before, droplet, coeffs) = setup();
        let layer = LayerInput { grid, before_um: &before, droplet: &droplet, coeffs: &coeffs, layer_index: 3 };
        let mut maps = ColumnMaps::default();
        maps.fill(&layer, &Scalars::default(), None);
        let point = Spot::new(grid, 0.0);
        let mut after = vec![0.0; grid.len()];
        deposit_layer_into(grid, &before, &droplet, &coeffs, &mut after);
        let increment: Vec<f64> = after.iter().zip(&before).map(|(a, b)| a - b).collect();
        for q in 0..grid.len() {
            assert!((increment_um(&maps, grid, q, &Scalars::default(), &point, None) - increment[q]).abs() < 1e-12);
            let ones = vec![1.0; grid.m_x];
            assert!((maps.increment_at(grid, q, Some(&ones)) - increment[q]).abs() < 1e-12);
        }
        let s = Scalars { levelling: 0.2, shrinkage: 0.1, ..Scalars::default() };
        let flowed = diffuse_once(grid, &increment, 0.2);
        for (q, want) in flowed.iter().enumerate() {
            assert!((increment_um(&maps, grid, q, &s, &point, None) - 0.9 * want).abs() < 1e-12);
        }
    }

    #[test]
    fn the_filter_predicts_the_reference_composition() {
        use crate::inkjet::discrepancy::filter::{Noise, Track, TrackInput};
        let (grid, before, droplet, coeffs) = setup();
        let s = Scalars { levelling: 0.1, shrinkage: 0.05, split: 0.2, anisotropy: 0.1, drift_per_layer: 0.0 };
        let spot = Spot::new(grid, 120.0);
        let (droplets, layer_coeffs) = (vec![droplet.clone()], vec![coeffs.clone()]);
        let noise = Noise::new(grid, &droplets, &layer_coeffs, 0.05, 1.0);
        let scans = vec![before.clone(), before.clone()];
        let input =
            TrackInput { grid, scans: &scans, droplets: &droplets, coeffs: &layer_coeffs, spot: &spot, noise: &noise };
        let mut track = Track::default();
        track.run(&input, &s, None, None, false);
        let layer = LayerInput { grid, before_um: &before, droplet: &droplet, coeffs: &coeffs, layer_index: 0 };
        let mut maps = ColumnMaps::default();
        maps.fill(&layer, &s, None);
        for q in 0..grid.len() {
            let mut seen_before = 0.0;
            spot.for_each_cell(grid, q, |n, w| seen_before += w * before[n]);
            let want = seen_before + increment_um(&maps, grid, q, &s, &spot, None);
            assert!((track.prior[0][q] - want).abs() < 1e-12, "cell {q}");
        }
    }

    #[test]
    fn split_and_anisotropy_conserve_the_droplet_volume_on_a_flat_surface() {
        let grid = Grid::new(7, 7, 263.0).unwrap();
        let before = vec![0.0; grid.len()];
        let droplet: Vec<bool> = (0..grid.len()).map(|c| c == grid.index(3, 3)).collect();
        let coeffs = uniform_coeffs(grid, DropletCoeffs::paper_table1());
        let layer = LayerInput { grid, before_um: &before, droplet: &droplet, coeffs: &coeffs, layer_index: 0 };
        let s = Scalars { split: 0.5, anisotropy: 0.3, drift_per_layer: 0.01, ..Scalars::default() };
        let mut maps = ColumnMaps::default();
        maps.fill(&layer, &s, None);
        let point = Spot::new(grid, 0.0);
        let total: f64 = (0..grid.len()).map(|q| increment_um(&maps, grid, q, &s, &point, None)).sum();
        assert!((total - 7.6).abs() < 1e-12, "{total}");
        // h2' = 0.9: 1.17 along x, 0.63 along y; h1' = 7.6 − 4·0.9 − 4·0.3 = 2.8.
        let at = |i, j| increment_um(&maps, grid, grid.index(i, j), &s, &point, None);
        assert!((at(4, 3) - 1.17).abs() < 1e-12 && (at(3, 4) - 0.63).abs() < 1e-12);
        assert!((at(3, 3) - 2.8).abs() < 1e-12);
        // A column factor scales what the droplet's column gives.
        let mut bias = vec![1.0; grid.m_x];
        bias[3] = 1.1;
        let scaled = maps.increment_at(grid, grid.index(4, 3), Some(&bias));
        assert!((scaled - 1.1 * 1.17).abs() < 1e-12);
        // Through a wide spot the volume is still all there, only spread.
        let spot = Spot::new(grid, 150.0);
        let seen: f64 = (0..grid.len()).map(|q| increment_um(&maps, grid, q, &s, &spot, None)).sum();
        assert!((seen - 7.6).abs() < 0.05 && increment_um(&maps, grid, grid.index(3, 3), &s, &spot, None) < 2.8);
    }

    #[test]
    fn the_spot_is_the_profilers_blur() {
        let grid = Grid::new(8, 6, 263.0).unwrap();
        let field =
            crate::inkjet::grid::HeightMap { grid, height_um: (0..grid.len()).map(|c| ((c * 5) % 7) as f64).collect() };
        let profiler = Profiler { noise_um: 0.0, spot_sigma_um: 120.0 };
        let blurred = profiler.blur(&field);
        let spot = Spot::new(grid, 120.0);
        for q in 0..grid.len() {
            let mut sum = 0.0;
            spot.for_each_cell(grid, q, |n, w| sum += w * field.height_um[n]);
            assert!((sum - blurred.height_um[q]).abs() < 1e-12);
        }
    }
}
