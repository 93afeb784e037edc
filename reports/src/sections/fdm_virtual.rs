//! `report.fdm_virtual`: paper 000 from photos. How closely the virtual Taz 5 / Taz 6
//! reproduce the real lines, how accurately the widths are segmented from their photos
//! (against the virtual printer's truth, beside a plain threshold baseline), paper
//! 000's leave-one-out on the segmented widths beside the same on the real widths, and
//! what the discrepancy engine names on a photo set with a hidden effect and on one
//! without. Every number is read from the input stages' tables.
//!
//! Inputs, in order: `fdm.virtual_agreement`, `fdm.segment_accuracy`, the segmentation
//! diagnostics, the leave-one-out on the photos, the leave-one-out on the real lines,
//! the discrepancy engine on the clean photo set, then on the one with a hidden effect.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::ParamError;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use tables::discrepancy::fdm::{causes, extension};
use tables::fdm::{agreement, loo, photo_sets, segment_accuracy, segment_diagnostics};
use tables::report::comparison;

use super::{comparison_frame, Row};
use crate::html::{escape, format_sig};
use crate::read::{bools, f64s, ints, read_parquet, strs};
use models::stats::finite_median;

/// The `report.fdm_virtual` stage kind.
pub struct FdmVirtualSection;

pipeline::params! {
    /// The parameters of `report.fdm_virtual`.
    pub struct FdmVirtualParams {
        /// The photo-set stages behind the two discrepancy-engine inputs, `clean, hidden` (their
        /// effects are read from the accuracy stage's photo_sets.parquet).
        pub engine_photo_sets: String,
    }
}

impl FdmVirtualParams {
    /// The photo-set stage names of `engine_photo_sets`: the clean one, then the one with
    /// a hidden effect.
    fn photo_sets(&self) -> Result<[&str; 2], ParamError> {
        let sets: Vec<&str> = self.engine_photo_sets.split(',').map(str::trim).collect();
        <[&str; 2]>::try_from(sets).map_err(|_| {
            let message = "expected two photo-set stage names, of the clean and of the hidden-effect run";
            ParamError::new("engine_photo_sets", message)
        })
    }
}

/// Both models' leave-one-out (a `table.concat` of their stages).
const LOO_KINDS: &[Source] = &[Source::Stage("fdm.piecewise_loo"), Source::Stage("fdm.lag_model")];
/// What `loo_part` reads of a leave-one-out.
const LOO_READS: &[Reads] = &[Reads { table: &loo::TABLE, columns: &[loo::printer, loo::model, loo::rmse_mm] }];

/// The virtual printers against the real lines.
const AGREEMENT: Input = Input::one(
    "agreement",
    &[Source::Stage("fdm.virtual_agreement")],
    "the held-out RMSE and virtual scatter per line (`agreement.parquet`)",
)
.reading(&[Reads {
    table: &agreement::TABLE,
    columns: &[agreement::printer, agreement::condition, agreement::rmse_mm, agreement::virtual_scatter_mm],
}]);

/// The segmentation's accuracy against the truth.
const ACCURACY: Input = Input::one(
    "accuracy",
    &[Source::Stage("fdm.segment_accuracy")],
    "the width RMSE and bias per photo, and what each photo set holds (`segment_accuracy.parquet`, `photo_sets.parquet`)",
)
.reading(&[
    Reads {
        table: &segment_accuracy::TABLE,
        columns: &[
            segment_accuracy::method,
            segment_accuracy::px_per_mm,
            segment_accuracy::rmse_mm,
            segment_accuracy::bias_mm,
        ],
    },
    Reads { table: &photo_sets::TABLE, columns: &[photo_sets::dataset, photo_sets::effects] },
]);

/// The segmentation's diagnostics (a `table.concat` of the segmentations').
const DIAGNOSTICS: Input = Input::one(
    "diagnostics",
    &[Source::Stage("fdm.segment_widths")],
    "the positions the segmentation skipped and why (`segment_diagnostics.parquet`)",
)
.reading(&[Reads {
    table: &segment_diagnostics::TABLE,
    columns: &[
        segment_diagnostics::printer,
        segment_diagnostics::line_id,
        segment_diagnostics::status,
        segment_diagnostics::problem,
    ],
}]);

/// Paper 000's leave-one-out on the segmented widths.
const PHOTO_LOO: Input =
    Input::one("photo_loo", LOO_KINDS, "the held-out RMSE on the widths from photos (`loo.parquet`)")
        .reading(LOO_READS);

