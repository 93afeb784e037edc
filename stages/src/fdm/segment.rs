//! Widths from photos (paper 000 Sec. III measured its widths from camera images):
//!
//! - `fdm.segment_widths`: an `fdm-lines` dataset → an `fdm-widths` dataset (the output
//!   folder), so every paper-000 stage and the discrepancy engine run on photos
//!   unchanged; one row per photo in `segment_diagnostics.parquet` says what was
//!   measured or why the photo was skipped (the other photos go on).
//! - `fdm.segment_accuracy` (evaluation: reads `truth/`): per photo and method, the
//!   width RMSE and bias against the true widths → `segment_accuracy.parquet`.
//!
//! The segmentation is [`vision::lines`]: the sub-pixel blurred-edge fit along a
//! refined axis (`edge_fit`), or the plain Otsu threshold and pixel count a lab writes
//! first (`threshold`).

use std::collections::BTreeMap;
use std::path::Path;

use datasets::fdm_lines::generate::{read_truth, LineTruth};
use datasets::fdm_lines::{FdmLinesDataset, PhotoLine};
use datasets::fdm_widths::{FdmWidthsDataset, WidthLine};
use datasets::limits::LINE_IMAGE_PIXELS;
use datasets::manifest::{DatasetManifest, Provenance};
use pipeline::schema::Table;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use rayon::prelude::*;
use tables::fdm::{photo_sets, segment_accuracy, segment_diagnostics};
use vision::lines::{segment_edge_fit, segment_threshold_columns, GrayImage, LineGeometry, Segmentation};

use crate::table::{f64_col, frame, i64_col, str_col};

pipeline::choice! {
    /// The segmentation methods.
    pub enum Method {
        /// The sub-pixel blurred-edge fit along a refined axis.
        EdgeFit = "edge_fit",
        /// The Otsu threshold and pixel count per column (the plain baseline).
        Threshold = "threshold",
    }
}

pipeline::params! {
    /// Where along a line widths are read, as both photo stages declare it.
    pub struct Step {
        /// Spacing of the widths along the line (mm); the real data's is 0.048 mm.
        pub step_mm: f64 [0.01, 5.0] = 0.05,
    }
}

/// One photo segmented, or why it could not be.
struct Measured<'a> {
    line: &'a PhotoLine,
    result: Result<Segmentation, String>,
}

/// Segments every photo of `data` with `method` (in parallel over photos). A photo that
/// cannot be measured, even one that makes the segmentation panic (a bug, caught here so
/// that the other photos go on), is its line's `Err` with the reason.
fn segment_all<'a>(data: &'a FdmLinesDataset, method: Method, step_mm: f64) -> Vec<Measured<'a>> {
    data.lines
        .par_iter()
        .map(|line| {
            let result = pipeline::panic::catch(|| segment_one(line, method, step_mm)).unwrap_or_else(|panic| {
                Err(format!(
                    "{}: internal error, a bug in amrepro (please report it with this photo): {panic}",
                    line.image.display()
                ))
            });
            Measured { line, result }
        })
        .collect()
}

fn segment_one(line: &PhotoLine, method: Method, step_mm: f64) -> Result<Segmentation, String> {
    let name = line.image.display();
    line.image_size_px.as_ref().map_err(|e| e.clone())?;
    let bytes = std::fs::read(&line.image).map_err(|e| format!("{name}: {e}"))?;
    let image = GrayImage::from_png_bytes(&bytes, *LINE_IMAGE_PIXELS.end()).map_err(|e| format!("{name}: {e}"))?;
    let p = line.placement;
    let geometry = LineGeometry {
        start_px: [p.start_x_px, p.start_y_px],
        direction_rad: p.direction_deg.to_radians(),
        length_mm: line.motion.length_mm,
        px_per_mm: p.px_per_mm,
        nominal_width_mm: line.nominal_width_mm,
    };
    let segmented = match method {
        Method::Threshold => segment_threshold_columns(&image, &geometry, step_mm),
        Method::EdgeFit => segment_edge_fit(&image, &geometry, step_mm),
    };
    segmented.map_err(|e| format!("{name}: {e}"))
}

