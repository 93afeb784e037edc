//! Heat of the virtual thermal printer (DESIGN §5.3 "Heat"): the temperature of the
//! layer being printed at any time, which the nozzle-mounted camera films (paper 003
//! Sec. 2.3) and whose 140-150 °C band marks "newly printed corners" (Sec. 3.2).
//!
//! Model: every deposited cell starts at the nozzle temperature and its excess over the
//! substrate obeys the linear equation ∂T/∂t = D∇²T − (T − T_sub)/τ_c in the plane
//! (lateral diffusion D stands for conduction into the layer below and the neighbours,
//! τ_c for convection and radiation). Its exact Green's function gives, at point p and
//! time t,
//!
//! ```text
//! T(p, t) = T_sub + (T_nozzle − T_sub) · Σ_i a_i·f_i · exp(−age_i/τ_c) · N(p − x_i; σ_i²),
//! σ_i² = σ0² + 2·D·age_i,  age_i = t − t_dep,i
//! ```
//!
//! with a_i·f_i the cell's area times its fill: a cell holding more material carries more
//! heat, so thick deposits (corner bulges, where several cells of material lie within a
//! diffusion length) stay hotter than a thin bead, whose heat spreads into the empty
//! surroundings. σ0 spreads each cell's heat over about a nozzle radius at deposition.
//! Where material piles above the layer height (fill f > 1: where a layer fills a dip of
//! the layer below, up to the nozzle plane, see `deposition`) the pile carries f times the heat but
//! also has f times the heat capacity: the temperature at a point p of a pile is the sum
//! above divided by f(p) (1 off the piles and before the pile is laid; f averaged with
//! the same σ0 as the heat, so content and capacity are compared at one scale), so a
//! pile is laid at the nozzle temperature, not above it, and stays hot because its
//! neighbours hold heat too. It also cools through the same top surface, so its Newton time
//! constant is τ_c·f (τ_c = ρ·c·h/h_conv grows with the thickness h).
//!
//! Numbers and why: D = 0.06 mm²/s is PLA's thermal diffusivity k/(ρc) = 0.13/(1240·1800)
//! m²/s; τ_c = 8 s is ρ·c·h/h_conv for a 0.25 mm layer under a part-cooling fan
//! (h_conv ≈ 70 W/m²K); σ0 = 0.05 mm. On a straight 0.45 mm bead the centre then cools
//! from 230 °C to 150 °C in 0.64 s and to 140 °C in 0.82 s (tested: 0.5-1 s), while
//! 0.8 s after the head passed the 45° corner, its bulge is still at 180 °C (tested:
//! more than 5 K warmer than the bead at the same age).
//! The paper reports neither number, only that fresh corners are found in that band.
//!
//! Evaluation: cells are binned by σ on a geometric ladder σ_k = σ0·q^k (q = 1.15); each
//! cell's heat is split linearly in ln σ between its two neighbouring rungs, splatted
//! bilinearly on a grid of spacing h_k = σ_k/2 covering only the requested region (the
//! camera's footprint), and each rung is blurred by a separable Gaussian of variance
//! σ_k² − h_k²/3 (the splat and the bilinear read-out each add h²/6). Binning error: the
//! linear split in ln σ is exact to first order, its second-order error in a line's peak
//! is ≈ (ln q)²/8 ≈ 0.25 % of the excess; tested against the direct sum (< 1.5 K).
//!
//! Simplifications, stated: the substrate is at one temperature per layer (the bed,
//! or with `layer_heat_accumulation` the bed plus the carried fraction of the previous
//! layer's mean residual excess); the previous layers' own heat field is not rendered;
//! latent heat of PLA (amorphous, small) is ignored; the bead's temperature is uniform
//! through its height.

use std::collections::HashMap;
use std::sync::Arc;

use super::deposition::LayerDeposit;
use super::effects::Effects;
use models::thermal::DepositGrid;

/// Parameters of the heat model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeatParams {
    /// Newton cooling time constant τ_c (s).
    pub cooling_tau_s: f64,
    /// Lateral diffusivity D (mm²/s).
    pub diffusivity_mm2_s: f64,
    /// Initial spread σ0 of a cell's heat (mm).
    pub sigma0_mm: f64,
    /// Ratio q of the σ ladder of the binned evaluation.
    pub bin_ratio: f64,
}

