//! Bounded, reproducible fuzzing of every dataset reader on stable Rust (part of
//! `make test`): each kind's seed dataset (`tests/seeds/`) with one file mutated (byte
//! splices, numbers swapped for 0, -1, huge, `nan`, paths for `..` and absolute ones, a
//! byte-order mark) or replaced by random bytes, through the public reader, which must
//! return `Ok` or `Err`, never panic or allocate absurdly (`tests/harness`). Fixed seed,
//! [`CASES`] per reader. Then every committed crasher (`tests/crashers/<target>/`, found
//! by the cargo-fuzz targets of `fuzz/` or by hand) is replayed.

mod harness;

use harness::{crashers, Reader, Workspace};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

/// Cases per reader: about 0.6 s each in release on an idle machine (0.3 ms a case).
const CASES: u32 = 2000;

/// Values that break readers: zero, negative, huge, not-a-number, paths out, markers.
const TOKENS: &[&str] = &[
    "0",
    "-1",
    "1",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "inf",
    "-inf",
    "18446744073709551616",
    "4294967296",
    "4000000000",
    "999999999",
    "",
    ",",
    "\n",
    "\r\n",
    "\u{feff}",
    "..",
    "/",
    "../../etc/passwd",
    "/etc/passwd",
    "\"",
    "[",
    "]",
    "=",
    "#",
    "0.0",
    "-0",
    "frames/../x.png",
    "2.5",
    "1000000",
];

/// One edit of a file: replace `len` bytes at `at` (a fraction of the length) by `with`.
fn splice() -> impl Strategy<Value = (prop::sample::Index, usize, Vec<u8>)> {
    let with = prop_oneof![
        3 => prop::sample::select(TOKENS).prop_map(|t| t.as_bytes().to_vec()),
        1 => prop::collection::vec(any::<u8>(), 0..6),
    ];
    (any::<prop::sample::Index>(), 0usize..10, with)
}

/// The seed's bytes with 1-6 splices, or random bytes.
fn input(original: Vec<u8>) -> impl Strategy<Value = Vec<u8>> {
    let edited = prop::collection::vec(splice(), 1..6).prop_map(move |edits| {
        let mut bytes = original.clone();
        for (at, len, with) in edits {
            let start = if bytes.is_empty() { 0 } else { at.index(bytes.len() + 1) };
            let end = (start + len).min(bytes.len());
            bytes.splice(start..end, with);
        }
        bytes
    });
    prop_oneof![4 => edited, 1 => prop::collection::vec(any::<u8>(), 0..400)]
}

fn fuzz(reader: Reader) {
    let ws = Workspace::new(reader);
    let originals: Vec<Vec<u8>> = (0..reader.files().len()).map(|i| ws.original(i)).collect();
    let strategy = (0..originals.len()).prop_flat_map(move |i| (Just(i), input(originals[i].clone())));
    let config = Config { cases: CASES, failure_persistence: None, ..Config::default() };
    let mut runner = TestRunner::new_with_rng(config, TestRng::deterministic_rng(RngAlgorithm::ChaCha));
    runner
        .run(&strategy, |(file, bytes)| {
            ws.check(file, &bytes);
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{}: {e}", reader.name()));
}

#[test]
fn every_reader_survives_mutated_files() {
    for reader in Reader::ALL {
        fuzz(reader);
    }
}

#[test]
fn committed_crashers_are_regression_tests() {
    let mut replayed = 0;
    for reader in Reader::ALL {
        let ws = Workspace::new(reader);
        for file in crashers(reader) {
            ws.check_input(&std::fs::read(&file).unwrap());
            replayed += 1;
        }
    }
    assert!(replayed > 0, "tests/crashers/ holds the inputs that crashed the readers");
}
