//! `amrepro datasets inject`: copies an `fdm-widths` dataset with one effect hidden in
//! its widths by its physics (`models::fdm::discrepancy::inject`), and records what was
//! injected in `truth/effect.toml`, which only evaluation stages read (DESIGN §7).
//!
//! ```text
//! DEST/dataset.toml        provenance: virtual, generator "amrepro datasets inject", the
//!                          seed and the effect with its strength; description names SRC
//! DEST/lines.csv, widths/  as SRC, widths changed by the effect
//! DEST/truth/effect.toml   effect, strength and its parameter name, seed, and for the
//!                          gear its period and each line's phase
//! ```
//!
//! The copy is written into a staging folder beside DEST and renamed into place. DEST
//! must not exist, be empty, or be an earlier output of this command; nothing else is
//! replaced.

use std::path::{Path, PathBuf};

use models::fdm::discrepancy::inject::{inject, Effect, InjectSettings, Injection};
use models::fdm::{LineKinematics, MeasuredLine};
use serde::{Deserialize, Serialize};

use crate::error::DatasetError;
use crate::fdm_widths::{FdmWidthsDataset, WidthLine, KIND, READABLE_VERSIONS};
use crate::manifest::Provenance;
use crate::output::{write_file, OutputDir, Ownership};
use crate::text::read_toml;

/// The generator name written into the copy's provenance.
pub const GENERATOR: &str = "amrepro datasets inject";
/// The truth file, relative to the dataset folder.
pub const TRUTH_FILE: &str = "truth/effect.toml";
/// The folders `inject` may replace: absent, empty, or an earlier output of it.
pub const OUTPUT: Ownership = Ownership {
    kind: KIND,
    versions: READABLE_VERSIONS,
    writer: "datasets inject",
    written_by_us: |p| matches!(p, Provenance::Virtual { generator, .. } if generator == GENERATOR),
};

/// `truth/effect.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectTruth {
    /// Effect name (`none`, `bed_tilt`, `gear_eccentricity`, `flow_saturation`), equal
    /// to the discrepancy mechanism's.
    pub effect: String,
    /// Strength, in the unit of `strength_parameter`.
    pub strength: f64,
    /// The mechanism parameter the strength is (`width_change`, `amplitude`,
    /// `loss_at_fastest_feed`; empty for `none`).
    pub strength_parameter: String,
    /// Seed of the injection's random parts.
    pub seed: u64,
    /// The dataset injected into.
    pub source: String,
    /// Gear period (mm), for `gear_eccentricity`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gear_period_mm: Option<f64>,
    /// The saturation's reference speed (mm/s), for `flow_saturation`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_speed_mm_s: Option<f64>,
    /// Per line: its id and, for the gear, its phase (rad).
    #[serde(default)]
    pub lines: Vec<LineTruth>,
}

/// One line of the truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineTruth {
    /// `line_id` in `lines.csv`.
    pub line_id: String,
    /// Gear ripple phase (rad), for `gear_eccentricity`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gear_phase_rad: Option<f64>,
}

