//! `fdm.pressure_advance`: the melt's lag τ and the pressure advance to set, from the
//! widths `fdm.measure_photos` measured on photos of a pressure-advance pattern and the
//! G-code that printed it ([`models::fdm::pa_tuning`]). The photos of one print are one
//! fit (their lines are the same lines); each photo is also fitted alone, so the heights
//! can be compared. A photo whose fit fails is a row with its reason; the stage fails
//! only when the print's fit over all photos fails.

use std::collections::BTreeMap;
use std::path::Path;

use datasets::fdm_photos::FdmPhotos;
use models::fdm::pa_tuning::{modelled_widths, tune, MeasuredLine, TauStatus, Tuning, TuningSettings};
use models::fdm::printed_lines::PrintedLine;
use pipeline::columns::{f64s, ints, strs};
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::fdm::{
    photo_lines as photo_lines_t, photo_widths as photo_widths_t, pressure_advance as pa_t,
    pressure_advance_lines as lines_t, pressure_advance_widths as widths_t,
};

use crate::table::{f64_col, frame, i64_col, str_col};

/// The `fdm.pressure_advance` stage kind.
pub struct PressureAdvanceStage;

/// The widths measured on the photos.
const MEASURED: Input = Input::one(
    "measured",
    &[Source::Stage("fdm.measure_photos")],
    "widths measured from photos of the print (`photo_widths`, `photo_lines`)",
)
.reading(&[
    Reads {
        table: &photo_widths_t::TABLE,
        columns: &[
            photo_widths_t::photo_id,
            photo_widths_t::line,
            photo_widths_t::position_mm,
            photo_widths_t::width_mm,
        ],
    },
    Reads { table: &photo_lines_t::TABLE, columns: &[photo_lines_t::photo_id] },
]);

/// The print's G-code (its lines, speeds and advances).
const PHOTOS: Input = Input::one(
    "photos",
    &[Source::Stage("fdm.import_photos"), Source::Dataset("fdm-photos")],
    "the photographed print and its G-code (`fdm-photos`)",
);

/// The `subset` of the fit over every photo.
pub const ALL_PHOTOS: &str = "all";

pipeline::params! {
    /// The parameters of `fdm.pressure_advance`.
    pub struct PressureAdvanceParams {
        /// Smallest τ searched (s).
        pub tau_min_s: f64 [1e-4, 1.0] = 0.002,
        /// Largest τ searched (s); Bowden extruders reach about 1 s.
        pub tau_max_s: f64 [1e-3, 10.0] = 1.0,
    }
}

impl Stage for PressureAdvanceStage {
    type Params = PressureAdvanceParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.pressure_advance",
        version: 1,
        summary: "Widths measured on photos of a pressure-advance pattern + its G-code → the lag τ and the pressure advance to set, with intervals, for all photos and each alone → pressure_advance, pressure_advance_lines, pressure_advance_widths.parquet",
        implements: "paper 000's first-order lag (Sec. IV) with the firmware's pressure advance, fitted over a print's lines",
        inputs: &[MEASURED, PHOTOS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&pa_t::TABLE, &lines_t::TABLE, &widths_t::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &PressureAdvanceParams) -> Result<(), StageError> {
        let data = FdmPhotos::read(&ctx.input(&PHOTOS).dir.clone()).map_err(StageError::domain)?;
        let measured = ctx.input(&MEASURED).dir.clone();
        let photos_path = measured.join(photo_lines_t::TABLE.file());
        let photo_ids = strs(&pipeline::artifact::read_parquet(&photos_path)?, photo_lines_t::photo_id, &photos_path)?;
        let widths = Widths::read(&measured.join(photo_widths_t::TABLE.file()), unique(photo_ids))?;
        let settings = TuningSettings {
            tau_range_s: (p.tau_min_s, p.tau_max_s),
            smoothing_mm: data.printer.nozzle_diameter_mm,
            ..TuningSettings::default()
        };
        let all_lines = widths.lines(None);
        let print = Print { data: &data, settings };
        let mut rows = Rows::default();
        let all = print.fit(&all_lines);
        let all = all.map_err(|reason| StageError::BadInput {
            file: measured.join(photo_widths_t::TABLE.file()),
            location: None,
            expected: format!("widths of at least two lines of the print to fit its lag: {reason}"),
        })?;
        rows.push(&print, ALL_PHOTOS, widths.photo_ids.len(), &Ok(all.clone()));
        rows.push_widths(&print, &widths, &all);
        for photo in &widths.photo_ids {
            let fit = print.fit(&widths.lines(Some(photo)));
            rows.push(&print, photo, 1, &fit);
        }
        ctx.write_table(pa_t::TABLE.name, &mut rows.fits.frame()?)?;
        ctx.write_table(lines_t::TABLE.name, &mut rows.lines.frame()?)?;
        ctx.write_table(widths_t::TABLE.name, &mut rows.widths.frame()?)?;
        Ok(())
    }
}

