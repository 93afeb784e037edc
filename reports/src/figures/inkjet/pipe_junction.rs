//! `figure.inkjet_pipe_junction`: the two-material pipe junction of paper 002 (Lu, Zheng,
//! Mishra 2015) Figs 13-15, open vs closed loop: aerial views of the printed part's top
//! surface once the support is washed away (Figs 13-14; cells without part in grey), and
//! a cross-section through the main pipe showing which material every layer put where
//! (the printing block of Fig. 15: part blue, support orange) with the desired part top.
//! Reads `part_top.parquet`, `layers.parquet` and `edge_deformation.parquet` of two
//! `inkjet.print_experiment` stages (scenario `pipe_junction`), open loop first.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::inkjet::{edge_deformation, layers, part_top};

use crate::figures::common::viridis;
use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_png_and_svg, house_mesh, text, PALETTE};

/// The `figure.inkjet_pipe_junction` stage kind.
pub struct InkjetPipeJunctionFigure;

const SIZE_PX: (u32, u32) = (1500, 1150);
const COLOUR_BAR_PX: u32 = 120;
const NO_PART: RGBColor = RGBColor(225, 225, 225);
const SUPPORT: RGBColor = RGBColor(240, 190, 120);

pipeline::params! {
    /// The parameters of `figure.inkjet_pipe_junction`.
    pub struct PipeJunctionParams {
        /// Figure title (default: a generic description).
        pub title: String = "",
        /// Grid column of the y–z cross-section (20: across the main pipe, away from the branch).
        pub section_x_index: i64 [0, 100_000] = 20,
    }
}

/// What the figure reads of each print.
const PRINT_READS: &[Reads] = &[
    Reads {
        table: &part_top::TABLE,
        columns: &[part_top::x_index, part_top::y_index, part_top::part_top_um, part_top::desired_top_um],
    },
    Reads {
        table: &layers::TABLE,
        columns: &[
            layers::layer,
            layers::x_index,
            layers::y_index,
            layers::bottom_um,
            layers::top_um,
            layers::material,
        ],
    },
    Reads {
        table: &edge_deformation::TABLE,
        columns: &[
            edge_deformation::controller,
            edge_deformation::region,
            edge_deformation::rmse_um,
            edge_deformation::max_abs_um,
        ],
    },
];

/// The open-loop print (drawn first).
const OPEN_LOOP: Input = Input::one(
    "open_loop",
    &[Source::Stage("inkjet.print_experiment")],
    "the open-loop pipe junction (`part_top.parquet`, `layers.parquet`, `edge_deformation.parquet`)",
)
.reading(PRINT_READS);

/// The closed-loop print.
const CLOSED_LOOP: Input = Input::one(
    "closed_loop",
    &[Source::Stage("inkjet.print_experiment")],
    "the closed-loop pipe junction (`part_top.parquet`, `layers.parquet`, `edge_deformation.parquet`)",
)
.reading(PRINT_READS);

/// One pipe-junction print as drawn.
struct PipePrint {
    controller: String,
    /// `(x_index, y_index, printed top, desired top)` per cell (NaN: none).
    tops: Vec<(i64, i64, f64, f64)>,
    /// `(layer, y_index, bottom, top, material)` in the section column.
    section: Vec<(i64, f64, f64, String)>,
    /// `(region, rmse, max)`.
    regions: Vec<(String, f64, f64)>,
}

impl Stage for InkjetPipeJunctionFigure {
    type Params = PipeJunctionParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.inkjet_pipe_junction",
        version: 1,
        summary: "Part-top aerial views and a material cross-section of the open- and closed-loop two-material pipe junction → inkjet_pipe_junction.png/.svg",
        implements: "paper 002 Figs 13-15 (two-material pipe junction, open vs closed loop)",
        inputs: &[OPEN_LOOP, CLOSED_LOOP],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &PipeJunctionParams) -> Result<(), StageError> {
        let column = p.section_x_index;
        let prints = [load(&ctx.input(&OPEN_LOOP).dir, column)?, load(&ctx.input(&CLOSED_LOOP).dir, column)?];
        let title = crate::figures::common::title_or(&p.title, || {
            "Two-material pipe junction: part top and material cross-section, open vs closed loop".to_string()
        });
        let stem = ctx.output_path("inkjet_pipe_junction")?;
        draw_png_and_svg(
            &stem,
            SIZE_PX,
            |a| draw_titled(a, &title, &prints, column),
            |a| draw_titled(a, &title, &prints, column),
        )
    }
}

