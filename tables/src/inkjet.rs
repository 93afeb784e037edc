//! Paper 002's tables (Lu et al. 2015): simulated prints (Figs 11-15, Table II), the
//! layer-to-layer height model's residuals on scans (eqs 2-7) and the exact recovery of
//! droplet patterns (Sec. IV-C), and the control study's closed-loop prints with the
//! discrepancy engine's extended model (`inkjet.control_gain`).

use pipeline::schema::Table;

pipeline::table! {
    /// `inkjet.print_experiment`: one row per simulated print.
    pub mod summary = "summary" {
        /// `cylinder`, `cuboid` or `pipe_junction`.
        scenario: Str "",
        /// `open_loop` or `closed_loop` (the MPC of eq. 8).
        controller: Str "",
        /// Largest droplet-volume shortfall p.
        variation_pct: Float64 "%",
        /// Layers printed.
        layers: Int64 "1",
        /// |mean(h_d − H)|, the mean error of Figs 11-12.
        mean_err_um: Float64 "µm",
        /// Population standard deviation of the final height H.
        std_um: Float64 "µm",
        /// sqrt(mean((H − h_d)²)), Table II's Z-axis RMSD.
        rmsd_um: Float64 "µm",
        /// Mean final height (Table II's average height).
        avg_height_um: Float64 "µm",
    }
}

pipeline::table! {
    /// `inkjet.print_experiment`: one row per grid cell, the final height.
    pub mod height_map = "height_map" {
        /// Cell column.
        x_index: Int64 "1",
        /// Cell row.
        y_index: Int64 "1",
        /// Cell position, x.
        x_um: Float64 "µm",
        /// Cell position, y.
        y_um: Float64 "µm",
        /// Final height.
        height_um: Float64 "µm",
    }
}

pipeline::table! {
    /// `inkjet.print_experiment` (pipe junction): one row per region, the part-top error
    /// (Figs 13-15).
    pub mod edge_deformation = "edge_deformation" {
        /// The scenario.
        scenario: Str "",
        /// The controller.
        controller: Str "",
        /// Largest droplet-volume shortfall.
        variation_pct: Float64 "%",
        /// `edge` (part cells within 2 cells of a non-part cell) or `interior`.
        region: Str "",
        /// Cells in the region.
        cells: Int64 "1",
        /// RMS of printed top − desired top.
        rmse_um: Float64 "µm",
        /// Largest absolute error.
        max_abs_um: Float64 "µm",
        /// Mean of printed top − desired top.
        mean_err_um: Float64 "µm",
    }
}

pipeline::table! {
    /// `inkjet.print_experiment` (two materials): one row per cell, the printed and the
    /// desired top of the part.
    pub mod part_top = "part_top" {
        /// Cell column.
        x_index: Int64 "1",
        /// Cell row.
        y_index: Int64 "1",
        /// Top of the part material printed there.
        part_top_um: Float64 "µm",
        /// Desired top of the part there.
        desired_top_um: Float64 "µm",
    }
}

pipeline::table! {
    /// `inkjet.print_experiment` (two materials): one row per (layer, cell), the true
    /// profile before and after the layer and the material printed.
    pub mod layers = "layers" {
        /// The layer (1-based).
        layer: Int64 "1",
        /// Cell column.
        x_index: Int64 "1",
        /// Cell row.
        y_index: Int64 "1",
        /// Height before the layer.
        bottom_um: Float64 "µm",
        /// Height after the layer.
        top_um: Float64 "µm",
        /// `part`, `support` or `none`.
        material: Str "",
    }
}

pipeline::table! {
    /// `inkjet.scan_residuals`: one row per (dataset, layer), the model's one-layer
    /// prediction error (eqs 2-7).
    pub mod scan_residuals = "scan_residuals" {
        /// From the dataset's `grid.toml`.
        scenario: Str "",
        /// From the dataset's `grid.toml`.
        controller: Str "",
        /// The dataset's extra effects, `name=strength,...`, `none`, or `measured`.
        effects: Str "",
        /// The dataset's droplet-volume shortfall.
        variation_pct: Float64 "%",
        /// The layer predicted (1-based).
        layer: Int64 "1",
        /// RMS of measured − predicted over the desired footprint.
        rmse_um: Float64 "µm",
        /// Mean of measured − predicted.
        bias_um: Float64 "µm",
        /// Largest absolute residual.
        max_abs_um: Float64 "µm",
    }
}

pipeline::table! {
    /// `inkjet.scan_residuals`: one row per (scan, cell), the measured and the predicted
    /// height.
    pub mod profiles = "profiles" {
        /// The scan (0: the substrate).
        layer: Int64 "1",
        /// Cell column.
        x_index: Int64 "1",
        /// Cell row.
        y_index: Int64 "1",
        /// Cell position, x.
        x_um: Float64 "µm",
        /// Cell position, y.
        y_um: Float64 "µm",
        /// Scanned height.
        measured_um: Float64 "µm",
        /// The model's height from the previous scan.
        model_um: Float64 "µm",
    }
}

