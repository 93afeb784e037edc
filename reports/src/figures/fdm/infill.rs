//! `figure.fdm_infill`: the estimated material coverage of infill lines printed side
//! by side near their two ends, in the style of paper 000 Fig. 7(b) (§III-A): cells
//! covered by no line (voids), one line, or several (overlap), one row of panels per
//! hatch spacing, with the void and overlap fractions per region of the line in the
//! row title. Reads `infill_map.parquet` and `infill.parquet` of one input folder.
//!
//! An uncovered cell counts as a void only when material lies both below and above it
//! in its column (a gap between lines); uncovered cells beyond the outermost material
//! are outside the layer and stay white.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{infill, infill_map};

use crate::read::{f64s, ints, no_rows, read_parquet, strs};
use crate::style::{draw_png_and_svg, text};

/// The `figure.fdm_infill` stage kind.
pub struct InfillFigure;

pipeline::params! {
    /// The parameters of `figure.fdm_infill`.
    pub struct InfillParams {
        /// Printer whose infill estimate is drawn.
        pub printer: String,
        /// Printing condition (`S800F9000`) whose infill estimate is drawn.
        pub condition: String,
        /// Length of line shown at each end; 15 mm covers the start blob and the end
        /// thinning of paper 000 Fig. 3(a).
        pub end_window_mm: f64 [1.0, 1000.0] = 15.0,
    }
}

/// The infill estimate drawn.
const INFILL: Input = Input::one(
    "infill",
    &[Source::Stage("fdm.infill")],
    "the coverage maps and region fractions (`infill_map.parquet`, `infill.parquet`)",
)
.reading(&[
    Reads {
        table: &infill_map::TABLE,
        columns: &[
            infill_map::printer,
            infill_map::condition,
            infill_map::hatch_mm,
            infill_map::x_mm,
            infill_map::y_mm,
            infill_map::coverage,
        ],
    },
    Reads {
        table: &infill::TABLE,
        columns: &[
            infill::printer,
            infill::condition,
            infill::region,
            infill::hatch_mm,
            infill::void_fraction,
            infill::overlap_fraction,
        ],
    },
]);

/// At most this many hatch spacings are drawn (the smallest ones), one row each.
const MAX_HATCHES: usize = 2;
/// Figure width and the height of one hatch row, in pixels.
const WIDTH_PX: u32 = 1400;
const ROW_PX: u32 = 420;
/// Height of the title band and of the legend band, in pixels.
const TITLE_PX: u32 = 50;
const LEGEND_PX: u32 = 44;
/// The regions of `infill.parquet` in drawing order.
const REGIONS: [&str; 3] = ["start", "middle", "end"];

/// How many deposited lines cover a cell, as drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coverage {
    /// No line, and no material on one side of it across the lines: not drawn.
    Outside,
    /// No line, between lines: a void.
    Void,
    /// Exactly one line.
    Single,
    /// Two or more lines: overlap.
    Overlap,
}

impl Coverage {
    /// The class of a cell covered by `lines` deposited lines.
    pub fn of(lines: i64) -> Self {
        match lines {
            i64::MIN..=0 => Self::Void,
            1 => Self::Single,
            _ => Self::Overlap,
        }
    }

    fn colour(self) -> RGBColor {
        match self {
            Self::Outside => WHITE,
            Self::Void => RGBColor(246, 178, 170),
            Self::Single => RGBColor(166, 206, 227),
            Self::Overlap => RGBColor(31, 90, 160),
        }
    }

    fn label(self) -> &'static str {
        match self {
            Self::Outside => "outside the layer",
            Self::Void => "void (gap between lines)",
            Self::Single => "one line",
            Self::Overlap => "overlap (two or more lines)",
        }
    }
}

/// Void and overlap fractions of one region of the lines.
#[derive(Debug, Clone)]
pub struct RegionFractions {
    /// `start`, `middle` or `end`.
    pub region: String,
    /// Fraction of the region's cells with no line.
    pub void_fraction: f64,
    /// Fraction of the region's cells with two or more lines.
    pub overlap_fraction: f64,
}

