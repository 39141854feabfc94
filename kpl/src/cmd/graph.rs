//! `kpl graph`: the process graph of a checked spec, with stream names and policies.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args as ClapArgs;
use kpl_semantic::render;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum GraphFormat {
    /// An SVG picture, laid out by kpl itself (no Graphviz needed).
    Svg,
    /// Graphviz dot, for Graphviz's own layouts (`| dot -Tpng > graph.png`).
    Dot,
    /// A Mermaid flowchart (renders in Markdown on most forges).
    Mermaid,
    /// Processes and streams as JSON.
    Json,
}

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl graph specs/traffic/bridge.kpl > bridge.svg\n  kpl graph --format mermaid specs/ok/overview.kpl\n  kpl graph --format json specs/ok/overview.kpl > overview.json\n\nStreams are labelled with their name and the parts of their policy that differ from the\ndefault (`no approximation, any update, any order, queue 1024 block`); --format json has every\npart."
)]
pub struct Args {
    /// The spec file.
    pub file: PathBuf,
    /// Output format.
    #[arg(long, value_enum, default_value = "svg")]
    pub format: GraphFormat,
}

pub fn run(args: Args) -> ExitCode {
    let spec = match super::check::load_checked(&args.file) {
        Ok(spec) => spec,
        Err(code) => return code,
    };
    let format = match args.format {
        GraphFormat::Svg => render::Format::Svg,
        GraphFormat::Dot => render::Format::Dot,
        GraphFormat::Mermaid => render::Format::Mermaid,
        GraphFormat::Json => render::Format::Json,
    };
    let mut stdout = std::io::stdout().lock();
    let _ = std::io::Write::write_all(&mut stdout, render::render(&spec, format).as_bytes());
    ExitCode::SUCCESS
}
