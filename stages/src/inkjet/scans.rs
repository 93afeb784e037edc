//! The `inkjet-scans` stages of paper 002 (Lu, Zheng, Mishra 2015):
//! `inkjet.generate_scans` prints a scenario on the virtual printer and its output folder
//! *is* an `inkjet-scans` dataset (written by the same writer as
//! `amrepro datasets generate inkjet`); `inkjet.scan_residuals` reads any such dataset
//! (generated, or your own measured scans) through the documented format and tests the
//! paper's layer-to-layer model on it: for each layer `k`, the nominal model (eqs 2-7,
//! the dataset's `grid.toml` coefficients) predicts scan `k` from scan `k − 1` and the
//! pattern printed in layer `k`, and the residual `measured − predicted` is summarised
//! over the desired footprint.

use datasets::inkjet::{generate, GenerateOptions, InkjetScans, Scenario};
use datasets::manifest::Provenance;
use models::inkjet::height_model::{deposit_layer_into, DropletCoeffs, Material};
use models::inkjet::printer::Effects;
use models::inkjet::Grid;
use pipeline::params::{NoParams, ParamError};
use pipeline::schema::Table;
use pipeline::stage::{Output, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;
use tables::inkjet::{profiles, scan_residuals};

use super::{Controller, Part};
use crate::roles;
use crate::table::{f64_col, frame, i64_col, str_col};

/// The `inkjet.generate_scans` stage kind.
pub struct GenerateScansStage;

pipeline::params! {
    /// The parameters of `inkjet.generate_scans`.
    pub struct GenerateScansParams {
        /// The part (as in inkjet.print_experiment).
        pub scenario: Part,
        /// Largest droplet-volume shortfall p in percent (the paper's [0 20%]).
        pub variation_pct: f64 [0.0, 100.0] = 20.0,
        /// How the patterns are chosen (open loop: the footprint every layer).
        pub controller: Controller = Controller::OpenLoop,
        /// Extra effects of the virtual printer, `name=strength,...` (curing_shrinkage, levelling_flow, nozzle_bias, substrate_tilt, volume_drift; DESIGN §5.2) or `none`.
        pub effects: String = "none",
        /// Open-loop layer count; 0 = the scenario's nominal count.
        pub layers: i64 [0, 10_000] = 0,
    }
}

impl Stage for GenerateScansStage {
    type Params = GenerateScansParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "inkjet.generate_scans",
        version: 1,
        summary: "A print on the virtual ink-jet printer, scanned after every layer → an inkjet-scans dataset (dataset.toml, grid.toml, target.csv, scans.csv, patterns.csv, truth/)",
        implements: "DESIGN §4 inkjet-scans, §5.2 virtual ink-jet printer; paper 002 Sec. V (profiler after each layer)",
        inputs: &[],
        output: Output::Dataset("inkjet-scans"),
    };

    fn check(p: &GenerateScansParams) -> Result<(), ParamError> {
        Effects::parse(&p.effects).map(|_| ()).map_err(|e| ParamError::new("effects", e.to_string()))
    }

    fn run(&self, ctx: &mut StageContext, p: &GenerateScansParams) -> Result<(), StageError> {
        let layers = p.layers as usize;
        let opts = GenerateOptions {
            scenario: Scenario::parse(p.scenario.name()).map_err(StageError::domain)?,
            seed: ctx.seed,
            variation_pct: p.variation_pct,
            controller: p.controller.law(),
            effects: Effects::parse(&p.effects).map_err(StageError::domain)?,
            open_loop_layers: (layers > 0).then_some(layers),
        };
        let (dataset, truth) = generate(&opts).map_err(StageError::domain)?;
        dataset.write(ctx.output_dir(), Some(&truth)).map_err(StageError::domain)?;
        Ok(())
    }
}

/// The `inkjet.scan_residuals` stage kind.
pub struct ScanResidualsStage;

