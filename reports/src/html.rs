//! The HTML report (`out/report/index.html`), rebuilt from every run manifest under
//! the out folder: per run its stages with status and timings, its figures and its
//! published tables rendered as HTML tables. Self-contained: one file with inline
//! CSS, figures referenced by relative paths, readable offline.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use pipeline::artifact::write_atomic;
use pipeline::manifest::ManifestStage;
use pipeline::{Manifest, StageError};
use polars::prelude::{AnyValue, DataFrame};

use crate::read::read_parquet;

/// Tables up to this many rows are shown whole.
const MAX_ROWS: usize = 40;
/// Rows shown of a longer table (the file has them all).
const PREVIEW_ROWS: usize = 8;

const CSS: &str = "body{font-family:DejaVu Sans,Helvetica,Arial,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}\
h1{border-bottom:2px solid #0072b2}h2{margin-top:2em;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;margin:1em 0;font-size:13px}td,th{border:1px solid #ddd;padding:3px 8px;text-align:right}\
th{background:#f2f6fa}td.t,th.t{text-align:left}figure{margin:1.5em 0}img{max-width:100%;border:1px solid #eee}\
figcaption{font-size:13px;color:#555}.run{color:#666;font-size:13px}.cached{color:#888}code{background:#f5f5f5;padding:0 3px}";

/// The report written, and the manifests it had to leave out.
#[derive(Debug)]
pub struct WrittenReport {
    /// `out/report/index.html`.
    pub path: PathBuf,
    /// `(manifest file, why)` of each run left out because its manifest is unreadable.
    pub skipped: Vec<(PathBuf, String)>,
}

/// Writes `out_dir/report/index.html` from all readable manifests; a run whose
/// manifest cannot be read is left out and named, in the report and the result.
pub fn write_report(out_dir: &Path) -> Result<WrittenReport, StageError> {
    let found = Manifest::read_all(out_dir).map_err(|e| StageError::io(out_dir.join("runs"), e))?;
    let manifests = &found.runs;
    let mut html = format!("<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>amrepro report</title><style>{CSS}</style></head><body>\n<h1>amrepro report</h1>\n");
    let _ = writeln!(html, "<p>Runs found under <code>{}</code>: {}. Every number below names the run and stage it comes from; the published tables are the Parquet files listed (see docs/OUTPUTS.md).</p>", escape(&out_dir.display().to_string()), manifests.len());
    for (_, why) in &found.unreadable {
        let _ = writeln!(html, "<p><strong>Left out:</strong> {} (rerun that spec to rewrite it).</p>", escape(why));
    }
    if out_dir.join("report").join("nightly.html").exists() {
        html += "<p>Trends over the nights, timings and regressions: <a href=\"nightly.html\">the nightly benchmark</a>.</p>\n";
    }
    html += &contents(manifests);
    for manifest in manifests {
        html += &run_section(out_dir, manifest)?;
    }
    html += "</body></html>\n";
    let path = out_dir.join("report").join("index.html");
    write_atomic(&path, html.as_bytes())?;
    Ok(WrittenReport { path, skipped: found.unreadable })
}

fn contents(manifests: &[Manifest]) -> String {
    let items: String = manifests
        .iter()
        .map(|m| {
            format!(
                "<li><a href=\"#{0}\">{1}</a> <span class=\"run\">({0})</span></li>",
                escape(&m.run),
                escape(if m.title.is_empty() { &m.run } else { &m.title })
            )
        })
        .collect();
    format!("<ul>{items}</ul>\n")
}

/// The code fingerprints of the build that produced the run's outputs, as
/// ` (code …)`, each once in stage order, if every stage records one (a kind's
/// fingerprint is that of the code it runs, so kinds of different crates differ), and
/// the parameters set on the command line (`--set`), if any.
fn code_text(m: &Manifest) -> String {
    let mut codes: Vec<&str> = Vec::new();
    for code in m.stages.iter().map(|s| s.record.code_fingerprint.as_str()) {
        if !codes.contains(&code) {
            codes.push(code);
        }
    }
    let mut text = match codes.is_empty() || codes.contains(&"") {
        true => String::new(),
        false => format!(" (code {})", escape(&codes.join(", "))),
    };
    if !m.overrides.is_empty() {
        text += &format!(", with --set {}", escape(&m.overrides.join(" ")));
    }
    text
}

