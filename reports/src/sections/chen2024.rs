//! `report.chen2024`: paper 003 (Chen, Yang, Liu, Duan: thermal-camera monitoring and
//! filtered-B-spline deposition compensation) against our reproduction on the virtual
//! printer. The over-deposition index O_E of eq. 40 (Sec. 3.3: mean over corners
//! 106.75 % → 31.73 %), the contour error of eq. 41 (Table 3: max 1.6805 → 0.2468 mm,
//! RMS 0.4301 → 0.2017 mm), the compensation time per corner (Sec. 3.3: about 0.5 s),
//! the corner detector (Sec. 3.2: mAP 99.5 %; ours is classical and reports precision
//! and recall instead) and the capture-time localisation of eq. 28 (the paper gives
//! no number, only δt within 10 ms), each with the paper's number beside ours and the
//! stage it came from.
//!
//! Inputs, in order: a `thermal.compensate` stage (`spans.parquet`), a
//! `thermal.reprint_evaluate` stage (`corners.parquet`, `contour.parquet`, `contour_regions.parquet`), a
//! `thermal.accuracy_evaluate` stage (`accuracy.parquet`) and a `thermal.monitor` stage
//! (`frames.parquet`); then, by name: `reprint_lag`, the re-print of our lag-model
//! extension (`thermal.compensate` with `source = "lag_model"`), reported beside the
//! paper's method with the same checks; every `reprint_X`, a variant the discussion
//! cites, with the stages that set it apart (`chen2024_variants`; table
//! `variants.parquet`); and `true_widths` (`thermal.true_widths_evaluate`: the monitor's width
//! error against the truth). Each source names the stage, its kind and its parameters
//! as recorded in the stage folder's `.stage.json` (the stage name alone when there is
//! no record).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::{NoParams, ParamValue};
use pipeline::schema::Table;
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{InputArtifact, StageContext, StageError};
use tables::report::{comparison, variants};
use tables::thermal::{accuracy, contour, contour_regions, corners, frames, spans, width_errors};

use super::chen2024_variants::{read_variants, variants_frame, Variant};
use super::{comparison_frame, Row};
use crate::html::escape;
use crate::read::{bools, f64s, ints, no_rows, read_parquet, strs};

/// The `report.chen2024` stage kind.
pub struct Chen2024Section;

/// The compensation of the paper's method.
const COMPENSATE: Input =
    Input::one("compensate", &[Source::Stage("thermal.compensate")], "the compensated spans (`spans.parquet`)");

/// The re-print of the paper's method.
const REPRINT: Input = Input::one(
    "reprint",
    &[Source::Stage("thermal.reprint_evaluate")],
    "O_E per corner and the contour error (`corners.parquet`, `contour.parquet`, `contour_regions.parquet`)",
);

/// The monitor's accuracy against the truth.
const ACCURACY: Input = Input::one(
    "accuracy",
    &[Source::Stage("thermal.accuracy_evaluate")],
    "the corner detector's and the localisation's scores (`accuracy.parquet`)",
);

/// The monitor of the paper's method.
const MONITOR: Input = Input::one(
    "monitor",
    &[Source::Stage("thermal.monitor")],
    "how every frame was placed or skipped (`frames.parquet`), and its `measure_age_s`",
);

/// Inputs found by their stage name: `reprint_lag`, every variant's chain (`reprint_X`
/// and `<stage>_X`, compared with the shipped chain's records) and `true_widths`. Any
/// stage: a variant may change any stage of the chain (a sequence, a monitor, a
/// compensation), and what it changes is read from the stages' records, not by kind.
const NAMED: Input = Input::many(
    "named",
    0,
    &[Source::AnyStage],
    "the extension, the variants and the true widths, found by their stage names (see the section's docs)",
);

/// Sec. 3.3: mean O_E over the corners before and after compensation (%).
pub const PAPER_OE_PCT: (f64, f64) = (106.75, 31.73);
/// Table 3: max contour error, conventional and T-DDTC (mm).
pub const PAPER_MAX_MM: (f64, f64) = (1.6805, 0.2468);
/// Table 3: RMS contour error, conventional and T-DDTC (mm).
pub const PAPER_RMS_MM: (f64, f64) = (0.4301, 0.2017);
/// Table 3: the reductions the paper prints (%).
pub const PAPER_REDUCTION_PCT: (f64, f64) = (85.31, 53.10);
/// Sec. 3.2: mAP of the Faster R-CNN corner detector (%).
pub const PAPER_MAP_PCT: f64 = 99.5;

impl Stage for Chen2024Section {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.chen2024",
        version: 17,
        summary: "Paper 003 vs ours: O_E (eq. 40), contour error (Table 3), compensation time, corner detection, capture-time localisation, done-when checks → section.html, comparison.parquet",
        implements: "paper 003 Sec. 3.2-3.3, eqs 40-41, Table 3",
        inputs: &[COMPENSATE, REPRINT, ACCURACY, MONITOR, NAMED],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE, &variants::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let ours = Ours::read(&ctx.inputs)?;
        let (rows, html) = section(&ours);
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        ctx.write_table(variants::TABLE.name, &mut variants_frame(&ours.reprint, &ours.variants)?)?;
        Ok(())
    }
}

/// The one input of `role` among the section's `inputs` (all of them, as its context
/// lists them).
///
/// # Panics
/// When no input fills `role`: the planner fills every declared role, so this is a bug.
fn input_of<'a>(inputs: &'a [InputArtifact], role: &Input) -> &'a InputArtifact {
    inputs.iter().find(|i| i.role == role.role).unwrap_or_else(|| panic!("no input of role `{}`", role.role))
}

/// Where a number came from: stage name, kind and parameters, and the file.
pub fn source(input: &InputArtifact, file: &str) -> String {
    match pipeline::cache::read_record(&input.dir) {
        Some(r) => {
            let params: Vec<String> = r.params.iter().map(|(k, v)| format!("{k} = {v}")).collect();
            let params = if params.is_empty() { "defaults".to_string() } else { params.join(", ") };
            format!("{file} of stage {} ({} v{}; {params})", input.name, r.kind, r.kind_version)
        }
        None => format!("{file} of stage {}", input.name),
    }
}

/// A row of `accuracy.parquet`: value, unit, n, note.
pub type AccuracyRow = (f64, String, i64, String);

/// One corner of `corners.parquet`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CornerOe {
    /// CAD vertex.
    pub vertex: i64,
    /// Angle (degrees).
    pub angle_deg: f64,
    /// O_E before and after (%).
    pub oe_pct: (f64, f64),
}

/// Everything of ours the section reports.
#[derive(Debug, Clone)]
pub struct Ours {
    /// The re-print of the paper's method.
    pub reprint: Reprint,
    /// Compensated spans (rows of `spans.parquet`).
    pub spans: usize,
    /// `accuracy.parquet`: metric → (value, unit, n, note).
    pub accuracy: BTreeMap<String, AccuracyRow>,
    /// Frames placed from their corners (eqs 27-30).
    pub frames_used: usize,
    /// Frames with no corner in view, placed by their recorded time (widths only).
    pub frames_by_recorded_time: usize,
    /// Frames filmed after the layer's last move, placed but not timed (widths only).
    pub frames_parked: usize,
    /// Skipped frames by reason.
    pub skipped: BTreeMap<String, usize>,
    /// Sources: spans, accuracy, frames.
    pub sources: [String; 3],
    /// Our lag-model extension's re-print (the input named `reprint_lag`), when given.
    pub extension: Option<Reprint>,
    /// The variants (inputs named `reprint_X`, the extension's among them).
    pub variants: Vec<Variant>,
    /// The monitor's width error against the true widths (the input named
    /// `true_widths`), when given.
    pub width_errors: Option<WidthErrors>,
    /// The shipped monitor's `measure_age_s`, from its record.
    pub measure_age_s: Option<f64>,
}

