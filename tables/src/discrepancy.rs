//! The discrepancy engine's tables (DESIGN §7), one module per domain: what each
//! domain's discrepancy stage writes (`fdm.discrepancy`, `inkjet.discrepancy`,
//! `thermal.discrepancy`: residuals, causes, extension, gain; FDM also its held-out
//! predictions) and what its power study writes (`*.discovery_power`: `power` — the same
//! columns in every domain, declared once here — `power_draws` and the work units'
//! `part`).
//!
//! A domain's engine tables differ from another's only in the column naming the data set
//! (`printer`, `dataset`) and the unit in the residual and RMSE columns' names (`_mm`,
//! `_um`, `_sd`); a power study's draws add each candidate's first-round p-value. So one
//! template below declares every domain's tables, and the code every domain shares (the
//! writer in `stages::discrepancy_tables`, the report sections' readers) names the
//! columns that differ through the domain's [`Engine`] and the columns every domain names
//! alike through the FDM declarations (the template makes them the same; a test checks).

use pipeline::schema::Table;

/// One domain's four engine tables, for the code every domain shares: the declarations,
/// and the names of the columns whose names depend on the domain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Engine {
    /// `residuals`: the held-out residuals binned per candidate variable.
    pub residuals: &'static Table,
    /// `causes`: every candidate of every round.
    pub causes: &'static Table,
    /// `extension`: the final model's parameters.
    pub extension: &'static Table,
    /// `gain`: the held-out RMSE before and after.
    pub gain: &'static Table,
    /// The column naming the data set, first in every table (`printer`, `dataset`).
    pub set: &'static str,
    /// `residuals`' mean held-out residual of a bin (`mean_residual_mm`).
    pub mean_residual: &'static str,
    /// `residuals`' lower end of its interval (`ci_lo_mm`).
    pub residual_ci_lo: &'static str,
    /// `residuals`' upper end of its interval (`ci_hi_mm`).
    pub residual_ci_hi: &'static str,
    /// `causes`' held-out RMSE of the round's model (`cv_rmse_before_mm`).
    pub cv_rmse_before: &'static str,
    /// `causes`' held-out RMSE with the candidate added (`cv_rmse_after_mm`).
    pub cv_rmse_after: &'static str,
    /// `gain`'s held-out RMSE of the baseline (`rmse_before_mm`).
    pub rmse_before: &'static str,
    /// `gain`'s held-out RMSE of the final model (`rmse_after_mm`).
    pub rmse_after: &'static str,
}

impl Engine {
    /// The four tables, in the order the stages write them.
    pub const fn tables(&self) -> [&'static Table; 4] {
        [self.residuals, self.causes, self.extension, self.gain]
    }
}