fn run_section(out_dir: &Path, m: &Manifest) -> Result<String, StageError> {
    let mut s = format!(
        "<h2 id=\"{0}\">{1} <small>({0})</small></h2>\n",
        escape(&m.run),
        escape(if m.title.is_empty() { &m.run } else { &m.title })
    );
    let _ = writeln!(
        s,
        "<p class=\"run\">spec <code>{}</code> (sha256 {}…), amrepro {}{}, wall time of the last invocation {:.2} s</p>",
        escape(&m.spec_file.display().to_string()),
        &m.spec_sha256[..12.min(m.spec_sha256.len())],
        escape(&m.tool_version),
        code_text(m),
        m.wall_time_s
    );
    s += &stage_table(m);
    for stage in &m.stages {
        s += &sections(out_dir, m, stage)?;
    }
    for stage in &m.stages {
        s += &figures(m, stage);
    }
    for stage in &m.stages {
        for (from, to) in &stage.published {
            if to.extension().is_some_and(|e| e == "parquet") {
                s += &published_table(out_dir, m, stage, from, to)?;
            }
        }
    }
    Ok(s)
}

fn stage_table(m: &Manifest) -> String {
    let mut s = String::from("<table><tr><th class=\"t\">stage</th><th class=\"t\">kind</th><th class=\"t\">status</th><th>wall time of outputs (s)</th><th>rows</th><th class=\"t\">why it ran</th></tr>\n");
    for st in &m.stages {
        let r = &st.record;
        let class = if st.status == "cached" { " class=\"cached\"" } else { "" };
        let _ = writeln!(
            s,
            "<tr{class}><td class=\"t\">{}</td><td class=\"t\">{} v{}</td><td class=\"t\">{}</td><td>{:.3}</td><td>{}</td><td class=\"t\">{}</td></tr>",
            escape(&r.stage), escape(&r.kind), r.kind_version, escape(&st.status), r.wall_time_s, r.rows, escape(&st.reason)
        );
    }
    s + "</table>\n"
}

/// The `section.html` fragments a stage wrote (paper-vs-ours sections), inline.
fn sections(out_dir: &Path, m: &Manifest, stage: &ManifestStage) -> Result<String, StageError> {
    let mut s = String::new();
    for out in stage.record.outputs.iter().filter(|o| o.path.file_name().is_some_and(|n| n == "section.html")) {
        let path = out_dir.join("runs").join(&m.run).join(&stage.record.stage).join(&out.path);
        s += &std::fs::read_to_string(&path).map_err(|e| StageError::io(&path, e))?;
    }
    Ok(s)
}

/// The figures a `figure.*` stage drew (other stages' images, e.g. a virtual camera's
/// frames in a generated dataset, are data, not figures).
fn figures(m: &Manifest, stage: &ManifestStage) -> String {
    let mut s = String::new();
    if !stage.record.kind.starts_with("figure.") {
        return s;
    }
    for out in stage.record.outputs.iter().filter(|o| o.path.extension().is_some_and(|e| e == "png")) {
        let rel = format!("../runs/{}/{}/{}", m.run, stage.record.stage, out.path.display());
        // an SVG twin is linked only where the stage drew one (a photo overlay has none)
        let svg_path = out.path.with_extension("svg");
        let svg = stage
            .record
            .outputs
            .iter()
            .any(|o| o.path == svg_path)
            .then(|| rel.trim_end_matches(".png").to_string() + ".svg");
        let svg_link = svg.map(|svg| format!(" · <a href=\"{}\">SVG</a>", escape(&svg))).unwrap_or_default();
        let _ = writeln!(
            s,
            "<figure><img src=\"{0}\" alt=\"{1}\"><figcaption>Figure from stage <code>{2}</code> ({3}), run {4}. <a href=\"{0}\">PNG</a>{5}</figcaption></figure>",
            escape(&rel), escape(&out.path.display().to_string()), escape(&stage.record.stage), escape(&stage.record.kind), escape(&m.run), svg_link
        );
    }
    s
}

fn published_table(
    out_dir: &Path,
    m: &Manifest,
    stage: &ManifestStage,
    from: &str,
    to: &Path,
) -> Result<String, StageError> {
    let df = read_parquet(&out_dir.join(to))?;
    let mut s = format!(
        "<h3><code>{}</code></h3>\n<p class=\"run\">{} rows × {} columns; from stage <code>{}</code> ({}) output <code>{}</code>, run {}, params {}.</p>\n",
        escape(&to.display().to_string()), df.height(), df.width(), escape(&stage.record.stage), escape(&stage.record.kind), escape(from), escape(&m.run), escape(&params_text(stage))
    );
    s += &frame_html(&df);
    if df.height() > MAX_ROWS {
        let _ = writeln!(
            s,
            "<p class=\"run\">First {PREVIEW_ROWS} of {} rows shown; query the file for the rest.</p>",
            df.height()
        );
    }
    Ok(s)
}