/// `width_errors.parquet` of a `thermal.true_widths_evaluate` stage: per region ("corner",
/// "straight"), the per-layer medians and 90th percentiles of the monitor's absolute
/// width error (mm), and the corner radius it used.
#[derive(Debug, Clone, Default)]
pub struct WidthErrors {
    /// Region → per-layer (median, 90th percentile).
    pub by_region: BTreeMap<String, Vec<(f64, f64)>>,
    /// `corner_radius_mm` of the stage (mm), from its record.
    pub corner_radius_mm: Option<f64>,
    /// Where the numbers come from.
    pub source: String,
}

impl WidthErrors {
    fn read(input: &InputArtifact) -> Result<Self, StageError> {
        let path = input.dir.join(width_errors::TABLE.file());
        let df = read_parquet(&path)?;
        let region = strs(&df, width_errors::region, &path)?;
        let (median, p90) =
            (f64s(&df, width_errors::median_abs_err_mm, &path)?, f64s(&df, width_errors::p90_abs_err_mm, &path)?);
        let mut by_region: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
        for i in 0..df.height() {
            by_region.entry(region[i].clone()).or_default().push((median[i], p90[i]));
        }
        Ok(Self {
            by_region,
            corner_radius_mm: recorded_f64(input, "corner_radius_mm"),
            source: source(input, &width_errors::TABLE.file()),
        })
    }

    /// The range over layers of a region's medians and 90th percentiles (mm).
    pub fn ranges_mm(&self, region: &str) -> Option<[(f64, f64); 2]> {
        let layers = self.by_region.get(region).filter(|l| !l.is_empty())?;
        let range = |pick: fn(&(f64, f64)) -> f64| {
            let values = layers.iter().map(pick);
            (values.clone().fold(f64::INFINITY, f64::min), values.fold(f64::NEG_INFINITY, f64::max))
        };
        Some([range(|l| l.0), range(|l| l.1)])
    }
}

/// A float parameter of the stage that wrote `input`, from its record.
fn recorded_f64(input: &InputArtifact, param: &str) -> Option<f64> {
    let record = pipeline::cache::read_record(&input.dir)?;
    let value = record.params.iter().find(|(name, _)| *name == param).and_then(|(_, v)| match v {
        ParamValue::Float(x) => Some(*x),
        _ => None,
    });
    value
}

/// The scores of one re-print: per-corner O_E and the contour error, with sources.
#[derive(Debug, Clone)]
pub struct Reprint {
    /// Per-corner O_E.
    pub corners: Vec<CornerOe>,
    /// (max, RMS) contour error, conventional then compensated (mm).
    pub contour_mm: [(f64, f64); 2],
    /// The contour error by region (corners, seam, straight runs).
    pub regions: Vec<RegionError>,
    /// Sources: corners, contour, contour regions.
    pub sources: [String; 3],
}

/// One row of `contour_regions.parquet`: eq. 41 near a corner, at the seam or along
/// the straight runs; pairs are (conventional, compensated).
#[derive(Debug, Clone, PartialEq)]
pub struct RegionError {
    /// "corner", "seam" or "straight".
    pub region: String,
    /// CAD vertex of a corner region (−1 otherwise).
    pub corner: i64,
    /// "apex", "valley", "seam" or "straight".
    pub kind: String,
    /// (point, layer) pairs in the region.
    pub points: i64,
    /// Largest e_t (mm).
    pub max_mm: (f64, f64),
    /// Whether the print falls short of the CAD point of the largest e_t.
    pub max_short: (bool, bool),
    /// RMS of e_t (mm).
    pub rms_mm: (f64, f64),
    /// Share of the whole contour's sum of e_t².
    pub sq_share: (f64, f64),
}

impl RegionError {
    /// "corner 11 (45° apex)", "the seam", "the straight runs".
    fn label(&self, corners: &[CornerOe]) -> String {
        match self.region.as_str() {
            "corner" => {
                let angle = corners.iter().find(|c| c.vertex == self.corner).map(|c| c.angle_deg);
                format!("corner {} ({}° {})", self.corner, angle.map_or("—".into(), angle_text), self.kind)
            }
            "seam" => "the seam".to_string(),
            _ => "the straight runs".to_string(),
        }
    }
}

impl Reprint {
    pub(crate) fn read(reprint: &InputArtifact) -> Result<Self, StageError> {
        Ok(Self {
            corners: read_corners(&reprint.dir.join(corners::TABLE.file()))?,
            contour_mm: read_contour(&reprint.dir.join(contour::TABLE.file()))?,
            regions: read_regions(&reprint.dir.join(contour_regions::TABLE.file()))?,
            sources: [
                source(reprint, &corners::TABLE.file()),
                source(reprint, &contour::TABLE.file()),
                source(reprint, &contour_regions::TABLE.file()),
            ],
        })
    }

    /// The region holding the largest e_t of the conventional (`after` false) or the
    /// compensated print.
    pub fn worst_region(&self, after: bool) -> Option<&RegionError> {
        let max = |r: &&RegionError| if after { r.max_mm.1 } else { r.max_mm.0 };
        self.regions.iter().max_by(|a, b| max(a).total_cmp(&max(b)))
    }

    /// Over every region of `kind`: the largest e_t and the RMS, conventional then
    /// compensated (NaN when there is no such region).
    pub fn kind_error_mm(&self, kind: &str) -> [(f64, f64); 2] {
        let of_kind = || self.regions.iter().filter(|r| r.kind == kind);
        let points = of_kind().map(|r| r.points as f64).sum::<f64>();
        let rms = |pick: fn(&RegionError) -> f64| {
            (of_kind().map(|r| pick(r).powi(2) * r.points as f64).sum::<f64>() / points).sqrt()
        };
        let max = |pick: fn(&RegionError) -> f64| of_kind().map(pick).fold(f64::NAN, f64::max);
        [(max(|r| r.max_mm.0), rms(|r| r.rms_mm.0)), (max(|r| r.max_mm.1), rms(|r| r.rms_mm.1))]
    }

    /// Mean O_E before and after over the corners with finite values (%).
    pub fn mean_oe_pct(&self) -> (f64, f64) {
        let mean = |pick: fn(&CornerOe) -> f64| {
            let v: Vec<f64> = self.corners.iter().map(pick).filter(|x| x.is_finite()).collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        };
        (mean(|c| c.oe_pct.0), mean(|c| c.oe_pct.1))
    }
}

impl Ours {
    /// Reads the section's `inputs` by role: compensate, reprint, accuracy, monitor, and
    /// among those of role `named`: `reprint_lag` (the extension), every `reprint_X` (a
    /// variant) with its stages, and `true_widths`.
    pub fn read(inputs: &[InputArtifact]) -> Result<Self, StageError> {
        let named = |name: &str| inputs.iter().filter(|i| i.role == NAMED.role).find(|i| i.name == name);
        let (compensate, reprint) = (input_of(inputs, &COMPENSATE), input_of(inputs, &REPRINT));
        let (accuracy, monitor) = (input_of(inputs, &ACCURACY), input_of(inputs, &MONITOR));
        let frames = read_frames(&monitor.dir.join(frames::TABLE.file()))?;
        Ok(Self {
            reprint: Reprint::read(reprint)?,
            spans: read_parquet(&compensate.dir.join(spans::TABLE.file()))?.height(),
            accuracy: read_accuracy(&accuracy.dir.join(accuracy::TABLE.file()))?,
            frames_used: frames.used,
            frames_by_recorded_time: frames.by_recorded_time,
            frames_parked: frames.parked,
            skipped: frames.skipped,
            sources: [
                source(compensate, &spans::TABLE.file()),
                source(accuracy, &accuracy::TABLE.file()),
                source(monitor, &frames::TABLE.file()),
            ],
            extension: named("reprint_lag").map(Reprint::read).transpose()?,
            variants: read_variants(inputs)?,
            width_errors: named("true_widths").map(WidthErrors::read).transpose()?,
            measure_age_s: recorded_f64(monitor, "measure_age_s"),
        })
    }

