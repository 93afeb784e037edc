//! Command-line arguments (clap derive): the raw values; `commands` resolves them.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};

/// `amrepro --version`: the release, then the whole program's code fingerprint, the
/// fingerprint of each crate's code, which the cache key of every stage kind that crate
/// defines holds, and the toolchain that built it (`build.rs`), which workers of one
/// run spread over machines must share (docs/SCALE.md).
const LONG_VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    "\ncode fingerprint: ",
    env!("AMREPRO_CODE_FINGERPRINT"),
    "\ncode by crate: ",
    env!("AMREPRO_CODE_BY_CRATE"),
    "\nbuilt by: ",
    env!("AMREPRO_TOOLCHAIN")
);

/// Reproduce additive-manufacturing papers end to end: declarative specs of stages
/// that write Parquet tables, figures and an HTML report.
#[derive(Debug, Parser)]
#[command(name = "amrepro", version, long_version = LONG_VERSION, about)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a spec: every stage whose inputs or parameters changed, then the report.
    Run(RunArgs),
    /// Print a spec's stage graph.
    Graph(GraphArgs),
    /// List every registered stage kind with its parameters.
    Stages(StagesArgs),
    /// List the tables specs publish: path, writing stage and declared columns.
    Outputs(OutputsArgs),
    /// Import or inspect datasets.
    #[command(subcommand)]
    Datasets(DatasetsCommand),
    /// Rebuild the HTML report from the manifests under the out folder.
    Report(ReportArgs),
    /// List the published numbers that changed between two out folders: per table, the
    /// row's key, the column, old → new and the relative change.
    Diff(DiffArgs),
    /// Benchmark night: run every spec from scratch, append its numbers and timings to a
    /// history, and write report/nightly.html with trends and regressions (docs/NIGHTLY.md).
    Nightly(NightlyArgs),
    /// List a spec's work units (JSON lines): what `run-unit` runs, one process or
    /// machine each (docs/SCALE.md).
    Plan(PlanArgs),
    /// Run one work unit of a spec into a shared out folder; a no-op when it is done.
    RunUnit(RunUnitArgs),
    /// Check that every work unit is in the shared out folder, merge, run the rest of
    /// the spec and write the report.
    Collect(CollectArgs),
    /// Write a Snakemake workflow that runs a spec's work units and collects them.
    Snakefile(SnakefileArgs),
    /// Photos of a printed pressure-advance pattern and its G-code → the pressure advance
    /// to set, with its 95 % interval, the melt's lag and the figures (README: pressure advance).
    PressureAdvance(PressureAdvanceArgs),
}

/// `amrepro pressure-advance`.
#[derive(Debug, Args)]
pub struct PressureAdvanceArgs {
    /// The G-code that printed the pattern (straight lines, each under its own
    /// SET_PRESSURE_ADVANCE or M900, with speed changes along them).
    #[arg(long)]
    pub gcode: PathBuf,
    /// Top-view photos of the printed pattern (JPEG or PNG), the whole pattern in view.
    #[arg(required = true)]
    pub photos: Vec<PathBuf>,
    /// The firmware that ran the G-code: klipper or marlin.
    #[arg(long, default_value = "klipper")]
    pub firmware: String,
    /// Filament diameter (mm).
    #[arg(long, default_value_t = 1.75)]
    pub filament_diameter_mm: f64,
    /// Nozzle diameter (mm).
    #[arg(long, default_value_t = 0.4)]
    pub nozzle_diameter_mm: f64,
    /// The printer's name (in the tables).
    #[arg(long, default_value = "printer")]
    pub printer: String,
    /// Out folder: the inputs' copies, the spec, the tables, figures and report.
    #[arg(long, default_value = "out/pressure-advance")]
    pub out: PathBuf,
    /// Print only errors and the result.
    #[arg(short, long)]
    pub quiet: bool,
}

/// `amrepro plan`.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// The spec file (TOML).
    pub spec: PathBuf,
    /// Print only the indices of the units at this level (the units they need are all at
    /// lower levels), as a list for `sbatch --array=`.
    #[arg(long, value_name = "LEVEL")]
    pub array_of_level: Option<usize>,
}

