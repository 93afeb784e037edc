//! Importer of the real FSU line-width data (paper 000's own measurements, from the
//! public repository FAMU-FSU-IME/IISE-Co-learning, `Linewidth_Data.zip`) into
//! `fdm-widths` datasets, one per printer.
//!
//! Each source file `S{a}F{F}_{tag}120.csv` holds `position_mm,width_mm` rows without
//! header for one 120 mm line printed at acceleration `a` (mm/s²) and feed `F`
//! (mm/min). Per the data's README (the authors' own analysis code), every line starts
//! and ends at the jerk speed of 8 mm/s. Each file is checked against the SHA-256 of
//! the published release below.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::csv_table::read_xy;
use crate::error::DatasetError;
use crate::fdm_widths::{
    check_sample, FdmWidthsDataset, LineMotion, SampleProblem, WidthLine, FORMAT_VERSION, KIND, READABLE_VERSIONS,
};
use crate::manifest::{DatasetManifest, Provenance};
use crate::output::{OutputDir, Ownership};

/// Where to get the data when it is missing.
pub const SOURCE_HINT: &str = "Get the FSU line-width data (paper 000, Table I lines): unzip `Linewidth_Data.zip` of the public repository FAMU-FSU-IME/IISE-Co-learning (Apache-2.0) so that taz5/ and taz6/ sit in this folder, or set AMREPRO_DATA to a folder holding fsu-linewidth/";

/// Start and end speed of every line (mm/s): the Taz firmware's jerk (data README).
pub const JERK_MM_S: f64 = 8.0;
/// Length of every printed line (mm).
pub const LINE_LENGTH_MM: f64 = 120.0;

/// SHA-256 of every file of the published release.
pub const CHECKSUMS: [(&str, &str); 18] = [
    ("taz5/S400F3000_xiao120.csv", "e77927cdf622a87133cd5548c3b13afde14a80e1ecc1e186f09970f59d38d24d"),
    ("taz5/S400F6000_xiao120.csv", "0c8544ca1246b9d6b7cbb0918b051d8ad0f98a15ba2d870357d9aa3f4b0cebd3"),
    ("taz5/S400F9000_xiao120.csv", "d311e19a1142276a3ac48297943b6c478152127979abce5df650651a7b629525"),
    ("taz5/S600F3000_xiao120.csv", "c6e7843fde945754585a311f44ba84c6491d5a1edda68880114feece26a2cf1a"),
    ("taz5/S600F6000_xiao120.csv", "76c8fac005489f98326d2e0a47663268f626c542e32d38220702878e5364b168"),
    ("taz5/S600F9000_xiao120.csv", "00815ad93e85061b7ace5aa272d5ade0d7f93c87ef93c791257e67209ccc1a98"),
    ("taz5/S800F3000_xiao120.csv", "2e4e8ec086c9b5c5ad04452d0524755f1fbe06a71d402ee8f6d10ab0120b8866"),
    ("taz5/S800F6000_xiao120.csv", "69639d591f2f7e826a0dea72d840a69331ed27a888349bfaf60271b4b1f857b3"),
    ("taz5/S800F9000_xiao120.csv", "ece3a782686fdf4d69dba21639019501d026647b838846534a03c9b8b1d34aca"),
    ("taz6/S400F3000_ino120.csv", "c580206d0c9dba6988594974bddb9e649e63ae8aaf86ceb933dc4e8802d5b8b5"),
    ("taz6/S400F6000_ino120.csv", "bf3a3bef13de828b722ce7d9b42084ac1311f4fd7a95b538aba933c110f5c412"),
    ("taz6/S400F9000_ino120.csv", "c76df976c2e20709887490ca8eeb9df24add82fffefd38a7a9613deedc150d88"),
    ("taz6/S600F3000_ino120.csv", "549b9ba11c0352835e91b10bc68f3ab346fd40162c4b6d9d341b36de6a2b676c"),
    ("taz6/S600F6000_ino120.csv", "51e1bd8c2877009cc7a95c4b6d9cd1300f2ab2524e9a54e19f2718e33cf81e88"),
    ("taz6/S600F9000_ino120.csv", "41b2184fe6d6d82481503d3c19b5a461ae95f5ae6ded6cc0c5a5162d0727ff77"),
    ("taz6/S800F3000_ino120.csv", "61a28cc4b423b4a1f56387b53ef608fe8ae59d91174170abb06879a783988219"),
    ("taz6/S800F6000_ino120.csv", "ad0c57702c600731023bc392f71725b27b89f3b8a669631574a061fc8b091f66"),
    ("taz6/S800F9000_ino120.csv", "c079502ca963cad4167eeaa087d17e92e19e364279569b87d1205f5b90bc009f"),
];