fn load(dir: &Path, column: i64) -> Result<PipePrint, StageError> {
    let path = dir.join(part_top::TABLE.file());
    let df = read_parquet(&path)?;
    let (xi, yi) = (ints(&df, part_top::x_index, &path)?, ints(&df, part_top::y_index, &path)?);
    let (top, want) = (f64s(&df, part_top::part_top_um, &path)?, f64s(&df, part_top::desired_top_um, &path)?);
    let tops: Vec<_> = (0..df.height()).map(|r| (xi[r], yi[r], top[r], want[r])).collect();
    if tops.is_empty() {
        return Err(no_rows(&path, part_top::part_top_um, "one row per grid cell"));
    }
    let path = dir.join(layers::TABLE.file());
    let df = read_parquet(&path)?;
    let (layer, xi, yi) =
        (ints(&df, layers::layer, &path)?, ints(&df, layers::x_index, &path)?, ints(&df, layers::y_index, &path)?);
    let (bottom, top, material) =
        (f64s(&df, layers::bottom_um, &path)?, f64s(&df, layers::top_um, &path)?, strs(&df, layers::material, &path)?);
    let section: Vec<_> = (0..df.height())
        .filter(|&r| xi[r] == column && layer[r] > 0)
        .map(|r| (yi[r], bottom[r], top[r], material[r].clone()))
        .collect();
    if section.is_empty() {
        return Err(no_rows(&path, layers::x_index, &format!("rows of grid column {column}")));
    }
    let path = dir.join(edge_deformation::TABLE.file());
    let df = read_parquet(&path)?;
    let (region, rmse, max) = (
        strs(&df, edge_deformation::region, &path)?,
        f64s(&df, edge_deformation::rmse_um, &path)?,
        f64s(&df, edge_deformation::max_abs_um, &path)?,
    );
    let controller = strs(&df, edge_deformation::controller, &path)?.into_iter().next().unwrap_or_default();
    let regions = (0..df.height()).map(|r| (region[r].clone(), rmse[r], max[r])).collect();
    Ok(PipePrint { controller, tops, section, regions })
}

