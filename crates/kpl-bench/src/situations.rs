//! `kpl bench situations`: the situation monitors of `specs/traffic/sumo_situations.kpl`, as the
//! spec writes them (overtake and tailgating over pairs of cars; speeding, stopped and wrong-way
//! driving per car), on synthetic traffic of N cars at 10 Hz, run on the simulated clock (one thread, so one core): how many cars are monitored faster
//! than real time, with the pair monitors gated (only pairs within their `close` distance are
//! progressed) and, as the baseline measured in the same run, ungated (every ordered pair).
//! Figures go to `docs/performance.md`.
//!
//! Times are the CPU time of the thread that runs the simulated clock's runtime (`CpuClock`:
//! the whole run is on that thread), so the real-time factor says whether one core keeps up
//! however busy the machine is; the wall time is printed beside it.
//!
//! The traffic (every attribute of the spec's `Car`): a straight one-way road with four lanes, a car every 30 m of each lane, lane k
//! driving at 20 + 3k m/s with a few per cent of spread per car, wrapping around at the road's
//! end, so faster cars keep passing slower ones on the neighbouring lanes. Every tenth car's
//! speed swings by 3 m/s either way over 5 s (so that sumo_weaving.kpl's `speed_swings` has
//! something to recognise), moving it at most 4.8 m from where a steady car would be.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use clap::Args as ClapArgs;
use kpl_core::{Record, Time, Value};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, Input, ProcessError, Source};
use kpl_runtime::{ClockKind, Registry, RunConfig};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use crate::BenchError;
use crate::clock::CpuClock;

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl bench situations                         # 100 to 4,000 cars, 30 s of traffic each\n  kpl bench situations --cars 500 --seconds 10"
)]
pub struct Args {
    /// Numbers of cars to try (the default: 100, 250, 500, 1000, 2000, 4000).
    #[arg(long, value_delimiter = ',')]
    cars: Vec<u32>,
    /// Simulated seconds of traffic per run.
    #[arg(long, default_value_t = 30)]
    seconds: u32,
    /// Largest number of cars also run ungated (every ordered pair progressed: quadratic).
    #[arg(long, default_value_t = 250)]
    ungated_up_to: u32,
}

const LANES: u32 = 4;
const SPACING_M: f64 = 30.0;
const PERIOD_US: Time = 100_000;
/// Every `SWINGING`-th car's speed swings by `SWING_MPS` either way over `SWING_PERIOD_S`.
const SWINGING: u32 = 10;
const SWING_MPS: f64 = 3.0;
const SWING_PERIOD_S: f64 = 5.0;

/// How far car `i` with the steady speed `base` has driven after `seconds`, and its speed then.
fn motion(i: u32, base: f64, seconds: f64) -> (f64, f64) {
    if !i.is_multiple_of(SWINGING) {
        return (base * seconds, base);
    }
    let w = std::f64::consts::TAU / SWING_PERIOD_S;
    let phase = f64::from(i % 17) * 0.37;
    let driven = base * seconds - SWING_MPS / w * ((w * seconds + phase).cos() - phase.cos());
    (driven, base + SWING_MPS * (w * seconds + phase).sin())
}

/// Synthetic cars at 10 Hz (module doc).
pub(crate) struct Highway {
    pub(crate) cars: u32,
    pub(crate) seconds: u32,
}

impl Highway {
    fn snapshot(&self, t: Time) -> Value {
        let per_lane = self.cars.div_ceil(LANES);
        let length = f64::from(per_lane) * SPACING_M;
        let seconds = t as f64 / 1e6;
        let cars: Vec<Value> = (0..self.cars)
            .map(|i| {
                let lane = i % LANES;
                let k = i / LANES;
                // A deterministic spread of -3 % to +3 % per car.
                let spread = 1.0 + (f64::from((i * 7919) % 61) - 30.0) / 1000.0;
                let base = (20.0 + 3.0 * f64::from(lane)) * spread;
                let (driven, speed) = motion(i, base, seconds);
                let (driven_before, speed_before) = motion(i, base, seconds - 2.0);
                let start = f64::from(k) * SPACING_M;
                let s = (start + driven).rem_euclid(length);
                let y = -1.6 - 3.2 * f64::from(lane);
                let field = |name: &str, v: Value| (Arc::<str>::from(name), v);
                Value::Record(Arc::new(Record {
                    id: Some(Arc::from(format!("co{i}"))),
                    fields: vec![
                        field("pos", Value::vec2(s, y)),
                        field("vel", Value::vec2(speed, 0.0)),
                        field("size", Value::Float(4.6)),
                        field("road", Value::Int(0)),
                        field("lane", Value::str(&format!("e_{lane}"))),
                        field("lane_pos", Value::Float(s)),
                        field("lane_length", Value::Float(length)),
                        field("speed", Value::Float(speed)),
                        field("speed_limit", Value::Float(25.0)),
                        field("heading", Value::Float(0.0)),
                        field("lane_heading", Value::Float(0.0)),
                        field("lane_offset", Value::Float(0.0)),
                        field("in_junction", Value::Bool(false)),
                        field("crossed_solid_line", Value::Bool(false)),
                        field("measured", Value::Bool(true)),
                        // Where it was 2 s ago (`anchor.kalman(smooth: 2s)`; sumo_weaving.kpl),
                        // last: the situation monitors never read them.
                        field("smoothed_pos", Value::vec2((start + driven_before).rem_euclid(length), y)),
                        field("smoothed_vel", Value::vec2(speed_before, 0.0)),
                        field("smoothed_lane_offset", Value::Float(0.0)),
                    ],
                }))
            })
            .collect();
        Value::List(cars.into())
    }
}