/// `amrepro run-unit`.
#[derive(Debug, Args)]
pub struct RunUnitArgs {
    /// The spec file (TOML).
    pub spec: PathBuf,
    /// The unit's index in `amrepro plan SPEC`.
    #[arg(long)]
    pub index: usize,
    /// The shared out folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Wait up to this long for the units it needs to finish (for schedulers that start
    /// units without ordering them, such as job arrays).
    #[arg(long, value_name = "SECONDS", default_value_t = 0)]
    pub wait: u64,
    /// Print only errors.
    #[arg(short, long)]
    pub quiet: bool,
}

/// `amrepro collect`.
#[derive(Debug, Args)]
pub struct CollectArgs {
    /// The spec file (TOML).
    pub spec: PathBuf,
    /// The shared out folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Print only errors.
    #[arg(short, long)]
    pub quiet: bool,
}

/// `amrepro snakefile`.
#[derive(Debug, Args)]
pub struct SnakefileArgs {
    /// The spec file (TOML).
    pub spec: PathBuf,
    /// The shared out folder the workflow writes (can be changed with `--config out=…`).
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Where to write the workflow (default: standard output).
    #[arg(short = 'o', long, value_name = "FILE")]
    pub output: Option<PathBuf>,
}

/// `amrepro nightly`.
#[derive(Debug, Args)]
pub struct NightlyArgs {
    /// The specs to run (default: every specs/*.toml of the current folder, the shipped ones).
    pub specs: Vec<PathBuf>,
    /// The history folder (Parquet, partitioned by date; created if absent, only ever appended to).
    #[arg(long, value_name = "DIR")]
    pub history: PathBuf,
    /// Out folder of the runs and of report/nightly.html.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Exit with status 3 when the night has a regression (for a scheduler to alert on).
    #[arg(long)]
    pub fail_on_regression: bool,
    /// Print only errors and the summary.
    #[arg(short, long)]
    pub quiet: bool,
}

/// `amrepro run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// The spec file (TOML).
    pub spec: PathBuf,
    /// Out folder.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Print which stages would run and why, run nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Run only this stage (and whatever of its upstream is out of date).
    #[arg(long, value_name = "STAGE")]
    pub only: Option<String>,
    /// Run even when the cache says the outputs are up to date.
    #[arg(long)]
    pub force: bool,
    /// Print the checked plan before running.
    #[arg(short, long, conflicts_with = "quiet")]
    pub verbose: bool,
    /// Print only errors.
    #[arg(short, long)]
    pub quiet: bool,
    /// Set a stage's parameter in place of the spec's value (repeatable; checked as the
    /// spec's own values are; VALUE is read as TOML, or as a string when it is none).
    #[arg(long = "set", value_name = "STAGE.PARAM=VALUE", value_parser = parse_override)]
    pub sets: Vec<pipeline::spec::Override>,
}

/// Parses one `--set` (clap's value parser).
fn parse_override(text: &str) -> Result<pipeline::spec::Override, String> {
    pipeline::spec::Override::parse(text)
}

/// `amrepro diff`.
#[derive(Debug, Args)]
pub struct DiffArgs {
    /// The first out folder (the old numbers).
    pub a: PathBuf,
    /// The second out folder (the new numbers).
    pub b: PathBuf,
    /// Count numbers within this relative difference (of the larger magnitude) as
    /// unchanged.
    #[arg(long, default_value_t = 0.0, value_name = "REL")]
    pub rel_tol: f64,
    /// Changed numbers listed per table (the counts are always complete).
    #[arg(long, default_value_t = 20, value_name = "N")]
    pub max_rows: usize,
}

/// `amrepro graph`.
#[derive(Debug, Args)]
pub struct GraphArgs {
    /// The spec file (TOML).
    pub spec: PathBuf,
    /// Output format.
    #[arg(long, value_enum, default_value_t = GraphFormatArg::Dot)]
    pub format: GraphFormatArg,
}

/// Graph output formats.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum GraphFormatArg {
    /// Graphviz dot.
    Dot,
    /// Mermaid flowchart.
    Mermaid,
}

