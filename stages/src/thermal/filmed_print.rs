//! The unit the thermal studies (`thermal.discovery_power`, `thermal.control_gain`)
//! share: one corner test part printed and filmed on the virtual printer
//! (`thermal.generate_sequence`'s generator, the Lepton's habits on) in a scratch
//! folder, measured by the monitor (`thermal.monitor`'s code) in memory, and read by
//! the discrepancy engine (`thermal.discrepancy`'s model), told nothing. The scratch
//! folder is removed once the part is measured.

use std::path::Path;

use datasets::thermal::sequence::ThermalSequence;
use datasets::thermal::{generate_into, Effects, GenerateConfig, LeptonHabits};
use discrepancy::{discover, Discovery, Mechanism, Settings};
use models::thermal::discrepancy::{ThermalFit, ThermalModel, CANDIDATES};
use pipeline::params::ParamError;
use pipeline::StageError;

use super::common::open_sequence;
use super::discrepancy::{record_from_tables, WidthClearance};
use super::monitor::{self, MonitorParams, MonitorTables, StudyMonitor};
use crate::discrepancy_tables::NamingTest;

pipeline::params! {
    /// What both thermal studies declare of how they film their prints and let the
    /// engine read them (beyond `layers` and `max_rounds`, which each words itself).
    pub struct FilmingParams {}
    groups {
        /// The engine's test: its false-alarm rate and the smallest gain worth naming.
        pub naming: NamingTest,
        /// Which bead widths enter the engine's model.
        pub width_clearance: WidthClearance,
        /// The monitor's parameters the study sets.
        pub monitor: StudyMonitor,
    }
}

impl FilmingParams {
    /// The constraints the planner checks: the monitor's, on the study's monitor parameters.
    pub fn check(&self) -> Result<(), ParamError> {
        self.monitor.monitor_params().map(|_| ())
    }
}

/// How a study films its prints and lets the engine read them.
#[derive(Debug, Clone)]
pub struct Filming {
    /// Filmed layers per print (the engine's groups).
    pub layers: usize,
    /// The monitor's parameters ([`StudyMonitor::monitor_params`]).
    pub monitor: MonitorParams,
    /// `thermal.discrepancy`'s `width_clearance_mm`.
    pub width_clearance_mm: f64,
    /// The engine's settings; each print's seed replaces `seed`.
    pub engine: Settings,
}

/// One filmed print: its dataset (read before the scratch folder went), the monitor's
/// tables and what the engine found.
pub struct FilmedPrint {
    /// The sequence the printer wrote.
    pub sequence: ThermalSequence,
    /// The monitor's tables of it.
    pub tables: MonitorTables,
    /// The engine's discovery on it.
    pub found: Discovery<ThermalFit>,
}

impl Filming {
    /// From a study's `layers`, `max_rounds` and filming parameters (its monitor
    /// parameters, `width_clearance_mm` and the engine's test), the engine seeded
    /// with the stage's `seed`.
    pub fn new(params: &FilmingParams, layers: i64, max_rounds: i64, seed: u64) -> Result<Self, ParamError> {
        Ok(Self {
            layers: layers as usize,
            monitor: params.monitor.monitor_params()?,
            width_clearance_mm: params.width_clearance.width_clearance_mm,
            engine: params.naming.study_settings(max_rounds, seed, 100),
        })
    }

    /// Prints `effects` with `seed` in `scratch`, monitors and discovers; `what` names
    /// the print in an engine error (`power draw 3`).
    pub fn film(&self, effects: Effects, seed: u64, scratch: &Path, what: &str) -> Result<FilmedPrint, StageError> {
        let habits = LeptonHabits { repeated_frames: true, shutter_freeze: true };
        let config = GenerateConfig { seed, layers: self.layers, effects, lepton_habits: habits };
        std::fs::create_dir_all(scratch).map_err(|e| StageError::Io { path: scratch.to_path_buf(), source: e })?;
        generate_into(&config, scratch).map_err(StageError::domain)?;
        let sequence = open_sequence(scratch)?;
        let tables = monitor::monitor_tables(&sequence, &self.monitor, seed)?;
        let record = record_from_tables(&sequence, &tables.frames, &tables.widths, scratch, self.width_clearance_mm)?;
        std::fs::remove_dir_all(scratch).ok();
        let model = ThermalModel::new(record);
        let groups = model.record().layer_groups();
        let found = discover(&model, &groups, &[], &Settings { seed, ..self.engine })
            .map_err(|e| StageError::Domain(format!("discrepancy engine on {what} (seed {seed:016x}): {e}").into()))?;
        Ok(FilmedPrint { sequence, tables, found })
    }
}

/// The candidates named, `+`-joined, or `none`.
pub fn named_list(named: &[usize]) -> String {
    if named.is_empty() {
        "none".to_string()
    } else {
        named.iter().map(|&m| CANDIDATES[m].name()).collect::<Vec<_>>().join("+")
    }
}