/// The coverage map of one hatch spacing.
#[derive(Debug)]
pub struct HatchMap {
    /// Centre-to-centre distance of the lines.
    pub hatch_mm: f64,
    /// Grid rows by y (in µm, so rows key exactly): (x in mm, class) sorted by x.
    pub rows: BTreeMap<i64, Vec<(f64, Coverage)>>,
    /// Grid spacing along and across the lines, in mm.
    pub cell_mm: (f64, f64),
    /// The fractions per region, in `REGIONS` order where present.
    pub regions: Vec<RegionFractions>,
}

/// Everything the figure draws.
#[derive(Debug)]
pub struct InfillData {
    /// Printer name.
    pub printer: String,
    /// Condition name.
    pub condition: String,
    /// One map per hatch spacing drawn, ascending.
    pub maps: Vec<HatchMap>,
}

impl Stage for InfillFigure {
    type Params = InfillParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_infill",
        version: 1,
        summary: "Coverage map (void / one line / overlap) of side-by-side infill lines near both ends, per hatch spacing → infill.png/.svg",
        implements: "paper 000 Fig. 7(b)",
        inputs: &[INFILL],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &InfillParams) -> Result<(), StageError> {
        let data = load(&ctx.input(&INFILL).dir, &p.printer, &p.condition)?;
        let window_mm = p.end_window_mm;
        let stem = ctx.output_path("infill")?;
        let size = figure_size_px(data.maps.len());
        draw_png_and_svg(&stem, size, |a| draw(a, &data, window_mm), |a| draw(a, &data, window_mm))
    }
}

/// Reads the maps and region fractions of `printer` at `condition`.
pub fn load(dir: &Path, printer: &str, condition: &str) -> Result<InfillData, StageError> {
    let mut maps = read_maps(&dir.join(infill_map::TABLE.file()), printer, condition)?;
    let fractions = read_fractions(&dir.join(infill::TABLE.file()), printer, condition)?;
    for map in &mut maps {
        let key = hatch_key(map.hatch_mm);
        map.regions = fractions.iter().filter(|f| f.0 == key).map(|f| f.1.clone()).collect();
        map.regions.sort_by_key(|r| REGIONS.iter().position(|n| *n == r.region).unwrap_or(REGIONS.len()));
    }
    Ok(InfillData { printer: printer.into(), condition: condition.into(), maps })
}

/// The figure size for `n_hatches` rows of panels.
pub fn figure_size_px(n_hatches: usize) -> (u32, u32) {
    (WIDTH_PX, TITLE_PX + LEGEND_PX + ROW_PX * n_hatches.max(1) as u32)
}

/// Merges neighbouring cells of one grid row (sorted by x, spaced `dx_mm`) with the
/// same coverage class into runs (x of first cell, x of last cell, class), so a map
/// draws as a few hundred rectangles instead of tens of thousands.
pub fn runs(row: &[(f64, Coverage)], dx_mm: f64) -> Vec<(f64, f64, Coverage)> {
    let mut out: Vec<(f64, f64, Coverage)> = Vec::new();
    for &(x, class) in row {
        match out.last_mut() {
            Some(run) if run.2 == class && x - run.1 <= 1.5 * dx_mm => run.1 = x,
            _ => out.push((x, x, class)),
        }
    }
    out
}

