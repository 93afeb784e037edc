//! `fdm.measure_photos`: an `fdm-photos` dataset (a lab's photos of a print and the G-code
//! that printed it) → every straight printed line's widths in bed millimetres, per photo,
//! with where each photo sits on the bed. The photo is placed from the G-code alone
//! ([`vision::photo::calibrate`]); a photo or line that cannot be measured is a row with
//! its reason and the others go on; only a dataset where no line of any photo can be
//! measured is an error, listing every photo's reason.

use datasets::fdm_photos::{FdmPhotos, Photo};
use datasets::limits::LINE_IMAGE_PIXELS;
use models::fdm::printed_lines::PrintedLine;
use pipeline::schema::Table;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;
use tables::fdm::{photo_calibration as cal_t, photo_lines as lines_t, photo_widths as widths_t};
use vision::photo::measure::{measure_paths, reprojection_error, PathMeasurement};
use vision::photo::orient::Choice;
use vision::photo::{calibrate, Calibration, ColourImage, PhotoCamera, PrintedPath};

use super::segment::Step;
use crate::table::{f64_col, frame, i64_col, str_col};

/// The `fdm.measure_photos` stage kind.
pub struct MeasurePhotosStage;

/// The photos and their G-code.
const PHOTOS: Input =
    Input::one("photos", &[Source::Dataset("fdm-photos")], "photos of a print and its G-code (`fdm-photos`)");

/// The optional `photos.csv` column saying the camera mirrors its image.
const MIRRORED_COLUMN: &str = "mirrored";

impl Stage for MeasurePhotosStage {
    type Params = Step;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.measure_photos",
        version: 2,
        summary: "Photos of a print and its G-code (fdm-photos) → per photo its place on the bed (lens and pose), per printed line its widths in bed mm → photo_lines, photo_widths, photo_calibration.parquet",
        implements: "paper 000 Sec. III (widths from camera images) on photos as labs take them",
        inputs: &[PHOTOS],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&lines_t::TABLE, &widths_t::TABLE, &cal_t::TABLE];

    fn run(&self, ctx: &mut StageContext, p: &Step) -> Result<(), StageError> {
        let dir = ctx.input(&PHOTOS).dir.clone();
        let data = FdmPhotos::read(&dir).map_err(StageError::domain)?;
        let paths: Vec<PrintedPath> = data.lines.iter().map(PrintedPath::from_line).collect();
        let bar = ctx.progress(data.photos.len() as u64);
        let mut rows = Rows::default();
        for photo in &data.photos {
            let result = pipeline::panic::catch(|| measure_photo(photo, &paths, p.step_mm)).unwrap_or_else(|panic| {
                Err(format!("internal error, a bug in amrepro (please report it with this photo): {panic}"))
            });
            rows.push(photo, &data.lines, &paths, &dir, result);
            bar.inc(1);
        }
        bar.finish_and_clear();
        if rows.measured_lines == 0 {
            return Err(StageError::BadInput {
                file: dir.join("photos.csv"),
                location: None,
                expected: rows.no_line_error(),
            });
        }
        ctx.write_table(lines_t::TABLE.name, &mut rows.lines.frame()?)?;
        ctx.write_table(widths_t::TABLE.name, &mut rows.widths.frame()?)?;
        ctx.write_table(cal_t::TABLE.name, &mut rows.calibration.frame()?)?;
        Ok(())
    }
}

/// One photo placed and measured.
struct Measured {
    size_px: (usize, usize),
    calibration: Calibration,
    paths: Vec<PathMeasurement>,
}

fn measure_photo(photo: &Photo, paths: &[PrintedPath], step_mm: f64) -> Result<Measured, String> {
    let name = photo.image.display();
    let mirrored = mirrored(photo)?;
    let bytes = std::fs::read(&photo.image).map_err(|e| format!("{name}: {e}"))?;
    let img = ColourImage::decode(&bytes, *LINE_IMAGE_PIXELS.end()).map_err(|e| format!("{name}: {e}"))?;
    let calibration = calibrate(&img, paths, mirrored).map_err(|e| format!("{name}: {e}"))?;
    let contrast = calibration.contrast_axis.apply(&img);
    let measured = measure_paths(&contrast, paths, &calibration.camera, step_mm);
    Ok(Measured { size_px: (img.width, img.height), calibration, paths: measured })
}

