//! Computational units in Python (or any language that speaks the process-unit protocol,
//! docs/process-units.md), declared in a spec as `python.unit(inputs..., module: ...,
//! function: ..., own parameters...)` and run by kpl in worker processes it starts and
//! supervises: one worker per unit, restarted when it dies or hangs, its failures counted.
//!
//! In simulated time a call is lockstep: the runtime waits for the worker's answer before
//! anything else happens (the call blocks the runtime's one thread, so tokio's paused clock
//! cannot advance), so a seeded run with a Python unit is byte-identical run to run; on the
//! wall clock it runs in `spawn_blocking`, so the other processes go on meanwhile. On the wall
//! clock the call's latency becomes the output's available time (the runtime stamps what an
//! asynchronous unit emits when its call returns).
//!
//! [`register`] adds the entry; `kpl check` checks what it can without running Python
//! ([`check`]: the module beside the spec, the function in it, the parameters it takes).

mod check;
pub mod protocol;
pub mod worker;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use kpl_core::{Time, Value, ValueType};
use kpl_runtime::Registry;
use kpl_runtime::process::{AsyncUnit, BoxFuture, Emitter, Input, ProcessError};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_runtime::stats::ProcessStats;
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use protocol::Hello;
use worker::{Answer, Launch, StartError, Worker};

/// The entry's name in specs.
pub const ENTRY: &str = "python.unit";

/// A unit in any language: a program that speaks the process-unit protocol (docs/process-units.md).
pub const PROCESS_ENTRY: &str = "process.unit";

/// The unit's own parameters among a call's: every one its entry does not declare.
fn own_params<'a>(
    entry: &Entry,
    params: &'a std::collections::BTreeMap<String, Value>,
) -> impl Iterator<Item = (&'a String, &'a Value)> {
    let declared: Vec<String> = entry.params.iter().map(|p| p.name.clone()).collect();
    params.iter().filter(move |(name, _)| !declared.contains(name))
}

/// What `kpl run` knows that a spec does not: the interpreter named on its command line
/// (`--python`) and the spec's file (for positions in errors). Kept in the registry
/// ([`Registry::extension_mut`]).
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    pub python: Option<PathBuf>,
    pub spec_file: Option<PathBuf>,
}

/// Adds `python.unit`.
pub fn register(registry: &mut Registry) {
    registry.add_unit(entry(), |ctx| build(ctx, Kind::Python));
    registry.add_unit(process_entry(), |ctx| build(ctx, Kind::Process));
}

/// Which of the two entries a unit is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Python,
    Process,
}

fn entry() -> Entry {
    let entry = Entry::new(
        EntryKind::Compute,
        ENTRY,
        "A unit written in Python: kpl runs `module.function` in a worker process it supervises (docs/python.md).",
    )
    .variadic(0, "inputs", TypeReq::Any, "the unit's inputs, given to the function in this order")
    .param(Param::required(
        "module",
        ParamType::Str,
        "the Python module: a file beside the spec (`vehicle_kind` is vehicle_kind.py) or an installed module",
    ))
    .param(Param::required("function", ParamType::Str, "the function (or class) in the module"))
    .param(Param::optional(
        "python",
        ParamType::Str,
        Value::str(""),
        "the interpreter (empty: `kpl run --python`, else the active virtual environment's, else python3)",
    ))
    .param(Param::optional(
        "arrays",
        ParamType::Choice(vec!["numpy".into(), "list".into()]),
        Value::str("numpy"),
        "how a list<float> input arrives: a NumPy array over the message's bytes, or a Python list",
    ));
    supervision(entry)
        .extra_params("the unit's own parameters, given to the function (or the class) as keyword arguments")
        .checked_by(check::check)
}

fn process_entry() -> Entry {
    let entry = Entry::new(
        EntryKind::Compute,
        PROCESS_ENTRY,
        "A unit in any language: kpl runs `command`, a program that speaks the process-unit protocol, as a worker process it supervises (docs/process-units.md).",
    )
    .variadic(0, "inputs", TypeReq::Any, "the unit's inputs, in the order of the calls' inputs")
    .param(Param::required(
        "command",
        ParamType::List(Box::new(ParamType::Str)),
        "the program and its arguments; a program path with a `/` is relative to the spec, a bare name is looked up on the PATH",
    ));
    supervision(entry)
        .extra_params("the unit's own parameters, given to the worker in its hello (`params`)")
        .checked_by(check::check_process)
}

