//! Paper 002's tables (Lu et al. 2015): printed parts, virtual scans and the
//! layer-to-layer height model's residuals.

use pipeline::schema::Table;

/// Every table of this module.
pub const ALL: &[&Table] = &[];
