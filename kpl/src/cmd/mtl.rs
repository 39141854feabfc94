//! `kpl mtl eval`: evaluates an MTL formula over a JSON-lines trace. (`kpl bench mtl` is
//! `kpl_bench::mtl`.)

use std::collections::{BTreeSet, VecDeque};
use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use clap::{Args, Subcommand};
use kpl_core::{Time, TimeUnit, Value};
use kpl_mtl::{CompileError, Context, EveryMonitor, Formula, Progressor, SlotState, StartVerdict};
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
