//! Deposition of the virtual thermal printer (DESIGN §5.3 "Deposition"; paper 003
//! Sec. 2.1 and eq. 34): commanded deposition velocity v_e(t) (the extruder's E-axis
//! velocity, mm/s of filament) → commanded flow E_cmd = A_fil·v_e → melt pressure
//! state G(s)·E_cmd with G(s) = 1/(τs+1) → actual flow E = max(0, state) → material on
//! a fine [`DepositGrid`] by mass conservation. A negative command is a retraction: it
//! pulls the pressure state down faster than letting it decay, and the nozzle only
//! extrudes while the state is positive (it cannot suck deposited material back), so
//! a retracted extruder must be primed again before material flows.
//!
//! The paper's geometric model (eqs 5-11) assumes a slender bead whose material goes
//! perpendicular to the path, and patches corners with the deposition direction
//! allocation (eqs 13-26). This printer does not use those equations. At each trajectory
//! sample (1 ms) the volume E·dt leaves the nozzle and fills the nearest cells around
//! the nozzle tip that are not yet full, in order of distance, up to the layer height
//! ("squeeze-out": melt flows where there is room). The offsets are sorted by distance
//! once. On a straight line at steady state the empty cells ahead of the nozzle form a
//! crescent of area 2r·|v|·dt, so the bead width 2r = E/(h·|v|), paper eq. 3, emerges;
//! at corners the head slows while the lagging flow keeps coming, the material piles up
//! around the tip and the over-deposition of Sec. 3.3 emerges instead of being drawn.
//!
//! Simplifications, stated: distances are taken from the centre of the nozzle's cell
//! (position error ≤ half a cell diagonal, 0.014 mm at 0.02 mm cells); a cell is filled
//! to at most the layer height, so excess material spreads sideways instead of raising
//! the layer; each layer is deposited on the plane of the layer below as if it were
//! flat (the part is printed from the same path every layer, so the previous layer's
//! footprint carries the new one); melt still in the nozzle when the last sample is
//! reached stays there (no ooze). Each layer's flow is scaled by a seeded factor
//! 1 + 0.5 %·N(0,1), the filament-diameter tolerance of commercial PLA (±0.02 mm on
//! 1.75 mm is ±2.3 % in area, 0.5 % is its layer-to-layer part); the flow lag starts
//! from rest at every layer (the travel between layers lets the melt pressure relax).

use models::thermal::dynamics::first_order_lag;
use models::thermal::{DepositGrid, PrintSetup, ThermalError, Trajectory};
use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::effects::Effects;

/// Edge of a deposit cell (mm): a tenth of the nominal half-width, 1/20 of the nozzle.
pub const CELL_MM: f64 = 0.02;
/// Margin of the deposit grid around the path (mm): room for corner bulges.
pub const MARGIN_MM: f64 = 1.5;
/// Largest distance from the nozzle at which material is placed (mm).
pub const MAX_SPREAD_MM: f64 = 1.4;
/// Standard deviation of the per-layer flow factor (filament diameter tolerance).
pub const FLOW_FACTOR_SD: f64 = 0.005;

/// One printed layer.
#[derive(Debug, Clone, PartialEq)]
pub struct LayerDeposit {
    /// Layer index, 0 = first.
    pub layer: usize,
    /// Fill fractions of the layer height.
    pub grid: DepositGrid,
    /// Time (s from the layer's start) at which each cell first received material;
    /// `f32::INFINITY` where it never did.
    pub deposit_time_s: Vec<f32>,
    /// Actual flow E at each trajectory sample (mm³/s).
    pub flow_mm3_s: Vec<f64>,
    /// Extruded volume ∫E dt (mm³).
    pub extruded_mm3: f64,
    /// Volume that found no room within [`MAX_SPREAD_MM`] or fell off the grid (mm³);
    /// zero for any realistic flow.
    pub lost_mm3: f64,
    /// Flow factor drawn for this layer (filament tolerance).
    pub flow_factor: f64,
}

