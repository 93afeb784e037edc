//! `thermal.reprint_evaluate`: paper 003 Sec. 3.3. Prints the test part again on the
//! virtual printer that made the dataset (same effects, read from its `dataset.toml`
//! provenance: this is an evaluation stage), once with the conventional command and
//! once with the compensated one from `thermal.compensate`, with the same per-layer
//! flow draws (paired comparison), and measures both against the CAD part:
//!
//! - Over-deposition index per corner (eq. 40), O_E = A_o / A_c on the first layer.
//!   A_c, "the perfect corner polytope area in a corner": the rhombus where the two
//!   edges' ideal beads (width W) overlap, area W²/sin θ for interior angle θ. A_o: the
//!   deposited area outside the ideal bead (the CAD polygon swept by W with mitred
//!   corners) within the corner window, a disc of radius `corner_radius_mm` around the
//!   vertex. The window must hold the whole corner bulge; A_c does not depend on it, so
//!   O_E is the bulge measured in corner polytopes.
//! - Contour error (eq. 41, Table 3): every CAD contour point to the nearest point of the
//!   printed footprint's boundary (fill level 0.5, marching squares), on every layer; max
//!   and RMS over all. The CAD points P_t are "the desirable external surface profile"
//!   the paper's laser profiler measures from outside the part: the outer offset polygon
//!   at W/2, every 0.05 mm (`inner_face = true` adds the wall's inside face at −W/2).
//! - Where that error lies (`contour_regions.parquet`): eq. 41 is unsigned, so each CAD
//!   point also records whether the print covers it (the error is a bulge beyond it) or
//!   falls short of it, and the points are grouped by region: within `corner_radius_mm`
//!   of a CAD vertex (its nearest; an apex if the part is convex there, a valley if
//!   not), the seam (within one flow time constant of travel, feed·τ, of the point
//!   where every layer starts and ends), and the straight runs. Per region and variant:
//!   the max, whether it is a bulge, the RMS and the region's share of the sum of e_t².
//!
//! Also writes the first layer's deposit classes near the corners (Fig. 10) and the
//! CAD polygon.

use datasets::manifest::Provenance;
use datasets::thermal::deposition::print_part_observed;
use datasets::thermal::effects::Effects;
use datasets::thermal::sequence::ThermalSequence;
use models::thermal::metrics::{
    contour_errors, contour_region, corner_deposition, corner_polytope_area_mm2, summarize, summarize_regions,
    ContourPoint, ContourRegion, IdealBead, RegionSummary,
};
use models::thermal::{DepositGrid, PrintSetup};
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::common::{f64s, open_sequence, read_table, trajectory_of};
use crate::progress::StageProgress;
use crate::roles;
use crate::table::{bool_col, f64_col, frame, i64_col, str_col};
use models::thermal::setup::{convex_vertices, interior_angles_deg};
use tables::thermal::{command, contour, contour_points, contour_regions, corners, deposit_regions, path};

/// The `thermal.reprint_evaluate` stage kind.
pub struct ReprintEvaluateStage;

/// The compensation to re-print.
pub const COMPENSATION: Input = Input::one(
    "compensation",
    &[Source::Stage("thermal.compensate")],
    "the conventional and the compensated command of `thermal.compensate` (command.parquet)",
)
.reading(&[Reads { table: &command::TABLE, columns: &[command::v_e_mm_s, command::v_ef_mm_s] }]);

pipeline::params! {
    /// The parameters of `thermal.reprint_evaluate`.
    pub struct ReprintParams {
        /// Layers of the evaluation part (Fig. 7b, Table 3: 20).
        pub layers: i64 [1, 50] = 20,
        /// Radius of the corner window around each vertex in which A_o is counted (mm); must hold the corner bulge (about twice the bead width).
        pub corner_radius_mm: f64 [0.1, 5.0] = 1.0,
        /// Spacing of the CAD contour points of eq. 41 (mm); the paper's profiler samples every 0.5 mm in z, we sample the contour finely.
        pub contour_spacing_mm: f64 [0.005, 1.0] = 0.05,
        /// Also score the wall's inside face in eq. 41; the paper's P_t is the external surface its profiler sees (Sec. 3.3).
        pub inner_face: bool = false,
    }
}

impl Stage for ReprintEvaluateStage {
    type Params = ReprintParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "thermal.reprint_evaluate",
        version: 7,
        summary:
            "Re-print with and without compensation on the virtual printer → corners (O_E), contour (max, RMS), maps",
        implements: "paper 003 Sec. 3.3, eqs 40-41, Table 3 (evaluation: reads the printer's effects)",
        inputs: &[roles::THERMAL_SEQUENCE, COMPENSATION],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[
        &corners::TABLE,
        &contour::TABLE,
        &contour_points::TABLE,
        &contour_regions::TABLE,
        &deposit_regions::TABLE,
        &path::TABLE,
    ];