fn draw_titled<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    prints: &[PipePrint; 2],
    column: i64,
) -> Result<(), String> {
    let area = area.margin(12, 8, 8, 12).titled(title, text(24.0)).map_err(|e| e.to_string())?;
    let (top, bottom) = area.split_vertically((area.dim_in_pixel().1 as f64 * 0.56) as u32);
    let (maps, bar) = top.split_horizontally(top.dim_in_pixel().0.saturating_sub(COLOUR_BAR_PX));
    let max_um = prints.iter().flat_map(|p| p.tops.iter().map(|t| t.3)).filter(|v| v.is_finite()).fold(1e-6, f64::max);
    for (panel, print) in maps.split_evenly((1, 2)).iter().zip(prints) {
        draw_aerial(panel, print, max_um, column).map_err(|e| e.to_string())?;
    }
    crate::figures::common::draw_viridis_bar(&bar, (0.0, max_um), "part top (µm)", 0, 120)
        .map_err(|e| e.to_string())?;
    for (panel, print) in bottom.split_evenly((1, 2)).iter().zip(prints) {
        draw_section(panel, print, column, max_um).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn caption(print: &PipePrint) -> String {
    let region = |name: &str| print.regions.iter().find(|r| r.0 == name).map_or(f64::NAN, |r| r.1);
    format!(
        "{}: part-top RMS error edge {:.1} µm, interior {:.1} µm",
        print.controller.replace('_', " "),
        region("edge"),
        region("interior")
    )
}

fn draw_aerial<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    print: &PipePrint,
    max_um: f64,
    column: i64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let n = print.tops.iter().map(|t| t.0.max(t.1)).max().unwrap_or(0) as f64 + 1.0;
    let area = area.titled(&caption(print), text(18.0))?;
    let (w, h) = area.dim_in_pixel();
    let side = w.saturating_sub(80).min(h.saturating_sub(60));
    let pad_w = w.saturating_sub(side + 80) / 2;
    let mut chart = ChartBuilder::on(&area)
        .margin_left(pad_w)
        .margin_right(pad_w)
        .margin_top(6)
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d(-0.5..n - 0.5, -0.5..n - 0.5)?;
    house_mesh(&mut chart)
        .disable_mesh()
        .x_desc("x index (cells)")
        .y_desc("y index (cells)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()?;
    let cell = |t: &(i64, i64, f64, f64)| {
        let (x, y) = (t.0 as f64, t.1 as f64);
        let colour = if t.2.is_finite() { viridis((t.2 / max_um).clamp(0.0, 1.0)) } else { NO_PART };
        Rectangle::new([(x - 0.5, y - 0.5), (x + 0.5, y + 0.5)], colour.filled())
    };
    chart.draw_series(print.tops.iter().map(cell))?;
    let c = column as f64;
    chart.draw_series(DashedLineSeries::new([(c, -0.5), (c, n - 0.5)], 6, 4, WHITE.stroke_width(2)))?;
    Ok(())
}

fn draw_section<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    print: &PipePrint,
    column: i64,
    max_um: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let n = print.tops.iter().map(|t| t.1).max().unwrap_or(0) as f64 + 1.0;
    let y_hi = print.section.iter().map(|s| s.2).fold(max_um, f64::max) * 1.08;
    let caption =
        format!("{}: materials by layer at x index {column} (dashed line above)", print.controller.replace('_', " "));
    let mut chart = ChartBuilder::on(area)
        .caption(caption, text(18.0))
        .margin(8)
        .margin_right(16)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(-0.5..n - 0.5, 0.0..y_hi)?;
    house_mesh(&mut chart)
        .disable_mesh()
        .x_desc("y index (cells)")
        .y_desc("height (µm)")
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.0}"))
        .draw()?;
    let block = |s: &(i64, f64, f64, String)| {
        let colour = if s.3 == "part" { PALETTE[0] } else { SUPPORT };
        let y = s.0 as f64;
        Rectangle::new([(y - 0.5, s.1), (y + 0.5, s.2)], colour.filled())
    };
    chart.draw_series(print.section.iter().filter(|s| s.3 != "none").map(block))?;
    let mut desired: Vec<(f64, f64)> =
        print.tops.iter().filter(|t| t.0 == column && t.3.is_finite()).map(|t| (t.1 as f64, t.3)).collect();
    desired.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(desired.iter().map(|&(y, z)| Circle::new((y, z), 3, BLACK.filled())))?
        .label("desired part top")
        .legend(|(x, y)| Circle::new((x + 12, y), 3, BLACK.filled()));
    chart
        .draw_series([Rectangle::new([(-1.0, -1.0), (-1.0, -1.0)], PALETTE[0].filled())])?
        .label("part material")
        .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 24, y + 6)], PALETTE[0].filled()));
    chart
        .draw_series([Rectangle::new([(-1.0, -1.0), (-1.0, -1.0)], SUPPORT.filled())])?
        .label("support material")
        .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 24, y + 6)], SUPPORT.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(text(14.0))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, declared, write_declared};
    use polars::df;

    /// A 20 × 20 print with a part band along x (rows 8-11), 3 layers.
    fn write_print(dir: &Path, controller: &str, offset_um: f64) {
        let (mut xi, mut yi, mut top, mut want) = (vec![], vec![], vec![], vec![]);
        for j in 0..20i64 {
            for i in 0..20i64 {
                xi.push(i);
                yi.push(j);
                let part = (8..12).contains(&j);
                want.push(part.then_some(20.0 + j as f64));
                top.push(part.then_some(20.0 + j as f64 + offset_um));
            }
        }
        write_declared(
            dir,
            &part_top::TABLE,
            declared(&part_top::TABLE, df!(part_top::x_index => xi, part_top::y_index => yi, part_top::part_top_um => top, part_top::desired_top_um => want).expect("frame")),
        );
        let (mut layer, mut xi, mut yi, mut bottom, mut upper, mut material) =
            (vec![], vec![], vec![], vec![], vec![], vec![]);
        for k in 1..=3i64 {
            for j in 0..20i64 {
                for i in 0..20i64 {
                    layer.push(k);
                    xi.push(i);
                    yi.push(j);
                    bottom.push(10.0 * (k - 1) as f64);
                    upper.push(10.0 * k as f64);
                    material.push(if (8..12).contains(&j) { "part" } else { "support" }.to_string());
                }
            }
        }
        write_declared(
            dir,
            &layers::TABLE,
            declared(
                &layers::TABLE,
                df!(layers::layer => layer, layers::x_index => xi, layers::y_index => yi, layers::bottom_um => bottom,
            layers::top_um => upper, layers::material => material)
                .expect("frame"),
            ),
        );
        write_declared(
            dir,
            &edge_deformation::TABLE,
            declared(&edge_deformation::TABLE, df!(edge_deformation::controller => [controller, controller], edge_deformation::region => ["edge", "interior"],
            edge_deformation::rmse_um => [offset_um, offset_um / 2.0], edge_deformation::max_abs_um => [offset_um, offset_um])
            .expect("frame")),
        );
    }

    #[test]
    fn loads_and_draws_open_and_closed_loop() {
        let dirs: Vec<_> = (0..3).map(|_| tempfile::tempdir().expect("tempdir")).collect();
        write_print(dirs[0].path(), "open_loop", 6.0);
        write_print(dirs[1].path(), "closed_loop", 1.0);
        let prints = [load(dirs[0].path(), 5).expect("loads"), load(dirs[1].path(), 5).expect("loads")];
        assert_eq!(prints[0].section.len(), 3 * 20);
        assert_eq!(caption(&prints[0]), "open loop: part-top RMS error edge 6.0 µm, interior 3.0 µm");
        assert!(load(dirs[0].path(), 50).is_err(), "no column 50");
        let stem = dirs[2].path().join("inkjet_pipe_junction");
        draw_png_and_svg(
            &stem,
            SIZE_PX,
            |a| draw_titled(a, "synthetic", &prints, 5),
            |a| draw_titled(a, "synthetic", &prints, 5),
        )
        .expect("draws");
        assert_drawn(&stem);
    }
}
