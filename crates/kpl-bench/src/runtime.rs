//! `kpl bench runtime`: the in-process runtime against bare tokio channels, and its memory over a
//! long run. Figures go to `docs/performance.md`.
//!
//! - **Chain**: a source, three computational units and a sink (`source -> CU -> CU -> CU -> sink`,
//!   default queues of 1024 that block), pushing samples as fast as they go; the baseline is a bare
//!   chain of tokio `mpsc` channels of the same length and bound forwarding the same `Sample`s,
//!   measured in the same run on the same kind of tokio runtime.
//! - **Memory**: a wall-clock run at a fixed rate (default 100,000 samples/s) through a unit and a
//!   policy to a sink; resident memory is read from `/proc/self/statm` after the first minute and
//!   at the end.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use clap::Args as ClapArgs;
use kpl_core::{Time, Value, ValueType};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, Emitter, Input, ProcessError, Source, SyncUnit, Unit};
use kpl_runtime::{ClockKind, Registry, RunConfig, Sample};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use crate::BenchError;

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl bench runtime                      # the chain, 1,000,000 samples\n  kpl bench runtime --memory 10min       # also a 10-minute run at 100,000 samples/s"
)]
pub struct Args {
    /// Samples pushed through the chain.
    #[arg(long, default_value_t = 1_000_000)]
    pub samples: u64,
    /// Repetitions of each measurement (the best is reported).
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    /// Also run the memory test for this long (e.g. 10min); off by default.
    #[arg(long, value_parser = parse_memory_duration)]
    pub memory: Option<Duration>,
    /// Samples per second in the memory test.
    #[arg(long, default_value_t = 100_000)]
    pub rate: u64,
}

/// A duration as `kpl run --for` takes it (10min, 90s, ...).
fn parse_memory_duration(text: &str) -> Result<Duration, String> {
    kpl_core::parse_duration(text).map(|us| Duration::from_micros(us.unsigned_abs()))
}

/// Emits `count` integers as fast as the consumers take them (or `rate` per second, in bursts
/// every millisecond, when `rate` > 0), valid at the clock's now.
struct Counter {
    count: u64,
    rate: u64,
}

impl Source for Counter {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let start = ctx.now();
            let mut sent: u64 = 0;
            while self.count == 0 || sent < self.count {
                if ctx.should_stop() {
                    break;
                }
                if self.rate > 0 {
                    // The number of samples due by now, sent in one burst per millisecond.
                    let tick: Time = ctx.now() + 1_000;
                    if !ctx.wait_until(tick).await {
                        break;
                    }
                    let due = ((tick - start) as u128 * u128::from(self.rate) / 1_000_000) as u64;
                    while sent < due {
                        ctx.emit(tick, Value::Int(sent as i64)).await;
                        sent += 1;
                    }
                } else {
                    let now = ctx.now();
                    ctx.emit(now, Value::Int(sent as i64)).await;
                    sent += 1;
                }
            }
            Ok(())
        })
    }
}

/// Counts what arrives.
struct Count(Arc<AtomicU64>);

impl Unit for Count {
    fn on_input(&mut self, _input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
        self.0.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }
}

fn registry(counted: Arc<AtomicU64>) -> Registry {
    let mut registry = Registry::with_builtins();
    registry.add_source(
        Entry::new(EntryKind::Source, "bench.counter", "Integers as fast as they go, or at a rate.")
            .param(Param::optional("count", ParamType::Int, Value::Int(0), "how many (0: until stopped)"))
            .param(Param::optional(
                "rate",
                ParamType::Int,
                Value::Int(0),
                "per second (0: as fast as possible)",
            ))
            .output(TypeReq::Exact(ValueType::Int)),
        |ctx| {
            let count = ctx.param("count").and_then(Value::as_i64).unwrap_or(0).max(0) as u64;
            let rate = ctx.param("rate").and_then(Value::as_i64).unwrap_or(0).max(0) as u64;
            Ok(Box::new(Counter { count, rate }))
        },
    );
    registry.add_unit(
        Entry::new(EntryKind::Sink, "bench.count", "Counts samples.").variadic(
            1,
            "in",
            TypeReq::Any,
            "anything",
        ),
        move |_| Ok(Box::new(SyncUnit(Count(counted.clone())))),
    );
    registry
}

fn check(text: &str, registry: &Registry) -> Result<kpl_semantic::hir::Spec, String> {
    let parse = kpl_syntax::parse(text);
    let checked = kpl_semantic::check(&parse.spec, registry.signatures());
    checked.spec.ok_or_else(|| format!("{:?}", checked.diagnostics))
}

/// Samples/s through the KPL chain.
fn kpl_chain(samples: u64, clock: ClockKind) -> Result<f64, String> {
    let counted = Arc::new(AtomicU64::new(0));
    let registry = registry(counted.clone());
    let spec = check(
        &format!(
            "source src : int = bench.counter(count: {samples})\n\
             compute a : int = kpl.merge(src)\n\
             compute b : int = kpl.merge(a)\n\
             compute c : int = kpl.merge(b)\n\
             sink out = bench.count(c)\n"
        ),
        &registry,
    )?;
    let config = RunConfig { clock, ..RunConfig::default() };
    let start = Instant::now();
    kpl_runtime::run(&spec, &registry, &config, None).map_err(|e| e.to_string())?;
    let elapsed = start.elapsed().as_secs_f64();
    let got = counted.load(Ordering::Relaxed);
    if got != samples {
        return Err(format!("the chain delivered {got} of {samples} samples"));
    }
    Ok(samples as f64 / elapsed)
}

