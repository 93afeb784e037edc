//! Paper 000's tables (Ren et al. 2021): measured line widths and their summary, the
//! nozzle's kinematics (eq. 1), the leave-one-out of the piecewise and lag models
//! (Table II, Fig. 6), infill nonuniformity (Fig. 7), the transfer between printers
//! (Case B, Fig. 9, and over several printers) with its work units' parts, the photo
//! segmentation and the virtual printer's agreement with the real lines.

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
    /// `fdm.measure_photos`: one row per (photo, printed line of the G-code).
    pub mod photo_lines = "photo_lines" {
        /// The photo (`photos.csv`).
        photo_id: Str "",
        /// The printed line: 0-based, in G-code order, every straight extrusion path.
        line: Int64 "1",
        /// The line's G-code start on the bed, x.
        x0_mm: Float64 "mm",
        /// The line's G-code start on the bed, y.
        y0_mm: Float64 "mm",
        /// The line's G-code end on the bed, x.
        x1_mm: Float64 "mm",
        /// The line's G-code end on the bed, y.
        y1_mm: Float64 "mm",
        /// The pressure (linear) advance in force while it was printed.
        pressure_advance_s: Float64 "s",
        /// `measured` (at least one position measured) or `skipped`.
        status: Str "",
        /// For a skipped line why; for a measured one the skipped positions by reason.
        reason: Str "",
        /// Median edge-fit width over its measured bead positions (gaps left out); NaN if none.
        median_width_mm: Float64 "mm",
        /// Positions measured as bead.
        widths: Int64 "1",
        /// Positions measured as a gap (width 0).
        gaps: Int64 "1",
        /// Positions skipped.
        positions_skipped: Int64 "1",
        /// Where the line's G-code start lies in the photo, x (px, right).
        start_x_px: Float64 "px",
        /// Where the line's G-code start lies in the photo, y (px, down).
        start_y_px: Float64 "px",
        /// Where the line's G-code end lies in the photo, x.
        end_x_px: Float64 "px",
        /// Where the line's G-code end lies in the photo, y.
        end_y_px: Float64 "px",
    }
}

pipeline::table! {
    /// `fdm.measure_photos`: one row per measured position of a line in a photo.
    pub mod photo_widths = "photo_widths" {
        /// The photo.
        photo_id: Str "",
        /// The printed line (as `photo_lines`).
        line: Int64 "1",
        /// Position along the line from its G-code start.
        position_mm: Float64 "mm",
        /// Edge-fit width (blurred two-edge model, sub-pixel); 0 in a gap.
        width_mm: Float64 "mm",
        /// The left edge's distance to the left of the G-code axis; NaN in a gap.
        left_mm: Float64 "mm",
        /// The right edge's distance to the right of the G-code axis; NaN in a gap.
        right_mm: Float64 "mm",
        /// Width of the run above half contrast (the plain threshold baseline); 0 in a gap.
        threshold_width_mm: Float64 "mm",
        /// The G-code axis at this position in the photo, x (px, right).
        axis_x_px: Float64 "px",
        /// The G-code axis at this position in the photo, y (px, down).
        axis_y_px: Float64 "px",
        /// The left edge in the photo, x; NaN in a gap.
        left_x_px: Float64 "px",
        /// The left edge in the photo, y; NaN in a gap.
        left_y_px: Float64 "px",
        /// The right edge in the photo, x; NaN in a gap.
        right_x_px: Float64 "px",
        /// The right edge in the photo, y; NaN in a gap.
        right_y_px: Float64 "px",
    }
}

