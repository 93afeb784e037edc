//! `fdm.infill`: infill nonuniformity from the width model (paper 000 Sec. III, Fig. 7).
//! The piecewise model is fitted on all of a printer's lines; for each condition, k
//! lines are laid side by side at a hatch spacing (a fraction of the fitted nominal
//! width c), alternating direction as rectilinear infill does, so one line's start sits
//! beside its neighbour's end. A raster of the layer counts how many lines cover each
//! cell; between the outer centre lines, a cell covered by none is a void and one
//! covered by two or more is an overlap.
//!
//! Outputs: `infill.parquet` (printer, condition, hatch_mm, region, void_fraction,
//! overlap_fraction) for every condition and hatch, and `infill_map.parquet` (printer,
//! condition, hatch_mm, x_mm, y_mm, coverage) near both line ends for `map_condition`.

use models::fdm::{FittedPiecewise, LineKinematics, PiecewiseParams};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;
use tables::fdm::{infill, infill_map};

use crate::fdm::lines::{fit_failed, model_param_error, PrinterLines};
use crate::roles;
use crate::table::{f64_col, frame, i64_col, str_col};

/// The `fdm.infill` stage kind.
pub struct InfillStage;

pipeline::params! {
    /// The parameters of `fdm.infill`.
    pub struct InfillParams {
        /// Fit the model with phase p1 (Taz 5) or without (Taz 6).
        pub start_blob: bool,
        /// Lines laid side by side.
        pub lines: i64 [2, 50] = 6,
        /// Hatch spacing / fitted nominal width c: 1.0 = lines just touch at steady state.
        pub hatch_factor: f64 [0.3, 2.0] = 1.0,
        /// A second, overlapping hatch (slicers' usual 10-20 % overlap).
        pub tight_hatch_factor: f64 [0.3, 2.0] = 0.85,
        /// Length of the start and end regions (mm).
        pub end_region_mm: f64 [1.0, 50.0] = 10.0,
        /// Condition whose coverage map is written.
        pub map_condition: String = "S800F9000",
        /// Raster step along the lines (mm).
        pub dx_mm: f64 [0.01, 1.0] = 0.1,
        /// Raster step across the lines (mm).
        pub dy_mm: f64 [0.002, 0.2] = 0.02,
    }
}

/// Raster settings, checked.
#[derive(Debug, Clone, Copy)]
struct Layout {
    lines: usize,
    hatch_mm: f64,
    end_region_mm: f64,
    dx_mm: f64,
    dy_mm: f64,
}

/// Void and overlap fractions of one region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionStats {
    /// Fraction of cells covered by no line.
    pub void_fraction: f64,
    /// Fraction of cells covered by two or more lines.
    pub overlap_fraction: f64,
}

impl Stage for InfillStage {
    type Params = InfillParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.infill",
        version: 1,
        summary: "Lines side by side from the fitted width model: coverage raster, void and overlap fractions at the line ends → infill.parquet, infill_map.parquet",
        implements: "paper 000 Sec. III, Fig. 7 (infill nonuniformity)",
        inputs: &[roles::FDM_WIDTHS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&infill::TABLE, &infill_map::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &InfillParams) -> Result<(), StageError> {
        let printer = PrinterLines::read(&ctx.input(&roles::FDM_WIDTHS).dir)?;
        let params = PiecewiseParams { has_start_blob: p.start_blob, ..PiecewiseParams::paper_defaults() }
            .check()
            .map_err(|e| StageError::params(ctx, model_param_error(e)))?;
        let model = models::fdm::fit(&printer.lines, &params).map_err(|e| fit_failed("piecewise fit", e))?;
        let mut stats = StatsRows::default();
        let mut map = MapRows::default();
        for factor in [p.hatch_factor, p.tight_hatch_factor] {
            let layout = Layout {
                lines: p.lines as usize,
                hatch_mm: factor * model.coefficients.c_mm,
                end_region_mm: p.end_region_mm,
                dx_mm: p.dx_mm,
                dy_mm: p.dy_mm,
            };
            for (line, condition) in printer.lines.iter().zip(&printer.conditions) {
                let raster = Raster::build(&model, &line.nominal, layout).map_err(|e| fit_failed(condition, e))?;
                stats.push(&printer.printer, condition, layout.hatch_mm, &raster);
                if *condition == p.map_condition {
                    map.push(&printer.printer, condition, layout.hatch_mm, &raster);
                }
            }
        }
        ctx.write_table(infill::TABLE.name, &mut stats.into_frame()?)?;
        ctx.write_table(infill_map::TABLE.name, &mut map.into_frame()?)?;
        Ok(())
    }
}

/// Coverage counts on a regular grid: `coverage[iy * nx + ix]`.
struct Raster {
    layout: Layout,
    length_mm: f64,
    xs: Vec<f64>,
    ys: Vec<f64>,
    coverage: Vec<u32>,
}

impl Raster {
    /// Lays `layout.lines` predicted lines of `nominal` kinematics side by side.
    fn build(model: &FittedPiecewise, nominal: &LineKinematics, layout: Layout) -> Result<Self, models::fdm::FitError> {
        let length_mm = nominal.length_mm;
        let nx = (length_mm / layout.dx_mm).round() as usize + 1;
        let xs: Vec<f64> = (0..nx).map(|i| (i as f64 * layout.dx_mm).min(length_mm)).collect();
        let forward = model.predict(nominal, &xs)?;
        let w_max = forward.iter().copied().fold(0.0_f64, f64::max);
        let y_top = (layout.lines - 1) as f64 * layout.hatch_mm + w_max / 2.0;
        let ny = ((y_top + w_max / 2.0) / layout.dy_mm).ceil() as usize + 1;
        let ys: Vec<f64> = (0..ny).map(|j| -w_max / 2.0 + j as f64 * layout.dy_mm).collect();
        let mut coverage = vec![0u32; nx * ny];
        for line in 0..layout.lines {
            let centre = line as f64 * layout.hatch_mm;
            for ix in 0..nx {
                // Alternate directions: odd lines run from x = L back to 0.
                let half = if line % 2 == 0 { forward[ix] } else { forward[nx - 1 - ix] } / 2.0;
                for (iy, y) in ys.iter().enumerate() {
                    if (y - centre).abs() <= half {
                        coverage[iy * nx + ix] += 1;
                    }
                }
            }
        }
        Ok(Self { layout, length_mm, xs, ys, coverage })
    }