/// `amrepro stages`.
#[derive(Debug, Args)]
pub struct StagesArgs {
    /// Print Markdown (as in docs/STAGES.md) instead of plain text.
    #[arg(long)]
    pub markdown: bool,
}

/// `amrepro outputs`.
#[derive(Debug, Args)]
pub struct OutputsArgs {
    /// Print Markdown (as in docs/COLUMNS.md) instead of plain text.
    #[arg(long)]
    pub markdown: bool,
    /// The spec files whose `publish` lists to read.
    #[arg(required = true)]
    pub specs: Vec<PathBuf>,
}

/// `amrepro datasets ...`.
#[derive(Debug, Subcommand)]
pub enum DatasetsCommand {
    /// Convert raw measured data into datasets of our format.
    #[command(subcommand)]
    Import(ImportCommand),
    /// Write datasets from a virtual printer.
    #[command(subcommand)]
    Generate(GenerateCommand),
    /// Copy an fdm-widths dataset with one effect hidden in its widths by its physics
    /// (bed_tilt, gear_eccentricity, flow_saturation or none); what was injected goes to
    /// DEST/truth/effect.toml.
    Inject(InjectArgs),
}

/// `amrepro datasets inject`.
#[derive(Debug, Args)]
pub struct InjectArgs {
    /// The effect: none, bed_tilt (strength: relative width change from the line's start
    /// to its end, signed), gear_eccentricity (relative flow ripple), flow_saturation
    /// (relative width loss at the fastest line's cruise flow).
    #[arg(long)]
    pub effect: String,
    /// Its strength (0 for none).
    #[arg(long, allow_negative_numbers = true)]
    pub strength: f64,
    /// Seed of its random parts (the gear's period when not given, each line's phase).
    #[arg(long)]
    pub seed: u64,
    /// The gear ripple's period in path length (mm, 2-60); drawn in 4-40 mm from the
    /// seed when not given.
    #[arg(long, value_name = "MM")]
    pub period_mm: Option<f64>,
    /// The bead's smoothing along the path (mm), as the model's.
    #[arg(long, value_name = "MM", default_value_t = 0.5)]
    pub smoothing_mm: f64,
    /// The fdm-widths dataset to copy.
    pub src: PathBuf,
    /// The folder to write (absent, empty, or an earlier output of this command).
    pub dest: PathBuf,
}

/// Virtual-printer generators, one variant each (arguments in one struct per generator).
#[derive(Debug, Subcommand)]
pub enum GenerateCommand {
    /// The virtual ink-jet printer of paper 002: an inkjet-scans dataset (scan after every layer).
    Inkjet(InkjetGenerateArgs),
    /// The virtual FDM printer of paper 000's single lines with a top-view camera: an
    /// fdm-lines dataset (photos, kinematics, truth/).
    Fdm(FdmGenerateArgs),
    /// The virtual extrusion printer with a nozzle-mounted thermal camera of paper 003:
    /// a thermal-sequence dataset (frames, trajectory, camera, truth/).
    Thermal(ThermalGenerateArgs),
}

/// `amrepro datasets generate fdm`.
#[derive(Debug, Args)]
pub struct FdmGenerateArgs {
    /// The printer profile, calibrated to the real lines of data/fsu-linewidth.
    #[arg(long, value_parser = ["taz5", "taz6"])]
    pub printer: String,
    /// The set of (acceleration, feed) conditions: ren2021 (paper 000 Table I, nine lines).
    #[arg(long, value_parser = ["ren2021"], default_value = "ren2021")]
    pub conditions: String,
    /// Seed of every random stream.
    #[arg(long)]
    pub seed: u64,
    /// An extra effect (bed_tilt, gear_eccentricity, flow_saturation, camera_scale_error);
    /// repeat, each followed by --strength.
    #[arg(long = "effect", value_name = "NAME")]
    pub effects: Vec<String>,
    /// Strength of the preceding --effect (same order).
    #[arg(long = "strength", value_name = "X", allow_negative_numbers = true)]
    pub strengths: Vec<f64>,
    /// The gear ripple's period in path length (mm), with --effect gear_eccentricity.
    #[arg(long, default_value_t = 12.0)]
    pub gear_period_mm: f64,
    /// Lines printed per condition.
    #[arg(long, default_value_t = 1)]
    pub lines_per_condition: usize,
    /// The camera's scale (px/mm).
    #[arg(long, default_value_t = 40.0)]
    pub px_per_mm: f64,
    /// Bits per pixel of the photos.
    #[arg(long, value_parser = ["8", "16"], default_value = "8")]
    pub bit_depth: String,
    /// Dataset folder to write (replaced atomically if it is an earlier output of this command).
    #[arg(long)]
    pub out: PathBuf,
}

