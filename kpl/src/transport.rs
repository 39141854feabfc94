//! Streams between hosts (`kpl run --host`) go over zenoh (`kpl-zenoh`), and `kpl bench zenoh`
//! measures them against bare zenoh code.
//!
//! The session of a host is configured by the deploy section and these environment variables:
//! `KPL_ZENOH_CONFIG` (a zenoh configuration file to start from: TLS, access control),
//! `KPL_ZENOH_PORT_BASE` (the first port of the loopback defaults, 7447), `KPL_ZENOH_WAIT`
//! (seconds a host waits for the others, 30) and `KPL_KEYS` (the deployment's keys folder).

use std::process::ExitCode;

use kpl_zenoh::bench::{self, BenchOptions, Implementation, Payload, PeerTask};

/// The transport `kpl run --host` uses, with the deployment's keys folder when given (`--keys`,
/// over `KPL_KEYS`), else keys made on first use, or none with `--insecure`. It opens a zenoh session only when a host sends or receives streams; a run
/// without `--host` never does.
pub fn factory(
    keys: Option<&std::path::Path>,
    insecure: bool,
) -> Option<Box<dyn kpl_runtime::run::TransportFactory>> {
    let sessions = kpl_zenoh::Sessions::process();
    if let Some(keys) = keys {
        sessions.configure(|options| options.keys = Some(keys.to_path_buf()));
    }
    if insecure {
        sessions.configure(|options| {
            options.keys = None;
            options.insecure = true;
        });
    }
    Some(Box::new(kpl_zenoh::ZenohFactory::new(sessions)))
}

#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum ValueArg {
    String,
    Floats,
}

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Two processes on 127.0.0.1: this one and a copy of it it starts. For each size, bare zenoh\npublisher/subscriber code and KPL's transport (typed samples, encoded and decoded) send the same\npayloads, interleaved; figures are medians over --repeat runs. Throughput: samples/s at the\nreceiver. Latency: ping-pong round trips, p50 and p99.\n\nExample:\n  cargo run --release -p kpl -- bench zenoh\n  cargo run --release -p kpl -- bench zenoh --sizes 64 --messages 50000 --repeat 1\n  cargo run --release -p kpl -- bench zenoh --value floats"
)]
pub struct BenchArgs {
    /// Payload sizes in bytes (a KPL sample carries a string of this size).
    #[arg(long, value_delimiter = ',', default_values_t = [64usize, 4096])]
    sizes: Vec<usize>,
    /// Samples per throughput run of 64-byte payloads (larger ones send proportionally fewer,
    /// at least an eighth as many).
    #[arg(long, default_value_t = 1_000_000)]
    messages: usize,
    /// Round trips per latency run (after a tenth as many to warm up).
    #[arg(long, default_value_t = 5_000)]
    round_trips: usize,
    /// Runs of each case; the figures are medians.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// What a KPL sample carries: a string of SIZE bytes, or a list of SIZE/8 floats.
    #[arg(long, value_enum, default_value = "string")]
    value: ValueArg,
    /// Output format: a table, or the report as JSON.
    #[arg(long, value_enum, default_value = "text")]
    format: crate::report::OutputFormat,
    /// The same as `--format json` (kept for scripts written before `--format`).
    #[arg(long, hide = true)]
    json: bool,
    /// Run as the other process of the benchmark (a task in JSON; started by `kpl bench zenoh`).
    #[arg(long, hide = true)]
    peer: Option<String>,
}

