//! `thermal.true_widths_evaluate`: the widths a perfect camera would read (evaluation: reads
//! `truth/` of the dataset; ARCHITECTURE.md). Paper 003's compensation (Sec. 2.4, eqs
//! 31-39) turns the widths the thermal camera reads into a flow correction; fed the
//! printer's true widths instead, it shows the method's limit on this printer apart
//! from measurement (the "oracle" of the chen2024 report), and the difference between
//! the two shows what the thermal reading costs.
//!
//! For every layer the monitor read and every trajectory sample, the true half widths
//! of the conventional print's deposit (`truth/deposit_L*.png`) along the monitor's own
//! allocated deposition directions (eqs 13-26, `directions.parquet`), from the commanded
//! point to where the fill drops below one half (`edge_distance_mm`, as
//! `thermal.accuracy_evaluate` scores the monitor). `widths.parquet` has the columns of
//! the monitor's, so `thermal.compensate` takes it as its optional `widths` input.
//!
//! `width_errors.parquet`: per layer and region, |(w_l + w_r) − true width| of the
//! monitor's readings at the samples it read: median and 90th percentile (nearest rank)
//! near the corners (within `corner_radius_mm` of a CAD vertex) and away from them.

use std::path::Path;

use datasets::thermal::deposition::edge_distance_mm;
use datasets::thermal::sequence::ThermalTruth;
use models::stats::{finite_median, nearest_rank_quantile};
use models::thermal::DepositGrid;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use rayon::prelude::*;

use super::common::{f64s, ints, open_sequence, read_table, sample_index, trajectory_of};
use crate::roles;
use crate::table::{f64_col, frame, i64_col, str_col};
use tables::thermal::{directions, true_widths, width_errors, widths};

/// The `thermal.true_widths_evaluate` stage kind.
pub struct TrueWidthsStage;

/// The monitor whose directions and readings are used.
pub const MONITOR: Input = Input::one(
    "monitor",
    &[Source::Stage("thermal.monitor")],
    "the sequence's monitor: its deposition directions (directions.parquet) and readings (widths.parquet)",
)
.reading(&[
    Reads { table: &directions::TABLE, columns: &[directions::sample, directions::dep_x, directions::dep_y] },
    Reads { table: &widths::TABLE, columns: &[widths::layer, widths::sample, widths::w_left_mm, widths::w_right_mm] },
]);

pipeline::params! {
    /// The parameters of `thermal.true_widths_evaluate`.
    pub struct TrueWidthsParams {
        /// A reading within this distance of a CAD vertex counts as near a corner in width_errors.parquet (mm); about two bead widths.
        pub corner_radius_mm: f64 [0.0, 5.0] = 0.5,
    }
}

impl Stage for TrueWidthsStage {
    type Params = TrueWidthsParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.true_widths_evaluate",
        version: 1,
        summary: "The deposit's true half widths along the monitor's deposition directions, and the monitor's width error near and away from the corners → widths, width_errors",
        implements: "paper 003 Sec. 2.4 (eqs 31-32) with a perfect camera (evaluation: reads truth/)",
        inputs: &[roles::THERMAL_SEQUENCE, MONITOR],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&true_widths::TABLE, &width_errors::TABLE];

    fn run(&self, ctx: &mut StageContext, params: &TrueWidthsParams) -> Result<(), StageError> {
        let sequence_dir = &ctx.input(&roles::THERMAL_SEQUENCE).dir;
        let seq = open_sequence(sequence_dir)?;
        let truth = ThermalTruth::open(sequence_dir).map_err(StageError::domain)?;
        let trajectory = trajectory_of(&seq)?;
        let monitor = Monitored::read(&ctx.input(&MONITOR).dir, trajectory.len())?;
        let points_mm: Vec<[f64; 2]> =
            (0..trajectory.len()).map(|k| [trajectory.x_mm[k], trajectory.y_mm[k]]).collect();
        let near_corner: Vec<bool> = points_mm
            .iter()
            .map(|p| seq.path_mm.iter().any(|v| (p[0] - v[0]).hypot(p[1] - v[1]) <= params.corner_radius_mm))
            .collect();
        let mut widths = WidthRows::default();
        let mut errors = ErrorRows::default();
        for &layer in &monitor.layers {
            let layer_index = usize::try_from(layer).map_err(|_| monitor.bad_layer(layer))?;
            let grid = truth.deposit(layer_index).map_err(StageError::domain)?;
            let true_mm = true_half_widths_mm(&grid, &points_mm, &monitor.left_dirs);
            errors.push_layer(layer, &monitor.read_width_errors_mm(layer, &true_mm), &near_corner);
            widths.push_layer(layer, &trajectory.t_s, &points_mm, &true_mm);
        }
        ctx.write_table(true_widths::TABLE.name, &mut widths.into_frame()?)?;
        ctx.write_table(width_errors::TABLE.name, &mut errors.into_frame()?)?;
        Ok(())
    }
}