/// The photo's `mirrored` column: `true`, `false` or empty/absent (false).
fn mirrored(photo: &Photo) -> Result<bool, String> {
    match photo.extra.iter().find(|(c, _)| c == MIRRORED_COLUMN).map(|(_, v)| v.trim()) {
        None | Some("") | Some("false") => Ok(false),
        Some("true") => Ok(true),
        Some(other) => Err(format!(
            "photos.csv: photo `{}`, field {MIRRORED_COLUMN}: expected true or false, got `{other}`",
            photo.photo_id
        )),
    }
}

/// The three tables' rows.
#[derive(Default)]
struct Rows {
    lines: LineRows,
    widths: WidthRows,
    calibration: CalibrationRows,
    measured_lines: usize,
    failures: Vec<String>,
}

impl Rows {
    fn push(
        &mut self,
        photo: &Photo,
        lines: &[PrintedLine],
        paths: &[PrintedPath],
        dir: &std::path::Path,
        result: Result<Measured, String>,
    ) {
        let image = photo.image.strip_prefix(dir).unwrap_or(&photo.image).to_string_lossy().into_owned();
        match result {
            Ok(m) => {
                for (index, (line, pm)) in lines.iter().zip(&m.paths).enumerate() {
                    let measured = self.lines.push_measured(&photo.photo_id, index, line, pm);
                    self.measured_lines += usize::from(measured);
                    self.widths.push(&photo.photo_id, index, pm, &paths[index], &m.calibration.camera);
                }
                self.calibration.push_calibrated(&photo.photo_id, &image, &m);
            }
            Err(reason) => {
                for (index, line) in lines.iter().enumerate() {
                    self.lines.push_skipped(&photo.photo_id, index, line, &format!("photo not measured: {reason}"));
                }
                self.calibration.push_failed(&photo.photo_id, &image, &reason);
                self.failures.push(format!("photo `{}`: {reason}", photo.photo_id));
            }
        }
    }

    fn no_line_error(&self) -> String {
        let why = if self.failures.is_empty() {
            "no photo had a line measured as a single bead".to_string()
        } else {
            self.failures.join("; ")
        };
        format!("expected at least one photo with a measurable line; none had one: {why}")
    }
}

#[derive(Default)]
struct LineRows {
    photo_id: Vec<String>,
    line: Vec<i64>,
    ends: [Vec<f64>; 4],
    pressure_advance_s: Vec<f64>,
    status: Vec<String>,
    reason: Vec<String>,
    median_width_mm: Vec<f64>,
    counts: [Vec<i64>; 3],
    photo_ends: [Vec<f64>; 4],
}

impl LineRows {
    fn push_common(&mut self, photo_id: &str, index: usize, line: &PrintedLine) {
        self.photo_id.push(photo_id.into());
        self.line.push(index as i64);
        for (k, v) in [line.start_mm[0], line.start_mm[1], line.end_mm[0], line.end_mm[1]].into_iter().enumerate() {
            self.ends[k].push(v);
        }
        self.pressure_advance_s.push(line.pressure_advance.advance_s);
    }

    /// Pushes a measured photo's line; true if at least one position was measured.
    fn push_measured(&mut self, photo_id: &str, index: usize, line: &PrintedLine, pm: &PathMeasurement) -> bool {
        self.push_common(photo_id, index, line);
        let mut beads: Vec<f64> = pm.samples.iter().filter(|s| s.width_mm > 0.0).map(|s| s.width_mm).collect();
        let gaps = pm.samples.len() - beads.len();
        beads.sort_by(f64::total_cmp);
        let measured = !pm.samples.is_empty();
        self.status.push(if measured { "measured" } else { "skipped" }.into());
        self.reason.push(skip_summary(pm));
        self.median_width_mm.push(models::stats::finite_median(beads.iter().copied()));
        for (k, v) in [beads.len(), gaps, pm.skipped.len()].into_iter().enumerate() {
            self.counts[k].push(v as i64);
        }
        let (s, e) = (pm.start_px.unwrap_or([f64::NAN; 2]), pm.end_px.unwrap_or([f64::NAN; 2]));
        for (k, v) in [s[0], s[1], e[0], e[1]].into_iter().enumerate() {
            self.photo_ends[k].push(v);
        }
        measured
    }

