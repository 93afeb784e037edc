//! The full-size transfer matrix of issue 18 (paper 000, Ren et al. 2021, Sec. II-B and
//! III-B, Algorithm 1, eqs 4-6, carried to four printers): four printers of nine lines,
//! every ordered pair and every printer from the three others, every method, the λ grid
//! of `fdm.transfer_matrix` (1e-6 to 1e4 in whole decades), each target as one work unit
//! (`transfer_matrix_for_target`), as `specs/ren2021_transfer.toml` runs it.
//!
//! ```text
//! cargo run --release -p models --example transfer_matrix_full -- [DATA_DIR] [--dump FILE] [--target K]
//!     [--kinematics grid|target_pair] [--summary]
//! cargo run --release -p models --example transfer_matrix_full -- DATA_DIR --self-source
//! ```
//!
//! With `DATA_DIR` (the folder holding `taz5/` and `taz6/` of `fsu-linewidth`) the
//! printers are those of the spec: the real Taz 5 and Taz 6, the Taz 5 with a 0.8 mm
//! nozzle (widths × 1.6) and the Taz 6 with a slow melt (widths lagged over 8 mm).
//! Without it they are the synthetic printers of the `fdm` bench. `--dump` writes every
//! row with its RMSE and λ as exact bit patterns, so two builds can be compared bit for
//! bit (`cmp`); `--target K` runs printer `K`'s unit only; `--kinematics` chooses where
//! the fits under a prior take `(r_a, r_F)` (`PriorKinematics`; `grid` by default, the
//! spec's choice is `target_pair`); `--summary` prints every (task, n, method) of the
//! summary. This example reads files;
//! the `models` library itself does no I/O.
//!
//! `--self-source` asks how much any source could give under paper 000's prior family:
//! the real Taz 5 and Taz 6 each learn from *themselves* (the source prior is
//! Algorithm 1 over all nine of the target's own lines, the held-out ones included, so
//! it is a bound, not a method), and the summary's improvements at n ≤ 3 are printed.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use models::fdm::synthetic::{perturbed_lines, TABLE_I};
use models::fdm::{
    default_tasks, other_family_widths, summarise, transfer_matrix_for_target, LineKinematics, MatrixRow, MeasuredLine,
    PiecewiseParams, PiecewiseValidParams, PriorKinematics, StudyPrinter, TransferParams, TransferTask,
    TransferValidParams,
};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dump = args.iter().position(|a| a == "--dump").map(|i| PathBuf::from(&args[i + 1]));
    let only = args.iter().position(|a| a == "--target").map(|i| args[i + 1].parse::<usize>().unwrap());
    let data = args.first().filter(|a| !a.starts_with("--")).map(PathBuf::from);
    if args.iter().any(|a| a == "--self-source") {
        return self_source(&spec_printers(data.as_deref().expect("--self-source needs DATA_DIR")));
    }
    let (lines, blob) = match &data {
        Some(dir) => (spec_printers(dir), [true, false, true, false]),
        None => (synthetic_printers(), [true, false, true, false]),
    };
    let (with_blob, without) = paper_params();
    let names = ["taz5", "taz6", "taz5-0.8mm", "taz6-slow-melt"];
    let printers: Vec<StudyPrinter> = (0..4)
        .map(|k| StudyPrinter { name: names[k], lines: &lines[k], params: if blob[k] { &with_blob } else { &without } })
        .collect();
    let kinematics = args.iter().position(|a| a == "--kinematics").map(|i| args[i + 1].as_str());
    let kinematics =
        kinematics.map_or(PriorKinematics::Grid, |k| PriorKinematics::parse(k).expect("grid or target_pair"));
    let transfer = decade_grid(kinematics);
    let tasks = default_tasks(4, true);
    let mut rows = Vec::new();
    let start = Instant::now();
    for target in (0..4).filter(|t| only.is_none_or(|o| o == *t)) {
        let unit = Instant::now();
        rows.extend(transfer_matrix_for_target(&printers, &tasks, &transfer, target).unwrap());
        eprintln!("target {}: {:.2} s", names[target], unit.elapsed().as_secs_f64());
    }
    eprintln!("four targets, {} rows: {:.2} s", rows.len(), start.elapsed().as_secs_f64());
    if let Some(path) = dump {
        std::fs::write(&path, dump_rows(&rows)).unwrap();
    }
    if args.iter().any(|a| a == "--summary") {
        print_summary(&rows, &tasks, &names);
    }
}

/// Every (task, n, method) of the summary on standard output.
fn print_summary(rows: &[MatrixRow], tasks: &[TransferTask], names: &[&str]) {
    println!("sources -> target  n  method                 median mm  improvement (%) [95 %]");
    for s in summarise(rows, 2000, 1) {
        let task = &tasks[s.task];
        let sources: Vec<&str> = task.sources.iter().map(|&k| names[k]).collect();
        let (imp, lo, hi) = (s.improvement_pct, s.ci_lo_pct, s.ci_hi_pct);
        println!(
            "{} -> {} {:<2} {:<22} {:.4} {imp:+6.1} [{lo:+6.1}, {hi:+6.1}]",
            sources.join("+"),
            names[task.target],
            s.n_train,
            s.method.name(),
            s.median_rmse_mm
        );
    }
}