/// Samples/s through a bare chain of tokio channels of the same length and bound.
fn bare_chain(samples: u64, clock: ClockKind) -> Result<f64, String> {
    let runtime = match clock {
        ClockKind::Sim => tokio::runtime::Builder::new_current_thread().enable_all().build(),
        ClockKind::Wall => tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build(),
    }
    .map_err(|e| e.to_string())?;
    let start = Instant::now();
    let got = runtime.block_on(async move {
        use tokio::sync::mpsc;
        let (tx, mut rx) = mpsc::channel::<Sample>(1024);
        let mut handles = Vec::new();
        handles.push(tokio::spawn(async move {
            for i in 0..samples {
                let _ = tx.send(Sample::new(i as i64, i as i64, Value::Int(i as i64))).await;
            }
        }));
        for _ in 0..3 {
            let (next_tx, next_rx) = mpsc::channel::<Sample>(1024);
            let mut input = std::mem::replace(&mut rx, next_rx);
            handles.push(tokio::spawn(async move {
                while let Some(s) = input.recv().await {
                    let _ = next_tx.send(s).await;
                }
            }));
        }
        let mut got = 0u64;
        while rx.recv().await.is_some() {
            got += 1;
        }
        for h in handles {
            let _ = h.await;
        }
        got
    });
    let elapsed = start.elapsed().as_secs_f64();
    if got != samples {
        return Err(format!("the bare chain delivered {got} of {samples} samples"));
    }
    Ok(samples as f64 / elapsed)
}

fn resident_kib() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4)
}

fn memory(duration: Duration, rate: u64, out: &mut dyn Write) -> Result<(), BenchError> {
    let counted = Arc::new(AtomicU64::new(0));
    let registry = registry(counted.clone());
    let spec = check(
        &format!(
            "source src : int = bench.counter(rate: {rate})\n\
             compute a : int = kpl.merge(src)\n\
             stream changes = a with any change, monotone order, queue 4096 block\n\
             monitor sane = always (changes >= 0)\n\
             sink out = bench.count(changes, sane)\n"
        ),
        &registry,
    )?;
    let config = RunConfig {
        clock: ClockKind::Wall,
        duration: Some(i64::try_from(duration.as_micros()).unwrap_or(i64::MAX)),
        ..RunConfig::default()
    };
    let sampler = std::thread::spawn(move || {
        let start = Instant::now();
        let mut readings = Vec::new();
        let mut next = Duration::from_secs(10);
        while start.elapsed() < duration + Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(200));
            if start.elapsed() >= next {
                readings.push((start.elapsed().as_secs(), resident_kib().unwrap_or(0)));
                next += Duration::from_secs(10);
            }
        }
        readings
    });
    let report = kpl_runtime::run(&spec, &registry, &config, None).map_err(|e| e.to_string())?;
    let readings = sampler.join().map_err(|_| "the memory sampler failed".to_string())?;
    let delivered = counted.load(Ordering::Relaxed);
    writeln!(
        out,
        "memory: {} s at {rate} samples/s: {delivered} samples delivered to the sink ({:.0}/s)",
        duration.as_secs(),
        delivered as f64 / duration.as_secs_f64()
    )?;
    for (t, kib) in &readings {
        writeln!(out, "  t = {t:>4} s  resident {kib} KiB")?;
    }
    let at_minute = readings.iter().find(|(t, _)| *t >= 60).map(|(_, k)| *k);
    let at_end = readings.iter().rev().find(|(t, _)| *t <= duration.as_secs()).map(|(_, k)| *k);
    if let (Some(minute), Some(end)) = (at_minute, at_end) {
        writeln!(
            out,
            "  resident at the end / after the first minute: {:.3} (target <= 1.10)",
            end as f64 / minute as f64
        )?;
    }
    writeln!(out, "  run ended: {:?}", report.ending)?;
    Ok(())
}

/// Runs the benchmark and writes its tables to `out`.
pub fn run(args: &Args, out: &mut dyn Write) -> Result<(), BenchError> {
    writeln!(
        out,
        "chain source -> CU -> CU -> CU -> sink, {} samples, best of {}:",
        args.samples, args.repeat
    )?;
    writeln!(out, "| runtime | kpl samples/s | bare tokio channels samples/s | ratio (target >= 0.5) |")?;
    writeln!(out, "|---|---:|---:|---:|")?;
    for (clock, label) in [
        (ClockKind::Sim, "current-thread (--clock sim)"),
        (ClockKind::Wall, "multi-thread, 2 workers (--clock wall)"),
    ] {
        let mut best_kpl = 0.0f64;
        let mut best_bare = 0.0f64;
        for _ in 0..args.repeat {
            match (kpl_chain(args.samples, clock), bare_chain(args.samples, clock)) {
                (Ok(k), Ok(b)) => {
                    best_kpl = best_kpl.max(k);
                    best_bare = best_bare.max(b);
                }
                (Err(e), _) | (_, Err(e)) => return Err(BenchError::Failed(e)),
            }
        }
        writeln!(out, "| {label} | {best_kpl:.0} | {best_bare:.0} | {:.2} |", best_kpl / best_bare)?;
    }
    if let Some(duration) = args.memory {
        memory(duration, args.rate, out)?;
    }
    Ok(())
}