impl HeatParams {
    /// The values of the module doc, with the `heat_diffusion_widening` effect applied.
    pub fn with_effects(effects: &Effects) -> Self {
        Self {
            cooling_tau_s: 8.0,
            diffusivity_mm2_s: 0.06 * (1.0 + effects.heat_diffusion_widening),
            sigma0_mm: 0.05,
            bin_ratio: 1.15,
        }
    }

    /// σ of a cell's heat at `age_s` (mm).
    pub fn sigma_mm(&self, age_s: f64) -> f64 {
        (self.sigma0_mm * self.sigma0_mm + 2.0 * self.diffusivity_mm2_s * age_s.max(0.0)).sqrt()
    }
}

/// A deposited cell as a heat source.
#[derive(Debug, Clone, Copy)]
struct HotCell {
    x_mm: f32,
    y_mm: f32,
    t_dep_s: f32,
    /// Cell area × fill (mm²).
    heat_mm2: f32,
    /// Cooling time constant of the cell: τ_c × max(fill, 1) (s).
    cooling_tau_s: f32,
    /// Age scale of the lateral spreading: 1 / max(fill, 1).
    spread_rate: f32,
}

/// The heat sources of one layer.
#[derive(Debug, Clone)]
pub struct LayerHeat {
    cells: Vec<HotCell>,
    piles: Arc<Piles>,
    params: HeatParams,
    /// Temperature of deposited material (°C).
    pub nozzle_temp_c: f64,
    /// Substrate temperature T_sub (°C).
    pub substrate_c: f64,
}

/// The cells whose fill exceeds the layer height, with their fill and deposit time: the
/// heat capacity (in layer heights) of the deposit at a point.
#[derive(Debug, Clone)]
struct Piles {
    /// The deposit's grid geometry (its fill is not kept: `cells` holds what is needed).
    geometry: DepositGrid,
    /// Cell index → (fill averaged over σ0, deposit time in s), for cells fuller than 1.
    cells: HashMap<usize, (f32, f32)>,
}

impl Piles {
    /// The pile cells of `deposit` with their capacity: the fill averaged with the
    /// Gaussian σ0 that spreads each cell's heat at deposition, so that capacity and heat
    /// content are seen at the same scale and a pile is laid at T_nozzle, not below it.
    fn of(deposit: &LayerDeposit, sigma0_mm: f64) -> Self {
        let grid = &deposit.grid;
        let kernel = gaussian_offsets(sigma0_mm / grid.cell_mm);
        let cells = (0..grid.fill.len())
            .filter(|&i| grid.fill[i] > 1.0)
            .map(|i| (i, (smoothed_fill(grid, i, &kernel) as f32, deposit.deposit_time_s[i])))
            .collect();
        let geometry = DepositGrid { fill: Vec::new(), ..*grid };
        Self { geometry, cells }
    }

    /// Heat capacity at `p_mm` and `t_s` in layer heights: the fill of a pile laid by
    /// then, 1 elsewhere.
    fn capacity(&self, p_mm: [f64; 2], t_s: f64) -> f64 {
        let Some((x, y)) = self.geometry.cell_of(p_mm) else {
            return 1.0;
        };
        match self.cells.get(&self.geometry.index(x, y)) {
            Some(&(fill, t_dep_s)) if f64::from(t_dep_s) <= t_s => f64::from(fill).max(1.0),
            _ => 1.0,
        }
    }
}

/// Offsets and weights (summing to 1) of a Gaussian of `sigma_cells`, truncated at 3σ.
fn gaussian_offsets(sigma_cells: f64) -> Vec<(i64, i64, f64)> {
    let reach = (3.0 * sigma_cells).ceil() as i64;
    let mut kernel: Vec<(i64, i64, f64)> = (-reach..=reach)
        .flat_map(|dy| (-reach..=reach).map(move |dx| (dx, dy)))
        .map(|(dx, dy)| (dx, dy, (-((dx * dx + dy * dy) as f64) / (2.0 * sigma_cells * sigma_cells)).exp()))
        .collect();
    let total: f64 = kernel.iter().map(|k| k.2).sum();
    kernel.iter_mut().for_each(|k| k.2 /= total);
    kernel
}

