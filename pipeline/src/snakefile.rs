//! A Snakemake workflow for a plan's work units ([`crate::units`]): one rule per unit
//! calling `amrepro run-unit`, its inputs the done-files of the units it needs, and a
//! `collect` rule over all of them, so `snakemake --cores N` runs the plan here and
//! Snakemake's executor plugins (Slurm, Kubernetes, …) run the same file on a cluster.
//! Paths are absolute and can be overridden with `--config amrepro=… spec=… out=…`.

use std::fmt::Write;
use std::path::Path;

use crate::plan::Plan;
use crate::units::UnitPlan;

/// What the workflow calls and where it writes.
pub struct SnakefileTarget<'a> {
    /// The `amrepro` executable the rules call.
    pub amrepro: &'a Path,
    /// The spec, as the workers will see it.
    pub spec: &'a Path,
    /// The shared out folder.
    pub out: &'a Path,
}

/// The Snakefile text for `plan`.
pub fn snakefile(plan: &Plan, units: &UnitPlan, target: &SnakefileTarget) -> String {
    let manifest = format!("runs/{}/manifest.json", plan.run_name);
    let mut s = format!(
        "# Snakemake workflow of {spec}, written by `amrepro snakefile` (amrepro {version}).\n\
         # {count} work units (`amrepro plan` lists them), then `collect`, which checks them,\n\
         # merges the split stages, runs the rest and writes the report.\n\
         #   here:          snakemake -s THIS_FILE --cores 2\n\
         #   on a cluster:  see docs/SCALE.md (Slurm and Kubernetes executor plugins)\n\n\
         AMREPRO = config.get(\"amrepro\", {amrepro})\n\
         SPEC = config.get(\"spec\", {spec_q})\n\
         OUT = config.get(\"out\", {out})\n\n\
         rule all:\n    input: OUT + \"/{manifest}\"\n\n",
        spec = target.spec.display(),
        version = crate::TOOL_VERSION,
        count = units.units.len(),
        amrepro = py_str(&target.amrepro.display().to_string()),
        spec_q = py_str(&target.spec.display().to_string()),
        out = py_str(&target.out.display().to_string()),
    );
    for unit in &units.units {
        let inputs: Vec<String> = unit.needs.iter().map(|&n| done_path(&units.units[n].done_file)).collect();
        let _ = writeln!(s, "# {} ({}): {}", unit.stage, unit.kind, unit.unit);
        let _ = writeln!(s, "rule unit_{:05}:", unit.index);
        let _ = writeln!(s, "    input: [{}]", inputs.join(", "));
        let _ = writeln!(s, "    output: {}", done_path(&unit.done_file));
        let _ = writeln!(s, "    params: amrepro=AMREPRO, spec=SPEC, out=OUT");
        let _ = writeln!(
            s,
            "    shell: \"{{params.amrepro:q}} run-unit {{params.spec:q}} --index {} --out {{params.out:q}} --quiet\"\n",
            unit.index
        );
    }
    let all: Vec<String> = units.units.iter().map(|u| done_path(&u.done_file)).collect();
    let _ = writeln!(s, "rule collect:");
    let _ = writeln!(s, "    input: [{}]", all.join(", "));
    let _ = writeln!(s, "    output: OUT + \"/{manifest}\"");
    let _ = writeln!(s, "    params: amrepro=AMREPRO, spec=SPEC, out=OUT");
    let _ = writeln!(s, "    shell: \"{{params.amrepro:q}} collect {{params.spec:q}} --out {{params.out:q}} --quiet\"");
    s
}

/// `OUT + "/units/…"` as Python.
fn done_path(rel: &Path) -> String {
    format!("OUT + {}", py_str(&format!("/{}", rel.display())))
}

/// A Python string literal.
fn py_str(text: &str) -> String {
    let mut quoted = String::from("\"");
    for c in text.chars() {
        match c {
            '"' | '\\' => {
                quoted.push('\\');
                quoted.push(c);
            }
            '\n' => quoted.push_str("\\n"),
            c => quoted.push(c),
        }
    }
    quoted + "\""
}