    fn push_skipped(&mut self, photo_id: &str, index: usize, line: &PrintedLine, reason: &str) {
        self.push_common(photo_id, index, line);
        self.status.push("skipped".into());
        self.reason.push(reason.into());
        self.median_width_mm.push(f64::NAN);
        self.counts.iter_mut().for_each(|c| c.push(0));
        self.photo_ends.iter_mut().for_each(|c| c.push(f64::NAN));
    }

    fn frame(&self) -> Result<DataFrame, StageError> {
        let [x0, y0, x1, y1] = self.ends.clone();
        let [widths, gaps, skipped] = self.counts.clone();
        let [su, sv, eu, ev] = self.photo_ends.clone();
        frame(vec![
            str_col(lines_t::photo_id, self.photo_id.clone()),
            i64_col(lines_t::line, self.line.clone()),
            f64_col(lines_t::x0_mm, x0),
            f64_col(lines_t::y0_mm, y0),
            f64_col(lines_t::x1_mm, x1),
            f64_col(lines_t::y1_mm, y1),
            f64_col(lines_t::pressure_advance_s, self.pressure_advance_s.clone()),
            str_col(lines_t::status, self.status.clone()),
            str_col(lines_t::reason, self.reason.clone()),
            f64_col(lines_t::median_width_mm, self.median_width_mm.clone()),
            i64_col(lines_t::widths, widths),
            i64_col(lines_t::gaps, gaps),
            i64_col(lines_t::positions_skipped, skipped),
            f64_col(lines_t::start_x_px, su),
            f64_col(lines_t::start_y_px, sv),
            f64_col(lines_t::end_x_px, eu),
            f64_col(lines_t::end_y_px, ev),
        ])
    }
}

/// "touches line 1: 31, no edge fit: 2": the skipped positions by reason, or why nothing
/// was measured.
fn skip_summary(pm: &PathMeasurement) -> String {
    let mut counts: std::collections::BTreeMap<String, usize> = std::collections::BTreeMap::new();
    for (_, skip) in &pm.skipped {
        *counts.entry(skip.reason()).or_default() += 1;
    }
    let summary = counts.iter().map(|(r, n)| format!("{r}: {n}")).collect::<Vec<_>>().join(", ");
    if pm.samples.is_empty() {
        format!("no position is a single bead in the photo ({summary})")
    } else {
        summary
    }
}

#[derive(Default)]
struct WidthRows {
    photo_id: Vec<String>,
    line: Vec<i64>,
    values: [Vec<f64>; 5],
    pixels: [Vec<f64>; 6],
}

impl WidthRows {
    /// The measured positions of one path, with the axis and both edges in the photo.
    fn push(&mut self, photo_id: &str, index: usize, pm: &PathMeasurement, path: &PrintedPath, camera: &PhotoCamera) {
        let in_photo = |s: f64, t: f64| {
            if t.is_finite() { camera.project(path.point(s, t)) } else { None }.unwrap_or([f64::NAN; 2])
        };
        for s in &pm.samples {
            self.photo_id.push(photo_id.into());
            self.line.push(index as i64);
            for (k, v) in
                [s.position_mm, s.width_mm, s.left_mm, s.right_mm, s.threshold_width_mm].into_iter().enumerate()
            {
                self.values[k].push(v);
            }
            let points = [
                in_photo(s.position_mm, 0.0),
                in_photo(s.position_mm, s.left_mm),
                in_photo(s.position_mm, -s.right_mm),
            ];
            for (k, v) in points.iter().flatten().enumerate() {
                self.pixels[k].push(*v);
            }
        }
    }

