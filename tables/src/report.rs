//! The report stages' own tables: each section's numbers beside the paper's
//! (`comparison`, published as `paper_comparison.parquet` or `comparison.parquet`) and
//! the paper 003 section's table of compensation variants.

use pipeline::schema::Table;

pipeline::table! {
    /// `report.*`: one row per number a report section compares or reports, with its
    /// source.
    pub mod comparison = "comparison" {
        /// The report section.
        section: Str "",
        /// What is compared.
        item: Str "",
        /// The paper's value; null where the paper gives none.
        paper_value: Float64 "",
        /// Ours, computed by the stage named in `source`.
        our_value: Float64 "",
        /// The values' unit.
        unit: Str "",
        /// The table and stage our value comes from.
        source: Str "",
    }
}

pipeline::table! {
    /// `report.chen2024`: one row per variant of the compensation (`defaults` first),
    /// re-printed and scored (eqs 40-41).
    pub mod variants = "variants" {
        /// The variant's name.
        variant: Str "",
        /// What its stages set differently, from their records.
        changes: Str "",
        /// Mean O_E of the conventional print.
        oe_before_pct: Float64 "%",
        /// Mean O_E of the compensated print.
        oe_after_pct: Float64 "%",
        /// Largest contour error, conventional.
        max_before_mm: Float64 "mm",
        /// Largest contour error, compensated.
        max_after_mm: Float64 "mm",
        /// RMS contour error, conventional.
        rms_before_mm: Float64 "mm",
        /// RMS contour error, compensated.
        rms_after_mm: Float64 "mm",
        /// Change of O_E by the compensation (negative: a reduction).
        oe_change_pct: Float64 "%",
        /// Change of the largest contour error.
        max_change_pct: Float64 "%",
        /// Change of the RMS contour error.
        rms_change_pct: Float64 "%",
        /// The tables the numbers come from.
        source: Str "",
    }
}

/// Every table of this module.
pub const ALL: &[&Table] = &[&comparison::TABLE, &variants::TABLE];
