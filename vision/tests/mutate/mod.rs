//! The proptest side of the PNG fuzz tests (`tests/fuzz_png.rs`, `tests/lines_fuzz.rs`):
//! a fixed-seed runner and seed PNGs with 1-4 byte splices (the header, bytes 16-28:
//! size, depth, colour, is hit often).
#![allow(dead_code)]

use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

/// A reproducible runner of `cases` cases.
pub fn runner(cases: u32) -> TestRunner {
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    TestRunner::new_with_rng(config, TestRng::deterministic_rng(RngAlgorithm::ChaCha))
}

/// One of `seeds` with 1-4 byte splices.
pub fn spliced(seeds: Vec<Vec<u8>>) -> impl Strategy<Value = Vec<u8>> {
    let edit = (prop_oneof![1 => 0usize..40, 1 => any::<usize>()], 0usize..8, prop::collection::vec(any::<u8>(), 0..8));
    (0..seeds.len(), prop::collection::vec(edit, 1..4)).prop_map(move |(which, edits)| {
        let mut bytes = seeds[which].clone();
        for (at, len, with) in edits {
            let start = at % (bytes.len() + 1);
            let end = (start + len).min(bytes.len());
            bytes.splice(start..end, with);
        }
        bytes
    })
}
