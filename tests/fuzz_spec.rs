//! Fuzzing the spec reader (`pipeline::spec::parse_spec` then `Plan::check` against
//! the real registry) on stable Rust, in `make test`: arbitrary text, and the shipped
//! specs mutated byte- and token-wise. Each input must give a plan or a `SpecError`
//! naming the spec file, never a panic. A fixed seed keeps the cases reproducible; the
//! coverage-guided target in `fuzz/` runs the same check ([`spec_harness`]) for longer.

mod spec_harness;

use std::path::Path;

use pipeline::spec::parse_spec;
use pipeline::Plan;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use spec_harness::{check, registry};

/// Tokens that stress a TOML spec: syntax, extreme numbers, variable expansions,
/// names of real sections, kinds and fields.
const TOKENS: &[&str] = &[
    "[",
    "]",
    "{",
    "}",
    "=",
    "\"",
    "'",
    ",",
    "\n",
    "#",
    "[[stage]]",
    "[stage.x]",
    "[dataset.d]",
    "[run]",
    "1e309",
    "-1",
    "nan",
    "inf",
    "-inf",
    "0",
    "9223372036854775807",
    "-9223372036854775808",
    "18446744073709551616",
    "true",
    "${",
    "${AMREPRO_DATA",
    ":-",
    "}",
    "${X:-${Y}}",
    "..",
    "/",
    "../../etc/passwd",
    "\u{feff}",
    "\u{0}",
    "kind = \"fdm.import\"",
    "inputs = [\"x\"]",
    "publish = { \"a\" = \"../a\" }",
    "params = { }",
    "seed = ",
];

/// Every shipped spec: `specs/*.toml` (run by `make run`) and `specs/studies/*.toml`
/// (the large studies).
fn shipped_specs() -> Vec<String> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs");
    let mut names: Vec<_> = [root.clone(), root.join("studies")]
        .iter()
        .flat_map(|dir| std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    names.sort();
    assert!(names.iter().any(|p| p.parent().is_some_and(|d| d.ends_with("studies"))), "the studies are checked too");
    names.iter().map(|p| std::fs::read_to_string(p).unwrap()).collect()
}

fn runner(cases: u32) -> TestRunner {
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    TestRunner::new_with_rng(config, TestRng::from_seed(RngAlgorithm::ChaCha, &[7; 32]))
}

/// One edit of a spec: replace the byte range `at..at+len` (clamped to a char
/// boundary) with a token, or with arbitrary text.
fn mutate(text: &str, edits: &[(usize, usize, usize, String)]) -> String {
    let mut text = text.to_string();
    for (at, len, token, junk) in edits {
        let start = floor_char(&text, at % (text.len() + 1));
        let end = floor_char(&text, (start + len).min(text.len()));
        let with = if *token < TOKENS.len() { TOKENS[*token] } else { junk.as_str() };
        text.replace_range(start..end, with);
    }
    text
}

fn floor_char(text: &str, mut i: usize) -> usize {
    while !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}

#[test]
fn arbitrary_text_gives_a_plan_or_a_named_error() {
    let registry = registry();
    runner(20_000)
        .run(&".{0,400}", |text| {
            check(&registry, &text);
            Ok(())
        })
        .unwrap();
}

#[test]
fn mutated_shipped_specs_give_a_plan_or_a_named_error() {
    let registry = registry();
    let specs = shipped_specs();
    assert!(specs.len() >= 5);
    let edit = (any::<usize>(), 0usize..40, 0usize..TOKENS.len() + 4, ".{0,12}");
    let strategy = (0..specs.len(), prop::collection::vec(edit, 1..6));
    runner(20_000)
        .run(&strategy, |(which, edits)| {
            check(&registry, &mutate(&specs[which], &edits));
            Ok(())
        })
        .unwrap();
}

#[test]
fn the_shipped_specs_themselves_check() {
    let registry = registry();
    for text in shipped_specs() {
        let file = Path::new("shipped.toml");
        let raw = parse_spec(file, &text).unwrap();
        Plan::check(file, raw, &registry, |_| None).unwrap();
    }
}