/// Paper 000's leave-one-out on the measured widths.
const REAL_LOO: Input =
    Input::one("real_loo", LOO_KINDS, "the held-out RMSE on the real widths (`loo.parquet`)").reading(LOO_READS);

/// What the section reads of an engine run on photos.
const ENGINE_READS: &[Reads] = &[
    Reads {
        table: &causes::TABLE,
        columns: &[
            causes::mechanism,
            causes::verdict,
            causes::named,
            causes::gain_pct,
            causes::p_adjusted,
            causes::round,
        ],
    },
    Reads {
        table: &extension::TABLE,
        columns: &[
            extension::mechanism,
            extension::parameter,
            extension::unit,
            extension::estimate,
            extension::ci_lo,
            extension::ci_hi,
        ],
    },
];

/// The engine on the clean photo set.
const CLEAN_ENGINE: Input = Input::one(
    "clean_engine",
    &[Source::Stage("fdm.discrepancy")],
    "the engine's causes and extension on the photo set as printed (`causes.parquet`, `extension.parquet`)",
)
.reading(ENGINE_READS);

/// The engine on the photo set with a hidden effect.
const HIDDEN_ENGINE: Input = Input::one(
    "hidden_engine",
    &[Source::Stage("fdm.discrepancy")],
    "the engine's causes and extension on the photo set with a hidden effect (`causes.parquet`, `extension.parquet`)",
)
.reading(ENGINE_READS);

impl Stage for FdmVirtualSection {
    type Params = FdmVirtualParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.fdm_virtual",
        version: 1,
        summary: "Paper 000 from photos: virtual vs real lines, segmentation accuracy, leave-one-out on photos vs real widths, the discrepancy engine on photos → section.html, comparison.parquet",
        implements: "paper 000 Sec. III (widths from camera images), DESIGN §5.1 and §7",
        inputs: &[AGREEMENT, ACCURACY, DIAGNOSTICS, PHOTO_LOO, REAL_LOO, CLEAN_ENGINE, HIDDEN_ENGINE],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE];

    fn check(p: &FdmVirtualParams) -> Result<(), ParamError> {
        p.photo_sets().map(|_| ())
    }

    fn run(&self, ctx: &mut StageContext, p: &FdmVirtualParams) -> Result<(), StageError> {
        let dir = |role: &Input| ctx.input(role).dir.clone();
        let name = |role: &Input| ctx.input(role).name.clone();
        let mut rows = Vec::new();
        let mut html =
            String::from("<h3>Paper 000 from photos: the virtual printers, their camera and the segmentation</h3>\n");
        html += &agreement_part(&dir(&AGREEMENT), &name(&AGREEMENT), &mut rows)?;
        html += &accuracy_part(&dir(&ACCURACY), &name(&ACCURACY), &mut rows)?;
        html += &skipped_part(&dir(&DIAGNOSTICS))?;
        html += &loo_part(&dir(&PHOTO_LOO), &dir(&REAL_LOO), (&name(&PHOTO_LOO), &name(&REAL_LOO)), &mut rows)?;
        let sets = read_photo_sets(&dir(&ACCURACY))?;
        let photo_sets = p.photo_sets().map_err(|e| StageError::params(ctx, e))?;
        let runs = [(dir(&CLEAN_ENGINE), name(&CLEAN_ENGINE)), (dir(&HIDDEN_ENGINE), name(&HIDDEN_ENGINE))];
        html += &discrepancy_part(&runs, &photo_sets, &sets, &mut rows)?;
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

fn row(section: &'static str, item: String, ours: f64, unit: &'static str, source: String) -> Row {
    Row { section, item, paper: None, ours, unit, source }
}

/// Per printer: the held-out RMSE of the real lines against the virtual printer
/// calibrated without them, pooled over the lines (root mean square), beside the
/// virtual lines' own scatter pooled the same way, and the worst line.
fn agreement_part(dir: &Path, stage: &str, rows: &mut Vec<Row>) -> Result<String, StageError> {
    let path = dir.join(agreement::TABLE.file());
    let df = read_parquet(&path)?;
    let (printer, condition) = (strs(&df, agreement::printer, &path)?, strs(&df, agreement::condition, &path)?);
    let (rmse, scatter) = (f64s(&df, agreement::rmse_mm, &path)?, f64s(&df, agreement::virtual_scatter_mm, &path)?);
    let mut html = String::from(
        "<h4>The virtual printers against the real lines</h4>\n<p>Each virtual printer's physics (the lag model with the start blob and the width cap where the discrepancy engine names them on the real lines, a layer height of its own per line, slow wander and rough edges) is calibrated on the real lines. Here each real line is held out: the printer calibrated on the other lines prints it, and the measured widths are compared with the virtual mean profile. If a real line were one more virtual line, its RMSE would be about the scatter of the virtual lines around that mean; both are pooled over the printer's lines as root mean squares.</p>\n<table><tr><th class=\"t\">printer</th><th>held-out RMSE, pooled (mm)</th><th>virtual scatter, pooled (mm)</th><th class=\"t\">worst line</th><th>its RMSE (mm)</th><th>its virtual scatter (mm)</th></tr>\n",
    );
    let pooled = |idx: &[usize], v: &[f64]| (idx.iter().map(|&i| v[i] * v[i]).sum::<f64>() / idx.len() as f64).sqrt();
    for p in distinct_strs(&printer) {
        let idx: Vec<usize> = (0..df.height()).filter(|&i| printer[i] == p).collect();
        let (real, virtual_scatter) = (pooled(&idx, &rmse), pooled(&idx, &scatter));
        let worst = *idx.iter().max_by(|&&a, &&b| rmse[a].total_cmp(&rmse[b])).expect("rows of the printer");
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{p}</td><td>{real:.3}</td><td>{virtual_scatter:.3}</td><td class=\"t\">{}</td><td>{:.3}</td><td>{:.3}</td></tr>",
            condition[worst], rmse[worst], scatter[worst]
        );
        let source = format!("out/fdm_virtual/agreement.parquet (stage {stage}, fdm.virtual_agreement)");
        rows.push(row("agreement", format!("{p} pooled held-out rmse"), real, "mm", source.clone()));
        rows.push(row("agreement", format!("{p} pooled virtual scatter"), virtual_scatter, "mm", source));
    }
    html += "</table>\n";
    Ok(html)
}

