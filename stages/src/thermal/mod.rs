//! Paper 003 (Chen, Yang, Liu, Duan): in-situ thermal-camera monitoring and
//! filtered-B-spline deposition compensation of a material-extrusion printer, as
//! stages over the `thermal-sequence` dataset format (DESIGN §4, §5.3).
//!
//! - [`generate`]: `thermal.generate_sequence`, the virtual printer with its camera,
//!   writing a `thermal-sequence` dataset as the stage's output folder.
//! - [`monitor`]: `thermal.monitor`, deposition directions (eqs 1-26), frame
//!   localisation (eqs 27-30) and width extraction (Sec. 2.4, eqs 31-32).
//! - [`compensate`]: `thermal.compensate`, the compensation of eqs 33-39.
//! - [`reprint`]: `thermal.reprint_evaluate`, re-print with and without it and measure
//!   eqs 40-41 (evaluation: uses the virtual printer's effects).
//! - [`accuracy`]: `thermal.accuracy_evaluate`, the frame pipeline against `truth/`;
//!   [`true_widths`]: `thermal.true_widths_evaluate`, the widths a perfect camera would read
//!   (evaluation), for the compensation fed the truth.
//! - [`discrepancy`]: `thermal.discrepancy`, what the paper's capture-time, layer and
//!   flow models get wrong about the monitor's measurements, and why (DESIGN §7);
//!   [`discovery_power`]: `thermal.discovery_power`, its power study on virtual prints;
//!   [`control`]: `thermal.control_gain`, the compensation with the extended model
//!   against the paper's, re-printed (evaluation).
//! - [`common`]: what the stages share (reading a sequence, the trajectory, the camera).

pub mod accuracy;
pub mod common;
pub mod compensate;
pub mod control;
pub mod discovery_power;
pub mod discrepancy;
pub mod filmed_print;
pub mod generate;
pub mod monitor;
pub mod reprint;
pub mod true_widths;

use pipeline::Registry;

/// Registers the paper-003 stage kinds.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(generate::GenerateSequenceStage));
    registry.register(Box::new(monitor::MonitorStage));
    registry.register(Box::new(compensate::CompensateStage));
    registry.register(Box::new(reprint::ReprintEvaluateStage));
    registry.register(Box::new(accuracy::AccuracyEvaluateStage));
    registry.register(Box::new(true_widths::TrueWidthsStage));
    registry.register(Box::new(discrepancy::DiscrepancyStage));
    registry.register(Box::new(discovery_power::DiscoveryPowerStage));
    registry.register(Box::new(control::ControlGainStage));
}
