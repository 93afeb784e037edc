//! The two-material print of paper 002 Sec. V-A (Figs 13-15): the junction section of two
//! pipes on a 100 × 100 grid, part material A with `(h1, h2, h3)` and sacrificial support
//! B with `(g1, g2, g3)`, the material of each cell chosen per layer by Fig. 10's rule
//! (part iff `(i·L, j·L, H_ij) ∈ M`, eqs 6-7), and the edge-deformation metrics that
//! compare open and closed loop.
//!
//! What the paper leaves open, and our choices:
//! - **Geometry** (the figures are not in our text copy): a T junction of two horizontal
//!   pipes, the pipe Fig. 15 says must be freed of support. The main pipe runs along x
//!   through the middle of the grid, the branch along y from the main axis to the far
//!   edge; outer radius 20 cells (5.3 mm), bore radius 13 cells, in plan. A 100-cell
//!   grid cannot hold a round pipe a few hundred µm high, so the cross-sections are
//!   ellipses squashed in z: the outer wall spans the whole block height
//!   `0 ≤ z ≤ h_d = 200 µm` (axis at 100 µm, vertical semi-axes 100 µm outside and
//!   65 µm in the bore). `M` is the union of the two walls minus the union of the two
//!   bores, so the branch's bore opens into the main pipe. The printed block is the
//!   grid with a 3-cell margin (94 × 94 cells), every cell printed with A or B.
//! - **Support droplets** `g1 = 4.0, g2 = 0.8, g3 = 0.3 µm` (the paper gives none): a
//!   lower-viscosity support that spreads more than the part material (lower centre,
//!   higher neighbours) and whose droplet adds 8.4 µm instead of 7.6 µm. The difference
//!   is what deforms the part at the part/support interface when the open loop assumes
//!   the part's fixed layer height.
//! - **Edge deformation**: the object's top surface after the support is removed is, per
//!   cell, the height after the last layer that deposited part material there; the
//!   desired top is the highest `z ≤ h_d` with `(x, y, z) ∈ M`. The *edge* region is the
//!   part's plan-view cells within 2 cells of a cell without part (the pipes' flanks and
//!   the junction opening, where part meets support), the *interior* the rest.

use super::controller::open_loop_layer_count;
use super::errors::InkjetError;
use super::experiments::{PrintOutcome, Scenario};
use super::grid::{Grid, Pattern};
use super::height_model::DropletCoeffs;
use super::mpc::MpcParams;
use super::objective::Target;
use super::printer::TruthPrinter;

/// Two-material printing: the part geometry `M` and the support droplets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoMaterial {
    /// The part.
    pub geometry: PipeJunction,
    /// Support droplet coefficients `(g1, g2, g3)`.
    pub support: DropletCoeffs,
}

/// A T junction of two horizontal pipes with elliptical cross-sections (see the module
/// doc). Positions in µm on the grid's coordinates `(i·L, j·L)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PipeJunction {
    /// Plan position of the junction: the main pipe's axis is `y = centre_y_um`, the
    /// branch's `x = centre_x_um` for `y ≥ centre_y_um`.
    pub centre_x_um: f64,
    /// See `centre_x_um`.
    pub centre_y_um: f64,
    /// Height of both axes, µm.
    pub axis_z_um: f64,
    /// Outer radius in plan, µm.
    pub outer_radius_um: f64,
    /// Bore radius in plan, µm.
    pub inner_radius_um: f64,
    /// Outer vertical semi-axis, µm.
    pub outer_half_height_um: f64,
    /// Bore vertical semi-axis, µm.
    pub inner_half_height_um: f64,
}

impl PipeJunction {
    /// Whether `(x, y, z)` lies in the pipe walls (the set `M` of Sec. IV-B).
    pub fn contains(&self, x_um: f64, y_um: f64, z_um: f64) -> bool {
        let dz = z_um - self.axis_z_um;
        let inside = |d: f64, r: f64, b: f64| (d / r).powi(2) + (dz / b).powi(2) <= 1.0;
        let branch = y_um >= self.centre_y_um;
        let (d_main, d_branch) = (y_um - self.centre_y_um, x_um - self.centre_x_um);
        let outer = |d| inside(d, self.outer_radius_um, self.outer_half_height_um);
        let bore = |d| inside(d, self.inner_radius_um, self.inner_half_height_um);
        let in_walls = outer(d_main) || (branch && outer(d_branch));
        let in_bores = bore(d_main) || (branch && bore(d_branch));
        in_walls && !in_bores
    }

