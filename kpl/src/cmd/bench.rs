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

/// A clock of the CPU time the calling thread has used: what a single-threaded benchmark costs,
/// unmoved by other processes on a shared machine (which only delay it). On Unix it is
/// `CLOCK_THREAD_CPUTIME_ID`; elsewhere the wall clock.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CpuClock {
    #[cfg(unix)]
    start: rustix::time::Timespec,
    #[cfg(not(unix))]
    start: std::time::Instant,
}

impl CpuClock {
    pub fn start() -> CpuClock {
        #[cfg(unix)]
        let start = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
        #[cfg(not(unix))]
        let start = std::time::Instant::now();
        CpuClock { start }
    }

    /// Seconds since [`CpuClock::start`].
    pub fn seconds(&self) -> f64 {
        #[cfg(unix)]
        {
            let now = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
            (now.tv_sec - self.start.tv_sec) as f64 + (now.tv_nsec - self.start.tv_nsec) as f64 * 1e-9
        }
        #[cfg(not(unix))]
        {
            self.start.elapsed().as_secs_f64()
        }
    }

    /// What the clock measures, for the benchmarks' headers.
    pub fn name() -> &'static str {
        if cfg!(unix) { "thread CPU time" } else { "wall-clock time" }
    }
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
