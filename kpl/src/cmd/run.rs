//! `kpl run`: check a spec, build its graph of knowledge processes and run it.

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime};

use clap::Args as ClapArgs;
use kpl_core::Time;
use kpl_runtime::run::Signal;
use kpl_runtime::stats::RunStats;
use kpl_runtime::{ClockKind, Ending, RunConfig, RunReport};

use crate::report;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ClockArg {
    /// Simulated time, as fast as the work allows; reproducible with a fixed --seed.
    Sim,
    /// Real time.
    Wall,
}

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl run specs/traffic/bridge.kpl --for 60s\n  kpl run specs/ok/ticks.kpl --clock wall --for 5s --out out/run\n  kpl run specs/zenoh/endless.kpl --host producer --clock wall --for 3s   # one host only\n  kpl run specs/ok/tracker.kpl --clock wall --for 5s --view 127.0.0.1:0 --foxglove 127.0.0.1:0\n\nOutputs of file sinks go under --out (default out/SPEC); the files written are listed at the end,\nwith what the processes achieved (objects anchored, symbols kept across gaps) and a summary per\nstream (produced, delivered, dropped by reason, policy violations), also written to summary.json\nthere (docs/runtime.md describes it field by field). While it runs, a progress line counts the\nsamples of every stream. Ctrl-C and SIGTERM stop the run alike, cleanly: sinks are flushed,\nthe summary is printed.\nExit status: 0 done, 1 the spec has errors or a process failed, 2 usage or I/O errors,\n3 an input from another host was cut short (its host lost) or nothing arrived from another host,\n130 Ctrl-C, 143 SIGTERM."
)]
pub struct Args {
    /// The spec to run.
    pub spec: PathBuf,
    /// Run only the processes the deploy section places on this host; streams to and from other
    /// hosts go over zenoh.
    #[arg(long)]
    pub host: Option<String>,
    /// The deployment's name (default: the spec's `deploy NAME`, else `default`); hosts of
    /// different deployments never exchange samples.
    #[arg(long, requires = "host")]
    pub deployment: Option<String>,
    /// The deployment's keys folder (made by `kpl keys`): mutual TLS between the hosts, access
    /// control, authenticated messages. Also KPL_KEYS.
    #[arg(long, requires = "host")]
    pub keys: Option<PathBuf>,
    /// Run this host without keys: no authentication between the hosts (anyone who reaches a
    /// host's port can send it samples, end its streams or pretend to be a host). Without --keys
    /// and without this, the deployment's keys are made on first use and every message is
    /// authenticated.
    #[arg(long, requires = "host", conflicts_with = "keys")]
    pub insecure: bool,
    /// The zenoh router (or peer) that the spec's ROS 2 topics (`ros2.subscribe`,
    /// `ros2.publish`) go through, over the spec's `router` (default: rmw_zenoh's,
    /// tcp/localhost:7447).
    #[arg(long = "ros2-router", value_name = "ENDPOINT")]
    pub ros2_router: Option<String>,
    /// Which clock drives the run.
    #[arg(long, value_enum, default_value = "sim")]
    pub clock: ClockArg,
    /// Stop after this much (simulated or wall) time, e.g. 60s, 500ms, 2min; a replay of dated
    /// stamps (a rosbag2 bag) counts it from its first stamp.
    #[arg(long = "for", value_parser = parse_duration)]
    pub duration: Option<Time>,
    /// Seed of every random process (mixed with each process's name and its own `seed`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Directory for the outputs of file sinks and summary.json (default: out/SPEC).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Stop at the first malformed input instead of counting it and going on.
    #[arg(long)]
    pub strict: bool,
    /// No progress line and no summary table.
    #[arg(long, short)]
    pub quiet: bool,
    /// How to print the end-of-run summary: a table on stderr, or summary.json's content on
    /// stdout.
    #[arg(long, value_enum, default_value = "text")]
    pub format: report::OutputFormat,
    /// Show the run in a browser while it goes: serve the page at HOST:PORT (port 0: any free
    /// one); the address is printed (docs/view.md).
    #[arg(long, value_name = "HOST:PORT")]
    pub view: Option<String>,
    /// Serve the run to Foxglove while it goes: its WebSocket protocol at HOST:PORT, Foxglove's
    /// schemas, the run's clock as its time (docs/view.md).
    #[arg(long, value_name = "HOST:PORT")]
    pub foxglove: Option<String>,
    /// With --foxglove: before the first sample, wait this long at most for a client to
    /// subscribe to every stream (so it misses nothing).
    #[arg(long, value_parser = parse_duration, requires = "foxglove")]
    pub foxglove_wait: Option<Time>,
    /// The Python interpreter of the spec's Python units (`python.unit`), over the spec's
    /// `python:` and the active virtual environment's (docs/python.md).
    #[arg(long, value_name = "PATH")]
    pub python: Option<PathBuf>,
}