    /// The desired top of the part at `(x, y)`: the highest `z` in `[0, h_d]` (on a
    /// 0.1 µm raster) inside `M`; `None` where no part lies above that point.
    pub fn top_um(&self, x_um: f64, y_um: f64, desired_um: f64) -> Option<f64> {
        let steps = (desired_um / 0.1).round() as usize;
        (0..=steps).rev().map(|s| s as f64 * 0.1).find(|&z| self.contains(x_um, y_um, z))
    }
}

/// Support droplets of our pipe-junction print: `g1 = 4.0, g2 = 0.8, g3 = 0.3 µm`.
pub fn support_coeffs() -> DropletCoeffs {
    DropletCoeffs { h1_um: 4.0, h2_um: 0.8, h3_um: 0.3 }
}

/// Figs 13-14: the pipe junction on a 100 × 100 grid, `h_d = 200 µm`, droplet shortfall
/// `U[0, p]`, Table I part droplets and [`support_coeffs`]; open loop 26 layers.
pub fn pipe_junction(max_shortfall: f64) -> Scenario {
    let grid = Grid::new(100, 100, Grid::paper_spacing_um()).expect("valid grid");
    let spacing = grid.spacing_um;
    let desired_um = 200.0;
    let margin_um = 3.0 * spacing;
    let far_um = 96.0 * spacing;
    let block = Pattern::from_fn(grid, |x, y| x >= margin_um && y >= margin_um && x <= far_um && y <= far_um);
    let geometry = PipeJunction {
        centre_x_um: 49.5 * spacing,
        centre_y_um: 49.5 * spacing,
        axis_z_um: desired_um / 2.0,
        outer_radius_um: 20.0 * spacing,
        inner_radius_um: 13.0 * spacing,
        outer_half_height_um: desired_um / 2.0,
        inner_half_height_um: 0.65 * desired_um / 2.0,
    };
    let model = DropletCoeffs::paper_table1();
    let open_loop_layers = open_loop_layer_count(desired_um, model);
    Scenario {
        target: Target::uniform(grid, block, desired_um).expect("non-empty block"),
        model,
        truth: TruthPrinter::paper(max_shortfall),
        open_loop_layers,
        mpc: MpcParams::recommended(),
        max_layers: 4 * open_loop_layers + 10,
        two_material: Some(TwoMaterial { geometry, support: support_coeffs() }),
    }
}

/// Where on the part a metric is taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Region {
    /// Plan-view part cells within the band of a non-part cell.
    Edge,
    /// The other plan-view part cells.
    Interior,
}

impl Region {
    /// `edge` / `interior`.
    pub fn name(self) -> &'static str {
        match self {
            Region::Edge => "edge",
            Region::Interior => "interior",
        }
    }
}

/// Error of the printed part's top surface against the desired one over a region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionMetrics {
    /// The region.
    pub region: Region,
    /// Number of cells in it.
    pub cells: usize,
    /// RMS of `printed top − desired top`, µm.
    pub rmse_um: f64,
    /// Largest `|printed top − desired top|`, µm.
    pub max_abs_um: f64,
    /// Mean of `printed top − desired top`, µm.
    pub mean_err_um: f64,
}

/// Desired part top per cell (`None` off the part in plan view, and outside the printed
/// block).
pub fn desired_part_top(scenario: &Scenario) -> Result<Vec<Option<f64>>, InkjetError> {
    let two = scenario.two_material.as_ref().ok_or(InkjetError::InvalidParameter {
        name: "two_material",
        value: 0.0,
        reason: "edge deformation needs a two-material scenario",
    })?;
    let grid = scenario.target.grid();
    let desired_um = scenario.target.mean_desired_um();
    let block = &scenario.target.footprint.droplet;
    Ok((0..grid.len())
        .map(|c| {
            let (i, j) = grid.coords(c);
            let (x, y) = grid.position_um(i, j);
            if block[c] {
                two.geometry.top_um(x, y, desired_um)
            } else {
                None
            }
        })
        .collect())
}

/// Edge and interior metrics of the printed part top (see the module doc); a plan-view
/// part cell that never received part material counts with a top at 0.
pub fn edge_deformation(
    scenario: &Scenario,
    outcome: &PrintOutcome,
    band_cells: usize,
) -> Result<[RegionMetrics; 2], InkjetError> {
    let desired = desired_part_top(scenario)?;
    let grid = scenario.target.grid();
    scenario.target.grid().check_len("part top", outcome.part_top_um.len())?;
    let mut errors: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    for (c, want) in desired.iter().enumerate() {
        let Some(want) = want else { continue };
        let got = outcome.part_top_um[c].unwrap_or(0.0);
        let edge = near_non_part(grid, &desired, c, band_cells);
        errors[if edge { 0 } else { 1 }].push(got - want);
    }
    Ok([region_metrics(Region::Edge, &errors[0]), region_metrics(Region::Interior, &errors[1])])
}

