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
    /// Colour diagnostics and logs: on a terminal (auto, unless NO_COLOR is set), always, never.
    #[arg(long, global = true, value_enum, default_value = "auto", value_name = "WHEN")]
    color: report::ColorChoice,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Parse and check specs: names, types, units, policies, links, cycles, deployment.
    Check(cmd::check::Args),
    /// Draw the process graph of a spec (svg, dot, mermaid or json), with streams and policies.
    Graph(cmd::graph::Args),
    /// Explain a diagnostic code (E0101, W0201, ...): what it means, with an example.
    Explain(cmd::explain::Args),
    /// Rewrite specs in the canonical layout, keeping comments.
    Fmt(cmd::fmt::Args),
    /// List the sources, units, sinks, prediction models and functions the runtime provides.
    List(cmd::list::Args),
    /// Run a spec: build its graph of knowledge processes and run it (sim or wall clock).
    Run(cmd::run::Args),
    /// Convert a recording between JSON lines and MCAP, losing nothing.
    Convert(cmd::convert::Args),
    /// Launch every host of a deployed spec on this machine, with one summary.
    Launch(cmd::launch::Args),
    /// Make the keys of a deployment: mutual TLS between its hosts, authenticated messages.
    Keys(cmd::keys::Args),
    /// Score recorded object streams against ground truth: MOTA, IDF1, HOTA, ... per stream.
    Score(cmd::score::Args),
    /// Draw a recorded run as SVG: roads, percepts, anchored objects, ground truth, situations.
    Plot(cmd::plot::Args),
    /// Show recordings in the browser: the map, each level's objects, situations, a time slider.
    View(cmd::view::Args),
    /// Score recognised traffic situations against the true ones of the recorded traffic: precision and recall per kind.
    Situations(cmd::situations::Args),
    /// Sample CATER-style videos and score snitch localisation (LA-CATER layout).
    #[command(
        subcommand,
        after_help = "Examples:\n  kpl cater generate --videos 20 --seed 1 --out out/cater\n  kpl cater eval --data out/cater --model aapa --perception detector"
    )]
    Cater(cmd::cater::Command),
    /// Metric temporal logic: evaluate formulas over traces.
    #[command(
        subcommand,
        after_help = "Examples:\n  kpl mtl eval --formula 'always[0, 10] (p -> eventually[0, 3] q)' --trace specs/mtl/trace.jsonl\n  kpl mtl eval --formula 'p until[0, 5s] q' --trace specs/mtl/trace.jsonl --every"
    )]
    Mtl(cmd::mtl::Command),
    /// Print a shell completion script (bash, zsh, fish, elvish or powershell).
    #[command(
        after_help = "Examples:\n  source <(kpl completions bash)     # bash: put this line in ~/.bashrc\n  kpl completions zsh > _kpl         # zsh: move _kpl into a directory of $fpath\n  kpl completions fish > kpl.fish    # fish: move it to ~/.config/fish/completions/"
    )]
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
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
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(err) => {
            // clap prints help and version to stdout with exit 0, usage errors to stderr with 2.
            let _ = err.print();
            return if err.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    report::set_color(cli.color);
    init_tracing();
    // A reader that stops early (`kpl check | head`, `kpl explain E0101 | less`) ends the command
    // quietly, as it ends cat or grep, instead of a panic in `println!`. Not for the commands that
    // run a deployment: they write their sinks out and report on stderr whatever happens to stdout.
    if !matches!(cli.command, Command::Run(_) | Command::Launch(_)) {
        sigpipe::reset();
    }
    match cli.command {
        Command::Check(args) => cmd::check::run(args),
        Command::Graph(args) => cmd::graph::run(args),
        Command::Explain(args) => cmd::explain::run(args),
        Command::Fmt(args) => cmd::fmt::run(args),
        Command::List(args) => cmd::list::run(args),
        Command::Run(args) => cmd::run::run(args),
        Command::Convert(args) => cmd::convert::run(args),
        Command::Launch(args) => cmd::launch::run(args),
        Command::Keys(args) => cmd::keys::run(args),
        Command::Score(args) => cmd::score::run(args),
        Command::Plot(args) => cmd::plot::run(args),
        Command::View(args) => cmd::view::run(args),
        Command::Situations(args) => cmd::situations::run(args),
        Command::Cater(command) => cmd::cater::run(command),
        Command::Mtl(command) => cmd::mtl::run(command),
        Command::Bench(command) => cmd::bench::run(command),
        Command::Completions { shell } => {
            let mut command = <Cli as clap::CommandFactory>::command();
            clap_complete::generate(shell, &mut command, "kpl", &mut std::io::stdout());
            ExitCode::SUCCESS
        }
    }
}

/// Logs go to stderr; `RUST_LOG` selects what is shown. By default: KPL's warnings, what the hosts
/// of a deployment say about each other (who is up, who is awaited), where a view is served, and only the errors of zenoh's
/// own crates (their warnings, such as a scouting delay, are about zenoh's internals; `kpl-zenoh`
/// reports what a user can act on in its own words).
fn init_tracing() {
    use tracing_subscriber::EnvFilter;
    const DEFAULT: &str = "warn,kpl_zenoh::transport=info,kpl_view=info,zenoh=error,zenoh_transport=error,zenoh_link=error,\
                           zenoh_link_tcp=error,zenoh_link_tls=error,zenoh_config=error,zenoh_runtime=error";
    let ansi = report::colour();
    let builder = tracing_subscriber::fmt().with_ansi(ansi).with_writer(std::io::stderr);
    match EnvFilter::try_from_default_env() {
        // Asked for: the full detail (times, modules), for debugging.
        Ok(filter) => {
            let _ = builder.with_env_filter(filter).try_init();
        }
        // By default, a warning reads as one line of text.
        Err(_) => {
            let filter = EnvFilter::new(DEFAULT);
            let _ = builder.with_env_filter(filter).with_target(false).without_time().try_init();
        }
    }
}
