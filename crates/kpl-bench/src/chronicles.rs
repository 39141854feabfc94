//! `kpl bench chronicles`: every chronicle of the shipped specs (`specs/traffic/sumo_chronicles.kpl`,
//! `sumo_reckless.kpl`, `sumo_weaving.kpl`, `sumo_no_passing.kpl`), as the specs write them, over the synthetic traffic of
//! `kpl bench situations` (N cars on a four-lane road at 10 Hz, faster lanes passing slower ones),
//! run on the simulated clock (one thread, so one core): how many cars are recognised faster than
//! real time with the adapter's gating (`crates/kpl-std/src/chronicle.rs`, "Gating") and, as the
//! baseline measured in the same run, without it (every ordered pair evaluated). Both must
//! recognise the same number of chronicles, or the benchmark fails. Times are the CPU time of the
//! runtime's thread (`CpuClock`); the wall time is printed beside it.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use clap::Args as ClapArgs;

use crate::BenchError;
use crate::clock::CpuClock;

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl bench chronicles                         # 100 to 2,000 cars, 30 s of traffic each\n  kpl bench chronicles --cars 1000 --seconds 10 --ungated-up-to 0"
)]
pub struct Args {
    /// Numbers of cars to try (the default: 100, 250, 500, 1000, 2000).
    #[arg(long, value_delimiter = ',')]
    cars: Vec<u32>,
    /// Simulated seconds of traffic per run.
    #[arg(long, default_value_t = 30)]
    seconds: u32,
    /// Largest number of cars also run ungated (every ordered pair evaluated: quadratic).
    #[arg(long, default_value_t = 250)]
    ungated_up_to: u32,
}

/// The shipped specs whose chronicles are measured; the object types come from the first.
pub const SPEC_PATHS: [&str; 4] = [
    "specs/traffic/sumo_chronicles.kpl",
    "specs/traffic/sumo_reckless.kpl",
    "specs/traffic/sumo_weaving.kpl",
    "specs/traffic/sumo_no_passing.kpl",
];
const SHIPPED: [&str; 4] = [
    include_str!("../../../specs/traffic/sumo_chronicles.kpl"),
    include_str!("../../../specs/traffic/sumo_reckless.kpl"),
    include_str!("../../../specs/traffic/sumo_weaving.kpl"),
    include_str!("../../../specs/traffic/sumo_no_passing.kpl"),
];

/// The shipped spec whose object types a run declares: sumo_weaving.kpl's have every attribute
/// the others' have, and the smoothed ones its chronicle reads, but for [`EXTRA_ATTRIBUTE`].
const TYPES_FROM: usize = 2;
/// What sumo_no_passing.kpl's cars declare beyond sumo_weaving.kpl's: added to its
/// `OnRoadObject` after `in_junction` (the synthetic cars never cross a solid line or a junction,
/// so those chronicles' partial instances wait for events that do not come, until their
/// deadlines).
const EXTRA_ATTRIBUTE: (&str, &str) =
    ("in_junction: bool,", "in_junction: bool,\n  crossed_solid_line: bool,");

/// The spec of a run: the object types of [`TYPES_FROM`], every chronicle of the shipped specs
/// (each name once) as written there, over the synthetic cars, and a sink counting the
/// recognitions.
pub fn spec_text(cars: u32, seconds: u32) -> Result<String, String> {
    let (mut types, mut text) = (String::new(), String::new());
    let mut names: Vec<String> = Vec::new();
    for (k, (path, shipped)) in SPEC_PATHS.iter().zip(SHIPPED).enumerate() {
        let parse = kpl_syntax::parse(shipped);
        if parse.has_errors() {
            return Err(format!("{path} does not parse"));
        }
        for item in &parse.spec.items {
            let span = item.span();
            let source = &shipped[span.start as usize..span.end as usize];
            let into = match item {
                kpl_syntax::ast::Item::Type(_) if k == TYPES_FROM => &mut types,
                kpl_syntax::ast::Item::Chronicle(c) if !names.contains(&c.name.name) => {
                    names.push(c.name.name.clone());
                    &mut text
                }
                _ => continue,
            };
            into.push_str(source);
            into.push('\n');
        }
    }
    if !types.contains(EXTRA_ATTRIBUTE.0) {
        return Err(format!("{} has no `{}`", SPEC_PATHS[TYPES_FROM], EXTRA_ATTRIBUTE.0));
    }
    let types = types.replacen(EXTRA_ATTRIBUTE.0, EXTRA_ATTRIBUTE.1, 1);
    let mut text = types + &text;
    if names.is_empty() {
        return Err("the shipped specs have no chronicles".into());
    }
    text.push_str(&format!("source cars : list<Car> = bench.highway(cars: {cars}, seconds: {seconds})\n"));
    text.push_str(&format!("sink out = bench.count({})\n", names.join(", ")));
    Ok(text)
}

/// What one run took: CPU seconds of its thread, wall seconds, the recognitions, and over the
/// chronicles the most partial instances alive at once and those refused (`max_instances`).
struct Timed {
    cpu: f64,
    wall: f64,
    recognitions: u64,
    peak: u64,
    refused: u64,
}

