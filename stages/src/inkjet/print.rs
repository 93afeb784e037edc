//! `inkjet.print_experiment`: one simulated print of paper 002 with the truth printer
//! (droplet-volume shortfall `U[0, p]`, 1 µm profiler noise): the cylinder of Sec. V-A
//! (Figs 11-12: open-loop vs closed-loop mean error and std at `[0 20%]` / `[0 40%]`
//! variation), the cuboid of Sec. V-D (Table II: average height and Z-axis RMSD; 3
//! nominal layers, or 4 as in Figs 21-23) or the two-material pipe junction of Figs
//! 13-15 (100 × 100 grid). Writes the footprint metrics and the final height map; the
//! pipe junction also writes its edge-deformation metrics, the printed part's top
//! surface and every layer's material map (for the cross-sections of Figs 13-14).

use models::inkjet::experiments::{
    cuboid_with_layers, cylinder, pipe_junction, run_print_predicting, PrintOutcome, PrintRecording, Scenario,
};
use models::inkjet::height_model::Material;
use models::inkjet::pipe_junction::{desired_part_top, edge_deformation, RegionMetrics};
use models::inkjet::HeightMap;
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::{DataFrame, IntoColumn, NamedFrom, Series};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use tables::inkjet::{edge_deformation, height_map, layers, part_top, summary};

use super::{Controller, Part};
use crate::progress::StageProgress;
use crate::table::{f64_col, frame, i64_col, str_col};

/// The `inkjet.print_experiment` stage kind.
pub struct PrintExperimentStage;

pipeline::params! {
    /// The parameters of `inkjet.print_experiment`.
    pub struct PrintParams {
        /// The part: the cylinder of Sec. V-A (h_d = 400 µm, radius 15 droplets), the 8 × 8-droplet cuboid of Table II (h_d = 22.8 µm) or the two-material pipe junction of Figs 13-15 (100 × 100 grid, h_d = 200 µm).
        pub scenario: Part,
        /// Largest droplet-volume shortfall p in percent (each droplet scaled by 1 − u, u ~ U[0, p]); the paper uses 20 and 40 (Figs 11-12).
        pub variation_pct: f64 [0.0, 100.0],
        /// open_loop: the footprint h_d / h_layer times (Sec. IV-A); closed_loop: measure, solve eq. 8, print the first layer of the plan (Sec. IV-C).
        pub controller: Controller,
        /// Open-loop layer count; 0 = the nominal h_d / (h1 + 4h2 + 4h3) (3 for the cuboid; 4 is the Sec. V-D-1 print of Figs 21-23). Ignored by the closed loop.
        pub layers: i64 [0, 10_000] = 0,
        /// Pipe junction only: width of the edge band (cells from the part's plan-view boundary) for edge_deformation.parquet.
        pub edge_band_cells: i64 [1, 10] = 2,
    }
}

