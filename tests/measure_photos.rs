//! End to end, widths from photos and their G-code (`fdm.measure_photos`), on a small
//! virtual `fdm-photos` print with the camera's habits on (the real photos are GPL and not
//! shipped; `specs/studies/pa_camera.toml` runs on them where they are): every test line
//! is measured on every photo, the tables say where each photo sits, and bad photos are
//! rows with their reason, never the end of the run, until no photo is left.

mod common;

use std::path::Path;

use common::*;
use datasets::fdm_photos::generate::{generate, GenerateConfig};
use polars::prelude::*;

fn virtual_print(dir: &Path) {
    let config = GenerateConfig { lines: 4, photos: 2, size_px: [1080, 900], ..GenerateConfig::new(7) };
    generate(&config, dir).unwrap();
}

fn spec(dir: &Path, data: &Path) -> String {
    let spec = format!(
        "[run]\nname = \"photos\"\nseed = 1\n\n[dataset.print]\npath = \"{}\"\n\n[stage.measure]\nkind = \"fdm.measure_photos\"\ninputs = [\"print\"]\n\n[stage.overlay]\nkind = \"figure.fdm_photo_overlay\"\ninputs = [\"measure\", \"print\"]\n",
        data.display()
    );
    let path = dir.join("photos.toml");
    std::fs::write(&path, spec).unwrap();
    path.to_str().unwrap().to_string()
}

fn table(dir: &Path, name: &str) -> DataFrame {
    let file = std::fs::File::open(dir.join("out/runs/photos/measure").join(name)).unwrap();
    ParquetReader::new(file).finish().unwrap()
}

#[test]
fn every_line_of_a_virtual_print_is_measured_and_each_photo_placed() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("print");
    virtual_print(&data);
    ok(tmp.path(), &["run", "-q", "--out", "out", &spec(tmp.path(), &data)]);
    let lines = table(tmp.path(), "photo_lines.parquet");
    // the frame's two perimeters (8 edges) merge in pairs; the 4 test lines are single beads
    let (line, status) = (lines.column("line").unwrap().i64().unwrap(), lines.column("status").unwrap().str().unwrap());
    let test_lines: Vec<usize> = (0..lines.height()).filter(|&i| line.get(i).unwrap() >= 8).collect();
    assert_eq!(test_lines.len(), 8, "4 lines on 2 photos: {lines}");
    assert!(test_lines.iter().all(|&i| status.get(i) == Some("measured")), "{lines}");
    let calibration = table(tmp.path(), "photo_calibration.parquet");
    let reprojection = calibration.column("reprojection_error_mm").unwrap().f64().unwrap();
    assert!((0..calibration.height()).all(|i| reprojection.get(i).is_some_and(|e| e < 0.1)), "{calibration}");
    for photo in ["p1", "p2"] {
        assert!(tmp.path().join(format!("out/runs/photos/overlay/overlay_{photo}.png")).is_file());
    }
}

#[test]
fn a_bad_photo_is_a_row_and_no_good_photo_is_an_error_naming_each() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("print");
    virtual_print(&data);
    let photos: Vec<std::path::PathBuf> =
        std::fs::read_dir(data.join("photos")).unwrap().map(|e| e.unwrap().path()).collect();
    let spec = spec(tmp.path(), &data);
    // one photo truncated: the other is still measured, the bad one is a failed row
    let first = &photos[0];
    let bytes = std::fs::read(first).unwrap();
    std::fs::write(first, &bytes[..bytes.len() / 3]).unwrap();
    ok(tmp.path(), &["run", "-q", "--out", "out", &spec]);
    let calibration = table(tmp.path(), "photo_calibration.parquet");
    let status_column = calibration.column("status").unwrap().str().unwrap();
    let status: Vec<Option<&str>> = (0..calibration.height()).map(|i| status_column.get(i)).collect();
    assert_eq!(status.iter().filter(|s| **s == Some("failed")).count(), 1, "{calibration}");
    assert_eq!(status.iter().filter(|s| **s == Some("calibrated")).count(), 1, "{calibration}");
    // every photo bad: the error names each photo and why
    for photo in &photos {
        std::fs::write(photo, b"not an image").unwrap();
    }
    let err = fails(tmp.path(), &["run", "-q", "--out", "out2", &spec]);
    assert!(err.contains("expected at least one photo with a measurable line"), "{err}");
    for id in ["p1", "p2"] {
        assert!(err.contains(&format!("photo `{id}`")), "{err}");
    }
    assert!(err.contains("unreadable image"), "{err}");
}