    /// Mean O_E before and after over the corners with finite values (%).
    pub fn mean_oe_pct(&self) -> (f64, f64) {
        self.reprint.mean_oe_pct()
    }

    /// A metric of `accuracy.parquet`, if present and finite.
    pub fn metric(&self, name: &str) -> Option<f64> {
        self.accuracy.get(name).map(|m| m.0).filter(|v| v.is_finite())
    }
}

fn read_corners(path: &Path) -> Result<Vec<CornerOe>, StageError> {
    let df = read_parquet(path)?;
    let (vertex, angle) = (ints(&df, corners::corner, path)?, f64s(&df, corners::angle_deg, path)?);
    let (before, after) = (f64s(&df, corners::oe_before_pct, path)?, f64s(&df, corners::oe_after_pct, path)?);
    let corners: Vec<CornerOe> = (0..df.height())
        .map(|i| CornerOe { vertex: vertex[i], angle_deg: angle[i], oe_pct: (before[i], after[i]) })
        .collect();
    if corners.is_empty() {
        return Err(no_rows(path, corners::corner, "one row per evaluated corner"));
    }
    Ok(corners)
}

fn read_contour(path: &Path) -> Result<[(f64, f64); 2], StageError> {
    let df = read_parquet(path)?;
    let variant = strs(&df, contour::variant, path)?;
    let (max, rms) = (f64s(&df, contour::max_mm, path)?, f64s(&df, contour::rms_mm, path)?);
    let row = |name: &str| {
        variant
            .iter()
            .position(|v| v == name)
            .map(|i| (max[i], rms[i]))
            .ok_or_else(|| no_rows(path, contour::variant, name))
    };
    Ok([row("conventional")?, row("compensated")?])
}

fn read_regions(path: &Path) -> Result<Vec<RegionError>, StageError> {
    let df = read_parquet(path)?;
    let (region, corner, kind) = (
        strs(&df, contour_regions::region, path)?,
        ints(&df, contour_regions::corner, path)?,
        strs(&df, contour_regions::kind, path)?,
    );
    let points = ints(&df, contour_regions::points, path)?;
    let pair = |a: &str, b: &str| -> Result<Vec<(f64, f64)>, StageError> {
        Ok(f64s(&df, a, path)?.into_iter().zip(f64s(&df, b, path)?).collect())
    };
    let (max, rms, share) = (
        pair("max_before_mm", "max_after_mm")?,
        pair("rms_before_mm", "rms_after_mm")?,
        pair("sq_share_before", "sq_share_after")?,
    );
    let short: Vec<(bool, bool)> = bools(&df, contour_regions::max_before_short, path)?
        .into_iter()
        .zip(bools(&df, contour_regions::max_after_short, path)?)
        .collect();
    let rows: Vec<RegionError> = (0..df.height())
        .map(|i| RegionError {
            region: region[i].clone(),
            corner: corner[i],
            kind: kind[i].clone(),
            points: points[i],
            max_mm: max[i],
            max_short: short[i],
            rms_mm: rms[i],
            sq_share: share[i],
        })
        .collect();
    if rows.is_empty() {
        return Err(no_rows(path, contour_regions::region, "one row per region of the contour"));
    }
    Ok(rows)
}

fn read_accuracy(path: &Path) -> Result<BTreeMap<String, AccuracyRow>, StageError> {
    let df = read_parquet(path)?;
    let (metric, value) = (strs(&df, accuracy::metric, path)?, f64s(&df, accuracy::value, path)?);
    let (unit, n, note) =
        (strs(&df, accuracy::unit, path)?, ints(&df, accuracy::n, path)?, strs(&df, accuracy::note, path)?);
    Ok((0..df.height()).map(|i| (metric[i].clone(), (value[i], unit[i].clone(), n[i], note[i].clone()))).collect())
}

/// How the monitor's frames were placed.
struct FrameCounts {
    used: usize,
    by_recorded_time: usize,
    parked: usize,
    skipped: BTreeMap<String, usize>,
}

/// Frames placed from their corners (`used`), placed by their recorded time or parked
/// (`placed_by`, absent in tables of older monitors) and skipped by reason.
fn read_frames(path: &Path) -> Result<FrameCounts, StageError> {
    let df = read_parquet(path)?;
    let (used, reason) = (bools(&df, frames::used, path)?, strs(&df, frames::skip_reason, path)?);
    let placed_by: Vec<String> = match df.column(frames::placed_by) {
        Ok(_) => strs(&df, frames::placed_by, path)?,
        Err(_) => vec![String::new(); used.len()],
    };
    let dead_reckoned: Vec<bool> = placed_by.iter().map(|p| p == "recorded_time").collect();
    let parked: Vec<bool> = placed_by.iter().map(|p| p == "parked").collect();
    let repeated: Vec<bool> = match df.column(frames::repeat_of_frame) {
        Ok(_) => ints(&df, frames::repeat_of_frame, path)?.iter().map(|r| *r >= 0).collect(),
        Err(_) => vec![false; used.len()],
    };
    let mut skipped: BTreeMap<String, usize> = BTreeMap::new();
    for (i, r) in reason.into_iter().enumerate().filter(|(i, _)| !used[*i] && !dead_reckoned[*i] && !parked[*i]) {
        let class = match (repeated[i], r.is_empty()) {
            (true, _) => REPEATED_FRAMES.to_string(),
            (false, true) => "unstated".to_string(),
            (false, false) => r,
        };
        *skipped.entry(class).or_default() += 1;
    }
    let count = |v: &[bool]| v.iter().filter(|b| **b).count();
    Ok(FrameCounts { used: count(&used), by_recorded_time: count(&dead_reckoned), parked: count(&parked), skipped })
}

/// The skip class of the frames that repeat the image before them (`repeat_of_frame`):
/// one count, whichever frame each repeats.
const REPEATED_FRAMES: &str = "same image as the frame before (a repeated or frozen camera frame)";

/// The relative reduction from `before` to `after` (%).
pub fn reduction_pct(before: f64, after: f64) -> f64 {
    100.0 * (before - after) / before
}

/// The comparison rows and the HTML of the section.
pub fn section(ours: &Ours) -> (Vec<Row>, String) {
    let mut rows = Vec::new();
    let mut html = String::from("<h3>Paper 003 vs ours</h3>\n");
    html += &comparison_table(ours, &mut rows);
    html += &corner_table(ours, &mut rows);
    html += &variants_table(ours);
    html += &discussion(ours);
    (rows, html)
}

/// "O_E −70 %, max +1 %, RMS −28 %": the changes of the mean O_E and of the contour
/// error's max and RMS from the conventional print to the compensated one.
fn changes_text(changes_pct: [f64; 3]) -> String {
    let [oe, max, rms] = changes_pct.map(|c| signed(c, 0));
    format!("O_E {oe} %, max {max} %, RMS {rms} %")
}

/// The paper method's changes with the stage's defaults (stage reprint).
fn defaults_text(ours: &Ours) -> String {
    let defaults = Variant::defaults(&ours.reprint);
    changes_text(defaults.changes_pct())
}

