//! `figure.inkjet_model_vs_scan`: the paper-002 layer-to-layer model against the profiler
//! scans of a print, in the style of Lu, Zheng, Mishra 2015 Fig. 8 (the model's
//! prediction of an open-loop printed cylinder, showing edge shrinkage) and Figs 21-22
//! (measured vs model-predicted four-layer cuboid, both dome-shaped): aerial heat maps of
//! the measured profile and of the model run open loop from the first scan with the
//! printed patterns, on a shared scale, and their cross-sections through the middle row.
//! Reads `profiles.parquet` of an `inkjet.scan_residuals` stage. Cells below
//! [`NO_MATERIAL_FRACTION`] of the desired height are drawn as bare substrate, so the
//! profiler's ±1 µm noise off the part does not speckle the maps.

use plotters::coord::Shift;
use plotters::prelude::{DrawingArea, DrawingBackend};

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::inkjet::profiles;

use crate::figures::inkjet::height_maps::{draw, Cell, Print};
use crate::read::{f64s, ints, no_rows, read_parquet};
use crate::style::{draw_png_and_svg, text};

/// The `figure.inkjet_model_vs_scan` stage kind.
pub struct InkjetModelVsScanFigure;

const SIZE_PX: (u32, u32) = (1400, 900);
/// Cells lower than this fraction of the desired height count as having no material.
pub const NO_MATERIAL_FRACTION: f64 = 0.05;

pipeline::params! {
    /// The parameters of `figure.inkjet_model_vs_scan`.
    pub struct ModelVsScanParams {
        /// Figure title (default: a generic description).
        pub title: String = "",
        /// Layer to show (0 = the last one in the table).
        pub layer: i64 [0, 100_000] = 0,
        /// Height drawn as the dashed reference line and against which the captions' mean
        /// error is taken (µm).
        pub desired_height_um: f64 [0.0, 10_000.0],
    }
}

/// The scans and the model's predictions drawn.
const RESIDUALS: Input = Input::one(
    "residuals",
    &[Source::Stage("inkjet.scan_residuals")],
    "the measured and model-predicted profiles per layer (`profiles.parquet`)",
)
.reading(&[Reads {
    table: &profiles::TABLE,
    columns: &[
        profiles::layer,
        profiles::x_index,
        profiles::y_index,
        profiles::x_um,
        profiles::y_um,
        profiles::measured_um,
        profiles::model_um,
    ],
}]);

impl Stage for InkjetModelVsScanFigure {
    type Params = ModelVsScanParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.inkjet_model_vs_scan",
        version: 1,
        summary: "Measured (profiler) vs model-predicted height maps of one layer of an inkjet-scans print, aerial and middle-row side views → inkjet_model_vs_scan.png/.svg",
        implements: "paper 002 Fig. 8 (model prediction of an open-loop print), Figs 21-22 (measured vs predicted four-layer cuboid)",
        inputs: &[RESIDUALS],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &ModelVsScanParams) -> Result<(), StageError> {
        let desired = p.desired_height_um;
        let prints = load(&ctx.input(&RESIDUALS).dir.join(profiles::TABLE.file()), p.layer, desired)?;
        let title = crate::figures::common::title_or(&p.title, || {
            "Layer-to-layer model (eqs 2-7) against the profiler scan".to_string()
        });
        let stem = ctx.output_path("inkjet_model_vs_scan")?;
        draw_png_and_svg(
            &stem,
            SIZE_PX,
            |a| draw_titled(a, &title, &prints, desired),
            |a| draw_titled(a, &title, &prints, desired),
        )
    }
}

fn draw_titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    prints: &[Print; 2],
    desired_um: f64,
) -> Result<(), String> {
    let area = area.margin(12, 8, 8, 12).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    draw(&area, prints, desired_um)
}