    fn frame(&self) -> Result<DataFrame, StageError> {
        let [ax, ay, lx, ly, rx, ry] = self.pixels.clone();
        let [position, width, left, right, threshold] = self.values.clone();
        frame(vec![
            str_col(widths_t::photo_id, self.photo_id.clone()),
            i64_col(widths_t::line, self.line.clone()),
            f64_col(widths_t::position_mm, position),
            f64_col(widths_t::width_mm, width),
            f64_col(widths_t::left_mm, left),
            f64_col(widths_t::right_mm, right),
            f64_col(widths_t::threshold_width_mm, threshold),
            f64_col(widths_t::axis_x_px, ax),
            f64_col(widths_t::axis_y_px, ay),
            f64_col(widths_t::left_x_px, lx),
            f64_col(widths_t::left_y_px, ly),
            f64_col(widths_t::right_x_px, rx),
            f64_col(widths_t::right_y_px, ry),
        ])
    }
}

/// Per photo: status, reason, size, the eight homography terms, k1, k2, scale, the
/// correlation, the orientation and its p-value, the contrast's separation, the
/// reprojection error and its count.
#[derive(Default)]
struct CalibrationRows {
    photo_id: Vec<String>,
    image: Vec<String>,
    status: Vec<String>,
    reason: Vec<String>,
    size: [Vec<i64>; 2],
    camera: [Vec<f64>; 10],
    scale: Vec<f64>,
    correlation: Vec<f64>,
    orientation: Vec<String>,
    orientation_p: Vec<f64>,
    separation: Vec<f64>,
    reprojection: Vec<f64>,
    reprojection_n: Vec<i64>,
}

impl CalibrationRows {
    fn push_calibrated(&mut self, photo_id: &str, image: &str, m: &Measured) {
        let c = &m.calibration;
        self.photo_id.push(photo_id.into());
        self.image.push(image.into());
        self.status.push("calibrated".into());
        self.reason.push(String::new());
        self.size[0].push(m.size_px.0 as i64);
        self.size[1].push(m.size_px.1 as i64);
        for (k, v) in c.camera.params().into_iter().enumerate() {
            self.camera[k].push(v);
        }
        self.scale.push(c.camera.mean_scale(bed_under_centre(&c.camera)).unwrap_or(f64::NAN));
        self.correlation.push(c.levels.last().map_or(f64::NAN, |l| l.correlation));
        let (orientation, p) = match c.orientation {
            Choice::Only => ("only", f64::NAN),
            Choice::ByPrint { p_value, .. } => ("by_print", p_value),
            Choice::Ambiguous { p_value, .. } => ("ambiguous", p_value),
        };
        self.orientation.push(orientation.into());
        self.orientation_p.push(p);
        self.separation.push(c.contrast_axis.separation);
        let (rms, n) = reprojection_error(&m.paths);
        self.reprojection.push(rms);
        self.reprojection_n.push(n as i64);
    }

    fn push_failed(&mut self, photo_id: &str, image: &str, reason: &str) {
        self.photo_id.push(photo_id.into());
        self.image.push(image.into());
        self.status.push("failed".into());
        self.reason.push(reason.into());
        self.size.iter_mut().for_each(|c| c.push(0));
        self.camera.iter_mut().for_each(|c| c.push(f64::NAN));
        for column in [
            &mut self.scale,
            &mut self.correlation,
            &mut self.orientation_p,
            &mut self.separation,
            &mut self.reprojection,
        ] {
            column.push(f64::NAN);
        }
        self.orientation.push(String::new());
        self.reprojection_n.push(0);
    }

    fn frame(&self) -> Result<DataFrame, StageError> {
        let names = [
            cal_t::h11,
            cal_t::h12,
            cal_t::h13,
            cal_t::h21,
            cal_t::h22,
            cal_t::h23,
            cal_t::h31,
            cal_t::h32,
            cal_t::k1,
            cal_t::k2,
        ];
        let mut columns = vec![
            str_col(cal_t::photo_id, self.photo_id.clone()),
            str_col(cal_t::image, self.image.clone()),
            str_col(cal_t::status, self.status.clone()),
            str_col(cal_t::reason, self.reason.clone()),
            i64_col(cal_t::width_px, self.size[0].clone()),
            i64_col(cal_t::height_px, self.size[1].clone()),
        ];
        columns.extend(names.iter().zip(&self.camera).map(|(n, v)| f64_col(n, v.clone())));
        columns.extend([
            f64_col(cal_t::scale_px_per_mm, self.scale.clone()),
            f64_col(cal_t::correlation, self.correlation.clone()),
            str_col(cal_t::orientation, self.orientation.clone()),
            f64_col(cal_t::orientation_p_value, self.orientation_p.clone()),
            f64_col(cal_t::contrast_separation, self.separation.clone()),
            f64_col(cal_t::reprojection_error_mm, self.reprojection.clone()),
            i64_col(cal_t::reprojection_positions, self.reprojection_n.clone()),
        ]);
        frame(columns)
    }
}