/// `ids` without repeats, in first-seen order.
fn unique(ids: Vec<String>) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for id in ids {
        if !out.contains(&id) {
            out.push(id);
        }
    }
    out
}

/// The print's lines and how they are fitted.
struct Print<'a> {
    data: &'a FdmPhotos,
    settings: TuningSettings,
}

impl Print<'_> {
    fn fit(&self, measured: &[MeasuredLine]) -> Result<Tuning, String> {
        tune(&self.data.lines, measured, &self.settings).map_err(|e| e.to_string())
    }

    /// The settings the dataset left out, with the value assumed.
    fn assumed(&self) -> String {
        self.data.assumed.iter().map(|a| format!("{} = {}", a.setting, a.value)).collect::<Vec<_>>().join(", ")
    }
}

/// `photo_widths`: per (photo, line) the positions and widths, in photo order.
struct Widths {
    photo_ids: Vec<String>,
    /// (photo, line) → (position, width) in position order.
    series: BTreeMap<(usize, usize), Vec<(f64, f64)>>,
}

impl Widths {
    /// `photo_widths` at `path`, of the photos `photo_ids` (every photo measured, in order).
    fn read(path: &Path, photo_ids: Vec<String>) -> Result<Self, StageError> {
        let df = pipeline::artifact::read_parquet(path)?;
        let ids = strs(&df, photo_widths_t::photo_id, path)?;
        let lines = ints(&df, photo_widths_t::line, path)?;
        let positions = f64s(&df, photo_widths_t::position_mm, path)?;
        let widths = f64s(&df, photo_widths_t::width_mm, path)?;
        let mut series: BTreeMap<(usize, usize), Vec<(f64, f64)>> = BTreeMap::new();
        for i in 0..ids.len() {
            let photo = photo_ids.iter().position(|p| *p == ids[i]).ok_or_else(|| StageError::BadInput {
                file: path.to_path_buf(),
                location: Some(format!("row {i}, column {}", photo_widths_t::photo_id)),
                expected: format!("a photo of photo_lines, got `{}`", ids[i]),
            })?;
            let line = usize::try_from(lines[i]).map_err(|_| StageError::BadInput {
                file: path.to_path_buf(),
                location: Some(format!("row {i}, column {}", photo_widths_t::line)),
                expected: format!("a line index ≥ 0, got {}", lines[i]),
            })?;
            if positions[i].is_finite() && widths[i].is_finite() {
                series.entry((photo, line)).or_default().push((positions[i], widths[i]));
            }
        }
        for s in series.values_mut() {
            s.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
        Ok(Self { photo_ids, series })
    }

    /// The measured lines of one photo, or of every photo (one series per photo).
    fn lines(&self, photo: Option<&String>) -> Vec<MeasuredLine> {
        let keep = photo.and_then(|id| self.photo_ids.iter().position(|p| p == id));
        let mut by_line: BTreeMap<usize, Vec<Vec<(f64, f64)>>> = BTreeMap::new();
        for ((p, line), s) in &self.series {
            if keep.is_none_or(|k| k == *p) {
                by_line.entry(*line).or_default().push(s.clone());
            }
        }
        by_line.into_iter().map(|(line, series)| MeasuredLine { line, series }).collect()
    }
}

#[derive(Default)]
struct Rows {
    fits: FitRows,
    lines: LineRows,
    widths: WidthRows,
}

impl Rows {
    fn push(&mut self, print: &Print, subset: &str, photos: usize, fit: &Result<Tuning, String>) {
        self.fits.push(print, subset, photos, fit);
        if let Ok(t) = fit {
            for f in &t.lines {
                self.lines.subset.push(subset.into());
                self.lines.line.push(f.line as i64);
                self.lines.ints[0].push(f.positions as i64);
                for (k, v) in
                    [f.advance_s, f.level, f.rmse_mm, f.tau_without_s, f.heldout_rmse_mm, f.noise_mm, f.spread]
                        .into_iter()
                        .enumerate()
                {
                    self.lines.values[k].push(v);
                }
            }
        }
    }