/// Per scale and method: the mean and worst RMSE and the worst bias over the photos.
fn accuracy_part(dir: &Path, stage: &str, rows: &mut Vec<Row>) -> Result<String, StageError> {
    let path = dir.join(segment_accuracy::TABLE.file());
    let df = read_parquet(&path)?;
    let (method, scale) = (strs(&df, segment_accuracy::method, &path)?, f64s(&df, segment_accuracy::px_per_mm, &path)?);
    let (rmse, bias) = (f64s(&df, segment_accuracy::rmse_mm, &path)?, f64s(&df, segment_accuracy::bias_mm, &path)?);
    let mut groups: BTreeMap<(i64, String), Vec<usize>> = BTreeMap::new();
    for i in 0..df.height() {
        groups.entry((-(scale[i].round() as i64), method[i].clone())).or_default().push(i);
    }
    let mut html = String::from(
        "<h4>Widths from photos: accuracy against the truth</h4>\n<p>Every virtual line is photographed from above (soft edges, bed texture, uneven lighting, vignetting, sensor noise, a small unknown rotation and offset) and its width measured every 0.05 mm: <em>edge fit</em> fits a blurred two-edge model with a linear background across the line at each position along an axis refined from the photo; <em>threshold</em> is the plain method (Otsu threshold, pixels counted per column). Errors are against the true width of the printed line.</p>\n<table><tr><th>px/mm</th><th class=\"t\">method</th><th>photos measured</th><th>not measured</th><th>mean RMSE (mm)</th><th>worst RMSE (mm)</th><th>worst |bias| (mm)</th></tr>\n",
    );
    for ((neg_scale, m), idx) in &groups {
        let ok: Vec<usize> = idx.iter().copied().filter(|&i| rmse[i].is_finite()).collect();
        let mean = ok.iter().map(|&i| rmse[i]).sum::<f64>() / ok.len().max(1) as f64;
        let worst = ok.iter().map(|&i| rmse[i]).fold(f64::NAN, f64::max);
        let worst_bias = ok.iter().map(|&i| bias[i].abs()).fold(f64::NAN, f64::max);
        let px = -neg_scale;
        let _ = writeln!(
            html,
            "<tr><td>{px}</td><td class=\"t\">{}</td><td>{}</td><td>{}</td><td>{mean:.4}</td><td>{worst:.4}</td><td>{worst_bias:.4}</td></tr>",
            m.replace('_', " "),
            ok.len(),
            idx.len() - ok.len()
        );
        let source = format!("out/fdm_virtual/segment_accuracy.parquet (stage {stage}, fdm.segment_accuracy)");
        rows.push(row("segmentation", format!("{m} at {px} px/mm worst rmse"), worst, "mm", source.clone()));
        rows.push(row("segmentation", format!("{m} at {px} px/mm worst abs bias"), worst_bias, "mm", source));
    }
    html += "</table>\n";
    Ok(html)
}

