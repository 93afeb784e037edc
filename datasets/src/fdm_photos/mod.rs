//! The `fdm-photos` dataset kind (issue 53): photos of a real print and the G-code that
//! printed it — what a lab or a hobbyist has. The reader turns the G-code into the
//! print's straight lines, each with the speed profile the firmware's planner commanded
//! and the pressure advance in force ([`models::fdm::printed_lines`]); the photos are
//! listed, not decoded (the `vision` crate reads them).
//!
//! ```text
//! dataset.toml   kind = "fdm-photos", format_version = 1, printer, description, [units],
//!                [provenance], and [printer_settings]: firmware ("klipper" | "marlin"),
//!                filament_diameter_mm, nozzle_diameter_mm and, where the G-code does
//!                not set them, accel_mm_s2, square_corner_velocity_mm_s,
//!                minimum_cruise_ratio, max_velocity_mm_s (Klipper), jerk_mm_s (Marlin),
//!                pressure_advance_s, smooth_time_s
//! print.gcode    the G-code that printed what the photos show
//! photos.csv     photo_id,image[,further columns, kept as text]
//! photos/…       JPEG or PNG, colour or grey
//! ```
//!
//! The printer's settings are a table: `[printer]` with the printer's `name` among them
//! (the folder's name when left out), or `[printer_settings]` beside the `printer = "name"`
//! every other kind has (TOML cannot hold both a `printer` string and a `[printer]` table). A setting left out is assumed ([`ASSUMED_DEFAULTS`]: the firmware's
//! default, or a typical value for the acceleration, which neither firmware defaults)
//! and listed in [`FdmPhotos::assumed`] unless the G-code sets it; a stage may fit it
//! instead and re-plan with [`FdmPhotos::replan`].
//!
//! - [`gcode`]: the G-code reader.

pub mod gcode;
pub mod generate;
pub mod import;

use std::path::{Path, PathBuf};

use models::fdm::planner::plan;
use models::fdm::printed_lines::{printed_lines, PrintedLine};
use serde::Deserialize;

use crate::csv_table::CsvTable;
use crate::error::DatasetError;
use crate::limits::{check_numbers, NumberRule, MAX_GCODE_BYTES};
use crate::manifest::{DatasetManifest, MANIFEST_FILE};
use crate::paths::{check_dataset_folder, file_in, referenced_file};
use crate::text::{read_text, read_toml};

pub use gcode::{read_gcode, Firmware, GcodeError, GcodeProgram, StartSettings};

/// The kind string in `dataset.toml`.
pub const KIND: &str = "fdm-photos";
/// Current folder layout version.
pub const FORMAT_VERSION: u32 = 1;
/// The folder layout versions this build reads.
pub const READABLE_VERSIONS: &[u32] = &[FORMAT_VERSION];
/// The G-code's file name.
pub const GCODE_FILE: &str = "print.gcode";
/// The photo table's file name.
pub const PHOTOS_FILE: &str = "photos.csv";
/// The `dataset.toml` table of the printer's settings beside `printer = "name"`.
pub const SETTINGS_TABLE: &str = "printer_settings";
/// The `dataset.toml` table of the printer's settings with its `name` (the other form).
pub const PRINTER_TABLE: &str = "printer";
/// Image file extensions read (any case).
pub const IMAGE_EXTENSIONS: [&str; 3] = ["jpg", "jpeg", "png"];

/// What is assumed for a setting left out of `[printer_settings]`: (setting, value, why).
pub const ASSUMED_DEFAULTS: [(&str, f64, &str); 7] = [
    ("accel_mm_s2", 3000.0, "a typical value (Klipper has no default; Marlin's example configuration 3000)"),
    ("square_corner_velocity_mm_s", 5.0, "Klipper's default"),
    ("minimum_cruise_ratio", 0.5, "Klipper's default"),
    ("jerk_mm_s", 10.0, "Marlin's default X/Y jerk"),
    ("pressure_advance_s", 0.0, "both firmwares' default"),
    ("smooth_time_s", 0.04, "Klipper's default (Marlin has none: 0)"),
    ("max_velocity_mm_s", f64::INFINITY, "no cap beyond the G-code's feeds"),
];