/// The two printers of the release.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FsuPrinter {
    /// LulzBot Taz 5: the data-rich source printer, lines start with a blob.
    Taz5,
    /// LulzBot Taz 6: the data-limited target printer, no start blob.
    Taz6,
}

impl FsuPrinter {
    /// Both printers.
    pub const ALL: [Self; 2] = [Self::Taz5, Self::Taz6];

    /// Their names, in the order of [`FsuPrinter::ALL`].
    pub const NAMES: [&'static str; 2] = ["taz5", "taz6"];

    /// Name used as folder and `printer` value.
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// Parses `taz5` / `taz6`.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }

    fn file_tag(self) -> &'static str {
        match self {
            Self::Taz5 => "xiao",
            Self::Taz6 => "ino",
        }
    }

    fn description(self) -> &'static str {
        match self {
            Self::Taz5 => "LulzBot Taz 5, 0.5 mm nozzle, PLA: 9 single 120 mm lines, a ∈ {400, 600, 800} mm/s² × F ∈ {50, 100, 150} mm/s (paper 000 Table I); widths measured from camera images by the authors (paper 000 Sec. III).",
            Self::Taz6 => "LulzBot Taz 6, 0.5 mm nozzle, PLA: 9 single 120 mm lines, a ∈ {400, 600, 800} mm/s² × F ∈ {50, 100, 150} mm/s (paper 000 Table I); no start blob (paper 000 Fig. 8).",
        }
    }
}

/// Acceleration and feed decoded from a file name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FileCondition {
    /// Commanded acceleration (mm/s²).
    pub accel_mm_s2: u32,
    /// Commanded feed (mm/min, as in G-code).
    pub feed_mm_min: u32,
}

impl FileCondition {
    /// The condition label `S{a}F{F}`.
    pub fn label(&self) -> String {
        format!("S{}F{}", self.accel_mm_s2, self.feed_mm_min)
    }
}

/// Decodes `S{a}F{F}_{tag}120.csv`; `Err` says what was expected.
pub fn parse_file_name(name: &str, printer: FsuPrinter) -> Result<FileCondition, String> {
    let expected = || {
        format!("expected a file name like `S800F9000_{}120.csv` (S<accel mm/s²>F<feed mm/min>)", printer.file_tag())
    };
    let stem = name.strip_suffix(&format!("_{}120.csv", printer.file_tag())).ok_or_else(expected)?;
    let (accel, feed) = stem.strip_prefix('S').and_then(|s| s.split_once('F')).ok_or_else(expected)?;
    let number = |s: &str| s.parse::<u32>().ok().filter(|v| *v > 0 && s.chars().all(|c| c.is_ascii_digit()));
    match (number(accel), number(feed)) {
        (Some(accel_mm_s2), Some(feed_mm_min)) => Ok(FileCondition { accel_mm_s2, feed_mm_min }),
        _ => Err(expected()),
    }
}

/// Import options.
#[derive(Debug, Clone, Copy)]
pub struct ImportOptions {
    /// Check every file against [`CHECKSUMS`] and require all 9 files per printer.
    /// Off only for data of one's own in the same layout.
    pub verify_sha256: bool,
}

/// Reads one printer's folder under `src_root` into an `fdm-widths` dataset.
pub fn read_printer(
    src_root: &Path,
    printer: FsuPrinter,
    opts: ImportOptions,
) -> Result<FdmWidthsDataset, DatasetError> {
    let folder = src_root.join(printer.name());
    if !folder.is_dir() {
        return Err(DatasetError::Missing { file: folder, hint: Some(SOURCE_HINT.into()) });
    }
    let files = source_files(&folder, printer)?;
    if opts.verify_sha256 {
        require_all_published(src_root, printer, &files)?;
    }
    let lines = files.iter().map(|(path, cond)| read_line(src_root, path, *cond, opts)).collect::<Result<_, _>>()?;
    Ok(FdmWidthsDataset { manifest: manifest(printer), lines })
}