/// The bed point seen at the photo's centre (mm): the homography's inverse there, where
/// the radial distortion is the identity.
fn bed_under_centre(camera: &PhotoCamera) -> [f64; 2] {
    let h = &camera.homography;
    let [u, v] = camera.centre_px;
    let a = [[h[0] - u * h[6], h[1] - u * h[7]], [h[3] - v * h[6], h[4] - v * h[7]]];
    let b = [u - h[2], v - h[5]];
    let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
    [(b[0] * a[1][1] - a[0][1] * b[1]) / det, (a[0][0] * b[1] - b[0] * a[1][0]) / det]
}

/// The `fdm.import_photos` stage kind.
pub struct ImportPhotosStage;

pipeline::choice! {
    /// The firmware that ran the G-code.
    pub enum FirmwareChoice {
        /// Klipper (square-corner velocity, SET_PRESSURE_ADVANCE).
        Klipper = "klipper",
        /// Marlin (jerk or junction deviation, M900 linear advance).
        Marlin = "marlin",
    }
}

pipeline::params! {
    /// The parameters of `fdm.import_photos`: what the folder does not say.
    pub struct ImportPhotosParams {
        /// The printer's name.
        pub printer: String = "printer",
        /// The firmware that ran the G-code.
        pub firmware: FirmwareChoice = FirmwareChoice::Klipper,
        /// Filament diameter (mm).
        pub filament_diameter_mm: f64 [0.1, 10.0] = 1.75,
        /// Nozzle diameter (mm).
        pub nozzle_diameter_mm: f64 [0.01, 10.0] = 0.4,
        /// The G-code file, relative to the folder.
        pub gcode: String = "print.gcode",
        /// The folder of photos (every .jpg, .jpeg and .png in it), relative to the folder.
        pub photos: String = "photos",
        /// Where the photos come from (recorded as the dataset's provenance).
        pub source: String = "",
        /// The photos' licence (recorded as the dataset's provenance).
        pub license: String = "",
    }
}

/// The lab's folder.
const RAW_PHOTOS: Input = Input::one("raw", &[Source::RawFolder], "a folder with the G-code and a folder of photos");

impl Stage for ImportPhotosStage {
    type Params = ImportPhotosParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "fdm.import_photos",
        version: 1,
        summary: "A folder with a print's G-code and its photos → an fdm-photos dataset (the output folder)",
        implements: "DESIGN §4 (datasets); the fdm-photos kind of docs/DATASETS.md",
        inputs: &[RAW_PHOTOS],
        output: Output::Dataset("fdm-photos"),
    };
    const WRITES: &'static [&'static Table] = &[];

    fn run(&self, ctx: &mut StageContext, p: &ImportPhotosParams) -> Result<(), StageError> {
        use datasets::fdm_photos::import::{import, ImportOptions};
        use datasets::fdm_photos::FirmwareName;
        let firmware = match p.firmware {
            FirmwareChoice::Klipper => FirmwareName::Klipper,
            FirmwareChoice::Marlin => FirmwareName::Marlin,
        };
        let opts = ImportOptions {
            printer: p.printer.clone(),
            firmware,
            filament_diameter_mm: p.filament_diameter_mm,
            nozzle_diameter_mm: p.nozzle_diameter_mm,
            gcode: p.gcode.clone(),
            photos: p.photos.clone(),
            source: p.source.clone(),
            license: p.license.clone(),
        };
        let raw = ctx.input(&RAW_PHOTOS).dir.clone();
        import(&raw, &opts, ctx.output_dir()).map_err(StageError::domain)?;
        Ok(())
    }
}