/// Declares a domain's four engine tables and its [`Engine`] (`ENGINE`): `stage` names
/// the writing stage in the tables' docs, `set` the data-set column, `unit` the unit of
/// residuals and RMSEs (with `scale`, words appended to their meanings), `groups` what a
/// group is, and the idents the domain's residual and RMSE columns are called.
macro_rules! engine_tables {
    (
        stage: $stage:literal,
        set: $set:ident $set_doc:literal,
        unit: $unit:literal $scale:literal,
        groups: $groups:literal,
        residual: $mean:ident $lo:ident $hi:ident,
        cv_rmse: $cv_before:ident $cv_after:ident,
        rmse: $before:ident $after:ident $(,)?
    ) => {
        pipeline::table! {
            #[doc = $stage]
            #[doc = ": one row per (data set, model, candidate variable, bin), the held-out residuals (measured − predicted) of the baseline and of the final model binned against the variable (DESIGN §7, show)."]
            pub mod residuals = "residuals" {
                #[doc = $set_doc]
                $set: Str "",
                /// `baseline` or `extended` (the final model).
                model: Str "",
                /// The candidate variable.
                variable: Str "",
                /// Its unit (empty for a categorical variable).
                unit: Str "",
                /// Bin index from 0.
                bin: Int64 "1",
                /// The category, the value of a one-value bin, or `[lo, hi]`.
                label: Str "",
                /// Lower bin edge, in the row's `unit` (equal-count bins; the category's code for a categorical variable).
                bin_lo: Float64 "",
                /// Upper bin edge (equal to `bin_lo` for a one-value bin).
                bin_hi: Float64 "",
                #[doc = "Mean held-out residual of the samples in the bin"]
                #[doc = $scale]
                #[doc = "."]
                $mean: Float64 $unit,
                #[doc = "Lower end of its 95 % interval, cluster-robust over "]
                #[doc = $groups]
                #[doc = " (NaN with fewer than two in the bin)."]
                $lo: Float64 $unit,
                /// Upper end of that interval.
                $hi: Float64 $unit,
                /// Samples in the bin.
                n: Int64 "1",
                #[doc = "Groups ("]
                #[doc = $groups]
                #[doc = ") with samples in the bin."]
                groups: Int64 "1",
                /// For the whole variable: the share of the residual sum of squares its bin means explain (0: none, 1: all).
                structure: Float64 "1",
            }
        }

        pipeline::table! {
            #[doc = $stage]
            #[doc = ": one row per data set, round and candidate, scored by grouped cross-validation (DESIGN §7, name the cause)."]
            pub mod causes = "causes" {
                #[doc = $set_doc]
                $set: Str "",
                /// 1, 2, …: round 1 starts from the baseline, each later round from the model extended by the causes named before it.
                round: Int64 "1",
                /// The round's starting model (`lag_model + width_cap`).
                base_model: Str "",
                /// The candidate mechanism.
                mechanism: Str "",
                #[doc = "Held-out RMSE of the round's model, pooled over every sample of every group"]
                #[doc = $scale]
                #[doc = "."]
                $cv_before: Float64 $unit,
                /// The same with the candidate added.
                $cv_after: Float64 $unit,
                /// 100·(1 − after/before).
                gain_pct: Float64 "%",
                /// Lower end of its 95 % interval (percentile bootstrap over groups).
                gain_ci_lo_pct: Float64 "%",
                /// Upper end of that interval.
                gain_ci_hi_pct: Float64 "%",
                /// Held-out groups whose squared error the candidate lowered.
                groups_helped: Int64 "1",
                #[doc = "Groups ("]
                #[doc = $groups]
                #[doc = ")."]
                groups: Int64 "1",
                /// One-sided sign-flip test over groups of ln(SSE before / SSE after).
                p_value: Float64 "1",
                /// Holm's step-down adjustment over the round's candidates.
                p_adjusted: Float64 "1",
                /// The family-wise false-alarm rate a round is held at.
                alpha: Float64 "1",
                /// The smallest held-out gain worth naming: `p_value` tests "the gain is at most this" (0: any gain).
                min_gain_pct: Float64 "%",
                /// The cause named in this round (at most one per data set and round).
                named: Bool "",
                /// The round's verdict: `named`, `none` (no significant candidate) or `too_few_groups` (nothing can be named).
                verdict: Str "",
                /// Why the candidate could not be fitted; empty when it was.
                failure: Str "",
            }
        }

        pipeline::table! {
            #[doc = $stage]
            #[doc = ": one row per parameter of the final model (the baseline and every cause named) fitted on all groups (DESIGN §7, extend)."]
            pub mod extension = "extension" {
                #[doc = $set_doc]
                $set: Str "",
                /// Round in which the mechanism was named; 0 for the baseline's own parameters.
                round: Int64 "1",
                /// The baseline's name or the mechanism's.
                mechanism: Str "",
                /// The parameter, its name with its unit.
                parameter: Str "",
                /// Its unit.
                unit: Str "",
                /// Fitted on all groups, in the row's `unit`.
                estimate: Float64 "",
                /// Lower end of its 95 % delete-one-group jackknife interval, clamped to the parameter's bounds.
                ci_lo: Float64 "",
                /// Upper end of that interval.
                ci_hi: Float64 "",
                /// One line of physics.
                meaning: Str "",
            }
        }

        pipeline::table! {
            #[doc = $stage]
            #[doc = ": one row per data set, the held-out RMSE of the baseline and of the final model (DESIGN §7, gain)."]
            pub mod gain = "gain" {
                #[doc = $set_doc]
                $set: Str "",
                /// The baseline model.
                baseline: Str "",
                /// The baseline extended by every cause named (the baseline when nothing was named).
                extended_model: Str "",
                #[doc = "Groups ("]
                #[doc = $groups]
                #[doc = ")."]
                groups: Int64 "1",
                #[doc = "Held-out RMSE of the baseline"]
                #[doc = $scale]
                #[doc = ", over the observations the named causes move, as `causes` scores them (over all of them when nothing is named or a cause may move any)."]
                $before: Float64 $unit,
                /// Held-out RMSE of the final model.
                $after: Float64 $unit,
                /// 100·(1 − after/before).
                gain_pct: Float64 "%",
                /// Lower end of its 95 % interval (bootstrap over groups).
                gain_ci_lo_pct: Float64 "%",
                /// Upper end of that interval.
                gain_ci_hi_pct: Float64 "%",
            }
        }

        /// The domain's engine tables as the shared code names them.
        pub const ENGINE: super::Engine = super::Engine {
            residuals: &residuals::TABLE,
            causes: &causes::TABLE,
            extension: &extension::TABLE,
            gain: &gain::TABLE,
            set: residuals::$set,
            mean_residual: residuals::$mean,
            residual_ci_lo: residuals::$lo,
            residual_ci_hi: residuals::$hi,
            cv_rmse_before: causes::$cv_before,
            cv_rmse_after: causes::$cv_after,
            rmse_before: gain::$before,
            rmse_after: gain::$after,
        };
    };
}

