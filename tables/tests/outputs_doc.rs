//! docs/OUTPUTS.md against the declared tables: every declared table is documented, and
//! its section names every declared column (as a `backticked` name, alone or in a
//! comma-separated list), so the analyst contract cannot drift from what is written.

use std::path::Path;

/// The part of OUTPUTS.md documenting `file`: from its `## ` heading, or from the
/// paragraph that starts with `` `file`: ``, to the next heading.
fn section<'a>(doc: &'a str, file: &str) -> Option<&'a str> {
    let heading = doc.lines().find(|l| l.starts_with("## ") && l.contains(&format!("/{file}`")));
    let start = match heading {
        Some(line) => doc.find(line)?,
        None => doc.find(&format!("`{file}`:"))?,
    };
    let rest = &doc[start + 1..];
    Some(&doc[start..start + 1 + rest.find("\n## ").unwrap_or(rest.len())])
}

/// Every name written between backticks, lists split at commas.
fn backticked(text: &str) -> Vec<String> {
    text.split('`').skip(1).step_by(2).flat_map(|span| span.split(',').map(|s| s.trim().to_string())).collect()
}

#[test]
fn every_declared_table_and_column_is_documented_in_outputs_md() {
    let doc = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/OUTPUTS.md")).unwrap();
    for table in tables::ALL {
        let file = match table.name {
            // Published once per printer (`widths_taz5.parquet`, …).
            "widths" => "widths_<printer>.parquet".to_string(),
            name => format!("{name}.parquet"),
        };
        let text = section(&doc, &file).unwrap_or_else(|| panic!("docs/OUTPUTS.md has no section for {file}"));
        let names = backticked(text);
        for column in table.columns {
            assert!(
                names.iter().any(|n| n == column.name),
                "docs/OUTPUTS.md, {file}: column `{}` missing",
                column.name
            );
        }
    }
}

#[test]
fn the_section_finder_reads_headings_and_inline_lists() {
    let doc = "## `out/a/x.parquet`\n| `p`, `q_mm` | float64 |\n`y.parquet`: `r, s`.\n## `out/a/z.parquet`\n";
    assert_eq!(backticked(section(doc, "x.parquet").unwrap()), ["out/a/x.parquet", "p", "q_mm", "y.parquet", "r", "s"]);
    assert_eq!(backticked(section(doc, "y.parquet").unwrap()), ["y.parquet", "r", "s"]);
    assert!(section(doc, "w.parquet").is_none());
}