    fn run(&self, ctx: &mut StageContext, p: &ReprintParams) -> Result<(), StageError> {
        let seq = open_sequence(&ctx.input(&roles::THERMAL_SEQUENCE).dir)?;
        let setup = seq.process.print_setup();
        let trajectory = trajectory_of(&seq)?;
        let (effects, dataset_seed) = virtual_printer(&seq)?;
        let commands = read_commands(&ctx.input(&COMPENSATION).dir, trajectory.len())?;
        let layers = p.layers as usize;
        let progress = StageProgress::new(ctx);
        let print = |command: &[f64]| -> Result<Vec<DepositGrid>, StageError> {
            // Seeded from the dataset, not the stage: every re-print of one dataset (the
            // paper's method, the extension) draws the same flow factors, so their
            // conventional prints are the same print.
            let mut rng = ChaCha8Rng::seed_from_u64(dataset_seed ^ REPRINT_SEED_SALT);
            let printed = print_part_observed(&setup, &trajectory, command, layers, &effects, &mut rng, &progress)
                .map_err(StageError::domain)?;
            Ok(printed.into_iter().map(|l| l.grid).collect())
        };
        let (before, after) = rayon::join(|| print(&commands.0), || print(&commands.1));
        let (before, after) = (before?, after?);
        let bead = IdealBead::new(&seq.path_mm, setup.bead_width_mm / 2.0).map_err(StageError::domain)?;
        let radius_mm = p.corner_radius_mm;
        let mut corners = corners_frame(&seq, &setup, &bead, radius_mm, &before[0], &after[0])?;
        ctx.write_table(corners::TABLE.name, &mut corners)?;
        let cad = bead.contour_points(p.contour_spacing_mm, p.inner_face);
        let errors_before: Vec<Vec<ContourPoint>> = before.iter().map(|g| contour_errors(g, &cad)).collect();
        let errors_after: Vec<Vec<ContourPoint>> = after.iter().map(|g| contour_errors(g, &cad)).collect();
        let mut contour = contour_frame(&errors_before, &errors_after)?;
        ctx.write_table(contour::TABLE.name, &mut contour)?;
        let mut points = contour_points_frame(&errors_before, &errors_after)?;
        ctx.write_table(contour_points::TABLE.name, &mut points)?;
        let seam_mm = [trajectory.x_mm[0], trajectory.y_mm[0]];
        let seam_radius_mm = setup.feed_mm_s * setup.tau_s;
        let regions: Vec<ContourRegion> =
            cad.iter().map(|p| contour_region(*p, &seq.path_mm, radius_mm, seam_mm, seam_radius_mm)).collect();
        let mut by_region = regions_summary_frame(&seq.path_mm, &errors_before, &errors_after, &regions)?;
        ctx.write_table(contour_regions::TABLE.name, &mut by_region)?;
        let mut regions = regions_frame(&seq.path_mm, &bead, radius_mm, &before[0], &after[0])?;
        ctx.write_table(deposit_regions::TABLE.name, &mut regions)?;
        let path = &seq.path_mm;
        let mut path_table = frame(vec![
            i64_col(path::vertex, (0..path.len() as i64).collect()),
            f64_col(path::x_mm, path.iter().map(|p| p[0]).collect()),
            f64_col(path::y_mm, path.iter().map(|p| p[1]).collect()),
        ])?;
        ctx.write_table(path::TABLE.name, &mut path_table)?;
        Ok(())
    }
}

/// The extra effects and the seed of the virtual printer that made the dataset.
fn virtual_printer(seq: &ThermalSequence) -> Result<(Effects, u64), StageError> {
    match &seq.manifest.provenance {
        Provenance::Virtual { effects, seed, .. } => Effects::from_pairs(effects.iter().map(|(k, v)| (k.as_str(), *v)))
            .map(|e| (e, *seed))
            .map_err(|e| super::common::bad_input(seq, "dataset.toml", e)),
        Provenance::Measured { .. } => Err(super::common::bad_input(
            seq,
            "dataset.toml",
            "a virtual dataset: re-printing needs the virtual printer that made it (provenance type = \"virtual\")",
        )),
    }
}

/// Mixed into the dataset's seed for the re-print's flow draws, so that they differ from
/// the draws that printed the dataset itself.
const REPRINT_SEED_SALT: u64 = 0x5245_5052_494e_5421;

