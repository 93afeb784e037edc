//! The subcommands: resolve arguments into library calls and add context to errors.

use anyhow::{bail, Context, Result};

use datasets::fsu::{self, FsuPrinter, ImportOptions};
use pipeline::execute::{open_out_dir, run_plan, run_plan_locked, RunOptions};
use pipeline::graph::{render, GraphFormat};
use pipeline::plan::sources_text;
use pipeline::schema::Reads;
use pipeline::stage::{Count, Input};
use pipeline::{Code, Plan, Registry, StageKind};

use crate::cli::{
    Cli, Command, DatasetsCommand, DiffArgs, FdmGenerateArgs, FsuImportArgs, GenerateCommand, GraphArgs,
    GraphFormatArg, ImportCommand, InjectArgs, InkjetGenerateArgs, ReportArgs, RunArgs, StagesArgs,
    ThermalGenerateArgs,
};

/// A crate's name, the fingerprint of its code and the parts (name, hash) that
/// fingerprint is taken over.
pub type CrateCode = (&'static str, &'static str, &'static [(&'static str, &'static str)]);

/// Every workspace crate's code (`build.rs`, `src/code_fingerprint.rs`).
pub const CODE_BY_CRATE: &[CrateCode] = include!(concat!(env!("OUT_DIR"), "/code_by_crate.rs"));

/// Every stage kind this binary knows: domain stages and figures (and, for the fault
/// tests only, `test.fault` when `AMREPRO_TEST_KINDS=1`), each under the code of the
/// crate defining it (`src/code_fingerprint.rs`), which its cache key holds.
pub fn registry() -> Registry {
    let code = |fingerprint: &str, parts: &[(&str, &str)]| Code {
        fingerprint: fingerprint.to_string(),
        parts: parts.iter().map(|(p, h)| (p.to_string(), h.to_string())).collect(),
    };
    let by_crate = CODE_BY_CRATE.iter().map(|(name, fp, parts)| (name.to_string(), code(fp, parts))).collect();
    let mut registry = Registry::with_code(code(env!("AMREPRO_CODE_FINGERPRINT"), &[]), by_crate);
    stages::register(&mut registry);
    reports::register(&mut registry);
    if std::env::var_os(pipeline::testing::ENV_VAR).is_some_and(|v| v == "1") {
        registry.register(Box::new(pipeline::testing::FaultKind));
    }
    registry
}

/// Runs one parsed command line.
pub fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Run(args) => run(args),
        Command::Graph(args) => graph(args),
        Command::Stages(args) => list_stages(args),
        Command::Outputs(args) => crate::outputs::list(args),
        Command::Datasets(DatasetsCommand::Import(ImportCommand::FsuLinewidth(args))) => import_fsu(args),
        Command::Datasets(DatasetsCommand::Generate(GenerateCommand::Fdm(args))) => generate_fdm(args),
        Command::Datasets(DatasetsCommand::Generate(GenerateCommand::Inkjet(args))) => generate_inkjet(args),
        Command::Datasets(DatasetsCommand::Generate(GenerateCommand::Thermal(args))) => generate_thermal(args),
        Command::Datasets(DatasetsCommand::Inject(args)) => inject(args),
        Command::Report(ReportArgs { out }) => report(&out),
        Command::Diff(args) => diff(args),
        Command::Nightly(args) => crate::nightly_run::run(args),
        Command::Plan(args) => crate::scale::plan(args),
        Command::RunUnit(args) => crate::scale::run_unit(args),
        Command::Collect(args) => crate::scale::collect(args),
        Command::Snakefile(args) => crate::scale::snakefile(args),
        Command::PressureAdvance(args) => crate::pressure_advance::pressure_advance(args),
    }
}