/// `amrepro datasets generate thermal`.
#[derive(Debug, Args)]
pub struct ThermalGenerateArgs {
    /// Seed of every random stream.
    #[arg(long)]
    pub seed: u64,
    /// Layers printed and filmed.
    #[arg(long, default_value_t = 1)]
    pub layers: usize,
    /// An extra effect (camera_latency, tau_mismatch, heat_diffusion_widening,
    /// layer_heat_accumulation, melt_squeeze_out); repeat, each followed by --strength.
    #[arg(long = "effect", value_name = "NAME")]
    pub effects: Vec<String>,
    /// Strength of the preceding --effect (same order).
    #[arg(long = "strength", value_name = "X", allow_negative_numbers = true)]
    pub strengths: Vec<f64>,
    /// Let the camera repeat frames and freeze for its shutter, as FLIR Leptons do.
    #[arg(long)]
    pub lepton_habits: bool,
    /// Dataset folder to write (replaced atomically).
    #[arg(long)]
    pub out: PathBuf,
}

/// `amrepro datasets generate inkjet`.
#[derive(Debug, Args)]
pub struct InkjetGenerateArgs {
    /// The part: cylinder (Figs 11-12), cuboid (Table II) or pipe_junction (Figs 13-15).
    #[arg(long, value_parser = ["cylinder", "cuboid", "pipe_junction"])]
    pub scenario: String,
    /// Seed of every random stream.
    #[arg(long)]
    pub seed: u64,
    /// An extra effect (curing_shrinkage, levelling_flow, nozzle_bias, substrate_tilt,
    /// volume_drift); repeat, each followed by --strength.
    #[arg(long = "effect", value_name = "NAME")]
    pub effects: Vec<String>,
    /// Strength of the preceding --effect (same order).
    #[arg(long = "strength", value_name = "X", allow_negative_numbers = true)]
    pub strengths: Vec<f64>,
    /// Largest droplet-volume shortfall in percent (the paper's [0 20%]).
    #[arg(long, default_value_t = 20.0)]
    pub variation_pct: f64,
    /// How the layer patterns are chosen.
    #[arg(long, value_parser = ["open_loop", "closed_loop"], default_value = "open_loop")]
    pub controller: String,
    /// Open-loop layer count (default: the scenario's nominal count).
    #[arg(long)]
    pub layers: Option<usize>,
    /// Dataset folder to write (replaced atomically if it is an inkjet-scans dataset).
    #[arg(long)]
    pub out: PathBuf,
}

/// Importers.
#[derive(Debug, Subcommand)]
pub enum ImportCommand {
    /// The FSU Taz 5 / Taz 6 line widths (paper 000): writes OUT/taz5 and OUT/taz6 as fdm-widths datasets.
    #[command(name = "fsu-linewidth")]
    FsuLinewidth(FsuImportArgs),
}

/// `amrepro datasets import fsu-linewidth`.
#[derive(Debug, Args)]
pub struct FsuImportArgs {
    /// Folder holding taz5/ and taz6/ (the unzipped Linewidth_Data.zip).
    #[arg(long)]
    pub src: PathBuf,
    /// Folder to write the datasets into.
    #[arg(long)]
    pub out: PathBuf,
    /// Import only this printer.
    #[arg(long, value_parser = ["taz5", "taz6"])]
    pub printer: Option<String>,
    /// Skip the SHA-256 check against the published release (for your own data).
    #[arg(long)]
    pub no_verify: bool,
}

/// `amrepro report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// Out folder holding runs/.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
}
