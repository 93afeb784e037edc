//! The virtual FDM printer and its camera writing an `fdm-lines` dataset (DESIGN §5.1):
//! `amrepro datasets generate fdm --printer taz5|taz6 --conditions ren2021 --seed S
//! [--effect NAME --strength X]... [--lines-per-condition K] --out DIR`.
//!
//! Each line is printed by [`models::fdm::printer::print_line`] (the physics) and
//! photographed by [`super::camera::photograph`]; the dataset holds only what a lab
//! would have (photos, G-code values, the marked placement), and `truth/` the true
//! edges every 0.05 mm and the true placement, for evaluation stages only.
//!
//! ```text
//! truth/widths/<line_id>.csv   position_mm,width_mm,left_mm,right_mm
//! truth/placement.csv          line_id,px_per_mm,start_x_px,start_y_px,direction_deg
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use models::fdm::kinematics::LineKinematics;
use models::fdm::printer::{print_line, Effects, PrintedLine, PrinterProfile, LAYER_HEIGHT_MM, PRINTERS};
use models::progress::Progress;
use rayon::prelude::*;

use super::camera::{photograph, CameraSettings, Photo};
use super::{lines_csv, ImagePlacement, PhotoLine, FORMAT_VERSION, KIND, READABLE_VERSIONS};
use crate::csv_table::CsvTable;
use crate::error::DatasetError;
use crate::fdm_widths::LineMotion;
use crate::manifest::{DatasetManifest, Provenance, MANIFEST_FILE};
use crate::output::{write_file, OutputDir, Ownership};
use crate::stream;

/// Generator name recorded in the provenance.
pub const GENERATOR: &str = "amrepro-fdm";
/// Paper 000's lines: 120 mm long, start and end at the 8 mm/s jerk speed.
pub const LENGTH_MM: f64 = 120.0;
/// The jerk (start and end) speed (mm/s).
pub const JERK_MM_S: f64 = 8.0;
/// Paper 000's Table I: accelerations × feeds, (mm/s², mm/s).
pub const REN2021_CONDITIONS: [(f64, f64); 9] = [
    (400.0, 50.0),
    (400.0, 100.0),
    (400.0, 150.0),
    (600.0, 50.0),
    (600.0, 100.0),
    (600.0, 150.0),
    (800.0, 50.0),
    (800.0, 100.0),
    (800.0, 150.0),
];

/// Which folders the generator may replace.
pub const OUTPUT: Ownership = Ownership {
    kind: KIND,
    versions: READABLE_VERSIONS,
    writer: "datasets generate fdm",
    written_by_us: |p| matches!(p, Provenance::Virtual { generator, .. } if generator == GENERATOR),
};

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct GenerateConfig {
    /// Printer profile name (`taz5`, `taz6`).
    pub printer: String,
    /// Seed of every random stream.
    pub seed: u64,
    /// `(acceleration mm/s², feed mm/s)` per condition.
    pub conditions: Vec<(f64, f64)>,
    /// Lines printed per condition.
    pub lines_per_condition: usize,
    /// Extra effects (default none).
    pub effects: Effects,
    /// The camera.
    pub camera: CameraSettings,
}

impl GenerateConfig {
    /// Paper 000's nine conditions, one line each, no effect, the default camera.
    pub fn new(printer: &str, seed: u64) -> Self {
        Self {
            printer: printer.into(),
            seed,
            conditions: REN2021_CONDITIONS.to_vec(),
            lines_per_condition: 1,
            effects: Effects::default(),
            camera: CameraSettings::default(),
        }
    }
}

/// A condition set by name: `ren2021` (paper 000 Table I).
pub fn conditions_named(name: &str) -> Option<Vec<(f64, f64)>> {
    (name == "ren2021").then(|| REN2021_CONDITIONS.to_vec())
}

/// Generates into `out` (absent, empty or an earlier output of this generator),
/// atomically; returns the number of lines.
pub fn generate(config: &GenerateConfig, out: &Path) -> Result<usize, DatasetError> {
    let output = OutputDir::begin(out, &OUTPUT)?;
    let lines = generate_into(config, output.path())?;
    output.commit()?;
    Ok(lines)
}

/// [`generate`] into the empty folder `out_dir` (a stage's output folder).
pub fn generate_into(config: &GenerateConfig, out_dir: &Path) -> Result<usize, DatasetError> {
    generate_into_observed(config, out_dir, &())
}