/// Declares a power study's `power_draws` (one row per draw: what was hidden, what the
/// engine named, its fitted strength, then each candidate's first-round p-value, `p`)
/// and its work units' `power_part` (the same rows with the bookkeeping columns `part`,
/// then `covered`), both through [`draw_table`].
macro_rules! draw_tables {
    (
        stage: $stage:literal,
        strength_unit: $su:literal,
        p: [$($p:ident $pdoc:literal),* $(,)?],
        part: [$($(#[doc = $xdoc:literal])* $x:ident: $xt:ident $xu:literal),* $(,)?] $(,)?
    ) => {
        draw_table! {
            #[doc = $stage]
            #[doc = ": one row per draw of the power study."]
            mod power_draws = "power_draws",
            strength_unit: $su,
            p: [$($p $pdoc),*],
            then: [],
        }

        draw_table! {
            #[doc = $stage]
            #[doc = ": one work unit's draws (`part.parquet`), the rows of `power_draws` with the merge's bookkeeping."]
            mod power_part = "part",
            strength_unit: $su,
            p: [$($p $pdoc),*],
            then: [
                $( $(#[doc = $xdoc])* $x: $xt $xu, )*
                /// Whether the strength's interval covered the injected value (null: no interval); the summary needs it, `power_draws` does not carry it.
                covered: Bool "",
            ],
        }
    };
}

/// One table of a power study's draws: the columns every draw has, each candidate's
/// first-round p-value (`p`), then the columns `then`.
macro_rules! draw_table {
    (
        $(#[doc = $doc:literal])*
        mod $module:ident = $file:literal,
        strength_unit: $su:literal,
        p: [$($p:ident $pdoc:literal),* $(,)?],
        then: [$($(#[doc = $tdoc:literal])* $t:ident: $tt:ident $tu:literal),* $(,)?] $(,)?
    ) => {
        pipeline::table! {
            $(#[doc = $doc])*
            pub mod $module = $file {
                /// The base the draws are made of (a printer, or the virtual print's description).
                base: Str "",
                /// The hidden effect (`none` for a null draw).
                effect: Str "",
                /// Its strength, in the effect's unit.
                strength: Float64 $su,
                /// Draw index within its (effect, strength).
                draw: Int64 "1",
                /// The draw's seed, in hex.
                seed: Str "",
                /// The strength the draw carries (signed).
                injected: Float64 $su,
                /// The mechanisms named, `+`-joined (`none`).
                named: Str "",
                /// `correct` (the hidden mechanism and nothing else), `wrong` or `none`.
                outcome: Str "",
                /// The fitted strength, when correct.
                estimate: Float64 $su,
                /// Lower end of its 95 % interval.
                ci_lo: Float64 $su,
                /// Upper end of that interval.
                ci_hi: Float64 $su,
                $(
                    #[doc = "First-round sign-flip p-value of the candidate "]
                    #[doc = $pdoc]
                    #[doc = " (for the null's validity check)."]
                    $p: Float64 "1",
                )*
                $( $(#[doc = $tdoc])* $t: $tt $tu, )*
            }
        }
    };
}

pipeline::table! {
    /// `fdm.discovery_power`, `inkjet.discovery_power`, `thermal.discovery_power`: one row
    /// per base, effect and strength, the draws with that effect hidden scored against
    /// what was hidden (DESIGN §7: hide an effect, require finding it).
    pub mod power = "power" {
        /// The base the draws are made of (a printer, or the virtual print's description).
        base: Str "",
        /// The draws' noise: `measured`, `white` (measurement noise only) or `virtual` (the virtual printer's own).
        noise: Str "",
        /// Causes the engine names on the base as measured, in every draw's starting model (`none`).
        own_causes: Str "",
        /// The hidden effect (`none` for the null draws).
        effect: Str "",
        /// Its strength, in the effect's unit.
        strength: Float64 "",
        /// Draws.
        draws: Int64 "1",
        /// Draws naming the hidden mechanism and nothing else.
        correct: Int64 "1",
        /// Draws naming anything else (for `none`: any cause at all).
        wrong: Int64 "1",
        /// Draws naming nothing.
        none: Int64 "1",
        /// correct/draws.
        correct_rate: Float64 "1",
        /// Lower end of its Clopper–Pearson 95 % interval.
        correct_ci_lo: Float64 "1",
        /// Upper end of that interval.
        correct_ci_hi: Float64 "1",
        /// wrong/draws.
        false_alarm_rate: Float64 "1",
        /// Lower end of its Clopper–Pearson 95 % interval.
        false_alarm_ci_lo: Float64 "1",
        /// Upper end of that interval.
        false_alarm_ci_hi: Float64 "1",
        /// Correct draws whose 95 % interval of the strength covers the injected value.
        covered: Int64 "1",
        /// Correct draws with an interval.
        with_interval: Int64 "1",
        /// covered/with_interval.
        coverage_rate: Float64 "1",
        /// Lower end of its Clopper–Pearson 95 % interval.
        coverage_ci_lo: Float64 "1",
        /// Upper end of that interval.
        coverage_ci_hi: Float64 "1",
    }
}

/// Paper 000's lines: one discovery per printer, a group is a printed line, widths in mm.
pub mod fdm {
    engine_tables! {
        stage: "`fdm.discrepancy`",
        set: printer "The printer (one discovery per printer, over the lines of every input of it).",
        unit: "mm" "",
        groups: "lines",
        residual: mean_residual_mm ci_lo_mm ci_hi_mm,
        cv_rmse: cv_rmse_before_mm cv_rmse_after_mm,
        rmse: rmse_before_mm rmse_after_mm,
    }

    pipeline::table! {
        /// `fdm.discrepancy`: one row per measured sample, the held-out widths of the
        /// baseline and of the final model (a gear ripple's phase cross-fitted on the
        /// line's other half).
        pub mod predictions = "predictions" {
            /// The printer.
            printer: Str "",
            /// The line's condition.
            condition: Str "",
            /// Commanded acceleration a0.
            accel_mm_s2: Float64 "mm/s²",
            /// Commanded feed F0.
            feed_mm_s: Float64 "mm/s",
            /// Position along the line.
            position_mm: Float64 "mm",
            /// Measured width.
            measured_width_mm: Float64 "mm",
            /// The baseline's held-out width.
            baseline_width_mm: Float64 "mm",
            /// The final model's held-out width.
            extended_width_mm: Float64 "mm",
        }
    }

    draw_tables! {
        stage: "`fdm.discovery_power`",
        strength_unit: "1",
        p: [],
        part: [
            /// Causes the engine names on the base as measured (`none`), for `power`.
            own_causes: Str "",
        ],
    }

    /// Every table of this module.
    pub const ALL: &[&super::Table] = &[
        &residuals::TABLE,
        &causes::TABLE,
        &extension::TABLE,
        &gain::TABLE,
        &predictions::TABLE,
        &power_draws::TABLE,
        &power_part::TABLE,
    ];
}

/// Paper 002's prints: one discovery per `inkjet-scans` dataset, a group is a block of
/// consecutive layers, heights in µm.
pub mod inkjet {
    engine_tables! {
        stage: "`inkjet.discrepancy`",
        set: dataset "The dataset (its input's name; one discovery each).",
        unit: "µm" "",
        groups: "blocks of layers",
        residual: mean_residual_um ci_lo_um ci_hi_um,
        cv_rmse: cv_rmse_before_um cv_rmse_after_um,
        rmse: rmse_before_um rmse_after_um,
    }

    draw_tables! {
        stage: "`inkjet.discovery_power`",
        strength_unit: "",
        p: [
            p_curing_shrinkage "`curing_shrinkage`",
            p_volume_drift "`volume_drift`",
            p_levelling_flow "`levelling_flow`",
            p_nozzle_bias "`nozzle_bias`",
            p_coefficient_split "`coefficient_split`",
            p_anisotropic_spread "`anisotropic_spread`",
        ],
        part: [],
    }

    /// Every table of this module.
    pub const ALL: &[&super::Table] =
        &[&residuals::TABLE, &causes::TABLE, &extension::TABLE, &gain::TABLE, &power_draws::TABLE, &power_part::TABLE];
}

/// Paper 003's filmed prints: one discovery per (sequence, monitor) pair, a group is a
/// filmed layer, residuals and RMSEs in noise standard deviations.
pub mod thermal {
    engine_tables! {
        stage: "`thermal.discrepancy`",
        set: dataset "The filmed print's `thermal-sequence` dataset (its input's name; one discovery each).",
        unit: "1" ", in noise standard deviations (each observation divided by its kind's noise scale)",
        groups: "filmed layers",
        residual: mean_residual_sd ci_lo_sd ci_hi_sd,
        cv_rmse: cv_rmse_before_sd cv_rmse_after_sd,
        rmse: rmse_before_sd rmse_after_sd,
    }

    draw_tables! {
        stage: "`thermal.discovery_power`",
        strength_unit: "",
        p: [
            p_camera_latency "`camera_latency`",
            p_clock_rate "`clock_rate`",
            p_layer_heat_accumulation "`layer_heat_accumulation`",
            p_bed_warming "`bed_warming`",
            p_tau_mismatch "`tau_mismatch`",
        ],
        part: [],
    }

    /// Every table of this module.
    pub const ALL: &[&super::Table] =
        &[&residuals::TABLE, &causes::TABLE, &extension::TABLE, &gain::TABLE, &power_draws::TABLE, &power_part::TABLE];
}

/// The tables of this module outside its domain modules (each domain's `ALL` lists its own).
pub const ALL: &[&Table] = &[&power::TABLE];

#[cfg(test)]
mod tests {
    use super::*;

    /// The names of `table`'s columns.
    fn names(table: &Table) -> Vec<&'static str> {
        table.columns.iter().map(|c| c.name).collect()
    }

    /// The shared readers and writer name a domain's columns through the FDM
    /// declarations except those its [`Engine`] names: every other column must be the
    /// same in every domain, at the same place, of the same type.
    #[test]
    fn domains_differ_only_in_the_columns_their_engine_names() {
        for engine in [inkjet::ENGINE, thermal::ENGINE] {
            let own = [
                engine.set,
                engine.mean_residual,
                engine.residual_ci_lo,
                engine.residual_ci_hi,
                engine.cv_rmse_before,
                engine.cv_rmse_after,
                engine.rmse_before,
                engine.rmse_after,
            ];
            for (table, reference) in engine.tables().into_iter().zip(fdm::ENGINE.tables()) {
                assert_eq!(table.name, reference.name);
                assert_eq!(table.columns.len(), reference.columns.len(), "{}", table.name);
                for (c, r) in table.columns.iter().zip(reference.columns) {
                    assert_eq!(c.dtype, r.dtype, "{}.{}", table.name, c.name);
                    assert!(c.name == r.name || own.contains(&c.name), "{}.{} vs {}", table.name, c.name, r.name);
                }
            }
        }
    }

    /// A study's draws start with FDM's columns (the shared writer names them through
    /// those), and its part is the draws, FDM's own bookkeeping, then `covered`.
    #[test]
    fn every_study_writes_the_fdm_draw_columns_first_and_its_part_adds_covered() {
        let fixed = names(&fdm::power_draws::TABLE);
        for (draws, part) in [
            (&inkjet::power_draws::TABLE, &inkjet::power_part::TABLE),
            (&thermal::power_draws::TABLE, &thermal::power_part::TABLE),
        ] {
            assert_eq!(names(draws)[..fixed.len()], fixed[..]);
            assert_eq!(names(part), [names(draws), vec![inkjet::power_part::covered]].concat());
        }
        assert_eq!(
            names(&fdm::power_part::TABLE),
            [fixed, vec![fdm::power_part::own_causes, fdm::power_part::covered]].concat()
        );
    }
}
