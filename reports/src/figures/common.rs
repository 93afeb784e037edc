//! What the figures share: the `title` parameter, the viridis scale and its colour bar,
//! and the grid arithmetic of heat maps.

use plotters::prelude::{DrawingAreaErrorKind, DrawingBackend, RGBColor};

/// A figure's `title` parameter, or `default()` when the spec leaves it empty.
pub(crate) fn title_or(title: &str, default: impl FnOnce() -> String) -> String {
    match title {
        "" => default(),
        title => title.to_string(),
    }
}

/// The distinct values, ascending (the rows and columns of a panel grid).
pub(crate) fn distinct(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// A vertical viridis colour bar for `lo..hi` in `bands` equal bands (band k has
/// viridis(k / (bands − 1)), as the heat maps colour their cells), labelled `desc`
/// with `decimals` decimals. The one colour bar of every heat-map figure.
pub(crate) fn draw_viridis_bar<DB: DrawingBackend>(
    area: &plotters::drawing::DrawingArea<DB, plotters::coord::Shift>,
    (lo, hi): (f64, f64),
    desc: &str,
    decimals: usize,
    bands: usize,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    use plotters::prelude::{ChartBuilder, Rectangle};
    let mut chart = ChartBuilder::on(area)
        .margin_top(12)
        .margin_bottom(52)
        .margin_left(4)
        .margin_right(10)
        .right_y_label_area_size(72)
        .build_cartesian_2d(0.0..1.0, lo..hi)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_desc(desc)
        .label_style(crate::style::text(14.0))
        .axis_desc_style(crate::style::text(15.0))
        .y_label_formatter(&|y| format!("{y:.decimals$}"))
        .draw()?;
    let step = (hi - lo) / bands as f64;
    let band = |k: usize| {
        let y = lo + k as f64 * step;
        let colour = viridis(k as f64 / (bands.max(2) - 1) as f64);
        Rectangle::new([(0.0, y), (1.0, y + step)], plotters::style::Color::filled(&colour))
    };
    chart.draw_series((0..bands).map(band))?;
    Ok(())
}

/// Matplotlib's viridis at nine equally spaced stops (perceptually uniform, readable in
/// grey scale and by colour-blind readers); values between stops are interpolated.
const VIRIDIS: [(u8, u8, u8); 9] = [
    (68, 1, 84),
    (71, 44, 122),
    (59, 81, 139),
    (44, 113, 142),
    (33, 145, 140),
    (39, 173, 129),
    (92, 200, 99),
    (170, 220, 50),
    (253, 231, 37),
];

/// Viridis at `t` in [0, 1] (clamped; NaN maps to the low end).
pub fn viridis(t: f64) -> RGBColor {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let scaled = t * (VIRIDIS.len() - 1) as f64;
    let i = (scaled.floor() as usize).min(VIRIDIS.len() - 2);
    let frac = scaled - i as f64;
    let mix = |a: u8, b: u8| (a as f64 + frac * (b as f64 - a as f64)).round() as u8;
    let (lo, hi) = (VIRIDIS[i], VIRIDIS[i + 1]);
    RGBColor(mix(lo.0, hi.0), mix(lo.1, hi.1), mix(lo.2, hi.2))
}

/// The grid spacing of `values`: the smallest gap between distinct values (1 when
/// there is a single value, so a one-point grid still draws a cell).
pub fn grid_step(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 1e-12).fold(f64::INFINITY, f64::min).min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viridis_ends_are_the_table_ends_and_out_of_range_clamps() {
        assert_eq!(viridis(0.0), RGBColor(68, 1, 84));
        assert_eq!(viridis(1.0), RGBColor(253, 231, 37));
        assert_eq!(viridis(-3.0), viridis(0.0));
        assert_eq!(viridis(7.0), viridis(1.0));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
        // Halfway between stops 4 (0.5) and 5 (0.625): the rounded mean of the two.
        assert_eq!(viridis(0.5625), RGBColor(36, 159, 135));
    }

    #[test]
    fn viridis_gets_lighter_along_the_scale() {
        let luma = |c: RGBColor| 0.299 * c.0 as f64 + 0.587 * c.1 as f64 + 0.114 * c.2 as f64;
        let lumas: Vec<f64> = (0..=20).map(|k| luma(viridis(k as f64 / 20.0))).collect();
        assert!(lumas.windows(2).all(|w| w[1] > w[0]), "{lumas:?}");
    }

    #[test]
    fn grid_step_is_the_smallest_gap() {
        assert!((grid_step([1.1, 0.9, 1.0, 1.0].into_iter()) - 0.1).abs() < 1e-12);
        assert_eq!(grid_step([1.0].into_iter()), 1.0);
    }
}