/// Variant `name`'s changes and its name, or that the spec did not run it.
fn variant_text(ours: &Ours, name: &str) -> String {
    match ours.variants.iter().find(|v| v.name == name) {
        Some(v) => format!("{} (variant {name})", changes_text(v.changes_pct())),
        None => format!("— (variant {name} was not run)"),
    }
}

/// Every variant beside the stage's defaults: what differs, the changes it brings.
fn variants_table(ours: &Ours) -> String {
    if ours.variants.is_empty() {
        return String::new();
    }
    let mut html = String::from(
        "<h4>Variants: each compensated, re-printed and scored like the stages above</h4>\n\
<p class=\"run\">Change from the conventional print to the compensated one of the mean O_E (eq. 40) and of the contour error's max and \
RMS (eq. 41, over every re-printed layer); what differs is read from the variant's stages' records, against the shipped stage of the same name \
(variants.parquet of this stage).</p>\n\
<table><tr><th class=\"t\">variant</th><th class=\"t\">what differs</th><th>mean O_E (%)</th><th>max (mm)</th><th>RMS (mm)</th>\
<th>O_E change (%)</th><th>max change (%)</th><th>RMS change (%)</th></tr>\n",
    );
    let defaults = Variant::defaults(&ours.reprint);
    for v in std::iter::once(&defaults).chain(&ours.variants) {
        let (oe0, oe1) = v.reprint.mean_oe_pct();
        let [(max0, rms0), (max1, rms1)] = v.reprint.contour_mm;
        let [oe, max, rms] = v.changes_pct().map(|c| signed(c, 1));
        let what = if v.name == "defaults" { "the stages above".to_string() } else { v.changes_text() };
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td class=\"t\">{}</td><td>{oe0:.1} → {oe1:.1}</td><td>{max0:.3} → {max1:.3}</td>\
<td>{rms0:.4} → {rms1:.4}</td><td>{oe}</td><td>{max}</td><td>{rms}</td></tr>",
            escape(&v.name),
            escape(&what)
        );
    }
    html + "</table>\n"
}

/// `v` to `decimals` places for the page: a true minus sign (−), no "−0.0", "—" when
/// missing or not finite.
fn fmt(v: Option<f64>, decimals: usize) -> String {
    v.filter(|x| x.is_finite()).map_or("—".into(), |x| {
        let text = format!("{x:.decimals$}");
        match text.strip_prefix('-') {
            Some(digits) if digits.chars().all(|c| c == '0' || c == '.') => digits.to_string(),
            Some(digits) => format!("−{digits}"),
            None => text,
        }
    })
}

/// An angle in degrees as the path has them: whole degrees, or one decimal (52.5°).
fn angle_text(deg: f64) -> String {
    if (deg - deg.round()).abs() < 0.05 {
        fmt(Some(deg), 0)
    } else {
        fmt(Some(deg), 1)
    }
}

/// One line of the main table, pushed as a comparison row too when we have a value.
struct Line<'a> {
    section: &'static str,
    item: &'a str,
    paper: Option<f64>,
    paper_text: &'a str,
    ours: Option<f64>,
    unit: &'static str,
    decimals: usize,
    source: &'a str,
}

fn push_line(html: &mut String, rows: &mut Vec<Row>, l: Line) {
    let paper = if l.paper_text.is_empty() { fmt(l.paper, l.decimals) } else { l.paper_text.to_string() };
    let _ = writeln!(
        html,
        "<tr><td class=\"t\">{}</td><td>{paper}</td><td>{}</td><td class=\"t\">{}</td><td class=\"t\">{}</td></tr>",
        escape(l.item),
        fmt(l.ours, l.decimals),
        l.unit,
        escape(l.source)
    );
    if let Some(ours) = l.ours.filter(|v| v.is_finite()) {
        rows.push(Row {
            section: l.section,
            item: l.item.to_string(),
            paper: l.paper,
            ours,
            unit: l.unit,
            source: l.source.to_string(),
        });
    }
}

fn comparison_table(ours: &Ours, rows: &mut Vec<Row>) -> String {
    let mut html = String::from("<table><tr><th class=\"t\">quantity</th><th>paper</th><th>ours</th><th class=\"t\">unit</th><th class=\"t\">our source</th></tr>\n");
    let (oe0, oe1) = ours.mean_oe_pct();
    let [(max0, rms0), (max1, rms1)] = ours.reprint.contour_mm;
    let [spans, accuracy, frames] = &ours.sources;
    let [corners, contour, _] = &ours.reprint.sources;
    let paper_oe_red = reduction_pct(PAPER_OE_PCT.0, PAPER_OE_PCT.1);
    let m = |name: &str| ours.metric(name);
    let map_text = format!("mAP {PAPER_MAP_PCT} %");
    let lines = [
        ("sec_3_3", "mean O_E before compensation (eq. 40)", Some(PAPER_OE_PCT.0), "", Some(oe0), "%", 2, corners),
        ("sec_3_3", "mean O_E after compensation (eq. 40)", Some(PAPER_OE_PCT.1), "", Some(oe1), "%", 2, corners),
        (
            "sec_3_3",
            "relative reduction of the mean O_E",
            Some(paper_oe_red),
            "",
            Some(reduction_pct(oe0, oe1)),
            "%",
            2,
            corners,
        ),
        ("table_3", "max contour error, conventional (eq. 41)", Some(PAPER_MAX_MM.0), "", Some(max0), "mm", 4, contour),
        ("table_3", "max contour error, compensated", Some(PAPER_MAX_MM.1), "", Some(max1), "mm", 4, contour),
        (
            "table_3",
            "max contour error reduction",
            Some(PAPER_REDUCTION_PCT.0),
            "",
            Some(reduction_pct(max0, max1)),
            "%",
            2,
            contour,
        ),
        ("table_3", "RMS contour error, conventional", Some(PAPER_RMS_MM.0), "", Some(rms0), "mm", 4, contour),
        ("table_3", "RMS contour error, compensated", Some(PAPER_RMS_MM.1), "", Some(rms1), "mm", 4, contour),
        (
            "table_3",
            "RMS contour error reduction",
            Some(PAPER_REDUCTION_PCT.1),
            "",
            Some(reduction_pct(rms0, rms1)),
            "%",
            2,
            contour,
        ),
        (
            "sec_3_2",
            "corner detector precision (paper: mAP 99.5 %)",
            None,
            &map_text,
            m("corner_precision").map(|v| 100.0 * v),
            "%",
            1,
            accuracy,
        ),
        ("sec_3_2", "corner detector recall", None, "—", m("corner_recall").map(|v| 100.0 * v), "%", 1, accuracy),
        (
            "sec_2_3",
            "capture-time localisation error, median (eq. 28)",
            None,
            "δt within 10",
            m("capture_time_err_median_ms"),
            "ms",
            2,
            accuracy,
        ),
        (
            "sec_2_3",
            "same, using the recorded time (baseline)",
            None,
            "—",
            m("capture_time_err_baseline_median_ms"),
            "ms",
            2,
            accuracy,
        ),
        (
            "sec_2_3",
            "homography reprojection error, RMS (eq. 27)",
            None,
            "—",
            m("reprojection_rms_mm"),
            "mm",
            3,
            accuracy,
        ),
        (
            "sec_2_4",
            "extracted width error, median (eqs 31-32)",
            None,
            "—",
            m("width_err_median_mm"),
            "mm",
            3,
            accuracy,
        ),
        ("sec_2_4", "compensated spans (eqs 32-39)", None, "—", Some(ours.spans as f64), "spans", 0, spans),
        (
            "sec_3_2",
            "frames placed from their corners (eqs 27-30)",
            None,
            "—",
            Some(ours.frames_used as f64),
            "frames",
            0,
            frames,
        ),
        (
            "sec_3_2",
            "frames placed by their recorded time (no corner in view; widths only)",
            None,
            "—",
            Some(ours.frames_by_recorded_time as f64),
            "frames",
            0,
            frames,
        ),
        (
            "sec_3_2",
            "frames filmed after the layer's last move (placed, not timed; widths only)",
            None,
            "—",
            Some(ours.frames_parked as f64),
            "frames",
            0,
            frames,
        ),
        (
            "sec_3_2",
            "frames skipped",
            None,
            "—",
            Some(ours.skipped.values().sum::<usize>() as f64),
            "frames",
            0,
            frames,
        ),
    ];
    for (section, item, paper, paper_text, value, unit, decimals, source) in lines {
        push_line(&mut html, rows, Line { section, item, paper, paper_text, ours: value, unit, decimals, source });
    }
    if let Some(ext) = &ours.extension {
        extension_lines(ext, &mut html, rows);
    }
    html += "</table>\n";
    let reasons: Vec<String> = ours.skipped.iter().map(|(r, n)| format!("{} × {n}", escape(r))).collect();
    if !reasons.is_empty() {
        let _ = writeln!(html, "<p class=\"run\">Skipped frames by reason: {}.</p>", reasons.join("; "));
    }
    html
}

