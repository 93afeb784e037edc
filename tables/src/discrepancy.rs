//! The discrepancy engine's tables, the same in all three domains: residuals (show),
//! causes (name), extension (extend), gain, and the hidden-effect power studies.

use pipeline::schema::Table;

/// Every table of this module.
pub const ALL: &[&Table] = &[];