/// [`generate_into`], telling `progress` of each line printed and photographed.
pub fn generate_into_observed(
    config: &GenerateConfig,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<usize, DatasetError> {
    let bad = |expected: String| DatasetError::Malformed { file: out_dir.to_path_buf(), location: None, expected };
    let profile = PrinterProfile::named(&config.printer)
        .ok_or_else(|| bad(format!("expected a printer among {PRINTERS:?}, got `{}`", config.printer)))?;
    if !(1..=100).contains(&config.lines_per_condition) || config.conditions.is_empty() {
        return Err(bad("expected 1 to 100 lines per condition and at least one condition".into()));
    }
    let jobs = jobs(config).map_err(|e| bad(format!("a condition's kinematics: {e}")))?;
    let v_ref_mm_s = jobs.iter().map(|j| j.kin.peak_speed_mm_s()).fold(0.0, f64::max);
    progress.add(jobs.len() as u64);
    let shots: Vec<(PrintedLine, Photo)> = jobs
        .par_iter()
        .enumerate()
        .map(|(index, job)| {
            let printed =
                print_line(&profile, &config.effects, &job.kin, v_ref_mm_s, &mut stream(config.seed, 2 * index as u64))
                    .map_err(|e| bad(format!("printing {}: {e}", job.line_id)))?;
            let photo = photograph(
                &printed,
                LENGTH_MM,
                &config.camera,
                config.effects.camera_scale_error,
                &mut stream(config.seed, 2 * index as u64 + 1),
            )
            .map_err(|e| bad(format!("photographing {}: {e}", job.line_id)))?;
            progress.done(1);
            Ok((printed, photo))
        })
        .collect::<Result<_, DatasetError>>()?;
    write(config, &profile, &jobs, &shots, out_dir)?;
    Ok(jobs.len())
}

struct Job {
    line_id: String,
    condition: String,
    accel_mm_s2: f64,
    feed_mm_s: f64,
    kin: LineKinematics,
}

fn jobs(config: &GenerateConfig) -> Result<Vec<Job>, String> {
    let mut jobs = Vec::new();
    for &(accel_mm_s2, feed_mm_s) in &config.conditions {
        let kin = LineKinematics::new(accel_mm_s2, feed_mm_s, JERK_MM_S, LENGTH_MM).map_err(|e| e.to_string())?;
        let condition = format!("S{}F{}", accel_mm_s2, feed_mm_s * 60.0);
        for k in 1..=config.lines_per_condition {
            let line_id = if config.lines_per_condition == 1 { condition.clone() } else { format!("{condition}_{k}") };
            jobs.push(Job { line_id, condition: condition.clone(), accel_mm_s2, feed_mm_s, kin });
        }
    }
    Ok(jobs)
}

fn write(
    config: &GenerateConfig,
    profile: &PrinterProfile,
    jobs: &[Job],
    shots: &[(PrintedLine, Photo)],
    dir: &Path,
) -> Result<(), DatasetError> {
    let mut lines = Vec::with_capacity(jobs.len());
    let mut placement = String::from("line_id,px_per_mm,start_x_px,start_y_px,direction_deg\n");
    for (job, (printed, photo)) in jobs.iter().zip(shots) {
        let image = PathBuf::from(format!("images/{}.png", job.line_id));
        write_file(dir, &image, &photo.png)?;
        write_file(dir, format!("truth/widths/{}.csv", job.line_id), truth_csv(printed).as_bytes())?;
        let t = photo.truth;
        placement +=
            &format!("{},{},{},{},{}\n", job.line_id, t.px_per_mm, t.start_x_px, t.start_y_px, t.direction_deg);
        lines.push(PhotoLine {
            line_id: job.line_id.clone(),
            condition: job.condition.clone(),
            image,
            image_size_px: Ok(photo.size_px),
            motion: LineMotion {
                accel_mm_s2: job.accel_mm_s2,
                feed_mm_s: job.feed_mm_s,
                jerk_mm_s: JERK_MM_S,
                length_mm: LENGTH_MM,
            },
            layer_height_mm: LAYER_HEIGHT_MM,
            nominal_width_mm: round_to_micron(profile.theta.w0_mm),
            placement: photo.recorded,
        });
    }
    write_file(dir, "truth/placement.csv", placement.as_bytes())?;
    write_file(dir, "lines.csv", lines_csv(&lines).as_bytes())?;
    write_file(dir, MANIFEST_FILE, manifest(config).to_toml().as_bytes())
}

fn round_to_micron(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

fn truth_csv(line: &PrintedLine) -> String {
    let mut text = String::from("position_mm,width_mm,left_mm,right_mm\n");
    for ((x, l), r) in line.positions_mm.iter().zip(&line.left_mm).zip(&line.right_mm) {
        text += &format!("{x:.2},{:.6},{l:.6},{r:.6}\n", l + r);
    }
    text
}

fn manifest(config: &GenerateConfig) -> DatasetManifest {
    let c = &config.camera;
    let mut effects: BTreeMap<String, f64> =
        config.effects.active().into_iter().map(|(name, strength)| (name.to_string(), strength)).collect();
    if config.effects.gear_eccentricity != 0.0 {
        effects.insert("gear_period_mm".into(), config.effects.gear_period_mm);
    }
    let mut units = crate::fdm_widths::UNITS.to_vec();
    units.extend([("pixel_scale", "px/mm"), ("pixel", "px"), ("direction", "deg")]);
    DatasetManifest {
        kind: KIND.into(),
        format_version: FORMAT_VERSION,
        printer: config.printer.clone(),
        description: format!(
            "Virtual {} (physics calibrated to the real lines, DESIGN §5.1): {} straight {LENGTH_MM} mm line{}, photographed from above at {} px/mm, {}-bit.",
            config.printer,
            config.conditions.len() * config.lines_per_condition,
            if config.conditions.len() * config.lines_per_condition == 1 { "" } else { "s" },
            c.px_per_mm,
            c.bit_depth
        ),
        units: crate::fdm_widths::units_table(&units),
        provenance: Provenance::Virtual {
            generator: GENERATOR.into(),
            version: env!("CARGO_PKG_VERSION").into(),
            seed: config.seed,
            effects,
        },
    }
}

/// One line's truth, as evaluation stages read it.
#[derive(Debug, Clone, PartialEq)]
pub struct LineTruth {
    /// Positions along the path (mm).
    pub positions_mm: Vec<f64>,
    /// True widths (mm).
    pub widths_mm: Vec<f64>,
    /// The true placement (true px/mm included).
    pub placement: ImagePlacement,
}

/// Reads `truth/` of a virtual `fdm-lines` dataset: line id → truth.
pub fn read_truth(dir: &Path) -> Result<BTreeMap<String, LineTruth>, DatasetError> {
    let table = CsvTable::read(&dir.join("truth/placement.csv"))?;
    let cols: Vec<usize> = ["line_id", "px_per_mm", "start_x_px", "start_y_px", "direction_deg"]
        .iter()
        .map(|c| table.column(c))
        .collect::<Result<_, _>>()?;
    let mut out = BTreeMap::new();
    for row in &table.rows {
        let id = row.1[cols[0]].clone();
        let widths = CsvTable::read(&dir.join(format!("truth/widths/{id}.csv")))?;
        let (xc, wc) = (widths.column("position_mm")?, widths.column("width_mm")?);
        let positions_mm = widths.rows.iter().map(|r| widths.number(r, xc)).collect::<Result<_, _>>()?;
        let widths_mm = widths.rows.iter().map(|r| widths.number(r, wc)).collect::<Result<_, _>>()?;
        let placement = ImagePlacement {
            px_per_mm: table.number(row, cols[1])?,
            start_x_px: table.number(row, cols[2])?,
            start_y_px: table.number(row, cols[3])?,
            direction_deg: table.number(row, cols[4])?,
        };
        out.insert(id, LineTruth { positions_mm, widths_mm, placement });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_writes_the_same_bytes_and_the_effects_are_recorded() {
        let tmp = tempfile::tempdir().unwrap();
        let config = GenerateConfig {
            conditions: vec![(800.0, 150.0)],
            effects: Effects::from_pairs([("bed_tilt", 0.03)]).unwrap(),
            camera: CameraSettings { px_per_mm: 10.0, ..CameraSettings::default() },
            ..GenerateConfig::new("taz5", 11)
        };
        let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
        generate(&config, &a).unwrap();
        generate(&config, &b).unwrap();
        for file in ["lines.csv", "dataset.toml", "images/S800F9000.png", "truth/widths/S800F9000.csv"] {
            assert_eq!(std::fs::read(a.join(file)).unwrap(), std::fs::read(b.join(file)).unwrap(), "{file}");
        }
        let toml = std::fs::read_to_string(a.join("dataset.toml")).unwrap();
        assert!(toml.contains("bed_tilt = 0.03") && toml.contains("amrepro-fdm"), "{toml}");
        let truth = read_truth(&a).unwrap();
        let t = &truth["S800F9000"];
        assert_eq!(t.positions_mm.len(), 2401);
        assert!(t.widths_mm.iter().all(|w| *w > 0.1 && *w < 2.0));
    }

    /// The real lines of `printer` as the models' input.
    fn real_lines(printer: crate::fsu::FsuPrinter) -> Vec<models::fdm::MeasuredLine> {
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/fsu-linewidth");
        let data = crate::fsu::read_printer(&src, printer, crate::fsu::ImportOptions { verify_sha256: false })
            .expect("data/fsu-linewidth ships with the repository");
        data.lines
            .iter()
            .map(|l| {
                let m = l.motion;
                let kin = LineKinematics::new(m.accel_mm_s2, m.feed_mm_s, m.jerk_mm_s, m.length_mm).unwrap();
                models::fdm::MeasuredLine::new(kin, l.positions_mm.clone(), l.widths_mm.clone()).unwrap()
            })
            .collect()
    }

    #[test]
    fn the_printer_profiles_are_their_calibration_on_the_real_lines() {
        use crate::fsu::FsuPrinter;
        use models::fdm::printer::calibrate;
        let cases = [
            (FsuPrinter::Taz5, PrinterProfile::taz5(), true, true),
            (FsuPrinter::Taz6, PrinterProfile::taz6(), false, false),
        ];
        let fits: Vec<PrinterProfile> = cases
            .iter()
            .map(|(printer, _, blob, cap)| calibrate(&real_lines(*printer), *blob, *cap).unwrap())
            .collect();
        for ((printer, ..), fitted) in cases.iter().zip(&fits) {
            eprintln!("{}: {fitted:?}", printer.name());
        }
        for ((_, profile, ..), fitted) in cases.iter().zip(&fits) {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-3 * b.abs().max(1e-3);
            let (t, f) = (profile.theta, fitted.theta);
            assert!(close(t.tau_s, f.tau_s) && close(t.w0_mm, f.w0_mm) && close(t.blob_mm2_s, f.blob_mm2_s));
            assert!(t.max_excess_mm == f.max_excess_mm || close(t.max_excess_mm, f.max_excess_mm));
            assert!(close(profile.line_height_sd, fitted.line_height_sd));
            assert!(
                close(profile.wander.sd, fitted.wander.sd) && close(profile.wander.length_mm, fitted.wander.length_mm)
            );
            assert!(close(profile.edge.sd, fitted.edge.sd) && close(profile.edge.length_mm, fitted.edge.length_mm));
        }
    }

    #[test]
    fn a_printer_calibrated_without_a_line_reproduces_it_within_its_own_scatter() {
        use crate::fsu::FsuPrinter;
        use models::fdm::printer::held_out_agreement;
        for (printer, blob, cap) in [(FsuPrinter::Taz5, true, true), (FsuPrinter::Taz6, false, false)] {
            let rows = held_out_agreement(&real_lines(printer), blob, cap, 20, 1).unwrap();
            // A real line held out is like one more virtual line: pooled over the
            // printer's lines, its RMSE against the virtual mean is about the virtual
            // lines' own scatter.
            let pooled = |v: Vec<f64>| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
            let rmse = pooled(rows.iter().map(|r| r.rmse_mm).collect());
            let scatter = pooled(rows.iter().map(|r| r.virtual_scatter_mm).collect());
            assert!((0.7..=1.4).contains(&(rmse / scatter)), "{}: {rmse} against {scatter}", printer.name());
        }
    }

    #[test]
    fn an_unknown_printer_and_a_foreign_folder_are_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let err = generate(&GenerateConfig::new("prusa", 1), &tmp.path().join("x")).unwrap_err().to_string();
        assert!(err.contains("taz5") && err.contains("prusa"), "{err}");
        let foreign = tmp.path().join("foreign");
        std::fs::create_dir(&foreign).unwrap();
        std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
        let config = GenerateConfig { conditions: vec![(400.0, 50.0)], ..GenerateConfig::new("taz6", 1) };
        assert!(generate(&config, &foreign).is_err());
        assert_eq!(std::fs::read_to_string(foreign.join("notes.txt")).unwrap(), "mine");
    }
}
