//! Deposition of the virtual thermal printer (DESIGN §5.3 "Deposition"; paper 003
//! Sec. 2.1 and eq. 34): commanded deposition velocity v_e(t) (the extruder's E-axis
//! velocity, mm/s of filament) → commanded flow E_cmd = A_fil·v_e → melt pressure
//! state G(s)·E_cmd with G(s) = 1/(τs+1) → actual flow E = max(0, state) → material on
//! a fine [`DepositGrid`] by mass conservation. A negative command is a retraction: it
//! pulls the pressure state down faster than letting it decay, and the nozzle only
//! extrudes while the state is positive (it cannot suck deposited material back), so
//! a retracted extruder must be primed again before material flows.
//!
//! The bead follows the paper's geometric model, as DESIGN §5.3 asks: at each
//! trajectory sample (1 ms) the deposition direction comes from the deposition direction
//! allocation (eqs 13-26, [`allocate_directions`] on the actual flow) and the left and
//! right half widths from mass conservation along it (eqs 5-11 with κ_eff,
//! [`boundary_points`]). The volume E·dt of sample k is spread uniformly (by area) over
//! the quadrilateral between the deposition segments of samples k and k+1, so the
//! deposited volume is exactly the extruded one; where quadrilaterals overlap the
//! material would pile up (but see the nozzle face below). At a corner the head
//! slows while the lagging flow keeps coming, the reach E/(|v|h) grows, and the
//! over-deposition of Sec. 3.3 emerges from eq. 3 instead of being drawn. Rays thinner
//! than a quarter nozzle that eqs 10-11 fan out of a slow apex collapse into the bead
//! they hang from ([`super::capillary`]).
//!
//! The nozzle's flat face confines the melt: no cell of a layer can hold more than the
//! room between the part below and the nozzle plane (its headroom: one layer height on
//! the bed). Where the quadrilaterals overlap at a slow apex and the collapsed rays land,
//! eqs 5-11 stack more than that; the excess is squeezed out sideways, poured into the
//! nearest cells with room, the earliest deposit first (the squeeze flow under the face).
//! Beyond the edge of the layer below the room reaches down to the bed (at most three
//! layer heights), so melt squeezed over the edge hangs down the wall.
//! Without it the apex of a sharp corner would stand several layer heights tall under a
//! nozzle one layer height above the bed, and the true widths would see little of the
//! excess the flow lag delivers at the corners; with it they see most of it, the rest
//! lying beside the deposition directions the widths are read along (the chen2024
//! report's variant `true_widths`).
//!
//! Layers stack: the nozzle of layer L sits at (L+1)·h above the bed, and the bead is
//! squeezed into the gap between the nozzle's flat face and the part printed so far
//! (the mean stack height under the face, radius = half the nozzle). Its reach is then
//! E/(|v|·gap) (eq. 3 with the gap in place of h), so a dip left by the layer below
//! makes the next bead narrower and taller there: the top of the part returns to the
//! nozzle plane. The headroom keeps every layer's top at or below its nozzle plane, so
//! the gap is never smaller than h and a corner's excess goes sideways within its own
//! layer. The first layer, on the flat bed, has gap = h.
//!
//! The `melt_squeeze_out` effect (strength s ∈ [0, 1]) sends a fraction s of each
//! sample's volume elsewhere: it fills the nearest cells around the nozzle tip that are
//! not yet full, in order of distance, up to their headroom ("melt flows where there
//! is room"). This breaks the slender-deposition assumption of eqs 5-7 (material stays
//! where and when it was extruded), for discrepancy studies (DESIGN §7; no shipped spec
//! switches it on). On a straight line at steady state the empty cells ahead of the nozzle
//! form a crescent of area 2r·|v|·dt, so the same bead width emerges there.
//!
//! Simplifications, stated: each quadrilateral is split into sub-quads of at most
//! [`SUBSTEP_MM`] on a side whose volume is split bilinearly between the four cells
//! around their centre (an edge is blurred over about one cell); half widths are
//! capped at [`MAX_SPREAD_MM`] (only reached when the head stands still with flow, at
//! the end of a layer); the squeeze-out part takes distances from the centre of the
//! nozzle's cell and fills a cell to at most its headroom; the face's squeeze runs once
//! per layer, after the collapse of thin rays, and pours into the nearest cells with
//! room around each overfull cell (not radially away from the nozzle); the gap is clamped to
//! 0.25-3 layer heights, and a bead lands where it is deposited even if the layer below
//! has no material there (no overhang sag); melt still in the nozzle when the last
//! sample is reached stays there (no ooze). Each layer's flow is scaled by a seeded factor
//! 1 + 0.5 %·N(0,1), the filament-diameter tolerance of commercial PLA (±0.02 mm on
//! 1.75 mm is ±2.3 % in area, 0.5 % is its layer-to-layer part); the flow lag starts
//! from rest at every layer (the travel between layers lets the melt pressure relax).

