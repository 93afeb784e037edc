//! The `inkjet-scans` generator: one print of a paper-002 scenario on the virtual printer
//! of [`models::inkjet::printer`] (the same machine the experiment stages print on), with
//! the profiler's scan after every layer, written as a dataset.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use models::inkjet::experiments::{cuboid, cylinder, pipe_junction, run_print, ControlLaw, PrintRecording};
use models::inkjet::height_model::Material;
use models::inkjet::printer::Effects;
use models::inkjet::InkjetError;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::format::{GridToml, InkjetScans, ProfilerToml, FORMAT_VERSION, KIND, READABLE_VERSIONS};
use crate::error::DatasetError;
use crate::limits::{check_option, INKJET_LAYERS};
use crate::manifest::{DatasetManifest, Provenance};
use crate::output::{OutputDir, Ownership};

/// Generator name recorded in `dataset.toml`.
pub const GENERATOR: &str = "amrepro-inkjet-virtual";
/// The folders the generator may replace: absent, empty, or a dataset it wrote.
pub const OUTPUT: Ownership = Ownership {
    kind: KIND,
    versions: READABLE_VERSIONS,
    writer: "datasets generate inkjet",
    written_by_us: |p| matches!(p, Provenance::Virtual { generator, .. } if generator == GENERATOR),
};

/// Why a dataset could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// A scenario, controller or effect that does not exist or is out of range.
    #[error("{0}")]
    Model(#[from] InkjetError),
    /// An unknown scenario name.
    #[error("unknown scenario `{0}` (known: cylinder, cuboid, pipe_junction)")]
    UnknownScenario(String),
    /// Writing the dataset failed, or its folder is not ours to replace.
    #[error("{0}")]
    Dataset(#[from] DatasetError),
}

/// The paper-002 parts the generator can print.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scenario {
    /// Sec. V-A cylinder (Figs 11-12), `h_d = 400 µm`.
    Cylinder,
    /// Table II cuboid, 8 × 8 droplets, `h_d = 22.8 µm`.
    Cuboid,
    /// Figs 13-15 two-material pipe junction, 100 × 100 grid.
    PipeJunction,
}

impl Scenario {
    /// The scenario of that name.
    pub fn parse(name: &str) -> Result<Self, GenerateError> {
        match name {
            "cylinder" => Ok(Self::Cylinder),
            "cuboid" => Ok(Self::Cuboid),
            "pipe_junction" => Ok(Self::PipeJunction),
            other => Err(GenerateError::UnknownScenario(other.to_string())),
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Cylinder => "cylinder",
            Self::Cuboid => "cuboid",
            Self::PipeJunction => "pipe_junction",
        }
    }
}

/// Everything that determines a generated dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct GenerateOptions {
    /// The part.
    pub scenario: Scenario,
    /// Seed of every random stream (droplets, profiler, nozzles, controller).
    pub seed: u64,
    /// Largest droplet-volume shortfall, percent.
    pub variation_pct: f64,
    /// Open or closed loop.
    pub controller: ControlLaw,
    /// Extra physical effects.
    pub effects: Effects,
    /// Open-loop layer count (`None`: the scenario's nominal count).
    pub open_loop_layers: Option<usize>,
}