/// The fill around cell `i` averaged with `kernel` (cells off the grid count as empty).
fn smoothed_fill(grid: &DepositGrid, i: usize, kernel: &[(i64, i64, f64)]) -> f64 {
    let (x, y) = ((i % grid.nx) as i64, (i / grid.nx) as i64);
    kernel
        .iter()
        .filter_map(|&(dx, dy, w)| {
            let (u, v) = (x + dx, y + dy);
            let inside = u >= 0 && v >= 0 && (u as usize) < grid.nx && (v as usize) < grid.ny;
            inside.then(|| w * f64::from(grid.fill[grid.index(u as usize, v as usize)]))
        })
        .sum()
}

/// The binned temperature field of one instant over a region.
#[derive(Debug, Clone)]
pub struct TemperatureField {
    rungs: Vec<Rung>,
    piles: Arc<Piles>,
    t_s: f64,
    substrate_c: f64,
    excess_c: f64,
}

/// One σ rung of the ladder: heat splatted on a grid and blurred.
#[derive(Debug, Clone)]
struct Rung {
    origin_mm: [f64; 2],
    h_mm: f64,
    nx: usize,
    ny: usize,
    values: Vec<f32>,
}

impl LayerHeat {
    /// Heat sources of `deposit`, starting at `nozzle_temp_c` over `substrate_c`.
    pub fn new(deposit: &LayerDeposit, nozzle_temp_c: f64, substrate_c: f64, params: HeatParams) -> Self {
        let grid = &deposit.grid;
        let area = grid.cell_mm * grid.cell_mm;
        let mut cells: Vec<HotCell> = Vec::new();
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                let i = grid.index(ix, iy);
                if grid.fill[i] > 0.0 {
                    let c = grid.cell_center_mm(ix, iy);
                    let fill = f64::from(grid.fill[i]);
                    cells.push(HotCell {
                        x_mm: c[0] as f32,
                        y_mm: c[1] as f32,
                        t_dep_s: deposit.deposit_time_s[i],
                        heat_mm2: (fill * area) as f32,
                        cooling_tau_s: (params.cooling_tau_s * fill.max(1.0)) as f32,
                        spread_rate: (1.0 / fill.max(1.0)) as f32,
                    });
                }
            }
        }
        cells.sort_by(|a, b| a.t_dep_s.total_cmp(&b.t_dep_s));
        let piles = Arc::new(Piles::of(deposit, params.sigma0_mm));
        Self { cells, piles, params, nozzle_temp_c, substrate_c }
    }

    /// The model parameters.
    pub fn params(&self) -> &HeatParams {
        &self.params
    }

    /// Temperature at `p_mm` and time `t_s` by the direct sum over all cells (slow; the
    /// reference for [`Self::field`]).
    pub fn exact_temp_c(&self, p_mm: [f64; 2], t_s: f64) -> f64 {
        let mut sum = 0.0;
        for c in self.deposited_by(t_s) {
            let age = t_s - f64::from(c.t_dep_s);
            let s2 = self.params.sigma_mm(age * f64::from(c.spread_rate)).powi(2);
            let r2 = (p_mm[0] - f64::from(c.x_mm)).powi(2) + (p_mm[1] - f64::from(c.y_mm)).powi(2);
            let decay = (-age / f64::from(c.cooling_tau_s)).exp();
            sum += f64::from(c.heat_mm2) * decay * (-r2 / (2.0 * s2)).exp() / (std::f64::consts::TAU * s2);
        }
        let capacity = self.piles.capacity(p_mm, t_s);
        self.substrate_c + (self.nozzle_temp_c - self.substrate_c) * sum / capacity
    }

    /// The binned field at `t_s` over the rectangle `[min_mm, max_mm]`.
    pub fn field(&self, t_s: f64, min_mm: [f64; 2], max_mm: [f64; 2]) -> TemperatureField {
        let p = self.params;
        let ln_q = p.bin_ratio.ln();
        let sources = self.deposited_by(t_s);
        // Rung position x = ln(σ/σ0)/ln q of every source, and each rung's extent.
        let places: Vec<(usize, f64)> = sources
            .iter()
            .map(|c| {
                let age = (t_s - f64::from(c.t_dep_s)) * f64::from(c.spread_rate);
                let x = (p.sigma_mm(age) / p.sigma0_mm).ln() / ln_q;
                (x.floor() as usize, x - x.floor())
            })
            .collect();
        let top = places.iter().map(|(k, _)| k + 1).max().unwrap_or(1);
        let mut rungs: Vec<Rung> = (0..=top).map(|k| Rung::empty(p.sigma0_mm * p.bin_ratio.powi(k as i32))).collect();
        let mut extents = vec![([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]); top + 1];
        for (c, &(k, _)) in sources.iter().zip(&places) {
            for e in &mut extents[k..=k + 1] {
                e.0 = [e.0[0].min(f64::from(c.x_mm)), e.0[1].min(f64::from(c.y_mm))];
                e.1 = [e.1[0].max(f64::from(c.x_mm)), e.1[1].max(f64::from(c.y_mm))];
            }
        }
        for (rung, (lo, hi)) in rungs.iter_mut().zip(&extents) {
            rung.cover(*lo, *hi, min_mm, max_mm);
        }
        for (c, &(k, frac)) in sources.iter().zip(&places) {
            let heat = f64::from(c.heat_mm2) * (-(t_s - f64::from(c.t_dep_s)) / f64::from(c.cooling_tau_s)).exp();
            let at = [f64::from(c.x_mm), f64::from(c.y_mm)];
            rungs[k].splat(at, heat * (1.0 - frac));
            rungs[k + 1].splat(at, heat * frac);
        }
        rungs.retain(|r| !r.values.is_empty());
        rungs.iter_mut().for_each(Rung::blur);
        let excess_c = self.nozzle_temp_c - self.substrate_c;
        TemperatureField { rungs, piles: Arc::clone(&self.piles), t_s, substrate_c: self.substrate_c, excess_c }
    }

    /// Fill-weighted mean excess over the substrate of the layer's material at `t_s` (K),
    /// from every 7th cell (the residual heat carried by `layer_heat_accumulation`).
    pub fn mean_excess_c(&self, t_s: f64) -> f64 {
        let (min, max) = self.bounds_mm();
        let field = self.field(t_s, min, max);
        let (mut sum, mut weight) = (0.0, 0.0);
        for c in self.deposited_by(t_s).iter().step_by(7) {
            let w = f64::from(c.heat_mm2);
            sum += w * (field.temp_c([f64::from(c.x_mm), f64::from(c.y_mm)]) - self.substrate_c);
            weight += w;
        }
        if weight > 0.0 {
            sum / weight
        } else {
            0.0
        }
    }

    /// Bounding box of the deposited cells (mm).
    pub fn bounds_mm(&self) -> ([f64; 2], [f64; 2]) {
        let mut min = [f64::INFINITY; 2];
        let mut max = [f64::NEG_INFINITY; 2];
        for c in &self.cells {
            let p = [f64::from(c.x_mm), f64::from(c.y_mm)];
            for a in 0..2 {
                min[a] = min[a].min(p[a]);
                max[a] = max[a].max(p[a]);
            }
        }
        (min, max)
    }

    /// Cells deposited at or before `t_s` (a prefix: cells are sorted by time).
    fn deposited_by(&self, t_s: f64) -> &[HotCell] {
        let n = self.cells.partition_point(|c| f64::from(c.t_dep_s) <= t_s);
        &self.cells[..n]
    }
}

