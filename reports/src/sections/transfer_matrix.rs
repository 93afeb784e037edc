//! `report.transfer_matrix`: paper 000's transfer (Sec. II-B, III-B; Fig. 9 for the Taz 5
//! → Taz 6 pair) carried to every ordered pair of several printers and to co-learning
//! from all the others. For each method: in how many (task, n) cells it is worse, or
//! better, than learning from the target's lines alone beyond its 95 % interval; per
//! task, the guarded method's (or co-learning's) improvement with its interval at a few
//! training-set sizes, beside the source-centred prior and the bound in hindsight
//! (`models::fdm::colearn`) at n = 1 and 2; where the fits under a prior took the
//! kinematic scales `(r_a, r_F)` (the table's `kinematics`). Every number is read from
//! `transfer_matrix.parquet`.
//!
//! Input: the `fdm.transfer_matrix` stage.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use pipeline::params::NoParams;
use pipeline::schema::{Reads, Table};
use pipeline::stage::{Input, Output, Source, Stage, StageInfo};
use pipeline::{StageContext, StageError};
use polars::prelude::DataFrame;
use tables::fdm::transfer_matrix;
use tables::report::comparison;

use super::{comparison_frame, Row};
use crate::figures::fdm::transfer_matrix::{matrix_of, Cell, Matrix, READS};
use crate::html::escape;
use crate::read::{no_rows, read_parquet, strs};

/// The `report.transfer_matrix` stage kind.
pub struct TransferMatrixSection;

/// The transfer matrix reported.
const MATRIX: Input = Input::one(
    "matrix",
    &[Source::Stage("fdm.transfer_matrix")],
    "the median improvements with their intervals per task, n and method (`transfer_matrix.parquet`)",
)
.reading(SECTION_READS);

/// What the section reads: the figure's columns and the kinematics rule.
const SECTION_READS: &[Reads] =
    &[READS[0], Reads { table: &transfer_matrix::TABLE, columns: &[transfer_matrix::kinematics] }];

/// Methods in table order, with what a reader of the paper calls them.
const METHODS: [(&str, &str); 4] = [
    ("transfer_zero_mean", "paper's prior N(0, Σ̂/λ) (eqs 4-5)"),
    ("transfer_source_mean", "prior centred on the source, N(θ̄, Σ̂/λ)"),
    ("guarded", "source-centred prior behind the negative-transfer guard"),
    ("co_learning", "co-learning from all other printers (guarded)"),
];
/// Training-set sizes shown per task, besides the largest (n = 1 is 0 by construction).
const SHOWN_N: [i64; 2] = [2, 3];
const SOURCE: &str = "fdm/transfer_matrix.parquet (stage matrix, fdm.transfer_matrix)";

impl Stage for TransferMatrixSection {
    type Params = NoParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "report.transfer_matrix",
        version: 3,
        summary: "Transfer among printers: per method the cells worse / better than single-printer learning beyond their interval, per task the guarded improvement → section.html, comparison.parquet",
        implements: "paper 000 Sec. III-B and Fig. 9, over several printers",
        inputs: &[MATRIX],
        output: Output::Tables,
    };
    const WRITES: &'static [&'static Table] = &[&comparison::TABLE];

    fn run(&self, ctx: &mut StageContext, _: &NoParams) -> Result<(), StageError> {
        let path = ctx.input(&MATRIX).dir.join(transfer_matrix::TABLE.file());
        let table = read_parquet(&path)?;
        let matrix = matrix_of(&table, &path)?;
        let (rows, tally_html) = tally(&matrix);
        let mut html = String::from("<h3>Transfer among printers: when it helps, and the guard</h3>\n");
        html += &tally_html;
        html += &per_task(&matrix);
        html += &kinematics_note(&kinematics_rule(&table, &path)?);
        pipeline::artifact::write_atomic(&ctx.output_path("section.html")?, html.as_bytes())?;
        ctx.write_table(comparison::TABLE.name, &mut comparison_frame(&rows)?)?;
        Ok(())
    }
}

/// Per method: cells, worse and better beyond the interval, the worst and best median.
fn tally(matrix: &Matrix) -> (Vec<Row>, String) {
    let mut html = String::from(
        "<table><tr><th class=\"t\">method</th><th>(task, n) cells</th><th>worse than single beyond the 95 % interval</th>\
<th>better beyond it</th><th>worst median improvement (%)</th><th>best (%)</th></tr>\n",
    );
    let mut rows = Vec::new();
    for (method, label) in METHODS {
        let cells: Vec<&Cell> = matrix.values().flatten().filter(|c| c.method == method).collect();
        if cells.is_empty() {
            continue;
        }
        let worse = cells.iter().filter(|c| c.ci_pct.1 < 0.0).count();
        let better = cells.iter().filter(|c| c.ci_pct.0 > 0.0).count();
        let imp = cells.iter().map(|c| c.improvement_pct);
        let (lo, hi) = imp.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
        let _ = writeln!(
            html,
            "<tr><td class=\"t\">{}</td><td>{}</td><td>{worse}</td><td>{better}</td><td>{lo:+.1}</td><td>{hi:+.1}</td></tr>",
            escape(label),
            cells.len()
        );
        for (item, value) in
            [("cells worse than single beyond the interval", worse), ("cells better beyond it", better)]
        {
            rows.push(Row {
                section: "transfer_matrix",
                item: format!("{method}: {item}"),
                paper: None,
                ours: value as f64,
                unit: "cells",
                source: SOURCE.into(),
            });
        }
    }
    html += "</table>\n<p class=\"run\">A cell is one (sources → target, number of target training lines n); its interval is a paired bootstrap over the target's held-out lines. \
Ours: run ren2021_transfer, stage matrix (fdm.transfer_matrix), table out/fdm/transfer_matrix.parquet.</p>\n";
    (rows, html)
}

