//! `kpl list`: what the runtime provides, with parameters and a one-line description each.

use std::fmt::Write as _;
use std::io::Write;
use std::process::ExitCode;

use clap::Args as ClapArgs;
use kpl_semantic::registry::{EntryKind, Inputs, Registry};

use crate::report::OutputFormat;

#[derive(Debug, ClapArgs)]
#[command(after_help = "Examples:\n  kpl list\n  kpl list --format json > registry.json")]
pub struct Args {
    /// Output format: text, or the registry as JSON ({entries, functions}).
    #[arg(long, value_enum, default_value = "text")]
    pub format: OutputFormat,
    /// The same as `--format json` (kept for scripts written before `--format`).
    #[arg(long, hide = true)]
    pub json: bool,
}

pub fn run(args: Args) -> ExitCode {
    let signatures = crate::registry::signatures();
    let registry = &signatures;
    let text = if args.json || args.format == OutputFormat::Json {
        let entries: Vec<_> = registry.entries().collect();
        let functions: Vec<_> = registry.functions().collect();
        serde_json::to_string_pretty(&serde_json::json!({ "entries": entries, "functions": functions }))
            .unwrap_or_default()
            + "\n"
    } else {
        describe(registry)
    };
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
    ExitCode::SUCCESS
}

pub fn describe(registry: &Registry) -> String {
    let mut out = String::new();
    for kind in EntryKind::ALL {
        let heading = match kind {
            EntryKind::Source => "Sources (`source NAME : TYPE = ...`)",
            EntryKind::Compute => "Computational units (`compute NAME : TYPE = ...`)",
            EntryKind::Link => "Link units (`link NAME : A -> B via ...`)",
            EntryKind::Sink => "Sinks (`sink NAME = ...`)",
            EntryKind::Predict => "Prediction models (`predict TYPE = ...`)",
        };
        let _ = writeln!(out, "{heading}");
        let mut any = false;
        for entry in registry.entries_of(kind) {
            any = true;
            let _ = writeln!(out, "  {:<26} {}", entry.name, entry.summary);
            match &entry.inputs {
                Inputs::Fixed(ports) => {
                    for port in ports {
                        let _ = writeln!(out, "      input {:<18} {} — {}", port.name, port.ty, port.doc);
                    }
                }
                Inputs::Variadic { min, port } => {
                    let _ = writeln!(
                        out,
                        "      inputs {:<17} {} — {} (at least {min})",
                        format!("{}...", port.name),
                        port.ty,
                        port.doc
                    );
                }
            }
            if !matches!(entry.output, kpl_semantic::registry::TypeReq::Any) {
                let label =
                    if kind == EntryKind::Link || kind == EntryKind::Predict { "objects" } else { "output" };
                let _ = writeln!(out, "      {label:<24} {}", entry.output);
            }
            for port in &entry.ports {
                let _ = writeln!(out, "      output .{:<16} {} — {}", port.name, port.ty, port.doc);
            }
            for param in &entry.params {
                let default =
                    param.default.as_ref().map_or("required".to_string(), |d| format!("default {d}"));
                let _ = writeln!(out, "      {:<24} {} ({default}) — {}", param.name, param.ty, param.doc);
            }
            if let kpl_semantic::registry::Computes::Attributes { names, copies_shared } = &entry.computes {
                let mut sets = names.join(", ");
                if *copies_shared {
                    sets = if sets.is_empty() {
                        "what the linked-from object also has".to_string()
                    } else {
                        format!("{sets}, and what the linked-from object also has")
                    };
                }
                let _ = writeln!(out, "      {:<24} {sets}", "sets");
            }
            for function in &entry.provides {
                let _ = writeln!(out, "      provides {:<15} — {}", function.signature(), function.summary);
            }
        }
        if !any {
            let _ = writeln!(out, "  (none)");
        }
        let _ = writeln!(out);
    }
    let _ = writeln!(out, "Functions (in formulas)");
    for function in registry.functions() {
        let _ = writeln!(out, "  {:<34} {}", function.signature(), function.summary);
    }
    out
}
