//! `kpl bench python`: the cost of a call to a Python unit (`python.unit`, a worker process over
//! the process-unit protocol) against a trivial Rust unit in the same run, in simulated time,
//! for a `float` and for a 1,000-element `list<float>`. Figures go to `docs/performance.md`.
//!
//! Each run is `source -> unit -> sink`: the source emits N values, the unit gives each back
//! unchanged (Python: `def identity(x): return x`; Rust: a `SyncUnit` that emits its input), a
//! sink counts them. The overhead per call is (Python run − Rust run) / N; calls per second is N
//! over the Python run's wall time (the worker's start, about 0.3 s, is measured apart and left
//! out).

use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use clap::Args as ClapArgs;
use kpl_core::Value;
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, Emitter, Input, ProcessError, Source, SyncUnit, Unit};
use kpl_runtime::{ClockKind, Registry, RunConfig};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use crate::BenchError;

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl bench python --python .venv/bin/python\n  kpl bench python --python .venv/bin/python --calls 200000 --repeat 5"
)]
pub struct Args {
    /// Calls per run.
    #[arg(long, default_value_t = 50_000)]
    pub calls: u64,
    /// Repetitions of each measurement (the best is reported).
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    /// The interpreter (default: the active virtual environment's, else python3); it needs the
    /// `kpl` package and NumPy.
    #[arg(long)]
    pub python: Option<PathBuf>,
}

/// N values: floats, or lists of `length` floats.
struct Values {
    count: u64,
    length: usize,
}

impl Source for Values {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            for i in 0..self.count {
                let value = if self.length == 0 {
                    Value::Float(i as f64)
                } else {
                    Value::List((0..self.length).map(|k| Value::Float((i as usize + k) as f64)).collect())
                };
                ctx.emit(i as i64, value).await;
            }
            Ok(())
        })
    }
}

/// Gives its input back.
struct Identity;

impl Unit for Identity {
    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        if let Some(value) = input.trigger_value() {
            out.emit(value.clone());
        }
        Ok(())
    }
}

fn registry(counted: Arc<AtomicU64>, python: Option<PathBuf>) -> Registry {
    let mut registry = kpl_std::registry();
    registry.add_source(
        Entry::new(EntryKind::Source, "bench.values", "N floats, or lists of floats.")
            .param(Param::required("count", ParamType::Int, "how many"))
            .param(Param::optional(
                "length",
                ParamType::Int,
                Value::Int(0),
                "0: floats; else lists this long",
            ))
            .output(TypeReq::Any),
        |ctx| {
            let count = ctx.param("count").and_then(Value::as_i64).unwrap_or(0).max(0) as u64;
            let length = ctx.param("length").and_then(Value::as_i64).unwrap_or(0).max(0) as usize;
            Ok(Box::new(Values { count, length }))
        },
    );
    registry.add_unit(
        Entry::new(EntryKind::Compute, "bench.identity", "Gives its input back.")
            .input("in", TypeReq::Any, "anything")
            .output(TypeReq::Any),
        |_| Ok(Box::new(SyncUnit(Identity))),
    );
    crate::add_count_sink(&mut registry, counted, |_| true);
    *registry.extension_mut::<kpl_std::python::RunOptions>() =
        kpl_std::python::RunOptions { python, spec_file: None };
    registry
}

/// Seconds of one run of `unit` over `calls` values of `ty`.
fn run_once(
    unit: &str,
    ty: &str,
    length: usize,
    calls: u64,
    dir: &std::path::Path,
    python: &Option<PathBuf>,
) -> Result<f64, String> {
    let counted = Arc::new(AtomicU64::new(0));
    let registry = registry(counted.clone(), python.clone());
    let text = format!(
        "source src : {ty} = bench.values(count: {calls}, length: {length})\n\
         compute a : {ty} = {unit}\n\
         sink out = bench.count(a)\n"
    );
    let parse = kpl_syntax::parse(&text);
    let checked = kpl_semantic::check(&parse.spec, registry.signatures());
    let spec = checked.spec.ok_or_else(|| format!("{:?}", checked.diagnostics))?;
    let config = RunConfig {
        clock: ClockKind::Sim,
        spec_dir: dir.to_path_buf(),
        out_dir: dir.join("out"),
        ..RunConfig::default()
    };
    let start = Instant::now();
    let report = kpl_runtime::run(&spec, &registry, &config, None).map_err(|e| e.to_string())?;
    let elapsed = start.elapsed().as_secs_f64();
    let got = counted.load(Ordering::Relaxed);
    if got != calls {
        return Err(format!("{unit}: {got} of {calls} values came through ({:?})", report.summary.processes));
    }
    Ok(elapsed)
}

const MODULE: &str = "def identity(x):\n    return x\n";

pub fn run(args: &Args, out: &mut dyn Write) -> Result<(), BenchError> {
    // Removed when dropped, however the run ends.
    let scratch = tempfile::Builder::new()
        .prefix("kpl-bench-python-")
        .tempdir()
        .map_err(|e| BenchError::Failed(e.to_string()))?;
    let dir = scratch.path();
    std::fs::write(dir.join("kpl_bench_unit.py"), MODULE).map_err(|e| BenchError::Failed(e.to_string()))?;
    let python_unit =
        "python.unit(src, module: \"kpl_bench_unit\", function: \"identity\", arrays: \"list\")";
    let numpy_unit =
        "python.unit(src, module: \"kpl_bench_unit\", function: \"identity\", arrays: \"numpy\")";
    let best = |unit: &str, ty: &str, length: usize, calls: u64| -> Result<f64, BenchError> {
        let mut best = f64::INFINITY;
        for _ in 0..args.repeat.max(1) {
            best =
                best.min(run_once(unit, ty, length, calls, dir, &args.python).map_err(BenchError::Failed)?);
        }
        Ok(best)
    };
    // The worker's start (interpreter, imports, handshake): a run of one call.
    let start = best(python_unit, "float", 0, 1)? - best("bench.identity(src)", "float", 0, 1)?;
    writeln!(
        out,
        "Python units against a Rust unit, simulated time, {} calls, best of {}",
        args.calls, args.repeat
    )?;
    writeln!(out, "worker start (interpreter, imports, handshake): {:.0} ms", start * 1e3)?;
    writeln!(
        out,
        "{:<26} {:>12} {:>12} {:>16} {:>14}",
        "value", "Rust us/call", "Python us/call", "overhead us/call", "Python calls/s"
    )?;
    for (name, ty, length, unit) in [
        ("float", "float", 0, python_unit),
        ("list<float> x 1000 (list)", "list<float>", 1000, python_unit),
        ("list<float> x 1000 (numpy)", "list<float>", 1000, numpy_unit),
    ] {
        let rust = best("bench.identity(src)", ty, length, args.calls)?;
        let python = (best(unit, ty, length, args.calls)? - start).max(0.0);
        let n = args.calls as f64;
        writeln!(
            out,
            "{name:<26} {:>12.2} {:>12.2} {:>16.2} {:>14.0}",
            rust / n * 1e6,
            python / n * 1e6,
            (python - rust) / n * 1e6,
            n / python
        )?;
    }
    Ok(())
}