pub(crate) fn run(args: RunArgs) -> Result<()> {
    let registry = registry();
    let plan = Plan::from_file_with(&args.spec, &args.sets, &registry)?;
    if args.verbose {
        print_plan(&plan);
    }
    let opts = RunOptions {
        out_dir: args.out.clone(),
        dry_run: args.dry_run,
        only: args.only.clone(),
        force: args.force,
        show_progress: !args.quiet,
        measure_usage: false,
        resumed_because: None,
    };
    let quiet = args.quiet;
    let log = move |line: &str| {
        if !quiet {
            eprintln!("{line}");
        }
    };
    if !quiet {
        eprintln!(
            "{} {} ({} stages)",
            if args.dry_run { "dry run of" } else { "running" },
            plan.run_name,
            plan.stages.len()
        );
    }
    let failed = || {
        format!(
            "run of {} failed; the published tables, the manifest and the report are as the last complete run left them \
             (stages that finished are kept and reused by the next run)",
            args.spec.display()
        )
    };
    if args.dry_run {
        let summary = run_plan(&plan, &registry, &opts, &log).with_context(failed)?;
        outln!("{} of {} stages would run", summary.executed(), summary.stages.len())?;
        return Ok(());
    }
    let lock = open_out_dir(&args.out, &format!("run {}", args.spec.display()))?;
    let summary = run_plan_locked(&plan, &registry, &opts, &log, &lock).with_context(failed)?;
    let report = write_report(&args.out)?;
    match summary.executed() {
        0 => outln!("all {} stages up to date: nothing executed", summary.stages.len())?,
        n => outln!("executed {n} of {} stages", summary.stages.len())?,
    }
    if let Some(manifest) = summary.manifest_path {
        outln!("manifest: {}", manifest.display())?;
    }
    outln!("report:   {}", report.display())?;
    Ok(())
}

/// Rebuilds the report (the caller holds the out folder's lock); warns about runs
/// left out because their manifest is unreadable.
pub fn write_report(out: &std::path::Path) -> Result<std::path::PathBuf> {
    let written = reports::html::write_report(out).context("writing the report")?;
    for (_, why) in &written.skipped {
        eprintln!("warning: the report leaves out a run: {why}");
    }
    Ok(written.path)
}

fn print_plan(plan: &Plan) {
    eprintln!("plan {} from {} (seed {})", plan.run_name, plan.spec_file.display(), plan.seed);
    for d in &plan.datasets {
        eprintln!("  dataset {:<20} {}", d.name, d.dir.display());
    }
    for (w, wave) in plan.waves.iter().enumerate() {
        for &i in wave {
            let s = &plan.stages[i];
            let params: Vec<String> = s.params.iter().map(|(k, v)| format!("{k}={v}")).collect();
            eprintln!("  wave {w}: {:<22} {:<26} {}", s.name, s.kind, params.join(" "));
        }
    }
}

fn graph(args: GraphArgs) -> Result<()> {
    let plan = Plan::from_file(&args.spec, &registry())?;
    let format = match args.format {
        GraphFormatArg::Dot => GraphFormat::Dot,
        GraphFormatArg::Mermaid => GraphFormat::Mermaid,
    };
    out!("{}", render(&plan, format))?;
    Ok(())
}

fn list_stages(args: StagesArgs) -> Result<()> {
    let registry = registry();
    let text: String = registry.kinds().map(|k| if args.markdown { kind_markdown(k) } else { kind_text(k) }).collect();
    if args.markdown {
        out!("# Stage kinds\n\nGenerated by `amrepro stages --markdown` from the registry; do not edit by hand.\n\n{text}")?;
    } else {
        out!("{text}")?;
    }
    Ok(())
}

fn kind_text(kind: &dyn StageKind) -> String {
    let info = kind.info();
    let mut s = format!("{} (v{})\n  {}\n  implements: {}\n", info.name, info.version, info.summary, info.implements);
    for input in info.inputs {
        s += &format!(
            "  input {:<14} {:<10} {}: {}{}\n",
            input.role,
            count_text(input.count),
            sources_text(input.takes),
            input.doc,
            role_reads_text(input)
        );
    }
    for p in kind.params() {
        s += &format!("    {:<18} {:<28} default {:<12} {}\n", p.name, p.ty.to_string(), p.default.to_string(), p.doc);
    }
    s + "\n"
}

