//! `kpl mtl eval`: evaluates an MTL formula over a JSON-lines trace; and `kpl bench mtl`, the
//! Timescales benchmark of the engine against R2U2.

use std::collections::{BTreeSet, VecDeque};
use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use clap::{Args, Subcommand};
use kpl_core::{Time, TimeUnit, Value};
use kpl_mtl::timescales::{PROPOSITIONS, Property, TimescalesState};
use kpl_mtl::{
    CompileError, Context, EngineConfig, EveryMonitor, Formula, InstanceId, Progressor, ProgressorGroup,
    SlotState, StartVerdict, State,
};
use serde_json::json;

use crate::cmd::bench::CpuClock;

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
  {\"t\":2,\"verdict\":true}
  $ cat condition.mtl
  always[0, 3] (p -> eventually[0, 5] q)
  $ kpl mtl eval --formula-file condition.mtl --trace trace.jsonl
  {\"decided_at\":null,\"verdict\":true}

Exit status: 0 with a verdict; 1 when the formula or the trace is wrong (the message names the
line); 2 when a file cannot be read or the arguments are wrong.";

#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("formula_source").required(true).args(["formula", "formula_file"]))]
pub struct EvalArgs {
    /// The formula, in KPL syntax (`always (p -> eventually[0, 5] q)`).
    #[arg(long)]
    formula: Option<String>,
    /// Read the formula from this file instead (for formulas too long for the command line).
    #[arg(long, value_name = "FILE")]
    formula_file: Option<PathBuf>,
    /// The trace: a JSON-lines file of states.
    #[arg(long)]
    trace: PathBuf,
    /// The unit of `t` and of bare integer interval bounds (us, ms, s, min, h).
    #[arg(long, default_value = "ms", value_parser = parse_time_unit)]
    time_unit: TimeUnit,
    /// Print the verdict of the formula evaluated from every state, one line per state, each as
    /// soon as it and every earlier one are known.
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

/// Longest formula file and longest trace line read (a file without line breaks, such as
/// `/dev/zero`, is refused instead of filling the memory).
const MAX_FORMULA_BYTES: u64 = 64 << 20;
const MAX_LINE_BYTES: usize = 64 << 20;

/// The formula's text and the name its errors are shown under.
fn formula_source(args: &EvalArgs) -> Result<(String, String), Failure> {
    let Some(path) = &args.formula_file else {
        return Ok((args.formula.clone().unwrap_or_default(), "<formula>".to_string()));
    };
    let name = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|e| Failure::Io(format!("cannot read {name}: {e}")))?;
    let mut bytes = Vec::new();
    file.take(MAX_FORMULA_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Failure::Io(format!("cannot read {name}: {e}")))?;
    if bytes.len() as u64 > MAX_FORMULA_BYTES {
        return Err(Failure::Input(format!("error: {name}: the formula file is larger than 64 MiB\n")));
    }
    let bytes = bytes.strip_prefix(UTF8_BOM).unwrap_or(&bytes);
    let text = String::from_utf8(bytes.to_vec()).map_err(|e| {
        let line = bytes[..e.utf8_error().valid_up_to()].iter().filter(|b| **b == b'\n').count() + 1;
        Failure::Input(format!("error: {name}:{line}: the formula is not valid UTF-8\n"))
    })?;
    Ok((text, name))
}

fn eval_inner(args: &EvalArgs) -> Result<(), Failure> {
    let mut context = Context::open(args.time_unit, args.time_unit);
    let (source, source_name) = formula_source(args)?;
    let formula = compile(&source, &source_name, &mut context)?;
    let file = std::fs::File::open(&args.trace)
        .map_err(|e| Failure::Io(format!("cannot read {}: {e}", args.trace.display())))?;
    let trace_name = args.trace.display().to_string();
    let mut reader = TraceReader::new(BufReader::new(file), &context, &trace_name);
    let mut stdout = std::io::BufWriter::new(std::io::stdout().lock());
    let no_states = || Failure::Input(format!("error: {trace_name}: the trace has no states\n"));
    if args.every {
        let mut printer = EveryPrinter::default();
        let mut monitor = EveryMonitor::new(formula);
        let mut verdicts: Vec<StartVerdict> = Vec::new();
        while let Some((line, time, state)) = reader.next_state()? {
            monitor.step(time, &state, &mut verdicts).map_err(|e| reader.error(line, &e.to_string()))?;
            printer.state(time);
            printer.decided(&mut verdicts, &mut stdout)?;
            // Before waiting for more input (a pipe), what is known goes out.
            if reader.input_drained() {
                stdout.flush().map_err(write_error)?;
            }
        }
        if printer.states == 0 {
            return Err(no_states());
        }
        monitor.finish(&mut verdicts);
        printer.decided(&mut verdicts, &mut stdout)?;
    } else {
        let mut progressor = Progressor::new(formula);
        let mut any = false;
        while let Some((line, time, state)) = reader.next_state()? {
            any = true;
            // Once decided, the rest of the trace is still read, so that a malformed line is
            // reported rather than silently ignored.
            progressor.step(time, &state).map_err(|e| reader.error(line, &e.to_string()))?;
        }
        let Some(verdict) = progressor.finish().filter(|_| any) else { return Err(no_states()) };
        let line = json!({ "verdict": verdict, "decided_at": progressor.decided_at() });
        writeln!(stdout, "{line}").map_err(write_error)?;
    }
    stdout.flush().map_err(write_error)
}

fn write_error(e: std::io::Error) -> Failure {
    Failure::Io(format!("cannot write the output: {e}"))
}

/// Prints `--every` verdicts in the order of their states as soon as a state's verdict and
/// every earlier one are known, keeping only the states from the earliest undecided one on.
#[derive(Default)]
struct EveryPrinter {
    /// Index of the first state not printed yet.
    first: usize,
    /// From `first` on: each state's time and verdict, once known.
    waiting: VecDeque<(Time, Option<bool>)>,
    states: usize,
}

impl EveryPrinter {
    fn state(&mut self, time: Time) {
        self.waiting.push_back((time, None));
        self.states += 1;
    }

    fn decided(&mut self, verdicts: &mut Vec<StartVerdict>, out: &mut impl Write) -> Result<(), Failure> {
        for v in verdicts.drain(..) {
            if let Some(slot) = v.start.checked_sub(self.first).and_then(|i| self.waiting.get_mut(i)) {
                slot.1 = Some(v.verdict);
            }
        }
        while let Some((time, Some(verdict))) = self.waiting.front().copied() {
            let line = json!({ "t": time, "verdict": verdict });
            writeln!(out, "{line}").map_err(write_error)?;
            self.waiting.pop_front();
            self.first += 1;
        }
        Ok(())
    }
}

/// Parses and compiles the formula; errors are rendered against the formula text.
fn compile(source: &str, name: &str, context: &mut Context) -> Result<Arc<Formula>, Failure> {
    let index = kpl_syntax::LineIndex::new(source);
    let expr = kpl_syntax::parse_formula(source).map_err(|diagnostics| {
        Failure::Input(diagnostics.iter().map(|d| d.render(name, source, &index)).collect())
    })?;
    let formula = Formula::from_ast(&expr, context).map_err(|errors| {
        Failure::Input(errors.iter().map(|e| render_compile_error(e, name, source, &index)).collect())
    })?;
    Ok(Arc::new(formula))
}

/// Renders a compile error like the syntax diagnostics: message, location, the formula with the
/// span marked, and the hint.
fn render_compile_error(
    error: &CompileError,
    name: &str,
    source: &str,
    index: &kpl_syntax::LineIndex,
) -> String {
    let mut out = String::new();
    let (line_no, column) = index.line_col(source, error.span.start);
    let (end_line, end_column) = index.line_col(source, error.span.end.max(error.span.start));
    let text = index.line_text(source, line_no);
    // The span is marked up to its end, or to the end of its first line.
    let end_column = if end_line == line_no { end_column } else { text.chars().count() + 1 };
    let width = end_column.saturating_sub(column).max(1);
    let _ = writeln!(out, "error: {}", error.message);
    let _ = writeln!(out, " --> {name}:{line_no}:{column}");
    let _ = writeln!(out, "  |");
    let _ = writeln!(out, "{line_no} | {text}");
    let _ = writeln!(out, "  | {}{}", " ".repeat(column - 1), "^".repeat(width));
    if let Some(help) = &error.help {
        let _ = writeln!(out, "  = hint: {help}");
    }
    out
}

const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// Reads states from a JSON-lines trace, checking each line against the names the formula uses.
struct TraceReader<'a, R> {
    reader: BufReader<R>,
    context: &'a Context,
    name: &'a str,
    line: usize,
    previous: Option<Time>,
    buffer: Vec<u8>,
}

impl<'a, R: Read> TraceReader<'a, R> {
    fn new(reader: BufReader<R>, context: &'a Context, name: &'a str) -> Self {
        TraceReader { reader, context, name, line: 0, previous: None, buffer: Vec::new() }
    }

    /// Whether everything read from the file so far was used: the next line needs a read that
    /// may wait (on a pipe).
    fn input_drained(&self) -> bool {
        self.reader.buffer().is_empty()
    }

    fn error(&self, line: usize, message: &str) -> Failure {
        Failure::Input(format!("error: {}:{line}: {message}\n", self.name))
    }

    /// The next line's text (without its line break); `None` at the end of the file.
    fn next_line(&mut self) -> Result<Option<&str>, Failure> {
        self.buffer.clear();
        let limit = MAX_LINE_BYTES as u64 + 1;
        let n = (&mut self.reader)
            .take(limit)
            .read_until(b'\n', &mut self.buffer)
            .map_err(|e| Failure::Io(format!("cannot read {}: {e}", self.name)))?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        let line = self.line;
        if self.buffer.len() > MAX_LINE_BYTES {
            return Err(self.error(line, "the line is longer than 64 MiB"));
        }
        // A byte-order mark (as some editors write) is not part of the first state.
        let start = if line == 1 && self.buffer.starts_with(UTF8_BOM) { UTF8_BOM.len() } else { 0 };
        match std::str::from_utf8(&self.buffer[start..]) {
            Ok(text) => Ok(Some(text)),
            Err(e) => {
                let column = e.valid_up_to() + 1;
                Err(self.error(line, &format!("the line is not valid UTF-8 (at byte {column})")))
            }
        }
    }

    /// The next state with its line number and time; `None` at the end of the file.
    fn next_state(&mut self) -> Result<Option<(usize, Time, SlotState)>, Failure> {
        loop {
            let Some(text) = self.next_line()? else { return Ok(None) };
            if text.trim().is_empty() {
                continue;
            }
            let parsed = serde_json::from_str::<serde_json::Value>(text);
            let line = self.line;
            let json = parsed.map_err(|e| self.error(line, &format!("not a JSON object: {e}")))?;
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
#[command(
    after_help = "Examples:\n  kpl bench mtl\n  kpl bench mtl --states 100000 --bounds 10,1000\n  kpl bench mtl --r2u2-cli /tmp/r2u2/bin/r2u2_cli --properties RecurGLB,AbsentBR"
)]
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
    /// Timed pairs per case: the engine and R2U2 run one after the other this many times.
    #[arg(long, default_value_t = 5)]
    repeat: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The `r2u2_cli` program, used to compile R2U2 specifications with C2PO. Without it the R2U2
    /// columns are left empty.
    #[arg(long)]
    r2u2_cli: Option<PathBuf>,
    /// Object pairs for the link-condition table (each condition progressed for every pair, once
    /// by independent progressors and once by one group); 0 skips it.
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

/// One timed run of a `Progressor` over the trace: seconds and verdict.
fn time_engine(
    formula: &Arc<Formula>,
    trace: &[TimescalesState],
    config: EngineConfig,
) -> (f64, Option<bool>) {
    let mut progressor = Progressor::with_config(formula.clone(), config);
    let clock = CpuClock::start();
    for (t, row) in trace.iter().enumerate() {
        if progressor.step(t as Time, &Row(row)).is_err() {
            break;
        }
    }
    let verdict = progressor.finish();
    (clock.seconds(), verdict)
}

/// The residual's mean and largest size and the share of steps the transition cache answered,
/// from an untimed run.
fn residual_profile(formula: &Arc<Formula>, trace: &[TimescalesState]) -> (f64, usize, f64) {
    let mut progressor = Progressor::new(formula.clone());
    let (mut sum, mut largest) = (0usize, 0usize);
    for (t, row) in trace.iter().enumerate() {
        if progressor.step(t as Time, &Row(row)).is_err() {
            break;
        }
        let size = progressor.residual_size();
        sum += size;
        largest = largest.max(size);
    }
    let stats = progressor.stats();
    let lookups = (stats.cache_hits + stats.cache_misses).max(1);
    (sum as f64 / trace.len().max(1) as f64, largest, stats.cache_hits as f64 / lookups as f64)
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

struct R2u2Run {
    seconds: f64,
    violations: usize,
    overflow: bool,
}

/// One timed run of R2U2, which panics (index out of bounds) when a specification needs more
/// queue slots than it was built with (`R2U2_MAX_QUEUE_SLOTS`, 2048 unless set when r2u2_core is
/// compiled): the panic is caught and reported.
fn time_r2u2(spec: &[u8], trace: &[TimescalesState]) -> Result<R2u2Run, String> {
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let result = std::panic::catch_unwind(|| {
        let mut monitor = r2u2_core::get_monitor(spec);
        let (mut violations, mut overflow) = (0, false);
        let clock = CpuClock::start();
        for row in trace {
            for (i, v) in row.iter().enumerate() {
                r2u2_core::load_bool_signal(&mut monitor, i, *v);
            }
            if !r2u2_core::monitor_step(&mut monitor) {
                overflow = true;
            }
            violations += r2u2_core::get_output_buffer(&monitor).iter().filter(|o| !o.verdict.truth).count();
        }
        R2u2Run { seconds: clock.seconds(), violations, overflow }
    });
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

/// Median and range of some ratios.
fn spread(values: &mut [f64]) -> (f64, f64, f64) {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let median = if n % 2 == 1 { values[n / 2] } else { (values[n / 2 - 1] + values[n / 2]) / 2.0 };
    (median, values[0], values[n - 1])
}

fn min(values: &[f64]) -> f64 {
    values.iter().copied().fold(f64::INFINITY, f64::min)
}

/// One row of the Timescales table.
struct Case {
    property: Property,
    bound: Time,
    states: usize,
    /// Best of the runs, ns per state, with and without the transition cache.
    kpl_ns: f64,
    no_cache_ns: f64,
    mean_residual: f64,
    largest_residual: usize,
    hit_rate: f64,
    verdict: Option<bool>,
    /// R2U2's best ns per state, the per-pair ratios (KPL throughput over R2U2's), or why not.
    r2u2: Result<(f64, Vec<f64>, String), String>,
}

fn run_case(args: &BenchArgs, property: Property, b: Time, scratch: &Path) -> Result<Case, String> {
    let trace = property.trace(b, args.states, args.seed, false);
    let mut context = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let mtl = property.formula(b, &mut context);
    let formula = Arc::new(Formula::new(&mtl, &context).map_err(|e| e.to_string())?);
    let spec = match (&args.r2u2_cli, r2u2_spec(property, b)) {
        (Some(cli), Some(spec)) => {
            r2u2_compile(cli, &spec, &scratch.join(format!("{}-{b}", property.name()))).map(Some)
        }
        (None, Some(_)) => Err("not run".to_string()),
        (_, None) => Err("not expressible".to_string()),
    };
    let n = trace.len() as f64;
    let (mut kpl, mut r2u2, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    let mut verdict = None;
    let mut r2u2_note = String::new();
    let mut r2u2_error = None;
    // Paired runs: the engine, then R2U2 on the same trace, `repeat` times.
    for _ in 0..args.repeat.max(1) {
        let (seconds, v) = time_engine(&formula, &trace, EngineConfig::default());
        verdict = v;
        kpl.push(seconds);
        if let Ok(Some(spec)) = &spec {
            match time_r2u2(spec, &trace) {
                Ok(run) => {
                    ratios.push(run.seconds / seconds);
                    r2u2.push(run.seconds);
                    r2u2_note = if run.overflow {
                        " (queue overflow)".to_string()
                    } else if run.violations > 0 {
                        format!(" ({} false verdicts)", run.violations)
                    } else {
                        String::new()
                    };
                }
                Err(e) => r2u2_error = Some(e),
            }
        }
    }
    let (no_cache, _) =
        time_engine(&formula, &trace, EngineConfig { transition_cache: false, ..Default::default() });
    let (mean_residual, largest_residual, hit_rate) = residual_profile(&formula, &trace);
    let r2u2 = match (spec, r2u2_error) {
        (Err(why), _) => Err(why),
        (_, Some(e)) => {
            eprintln!("warning: R2U2 {} bound {b}: {e}", property.name());
            Err("queue too small".to_string())
        }
        (Ok(_), None) => Ok((min(&r2u2) * 1e9 / n, ratios, r2u2_note)),
    };
    Ok(Case {
        property,
        bound: b,
        states: trace.len(),
        kpl_ns: min(&kpl) * 1e9 / n,
        no_cache_ns: no_cache * 1e9 / n,
        mean_residual,
        largest_residual,
        hit_rate,
        verdict,
        r2u2,
    })
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
        "Timescales properties, {} states per trace, {} pairs of runs; times are {}.\n",
        args.states,
        args.repeat.max(1),
        CpuClock::name()
    );
    let _ = writeln!(
        stdout,
        "| property | bound | states | kpl ns/state | without cache | residual nodes (mean / largest) | ns per state per node | cached steps | verdict | R2U2 ns/state | kpl / R2U2 (median [range]) |"
    );
    let _ = writeln!(stdout, "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|");
    let mut flatness: Vec<(Property, f64, f64)> = Vec::new();
    let mut worst_ratio: Option<(f64, String)> = None;
    let mut worst_per_node: Option<(f64, String)> = None;
    for property in &properties {
        let mut first_ns = None;
        let mut last_ns = None;
        for &b in &args.bounds {
            let case = match run_case(&args, *property, b, &scratch) {
                Ok(case) => case,
                Err(e) => {
                    eprintln!("error: {} bound {b}: {e}", property.name());
                    return ExitCode::from(1);
                }
            };
            first_ns.get_or_insert(case.kpl_ns);
            last_ns = Some(case.kpl_ns);
            let verdict = match case.verdict {
                Some(true) => "holds",
                Some(false) => "VIOLATED",
                None => "error",
            };
            let name = format!("{} {}", case.property.name(), case.bound);
            let per_node = case.kpl_ns / case.mean_residual.max(1.0);
            if worst_per_node.as_ref().is_none_or(|(w, _)| per_node > *w) {
                worst_per_node = Some((per_node, name.clone()));
            }
            let (r2u2_ns, ratio) = match case.r2u2 {
                Ok((ns, mut ratios, note)) => {
                    let (median, lo, hi) = spread(&mut ratios);
                    if worst_ratio.as_ref().is_none_or(|(w, _)| median < *w) {
                        worst_ratio = Some((median, name));
                    }
                    (format!("{ns:.1}{note}"), format!("{median:.2} [{lo:.2} - {hi:.2}]"))
                }
                Err(why) => (why, "-".to_string()),
            };
            let _ = writeln!(
                stdout,
                "| {} | {} | {} | {:.1} | {:.1} | {:.1} / {} | {per_node:.1} | {:.1} % | {verdict} | {r2u2_ns} | {ratio} |",
                case.property.name(),
                case.bound,
                case.states,
                case.kpl_ns,
                case.no_cache_ns,
                case.mean_residual,
                case.largest_residual,
                case.hit_rate * 100.0,
            );
            let _ = stdout.flush();
        }
        if let (Some(first), Some(last)) = (first_ns, last_ns) {
            flatness.push((*property, first, last));
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    if let Some((ratio, case)) = worst_ratio {
        let _ = writeln!(
            stdout,
            "\nLowest KPL / R2U2 (median of the pairs): {ratio:.2} ({case}; target: at least 1.5)."
        );
    }
    if let Some((ns, case)) = worst_per_node {
        let _ =
            writeln!(stdout, "Highest ns per state per residual node: {ns:.1} ({case}; target: at most 15).");
    }
    if let (Some(lo), Some(hi)) = (args.bounds.first(), args.bounds.last()) {
        let _ =
            writeln!(stdout, "\nCost per state, bound {hi} relative to bound {lo} (target: at most 2):\n");
        let _ = writeln!(stdout, "| property | ns/state at {lo} | ns/state at {hi} | ratio |");
        let _ = writeln!(stdout, "|---|---:|---:|---:|");
        for (property, first, last) in flatness {
            let _ =
                writeln!(stdout, "| {} | {first:.1} | {last:.1} | {:.2} |", property.name(), last / first);
        }
    }
    if args.links > 0 {
        bench_links(args.links, args.repeat, &mut stdout);
    }
    ExitCode::SUCCESS
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

/// The objects of the link benchmark at one step: object i moves along x at 10 m/s; its
/// partner is 4 m (even i) or 30 m away; it leaves the road (|y| >= 5) for 0.3 s every 1.7 s,
/// shifted by i.
fn link_objects(links: usize, step: usize, partner: bool) -> Vec<Value> {
    (0..links)
        .map(|i| {
            let offset = if !partner {
                0.0
            } else if i % 2 == 0 {
                4.0
            } else {
                30.0
            };
            let x = i as f64 * 50.0 + step as f64 + offset;
            let off_road = (step + i) % 17 < 3;
            let y = if off_road { 8.0 } else { 1.0 };
            let fields = vec![(Arc::from("pos"), Value::vec2(x, y))];
            Value::Record(Arc::new(kpl_core::Record { id: None, fields }))
        })
        .collect()
}

fn link_formula(text: &str) -> Result<Arc<Formula>, String> {
    let mut context = Context::new(TimeUnit::Us, TimeUnit::Ms);
    context.declare_value("from");
    context.declare_value("to");
    context.register_function(kpl_mtl::Function::new("on_road", (1, Some(1)), |args| match &args[0] {
        Value::Vec2([_, y]) => Ok(Value::Bool(y.abs() < 5.0)),
        other => Err(format!("expected a position, found {}", other.kind())),
    }));
    let expr = kpl_syntax::parse_formula(text).map_err(|_| format!("`{text}` does not parse"))?;
    Formula::from_ast(&expr, &mut context).map(Arc::new).map_err(|e| format!("{e:?}"))
}

/// What one way of progressing the link conditions did: seconds, decisions, and residual nodes
/// held at the end (distinct nodes: shared ones count once).
struct LinkRun {
    seconds: f64,
    decisions: usize,
    nodes: usize,
}

const LINK_STEPS: usize = 100;
const LINK_DT: Time = 100_000;

/// One progressor per pair.
fn links_independent(
    formula: &Arc<Formula>,
    from: &[Vec<Value>],
    to: &[Vec<Value>],
) -> Result<LinkRun, String> {
    let links = from[0].len();
    let mut progressors: Vec<Progressor> = (0..links).map(|_| Progressor::new(formula.clone())).collect();
    let mut decisions = 0;
    let clock = CpuClock::start();
    for step in 0..LINK_STEPS {
        let time = step as Time * LINK_DT;
        for (i, progressor) in progressors.iter_mut().enumerate() {
            let state = PairState { from: &from[step][i], to: &to[step][i] };
            // A decided condition is started again, as a link process does when it goes back to
            // unlinked, so every instance works at every state.
            if progressor.step(time, &state).map_err(|e| e.to_string())?.is_some() {
                decisions += 1;
                progressor.reset();
            }
        }
    }
    let seconds = clock.seconds();
    let nodes = progressors.iter().map(Progressor::residual_size).sum();
    Ok(LinkRun { seconds, decisions, nodes })
}

/// One group for all pairs.
fn links_shared(formula: &Arc<Formula>, from: &[Vec<Value>], to: &[Vec<Value>]) -> Result<LinkRun, String> {
    let links = from[0].len();
    let mut group = ProgressorGroup::new(formula.clone());
    let ids: Vec<InstanceId> = (0..links).map(|_| group.start()).collect();
    let mut decisions = 0;
    let clock = CpuClock::start();
    for step in 0..LINK_STEPS {
        let time = step as Time * LINK_DT;
        for (i, id) in ids.iter().enumerate() {
            let state = PairState { from: &from[step][i], to: &to[step][i] };
            if group.step(*id, time, &state).map_err(|e| e.to_string())?.is_some() {
                decisions += 1;
                group.restart(*id);
            }
        }
    }
    Ok(LinkRun { seconds: clock.seconds(), decisions, nodes: group.total_residual_size() })
}

/// DyKnow's link conditions (paper, section V) for `links` object pairs at 10 Hz for 10 s, in
/// microseconds with millisecond bounds, as the runtime runs them: one progressor per pair
/// (independent), against one group holding every pair's instance (shared), paired runs.
fn bench_links(links: usize, repeat: usize, out: &mut impl Write) {
    let conditions = [
        ("reestablish", "eventually[0, 1000] xydist(from.pos, to.pos) < 10.0"),
        ("establish", "eventually[1000, inf] always[0, 1000] on_road(from.pos)"),
        ("maintain", "always eventually[0, 10000] always[0, 1000] on_road(from.pos)"),
    ];
    let from: Vec<Vec<Value>> = (0..LINK_STEPS).map(|k| link_objects(links, k, false)).collect();
    let to: Vec<Vec<Value>> = (0..LINK_STEPS).map(|k| link_objects(links, k, true)).collect();
    let _ = writeln!(
        out,
        "\nLink conditions: {links} object pairs, {LINK_STEPS} states 100 ms apart, {} pairs of runs ({}):\n",
        repeat.max(1),
        CpuClock::name()
    );
    let _ = writeln!(
        out,
        "| condition | formula | independent ns per instance-step | shared ns per instance-step | shared / independent rate (median [range]) | residual nodes independent / shared | decisions |"
    );
    let _ = writeln!(out, "|---|---|---:|---:|---:|---:|---:|");
    for (name, text) in conditions {
        let formula = match link_formula(text) {
            Ok(f) => f,
            Err(e) => {
                eprintln!("error: {name}: {e}");
                return;
            }
        };
        let (mut alone, mut shared, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
        let mut last = None;
        for _ in 0..repeat.max(1) {
            let runs = links_independent(&formula, &from, &to)
                .and_then(|a| Ok((a, links_shared(&formula, &from, &to)?)));
            let (a, s) = match runs {
                Ok(runs) => runs,
                Err(e) => {
                    eprintln!("error: {name}: {e}");
                    return;
                }
            };
            if a.decisions != s.decisions {
                eprintln!("error: {name}: {} decisions independently, {} shared", a.decisions, s.decisions);
                return;
            }
            ratios.push(a.seconds / s.seconds);
            alone.push(a.seconds);
            shared.push(s.seconds);
            last = Some((a, s));
        }
        let Some((a, s)) = last else { return };
        let steps = (links * LINK_STEPS) as f64;
        let (median, lo, hi) = spread(&mut ratios);
        let _ = writeln!(
            out,
            "| {name} | `{text}` | {:.0} | {:.0} | {median:.1} [{lo:.1} - {hi:.1}] | {} / {} | {} |",
            min(&alone) * 1e9 / steps,
            min(&shared) * 1e9 / steps,
            a.nodes,
            s.nodes,
            a.decisions,
        );
    }
}