/// The printer's settings as `[printer_settings]` gives them (`None`: left out).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PrinterSettings {
    /// `klipper` or `marlin`.
    pub firmware: FirmwareName,
    /// Filament diameter (mm).
    pub filament_diameter_mm: f64,
    /// Nozzle diameter (mm).
    pub nozzle_diameter_mm: f64,
    /// Acceleration (mm/s²).
    pub accel_mm_s2: Option<f64>,
    /// Klipper's square-corner velocity (mm/s).
    pub square_corner_velocity_mm_s: Option<f64>,
    /// Klipper's minimum cruise ratio (0 to < 1).
    pub minimum_cruise_ratio: Option<f64>,
    /// Klipper's `max_velocity` (mm/s).
    pub max_velocity_mm_s: Option<f64>,
    /// Marlin's classic X/Y jerk (mm/s).
    pub jerk_mm_s: Option<f64>,
    /// Pressure (linear) advance where the G-code starts (s).
    pub pressure_advance_s: Option<f64>,
    /// Klipper's pressure-advance smooth time (s).
    pub smooth_time_s: Option<f64>,
}

/// The firmware's name as `dataset.toml` spells it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FirmwareName {
    /// Klipper.
    Klipper,
    /// Marlin.
    Marlin,
}

/// A setting the dataset left out and the G-code does not set: what was assumed.
#[derive(Debug, Clone, PartialEq)]
pub struct Assumption {
    /// The `[printer_settings]` key.
    pub setting: &'static str,
    /// The value used.
    pub value: f64,
    /// Why this value.
    pub why: &'static str,
}

/// One photo.
#[derive(Debug, Clone, PartialEq)]
pub struct Photo {
    /// Unique id (letters, digits, `_`, `-`).
    pub photo_id: String,
    /// The image file (inside the dataset folder).
    pub image: PathBuf,
    /// Further columns of `photos.csv`: (column, value as written), in column order.
    pub extra: Vec<(String, String)>,
}

/// A whole `fdm-photos` dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct FdmPhotos {
    /// The folder it was read from.
    pub dir: PathBuf,
    /// Its `dataset.toml` without `[printer_settings]`.
    pub manifest: DatasetManifest,
    /// `[printer_settings]` as given.
    pub printer: PrinterSettings,
    /// The settings the G-code starts from (given or assumed).
    pub start: StartSettings,
    /// What was assumed, for settings left out that the G-code does not set.
    pub assumed: Vec<Assumption>,
    /// The G-code's moves.
    pub gcode: GcodeProgram,
    /// The print's straight lines, planned from `start`.
    pub lines: Vec<PrintedLine>,
    /// The photos, in `photos.csv` order.
    pub photos: Vec<Photo>,
}

impl FdmPhotos {
    /// Reads and checks a dataset folder: `dataset.toml`, the G-code (planned into its
    /// lines) and `photos.csv` (each image present, inside the folder, `.jpg`, `.jpeg`
    /// or `.png`; not decoded).
    pub fn read(dir: &Path) -> Result<Self, DatasetError> {
        let (manifest, printer) = read_manifest(dir)?;
        let (start, defaulted) = start_settings(&printer);
        let gcode_file = file_in(dir, GCODE_FILE)?;
        let gcode = read_gcode(&gcode_file, &read_gcode_text(&gcode_file)?, start)?;
        let assumed = defaulted.into_iter().filter(|a| !gcode.sets.contains_key(setting_name(a.setting))).collect();
        let lines = plan_lines(&gcode_file, &gcode, printer.filament_diameter_mm)?;
        let photos = read_photos(dir)?;
        Ok(Self { dir: dir.to_path_buf(), manifest, printer, start, assumed, gcode, lines, photos })
    }

    /// The print's lines planned from other start settings (e.g. a fitted acceleration).
    pub fn replan(&self, start: StartSettings) -> Result<Vec<PrintedLine>, DatasetError> {
        let gcode_file = file_in(&self.dir, GCODE_FILE)?;
        let gcode = read_gcode(&gcode_file, &read_gcode_text(&gcode_file)?, start)?;
        plan_lines(&gcode_file, &gcode, self.printer.filament_diameter_mm)
    }
}