/// Whether a source, unit or sink of the spec calls an entry that `wanted` names (so that an
/// option for those entries, `--python` or `--ros2-router`, does something).
fn calls(spec: &kpl_semantic::hir::Spec, wanted: impl Fn(&str) -> bool) -> bool {
    use kpl_semantic::hir::ProcessKind;
    spec.processes.iter().any(|p| match &p.kind {
        ProcessKind::Source(call) | ProcessKind::Compute(call) | ProcessKind::Sink(call) => {
            wanted(&call.entry)
        }
        _ => false,
    })
}

/// A duration as `--for` takes it (`60s`, `1.5min`, `250ms`).
pub(crate) use kpl_core::parse_duration;

pub fn run(args: Args) -> ExitCode {
    let mut spec = match super::check::load_checked(&args.spec) {
        Ok(spec) => spec,
        Err(code) => return code,
    };
    if args.view.is_some() || args.foxglove.is_some() {
        let options = super::view::LiveOptions {
            http: args.view.clone(),
            foxglove: args.foxglove.clone(),
            wait: args.foxglove_wait,
        };
        spec = match super::view::attach(&args.spec, &spec, args.host.as_deref(), &options) {
            Ok(spec) => spec,
            Err(code) => return code,
        };
    }

    if let Some(host) = &args.host
        && let Err(message) = check_host(&spec, host)
    {
        eprintln!("error: --host {host}: {message}");
        return ExitCode::from(2);
    }
    let stem = args.spec.file_stem().map_or_else(|| "spec".to_string(), |s| s.to_string_lossy().into_owned());
    let out_dir = args.out.clone().unwrap_or_else(|| PathBuf::from("out").join(&stem));
    if let Err(err) = std::fs::create_dir_all(&out_dir) {
        report::io_error(&out_dir, &err);
        return ExitCode::from(2);
    }
    let config = RunConfig {
        clock: match args.clock {
            ClockArg::Sim => ClockKind::Sim,
            ClockArg::Wall => ClockKind::Wall,
        },
        duration: args.duration,
        seed: args.seed,
        out_dir: out_dir.clone(),
        spec_dir: args.spec.parent().map(PathBuf::from).unwrap_or_default(),
        spec_name: stem,
        strict: args.strict,
        host: args.host.clone(),
        deployment: args.deployment.clone(),
        stats: Some(Arc::new(RunStats::default())),
    };
    if args.deployment.as_deref() == Some("") {
        eprintln!("error: --deployment needs a name");
        return ExitCode::from(2);
    }
    if args.host.is_some()
        && config.clock == ClockKind::Sim
        && spec.deploy.as_ref().is_some_and(|d| d.hosts.len() > 1)
    {
        eprintln!(
            "error: --host runs one host of several; simulated time cannot be shared between processes, use --clock wall"
        );
        return ExitCode::from(2);
    }
    if args.ros2_router.is_some() && !calls(&spec, |entry| entry.starts_with("ros2.")) {
        eprintln!(
            "warning: --ros2-router has no effect: the spec has no ROS 2 topic (ros2.subscribe, ros2.publish)"
        );
    }
    kpl_zenoh::ros2::set_router(args.ros2_router.clone());
    if args.python.is_some() && !calls(&spec, |entry| entry == kpl_std::python::ENTRY) {
        eprintln!("warning: --python has no effect: the spec has no Python unit (python.unit)");
    }
    let mut registry = crate::registry::registry();
    *registry.extension_mut::<kpl_std::python::RunOptions>() =
        kpl_std::python::RunOptions { python: args.python.clone(), spec_file: Some(args.spec.clone()) };
    if args.insecure {
        eprintln!(
            "warning: host `{}` runs without keys (--insecure): any program that reaches its port can send it \
             samples, end its streams or pretend to be a host of the deployment",
            args.host.as_deref().unwrap_or_default()
        );
    }
    let transport = crate::transport::factory(args.keys.as_deref(), args.insecure);
    #[allow(clippy::disallowed_methods)] // when the command started, for summary.json (not a sample's time)
    let started = SystemTime::now();
    let progress = (!args.quiet).then(|| {
        let stats = config.stats.clone().unwrap_or_default();
        Progress::start(stats, config.clock, args.duration.is_some())
    });
    let result = kpl_runtime::run(&spec, &registry, &config, transport.as_deref());
    if let Some(progress) = progress {
        progress.finish();
    }
    let report = match result {
        Ok(report) => report,
        Err(err) => {
            eprintln!("error: {err}");
            return ExitCode::from(1);
        }
    };
    let summary_path = out_dir.join("summary.json");
    let json = serde_json::to_string_pretty(&report).unwrap_or_default() + "\n";
    if let Err(err) = std::fs::write(&summary_path, &json) {
        eprintln!("error: cannot write {}: {err}", summary_path.display());
    }
    if args.format == report::OutputFormat::Json {
        let _ = std::io::stdout().lock().write_all(json.as_bytes());
    } else if !args.quiet {
        let mut text = describe(&report, config.clock);
        text.push_str(&results(&report));
        text.push_str(&outputs(&out_dir, started));
        let _ = std::io::stderr().lock().write_all(text.as_bytes());
    } else {
        // Quiet, but an exit status 3 says why.
        for incomplete in report.incomplete() {
            eprintln!("incomplete: {incomplete}");
        }
    }
    // Warnings are printed even with --quiet: each says why a run may not have done what the spec
    // meant (a replay filter matching nothing gives an empty source).
    for p in &report.summary.processes {
        for warning in &p.warnings {
            eprintln!("warning: {}: {warning}", p.process);
        }
    }
    exit_code(&report)
}

