//! cargo-fuzz target: `datasets/tests/harness` with the `FdmLines` reader (fuzz/README.md).
#![no_main]

#[path = "../../datasets/tests/harness/mod.rs"]
mod harness;

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

static WORKSPACE: OnceLock<harness::Workspace> = OnceLock::new();

fuzz_target!(|data: &[u8]| {
    WORKSPACE.get_or_init(|| harness::Workspace::new(harness::Reader::FdmLines)).check_input(data);
});