impl TemperatureField {
    /// Temperature at `p_mm` (°C); the substrate temperature outside all rungs.
    pub fn temp_c(&self, p_mm: [f64; 2]) -> f64 {
        let sum: f64 = self.rungs.iter().map(|r| r.sample(p_mm)).sum();
        self.substrate_c + self.excess_c * sum / self.piles.capacity(p_mm, self.t_s)
    }

    /// The substrate temperature (°C).
    pub fn substrate_c(&self) -> f64 {
        self.substrate_c
    }
}

impl Rung {
    fn empty(sigma_mm: f64) -> Self {
        Self { origin_mm: [0.0; 2], h_mm: sigma_mm / 2.0, nx: 0, ny: 0, values: Vec::new() }
    }

    /// Sizes the grid to the sources' extent `[lo, hi]` plus the 3σ reach of their heat,
    /// clipped to the region `[min_mm, max_mm]` plus that reach.
    fn cover(&mut self, lo: [f64; 2], hi: [f64; 2], min_mm: [f64; 2], max_mm: [f64; 2]) {
        let reach = 6.0 * self.h_mm + 2.0 * self.h_mm;
        let lo = [(lo[0] - reach).max(min_mm[0] - reach), (lo[1] - reach).max(min_mm[1] - reach)];
        let hi = [(hi[0] + reach).min(max_mm[0] + reach), (hi[1] + reach).min(max_mm[1] + reach)];
        if hi[0] <= lo[0] || hi[1] <= lo[1] {
            return;
        }
        self.origin_mm = lo;
        self.nx = ((hi[0] - lo[0]) / self.h_mm).ceil() as usize + 1;
        self.ny = ((hi[1] - lo[1]) / self.h_mm).ceil() as usize + 1;
        self.values = vec![0.0; self.nx * self.ny];
    }