/// The exit status of a run (documented in `--help` and docs/runtime.md).
fn exit_code(report: &RunReport) -> ExitCode {
    match report.ending {
        Ending::Interrupted if report.signal == Some(Signal::Terminate) => ExitCode::from(143),
        Ending::Interrupted => ExitCode::from(130),
        Ending::Strict | Ending::UnitStopped => ExitCode::from(1),
        _ if !report.failures.is_empty() => ExitCode::from(1),
        _ if !report.incomplete().is_empty() => ExitCode::from(3),
        _ => ExitCode::SUCCESS,
    }
}

/// Whether `--host` names a host of the spec's deploy section (else: what to say).
fn check_host(spec: &kpl_semantic::hir::Spec, host: &str) -> Result<(), String> {
    let Some(deploy) = &spec.deploy else {
        return Err("the spec has no deploy section; run it without --host".into());
    };
    if deploy.hosts.iter().any(|h| h.name == host) {
        return Ok(());
    }
    let names: Vec<String> = deploy.hosts.iter().map(|h| format!("`{}`", h.name)).collect();
    Err(format!("the spec's deploy section has no such host; its hosts are {}", names.join(", ")))
}

/// What the processes achieved (`results` of each process in the summary), one line each.
fn results(report: &RunReport) -> String {
    let mut out = String::new();
    for p in report.summary.processes.iter().filter(|p| !p.results.is_empty()) {
        let parts: Vec<String> = p.results.iter().map(|o| format!("{} {}", o.count, o.what)).collect();
        if out.is_empty() {
            out.push_str("result:\n");
        }
        let _ = writeln!(out, "  {}: {}", p.process, parts.join(", "));
    }
    out
}

/// The files under `dir` written since `since`, with their sizes.
fn outputs(dir: &Path, since: SystemTime) -> String {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for entry in entries.flatten() {
            let path = entry.path();
            let Ok(meta) = entry.metadata() else { continue };
            if meta.is_dir() {
                stack.push(path);
            } else if meta.modified().is_ok_and(|m| m >= since) {
                files.push((path, meta.len()));
            }
        }
    }
    files.sort();
    let mut out = format!("outputs in {}:\n", dir.display());
    for (path, len) in &files {
        let name = path.strip_prefix(dir).unwrap_or(path);
        let _ = writeln!(out, "  {:<30} {}", name.display(), size(*len));
    }
    out
}

fn size(bytes: u64) -> String {
    match bytes {
        0..1_000 => format!("{bytes} B"),
        1_000..1_000_000 => format!("{:.1} kB", bytes as f64 / 1e3),
        _ => format!("{:.1} MB", bytes as f64 / 1e6),
    }
}