/// Prints `layers` layers of `trajectory` with the commanded deposition velocity
/// `deposition_velocity_mm_s` (E-axis, mm/s of filament, one value per sample; the
/// conventional print uses [`PrintSetup::nominal_deposition_velocity_mm_s`] of |v|),
/// through the actual τ of `effects`. This is what a re-print with a compensated v_e calls.
pub fn print_part<R: Rng>(
    setup: &PrintSetup,
    trajectory: &Trajectory,
    deposition_velocity_mm_s: &[f64],
    layers: usize,
    effects: &Effects,
    rng: &mut R,
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
    let offsets = spread_offsets(CELL_MM, MAX_SPREAD_MM);
    let normal = Normal::new(1.0, FLOW_FACTOR_SD).expect("valid normal");
    let factors: Vec<f64> = (0..layers).map(|_| normal.sample(rng).clamp(0.97, 1.03)).collect();
    let layers = factors
        .iter()
        .enumerate()
        .map(|(layer, &factor)| {
            let flow: Vec<f64> = nominal_flow.iter().map(|e| e * factor).collect();
            deposit_layer(layer, trajectory, flow, setup.layer_height_mm, &offsets, factor)
        })
        .collect();
    Ok(layers)
}

/// The conventional print's command: at every sample the deposition velocity that
/// gives the nominal bead at the commanded path speed (flow ∝ speed, DESIGN §5.3).
pub fn conventional_command(setup: &PrintSetup, trajectory: &Trajectory) -> Vec<f64> {
    trajectory.speed_mm_s().iter().map(|v| setup.nominal_deposition_velocity_mm_s(*v)).collect()
}

