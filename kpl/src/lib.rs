//! The `kpl` command: the only crate that prints. It parses arguments, loads files, renders
//! diagnostics and wires the library crates together; each subcommand lives in its own module
//! under `cmd/`.
//!
//! It is also a library, so that a user's crate can build its own `kpl` with its own
//! computational units registered ([`main_with`]; see `examples/custom-unit`):
//!
//! ```no_run
//! fn main() -> std::process::ExitCode {
//!     kpl::main_with(|registry| {
//!         // registry.add_unit(...) for each of the crate's units
//!         let _ = registry;
//!     })
//! }
//! ```

// The binary is the one crate that prints (the lints keep printing out of the libraries).
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cmd;
mod registry;
mod report;
mod transport;

/// KPL: stream-based knowledge processing with hierarchical anchoring.
#[derive(Debug, Parser)]
#[command(name = "kpl", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Parse and check specs: names, types, units, policies, links, cycles, deployment.
    Check(cmd::check::Args),
    /// Draw the process graph of a spec (dot, mermaid or json), with streams and policies.
    Graph(cmd::graph::Args),
    /// Rewrite specs in the canonical layout, keeping comments.
    Fmt(cmd::fmt::Args),
    /// List the sources, units, sinks, prediction models and functions the runtime provides.
    List(cmd::list::Args),
    /// Run a spec: build its graph of knowledge processes and run it (sim or wall clock).
    Run(cmd::run::Args),
    /// Convert a recording between JSON lines and MCAP, losing nothing.
    Convert(cmd::convert::Args),
    /// Score recorded object streams against ground truth: MOTA, IDF1, HOTA, ... per stream.
    Score(cmd::score::Args),
    /// Sample CATER-style videos and score snitch localisation (LA-CATER layout).
    #[command(
        subcommand,
        after_help = "Examples:\n  kpl cater generate --videos 20 --seed 1 --out /tmp/cater\n  kpl cater eval --data /tmp/cater --model aapa --perception detector"
    )]
    Cater(cmd::cater::Command),
    /// Metric temporal logic: evaluate formulas over traces.
    #[command(
        subcommand,
        after_help = "Examples:\n  kpl mtl eval --formula 'always[0, 10] (p -> eventually[0, 3] q)' --trace trace.jsonl\n  kpl mtl eval --formula 'p until[0, 5s] q' --trace trace.jsonl --every"
    )]
    Mtl(cmd::mtl::Command),
    /// Benchmarks whose figures go to docs/performance.md.
    #[command(
        subcommand,
        after_help = "Examples:\n  kpl bench runtime\n  kpl bench anchor\n  kpl bench mtl --states 1000000"
    )]
    Bench(cmd::bench::Command),
}

/// Runs the `kpl` command with extra processes registered by `extend` (user crates add their
/// computational units this way; they are then available to `check`, `list` and `run`).
pub fn main_with(extend: fn(&mut kpl_runtime::Registry)) -> ExitCode {
    registry::extend_with(extend);
    main()
}

/// Runs the `kpl` command.
pub fn main() -> ExitCode {
    init_tracing();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(err) => {
            // clap prints help and version to stdout with exit 0, usage errors to stderr with 2.
            let _ = err.print();
            return if err.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    match cli.command {
        Command::Check(args) => cmd::check::run(args),
        Command::Graph(args) => cmd::graph::run(args),
        Command::Fmt(args) => cmd::fmt::run(args),
        Command::List(args) => cmd::list::run(args),
        Command::Run(args) => cmd::run::run(args),
        Command::Convert(args) => cmd::convert::run(args),
        Command::Score(args) => cmd::score::run(args),
        Command::Cater(command) => cmd::cater::run(command),
        Command::Mtl(command) => cmd::mtl::run(command),
        Command::Bench(command) => cmd::bench::run(command),
    }
}

/// Logs go to stderr; `RUST_LOG` selects what is shown (default: warnings).
fn init_tracing() {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn"));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(ansi)
        .with_writer(std::io::stderr)
        .try_init();
}