/// The rows of our lag-model extension: what the paper's method would be compared on,
/// without a paper number (the paper has no such variant).
fn extension_lines(ext: &Reprint, html: &mut String, rows: &mut Vec<Row>) {
    let (oe0, oe1) = ext.mean_oe_pct();
    let [(max0, rms0), (max1, rms1)] = ext.contour_mm;
    let [corners, contour, _] = &ext.sources;
    let lines = [
        ("sec_3_3", "extension (lag model): mean O_E after", Some(oe1), "%", 2, corners),
        (
            "sec_3_3",
            "extension (lag model): relative reduction of the mean O_E",
            Some(reduction_pct(oe0, oe1)),
            "%",
            2,
            corners,
        ),
        ("table_3", "extension (lag model): max contour error, compensated", Some(max1), "mm", 4, contour),
        (
            "table_3",
            "extension (lag model): max contour error reduction",
            Some(reduction_pct(max0, max1)),
            "%",
            2,
            contour,
        ),
        ("table_3", "extension (lag model): RMS contour error, compensated", Some(rms1), "mm", 4, contour),
        (
            "table_3",
            "extension (lag model): RMS contour error reduction",
            Some(reduction_pct(rms0, rms1)),
            "%",
            2,
            contour,
        ),
    ];
    for (section, item, value, unit, decimals, source) in lines {
        let line = Line { section, item, paper: None, paper_text: "—", ours: value, unit, decimals, source };
        push_line(html, rows, line);
    }
}

fn corner_table(ours: &Ours, rows: &mut Vec<Row>) -> String {
    let reprint = &ours.reprint;
    let mut html = format!(
        "<h4>Per corner: O_E (eq. 40; the paper prints only the mean) and the contour error near it (eq. 41)</h4>\n\
<p class=\"run\">Contour error within the corner window of each vertex, at the seam where every layer starts and ends, and along the \
straight runs, over all layers, conventional → compensated; \"short\" where the print falls short of the CAD point of the largest error, \
\"bulge\" where it covers it and its edge lies beyond; share = the region's part of the sum of e_t² (Σ = 1). {}.</p>\n\
<table><tr><th>vertex</th><th>angle (°)</th><th class=\"t\">kind</th><th>O_E before (%)</th><th>O_E after (%)</th><th>reduction (%)</th>\
<th>max e_t before (mm)</th><th>max e_t after (mm)</th><th>RMS before (mm)</th><th>RMS after (mm)</th><th>share before</th><th>share after</th></tr>\n",
        escape(&reprint.sources[2])
    );
    for c in &reprint.corners {
        let region = reprint.regions.iter().find(|r| r.region == "corner" && r.corner == c.vertex);
        let red = reduction_pct(c.oe_pct.0, c.oe_pct.1);
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td>{}</td><td class=\"t\">{}</td><td>{}</td><td>{}</td><td>{}</td>{}</tr>",
            c.vertex,
            angle_text(c.angle_deg),
            region.map_or("", |r| r.kind.as_str()),
            fmt(Some(c.oe_pct.0), 1),
            fmt(Some(c.oe_pct.1), 1),
            fmt(Some(red), 1),
            region_cells(region)
        );
        for (when, v) in [("before", c.oe_pct.0), ("after", c.oe_pct.1)] {
            if v.is_finite() {
                rows.push(Row {
                    section: "sec_3_3",
                    item: format!("O_E {when}, vertex {} ({}°)", c.vertex, angle_text(c.angle_deg)),
                    paper: None,
                    ours: v,
                    unit: "%",
                    source: reprint.sources[0].clone(),
                });
            }
        }
    }
    for r in reprint.regions.iter().filter(|r| r.region != "corner") {
        let _ = writeln!(
            html,
            "<tr><td class=\"t\" colspan=\"3\">{}</td><td></td><td></td><td></td>{}</tr>",
            escape(&r.label(&reprint.corners)),
            region_cells(Some(r))
        );
    }
    html + "</table>\n"
}

/// The contour-error cells of a region's row (empty cells when it has none).
fn region_cells(region: Option<&RegionError>) -> String {
    let Some(r) = region else {
        return "<td></td>".repeat(6);
    };
    let max = |v: f64, short: bool| format!("{} ({})", fmt(Some(v), 3), if short { "short" } else { "bulge" });
    format!(
        "<td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
        max(r.max_mm.0, r.max_short.0),
        max(r.max_mm.1, r.max_short.1),
        fmt(Some(r.rms_mm.0), 4),
        fmt(Some(r.rms_mm.1), 4),
        fmt(Some(r.sq_share.0), 3),
        fmt(Some(r.sq_share.1), 3)
    )
}

/// The extension's result in one sentence, or nothing when it was not run.
fn extension_sentence(ours: &Ours) -> String {
    let Some(ext) = &ours.extension else {
        return String::new();
    };
    let (oe0, oe1) = ext.mean_oe_pct();
    let [(max0, rms0), (max1, rms1)] = ext.contour_mm;
    format!(
        "Fed instead with the flow excess eq. 34 predicts for the nominal command (our extension, no widths: stage compensate_lag), the same \
filtered-B-spline solve lowers the mean O_E by {:.1} % and the RMS contour error by {:.1} %, and changes the max by {} %. It knows nothing of \
the CAD bead: it removes the whole predicted excess, also where that excess was filling the CAD bead's sharp tips, which the width feedback partly keeps \
because the desired width there is the CAD bead's long extent along the bisector. ",
        reduction_pct(oe0, oe1),
        reduction_pct(rms0, rms1),
        signed(-reduction_pct(max0, max1), 1)
    )
}

/// The maximum and RMS of the contour error over every region of one kind, before →
/// after, as text.
fn kind_change(reprint: &Reprint, kind: &str) -> String {
    let [(max0, rms0), (max1, rms1)] = reprint.kind_error_mm(kind);
    format!(
        "the largest error {max0:.3} → {max1:.3} mm, the RMS {rms0:.4} → {rms1:.4} mm ({} %)",
        signed(-reduction_pct(rms0, rms1), 0)
    )
}

/// `value` with an explicit sign, the minus a true minus sign (−).
fn signed(value: f64, decimals: usize) -> String {
    let text = fmt(Some(value), decimals);
    if value > 0.0 && text.chars().any(|c| c.is_ascii_digit() && c != '0') {
        format!("+{text}")
    } else {
        text
    }
}

