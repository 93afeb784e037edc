//! `amrepro pressure-advance`: a hobbyist's photos of a printed pressure-advance pattern
//! and its G-code → the pressure advance to set, with its interval. The photos and the
//! G-code are copied into `OUT/input/` (the G-code as `print.gcode`, the photos under
//! `photos/`), a spec running `fdm.import_photos` → `fdm.measure_photos` →
//! `fdm.pressure_advance` and its figures is written to `OUT/pressure_advance.toml`, and
//! run as `amrepro run` runs any spec (cached: a second call with the same files reruns
//! nothing); the numbers printed come from the stage's table.

use std::path::Path;

use anyhow::{bail, Context, Result};
use pipeline::columns::{f64s, strs};
use tables::fdm::pressure_advance as pa_t;

use crate::cli::{PressureAdvanceArgs, RunArgs};

/// The run's name in the spec (and its folder under `OUT/runs/`).
const RUN: &str = "pressure_advance";
/// The pressure-advance stage's name in the spec.
const STAGE: &str = "fit";

/// Runs the command.
pub fn pressure_advance(args: PressureAdvanceArgs) -> Result<()> {
    if args.photos.is_empty() {
        bail!("expected at least one photo of the printed pattern");
    }
    let input = args.out.join("input");
    copy_inputs(&args, &input)?;
    let spec = args.out.join("pressure_advance.toml");
    std::fs::write(&spec, spec_text(&args, &input)).with_context(|| format!("writing {}", spec.display()))?;
    crate::commands::run(RunArgs {
        spec,
        out: args.out.clone(),
        dry_run: false,
        only: None,
        force: false,
        verbose: false,
        quiet: args.quiet,
        sets: Vec::new(),
    })?;
    print_result(&args.out.join("runs").join(RUN).join(STAGE).join(pa_t::TABLE.file()))
}

/// The G-code as `print.gcode` and each photo under `photos/` (names must differ).
fn copy_inputs(args: &PressureAdvanceArgs, input: &Path) -> Result<()> {
    let photos = input.join("photos");
    if photos.exists() {
        std::fs::remove_dir_all(&photos).with_context(|| format!("clearing {}", photos.display()))?;
    }
    std::fs::create_dir_all(&photos).with_context(|| format!("creating {}", photos.display()))?;
    copy(&args.gcode, &input.join("print.gcode"))?;
    let mut names: Vec<String> = Vec::new();
    for photo in &args.photos {
        let name = photo.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if name.is_empty() || names.contains(&name) {
            bail!("{}: expected photos with different file names, got `{name}` twice", photo.display());
        }
        copy(photo, &photos.join(&name))?;
        names.push(name);
    }
    Ok(())
}

fn copy(from: &Path, to: &Path) -> Result<()> {
    std::fs::copy(from, to).with_context(|| format!("copying {} to {}", from.display(), to.display()))?;
    Ok(())
}

/// The one-print spec: import, measure, fit, and the overlay and fit figures.
fn spec_text(args: &PressureAdvanceArgs, input: &Path) -> String {
    let input = std::path::absolute(input).unwrap_or_else(|_| input.to_path_buf());
    format!(
        r#"# Written by `amrepro pressure-advance`: photos of a printed pressure-advance pattern
# and its G-code → the lag τ and the pressure advance to set.
[run]
name = "{RUN}"
title = "Pressure advance from photos of a printed pattern"
seed = 1

[dataset.raw]
path = {input}

[stage.print]
kind = "fdm.import_photos"
inputs = ["raw"]
params = {{ printer = {printer}, firmware = {firmware}, filament_diameter_mm = {filament}, nozzle_diameter_mm = {nozzle}, gcode = "print.gcode", photos = "photos", source = "photos given to amrepro pressure-advance", license = "the user's own" }}

[stage.measure]
kind = "fdm.measure_photos"
inputs = ["print"]

[stage.{STAGE}]
kind = "fdm.pressure_advance"
inputs = ["measure", "print"]

[stage.overlay]
kind = "figure.fdm_photo_overlay"
inputs = ["measure", "print"]

[stage.figure]
kind = "figure.fdm_pressure_advance"
inputs = ["{STAGE}"]
"#,
        input = toml_string(&input.display().to_string()),
        printer = toml_string(&args.printer),
        firmware = toml_string(&args.firmware),
        filament = args.filament_diameter_mm,
        nozzle = args.nozzle_diameter_mm,
    )
}

/// `text` as a TOML basic string.
fn toml_string(text: &str) -> String {
    let mut quoted = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => quoted.push_str("\\\""),
            '\\' => quoted.push_str("\\\\"),
            c if c.is_control() => quoted.push_str(&format!("\\u{:04X}", c as u32)),
            c => quoted.push(c),
        }
    }
    quoted + "\""
}

/// Prints the fit over all photos and each photo's τ.
fn print_result(table: &Path) -> Result<()> {
    let df = pipeline::artifact::read_parquet(table)?;
    let subset = strs(&df, pa_t::subset, table)?;
    let status = strs(&df, pa_t::status, table)?;
    let reason = strs(&df, pa_t::reason, table)?;
    let column = |c: &str| f64s(&df, c, table);
    let (tau, tau_lo, tau_hi) = (column(pa_t::tau_s)?, column(pa_t::tau_ci_lo_s)?, column(pa_t::tau_ci_hi_s)?);
    let (pa, pa_lo, pa_hi) = (column(pa_t::recommended_pa_s)?, column(pa_t::pa_ci_lo_s)?, column(pa_t::pa_ci_hi_s)?);
    let (flattest, heldout, noise) =
        (column(pa_t::flattest_line_pa_s)?, column(pa_t::heldout_rmse_mm)?, column(pa_t::noise_mm)?);
    let assumed = strs(&df, pa_t::assumed, table)?;
    for i in 0..df.height() {
        if status[i] == "failed" {
            outln!("{}: not fitted: {}", subset[i], reason[i])?;
            continue;
        }
        let bound = if status[i] == "at_bound" { " (at the end of the searched range)" } else { "" };
        outln!(
            "{}: pressure advance {:.4} s (95 % interval {:.4}-{:.4}); lag τ {:.4} s ({:.4}-{:.4}){bound}; flattest printed line {:.4} s; held-out error {:.3} mm, noise {:.3} mm",
            subset[i], pa[i], pa_lo[i], pa_hi[i], tau[i], tau_lo[i], tau_hi[i], flattest[i], heldout[i], noise[i]
        )?;
    }
    if let Some(a) = assumed.first().filter(|a| !a.is_empty()) {
        outln!("assumed (not in the G-code): {a}")?;
    }
    outln!("table:    {}", table.display())?;
    Ok(())
}