fn kind_markdown(kind: &dyn StageKind) -> String {
    let info = kind.info();
    let mut s = format!(
        "## `{}` (version {})\n\n{}\n\nImplements: {}.\n\n",
        info.name, info.version, info.summary, info.implements
    );
    for table in kind.writes() {
        let columns: Vec<String> = table.columns.iter().map(|c| format!("`{}` {}", c.name, c.dtype)).collect();
        s += &format!("Writes `{}` (declared in `tables`): {}.\n\n", table.file(), columns.join(", "));
    }
    if info.inputs.is_empty() {
        s += "No inputs.\n\n";
    } else {
        s += "| input role | count | takes | read for |\n|---|---|---|---|\n";
        for input in info.inputs {
            s += &format!(
                "| `{}` | {} | {} | {} |\n",
                input.role,
                count_text(input.count),
                sources_text(input.takes),
                format!("{}{}", input.doc, role_reads_text(input)).replace('|', "\\|")
            );
        }
        s += "\n";
    }
    if kind.params().is_empty() {
        return s + "No parameters.\n\n";
    }
    s += "| parameter | type | default | meaning |\n|---|---|---|---|\n";
    for p in kind.params() {
        s += &format!("| `{}` | {} | `{}` | {} |\n", p.name, p.ty, p.default, p.doc.replace('|', "\\|"));
    }
    s + "\n"
}

/// "; reads `t.parquet` (a, b)" for each declared table a role reads, and "; from a
/// `k`: reads …" for what it reads from an upstream kind `k` (checked at plan time).
fn role_reads_text(input: &Input) -> String {
    let by_kind = input
        .reads_by_kind
        .iter()
        .map(|(kind, reads)| format!("; from a `{kind}`{}", reads_text(reads).replacen("; reads", ", reads", 1)));
    reads_text(input.reads) + &by_kind.collect::<String>()
}

fn reads_text(reads: &[Reads]) -> String {
    reads.iter().map(|r| format!("; reads `{}` ({})", r.table.file(), r.columns.join(", "))).collect()
}

/// How many inputs a role takes, in words.
fn count_text(count: Count) -> String {
    match count {
        Count::One => "one".into(),
        Count::Optional => "optional".into(),
        Count::Many { min } => format!("{min} or more"),
    }
}

fn import_fsu(args: FsuImportArgs) -> Result<()> {
    let printers: Vec<FsuPrinter> = match &args.printer {
        Some(name) => vec![FsuPrinter::parse(name).expect("clap checked the value")],
        None => FsuPrinter::ALL.to_vec(),
    };
    if args.src.is_file() {
        bail!("{}: is a file, expected the folder holding taz5/ and taz6/. {}", args.src.display(), fsu::SOURCE_HINT);
    }
    if !args.src.is_dir() {
        bail!("{}: no such folder. {}", args.src.display(), fsu::SOURCE_HINT);
    }
    let opts = ImportOptions { verify_sha256: !args.no_verify };
    let written = fsu::import(&args.src, &args.out, &printers, opts)
        .with_context(|| format!("importing {}", args.src.display()))?;
    for dir in written {
        outln!("wrote fdm-widths dataset {}", dir.display())?;
    }
    Ok(())
}

/// The `--effect NAME --strength X` pairs of a generator, checked for matching counts.
fn effect_pairs<'a>(effects: &'a [String], strengths: &[f64]) -> Result<Vec<(&'a str, f64)>> {
    if effects.len() != strengths.len() {
        bail!("every --effect needs one --strength (got {} effects, {} strengths)", effects.len(), strengths.len());
    }
    Ok(effects.iter().map(String::as_str).zip(strengths.iter().copied()).collect())
}