/// "a bulge 0.335 mm beyond the CAD contour" or "0.328 mm short of the CAD contour".
fn error_kind(max_mm: f64, short: bool) -> String {
    if short {
        format!("{max_mm:.3} mm short of the CAD contour")
    } else {
        format!("a bulge {max_mm:.3} mm beyond the CAD contour")
    }
}

/// Where the largest contour error lies before and after, in one sentence.
fn worst_points_sentence(reprint: &Reprint) -> String {
    let (Some(before), Some(after)) = (reprint.worst_region(false), reprint.worst_region(true)) else {
        return String::new();
    };
    format!(
        "The conventional part's largest error is at {}: {}. The compensated part's is at {}: {}, where the conventional part's was {}. ",
        escape(&before.label(&reprint.corners)),
        error_kind(before.max_mm.0, before.max_short.0),
        escape(&after.label(&reprint.corners)),
        error_kind(after.max_mm.1, after.max_short.1),
        error_kind(after.max_mm.0, after.max_short.0),
    )
}

/// The contour-error paragraphs: Table 3 beside ours, where ours lies, and why.
fn contour_paragraphs(ours: &Ours) -> String {
    let reprint = &ours.reprint;
    let [(max0, rms0), (max1, rms1)] = reprint.contour_mm;
    let lag = ours.extension.as_ref().map_or(String::new(), |ext| {
        let [(m0, _), (m1, _)] = ext.contour_mm;
        format!(
            " The lag model, which removes the whole predicted excess, changes the maximum by {} % (stage reprint_lag).",
            signed(-reduction_pct(m0, m1), 0)
        )
    });
    format!(
        "<p><b>Contour error.</b> Ours: max {max0:.4} → {max1:.4} mm, RMS {rms0:.4} → {rms1:.4} mm over 20 layers (paper, Table 3: 1.6805 → 0.2468 mm \
and 0.4301 → 0.2017 mm; the paper's text calls the second column the mean value, its Table 3 heads it RMS: we compare with our RMS). The paper \
measured the external surface of a 20-layer part with a laser profiler at 0.5 mm z spacing; ours applies eq. 41 to the virtual deposit's boundary \
on every layer, at the CAD points of the external surface (stage reprint's inner_face = false; inner_face = true adds the wall's inside face, \
where the apexes' inner bulges count), with no profiler noise. Eq. 41 takes each CAD \
point's distance to the nearest printed edge, so a bulge that pushes the edge out and a part of the CAD bead left empty both cost; the table above \
says which each region's largest error is. By region, from {source}: at the valleys, where a corner's bulge fills the notch of the external surface, \
{valley}; at the apexes {apex}; at the seam {seam}; along the straight runs {straight}. {worst}</p>\n\
<p><b>Why the apexes do not improve.</b> At an apex the external surface is the outside of the turn. A round bead on a blended path does not reach \
the mitred tip of the CAD bead there (at 45° its tip lies W/(2 sin 22.5°) = 0.59 mm beyond the vertex; the round bead's edge stops well short of it), and the corner's excess bulges \
on the inside of the turn, which the external surface does not include (Fig. 10). The compensation sets one flow for both sides (eq. 32 sums \
w_l + w_r): removing the inner bulge thins the outside too, so the sharper apexes end up short. {apex_before} With the printer's true widths in \
place of the thermal ones the changes are {true_widths}.{lag} A fall of the maximum like the paper's is out of reach of a \
flow-only compensation on this part; the paper's conventional maximum, 1.68 mm, comes from corner blobs of its real printer far larger than this \
printer's, next to which a tip's shortfall is small.</p>\n",
        source = escape(&reprint.sources[2]),
        valley = kind_change(reprint, "valley"),
        apex = kind_change(reprint, "apex"),
        seam = kind_change(reprint, "seam"),
        straight = kind_change(reprint, "straight"),
        worst = worst_points_sentence(reprint),
        apex_before = apex_before_sentence(reprint),
        true_widths = variant_text(ours, "true_widths"),
    )
}

/// The apex with the largest error before compensation, in one sentence.
fn apex_before_sentence(reprint: &Reprint) -> String {
    let apexes = reprint.regions.iter().filter(|r| r.kind == "apex");
    let Some(worst) = apexes.max_by(|a, b| a.max_mm.0.total_cmp(&b.max_mm.0)) else {
        return String::new();
    };
    format!(
        "Before compensation the largest apex error is at {}: {}.",
        escape(&worst.label(&reprint.corners)),
        error_kind(worst.max_mm.0, worst.max_short.0)
    )
}

/// The monitor's width error near and away from the corners, in one sentence (nothing
/// when stage true_widths was not run).
fn width_errors_sentence(ours: &Ours) -> String {
    let Some(errors) = &ours.width_errors else {
        return String::new();
    };
    let (Some([corner, corner_p90]), Some([straight, _])) = (errors.ranges_mm("corner"), errors.ranges_mm("straight"))
    else {
        return String::new();
    };
    let range = |r: (f64, f64)| format!("{:.3}-{:.3} mm", r.0, r.1);
    let heat = if corner.1 > straight.1 {
        " A corner's bulge holds more heat, and its warm contour spreads as it ages."
    } else {
        " Here the corners are read no worse than the straight runs."
    };
    format!(
        "Within {} mm of a vertex the thermal widths differ from the true ones by {} (median absolute per layer; 90th percentile {}), \
against {} away from the corners ({}).{heat} ",
        fmt(errors.corner_radius_mm, 2),
        range(corner),
        range(corner_p90),
        range(straight),
        escape(&errors.source),
    )
}

/// What reading the widths at other ages gives: every variant that sets the monitor's
/// `measure_age_s`, youngest first.
fn age_sentence(ours: &Ours) -> String {
    let mut ages: Vec<(f64, &Variant)> = ours
        .variants
        .iter()
        .filter_map(|v| match v.param("measure_age_s") {
            Some(ParamValue::Float(age)) => Some((*age, v)),
            _ => None,
        })
        .collect();
    ages.sort_by(|a, b| a.0.total_cmp(&b.0));
    let read: Vec<String> = ages
        .iter()
        .map(|(age, v)| format!("read at {age} s: {} (variant {})", changes_text(v.changes_pct()), v.name))
        .collect();
    if read.is_empty() {
        return format!("that age: {}", defaults_text(ours));
    }
    format!("that age: {}; {}", defaults_text(ours), read.join("; "))
}

/// Whether eq. 30 beat the recorded time on this run, in one sentence.
fn localisation_verdict(ours: &Ours) -> &'static str {
    match (ours.metric("capture_time_err_median_ms"), ours.metric("capture_time_err_baseline_median_ms")) {
        (Some(loc), Some(base)) if loc < base => "On this run eq. 30 improves on the recorded time.",
        (Some(_), Some(_)) => "So on this run eq. 30 does not improve on the recorded time.",
        _ => "",
    }
}