/// Fewest widths inside the line for it to be written.
const MIN_WIDTHS: usize = 10;

/// The widths of a segmentation inside the line `[0, length]`, as a width line.
fn width_line(line: &PhotoLine, s: &Segmentation) -> Option<WidthLine> {
    let length = line.motion.length_mm;
    let (positions_mm, widths_mm): (Vec<f64>, Vec<f64>) = s
        .positions_mm
        .iter()
        .zip(&s.widths_mm)
        .filter(|(x, w)| (0.0..=length).contains(*x) && **w > 0.0)
        .map(|(x, w)| (*x, *w))
        .unzip();
    (positions_mm.len() >= MIN_WIDTHS).then(|| WidthLine {
        line_id: line.line_id.clone(),
        condition: line.condition.clone(),
        motion: line.motion,
        positions_mm,
        widths_mm,
    })
}

/// "low_contrast 3, near_line_end 8": the skipped positions by reason.
fn skip_summary(s: &Segmentation) -> String {
    let mut counts: BTreeMap<String, usize> = BTreeMap::new();
    for skipped in &s.skipped {
        *counts.entry(skipped.reason.to_string()).or_default() += 1;
    }
    counts.iter().map(|(r, n)| format!("{r} {n}")).collect::<Vec<_>>().join(", ")
}

fn read_lines(dir: &Path) -> Result<FdmLinesDataset, StageError> {
    FdmLinesDataset::read(dir).map_err(StageError::domain)
}

/// The `fdm.segment_widths` stage kind.
pub struct SegmentWidthsStage;

pipeline::params! {
    /// The parameters of `fdm.segment_widths`.
    pub struct SegmentParams {
        /// edge_fit: blurred-edge model fitted across the line at each position (sub-pixel); threshold: Otsu threshold and pixel count per column (the plain baseline).
        pub method: Method = Method::EdgeFit,
    }
    groups { pub step: Step }
}

/// The photos segmented.
const PHOTOS: Input = Input::one("photos", &[Source::Dataset("fdm-lines")], "photos of printed lines (`fdm-lines`)");

impl Stage for SegmentWidthsStage {
    type Params = SegmentParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.segment_widths",
        // 2: the threshold window is cut at the photo's edge; positions are the exact decimals k·step
        version: 2,
        summary: "Photos of lines (fdm-lines) → widths along each line (an fdm-widths dataset, the output folder) + segment_diagnostics.parquet",
        implements: "paper 000 Sec. III (widths measured from camera images); DESIGN §4",
        inputs: &[PHOTOS],
        output: Output::Dataset("fdm-widths"),
    };
    const WRITES: &'static [&'static Table] = &[&segment_diagnostics::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &SegmentParams) -> Result<(), StageError> {
        let dir = ctx.input(&PHOTOS).dir.clone();
        let data = read_lines(&dir)?;
        let method = p.method.name();
        let (lines, diagnostics) = measure_lines(&data, p.method, p.step.step_mm)
            .map_err(|expected| StageError::BadInput { file: dir.join("lines.csv"), location: None, expected })?;
        let widths = FdmWidthsDataset { manifest: segmented_manifest(&data.manifest, method), lines };
        widths.write(ctx.output_dir()).map_err(StageError::domain)?;
        ctx.write_table(segment_diagnostics::TABLE.name, &mut diagnostics.frame(&data.manifest.printer, method)?)?;
        Ok(())
    }
}

/// The lines of `data` that could be measured, and a diagnostic row per line (measured,
/// or skipped and why); an error listing every line's reason when none could.
fn measure_lines(
    data: &FdmLinesDataset,
    method: Method,
    step_mm: f64,
) -> Result<(Vec<WidthLine>, Diagnostics), String> {
    let measured = segment_all(data, method, step_mm);
    let mut diagnostics = Diagnostics::default();
    let mut lines = Vec::new();
    for m in &measured {
        let line = m.result.as_ref().ok().and_then(|s| width_line(m.line, s));
        diagnostics.push(m, line.is_some());
        lines.extend(line);
    }
    if lines.is_empty() {
        return Err(format!(
            "expected at least one photo with a measurable line ({}); none of the {} had one: {}",
            method.name(),
            measured.len(),
            diagnostics.problems()
        ));
    }
    Ok((lines, diagnostics))
}

