//! `kpl bench ...`: benchmarks whose figures go to `docs/performance.md`. Each reports ratios
//! against a baseline measured in the same run; nothing here is asserted by a test.

use std::process::ExitCode;

use clap::Subcommand;

use crate::cmd::mtl;

#[derive(Debug, Subcommand)]
pub enum Command {
    /// The MTL engine on the ten timed properties of the Timescales benchmark, against R2U2.
    Mtl(mtl::BenchArgs),
    /// Hierarchical anchoring of 100 to 10,000 cars at 10 Hz through two link levels.
    Anchor(crate::cmd::bench_anchor::Args),
    /// The in-process runtime against bare tokio channels, and its memory over a long run.
    Runtime(crate::cmd::bench_runtime::Args),
    /// The situation monitors over 100 to 4,000 cars, with and without gating of pairs.
    Situations(crate::cmd::bench_situations::Args),
    /// Streams between two processes over zenoh, against bare zenoh publisher/subscriber code.
    Zenoh(crate::transport::BenchArgs),
}

pub fn run(command: Command) -> ExitCode {
    match command {
        Command::Mtl(args) => mtl::bench(args),
        Command::Anchor(args) => crate::cmd::bench_anchor::run(args),
        Command::Runtime(args) => crate::cmd::bench_runtime::run(args),
        Command::Situations(args) => crate::cmd::bench_situations::run(args),
        Command::Zenoh(args) => crate::transport::bench(args),
    }
}
