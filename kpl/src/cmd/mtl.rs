//! `kpl mtl eval`: evaluates an MTL formula over a JSON-lines trace; and `kpl bench mtl`, the
//! Timescales benchmark of the engine against R2U2.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use clap::{Args, Subcommand};
use kpl_core::{Time, TimeUnit, Value};
use kpl_mtl::timescales::{PROPOSITIONS, Property, TimescalesState};
use kpl_mtl::{CompileError, Context, EveryMonitor, Formula, Progressor, SlotState, StartVerdict, State};
use serde_json::json;

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Evaluate a formula over a trace of timed states.
    #[command(after_help = EVAL_EXAMPLE)]
    Eval(EvalArgs),
}

const EVAL_EXAMPLE: &str = "\
Trace: one JSON object per line, `t` an integer in the time unit, strictly increasing; the other
fields are the state. Objects that `forall c: Car . ...` ranges over are a field named after the
type: a list of objects, each with an \"id\".

Example:
  $ cat trace.jsonl
  {\"t\": 0, \"p\": true,  \"q\": false, \"x\": 1.5}
  {\"t\": 2, \"p\": false, \"q\": true,  \"x\": 0.5}
  $ kpl mtl eval --formula 'p -> eventually[0, 5] (q and x < 1.0)' --trace trace.jsonl
  {\"decided_at\":2,\"verdict\":true}
  $ kpl mtl eval --formula 'eventually[0, 1] q' --trace trace.jsonl --every
  {\"t\":0,\"verdict\":false}
  {\"t\":2,\"verdict\":true}";

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// The formula, in KPL syntax (`always (p -> eventually[0, 5] q)`).
    #[arg(long)]
    formula: String,
    /// The trace: a JSON-lines file of states.
    #[arg(long)]
    trace: PathBuf,
    /// The unit of `t` and of bare integer interval bounds (us, ms, s, min, h).
    #[arg(long, default_value = "ms", value_parser = parse_time_unit)]
    time_unit: TimeUnit,
    /// Print the verdict of the formula evaluated from every state, one line per state.
    #[arg(long)]
    every: bool,
}

fn parse_time_unit(s: &str) -> Result<TimeUnit, String> {
    TimeUnit::from_suffix(s).ok_or_else(|| format!("unknown time unit `{s}` (use us, ms, s, min or h)"))
}

pub fn run(command: Command) -> ExitCode {
    match command {
        Command::Eval(args) => eval(args),
    }
}

/// An error the user has to fix in the input (exit 1) or an I/O problem (exit 2).
enum Failure {
    Input(String),
    Io(String),
}

fn eval(args: EvalArgs) -> ExitCode {
    match eval_inner(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Input(message)) => {
            eprint!("{message}");
            ExitCode::from(1)
        }
        Err(Failure::Io(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(2)
        }
    }
}

fn eval_inner(args: &EvalArgs) -> Result<(), Failure> {
    let mut context = Context::open(args.time_unit, args.time_unit);
    let formula = compile(&args.formula, &mut context)?;
    let file = std::fs::File::open(&args.trace)
        .map_err(|e| Failure::Io(format!("cannot read {}: {e}", args.trace.display())))?;
    let trace_name = args.trace.display().to_string();
    let mut reader = TraceReader::new(BufReader::new(file), &context, &trace_name);
    let mut stdout = std::io::stdout().lock();
    let write_error = |e: std::io::Error| Failure::Io(format!("cannot write the output: {e}"));

    if args.every {
        let mut monitor = EveryMonitor::new(formula);
        let mut verdicts: Vec<StartVerdict> = Vec::new();
        let mut times: Vec<Time> = Vec::new();
        while let Some((line, time, state)) = reader.next_state()? {
            monitor.step(time, &state, &mut verdicts).map_err(|e| reader.error(line, &e.to_string()))?;
            times.push(time);
        }
        if times.is_empty() {
            return Err(Failure::Input(format!("error: {trace_name}: the trace has no states\n")));
        }
        monitor.finish(&mut verdicts);
        let mut by_start: Vec<Option<bool>> = vec![None; times.len()];
        for v in verdicts {
            by_start[v.start] = Some(v.verdict);
        }
        for (time, verdict) in times.iter().zip(by_start) {
            let line = json!({ "t": time, "verdict": verdict });
            writeln!(stdout, "{line}").map_err(write_error)?;
        }
    } else {
        let mut progressor = Progressor::new(formula);
        let mut any = false;
        while let Some((line, time, state)) = reader.next_state()? {
            any = true;
            if progressor.step(time, &state).map_err(|e| reader.error(line, &e.to_string()))?.is_some() {
                // Decided: the rest of the trace is still read, so that a malformed line is
                // reported rather than silently ignored.
                continue;
            }
        }
        let Some(verdict) = progressor.finish().filter(|_| any) else {
            return Err(Failure::Input(format!("error: {trace_name}: the trace has no states\n")));
        };
        let line = json!({ "verdict": verdict, "decided_at": progressor.decided_at() });
        writeln!(stdout, "{line}").map_err(write_error)?;
    }
    Ok(())
}

/// Parses and compiles the formula; errors are rendered against the formula text.
fn compile(source: &str, context: &mut Context) -> Result<Arc<Formula>, Failure> {
    let index = kpl_syntax::LineIndex::new(source);
    let expr = kpl_syntax::parse_formula(source).map_err(|diagnostics| {
        Failure::Input(diagnostics.iter().map(|d| d.render("<formula>", source, &index)).collect())
    })?;
    let formula = Formula::from_ast(&expr, context).map_err(|errors| {
        Failure::Input(errors.iter().map(|e| render_compile_error(e, source, &index)).collect())
    })?;
    Ok(Arc::new(formula))
}

/// Renders a compile error like the syntax diagnostics: message, location, the formula with the
/// span marked, and the hint.
fn render_compile_error(error: &CompileError, source: &str, index: &kpl_syntax::LineIndex) -> String {
    let mut out = String::new();
    let (line_no, column) = index.line_col(source, error.span.start);
    let (end_line, end_column) = index.line_col(source, error.span.end.max(error.span.start));
    let text = index.line_text(source, line_no);
    // The span is marked up to its end, or to the end of its first line.
    let end_column = if end_line == line_no { end_column } else { text.chars().count() + 1 };
    let width = end_column.saturating_sub(column).max(1);
    let _ = writeln!(out, "error: {}", error.message);
    let _ = writeln!(out, " --> <formula>:{line_no}:{column}");
    let _ = writeln!(out, "  |");
    let _ = writeln!(out, "{line_no} | {text}");
    let _ = writeln!(out, "  | {}{}", " ".repeat(column - 1), "^".repeat(width));
    if let Some(help) = &error.help {
        let _ = writeln!(out, "  = hint: {help}");
    }
    out
}

/// Reads states from a JSON-lines trace, checking each line against the names the formula uses.
struct TraceReader<'a, R> {
    reader: R,
    context: &'a Context,
    name: &'a str,
    line: usize,
    previous: Option<Time>,
    buffer: String,
}

impl<'a, R: BufRead> TraceReader<'a, R> {
    fn new(reader: R, context: &'a Context, name: &'a str) -> Self {
        TraceReader { reader, context, name, line: 0, previous: None, buffer: String::new() }
    }

    fn error(&self, line: usize, message: &str) -> Failure {
        Failure::Input(format!("error: {}:{line}: {message}\n", self.name))
    }

    /// The next state with its line number and time; `None` at the end of the file.
    fn next_state(&mut self) -> Result<Option<(usize, Time, SlotState)>, Failure> {
        loop {
            self.buffer.clear();
            let n = self
                .reader
                .read_line(&mut self.buffer)
                .map_err(|e| Failure::Io(format!("cannot read {}: {e}", self.name)))?;
            if n == 0 {
                return Ok(None);
            }
            self.line += 1;
            if self.buffer.trim().is_empty() {
                continue;
            }
            let line = self.line;
            let json: serde_json::Value = serde_json::from_str(&self.buffer)
                .map_err(|e| self.error(line, &format!("not a JSON object: {e}")))?;
            let serde_json::Value::Object(fields) = json else {
                return Err(self.error(line, "expected a JSON object such as {\"t\": 0, \"p\": true}"));
            };
            let time = match fields.get("t") {
                Some(t) => t.as_i64().ok_or_else(|| {
                    self.error(line, &format!("`t` must be an integer number of {}, found {t}", self.unit()))
                })?,
                None => return Err(self.error(line, "the state has no time stamp `t`")),
            };
            if let Some(previous) = self.previous
                && time <= previous
            {
                return Err(self.error(
                    line,
                    &format!(
                        "time stamps must increase: `t` is {time}, after {previous} on the previous state"
                    ),
                ));
            }
            let mut values = Vec::with_capacity(self.context.slot_names().len());
            for name in self.context.slot_names() {
                let Some(json) = fields.get(&**name) else {
                    let known: BTreeSet<&str> = fields.keys().map(String::as_str).collect();
                    let known: Vec<&str> = known.into_iter().collect();
                    return Err(self.error(
                        line,
                        &format!("unknown name `{name}`: this state has {}", known.join(", ")),
                    ));
                };
                let value = Value::from_json_untyped(json)
                    .map_err(|e| self.error(line, &format!("field `{name}`: {e}")))?;
                values.push(Some(value));
            }
            let mut objects = Vec::with_capacity(self.context.domain_names().len());
            for domain in self.context.domain_names() {
                objects.push(self.objects(line, &fields, domain)?);
            }
            self.previous = Some(time);
            return Ok(Some((line, time, SlotState { values, objects })));
        }
    }

    fn unit(&self) -> &'static str {
        self.context.time_unit().suffix()
    }

    /// The objects of a type: a field named after the type holding a list of objects with ids.
    fn objects(
        &self,
        line: usize,
        fields: &serde_json::Map<String, serde_json::Value>,
        domain: &str,
    ) -> Result<Vec<Value>, Failure> {
        let Some(json) = fields.get(domain) else {
            return Err(
                self.error(line, &format!("no objects of type `{domain}`: expected a field `{domain}`"))
            );
        };
        let serde_json::Value::Array(items) = json else {
            return Err(
                self.error(line, &format!("`{domain}` must be a list of objects, each with an \"id\""))
            );
        };
        let mut out = Vec::with_capacity(items.len());
        for (i, item) in items.iter().enumerate() {
            let value = Value::from_json_untyped(item)
                .map_err(|e| self.error(line, &format!("`{domain}[{i}]`: {e}")))?;
            if value.as_record().is_none_or(|r| r.id.is_none()) {
                return Err(
                    self.error(line, &format!("`{domain}[{i}]` must be an object with a string \"id\""))
                );
            }
            out.push(value);
        }
        Ok(out)
    }
}

#[derive(Debug, Args)]
#[command(after_help = "Examples:\n  kpl bench mtl\n  kpl bench mtl --states 100000 --bounds 10,1000")]
pub struct BenchArgs {
    /// States per trace.
    #[arg(long, default_value_t = 1_000_000)]
    states: usize,
    /// Upper bounds of the properties' intervals, in time units (one state per time unit).
    #[arg(long, value_delimiter = ',', default_values_t = [10, 100, 1000, 10000])]
    bounds: Vec<Time>,
    /// Properties to run (default: all ten).
    #[arg(long, value_delimiter = ',')]
    properties: Vec<String>,
    /// Timed runs per case; the fastest counts.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The `r2u2_cli` program, used to compile R2U2 specifications with C2PO. Without it the R2U2
    /// columns are left empty.
    #[arg(long)]
    r2u2_cli: Option<PathBuf>,
    /// Object pairs for the link-condition table (one progressor per pair and condition, as a link
    /// process keeps them); 0 skips it.
    #[arg(long, default_value_t = 10_000)]
    links: usize,
}

/// A state of a Timescales trace, as the engine reads it.
struct Row<'a>(&'a TimescalesState);

static BOOLS: [Value; 2] = [Value::Bool(false), Value::Bool(true)];

impl State for Row<'_> {
    fn value(&self, slot: kpl_mtl::SlotId) -> Option<&Value> {
        self.0.get(slot as usize).map(|b| &BOOLS[usize::from(*b)])
    }
}