use models::progress::Progress;
use models::thermal::dda::{allocate_directions, boundary_points, DdaParams, DepositionDirections};
use models::thermal::dynamics::first_order_lag;
use models::thermal::{DepositGrid, PrintSetup, ThermalError, Trajectory};
use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::capillary::{cells_near, disc_offsets, LayerFill, MAX_COLLAPSE_MM, THIN_FEATURE_RADIUS_MM};
use super::effects::Effects;
use crate::limits::DEPOSIT_SIDE_CELLS;

/// Edge of a deposit cell (mm): a tenth of the nominal half-width, 1/20 of the nozzle.
pub const CELL_MM: f64 = 0.02;
/// Margin of the deposit grid around the path (mm): room for corner bulges.
pub const MARGIN_MM: f64 = 3.0;
/// Largest half width of a deposition segment (mm): reached only with flow at rest.
pub const MAX_SPREAD_MM: f64 = 2.8;
/// Farthest from its source (the nozzle, or an overfull cell) that squeezed-out melt is
/// placed (mm).
pub const SQUEEZE_REACH_MM: f64 = 1.4;
/// Largest side of the sub-quads a deposition quadrilateral is split into (mm).
pub const SUBSTEP_MM: f64 = 0.02;
/// Standard deviation of the per-layer flow factor (filament diameter tolerance).
pub const FLOW_FACTOR_SD: f64 = 0.005;

/// One printed layer.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerDeposit {
    /// Layer index, 0 = first.
    pub layer: usize,
    /// Fill fractions of the layer height (above 1 only where the layer below leaves room
    /// under the nozzle plane).
    pub grid: DepositGrid,
    /// Time (s from the layer's start) at which each cell first received material;
    /// `f32::INFINITY` where it never did.
    pub deposit_time_s: Vec<f32>,
    /// Actual flow E at each trajectory sample (mm³/s).
    pub flow_mm3_s: Vec<f64>,
    /// Extruded volume ∫E dt (mm³).
    pub extruded_mm3: f64,
    /// Volume that fell off the grid or, squeezed out (by the nozzle face or the
    /// `melt_squeeze_out` effect), found no room within [`SQUEEZE_REACH_MM`] (mm³);
    /// zero for any realistic flow.
    pub lost_mm3: f64,
    /// Flow factor drawn for this layer (filament tolerance).
    pub flow_factor: f64,
}

/// Prints `layers` layers of `trajectory` with the commanded deposition velocity
/// `deposition_velocity_mm_s` (E-axis, mm/s of filament, one value per sample; the
/// conventional print uses [`PrintSetup::nominal_deposition_velocity_mm_s`] of |v|),
/// through the actual τ of `effects`. This is what a re-print with a compensated v_e calls.
/// Fails when the deposition direction allocation cannot place a layer's rotation.
pub fn print_part<R: Rng>(
    setup: &PrintSetup,
    trajectory: &Trajectory,
    deposition_velocity_mm_s: &[f64],
    layers: usize,
    effects: &Effects,
    rng: &mut R,
) -> Result<Vec<LayerDeposit>, ThermalError> {
    print_part_observed(setup, trajectory, deposition_velocity_mm_s, layers, effects, rng, &())
}

/// [`print_part`], telling `progress` of each layer as it is printed.
pub fn print_part_observed<R: Rng>(
    setup: &PrintSetup,
    trajectory: &Trajectory,
    deposition_velocity_mm_s: &[f64],
    layers: usize,
    effects: &Effects,
    rng: &mut R,
    progress: &dyn Progress,
) -> Result<Vec<LayerDeposit>, ThermalError> {
    let setup = setup.check()?;
    if deposition_velocity_mm_s.len() != trajectory.len() {
        return Err(ThermalError::BadTrajectory {
            message: format!(
                "deposition velocity has {} samples, the trajectory {}",
                deposition_velocity_mm_s.len(),
                trajectory.len()
            ),
        });
    }
    let tau_s = effects.actual_tau_s(setup.tau_s);
    let command: Vec<f64> = deposition_velocity_mm_s.iter().map(|v| setup.filament_area_mm2() * v).collect();
    let mut nominal_flow = first_order_lag(&command, trajectory.dt_s, tau_s, 0.0);
    nominal_flow.iter_mut().for_each(|e| *e = e.max(0.0));
    let normal = Normal::new(1.0, FLOW_FACTOR_SD).expect("valid normal");
    let factors: Vec<f64> = (0..layers).map(|_| normal.sample(rng).clamp(0.97, 1.03)).collect();
    check_grid_size(trajectory)?;
    let printer = LayerPrinter::new(trajectory, &setup, effects.melt_squeeze_out);
    let mut stack = PartStack::new(grid_for(trajectory), setup.nozzle_mm / 2.0);
    let mut printed = Vec::with_capacity(layers);
    progress.add(layers as u64);
    for (layer, &factor) in factors.iter().enumerate() {
        let flow: Vec<f64> = nominal_flow.iter().map(|e| e * factor).collect();
        let nozzle_z_mm = (layer + 1) as f64 * setup.layer_height_mm;
        let gap_mm = stack.gaps_mm(trajectory, nozzle_z_mm, setup.layer_height_mm);
        let headroom = stack.headroom_layers(nozzle_z_mm, setup.layer_height_mm);
        let deposit = printer.print(layer, flow, &gap_mm, headroom, factor)?;
        stack.add(&deposit.grid, setup.layer_height_mm);
        printed.push(deposit);
        progress.done(1);
    }
    Ok(printed)
}