fn segmented_manifest(photos: &DatasetManifest, method: &str) -> DatasetManifest {
    let mut units = photos.units.clone();
    units.retain(|q, _| ["accel", "feed", "jerk", "length", "position", "width"].contains(&q.as_str()));
    DatasetManifest {
        kind: datasets::fdm_widths::KIND.into(),
        format_version: datasets::fdm_widths::FORMAT_VERSION,
        printer: photos.printer.clone(),
        description: format!(
            "Widths measured from the photos of an fdm-lines dataset ({method}). {}",
            photos.description
        ),
        units,
        provenance: Provenance::Measured {
            source: format!("photos of the {} lines, segmented by fdm.segment_widths ({method})", photos.printer),
            license: "as the photos".into(),
            imported_by: format!("amrepro {}", env!("CARGO_PKG_VERSION")),
        },
    }
}

#[derive(Default)]
struct Diagnostics {
    line_id: Vec<String>,
    image: Vec<String>,
    status: Vec<String>,
    problem: Vec<String>,
    used: Vec<i64>,
    skipped: Vec<i64>,
}

impl Diagnostics {
    fn push(&mut self, m: &Measured, written: bool) {
        self.line_id.push(m.line.line_id.clone());
        self.image.push(m.line.image.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default());
        let (status, problem, used, skipped) = match &m.result {
            Ok(s) if written => ("measured", skip_summary(s), s.widths_mm.len(), s.skipped.len()),
            Ok(s) => {
                let why = format!(
                    "fewer than {MIN_WIDTHS} widths inside the line's {} mm ({} measured; skipped: {})",
                    m.line.motion.length_mm,
                    s.widths_mm.len(),
                    skip_summary(s)
                );
                ("skipped", why, s.widths_mm.len(), s.skipped.len())
            }
            Err(e) => ("skipped", e.clone(), 0, 0),
        };
        self.status.push(status.into());
        self.problem.push(problem);
        self.used.push(used as i64);
        self.skipped.push(skipped as i64);
    }

    /// Every skipped line with its reason: "line `a`: …; line `b`: …".
    fn problems(&self) -> String {
        if self.line_id.is_empty() {
            return "lines.csv lists no line".into();
        }
        let skipped = self.line_id.iter().zip(&self.status).zip(&self.problem).filter(|((_, s), _)| *s == "skipped");
        skipped.map(|((id, _), problem)| format!("line `{id}`: {problem}")).collect::<Vec<_>>().join("; ")
    }

    fn frame(&self, printer: &str, method: &str) -> Result<polars::prelude::DataFrame, StageError> {
        let n = self.line_id.len();
        frame(vec![
            str_col(segment_diagnostics::printer, vec![printer.to_string(); n]),
            str_col(segment_diagnostics::method, vec![method.to_string(); n]),
            str_col(segment_diagnostics::line_id, self.line_id.clone()),
            str_col(segment_diagnostics::image, self.image.clone()),
            str_col(segment_diagnostics::status, self.status.clone()),
            str_col(segment_diagnostics::problem, self.problem.clone()),
            i64_col(segment_diagnostics::columns_used, self.used.clone()),
            i64_col(segment_diagnostics::columns_skipped, self.skipped.clone()),
        ])
    }
}

/// The `fdm.segment_accuracy` stage kind.
pub struct SegmentAccuracyStage;

/// The photo sets scored, each with its `truth/`.
const PHOTO_SETS: Input =
    Input::many("photos", 1, &[Source::Dataset("fdm-lines")], "virtual photos with their truth (`fdm-lines`)");

