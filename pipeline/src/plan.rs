//! Spec → validated, resolved plan. Nothing executes an unchecked spec: every name,
//! input, parameter, publish path and the absence of cycles is checked here, and each
//! error names the spec file, the stage and the field.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

use crate::error::SpecError;
use crate::params::Params;
use crate::spec::{expand_path, read_spec, RawSpec, RawStage};
use crate::stage::Registry;

/// A checked, ordered plan.
#[derive(Debug, Clone)]
pub struct Plan {
    /// The spec file it came from.
    pub spec_file: PathBuf,
    /// Run name (folder under `out/runs/`).
    pub run_name: String,
    /// Title shown in the report.
    pub title: String,
    /// Run seed.
    pub seed: u64,
    /// External datasets.
    pub datasets: Vec<PlannedDataset>,
    /// Stages in a topological order.
    pub stages: Vec<PlannedStage>,
    /// Groups of stage indices that can run in parallel, in dependency order.
    pub waves: Vec<Vec<usize>>,
}

/// A dataset folder the plan reads.
#[derive(Debug, Clone)]
pub struct PlannedDataset {
    /// Name in the spec.
    pub name: String,
    /// Resolved folder.
    pub dir: PathBuf,
    /// Where to get it if it is missing.
    pub source: String,
}

/// Where a stage input comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputRef {
    /// Index into [`Plan::datasets`].
    Dataset(usize),
    /// Index into [`Plan::stages`].
    Stage(usize),
}

/// A checked stage.
#[derive(Debug, Clone)]
pub struct PlannedStage {
    /// Name in the spec.
    pub name: String,
    /// Registered kind.
    pub kind: &'static str,
    /// Kind version at planning time.
    pub kind_version: u32,
    /// Complete, checked parameters.
    pub params: Params,
    /// Inputs in spec order.
    pub inputs: Vec<InputRef>,
    /// Output file → stable path relative to the out folder.
    pub publish: Vec<(String, PathBuf)>,
}

impl Plan {
    /// Reads `spec_file` and checks it against `registry`; `${VAR}` in dataset paths
    /// are read from the process environment.
    pub fn from_file(spec_file: &Path, registry: &Registry) -> Result<Self, SpecError> {
        let raw = read_spec(spec_file)?;
        Self::check(spec_file, raw, registry, |v| std::env::var(v).ok())
    }

    /// Checks a parsed spec.
    pub fn check(
        spec_file: &Path,
        raw: RawSpec,
        registry: &Registry,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Self, SpecError> {
        let err = |loc: String, msg: String| SpecError::new(spec_file, loc, msg);
        check_name(&raw.run.name).map_err(|m| err("run.name".into(), m))?;
        let base = spec_file.parent().unwrap_or(Path::new("."));
        let datasets = plan_datasets(&raw, base, &env).map_err(|(l, m)| err(l, m))?;
        let order = topological_order(&raw, &datasets).map_err(|(l, m)| err(l, m))?;
        let mut stages = Vec::with_capacity(order.len());
        for name in &order {
            let planned = plan_stage(name, &raw.stage[name], registry, &datasets, &order)
                .map_err(|(field, m)| err(format!("stage.{name}.{field}"), m))?;
            stages.push(planned);
        }
        check_publish_unique(&stages).map_err(|(l, m)| err(l, m))?;
        let waves = waves(&stages);
        Ok(Self {
            spec_file: spec_file.to_path_buf(),
            run_name: raw.run.name,
            title: raw.run.title,
            seed: raw.run.seed,
            datasets,
            stages,
            waves,
        })
    }

    /// Index of the stage called `name`.
    pub fn stage_index(&self, name: &str) -> Option<usize> {
        self.stages.iter().position(|s| s.name == name)
    }

    /// Human name of an input.
    pub fn input_name(&self, input: InputRef) -> &str {
        match input {
            InputRef::Dataset(i) => &self.datasets[i].name,
            InputRef::Stage(i) => &self.stages[i].name,
        }
    }
}

type Located = (String, String);

fn check_name(name: &str) -> Result<(), String> {
    let ok =
        !name.is_empty() && name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == '-');
    if ok {
        Ok(())
    } else {
        Err(format!("`{name}` is not a valid name: use lowercase letters, digits, `_` and `-`"))
    }
}

fn plan_datasets(
    raw: &RawSpec,
    base: &Path,
    env: &impl Fn(&str) -> Option<String>,
) -> Result<Vec<PlannedDataset>, Located> {
    raw.dataset
        .iter()
        .map(|(name, ds)| {
            check_name(name).map_err(|m| (format!("dataset.{name}"), m))?;
            if raw.stage.contains_key(name) {
                return Err((format!("dataset.{name}"), "a stage has the same name".into()));
            }
            let dir = expand_path(&ds.path, base, env).map_err(|m| (format!("dataset.{name}.path"), m))?;
            if dir.is_file() {
                return Err((
                    format!("dataset.{name}.path"),
                    format!("{} is a file, expected a dataset folder", dir.display()),
                ));
            }
            Ok(PlannedDataset { name: name.clone(), dir, source: ds.source.clone() })
        })
        .collect()
}

