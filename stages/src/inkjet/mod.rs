//! Stages of paper 002 (Lu, Zheng, Mishra 2015, "A Layer-To-Layer Model and Feedback
//! Control of Ink-Jet 3-D Printing"): the simulated prints of the cylinder (Sec. V-A,
//! Figs 11-12) and the cuboid (Sec. V-D, Table II), open and closed loop, and the
//! exact-recovery check of the optimiser (Sec. IV-C). The numerics live in
//! [`models::inkjet::experiments`]; these stages only run them and write tables.

mod print;
mod recovery;

pub use print::{height_map_frame, summary_frame, PrintExperimentStage};
pub use recovery::{recovery_frame, RecoveryStage};

use pipeline::Registry;

/// Registers the paper-002 stage kinds.
pub fn register(registry: &mut Registry) {
    registry.register(Box::new(PrintExperimentStage));
    registry.register(Box::new(RecoveryStage));
}