/// The folders `import` may replace: absent, empty, or an `fdm-widths` dataset this
/// importer wrote.
pub const OUTPUT: Ownership = Ownership {
    kind: KIND,
    versions: READABLE_VERSIONS,
    writer: "datasets import fsu-linewidth",
    written_by_us: |p| matches!(p, Provenance::Measured { imported_by, .. } if imported_by.starts_with("amrepro ")),
};

/// Imports the given printers into `out_dir/<printer>/`, each folder written whole
/// ([`OutputDir`]: every destination checked first, staged, then swapped in), so a
/// failure leaves no partial dataset and nothing that is not ours is replaced.
pub fn import(
    src_root: &Path,
    out_dir: &Path,
    printers: &[FsuPrinter],
    opts: ImportOptions,
) -> Result<Vec<PathBuf>, DatasetError> {
    let datasets: Vec<FdmWidthsDataset> =
        printers.iter().map(|p| read_printer(src_root, *p, opts)).collect::<Result<_, _>>()?;
    let outputs: Vec<OutputDir> =
        printers.iter().map(|p| OutputDir::begin(&out_dir.join(p.name()), &OUTPUT)).collect::<Result<_, _>>()?;
    for (output, dataset) in outputs.iter().zip(&datasets) {
        dataset.write(output.path())?;
    }
    outputs.into_iter().map(OutputDir::commit).collect()
}

/// The CSV files of a printer folder with their decoded conditions, sorted by
/// acceleration then feed.
fn source_files(folder: &Path, printer: FsuPrinter) -> Result<Vec<(PathBuf, FileCondition)>, DatasetError> {
    let mut files: Vec<(PathBuf, FileCondition)> = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(|e| DatasetError::io(folder, e))? {
        let path = entry.map_err(|e| DatasetError::io(folder, e))?.path();
        let name = path.file_name().unwrap_or_default().to_string_lossy().to_string();
        if !name.ends_with(".csv") {
            continue;
        }
        let cond = parse_file_name(&name, printer).map_err(|expected| DatasetError::Malformed {
            file: path.clone(),
            location: Some("file name".into()),
            expected,
        })?;
        if let Some((other, _)) = files.iter().find(|(_, c)| c.label() == cond.label()) {
            return Err(DatasetError::Malformed {
                file: path.clone(),
                location: Some("file name".into()),
                expected: format!("expected one file per condition, {} is {} again", other.display(), cond.label()),
            });
        }
        files.push((path, cond));
    }
    if files.is_empty() {
        return Err(DatasetError::Missing { file: folder.join("*.csv"), hint: Some(SOURCE_HINT.into()) });
    }
    files.sort_by_key(|(_, c)| (c.accel_mm_s2, c.feed_mm_min));
    Ok(files)
}

fn require_all_published(
    src_root: &Path,
    printer: FsuPrinter,
    files: &[(PathBuf, FileCondition)],
) -> Result<(), DatasetError> {
    let prefix = format!("{}/", printer.name());
    for (rel, _) in CHECKSUMS.iter().filter(|(rel, _)| rel.starts_with(&prefix)) {
        let path = src_root.join(rel);
        if !files.iter().any(|(p, _)| *p == path) {
            return Err(DatasetError::Missing { file: path, hint: Some(SOURCE_HINT.into()) });
        }
    }
    Ok(())
}

fn read_line(
    src_root: &Path,
    path: &Path,
    cond: FileCondition,
    opts: ImportOptions,
) -> Result<WidthLine, DatasetError> {
    if opts.verify_sha256 {
        verify_checksum(src_root, path)?;
    }
    let (positions_mm, widths_mm) = read_widths(path)?;
    let motion = LineMotion {
        accel_mm_s2: f64::from(cond.accel_mm_s2),
        feed_mm_s: f64::from(cond.feed_mm_min) / 60.0,
        jerk_mm_s: JERK_MM_S,
        length_mm: LINE_LENGTH_MM,
    };
    Ok(WidthLine { line_id: cond.label(), condition: cond.label(), motion, positions_mm, widths_mm })
}

