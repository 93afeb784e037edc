//! The report stages' own tables: each paper's numbers beside ours
//! (`paper_comparison.parquet`).

use pipeline::schema::Table;

/// Every table of this module.
pub const ALL: &[&Table] = &[];