impl Source for Highway {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let end = Time::from(self.seconds) * 1_000_000;
            let mut t: Time = 0;
            while t <= end {
                if ctx.should_stop() || !ctx.wait_until(t).await {
                    break;
                }
                ctx.emit(t, self.snapshot(t)).await;
                t += PERIOD_US;
            }
            Ok(())
        })
    }
}

/// Whether a sample is a situation reported (a `true` episode: ungated pair monitors also report
/// the `false` ones of pairs far apart).
pub(crate) fn is_situation(input: &Input<'_>) -> bool {
    matches!(input.trigger_value(), Some(Value::Record(r)) if r.get("verdict") == Some(&Value::Bool(true)))
}

pub(crate) fn registry(counted: Arc<AtomicU64>) -> Registry {
    let mut registry = kpl_std::registry();
    registry.add_source(
        Entry::new(EntryKind::Source, "bench.highway", "Synthetic cars on a four-lane road at 10 Hz.")
            .param(Param::optional("cars", ParamType::Int, Value::Int(100), "how many cars"))
            .param(Param::optional("seconds", ParamType::Int, Value::Int(30), "simulated seconds"))
            .output(TypeReq::Any),
        |ctx| {
            let cars = ctx.param("cars").and_then(Value::as_i64).unwrap_or(100).clamp(1, 1_000_000) as u32;
            let seconds = ctx.param("seconds").and_then(Value::as_i64).unwrap_or(30).clamp(1, 86_400) as u32;
            Ok(Box::new(Highway { cars, seconds }))
        },
    );
    crate::add_count_sink(&mut registry, counted, is_situation);
    registry
}

/// The shipped spec whose monitors are measured.
pub const SPEC_PATH: &str = "specs/traffic/sumo_situations.kpl";
const SHIPPED: &str = include_str!("../../../specs/traffic/sumo_situations.kpl");

/// The spec of a run: the object types and every monitor of [`SPEC_PATH`] as they are written
/// there, over [`Highway`]'s cars instead of the spec's tracker and links. Ungated, the `close`
/// conjunct that gates a pair monitor is hidden in a disjunction (`(close(a, b, 50.0) or false)`),
/// which keeps the meaning and loses the gate.
pub fn spec_text(cars: u32, seconds: u32, gated: bool) -> Result<String, String> {
    let parse = kpl_syntax::parse(SHIPPED);
    if parse.has_errors() {
        return Err(format!("{SPEC_PATH} does not parse"));
    }
    let mut text = String::new();
    let mut monitors = Vec::new();
    for item in &parse.spec.items {
        match item {
            kpl_syntax::ast::Item::Type(t) => {
                text.push_str(&SHIPPED[t.span.start as usize..t.span.end as usize]);
                text.push('\n');
            }
            kpl_syntax::ast::Item::Monitor(m) => {
                let monitor = &SHIPPED[m.span.start as usize..m.span.end as usize];
                text.push_str(&if gated { monitor.to_string() } else { ungated(monitor) });
                text.push('\n');
                monitors.push(m.name.name.clone());
            }
            _ => {}
        }
    }
    if monitors.is_empty() {
        return Err(format!("{SPEC_PATH} has no monitors"));
    }
    text.push_str(&format!("source cars : list<Car> = bench.highway(cars: {cars}, seconds: {seconds})\n"));
    text.push_str(&format!("sink out = bench.count({})\n", monitors.join(", ")));
    Ok(text)
}