fn params_text(stage: &ManifestStage) -> String {
    let parts: Vec<String> = stage.record.params.iter().map(|(k, v)| format!("{k} = {v}")).collect();
    if parts.is_empty() {
        "none".into()
    } else {
        parts.join(", ")
    }
}

/// A table as HTML, numbers to 4 significant digits.
pub fn frame_html(df: &DataFrame) -> String {
    let mut s = String::from("<table><tr>");
    for name in df.get_column_names() {
        let _ = write!(s, "<th>{}</th>", escape(name));
    }
    s += "</tr>\n";
    let shown = if df.height() > MAX_ROWS { PREVIEW_ROWS } else { df.height() };
    for row in 0..shown {
        s += "<tr>";
        for col in df.columns() {
            let value = col.get(row).map(|v| cell(&v)).unwrap_or_default();
            let class = if matches!(col.dtype(), polars::prelude::DataType::String) { " class=\"t\"" } else { "" };
            let _ = write!(s, "<td{class}>{}</td>", escape(&value));
        }
        s += "</tr>\n";
    }
    s + "</table>\n"
}

fn cell(value: &AnyValue) -> String {
    match value {
        AnyValue::Float64(x) => format_sig(*x),
        AnyValue::Float32(x) => format_sig(f64::from(*x)),
        AnyValue::String(s) => s.to_string(),
        AnyValue::Null => String::new(),
        other => other.to_string(),
    }
}

/// `x` with 4 significant digits, without exponent for ordinary magnitudes.
pub fn format_sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return x.to_string();
    }
    let magnitude = x.abs().log10().floor() as i32;
    if !(-4..6).contains(&magnitude) {
        return format!("{x:.3e}");
    }
    let decimals = (3 - magnitude).max(0) as usize;
    format!("{x:.decimals$}")
}

/// Escapes text for HTML.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_significant_digits() {
        assert_eq!(format_sig(0.0312345), "0.03123");
        assert_eq!(format_sig(150.0), "150.0");
        assert_eq!(format_sig(-12.3456), "-12.35");
        assert_eq!(format_sig(1.5e-7), "1.500e-7");
    }

    #[test]
    fn escapes_markup() {
        assert_eq!(escape("<a href=\"x\">&</a>"), "&lt;a href=&quot;x&quot;&gt;&amp;&lt;/a&gt;");
    }

    #[test]
    fn the_run_line_names_the_code_every_stage_records() {
        let stage = |code: &str| -> ManifestStage {
            let mut record: pipeline::StageRecord =
                serde_json::from_str(RECORD).expect("a record without a code fingerprint parses");
            record.code_fingerprint = code.into();
            ManifestStage {
                record,
                status: "run".into(),
                reason: String::new(),
                this_run_wall_time_s: 0.0,
                published: Default::default(),
            }
        };
        let manifest = |codes: &[&str]| Manifest {
            tool_version: "0.1.0".into(),
            run: "r".into(),
            title: String::new(),
            spec_file: "s.toml".into(),
            spec_sha256: String::new(),
            overrides: Vec::new(),
            finished_unix_s: 0,
            wall_time_s: 0.0,
            stages: codes.iter().map(|c| stage(c)).collect(),
        };
        assert_eq!(code_text(&manifest(&["d26b3398084096a6", "d26b3398084096a6"])), " (code d26b3398084096a6)");
        assert_eq!(
            code_text(&manifest(&["d26b3398084096a6", "0123456789abcdef", "d26b3398084096a6"])),
            " (code d26b3398084096a6, 0123456789abcdef)"
        );
        assert_eq!(code_text(&manifest(&["d26b3398084096a6", ""])), "");
        assert_eq!(code_text(&manifest(&["", ""])), "");
        assert_eq!(code_text(&manifest(&[])), "");
    }

    /// A stage record as written before records held the code fingerprint.
    const RECORD: &str = r#"{"stage": "a", "kind": "k", "kind_version": 1, "tool_version": "0.1.0",
        "key_hash": "h", "params": {}, "seed": 0, "input_hashes": {}, "output_hash": "o", "outputs": [],
        "rows": 0, "wall_time_s": 0.0}"#;
}
