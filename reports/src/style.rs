//! The look shared by all figures: an embedded font (DejaVu Sans, so figures render
//! the same on every machine), sizes and a colour cycle, and a helper that draws one
//! figure to both PNG and SVG.

use std::path::Path;
use std::sync::Once;

use plotters::chart::{ChartContext, MeshStyle, SeriesLabelPosition};
use plotters::coord::ranged1d::{Ranged, ValueFormatter};
use plotters::coord::CoordTranslate;
use plotters::coord::{cartesian::Cartesian2d, Shift};
use plotters::prelude::*;

use pipeline::StageError;

/// The embedded font family name.
pub const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

/// A colour cycle that stays distinguishable in print (Okabe-Ito).
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(120, 120, 120),
    RGBColor(0, 0, 0),
];

/// Registers the embedded font with plotters (once per process).
pub fn ensure_font() {
    REGISTER.call_once(|| {
        for style in [FontStyle::Normal, FontStyle::Bold] {
            if plotters::style::register_font(FONT, style, FONT_BYTES).is_err() {
                panic!("embedded DejaVu Sans is not a valid font");
            }
        }
    });
}

/// A text style of the embedded font.
pub fn text(size: f64) -> TextStyle<'static> {
    ensure_font();
    (FONT, size).into_font().into()
}

/// Draws a figure of `size` pixels with `draw` into `<stem>.png` and `<stem>.svg`.
pub fn draw_png_and_svg(
    stem: &Path,
    size: (u32, u32),
    draw: impl Fn(&DrawingArea<BitMapBackend, Shift>) -> Result<(), String> + Copy,
    draw_svg: impl Fn(&DrawingArea<SVGBackend, Shift>) -> Result<(), String>,
) -> Result<(), StageError> {
    ensure_font();
    let fail = |path: &Path, e: String| StageError::BadInput {
        file: path.to_path_buf(),
        location: None,
        expected: format!("could not draw figure: {e}"),
    };
    let png = stem.with_extension("png");
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(&png, e.to_string()))?;
        draw(&root).map_err(|e| fail(&png, e))?;
        root.present().map_err(|e| fail(&png, e.to_string()))?;
    }
    let svg = stem.with_extension("svg");
    let root = SVGBackend::new(&svg, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(&svg, e.to_string()))?;
    draw_svg(&root).map_err(|e| fail(&svg, e))?;
    root.present().map_err(|e| fail(&svg, e.to_string()))
}

/// The house mesh of every chart: the embedded font for tick labels (14 px) and axis
/// descriptions (15 px) and no minor grid lines. Callers add descriptions, label
/// formatters and anything particular to their chart, then `draw()`.
pub fn house_mesh<'a, 'b, DB, XT, YT, X, Y>(
    chart: &'b mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
) -> MeshStyle<'a, 'b, X, Y, DB>
where
    DB: DrawingBackend,
    X: Ranged<ValueType = XT> + ValueFormatter<XT>,
    Y: Ranged<ValueType = YT> + ValueFormatter<YT>,
{
    let mut mesh = chart.configure_mesh();
    mesh.label_style(text(14.0)).axis_desc_style(text(15.0)).light_line_style(WHITE);
    mesh
}

/// Draws the series legend of `chart` at `position` in the house style: the embedded
/// font at 14 px on a translucent white box with a faint border.
pub fn draw_house_legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .position(position)
        .label_font(text(14.0))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .draw()
}
