//! Renders a plan's DAG as Graphviz dot or Mermaid, for `amrepro graph`.

use crate::plan::{InputRef, Plan};

/// Output format of [`render`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GraphFormat {
    /// Graphviz `digraph`.
    Dot,
    /// Mermaid `flowchart`.
    Mermaid,
}

/// The plan's datasets and stages as nodes, inputs as edges.
pub fn render(plan: &Plan, format: GraphFormat) -> String {
    let edges: Vec<(String, String)> = plan
        .stages
        .iter()
        .flat_map(|s| {
            s.inputs.iter().map(move |i| {
                let from = match i {
                    InputRef::Dataset(_) => format!("dataset:{}", plan.input_name(*i)),
                    InputRef::Stage(_) => plan.input_name(*i).to_string(),
                };
                (from, s.name.clone())
            })
        })
        .collect();
    match format {
        GraphFormat::Dot => dot(plan, &edges),
        GraphFormat::Mermaid => mermaid(plan, &edges),
    }
}

fn dot(plan: &Plan, edges: &[(String, String)]) -> String {
    let mut out = format!("digraph \"{}\" {{\n  rankdir=LR;\n", plan.run_name);
    for d in &plan.datasets {
        out += &format!("  \"dataset:{0}\" [shape=cylinder, label=\"{0}\"];\n", d.name);
    }
    for s in &plan.stages {
        out += &format!("  \"{0}\" [shape=box, label=\"{0}\\n{1}\"];\n", s.name, s.kind);
    }
    for (from, to) in edges {
        out += &format!("  \"{from}\" -> \"{to}\";\n");
    }
    out + "}\n"
}

fn mermaid(plan: &Plan, edges: &[(String, String)]) -> String {
    let id = |n: &str| n.replace([':', '-', '.'], "_");
    let mut out = String::from("flowchart LR\n");
    for d in &plan.datasets {
        out += &format!("  {}[(\"{}\")]\n", id(&format!("dataset:{}", d.name)), d.name);
    }
    for s in &plan.stages {
        out += &format!("  {}[\"{}<br/>{}\"]\n", id(&s.name), s.name, s.kind);
    }
    for (from, to) in edges {
        out += &format!("  {} --> {}\n", id(from), id(to));
    }
    out
}