/// Per task: the guarded improvement (co-learning for several sources) at a few n.
fn per_task(matrix: &Matrix) -> String {
    let n_max = matrix.values().flatten().map(|c| c.n_train).max().unwrap_or(0);
    let shown: Vec<i64> = SHOWN_N.iter().copied().filter(|&n| n < n_max).chain([n_max]).collect();
    let mut html = String::from("<table><tr><th class=\"t\">sources → target</th><th class=\"t\">method</th>");
    for n in &shown {
        let _ = write!(html, "<th>n = {n}: improvement (%) [95 %]</th>");
    }
    html += "<th>source-centred prior, n = 1 / 2 (%)</th><th>bound in hindsight, n = 1 / 2 (%)</th></tr>\n";
    let mut tasks: BTreeMap<(&str, &str), Vec<&Cell>> = BTreeMap::new();
    for (target, cells) in matrix {
        for c in cells {
            tasks.entry((c.sources.as_str(), target.as_str())).or_default().push(c);
        }
    }
    for ((sources, target), cells) in tasks {
        let method = if sources.contains('+') { "co_learning" } else { "guarded" };
        let at = |m: &str, n: i64| cells.iter().find(|c| c.method == m && c.n_train == n);
        let _ = write!(
            html,
            "<tr><td class=\"t\">{} → {}</td><td class=\"t\">{method}</td>",
            escape(sources),
            escape(target)
        );
        for &n in &shown {
            let text = at(method, n).map_or("—".into(), |c| {
                format!("{:+.1} [{:+.1}, {:+.1}]", c.improvement_pct, c.ci_pct.0, c.ci_pct.1)
            });
            let _ = write!(html, "<td>{text}</td>");
        }
        let plain = |m, n| at(m, n).map_or("—".into(), |c| format!("{:+.1}", c.improvement_pct));
        let (source, bound) = ("transfer_source_mean", "hindsight_bound");
        let _ = writeln!(
            html,
            "<td>{} / {}</td><td>{} / {}</td></tr>",
            plain(source, 1),
            plain(source, 2),
            plain(bound, 1),
            plain(bound, 2)
        );
    }
    html + "</table>\n<p class=\"run\">With one target line the guard does not transfer (nothing on the target validates a transfer), so at n = 1 it is single-printer learning by construction (not shown). \
The bound in hindsight is not a method: for each training subset it takes, among no transfer and every prior of the task at every λ of the grid, the one with the smallest mean RMSE on that subset's own held-out lines. \
No rule that chooses the prior and λ from the training lines has a smaller mean held-out RMSE on any subset, so where the bound is small, no such rule helps with these priors. \
The printers other than the Taz 5 and Taz 6 are made from their measured lines by the stated physical change of stage fdm.other_family (a wider nozzle, a slower melt).</p>\n"
}

/// The one kinematics rule of every row of `transfer_matrix.parquet` (read from `path`).
fn kinematics_rule(table: &DataFrame, path: &Path) -> Result<String, StageError> {
    use transfer_matrix as t;
    let rules = strs(table, t::kinematics, path)?;
    match rules.first() {
        Some(first) if rules.iter().all(|r| r == first) => Ok(first.clone()),
        _ => Err(no_rows(path, t::kinematics, "one kinematics rule for every row")),
    }
}

/// Where the fits under a prior took `(r_a, r_F)`, for a reader of the paper.
fn kinematics_note(rule: &str) -> String {
    let how = match rule {
        "target_pair" => "Every fit under a prior takes the kinematic scales (r_a, r_F) of eq. 1 that the same training lines give without prior \
(the single-printer grid search of Sec. II-A) and fits the prior of eq. 5 at that pair. \
The prior is on the shape parameters, not on (r_a, r_F). The reproduction of Fig. 9 repeats the grid search under each prior and λ instead, \
where a strong prior can move the pair to absorb its misfit.",
        "grid" => "Every fit under a prior repeats the grid search over the kinematic scales (r_a, r_F) of eq. 1 for its own prior and λ, as the reproduction of Fig. 9 does.",
        other => return format!("<p class=\"run\">Kinematics rule of the fits under a prior: {}.</p>\n", escape(other)),
    };
    format!("<p class=\"run\">{how}</p>\n")
}
