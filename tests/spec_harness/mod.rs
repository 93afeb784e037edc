//! The spec reader's fuzz check, shared by the bounded proptest run in `make test`
//! (`tests/fuzz_spec.rs`) and the cargo-fuzz target `fuzz/fuzz_targets/spec.rs`:
//! `pipeline::spec::parse_spec` then `Plan::check` against the real registry must give
//! a plan or a `SpecError` naming the spec file, never a panic.

use std::path::Path;

use pipeline::spec::parse_spec;
use pipeline::{Plan, Registry};

/// Every stage kind of the binary (domain stages and figures).
pub fn registry() -> Registry {
    let mut registry = Registry::new();
    stages::register(&mut registry);
    reports::register(&mut registry);
    registry
}

/// Parses and checks `text` as a spec; any error must name the spec file.
pub fn check(registry: &Registry, text: &str) {
    let file = Path::new("fuzzed.toml");
    let result = parse_spec(file, text).and_then(|raw| Plan::check(file, raw, registry, |_| None));
    if let Err(err) = result {
        assert!(err.to_string().starts_with("fuzzed.toml: "), "{err}");
    }
}