    /// Adds `heat_mm2` at `p_mm`, bilinearly, as a density (per node area).
    fn splat(&mut self, p_mm: [f64; 2], heat_mm2: f64) {
        if self.values.is_empty() || heat_mm2 == 0.0 {
            return;
        }
        let fx = (p_mm[0] - self.origin_mm[0]) / self.h_mm;
        let fy = (p_mm[1] - self.origin_mm[1]) / self.h_mm;
        if fx < 0.0 || fy < 0.0 || fx >= (self.nx - 1) as f64 || fy >= (self.ny - 1) as f64 {
            return;
        }
        let (x0, y0) = (fx as usize, fy as usize);
        let (ax, ay) = (fx - x0 as f64, fy - y0 as f64);
        let density = heat_mm2 / (self.h_mm * self.h_mm);
        let i = y0 * self.nx + x0;
        self.values[i] += (density * (1.0 - ax) * (1.0 - ay)) as f32;
        self.values[i + 1] += (density * ax * (1.0 - ay)) as f32;
        self.values[i + self.nx] += (density * (1.0 - ax) * ay) as f32;
        self.values[i + self.nx + 1] += (density * ax * ay) as f32;
    }

    /// Separable Gaussian blur of variance σ² − h²/3 (in nodes: 4 − 1/3).
    fn blur(&mut self) {
        let sigma_nodes = (4.0f64 - 1.0 / 3.0).sqrt();
        let kernel = gaussian_kernel(sigma_nodes);
        let mut line = Vec::with_capacity(self.nx.max(self.ny));
        for y in 0..self.ny {
            line.clear();
            line.extend_from_slice(&self.values[y * self.nx..(y + 1) * self.nx]);
            for x in 0..self.nx {
                self.values[y * self.nx + x] = convolve_at(&line, x, &kernel);
            }
        }
        for x in 0..self.nx {
            line.clear();
            line.extend((0..self.ny).map(|y| self.values[y * self.nx + x]));
            for y in 0..self.ny {
                self.values[y * self.nx + x] = convolve_at(&line, y, &kernel);
            }
        }
    }

    /// Bilinear read-out at `p_mm` (0 outside the grid).
    fn sample(&self, p_mm: [f64; 2]) -> f64 {
        let fx = (p_mm[0] - self.origin_mm[0]) / self.h_mm;
        let fy = (p_mm[1] - self.origin_mm[1]) / self.h_mm;
        if fx < 0.0 || fy < 0.0 || fx >= (self.nx - 1) as f64 || fy >= (self.ny - 1) as f64 {
            return 0.0;
        }
        let (x0, y0) = (fx as usize, fy as usize);
        let (ax, ay) = (fx - x0 as f64, fy - y0 as f64);
        let i = y0 * self.nx + x0;
        let v = |j: usize| f64::from(self.values[j]);
        (v(i) * (1.0 - ax) + v(i + 1) * ax) * (1.0 - ay) + (v(i + self.nx) * (1.0 - ax) + v(i + self.nx + 1) * ax) * ay
    }
}