/// The class of every cell (x, y, lines): [`Coverage::of`], except that an uncovered
/// cell with no covered cell below or above it in its column (same x) is outside.
pub fn classify(cells: &[(f64, f64, i64)]) -> Vec<Coverage> {
    let column = |x: f64| (x * 1e4).round() as i64;
    let mut covered_y: BTreeMap<i64, (f64, f64)> = BTreeMap::new();
    for &(x, y, _) in cells.iter().filter(|c| c.2 > 0) {
        let extent = covered_y.entry(column(x)).or_insert((y, y));
        *extent = (extent.0.min(y), extent.1.max(y));
    }
    let inside = |x: f64, y: f64| covered_y.get(&column(x)).is_some_and(|&(lo, hi)| lo < y && y < hi);
    cells
        .iter()
        .map(|&(x, y, lines)| match Coverage::of(lines) {
            Coverage::Void if !inside(x, y) => Coverage::Outside,
            class => class,
        })
        .collect()
}

/// Hatch spacings key maps in whole nanometres, so equal spacings compare equal.
fn hatch_key(hatch_mm: f64) -> i64 {
    (hatch_mm * 1e6).round() as i64
}

fn read_maps(path: &Path, printer: &str, condition: &str) -> Result<Vec<HatchMap>, StageError> {
    use infill_map as t;
    let df = read_parquet(path)?;
    let (printers, conditions) = (strs(&df, t::printer, path)?, strs(&df, t::condition, path)?);
    let (hatch, x, y) = (f64s(&df, t::hatch_mm, path)?, f64s(&df, t::x_mm, path)?, f64s(&df, t::y_mm, path)?);
    let coverage = ints(&df, t::coverage, path)?;
    let mut cells: BTreeMap<i64, Vec<(f64, f64, i64)>> = BTreeMap::new();
    for i in (0..df.height()).filter(|&i| printers[i] == printer && conditions[i] == condition) {
        cells.entry(hatch_key(hatch[i])).or_default().push((x[i], y[i], coverage[i]));
    }
    if cells.is_empty() {
        return Err(no_rows(path, t::condition, &format!("printer `{printer}`, condition `{condition}`")));
    }
    Ok(cells.into_iter().take(MAX_HATCHES).map(|(key, cells)| hatch_map(key as f64 * 1e-6, cells)).collect())
}

fn hatch_map(hatch_mm: f64, cells: Vec<(f64, f64, i64)>) -> HatchMap {
    let cell_mm = (grid_step(cells.iter().map(|c| c.0)), grid_step(cells.iter().map(|c| c.1)));
    let mut rows: BTreeMap<i64, Vec<(f64, Coverage)>> = BTreeMap::new();
    for (&(x, y, _), class) in cells.iter().zip(classify(&cells)) {
        rows.entry((y * 1e3).round() as i64).or_default().push((x, class));
    }
    for row in rows.values_mut() {
        row.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    HatchMap { hatch_mm, rows, cell_mm, regions: Vec::new() }
}

/// The smallest gap between distinct values (the grid spacing), 1 for a single value.
fn grid_step(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 1e-9).fold(f64::INFINITY, f64::min).min(1.0)
}

fn read_fractions(path: &Path, printer: &str, condition: &str) -> Result<Vec<(i64, RegionFractions)>, StageError> {
    use infill as t;
    let df = read_parquet(path)?;
    let (printers, conditions, regions) =
        (strs(&df, t::printer, path)?, strs(&df, t::condition, path)?, strs(&df, t::region, path)?);
    let (hatch, void, overlap) =
        (f64s(&df, t::hatch_mm, path)?, f64s(&df, t::void_fraction, path)?, f64s(&df, t::overlap_fraction, path)?);
    Ok((0..df.height())
        .filter(|&i| printers[i] == printer && conditions[i] == condition)
        .map(|i| {
            let region =
                RegionFractions { region: regions[i].clone(), void_fraction: void[i], overlap_fraction: overlap[i] };
            (hatch_key(hatch[i]), region)
        })
        .collect())
}

