//! `inkjet.print_experiment`: one simulated print of paper 002 with the truth printer
//! (droplet-volume shortfall `U[0, p]`, 1 µm profiler noise): the cylinder of Sec. V-A
//! (Figs 11-12: open-loop vs closed-loop mean error and std at `[0 20%]` / `[0 40%]`
//! variation) or the cuboid of Sec. V-D-2 (Table II: average height and Z-axis RMSD).
//! Writes the footprint metrics and the final height map.

use models::inkjet::experiments::{cuboid, cylinder, run_closed_loop, run_open_loop, PrintOutcome};
use models::inkjet::HeightMap;
use pipeline::params::ParamDefault;
use pipeline::stage::Arity;
use pipeline::{ParamSpec, ParamType, StageContext, StageError, StageKind};
use polars::prelude::DataFrame;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::table::{f64_col, frame, i64_col, str_col};

/// The `inkjet.print_experiment` stage kind.
pub struct PrintExperimentStage;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "scenario",
        ty: ParamType::Choice(&["cylinder", "cuboid"]),
        default: ParamDefault::Required,
        doc: "The part: the cylinder of Sec. V-A (h_d = 400 µm, radius 15 droplets) or the 8 × 8-droplet cuboid of Table II (h_d = 22.8 µm).",
    },
    ParamSpec {
        name: "variation_pct",
        ty: ParamType::Float { min: 0.0, max: 100.0 },
        default: ParamDefault::Required,
        doc: "Largest droplet-volume shortfall p in percent (each droplet scaled by 1 − u, u ~ U[0, p]); the paper uses 20 and 40 (Figs 11-12).",
    },
    ParamSpec {
        name: "controller",
        ty: ParamType::Choice(&["open_loop", "closed_loop"]),
        default: ParamDefault::Required,
        doc: "open_loop: the footprint h_d / h_layer times (Sec. IV-A); closed_loop: measure, solve eq. 8, print the first layer of the plan (Sec. IV-C).",
    },
];

impl StageKind for PrintExperimentStage {
    fn name(&self) -> &'static str {
        "inkjet.print_experiment"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "One simulated ink-jet print (cylinder or cuboid, open or closed loop) → summary.parquet, height_map.parquet"
    }
    fn implements(&self) -> &'static str {
        "paper 002 Sec. V-A (Figs 11-12), Sec. V-D-2 (Table II), Sec. IV (open / closed loop)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::exactly(0)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        let scenario_name = ctx.params.str("scenario").to_string();
        let controller = ctx.params.str("controller").to_string();
        let variation_pct = ctx.params.f64("variation_pct");
        let max_shortfall = variation_pct / 100.0;
        let scenario = match scenario_name.as_str() {
            "cylinder" => cylinder(max_shortfall),
            _ => cuboid(max_shortfall),
        };
        let mut rng = ChaCha8Rng::seed_from_u64(ctx.seed);
        let outcome = match controller.as_str() {
            "open_loop" => run_open_loop(&scenario, &mut rng),
            _ => run_closed_loop(&scenario, &mut rng).map_err(StageError::domain)?,
        };
        let mut summary = summary_frame(&scenario_name, &controller, variation_pct, &outcome)?;
        ctx.write_table("summary", &mut summary)?;
        let mut map = height_map_frame(&outcome.final_heights)?;
        ctx.write_table("height_map", &mut map)?;
        Ok(())
    }
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
        str_col("scenario", vec![scenario.to_string()]),
        str_col("controller", vec![controller.to_string()]),
        f64_col("variation_pct", vec![variation_pct]),
        i64_col("layers", vec![outcome.layers_printed as i64]),
        f64_col("mean_err_um", vec![m.mean_error_um]),
        f64_col("std_um", vec![m.std_um]),
        f64_col("rmsd_um", vec![m.rmsd_um]),
        f64_col("avg_height_um", vec![m.average_height_um]),
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
        i64_col("x_index", xi),
        i64_col("y_index", yi),
        f64_col("x_um", x),
        f64_col("y_um", y),
        f64_col("height_um", map.height_um.clone()),
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
        let outcome = PrintOutcome { final_heights: heights, metrics, layers_printed: 7, droplets_printed: 42 };

        let summary = summary_frame("cuboid", "closed_loop", 20.0, &outcome).unwrap();
        assert_eq!(summary.height(), 1);
        assert_eq!(summary.column("layers").unwrap().i64().unwrap().get(0), Some(7));
        assert_eq!(summary.column("rmsd_um").unwrap().f64().unwrap().get(0), Some(2.5));
        assert_eq!(summary.column("scenario").unwrap().str().unwrap().get(0), Some("cuboid"));

        let map = height_map_frame(&outcome.final_heights).unwrap();
        assert_eq!(map.height(), 6);
        // Row-major: index 4 is cell (1, 1) at (10, 10) µm.
        assert_eq!(map.column("x_index").unwrap().i64().unwrap().get(4), Some(1));
        assert_eq!(map.column("y_index").unwrap().i64().unwrap().get(4), Some(1));
        assert_eq!(map.column("y_um").unwrap().f64().unwrap().get(4), Some(10.0));
        assert_eq!(map.column("height_um").unwrap().f64().unwrap().get(4), Some(5.0));
    }
}