/// Why an injection could not be made.
#[derive(Debug, thiserror::Error)]
pub enum InjectDatasetError {
    /// The source dataset could not be read or the copy written.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The effect name is unknown.
    #[error("unknown effect `{0}`; expected one of none, bed_tilt, gear_eccentricity, flow_saturation")]
    Effect(String),
    /// The physics refused the strength or the result.
    #[error("{0}")]
    Inject(#[from] models::fdm::discrepancy::inject::InjectError),
    /// A line of the source has no valid kinematics or widths.
    #[error("{file}: line_id {line_id}: {reason}")]
    Line {
        /// `lines.csv` of the source.
        file: PathBuf,
        /// The line.
        line_id: String,
        /// What is wrong.
        reason: String,
    },
    /// The destination is the source itself.
    #[error("{}: is the source dataset itself; choose a new folder", path.display())]
    SameAsSource {
        /// The destination.
        path: PathBuf,
    },
}

/// Reads `src`, injects `effect_name` of `strength` with `seed`, and writes the copy
/// to `dest` atomically. Returns what was injected.
pub fn inject_dataset(
    src: &Path,
    dest: &Path,
    effect_name: &str,
    strength: f64,
    seed: u64,
    settings: &InjectSettings,
) -> Result<EffectTruth, InjectDatasetError> {
    let effect = Effect::parse(effect_name).ok_or_else(|| InjectDatasetError::Effect(effect_name.into()))?;
    if let (Ok(a), Ok(b)) = (src.canonicalize(), dest.canonicalize()) {
        if a == b {
            return Err(InjectDatasetError::SameAsSource { path: dest.to_path_buf() });
        }
    }
    let output = OutputDir::begin(dest, &OUTPUT)?;
    let dataset = FdmWidthsDataset::read(src)?;
    let lines = measured_lines(src, &dataset)?;
    let (injected, record) = inject(&lines, effect, strength, seed, settings)?;
    let copy = injected_copy(src, &dataset, &injected, &record);
    let truth = truth_of(src, &dataset, &record);
    copy.write(output.path())?;
    write_file(output.path(), TRUTH_FILE, toml::to_string_pretty(&truth).expect("truth serialises").as_bytes())?;
    output.commit()?;
    Ok(truth)
}

fn measured_lines(src: &Path, dataset: &FdmWidthsDataset) -> Result<Vec<MeasuredLine>, InjectDatasetError> {
    dataset
        .lines
        .iter()
        .map(|l| {
            let bad = |reason: String| InjectDatasetError::Line {
                file: src.join("lines.csv"),
                line_id: l.line_id.clone(),
                reason,
            };
            let m = l.motion;
            let k = LineKinematics::new(m.accel_mm_s2, m.feed_mm_s, m.jerk_mm_s, m.length_mm)
                .map_err(|e| bad(e.to_string()))?;
            MeasuredLine::new(k, l.positions_mm.clone(), l.widths_mm.clone()).map_err(|e| bad(e.to_string()))
        })
        .collect()
}

fn injected_copy(
    src: &Path,
    dataset: &FdmWidthsDataset,
    injected: &[MeasuredLine],
    record: &Injection,
) -> FdmWidthsDataset {
    let mut manifest = dataset.manifest.clone();
    let name = record.effect.name();
    manifest.description = format!(
        "{} [copy of {} with `{name}` of strength {} injected by {GENERATOR} (seed {}); truth in {TRUTH_FILE}]",
        dataset.manifest.description,
        src.display(),
        record.strength,
        record.seed
    )
    .trim_start()
    .to_string();
    manifest.provenance = Provenance::Virtual {
        generator: GENERATOR.into(),
        version: env!("CARGO_PKG_VERSION").into(),
        seed: record.seed,
        effects: [(name.to_string(), record.strength)].into(),
    };
    let lines = dataset
        .lines
        .iter()
        .zip(injected)
        .map(|(l, m)| WidthLine { widths_mm: m.widths_mm.clone(), ..l.clone() })
        .collect();
    FdmWidthsDataset { manifest, lines }
}

fn truth_of(src: &Path, dataset: &FdmWidthsDataset, record: &Injection) -> EffectTruth {
    let lines = dataset
        .lines
        .iter()
        .enumerate()
        .map(|(i, l)| LineTruth { line_id: l.line_id.clone(), gear_phase_rad: record.gear_phases_rad.get(i).copied() })
        .collect();
    EffectTruth {
        effect: record.effect.name().into(),
        strength: record.strength,
        strength_parameter: record.effect.strength_parameter().unwrap_or_default().into(),
        seed: record.seed,
        source: src.display().to_string(),
        gear_period_mm: record.gear_period_mm,
        reference_speed_mm_s: record.reference_speed_mm_s,
        lines,
    }
}

/// Reads `truth/effect.toml` of an injected dataset (for evaluation).
pub fn read_truth(dir: &Path) -> Result<EffectTruth, DatasetError> {
    read_toml(&dir.join(TRUTH_FILE))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fdm_widths::{LineMotion, FORMAT_VERSION};
    use crate::manifest::DatasetManifest;

    fn source(dir: &Path) {
        let manifest = DatasetManifest {
            kind: KIND.into(),
            format_version: FORMAT_VERSION,
            printer: "demo".into(),
            description: "two lines".into(),
            units: [("width".to_string(), "mm".to_string())].into(),
            provenance: Provenance::Measured {
                source: "hand".into(),
                license: "CC0".into(),
                imported_by: "test".into(),
            },
        };
        let line = |id: &str, feed: f64| WidthLine {
            line_id: id.into(),
            condition: id.into(),
            motion: LineMotion { accel_mm_s2: 500.0, feed_mm_s: feed, jerk_mm_s: 8.0, length_mm: 100.0 },
            positions_mm: (0..=100).map(f64::from).collect(),
            widths_mm: vec![0.8; 101],
        };
        FdmWidthsDataset { manifest, lines: vec![line("a", 60.0), line("b", 120.0)] }.write(dir).unwrap();
    }

    #[test]
    fn writes_the_copy_and_its_truth_and_refuses_foreign_folders() {
        let tmp = tempfile::tempdir().unwrap();
        let (src, dest) = (tmp.path().join("src"), tmp.path().join("dest"));
        source(&src);
        let settings = InjectSettings { gear_period_mm: Some(12.0), ..InjectSettings::default() };
        let truth = inject_dataset(&src, &dest, "gear_eccentricity", 0.03, 9, &settings).unwrap();
        assert_eq!(read_truth(&dest).unwrap(), truth);
        assert_eq!((truth.gear_period_mm, truth.lines.len()), (Some(12.0), 2));
        let copy = FdmWidthsDataset::read(&dest).unwrap();
        assert!(copy.lines[0].widths_mm.iter().any(|w| (w - 0.8).abs() > 0.01));
        // Again into our own output: replaced. Into the source or a foreign folder: refused.
        inject_dataset(&src, &dest, "none", 0.0, 1, &settings).unwrap();
        assert_eq!(FdmWidthsDataset::read(&dest).unwrap().lines[0].widths_mm, vec![0.8; 101]);
        assert!(matches!(
            inject_dataset(&src, &src, "none", 0.0, 1, &settings),
            Err(InjectDatasetError::SameAsSource { .. })
        ));
        let foreign = tmp.path().join("foreign");
        std::fs::create_dir_all(&foreign).unwrap();
        std::fs::write(foreign.join("notes.txt"), "mine").unwrap();
        let err = inject_dataset(&src, &foreign, "none", 0.0, 1, &settings).unwrap_err().to_string();
        assert!(err.contains("refusing to replace"), "{err}");
        assert_eq!(std::fs::read_to_string(foreign.join("notes.txt")).unwrap(), "mine");
        let err = inject_dataset(&src, &tmp.path().join("x"), "wobble", 0.1, 1, &settings).unwrap_err().to_string();
        assert!(err.contains("unknown effect `wobble`"), "{err}");
        assert!(!tmp.path().join("x").exists());
    }

    #[test]
    fn a_source_that_fails_leaves_no_staging_folder() {
        let tmp = tempfile::tempdir().unwrap();
        let (src, dest) = (tmp.path().join("src"), tmp.path().join("dest"));
        source(&src);
        std::fs::write(src.join("widths/a.csv"), "position_mm,width_mm\n0,0.8\n1,0.8\n").unwrap();
        let err = inject_dataset(&src, &dest, "none", 0.0, 1, &InjectSettings::default()).unwrap_err().to_string();
        assert_eq!(
            err,
            format!("{}: line_id a: measured line: fewer than 10 samples", src.join("lines.csv").display())
        );
        let mut left: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        left.sort();
        assert_eq!(left, ["src"], "no staging folder left");
    }
}