/// The `position_mm,width_mm` rows of a raw file, each checked as the `fdm-widths`
/// reader checks it, so a bad row is named in the raw file, not in the converted copy.
fn read_widths(path: &Path) -> Result<(Vec<f64>, Vec<f64>), DatasetError> {
    let rows = read_xy(path, "position_mm,width_mm")?;
    let mut positions: Vec<f64> = Vec::with_capacity(rows.len());
    let mut widths = Vec::with_capacity(rows.len());
    for (line, x, w) in rows {
        check_sample(positions.last().copied(), x, w, LINE_LENGTH_MM).map_err(|problem| {
            let (column, e) = match problem {
                SampleProblem::Position(e) => ("position_mm", e),
                SampleProblem::Width(e) => ("width_mm", e),
            };
            DatasetError::Malformed {
                file: path.to_path_buf(),
                location: Some(format!("line {line}, field {column}")),
                expected: e,
            }
        })?;
        positions.push(x);
        widths.push(w);
    }
    Ok((positions, widths))
}

fn verify_checksum(src_root: &Path, path: &Path) -> Result<(), DatasetError> {
    let rel = path.strip_prefix(src_root).unwrap_or(path).to_string_lossy().replace('\\', "/");
    let bytes = std::fs::read(path).map_err(|e| DatasetError::io(path, e))?;
    let actual: String = Sha256::digest(&bytes).iter().map(|b| format!("{b:02x}")).collect();
    match CHECKSUMS.iter().find(|(name, _)| *name == rel) {
        Some((_, expected)) if *expected == actual => Ok(()),
        Some((_, expected)) => {
            Err(DatasetError::Checksum { file: path.to_path_buf(), expected: expected.to_string(), actual })
        }
        None => Err(DatasetError::Malformed {
            file: path.to_path_buf(),
            location: Some("file name".into()),
            expected: "not a file of the published release; import it with checksum verification off".into(),
        }),
    }
}

