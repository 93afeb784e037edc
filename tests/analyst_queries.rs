//! Analysts' contract: DuckDB and Polars (Python, installed by `make test` into a
//! venv from PyPI) read every published table of a full run, and the example queries
//! of docs/OUTPUTS.md run on them, for every shipped spec.

mod common;

use std::path::Path;
use std::process::Command;

use common::*;

#[test]
fn duckdb_and_polars_read_every_published_table() {
    let python = std::env::var("AMREPRO_PYTHON").unwrap_or_else(|_| "python3".into());
    let tmp = tempfile::tempdir().unwrap();
    let raw = data_root().join("fsu-linewidth");
    for name in shipped_spec_names() {
        let name = name.as_str();
        let spec = shipped_spec(tmp.path(), name, &raw);
        ok(tmp.path(), &["run", "-q", spec.to_str().unwrap()]);
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(&python)
        .arg(root.join("tests/analyst_queries.py"))
        .arg("out")
        .arg(root.join("docs/OUTPUTS.md"))
        .current_dir(tmp.path())
        .output()
        .unwrap_or_else(|e| {
            panic!("cannot start {python}: {e}; run `make test`, which installs duckdb and polars into a venv")
        });
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success(),
        "{python} tests/analyst_queries.py failed (run `make test` to install duckdb and polars):\n{text}"
    );
    assert!(text.contains("ok  fdm/line_summary.parquet  18 rows"), "{text}");
    assert!(text.contains("ok  fdm/loo.parquet  36 rows"), "2 printers × 9 lines × 2 models: {text}");
    assert!(text.contains("ok  inkjet/recovery.parquet  50 rows"), "{text}");
}