/// Smallest and largest gap between the nozzle and the part below it, in layer heights.
const GAP_RANGE_LAYERS: (f64, f64) = (0.25, 3.0);

/// The part printed so far: height of the material stack above the bed in every cell,
/// which sets the gap under the nozzle of the next layer.
struct PartStack {
    grid: DepositGrid,
    height_mm: Vec<f64>,
    /// Cell offsets under the nozzle's flat face.
    face: Vec<(i64, i64)>,
}

impl PartStack {
    fn new(grid: DepositGrid, face_radius_mm: f64) -> Self {
        let cells = grid.nx * grid.ny;
        let face = disc_offsets(face_radius_mm / grid.cell_mm);
        Self { grid, height_mm: vec![0.0; cells], face }
    }

    /// The gap between the nozzle at height `nozzle_z_mm` and the mean height of the
    /// stack under its face at every sample, clamped to [`GAP_RANGE_LAYERS`].
    fn gaps_mm(&self, trajectory: &Trajectory, nozzle_z_mm: f64, layer_height_mm: f64) -> Vec<f64> {
        let (low, high) = (GAP_RANGE_LAYERS.0 * layer_height_mm, GAP_RANGE_LAYERS.1 * layer_height_mm);
        (0..trajectory.len())
            .map(|k| (nozzle_z_mm - self.mean_height_mm([trajectory.x_mm[k], trajectory.y_mm[k]])).clamp(low, high))
            .collect()
    }

    /// Room under the nozzle plane at `nozzle_z_mm` above every cell, in layer heights,
    /// clamped to [`GAP_RANGE_LAYERS`]: the thickest this layer can be there.
    fn headroom_layers(&self, nozzle_z_mm: f64, layer_height_mm: f64) -> Vec<f64> {
        self.height_mm
            .iter()
            .map(|h| ((nozzle_z_mm - h) / layer_height_mm).clamp(GAP_RANGE_LAYERS.0, GAP_RANGE_LAYERS.1))
            .collect()
    }

    fn mean_height_mm(&self, p_mm: [f64; 2]) -> f64 {
        let Some((cx, cy)) = self.grid.cell_of(p_mm) else {
            return 0.0;
        };
        let (mut sum, mut count) = (0.0, 0usize);
        for &(dx, dy) in &self.face {
            let (x, y) = (cx as i64 + dx, cy as i64 + dy);
            if x >= 0 && y >= 0 && (x as usize) < self.grid.nx && (y as usize) < self.grid.ny {
                sum += self.height_mm[self.grid.index(x as usize, y as usize)];
            }
            count += 1;
        }
        sum / count as f64
    }

    fn add(&mut self, layer: &DepositGrid, layer_height_mm: f64) {
        for (h, f) in self.height_mm.iter_mut().zip(&layer.fill) {
            *h += f64::from(*f) * layer_height_mm;
        }
    }
}

/// An empty deposit grid covering the trajectory with [`MARGIN_MM`] around it.
pub fn grid_for(trajectory: &Trajectory) -> DepositGrid {
    let (origin, max) = grid_corners_mm(trajectory);
    DepositGrid::covering(origin, max, CELL_MM)
}

/// The lower-left and upper-right corners of [`grid_for`]'s grid (mm).
fn grid_corners_mm(trajectory: &Trajectory) -> ([f64; 2], [f64; 2]) {
    let fold = |v: &[f64], f: fn(f64, f64) -> f64, init: f64| v.iter().copied().fold(init, f);
    let min = [fold(&trajectory.x_mm, f64::min, f64::INFINITY), fold(&trajectory.y_mm, f64::min, f64::INFINITY)];
    let max =
        [fold(&trajectory.x_mm, f64::max, f64::NEG_INFINITY), fold(&trajectory.y_mm, f64::max, f64::NEG_INFINITY)];
    // Snap the origin to the cell lattice so that grids of the same path coincide.
    let origin =
        [((min[0] - MARGIN_MM) / CELL_MM).floor() * CELL_MM, ((min[1] - MARGIN_MM) / CELL_MM).floor() * CELL_MM];
    (origin, [max[0] + MARGIN_MM, max[1] + MARGIN_MM])
}

/// Refuses a trajectory whose grid would exceed [`DEPOSIT_SIDE_CELLS`], before it is allocated.
fn check_grid_size(trajectory: &Trajectory) -> Result<(), ThermalError> {
    let (origin, max) = grid_corners_mm(trajectory);
    let cells = |axis: usize| ((max[axis] - origin[axis]) / CELL_MM).ceil();
    let limit = *DEPOSIT_SIDE_CELLS.end() as f64;
    if cells(0) <= limit && cells(1) <= limit {
        return Ok(());
    }
    let message = format!(
        "the part needs a deposit grid of {}×{} cells of {CELL_MM} mm; the virtual printer prints parts up to {limit} cells per side",
        cells(0),
        cells(1)
    );
    Err(ThermalError::BadTrajectory { message })
}