pipeline::table! {
    /// `inkjet.recovery`: one row per exact-recovery trial (Sec. IV-C).
    pub mod recovery = "recovery" {
        /// Trial index (its generator is seeded with the stage seed + trial).
        trial: Int64 "1",
        /// The found pattern equals the applied one.
        recovered: Bool "",
        /// Cells where the found pattern differs from the applied one.
        flips_wrong: Int64 "1",
        /// Eq. 8 objective of the found pattern.
        objective_um: Float64 "µm",
        /// Droplets in the applied pattern.
        droplets_applied: Int64 "1",
    }
}

pipeline::table! {
    /// `inkjet.control_gain`: one row per effect, strength and controller model, the
    /// closed-loop cylinder's top surface over the printers (paper 002 eq. 8 with the
    /// discrepancy engine's extended model).
    pub mod control_gain = "control_gain" {
        /// The printers' effect: `curing_shrinkage`, `volume_drift` or `nozzle_bias`.
        effect: Str "",
        /// Its strength (magnitude; the drift's sign is drawn per printer).
        strength: Float64 "1",
        /// The controller's model: `paper`, `mean_droplet` (the engine's baseline) or `extended`.
        controller: Str "",
        /// Printers (trials) summarised.
        printers: Int64 "1",
        /// The desired height h_d.
        desired_um: Float64 "µm",
        /// |mean(h_d − H)| of the true top surface over the footprint, mean over printers.
        mean_error_um: Float64 "µm",
        /// Its 95 % Student-t interval over printers, low end.
        mean_error_ci_lo: Float64 "µm",
        /// Its 95 % Student-t interval over printers, high end.
        mean_error_ci_hi: Float64 "µm",
        /// sqrt(mean((H − h_d)²)), mean over printers.
        rmsd_um: Float64 "µm",
        /// Its 95 % interval, low end.
        rmsd_ci_lo: Float64 "µm",
        /// Its 95 % interval, high end.
        rmsd_ci_hi: Float64 "µm",
        /// mean(H), mean over printers.
        average_height_um: Float64 "µm",
        /// Its 95 % interval, low end.
        average_height_ci_lo: Float64 "µm",
        /// Its 95 % interval, high end.
        average_height_ci_hi: Float64 "µm",
        /// Mean over printers of this controller's mean error minus the paper controller's on the same printer (0 for `paper`).
        mean_error_vs_paper_um: Float64 "µm",
        /// Its paired 95 % interval, low end.
        mean_error_vs_paper_ci_lo: Float64 "µm",
        /// Its paired 95 % interval, high end.
        mean_error_vs_paper_ci_hi: Float64 "µm",
        /// The same paired difference for the RMSD.
        rmsd_vs_paper_um: Float64 "µm",
        /// Its paired 95 % interval, low end.
        rmsd_vs_paper_ci_lo: Float64 "µm",
        /// Its paired 95 % interval, high end.
        rmsd_vs_paper_ci_hi: Float64 "µm",
    }
}

pipeline::table! {
    /// `inkjet.control_gain`: one row per production print (printer and controller model).
    pub mod control_trials = "control_trials" {
        /// The printer's effect.
        effect: Str "",
        /// Its strength (signed: the drift's sign is drawn per printer).
        strength: Float64 "1",
        /// The printer (trial) within its effect and strength.
        printer: Int64 "1",
        /// The printer's seed, 16 hex digits.
        seed: Str "",
        /// What the engine named on the printer's calibration print (`none`: nothing).
        named: Str "",
        /// The controller's model: `paper`, `mean_droplet` or `extended`.
        controller: Str "",
        /// Layers the controller printed.
        layers_printed: Int64 "1",
        /// The desired height h_d.
        desired_um: Float64 "µm",
        /// |mean(h_d − H)| of the true top surface over the footprint.
        mean_error_um: Float64 "µm",
        /// sqrt(mean((H − h_d)²)).
        rmsd_um: Float64 "µm",
        /// Population standard deviation of H.
        std_um: Float64 "µm",
        /// mean(H).
        average_height_um: Float64 "µm",
    }
}

/// Every table of this module.
pub const ALL: &[&Table] = &[
    &summary::TABLE,
    &height_map::TABLE,
    &edge_deformation::TABLE,
    &part_top::TABLE,
    &layers::TABLE,
    &scan_residuals::TABLE,
    &profiles::TABLE,
    &recovery::TABLE,
    &control_gain::TABLE,
    &control_trials::TABLE,
];
