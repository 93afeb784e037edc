//! The frame path's fuzz harness, shared by `tests/fuzz_png.rs` (bounded proptest runs
//! in `make test`) and the cargo-fuzz target `fuzz/fuzz_targets/png_frame.rs` (which
//! includes this file by path): what `thermal.monitor` does with one frame file.
//!
//! An input is the camera's width and height (one byte each, px) and then the PNG's
//! bytes. The PNG is decoded as a Lepton frame, as a 4 × 3 image and at the camera's
//! size; an undistorter is built for the camera and undistorts the frame. Each step may
//! fail with a typed error but must not panic or allocate from a lying header.
#![allow(dead_code)]

use vision::camera::{CameraModel, Distortion, Undistorter};
use vision::frame::ThermalFrame;

/// Runs one input (see the module doc).
pub fn check_input(data: &[u8]) {
    let [width, height, png @ ..] = data else { return };
    let (width, height) = (usize::from(*width), usize::from(*height));
    if let Ok(frame) = ThermalFrame::from_png_bytes(png) {
        assert_eq!((frame.width, frame.height, frame.temp_c.len()), (160, 120, 160 * 120));
    }
    let _ = ThermalFrame::from_png_bytes_sized(png, 4, 3);
    let camera = CameraModel { width_px: width, height_px: height, ..CameraModel::lepton35(Distortion::default()) };
    let Ok(undistorter) = Undistorter::new(&camera) else { return };
    if let Ok(frame) = ThermalFrame::from_png_bytes_sized(png, width, height) {
        let out = undistorter.undistort(&frame).expect("the frame has the camera's size");
        assert_eq!(out.temp_c.len(), width * height);
    }
}

/// Every committed crasher input (`tests/crashers/png_frame/*`), sorted.
pub fn crashers() -> Vec<std::path::PathBuf> {
    let here = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let root = if here.join("tests/crashers").is_dir() { here.to_path_buf() } else { here.join("../vision") };
    let mut files: Vec<_> = std::fs::read_dir(root.join("tests/crashers/png_frame"))
        .map(|d| d.map(|e| e.expect("entry").path()).collect())
        .unwrap_or_default();
    files.sort();
    files
}
