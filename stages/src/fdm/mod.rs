//! Stages of paper 000 (Ren et al. 2021): importing and summarising measured line
//! widths, kinematics, the piecewise model's and the lag baseline's leave-one-out,
//! transfer learning between printers, infill nonuniformity, and what the lag model
//! gets wrong (the discrepancy engine and its power study).

mod discovery_power;
mod discrepancy;
mod import;
mod infill;
mod kinematics;
mod line_summary;
mod lines;
mod loo;
mod other_family;
mod photos;
mod pressure_advance;
mod segment;
mod transfer;
mod transfer_matrix;
mod virtual_lines;

pub use discovery_power::DiscoveryPowerStage;
pub use discrepancy::DiscrepancyStage;
pub use import::ImportStage;
pub use infill::InfillStage;
pub use kinematics::KinematicsStage;
pub use line_summary::{summarize_line, LineSummary, LineSummaryStage, SummaryWindows};
pub use loo::{LagLooStage, PiecewiseLooStage};
pub use other_family::OtherFamilyStage;
pub use photos::{ImportPhotosStage, MeasurePhotosStage};
pub use pressure_advance::PressureAdvanceStage;
pub use segment::{SegmentAccuracyStage, SegmentWidthsStage};
pub use transfer::TransferCvStage;
pub use transfer_matrix::TransferMatrixStage;
pub use virtual_lines::{GenerateLinesStage, VirtualAgreementStage};

use pipeline::Registry;

/// Registers the paper-000 stage kinds.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(ImportStage));
    registry.register(Box::new(LineSummaryStage));
    registry.register(Box::new(KinematicsStage));
    registry.register(Box::new(PiecewiseLooStage));
    registry.register(Box::new(LagLooStage));
    registry.register(Box::new(TransferCvStage));
    registry.register(Box::new(TransferMatrixStage));
    registry.register(Box::new(OtherFamilyStage));
    registry.register(Box::new(InfillStage));
    registry.register(Box::new(DiscrepancyStage));
    registry.register(Box::new(DiscoveryPowerStage));
    registry.register(Box::new(GenerateLinesStage));
    registry.register(Box::new(VirtualAgreementStage));
    registry.register(Box::new(SegmentWidthsStage));
    registry.register(Box::new(SegmentAccuracyStage));
    registry.register(Box::new(ImportPhotosStage));
    registry.register(Box::new(PressureAdvanceStage));
    registry.register(Box::new(MeasurePhotosStage));
}