/// Draws one row per hatch spacing (start and end windows) and a colour legend.
pub fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    data: &InfillData,
    window_mm: f64,
) -> Result<(), String> {
    let fail = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let title = format!(
        "Estimated infill coverage near the line ends: {}, {} (paper 000 Fig. 7(b))",
        data.printer, data.condition
    );
    let (title_area, rest) = area.split_vertically(TITLE_PX);
    title_area.margin(8, 0, 0, 0).titled(&title, text(24.0)).map_err(fail)?;
    let (body, legend) = rest.split_vertically(rest.dim_in_pixel().1.saturating_sub(LEGEND_PX));
    let rows = body.split_evenly((data.maps.len().max(1), 1));
    for (row, map) in rows.iter().zip(&data.maps) {
        draw_row(row, map, window_mm).map_err(fail)?;
    }
    draw_legend(&legend).map_err(fail)
}

fn row_caption(map: &HatchMap) -> String {
    let regions: Vec<String> = map
        .regions
        .iter()
        .map(|r| format!("{} {:.1} / {:.1} %", r.region, 100.0 * r.void_fraction, 100.0 * r.overlap_fraction))
        .collect();
    match regions.is_empty() {
        true => format!("hatch {:.2} mm", map.hatch_mm),
        false => format!("hatch {:.2} mm — void / overlap: {}", map.hatch_mm, regions.join(", ")),
    }
}

/// The x windows drawn: at each end of the map at most `window_mm`, and no further
/// than the block of columns the map holds there (stages may write only the ends);
/// the whole map when it is one block no longer than two windows.
fn windows_mm(map: &HatchMap, window_mm: f64) -> Vec<(&'static str, Range<f64>)> {
    let blocks = column_blocks(map);
    let half = map.cell_mm.0 / 2.0;
    let ((lo, first_end), (last_start, hi)) = (blocks[0], blocks[blocks.len() - 1]);
    if blocks.len() == 1 && hi - lo <= 2.0 * window_mm {
        return vec![("whole line", (lo - half)..(hi + half))];
    }
    let left = (lo - half)..(first_end.min(lo + window_mm) + half);
    let right = (last_start.max(hi - window_mm) - half)..(hi + half);
    vec![("left end (region \"start\")", left), ("right end (region \"end\")", right)]
}

/// Runs of x columns present in the map without gaps, as (first x, last x).
fn column_blocks(map: &HatchMap) -> Vec<(f64, f64)> {
    let mut xs: Vec<f64> = map.rows.values().flat_map(|r| r.iter().map(|c| c.0)).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    let mut blocks: Vec<(f64, f64)> = Vec::new();
    for x in xs {
        match blocks.last_mut() {
            Some(block) if x - block.1 <= 1.5 * map.cell_mm.0 => block.1 = x,
            _ => blocks.push((x, x)),
        }
    }
    if blocks.is_empty() {
        blocks.push((0.0, 1.0));
    }
    blocks
}

fn draw_row<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    map: &HatchMap,
    window_mm: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let area = area.titled(&row_caption(map), text(19.0))?;
    let windows = windows_mm(map, window_mm);
    let panels = area.split_evenly((1, windows.len()));
    for (panel, (name, x_mm)) in panels.iter().zip(windows) {
        draw_panel(panel, map, name, x_mm)?;
    }
    Ok(())
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    map: &HatchMap,
    name: &str,
    x_mm: Range<f64>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (dx, dy) = (map.cell_mm.0, map.cell_mm.1);
    let ys = map.rows.keys().map(|k| *k as f64 * 1e-3);
    let (y_lo, y_hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| (lo.min(y), hi.max(y)));
    let mut chart = ChartBuilder::on(area)
        .caption(name, text(16.0))
        .margin(8)
        .margin_right(20)
        .x_label_area_size(42)
        .y_label_area_size(56)
        .build_cartesian_2d(x_mm.clone(), (y_lo - dy / 2.0)..(y_hi + dy / 2.0))?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("position along the lines (mm)")
        .y_desc("across the lines (mm)")
        .label_style(text(14.0))
        .axis_desc_style(text(15.0))
        .x_label_formatter(&|x| format!("{x:.0}"))
        .y_label_formatter(&|y| format!("{y:.1}"))
        .draw()?;
    for (&y_um, row) in &map.rows {
        let y = y_um as f64 * 1e-3;
        let inside: Vec<(f64, Coverage)> = row.iter().copied().filter(|c| x_mm.contains(&c.0)).collect();
        let rect = |(x0, x1, class): (f64, f64, Coverage)| {
            let (x0, x1) = ((x0 - dx / 2.0).max(x_mm.start), (x1 + dx / 2.0).min(x_mm.end));
            Rectangle::new([(x0, y - dy / 2.0), (x1, y + dy / 2.0)], class.colour().filled())
        };
        let drawn = runs(&inside, dx).into_iter().filter(|r| r.2 != Coverage::Outside);
        chart.draw_series(drawn.map(rect))?;
    }
    Ok(())
}