/// Cell offsets within `radius_mm`, nearest first (ties broken by angle so that the
/// order does not favour a side).
pub fn spread_offsets(cell_mm: f64, radius_mm: f64) -> Vec<(i32, i32)> {
    let reach = (radius_mm / cell_mm).ceil() as i32;
    let r2 = (radius_mm / cell_mm).powi(2);
    let mut offsets: Vec<(i32, i32, i64, f64)> = Vec::new();
    for dy in -reach..=reach {
        for dx in -reach..=reach {
            let d2 = i64::from(dx * dx + dy * dy);
            if (d2 as f64) <= r2 {
                offsets.push((dx, dy, d2, f64::from(dy).atan2(f64::from(dx))));
            }
        }
    }
    offsets.sort_by(|a, b| a.2.cmp(&b.2).then(a.3.total_cmp(&b.3)));
    offsets.into_iter().map(|(dx, dy, _, _)| (dx, dy)).collect()
}

/// What every layer of one print shares: the path, the layer height, the squeeze-out
/// fraction and the precomputed squeeze-out offsets.
struct LayerPrinter<'a> {
    trajectory: &'a Trajectory,
    layer_height_mm: f64,
    squeeze_out: f64,
    offsets: Vec<(i32, i32)>,
    /// Cells the nozzle's face passes over (see [`super::capillary`]).
    held: Vec<bool>,
}

/// A layer being deposited: the grid and its per-cell state.
struct LayerCells {
    grid: DepositGrid,
    fill: Vec<f64>,
    deposit_time_s: Vec<f32>,
    /// Sub-quad centres and areas of the quadrilateral being spread (reused).
    scratch: Vec<([f64; 2], f64)>,
    /// Thickest the layer may be in each cell (layer heights): the room between the
    /// part below and the nozzle plane, clamped to [`GAP_RANGE_LAYERS`].
    headroom: Vec<f64>,
}

impl<'a> LayerPrinter<'a> {
    fn new(trajectory: &'a Trajectory, setup: &PrintSetup, squeeze_out: f64) -> Self {
        let offsets = spread_offsets(CELL_MM, SQUEEZE_REACH_MM);
        let grid = grid_for(trajectory);
        let to_cells = |k: usize| {
            let [ox, oy] = grid.origin_mm;
            [(trajectory.x_mm[k] - ox) / CELL_MM, (trajectory.y_mm[k] - oy) / CELL_MM]
        };
        let face_cells = setup.nozzle_mm / 2.0 / CELL_MM;
        let held = cells_near((0..trajectory.len()).map(to_cells), face_cells, grid.nx, grid.ny);
        Self { trajectory, layer_height_mm: setup.layer_height_mm, squeeze_out, offsets, held }
    }

    /// Deposits one layer with the actual flow `flow_mm3_s` (mm³/s per sample) under a
    /// nozzle that leaves `gap_mm` above the part at each sample: the bead is squeezed
    /// to the gap, so its reach is E/(|v|·gap) (eq. 3 with the gap for h).
    fn print(
        &self,
        layer: usize,
        flow_mm3_s: Vec<f64>,
        gap_mm: &[f64],
        headroom: Vec<f64>,
        flow_factor: f64,
    ) -> Result<LayerDeposit, ThermalError> {
        let trajectory = self.trajectory;
        let h = self.layer_height_mm;
        let squeezed: Vec<f64> = flow_mm3_s.iter().zip(gap_mm).map(|(e, gap)| e * h / gap).collect();
        let directions = allocate_directions(trajectory, &squeezed, h, &DdaParams::default())?;
        let edges = capped_edges(trajectory, &directions);
        let grid = grid_for(trajectory);
        let cells = grid.nx * grid.ny;
        let mut layer_cells = LayerCells {
            grid,
            fill: vec![0.0; cells],
            deposit_time_s: vec![f32::INFINITY; cells],
            scratch: Vec::new(),
            headroom,
        };
        let cell_volume_mm3 = CELL_MM * CELL_MM * self.layer_height_mm;
        let (mut extruded_mm3, mut lost_cells) = (0.0, 0.0);
        let last_quad = trajectory.len().saturating_sub(2);
        for (k, flow) in flow_mm3_s.iter().enumerate() {
            let volume_mm3 = flow * trajectory.dt_s;
            extruded_mm3 += volume_mm3;
            if volume_mm3 <= 0.0 {
                continue;
            }
            let volume_cells = volume_mm3 / cell_volume_mm3;
            let t_s = trajectory.t_s[k] as f32;
            let q = k.min(last_quad);
            let quad = [edges[q].0, edges[q + 1].0, edges[q + 1].1, edges[q].1];
            lost_cells += layer_cells.spread_over_quad(quad, (1.0 - self.squeeze_out) * volume_cells, t_s);
            if self.squeeze_out > 0.0 {
                lost_cells += self.squeeze(&mut layer_cells, k, self.squeeze_out * volume_cells, t_s);
            }
        }
        let (nx, ny) = (layer_cells.grid.nx, layer_cells.grid.ny);
        let radius_cells = (THIN_FEATURE_RADIUS_MM / CELL_MM).round() as usize;
        let reach_cells = (MAX_COLLAPSE_MM / CELL_MM).round() as usize;
        LayerFill { fill: &mut layer_cells.fill, deposit_time_s: &mut layer_cells.deposit_time_s, nx, ny }
            .collapse_thin_features(&self.held, radius_cells, reach_cells);
        lost_cells += layer_cells.squeeze_to_headroom(&self.offsets);
        let LayerCells { mut grid, fill, deposit_time_s, .. } = layer_cells;
        grid.fill = fill.iter().map(|f| *f as f32).collect();
        let lost_mm3 = lost_cells * cell_volume_mm3;
        Ok(LayerDeposit { layer, grid, deposit_time_s, flow_mm3_s, extruded_mm3, lost_mm3, flow_factor })
    }

