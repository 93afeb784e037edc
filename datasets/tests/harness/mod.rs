//! The readers' fuzz harness, shared by the bounded proptest runs
//! (`tests/fuzz_readers.rs`, part of `make test`) and the cargo-fuzz targets
//! (`fuzz/fuzz_targets/*.rs`, which include this file by path).
//!
//! A [`Workspace`] is a copy of one seed dataset (`tests/seeds/<kind>`). [`Workspace::check`]
//! overwrites one of its files with arbitrary bytes, runs the kind's public reader and
//! restores the file. The reader may return `Ok` or `Err` but must not panic or
//! allocate absurdly, and an `Ok` must hold the documented bounds. A fuzz input is one
//! selector byte (which file, modulo the kind's file count) followed by the file's bytes.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use datasets::fdm_lines::FdmLinesDataset;
use datasets::fdm_widths::FdmWidthsDataset;
use datasets::fsu::{read_printer, FsuPrinter, ImportOptions};
use datasets::inkjet::InkjetScans;
use datasets::limits::{GRID_SIDE_CELLS, IMAGE_SIDE_PX, LINE_IMAGE_PIXELS, LINE_IMAGE_SIDE_PX, MAX_COORDINATE_MM};
use datasets::thermal::{ThermalSequence, ThermalTruth};

/// The readers under test, one per fuzz target.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reader {
    /// `FdmWidthsDataset::read` (and `fdm_inject::read_truth`).
    FdmWidths,
    /// `InkjetScans::read` (and `read_truth`).
    InkjetScans,
    /// `ThermalSequence::open`.
    ThermalSequence,
    /// `ThermalTruth::open` and `deposit` (the PNG decoder of `truth/`).
    ThermalTruth,
    /// `fsu::read_printer` without checksums (the raw files `import --no-verify` reads).
    FsuRaw,
    /// `FdmLinesDataset::read` (its PNG headers) and `fdm_lines::generate::read_truth`.
    FdmLines,
}

impl Reader {
    /// Every reader.
    pub const ALL: [Self; 6] =
        [Self::FdmWidths, Self::InkjetScans, Self::ThermalSequence, Self::ThermalTruth, Self::FsuRaw, Self::FdmLines];

    /// The fuzz target's name (`fuzz/fuzz_targets/<name>.rs`, `tests/crashers/<name>/`).
    pub fn name(self) -> &'static str {
        match self {
            Self::FdmWidths => "fdm_widths",
            Self::InkjetScans => "inkjet_scans",
            Self::ThermalSequence => "thermal_sequence",
            Self::ThermalTruth => "thermal_truth",
            Self::FsuRaw => "fsu_raw",
            Self::FdmLines => "fdm_lines",
        }
    }

    /// The seed folder under `tests/seeds/`.
    fn seed(self) -> &'static str {
        match self {
            Self::FdmWidths => "fdm-widths",
            Self::InkjetScans => "inkjet-scans",
            Self::ThermalSequence | Self::ThermalTruth => "thermal-sequence",
            Self::FsuRaw => "fsu-raw",
            Self::FdmLines => "fdm-lines",
        }
    }

    /// The files the reader reads that the fuzzer overwrites.
    pub fn files(self) -> &'static [&'static str] {
        match self {
            Self::FdmWidths => &["dataset.toml", "lines.csv", "widths/a1000_f60.csv", "truth/effect.toml"],
            Self::InkjetScans => &["dataset.toml", "grid.toml", "target.csv", "scans.csv", "patterns.csv"],
            Self::ThermalSequence => {
                &["dataset.toml", "camera.toml", "process.toml", "path.csv", "trajectory.csv", "frames.csv"]
            }
            Self::ThermalTruth => &[
                "truth/truth.toml",
                "truth/frames.csv",
                "truth/corners.csv",
                "truth/widths.csv",
                "truth/deposit_L00.png",
            ],
            Self::FsuRaw => &["taz5/S400F3000_xiao120.csv"],
            Self::FdmLines => &[
                "dataset.toml",
                "lines.csv",
                "images/S400F3000.png",
                "truth/placement.csv",
                "truth/widths/S400F3000.csv",
            ],
        }
    }
}

/// The datasets crate's folder (this file is also built by the `fuzz/` crate beside it).
fn datasets_dir() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    if here.join("tests/seeds").is_dir() {
        here.to_path_buf()
    } else {
        here.join("../datasets")
    }
}

/// `tests/seeds` of the datasets crate.
pub fn seeds_root() -> PathBuf {
    datasets_dir().join("tests/seeds")
}

/// A writable copy of a reader's seed dataset.
pub struct Workspace {
    reader: Reader,
    _tmp: tempfile::TempDir,
    dir: PathBuf,
}