fn generate_fdm(args: FdmGenerateArgs) -> Result<()> {
    use datasets::fdm_lines::camera::CameraSettings;
    use datasets::fdm_lines::generate::{conditions_named, generate, GenerateConfig};
    use models::fdm::printer::Effects;
    let pairs = effect_pairs(&args.effects, &args.strengths)?;
    let effects = Effects { gear_period_mm: args.gear_period_mm, ..Effects::from_pairs(pairs)? };
    let config = GenerateConfig {
        conditions: conditions_named(&args.conditions).context("an unknown condition set")?,
        lines_per_condition: args.lines_per_condition,
        effects,
        camera: CameraSettings {
            px_per_mm: args.px_per_mm,
            bit_depth: args.bit_depth.parse()?,
            ..CameraSettings::default()
        },
        ..GenerateConfig::new(&args.printer, args.seed)
    };
    let lines = generate(&config, &args.out).with_context(|| format!("generating {}", args.out.display()))?;
    let described: Vec<String> = effects.active().iter().map(|(n, s)| format!("{n} {s}")).collect();
    outln!(
        "wrote fdm-lines dataset {} ({lines} lines of the virtual {}, effects: {})",
        args.out.display(),
        args.printer,
        if described.is_empty() { "none".into() } else { described.join(", ") }
    )?;
    Ok(())
}

fn generate_thermal(args: ThermalGenerateArgs) -> Result<()> {
    use datasets::thermal::{generate, Effects, GenerateConfig, LeptonHabits};
    let pairs = effect_pairs(&args.effects, &args.strengths)?;
    let config = GenerateConfig {
        seed: args.seed,
        layers: args.layers.max(1),
        effects: Effects::from_pairs(pairs)?,
        lepton_habits: LeptonHabits { repeated_frames: args.lepton_habits, shutter_freeze: args.lepton_habits },
    };
    let summary = generate(&config, &args.out).with_context(|| format!("generating {}", args.out.display()))?;
    outln!(
        "wrote thermal-sequence dataset {} ({} layers, {} frames)",
        args.out.display(),
        summary.layers,
        summary.frames
    )?;
    Ok(())
}

fn generate_inkjet(args: InkjetGenerateArgs) -> Result<()> {
    use datasets::inkjet::{write_dataset, ControlLaw, Effects, GenerateOptions, Scenario};
    let pairs = effect_pairs(&args.effects, &args.strengths)?;
    let opts = GenerateOptions {
        scenario: Scenario::parse(&args.scenario)?,
        seed: args.seed,
        variation_pct: args.variation_pct,
        controller: if args.controller == "open_loop" { ControlLaw::OpenLoop } else { ControlLaw::ClosedLoop },
        effects: Effects::from_pairs(&pairs)?,
        open_loop_layers: args.layers,
    };
    let dir = write_dataset(&opts, &args.out).with_context(|| format!("generating {}", args.out.display()))?;
    outln!("wrote inkjet-scans dataset {} (effects: {})", dir.display(), opts.effects.describe())?;
    Ok(())
}

fn inject(args: InjectArgs) -> Result<()> {
    use models::fdm::discrepancy::inject::InjectSettings;
    let settings = InjectSettings { smoothing_mm: args.smoothing_mm, gear_period_mm: args.period_mm };
    let truth =
        datasets::fdm_inject::inject_dataset(&args.src, &args.dest, &args.effect, args.strength, args.seed, &settings)
            .with_context(|| format!("injecting `{}` into a copy of {}", args.effect, args.src.display()))?;
    let period = truth.gear_period_mm.map(|p| format!(", period {p:.3} mm")).unwrap_or_default();
    outln!(
        "wrote fdm-widths dataset {} ({} of strength {}{period}; truth in {})",
        args.dest.display(),
        truth.effect,
        truth.strength,
        args.dest.join(datasets::fdm_inject::TRUTH_FILE).display()
    )?;
    Ok(())
}

fn diff(args: DiffArgs) -> Result<()> {
    for dir in [&args.a, &args.b] {
        if !dir.join("runs").is_dir() {
            bail!("{}: not an out folder (no runs/ in it)", dir.display());
        }
    }
    let mut diff = pipeline::diff::diff_out_dirs(&args.a, &args.b, args.rel_tol)
        .with_context(|| format!("comparing {} with {}", args.a.display(), args.b.display()))?;
    diff.max_listed = args.max_rows;
    out!("{diff}")?;
    Ok(())
}

fn report(out: &std::path::Path) -> Result<()> {
    let _lock = open_out_dir(out, "report")?;
    let path = write_report(out)?;
    outln!("report: {}", path.display())?;
    Ok(())
}