/// The photos the segmentation could not measure, and why.
fn skipped_part(dir: &Path) -> Result<String, StageError> {
    let path = dir.join(segment_diagnostics::TABLE.file());
    let df = read_parquet(&path)?;
    let (printer, line, status, problem) = (
        strs(&df, segment_diagnostics::printer, &path)?,
        strs(&df, segment_diagnostics::line_id, &path)?,
        strs(&df, segment_diagnostics::status, &path)?,
        strs(&df, segment_diagnostics::problem, &path)?,
    );
    let skipped: Vec<usize> = (0..df.height()).filter(|&i| status[i] != "measured").collect();
    if skipped.is_empty() {
        return Ok(format!("<p>All {} photos the leave-one-out uses were measured.</p>\n", df.height()));
    }
    let mut html = String::from("<p>Photos left out of the analysis:</p>\n<ul>\n");
    for i in skipped {
        let _ = writeln!(html, "<li>{} {}: {}</li>", printer[i], line[i], escape(&problem[i]));
    }
    Ok(html + "</ul>\n")
}

/// Per printer and model: the median leave-one-out RMSE on the photos and on the real lines.
fn loo_part(photos: &Path, real: &Path, stages: (&str, &str), rows: &mut Vec<Row>) -> Result<String, StageError> {
    let read = |dir: &Path| -> Result<BTreeMap<(String, String), Vec<f64>>, StageError> {
        let path = dir.join(loo::TABLE.file());
        let df = read_parquet(&path)?;
        let (printer, model, rmse) =
            (strs(&df, loo::printer, &path)?, strs(&df, loo::model, &path)?, f64s(&df, loo::rmse_mm, &path)?);
        let mut out: BTreeMap<(String, String), Vec<f64>> = BTreeMap::new();
        for i in 0..df.height() {
            out.entry((printer[i].clone(), model[i].clone())).or_default().push(rmse[i]);
        }
        Ok(out)
    };
    let (virtual_loo, real_loo) = (read(photos)?, read(real)?);
    let mut html = String::from(
        "<h4>Paper 000's leave-one-out on the photos and on the real lines</h4>\n<p>The same stages as on the measured widths, run on the widths segmented from the virtual photos: median held-out RMSE over the nine lines.</p>\n<table><tr><th class=\"t\">printer</th><th class=\"t\">model</th><th>photos of the virtual printer (mm)</th><th>real lines (mm)</th></tr>\n",
    );
    for ((printer, model), v) in &virtual_loo {
        let ours = finite_median(v.iter().copied());
        let measured = real_loo.get(&(printer.clone(), model.clone())).map(|r| finite_median(r.iter().copied()));
        let cell = measured.map_or("—".into(), |m| format!("{m:.3}"));
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{printer}</td><td class=\"t\">{model}</td><td>{ours:.3}</td><td>{cell}</td></tr>"
        );
        let source = format!("out/fdm_virtual/loo.parquet (stage {}, table.concat)", stages.0);
        rows.push(row("loo", format!("{printer} {model} median loo rmse on photos"), ours, "mm", source));
        if let Some(m) = measured {
            let source = format!("stage {} of this run (table.concat of the real lines' leave-one-out)", stages.1);
            rows.push(row("loo", format!("{printer} {model} median loo rmse on real lines"), m, "mm", source));
        }
    }
    Ok(html + "</table>\n")
}

/// Dataset stage name → the effects its photos hold, from `photo_sets.parquet`.
fn read_photo_sets(dir: &Path) -> Result<BTreeMap<String, String>, StageError> {
    let path = dir.join(photo_sets::TABLE.file());
    let df = read_parquet(&path)?;
    let (dataset, effects) = (strs(&df, photo_sets::dataset, &path)?, strs(&df, photo_sets::effects, &path)?);
    Ok(dataset.into_iter().zip(effects).collect())
}