/// Whether a cell within `band` cells (Chebyshev distance) of `c` is off the part.
fn near_non_part(grid: Grid, desired: &[Option<f64>], c: usize, band: usize) -> bool {
    let (i, j) = grid.coords(c);
    let band = band as isize;
    (-band..=band).any(|dj| {
        (-band..=band).any(|di| match grid.offset(i, j, di, dj) {
            Some((ni, nj)) => desired[grid.index(ni, nj)].is_none(),
            None => true,
        })
    })
}

fn region_metrics(region: Region, errors: &[f64]) -> RegionMetrics {
    let n = errors.len().max(1) as f64;
    RegionMetrics {
        region,
        cells: errors.len(),
        rmse_um: (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        max_abs_um: errors.iter().fold(0.0, |m, e| m.max(e.abs())),
        mean_err_um: errors.iter().sum::<f64>() / n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inkjet::experiments::{run_closed_loop, run_open_loop};
    use crate::inkjet::height_model::Material;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_junction_is_two_hollow_pipes() {
        let scenario = pipe_junction(0.2);
        let geometry = scenario.two_material.unwrap().geometry;
        let (xc, yc, l) = (geometry.centre_x_um, geometry.centre_y_um, 263.256);
        // On the main axis the bore is empty, the wall crest lies on top.
        assert!(!geometry.contains(10.0 * l, yc, 100.0));
        assert!(geometry.contains(10.0 * l, yc, 190.0));
        // Far from both pipes: support.
        assert!(!geometry.contains(10.0 * l, 5.0 * l, 100.0));
        // The branch exists only on one side of the main pipe.
        assert!(geometry.contains(xc, yc + 35.0 * l, 190.0));
        assert!(!geometry.contains(xc, yc - 35.0 * l, 190.0));
        // The branch bore opens into the main pipe: no wall at the junction's centre top.
        assert!(!geometry.contains(xc, yc + 2.0 * l, 150.0));
        // The crest of the main pipe is at h_d, the flank lower.
        assert!((geometry.top_um(10.0 * l, yc, 200.0).unwrap() - 200.0).abs() < 0.11);
        let flank = geometry.top_um(10.0 * l, yc + 19.0 * l, 200.0).unwrap();
        let expected = 100.0 + 100.0 * (1.0 - (19.0f64 / 20.0).powi(2)).sqrt();
        assert!((flank - expected).abs() < 0.11, "{flank} vs {expected}");
    }

    #[test]
    fn the_material_map_follows_the_height() {
        let scenario = pipe_junction(0.0);
        let grid = scenario.target.grid();
        let on_crest = grid.index(20, 50);
        let low = crate::inkjet::HeightMap::flat(grid, 10.0);
        let high = crate::inkjet::HeightMap::flat(grid, 195.0);
        // On the main axis, low down is the bore's floor wall, half-way up the bore.
        assert_eq!(scenario.layer_coeffs(&low).0[on_crest], Material::Part);
        assert_eq!(scenario.layer_coeffs(&crate::inkjet::HeightMap::flat(grid, 100.0)).0[on_crest], Material::Support);
        assert_eq!(scenario.layer_coeffs(&high).0[on_crest], Material::Part);
        assert_eq!(scenario.layer_coeffs(&high).1[grid.index(20, 5)], support_coeffs());
    }

    #[test]
    fn closed_loop_cuts_the_edge_deformation_of_the_open_loop() {
        let scenario = pipe_junction(0.2);
        let open = run_open_loop(&scenario, &mut ChaCha8Rng::seed_from_u64(4));
        let closed = run_closed_loop(&scenario, &mut ChaCha8Rng::seed_from_u64(4)).unwrap();
        let [open_edge, open_interior] = edge_deformation(&scenario, &open, 2).unwrap();
        let [closed_edge, closed_interior] = edge_deformation(&scenario, &closed, 2).unwrap();
        assert!(open_edge.cells > 100 && open_interior.cells > 100);
        assert!(closed_edge.rmse_um < 0.6 * open_edge.rmse_um, "{closed_edge:?} vs {open_edge:?}");
        assert!(closed_interior.rmse_um < 0.6 * open_interior.rmse_um, "{closed_interior:?} vs {open_interior:?}");
        assert!(closed.metrics.mean_error_um < 2.0 && closed.metrics.std_um < open.metrics.std_um);
    }

    #[test]
    fn region_metrics_of_known_errors() {
        let m = region_metrics(Region::Edge, &[-3.0, 1.0, 2.0]);
        assert_eq!((m.cells, m.max_abs_um, m.mean_err_um), (3, 3.0, 0.0));
        assert!((m.rmse_um - (14.0f64 / 3.0).sqrt()).abs() < 1e-12);
    }
}
