//! A lab's folder as it comes (a G-code file and a folder of photos, beside whatever else)
//! made into an `fdm-photos` dataset: `dataset.toml` written from the options, the G-code
//! copied to `print.gcode`, every JPEG or PNG of the photo folder (sorted by name) copied
//! to `photos/` and listed in `photos.csv` with its file stem as `photo_id` (characters
//! other than letters, digits, `_` and `-` become `_`). The result is read back with
//! [`super::FdmPhotos::read`], so an import never yields a dataset the reader refuses.

use std::path::{Path, PathBuf};

use super::{FdmPhotos, FirmwareName, GCODE_FILE, IMAGE_EXTENSIONS, PHOTOS_FILE};
use crate::error::DatasetError;
use crate::limits::MAX_GCODE_BYTES;
use crate::manifest::MANIFEST_FILE;
use crate::output::write_file;
use crate::paths::referenced_file;

/// What the folder does not say.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// The printer's name.
    pub printer: String,
    /// The firmware that ran the G-code.
    pub firmware: FirmwareName,
    /// Filament diameter (mm).
    pub filament_diameter_mm: f64,
    /// Nozzle diameter (mm).
    pub nozzle_diameter_mm: f64,
    /// The G-code file, relative to the folder.
    pub gcode: String,
    /// The photo folder, relative to the folder.
    pub photos: String,
    /// Where the photos come from (the provenance's `source`).
    pub source: String,
    /// Their licence.
    pub license: String,
}

/// Writes the dataset into `out` (an empty folder) and returns it as read back.
pub fn import(raw: &Path, opts: &ImportOptions, out: &Path) -> Result<FdmPhotos, DatasetError> {
    let gcode = referenced_file(raw, &opts.gcode).map_err(|expected| bad(raw, "gcode", expected))?;
    let size = std::fs::metadata(&gcode).map_err(|e| DatasetError::io(&gcode, e))?.len();
    if size > MAX_GCODE_BYTES as u64 {
        return Err(bad(&gcode, "size", format!("expected a G-code of at most {MAX_GCODE_BYTES} bytes, got {size}")));
    }
    write_file(out, GCODE_FILE, &std::fs::read(&gcode).map_err(|e| DatasetError::io(&gcode, e))?)?;
    let photos = photo_files(raw, &opts.photos)?;
    let mut csv = String::from("photo_id,image\n");
    for photo in &photos {
        let name = photo.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        write_file(
            out,
            Path::new("photos").join(&name),
            &std::fs::read(photo).map_err(|e| DatasetError::io(photo, e))?,
        )?;
        csv.push_str(&format!("{},photos/{name}\n", photo_id(photo)));
    }
    write_file(out, PHOTOS_FILE, csv.as_bytes())?;
    write_file(out, MANIFEST_FILE, manifest(opts, photos.len()).as_bytes())?;
    FdmPhotos::read(out)
}

/// The JPEG and PNG files of the photo folder, sorted by name; an error if there are none.
fn photo_files(raw: &Path, folder: &str) -> Result<Vec<PathBuf>, DatasetError> {
    let dir = referenced_file(raw, folder).map_err(|expected| bad(raw, "photos", expected))?;
    let entries = std::fs::read_dir(&dir).map_err(|e| DatasetError::io(&dir, e))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter(|p| {
            p.extension()
                .and_then(|x| x.to_str())
                .is_some_and(|x| IMAGE_EXTENSIONS.contains(&x.to_ascii_lowercase().as_str()))
        })
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(bad(
            &dir,
            "photos",
            format!("expected at least one .jpg, .jpeg or .png photo in {}", dir.display()),
        ));
    }
    Ok(files)
}

fn photo_id(photo: &Path) -> String {
    let stem = photo.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect()
}

fn manifest(opts: &ImportOptions, photos: usize) -> String {
    let firmware = match opts.firmware {
        FirmwareName::Klipper => "klipper",
        FirmwareName::Marlin => "marlin",
    };
    let quoted = |s: &str| toml::Value::String(s.to_string()).to_string();
    format!(
        "kind = \"fdm-photos\"\nformat_version = 1\nprinter = {}\ndescription = {}\n\n[units]\nlength = \"mm\"\n\n[provenance]\ntype = \"measured\"\nsource = {}\nlicense = {}\nimported_by = {}\n\n[printer_settings]\nfirmware = \"{firmware}\"\nfilament_diameter_mm = {}\nnozzle_diameter_mm = {}\n",
        quoted(&opts.printer),
        quoted(&format!("{photos} photos of a print and its G-code ({})", opts.gcode)),
        quoted(&opts.source),
        quoted(&opts.license),
        quoted(&format!("amrepro {}", env!("CARGO_PKG_VERSION"))),
        opts.filament_diameter_mm,
        opts.nozzle_diameter_mm,
    )
}

fn bad(file: &Path, field: &str, expected: String) -> DatasetError {
    DatasetError::Malformed { file: file.to_path_buf(), location: Some(field.into()), expected }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options() -> ImportOptions {
        ImportOptions {
            printer: "lab".into(),
            firmware: FirmwareName::Klipper,
            filament_diameter_mm: 1.75,
            nozzle_diameter_mm: 0.4,
            gcode: "pattern.gcode".into(),
            photos: "shots".into(),
            source: "our lab".into(),
            license: "CC0-1.0".into(),
        }
    }

    #[test]
    fn a_folder_of_photos_and_gcode_imports_and_reads_back() {
        let raw = tempfile::tempdir().unwrap();
        let out = tempfile::tempdir().unwrap();
        std::fs::create_dir(raw.path().join("shots")).unwrap();
        std::fs::write(
            raw.path().join("pattern.gcode"),
            "G21\nG90\nM83\nG1 Z0.2 F600\nG1 X10 Y0 E0.5 F600\nG1 X20 Y0 E0.5\n",
        )
        .unwrap();
        for name in ["b plate.JPG", "a.png", "notes.txt"] {
            std::fs::write(raw.path().join("shots").join(name), b"x").unwrap();
        }
        let data = import(raw.path(), &options(), out.path()).unwrap();
        let ids: Vec<&str> = data.photos.iter().map(|p| p.photo_id.as_str()).collect();
        assert_eq!(ids, ["a", "b_plate"]);
        assert_eq!(data.lines.len(), 1);
        assert_eq!(data.manifest.printer, "lab");
    }

    #[test]
    fn a_folder_without_photos_or_gcode_is_refused_naming_it() {
        let raw = tempfile::tempdir().unwrap();
        let out = tempfile::tempdir().unwrap();
        std::fs::create_dir(raw.path().join("shots")).unwrap();
        let err = import(raw.path(), &options(), out.path()).unwrap_err().to_string();
        assert!(err.contains("pattern.gcode"), "{err}");
        std::fs::write(raw.path().join("pattern.gcode"), "G1 X1 E1\n").unwrap();
        let err = import(raw.path(), &options(), out.path()).unwrap_err().to_string();
        assert!(err.contains("expected at least one .jpg"), "{err}");
    }
}
