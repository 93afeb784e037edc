//! Test helpers for the paper-000 models: synthetic lines drawn from a known piecewise
//! model (eq. 3) at the nine conditions of Table I, and a reader of the real Taz 5 /
//! Taz 6 widths in the repository's `data/fsu-linewidth` (test-only file I/O; the crate itself
//! does none).

use std::path::PathBuf;

use super::kinematics::LineKinematics;
use super::line::MeasuredLine;
use super::predict::FittedPiecewise;
pub(crate) use super::synthetic::{synthetic_truth, TABLE_I};

/// Noiseless lines of Table I sampled every `step_mm`, widths from `truth`.
pub(crate) fn synthetic_lines(truth: &FittedPiecewise, step_mm: f64) -> Vec<MeasuredLine> {
    TABLE_I
        .iter()
        .map(|&(a, f)| {
            let nominal = LineKinematics::paper_line(a, f).unwrap();
            let n = (120.0 / step_mm).floor() as usize;
            let xs: Vec<f64> = (0..=n).map(|i| i as f64 * step_mm).collect();
            let ws = truth.predict(&nominal, &xs).unwrap();
            MeasuredLine::new(nominal, xs, ws).unwrap()
        })
        .collect()
}

/// The real lines of one printer folder (`taz5` or `taz6`) in Table I order, or `None`
/// (with a printed note) when the data folder is missing.
pub(crate) fn real_lines(printer: &str) -> Option<Vec<MeasuredLine>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/fsu-linewidth").join(printer);
    if !dir.is_dir() {
        eprintln!("note: {} missing, real-data check skipped", dir.display());
        return None;
    }
    let suffix = if printer == "taz5" { "xiao120" } else { "ino120" };
    let lines = TABLE_I
        .iter()
        .map(|&(a, f)| {
            let name = format!("S{}F{}_{}.csv", a as u32, (f * 60.0) as u32, suffix);
            let text = std::fs::read_to_string(dir.join(&name)).expect("read csv");
            let (mut xs, mut ws) = (Vec::new(), Vec::new());
            for row in text.lines().filter(|r| !r.trim().is_empty()) {
                let mut it = row.split(',').map(|v| v.trim().parse::<f64>().unwrap());
                xs.push(it.next().unwrap());
                ws.push(it.next().unwrap());
            }
            MeasuredLine::new(LineKinematics::paper_line(a, f).unwrap(), xs, ws).unwrap()
        })
        .collect();
    Some(lines)
}