impl Stage for ScanResidualsStage {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "inkjet.scan_residuals",
        version: 1,
        summary: "The paper's layer-to-layer model tested on an inkjet-scans dataset: predict each scan from the previous one and the printed pattern → scan_residuals.parquet; the open-loop model run from the first scan → profiles.parquet (Figs 8, 21-22)",
        implements: "paper 002 eqs 2-7 (height-change model), Sec. V-D-1 (model verification against measured layers)",
        inputs: &[roles::INKJET_SCANS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&scan_residuals::TABLE, &profiles::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let dataset = InkjetScans::read(&ctx.input(&roles::INKJET_SCANS).dir).map_err(StageError::domain)?;
        let residuals = layer_residuals(&dataset).map_err(StageError::domain)?;
        let mut table = residuals_frame(&dataset, &residuals)?;
        ctx.write_table(scan_residuals::TABLE.name, &mut table)?;
        let model = open_model_prediction(&dataset).map_err(StageError::domain)?;
        let mut profiles = profiles_frame(&dataset, &model)?;
        ctx.write_table(profiles::TABLE.name, &mut profiles)?;
        Ok(())
    }
}

/// Residual `measured − predicted` of one layer over the footprint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerResidual {
    /// The layer predicted (1-based).
    pub layer: usize,
    /// RMS residual, µm.
    pub rmse_um: f64,
    /// Mean residual (measured − predicted), µm.
    pub bias_um: f64,
    /// Largest absolute residual, µm.
    pub max_abs_um: f64,
}

/// One printed layer as the model sees it: droplet mask and per-cell coefficients.
type LayerInput = (Vec<bool>, Vec<DropletCoeffs>);

/// The grid and per-layer droplet masks and coefficients of a dataset.
fn layer_inputs(dataset: &InkjetScans) -> Result<(Grid, Vec<LayerInput>), models::inkjet::InkjetError> {
    let g = &dataset.grid;
    let grid = Grid::new(g.m_x, g.m_y, g.spacing_um)?;
    let part = DropletCoeffs::from(g.part).check()?;
    let support = g.support.map(DropletCoeffs::from).unwrap_or(part).check()?;
    let layers = dataset
        .patterns
        .iter()
        .map(|pattern| {
            let droplet = pattern.iter().map(Option::is_some).collect();
            let coeffs = pattern.iter().map(|m| if *m == Some(Material::Support) { support } else { part }).collect();
            (droplet, coeffs)
        })
        .collect();
    Ok((grid, layers))
}

/// The nominal model run open loop from the first scan with the recorded patterns (the
/// paper's Fig. 8 / Fig. 22 prediction): one profile per layer, `[0]` = the first scan.
pub fn open_model_prediction(dataset: &InkjetScans) -> Result<Vec<Vec<f64>>, models::inkjet::InkjetError> {
    let (grid, layers) = layer_inputs(dataset)?;
    let mut profiles = vec![dataset.scans[0].clone()];
    for (droplet, coeffs) in &layers {
        let mut next = vec![0.0; grid.len()];
        deposit_layer_into(grid, profiles.last().expect("non-empty"), droplet, coeffs, &mut next);
        profiles.push(next);
    }
    Ok(profiles)
}

/// For each layer `k`, the nominal model's one-layer prediction from scan `k − 1` and
/// pattern `k`, compared with scan `k` over the target footprint.
pub fn layer_residuals(dataset: &InkjetScans) -> Result<Vec<LayerResidual>, models::inkjet::InkjetError> {
    let (grid, layers) = layer_inputs(dataset)?;
    let cells: Vec<usize> = (0..grid.len()).filter(|&c| dataset.target[c].is_some()).collect();
    let mut predicted = vec![0.0; grid.len()];
    let mut rows = Vec::with_capacity(dataset.layers());
    for (k, (droplet, coeffs)) in layers.iter().enumerate() {
        deposit_layer_into(grid, &dataset.scans[k], droplet, coeffs, &mut predicted);
        let residuals: Vec<f64> = cells.iter().map(|&c| dataset.scans[k + 1][c] - predicted[c]).collect();
        let n = residuals.len().max(1) as f64;
        rows.push(LayerResidual {
            layer: k + 1,
            rmse_um: (residuals.iter().map(|r| r * r).sum::<f64>() / n).sqrt(),
            bias_um: residuals.iter().sum::<f64>() / n,
            max_abs_um: residuals.iter().fold(0.0, |m, r| m.max(r.abs())),
        });
    }
    Ok(rows)
}