fn discussion(ours: &Ours) -> String {
    let (oe0, oe1) = ours.mean_oe_pct();
    let loc = fmt(ours.metric("capture_time_err_median_ms"), 2);
    let base = fmt(ours.metric("capture_time_err_baseline_median_ms"), 2);
    let (p, r) = (
        fmt(ours.metric("corner_precision").map(|v| 100.0 * v), 1),
        fmt(ours.metric("corner_recall").map(|v| 100.0 * v), 1),
    );
    format!(
        "<h4>Where and why ours differs</h4>\n\
<p><b>Over-deposition index.</b> Ours, mean over {n} corners: {oe0:.2} % → {oe1:.2} % (paper: 106.75 % → 31.73 %, over the four corner types of its one-layer part). \
The paper measures O_E on photographs of real prints (Figs 9-10); ours is computed on the first layer the virtual printer deposits again (a 0.02 mm fill grid, \
stage reprint), with A_c the corner polytope, the rhombus where the two edges' ideal beads overlap (W²/sin θ), and A_o the deposited area outside the ideal \
(mitred) bead within a disc around the vertex. Our test path has {n} corners (45° to 120° apexes on two zig-zags, their valleys and four side corners) where \
the paper's has four types. Corners over-deposit on the virtual printer because the flow lags (τ = 0.0873 s, eq. 34) while the head slows: the beads \
of eqs 5-11 widen and, at the sharp apexes, the deposition segments of the incoming and outgoing beads overlap; what would stand higher than the nozzle \
plane the nozzle face squeezes out sideways, into a bulge. Only corners covered by a localised frame get a width reading and a compensation; the others \
keep O_E before = after in the table above.</p>\n\
<p><b>Deposition velocity.</b> We read the paper's deposition velocity v_e as the extruder's filament velocity (E = A_fil·v_e, 1.75 mm filament), the reading \
under which its w0 = K·α + b (K = 3.44 mm, b = 0.67 mm) gives a sub-millimetre bead and its bounds ΔV ∈ [−2, 4] mm/s allow the short retraction a corner needs; \
the virtual printer lets a negative command pull the melt pressure down and extrudes only while it is positive. \
Where the stage's defaults depart from eqs 31-33 (stage compensate's parameters, in the source column), they do so for reasons measured on the virtual printer \
with its true widths: the desired width is the CAD bead's extent along each allocated direction (at a sharp corner's inner side eq. 31's w0/cos ψ is far \
narrower than the overlapping beads, so a perfect corner would read as over-deposited); the width error is signed, as eq. 33 is, so thin stretches get \
material too; the fit runs 3τ past each window so the lagged tail does not starve the bead after the corner; and K_e = 1, since the paper's K_e was \
identified for corners read at 140-150 °C and ours are read in a wider band: its formula with T_p clamped to that band gives every corner read \
below 140 °C K_e = 5/3 and every one above 150 °C K_e = 1, and gives {paper_gain}, against {defaults} with K_e = 1 (stage reprint).</p>\n\
<p><b>Monitored layers.</b> The paper verifies on one layer; our camera has the habits of its \
Lepton 3.5 (it repeats its last image now and then and holds one through a ~0.9 s shutter freeze once a layer; the monitor skips such repeats), so a \
corner the freeze hides in the first layer is read in another: the widths are the median over the filmed layers per sample (stage compensate's \
layer and layers), which gives {defaults}. With the first layer alone: {first_layer}; with a camera without those habits, the first layer \
alone: {no_habits}.</p>\n\
<p><b>Width feedback against the truth.</b> The virtual printer lays each bead by eqs 5-11 along the directions of eqs 13-26 (DESIGN §5.3), \
so the paper's geometric model is the printer's own, except where the nozzle face squeezes the excess sideways. With the printer's true widths of the \
filmed layers in place of the thermal ones (stage true_widths, an evaluation stage: a perfect camera), the stage's defaults give {true_widths}; eqs 31-33 \
as printed (desired width w0/cos ψ, over-deposition only, the fit over the extended window only) give {true_widths_as_printed}, and on the thermal \
widths {as_printed}: eq. 31 counts the inner wedge of a sharp corner as excess, so they also thin the flanks. What even the true widths miss is what \
this reproduction names as the model's blind spot: eqs 31-33 read the flow error along the deposition directions, and the squeezed-out part of a \
corner's excess lies around the apex, between them. {width_errors}Reading the widths young limits that spread \
(stage monitor's measure_age_s = {age} s; {ages}). The first frames of every layer show no corner; placing them by their recorded time through the \
fitted mount (stage monitor's place_cornerless) lets the compensation also fill the thin start of the layer, where the flow builds up from rest; \
without it: {cornerless}. The camera films on through the layer change, while the nozzle stands at the layer's end point; those \
frames are placed but not timed (eq. 30 needs a moving nozzle) and give the widths of the layer's last stretch, where the head stops while the flow lags on. The very first millimetre of a layer is too thin for the threshold contour and reads as nothing; the fit \
of eq. 39 leaves such unread samples out rather than asking for no change there, so the added flow can start with the layer. {extension}The <code>melt_squeeze_out</code> effect of the virtual printer sends part of every millisecond's melt into \
the nearest free cells instead of along the deposition direction: the more the melt moves after it leaves the nozzle, the less a width says about the \
flow.</p>\n\
{contour}\
<p><b>Compensation time.</b> The paper's ≈ 0.5 s per corner (Sec. 3.3) includes the Faster R-CNN on an RTX 2050 GPU and the filtered B-spline solve. \
Timings would make our tables differ from run to run, so the pipeline does not record them: <code>make bench</code> measures the constrained least-squares \
solve of eq. 39 per corner (models/benches/thermal.rs) and the whole frame pipeline per frame (vision/benches/frames.rs); see the README for the numbers.</p>\n\
<p><b>Corner detection.</b> The paper reports mAP 99.5 % for a Faster R-CNN trained on 69 annotated real frames (Sec. 3.2). We have no GPU, no weights and no \
annotated real frames, so we detect corners classically (local temperature maxima with blob-like curvature) on synthetic frames whose true corner positions \
are known, and report precision {p} % and recall {r} % against that ground truth instead; mAP is not computed. The paper keeps frames whose corners are at \
140-150 °C; on the virtual printer a corner reaches that band long after it is printed and passes through it quickly, so too few corners \
are in it at once for eq. 27, which needs four: the shipped spec widens the band (stage monitor's band_low_c/band_high_c, in the source column). A corner's heat peak \
sits inside the corner, where the material bulges; we place each matched corner at the intersection of its two bead ridges instead (vision::vertex).</p>\n\
<p><b>Capture-time localisation.</b> The paper gives no error figure, only that the search neighbourhood δt of eq. 30 should be within 10 ms. Ours: median \
error {loc} ms against the virtual camera's true capture times, against {base} ms when the recorded time is used as is (the camera's timestamps jitter \
with σ = 3 ms); the paper's per-frame DLT homography (eq. 27, stage monitor with localisation = \"dlt\") gives {dlt} ms on the {dlt_frames} frames that \
hold the four in-band corners it needs, and corners bunched on one side of the image let an 8-parameter homography extrapolate their errors onto \
the nozzle. Our extension uses that the camera is rigid on a head that only translates: one mount homography is fitted to the whole sequence and each \
frame needs only its translation, which a single corner gives (vision::mount, vision::rigid); corner vertices are placed where the two bead ridges meet, \
with the arm lines through the ridges' centres so that the heat of the corner's bulge does not tilt them. The nozzle then lands within {nozzle} mm of its true \
position, the floor set by the camera's vibration being {floor} mm. {loc_verdict} Eq. 30 pays off most with a larger or unknown capture delay (the \
camera_latency effect of the virtual camera), which the recorded time cannot see.</p>\n",
        n = ours.reprint.corners.len(),
        contour = contour_paragraphs(ours),
        defaults = defaults_text(ours),
        paper_gain = variant_text(ours, "paper_gain"),
        first_layer = variant_text(ours, "first_layer"),
        no_habits = variant_text(ours, "no_habits"),
        true_widths = variant_text(ours, "true_widths"),
        true_widths_as_printed = variant_text(ours, "true_widths_as_printed"),
        as_printed = variant_text(ours, "as_printed"),
        width_errors = width_errors_sentence(ours),
        age = fmt(ours.measure_age_s, 2),
        ages = age_sentence(ours),
        cornerless = variant_text(ours, "cornerless_unplaced"),
        extension = extension_sentence(ours),
        loc_verdict = localisation_verdict(ours),
        dlt = fmt(ours.metric("dlt_capture_time_err_median_ms"), 2),
        dlt_frames = fmt(ours.metric("dlt_frames_used"), 0),
        nozzle = fmt(ours.metric("nozzle_err_median_mm"), 3),
        floor = fmt(ours.metric("nozzle_err_floor_median_mm"), 3),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_util::write_table;
    use crate::figures::thermal::test_data::{accuracy, frames, write_compensate, write_reprint};

    #[test]
    fn paper_reductions_match_table_3() {
        // Table 3 prints the reductions; they follow from its max and RMS columns.
        assert!((reduction_pct(PAPER_MAX_MM.0, PAPER_MAX_MM.1) - PAPER_REDUCTION_PCT.0).abs() < 0.01);
        assert!((reduction_pct(PAPER_RMS_MM.0, PAPER_RMS_MM.1) - PAPER_REDUCTION_PCT.1).abs() < 0.01);
    }

    fn inputs(root: &Path) -> Vec<InputArtifact> {
        // The four single roles, each filled by a stage named like it.
        let roles = [COMPENSATE, REPRINT, ACCURACY, MONITOR];
        let inputs: Vec<InputArtifact> = roles
            .iter()
            .map(|r| InputArtifact { name: r.role.to_string(), role: r.role, dir: root.join(r.role) })
            .collect();
        for i in &inputs {
            std::fs::create_dir_all(&i.dir).expect("dir");
        }
        write_compensate(&inputs[0].dir);
        write_reprint(&inputs[1].dir);
        write_table(&inputs[2].dir, "accuracy", accuracy());
        write_table(&inputs[3].dir, "frames", frames());
        inputs
    }

    #[test]
    fn section_reports_every_number_with_its_source() {
        let root = tempfile::tempdir().expect("tempdir");
        let ours = Ours::read(&inputs(root.path())).expect("reads");
        let counts =
            (ours.frames_used, ours.frames_by_recorded_time, ours.frames_parked, ours.skipped.values().sum::<usize>());
        assert_eq!(counts, (30, 2, 1, 7));
        // Repeats of different frames count as one reason.
        let repeats = ours.skipped.get(REPEATED_FRAMES);
        assert_eq!((ours.skipped.len(), repeats), (2, Some(&4)), "{:?}", ours.skipped);
        let (rows, html) = section(&ours);
        let df = comparison_frame(&rows).expect("frame");
        let names: Vec<&str> = df.get_column_names().iter().map(|s| s.as_str()).collect();
        assert_eq!(names, ["section", "item", "paper_value", "our_value", "unit", "source"]);
        // Synthetic contour: 1.52 → 0.27 (−82.2 %), 0.41 → 0.19 (−53.7 %); localisation 2.1 ms.
        let row = |item: &str| rows.iter().find(|r| r.item == item).expect(item);
        assert!((row("max contour error reduction").ours - reduction_pct(1.52, 0.27)).abs() < 1e-9);
        assert_eq!(row("max contour error, conventional (eq. 41)").paper, Some(1.6805));
        assert!(row("corner detector recall").paper.is_none());
        assert!(row("mean O_E before compensation (eq. 40)").source.contains("corners.parquet of stage reprint"));
        let spans = row("compensated spans (eqs 32-39)");
        assert!(spans.ours >= 1.0 && spans.source.contains("spans.parquet of stage compensate"), "{}", spans.source);
        assert!(!html.contains("issue") && !html.contains("<b>pass</b>"), "the report speaks to a reader of the paper");
        assert!(html.contains("106.75") && html.contains("mAP 99.5 %") && html.contains("within 10"));
        // Where the contour error lies: the largest errors before and after, from
        // contour_regions.parquet (synthetic: a 1.52 mm bulge at the first valley, a
        // 0.27 mm shortfall at the first apex).
        assert!(html.contains("contour_regions.parquet of stage reprint"));
        assert!(html.contains("The conventional part's largest error is at corner 1 ("), "{html}");
        assert!(html.contains("a bulge 1.520 mm beyond the CAD contour"));
        assert!(
            html.contains("The compensated part's is at corner 0 (")
                && html.contains("0.270 mm short of the CAD contour")
        );
        assert!(html.contains("<td class=\"t\" colspan=\"3\">the seam</td>"));
        let [(_, rms0), (_, rms1)] = ours.reprint.kind_error_mm("valley");
        assert!((rms0 - 0.41).abs() < 1e-12 && (rms1 - 0.19).abs() < 1e-12);
    }

    #[test]
    fn the_extension_is_reported_beside_the_paper_method() {
        let root = tempfile::tempdir().expect("tempdir");
        let mut inputs = inputs(root.path());
        let dir = root.path().join("reprint_lag");
        std::fs::create_dir_all(&dir).expect("dir");
        write_reprint(&dir);
        inputs.push(InputArtifact { name: "reprint_lag".into(), role: NAMED.role, dir });
        let ours = Ours::read(&inputs).expect("reads");
        let (rows, html) = section(&ours);
        let row = rows.iter().find(|r| r.item == "extension (lag model): max contour error reduction").expect("row");
        assert!((row.ours - reduction_pct(1.52, 0.27)).abs() < 1e-9 && row.paper.is_none());
        assert!(row.source.contains("stage reprint_lag"), "{}", row.source);
        assert!(html.contains("(our extension, no widths: stage compensate_lag)"), "{html}");
    }

    #[test]
    fn a_variant_is_read_by_name_and_one_not_run_is_said_to_be_so() {
        let root = tempfile::tempdir().expect("tempdir");
        let mut inputs = inputs(root.path());
        let dir = root.path().join("reprint_paper_gain");
        std::fs::create_dir_all(&dir).expect("dir");
        write_reprint(&dir);
        inputs.push(InputArtifact { name: "reprint_paper_gain".into(), role: NAMED.role, dir });
        let ours = Ours::read(&inputs).expect("reads");
        assert_eq!(ours.variants.len(), 1);
        assert!(ours.extension.is_none(), "only reprint_lag is the extension");
        let (_, html) = section(&ours);
        // Synthetic re-print: max 1.52 → 0.27 mm (−82 %), RMS 0.41 → 0.19 mm (−54 %).
        assert!(html.contains("max −82 %, RMS −54 % (variant paper_gain)"), "{html}");
        assert!(html.contains("— (variant first_layer was not run)"));
        let df = super::super::chen2024_variants::variants_frame(&ours.reprint, &ours.variants).expect("frame");
        assert_eq!(df.height(), 2, "defaults and the variant");
    }

    #[test]
    fn a_missing_number_is_shown_as_missing() {
        let root = tempfile::tempdir().expect("tempdir");
        let mut ours = Ours::read(&inputs(root.path())).expect("reads");
        ours.accuracy.remove("capture_time_err_median_ms");
        let (rows, html) = section(&ours);
        assert!(!rows.iter().any(|r| r.item == "capture-time localisation error, median (eq. 28)"));
        assert!(html.contains("<td>—</td>"), "{html}");
    }

    #[test]
    fn missing_table_or_column_is_named() {
        let root = tempfile::tempdir().expect("tempdir");
        let inputs = inputs(root.path());
        std::fs::remove_file(inputs[2].dir.join(accuracy::TABLE.file())).expect("removes");
        let err = Ours::read(&inputs).expect_err("no accuracy").to_string();
        assert!(err.contains("accuracy.parquet"), "{err}");
        write_table(&inputs[2].dir, "accuracy", accuracy().drop("unit").expect("drops"));
        let err = Ours::read(&inputs).expect_err("no unit column").to_string();
        assert!(err.contains("accuracy.parquet") && err.contains("unit"), "{err}");
    }
}