/// Per engine run: its verdict on the photos, beside what the photo set holds.
fn discrepancy_part(
    runs: &[(std::path::PathBuf, String)],
    photo_sets: &[&str],
    sets: &BTreeMap<String, String>,
    rows: &mut Vec<Row>,
) -> Result<String, StageError> {
    let mut html = String::from(
        "<h4>The discrepancy engine on photos</h4>\n<p>The engine runs on widths segmented from two photo sets of the virtual Taz 6, whose physics is the lag model alone: one set as printed, one with an effect hidden in the printer. It is told nothing of either; what each set holds is read from its dataset afterwards.</p>\n<table><tr><th class=\"t\">engine run</th><th class=\"t\">photo set holds</th><th class=\"t\">verdict</th><th class=\"t\">named</th><th class=\"t\">fitted, with 95 % interval</th><th>held-out gain (%)</th><th>adjusted p</th></tr>\n",
    );
    for ((dir, stage), photos) in runs.iter().zip(photo_sets) {
        let path = dir.join(causes::TABLE.file());
        let df = read_parquet(&path)?;
        let (mechanism, verdict) = (strs(&df, causes::mechanism, &path)?, strs(&df, causes::verdict, &path)?);
        let (named, gain, p) = (
            bools(&df, causes::named, &path)?,
            f64s(&df, causes::gain_pct, &path)?,
            f64s(&df, causes::p_adjusted, &path)?,
        );
        let round = ints(&df, causes::round, &path)?;
        let holds =
            sets.get(*photos).map_or("(not among the accuracy stage's photo sets)".into(), |e| e.replace('_', " "));
        let hits: Vec<usize> = (0..df.height()).filter(|&i| named[i]).collect();
        let first_verdict =
            (0..df.height()).min_by_key(|&i| round[i]).map_or("—".to_string(), |i| verdict[i].clone());
        if hits.is_empty() {
            let _ = writeln!(html, "<tr><td class=\"t\">{stage}</td><td class=\"t\">{}</td><td class=\"t\">{}</td><td class=\"t\">nothing</td><td class=\"t\">—</td><td>—</td><td>—</td></tr>", escape(&holds), first_verdict.replace('_', " "));
        }
        for &i in &hits {
            let fitted = fitted_parameters(dir, &mechanism[i])?;
            let _ = writeln!(html, "<tr><td class=\"t\">{stage}</td><td class=\"t\">{}</td><td class=\"t\">named (round {})</td><td class=\"t\">{}</td><td class=\"t\">{}</td><td>{:.1}</td><td>{:.2e}</td></tr>", escape(&holds), round[i], mechanism[i].replace('_', " "), escape(&fitted), gain[i], p[i]);
            let source = format!("causes.parquet of stage {stage} (fdm.discrepancy)");
            rows.push(row("discrepancy", format!("{stage} {} gain", mechanism[i]), gain[i], "%", source));
        }
    }
    Ok(html + "</table>\n")
}

/// The named mechanism's parameters from the run's `extension.parquet`:
/// `period_mm 12.10 mm [12.00, 12.20]; …`.
fn fitted_parameters(dir: &Path, mechanism: &str) -> Result<String, StageError> {
    use extension as e;
    let path = dir.join(e::TABLE.file());
    let df = read_parquet(&path)?;
    let (m, name, unit) =
        (strs(&df, e::mechanism, &path)?, strs(&df, e::parameter, &path)?, strs(&df, e::unit, &path)?);
    let (est, lo, hi) = (f64s(&df, e::estimate, &path)?, f64s(&df, e::ci_lo, &path)?, f64s(&df, e::ci_hi, &path)?);
    let unit_text = |u: &str| if u == "1" || u.is_empty() { String::new() } else { format!(" {u}") };
    let parts: Vec<String> = (0..df.height())
        .filter(|&i| m[i] == mechanism)
        .map(|i| {
            format!(
                "{} {}{} [{}, {}]",
                name[i],
                format_sig(est[i]),
                unit_text(&unit[i]),
                format_sig(lo[i]),
                format_sig(hi[i])
            )
        })
        .collect();
    Ok(if parts.is_empty() { "—".into() } else { parts.join("; ") })
}

fn distinct_strs(values: &[String]) -> Vec<String> {
    let mut v = values.to_vec();
    v.sort();
    v.dedup();
    v
}