/// A monitor's text with its first `close(...)` call hidden in `(close(...) or false)`.
fn ungated(monitor: &str) -> String {
    let Some(start) = monitor.find("close(") else { return monitor.to_string() };
    let mut depth = 0;
    for (i, c) in monitor[start..].char_indices() {
        match c {
            '(' => depth += 1,
            ')' => {
                depth -= 1;
                if depth == 0 {
                    let end = start + i + 1;
                    return format!(
                        "{}({} or false){}",
                        &monitor[..start],
                        &monitor[start..end],
                        &monitor[end..]
                    );
                }
            }
            _ => {}
        }
    }
    monitor.to_string()
}

/// What one run took: CPU seconds of its thread, wall seconds, and the situations reported.
struct Timed {
    cpu: f64,
    wall: f64,
    reports: u64,
}

fn run_once(cars: u32, seconds: u32, gated: bool) -> Result<Timed, String> {
    let counted = Arc::new(AtomicU64::new(0));
    let registry = registry(counted.clone());
    let (cpu, wall, _) = timed_run(&spec_text(cars, seconds, gated)?, &registry)?;
    Ok(Timed { cpu, wall, reports: counted.load(Ordering::Relaxed) })
}

/// Checks `text` and runs it on the simulated clock: the CPU seconds of the runtime's thread, the
/// wall seconds, and the run's report.
pub(crate) fn timed_run(
    text: &str,
    registry: &Registry,
) -> Result<(f64, f64, kpl_runtime::RunReport), String> {
    let spec = kpl_semantic::check_text(text, registry.signatures()).map_err(|e| e.to_string())?;
    let config = RunConfig { clock: ClockKind::Sim, ..RunConfig::default() };
    let (start, clock) = (Instant::now(), CpuClock::start());
    let report = kpl_runtime::run(&spec, registry, &config, None).map_err(|e| e.to_string())?;
    Ok((clock.seconds(), start.elapsed().as_secs_f64(), report))
}

/// The baseline's three columns (CPU seconds, real-time factor, baseline / gated), or dashes when
/// the baseline was not run.
pub(crate) fn baseline_cells(seconds: u32, gated_cpu: f64, baseline_cpu: Option<f64>) -> [String; 3] {
    match baseline_cpu {
        Some(w) => {
            [format!("{w:.2}"), format!("{:.2}", f64::from(seconds) / w), format!("{:.1}", w / gated_cpu)]
        }
        None => ["-".to_string(), "-".to_string(), "-".to_string()],
    }
}

/// Runs the benchmark and writes its table to `out`.
pub fn run(args: &Args, out: &mut dyn Write) -> Result<(), BenchError> {
    let cars = if args.cars.is_empty() { vec![100, 250, 500, 1000, 2000, 4000] } else { args.cars.clone() };
    let seconds = args.seconds.max(1);
    writeln!(
        out,
        "situation monitors (overtake, tailgating: pairs; speeding), {seconds} s of traffic at 10 Hz, simulated clock (one thread; {})",
        CpuClock::name()
    )?;
    writeln!(
        out,
        "{:>6} {:>12} {:>10} {:>10} {:>12} {:>10} {:>8} {:>10}",
        "cars", "gated s", "x realtime", "(wall s)", "ungated s", "x realtime", "ratio", "reports"
    )?;
    let mut largest = None;
    for &n in &cars {
        let gated = run_once(n, seconds, true)?;
        let reports = gated.reports;
        let speed = f64::from(seconds) / gated.cpu;
        if speed > 1.0 {
            largest = Some(n);
        }
        let ungated = if n <= args.ungated_up_to {
            let ungated = run_once(n, seconds, false)?;
            if ungated.reports != reports {
                return Err(BenchError::Failed(format!(
                    "{n} cars: {reports} reports gated, {} ungated",
                    ungated.reports
                )));
            }
            Some(ungated.cpu)
        } else {
            None
        };
        let [base, factor, ratio] = baseline_cells(seconds, gated.cpu, ungated);
        writeln!(
            out,
            "{n:>6} {:>12.2} {speed:>10.2} {:>10.2} {base:>12} {factor:>10} {ratio:>8} {reports:>10}",
            gated.cpu, gated.wall,
        )?;
    }
    match largest {
        Some(n) => writeln!(out, "largest number of cars monitored faster than real time (gated): {n}")?,
        None => writeln!(out, "no number of cars tried was monitored faster than real time")?,
    }
    Ok(())
}
