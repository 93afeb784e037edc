//! The analyst contract against the tables' declarations: every table a shipped spec
//! publishes is declared (the `tables` crate; those not yet declared are listed in
//! `published_tables_undeclared.txt`, a list that only shrinks), docs/COLUMNS.md is generated from those
//! declarations and current, every hand-written section of docs/OUTPUTS.md names the
//! declared columns of the tables it documents, and every declared table is written by
//! some stage kind.

mod common;

use std::path::Path;

use common::*;

/// The shipped specs as `make docs` passes them: `specs/*.toml`, then
/// `specs/studies/*.toml`, each sorted.
fn shipped_specs(root: &Path) -> Vec<String> {
    let mut specs = Vec::new();
    for folder in ["specs", "specs/studies"] {
        let mut names: Vec<String> = std::fs::read_dir(root.join(folder))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".toml"))
            .map(|n| format!("{folder}/{n}"))
            .collect();
        names.sort();
        specs.extend(names);
    }
    specs
}

/// `amrepro outputs --markdown` over the shipped specs.
fn columns_markdown(root: &Path) -> String {
    let specs = shipped_specs(root);
    let mut args = vec!["outputs", "--markdown"];
    args.extend(specs.iter().map(String::as_str));
    ok(root, &args)
}

/// The generated reference's sections: published path → declared column names.
fn declared_columns(markdown: &str) -> Vec<(String, Vec<String>)> {
    let mut sections: Vec<(String, Vec<String>)> = Vec::new();
    for line in markdown.lines() {
        if let Some(path) = line.strip_prefix("## `").and_then(|l| l.strip_suffix('`')) {
            sections.push((path.to_string(), Vec::new()));
        } else if let (Some(column), Some((_, columns))) =
            (line.strip_prefix("| `").and_then(|l| l.split('`').next()), sections.last_mut())
        {
            columns.push(column.to_string());
        }
    }
    sections
}

/// Published tables whose columns are not declared yet (their writers and readers still
/// spell the names): the list only shrinks. A table declared since must leave it, and a
/// new published table must be declared.
const NOT_YET_DECLARED: &str = include_str!("published_tables_undeclared.txt");

/// docs/COLUMNS.md is generated from the declarations; `UPDATE_DOCS=1` rewrites it.
#[test]
fn columns_doc_is_current_and_every_published_table_is_declared() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let generated = columns_markdown(root);
    let undeclared: Vec<&str> = generated
        .split("\n## ")
        .filter(|section| section.contains("Columns not declared"))
        .filter_map(|section| section.lines().next())
        .map(|heading| heading.trim_matches(|c| c == '`' || c == '#' || c == ' '))
        .collect();
    let listed: Vec<&str> = NOT_YET_DECLARED.lines().filter(|l| !l.is_empty() && !l.starts_with('#')).collect();
    let newly: Vec<&&str> = undeclared.iter().filter(|p| !listed.contains(p)).collect();
    assert!(newly.is_empty(), "published tables without a declaration in `tables`: {newly:?}");
    let declared_since: Vec<&&str> = listed.iter().filter(|p| !undeclared.contains(p)).collect();
    assert!(
        declared_since.is_empty(),
        "declared now: remove from tests/published_tables_undeclared.txt: {declared_since:?}"
    );
    let doc = root.join("docs/COLUMNS.md");
    if std::env::var("UPDATE_DOCS").is_ok() {
        std::fs::write(&doc, &generated).unwrap();
    }
    let current = std::fs::read_to_string(&doc).unwrap_or_default();
    assert!(
        current == generated,
        "docs/COLUMNS.md is stale: run `make docs` or `UPDATE_DOCS=1 cargo test --release --workspace --test published_tables`"
    );
}

