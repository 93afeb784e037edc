//! `figure.fdm_segment_accuracy`: width RMSE of each photo against the true widths,
//! per camera scale and segmentation method (the sub-pixel edge fit and the plain
//! threshold count), with the median per method joined across scales. Reads
//! `segment_accuracy.parquet` of an `fdm.segment_accuracy` stage.

use std::collections::BTreeMap;

use plotters::coord::Shift;
use plotters::prelude::*;

use pipeline::params::NoParams;
use pipeline::schema::Reads;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::segment_accuracy;

use crate::read::{f64s, read_parquet, strs};
use crate::style::{draw_house_legend, draw_png_and_svg, house_mesh, text, PALETTE};

use crate::figures::common::distinct;

/// The `figure.fdm_segment_accuracy` stage kind.
pub struct SegmentAccuracyFigure;

/// The accuracy study drawn.
const ACCURACY: Input = Input::one(
    "accuracy",
    &[Source::Stage("fdm.segment_accuracy")],
    "the width RMSE of every photo per scale and method (`segment_accuracy.parquet`)",
)
.reading(&[Reads {
    table: &segment_accuracy::TABLE,
    columns: &[segment_accuracy::method, segment_accuracy::px_per_mm, segment_accuracy::rmse_mm],
}]);

/// Method → (px/mm, RMSE mm) per measured photo.
type Points = BTreeMap<String, Vec<(f64, f64)>>;

impl Stage for SegmentAccuracyFigure {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "figure.fdm_segment_accuracy",
        version: 1,
        summary: "Width RMSE per photo against the truth, per camera scale and segmentation method → segment_accuracy.png/.svg",
        implements: "paper 000 Sec. III (widths from camera images), checked on virtual photos",
        inputs: &[ACCURACY],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let path = ctx.input(&ACCURACY).dir.join(segment_accuracy::TABLE.file());
        let df = read_parquet(&path)?;
        let (method, scale, rmse) = (
            strs(&df, segment_accuracy::method, &path)?,
            f64s(&df, segment_accuracy::px_per_mm, &path)?,
            f64s(&df, segment_accuracy::rmse_mm, &path)?,
        );
        let mut points = Points::new();
        for i in (0..df.height()).filter(|&i| rmse[i].is_finite() && rmse[i] > 0.0) {
            points.entry(method[i].clone()).or_default().push((scale[i], rmse[i]));
        }
        if points.is_empty() {
            return Err(StageError::BadInput {
                file: path,
                location: Some(segment_accuracy::rmse_mm.into()),
                expected: "expected at least one measured photo".into(),
            });
        }
        let stem = ctx.output_path("segment_accuracy")?;
        draw_png_and_svg(&stem, (1000, 700), |a| draw(a, &points), |a| draw(a, &points))
    }
}

fn draw<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, points: &Points) -> Result<(), String> {
    draw_chart(area, points).map_err(|e| e.to_string())
}

fn draw_chart<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    points: &Points,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let all = || points.values().flatten();
    let scales = distinct(all().map(|p| p.0));
    let (lo, hi) = all().fold((f64::INFINITY, 0.0_f64), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    // One column per scale, evenly spaced (the scales double: 10, 20, 40 px/mm).
    let column = |px: f64| scales.iter().position(|s| *s == px).expect("collected") as f64;
    let x_range = -0.5..scales.len() as f64 - 0.5;
    let mut chart = ChartBuilder::on(area)
        .caption("Width from photos: RMSE against the true width, per photo", text(24.0))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(x_range, (lo * 0.7).log10()..(hi * 1.4).log10())?;
    house_mesh(&mut chart)
        .x_desc("camera scale (px/mm)")
        .y_desc("width RMSE (mm)")
        .x_labels(scales.len() + 1)
        .x_label_formatter(&|x| {
            let k = x.round();
            match scales.get(k as usize) {
                Some(px) if (x - k).abs() < 1e-6 && k >= 0.0 => format!("{px}"),
                _ => String::new(),
            }
        })
        .y_label_formatter(&|y| format!("{:.3}", 10f64.powf(*y)))
        .draw()?;
    for (k, (method, pts)) in points.iter().enumerate() {
        let colour = PALETTE[k % PALETTE.len()];
        let offset = (k as f64 - 0.5) * 0.12;
        let label = method.replace('_', " ");
        chart
            .draw_series(
                pts.iter().map(|&(s, r)| Circle::new((column(s) + offset, r.log10()), 4, colour.mix(0.6).filled())),
            )?
            .label(label)
            .legend(move |(x, y)| Circle::new((x + 9, y), 4, colour.filled()));
        let medians: Vec<(f64, f64)> = scales
            .iter()
            .filter_map(|&s| {
                let mut v: Vec<f64> = pts.iter().filter(|p| p.0 == s).map(|p| p.1).collect();
                v.sort_by(f64::total_cmp);
                (!v.is_empty()).then(|| (column(s) + offset, v[v.len() / 2].log10()))
            })
            .collect();
        chart.draw_series(LineSeries::new(medians, colour.stroke_width(2)))?;
    }
    draw_house_legend(&mut chart, SeriesLabelPosition::UpperRight)
}