/// The name under which [`GcodeProgram::sets`] records a `[printer_settings]` key.
fn setting_name(key: &str) -> &str {
    match key {
        "accel_mm_s2" => "accel",
        "square_corner_velocity_mm_s" => "square_corner_velocity",
        "jerk_mm_s" => "jerk",
        "pressure_advance_s" => "pressure_advance",
        "smooth_time_s" => "smooth_time",
        other => other,
    }
}

fn read_gcode_text(file: &Path) -> Result<String, DatasetError> {
    if let Ok(meta) = std::fs::metadata(file) {
        if meta.len() > MAX_GCODE_BYTES as u64 {
            return Err(DatasetError::Malformed {
                file: file.to_path_buf(),
                location: None,
                expected: format!("expected at most {MAX_GCODE_BYTES} bytes of G-code, got {}", meta.len()),
            });
        }
    }
    read_text(file)
}

fn plan_lines(file: &Path, gcode: &GcodeProgram, filament_diameter_mm: f64) -> Result<Vec<PrintedLine>, DatasetError> {
    let planned = plan(&gcode.moves).map_err(|e| {
        let index = match &e {
            models::fdm::planner::PlanError::NotPositive { index, .. } => *index,
            models::fdm::planner::PlanError::NotFinite { index } => *index,
        };
        DatasetError::at_line(file, gcode.move_lines[index], format!("cannot plan this move: {e}"))
    })?;
    Ok(printed_lines(&gcode.moves, &planned, filament_diameter_mm))
}

/// `dataset.toml`: the common manifest and `[printer_settings]`.
fn read_manifest(dir: &Path) -> Result<(DatasetManifest, PrinterSettings), DatasetError> {
    check_dataset_folder(dir)?;
    let file = file_in(dir, MANIFEST_FILE)?;
    let mut table: toml::Table = read_toml(&file)?;
    let bad = |key: &str, expected: String| DatasetError::Malformed {
        file: file.clone(),
        location: Some(key.into()),
        expected,
    };
    let kind = table.get("kind").and_then(|k| k.as_str()).unwrap_or("");
    if kind != KIND {
        return Err(bad("kind", format!("expected kind `{KIND}`, got `{kind}`")));
    }
    let settings = printer_settings(dir, &mut table).ok_or_else(|| {
        bad(
            SETTINGS_TABLE,
            "expected a [printer] (or [printer_settings]) table with firmware, filament_diameter_mm, nozzle_diameter_mm".into(),
        )
    })?;
    let manifest: DatasetManifest =
        toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| bad("manifest", one_line(&e)))?;
    if !READABLE_VERSIONS.contains(&manifest.format_version) {
        let expected = format!(
            "this build of amrepro reads `{KIND}` format_version {FORMAT_VERSION}, got {}; a newer amrepro may read it",
            manifest.format_version
        );
        return Err(bad("format_version", expected));
    }
    let printer: PrinterSettings =
        settings.try_into().map_err(|e: toml::de::Error| bad(SETTINGS_TABLE, one_line(&e)))?;
    check_settings(&file, &printer)?;
    Ok((manifest, printer))
}

/// The printer's settings: a `[printer]` table (its `name`, or else the folder's name,
/// becomes the manifest's `printer`), or `[printer_settings]` beside `printer = "name"`.
fn printer_settings(dir: &Path, table: &mut toml::Table) -> Option<toml::Value> {
    if let Some(toml::Value::Table(mut settings)) = table.get(PRINTER_TABLE).filter(|v| v.is_table()).cloned() {
        let folder = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let name = match settings.remove("name") {
            Some(toml::Value::String(name)) => name,
            _ => folder,
        };
        table.insert(PRINTER_TABLE.into(), toml::Value::String(name));
        return Some(toml::Value::Table(settings));
    }
    table.remove(SETTINGS_TABLE)
}

fn one_line(e: &toml::de::Error) -> String {
    e.to_string().trim().replace('\n', " ")
}