pipeline::table! {
    /// `fdm.measure_photos`: one row per photo, where it sits on the bed.
    pub mod photo_calibration = "photo_calibration" {
        /// The photo.
        photo_id: Str "",
        /// The photo's file, relative to the dataset folder (`photos.csv`).
        image: Str "",
        /// `calibrated` or `failed`.
        status: Str "",
        /// Why a photo failed; empty otherwise.
        reason: Str "",
        /// Image width.
        width_px: Int64 "px",
        /// Image height.
        height_px: Int64 "px",
        /// Homography bed mm → undistorted px, row 1 (h11, h12, h13).
        h11: Float64 "px/mm",
        /// h12.
        h12: Float64 "px/mm",
        /// h13.
        h13: Float64 "px",
        /// Row 2: h21.
        h21: Float64 "px/mm",
        /// h22.
        h22: Float64 "px/mm",
        /// h23.
        h23: Float64 "px",
        /// Row 3: h31 (h33 = 1).
        h31: Float64 "1/mm",
        /// h32.
        h32: Float64 "1/mm",
        /// Radial distortion about the image centre, coefficient of (r/R)², R the half-diagonal.
        k1: Float64 "1",
        /// Coefficient of (r/R)⁴.
        k2: Float64 "1",
        /// Mean image scale at the photo's centre (the square root of the camera's Jacobian determinant).
        scale_px_per_mm: Float64 "px/mm",
        /// Enhanced correlation coefficient of the G-code's material with the photo at the finest blur (0.1 mm).
        correlation: Float64 "1",
        /// `only` (one pose fitted best), `by_print` (poses alike by geometry told apart by where the widths change) or `ambiguous`.
        orientation: Str "",
        /// Sign-test p-value of the orientation's choice over lines; NaN for `only`.
        orientation_p_value: Float64 "1",
        /// Fisher separation of print and plate in the learnt colour contrast (pooled sd).
        contrast_separation: Float64 "1",
        /// RMS over measured bead positions of the bead's centre (mid-edges) from the G-code axis.
        reprojection_error_mm: Float64 "mm",
        /// Bead positions the reprojection error is over.
        reprojection_positions: Int64 "1",
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

pipeline::table! {
    /// `fdm.transfer_cv`: one row per training subset of the target's lines, held-out
    /// line and method (paper 000 Case B, Fig. 9).
    pub mod transfer_cv = "transfer_cv" {
        /// Target training lines.
        n_train: Int64 "1",
        /// Which ones: `n3-0_4_8` = the target's lines 0, 4, 8 in `lines.csv` order.
        subset: Str "",
        /// The held-out target line's condition.
        test_condition: Str "",
        /// `single`, `transfer_zero_mean` (the paper's prior N(0, Σ)) or `transfer_source_mean` (the prior centred on the source's estimates).
        method: Str "",
        /// RMSE over the whole held-out line.
        rmse_mm: Float64 "mm",
        /// Prior weight chosen (0 for `single`).
        lambda: Float64 "1",
    }
}

pipeline::table! {
    /// `fdm.transfer_cv`: one work unit's grid winners (`part.parquet`), one row per
    /// (training subset, prior configuration) in that order, exactly as the merge needs
    /// them back.
    pub mod transfer_cv_part = "part" {
        /// Prior configurations per subset.
        configurations: Int64 "1",
        /// Training SSE of the winner (infinite while no pair of the block gave a finite one).
        sse: Float64 "mm²",
        /// Index of the winning pair in the target's grid; −1 where none gave a finite SSE.
        pair: Int64 "1",
        /// The bp1 law's α1 at that pair (eq. 2).
        alpha_1: Float64 "s/mm²",
        /// The bp1 law's α2 at that pair.
        alpha_2: Float64 "1/mm",
        /// The fitted β (p2's growth coefficient).
        theta_0: Float64 "s",
        /// The fitted γ (p3's growth coefficient).
        theta_1: Float64 "√mm",
        /// The fitted steady width c.
        theta_2: Float64 "mm",
        /// The fitted ρ (p5's coefficient of log(F/v)).
        theta_3: Float64 "mm",
        /// The fitted width at t = 0 without a start blob.
        theta_4: Float64 "mm",
    }
}

pipeline::table! {
    /// `fdm.transfer_cv`: one work unit's failures (`part_errors.parquet`), one row per
    /// training subset whose fit failed at a pair of the unit's block.
    pub mod transfer_cv_errors = "part_errors" {
        /// The subset's index.
        subset: Int64 "1",
        /// The first pair of the block at which its fit failed.
        pair: Int64 "1",
        /// Why.
        error: Str "",
    }
}

pipeline::table! {
    /// `fdm.transfer_matrix`: one row per task (sources → target), training-set size and
    /// method, the held-out RMSEs summarised (paper 000 Fig. 9 over several printers).
    pub mod transfer_matrix = "transfer_matrix" {
        /// The source printer(s), `+`-joined.
        sources: Str "",
        /// The target printer.
        target: Str "",
        /// Target training lines (every subset of that size).
        n_train: Int64 "1",
        /// `single`, `transfer_zero_mean`, `transfer_source_mean`, `guarded` (the negative-transfer guard), `co_learning` (several sources), or `hindsight_bound` (not a method: per training subset the prior and λ best on its own held-out lines, how far any choice of λ could go).
        method: Str "",
        /// Median held-out RMSE over every (subset, held-out line).
        median_rmse_mm: Float64 "mm",
        /// 100·(single − method)/single of the medians; above 0 is better than learning from the target alone.
        improvement_pct: Float64 "%",
        /// Lower end of its 95 % interval (paired bootstrap over the target's held-out lines).
        ci_lo_pct: Float64 "%",
        /// Upper end of that interval.
        ci_hi_pct: Float64 "%",
        /// Predictions behind the median.
        rows: Int64 "1",
        /// Where the fits under a prior took the kinematic scales (r_a, r_F) of eq. 1: `grid` (the grid search repeated under each prior and λ) or `target_pair` (the training lines' own pair, found without prior).
        kinematics: Str "",
    }
}

pipeline::table! {
    /// `fdm.transfer_matrix`: one row per prediction: task, training subset, held-out
    /// line and method.
    pub mod transfer_matrix_rows = "transfer_matrix_rows" {
        /// The source printer(s), `+`-joined.
        sources: Str "",
        /// The target printer.
        target: Str "",
        /// Target training lines.
        n_train: Int64 "1",
        /// Which ones (`n3-0_4_8`).
        subset: Str "",
        /// The held-out target line's condition.
        test_condition: Str "",
        /// The method.
        method: Str "",
        /// RMSE over the whole held-out line.
        rmse_mm: Float64 "mm",
        /// Prior weight chosen.
        lambda: Float64 "1",
        /// The prior used: `none`, the source printer's name (followed by ` (zero mean)` for the paper's zero-mean prior), or `pooled`.
        prior: Str "",
    }
}

pipeline::table! {
    /// `fdm.transfer_matrix`: one work unit's rows (`part.parquet`, one target printer),
    /// with indices instead of names, as the merge needs them back.
    pub mod transfer_matrix_part = "part" {
        /// The task's index.
        task: Int64 "1",
        /// Target training lines.
        n_train: Int64 "1",
        /// Which ones.
        subset: Str "",
        /// The held-out line's index among the target's lines.
        test_index: Int64 "1",
        /// The method.
        method: Str "",
        /// RMSE over the whole held-out line.
        rmse_mm: Float64 "mm",
        /// Prior weight chosen.
        lambda: Float64 "1",
        /// The prior used.
        prior: Str "",
    }
}

pipeline::table! {
    /// `fdm.pressure_advance`: one row per fit of a print's lag: all its photos together
    /// (`subset` = `all`), then each photo alone.
    pub mod pressure_advance = "pressure_advance" {
        /// The print (the dataset's printer).
        print: Str "",
        /// `all` (every photo of the print) or the one photo fitted.
        subset: Str "",
        /// Photos fitted.
        photos: Int64 "1",
        /// Lines fitted (measured lines; a line's photos are one group).
        lines: Int64 "1",
        /// `fitted`, `at_bound` (the best τ is an end of the searched range) or `failed`.
        status: Str "",
        /// Why a fit failed; empty otherwise.
        reason: Str "",
        /// The melt's first-order lag τ.
        tau_s: Float64 "s",
        /// Lower end of τ's 95 % delete-one-line jackknife interval (log scale).
        tau_ci_lo_s: Float64 "s",
        /// Upper end of τ's interval.
        tau_ci_hi_s: Float64 "s",
        /// The pressure advance that makes the modelled width flattest under τ.
        recommended_pa_s: Float64 "s",
        /// Lower end of the recommendation's 95 % jackknife interval.
        pa_ci_lo_s: Float64 "s",
        /// Upper end of the recommendation's interval.
        pa_ci_hi_s: Float64 "s",
        /// RMSE of each line predicted under the τ fitted without it (its level fitted on itself).
        heldout_rmse_mm: Float64 "mm",
        /// RMSE at τ over every measured position.
        rmse_mm: Float64 "mm",
        /// Sample-to-sample noise of the widths (1.4826·median|Δw|/√2, median over lines).
        noise_mm: Float64 "mm",
        /// The pressure advance of the measured line whose width is flattest (least `width_spread`): the line a person would pick by eye.
        flattest_line_pa_s: Float64 "s",
        /// Acceleration the lines were planned with.
        accel_mm_s2: Float64 "mm/s²",
        /// Printer settings the dataset left out and the G-code does not set, with the value assumed.
        assumed: Str "",
    }
}

pipeline::table! {
    /// `fdm.pressure_advance`: one row per (fit, line).
    pub mod pressure_advance_lines = "pressure_advance_lines" {
        /// The fit (as `pressure_advance.subset`).
        subset: Str "",
        /// The printed line (as `photo_lines`).
        line: Int64 "1",
        /// The pressure advance it was printed with.
        pressure_advance_s: Float64 "s",
        /// Measured over modelled width (the line's squish), fitted on the line.
        level: Float64 "1",
        /// RMSE at the fit's τ.
        rmse_mm: Float64 "mm",
        /// τ fitted without this line.
        tau_without_s: Float64 "s",
        /// RMSE of this line under the τ fitted without it.
        heldout_rmse_mm: Float64 "mm",
        /// Positions measured (all photos of the fit).
        positions: Int64 "1",
        /// Sample-to-sample noise of its widths.
        noise_mm: Float64 "mm",
        /// RMS of its measured width over its median − 1 (a gap counts as 0): how uneven it is.
        width_spread: Float64 "1",
    }
}

pipeline::table! {
    /// `fdm.pressure_advance`: per measured position, the width against the model's under
    /// the print's τ (the `all` fit).
    pub mod pressure_advance_widths = "pressure_advance_widths" {
        /// The photo.
        photo_id: Str "",
        /// The printed line.
        line: Int64 "1",
        /// The pressure advance it was printed with.
        pressure_advance_s: Float64 "s",
        /// Position along the line from its G-code start.
        position_mm: Float64 "mm",
        /// Measured width (0 in a gap).
        width_mm: Float64 "mm",
        /// The model's width under the print's τ and the line's advance (0 in a gap).
        predicted_mm: Float64 "mm",
        /// The commanded speed at this position.
        speed_mm_s: Float64 "mm/s",
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
    &photo_lines::TABLE,
    &photo_widths::TABLE,
    &photo_calibration::TABLE,
    &pressure_advance::TABLE,
    &pressure_advance_lines::TABLE,
    &pressure_advance_widths::TABLE,
    &agreement::TABLE,
    &agreement_profiles::TABLE,
    &transfer_cv::TABLE,
    &transfer_cv_part::TABLE,
    &transfer_cv_errors::TABLE,
    &transfer_matrix::TABLE,
    &transfer_matrix_rows::TABLE,
    &transfer_matrix_part::TABLE,
];