impl Stage for PrintExperimentStage {
    type Params = PrintParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "inkjet.print_experiment",
        version: 2,
        summary: "One simulated ink-jet print (cylinder, cuboid or two-material pipe junction, open or closed loop) → summary.parquet, height_map.parquet (+ edge_deformation.parquet, part_top.parquet, layers.parquet for the pipe junction)",
        implements: "paper 002 Sec. V-A (Figs 11-15), Sec. V-D (Table II, Figs 21-24), Sec. IV (open / closed loop, two materials)",
        inputs: &[],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] =
        &[&summary::TABLE, &height_map::TABLE, &edge_deformation::TABLE, &part_top::TABLE, &layers::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &PrintParams) -> Result<(), StageError> {
        let (scenario_name, controller) = (p.scenario.name(), p.controller.name());
        let variation_pct = p.variation_pct;
        let layers = p.layers as usize;
        let max_shortfall = variation_pct / 100.0;
        let scenario = match p.scenario {
            Part::Cylinder => cylinder(max_shortfall),
            Part::PipeJunction => pipe_junction(max_shortfall),
            Part::Cuboid => cuboid_with_layers(max_shortfall, (layers > 0).then_some(layers)),
        };
        let law = p.controller.law();
        let two_material = scenario.two_material.is_some();
        let mut rng = ChaCha8Rng::seed_from_u64(ctx.seed);
        let progress = StageProgress::new(ctx);
        let (outcome, recording) = run_print_predicting(&scenario, law, &mut rng, two_material, None, &progress)
            .map_err(StageError::domain)?;
        drop(progress);
        let mut summary = summary_frame(scenario_name, controller, variation_pct, &outcome)?;
        ctx.write_table(summary::TABLE.name, &mut summary)?;
        let mut map = height_map_frame(&outcome.final_heights)?;
        ctx.write_table(height_map::TABLE.name, &mut map)?;
        if let Some(recording) = recording {
            let band = p.edge_band_cells as usize;
            let regions = edge_deformation(&scenario, &outcome, band).map_err(StageError::domain)?;
            let mut edges = edge_frame(scenario_name, controller, variation_pct, &regions)?;
            ctx.write_table(edge_deformation::TABLE.name, &mut edges)?;
            let mut top = part_top_frame(&scenario, &outcome)?;
            ctx.write_table(part_top::TABLE.name, &mut top)?;
            let mut layers = layers_frame(&recording)?;
            ctx.write_table(layers::TABLE.name, &mut layers)?;
        }
        Ok(())
    }
}

/// One row per region (`edge`, `interior`) of the part-top error of a two-material print.
pub fn edge_frame(
    scenario: &str,
    controller: &str,
    variation_pct: f64,
    regions: &[RegionMetrics],
) -> Result<DataFrame, StageError> {
    let n = regions.len();
    frame(vec![
        str_col(edge_deformation::scenario, vec![scenario.to_string(); n]),
        str_col(edge_deformation::controller, vec![controller.to_string(); n]),
        f64_col(edge_deformation::variation_pct, vec![variation_pct; n]),
        str_col(edge_deformation::region, regions.iter().map(|r| r.region.name().to_string()).collect()),
        i64_col(edge_deformation::cells, regions.iter().map(|r| r.cells as i64).collect()),
        f64_col(edge_deformation::rmse_um, regions.iter().map(|r| r.rmse_um).collect()),
        f64_col(edge_deformation::max_abs_um, regions.iter().map(|r| r.max_abs_um).collect()),
        f64_col(edge_deformation::mean_err_um, regions.iter().map(|r| r.mean_err_um).collect()),
    ])
}

/// One row per grid cell: the printed part's top and the desired one (null off the part).
fn part_top_frame(scenario: &Scenario, outcome: &PrintOutcome) -> Result<DataFrame, StageError> {
    let grid = scenario.target.grid();
    let desired = desired_part_top(scenario).map_err(StageError::domain)?;
    let (xi, yi): (Vec<i64>, Vec<i64>) =
        (0..grid.len()).map(|c| grid.coords(c)).map(|(i, j)| (i as i64, j as i64)).unzip();
    frame(vec![
        i64_col(part_top::x_index, xi),
        i64_col(part_top::y_index, yi),
        Series::new(part_top::part_top_um.into(), outcome.part_top_um.clone()).into_column(),
        Series::new(part_top::desired_top_um.into(), desired).into_column(),
    ])
}

/// One row per layer and cell: the profile before and after the layer (true heights) and
/// the material printed there (`part`, `support`, or `none`).
fn layers_frame(recording: &PrintRecording) -> Result<DataFrame, StageError> {
    let grid = recording.substrate_truth.grid;
    let n = grid.len() * recording.layers.len();
    let (mut layer, mut xi, mut yi) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut bottom, mut top, mut material) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let mut before = &recording.substrate_truth;
    for (k, record) in recording.layers.iter().enumerate() {
        for c in 0..grid.len() {
            let (i, j) = grid.coords(c);
            layer.push(k as i64 + 1);
            xi.push(i as i64);
            yi.push(j as i64);
            bottom.push(before.height_um[c]);
            top.push(record.truth.height_um[c]);
            let name = match (record.pattern.droplet[c], record.materials[c]) {
                (false, _) => "none",
                (true, Material::Part) => "part",
                (true, Material::Support) => "support",
            };
            material.push(name.to_string());
        }
        before = &record.truth;
    }
    frame(vec![
        i64_col(layers::layer, layer),
        i64_col(layers::x_index, xi),
        i64_col(layers::y_index, yi),
        f64_col(layers::bottom_um, bottom),
        f64_col(layers::top_um, top),
        str_col(layers::material, material),
    ])
}

