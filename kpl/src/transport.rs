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
    let exe = match std::env::current_exe() {
        Ok(exe) => exe,
        Err(err) => {
            eprintln!("error: cannot find the kpl executable to start the other process: {err}");
            return ExitCode::from(2);
        }
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
