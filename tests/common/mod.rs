//! Helpers for the end-to-end tests: run the real `amrepro` binary in a temp folder.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The real FSU data folder (`data/` of the repository, or `$AMREPRO_DATA`).
pub fn data_root() -> PathBuf {
    let root = std::env::var("AMREPRO_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|_| Path::new(env!("CARGO_MANIFEST_DIR")).join("data"));
    let root = root.canonicalize().unwrap_or(root);
    assert!(
        root.join("fsu-linewidth/taz5").is_dir(),
        "the FSU data is missing under {}: set AMREPRO_DATA",
        root.display()
    );
    root
}

/// Runs `amrepro args...` in `cwd`.
pub fn amrepro(cwd: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_amrepro"))
        .args(args)
        .current_dir(cwd)
        .env_remove("AMREPRO_DATA")
        .output()
        .expect("amrepro runs")
}

/// Runs `amrepro args...` in `cwd` with one extra environment variable.
pub fn amrepro_with_env(cwd: &Path, args: &[&str], (key, value): (&str, &str)) -> Output {
    Command::new(env!("CARGO_BIN_EXE_amrepro"))
        .args(args)
        .current_dir(cwd)
        .env_remove("AMREPRO_DATA")
        .env(key, value)
        .output()
        .expect("amrepro runs")
}

/// Runs and asserts success; returns stdout + stderr.
pub fn ok(cwd: &Path, args: &[&str]) -> String {
    let out = amrepro(cwd, args);
    let text = text(&out);
    assert!(out.status.success(), "amrepro {args:?} failed:\n{text}");
    text
}

/// Runs and asserts failure; returns stdout + stderr.
pub fn fails(cwd: &Path, args: &[&str]) -> String {
    let out = amrepro(cwd, args);
    let text = text(&out);
    assert!(!out.status.success(), "amrepro {args:?} should have failed:\n{text}");
    assert!(text.contains("error:"), "{text}");
    text
}

/// A finished command's standard output and error, for messages.
pub fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// The shipped FSU spec with its dataset path pointed at `raw` (a folder holding
/// taz5/ and taz6/), written into `dir`.
pub fn fsu_spec(dir: &Path, raw: &Path) -> PathBuf {
    let path = shipped_spec(dir, "fsu_linewidth", raw);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(!text.contains("${AMREPRO_DATA"), "the shipped spec's dataset path changed; update shipped_spec");
    path
}

/// Names of every shipped spec (`specs/*.toml`), sorted.
pub fn shipped_spec_names() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs");
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().to_string())
        .collect();
    names.sort();
    names
}

/// The power study's draws in the shipped `specs/discrepancy_fdm.toml` (about four
/// minutes, run by `make run`), and the small fixed-seed study the tests run instead.
pub const SHIPPED_POWER_STUDY: &str = "draws = 28, null_draws = 200";
/// See [`SHIPPED_POWER_STUDY`].
pub const TEST_POWER_STUDY: &str =
    "draws = 2, null_draws = 4, bed_tilt = \"0.2\", gear_eccentricity = \"0.1\", flow_saturation = \"0.2\"";
/// The shipped study with measurement noise only, and the tests' cut of it.
pub const SHIPPED_WHITE_STUDY: &str = "draws = 10, null_draws = 50";
/// See [`SHIPPED_WHITE_STUDY`].
pub const TEST_WHITE_STUDY: &str = "draws = 1, null_draws = 2";

/// The transfer matrix of the shipped `specs/ren2021_transfer.toml` (four printers,
/// about two minutes), and the two-printer matrix the tests run instead.
pub const SHIPPED_MATRIX: &str =
    "inputs = [\"taz5\", \"taz6\", \"taz5_wide_nozzle\", \"taz6_slow_melt\"]\nparams = { blob_printers = \"taz5, taz5-0.8mm\", kinematics = \"target_pair\" }";
/// See [`SHIPPED_MATRIX`].
pub const TEST_MATRIX: &str =
    "inputs = [\"taz6\", \"taz6_slow_melt\"]\nparams = { bootstrap_draws = 400, kinematics = \"target_pair\" }";