/// The parameters both entries share: how the worker is supervised.
fn supervision(entry: Entry) -> Entry {
    entry
    .param(Param::optional(
        "timeout",
        ParamType::Duration,
        Value::Duration(10_000_000),
        "the longest one call may take (real time) before the worker is taken as hung, killed and restarted",
    ))
    .param(Param::optional(
        "start_timeout",
        ParamType::Duration,
        Value::Duration(60_000_000),
        "the longest a worker may take to load the unit",
    ))
    .param(Param::optional(
        "on_error",
        ParamType::Choice(vec!["skip".into(), "stop".into()]),
        Value::str("skip"),
        "when a call fails (the unit raised, returned a wrong value, hung, its worker died): skip that input and go on, or stop the run",
    ))
    .param(Param::optional(
        "restarts",
        ParamType::Int,
        Value::Int(3),
        "how many times a worker that died or hung is started again before the unit gives up",
    ))
    .param(Param::optional(
        "synchronized",
        ParamType::Bool,
        Value::Bool(true),
        "call once per valid time with every input's sample at that time (false: once per sample, with the latest of the others)",
    ))
}

/// The unit's settings, from its call in the spec.
#[derive(Debug, Clone)]
struct Config {
    /// `kinds` (vehicle_kind.classify, spec.kpl:12:1): how errors name the unit.
    name: String,
    launch: Launch,
    output: ValueType,
    timeout: Duration,
    stop_on_error: bool,
    restarts: u64,
    synchronized: bool,
    /// Simulated time: a call blocks the runtime's one thread until the worker answers (nothing
    /// else may happen meanwhile anyway), without a hand-off to a blocking thread.
    lockstep: bool,
}

fn build(ctx: &mut BuildContext<'_>, kind: Kind) -> Result<Box<dyn AsyncUnit>, BuildError> {
    let string = |name: &str| ctx.param(name).and_then(Value::as_str).unwrap_or_default().to_string();
    let duration = |name: &str, default: Time| match ctx.param(name) {
        Some(Value::Duration(us)) => Duration::from_micros(u64::try_from(*us).unwrap_or(0)),
        _ => Duration::from_micros(default as u64),
    };
    let (module, function) = (string("module"), string("function"));
    let options = ctx.registry.extension::<RunOptions>().cloned().unwrap_or_default();
    let spec_dir = if ctx.spec_dir.as_os_str().is_empty() { Path::new(".") } else { ctx.spec_dir };
    let (program, args, what, entry) = match kind {
        Kind::Python => (
            interpreter(&string("python"), options.python.as_deref(), spec_dir),
            vec!["-m".to_string(), "kpl.unit".to_string()],
            format!("{module}.{function}"),
            entry(),
        ),
        Kind::Process => {
            let command: Vec<String> = match ctx.param("command") {
                Some(Value::List(items)) => {
                    items.iter().filter_map(|v| v.as_str().map(str::to_string)).collect()
                }
                _ => Vec::new(),
            };
            let Some((program, args)) = command.split_first() else {
                return Err(ctx.error("`command` is empty: name the worker's program"));
            };
            (program_path(program, spec_dir), args.to_vec(), program.clone(), process_entry())
        }
    };
    let mut params = serde_json::Map::new();
    let Some(call) = ctx.call() else { return Err(ctx.error("a process unit is a computational unit")) };
    for (name, value) in own_params(&entry, &call.params) {
        params.insert(name.clone(), value.to_json());
    }
    let output = ctx.process.output.clone().unwrap_or(ValueType::Any);
    let position =
        options.spec_file.as_deref().and_then(|file| position(file, ctx.process.span.start as usize));
    let name = match position {
        Some(at) => format!("`{}` ({what}, {at})", ctx.process.name),
        None => format!("`{}` ({what})", ctx.process.name),
    };
    let hello = Hello {
        protocol: protocol::PROTOCOL,
        wire: 2,
        unit: ctx.process.name.clone(),
        module,
        function,
        path: vec![spec_dir.canonicalize().unwrap_or_else(|_| spec_dir.to_path_buf()).display().to_string()],
        inputs: ctx.process.inputs.iter().map(|i| i.stream.name.clone()).collect(),
        output: output.to_string(),
        params,
        arrays: if kind == Kind::Python { string("arrays") } else { "list".to_string() },
    };
    let config = Config {
        name,
        launch: Launch {
            interpreter: program,
            args,
            hello,
            start_timeout: duration("start_timeout", 60_000_000),
        },
        output,
        timeout: duration("timeout", 10_000_000),
        stop_on_error: string("on_error") == "stop",
        restarts: ctx.param("restarts").and_then(Value::as_i64).map_or(3, |n| n.max(0) as u64),
        synchronized: ctx.param("synchronized").and_then(Value::as_bool).unwrap_or(true),
        lockstep: ctx.clock == kpl_runtime::ClockKind::Sim,
    };
    Ok(Box::new(PythonUnit::new(Arc::new(config), ctx.stats.clone())))
}