struct EngineRun {
    seconds: f64,
    verdict: Option<bool>,
    largest_residual: usize,
}

fn run_engine(formula: &Arc<Formula>, trace: &[TimescalesState], repeat: usize) -> EngineRun {
    let mut best = f64::INFINITY;
    let mut verdict = None;
    for _ in 0..repeat.max(1) {
        let mut progressor = Progressor::new(formula.clone());
        let start = Instant::now();
        for (t, row) in trace.iter().enumerate() {
            if progressor.step(t as Time, &Row(row)).is_err() {
                break;
            }
        }
        verdict = progressor.finish();
        best = best.min(start.elapsed().as_secs_f64());
    }
    // Residual sizes are measured in a separate, untimed run.
    let mut progressor = Progressor::new(formula.clone());
    let mut largest_residual = 0;
    for (t, row) in trace.iter().enumerate() {
        if progressor.step(t as Time, &Row(row)).is_err() {
            break;
        }
        largest_residual = largest_residual.max(progressor.residual_size());
    }
    EngineRun { seconds: best, verdict, largest_residual }
}

/// The property in R2U2's bounded MLTL (C2PO syntax), if it can be written there. R2U2 gives a
/// verdict at every time step, which stands for our outer `always`.
fn r2u2_spec(property: Property, b: Time) -> Option<String> {
    let a = property.lower_bound(b);
    let formula = match property {
        Property::AbsentAQ => format!("q -> G[0,{b}] !p"),
        Property::AlwaysAQ => format!("q -> G[0,{b}] p"),
        Property::RecurGLB => format!("F[0,{b}] p"),
        Property::RespondGLB => format!("p -> F[{a},{b}] s"),
        // With `F[0,b] r` as premise the first r comes within b, so `U` may be bounded by b.
        Property::AbsentBR => format!("F[0,{b}] r -> (!p U[0,{b}] r)"),
        Property::AlwaysBR => format!("F[0,{b}] r -> (p U[0,{b}] r)"),
        // The "between Q and R" properties need an unbounded `eventually r`.
        _ => return None,
    };
    Some(format!("INPUT\n    p, q, r, s: bool;\n\nFTSPEC\n    {formula};\n"))
}