impl Stage for SegmentAccuracyStage {
    type Params = Step;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.segment_accuracy",
        version: 1,
        summary: "Evaluation (reads truth/): per photo and method (edge_fit, threshold), width RMSE and bias against the true widths → segment_accuracy.parquet, photo_sets.parquet (each set's effects)",
        implements: "paper 000 Sec. III (widths from camera images), checked on virtual photos",
        inputs: &[PHOTO_SETS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&segment_accuracy::TABLE, &photo_sets::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &Step) -> Result<(), StageError> {
        let step_mm = p.step_mm;
        let mut rows = AccuracyRows::default();
        let mut sets = PhotoSets::default();
        let inputs = ctx.inputs_of(&PHOTO_SETS);
        let bar = ctx.progress((inputs.len() * Method::ALL.len()) as u64);
        for input in inputs {
            let data = read_lines(&input.dir)?;
            let truth = read_truth(&input.dir).map_err(StageError::domain)?;
            sets.push(&input.name, &data);
            for &method in Method::ALL {
                for m in segment_all(&data, method, step_mm) {
                    rows.push(&data.manifest.printer, method.name(), &m, truth.get(&m.line.line_id));
                }
                bar.inc(1);
            }
        }
        bar.finish_and_clear();
        ctx.write_table(segment_accuracy::TABLE.name, &mut rows.frame()?)?;
        ctx.write_table(photo_sets::TABLE.name, &mut sets.frame()?)?;
        Ok(())
    }
}

/// What each photo set is: its stage, printer, scale, lines and the effects its
/// `dataset.toml` records (`none`).
#[derive(Default)]
struct PhotoSets {
    dataset: Vec<String>,
    printer: Vec<String>,
    px_per_mm: Vec<f64>,
    lines: Vec<i64>,
    effects: Vec<String>,
}

impl PhotoSets {
    fn push(&mut self, name: &str, data: &FdmLinesDataset) {
        self.dataset.push(name.into());
        self.printer.push(data.manifest.printer.clone());
        self.px_per_mm.push(data.lines.first().map_or(f64::NAN, |l| l.placement.px_per_mm));
        self.lines.push(data.lines.len() as i64);
        let effects = match &data.manifest.provenance {
            Provenance::Virtual { effects, .. } if !effects.is_empty() => {
                effects.iter().map(|(n, v)| format!("{n}={v}")).collect::<Vec<_>>().join(", ")
            }
            Provenance::Virtual { .. } => "none".into(),
            Provenance::Measured { .. } => "measured".into(),
        };
        self.effects.push(effects);
    }

    fn frame(&self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            str_col(photo_sets::dataset, self.dataset.clone()),
            str_col(photo_sets::printer, self.printer.clone()),
            f64_col(photo_sets::px_per_mm, self.px_per_mm.clone()),
            i64_col(photo_sets::lines, self.lines.clone()),
            str_col(photo_sets::effects, self.effects.clone()),
        ])
    }
}

#[derive(Default)]
struct AccuracyRows {
    printer: Vec<String>,
    line_id: Vec<String>,
    px_per_mm: Vec<f64>,
    method: Vec<String>,
    rmse_mm: Vec<f64>,
    bias_mm: Vec<f64>,
    used: Vec<i64>,
    skipped: Vec<i64>,
    problem: Vec<String>,
}

impl AccuracyRows {
    fn push(&mut self, printer: &str, method: &str, m: &Measured, truth: Option<&LineTruth>) {
        let (rmse, bias, used, skipped, problem) = match (&m.result, truth) {
            (Ok(s), Some(t)) => {
                let errors: Vec<f64> =
                    s.positions_mm.iter().zip(&s.widths_mm).map(|(x, w)| w - true_width_at(t, *x)).collect();
                let n = errors.len().max(1) as f64;
                let bias = errors.iter().sum::<f64>() / n;
                let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
                (rmse, bias, s.widths_mm.len(), s.skipped.len(), String::new())
            }
            (Ok(_), None) => (f64::NAN, f64::NAN, 0, 0, "no truth for this line".into()),
            (Err(e), _) => (f64::NAN, f64::NAN, 0, 0, e.clone()),
        };
        self.printer.push(printer.into());
        self.line_id.push(m.line.line_id.clone());
        self.px_per_mm.push(m.line.placement.px_per_mm);
        self.method.push(method.into());
        self.rmse_mm.push(rmse);
        self.bias_mm.push(bias);
        self.used.push(used as i64);
        self.skipped.push(skipped as i64);
        self.problem.push(problem);
    }