fn run_once(cars: u32, seconds: u32, gated: bool) -> Result<Timed, String> {
    let counted = Arc::new(AtomicU64::new(0));
    let mut registry = crate::situations::registry(counted.clone());
    registry.set_chronicle_processes(move |ctx| kpl_std::chronicle::process(ctx, gated));
    let (cpu, wall, report) = crate::situations::timed_run(&spec_text(cars, seconds)?, &registry)?;
    if let Some(failure) = report.failures.first() {
        return Err(failure.clone());
    }
    let sum = |prefix: &str| -> u64 {
        let results = report.summary.processes.iter().flat_map(|p| &p.results);
        results.filter(|r| r.what.starts_with(prefix)).map(|r| r.count).sum()
    };
    Ok(Timed {
        cpu,
        wall,
        recognitions: counted.load(Ordering::Relaxed),
        peak: sum("partial instances at most"),
        refused: sum("instances refused"),
    })
}

/// Runs the benchmark and writes its table to `out`.
pub fn run(args: &Args, out: &mut dyn Write) -> Result<(), BenchError> {
    let cars = if args.cars.is_empty() { vec![100, 250, 500, 1000, 2000] } else { args.cars.clone() };
    let seconds = args.seconds.max(1);
    writeln!(
        out,
        "chronicles of {}, {seconds} s of traffic at 10 Hz, simulated clock (one thread; {})",
        SPEC_PATHS.join(" and "),
        CpuClock::name()
    )?;
    writeln!(
        out,
        "{:>6} {:>12} {:>10} {:>10} {:>12} {:>10} {:>8} {:>12} {:>10} {:>9}",
        "cars",
        "gated s",
        "x realtime",
        "(wall s)",
        "ungated s",
        "x realtime",
        "ratio",
        "recognised",
        "instances",
        "refused"
    )?;
    let mut largest = None;
    for &n in &cars {
        let gated = run_once(n, seconds, true)?;
        let speed = f64::from(seconds) / gated.cpu;
        if speed > 1.0 {
            largest = Some(n);
        }
        let ungated = if n <= args.ungated_up_to {
            let ungated = run_once(n, seconds, false)?;
            if ungated.recognitions != gated.recognitions {
                return Err(BenchError::Failed(format!(
                    "{n} cars: {} recognitions gated, {} ungated",
                    gated.recognitions, ungated.recognitions
                )));
            }
            Some(ungated.cpu)
        } else {
            None
        };
        let [base, factor, ratio] = crate::situations::baseline_cells(seconds, gated.cpu, ungated);
        writeln!(
            out,
            "{n:>6} {:>12.2} {speed:>10.2} {:>10.2} {base:>12} {factor:>10} {ratio:>8} {:>12} {:>10} {:>9}",
            gated.cpu, gated.wall, gated.recognitions, gated.peak, gated.refused,
        )?;
    }
    match largest {
        Some(n) => writeln!(out, "largest number of cars recognised faster than real time (gated): {n}")?,
        None => writeln!(out, "no number of cars tried was recognised faster than real time")?,
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use std::sync::Mutex;

    use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
    use kpl_runtime::{ClockKind, RunConfig};
    use kpl_semantic::registry::{Entry, EntryKind, TypeReq};

    use super::*;

    /// Every recognition that reaches it, as `stream valid value`.
    struct Collect(Arc<Mutex<Vec<String>>>);

    impl Unit for Collect {
        fn on_input(&mut self, input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
            if let Some((port, sample)) = input.trigger_sample() {
                let line = format!("{} {} {:?}", input.names[port], input.valid, sample.value);
                self.0.lock().unwrap().push(line);
            }
            Ok(())
        }
    }

    fn recognitions(cars: u32, seconds: u32, gated: bool) -> Vec<String> {
        let collected = Arc::new(Mutex::new(Vec::new()));
        let mut registry = crate::situations::registry(Arc::new(AtomicU64::new(0)));
        registry.set_chronicle_processes(move |ctx| kpl_std::chronicle::process(ctx, gated));
        let sink = collected.clone();
        registry.add_unit(
            Entry::new(EntryKind::Sink, "test.collect", "Collects.").variadic(
                1,
                "in",
                TypeReq::Any,
                "anything",
            ),
            move |_| Ok(Box::new(SyncUnit(Collect(sink.clone())))),
        );
        let text = spec_text(cars, seconds).unwrap().replace("bench.count(", "test.collect(");
        let spec = kpl_semantic::check_text(&text, registry.signatures()).unwrap();
        let config = RunConfig { clock: ClockKind::Sim, ..RunConfig::default() };
        let report = kpl_runtime::run(&spec, &registry, &config, None).unwrap();
        assert!(report.failures.is_empty(), "{:?}", report.failures);
        let mut lines = collected.lock().unwrap().clone();
        lines.sort();
        lines
    }

    /// Gating changes what is evaluated, never what is recognised: the same recognitions, line for
    /// line, as evaluating every pair, on traffic where faster lanes keep passing slower ones.
    #[test]
    fn gated_chronicles_recognise_exactly_what_ungated_ones_do() {
        let gated = recognitions(160, 40, true);
        let ungated = recognitions(160, 40, false);
        assert!(gated.len() > 20, "too few recognitions to compare: {}", gated.len());
        assert_eq!(gated, ungated);
    }
}