    /// Every measured position against the model under the print's τ and each line's level.
    fn push_widths(&mut self, print: &Print, widths: &Widths, fit: &Tuning) {
        for ((photo, line), series) in &widths.series {
            let printed: &PrintedLine = &print.data.lines[*line];
            let positions: Vec<f64> = series.iter().map(|s| s.0).collect();
            let modelled = modelled_widths(printed, &positions, fit.tau_s, &print.settings);
            let level = fit.lines.iter().find(|f| f.line == *line).map_or(f64::NAN, |f| f.level);
            let w = &mut self.widths;
            for (&(x, width), m) in series.iter().zip(modelled) {
                w.photo_id.push(widths.photo_ids[*photo].clone());
                w.line.push(*line as i64);
                let values = [printed.pressure_advance.advance_s, x, width, level * m, printed.speed_at_mm(x)];
                for (k, v) in values.into_iter().enumerate() {
                    w.values[k].push(v);
                }
            }
        }
    }
}

#[derive(Default)]
struct FitRows {
    text: [Vec<String>; 5],
    counts: [Vec<i64>; 2],
    values: [Vec<f64>; 11],
}

impl FitRows {
    fn push(&mut self, print: &Print, subset: &str, photos: usize, fit: &Result<Tuning, String>) {
        let (status, reason, lines, values) = match fit {
            Ok(t) => {
                let status = match t.status {
                    TauStatus::Fitted => "fitted",
                    TauStatus::AtBound => "at_bound",
                };
                let values = [
                    t.tau_s,
                    t.tau_ci_s.0,
                    t.tau_ci_s.1,
                    t.recommended_pa_s,
                    t.pa_ci_s.0,
                    t.pa_ci_s.1,
                    t.heldout_rmse_mm,
                    t.rmse_mm,
                    t.noise_mm,
                    t.flattest_line_advance_s,
                ];
                (status, String::new(), t.lines.len(), values)
            }
            Err(reason) => ("failed", reason.clone(), 0, [f64::NAN; 10]),
        };
        let text = [print.data.manifest.printer.clone(), subset.into(), status.into(), reason, print.assumed()];
        for (k, v) in text.into_iter().enumerate() {
            self.text[k].push(v);
        }
        self.counts[0].push(photos as i64);
        self.counts[1].push(lines as i64);
        for (k, v) in values.into_iter().chain([print.data.start.accel_mm_s2]).enumerate() {
            self.values[k].push(v);
        }
    }

    fn frame(&self) -> Result<polars::prelude::DataFrame, StageError> {
        let [print, subset, status, reason, assumed] = self.text.clone();
        let [photos, lines] = self.counts.clone();
        let v = |k: usize| self.values[k].clone();
        frame(vec![
            str_col(pa_t::print, print),
            str_col(pa_t::subset, subset),
            i64_col(pa_t::photos, photos),
            i64_col(pa_t::lines, lines),
            str_col(pa_t::status, status),
            str_col(pa_t::reason, reason),
            f64_col(pa_t::tau_s, v(0)),
            f64_col(pa_t::tau_ci_lo_s, v(1)),
            f64_col(pa_t::tau_ci_hi_s, v(2)),
            f64_col(pa_t::recommended_pa_s, v(3)),
            f64_col(pa_t::pa_ci_lo_s, v(4)),
            f64_col(pa_t::pa_ci_hi_s, v(5)),
            f64_col(pa_t::heldout_rmse_mm, v(6)),
            f64_col(pa_t::rmse_mm, v(7)),
            f64_col(pa_t::noise_mm, v(8)),
            f64_col(pa_t::flattest_line_pa_s, v(9)),
            f64_col(pa_t::accel_mm_s2, v(10)),
            str_col(pa_t::assumed, assumed),
        ])
    }
}

#[derive(Default)]
struct LineRows {
    subset: Vec<String>,
    line: Vec<i64>,
    ints: [Vec<i64>; 1],
    values: [Vec<f64>; 7],
}

impl LineRows {
    fn frame(&self) -> Result<polars::prelude::DataFrame, StageError> {
        let v = |k: usize| self.values[k].clone();
        frame(vec![
            str_col(lines_t::subset, self.subset.clone()),
            i64_col(lines_t::line, self.line.clone()),
            f64_col(lines_t::pressure_advance_s, v(0)),
            f64_col(lines_t::level, v(1)),
            f64_col(lines_t::rmse_mm, v(2)),
            f64_col(lines_t::tau_without_s, v(3)),
            f64_col(lines_t::heldout_rmse_mm, v(4)),
            i64_col(lines_t::positions, self.ints[0].clone()),
            f64_col(lines_t::noise_mm, v(5)),
            f64_col(lines_t::width_spread, v(6)),
        ])
    }
}

#[derive(Default)]
struct WidthRows {
    photo_id: Vec<String>,
    line: Vec<i64>,
    values: [Vec<f64>; 5],
}

impl WidthRows {
    fn frame(&self) -> Result<polars::prelude::DataFrame, StageError> {
        let v = |k: usize| self.values[k].clone();
        frame(vec![
            str_col(widths_t::photo_id, self.photo_id.clone()),
            i64_col(widths_t::line, self.line.clone()),
            f64_col(widths_t::pressure_advance_s, v(0)),
            f64_col(widths_t::position_mm, v(1)),
            f64_col(widths_t::width_mm, v(2)),
            f64_col(widths_t::predicted_mm, v(3)),
            f64_col(widths_t::speed_mm_s, v(4)),
        ])
    }
}