/// The conventional and the compensated command (mm/s of filament) per sample.
fn read_commands(dir: &std::path::Path, samples: usize) -> Result<(Vec<f64>, Vec<f64>), StageError> {
    let file = dir.join(command::TABLE.file());
    let df = read_table(dir, &command::TABLE.file())?;
    let (v_e, v_ef) = (f64s(&df, command::v_e_mm_s, &file)?, f64s(&df, command::v_ef_mm_s, &file)?);
    if v_e.len() != samples {
        return Err(StageError::BadInput {
            file,
            location: None,
            expected: format!("{samples} rows, one per trajectory sample; found {}", v_e.len()),
        });
    }
    Ok((v_e, v_ef))
}

/// `corners.parquet`: eq. 40 per CAD vertex, before and after.
fn corners_frame(
    seq: &ThermalSequence,
    setup: &PrintSetup,
    bead: &IdealBead,
    radius_mm: f64,
    before: &DepositGrid,
    after: &DepositGrid,
) -> Result<polars::prelude::DataFrame, StageError> {
    let angles = interior_angles_deg(&seq.path_mm);
    let width = setup.bead_width_mm;
    let polytope: Vec<f64> = angles.iter().map(|a| corner_polytope_area_mm2(width, *a)).collect();
    let b: Vec<_> = seq.path_mm.iter().map(|v| corner_deposition(before, bead, *v, radius_mm)).collect();
    let a: Vec<_> = seq.path_mm.iter().map(|v| corner_deposition(after, bead, *v, radius_mm)).collect();
    frame(vec![
        i64_col(corners::corner, (0..angles.len() as i64).collect()),
        f64_col(corners::angle_deg, angles),
        f64_col(corners::oe_before_pct, b.iter().zip(&polytope).map(|(c, p)| 100.0 * c.over_area_mm2 / p).collect()),
        f64_col(corners::oe_after_pct, a.iter().zip(&polytope).map(|(c, p)| 100.0 * c.over_area_mm2 / p).collect()),
        f64_col(corners::a_c_mm2, polytope.clone()),
        f64_col(corners::a_o_before_mm2, b.iter().map(|c| c.over_area_mm2).collect()),
        f64_col(corners::a_o_after_mm2, a.iter().map(|c| c.over_area_mm2).collect()),
        f64_col(corners::a_u_before_mm2, b.iter().map(|c| c.under_area_mm2).collect()),
        f64_col(corners::a_u_after_mm2, a.iter().map(|c| c.under_area_mm2).collect()),
        f64_col(corners::window_ideal_mm2, b.iter().map(|c| c.ideal_area_mm2).collect()),
    ])
}

/// `contour.parquet`: Table 3's max and RMS per variant over all layers.
fn contour_frame(
    before: &[Vec<ContourPoint>],
    after: &[Vec<ContourPoint>],
) -> Result<polars::prelude::DataFrame, StageError> {
    let (b, a) = (summarize(before), summarize(after));
    frame(vec![
        str_col(contour::variant, vec!["conventional".into(), "compensated".into()]),
        f64_col(contour::max_mm, vec![b.max_mm, a.max_mm]),
        f64_col(contour::rms_mm, vec![b.rms_mm, a.rms_mm]),
        i64_col(contour::points, vec![b.points as i64, a.points as i64]),
    ])
}

/// `contour_points.parquet`: e_t of eq. 41 per CAD point and layer (Fig. 11).
fn contour_points_frame(
    before: &[Vec<ContourPoint>],
    after: &[Vec<ContourPoint>],
) -> Result<polars::prelude::DataFrame, StageError> {
    let mut cols = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (variant, layers) in [("conventional", before), ("compensated", after)] {
        for (layer, points) in layers.iter().enumerate() {
            for p in points {
                cols.0.push(variant.to_string());
                cols.1.push(layer as i64);
                cols.2.push(p.x_mm);
                cols.3.push(p.y_mm);
                cols.4.push(p.error_mm);
                cols.5.push(p.covered);
            }
        }
    }
    frame(vec![
        str_col(contour_points::variant, cols.0),
        i64_col(contour_points::layer, cols.1),
        f64_col(contour_points::x_mm, cols.2),
        f64_col(contour_points::y_mm, cols.3),
        f64_col(contour_points::error_mm, cols.4),
        bool_col(contour_points::covered, cols.5),
    ])
}

