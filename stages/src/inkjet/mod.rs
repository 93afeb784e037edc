//! Stages of paper 002 (Lu, Zheng, Mishra 2015, "A Layer-To-Layer Model and Feedback
//! Control of Ink-Jet 3-D Printing"): the simulated prints of the cylinder (Sec. V-A,
//! Figs 11-12) and the cuboid (Sec. V-D, Table II), open and closed loop, and the
//! exact-recovery check of the optimiser (Sec. IV-C), the two-material pipe junction
//! (Figs 13-15), and `inkjet-scans` datasets from the virtual printer with the test of
//! the layer-to-layer model against them. The numerics live in
//! [`models::inkjet::experiments`]; these stages only run them and write tables.

mod control;
mod discrepancy;
mod print;
mod recovery;
mod scans;

pub use control::ControlGainStage;
pub use discrepancy::{print_of, DiscoveryPowerStage, DiscrepancyStage};
pub use print::{height_map_frame, summary_frame, PrintExperimentStage};
pub use recovery::{recovery_frame, RecoveryStage};
pub use scans::{effects_label, layer_residuals, GenerateScansStage, LayerResidual, ScanResidualsStage};

use models::inkjet::experiments::ControlLaw;
use pipeline::Registry;

pipeline::choice! {
    /// The parts of paper 002's experiments.
    pub enum Part {
        /// The cylinder of Sec. V-A.
        Cylinder = "cylinder",
        /// The cuboid of Sec. V-D (Table II).
        Cuboid = "cuboid",
        /// The two-material pipe junction of Figs 13-15.
        PipeJunction = "pipe_junction",
    }
}

pipeline::choice! {
    /// How the patterns of a print are chosen.
    pub enum Controller {
        /// The footprint every layer (Sec. IV-A).
        OpenLoop = "open_loop",
        /// Measure, solve eq. 8, print the first layer of the plan (Sec. IV-C).
        ClosedLoop = "closed_loop",
    }
}

impl Controller {
    /// The experiments' control law.
    pub fn law(self) -> ControlLaw {
        match self {
            Self::OpenLoop => ControlLaw::OpenLoop,
            Self::ClosedLoop => ControlLaw::ClosedLoop,
        }
    }
}

/// Registers the paper-002 stage kinds.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(PrintExperimentStage));
    registry.register(Box::new(RecoveryStage));
    registry.register(Box::new(GenerateScansStage));
    registry.register(Box::new(ScanResidualsStage));
    registry.register(Box::new(DiscrepancyStage));
    registry.register(Box::new(DiscoveryPowerStage));
    registry.register(Box::new(ControlGainStage));
}
