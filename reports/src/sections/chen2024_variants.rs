//! The variants of paper 003's compensation that the chen2024 section discusses, read
//! from the stages that ran them: each variant `X` is a chain of stages ending in a
//! `thermal.reprint_evaluate` stage named `reprint_X`, re-printed and scored like the
//! paper's method (eqs 40-41), and what sets it apart is read from the records
//! (`.stage.json`) of the report's inputs named `<stage>_X`, compared with the input
//! named `<stage>` (the shipped chain's `sequence`, `monitor`, `compensate`): the
//! parameters that differ and the inputs it adds. Nothing about a variant is typed
//! into the section; a variant the spec does not run is reported as not run.

use std::collections::BTreeMap;
use tables::report::variants;

use pipeline::params::ParamValue;
use pipeline::{InputArtifact, StageError};
use polars::prelude::{Column, DataFrame, IntoColumn, NamedFrom, Series};

use super::chen2024::{reduction_pct, Reprint};

/// The prefix of a variant's re-print stage.
const REPRINT_PREFIX: &str = "reprint_";

/// One thing a variant's stage does differently from the shipped chain's.
#[derive(Debug, Clone, PartialEq)]
pub enum Change {
    /// `stage` runs with `param = value` where the shipped stage `base` has `base_value`.
    Param { stage: String, base: String, param: String, value: ParamValue, base_value: Option<ParamValue> },
    /// `stage` reads an input the shipped stage `base` does not.
    Input { stage: String, base: String, input: String },
}

impl Change {
    /// "compensate_paper_gain: gain = "paper" (compensate: "unit")".
    pub fn text(&self) -> String {
        match self {
            Change::Param { stage, base, param, value, base_value } => {
                let was = base_value.as_ref().map_or("unset".to_string(), |v| v.to_string());
                format!("{stage}: {param} = {value} ({base}: {was})")
            }
            Change::Input { stage, base, input } => format!("{stage}: also reads {input} (not read by {base})"),
        }
    }
}

/// A variant's re-print and what sets it apart.
#[derive(Debug, Clone)]
pub struct Variant {
    /// `X` of `reprint_X`.
    pub name: String,
    /// Its re-print's scores.
    pub reprint: Reprint,
    /// What its stages do differently from the shipped chain.
    pub changes: Vec<Change>,
}

impl Variant {
    /// The shipped chain's re-print, as the row `defaults`.
    pub fn defaults(reprint: &Reprint) -> Self {
        Self { name: "defaults".into(), reprint: reprint.clone(), changes: Vec::new() }
    }

    /// Change of the mean O_E, of the max and of the RMS contour error from the
    /// conventional print to the compensated one (%; negative: a reduction).
    pub fn changes_pct(&self) -> [f64; 3] {
        let (oe0, oe1) = self.reprint.mean_oe_pct();
        let [(max0, rms0), (max1, rms1)] = self.reprint.contour_mm;
        [-reduction_pct(oe0, oe1), -reduction_pct(max0, max1), -reduction_pct(rms0, rms1)]
    }

    /// The value the variant sets for `param`, if one of its changes does.
    pub fn param(&self, param: &str) -> Option<&ParamValue> {
        self.changes.iter().find_map(|c| match c {
            Change::Param { param: p, value, .. } if p == param => Some(value),
            _ => None,
        })
    }

    /// Its changes as text, "; "-separated ("—" when none is known).
    pub fn changes_text(&self) -> String {
        if self.changes.is_empty() {
            return "—".to_string();
        }
        self.changes.iter().map(Change::text).collect::<Vec<_>>().join("; ")
    }
}

/// The variants among `inputs`, in their order: every input named `reprint_X`.
pub fn read_variants(inputs: &[InputArtifact]) -> Result<Vec<Variant>, StageError> {
    let records: BTreeMap<&str, pipeline::manifest::StageRecord> =
        inputs.iter().filter_map(|i| pipeline::cache::read_record(&i.dir).map(|r| (i.name.as_str(), r))).collect();
    let names: Vec<&str> = inputs.iter().filter_map(|i| i.name.strip_prefix(REPRINT_PREFIX)).collect();
    // The shipped chain: the inputs that are no variant's stage.
    let shipped: Vec<&str> = inputs
        .iter()
        .map(|i| i.name.as_str())
        .filter(|stage| !names.iter().any(|name| base_of(stage, name).is_some()))
        .collect();
    let mut variants = Vec::new();
    for input in inputs {
        let Some(name) = input.name.strip_prefix(REPRINT_PREFIX) else { continue };
        let changes = inputs
            .iter()
            .filter_map(|i| base_of(&i.name, name).map(|base| (i.name.as_str(), base)))
            .filter(|(_, base)| shipped.contains(base))
            .flat_map(|(stage, base)| changes_between(stage, base, name, &records))
            .collect();
        variants.push(Variant { name: name.to_string(), reprint: Reprint::read(input)?, changes });
    }
    Ok(variants)
}

