//! `kpl bench ...`: benchmarks whose figures go to `docs/performance.md`. The workloads live in
//! `kpl-bench` (and the bare-zenoh baseline, with its ROS 2 cases, in `kpl-zenoh`); each reports ratios against a
//! baseline measured in the same run, and nothing here is asserted by a test.

use std::io::Write;
use std::process::ExitCode;

use clap::Subcommand;

#[derive(Debug, Subcommand)]
pub enum Command {
    /// The MTL engine on the ten timed properties of the Timescales benchmark, against R2U2 (in a
    /// `kpl` built with `--features r2u2`), and DyKnow's link conditions.
    Mtl(kpl_bench::mtl::Args),
    /// Hierarchical anchoring of 100 to 10,000 cars at 10 Hz through two link levels.
    Anchor(kpl_bench::anchor::Args),
    /// The in-process runtime against bare tokio channels, and its memory over a long run.
    Runtime(kpl_bench::runtime::Args),
    /// The situation monitors of specs/traffic/sumo_situations.kpl over 100 to 4,000 cars, with and
    /// without gating of pairs.
    Situations(kpl_bench::situations::Args),
    /// The chronicles of the shipped specs (sumo_chronicles, sumo_reckless, sumo_weaving) over 100 to
    /// 2,000 cars, with and without gating of pairs.
    Chronicles(kpl_bench::chronicles::Args),
    /// A call to a trivial Python unit against a trivial Rust unit, for a float and a list of
    /// 1,000 floats, in simulated time.
    Python(kpl_bench::python::Args),
    /// Streams between two processes over zenoh, against bare zenoh publisher/subscriber code.
    Zenoh(crate::transport::BenchArgs),
    /// ROS 2 messages (a PoseStamped, a 100-marker MarkerArray) between two processes through
    /// kpl's ROS 2 path, against bare zenoh sending the same CDR bytes.
    Ros2(crate::transport::Ros2BenchArgs),
}

pub fn run(command: Command) -> ExitCode {
    let mut stdout = std::io::stdout().lock();
    let out: &mut dyn Write = &mut stdout;
    let result = match command {
        Command::Mtl(args) => kpl_bench::mtl::run(&args, out),
        Command::Anchor(args) => kpl_bench::anchor::run(&args, out),
        Command::Runtime(args) => kpl_bench::runtime::run(&args, out),
        Command::Situations(args) => kpl_bench::situations::run(&args, out),
        Command::Chronicles(args) => kpl_bench::chronicles::run(&args, out),
        Command::Python(args) => kpl_bench::python::run(&args, out),
        Command::Zenoh(args) => return crate::transport::bench(args),
        Command::Ros2(args) => return crate::transport::bench_ros2(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            drop(stdout);
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}