    /// Fractions over cells with x in `[x0, x1]` between the outer centre lines.
    fn stats(&self, x0: f64, x1: f64) -> RegionStats {
        let y_last = (self.layout.lines - 1) as f64 * self.layout.hatch_mm;
        let (mut cells, mut voids, mut overlaps) = (0usize, 0usize, 0usize);
        for (iy, _) in self.ys.iter().enumerate().filter(|(_, y)| (0.0..=y_last).contains(*y)) {
            for (ix, _) in self.xs.iter().enumerate().filter(|(_, x)| (x0..=x1).contains(*x)) {
                let c = self.coverage[iy * self.xs.len() + ix];
                cells += 1;
                voids += usize::from(c == 0);
                overlaps += usize::from(c >= 2);
            }
        }
        let n = cells.max(1) as f64;
        RegionStats { void_fraction: voids as f64 / n, overlap_fraction: overlaps as f64 / n }
    }

    fn regions(&self) -> [(&'static str, RegionStats); 3] {
        let end = self.layout.end_region_mm;
        [
            ("start", self.stats(0.0, end)),
            ("middle", self.stats(end, self.length_mm - end)),
            ("end", self.stats(self.length_mm - end, self.length_mm)),
        ]
    }
}

#[derive(Default)]
struct StatsRows {
    printer: Vec<String>,
    condition: Vec<String>,
    hatch: Vec<f64>,
    region: Vec<String>,
    void: Vec<f64>,
    overlap: Vec<f64>,
}

impl StatsRows {
    fn push(&mut self, printer: &str, condition: &str, hatch_mm: f64, raster: &Raster) {
        for (region, s) in raster.regions() {
            self.printer.push(printer.to_string());
            self.condition.push(condition.to_string());
            self.hatch.push(hatch_mm);
            self.region.push(region.to_string());
            self.void.push(s.void_fraction);
            self.overlap.push(s.overlap_fraction);
        }
    }

    fn into_frame(self) -> Result<DataFrame, StageError> {
        frame(vec![
            str_col(infill::printer, self.printer),
            str_col(infill::condition, self.condition),
            f64_col(infill::hatch_mm, self.hatch),
            str_col(infill::region, self.region),
            f64_col(infill::void_fraction, self.void),
            f64_col(infill::overlap_fraction, self.overlap),
        ])
    }
}

#[derive(Default)]
struct MapRows {
    printer: Vec<String>,
    condition: Vec<String>,
    hatch: Vec<f64>,
    x: Vec<f64>,
    y: Vec<f64>,
    coverage: Vec<i64>,
}

impl MapRows {
    /// Cells within 1.5 end regions of either end (the map of Fig. 7(b)).
    fn push(&mut self, printer: &str, condition: &str, hatch_mm: f64, raster: &Raster) {
        let window = 1.5 * raster.layout.end_region_mm;
        let near_end = |x: f64| x <= window || x >= raster.length_mm - window;
        for (iy, y) in raster.ys.iter().enumerate() {
            for (ix, x) in raster.xs.iter().enumerate().filter(|(_, x)| near_end(**x)) {
                self.printer.push(printer.to_string());
                self.condition.push(condition.to_string());
                self.hatch.push(hatch_mm);
                self.x.push(*x);
                self.y.push(*y);
                self.coverage.push(i64::from(raster.coverage[iy * raster.xs.len() + ix]));
            }
        }
    }

    fn into_frame(self) -> Result<DataFrame, StageError> {
        frame(vec![
            str_col(infill_map::printer, self.printer),
            str_col(infill_map::condition, self.condition),
            f64_col(infill_map::hatch_mm, self.hatch),
            f64_col(infill_map::x_mm, self.x),
            f64_col(infill_map::y_mm, self.y),
            i64_col(infill_map::coverage, self.coverage),
        ])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use models::fdm::synthetic::synthetic_truth;

    fn layout(hatch_mm: f64) -> Layout {
        Layout { lines: 4, hatch_mm, end_region_mm: 10.0, dx_mm: 0.1, dy_mm: 0.005 }
    }

    /// In the steady middle the predicted width is c (0.8 mm): at hatch = c lines just
    /// touch (no voids, overlap only on the touching rows), at hatch = 1.2 c a gap of
    /// 0.2 c between neighbours is void: 0.16 / 0.96 = 1/6 of the band.
    #[test]
    fn steady_middle_follows_the_hatch_geometry() {
        let model = synthetic_truth(true);
        let nominal = LineKinematics::paper_line(400.0, 50.0).unwrap();
        let touching = Raster::build(&model, &nominal, layout(0.8)).unwrap().regions()[1].1;
        assert!(touching.void_fraction < 0.02, "{touching:?}");
        let gap = Raster::build(&model, &nominal, layout(0.96)).unwrap().regions()[1].1;
        assert!((gap.void_fraction - 1.0 / 6.0).abs() < 0.02, "{gap:?}");
        assert!(gap.overlap_fraction < 1e-9);
    }
}