/// `stage` may be variant `name`'s version of the stage `<base>` when it is named
/// `<base>_<name>` (and is not the variant's re-print).
fn base_of<'a>(stage: &'a str, name: &str) -> Option<&'a str> {
    let base = stage.strip_suffix(name)?.strip_suffix('_')?;
    (!base.is_empty() && format!("{base}_") != REPRINT_PREFIX).then_some(base)
}

/// The parameters of `stage` that differ from `base`'s, and the inputs it adds (other
/// than the variant's own versions of the shipped stages).
fn changes_between(
    stage: &str,
    base: &str,
    name: &str,
    records: &BTreeMap<&str, pipeline::manifest::StageRecord>,
) -> Vec<Change> {
    let (Some(ours), Some(theirs)) = (records.get(stage), records.get(base)) else {
        return Vec::new();
    };
    let base_params: BTreeMap<&String, &ParamValue> = theirs.params.iter().collect();
    let mut changes: Vec<Change> = ours
        .params
        .iter()
        .filter(|(p, v)| base_params.get(p) != Some(v))
        .map(|(p, v)| Change::Param {
            stage: stage.into(),
            base: base.into(),
            param: p.clone(),
            value: v.clone(),
            base_value: base_params.get(p).map(|v| (*v).clone()),
        })
        .collect();
    let suffix = format!("_{name}");
    for input in ours.input_hashes.keys() {
        if !theirs.input_hashes.contains_key(input) && !input.ends_with(&suffix) {
            changes.push(Change::Input { stage: stage.into(), base: base.into(), input: input.clone() });
        }
    }
    changes
}

/// `variants.parquet`: one row per re-print (the shipped chain's first, as `defaults`):
/// variant, what differs, the mean O_E and the contour error's max and RMS before and
/// after, their changes (%) and the source.
pub fn variants_frame(main: &Reprint, variants: &[Variant]) -> Result<DataFrame, StageError> {
    let defaults = Variant::defaults(main);
    let all: Vec<&Variant> = std::iter::once(&defaults).chain(variants).collect();
    let strs = |name: &str, f: &dyn Fn(&Variant) -> String| -> Column {
        Series::new(name.into(), all.iter().map(|v| f(v)).collect::<Vec<String>>()).into_column()
    };
    let floats = |name: &str, f: &dyn Fn(&Variant) -> f64| -> Column {
        Series::new(name.into(), all.iter().map(|v| f(v)).collect::<Vec<f64>>()).into_column()
    };
    let columns = vec![
        strs(variants::variant, &|v| v.name.clone()),
        strs(variants::changes, &|v| if v.name == "defaults" { String::new() } else { v.changes_text() }),
        floats(variants::oe_before_pct, &|v| v.reprint.mean_oe_pct().0),
        floats(variants::oe_after_pct, &|v| v.reprint.mean_oe_pct().1),
        floats(variants::max_before_mm, &|v| v.reprint.contour_mm[0].0),
        floats(variants::max_after_mm, &|v| v.reprint.contour_mm[1].0),
        floats(variants::rms_before_mm, &|v| v.reprint.contour_mm[0].1),
        floats(variants::rms_after_mm, &|v| v.reprint.contour_mm[1].1),
        floats(variants::oe_change_pct, &|v| v.changes_pct()[0]),
        floats(variants::max_change_pct, &|v| v.changes_pct()[1]),
        floats(variants::rms_change_pct, &|v| v.changes_pct()[2]),
        strs(variants::source, &|v| v.reprint.sources[1].clone()),
    ];
    DataFrame::new(all.len(), columns).map_err(|source| StageError::Table { path: "variants".into(), source })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stage_belongs_to_the_variant_its_name_ends_with() {
        assert_eq!(base_of("compensate_paper_gain", "paper_gain"), Some("compensate"));
        assert_eq!(base_of("monitor_read_later", "read_later"), Some("monitor"));
        assert_eq!(base_of("reprint_paper_gain", "paper_gain"), None, "the re-print itself");
        assert_eq!(base_of("compensate_true_widths", "widths"), Some("compensate_true"));
        assert_eq!(base_of("paper_gain", "paper_gain"), None);
        assert_eq!(base_of("compensatepaper_gain", "paper_gain"), None);
    }

    #[test]
    fn a_change_names_the_stage_the_value_and_the_shipped_value() {
        let change = Change::Param {
            stage: "compensate_paper_gain".into(),
            base: "compensate".into(),
            param: "gain".into(),
            value: ParamValue::Str("paper".into()),
            base_value: Some(ParamValue::Str("unit".into())),
        };
        assert_eq!(change.text(), "compensate_paper_gain: gain = \"paper\" (compensate: \"unit\")");
        let input =
            Change::Input { stage: "compensate_x".into(), base: "compensate".into(), input: "true_widths".into() };
        assert_eq!(input.text(), "compensate_x: also reads true_widths (not read by compensate)");
    }
}
