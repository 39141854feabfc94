//! The process graph as SVG (laid out by [`crate::svg`]), Graphviz dot, Mermaid or JSON (`kpl
//! graph`), with stream names and the policies each consumer applies: the pictures show only what
//! differs from the default policy, the JSON every part of it.

use serde_json::json;

use crate::hir::{self, Spec};

/// Output formats of `kpl graph`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Svg,
    Dot,
    Mermaid,
    Json,
}

pub fn render(spec: &Spec, format: Format) -> String {
    match format {
        Format::Svg => crate::svg::svg(spec),
        Format::Dot => dot(spec),
        Format::Mermaid => mermaid(spec),
        Format::Json => serde_json::to_string_pretty(&json_value(spec)).unwrap_or_default() + "\n",
    }
}

fn kind_detail(p: &hir::Process) -> String {
    match &p.kind {
        hir::ProcessKind::Source(c) | hir::ProcessKind::Compute(c) | hir::ProcessKind::Sink(c) => {
            c.entry.clone()
        }
        hir::ProcessKind::Link(l) => format!("{} -> {} via {}", l.from_type, l.to_type, l.via.entry),
        hir::ProcessKind::Monitor(_) => "formula".to_string(),
        hir::ProcessKind::Chronicle(_) => "events".to_string(),
    }
}

fn edges(spec: &Spec) -> impl Iterator<Item = (usize, usize, &hir::Edge)> {
    spec.graph.graph.edge_indices().filter_map(|e| {
        let (a, b) = spec.graph.graph.edge_endpoints(e)?;
        Some((spec.graph.graph[a], spec.graph.graph[b], &spec.graph.graph[e]))
    })
}

fn escape(s: &str) -> String {
    s.replace('\\', "\\\\").replace('"', "\\\"")
}

fn dot(spec: &Spec) -> String {
    let mut out = String::from("digraph kpl {\n  rankdir=LR;\n  node [fontname=\"Helvetica\"];\n");
    let shape = |p: &hir::Process| match p.kind {
        hir::ProcessKind::Source(_) => "invhouse",
        hir::ProcessKind::Sink(_) => "house",
        hir::ProcessKind::Link(_) => "hexagon",
        hir::ProcessKind::Monitor(_) | hir::ProcessKind::Chronicle(_) => "diamond",
        hir::ProcessKind::Compute(_) => "box",
    };
    let node = |out: &mut String, p: &hir::Process, indent: &str| {
        out.push_str(&format!(
            "{indent}\"{}\" [shape={}, label=\"{}\\n{} {}\"];\n",
            escape(&p.name),
            shape(p),
            escape(&p.name),
            p.kind_name(),
            escape(&kind_detail(p))
        ));
    };
    match &spec.deploy {
        Some(deploy) => {
            for host in &deploy.hosts {
                out.push_str(&format!(
                    "  subgraph \"cluster_{}\" {{\n    label=\"host {}\";\n",
                    escape(&host.name),
                    escape(&host.name)
                ));
                for id in &host.processes {
                    node(&mut out, &spec.processes[*id], "    ");
                }
                out.push_str("  }\n");
            }
        }
        None => spec.processes.iter().for_each(|p| node(&mut out, p, "  ")),
    }
    for (from, to, edge) in edges(spec) {
        let style = if edge.policy.feedback { ", style=dashed" } else { "" };
        let policy = edge.policy.describe_changes();
        let label = if policy.is_empty() {
            escape(&edge.stream)
        } else {
            format!("{}\\n{}", escape(&edge.stream), escape(&policy))
        };
        out.push_str(&format!(
            "  \"{}\" -> \"{}\" [label=\"{label}\"{style}];\n",
            escape(&spec.processes[from].name),
            escape(&spec.processes[to].name),
        ));
    }
    out.push_str("}\n");
    out
}

fn mermaid(spec: &Spec) -> String {
    let mut out = String::from("flowchart LR\n");
    let id = |p: &hir::Process| format!("p{}", p.id);
    let node = |out: &mut String, p: &hir::Process, indent: &str| {
        let label = format!("{}<br/>{} {}", p.name, p.kind_name(), kind_detail(p)).replace('"', "'");
        let (open, close) = match p.kind {
            hir::ProcessKind::Source(_) => ("[/", "/]"),
            hir::ProcessKind::Sink(_) => ("[\\", "\\]"),
            hir::ProcessKind::Link(_) => ("{{", "}}"),
            hir::ProcessKind::Monitor(_) | hir::ProcessKind::Chronicle(_) => ("{", "}"),
            hir::ProcessKind::Compute(_) => ("[", "]"),
        };
        out.push_str(&format!("{indent}{}{open}\"{label}\"{close}\n", id(p)));
    };
    match &spec.deploy {
        Some(deploy) => {
            for host in &deploy.hosts {
                out.push_str(&format!("  subgraph host_{}[\"host {}\"]\n", host.name, host.name));
                for pid in &host.processes {
                    node(&mut out, &spec.processes[*pid], "    ");
                }
                out.push_str("  end\n");
            }
        }
        None => spec.processes.iter().for_each(|p| node(&mut out, p, "  ")),
    }
    for (from, to, edge) in edges(spec) {
        let arrow = if edge.policy.feedback { "-.->" } else { "-->" };
        let policy = edge.policy.describe_changes();
        let label =
            if policy.is_empty() { edge.stream.clone() } else { format!("{}: {policy}", edge.stream) }
                .replace('"', "'");
        out.push_str(&format!(
            "  {} {arrow}|\"{label}\"| {}\n",
            id(&spec.processes[from]),
            id(&spec.processes[to])
        ));
    }
    out
}

fn json_value(spec: &Spec) -> serde_json::Value {
    let processes: Vec<serde_json::Value> = spec
        .processes
        .iter()
        .map(|p| {
            json!({
                "name": p.name,
                "kind": p.kind_name(),
                "entry": kind_detail(p),
                "output": p.output.as_ref().map(ToString::to_string),
                "host": spec.host_of(p.id),
            })
        })
        .collect();
    let streams: Vec<serde_json::Value> = edges(spec)
        .map(|(from, to, edge)| {
            json!({
                "stream": edge.stream,
                "from": spec.processes[from].name,
                "port": edge.port,
                "to": spec.processes[to].name,
                "input": edge.input,
                "policy": edge.policy,
                "policy_text": edge.policy.describe(),
                "policy_changes": edge.policy.describe_changes(),
            })
        })
        .collect();
    json!({ "processes": processes, "streams": streams })
}
