//! Bounded, reproducible fuzzing of the radiometric PNG decoder and the undistorter on
//! stable Rust (part of `make test`): valid Lepton frames with mutated bytes (headers
//! claiming other or huge sizes, bit depths, colour types; truncated and corrupt data)
//! or random bytes, for cameras of any size up to 255 px (`tests/harness`), must decode
//! to a frame or a `FrameError`, never panic or allocate from the header; cameras of any
//! size and coefficients must give an undistorter or a `CameraError`. Then every
//! committed crasher (`tests/crashers/png_frame/`) is replayed.

mod harness;
mod mutate;

use proptest::prelude::*;
use vision::camera::{CameraModel, Distortion, Undistorter};
use vision::frame::{encode_centikelvin_png, ThermalFrame};

/// Cases of each test: about 1 s each in release.
const CASES: u32 = 4000;

/// A valid 160 × 120 frame and a small one, as PNG bytes.
fn seeds() -> Vec<Vec<u8>> {
    let ramp: Vec<u16> = (0..160 * 120).map(|i| 30_000 + (i % 700) as u16).collect();
    vec![encode_centikelvin_png(160, 120, &ramp).unwrap(), encode_centikelvin_png(4, 3, &[30_000; 12]).unwrap()]
}

#[test]
fn the_png_decoder_survives_mutated_and_random_bytes() {
    let png = prop_oneof![4 => mutate::spliced(seeds()), 1 => prop::collection::vec(any::<u8>(), 0..300)];
    let strategy = (prop_oneof![Just((160u8, 120u8)), Just((4, 3)), any::<(u8, u8)>()], png);
    mutate::runner(CASES)
        .run(&strategy, |((width, height), png)| {
            harness::check_input(&[&[width, height][..], &png].concat());
            Ok(())
        })
        .unwrap();
}

#[test]
fn the_undistorter_survives_any_camera() {
    let coefficient = prop_oneof![4 => -1.0f64..1.0, 1 => any::<f64>()];
    let strategy = (0usize..24, 0usize..24, prop::collection::vec(coefficient, 8));
    mutate::runner(CASES)
        .run(&strategy, |(width, height, c)| {
            let mut camera = CameraModel::lepton35(Distortion { k1: c[0], k2: c[1], p1: c[2], p2: c[3] });
            camera.intrinsics.fx_px = c[4] * 300.0;
            camera.intrinsics.cx_px = c[5] * 100.0;
            (camera.width_px, camera.height_px) = (width, height);
            if let Ok(u) = Undistorter::new(&camera) {
                let raw = ThermalFrame::filled(width, height, 50.0);
                let out = u.undistort(&raw).unwrap();
                assert_eq!(out.temp_c.len(), width * height);
            }
            Ok(())
        })
        .unwrap();
}

#[test]
fn committed_crashers_are_regression_tests() {
    let crashers = harness::crashers();
    for file in &crashers {
        harness::check_input(&std::fs::read(file).unwrap());
    }
    assert!(!crashers.is_empty(), "tests/crashers/png_frame holds the inputs that crashed the frame path");
}