impl Workspace {
    /// Copies the seed of `reader` into a fresh temporary folder.
    pub fn new(reader: Reader) -> Self {
        let tmp = tempfile::tempdir().expect("temp dir");
        let dir = tmp.path().join("ds");
        copy_dir(&seeds_root().join(reader.seed()), &dir);
        Self { reader, _tmp: tmp, dir }
    }

    /// The seed's bytes of file `index` (modulo the file count).
    pub fn original(&self, index: usize) -> Vec<u8> {
        let name = self.file(index);
        std::fs::read(seeds_root().join(self.reader.seed()).join(name)).expect("seed file")
    }

    /// The name of file `index` (modulo the file count).
    pub fn file(&self, index: usize) -> &'static str {
        let files = self.reader.files();
        files[index % files.len()]
    }

    /// Runs the reader with `bytes` as file `index`; panics (the failure) only where
    /// the reader panics or an `Ok` breaks a documented bound.
    pub fn check(&self, index: usize, bytes: &[u8]) {
        let path = self.dir.join(self.file(index));
        std::fs::write(&path, bytes).expect("write fuzz input");
        self.read();
        std::fs::write(&path, self.original(index)).expect("restore seed file");
    }

    /// A fuzz input: selector byte, then the file's bytes.
    pub fn check_input(&self, data: &[u8]) {
        if let Some((&selector, bytes)) = data.split_first() {
            self.check(usize::from(selector), bytes);
        }
    }

    fn read(&self) {
        let dir = &self.dir;
        match self.reader {
            Reader::FdmWidths => {
                if let Ok(d) = FdmWidthsDataset::read(dir) {
                    for (i, l) in d.lines.iter().enumerate() {
                        assert!(d.lines[..i].iter().all(|o| o.line_id != l.line_id), "duplicate line_id read");
                        assert!(l.positions_mm.windows(2).all(|w| w[0] < w[1]), "positions not increasing");
                    }
                }
                let _ = datasets::fdm_inject::read_truth(dir);
            }
            Reader::InkjetScans => {
                if let Ok(s) = InkjetScans::read(dir) {
                    assert!(GRID_SIDE_CELLS.contains(&s.grid.m_x) && GRID_SIDE_CELLS.contains(&s.grid.m_y));
                    let _ = InkjetScans::read_truth(dir, &s.grid);
                }
            }
            Reader::ThermalSequence => {
                if let Ok(s) = ThermalSequence::open(dir) {
                    let c = &s.camera;
                    assert!(IMAGE_SIDE_PX.contains(&c.width_px) && IMAGE_SIDE_PX.contains(&c.height_px));
                    assert!(s.frames.iter().all(|f| f.layer < s.process.layers_printed), "frame of an unknown layer");
                    let mut xs = s.trajectory.x_mm.iter().chain(s.path_mm.iter().map(|p| &p[0]));
                    assert!(xs.all(|x| x.abs() <= MAX_COORDINATE_MM), "position out of bounds");
                    assert!(s.frames.iter().all(|f| f.file.is_relative()), "frame path not relative");
                }
            }
            Reader::ThermalTruth => {
                if let Ok(t) = ThermalTruth::open(dir) {
                    let _ = t.deposit(0);
                }
            }
            Reader::FsuRaw => {
                let _ = read_printer(dir, FsuPrinter::Taz5, ImportOptions { verify_sha256: false });
            }
            Reader::FdmLines => {
                if let Ok(d) = FdmLinesDataset::read(dir) {
                    for l in &d.lines {
                        assert!(l.image.starts_with(dir), "photo outside the folder");
                        if let Ok((w, h)) = l.image_size_px {
                            assert!(LINE_IMAGE_SIDE_PX.contains(&w) && LINE_IMAGE_SIDE_PX.contains(&h));
                            assert!(LINE_IMAGE_PIXELS.contains(&(w * h)), "photo too large");
                        }
                    }
                }
                let _ = datasets::fdm_lines::generate::read_truth(dir);
            }
        }
    }
}

fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).expect("create");
    for entry in std::fs::read_dir(src).expect("seed folder") {
        let path = entry.expect("entry").path();
        let to = dst.join(path.file_name().expect("name"));
        if path.is_dir() {
            copy_dir(&path, &to);
        } else {
            std::fs::copy(&path, &to).expect("copy");
        }
    }
}

/// Every committed crasher input of `reader` (`tests/crashers/<name>/*`), sorted.
pub fn crashers(reader: Reader) -> Vec<PathBuf> {
    let dir = datasets_dir().join("tests/crashers").join(reader.name());
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(d) => d.map(|e| e.expect("entry").path()).filter(|p| p.is_file()).collect(),
        Err(_) => Vec::new(),
    };
    files.sort();
    files
}