/// The measured and the model-predicted profile of `layer` (0: the last) as two prints,
/// captioned with their mean error against `desired_um` and std over the cells above
/// half the desired height (the part).
fn load(path: &std::path::Path, layer: i64, desired_um: f64) -> Result<[Print; 2], StageError> {
    let df = read_parquet(path)?;
    let layers = ints(&df, profiles::layer, path)?;
    let last =
        layers.iter().copied().max().ok_or_else(|| no_rows(path, profiles::layer, "one row per layer and cell"))?;
    let layer = if layer == 0 { last } else { layer };
    let (xi, yi) = (ints(&df, profiles::x_index, path)?, ints(&df, profiles::y_index, path)?);
    let (x, y) = (f64s(&df, profiles::x_um, path)?, f64s(&df, profiles::y_um, path)?);
    let rows: Vec<usize> = (0..df.height()).filter(|&r| layers[r] == layer).collect();
    if rows.is_empty() {
        return Err(no_rows(path, profiles::layer, &format!("rows of layer {layer}")));
    }
    let print = |column: &str, label: &str| -> Result<Print, StageError> {
        let h = f64s(&df, column, path)?;
        let cells: Vec<Cell> = rows
            .iter()
            .map(|&r| {
                let height_um = if h[r] < NO_MATERIAL_FRACTION * desired_um { 0.0 } else { h[r] };
                Cell { x_index: xi[r], y_index: yi[r], x_um: x[r], y_um: y[r], height_um }
            })
            .collect();
        let part: Vec<f64> = cells.iter().map(|c| c.height_um).filter(|&v| v > desired_um / 2.0).collect();
        let n = part.len().max(1) as f64;
        let mean = part.iter().sum::<f64>() / n;
        let std = (part.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
        Ok(Print {
            controller: label.to_string(),
            layers: layer,
            mean_err_um: (desired_um - mean).abs(),
            std_um: std,
            cells,
        })
    };
    Ok([print(profiles::measured_um, "profiler scan")?, print(profiles::model_um, "model prediction")?])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, declared, noise, write_declared};
    use polars::df;

    /// Two layers of a 12 × 12 square part: the "scan" 10 % lower and noisy, the
    /// "model" nominal.
    fn profiles(dir: &std::path::Path) {
        let (mut layer, mut xi, mut yi, mut x, mut y, mut measured, mut model) =
            (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
        for k in 1..=2i64 {
            for j in 0..12i64 {
                for i in 0..12i64 {
                    let inside = (2..10).contains(&i) && (2..10).contains(&j);
                    let h = if inside { 7.6 * k as f64 } else { 0.0 };
                    layer.push(k);
                    xi.push(i);
                    yi.push(j);
                    x.push(i as f64 * 263.0);
                    y.push(j as f64 * 263.0);
                    measured.push(0.9 * h + noise((k * 144 + j * 12 + i) as usize));
                    model.push(h);
                }
            }
        }
        let df = df!(profiles::layer => layer, profiles::x_index => xi, profiles::y_index => yi, profiles::x_um => x,
            profiles::y_um => y, profiles::measured_um => measured, profiles::model_um => model)
        .expect("frame");
        write_declared(dir, &profiles::TABLE, declared(&profiles::TABLE, df));
    }

    #[test]
    fn loads_the_last_layer_and_draws_scan_against_model() {
        let (input, out) = (tempfile::tempdir().expect("tempdir"), tempfile::tempdir().expect("tempdir"));
        profiles(input.path());
        let prints = load(&input.path().join("profiles.parquet"), 0, 15.2).expect("loads");
        assert_eq!(prints[1].layers, 2);
        assert!((prints[1].mean_err_um).abs() < 1e-9, "the model sits at 15.2 µm");
        // Cells off the part (noise around 0) are drawn as bare substrate.
        assert!(prints[0].cells.iter().filter(|c| c.x_index < 2).all(|c| c.height_um == 0.0));
        assert!(load(&input.path().join("profiles.parquet"), 7, 15.2).is_err(), "no layer 7");
        let stem = out.path().join("inkjet_model_vs_scan");
        draw_png_and_svg(
            &stem,
            SIZE_PX,
            |a| draw_titled(a, "synthetic", &prints, 15.2),
            |a| draw_titled(a, "synthetic", &prints, 15.2),
        )
        .expect("draws");
        assert_drawn(&stem);
    }
}