/// Prints the scenario and returns the dataset and the true heights per layer.
pub fn generate(opts: &GenerateOptions) -> Result<(InkjetScans, Vec<Vec<f64>>), GenerateError> {
    if !(0.0..=100.0).contains(&opts.variation_pct) {
        return Err(InkjetError::InvalidParameter {
            name: "variation_pct",
            value: opts.variation_pct,
            reason: "must lie in [0, 100] percent",
        }
        .into());
    }
    let p = opts.variation_pct / 100.0;
    let mut scenario = match opts.scenario {
        Scenario::Cylinder => cylinder(p),
        Scenario::Cuboid => cuboid(p),
        Scenario::PipeJunction => pipe_junction(p),
    };
    if let Some(layers) = opts.open_loop_layers {
        check_option("--layers", layers.max(1), &INKJET_LAYERS)?;
        scenario.open_loop_layers = layers.max(1);
    }
    scenario.truth.effects = opts.effects;
    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    let (_, recording) = run_print(&scenario, opts.controller, &mut rng, true)?;
    let recording = recording.expect("recorded");
    let grid = scenario.target.grid();
    let grid_toml = GridToml {
        m_x: grid.m_x,
        m_y: grid.m_y,
        spacing_um: grid.spacing_um,
        desired_height_um: scenario.target.mean_desired_um(),
        scenario: opts.scenario.name().to_string(),
        controller: opts.controller.name().to_string(),
        variation_pct: opts.variation_pct,
        part: scenario.model.into(),
        support: scenario.two_material.map(|t| t.support.into()),
        profiler: ProfilerToml {
            noise_um: scenario.truth.profiler.noise_um,
            spot_sigma_um: scenario.truth.profiler.spot_sigma_um,
        },
    };
    let target = (0..grid.len())
        .map(|c| scenario.target.footprint.droplet[c].then_some(scenario.target.desired.height_um[c]))
        .collect();
    let (scans, patterns, truth) = unpack(recording);
    let dataset = InkjetScans { manifest: manifest(opts), grid: grid_toml, target, scans, patterns };
    Ok((dataset, truth))
}

/// Per-layer height maps, row-major.
type Layers = Vec<Vec<f64>>;

/// Scans, patterns and true heights of a recording, in the dataset's layout.
fn unpack(recording: PrintRecording) -> (Layers, Vec<Vec<Option<Material>>>, Layers) {
    let mut scans = vec![recording.substrate_measured.height_um];
    let mut truth = vec![recording.substrate_truth.height_um];
    let mut patterns = Vec::with_capacity(recording.layers.len());
    for layer in recording.layers {
        patterns.push(layer.pattern.droplet.iter().zip(&layer.materials).map(|(&d, &m)| d.then_some(m)).collect());
        scans.push(layer.measured.height_um);
        truth.push(layer.truth.height_um);
    }
    (scans, patterns, truth)
}

fn manifest(opts: &GenerateOptions) -> DatasetManifest {
    let units = [("height_um", "um"), ("spacing_um", "um"), ("desired_um", "um"), ("variation_pct", "percent")]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let effects: BTreeMap<String, f64> =
        opts.effects.active().iter().map(|(e, s)| (e.name().to_string(), *s)).collect();
    DatasetManifest {
        kind: KIND.to_string(),
        format_version: FORMAT_VERSION,
        printer: "virtual-inkjet".to_string(),
        description: format!(
            "Virtual ink-jet print of the paper-002 {} ({}, droplet shortfall U[0, {}%]), profiler scan after every layer; extra effects: {}.",
            opts.scenario.name(),
            opts.controller.name(),
            opts.variation_pct,
            opts.effects.describe()
        ),
        units,
        provenance: Provenance::Virtual {
            generator: GENERATOR.to_string(),
            version: env!("CARGO_PKG_VERSION").to_string(),
            seed: opts.seed,
            effects,
        },
    }
}