/// The true half widths (left, right) of `grid` at each point along its unit left
/// direction and the opposite one (mm).
pub fn true_half_widths_mm(grid: &DepositGrid, points_mm: &[[f64; 2]], left_dirs: &[[f64; 2]]) -> Vec<(f64, f64)> {
    points_mm
        .par_iter()
        .zip(left_dirs)
        .map(|(&p, &d)| (edge_distance_mm(grid, p, d), edge_distance_mm(grid, p, [-d[0], -d[1]])))
        .collect()
}

/// What the stage reads of the monitor: its deposition directions and its readings.
struct Monitored {
    dir: std::path::PathBuf,
    /// The layers it read, ascending.
    layers: Vec<i64>,
    /// Unit left deposition direction per trajectory sample.
    left_dirs: Vec<[f64; 2]>,
    /// Rows of `widths.parquet`: layer, sample, w_l + w_r (mm; NaN: unread).
    readings: Vec<(i64, usize, f64)>,
}

impl Monitored {
    fn read(dir: &Path, samples: usize) -> Result<Self, StageError> {
        let dirs_file = dir.join(directions::TABLE.file());
        let dirs = read_table(dir, &directions::TABLE.file())?;
        let sample = ints(&dirs, directions::sample, &dirs_file)?;
        let (dep_x, dep_y) = (f64s(&dirs, directions::dep_x, &dirs_file)?, f64s(&dirs, directions::dep_y, &dirs_file)?);
        let mut left_dirs = vec![[f64::NAN; 2]; samples];
        for (row, &k) in sample.iter().enumerate() {
            left_dirs[sample_index(&dirs_file, row, k, samples)?] = [dep_x[row], dep_y[row]];
        }
        if let Some(k) = left_dirs.iter().position(|d| !d[0].is_finite() || !d[1].is_finite()) {
            return Err(StageError::BadInput {
                file: dirs_file,
                location: Some(format!("sample {k}")),
                expected: "a finite deposition direction (dep_x, dep_y) for every trajectory sample".into(),
            });
        }
        let file = dir.join(widths::TABLE.file());
        let df = read_table(dir, &widths::TABLE.file())?;
        let (layer, sample) = (ints(&df, widths::layer, &file)?, ints(&df, widths::sample, &file)?);
        let (wl, wr) = (f64s(&df, widths::w_left_mm, &file)?, f64s(&df, widths::w_right_mm, &file)?);
        let mut readings = Vec::with_capacity(layer.len());
        for row in 0..layer.len() {
            readings.push((layer[row], sample_index(&file, row, sample[row], samples)?, wl[row] + wr[row]));
        }
        let mut layers = layer.clone();
        layers.sort_unstable();
        layers.dedup();
        Ok(Self { dir: dir.to_path_buf(), layers, left_dirs, readings })
    }

    /// |(w_l + w_r) − true width| of every finite reading of `layer`, with its sample.
    fn read_width_errors_mm(&self, layer: i64, true_mm: &[(f64, f64)]) -> Vec<(usize, f64)> {
        self.readings
            .iter()
            .filter(|(l, _, w)| *l == layer && w.is_finite())
            .map(|&(_, k, w)| (k, (w - true_mm[k].0 - true_mm[k].1).abs()))
            .collect()
    }

    fn bad_layer(&self, layer: i64) -> StageError {
        StageError::BadInput {
            file: self.dir.join("widths.parquet"),
            location: Some("column layer".into()),
            expected: format!("a layer index of 0 or more, found {layer}"),
        }
    }
}

/// `widths.parquet`: the columns of the monitor's that `thermal.compensate` reads.
#[derive(Default)]
struct WidthRows {
    layer: Vec<i64>,
    sample: Vec<i64>,
    t_s: Vec<f64>,
    x_mm: Vec<f64>,
    y_mm: Vec<f64>,
    w_left_mm: Vec<f64>,
    w_right_mm: Vec<f64>,
}