/// The interpreter: `kpl run --python`, else the spec's, else the active virtual environment's,
/// else `python3` from the PATH. A relative path in the spec is relative to the spec.
fn interpreter(in_spec: &str, on_command_line: Option<&Path>, spec_dir: &Path) -> PathBuf {
    if let Some(path) = on_command_line {
        return path.to_path_buf();
    }
    if !in_spec.is_empty() {
        return program_path(in_spec, spec_dir);
    }
    if let Some(env) = std::env::var_os("VIRTUAL_ENV") {
        let python = Path::new(&env).join("bin").join("python");
        if python.exists() {
            return python;
        }
    }
    PathBuf::from("python3")
}

/// A process unit's program: a path with a `/` relative to the spec, a bare name as it is (the
/// PATH finds it).
pub(crate) fn program_path(program: &str, spec_dir: &Path) -> PathBuf {
    let path = Path::new(program);
    if program.contains('/') && path.is_relative() { spec_dir.join(path) } else { path.into() }
}

/// `file:line:column` of a byte offset in the spec file.
fn position(file: &Path, offset: usize) -> Option<String> {
    let text = kpl_core::read::read_file(file, 16 << 20).ok()?;
    let before = text.get(..offset)?;
    let line = before.iter().filter(|b| **b == b'\n').count() + 1;
    let column = before.iter().rev().take_while(|b| **b != b'\n').count() + 1;
    Some(format!("{}:{line}:{column}", file.display()))
}

/// The counts a Python unit reports in the run's summary.
#[derive(Debug, Default)]
struct Counts {
    calls: u64,
    failed: u64,
    restarts: u64,
    lost: u64,
}

/// A `python.unit` process: its worker, started on the first call and again after it died.
struct PythonUnit {
    config: Arc<Config>,
    worker: Option<Worker>,
    stats: Arc<ProcessStats>,
    counts: Counts,
    /// Workers started so far (the first is not a restart).
    started: u64,
    /// The worker failed too often: every call fails at once.
    gave_up: Option<String>,
    call: Vec<u8>,
}

impl PythonUnit {
    fn new(config: Arc<Config>, stats: Arc<ProcessStats>) -> PythonUnit {
        PythonUnit {
            config,
            worker: None,
            stats,
            counts: Counts::default(),
            started: 0,
            gave_up: None,
            call: Vec::new(),
        }
    }

    fn report(&self) {
        let c = &self.counts;
        self.stats.result("calls", c.calls);
        self.stats.result("failed calls", c.failed);
        self.stats.result("worker restarts", c.restarts);
        self.stats.result("inputs lost with a worker", c.lost);
    }

    /// A failed call: counted, reported with the unit's name, stopping the run if the spec says.
    fn fail(&mut self, message: String) -> ProcessError {
        self.counts.failed += 1;
        self.report();
        let message = format!("Python unit {}: {message}", self.config.name);
        if self.config.stop_on_error { ProcessError::Stop(message) } else { ProcessError::failed(message) }
    }