/// `name=strength,...` of a virtual dataset's effects, `none`, or `measured`.
pub fn effects_label(dataset: &InkjetScans) -> String {
    match &dataset.manifest.provenance {
        Provenance::Measured { .. } => "measured".into(),
        Provenance::Virtual { effects, .. } if effects.is_empty() => "none".into(),
        Provenance::Virtual { effects, .. } => {
            effects.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(",")
        }
    }
}

fn residuals_frame(dataset: &InkjetScans, rows: &[LayerResidual]) -> Result<DataFrame, StageError> {
    let n = rows.len();
    frame(vec![
        str_col(scan_residuals::scenario, vec![dataset.grid.scenario.clone(); n]),
        str_col(scan_residuals::controller, vec![dataset.grid.controller.clone(); n]),
        str_col(scan_residuals::effects, vec![effects_label(dataset); n]),
        f64_col(scan_residuals::variation_pct, vec![dataset.grid.variation_pct; n]),
        i64_col(scan_residuals::layer, rows.iter().map(|r| r.layer as i64).collect()),
        f64_col(scan_residuals::rmse_um, rows.iter().map(|r| r.rmse_um).collect()),
        f64_col(scan_residuals::bias_um, rows.iter().map(|r| r.bias_um).collect()),
        f64_col(scan_residuals::max_abs_um, rows.iter().map(|r| r.max_abs_um).collect()),
    ])
}

/// One row per layer (0 = first scan) and cell: measured height and the open-loop model
/// prediction from the first scan.
fn profiles_frame(dataset: &InkjetScans, model: &[Vec<f64>]) -> Result<DataFrame, StageError> {
    let m_x = dataset.grid.m_x;
    let cells = dataset.scans[0].len();
    let n = cells * dataset.scans.len();
    let (mut layer, mut xi, mut yi) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut measured, mut predicted) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut x, mut y) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let spacing_um = dataset.grid.spacing_um;
    for (k, (scan, prediction)) in dataset.scans.iter().zip(model).enumerate() {
        for c in 0..cells {
            layer.push(k as i64);
            xi.push((c % m_x) as i64);
            yi.push((c / m_x) as i64);
            x.push((c % m_x) as f64 * spacing_um);
            y.push((c / m_x) as f64 * spacing_um);
            measured.push(scan[c]);
            predicted.push(prediction[c]);
        }
    }
    frame(vec![
        i64_col(profiles::layer, layer),
        i64_col(profiles::x_index, xi),
        i64_col(profiles::y_index, yi),
        f64_col(profiles::x_um, x),
        f64_col(profiles::y_um, y),
        f64_col(profiles::measured_um, measured),
        f64_col(profiles::model_um, predicted),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;
    use models::inkjet::experiments::ControlLaw;

    fn dataset(effects: &str, variation_pct: f64) -> InkjetScans {
        let opts = GenerateOptions {
            scenario: Scenario::Cuboid,
            seed: 3,
            variation_pct,
            controller: ControlLaw::OpenLoop,
            effects: Effects::parse(effects).unwrap(),
            open_loop_layers: Some(4),
        };
        generate(&opts).unwrap().0
    }

    #[test]
    fn the_model_predicts_its_own_printer_to_the_profiler_noise() {
        // No shortfall, no effect: scan k - scan k-1 differs from the model only by the
        // profiler (1 µm noise on both scans, plus the spot's small edge blur).
        let exact = layer_residuals(&dataset("none", 0.0)).unwrap();
        assert_eq!(exact.len(), 4);
        assert!(exact.iter().all(|r| r.rmse_um < 1.8 && r.bias_um.abs() < 0.6), "{exact:?}");
        // Curing shrinkage of 20 % removes about 1.5 µm of each 7.6 µm layer inside the
        // part (less on the rim, where the layer is thinner).
        let shrunk = layer_residuals(&dataset("curing_shrinkage=0.2", 0.0)).unwrap();
        let mean_bias = shrunk.iter().map(|r| r.bias_um).sum::<f64>() / shrunk.len() as f64;
        assert!(mean_bias < -1.0 && shrunk.iter().all(|r| r.bias_um < -0.5), "{shrunk:?}");
        assert_eq!(effects_label(&dataset("curing_shrinkage=0.2", 0.0)), "curing_shrinkage=0.2");
    }
}