pub fn bench(args: BenchArgs) -> ExitCode {
    if let Some(task) = &args.peer {
        return peer(task);
    }
    let exe = match own_exe() {
        Ok(exe) => exe,
        Err(code) => return code,
    };
    let options = BenchOptions {
        sizes: args.sizes.clone(),
        messages: args.messages.max(2),
        round_trips: args.round_trips.max(1),
        repeat: args.repeat.max(1),
        payload: match args.value {
            ValueArg::String => Payload::String,
            ValueArg::Floats => Payload::Floats,
        },
    };
    let make_peer = |task: &str| {
        let mut command = std::process::Command::new(&exe);
        command.args(["bench", "zenoh", "--peer", task]);
        command
    };
    let report = match bench::run(&options, &make_peer) {
        Ok(report) => report,
        Err(err) => {
            eprintln!("error: {err}");
            return ExitCode::from(1);
        }
    };
    if args.json || args.format == crate::report::OutputFormat::Json {
        match serde_json::to_string_pretty(&report) {
            Ok(json) => println!("{json}"),
            Err(err) => eprintln!("error: {err}"),
        }
        return ExitCode::SUCCESS;
    }
    println!(
        "zenoh, two processes on 127.0.0.1, KPL samples carrying {}: {} samples per throughput run of 64 B, {} round trips, median of {} run(s)",
        match report.payload {
            Payload::String => "a string of SIZE bytes",
            Payload::Floats => "a list of SIZE/8 floats",
            Payload::PoseStamped | Payload::MarkerArray => "a ROS 2 message (kpl bench ros2)",
        },
        report.messages,
        report.round_trips,
        report.repeat
    );
    println!(
        "{:>7}  {:<5} {:>12} {:>10} {:>16} {:>16} {:>6}",
        "size", "code", "samples/s", "MB/s", "round trip p50", "round trip p99", "lost"
    );
    for case in &report.cases {
        let code = match case.implementation {
            Implementation::Bare => "bare",
            Implementation::Kpl => "kpl",
        };
        println!(
            "{:>5} B  {:<5} {:>12.0} {:>10.1} {:>13.1} us {:>13.1} us {:>6}",
            case.size,
            code,
            case.samples_per_s,
            case.samples_per_s * case.size as f64 / 1e6,
            case.round_trip_p50_us,
            case.round_trip_p99_us,
            case.lost
        );
    }
    println!("kpl / bare, median [min - max] over the runs:");
    for r in &report.ratios {
        let spread = |s: &bench::Spread| format!("{:.2} [{:.2} - {:.2}]", s.median, s.min, s.max);
        println!(
            "{:>5} B  throughput {} (target >= 0.7)   round trip p50 {} (target <= 1.5)   p99 {}",
            r.size,
            spread(&r.throughput),
            spread(&r.round_trip_p50),
            spread(&r.round_trip_p99)
        );
    }
    ExitCode::SUCCESS
}

/// The other process of the benchmark: does its task and prints its report as one JSON line.
fn peer(task: &str) -> ExitCode {
    let task: PeerTask = match serde_json::from_str(task) {
        Ok(task) => task,
        Err(err) => {
            eprintln!("error: --peer: {err}");
            return ExitCode::from(2);
        }
    };
    match bench::run_peer(&task)
        .and_then(|r| serde_json::to_string(&r).map_err(std::io::Error::from).map_err(Into::into))
    {
        Ok(line) => {
            println!("{line}");
            ExitCode::SUCCESS
        }
        Err(err) => {
            eprintln!("error: {err}");
            ExitCode::from(1)
        }
    }
}

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Two processes on 127.0.0.1: this one and a copy of it it starts. For a geometry_msgs/msg/PoseStamped\nand a visualization_msgs/msg/MarkerArray of 100 markers, bare zenoh sends the message's CDR bytes and\nkpl sends KPL values through its ROS 2 path (ros2.publish and ros2.subscribe: mapping, CDR, rmw_zenoh's\nkeys, attachment and liveliness tokens), interleaved; figures are medians over --repeat runs.\nThroughput: messages/s at the receiver. Latency: ping-pong round trips (the other process decodes the\nmessage into a KPL value and publishes it back), p50 and p99.\n\nExample:\n  cargo run --release -p kpl -- bench ros2\n  cargo run --release -p kpl -- bench ros2 --quick"
)]
pub struct Ros2BenchArgs {
    /// Messages per throughput run of a PoseStamped (the MarkerArray sends proportionally fewer
    /// by size, at least an eighth as many).
    #[arg(long, default_value_t = 100_000)]
    messages: usize,
    /// Round trips per latency run (after a tenth as many to warm up).
    #[arg(long, default_value_t = 2_000)]
    round_trips: usize,
    /// Runs of each case; the figures are medians.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// A short run (1,000 messages, 100 round trips, one run): that everything arrives, not a
    /// measurement.
    #[arg(long)]
    quick: bool,
    /// Output format: a table, or the reports as JSON.
    #[arg(long, value_enum, default_value = "text")]
    format: crate::report::OutputFormat,
    /// Run as the other process of the benchmark (a task in JSON; started by `kpl bench ros2`).
    #[arg(long, hide = true)]
    peer: Option<String>,
}