fn manifest(printer: FsuPrinter) -> DatasetManifest {
    DatasetManifest {
        kind: KIND.into(),
        format_version: FORMAT_VERSION,
        printer: printer.name().into(),
        description: printer.description().into(),
        units: crate::fdm_widths::units_table(&crate::fdm_widths::UNITS),
        provenance: Provenance::Measured {
            source: "FAMU-FSU-IME/IISE-Co-learning, Linewidth_Data.zip (sha256 30fe042feb5dbae124fa844c570da0f285b4dd13e73b2f9055b090e83c7bf169)".into(),
            license: "Apache-2.0".into(),
            imported_by: format!("amrepro {}", env!("CARGO_PKG_VERSION")),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn real_data() -> Option<PathBuf> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/fsu-linewidth");
        dir.is_dir().then_some(dir)
    }

    #[test]
    fn file_names_decode_to_kinematics() {
        let c = parse_file_name("S800F9000_xiao120.csv", FsuPrinter::Taz5).unwrap();
        assert_eq!((c.accel_mm_s2, c.feed_mm_min), (800, 9000));
        assert_eq!(c.label(), "S800F9000");
        for bad in [
            "S800F9000_ino120.csv",
            "S8x0F9000_xiao120.csv",
            "800F9000_xiao120.csv",
            "S800F-900_xiao120.csv",
            "S0F9000_xiao120.csv",
        ] {
            assert!(parse_file_name(bad, FsuPrinter::Taz5).is_err(), "{bad}");
        }
    }

    #[test]
    fn imports_the_real_release_with_checksums() {
        let Some(src) = real_data() else {
            panic!("data/fsu-linewidth is missing: {SOURCE_HINT}");
        };
        let opts = ImportOptions { verify_sha256: true };
        let taz5 = read_printer(&src, FsuPrinter::Taz5, opts).unwrap();
        assert_eq!(taz5.lines.len(), 9);
        let fast = taz5.lines.iter().find(|l| l.condition == "S800F9000").unwrap();
        assert_eq!(fast.motion.feed_mm_s, 150.0, "9000 mm/min = 150 mm/s");
        assert_eq!(fast.motion.accel_mm_s2, 800.0);
        assert!(fast.positions_mm.len() > 2000);
    }

    #[test]
    fn modified_file_fails_its_checksum() {
        let Some(src) = real_data() else {
            panic!("data/fsu-linewidth is missing: {SOURCE_HINT}");
        };
        let dir = tempfile::tempdir().unwrap();
        let taz5 = dir.path().join("taz5");
        std::fs::create_dir_all(&taz5).unwrap();
        for (rel, _) in CHECKSUMS.iter().filter(|(r, _)| r.starts_with("taz5/")) {
            std::fs::copy(src.join(rel), dir.path().join(rel)).unwrap();
        }
        let victim = taz5.join("S400F3000_xiao120.csv");
        let text = std::fs::read_to_string(&victim).unwrap().replacen("0.764326", "0.764327", 1);
        std::fs::write(&victim, text).unwrap();
        let err = read_printer(dir.path(), FsuPrinter::Taz5, ImportOptions { verify_sha256: true }).unwrap_err();
        assert!(matches!(err, DatasetError::Checksum { .. }), "{err}");
        assert!(read_printer(dir.path(), FsuPrinter::Taz5, ImportOptions { verify_sha256: false }).is_ok());
    }

    /// A taz5 folder of our own (no checksums) with one file `name` holding `text`.
    fn own_folder(name: &str, text: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("taz5")).unwrap();
        std::fs::write(dir.path().join("taz5").join(name), text).unwrap();
        dir
    }

    #[test]
    fn unverified_files_are_checked_at_import_and_named_in_the_raw_file() {
        let opts = ImportOptions { verify_sha256: false };
        let cases = [
            (
                "0,0.5\n1,0.6\n0.5,0.7\n",
                "S400F3000_xiao120.csv:line 3, field position_mm: expected increasing positions",
            ),
            ("0,0.5\n1,-0.6\n", "S400F3000_xiao120.csv:line 2, field width_mm: expected a positive width, got -0.6"),
            (
                "0,0.5\n130,0.6\n",
                "S400F3000_xiao120.csv:line 2, field position_mm: expected increasing positions within [0, 120] mm",
            ),
        ];
        for (text, expected) in cases {
            let src = own_folder("S400F3000_xiao120.csv", text);
            let out = tempfile::tempdir().unwrap();
            let err = import(src.path(), out.path(), &[FsuPrinter::Taz5], opts).unwrap_err().to_string();
            assert!(err.contains(expected), "{err}");
            assert!(std::fs::read_dir(out.path()).unwrap().next().is_none(), "nothing written");
        }
        let src = own_folder("S400F3000_xiao120.csv", "0,0.5\n1,0.6\n");
        std::fs::write(src.path().join("taz5/S0400F3000_xiao120.csv"), "0,0.5\n").unwrap();
        let err = read_printer(src.path(), FsuPrinter::Taz5, opts).unwrap_err().to_string();
        assert!(err.contains("expected one file per condition") && err.contains("S400F3000 again"), "{err}");
    }

    #[test]
    fn import_replaces_its_own_output_and_refuses_a_foreign_folder() {
        let opts = ImportOptions { verify_sha256: false };
        let src = own_folder("S400F3000_xiao120.csv", "0,0.5\n1,0.6\n");
        let out = tempfile::tempdir().unwrap();
        import(src.path(), out.path(), &[FsuPrinter::Taz5], opts).unwrap();
        import(src.path(), out.path(), &[FsuPrinter::Taz5], opts).unwrap();
        std::fs::remove_dir_all(out.path().join("taz5")).unwrap();
        std::fs::create_dir_all(out.path().join("taz5")).unwrap();
        std::fs::write(out.path().join("taz5/thesis.tex"), "years of work").unwrap();
        let err = import(src.path(), out.path(), &[FsuPrinter::Taz5], opts).unwrap_err().to_string();
        assert!(err.contains("refusing to replace it"), "{err}");
        assert_eq!(std::fs::read_to_string(out.path().join("taz5/thesis.tex")).unwrap(), "years of work");
        let listing: Vec<_> = std::fs::read_dir(out.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(listing, ["taz5"], "no staging folder left");
    }

    #[test]
    fn missing_folder_says_where_to_get_the_data() {
        let dir = tempfile::tempdir().unwrap();
        let err =
            read_printer(dir.path(), FsuPrinter::Taz6, ImportOptions { verify_sha256: true }).unwrap_err().to_string();
        assert!(err.contains("IISE-Co-learning") && err.contains("AMREPRO_DATA"), "{err}");
    }
}