#[test]
fn every_hand_written_outputs_section_names_the_declared_columns() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let outputs = std::fs::read_to_string(root.join("docs/OUTPUTS.md")).unwrap();
    let mut checked = 0;
    for (path, columns) in declared_columns(&columns_markdown(root)) {
        let Some(text) = section(&outputs, &path) else { continue };
        checked += 1;
        let names = backticked(text);
        for column in columns {
            assert!(names.contains(&column), "docs/OUTPUTS.md, section of {path}: declared column `{column}` missing");
        }
    }
    assert!(checked > 10, "only {checked} sections of docs/OUTPUTS.md were found");
}

/// Every declared table is written by a registered kind (docs/STAGES.md lists what each
/// kind writes, with the columns' names and types).
#[test]
fn every_declared_table_is_written_by_a_stage_kind() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let stages = ok(root, &["stages", "--markdown"]);
    for table in tables::all() {
        let columns: Vec<String> = table.columns.iter().map(|c| format!("`{}` {}", c.name, c.dtype)).collect();
        let line = format!("Writes `{}` (declared in `tables`): {}.", table.file(), columns.join(", "));
        assert!(stages.contains(&line), "no stage kind writes the declared `{}` ({})", table.name, table.doc);
    }
}

/// The part of OUTPUTS.md documenting `path` (`out/thermal/spans.parquet`): from the
/// `## ` heading naming it (a name without a folder is in the heading's first path's
/// folder; `<printer>` matches any name), or from a paragraph starting with
/// `` `spans.parquet`: ``, to the next heading.
fn section<'a>(doc: &'a str, path: &str) -> Option<&'a str> {
    let file = path.rsplit('/').next()?;
    let heading = doc.lines().find(|l| l.starts_with("## ") && heading_names(l).iter().any(|p| matches(p, path)));
    let start = match heading {
        Some(line) => doc.find(line)?,
        None => doc.find(&format!("`{file}`:"))?,
    };
    let rest = &doc[start + 1..];
    Some(&doc[start..start + 1 + rest.find("\n## ").unwrap_or(rest.len())])
}

/// The paths a heading names: its backticked `.parquet` names, resolved against the
/// folder of the first one.
fn heading_names(heading: &str) -> Vec<String> {
    let names: Vec<&str> = heading.split('`').skip(1).step_by(2).filter(|n| n.ends_with(".parquet")).collect();
    let folder = names.first().and_then(|n| n.rsplit_once('/')).map_or("", |(folder, _)| folder);
    names.iter().map(|n| if n.contains('/') { n.to_string() } else { format!("{folder}/{n}") }).collect()
}

/// Whether `pattern` (which may hold one `<placeholder>`) names `path`.
fn matches(pattern: &str, path: &str) -> bool {
    match (pattern.split_once('<'), pattern.split_once('>')) {
        (Some((prefix, _)), Some((_, suffix))) => {
            path.len() > prefix.len() + suffix.len() && path.starts_with(prefix) && path.ends_with(suffix)
        }
        _ => pattern == path,
    }
}

/// Every name written between backticks, lists split at commas.
fn backticked(text: &str) -> Vec<String> {
    text.split('`').skip(1).step_by(2).flat_map(|span| span.split(',').map(|s| s.trim().to_string())).collect()
}

#[test]
fn the_section_finder_reads_headings_placeholders_and_inline_lists() {
    let doc = "## `out/a/x.parquet` and `w.parquet`\n| `p`, `q_mm` | float64 |\n`y.parquet`: `r, s`.\n\
               ## `out/a/z_<printer>.parquet`\n`t`\n";
    assert_eq!(backticked(section(doc, "out/a/x.parquet").unwrap())[1..4], ["w.parquet", "p", "q_mm"]);
    assert_eq!(section(doc, "out/a/w.parquet"), section(doc, "out/a/x.parquet"));
    assert_eq!(backticked(section(doc, "out/a/y.parquet").unwrap()), ["y.parquet", "r", "s"]);
    assert_eq!(backticked(section(doc, "out/a/z_taz5.parquet").unwrap()), ["out/a/z_<printer>.parquet", "t"]);
    assert!(section(doc, "out/a/v.parquet").is_none());
    assert!(!matches("out/a/z_<printer>.parquet", "out/a/z_.parquet"));
}
