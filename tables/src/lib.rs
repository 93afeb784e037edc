//! The tables the stages write, each declared once with [`pipeline::table!`]: its
//! columns in file order with their types, units and meanings. The stage writing a table
//! declares it (`Stage::WRITES`, checked on every write), the stages and reports reading
//! it name its columns through the constants declared here (a renamed column breaks
//! their build) and declare what they read on their input roles (checked by the planner),
//! test fixtures build frames from the same declarations, and a test holds
//! docs/OUTPUTS.md to them.
//!
//! One module per domain: paper 000's FDM tables (`fdm`), paper 002's ink-jet tables
//! (`inkjet`), paper 003's thermal tables (`thermal`) and the report stages' own tables
//! (`report`), and the discrepancy engine's tables and its power studies', one module
//! per domain (`discrepancy`).
#![deny(missing_docs)]

pub mod discrepancy;
pub mod fdm;
pub mod inkjet;
pub mod report;
pub mod thermal;

use pipeline::schema::Table;

/// Every declared table, domain by domain.
pub fn all() -> impl Iterator<Item = &'static Table> {
    [
        fdm::ALL,
        inkjet::ALL,
        thermal::ALL,
        discrepancy::ALL,
        discrepancy::fdm::ALL,
        discrepancy::inkjet::ALL,
        discrepancy::thermal::ALL,
        report::ALL,
    ]
    .into_iter()
    .flatten()
    .copied()
}
