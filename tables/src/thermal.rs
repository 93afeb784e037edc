//! Paper 003's tables (Chen et al. 2024): what the thermal monitor measures (the
//! deposition directions of Sec. 2.2, the frames' localisation of eqs 27-30, the widths
//! of Sec. 2.4 and eqs 31-32, and the example frame of Fig. 4) and the evaluation's true
//! widths, the compensation (eqs 33-39), the re-print's scores (eqs 40-41) and the control
//! study's re-prints with the discrepancy engine's τ (`thermal.control_gain`). The
//! discrepancy engine's and the power study's tables are in `crate::discrepancy`.

use pipeline::schema::Table;

pipeline::table! {
    /// `thermal.monitor`: one row per trajectory sample, its deposition frame with and
    /// without the allocation of Sec. 2.2 (Fig. 3) and the half widths it predicts.
    pub mod directions = "directions" {
        /// Trajectory sample: row of `trajectory.csv` (0-based).
        sample: Int64 "1",
        /// Its commanded time.
        t_s: Float64 "s",
        /// Commanded nozzle position, x.
        x_mm: Float64 "mm",
        /// Commanded nozzle position, y.
        y_mm: Float64 "mm",
        /// Commanded path speed.
        speed_mm_s: Float64 "mm/s",
        /// Path curvature κ.
        kappa_per_mm: Float64 "1/mm",
        /// Effective curvature of the allocation (eqs 12-20).
        kappa_eff_per_mm: Float64 "1/mm",
        /// Angle ψ between the deposition direction and the path normal (eq. 21).
        psi_rad: Float64 "rad",
        /// Slenderness of the deposit before the sample (1 or less: slender).
        slender_before: Float64 "1",
        /// Slenderness of the deposit after the sample.
        slender_after: Float64 "1",
        /// Unit left path normal, x (the deposition direction without the allocation).
        normal_x: Float64 "1",
        /// Unit left path normal, y.
        normal_y: Float64 "1",
        /// Unit left deposition direction n_k with the allocation, x.
        dep_x: Float64 "1",
        /// Unit left deposition direction, y.
        dep_y: Float64 "1",
        /// Predicted left half width with the allocation.
        w_left_mm: Float64 "mm",
        /// Predicted right half width with the allocation.
        w_right_mm: Float64 "mm",
        /// Predicted left half width without it (NaN where the deposit is not slender).
        w_left_no_dda_mm: Float64 "mm",
        /// Predicted right half width without it.
        w_right_no_dda_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per (layer, trajectory sample), the half widths read in
    /// the frame where its bead is `measure_age_s` old, at the layer's threshold T_t, and
    /// eqs 31-32.
    pub mod widths = "widths" {
        /// The layer.
        layer: Int64 "1",
        /// Trajectory sample: row of `trajectory.csv` (0-based).
        sample: Int64 "1",
        /// Its commanded time.
        t_s: Float64 "s",
        /// Commanded nozzle position, x.
        x_mm: Float64 "mm",
        /// Commanded nozzle position, y.
        y_mm: Float64 "mm",
        /// Temperature at that point in the frame it was read in; NaN when not read.
        temp_c: Float64 "°C",
        /// Measured left half width w_l; NaN when not read or no edge at T_t was found.
        w_left_mm: Float64 "mm",
        /// Measured right half width w_r.
        w_right_mm: Float64 "mm",
        /// Desired width 2·w_d, w_d = w0 / cos ψ (eq. 31).
        w_desired_mm: Float64 "mm",
        /// Width error Δw = w_l + w_r − 2·w_d (eq. 32); positive: over-deposition.
        dw_mm: Float64 "mm",
        /// Row of `frames.parquet` (0-based) it was read in; −1 when no placed frame shows it at that age.
        frame_index: Int64 "1",
        /// T_t of the layer, given or calibrated on straight samples.
        threshold_c: Float64 "°C",
    }
}

pipeline::table! {
    /// `thermal.true_widths_evaluate`: one row per (layer, trajectory sample), the
    /// printed part's true half widths along the monitor's deposition directions (read
    /// from `truth/`; file `widths.parquet`, a drop-in for the monitor's widths).
    pub mod true_widths = "widths" {
        /// The layer.
        layer: Int64 "1",
        /// Trajectory sample: row of `trajectory.csv` (0-based).
        sample: Int64 "1",
        /// Its commanded time.
        t_s: Float64 "s",
        /// Commanded nozzle position, x.
        x_mm: Float64 "mm",
        /// Commanded nozzle position, y.
        y_mm: Float64 "mm",
        /// True left half width.
        w_left_mm: Float64 "mm",
        /// True right half width.
        w_right_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per frame of the sequence: how it was localised (eqs
    /// 27-30), by the chosen estimator and by both.
    pub mod frames = "frames" {
        /// Layer, from `frames.csv`.
        layer: Int64 "1",
        /// Frame number, from `frames.csv`.
        frame: Int64 "1",
        /// The camera's timestamp t_r from the layer start.
        recorded_time_s: Float64 "s",
        /// Estimated capture time t̂_c (eq. 30); NaN when skipped, placed by the recorded time or parked.
        estimated_time_s: Float64 "s",
        /// Hot corners detected in the band.
        corners_found: Int64 "1",
        /// Of those, paired with a predicted CAD corner.
        corners_matched: Int64 "1",
        /// RMS plane-side error of the fit over the pairs it used; NaN when skipped.
        reproj_err_mm: Float64 "mm",
        /// Localised from its corners (eqs 27-30).
        used: Bool "",
        /// `corners`, `recorded_time` or `parked`; empty when skipped.
        placed_by: Str "",
        /// t̂_c lies on the edge of the search window.
        at_window_edge: Bool "",
        /// Why the frame was not used; empty when used.
        skip_reason: Str "",
        /// The frame whose image this one repeats; −1 otherwise.
        repeat_of_frame: Int64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 1, column 1.
        h11: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 1, column 2.
        h12: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 1, column 3.
        h13: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 2, column 1.
        h21: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 2, column 2.
        h22: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 2, column 3.
        h23: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 3, column 1.
        h31: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 3, column 2.
        h32: Float64 "1",
        /// The frame's homography (undistorted pixel → plane mm, up to scale; NaN when skipped) H, row 3, column 3.
        h33: Float64 "1",
        /// The estimator of this table: `dlt` or `rigid_mount`.
        localisation: Str "",
        /// Corner pairs the estimator used.
        corners_used: Int64 "1",
        /// Nozzle position P_N,i (eq. 29), x; NaN when skipped.
        nozzle_x_mm: Float64 "mm",
        /// Nozzle position, y.
        nozzle_y_mm: Float64 "mm",
        /// t̂_c of the paper's per-frame homography; NaN where it could not localise the frame.
        dlt_time_s: Float64 "s",
        /// t̂_c of the rigid-mount estimator; NaN where it could not localise the frame.
        rigid_mount_time_s: Float64 "s",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per hot corner detected in a frame's band.
    pub mod detections = "detections" {
        /// Layer of the frame.
        layer: Int64 "1",
        /// Frame number.
        frame: Int64 "1",
        /// Undistorted pixel column.
        u_px: Float64 "px",
        /// Undistorted pixel row.
        v_px: Float64 "px",
        /// Raw (distorted) pixel column.
        raw_u_px: Float64 "px",
        /// Raw pixel row.
        raw_v_px: Float64 "px",
        /// Temperature of the detection.
        temp_c: Float64 "°C",
        /// The CAD vertex it was paired with; −1 when unpaired.
        matched_vertex: Int64 "1",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per pass of the rigid-mount fit (0 the nominal start, 1
    /// the fit to the detections' pairs, 2 and up the re-pairing rounds).
    pub mod mount = "mount" {
        /// The pass.
        pass: Int64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 1, column 1.
        h11: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 1, column 2.
        h12: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 1, column 3.
        h13: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 2, column 1.
        h21: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 2, column 2.
        h22: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 2, column 3.
        h23: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 3, column 1.
        h31: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 3, column 2.
        h32: Float64 "1",
        /// The mount homography (row-major; NaN when the fit failed) H, row 3, column 3.
        h33: Float64 "1",
        /// Corner pairs the fit used.
        pairs_used: Int64 "1",
        /// Frames the fit used.
        frames_used: Int64 "1",
        /// RMS residual of the fit.
        rms_mm: Float64 "mm",
        /// This pass's mount placed the frames.
        applied: Bool "",
        /// Why the fit failed; empty when it did not.
        error: Str "",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per ridge-placed corner pair of the rigid estimator.
    pub mod vertices = "vertices" {
        /// Layer of the frame.
        layer: Int64 "1",
        /// Frame number.
        frame: Int64 "1",
        /// The CAD vertex.
        vertex: Int64 "1",
        /// Undistorted pixel column of the placed corner.
        u_px: Float64 "px",
        /// Undistorted pixel row.
        v_px: Float64 "px",
        /// Raw (distorted) pixel column.
        raw_u_px: Float64 "px",
        /// Raw pixel row.
        raw_v_px: Float64 "px",
        /// The pair placed the nozzle.
        used: Bool "",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per pixel of the undistorted frame with the most
    /// matched corners (Fig. 4).
    pub mod frame_example = "frame_example" {
        /// Pixel column.
        u_px: Int64 "px",
        /// Pixel row.
        v_px: Int64 "px",
        /// Temperature.
        temp_c: Float64 "°C",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per corner detected in the example frame.
    pub mod detections_example = "detections_example" {
        /// Undistorted pixel column.
        u_px: Float64 "px",
        /// Undistorted pixel row.
        v_px: Float64 "px",
        /// Temperature of the detection.
        temp_c: Float64 "°C",
        /// The CAD vertex it was paired with; −1 when unpaired.
        matched_vertex: Int64 "1",
    }
}

pipeline::table! {
    /// `thermal.monitor`: the example frame's layer, number and nozzle pixel (one row).
    pub mod frame_example_meta = "frame_example_meta" {
        /// Layer of the example frame.
        layer: Int64 "1",
        /// Its frame number.
        frame: Int64 "1",
        /// The nozzle's undistorted pixel column.
        nozzle_u_px: Float64 "px",
        /// The nozzle's undistorted pixel row.
        nozzle_v_px: Float64 "px",
    }
}

pipeline::table! {
    /// `thermal.monitor`: one row per plane cell seen by a localised frame of the example
    /// layer, the latest frame on top (Fig. 4d).
    pub mod mosaic = "mosaic" {
        /// Cell centre, x.
        x_mm: Float64 "mm",
        /// Cell centre, y.
        y_mm: Float64 "mm",
        /// Temperature.
        temp_c: Float64 "°C",
    }
}

pipeline::table! {
    /// `thermal.true_widths_evaluate`: one row per (filmed layer, region), the monitor's
    /// |w_l + w_r − true width| (evaluation: reads `truth/`).
    pub mod width_errors = "width_errors" {
        /// The layer.
        layer: Int64 "1",
        /// `corner` (within `corner_radius_mm` of a CAD vertex) or `straight`.
        region: Str "",
        /// Samples with both widths.
        n: Int64 "1",
        /// Median absolute width error.
        median_abs_err_mm: Float64 "mm",
        /// 90th percentile of the absolute width error (nearest rank).
        p90_abs_err_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `thermal.accuracy_evaluate`: one row per accuracy metric of the frame pipeline
    /// against `truth/`.
    pub mod accuracy = "accuracy" {
        /// The metric's name.
        metric: Str "",
        /// Its value, in `unit`.
        value: Float64 "",
        /// The value's unit.
        unit: Str "",
        /// How many observations it is computed over.
        n: Int64 "1",
        /// What it measures.
        note: Str "",
    }
}

pipeline::table! {
    /// `thermal.compensate`: one row per trajectory sample, the conventional and the
    /// compensated command (eqs 36-39).
    pub mod command = "command" {
        /// Trajectory sample: row of `trajectory.csv` (0-based).
        sample: Int64 "1",
        /// Its commanded time.
        t_s: Float64 "s",
        /// The conventional deposition (extruder) velocity v_e, of filament.
        v_e_mm_s: Float64 "mm/s",
        /// The compensated command v_ef = v_e − Δv_er.
        v_ef_mm_s: Float64 "mm/s",
    }
}

pipeline::table! {
    /// `thermal.compensate`: one row per compensated width-error span.
    pub mod spans = "spans" {
        /// Span index, in time order.
        span: Int64 "1",
        /// CAD vertex nearest the span's largest error.
        vertex: Int64 "1",
        /// Interior angle of the CAD polygon there.
        angle_deg: Float64 "°",
        /// First sample with Δw ≥ ε.
        t_start_s: Float64 "s",
        /// Last sample with Δw ≥ ε.
        t_end_s: Float64 "s",
        /// Start of the extended window, clipped to the layer.
        t_ext_start_s: Float64 "s",
        /// End of the extended window.
        t_ext_end_s: Float64 "s",
        /// T_p: median temperature of the monitor's detections matched to the vertex; NaN if never detected.
        corner_temp_c: Float64 "°C",
        /// The deposition gain K_e used.
        gain_ke: Float64 "1",
        /// Largest Δw in the span.
        max_dw_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `thermal.compensate`: one row per sample of each span's extended window.
    pub mod compensation = "compensation" {
        /// Span index, as in `spans.parquet`.
        span: Int64 "1",
        /// CAD vertex, as in `spans.parquet`.
        vertex: Int64 "1",
        /// Sample time.
        t_s: Float64 "s",
        /// Δw used there, after the clamp; NaN where not measured (left out of the fit, eq. 39).
        dw_mm: Float64 "mm",
        /// Measured width w_l + w_r there.
        w_measured_mm: Float64 "mm",
        /// Desired width 2·w_d there.
        w_desired_mm: Float64 "mm",
        /// Desired change of the deposition velocity (eq. 33), of filament.
        dv_desired_mm_s: Float64 "mm/s",
        /// What the solved input achieves through G(s) (eq. 38).
        dv_output_mm_s: Float64 "mm/s",
        /// The B-spline input Δv_er (eq. 36).
        dv_input_mm_s: Float64 "mm/s",
    }
}

pipeline::table! {
    /// `thermal.reprint_evaluate`: one row per CAD corner, over-deposition O_E (eq. 40)
    /// of the conventional and the compensated re-print.
    pub mod corners = "corners" {
        /// The corner's CAD vertex (row of `path.csv`).
        corner: Int64 "1",
        /// Interior angle θ.
        angle_deg: Float64 "°",
        /// O_E = 100·A_o/A_c, conventional.
        oe_before_pct: Float64 "%",
        /// O_E, compensated.
        oe_after_pct: Float64 "%",
        /// A_c, the corner polytope W²/sin θ.
        a_c_mm2: Float64 "mm²",
        /// A_o, deposited area in the window outside the ideal bead, conventional.
        a_o_before_mm2: Float64 "mm²",
        /// A_o, compensated.
        a_o_after_mm2: Float64 "mm²",
        /// Ideal bead area in the window left unfilled, conventional.
        a_u_before_mm2: Float64 "mm²",
        /// The same, compensated.
        a_u_after_mm2: Float64 "mm²",
        /// Ideal bead area in the window.
        window_ideal_mm2: Float64 "mm²",
    }
}

pipeline::table! {
    /// `thermal.reprint_evaluate`: one row per variant, the contour error of eq. 41
    /// over all points and layers (Table 3).
    pub mod contour = "contour" {
        /// `conventional` or `compensated`.
        variant: Str "",
        /// Largest contour error.
        max_mm: Float64 "mm",
        /// RMS contour error.
        rms_mm: Float64 "mm",
        /// Contour points × layers.
        points: Int64 "1",
    }
}

pipeline::table! {
    /// `thermal.reprint_evaluate`: one row per (variant, layer, CAD contour point), its
    /// error e_t of eq. 41 (Fig. 11).
    pub mod contour_points = "contour_points" {
        /// `conventional` or `compensated`.
        variant: Str "",
        /// The layer.
        layer: Int64 "1",
        /// CAD contour point, x.
        x_mm: Float64 "mm",
        /// CAD contour point, y.
        y_mm: Float64 "mm",
        /// e_t: distance to the printed footprint's boundary.
        error_mm: Float64 "mm",
        /// The print covers the CAD point (its edge bulges beyond it).
        covered: Bool "",
    }
}

pipeline::table! {
    /// `thermal.reprint_evaluate`: one row per region of the contour (each corner, the
    /// seam, the straight runs), eq. 41 before and after.
    pub mod contour_regions = "contour_regions" {
        /// `corner`, `seam` or `straight`.
        region: Str "",
        /// CAD vertex of a corner region; −1 otherwise.
        corner: Int64 "1",
        /// Interior angle there; NaN for the seam and straight runs.
        angle_deg: Float64 "°",
        /// `apex`, `valley`, `seam` or `straight`.
        kind: Str "",
        /// Contour points × layers in the region.
        points: Int64 "1",
        /// Largest e_t, conventional.
        max_before_mm: Float64 "mm",
        /// Largest e_t, compensated.
        max_after_mm: Float64 "mm",
        /// The print falls short of the CAD point of the largest e_t, conventional.
        max_before_short: Bool "",
        /// The same, compensated.
        max_after_short: Bool "",
        /// RMS of e_t in the region, conventional.
        rms_before_mm: Float64 "mm",
        /// RMS, compensated.
        rms_after_mm: Float64 "mm",
        /// The region's share of the whole contour's sum of e_t², conventional.
        sq_share_before: Float64 "1",
        /// The same, compensated.
        sq_share_after: Float64 "1",
    }
}

pipeline::table! {
    /// `thermal.reprint_evaluate`: one row per cell of the first layer near a corner,
    /// classed against the ideal bead (Figs 9-10).
    pub mod deposit_regions = "deposit_regions" {
        /// `conventional` or `compensated`.
        variant: Str "",
        /// Cell centre, x.
        x_mm: Float64 "mm",
        /// Cell centre, y.
        y_mm: Float64 "mm",
        /// `desired` (filled, in the ideal bead), `over` (filled, outside) or `under` (unfilled, inside).
        class: Str "",
    }
}

pipeline::table! {
    /// `thermal.reprint_evaluate`: one row per vertex of the CAD path.
    pub mod path = "path" {
        /// The vertex (row of `path.csv`).
        vertex: Int64 "1",
        /// Its position, x.
        x_mm: Float64 "mm",
        /// Its position, y.
        y_mm: Float64 "mm",
    }
}

pipeline::table! {
    /// `thermal.control_gain`: one row per strength and controller, the re-prints'
    /// scores (eqs 40-41) over the prints with 95 % Student-t intervals and the paired
    /// difference to the paper's controller.
    pub mod control_gain = "control_gain" {
        /// The effect printed: `tau_mismatch`.
        effect: Str "",
        /// Its relative strength (the printer's τ = τ0·(1 + strength)).
        strength: Float64 "1",
        /// The re-print's command: `conventional` (nominal), `paper` (eqs 31-39 with the nominal τ) or `extended` (with the τ the engine fitted).
        controller: Str "",
        /// Prints (seeds) summarised.
        prints: Int64 "1",
        /// Prints on which the engine named `tau_mismatch`.
        tau_named: Int64 "1",
        /// Eq. 40's O_E of the first re-printed layer, mean over the corners: mean over prints.
        mean_oe_pct: Float64 "%",
        /// Its 95 % Student-t interval over prints, low end.
        mean_oe_pct_ci_lo: Float64 "%",
        /// Its 95 % Student-t interval over prints, high end.
        mean_oe_pct_ci_hi: Float64 "%",
        /// Mean over prints of this controller's `mean_oe_pct` minus the paper controller's on the same print (0 for `paper`).
        mean_oe_pct_vs_paper: Float64 "%",
        /// Its paired 95 % Student-t interval, low end.
        mean_oe_pct_vs_paper_ci_lo: Float64 "%",
        /// Its paired 95 % Student-t interval, high end.
        mean_oe_pct_vs_paper_ci_hi: Float64 "%",
        /// Eq. 41's contour error, RMS over every re-printed layer's CAD points: mean over prints.
        contour_rms_mm: Float64 "mm",
        /// Its 95 % Student-t interval over prints, low end.
        contour_rms_mm_ci_lo: Float64 "mm",
        /// Its 95 % Student-t interval over prints, high end.
        contour_rms_mm_ci_hi: Float64 "mm",
        /// Mean over prints of this controller's `contour_rms_mm` minus the paper controller's on the same print (0 for `paper`).
        contour_rms_mm_vs_paper: Float64 "mm",
        /// Its paired 95 % Student-t interval, low end.
        contour_rms_mm_vs_paper_ci_lo: Float64 "mm",
        /// Its paired 95 % Student-t interval, high end.
        contour_rms_mm_vs_paper_ci_hi: Float64 "mm",
        /// Eq. 41's contour error, maximum over every re-printed layer's CAD points: mean over prints.
        contour_max_mm: Float64 "mm",
        /// Its 95 % Student-t interval over prints, low end.
        contour_max_mm_ci_lo: Float64 "mm",
        /// Its 95 % Student-t interval over prints, high end.
        contour_max_mm_ci_hi: Float64 "mm",
        /// Mean over prints of this controller's `contour_max_mm` minus the paper controller's on the same print (0 for `paper`).
        contour_max_mm_vs_paper: Float64 "mm",
        /// Its paired 95 % Student-t interval, low end.
        contour_max_mm_vs_paper_ci_lo: Float64 "mm",
        /// Its paired 95 % Student-t interval, high end.
        contour_max_mm_vs_paper_ci_hi: Float64 "mm",
    }
}

pipeline::table! {
    /// `thermal.control_gain`: one row per print and controller, what the engine named
    /// and fitted on the filmed print and the re-print's scores.
    pub mod control_trials = "control_trials" {
        /// The effect printed: `tau_mismatch`.
        effect: Str "",
        /// Its relative strength (the printer's τ = τ0·(1 + strength)).
        strength: Float64 "1",
        /// The print (seed index) within its strength.
        print: Int64 "1",
        /// The print's seed, in hex.
        seed: Str "",
        /// What the engine named on the filmed print (`+`-joined, or `none`).
        named: Str "",
        /// The τ excess m̂ the engine fitted (τ = τ0·(1 + m̂)); NaN when it did not name `tau_mismatch`.
        tau_excess: Float64 "1",
        /// Its jackknife interval, low end.
        tau_excess_ci_lo: Float64 "1",
        /// Its jackknife interval, high end.
        tau_excess_ci_hi: Float64 "1",
        /// The re-print's command: `conventional`, `paper` or `extended`.
        controller: Str "",
        /// Eq. 40's O_E of the first re-printed layer, mean over the corners.
        mean_oe_pct: Float64 "%",
        /// Eq. 41's contour error, RMS over every re-printed layer's CAD points.
        contour_rms_mm: Float64 "mm",
        /// Eq. 41's contour error, maximum over every re-printed layer's CAD points.
        contour_max_mm: Float64 "mm",
    }
}

/// `thermal.control_gain`: one work unit's print (`part.parquet`), its rows of
/// `control_trials`, column for column, from which the merge rebuilds the trial.
#[allow(non_upper_case_globals)]
pub mod control_part {
    pub use super::control_trials::*;
    /// The declaration: `control_trials`'s columns under the unit's file name.
    pub const TABLE: pipeline::schema::Table = pipeline::schema::Table {
        name: "part",
        doc: "`thermal.control_gain`: one work unit's print, its rows of `control_trials`.",
        columns: super::control_trials::TABLE.columns,
    };
}

/// The homography columns of `frames.parquet`, row-major.
pub const FRAME_HOMOGRAPHY: [&str; 9] = [
    frames::h11,
    frames::h12,
    frames::h13,
    frames::h21,
    frames::h22,
    frames::h23,
    frames::h31,
    frames::h32,
    frames::h33,
];

/// The mount homography columns of `mount.parquet`, row-major.
pub const MOUNT_HOMOGRAPHY: [&str; 9] =
    [mount::h11, mount::h12, mount::h13, mount::h21, mount::h22, mount::h23, mount::h31, mount::h32, mount::h33];

/// Every table of this module.
pub const ALL: &[&Table] = &[
    &directions::TABLE,
    &widths::TABLE,
    &frames::TABLE,
    &detections::TABLE,
    &mount::TABLE,
    &vertices::TABLE,
    &frame_example::TABLE,
    &detections_example::TABLE,
    &frame_example_meta::TABLE,
    &mosaic::TABLE,
    &true_widths::TABLE,
    &width_errors::TABLE,
    &accuracy::TABLE,
    &command::TABLE,
    &spans::TABLE,
    &compensation::TABLE,
    &corners::TABLE,
    &contour::TABLE,
    &contour_points::TABLE,
    &contour_regions::TABLE,
    &deposit_regions::TABLE,
    &path::TABLE,
    &control_gain::TABLE,
    &control_trials::TABLE,
    &control_part::TABLE,
];

#[cfg(test)]
mod tests {
    use super::*;

    /// A control work unit's part is its rows of `control_trials`, column for column
    /// (the merge rebuilds the trials from the parts and writes them again).
    #[test]
    fn the_control_part_has_the_trials_columns() {
        assert_eq!(control_part::TABLE.columns, control_trials::TABLE.columns);
    }
}