    /// One call, on a blocking thread (the worker answers on a pipe); the worker comes back.
    async fn call(
        &mut self,
        valid: Time,
        now: Time,
        input: &Input<'_>,
        out: &mut Emitter,
    ) -> Result<(), ProcessError> {
        self.counts.calls += 1;
        if let Some(why) = &self.gave_up {
            self.counts.lost += 1;
            let why = why.clone();
            return Err(self.fail(why));
        }
        let inputs: Vec<_> = (0..input.values.len()).map(|k| input.values[k].as_ref()).collect();
        let mut body = std::mem::take(&mut self.call);
        if let Err(e) = protocol::encode_call(valid, now, &inputs, &mut body) {
            self.call = body;
            return Err(self.fail(format!("cannot send the input: {e}")));
        }
        let worker = self.worker.take();
        let config = self.config.clone();
        let restart = self.started > 0 && worker.is_none();
        let lockstep = config.lockstep;
        let work = move || {
            let started = worker.is_none();
            let mut worker = match worker {
                Some(worker) => worker,
                None => match Worker::start(&config.launch) {
                    Ok(worker) => worker,
                    Err(e) => return (None, body, started, Err(e)),
                },
            };
            let answer = worker.call(&body, config.timeout);
            (Some(worker), body, started, answer.map_err(StartError::Trouble))
        };
        let joined = if lockstep { Ok(work()) } else { tokio::task::spawn_blocking(work).await };
        let (worker, body, started, answer) =
            joined.map_err(|e| self.fail(format!("the call's thread failed: {e}")))?;
        self.call = body;
        if started {
            self.started += 1;
            if restart {
                self.counts.restarts += 1;
            }
        }
        let answer = match answer {
            Ok(answer) => {
                self.worker = worker;
                answer
            }
            Err(StartError::Trouble(trouble)) => {
                if let Some(worker) = worker {
                    worker.kill();
                }
                self.counts.lost += 1;
                if self.started > self.config.restarts {
                    self.gave_up = Some(format!(
                        "gave up after {} workers failed (the unit's `restarts` is {}); the last {trouble}",
                        self.started, self.config.restarts
                    ));
                }
                let lost = format!(
                    "{trouble}; the input at valid time {} is lost and a new worker is started for the next",
                    kpl_core::format_micros(valid)
                );
                return Err(self.fail(lost));
            }
            Err(StartError::Spawn(e)) => {
                self.gave_up = Some(e.clone());
                return Err(self.fail(e));
            }
            Err(StartError::Refused(e)) => {
                let message =
                    format!("the worker could not load the unit: {}\n{}", e.error, e.traceback.trim_end());
                self.gave_up = Some(message.clone());
                return Err(self.fail(message));
            }
        };
        match answer {
            Answer::Nothing => Ok(()),
            Answer::Output(bytes) => match kpl_zenoh::codec::decode(&bytes, &self.config.output) {
                Ok(kpl_zenoh::codec::Message::Sample(sample)) => {
                    out.emit(sample.value);
                    Ok(())
                }
                Ok(kpl_zenoh::codec::Message::End { .. }) => {
                    Err(self.fail("the worker sent an end, not an output".into()))
                }
                Err(e) => {
                    Err(self.fail(format!("returned a value that is not a `{}`: {e}", self.config.output)))
                }
            },
            Answer::Raised(e) => {
                let message = if e.traceback.is_empty() {
                    e.error
                } else {
                    format!("raised {}\n{}", e.error, e.traceback.trim_end())
                };
                Err(self.fail(message))
            }
        }
    }
}

impl AsyncUnit for PythonUnit {
    fn synchronized(&self) -> bool {
        self.config.synchronized
    }

    fn on_input<'a>(
        &'a mut self,
        input: &'a Input<'a>,
        out: &'a mut Emitter,
    ) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move { self.call(input.valid, input.now, input, out).await })
    }

    fn on_end<'a>(&'a mut self, _out: &'a mut Emitter) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            self.report();
            if let Some(worker) = self.worker.take() {
                let _ = tokio::task::spawn_blocking(move || worker.quit(Duration::from_secs(2))).await;
            }
            Ok(())
        })
    }
}