fn check_settings(file: &Path, p: &PrinterSettings) -> Result<(), DatasetError> {
    use NumberRule::{Below, Within};
    let mut checks = vec![
        ("printer_settings.filament_diameter_mm", p.filament_diameter_mm, Within(0.1, 10.0)),
        ("printer_settings.nozzle_diameter_mm", p.nozzle_diameter_mm, Within(0.01, 10.0)),
    ];
    let optional = [
        ("printer_settings.accel_mm_s2", p.accel_mm_s2, Within(1.0, 1e6)),
        ("printer_settings.square_corner_velocity_mm_s", p.square_corner_velocity_mm_s, Within(0.01, 1000.0)),
        ("printer_settings.minimum_cruise_ratio", p.minimum_cruise_ratio, Below(0.0, 1.0)),
        ("printer_settings.max_velocity_mm_s", p.max_velocity_mm_s, Within(0.1, 1e5)),
        ("printer_settings.jerk_mm_s", p.jerk_mm_s, Within(0.01, 1000.0)),
        ("printer_settings.pressure_advance_s", p.pressure_advance_s, Within(0.0, 2.0)),
        ("printer_settings.smooth_time_s", p.smooth_time_s, Within(0.0, 0.2)),
    ];
    checks.extend(optional.into_iter().filter_map(|(k, v, r)| v.map(|v| (k, v, r))));
    check_numbers(file, &checks)
}

/// The settings the G-code starts from, and what was assumed for those left out.
fn start_settings(p: &PrinterSettings) -> (StartSettings, Vec<Assumption>) {
    let mut assumed = Vec::new();
    let mut value = |key: &'static str, given: Option<f64>, relevant: bool| -> f64 {
        let (_, default, why) = ASSUMED_DEFAULTS.iter().find(|(k, ..)| *k == key).copied().unwrap_or((key, 0.0, ""));
        given.unwrap_or_else(|| {
            if relevant {
                assumed.push(Assumption { setting: key, value: default, why });
            }
            default
        })
    };
    let klipper = p.firmware == FirmwareName::Klipper;
    let start = StartSettings {
        firmware: if klipper { Firmware::Klipper } else { Firmware::Marlin },
        accel_mm_s2: value("accel_mm_s2", p.accel_mm_s2, true),
        square_corner_velocity_mm_s: value("square_corner_velocity_mm_s", p.square_corner_velocity_mm_s, klipper),
        minimum_cruise_ratio: value("minimum_cruise_ratio", p.minimum_cruise_ratio, klipper),
        max_velocity_mm_s: value("max_velocity_mm_s", p.max_velocity_mm_s, klipper),
        extruder_corner_mm_s: 1.0,
        jerk_mm_s: value("jerk_mm_s", p.jerk_mm_s, !klipper),
        jerk_z_mm_s: 0.3,
        pressure_advance_s: value("pressure_advance_s", p.pressure_advance_s, true),
        smooth_time_s: value("smooth_time_s", p.smooth_time_s.or((!klipper).then_some(0.0)), klipper),
    };
    (start, assumed)
}

/// `photos.csv`: ids unique, images inside the folder, present, JPEG or PNG by name.
fn read_photos(dir: &Path) -> Result<Vec<Photo>, DatasetError> {
    let table = CsvTable::read(&file_in(dir, PHOTOS_FILE)?)?;
    let (id_col, image_col) = (table.column("photo_id")?, table.column("image")?);
    table.rows_with_unique_ids(
        id_col,
        |p: &Photo| &p.photo_id,
        |row| {
            let photo_id = row.1[id_col].clone();
            if photo_id.is_empty() || !photo_id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
                return Err(table.field_error(row.0, id_col, "expected a non-empty id of letters, digits, `_`, `-`"));
            }
            let raw = &row.1[image_col];
            let image = referenced_file(dir, raw).map_err(|rule| table.field_error(row.0, image_col, rule))?;
            check_image(&image, raw).map_err(|e| table.field_error(row.0, image_col, e))?;
            let extra = (0..table.header.len())
                .filter(|&c| c != id_col && c != image_col)
                .map(|c| (table.header[c].clone(), row.1[c].clone()))
                .collect();
            Ok(Photo { photo_id, image, extra })
        },
    )
}

fn check_image(image: &Path, raw: &str) -> Result<(), String> {
    let ext = image.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    if !IMAGE_EXTENSIONS.contains(&ext.as_str()) {
        return Err(format!("expected a .jpg, .jpeg or .png image, got `{raw}`"));
    }
    if !image.is_file() {
        return Err(format!("expected an image file, `{raw}` is missing"));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