fn draw_legend<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let mut x = 80;
    for class in [Coverage::Void, Coverage::Single, Coverage::Overlap] {
        area.draw(&Rectangle::new([(x, 12), (x + 22, 34)], class.colour().filled()))?;
        area.draw(&Rectangle::new([(x, 12), (x + 22, 34)], BLACK.mix(0.5)))?;
        area.draw(&Text::new(class.label(), (x + 30, 14), text(16.0)))?;
        x += 70 + 8 * class.label().len() as i32;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::{assert_drawn, synthetic_width_mm, write_declared};
    use polars::df;

    const LENGTH_MM: f64 = 80.0;
    const LINES: usize = 6;
    const END_REGION_MM: f64 = 10.0;
    const MAP_WINDOW_MM: f64 = 15.0;
    const DX_MM: f64 = 0.1;
    const DY_MM: f64 = 0.02;

    #[test]
    fn coverage_classes_split_at_zero_one_and_two_lines() {
        assert_eq!(Coverage::of(0), Coverage::Void);
        assert_eq!(Coverage::of(1), Coverage::Single);
        assert_eq!(Coverage::of(2), Coverage::Overlap);
        assert_eq!(Coverage::of(5), Coverage::Overlap);
    }

    #[test]
    fn uncovered_cells_are_voids_only_between_material() {
        // Column x = 0: uncovered, line, gap, line, uncovered; column x = 1: empty.
        let cells =
            [(0.0, 0.0, 0), (0.0, 0.1, 1), (0.0, 0.2, 0), (0.0, 0.3, 2), (0.0, 0.4, 0), (1.0, 0.1, 0), (1.0, 0.2, 0)];
        use Coverage::*;
        assert_eq!(classify(&cells), [Outside, Single, Void, Overlap, Outside, Outside, Outside]);
    }

    #[test]
    fn runs_merge_neighbours_of_one_class_and_break_at_gaps() {
        use Coverage::*;
        let row = [(0.0, Single), (0.1, Single), (0.2, Overlap), (0.3, Overlap), (0.4, Void), (0.8, Void)];
        let merged = runs(&row, 0.1);
        assert_eq!(merged, [(0.0, 0.1, Single), (0.2, 0.3, Overlap), (0.4, 0.4, Void), (0.8, 0.8, Void)]);
    }

    /// Rasters as `fdm.infill` writes them: `LINES` lines at `hatch_mm` with the
    /// synthetic width profile, alternating direction, y from half a width below the
    /// first centre line to half a width above the last, map columns only within
    /// `MAP_WINDOW_MM` of either end; fractions between the outer centre lines.
    fn tables() -> (polars::prelude::DataFrame, polars::prelude::DataFrame) {
        let (mut hatch, mut xs, mut ys, mut coverage) = (vec![], vec![], vec![], vec![]);
        let (mut f_hatch, mut f_region, mut f_void, mut f_overlap) = (vec![], vec![], vec![], vec![]);
        let width_mm = |x: f64| synthetic_width_mm(x, LENGTH_MM, 100.0);
        for h in [0.4, 0.5] {
            let mut counts = [[0_usize; 3]; 3];
            let y_last = (LINES - 1) as f64 * h;
            let ny = ((y_last + 0.7) / DY_MM).round() as usize;
            for i in 0..=(LENGTH_MM / DX_MM).round() as usize {
                let x = i as f64 * DX_MM;
                let half_mm = |l: usize| width_mm([x, LENGTH_MM - x][l % 2]) / 2.0;
                let region = usize::from(x > END_REGION_MM) + usize::from(x > LENGTH_MM - END_REGION_MM);
                let in_map = x <= MAP_WINDOW_MM || x >= LENGTH_MM - MAP_WINDOW_MM;
                for j in 0..=ny {
                    let y = -0.35 + j as f64 * DY_MM;
                    let lines = (0..LINES).filter(|&l| (y - l as f64 * h).abs() <= half_mm(l)).count();
                    if (0.0..=y_last).contains(&y) {
                        counts[region][lines.min(2)] += 1;
                    }
                    if in_map {
                        hatch.push(h);
                        xs.push(x);
                        ys.push(y);
                        coverage.push(lines as i64);
                    }
                }
            }
            for (r, name) in REGIONS.iter().enumerate() {
                let total = counts[r].iter().sum::<usize>() as f64;
                f_hatch.push(h);
                f_region.push(*name);
                f_void.push(counts[r][0] as f64 / total);
                f_overlap.push(counts[r][2] as f64 / total);
            }
        }
        let (n, m) = (hatch.len(), f_hatch.len());
        use {infill as f, infill_map as t};
        let map = df!(t::printer => vec!["taz5"; n], t::condition => vec!["S800F6000"; n], t::hatch_mm => hatch,
            t::x_mm => xs, t::y_mm => ys, t::coverage => coverage)
        .expect("frame");
        let fractions = df!(f::printer => vec!["taz5"; m], f::condition => vec!["S800F6000"; m],
            f::hatch_mm => f_hatch, f::region => f_region, f::void_fraction => f_void, f::overlap_fraction => f_overlap)
        .expect("frame");
        (map, fractions)
    }

    #[test]
    fn draws_both_ends_for_each_hatch() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (map, fractions) = tables();
        write_declared(dir.path(), &infill_map::TABLE, map);
        write_declared(dir.path(), &infill::TABLE, fractions);
        let data = load(dir.path(), "taz5", "S800F6000").expect("loads");
        assert_eq!(data.maps.len(), 2);
        assert_eq!(data.maps[0].regions.iter().map(|r| r.region.as_str()).collect::<Vec<_>>(), REGIONS);
        assert!((data.maps[0].cell_mm.0 - DX_MM).abs() < 1e-9 && (data.maps[0].cell_mm.1 - DY_MM).abs() < 1e-9);
        // A 20 mm window is cut back to the 15 mm the map holds at each end.
        let windows = windows_mm(&data.maps[0], 20.0);
        assert_eq!(windows.len(), 2);
        assert!((windows[0].1.end - (MAP_WINDOW_MM + DX_MM / 2.0)).abs() < 1e-6, "{windows:?}");
        assert!((windows[1].1.start - (LENGTH_MM - MAP_WINDOW_MM - DX_MM / 2.0)).abs() < 1e-6, "{windows:?}");
        let stem = dir.path().join("infill");
        let size = figure_size_px(data.maps.len());
        draw_png_and_svg(&stem, size, |a| draw(a, &data, 15.0), |a| draw(a, &data, 15.0)).expect("draws");
        assert_drawn(&stem);
    }

    #[test]
    fn unknown_condition_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (map, fractions) = tables();
        write_declared(dir.path(), &infill_map::TABLE, map);
        write_declared(dir.path(), &infill::TABLE, fractions);
        let err = load(dir.path(), "taz5", "S1F1").expect_err("no such condition");
        assert!(err.to_string().contains(&infill_map::TABLE.file()), "{err}");
    }
}