struct R2u2Run {
    seconds: f64,
    violations: usize,
    overflow: bool,
}

/// Compiles a spec with C2PO through `r2u2_cli compile` and returns the binary specification.
fn r2u2_compile(cli: &Path, spec: &str, dir: &Path) -> Result<Vec<u8>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let spec_path = dir.join("spec.c2po");
    let map_path = dir.join("signals.map");
    let bin_path = dir.join("spec.bin");
    let _ = std::fs::remove_file(&bin_path);
    std::fs::write(&spec_path, spec).map_err(|e| format!("cannot write {}: {e}", spec_path.display()))?;
    let map: String = PROPOSITIONS.iter().enumerate().map(|(i, n)| format!("{n}:{i}\n")).collect();
    std::fs::write(&map_path, map).map_err(|e| format!("cannot write {}: {e}", map_path.display()))?;
    let output = std::process::Command::new(cli)
        .arg("compile")
        .arg(&spec_path)
        .arg(&map_path)
        .arg("--output")
        .arg(dir)
        .current_dir(dir)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", cli.display()))?;
    if !output.status.success() {
        return Err(format!(
            "C2PO failed: {}{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    std::fs::read(&bin_path).map_err(|e| format!("C2PO wrote no {}: {e}", bin_path.display()))
}

/// Runs R2U2, which panics (index out of bounds) when a specification needs more queue slots
/// than it was built with (`R2U2_MAX_QUEUE_SLOTS`, 2048 unless set when r2u2_core is compiled).
fn run_r2u2_guarded(spec: &[u8], trace: &[TimescalesState], repeat: usize) -> Result<R2u2Run, String> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let result = std::panic::catch_unwind(|| run_r2u2(spec, trace, repeat));
    std::panic::set_hook(hook);
    result.map_err(|panic| {
        let message = panic
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default();
        format!(
            "R2U2 panicked ({message}); its queues hold {} slots, set R2U2_MAX_QUEUE_SLOTS when building",
            r2u2_core::R2U2_MAX_QUEUE_SLOTS
        )
    })
}

fn run_r2u2(spec: &[u8], trace: &[TimescalesState], repeat: usize) -> R2u2Run {
    let mut best = f64::INFINITY;
    let mut violations = 0;
    let mut overflow = false;
    for _ in 0..repeat.max(1) {
        let mut monitor = r2u2_core::get_monitor(spec);
        violations = 0;
        let start = Instant::now();
        for row in trace {
            for (i, v) in row.iter().enumerate() {
                r2u2_core::load_bool_signal(&mut monitor, i, *v);
            }
            if !r2u2_core::monitor_step(&mut monitor) {
                overflow = true;
            }
            violations += r2u2_core::get_output_buffer(&monitor).iter().filter(|o| !o.verdict.truth).count();
        }
        best = best.min(start.elapsed().as_secs_f64());
    }
    R2u2Run { seconds: best, violations, overflow }
}

pub fn bench(args: BenchArgs) -> ExitCode {
    let properties: Vec<Property> = if args.properties.is_empty() {
        Property::ALL.to_vec()
    } else {
        let mut out = Vec::new();
        for name in &args.properties {
            match Property::ALL.iter().find(|p| p.name().eq_ignore_ascii_case(name)) {
                Some(p) => out.push(*p),
                None => {
                    let names: Vec<&str> = Property::ALL.iter().map(|p| p.name()).collect();
                    eprintln!("error: unknown property `{name}` (known: {})", names.join(", "));
                    return ExitCode::from(2);
                }
            }
        }
        out
    };
    let scratch = std::env::temp_dir().join(format!("kpl-bench-r2u2-{}", std::process::id()));
    let mut stdout = std::io::stdout().lock();
    let _ = writeln!(
        stdout,
        "| property | bound | states | kpl states/s | kpl ns/state | largest residual | verdict | R2U2 states/s | kpl / R2U2 |"
    );
    let _ = writeln!(stdout, "|---|---:|---:|---:|---:|---:|---|---:|---:|");
    let mut flatness: Vec<(Property, f64, f64)> = Vec::new();
    for property in &properties {
        let mut first_ns = None;
        let mut last_ns = None;
        for &b in &args.bounds {
            let trace = property.trace(b, args.states, args.seed, false);
            let mut context = Context::new(TimeUnit::Ms, TimeUnit::Ms);
            let mtl = property.formula(b, &mut context);
            let formula = match Formula::new(&mtl, &context) {
                Ok(f) => Arc::new(f),
                Err(e) => {
                    eprintln!("error: {}: {e}", property.name());
                    return ExitCode::from(1);
                }
            };
            let run = run_engine(&formula, &trace, args.repeat);
            let rate = trace.len() as f64 / run.seconds;
            let ns = run.seconds * 1e9 / trace.len() as f64;
            first_ns.get_or_insert(ns);
            last_ns = Some(ns);
            let verdict = match run.verdict {
                Some(true) => "holds".to_string(),
                Some(false) => "VIOLATED".to_string(),
                None => "error".to_string(),
            };
            let (r2u2_rate, ratio) = match (&args.r2u2_cli, r2u2_spec(*property, b)) {
                (Some(cli), Some(spec)) => {
                    match r2u2_compile(cli, &spec, &scratch.join(format!("{}-{b}", property.name()))) {
                        Ok(bin) => match run_r2u2_guarded(&bin, &trace, args.repeat) {
                            Ok(r) => {
                                let r_rate = trace.len() as f64 / r.seconds;
                                let note = if r.overflow {
                                    " (queue overflow)".to_string()
                                } else if r.violations > 0 {
                                    format!(" ({} false verdicts)", r.violations)
                                } else {
                                    String::new()
                                };
                                (format!("{}{note}", si(r_rate)), format!("{:.2}", rate / r_rate))
                            }
                            Err(e) => {
                                eprintln!("warning: R2U2 {} bound {b}: {e}", property.name());
                                ("queue too small".to_string(), "-".to_string())
                            }
                        },
                        Err(e) => {
                            eprintln!("warning: R2U2 {} bound {b}: {e}", property.name());
                            ("failed".to_string(), "-".to_string())
                        }
                    }
                }
                (None, Some(_)) => ("not run".to_string(), "-".to_string()),
                (_, None) => ("not expressible".to_string(), "-".to_string()),
            };
            let _ = writeln!(
                stdout,
                "| {} | {b} | {} | {} | {ns:.0} | {} | {verdict} | {r2u2_rate} | {ratio} |",
                property.name(),
                trace.len(),
                si(rate),
                run.largest_residual,
            );
            let _ = stdout.flush();
        }
        if let (Some(first), Some(last)) = (first_ns, last_ns) {
            flatness.push((*property, first, last));
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    if args.links > 0 {
        bench_links(args.links, &mut stdout);
    }
    if let (Some(lo), Some(hi)) = (args.bounds.first(), args.bounds.last()) {
        let _ =
            writeln!(stdout, "\nCost per state, bound {hi} relative to bound {lo} (target: at most 2):\n");
        let _ = writeln!(stdout, "| property | ns/state at {lo} | ns/state at {hi} | ratio |");
        let _ = writeln!(stdout, "|---|---:|---:|---:|");
        for (property, first, last) in flatness {
            let _ =
                writeln!(stdout, "| {} | {first:.0} | {last:.0} | {:.2} |", property.name(), last / first);
        }
    }
    ExitCode::SUCCESS
}

/// `1234567.0` as `1.23 M`.
fn si(x: f64) -> String {
    if x >= 1e6 { format!("{:.2} M", x / 1e6) } else { format!("{:.0} k", x / 1e3) }
}

/// The state of one link instance: the two objects bound to `from` and `to`.
struct PairState<'a> {
    from: &'a Value,
    to: &'a Value,
}

impl State for PairState<'_> {
    fn value(&self, slot: kpl_mtl::SlotId) -> Option<&Value> {
        match slot {
            0 => Some(self.from),
            1 => Some(self.to),
            _ => None,
        }
    }
}

/// DyKnow's link conditions (paper, section V) for `links` object pairs at 10 Hz for 10 s, in
/// microseconds with millisecond bounds, as the runtime will run them: one progressor per pair.
fn bench_links(links: usize, out: &mut impl Write) {
    const STEPS: usize = 100;
    const DT: Time = 100_000;
    let conditions = [
        ("reestablish", "eventually[0, 1000] xydist(from.pos, to.pos) < 10.0"),
        ("establish", "eventually[1000, inf] always[0, 1000] on_road(from.pos)"),
        ("maintain", "always eventually[0, 10000] always[0, 1000] on_road(from.pos)"),
    ];
    // Object i moves along x at 10 m/s; its partner is 4 m (pairs of even i) or 30 m away; it
    // leaves the road (|y| >= 5) for 0.3 s every 1.7 s, shifted by i.
    let objects = |step: usize, offset: f64| -> Vec<Value> {
        (0..links)
            .map(|i| {
                let x = i as f64 * 50.0 + step as f64 + offset * if i % 2 == 0 { 4.0 } else { 30.0 };
                let off_road = (step + i) % 17 < 3;
                let y = if off_road { 8.0 } else { 1.0 };
                let fields = vec![(Arc::from("pos"), Value::vec2(x, y))];
                Value::Record(Arc::new(kpl_core::Record { id: None, fields }))
            })
            .collect()
    };
    let from: Vec<Vec<Value>> = (0..STEPS).map(|k| objects(k, 0.0)).collect();
    let to: Vec<Vec<Value>> = (0..STEPS).map(|k| objects(k, 1.0)).collect();
    let _ = writeln!(
        out,
        "\nLink conditions: {links} object pairs, one progressor each, {STEPS} states 100 ms apart:\n"
    );
    let _ = writeln!(
        out,
        "| condition | formula | instance-steps/s | ns per instance-step | largest residual | decisions |"
    );
    let _ = writeln!(out, "|---|---|---:|---:|---:|---:|");
    for (name, text) in conditions {
        let mut context = Context::new(TimeUnit::Us, TimeUnit::Ms);
        context.declare_value("from");
        context.declare_value("to");
        context.register_function(kpl_mtl::Function::new("on_road", (1, Some(1)), |args| match &args[0] {
            Value::Vec2([_, y]) => Ok(Value::Bool(y.abs() < 5.0)),
            other => Err(format!("expected a position, found {}", other.kind())),
        }));
        let formula = match kpl_syntax::parse_formula(text)
            .map_err(|_| "syntax".to_string())
            .and_then(|e| Formula::from_ast(&e, &mut context).map_err(|e| format!("{e:?}")))
        {
            Ok(f) => Arc::new(f),
            Err(e) => {
                eprintln!("error: {name}: {e}");
                return;
            }
        };
        let mut progressors: Vec<Progressor> = (0..links).map(|_| Progressor::new(formula.clone())).collect();
        let start = Instant::now();
        let mut largest = 0;
        let mut decisions = 0usize;
        for step in 0..STEPS {
            let time = step as Time * DT;
            for (i, progressor) in progressors.iter_mut().enumerate() {
                let state = PairState { from: &from[step][i], to: &to[step][i] };
                match progressor.step(time, &state) {
                    // A decided condition is started again, as a link process does when it goes
                    // back to unlinked, so every instance works at every state.
                    Ok(Some(_)) => {
                        decisions += 1;
                        progressor.reset();
                    }
                    Ok(None) => {}
                    Err(e) => {
                        eprintln!("error: {name}: {e}");
                        return;
                    }
                }
            }
            // Sizes are sampled every second so the timing stays about stepping.
            if step % 10 == 9 {
                largest = largest.max(progressors.iter().map(Progressor::residual_size).max().unwrap_or(0));
            }
        }
        let seconds = start.elapsed().as_secs_f64();
        let steps = (links * STEPS) as f64;
        let _ = writeln!(
            out,
            "| {name} | `{text}` | {} | {:.0} | {largest} | {decisions} |",
            si(steps / seconds),
            seconds * 1e9 / steps
        );
    }
}