impl WidthRows {
    fn push_layer(&mut self, layer: i64, t_s: &[f64], points_mm: &[[f64; 2]], true_mm: &[(f64, f64)]) {
        for (k, (p, w)) in points_mm.iter().zip(true_mm).enumerate() {
            self.layer.push(layer);
            self.sample.push(k as i64);
            self.t_s.push(t_s[k]);
            self.x_mm.push(p[0]);
            self.y_mm.push(p[1]);
            self.w_left_mm.push(w.0);
            self.w_right_mm.push(w.1);
        }
    }

    fn into_frame(self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            i64_col(true_widths::layer, self.layer),
            i64_col(true_widths::sample, self.sample),
            f64_col(true_widths::t_s, self.t_s),
            f64_col(true_widths::x_mm, self.x_mm),
            f64_col(true_widths::y_mm, self.y_mm),
            f64_col(true_widths::w_left_mm, self.w_left_mm),
            f64_col(true_widths::w_right_mm, self.w_right_mm),
        ])
    }
}

/// `width_errors.parquet`: one row per (layer, region).
#[derive(Default)]
struct ErrorRows {
    layer: Vec<i64>,
    region: Vec<String>,
    n: Vec<i64>,
    median_abs_err_mm: Vec<f64>,
    p90_abs_err_mm: Vec<f64>,
}

impl ErrorRows {
    /// The layer's errors `(sample, |error|)` split by whether the sample is near a corner.
    fn push_layer(&mut self, layer: i64, errors_mm: &[(usize, f64)], near_corner: &[bool]) {
        for (region, near) in [("corner", true), ("straight", false)] {
            let mut errs: Vec<f64> = errors_mm.iter().filter(|(k, _)| near_corner[*k] == near).map(|e| e.1).collect();
            self.layer.push(layer);
            self.region.push(region.into());
            self.n.push(errs.len() as i64);
            self.median_abs_err_mm.push(finite_median(errs.iter().copied()));
            self.p90_abs_err_mm.push(nearest_rank_quantile(&mut errs, 0.9));
        }
    }

    fn into_frame(self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            i64_col(width_errors::layer, self.layer),
            str_col(width_errors::region, self.region),
            i64_col(width_errors::n, self.n),
            f64_col(width_errors::median_abs_err_mm, self.median_abs_err_mm),
            f64_col(width_errors::p90_abs_err_mm, self.p90_abs_err_mm),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deposit grid filled over |y| ≤ `half_mm` (cells of 0.01 mm, 4 × 2 mm).
    fn strip(half_mm: f64) -> DepositGrid {
        let mut grid = DepositGrid::covering([-2.0, -1.0], [2.0, 1.0], 0.01);
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                if grid.cell_center_mm(ix, iy)[1].abs() <= half_mm {
                    let i = grid.index(ix, iy);
                    grid.fill[i] = 1.0;
                }
            }
        }
        grid
    }

    #[test]
    fn a_straight_strip_has_its_half_width_on_both_sides_and_the_secant_when_tilted() {
        let grid = strip(0.25);
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let widths = true_half_widths_mm(&grid, &[[0.0, 0.0], [0.5, 0.1]], &[[0.0, 1.0], [-s, c]]);
        assert!((widths[0].0 - 0.25).abs() < 0.01 && (widths[0].1 - 0.25).abs() < 0.01, "{widths:?}");
        // Tilted by 30° from the normal: (0.25 ∓ 0.1)/cos 30°.
        assert!((widths[1].0 - 0.15 / c).abs() < 0.012 && (widths[1].1 - 0.35 / c).abs() < 0.012, "{widths:?}");
    }

    #[test]
    fn errors_split_by_region_with_their_median_and_90th_percentile() {
        let mut rows = ErrorRows::default();
        let errors: Vec<(usize, f64)> = (0..10).map(|k| (k, k as f64)).collect();
        let near: Vec<bool> = (0..10).map(|k| k < 4).collect();
        rows.push_layer(2, &errors, &near);
        assert_eq!(rows.region, ["corner", "straight"]);
        assert_eq!(rows.n, [4, 6]);
        assert_eq!(rows.median_abs_err_mm, [1.5, 6.5]);
        assert_eq!(rows.p90_abs_err_mm, [3.0, 9.0]);
    }
}