    /// The squeeze-out part of sample `k`: fills the nearest free cells; returns what
    /// found no room (cells).
    fn squeeze(&self, cells: &mut LayerCells, k: usize, volume_cells: f64, t_s: f32) -> f64 {
        let nozzle = [self.trajectory.x_mm[k], self.trajectory.y_mm[k]];
        match cells.grid.cell_of(nozzle) {
            Some(centre) => cells.pour(centre, volume_cells, t_s, &self.offsets),
            None => volume_cells,
        }
    }
}

impl LayerCells {
    /// Pours `volume_cells` into the cells nearest `centre` (in the order of `offsets`)
    /// that have room under their headroom; returns what found none (cells).
    fn pour(&mut self, centre: (usize, usize), mut volume_cells: f64, t_s: f32, offsets: &[(i32, i32)]) -> f64 {
        let (cx, cy) = (centre.0 as i64, centre.1 as i64);
        for &(dx, dy) in offsets {
            if volume_cells <= 0.0 {
                return 0.0;
            }
            let (x, y) = (cx + i64::from(dx), cy + i64::from(dy));
            if x < 0 || y < 0 || x >= self.grid.nx as i64 || y >= self.grid.ny as i64 {
                continue;
            }
            let i = self.grid.index(x as usize, y as usize);
            let room = self.headroom[i] - self.fill[i];
            if room <= 0.0 {
                continue;
            }
            if self.deposit_time_s[i].is_infinite() {
                self.deposit_time_s[i] = t_s;
            }
            let add = room.min(volume_cells);
            self.fill[i] += add;
            volume_cells -= add;
        }
        volume_cells.max(0.0)
    }

    /// The nozzle face's squeeze (module doc): every cell filled above its headroom
    /// pours the excess into the nearest cells with room, earliest deposit first;
    /// returns what found no room within `offsets` (cells).
    fn squeeze_to_headroom(&mut self, offsets: &[(i32, i32)]) -> f64 {
        let mut over: Vec<usize> = (0..self.fill.len()).filter(|&i| self.fill[i] > self.headroom[i]).collect();
        over.sort_by(|&a, &b| self.deposit_time_s[a].total_cmp(&self.deposit_time_s[b]).then(a.cmp(&b)));
        let mut lost = 0.0;
        for i in over {
            let excess = self.fill[i] - self.headroom[i];
            if excess <= 0.0 {
                continue;
            }
            self.fill[i] = self.headroom[i];
            lost += self.pour((i % self.grid.nx, i / self.grid.nx), excess, self.deposit_time_s[i], offsets);
        }
        lost
    }

    /// Spreads `volume_cells` (full-cell units) uniformly by area over the bilinear
    /// quadrilateral `[left_k, left_k+1, right_k+1, right_k]`; returns what fell off
    /// the grid. A degenerate quadrilateral (no area: the head at rest) gets the
    /// volume in equal parts along its sub-quads.
    fn spread_over_quad(&mut self, quad: [[f64; 2]; 4], volume_cells: f64, t_s: f32) -> f64 {
        if volume_cells <= 0.0 {
            return 0.0;
        }
        let [a, b, c, d] = quad;
        let across = distance(a, d).max(distance(b, c));
        let along = distance(a, b).max(distance(d, c));
        let n_u = ((across / SUBSTEP_MM).ceil() as usize).max(1);
        let n_s = ((along / SUBSTEP_MM).ceil() as usize).max(1);
        // Sub-quad (i, j) has centre P(u, s) and area |∂P/∂u × ∂P/∂s|·Δu·Δs (the factor
        // Δu·Δs cancels in the shares).
        self.scratch.clear();
        let mut total = 0.0;
        for i in 0..n_u {
            let u = (i as f64 + 0.5) / n_u as f64;
            let (left, right) = (lerp2(a, d, u), lerp2(b, c, u));
            let d_s = sub(right, left);
            for j in 0..n_s {
                let s = (j as f64 + 0.5) / n_s as f64;
                let d_u = lerp2(sub(d, a), sub(c, b), s);
                let area = (d_u[0] * d_s[1] - d_u[1] * d_s[0]).abs();
                total += area;
                self.scratch.push((lerp2(left, right, s), area));
            }
        }
        let equal = total <= f64::EPSILON;
        let mut lost = 0.0;
        for k in 0..self.scratch.len() {
            let (point, area) = self.scratch[k];
            let share = if equal { 1.0 / self.scratch.len() as f64 } else { area / total };
            lost += self.add(point, share * volume_cells, t_s);
        }
        lost
    }

