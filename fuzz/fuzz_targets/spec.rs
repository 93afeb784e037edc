//! cargo-fuzz target: the spec reader (`tests/spec_harness`, fuzz/README.md).
#![no_main]

#[path = "../../tests/spec_harness/mod.rs"]
mod spec_harness;

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use pipeline::Registry;

static REGISTRY: OnceLock<Registry> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        spec_harness::check(REGISTRY.get_or_init(spec_harness::registry), text);
    }
});