/// Normalised Gaussian taps out to 3σ.
fn gaussian_kernel(sigma: f64) -> Vec<f32> {
    let radius = (3.0 * sigma).ceil() as i32;
    let taps: Vec<f64> = (-radius..=radius).map(|i| (-f64::from(i * i) / (2.0 * sigma * sigma)).exp()).collect();
    let sum: f64 = taps.iter().sum();
    taps.iter().map(|t| (t / sum) as f32).collect()
}

/// One output sample of the convolution of `line` with the centred `kernel` (zero outside).
fn convolve_at(line: &[f32], at: usize, kernel: &[f32]) -> f32 {
    let radius = kernel.len() / 2;
    let lo = at.saturating_sub(radius);
    let hi = (at + radius).min(line.len() - 1);
    (lo..=hi).map(|j| line[j] * kernel[j + radius - at]).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::thermal::deposition::print_part;
    use crate::thermal::deposition::tests::straight_sample;
    use models::thermal::{PrintSetup, Trajectory};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn heat_of_conventional_layer() -> (Trajectory, LayerDeposit, LayerHeat) {
        let setup = PrintSetup::paper_defaults();
        let trajectory = Trajectory::corner_test(&setup).unwrap();
        let v_e = setup.conventional_command(&trajectory);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let deposit = print_part(&setup, &trajectory, &v_e, 1, &Effects::none(), &mut rng).unwrap().remove(0);
        let heat =
            LayerHeat::new(&deposit, setup.nozzle_temp_c, setup.bed_temp_c, HeatParams::with_effects(&Effects::none()));
        (trajectory, deposit, heat)
    }

    /// First time (s, 10 ms steps) after `t0` at which the temperature at `p` drops below `temp_c`.
    fn crossing_s(heat: &LayerHeat, p: [f64; 2], t0: f64, temp_c: f64) -> f64 {
        (0..400).map(|i| t0 + 0.01 * i as f64).find(|&t| heat.exact_temp_c(p, t) < temp_c).unwrap_or(f64::INFINITY) - t0
    }

    #[test]
    fn straight_bead_crosses_the_corner_band_within_a_second() {
        // Mid left side: the bead centre passes 150 °C and 140 °C 0.5-1 s after deposition.
        let (trajectory, _, heat) = heat_of_conventional_layer();
        let k = straight_sample(&trajectory);
        let p = [trajectory.x_mm[k], trajectory.y_mm[k]];
        let (t150, t140) =
            (crossing_s(&heat, p, trajectory.t_s[k], 150.0), crossing_s(&heat, p, trajectory.t_s[k], 140.0));
        assert!(t150 > 0.5 && t140 < 1.0 && t150 < t140, "150 °C after {t150} s, 140 °C after {t140} s");
    }

    #[test]
    fn sharp_corners_stay_hot_longer_than_straight_edges() {
        // The 45° corner holds more material within a diffusion length than a straight
        // bead (its bulge): 0.8 s after the head passed, its hottest point within 0.6 mm
        // of the vertex is warmer than the straight bead's centre at the same age.
        let (trajectory, _, heat) = heat_of_conventional_layer();
        let age_s = 0.8;
        let k = straight_sample(&trajectory);
        let edge_c = heat.exact_temp_c([trajectory.x_mm[k], trajectory.y_mm[k]], trajectory.t_s[k] + age_s);
        let corner = trajectory.corners.iter().find(|c| (c.interior_angle_deg - 45.0).abs() < 1e-6).unwrap();
        let t_s = 0.5 * (corner.arc_start_s + corner.arc_end_s) + age_s;
        let v = corner.vertex_mm;
        let offsets = (-12..=12).flat_map(|i| (-12..=12).map(move |j| [0.05 * i as f64, 0.05 * j as f64]));
        let corner_c = offsets
            .filter(|d| d[0].hypot(d[1]) < 0.6)
            .map(|d| heat.exact_temp_c([v[0] + d[0], v[1] + d[1]], t_s))
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(corner_c > edge_c + 5.0, "corner {corner_c} °C vs edge {edge_c} °C at {age_s} s");
    }

    #[test]
    fn binned_field_matches_the_direct_sum() {
        let (trajectory, _, heat) = heat_of_conventional_layer();
        let t = 4.3;
        let k = (t / trajectory.dt_s) as usize;
        let nozzle = [trajectory.x_mm[k], trajectory.y_mm[k]];
        let (min, max) = ([nozzle[0] - 5.0, nozzle[1] - 10.0], [nozzle[0] + 15.0, nozzle[1] + 10.0]);
        let field = heat.field(t, min, max);
        let mut worst: f64 = 0.0;
        for j in (0..k).step_by(97) {
            for off in [0.0, 0.15, -0.3] {
                let p = [trajectory.x_mm[j] + off, trajectory.y_mm[j] - off];
                if p[0] < min[0] || p[0] > max[0] || p[1] < min[1] || p[1] > max[1] {
                    continue;
                }
                worst = worst.max((field.temp_c(p) - heat.exact_temp_c(p, t)).abs());
            }
        }
        assert!(worst < 1.5, "largest difference {worst} K");
    }

    #[test]
    fn a_full_plane_starts_at_the_nozzle_temperature() {
        // Green's function normalisation: a uniform patch of age 0 is at T_nozzle at its centre.
        let (_, deposit, heat) = heat_of_conventional_layer();
        let mut full = deposit.clone();
        full.grid.fill.iter_mut().for_each(|f| *f = 1.0);
        full.deposit_time_s.iter_mut().for_each(|t| *t = 0.0);
        let plane = LayerHeat::new(&full, heat.nozzle_temp_c, heat.substrate_c, *heat.params());
        let centre = full.grid.cell_center_mm(full.grid.nx / 2, full.grid.ny / 2);
        assert!((plane.exact_temp_c(centre, 0.0) - 230.0).abs() < 1e-3);
        let field = plane.field(0.0, [centre[0] - 1.0, centre[1] - 1.0], [centre[0] + 1.0, centre[1] + 1.0]);
        assert!((field.temp_c(centre) - 230.0).abs() < 0.5, "{}", field.temp_c(centre));
    }

    #[test]
    fn a_pile_is_laid_at_the_nozzle_temperature_and_cools_slower() {
        // A uniform pile 2.5 layers high holds 2.5 times the heat in 2.5 times the
        // capacity: it starts at T_nozzle, and with τ_c·2.5 it is warmer than a single
        // layer once Newton cooling has acted (lateral diffusion is the same for both).
        let (_, deposit, heat) = heat_of_conventional_layer();
        let plane_of = |fill: f32| {
            let mut d = deposit.clone();
            d.grid.fill.iter_mut().for_each(|f| *f = fill);
            d.deposit_time_s.iter_mut().for_each(|t| *t = 0.0);
            LayerHeat::new(&d, heat.nozzle_temp_c, heat.substrate_c, *heat.params())
        };
        let (single, pile) = (plane_of(1.0), plane_of(2.5));
        let centre = deposit.grid.cell_center_mm(deposit.grid.nx / 2, deposit.grid.ny / 2);
        assert!((pile.exact_temp_c(centre, 0.0) - 230.0).abs() < 1e-3);
        let excess = |plane: &LayerHeat, t: f64| plane.exact_temp_c(centre, t) - heat.substrate_c;
        // Uniform planes: excess(t) = ΔT·e^(−t/(τ_c·f)), so the ratio is e^(t/τ_c·(1 − 1/f)).
        let t = 4.0;
        let ratio = excess(&pile, t) / excess(&single, t);
        let expected = (t / heat.params().cooling_tau_s * (1.0 - 1.0 / 2.5)).exp();
        assert!((ratio - expected).abs() < 1e-6 * expected, "{ratio} vs {expected}");
    }
}