/// A shipped spec's text with its studies cut to the tests' size: the power studies
/// ([`TEST_POWER_STUDY`], [`TEST_WHITE_STUDY`]) and the transfer matrix
/// ([`TEST_MATRIX`]); `file` names it in the message when a shipped study changed.
pub fn cut_studies(file: &str, shipped: &str) -> String {
    if shipped.contains("fdm.discovery_power") {
        assert!(
            shipped.contains(SHIPPED_POWER_STUDY),
            "{file}: the power study's draws changed; update SHIPPED_POWER_STUDY"
        );
        assert!(
            shipped.contains(SHIPPED_WHITE_STUDY),
            "{file}: the white-noise study changed; update SHIPPED_WHITE_STUDY"
        );
    }
    if shipped.contains("fdm.transfer_matrix") {
        assert!(shipped.contains(SHIPPED_MATRIX), "{file}: the transfer matrix changed; update SHIPPED_MATRIX");
    }
    shipped
        .replace(SHIPPED_POWER_STUDY, TEST_POWER_STUDY)
        .replace(SHIPPED_WHITE_STUDY, TEST_WHITE_STUDY)
        .replace(SHIPPED_MATRIX, TEST_MATRIX)
}

/// The shipped `specs/<name>.toml` with its FSU dataset path (if it has one) pointed
/// at `raw` and its studies cut to the tests' size ([`cut_studies`]), written into `dir`.
pub fn shipped_spec(dir: &Path, name: &str, raw: &Path) -> PathBuf {
    let file = format!("specs/{name}.toml");
    let shipped = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(&file)).unwrap();
    let text = shipped.replace("${AMREPRO_DATA:-../data}/fsu-linewidth", &raw.display().to_string());
    let text = cut_studies(&file, &text);
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// A copy of the real FSU folder in `dir`, to corrupt.
pub fn copy_raw(dir: &Path) -> PathBuf {
    let src = data_root().join("fsu-linewidth");
    let dst = dir.join("raw");
    for printer in ["taz5", "taz6"] {
        std::fs::create_dir_all(dst.join(printer)).unwrap();
        for entry in std::fs::read_dir(src.join(printer)).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, dst.join(printer).join(path.file_name().unwrap())).unwrap();
        }
    }
    dst
}

/// Number of rows of a Parquet file.
pub fn parquet_rows(path: &Path) -> usize {
    use polars::prelude::{ParquetReader, SerReader};
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap().height()
}

/// A Parquet file as a DataFrame.
pub fn read_table(path: &Path) -> polars::prelude::DataFrame {
    use polars::prelude::{ParquetReader, SerReader};
    ParquetReader::new(std::fs::File::open(path).unwrap()).finish().unwrap()
}

/// A string column (nulls as empty strings).
pub fn strings(df: &polars::prelude::DataFrame, column: &str) -> Vec<String> {
    df.column(column).unwrap().str().unwrap().iter().map(|s| s.unwrap_or_default().to_string()).collect()
}

/// A float column (nulls as NaN).
pub fn floats(df: &polars::prelude::DataFrame, column: &str) -> Vec<f64> {
    df.column(column).unwrap().f64().unwrap().iter().map(|x| x.unwrap_or(f64::NAN)).collect()
}

/// `scale.toml` in `dir`: a power study split into eight work units (two bases × four
/// blocks of draws; docs/SCALE.md), its inputs, and a figure of it that `collect` draws
/// (the tail).
pub fn split_study_spec(dir: &Path) -> PathBuf {
    let raw = data_root().join("fsu-linewidth");
    let text = format!(
        r#"[run]
name = "scale"
title = "A power study spread over workers"
seed = 7

[dataset.fsu_raw]
path = "{raw}"

[stage.taz5]
kind = "fdm.import"
inputs = ["fsu_raw"]
params = {{ printer = "taz5" }}

[stage.taz6]
kind = "fdm.import"
inputs = ["fsu_raw"]
params = {{ printer = "taz6" }}

[stage.power]
kind = "fdm.discovery_power"
inputs = ["taz5", "taz6"]
params = {{ start_blob = "taz5", {TEST_POWER_STUDY}, draws_per_unit = 3 }}
publish = {{ "power.parquet" = "discrepancy/power.parquet", "power_draws.parquet" = "discrepancy/power_draws.parquet" }}

[stage.power_curves]
kind = "figure.fdm_discovery_power"
inputs = ["power"]
"#,
        raw = raw.display()
    );
    let path = dir.join("scale.toml");
    std::fs::write(&path, text).unwrap();
    path
}