/// The one-row summary of a print: scenario, controller, variation, layers printed and
/// the footprint metrics of [`models::inkjet::experiments::PrintMetrics`].
pub fn summary_frame(
    scenario: &str,
    controller: &str,
    variation_pct: f64,
    outcome: &PrintOutcome,
) -> Result<DataFrame, StageError> {
    let m = &outcome.metrics;
    frame(vec![
        str_col(summary::scenario, vec![scenario.to_string()]),
        str_col(summary::controller, vec![controller.to_string()]),
        f64_col(summary::variation_pct, vec![variation_pct]),
        i64_col(summary::layers, vec![outcome.layers_printed as i64]),
        f64_col(summary::mean_err_um, vec![m.mean_error_um]),
        f64_col(summary::std_um, vec![m.std_um]),
        f64_col(summary::rmsd_um, vec![m.rmsd_um]),
        f64_col(summary::avg_height_um, vec![m.average_height_um]),
    ])
}

/// One row per grid cell, row-major: cell indices, position `(i·L, j·L)` and height.
pub fn height_map_frame(map: &HeightMap) -> Result<DataFrame, StageError> {
    let grid = map.grid;
    let n = grid.len();
    let (mut xi, mut yi, mut x, mut y) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for index in 0..n {
        let (i, j) = grid.coords(index);
        let (px, py) = grid.position_um(i, j);
        xi.push(i as i64);
        yi.push(j as i64);
        x.push(px);
        y.push(py);
    }
    frame(vec![
        i64_col(height_map::x_index, xi),
        i64_col(height_map::y_index, yi),
        f64_col(height_map::x_um, x),
        f64_col(height_map::y_um, y),
        f64_col(height_map::height_um, map.height_um.clone()),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use models::inkjet::experiments::PrintMetrics;
    use models::inkjet::Grid;

    #[test]
    fn summary_and_height_map_tables_hold_the_outcome() {
        let grid = Grid::new(3, 2, 10.0).unwrap();
        let heights = HeightMap::from_vec(grid, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let metrics = PrintMetrics {
            mean_error_um: 1.5,
            mean_abs_error_um: 2.0,
            std_um: 0.5,
            rmsd_um: 2.5,
            average_height_um: 3.5,
        };
        let outcome = PrintOutcome {
            final_heights: heights,
            metrics,
            layers_printed: 7,
            droplets_printed: 42,
            part_top_um: Vec::new(),
        };

        let table = summary_frame("cuboid", "closed_loop", 20.0, &outcome).unwrap();
        assert_eq!(table.height(), 1);
        assert_eq!(table.column(summary::layers).unwrap().i64().unwrap().get(0), Some(7));
        assert_eq!(table.column(summary::rmsd_um).unwrap().f64().unwrap().get(0), Some(2.5));
        assert_eq!(table.column(summary::scenario).unwrap().str().unwrap().get(0), Some("cuboid"));

        let map = height_map_frame(&outcome.final_heights).unwrap();
        assert_eq!(map.height(), 6);
        // Row-major: index 4 is cell (1, 1) at (10, 10) µm.
        assert_eq!(map.column(height_map::x_index).unwrap().i64().unwrap().get(4), Some(1));
        assert_eq!(map.column(height_map::y_index).unwrap().i64().unwrap().get(4), Some(1));
        assert_eq!(map.column(height_map::y_um).unwrap().f64().unwrap().get(4), Some(10.0));
        assert_eq!(map.column(height_map::height_um).unwrap().f64().unwrap().get(4), Some(5.0));
    }
}