/// Generates and writes the dataset to `out` atomically ([`OutputDir`]: an existing
/// `out` must be empty or a dataset this generator wrote, so nothing else is replaced).
pub fn write_dataset(opts: &GenerateOptions, out: &Path) -> Result<PathBuf, GenerateError> {
    let output = OutputDir::begin(out, &OUTPUT)?;
    let (dataset, truth) = generate(opts)?;
    dataset.write(output.path(), Some(&truth))?;
    Ok(output.commit()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(controller: ControlLaw, effects: Effects) -> GenerateOptions {
        GenerateOptions {
            scenario: Scenario::Cuboid,
            seed: 7,
            variation_pct: 20.0,
            controller,
            effects,
            open_loop_layers: None,
        }
    }

    #[test]
    fn a_generated_dataset_reads_back_identically() {
        let effects = Effects::parse("curing_shrinkage=0.05").unwrap();
        let opts = options(ControlLaw::ClosedLoop, effects);
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("scans");
        write_dataset(&opts, &out).unwrap();
        let read = InkjetScans::read(&out).unwrap();
        let (made, truth) = generate(&opts).unwrap();
        assert_eq!(read.grid, made.grid);
        assert_eq!(read.manifest, made.manifest);
        assert_eq!(read.target, made.target);
        assert_eq!(read.patterns, made.patterns);
        assert_eq!(read.scans.len(), read.layers() + 1);
        // Heights are written to 0.1 nm.
        for (a, b) in read.scans.iter().flatten().zip(made.scans.iter().flatten()) {
            assert!((a - b).abs() <= 5e-5);
        }
        let read_truth = InkjetScans::read_truth(&out, &read.grid).unwrap();
        assert_eq!(read_truth.len(), truth.len());
        let Provenance::Virtual { effects, seed, .. } = &read.manifest.provenance else { panic!("virtual") };
        assert_eq!((effects.get("curing_shrinkage"), *seed), (Some(&0.05), 7));
        // Writing again replaces the folder.
        write_dataset(&opts, &out).unwrap();
    }

    #[test]
    fn the_same_seed_gives_the_same_dataset_and_the_open_loop_prints_the_footprint() {
        let opts = options(ControlLaw::OpenLoop, Effects::none());
        let (a, _) = generate(&opts).unwrap();
        let (b, _) = generate(&opts).unwrap();
        assert_eq!(a, b);
        assert_eq!(a.layers(), 3);
        let footprint: Vec<bool> = a.target.iter().map(Option::is_some).collect();
        assert!(a.patterns.iter().all(|p| p.iter().map(Option::is_some).collect::<Vec<_>>() == footprint));
    }

    #[test]
    fn bad_files_are_reported_with_file_line_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("scans");
        write_dataset(&options(ControlLaw::OpenLoop, Effects::none()), &out).unwrap();
        let scans = std::fs::read_to_string(out.join("scans.csv")).unwrap();
        std::fs::write(out.join("scans.csv"), scans.replacen("0,0,0,", "0,0,99,", 1)).unwrap();
        let err = InkjetScans::read(&out).unwrap_err().to_string();
        assert!(err.contains("scans.csv:line 2, field j: expected a cell index in 0..14, got `99`"), "{err}");
        std::fs::write(out.join("scans.csv"), scans).unwrap();
        let patterns = std::fs::read_to_string(out.join("patterns.csv")).unwrap();
        std::fs::write(out.join("patterns.csv"), patterns.replacen(",part", ",gel", 1)).unwrap();
        let err = InkjetScans::read(&out).unwrap_err().to_string();
        assert!(err.contains("patterns.csv:line 2, field material: expected `part` or `support`, got `gel`"), "{err}");
        std::fs::write(out.join("patterns.csv"), patterns.replacen("1,", "9,", 1)).unwrap();
        let err = InkjetScans::read(&out).unwrap_err().to_string();
        assert!(err.contains("field layer"), "{err}");
    }

    #[test]
    fn refuses_to_replace_a_folder_that_is_not_a_dataset() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("precious.txt"), "keep").unwrap();
        let err = write_dataset(&options(ControlLaw::OpenLoop, Effects::none()), dir.path()).unwrap_err();
        assert!(err.to_string().contains("refusing"), "{err}");
        assert!(dir.path().join("precious.txt").is_file());
        assert!(matches!(Scenario::parse("sphere"), Err(GenerateError::UnknownScenario(_))));
    }

    #[test]
    fn a_layer_count_beyond_the_bound_is_refused_before_printing() {
        let opts =
            GenerateOptions { open_loop_layers: Some(usize::MAX), ..options(ControlLaw::OpenLoop, Effects::none()) };
        let err = generate(&opts).unwrap_err().to_string();
        assert_eq!(err, format!("--layers: expected 1 to 1000, got {}", usize::MAX));
    }

    #[test]
    fn refuses_to_replace_measured_scans_and_leaves_no_staging_folder() {
        // A hand-written inkjet-scans dataset is somebody's measurement, not ours to replace.
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("mine");
        let mut scans = generate(&options(ControlLaw::OpenLoop, Effects::none())).unwrap().0;
        scans.manifest.provenance =
            Provenance::Measured { source: "lab".into(), license: "CC0".into(), imported_by: "hand".into() };
        scans.write(&out, None).unwrap();
        let err = write_dataset(&options(ControlLaw::OpenLoop, Effects::none()), &out).unwrap_err().to_string();
        assert!(err.contains("refusing to replace it"), "{err}");
        assert!(matches!(InkjetScans::read(&out).unwrap().manifest.provenance, Provenance::Measured { .. }));
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, ["mine"]);
    }
}