    fn frame(&self) -> Result<polars::prelude::DataFrame, StageError> {
        frame(vec![
            str_col(segment_accuracy::printer, self.printer.clone()),
            str_col(segment_accuracy::line_id, self.line_id.clone()),
            f64_col(segment_accuracy::px_per_mm, self.px_per_mm.clone()),
            str_col(segment_accuracy::method, self.method.clone()),
            f64_col(segment_accuracy::rmse_mm, self.rmse_mm.clone()),
            f64_col(segment_accuracy::bias_mm, self.bias_mm.clone()),
            i64_col(segment_accuracy::columns_used, self.used.clone()),
            i64_col(segment_accuracy::columns_skipped, self.skipped.clone()),
            str_col(segment_accuracy::problem, self.problem.clone()),
        ])
    }
}

/// The true width at `x_mm`, linear between the truth samples.
fn true_width_at(t: &LineTruth, x_mm: f64) -> f64 {
    let xs = &t.positions_mm;
    let i = xs.partition_point(|&p| p <= x_mm).clamp(1, xs.len() - 1);
    let f = ((x_mm - xs[i - 1]) / (xs[i] - xs[i - 1])).clamp(0.0, 1.0);
    t.widths_mm[i - 1] + f * (t.widths_mm[i] - t.widths_mm[i - 1])
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use datasets::fdm_lines::camera::{photograph, CameraSettings};
    use datasets::fdm_lines::generate::{generate_into, GenerateConfig};
    use models::fdm::printer::{Effects, PrintedLine, TRUTH_STEP_MM};
    use rand::SeedableRng;

    use super::*;

    /// The widths segmented from a one-line photo set of the virtual Taz 6 at the
    /// fastest condition with `effects`, seed 7.
    fn segmented(effects: &str) -> (Vec<f64>, Vec<f64>) {
        let tmp = tempfile::tempdir().unwrap();
        let config = GenerateConfig {
            conditions: vec![(800.0, 150.0)],
            effects: Effects {
                gear_period_mm: 12.0,
                ..Effects::from_pairs(crate::effects::pairs(effects).unwrap()).unwrap()
            },
            ..GenerateConfig::new("taz6", 7)
        };
        generate_into(&config, tmp.path()).unwrap();
        let data = FdmLinesDataset::read(tmp.path()).unwrap();
        let s = segment_one(&data.lines[0], Method::EdgeFit, 0.05).unwrap();
        (s.positions_mm, s.widths_mm)
    }

    /// Least-squares `a + b·x` through the points.
    fn line_fit(x: &[f64], y: &[f64]) -> (f64, f64) {
        let n = x.len() as f64;
        let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
        let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
        let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
        (my - sxy / sxx * mx, sxy / sxx)
    }

    /// The amplitude of the `period_mm` sinusoid in `y(x)` by least squares.
    fn amplitude_at(x: &[f64], y: &[f64], period_mm: f64) -> f64 {
        let (mut ss, mut cc, mut sc, mut sy, mut cy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (&x, &y) in x.iter().zip(y) {
            let (s, c) = (2.0 * PI * x / period_mm).sin_cos();
            (ss, cc, sc, sy, cy) = (ss + s * s, cc + c * c, sc + s * c, sy + s * y, cy + c * y);
        }
        let det = ss * cc - sc * sc;
        let (a, b) = ((sy * cc - cy * sc) / det, (cy * ss - sy * sc) / det);
        a.hypot(b)
    }

    /// The ratio of the segmented widths with `effects` to those without, inside
    /// `[from, to]` mm (the same seed prints the same line and photographs it alike).
    fn ratio(effects: &str, from: f64, to: f64) -> (Vec<f64>, Vec<f64>) {
        let ((x0, w0), (x1, w1)) = (segmented(""), segmented(effects));
        x0.iter()
            .zip(&w0)
            .filter(|(x, _)| (from..=to).contains(*x))
            .filter_map(|(x, w)| {
                let k = x1.iter().position(|y| (y - x).abs() < 0.01)?;
                Some((*x, w1[k] / w))
            })
            .unzip()
    }

    #[test]
    fn a_photo_of_a_known_width_profile_gives_the_profile_back() {
        // A line with a blob, a ripple and a trend, photographed by the virtual camera
        // (rotated, unevenly lit, textured, noisy): the edge fit recovers the width to
        // well under a hundredth of a millimetre, the threshold count does not.
        let n = (120.0 / TRUTH_STEP_MM) as usize + 1;
        let x: Vec<f64> = (0..n).map(|i| i as f64 * TRUTH_STEP_MM).collect();
        let width = |x: f64| 0.8 + 0.4 * (-x / 2.0).exp() + 0.05 * (2.0 * PI * x / 10.0).sin() + 0.001 * x;
        let half: Vec<f64> = x.iter().map(|&x| width(x) / 2.0).collect();
        let line = PrintedLine { positions_mm: x.clone(), left_mm: half.clone(), right_mm: half };
        let photo =
            photograph(&line, 120.0, &CameraSettings::default(), 0.0, &mut rand_chacha::ChaCha8Rng::seed_from_u64(3))
                .unwrap();
        let image = GrayImage::from_png_bytes(&photo.png, 1 << 26).unwrap();
        let p = photo.recorded;
        let geometry = LineGeometry {
            start_px: [p.start_x_px, p.start_y_px],
            direction_rad: p.direction_deg.to_radians(),
            length_mm: 120.0,
            px_per_mm: p.px_per_mm,
            nominal_width_mm: 0.8,
        };
        let error = |s: &Segmentation| {
            let e: Vec<f64> = s.positions_mm.iter().zip(&s.widths_mm).map(|(x, w)| w - width(*x)).collect();
            ((e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64).sqrt(), e.iter().sum::<f64>() / e.len() as f64)
        };
        let fitted = segment_edge_fit(&image, &geometry, 0.05).unwrap();
        let (rmse, bias) = error(&fitted);
        assert!(fitted.widths_mm.len() > 2300 && rmse < 0.006 && bias.abs() < 0.002, "edge fit {rmse} {bias}");
        let (threshold_rmse, _) = error(&segment_threshold_columns(&image, &geometry, 0.05).unwrap());
        assert!(threshold_rmse > 2.0 * rmse, "threshold {threshold_rmse} vs edge fit {rmse}");
    }

    #[test]
    fn a_photo_cropped_close_to_the_line_is_still_measured() {
        // 10 px/mm with 1.6 mm of bed around the line (16 px): the ends' search windows
        // (24 px) are clipped at the frame, and the widths come out as on a wide photo.
        let tmp = tempfile::tempdir().unwrap();
        let camera =
            CameraSettings { px_per_mm: 10.0, margin_mm: 1.6, max_offset_px: 0.0, ..CameraSettings::default() };
        let config = GenerateConfig { conditions: vec![(400.0, 100.0)], camera, ..GenerateConfig::new("taz6", 5) };
        generate_into(&config, tmp.path()).unwrap();
        let data = FdmLinesDataset::read(tmp.path()).unwrap();
        let s = segment_one(&data.lines[0], Method::EdgeFit, 0.05).unwrap();
        assert!(s.widths_mm.len() > 2300, "{} widths", s.widths_mm.len());
        let truth = &read_truth(tmp.path()).unwrap()["S400F6000"];
        let errors: Vec<f64> =
            s.positions_mm.iter().zip(&s.widths_mm).map(|(x, w)| w - true_width_at(truth, *x)).collect();
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        assert!(rmse < 0.02, "rmse {rmse}");
    }

    /// Three lines of the virtual Taz 6 photographed at 10 px/mm, seed 9.
    fn three_photos(dir: &Path) -> FdmLinesDataset {
        let camera = CameraSettings { px_per_mm: 10.0, ..CameraSettings::default() };
        let conditions = vec![(400.0, 50.0), (600.0, 100.0), (800.0, 150.0)];
        generate_into(&GenerateConfig { conditions, camera, ..GenerateConfig::new("taz6", 9) }, dir).unwrap();
        FdmLinesDataset::read(dir).unwrap()
    }

    #[test]
    fn a_line_that_cannot_be_measured_is_a_row_and_only_none_measured_fails() {
        let tmp = tempfile::tempdir().unwrap();
        let mut data = three_photos(tmp.path());
        let ids: Vec<String> = data.lines.iter().map(|l| l.line_id.clone()).collect();
        // One truncated photo: a row with its reason, the other two are measured.
        let bytes = std::fs::read(&data.lines[0].image).unwrap();
        std::fs::write(&data.lines[0].image, &bytes[..bytes.len() / 2]).unwrap();
        let (lines, diagnostics) = measure_lines(&data, Method::EdgeFit, 0.05).unwrap();
        assert_eq!(lines.iter().map(|l| &l.line_id).collect::<Vec<_>>(), [&ids[1], &ids[2]]);
        assert_eq!(diagnostics.status, ["skipped", "measured", "measured"]);
        assert!(diagnostics.problem[0].contains("PNG"), "{}", diagnostics.problem[0]);
        // The two others with a scale twice the camera's: nothing to write, and the error
        // gives every line's reason, not only the first.
        for line in &mut data.lines[1..] {
            line.placement.px_per_mm *= 2.0;
        }
        for method in [Method::EdgeFit, Method::Threshold] {
            let err = measure_lines(&data, method, 0.05).err().unwrap();
            assert!(err.contains("none of the 3") && err.contains(method.name()), "{err}");
            for id in &ids {
                assert!(err.contains(&format!("line `{id}`: ")), "{id}: {err}");
            }
            assert!(err.contains("PNG") && err.matches("px_per_mm").count() >= 2, "{err}");
        }
    }

    #[test]
    fn bed_tilt_shows_in_the_photos_as_a_linear_trend() {
        let (x, r) = ratio("bed_tilt=0.1", 2.0, 118.0);
        let (a, b) = line_fit(&x, &r);
        let end_to_end = (a + b * 120.0) / a - 1.0;
        assert!((end_to_end - 0.1).abs() < 0.01, "end to end {end_to_end}");
        let curvature = x.iter().zip(&r).map(|(x, r)| (r - a - b * x).abs()).sum::<f64>() / x.len() as f64;
        assert!(curvature < 0.01, "a trend, not a curve: {curvature}");
    }

    #[test]
    fn gear_eccentricity_shows_in_the_photos_at_the_gears_period() {
        // 5 % ripple, 12 mm of path, smoothed by the bead over 0.5 mm (sinc attenuation).
        let (x, r) = ratio("gear_eccentricity=0.05", 2.0, 118.0);
        let ripple: Vec<f64> = r.iter().map(|r| r - 1.0).collect();
        let at_gear = amplitude_at(&x, &ripple, 12.0);
        let g = models::fdm::discrepancy::gear::attenuation(12.0, 0.5);
        assert!((at_gear - 0.05 * g).abs() < 0.004, "amplitude {at_gear}");
        for other in [5.0, 7.3, 20.0, 31.0] {
            assert!(amplitude_at(&x, &ripple, other) < 0.005, "{other} mm");
        }
    }

    #[test]
    fn flow_saturation_takes_its_loss_at_the_fastest_cruise() {
        let (_, r) = ratio("flow_saturation=0.1", 40.0, 80.0);
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        assert!((mean - 0.9).abs() < 0.005, "cruise ratio {mean}");
    }

    #[test]
    fn a_camera_scale_error_scales_the_measured_widths() {
        let (_, r) = ratio("camera_scale_error=0.003", 40.0, 80.0);
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        assert!((mean - 1.003).abs() < 0.001, "width ratio {mean}");
    }
}