/// Orders stages so every stage follows its stage inputs (Kahn's algorithm, ties by
/// name); an unknown input or a cycle is an error naming the stage.
fn topological_order(raw: &RawSpec, datasets: &[PlannedDataset]) -> Result<Vec<String>, Located> {
    let is_dataset = |n: &str| datasets.iter().any(|d| d.name == n);
    for (name, stage) in &raw.stage {
        check_name(name).map_err(|m| (format!("stage.{name}"), m))?;
        for input in &stage.inputs {
            if !is_dataset(input) && !raw.stage.contains_key(input) {
                return Err((
                    format!("stage.{name}.inputs"),
                    format!("`{input}` is neither a dataset nor a stage of this spec"),
                ));
            }
        }
    }
    let mut pending: BTreeMap<&str, BTreeSet<&str>> = raw
        .stage
        .iter()
        .map(|(n, s)| (n.as_str(), s.inputs.iter().map(String::as_str).filter(|i| !is_dataset(i)).collect()))
        .collect();
    let mut order = Vec::new();
    while !pending.is_empty() {
        let ready: Vec<&str> = pending.iter().filter(|(_, deps)| deps.is_empty()).map(|(n, _)| *n).collect();
        if ready.is_empty() {
            let cycle: Vec<&str> = pending.keys().copied().collect();
            return Err((format!("stage.{}.inputs", cycle[0]), format!("cycle among stages: {}", cycle.join(" → "))));
        }
        for name in ready {
            pending.remove(name);
            pending.values_mut().for_each(|deps| {
                deps.remove(name);
            });
            order.push(name.to_string());
        }
    }
    Ok(order)
}

fn plan_stage(
    name: &str,
    raw: &RawStage,
    registry: &Registry,
    datasets: &[PlannedDataset],
    order: &[String],
) -> Result<PlannedStage, Located> {
    let kind = registry.get(&raw.kind).ok_or_else(|| ("kind".to_string(), unknown_kind(&raw.kind, registry)))?;
    let arity = kind.arity();
    if raw.inputs.len() < arity.min || raw.inputs.len() > arity.max {
        return Err((
            "inputs".into(),
            format!("`{}` takes {} input(s), got {}", kind.name(), arity_text(arity), raw.inputs.len()),
        ));
    }
    let params = Params::check(kind.params(), &raw.params).map_err(|(f, m)| (format!("params.{f}"), m))?;
    let inputs = raw
        .inputs
        .iter()
        .map(|i| match datasets.iter().position(|d| &d.name == i) {
            Some(d) => InputRef::Dataset(d),
            None => InputRef::Stage(order.iter().position(|s| s == i).expect("checked in ordering")),
        })
        .collect();
    let publish = raw
        .publish
        .iter()
        .map(|(from, to)| {
            check_publish_path(to).map(|p| (from.clone(), p)).map_err(|m| (format!("publish.\"{from}\""), m))
        })
        .collect::<Result<_, _>>()?;
    Ok(PlannedStage {
        name: name.to_string(),
        kind: kind.name(),
        kind_version: kind.version(),
        params,
        inputs,
        publish,
    })
}

fn arity_text(arity: crate::stage::Arity) -> String {
    match (arity.min, arity.max) {
        (a, b) if a == b => a.to_string(),
        (a, usize::MAX) => format!("at least {a}"),
        (a, b) => format!("{a} to {b}"),
    }
}

fn unknown_kind(kind: &str, registry: &Registry) -> String {
    let names = registry.names();
    let closest = names.iter().min_by_key(|n| edit_distance(kind, n));
    match closest {
        Some(c) if edit_distance(kind, c) <= 3 => format!("unknown stage kind `{kind}`; did you mean `{c}`?"),
        _ => format!("unknown stage kind `{kind}`; known kinds: {}", names.join(", ")),
    }
}

/// Levenshtein distance, for "did you mean" hints.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

fn check_publish_path(to: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(to);
    let plain = path.components().all(|c| matches!(c, Component::Normal(_)));
    if to.is_empty() || !plain || to.starts_with("runs/") || to.starts_with("report/") {
        return Err(format!(
            "`{to}` must be a relative path inside the out folder, without `..`, outside runs/ and report/"
        ));
    }
    Ok(path)
}