    /// Adds `volume_cells` at `point_mm`, split bilinearly between the four cells
    /// whose centres surround it; returns the part that falls off the grid.
    fn add(&mut self, point_mm: [f64; 2], volume_cells: f64, t_s: f32) -> f64 {
        let fx = (point_mm[0] - self.grid.origin_mm[0]) / self.grid.cell_mm - 0.5;
        let fy = (point_mm[1] - self.grid.origin_mm[1]) / self.grid.cell_mm - 0.5;
        if fx < 0.0 || fy < 0.0 {
            return volume_cells; // within half a cell of the grid's low border: off the grid
        }
        let (x0, y0) = ((fx as usize) as f64, (fy as usize) as f64); // floor of a non-negative value
        let (ax, ay) = (fx - x0, fy - y0);
        let mut lost = 0.0;
        for (dx, dy, weight) in [
            (0.0, 0.0, (1.0 - ax) * (1.0 - ay)),
            (1.0, 0.0, ax * (1.0 - ay)),
            (0.0, 1.0, (1.0 - ax) * ay),
            (1.0, 1.0, ax * ay),
        ] {
            let (x, y) = (x0 + dx, y0 + dy);
            let share = weight * volume_cells;
            if x >= self.grid.nx as f64 || y >= self.grid.ny as f64 {
                lost += share;
                continue;
            }
            let i = self.grid.index(x as usize, y as usize);
            self.fill[i] += share;
            if share > 0.0 && self.deposit_time_s[i].is_infinite() {
                self.deposit_time_s[i] = t_s;
            }
        }
        lost
    }
}

