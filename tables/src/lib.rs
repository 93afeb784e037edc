//! The tables the stages write, each declared once with [`pipeline::table!`]: its
//! columns in file order with their types, units and meanings. The stage writing a table
//! declares it (`Stage::WRITES`, checked on every write), the stages and reports reading
//! it name its columns through the constants declared here (a renamed column breaks
//! their build) and declare what they read on their input roles (checked by the planner),
//! test fixtures build frames from the same declarations, and a test holds
//! docs/OUTPUTS.md to them.
//!
//! Declared so far: paper 000's tables (`fdm`). The other domains' tables are still
//! spelled where they are written and read.
#![deny(missing_docs)]

pub mod fdm;

use pipeline::schema::Table;

/// Every declared table, for the docs test.
pub const ALL: &[&Table] = &[
    &fdm::line_summary::TABLE,
    &fdm::widths::TABLE,
    &fdm::kinematics::TABLE,
    &fdm::loo::TABLE,
    &fdm::loo_predictions::TABLE,
    &fdm::r_surface::TABLE,
    &fdm::infill::TABLE,
    &fdm::infill_map::TABLE,
];