/// `contour_regions.parquet`: eq. 41 per region (corners in vertex order, then the seam
/// and the straight runs), before and after.
fn regions_summary_frame(
    path_mm: &[[f64; 2]],
    before: &[Vec<ContourPoint>],
    after: &[Vec<ContourPoint>],
    regions: &[ContourRegion],
) -> Result<polars::prelude::DataFrame, StageError> {
    let (b, a) = (summarize_regions(before, regions), summarize_regions(after, regions));
    let total = |m: &std::collections::BTreeMap<ContourRegion, RegionSummary>| -> f64 {
        m.values().map(|r| r.sum_sq_mm2).sum()
    };
    let (total_b, total_a) = (total(&b), total(&a));
    let (angles, convex) = (interior_angles_deg(path_mm), convex_vertices(path_mm));
    let mut cols = RegionColumns::default();
    for (region, rb) in &b {
        let ra = &a[region];
        let (name, corner, angle, kind) = match *region {
            ContourRegion::Corner(i) => ("corner", i as i64, angles[i], if convex[i] { "apex" } else { "valley" }),
            ContourRegion::Seam => ("seam", -1, f64::NAN, "seam"),
            ContourRegion::Straight => ("straight", -1, f64::NAN, "straight"),
        };
        cols.region.push(name.into());
        cols.corner.push(corner);
        cols.angle_deg.push(angle);
        cols.kind.push(kind.into());
        cols.points.push(rb.points as i64);
        for (side, r, sum) in [(&mut cols.before, rb, total_b), (&mut cols.after, ra, total_a)] {
            side.max_mm.push(r.max_mm);
            side.max_short.push(!r.max_covered);
            side.rms_mm.push((r.sum_sq_mm2 / r.points as f64).sqrt());
            side.share.push(r.sum_sq_mm2 / sum);
        }
    }
    let RegionColumns { region, corner, angle_deg, kind, points, before, after } = cols;
    frame(vec![
        str_col(contour_regions::region, region),
        i64_col(contour_regions::corner, corner),
        f64_col(contour_regions::angle_deg, angle_deg),
        str_col(contour_regions::kind, kind),
        i64_col(contour_regions::points, points),
        f64_col(contour_regions::max_before_mm, before.max_mm),
        f64_col(contour_regions::max_after_mm, after.max_mm),
        bool_col(contour_regions::max_before_short, before.max_short),
        bool_col(contour_regions::max_after_short, after.max_short),
        f64_col(contour_regions::rms_before_mm, before.rms_mm),
        f64_col(contour_regions::rms_after_mm, after.rms_mm),
        f64_col(contour_regions::sq_share_before, before.share),
        f64_col(contour_regions::sq_share_after, after.share),
    ])
}

/// Columns of `contour_regions.parquet`.
#[derive(Default)]
struct RegionColumns {
    region: Vec<String>,
    corner: Vec<i64>,
    angle_deg: Vec<f64>,
    kind: Vec<String>,
    points: Vec<i64>,
    before: VariantColumns,
    after: VariantColumns,
}

/// The per-variant columns of `contour_regions.parquet`.
#[derive(Default)]
struct VariantColumns {
    max_mm: Vec<f64>,
    max_short: Vec<bool>,
    rms_mm: Vec<f64>,
    share: Vec<f64>,
}

/// `deposit_regions.parquet`: the first layer's cells near the corners as desired
/// (ideal and filled), over (filled outside the ideal bead) or under (ideal, empty).
fn regions_frame(
    path_mm: &[[f64; 2]],
    bead: &IdealBead,
    radius_mm: f64,
    before: &DepositGrid,
    after: &DepositGrid,
) -> Result<polars::prelude::DataFrame, StageError> {
    let reach = radius_mm * 1.2;
    let mut cols = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (variant, grid) in [("conventional", before), ("compensated", after)] {
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                let p = grid.cell_center_mm(ix, iy);
                if !path_mm.iter().any(|v| (v[0] - p[0]).hypot(v[1] - p[1]) <= reach) {
                    continue;
                }
                let filled = grid.fill[grid.index(ix, iy)] >= 0.5;
                let class = match (filled, bead.contains(p)) {
                    (true, true) => "desired",
                    (true, false) => "over",
                    (false, true) => "under",
                    (false, false) => continue,
                };
                cols.0.push(variant.to_string());
                cols.1.push(p[0]);
                cols.2.push(p[1]);
                cols.3.push(class.to_string());
            }
        }
    }
    frame(vec![
        str_col(deposit_regions::variant, cols.0),
        f64_col(deposit_regions::x_mm, cols.1),
        f64_col(deposit_regions::y_mm, cols.2),
        str_col(deposit_regions::class, cols.3),
    ])
}
