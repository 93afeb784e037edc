//! Paper 000's tables (Ren et al. 2021): measured line widths and their summary, the
//! nozzle's kinematics (eq. 1), the leave-one-out of the piecewise and lag models
//! (Table II, Fig. 6) and infill nonuniformity (Fig. 7).

pipeline::table! {
    /// `fdm.line_summary`: one row per measured line (paper 000 Figs 3-4).
    pub mod line_summary = "line_summary" {
        /// The printer (dataset.toml `printer`).
        printer: Str "",
        /// `S{a}F{F}`: commanded acceleration (mm/s²) and feed (mm/min).
        condition: Str "",
        /// Commanded acceleration a0.
        accel_mm_s2: Float64 "mm/s²",
        /// Commanded feed F0.
        feed_mm_s: Float64 "mm/s",
        /// Mean width over the steady window (phase p4).
        steady_width_mm: Float64 "mm",
        /// Smallest width in the start window (the start dip).
        start_min_width_mm: Float64 "mm",
        /// Where it lies.
        start_min_position_mm: Float64 "mm",
        /// 100·(steady − start minimum)/steady.
        start_dip_pct: Float64 "%",
        /// 100·(maximum over the end window − steady)/steady (phase p5).
        end_bulge_pct: Float64 "%",
        /// Largest width anywhere on the line.
        max_width_mm: Float64 "mm",
        /// Where it lies.
        max_width_position_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `fdm.import`: one row per width measurement of a printer's lines.
    pub mod widths = "widths" {
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
        /// Measured width there.
        width_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `fdm.kinematics`: one row per measured sample, the nozzle's motion there (eq. 1).
    pub mod kinematics = "kinematics" {
        /// The printer.
        printer: Str "",
        /// The line's condition.
        condition: Str "",
        /// Position along the line.
        position_mm: Float64 "mm",
        /// Time since the line's start.
        time_s: Float64 "s",
        /// Nozzle speed.
        speed_mm_s: Float64 "mm/s",
        /// Nozzle acceleration (negative while decelerating).
        accel_mm_s2: Float64 "mm/s²",
        /// Motion phase: `accelerating`, `cruise` or `decelerating`.
        phase: Str "",
    }
}

pipeline::table! {
    /// `fdm.piecewise_loo` and `fdm.lag_model`: one row per held-out line and model
    /// (paper 000 Table II, Case A).
    pub mod loo = "loo" {
        /// The printer.
        printer: Str "",
        /// The held-out line's condition.
        condition: Str "",
        /// Commanded acceleration a0.
        accel_mm_s2: Float64 "mm/s²",
        /// Commanded feed F0.
        feed_mm_s: Float64 "mm/s",
        /// `piecewise` (eqs 2-3 with the r_a × r_F grid search) or `lag` (first-order extrusion lag).
        model: Str "",
        /// RMSE of the prediction over the whole held-out line, trained on the printer's other lines.
        rmse_mm: Float64 "mm",
        /// Actual / commanded acceleration chosen on the training lines (1 for `lag`).
        r_a: Float64 "1",
        /// Actual / commanded feed chosen on the training lines (1 for `lag`).
        r_f: Float64 "1",
        /// The lag model's fitted time constant (null for `piecewise`).
        tau_s: Float64 "s",
    }
}

pipeline::table! {
    /// `fdm.piecewise_loo` and `fdm.lag_model`: one row per measured sample of a
    /// held-out line and model (paper 000 Fig. 6).
    pub mod loo_predictions = "loo_predictions" {
        /// The printer.
        printer: Str "",
        /// The held-out line's condition.
        condition: Str "",
        /// `piecewise` or `lag`.
        model: Str "",
        /// Position along the line.
        position_mm: Float64 "mm",
        /// Measured width.
        measured_width_mm: Float64 "mm",
        /// The held-out prediction.
        predicted_width_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `fdm.piecewise_loo`: the training RMSE on all lines at every (r_a, r_F) of the grid.
    pub mod r_surface = "r_surface" {
        /// The printer.
        printer: Str "",
        /// Actual / commanded acceleration.
        r_a: Float64 "1",
        /// Actual / commanded feed.
        r_f: Float64 "1",
        /// Training RMSE of the fit on all lines at that grid point.
        training_rmse_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `fdm.infill`: one row per condition, hatch and region (paper 000 Fig. 7).
    pub mod infill = "infill" {
        /// The printer.
        printer: Str "",
        /// The condition of the lines laid side by side.
        condition: Str "",
        /// Hatch spacing.
        hatch_mm: Float64 "mm",
        /// `start`, `middle` or `end`: the first end-region, the rest, the last end-region.
        region: Str "",
        /// Fraction of raster cells between the outer centre lines covered by no line.
        void_fraction: Float64 "1",
        /// Fraction covered by two or more lines.
        overlap_fraction: Float64 "1",
    }
}

pipeline::table! {
    /// `fdm.infill`: one row per raster cell near the line ends of the mapped condition.
    pub mod infill_map = "infill_map" {
        /// The printer.
        printer: Str "",
        /// The mapped condition.
        condition: Str "",
        /// Hatch spacing.
        hatch_mm: Float64 "mm",
        /// Position along the lines.
        x_mm: Float64 "mm",
        /// Position across the lines.
        y_mm: Float64 "mm",
        /// Lines covering the cell.
        coverage: Int64 "1",
    }
}

pipeline::table! {
    /// `fdm.segment_widths`: one row per photo of the set, measured or skipped and why.
    pub mod segment_diagnostics = "segment_diagnostics" {
        /// The printer.
        printer: Str "",
        /// `edge_fit` or `threshold`.
        method: Str "",
        /// The photographed line.
        line_id: Str "",
        /// The photo's file.
        image: Str "",
        /// `measured` or `skipped`.
        status: Str "",
        /// For a skipped photo what is wrong; for a measured one the skipped positions by reason.
        problem: Str "",
        /// Positions measured.
        columns_used: Int64 "1",
        /// Positions skipped.
        columns_skipped: Int64 "1",
    }
}

pipeline::table! {
    /// `fdm.segment_accuracy`: one row per (photo, method), the segmented widths against
    /// the virtual printer's truth.
    pub mod segment_accuracy = "segment_accuracy" {
        /// The virtual printer.
        printer: Str "",
        /// The photographed line.
        line_id: Str "",
        /// The camera's scale.
        px_per_mm: Float64 "px/mm",
        /// `edge_fit` (blurred two-edge model, sub-pixel) or `threshold` (Otsu, pixels counted).
        method: Str "",
        /// RMSE of segmented − true width; NaN when the photo was not measured.
        rmse_mm: Float64 "mm",
        /// Mean of segmented − true width.
        bias_mm: Float64 "mm",
        /// Positions measured.
        columns_used: Int64 "1",
        /// Positions skipped (near the line's ends).
        columns_skipped: Int64 "1",
        /// Why the photo was not measured; empty otherwise.
        problem: Str "",
    }
}

pipeline::table! {
    /// `fdm.segment_accuracy`: one row per photo set.
    pub mod photo_sets = "photo_sets" {
        /// The set (its stage name).
        dataset: Str "",
        /// The printer.
        printer: Str "",
        /// The camera's scale.
        px_per_mm: Float64 "px/mm",
        /// Lines photographed.
        lines: Int64 "1",
        /// The effects its `dataset.toml` records, `none` or `measured`.
        effects: Str "",
    }
}

pipeline::table! {
    /// `fdm.virtual_agreement`: one row per real line, against the virtual printer
    /// calibrated on the printer's other lines.
    pub mod agreement = "agreement" {
        /// The printer.
        printer: Str "",
        /// The line's condition.
        condition: Str "",
        /// Commanded acceleration a0.
        accel_mm_s2: Float64 "mm/s²",
        /// Commanded feed F0.
        feed_mm_s: Float64 "mm/s",
        /// RMSE of the measured widths against the virtual mean profile.
        rmse_mm: Float64 "mm",
        /// RMS of the virtual lines around that mean.
        virtual_scatter_mm: Float64 "mm",
        /// Their ratio.
        rmse_over_scatter: Float64 "1",
    }
}

pipeline::table! {
    /// `fdm.virtual_agreement`: one row per (real line, position), the measured width
    /// and the virtual printer's mean and 95 % band.
    pub mod agreement_profiles = "agreement_profiles" {
        /// The printer.
        printer: Str "",
        /// The line's condition.
        condition: Str "",
        /// Position along the line.
        position_mm: Float64 "mm",
        /// Measured width.
        real_mm: Float64 "mm",
        /// Mean width of the virtual lines.
        virtual_mean_mm: Float64 "mm",
        /// 2.5 % quantile of the virtual lines.
        virtual_lo_mm: Float64 "mm",
        /// 97.5 % quantile of the virtual lines.
        virtual_hi_mm: Float64 "mm",
    }
}

/// Every table of this module.
pub const ALL: &[&pipeline::schema::Table] = &[
    &line_summary::TABLE,
    &widths::TABLE,
    &kinematics::TABLE,
    &loo::TABLE,
    &loo_predictions::TABLE,
    &r_surface::TABLE,
    &infill::TABLE,
    &infill_map::TABLE,
    &segment_diagnostics::TABLE,
    &segment_accuracy::TABLE,
    &photo_sets::TABLE,
    &agreement::TABLE,
    &agreement_profiles::TABLE,
];