/// The progress line: clock and wall time and the samples of every stream, once a second on
/// stderr (rewritten in place on a terminal), from its own thread so that a simulated run is not
/// disturbed. First, if a source never ends and there is no `--for`, it says so.
struct Progress {
    done: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Progress {
    #[allow(clippy::disallowed_methods)] // the progress line shows the wall time the command has run
    fn start(stats: Arc<RunStats>, clock: ClockKind, bounded: bool) -> Progress {
        let done = Arc::new(AtomicBool::new(false));
        let flag = done.clone();
        let terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
        let thread = std::thread::spawn(move || {
            let start = Instant::now();
            let (mut last_count, mut last_tick) = (0u64, Instant::now());
            let mut told_endless = bounded;
            let mut shown = false;
            while !flag.load(Ordering::Relaxed) {
                std::thread::sleep(Duration::from_millis(50));
                if !told_endless && let Some(endless) = stats.endless.lock().ok().and_then(|e| e.clone()) {
                    told_endless = true;
                    if !endless.is_empty() {
                        let names: Vec<String> = endless.iter().map(|n| format!("`{n}`")).collect();
                        eprintln!(
                            "note: this run does not end by itself ({} never ends): stop it with Ctrl-C, or give --for",
                            names.join(", ")
                        );
                    }
                }
                if last_tick.elapsed() < Duration::from_secs(1) {
                    continue;
                }
                let count = stats.samples.load(Ordering::Relaxed);
                let rate = (count - last_count) as f64 / last_tick.elapsed().as_secs_f64();
                (last_count, last_tick) = (count, Instant::now());
                let wall = start.elapsed().as_secs_f64();
                let time = match clock {
                    ClockKind::Sim => {
                        // From the first sample: a replay's clock jumps to its first stamp.
                        let now = stats
                            .span_to(stats.now.load(Ordering::Relaxed), stats.start.load(Ordering::Relaxed));
                        format!("sim {:.1}s  wall {wall:.1}s", now.max(0) as f64 / 1e6)
                    }
                    ClockKind::Wall => format!("{wall:.1}s"),
                };
                let line = format!("{time}  {rate:.0} samples/s  ({count} samples, every stream)");
                if terminal {
                    eprint!("\r\x1b[2K{line}");
                    shown = true;
                } else {
                    eprintln!("{line}");
                }
            }
            if shown {
                eprint!("\r\x1b[2K");
            }
        });
        Progress { done, thread: Some(thread) }
    }

    fn finish(mut self) {
        self.done.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// How much clock time the run covered. Simulated time counts from the first sample (a replay's
/// clock jumps to its first stamp, which may be a date: then the span says from when).
fn clock_span(report: &RunReport, clock: ClockKind) -> String {
    let first = match (clock, report.first_sample) {
        (ClockKind::Sim, Some(first)) if first >= kpl_runtime::stats::DATES => first,
        (ClockKind::Sim, _) => return format!("{:.3} s simulated time", report.clock_elapsed as f64 / 1e6),
        (ClockKind::Wall, _) => return format!("{:.3} s clock time", report.clock_elapsed as f64 / 1e6),
    };
    let span = (report.clock_elapsed - first).max(0) as f64 / 1e6;
    let at = std::time::UNIX_EPOCH + Duration::from_micros(first.unsigned_abs());
    format!("{span:.3} s simulated time from {} (the first sample)", humantime::format_rfc3339_millis(at))
}

/// The end-of-run summary as a table.
fn describe(report: &RunReport, clock: ClockKind) -> String {
    let mut out = String::new();
    let how = match report.ending {
        Ending::SourcesEnded => "every source ended",
        Ending::DurationReached => "--for reached",
        Ending::Interrupted => match report.signal {
            Some(Signal::Terminate) => "interrupted by SIGTERM",
            _ => "interrupted by Ctrl-C",
        },
        Ending::Strict => "stopped at a malformed input (--strict)",
        Ending::UnitStopped => "stopped: a unit failed whose policy is to stop the run",
    };
    let _ = writeln!(
        out,
        "run ended ({how}) after {}, {:.3} s wall",
        clock_span(report, clock),
        report.wall_elapsed as f64 / 1e6
    );
    let width = report
        .summary
        .streams
        .iter()
        .map(|s| s.stream.len() + s.consumer.len() + 4)
        .max()
        .unwrap_or(10)
        .max(18);
    let _ = writeln!(
        out,
        "{:<width$} {:>10} {:>10} {:>10} {:>10}  dropped",
        "stream -> consumer", "produced", "delivered", "approx.", "violations"
    );
    for s in &report.summary.streams {
        let dropped: Vec<String> = s.dropped.iter().map(|(r, n)| format!("{r} {n}")).collect();
        let _ = writeln!(
            out,
            "{:<width$} {:>10} {:>10} {:>10} {:>10}  {}",
            format!("{} -> {}", s.stream, s.consumer),
            s.produced,
            s.delivered,
            s.approximated,
            s.policy_violations,
            if dropped.is_empty() { "-".to_string() } else { dropped.join(", ") }
        );
    }
    for p in &report.summary.processes {
        let mut parts = Vec::new();
        if p.malformed > 0 {
            parts.push(format!("{} malformed input(s)", p.malformed));
        }
        if p.errors > 0 {
            parts.push(format!("{} error(s)", p.errors));
        }
        if p.instances_created > 0 {
            parts.push(format!(
                "{} instance(s) created, {} removed",
                p.instances_created, p.instances_removed
            ));
        }
        if !parts.is_empty() {
            let _ = writeln!(out, "{}: {}", p.process, parts.join("; "));
        }
        for m in &p.malformed_examples {
            let _ = writeln!(out, "  malformed at {}: {}", m.location, m.error);
        }
        for e in &p.error_examples {
            let _ = writeln!(out, "  error: {e}");
        }
    }
    for failure in &report.failures {
        let _ = writeln!(out, "failed: {failure}");
    }
    if let Some(transport) = &report.transport {
        describe_hosts(&mut out, transport);
    }
    for incomplete in report.incomplete() {
        let _ = writeln!(out, "incomplete: {incomplete}");
    }
    out
}

/// Streams between hosts: who came and went, what was lost, refused or cut short.
fn describe_hosts(out: &mut String, transport: &kpl_runtime::transport::TransportReport) {
    let _ = writeln!(out, "host `{}` of deployment `{}`:", transport.host, transport.deployment);
    for h in &transport.hosts {
        let seen = match h.first_seen_s {
            Some(s) => format!("up after {s:.1} s"),
            None => "never seen".to_string(),
        };
        let mut line = format!("  host `{}`: {seen}", h.host);
        if h.lost > 0 {
            let _ = write!(
                line,
                ", went away {} time(s), came back {} time(s), away {:.1} s{}",
                h.lost,
                h.returned,
                h.away_s,
                if h.up_at_end { "" } else { " (away at the end)" }
            );
        }
        let _ = writeln!(out, "{line}");
    }
    for s in &transport.inbound {
        let ending = match &s.ending {
            kpl_runtime::transport::InboundEnding::Open => "open when the run stopped".to_string(),
            kpl_runtime::transport::InboundEnding::End => "ended by its producer".to_string(),
            kpl_runtime::transport::InboundEnding::CutShort(why) => format!("cut short: {why}"),
        };
        let _ = writeln!(
            out,
            "  `{}` from `{}`: {} received, {} lost, {} refused, producer restarted {} time(s); {ending}",
            s.stream, s.from, s.received, s.lost, s.refused, s.producer_restarts
        );
        for r in &s.refused_examples {
            let _ = writeln!(out, "    refused at {}: {}", r.location, r.error);
        }
    }
    for s in &transport.outbound {
        let missed: Vec<String> = s.missed.iter().map(|(h, n)| format!("{n} while `{h}` was away")).collect();
        let _ = writeln!(
            out,
            "  `{}` sent: {} published{}{}",
            s.stream,
            s.published,
            if missed.is_empty() { String::new() } else { format!(", {}", missed.join(", ")) },
            if s.end_not_confirmed.is_empty() {
                String::new()
            } else {
                format!("; the end not confirmed by {}", s.end_not_confirmed.join(", "))
            }
        );
    }
}

#[cfg(test)]
mod tests {
    use super::parse_duration;

    #[test]
    fn durations() {
        assert_eq!(parse_duration("60s"), Ok(60_000_000));
        assert_eq!(parse_duration("1.5min"), Ok(90_000_000));
        assert_eq!(parse_duration("250ms"), Ok(250_000));
        assert!(parse_duration("60").is_err());
        assert!(parse_duration("0s").is_err());
        assert!(parse_duration("-1s").is_err());
    }
}