/// The real Taz 5 and Taz 6 (`lines[0]`, `lines[1]`) each as its own source: the
/// summary at n ≤ 3 on standard output.
fn self_source(lines: &[Vec<MeasuredLine>]) {
    let (with_blob, without) = paper_params();
    let params = [&with_blob, &without, &with_blob, &without];
    let names = ["taz5", "taz6", "taz5 (itself)", "taz6 (itself)"];
    let printers: Vec<StudyPrinter> =
        (0..4).map(|k| StudyPrinter { name: names[k], lines: &lines[k % 2], params: params[k] }).collect();
    let tasks = [TransferTask { sources: vec![2], target: 0 }, TransferTask { sources: vec![3], target: 1 }];
    let rows: Vec<MatrixRow> = (0..2)
        .flat_map(|t| transfer_matrix_for_target(&printers, &tasks, &decade_grid(PriorKinematics::Grid), t).unwrap())
        .collect();
    println!("target  n  method                 improvement over single (%) [95 %]");
    for s in summarise(&rows, 2000, 1).iter().filter(|s| s.n_train <= 3) {
        let (target, method) = (names[tasks[s.task].target], s.method.name());
        let (imp, lo, hi) = (s.improvement_pct, s.ci_lo_pct, s.ci_hi_pct);
        println!("{target:<7} {:<2} {method:<22} {imp:+6.1} [{lo:+6.1}, {hi:+6.1}]", s.n_train);
    }
}

/// The paper's piecewise-model settings with the start blob (Taz 5 family) and without
/// (Taz 6 family).
fn paper_params() -> (PiecewiseValidParams, PiecewiseValidParams) {
    (
        PiecewiseParams::paper_defaults().check().unwrap(),
        PiecewiseParams::paper_defaults_without_blob().check().unwrap(),
    )
}

/// The λ grid of `fdm.transfer_matrix`, 1e-6 to 1e4 in whole decades, with the
/// kinematics rule `kinematics`.
fn decade_grid(kinematics: PriorKinematics) -> TransferValidParams {
    let lambda_grid = TransferParams::log_lambda_grid(1.0);
    TransferParams { lambda_grid, kinematics, ..TransferParams::paper_defaults() }.check().unwrap()
}

/// One line per row: task, n, subset, held-out line, method, prior, and the RMSE and λ
/// as bit patterns.
fn dump_rows(rows: &[MatrixRow]) -> String {
    let mut out = String::new();
    for r in rows {
        let (rmse, lambda) = (r.rmse_mm.to_bits(), r.lambda.to_bits());
        let (t, n, s, k, m, p) = (r.task, r.n_train, &r.subset, r.test_index, r.method.name(), &r.prior);
        writeln!(out, "{t} {n} {s} {k} {m} {p} {rmse:016x} {lambda:016x}").unwrap();
    }
    out
}

/// The spec's four printers from the measured lines in `dir`.
fn spec_printers(dir: &Path) -> Vec<Vec<MeasuredLine>> {
    let (taz5, taz6) = (read_printer(dir, "taz5", "xiao120"), read_printer(dir, "taz6", "ino120"));
    let other = |lines: &[MeasuredLine], scale: f64, lag_mm: f64| -> Vec<MeasuredLine> {
        lines
            .iter()
            .map(|l| {
                let w = other_family_widths(&l.positions_mm, &l.widths_mm, scale, lag_mm);
                MeasuredLine::new(l.nominal, l.positions_mm.clone(), w).unwrap()
            })
            .collect()
    };
    let (wide, slow) = (other(&taz5, 1.6, 0.0), other(&taz6, 1.0, 8.0));
    vec![taz5, taz6, wide, slow]
}

/// The nine lines of one printer folder in Table I order (`S<a>F<f>_<suffix>.csv`).
fn read_printer(dir: &Path, printer: &str, suffix: &str) -> Vec<MeasuredLine> {
    TABLE_I
        .iter()
        .map(|&(a, f)| {
            let name = format!("S{}F{}_{suffix}.csv", a as u32, (f * 60.0) as u32);
            let text = std::fs::read_to_string(dir.join(printer).join(&name)).expect("read csv");
            let (mut xs, mut ws) = (Vec::new(), Vec::new());
            for row in text.lines().filter(|r| !r.trim().is_empty()) {
                let mut it = row.split(',').map(|v| v.trim().parse::<f64>().unwrap());
                xs.push(it.next().unwrap());
                ws.push(it.next().unwrap());
            }
            MeasuredLine::new(LineKinematics::paper_line(a, f).unwrap(), xs, ws).unwrap()
        })
        .collect()
}

/// The `fdm` bench's four synthetic printers, all nine lines each.
fn synthetic_printers() -> Vec<Vec<MeasuredLine>> {
    vec![
        perturbed_lines(true, 0.01, 1.0),
        perturbed_lines(false, 0.012, 1.0),
        perturbed_lines(true, 0.008, 1.3),
        perturbed_lines(false, 0.01, 1.3),
    ]
}
