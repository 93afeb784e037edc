//! cargo-fuzz target: `vision/tests/harness`, one frame file through the decoder and the
//! undistorter (fuzz/README.md).
#![no_main]

#[path = "../../vision/tests/harness/mod.rs"]
mod harness;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| harness::check_input(data));