/// An empty deposit grid covering the trajectory with [`MARGIN_MM`] around it.
pub fn grid_for(trajectory: &Trajectory) -> DepositGrid {
    let fold = |v: &[f64], f: fn(f64, f64) -> f64, init: f64| v.iter().copied().fold(init, f);
    let min = [fold(&trajectory.x_mm, f64::min, f64::INFINITY), fold(&trajectory.y_mm, f64::min, f64::INFINITY)];
    let max =
        [fold(&trajectory.x_mm, f64::max, f64::NEG_INFINITY), fold(&trajectory.y_mm, f64::max, f64::NEG_INFINITY)];
    // Snap the origin to the cell lattice so that grids of the same path coincide.
    let origin =
        [((min[0] - MARGIN_MM) / CELL_MM).floor() * CELL_MM, ((min[1] - MARGIN_MM) / CELL_MM).floor() * CELL_MM];
    DepositGrid::covering(origin, [max[0] + MARGIN_MM, max[1] + MARGIN_MM], CELL_MM)
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

/// Deposits one layer: fills the nearest free cells around the nozzle at every sample.
fn deposit_layer(
    layer: usize,
    trajectory: &Trajectory,
    flow_mm3_s: Vec<f64>,
    layer_height_mm: f64,
    offsets: &[(i32, i32)],
    flow_factor: f64,
) -> LayerDeposit {
    let mut grid = grid_for(trajectory);
    let mut fill = vec![0.0f64; grid.nx * grid.ny];
    let mut deposit_time_s = vec![f32::INFINITY; grid.nx * grid.ny];
    let cell_volume_mm3 = grid.cell_mm * grid.cell_mm * layer_height_mm;
    let (mut extruded_mm3, mut lost_mm3) = (0.0, 0.0);
    for k in 0..trajectory.len() {
        let volume_mm3 = flow_mm3_s[k] * trajectory.dt_s;
        extruded_mm3 += volume_mm3;
        let Some(cell) = grid.cell_of([trajectory.x_mm[k], trajectory.y_mm[k]]) else {
            lost_mm3 += volume_mm3;
            continue;
        };
        let cells = volume_mm3 / cell_volume_mm3;
        let t_s = trajectory.t_s[k] as f32;
        let left = fill_nearest(&grid, &mut fill, &mut deposit_time_s, cell, cells, t_s, offsets);
        lost_mm3 += left * cell_volume_mm3;
    }
    grid.fill = fill.iter().map(|f| *f as f32).collect();
    LayerDeposit { layer, grid, deposit_time_s, flow_mm3_s, extruded_mm3, lost_mm3, flow_factor }
}

/// Pours `cells` (volume in full-cell units) into the free cells nearest to `centre`;
/// returns what found no room.
fn fill_nearest(
    grid: &DepositGrid,
    fill: &mut [f64],
    deposit_time_s: &mut [f32],
    centre: (usize, usize),
    mut cells: f64,
    t_s: f32,
    offsets: &[(i32, i32)],
) -> f64 {
    if cells <= 0.0 {
        return 0.0;
    }
    let (cx, cy) = (centre.0 as i64, centre.1 as i64);
    for &(dx, dy) in offsets {
        let (x, y) = (cx + i64::from(dx), cy + i64::from(dy));
        if x < 0 || y < 0 || x >= grid.nx as i64 || y >= grid.ny as i64 {
            continue;
        }
        let i = y as usize * grid.nx + x as usize;
        let room = 1.0 - fill[i];
        if room <= 0.0 {
            continue;
        }
        if deposit_time_s[i].is_infinite() {
            deposit_time_s[i] = t_s;
        }
        let add = room.min(cells);
        fill[i] += add;
        cells -= add;
        if cells <= 0.0 {
            return 0.0;
        }
    }
    cells
}

/// Fill fraction at `p_mm`, bilinear between cell centres (0 outside the grid).
pub fn fill_at(grid: &DepositGrid, p_mm: [f64; 2]) -> f64 {
    let fx = (p_mm[0] - grid.origin_mm[0]) / grid.cell_mm - 0.5;
    let fy = (p_mm[1] - grid.origin_mm[1]) / grid.cell_mm - 0.5;
    let (x0, y0) = (fx.floor(), fy.floor());
    let (ax, ay) = (fx - x0, fy - y0);
    let get = |x: f64, y: f64| -> f64 {
        if x < 0.0 || y < 0.0 || x >= grid.nx as f64 || y >= grid.ny as f64 {
            0.0
        } else {
            f64::from(grid.fill[y as usize * grid.nx + x as usize])
        }
    };
    let bottom = get(x0, y0) * (1.0 - ax) + get(x0 + 1.0, y0) * ax;
    let top = get(x0, y0 + 1.0) * (1.0 - ax) + get(x0 + 1.0, y0 + 1.0) * ax;
    bottom * (1.0 - ay) + top * ay
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
    let mut prev = fill_at(grid, p);
    if prev < 0.5 {
        return 0.0;
    }
    for i in 1..=600 {
        let d = i as f64 * STEP_MM;
        let f = fill_at(grid, [p[0] + d * dir[0], p[1] + d * dir[1]]);
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
        let v_e = conventional_command(&setup, &trajectory);
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
    fn sharper_corners_bulge_more() {
        // Over-deposit = material farther than w/2 from the polygon, within 1.5 mm of the vertex.
        let (setup, trajectory, deposit) = conventional();
        let path = models::thermal::setup::corner_test_path();
        let over = |angle: f64| {
            let corner = trajectory.corners.iter().find(|c| (c.interior_angle_deg - angle).abs() < 1e-6).unwrap();
            over_deposit_mm2(&deposit.grid, &path, corner.vertex_mm, 1.5, setup.bead_width_mm / 2.0)
        };
        let (sharp, blunt) = (over(45.0), over(120.0));
        assert!(sharp > blunt && sharp > 0.01, "45°: {sharp} mm², 120°: {blunt} mm²");
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

    fn over_deposit_mm2(grid: &DepositGrid, path: &[[f64; 2]], vertex: [f64; 2], radius: f64, half: f64) -> f64 {
        let mut area = 0.0;
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                let c = grid.cell_center_mm(ix, iy);
                if (c[0] - vertex[0]).hypot(c[1] - vertex[1]) > radius {
                    continue;
                }
                if distance_to_polygon(path, c) > half {
                    area += f64::from(grid.fill[grid.index(ix, iy)]) * grid.cell_mm * grid.cell_mm;
                }
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
