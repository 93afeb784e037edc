//! No measured number is typed into the report's prose or into a module doc: a number a
//! reader sees is computed by a stage and names its source, and a doc describes a
//! mechanism, not a figure that goes stale when the code changes. This test greps for
//! the shapes a typed-in measurement takes (a result tied to a seed, a signed change in
//! per cent, a range of a measured quantity (`N-M mm`, `N to M mm`), "measured on … N") in every crate's module
//! docs (`//!`) and in the report sections' code (their prose is string literals).
//! What it allows is listed below, each with why it is not a measurement.

use std::path::{Path, PathBuf};

/// (file, matched text, why it is not a measured number).
const ALLOWED: &[(&str, &str, &str)] = &[
    ("models/src/fdm/discrepancy/gear.rs", "2-60 mm", "the period grid searched, a setting"),
    ("models/src/thermal/setup.rs", "5-10 mm", "the test path's geometry, a design choice"),
    ("vision/src/lines/mod.rs", "0.4-2 mm", "paper 000's line widths, Sec. III"),
];

/// The crates whose `src/` is scanned (the workspace's own code, not tests or fuzzing).
const CRATES: &[&str] =
    &[".", "pipeline", "tables", "discrepancy", "models", "datasets", "stages", "reports", "vision", "nightly"];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The first typed-in-measurement shape in `line`, if any.
fn measured_shape(line: &str) -> Option<String> {
    let chars: Vec<char> = line.chars().collect();
    let number_at = |i: usize| -> Option<usize> {
        // The end of the number (digits and one decimal point) starting at `i`.
        let mut j = i;
        while j < chars.len() && (chars[j].is_ascii_digit() || (chars[j] == '.' && j > i)) {
            j += 1;
        }
        (j > i && chars[i].is_ascii_digit()).then_some(j)
    };
    let unit_at = |i: usize| -> bool {
        let rest: String = chars[i..].iter().collect();
        let rest = rest.trim_start_matches(' ');
        ["%", "mm", "ms", "px", "frames"].iter().any(|u| {
            rest.starts_with(u) && !rest[u.len()..].starts_with(|c: char| c.is_alphanumeric() || c == '³' || c == '²')
        })
    };
    let lower = line.to_lowercase();
    for key in ["seed ", "seeds "] {
        if let Some(at) = lower.find(key) {
            let after = &lower[at + key.len()..];
            if after.starts_with(|c: char| c.is_ascii_digit())
                && (at == 0 || !lower[..at].ends_with(char::is_alphanumeric))
            {
                return Some(format!("{key}{}", &after[..1]));
            }
        }
    }
    if lower.contains("measured on") && lower.split("measured on").nth(1).is_some_and(|r| r.contains(char::is_numeric))
    {
        return Some("measured on … N".into());
    }
    for i in 0..chars.len() {
        let starts_number =
            chars[i].is_ascii_digit() && (i == 0 || !chars[i - 1].is_ascii_digit() && chars[i - 1] != '.');
        if !starts_number {
            continue;
        }
        let Some(end) = number_at(i) else { continue };
        let signed = i > 0 && (chars[i - 1] == '−' || chars[i - 1] == '+');
        let next = chars[end..].iter().find(|c| **c != ' ');
        if signed && next == Some(&'%') {
            return Some(chars[i - 1..end].iter().collect::<String>() + " %");
        }
        // A range: N-M unit, or N to M unit.
        let to = chars[end..].starts_with(&[' ', 't', 'o', ' ']);
        let second = if to { end + 4 } else { end + 1 };
        if second < chars.len() && (to || chars[end] == '-' || chars[end] == '–') {
            if let Some(end2) = number_at(second) {
                if unit_at(end2) {
                    let unit: String = chars[end2..]
                        .iter()
                        .collect::<String>()
                        .trim_start()
                        .chars()
                        .take_while(|c| c.is_alphabetic() || *c == '%')
                        .collect();
                    return Some(format!("{} {unit}", chars[i..end2].iter().collect::<String>()));
                }
            }
        }
    }
    None
}

/// The lines of `text` the test reads: module docs everywhere, and in a report
/// section every non-comment line of the code before its tests.
fn scanned_lines(text: &str, section: bool) -> impl Iterator<Item = (usize, &str)> {
    let code = text.split("#[cfg(test)]").next().unwrap_or("");
    code.lines().enumerate().filter(move |(_, line)| {
        let t = line.trim_start();
        t.starts_with("//!") || (section && !t.starts_with("//"))
    })
}

#[test]
fn no_measured_number_is_typed_into_report_prose_or_module_docs() {
    let root = root();
    let mut files = Vec::new();
    for krate in CRATES {
        rust_files(&root.join(krate).join("src"), &mut files);
    }
    files.sort();
    files.dedup();
    assert!(files.len() > 100, "found only {} source files under {}", files.len(), root.display());
    let mut found = Vec::new();
    let mut allowed_used = vec![false; ALLOWED.len()];
    for file in &files {
        let rel = file.strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/");
        let text = std::fs::read_to_string(file).unwrap();
        let section = rel.starts_with("reports/src/sections/");
        for (n, line) in scanned_lines(&text, section) {
            let Some(shape) = measured_shape(line) else { continue };
            match ALLOWED.iter().position(|(f, m, _)| *f == rel && line.contains(m)) {
                Some(k) => allowed_used[k] = true,
                None => found.push(format!("{rel}:{}: `{shape}` in: {}", n + 1, line.trim())),
            }
        }
    }
    assert!(
        found.is_empty(),
        "typed-in measured numbers (compute them in a stage, or describe the mechanism):\n{}",
        found.join("\n")
    );
    let stale: Vec<&str> = ALLOWED.iter().zip(&allowed_used).filter(|(_, used)| !**used).map(|(a, _)| a.0).collect();
    assert!(stale.is_empty(), "allowances that match nothing any more: {stale:?}");
}

#[test]
fn the_shapes_of_a_typed_in_measurement_are_recognised() {
    for line in [
        "//! gives on seed 3 O_E −67 % and RMS −27 %",
        "//! thermal widths 46-51 % against 69-70 %",
        "\"RMS falls by 23 %; max +22 %\"",
        "//! 0.024-0.029 mm against the floor",
        "//! 45-53 frames skipped",
        "//! measured on the printer: 0.23 px",
        "widths vary from 0.58 to 0.90 mm between conditions",
    ] {
        assert!(measured_shape(line).is_some(), "{line}");
    }
    for line in [
        "//! eqs 5-11 and Sec. 3.2",
        "//! with a 95 % interval",
        "//! at 140-150 °C",
        "//! the seed of the spec",
        "//! paper: 106.75 % → 31.73 %",
        "//! ΔV ∈ [−2, 4] mm/s",
        "//! from 1 to 3 lines",
    ] {
        assert!(measured_shape(line).is_none(), "{line}: {:?}", measured_shape(line));
    }
}
