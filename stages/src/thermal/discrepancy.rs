//! `thermal.discrepancy`: what paper 003's models get wrong about what the thermal
//! monitor measures — the frames' capture offsets (eq. 28) and the beads' centre
//! temperatures layer after layer — which physical cause explains it, the extended model
//! and its held-out gain: the thermal domain of the `discrepancy` engine
//! (`models::thermal::discrepancy`, whose module doc states the baseline, the four
//! candidates, why a group is a whole layer and why the width effects have no candidate
//! yet). One discovery per (sequence, monitor) pair of inputs; a group is a filmed layer.
//! Reads the sequence's `process.toml` and the monitor's `frames.parquet` and
//! `widths.parquet`, never `truth/`.
//!
//! Outputs (docs/OUTPUTS.md): `residuals`, `causes`, `extension`, `gain`, the columns of
//! `fdm.discrepancy` with `dataset` for `printer`; residuals and RMSEs are in noise
//! standard deviations (`_sd`: each observation divided by its kind's noise scale).

use std::path::Path;

use datasets::thermal::ThermalSequence;
use discrepancy::discover;
use models::thermal::discrepancy::{
    FrameObservation, RecordParts, TemperatureObservation, ThermalModel, ThermalRecord,
};
use pipeline::stage::Arity;
use pipeline::{ParamSpec, StageContext, StageError, StageKind};
use polars::prelude::DataFrame;

use super::common::{f64_column, i64_column, open_sequence, read_table, trajectory_of};
use crate::discrepancy_tables::{engine_settings, max_rounds, DiscrepancyTables, Domain, ALPHA, BINS, BOOTSTRAP_DRAWS};

/// The thermal tables' names: one discovery per dataset, residuals in noise std's.
const THERMAL: Domain = Domain { set_column: "dataset", unit: "sd" };

/// The `thermal.discrepancy` stage kind.
pub struct DiscrepancyStage;

const PARAMS: &[ParamSpec] = &[ALPHA, max_rounds(4, 3), BINS, BOOTSTRAP_DRAWS];

impl StageKind for DiscrepancyStage {
    fn name(&self) -> &'static str {
        "thermal.discrepancy"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "What eq. 28's capture times and the paper's layer-invariant printing get wrong about the monitor's frames and centre temperatures, the cause named among 4 mechanisms, the extended model and its held-out gain → residuals, causes, extension, gain (.parquet)"
    }
    fn implements(&self) -> &'static str {
        "DESIGN §7 on paper 003's eq. 28 and layer model, over thermal.monitor's frames.parquet and widths.parquet"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity::at_least(2)
    }

    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        if !ctx.inputs.len().is_multiple_of(2) {
            return Err(StageError::Params {
                stage: ctx.stage.clone(),
                message: format!(
                    "inputs come in (sequence, monitor) pairs, got {} inputs: {}",
                    ctx.inputs.len(),
                    ctx.inputs.iter().map(|i| i.name.as_str()).collect::<Vec<_>>().join(", ")
                ),
            });
        }
        let settings = engine_settings(ctx)?;
        let mut tables = DiscrepancyTables::new(THERMAL, settings.alpha);
        for pair in ctx.inputs.chunks(2) {
            let (sequence, monitor) = (&pair[0], &pair[1]);
            let model = ThermalModel::new(record_of(&sequence.dir, &monitor.dir)?);
            let blocks = model.record().layer_groups();
            let found = discover(&model, &blocks, &[], &settings).map_err(|e| {
                StageError::Domain(
                    format!("discrepancy engine on dataset `{}` ({} filmed layers): {e}", sequence.name, blocks.len())
                        .into(),
                )
            })?;
            tables.add(&sequence.name, &model, blocks.len(), &found);
        }
        tables.write(ctx)
    }
}

/// The model's view of a filmed print: the sequence's process and the monitor's
/// frame offsets and centre temperatures.
pub fn record_of(sequence_dir: &Path, monitor_dir: &Path) -> Result<ThermalRecord, StageError> {
    let seq = open_sequence(sequence_dir)?;
    let frames = read_table(monitor_dir, "frames.parquet")?;
    let widths = read_table(monitor_dir, "widths.parquet")?;
    record_from_tables(&seq, &frames, &widths, monitor_dir)
}

/// [`record_of`] from the monitor's two tables, read from (or written for) `monitor_dir`.
pub fn record_from_tables(
    seq: &ThermalSequence,
    frames: &DataFrame,
    widths: &DataFrame,
    monitor_dir: &Path,
) -> Result<ThermalRecord, StageError> {
    let trajectory = trajectory_of(seq)?;
    let frame_file = monitor_dir.join("frames.parquet");
    let frames = frame_offsets(frames, &frame_file)?;
    let temps = centre_temperatures(widths, &monitor_dir.join("widths.parquet"))?;
    ThermalRecord::new(RecordParts {
        frames: &frames,
        temps: &temps,
        samples: trajectory.len(),
        layer_duration_s: trajectory.duration_s(),
        nozzle_temp_c: seq.process.nozzle_temp_c,
        bed_temp_c: seq.process.bed_temp_c,
    })
    .map_err(|e| StageError::BadInput {
        file: frame_file,
        location: None,
        expected: format!("a monitored print the discrepancy model can use: {e}"),
    })
}

/// Localised, uncensored, non-repeated frames with a capture-time estimate.
fn frame_offsets(df: &DataFrame, file: &Path) -> Result<Vec<FrameObservation>, StageError> {
    let (layer, repeat, edge) = (
        i64_column(df, file, "layer")?,
        i64_column(df, file, "repeat_of_frame")?,
        i64_column(df, file, "at_window_edge")?,
    );
    let (recorded, estimated) = (f64_column(df, file, "recorded_time_s")?, f64_column(df, file, "estimated_time_s")?);
    Ok((0..df.height())
        .filter(|&i| estimated[i].is_finite() && repeat[i] < 0 && edge[i] == 0 && layer[i] >= 0)
        .map(|i| FrameObservation {
            layer: layer[i] as usize,
            recorded_time_s: recorded[i],
            offset_s: estimated[i] - recorded[i],
        })
        .collect())
}

/// Every sample's finite centre temperature.
fn centre_temperatures(df: &DataFrame, file: &Path) -> Result<Vec<TemperatureObservation>, StageError> {
    let (layer, sample) = (i64_column(df, file, "layer")?, i64_column(df, file, "sample")?);
    let (t, temp) = (f64_column(df, file, "t_s")?, f64_column(df, file, "temp_c")?);
    Ok((0..df.height())
        .filter(|&i| temp[i].is_finite() && layer[i] >= 0 && sample[i] >= 0)
        .map(|i| TemperatureObservation {
            layer: layer[i] as usize,
            sample: sample[i] as usize,
            t_s: t[i],
            temp_c: temp[i],
        })
        .collect())
}