fn check_publish_unique(stages: &[PlannedStage]) -> Result<(), Located> {
    let mut seen = BTreeMap::new();
    for stage in stages {
        for (from, to) in &stage.publish {
            if let Some(other) = seen.insert(to.clone(), stage.name.clone()) {
                return Err((
                    format!("stage.{}.publish.\"{from}\"", stage.name),
                    format!("`{}` is also published by stage `{other}`", to.display()),
                ));
            }
        }
    }
    Ok(())
}

/// Groups stages into waves: a stage's wave is one more than its latest stage input's.
fn waves(stages: &[PlannedStage]) -> Vec<Vec<usize>> {
    let mut level = vec![0usize; stages.len()];
    for (i, stage) in stages.iter().enumerate() {
        level[i] = stage
            .inputs
            .iter()
            .filter_map(|inp| match inp {
                InputRef::Stage(j) => Some(level[*j] + 1),
                InputRef::Dataset(_) => None,
            })
            .max()
            .unwrap_or(0);
    }
    let depth = level.iter().max().map_or(0, |m| m + 1);
    (0..depth).map(|d| (0..stages.len()).filter(|i| level[*i] == d).collect()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::StageError;
    use crate::params::{ParamDefault, ParamSpec, ParamType};
    use crate::spec::parse_spec;
    use crate::stage::{Arity, StageContext, StageKind};

    struct Noop;

    const NOOP_PARAMS: &[ParamSpec] =
        &[ParamSpec { name: "k", ty: ParamType::Int { min: 0, max: 9 }, default: ParamDefault::Int(1), doc: "a knob" }];

    impl StageKind for Noop {
        fn name(&self) -> &'static str {
            "test.noop"
        }
        fn version(&self) -> u32 {
            1
        }
        fn summary(&self) -> &'static str {
            "does nothing"
        }
        fn implements(&self) -> &'static str {
            "tests"
        }
        fn params(&self) -> &'static [ParamSpec] {
            NOOP_PARAMS
        }
        fn arity(&self) -> Arity {
            Arity { min: 0, max: 3 }
        }
        fn run(&self, _: &mut StageContext) -> Result<(), StageError> {
            Ok(())
        }
    }

    fn plan(text: &str) -> Result<Plan, SpecError> {
        let mut registry = Registry::new();
        registry.register(Box::new(Noop));
        let file = Path::new("t.toml");
        Plan::check(file, parse_spec(file, text)?, &registry, |_| None)
    }

    #[test]
    fn diamond_orders_into_three_waves_with_the_middle_in_parallel() {
        let p = plan(
            "[run]\nname = \"d\"\n[dataset.raw]\npath = \"x\"\n\
             [stage.top]\nkind = \"test.noop\"\ninputs = [\"raw\"]\n\
             [stage.left]\nkind = \"test.noop\"\ninputs = [\"top\"]\n\
             [stage.right]\nkind = \"test.noop\"\ninputs = [\"top\"]\n\
             [stage.bottom]\nkind = \"test.noop\"\ninputs = [\"left\", \"right\"]\n",
        )
        .unwrap();
        let names = |w: &Vec<usize>| w.iter().map(|i| p.stages[*i].name.clone()).collect::<Vec<_>>();
        let waves: Vec<Vec<String>> = p.waves.iter().map(names).collect();
        assert_eq!(waves, vec![vec!["top"], vec!["left", "right"], vec!["bottom"]]);
        assert_eq!(p.datasets[0].dir, Path::new("x"), "relative to the spec's folder (here: none)");
    }

    #[test]
    fn publish_paths_must_stay_inside_out_and_be_unique() {
        let base = "[run]\nname = \"d\"\n[stage.a]\nkind = \"test.noop\"\n";
        let err = plan(&format!("{base}publish = {{ \"t.parquet\" = \"../t.parquet\" }}\n")).unwrap_err();
        assert_eq!(err.location, "stage.a.publish.\"t.parquet\"");
        let two = format!("{base}publish = {{ \"t.parquet\" = \"x/t.parquet\" }}\n[stage.b]\nkind = \"test.noop\"\npublish = {{ \"u.parquet\" = \"x/t.parquet\" }}\n");
        assert!(plan(&two).unwrap_err().message.contains("also published by stage `a`"));
    }

    #[test]
    fn a_dataset_path_that_is_a_file_is_named_so() {
        // It used to pass the plan and fail the run with "folder … does not exist".
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("lines.csv");
        std::fs::write(&file, "x").unwrap();
        let text = format!("[run]\nname = \"d\"\n[dataset.raw]\npath = \"{}\"\n", file.display());
        let err = plan(&text).unwrap_err();
        assert_eq!(err.location, "dataset.raw.path");
        assert!(err.message.ends_with("lines.csv is a file, expected a dataset folder"), "{}", err.message);
    }

    #[test]
    fn edit_distance_suggests_close_kinds() {
        assert_eq!(edit_distance("fdm.line_sumary", "fdm.line_summary"), 1);
        assert_eq!(edit_distance("", "abc"), 3);
    }
}