/// Left and right bead edges p ± w·n_dep of every sample (eqs 10-11 with κ_eff along
/// the allocated direction n_dep), with the half widths capped at [`MAX_SPREAD_MM`].
fn capped_edges(trajectory: &Trajectory, directions: &DepositionDirections) -> Vec<([f64; 2], [f64; 2])> {
    let boundary = boundary_points(trajectory, directions);
    (0..trajectory.len())
        .map(|k| {
            let p = [trajectory.x_mm[k], trajectory.y_mm[k]];
            let (sin, cos) = directions.deposition_heading_rad[k].sin_cos();
            let left_mm = boundary.left_half_width_mm[k].min(MAX_SPREAD_MM);
            let right_mm = boundary.right_half_width_mm[k].min(MAX_SPREAD_MM);
            ([p[0] - left_mm * sin, p[1] + left_mm * cos], [p[0] + right_mm * sin, p[1] - right_mm * cos])
        })
        .collect()
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn lerp2(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// True left and right half widths (mm) of the deposit at every trajectory sample,
/// measured along the path normal from the nozzle position to where the fill drops
/// below one half (linear interpolation between 0.005 mm steps, up to 3 mm).
pub fn half_widths_mm(grid: &DepositGrid, trajectory: &Trajectory) -> Vec<(f64, f64)> {
    let directions = unit_tangents(trajectory);
    (0..trajectory.len())
        .map(|k| {
            let p = [trajectory.x_mm[k], trajectory.y_mm[k]];
            let [tx, ty] = directions[k];
            let left = edge_distance_mm(grid, p, [-ty, tx]);
            let right = edge_distance_mm(grid, p, [ty, -tx]);
            (left, right)
        })
        .collect()
}

/// Direction of travel at every sample; at rest, that of the nearest moving sample.
fn unit_tangents(trajectory: &Trajectory) -> Vec<[f64; 2]> {
    let speeds = trajectory.speed_mm_s();
    let mut out = vec![[1.0, 0.0]; trajectory.len()];
    let moving: Vec<usize> = (0..trajectory.len()).filter(|&k| speeds[k] > 1e-9).collect();
    if moving.is_empty() {
        return out;
    }
    for (k, dir) in out.iter_mut().enumerate() {
        let j = match moving.binary_search(&k) {
            Ok(i) => moving[i],
            Err(i) => moving[i.min(moving.len() - 1)],
        };
        *dir = [trajectory.vx_mm_s[j] / speeds[j], trajectory.vy_mm_s[j] / speeds[j]];
    }
    out
}

/// Distance from `p` along the unit direction `dir` to the first crossing of fill = 0.5
/// (linear between 0.005 mm steps, up to 3 mm; 0 if `p` is empty): the true half width
/// of the deposit along any direction, as the truth tables and the evaluation use it.
pub fn edge_distance_mm(grid: &DepositGrid, p: [f64; 2], dir: [f64; 2]) -> f64 {
    const STEP_MM: f64 = 0.005;
    let mut prev = grid.fill_at(p);
    if prev < 0.5 {
        return 0.0;
    }
    for i in 1..=600 {
        let d = i as f64 * STEP_MM;
        let f = grid.fill_at([p[0] + d * dir[0], p[1] + d * dir[1]]);
        if f < 0.5 {
            return d - STEP_MM * (0.5 - f) / (prev - f);
        }
        prev = f;
    }
    600.0 * STEP_MM
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn conventional() -> (PrintSetup, Trajectory, LayerDeposit) {
        let setup = PrintSetup::paper_defaults();
        let trajectory = Trajectory::corner_test(&setup).unwrap();
        let v_e = setup.conventional_command(&trajectory);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut layers = print_part(&setup, &trajectory, &v_e, 1, &Effects::none(), &mut rng).unwrap();
        (setup, trajectory, layers.remove(0))
    }

    #[test]
    fn deposited_volume_equals_extruded_volume() {
        // Mass conservation: Σ fill·cell area·h = ∫E dt, nothing lost.
        let (setup, trajectory, deposit) = conventional();
        let deposited = deposit.grid.area_mm2() * setup.layer_height_mm;
        let integral: f64 = deposit.flow_mm3_s.iter().sum::<f64>() * trajectory.dt_s;
        assert!(deposit.lost_mm3 == 0.0, "lost {}", deposit.lost_mm3);
        assert!((deposited - integral).abs() < 1e-5 * integral, "{deposited} vs {integral}");
        assert!((deposit.extruded_mm3 - integral).abs() < 1e-9 * integral);
    }

    #[test]
    fn squeezed_out_melt_is_conserved_too() {
        let setup = PrintSetup::paper_defaults();
        let trajectory = Trajectory::corner_test(&setup).unwrap();
        let v_e = setup.conventional_command(&trajectory);
        let effects = Effects::from_pairs([("melt_squeeze_out", 0.5)]).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let deposit = print_part(&setup, &trajectory, &v_e, 1, &effects, &mut rng).unwrap().remove(0);
        let deposited = deposit.grid.area_mm2() * setup.layer_height_mm;
        assert!(deposit.lost_mm3 == 0.0, "lost {}", deposit.lost_mm3);
        assert!((deposited - deposit.extruded_mm3).abs() < 1e-5 * deposit.extruded_mm3);
    }

    #[test]
    fn no_layer_rises_above_its_nozzle_plane() {
        // The nozzle face squeezes sideways what eqs 5-11 stack at a slow apex: on the bed
        // no cell holds more than one layer height, each layer keeps its volume, and the
        // part's top never rises above the nozzle plane of the last layer, so no corner
        // pile grows from layer to layer. On the straight edge the next layer is unchanged.
        let setup = PrintSetup::paper_defaults();
        let trajectory = Trajectory::corner_test(&setup).unwrap();
        let v_e = setup.conventional_command(&trajectory);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let layers = print_part(&setup, &trajectory, &v_e, 3, &Effects::none(), &mut rng).unwrap();
        let h = setup.layer_height_mm;
        let first_max = layers[0].grid.fill.iter().copied().fold(0.0f32, f32::max);
        assert!(first_max <= 1.0 + 1e-5, "layer 0 holds {first_max} layer heights");
        let mut top_mm = vec![0.0f64; layers[0].grid.fill.len()];
        for (layer, deposit) in layers.iter().enumerate() {
            assert!(deposit.lost_mm3 == 0.0, "layer {layer} lost {}", deposit.lost_mm3);
            let deposited = deposit.grid.area_mm2() * h;
            assert!((deposited - deposit.extruded_mm3).abs() < 1e-5 * deposit.extruded_mm3);
            top_mm.iter_mut().zip(&deposit.grid.fill).for_each(|(t, f)| *t += f64::from(*f) * h);
            let highest = top_mm.iter().copied().fold(0.0, f64::max);
            assert!(highest <= (layer + 1) as f64 * h * (1.0 + 1e-5), "layer {layer}: top at {highest} mm");
        }
        let k = straight_sample(&trajectory);
        let width = |d: &LayerDeposit| {
            let (l, r) = half_widths_mm(&d.grid, &trajectory)[k];
            (l + r) / d.flow_factor
        };
        assert!((width(&layers[1]) - width(&layers[0])).abs() < 0.01);
    }

    #[test]
    fn an_overfull_cell_pours_its_excess_into_the_nearest_cells_with_room() {
        // Five layer heights in one cell of an empty bed: the cell keeps one, its four
        // edge neighbours (distance 1, nearest first) take one each, with its deposit time.
        let grid = DepositGrid::covering([0.0, 0.0], [0.42, 0.42], CELL_MM);
        let cells = grid.nx * grid.ny;
        let centre = grid.index(10, 10);
        let (mut fill, mut time) = (vec![0.0; cells], vec![f32::INFINITY; cells]);
        (fill[centre], time[centre]) = (5.0, 0.5);
        let mut layer =
            LayerCells { grid, fill, deposit_time_s: time, scratch: Vec::new(), headroom: vec![1.0; cells] };
        let lost = layer.squeeze_to_headroom(&spread_offsets(CELL_MM, 0.1));
        assert_eq!(lost, 0.0);
        assert!((layer.fill.iter().sum::<f64>() - 5.0).abs() < 1e-12);
        for (x, y) in [(10, 10), (9, 10), (11, 10), (10, 9), (10, 11)] {
            let i = layer.grid.index(x, y);
            assert_eq!((layer.fill[i], layer.deposit_time_s[i]), (1.0, 0.5), "cell ({x}, {y})");
        }
        // A cell already full has no room: the excess goes one ring farther.
        layer.fill.iter_mut().for_each(|f| *f = 0.0);
        layer.fill[centre] = 2.0;
        layer.fill[layer.grid.index(9, 10)] = 1.0;
        layer.squeeze_to_headroom(&spread_offsets(CELL_MM, 0.1));
        assert_eq!(layer.fill[layer.grid.index(9, 10)], 1.0);
        assert!((layer.fill.iter().sum::<f64>() - 3.0).abs() < 1e-12);
        assert!(layer.fill.iter().all(|f| *f <= 1.0));
    }

    #[test]
    fn a_part_too_large_for_the_deposit_grid_is_refused_before_the_grid_is_allocated() {
        // 300 mm at 0.02 mm cells is 15 300 cells per side (about 4 GB of state).
        let setup = PrintSetup::paper_defaults();
        let t: Vec<f64> = (0..100).map(|k| k as f64 * setup.sample_period_s).collect();
        let x: Vec<f64> = (0..100).map(|k| k as f64 * 3.0).collect();
        let trajectory = Trajectory::from_samples(&t, &x, &vec![0.0; 100]).unwrap();
        let v_e = setup.conventional_command(&trajectory);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let err = print_part(&setup, &trajectory, &v_e, 1, &Effects::none(), &mut rng).unwrap_err().to_string();
        assert!(err.contains("the virtual printer prints parts up to 8192 cells per side"), "{err}");
    }

    #[test]
    fn straight_edge_has_the_nominal_width() {
        // Mid left side (x = 0, after a gentle corner taken at full speed) the flow has
        // settled and eq. 3 gives the bead width w = E/(h|v|) = bead_width × flow factor.
        let (setup, _, deposit) = conventional();
        let grid = &deposit.grid;
        let (centre, _) = models::thermal::setup::straight_test_point();
        for dy_mm in [-1.0, 0.0, 1.0] {
            let (_, iy) = grid.cell_of([centre[0], centre[1] + dy_mm]).unwrap();
            // Only the side's cells: the zig-zag teeth cross the same row farther in.
            let near_edge = |ix: usize| (grid.cell_center_mm(ix, iy)[0] - centre[0]).abs() < 1.0;
            let filled = (0..grid.nx).filter(|&ix| near_edge(ix) && grid.fill[grid.index(ix, iy)] >= 0.5).count();
            let width_mm = filled as f64 * grid.cell_mm;
            let expected = setup.bead_width_mm * deposit.flow_factor;
            assert!((width_mm - expected).abs() <= grid.cell_mm, "dy {dy_mm}: {width_mm} vs {expected}");
        }
    }

    #[test]
    fn sharper_corners_get_more_excess_material() {
        // Excess within 1.5 mm of the vertex: material outside the ideal bead (farther than
        // w/2 from the polygon) plus what piles above one layer inside it. The head slows
        // more at a sharper corner while the flow lags, so more material arrives there.
        let (setup, trajectory, deposit) = conventional();
        let path = models::thermal::setup::corner_test_path();
        let excess = |angle: f64| {
            let corner = trajectory.corners.iter().find(|c| (c.interior_angle_deg - angle).abs() < 1e-6).unwrap();
            excess_mm2(&deposit.grid, &path, corner.vertex_mm, 1.5, setup.bead_width_mm / 2.0)
        };
        let (sharp, blunt) = (excess(45.0), excess(120.0));
        assert!(sharp > blunt && sharp > 0.05, "45°: {sharp} mm², 120°: {blunt} mm²");
    }

    #[test]
    fn truth_widths_match_the_bead_on_straight_edges() {
        let (setup, trajectory, deposit) = conventional();
        let widths = half_widths_mm(&deposit.grid, &trajectory);
        let k = straight_sample(&trajectory);
        let (l, r) = widths[k];
        let half = setup.bead_width_mm * deposit.flow_factor / 2.0;
        assert!((l - half).abs() < 0.015 && (r - half).abs() < 0.015, "{l} {r} vs {half}");
    }

    /// The trajectory sample nearest the middle of the left side.
    pub(crate) fn straight_sample(trajectory: &Trajectory) -> usize {
        trajectory.nearest_sample(models::thermal::setup::straight_test_point().0)
    }

    /// Fill-weighted area (volume / h) within `radius` of `vertex` beyond the ideal bead.
    fn excess_mm2(grid: &DepositGrid, path: &[[f64; 2]], vertex: [f64; 2], radius: f64, half: f64) -> f64 {
        let mut area = 0.0;
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                let c = grid.cell_center_mm(ix, iy);
                if (c[0] - vertex[0]).hypot(c[1] - vertex[1]) > radius {
                    continue;
                }
                let fill = f64::from(grid.fill[grid.index(ix, iy)]);
                let beyond = if distance_to_polygon(path, c) > half { fill } else { (fill - 1.0).max(0.0) };
                area += beyond * grid.cell_mm * grid.cell_mm;
            }
        }
        area
    }

    fn distance_to_polygon(path: &[[f64; 2]], p: [f64; 2]) -> f64 {
        (0..path.len())
            .map(|i| {
                let (a, b) = (path[i], path[(i + 1) % path.len()]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
                (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
            })
            .fold(f64::INFINITY, f64::min)
    }
}
