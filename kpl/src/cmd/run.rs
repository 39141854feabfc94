//! `kpl run`: check a spec, build its graph of knowledge processes and run it.

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args as ClapArgs;
use kpl_core::{Time, TimeUnit};
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
    after_help = "Examples:\n  kpl run specs/traffic/bridge.kpl --for 60s\n  kpl run specs/ok/timer.kpl --clock wall --for 5s --out /tmp/run\n  kpl run spec.kpl --host ground --clock wall     # one host of a deployed spec\n\nOutputs of file sinks go under --out (default out/SPEC). A summary per stream (produced,\ndelivered, dropped by reason, policy violations) is printed at the end and written to\nsummary.json there. Ctrl-C stops the run cleanly: sinks are flushed.\nExit status: 0 done, 1 the spec has errors or a process failed, 2 usage or I/O errors, 130 interrupted."
)]
pub struct Args {
    /// The spec to run.
    pub spec: PathBuf,
    /// Run only the processes the deploy section places on this host; streams to and from other
    /// hosts go over zenoh.
    #[arg(long)]
    pub host: Option<String>,
    /// Which clock drives the run.
    #[arg(long, value_enum, default_value = "sim")]
    pub clock: ClockArg,
    /// Stop after this much (simulated or wall) time, e.g. 60s, 500ms, 2min.
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
}

pub(crate) fn parse_duration(text: &str) -> Result<Time, String> {
    let split = text.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(text.len());
    let (number, unit) = text.split_at(split);
    let unit = TimeUnit::from_suffix(unit)
        .ok_or_else(|| format!("`{text}`: write a number and a unit (us, ms, s, min, h), e.g. 60s"))?;
    let value: f64 = number.parse().map_err(|_| format!("`{text}` is not a duration"))?;
    unit.float_to_micros(value)
        .filter(|us| *us > 0)
        .ok_or_else(|| format!("`{text}` is not a positive duration"))
}

pub fn run(args: Args) -> ExitCode {
    let spec = match super::check::load_checked(&args.spec) {
        Ok(spec) => spec,
        Err(code) => return code,
    };

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
        progress: !args.quiet,
    };
    if args.host.is_some()
        && config.clock == ClockKind::Sim
        && spec.deploy.as_ref().is_some_and(|d| d.hosts.len() > 1)
    {
        eprintln!(
            "error: --host runs one host of several; simulated time cannot be shared between processes, use --clock wall"
        );
        return ExitCode::from(2);
    }
    let registry = crate::registry::registry();
    let transport = crate::transport::factory();
    let report = match kpl_runtime::run(&spec, &registry, &config, transport.as_deref()) {
        Ok(report) => report,
        Err(err) => {
            eprintln!("error: {err}");
            return ExitCode::from(1);
        }
    };
    let summary_path = out_dir.join("summary.json");
    if let Ok(json) = serde_json::to_string_pretty(&report) {
        let _ = std::fs::write(&summary_path, json + "\n");
    }
    if !args.quiet {
        let _ = std::io::stderr().lock().write_all(describe(&report, config.clock).as_bytes());
    }
    // Warnings are printed even with --quiet: each says why a run may not have done what the spec
    // meant (a replay filter matching nothing gives an empty source).
    for p in &report.summary.processes {
        for warning in &p.warnings {
            eprintln!("warning: {}: {warning}", p.process);
        }
    }
    match report.ending {
        Ending::Interrupted => ExitCode::from(130),
        Ending::Strict => ExitCode::from(1),
        _ if !report.failures.is_empty() => ExitCode::from(1),
        _ => ExitCode::SUCCESS,
    }
}

/// The end-of-run summary as a table.
fn describe(report: &RunReport, clock: ClockKind) -> String {
    let mut out = String::new();
    let how = match report.ending {
        Ending::SourcesEnded => "every source ended",
        Ending::DurationReached => "--for reached",
        Ending::Interrupted => "interrupted",
        Ending::Strict => "stopped at a malformed input (--strict)",
    };
    let kind = if clock == ClockKind::Sim { "simulated" } else { "clock" };
    let _ = writeln!(
        out,
        "run ended ({how}) after {:.3} s {kind} time, {:.3} s wall",
        report.clock_elapsed as f64 / 1e6,
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
        if parts.is_empty() {
            continue; // only warnings, printed after the summary
        }
        let _ = writeln!(out, "{}: {}", p.process, parts.join("; "));
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
    out
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