/// `kpl bench ros2`: the targets are a throughput of at least 0.8 of bare zenoh's and a
/// round-trip p50 of at most 1.2 times.
pub fn bench_ros2(args: Ros2BenchArgs) -> ExitCode {
    if let Some(task) = &args.peer {
        return peer(task);
    }
    let exe = match own_exe() {
        Ok(exe) => exe,
        Err(code) => return code,
    };
    let make_peer = |task: &str| {
        let mut command = std::process::Command::new(&exe);
        command.args(["bench", "ros2", "--peer", task]);
        command
    };
    let (messages, round_trips, repeat) = if args.quick {
        (1_000, 100, 1)
    } else {
        (args.messages.max(2), args.round_trips.max(1), args.repeat.max(1))
    };
    let mut reports = Vec::new();
    for payload in [Payload::PoseStamped, Payload::MarkerArray] {
        let size = match payload.size(0) {
            Ok(size) => size,
            Err(err) => {
                eprintln!("error: {err}");
                return ExitCode::from(1);
            }
        };
        let options = BenchOptions { sizes: vec![size], messages, round_trips, repeat, payload };
        match bench::run(&options, &make_peer) {
            Ok(report) => reports.push(report),
            Err(err) => {
                eprintln!("error: {err}");
                return ExitCode::from(1);
            }
        }
    }
    if args.format == crate::report::OutputFormat::Json {
        match serde_json::to_string_pretty(&reports) {
            Ok(json) => println!("{json}"),
            Err(err) => eprintln!("error: {err}"),
        }
        return ExitCode::SUCCESS;
    }
    println!(
        "ROS 2 over zenoh, two processes on 127.0.0.1: kpl's ROS 2 path against bare zenoh sending the same CDR bytes; {messages} PoseStamped per throughput run, {round_trips} round trips, median of {repeat} run(s)"
    );
    println!(
        "{:<13} {:>8}  {:<5} {:>10} {:>10} {:>16} {:>16} {:>9} {:>6}",
        "message", "CDR", "code", "messages", "msg/s", "round trip p50", "round trip p99", "received", "lost"
    );
    for report in &reports {
        let name = match report.payload {
            Payload::MarkerArray => "MarkerArray",
            _ => "PoseStamped",
        };
        for case in &report.cases {
            let code = match case.implementation {
                Implementation::Bare => "bare",
                Implementation::Kpl => "kpl",
            };
            let sent = bench::messages_for(report.messages, case.size) * report.repeat;
            println!(
                "{name:<13} {:>6} B  {code:<5} {sent:>10} {:>10.0} {:>13.1} us {:>13.1} us {:>9} {:>6}",
                case.size,
                case.samples_per_s,
                case.round_trip_p50_us,
                case.round_trip_p99_us,
                sent - case.lost.min(sent),
                case.lost
            );
        }
    }
    println!("kpl / bare, median [min - max] over the runs:");
    for report in &reports {
        let name = match report.payload {
            Payload::MarkerArray => "MarkerArray",
            _ => "PoseStamped",
        };
        for r in &report.ratios {
            let spread = |s: &bench::Spread| format!("{:.2} [{:.2} - {:.2}]", s.median, s.min, s.max);
            println!(
                "{name:<13} throughput {} (target >= 0.8)   round trip p50 {} (target <= 1.2)   p99 {}",
                spread(&r.throughput),
                spread(&r.round_trip_p50),
                spread(&r.round_trip_p99)
            );
        }
    }
    ExitCode::SUCCESS
}

/// This `kpl` executable, which a benchmark starts again as its other process.
fn own_exe() -> Result<std::path::PathBuf, ExitCode> {
    std::env::current_exe().map_err(|err| {
        eprintln!("error: cannot find the kpl executable to start the other process: {err}");
        ExitCode::from(2)
    })
}
