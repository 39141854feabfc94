//! Running a checked spec: build every process from the registry, wire the edges (in-process
//! queues, or a transport between hosts), start the tasks, stop cleanly, and report.
//!
//! With `ClockKind::Sim` the run happens on a single-threaded tokio runtime with paused time,
//! so a run with a fixed seed produces the same output files every time; with `ClockKind::Wall`
//! on a multi-threaded one. A run ends when every source has ended and every queue has drained,
//! when `--for` has passed, or on Ctrl-C; sinks are flushed in every case.

use std::collections::BTreeMap;
use std::future::poll_fn;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::task::Poll;
use std::time::Duration;

use kpl_core::Time;
use kpl_semantic::hir::{self, ProcessId};
use kpl_semantic::registry::EntryKind;
use tokio::task::JoinSet;

use crate::clock::{Clock, ClockKind, RunEnd};
use crate::context::{Outputs, SourceContext, StopSignal};
use crate::edge::{EdgeReceiver, EdgeSender, Received, edge};
use crate::plan::{Origin, Plan, Role, Target};
use crate::policy::PolicyFilter;
use crate::process::{AsyncUnit, Emitter, Input, ProcessError, Source, SyncUnit, Trigger};
use crate::registry::{BuildContext, BuildError, Extensions, Registry};
use crate::sample::Sample;
use crate::stats::{ProcessStats, RunStats, Summary};
use crate::sync::{StateSync, SyncInput, SyncState};
use crate::transport::{Remote, Transport, TransportError, TransportReport};

/// How to run a spec.
#[derive(Debug, Clone)]
pub struct RunConfig {
    pub clock: ClockKind,
    /// Stop after this much clock time (`--for`).
    pub duration: Option<Time>,
    /// The run's seed (`--seed`).
    pub seed: u64,
    /// Where sinks write relative paths (`--out`).
    pub out_dir: PathBuf,
    /// The spec's directory: where sources read relative paths.
    pub spec_dir: PathBuf,
    /// The spec's name (its file stem): names the streams between hosts.
    pub spec_name: String,
    /// Stop at the first malformed input (`--strict`).
    pub strict: bool,
    /// Run only this host's processes (`--host`).
    pub host: Option<String>,
    /// The deployment's name (`--deployment`); `None`: the spec's (`deploy NAME { ... }`), else
    /// [`DEFAULT_DEPLOYMENT`].
    pub deployment: Option<String>,
    /// The counters to fill, when the caller wants to watch them while the run goes (the
    /// progress line of `kpl run`); a run without them counts in its own.
    pub stats: Option<Arc<RunStats>>,
}

impl Default for RunConfig {
    fn default() -> RunConfig {
        RunConfig {
            clock: ClockKind::Sim,
            duration: None,
            seed: 0,
            out_dir: PathBuf::from("out"),
            spec_dir: PathBuf::from("."),
            spec_name: "spec".into(),
            strict: false,
            host: None,
            deployment: None,
            stats: None,
        }
    }
}

/// The name of a deployment that neither `--deployment` nor the spec names.
pub const DEFAULT_DEPLOYMENT: &str = "default";

impl RunConfig {
    /// What this run executes of a spec ([`Plan::new`]): its host, deployment and spec name.
    pub fn target(&self, spec: &hir::Spec) -> Target {
        Target {
            host: self.host.clone(),
            deployment: self.deployment(spec),
            spec_name: self.spec_name.clone(),
        }
    }

    /// The deployment's name: `--deployment`, else the spec's, else [`DEFAULT_DEPLOYMENT`].
    pub fn deployment(&self, spec: &hir::Spec) -> String {
        self.deployment
            .clone()
            .or_else(|| spec.deploy.as_ref().and_then(|d| d.name.clone()))
            .unwrap_or_else(|| DEFAULT_DEPLOYMENT.to_string())
    }
}

/// Why a run could not start or was cut short.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("cannot build {} process(es):\n{}", .0.len(), .0.iter().map(|e| format!("  {e}")).collect::<Vec<_>>().join("\n"))]
    Build(Vec<BuildError>),
    #[error("{0}")]
    Host(String),
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error("cannot start the runtime: {0}")]
    Io(#[from] std::io::Error),
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Ending {
    /// Every source ended and every queue drained.
    SourcesEnded,
    /// `--for` passed.
    DurationReached,
    Interrupted,
    /// A malformed input in a `--strict` run.
    Strict,
    /// A unit failed whose policy is to stop the run then ([`ProcessError::Stop`]).
    UnitStopped,
}

/// The signal that interrupted a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Signal {
    /// Ctrl-C.
    #[serde(rename = "SIGINT")]
    Interrupt,
    /// What `kill`, `timeout`, systemd and container runtimes send.
    #[serde(rename = "SIGTERM")]
    Terminate,
}

impl Signal {
    pub fn name(self) -> &'static str {
        match self {
            Signal::Interrupt => "SIGINT",
            Signal::Terminate => "SIGTERM",
        }
    }

    /// Waits for Ctrl-C or SIGTERM (only Ctrl-C where there is no SIGTERM).
    pub async fn next() -> Signal {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            if let Ok(mut terminate) = signal(SignalKind::terminate()) {
                return tokio::select! {
                    _ = tokio::signal::ctrl_c() => Signal::Interrupt,
                    _ = terminate.recv() => Signal::Terminate,
                };
            }
        }
        let _ = tokio::signal::ctrl_c().await;
        Signal::Interrupt
    }
}

/// What a run did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunReport {
    pub ending: Ending,
    /// The signal that interrupted the run (with [`Ending::Interrupted`]).
    pub signal: Option<Signal>,
    /// Clock time elapsed (simulated or wall), microseconds, from the run's start (0 in
    /// simulated time).
    pub clock_elapsed: Time,
    /// The clock time of the first sample a source produced (simulated time jumps there: a
    /// replayed bag's first stamp, a date), if any.
    pub first_sample: Option<Time>,
    /// Wall time the run took, microseconds.
    pub wall_elapsed: Time,
    /// Processes that stopped with an error.
    pub failures: Vec<String>,
    pub summary: Summary,
    /// Streams between hosts (`--host`): who was up, what was lost, refused or cut short.
    pub transport: Option<TransportReport>,
}

impl RunReport {
    /// Inputs from other hosts that were cut short (their host lost) or delivered nothing: the
    /// run is incomplete even though it ended normally.
    pub fn incomplete(&self) -> Vec<String> {
        let Some(transport) = &self.transport else { return Vec::new() };
        let mut out: Vec<String> =
            transport.cut_short().into_iter().map(|s| format!("cut short: {s}")).collect();
        for stream in transport.received_nothing() {
            out.push(format!("nothing arrived on `{stream}` from another host"));
        }
        out.extend(transport.end_not_confirmed());
        out
    }
}

/// Opens the transport for streams between hosts (`kpl-zenoh` implements it), for the host of
/// `config` (`config.host`), in the deployment `config.deployment(spec)`.
pub trait TransportFactory: Send + Sync {
    fn open<'a>(
        &'a self,
        spec: &'a hir::Spec,
        config: &'a RunConfig,
    ) -> crate::process::BoxFuture<'a, Result<Arc<dyn Transport>, TransportError>>;
}

/// Runs a spec to its end on a runtime of the configured kind.
pub fn run(
    spec: &hir::Spec,
    registry: &Registry,
    config: &RunConfig,
    transport: Option<&dyn TransportFactory>,
) -> Result<RunReport, RunError> {
    let runtime = match config.clock {
        ClockKind::Sim => tokio::runtime::Builder::new_current_thread()
            .enable_time()
            .enable_io()
            .start_paused(true)
            .build()?,
        ClockKind::Wall => {
            tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?
        }
    };
    let report = runtime.block_on(run_async(spec, registry, config, transport));
    // Instances and transport tasks that outlive the run are cut off here.
    runtime.shutdown_timeout(Duration::from_millis(200));
    report
}

struct ProcessTask {
    id: ProcessId,
    kind: TaskKind,
    outputs: Outputs,
    inputs: Vec<InputEdge>,
}

enum TaskKind {
    Source(Box<dyn Source>),
    Unit(Box<dyn AsyncUnit>),
}

struct InputEdge {
    rx: EdgeReceiver,
    filter: PolicyFilter,
    feedback: bool,
    name: Arc<str>,
}

/// Runs a spec on the current tokio runtime (which must match the clock: paused and
/// single-threaded for `Sim`): plans the configured host ([`Plan::new`]) and executes the plan.
pub async fn run_async(
    spec: &hir::Spec,
    registry: &Registry,
    config: &RunConfig,
    transport_factory: Option<&dyn TransportFactory>,
) -> Result<RunReport, RunError> {
    let plan = Plan::new(spec, &config.target(spec)).map_err(|e| RunError::Host(e.to_string()))?;
    execute(spec, &plan, registry, config, transport_factory).await
}

/// Executes a plan: watches for signals and `--for`, opens the transport if the plan has streams
/// between hosts, builds the processes, wires the edges, spawns one task per process and feed,
/// waits for them and reports.
pub async fn execute(
    spec: &hir::Spec,
    plan: &Plan,
    registry: &Registry,
    config: &RunConfig,
    transport_factory: Option<&dyn TransportFactory>,
) -> Result<RunReport, RunError> {
    let clock = Clock::new(config.clock);
    let stats = config.stats.clone().unwrap_or_default();
    stats.start.store(clock.start(), Ordering::Relaxed);
    stats.observe_time(clock.start());
    let stop = StopSignal::default();
    let end = config.duration.map(|d| Arc::new(RunEnd::new(&clock, d)));
    // Ctrl-C and SIGTERM from the start: a host waiting for the others stops cleanly too; and
    // --for from the start: waiting for other hosts counts in the run's time.
    let signals = Signals::watch(&stop);
    let watchers = watch_for_the_end(&clock, end.clone(), &stop);
    let stop_watching = || {
        signals.task.abort();
        watchers.abort();
    };

    let transport = match open_transport(spec, plan, config, transport_factory).await {
        Ok(transport) => transport,
        Err(e) => {
            stop_watching();
            return Err(e);
        }
    };
    let mut tasks = match build_processes(spec, plan, registry, config, &stats, &stop) {
        Ok(tasks) => tasks,
        Err(errors) => {
            stop_watching();
            return Err(RunError::Build(errors));
        }
    };
    // A transport that cannot go on (a clash with another run of this host) stops the run.
    let transport_watch = transport.as_ref().map(|transport| TransportWatch::watch(transport, &stop));
    let stop_all = || {
        stop_watching();
        if let Some(watch) = &transport_watch {
            watch.task.abort();
        }
    };
    let remote_feeds = wire_edges(plan, &mut tasks, &stats);
    let mut join = JoinSet::new();
    if let Some(transport) = &transport
        && let Err(e) =
            connect_remote(plan, transport, &mut tasks, remote_feeds, &stats, &stop, &mut join).await
    {
        stop_all();
        return Err(e);
    }
    stats.set_endless(
        tasks
            .values()
            .filter(|t| matches!(&t.kind, TaskKind::Source(source) if !source.ends_by_itself()))
            .map(|t| spec.processes[t.id].name.clone())
            .collect(),
    );
    spawn_processes(spec, tasks, config, &clock, &stats, &stop, end, &mut join);
    let (mut failures, stopping_failure) = join_processes(&mut join, &stop).await;
    let strict_failure = stopping_failure == Some(Stopping::Strict);
    if let Some(why) = transport_watch.as_ref().and_then(TransportWatch::failure) {
        failures.push(format!("transport: {why}"));
    }

    let signal = signals.received();
    let duration_reached = (stop.is_stopped() || stats.reached_end.load(Ordering::Relaxed))
        && signal.is_none()
        && !strict_failure;
    stop_all();
    let transport_report = match transport {
        Some(transport) => {
            transport.clone().close().await;
            Some(transport.report())
        }
        None => None,
    };
    let ending = if strict_failure {
        Ending::Strict
    } else if stopping_failure == Some(Stopping::Unit) {
        Ending::UnitStopped
    } else if signal.is_some() {
        Ending::Interrupted
    } else if duration_reached {
        Ending::DurationReached
    } else {
        Ending::SourcesEnded
    };
    Ok(RunReport {
        ending,
        signal,
        clock_elapsed: clock.elapsed(),
        first_sample: stats.first_sample.get().copied(),
        wall_elapsed: clock.wall_elapsed(),
        failures,
        summary: stats.summary(),
        transport: transport_report,
    })
}

/// Ctrl-C and SIGTERM: the first one received stops the run and is remembered for its report.
struct Signals {
    task: tokio::task::JoinHandle<()>,
    received: Arc<std::sync::Mutex<Option<Signal>>>,
}

impl Signals {
    fn watch(stop: &StopSignal) -> Signals {
        let received: Arc<std::sync::Mutex<Option<Signal>>> = Arc::default();
        let (stop, slot) = (stop.clone(), received.clone());
        let task = tokio::spawn(async move {
            let signal = Signal::next().await;
            tracing::info!("{}: stopping the run", signal.name());
            if let Ok(mut slot) = slot.lock() {
                *slot = Some(signal);
            }
            stop.interrupt();
        });
        Signals { task, received }
    }

    fn received(&self) -> Option<Signal> {
        self.received.lock().ok().and_then(|s| *s)
    }
}

/// Watches the transport for a failure it cannot go on after: the first one stops the run and is
/// remembered for its report.
struct TransportWatch {
    task: tokio::task::JoinHandle<()>,
    failure: Arc<std::sync::Mutex<Option<String>>>,
}

impl TransportWatch {
    fn watch(transport: &Arc<dyn Transport>, stop: &StopSignal) -> TransportWatch {
        let failure: Arc<std::sync::Mutex<Option<String>>> = Arc::default();
        let (transport, stop, slot) = (transport.clone(), stop.clone(), failure.clone());
        let task = tokio::spawn(async move {
            let why = transport.failed().await;
            tracing::error!("{why}");
            if let Ok(mut slot) = slot.lock() {
                *slot = Some(why);
            }
            stop.interrupt();
        });
        TransportWatch { task, failure }
    }

    fn failure(&self) -> Option<String> {
        self.failure.lock().ok().and_then(|mut f| f.take())
    }
}

/// The transport for streams between hosts, when the plan has some and the run has a host.
async fn open_transport(
    spec: &hir::Spec,
    plan: &Plan,
    config: &RunConfig,
    factory: Option<&dyn TransportFactory>,
) -> Result<Option<Arc<dyn Transport>>, RunError> {
    match (&config.host, factory) {
        (Some(_), Some(factory)) if plan.needs_transport() => Ok(Some(factory.open(spec, config).await?)),
        (Some(_), None) if plan.needs_transport() => {
            Err(RunError::Host("this spec sends streams between hosts, but no transport is available".into()))
        }
        _ => Ok(None),
    }
}

/// Builds every planned process from the registry; every error, not only the first.
fn build_processes(
    spec: &hir::Spec,
    plan: &Plan,
    registry: &Registry,
    config: &RunConfig,
    stats: &Arc<RunStats>,
    stop: &StopSignal,
) -> Result<BTreeMap<ProcessId, ProcessTask>, Vec<BuildError>> {
    let mut shared = Extensions::default();
    let mut tasks = BTreeMap::new();
    let mut errors = Vec::new();
    for planned in &plan.processes {
        let process = &spec.processes[planned.id];
        let process_stats = stats.process(&process.name);
        let mut ctx = BuildContext {
            spec,
            process,
            spec_dir: &config.spec_dir,
            out_dir: &config.out_dir,
            run_seed: config.seed,
            clock: config.clock,
            shared: &mut shared,
            registry,
            stats: process_stats.clone(),
        };
        let built = match (&planned.role, &process.kind) {
            (Role::Source { entry }, _) => registry.build_source(&mut ctx, entry).map(TaskKind::Source),
            (Role::Compute { entry }, _) => {
                registry.build_unit(&mut ctx, EntryKind::Compute, entry).map(TaskKind::Unit)
            }
            (Role::Sink { entry }, _) => {
                registry.build_unit(&mut ctx, EntryKind::Sink, entry).map(TaskKind::Unit)
            }
            (Role::Link { .. }, _) => registry.build_link(&mut ctx).map(TaskKind::Unit),
            (Role::Chronicle, _) => registry.build_chronicle(&mut ctx).map(TaskKind::Unit),
            (Role::Monitor, hir::ProcessKind::Monitor(monitor)) => {
                crate::monitor::build(process, monitor, registry, process_stats)
                    .map(|m| TaskKind::Unit(Box::new(SyncUnit(m)) as Box<dyn AsyncUnit>))
            }
            (Role::Monitor, _) => Err(ctx.error("planned as a monitor, but it is not one")),
        };
        match built {
            Ok(kind) => {
                let outputs = Outputs::with_ports(planned.ports.len(), stop.clone());
                tasks.insert(planned.id, ProcessTask { id: planned.id, kind, outputs, inputs: Vec::new() });
            }
            Err(e) => errors.push(e),
        }
    }
    if errors.is_empty() { Ok(tasks) } else { Err(errors) }
}

/// Makes the planned edges: a bounded queue per edge, its sender at the local producer's port or
/// kept for the remote stream that feeds it (returned, by subscription), its receiver with the
/// consumer's policy.
fn wire_edges(
    plan: &Plan,
    tasks: &mut BTreeMap<ProcessId, ProcessTask>,
    stats: &Arc<RunStats>,
) -> Vec<Vec<EdgeSender>> {
    let mut remote: BTreeMap<usize, EdgeSender> = BTreeMap::new();
    for (index, planned) in plan.edges.iter().enumerate() {
        let consumer_name = plan.processes.iter().find(|p| p.id == planned.consumer).map_or("", |p| &p.name);
        let edge_stats = stats.edge(&planned.stream, consumer_name);
        let (tx, rx) = edge(planned.capacity, planned.overflow, edge_stats.clone());
        match &planned.origin {
            Origin::Local { producer, port } => {
                if let Some(task) = tasks.get_mut(producer) {
                    task.outputs.ports[*port].local.push(tx);
                }
            }
            Origin::Remote { .. } => {
                remote.insert(index, tx);
            }
        }
        if let Some(task) = tasks.get_mut(&planned.consumer) {
            task.inputs.push(InputEdge {
                rx,
                filter: PolicyFilter::new(planned.policy.clone(), edge_stats),
                feedback: planned.policy.feedback,
                name: Arc::from(planned.stream.as_str()),
            });
        }
    }
    plan.subscriptions.iter().map(|s| s.edges.iter().filter_map(|i| remote.remove(i)).collect()).collect()
}

/// Streams to and from other hosts: one publisher per planned publication, one subscription per
/// planned subscription feeding its edges; then the transport waits for the consuming hosts, all
/// streams at once.
async fn connect_remote(
    plan: &Plan,
    transport: &Arc<dyn Transport>,
    tasks: &mut BTreeMap<ProcessId, ProcessTask>,
    remote_feeds: Vec<Vec<EdgeSender>>,
    stats: &Arc<RunStats>,
    stop: &StopSignal,
    join: &mut JoinSet<Result<(), (String, ProcessError)>>,
) -> Result<(), RunError> {
    for publication in &plan.publications {
        let publisher = transport.publisher(&publication.key).await?;
        if let Some(task) = tasks.get_mut(&publication.producer) {
            task.outputs.ports[publication.port].remote.push(publisher);
        }
    }
    for (subscription, senders) in plan.subscriptions.iter().zip(remote_feeds) {
        let receiver = transport.subscriber(&subscription.key).await?;
        let feed_stats = stats.process(&format!("{}@remote", subscription.key.producer));
        let (stop, run_stats) = (stop.clone(), stats.clone());
        join.spawn(async move {
            feed_remote(receiver, senders, feed_stats, run_stats, stop).await;
            Ok::<(), (String, ProcessError)>(())
        });
    }
    tokio::select! {
        () = transport.start() => {}
        () = stop.stopped() => {}
    }
    Ok(())
}

/// One task per process: a source runs until it ends, a unit until its inputs have ended.
#[allow(clippy::too_many_arguments)] // what every task shares, passed once
fn spawn_processes(
    spec: &hir::Spec,
    tasks: BTreeMap<ProcessId, ProcessTask>,
    config: &RunConfig,
    clock: &Clock,
    stats: &Arc<RunStats>,
    stop: &StopSignal,
    end: Option<Arc<RunEnd>>,
    join: &mut JoinSet<Result<(), (String, ProcessError)>>,
) {
    for (id, task) in tasks {
        let name = spec.processes[id].name.clone();
        let process_stats = stats.process(&name);
        let run_stats = stats.clone();
        let clock = clock.clone();
        let stop = stop.clone();
        let strict = config.strict;
        let end = end.clone();
        let port_names: Arc<[String]> = spec.processes[id].ports.iter().map(|(n, _)| n.clone()).collect();
        join.spawn(async move {
            let result = match task.kind {
                TaskKind::Source(mut source) => {
                    let mut ctx = SourceContext {
                        name: name.clone(),
                        clock,
                        outputs: task.outputs,
                        stop,
                        run_end: end,
                        strict,
                        stats: process_stats,
                        run_stats,
                    };
                    let result = source.run(&mut ctx).await;
                    ctx.outputs.close().await;
                    result
                }
                TaskKind::Unit(unit) => {
                    let names = task.inputs.iter().map(|i| i.name.clone()).collect();
                    let caller = Caller {
                        unit,
                        emitter: Emitter::new(port_names),
                        outputs: task.outputs,
                        names,
                        stats: process_stats,
                        run_stats,
                        strict,
                        wall: (clock.kind() == ClockKind::Wall).then(|| clock.clone()),
                    };
                    run_unit(caller, task.inputs, clock).await
                }
            };
            tracing::debug!(process = %name, id = task.id, "process ended");
            result.map_err(|e| (name, e))
        });
    }
}

/// Why a process's failure stopped the run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stopping {
    /// A malformed input in a `--strict` run.
    Strict,
    /// A unit whose policy is to stop on a failure.
    Unit,
}

/// Waits for every task; the failures, and whether one of them stopped the run (a `--strict`
/// run at a malformed input, a unit whose policy says so).
async fn join_processes(
    join: &mut JoinSet<Result<(), (String, ProcessError)>>,
    stop: &StopSignal,
) -> (Vec<String>, Option<Stopping>) {
    let mut failures = Vec::new();
    let mut stopping = None;
    while let Some(joined) = join.join_next().await {
        match joined {
            Ok(Ok(())) => {}
            Ok(Err((name, error))) => {
                tracing::error!(process = %name, "{error}");
                let why = match error {
                    ProcessError::Strict { .. } => Some(Stopping::Strict),
                    ProcessError::Stop(_) => Some(Stopping::Unit),
                    ProcessError::Failed(_) => None,
                };
                if let Some(why) = why {
                    stopping = stopping.or(Some(why));
                    stop.interrupt();
                }
                failures.push(format!("{name}: {error}"));
            }
            Err(join_error) => failures.push(format!("a process task failed: {join_error}")),
        }
    }
    (failures, stopping)
}

/// Stops the run when the clock reaches `end` (`--for`); Ctrl-C and SIGTERM are watched by the
/// run's signal task, which interrupts it.
fn watch_for_the_end(
    clock: &Clock,
    end: Option<Arc<RunEnd>>,
    stop: &StopSignal,
) -> tokio::task::JoinHandle<()> {
    let (stop, clock) = (stop.clone(), clock.clone());
    tokio::spawn(async move {
        if let Some(end) = end {
            end.reached(&clock).await;
            stop.stop();
        }
    })
}

async fn feed_remote(
    mut receiver: Box<dyn crate::transport::RemoteReceiver>,
    senders: Vec<EdgeSender>,
    stats: Arc<ProcessStats>,
    run_stats: Arc<RunStats>,
    stop: StopSignal,
) {
    loop {
        let received = tokio::select! {
            biased;
            () = stop.stopped() => None,
            r = receiver.recv() => r,
        };
        match received {
            Some(Remote::Sample(sample)) => {
                run_stats.source_sample(sample.available);
                for sender in &senders {
                    let _ = sender.send(sample.clone()).await;
                }
            }
            Some(Remote::Malformed { location, error }) => {
                stats.malformed(crate::stats::Malformed { location, error })
            }
            Some(Remote::CutShort(why)) => {
                tracing::warn!("{why}; ending the stream here");
                break;
            }
            Some(Remote::End) | None => break,
        }
    }
}

/// One unit's loop: receive from the input edges (fairly, in batches), apply each consumer
/// policy, synchronize if the unit asks for it, run the unit, send what it emits.
async fn run_unit(mut caller: Caller, mut inputs: Vec<InputEdge>, clock: Clock) -> Result<(), ProcessError> {
    let mut sync = caller.unit.synchronized().then(|| {
        StateSync::new(
            inputs
                .iter()
                .map(|i| SyncInput {
                    max_delay: i.filter.policy().max_delay,
                    approximate: i.filter.policy().approximation == hir::Approximation::UseMostRecent,
                    feedback: i.feedback,
                    stats: i.rx.stats().clone(),
                })
                .collect(),
        )
    });
    let mut latest: Vec<Option<Sample>> = vec![None; inputs.len()];
    let mut ended = vec![false; inputs.len()];
    let mut batch: Vec<Sample> = Vec::new();
    let mut delivered: Vec<Sample> = Vec::new();
    // What the policies let through, by input port, in arrival order.
    let mut arrived: Vec<(usize, Sample)> = Vec::new();
    let mut states: Vec<SyncState> = Vec::new();
    let mut next = 0usize;
    let live =
        |ended: &[bool], inputs: &[InputEdge]| ended.iter().zip(inputs).any(|(e, i)| !e && !i.feedback);

    while live(&ended, &inputs) {
        let deadline = inputs
            .iter()
            .filter_map(|i| i.filter.deadline())
            .chain(sync.as_ref().and_then(StateSync::deadline))
            .min();
        let mut sleep = std::pin::pin!(deadline.map(|t| tokio::time::sleep_until(clock.instant(t))));
        enum Event {
            Samples(usize),
            Ended(usize),
            Timer,
        }
        let event = poll_fn(|cx| {
            let n = inputs.len();
            for k in 0..n {
                let i = (next + k) % n;
                if ended[i] {
                    continue;
                }
                match inputs[i].rx.poll_recv_many(cx, &mut batch, 256) {
                    Poll::Ready(Received::Samples) => return Poll::Ready(Event::Samples(i)),
                    Poll::Ready(Received::Ended) => return Poll::Ready(Event::Ended(i)),
                    Poll::Pending => {}
                }
            }
            if let Some(sleep) = sleep.as_mut().as_pin_mut()
                && sleep.poll(cx).is_ready()
            {
                return Poll::Ready(Event::Timer);
            }
            Poll::Pending
        })
        .await;
        let now = clock.now();
        let timer = matches!(event, Event::Timer);
        match event {
            Event::Samples(port) => {
                next = (port + 1) % inputs.len();
                if let Some(last) = batch.last() {
                    caller.run_stats.observe_time(last.available);
                }
                for sample in batch.drain(..) {
                    inputs[port].filter.on_sample(sample, now, &mut delivered);
                }
                arrived.extend(delivered.drain(..).map(|s| (port, s)));
            }
            Event::Ended(port) => {
                ended[port] = true;
                if let Some(sync) = &mut sync {
                    sync.end(port, now, &mut states);
                }
            }
            Event::Timer => {
                for (port, input) in inputs.iter_mut().enumerate() {
                    input.filter.on_timer(now, &mut delivered);
                    arrived.extend(delivered.drain(..).map(|s| (port, s)));
                }
            }
        }
        for (port, sample) in arrived.drain(..) {
            match &mut sync {
                Some(sync) => sync.push(port, sample, now, &mut states),
                None => {
                    let valid = sample.valid;
                    latest[port] = Some(sample);
                    caller.call(now, valid, Trigger::Sample(port), &latest).await?;
                }
            }
        }
        if let Some(sync) = &mut sync {
            if timer {
                sync.on_timer(now, &mut states);
            }
            caller.call_states(sync, &mut inputs, &mut states, now).await?;
        }
    }
    if let Some(sync) = &mut sync {
        sync.finish(&mut states);
        caller.call_states(sync, &mut inputs, &mut states, clock.now()).await?;
    }
    caller.end(clock.now()).await;
    Ok(())
}

/// Before a synchronized unit runs on a state, takes in what its `feedback` inputs have
/// received meanwhile, so the state carries the unit's latest previous output (AAPA's world model
/// of the previous cycle), even when several states were released at once.
fn refresh_feedback(sync: &mut StateSync, inputs: &mut [InputEdge], state: &mut SyncState, now: Time) {
    let mut fresh = Vec::new();
    let mut passed = Vec::new();
    for (port, input) in inputs.iter_mut().enumerate() {
        if !input.feedback {
            continue;
        }
        input.rx.try_recv_many(&mut fresh, usize::MAX);
        for sample in fresh.drain(..) {
            input.filter.on_sample(sample, now, &mut passed);
        }
        for sample in passed.drain(..) {
            sync.record_feedback(port, sample);
        }
        state.values[port] = sync.feedback_value(port, state.valid);
    }
}

/// A unit with what each call needs: where its output goes, its input names, its counters.
struct Caller {
    unit: Box<dyn AsyncUnit>,
    emitter: Emitter,
    outputs: Outputs,
    names: Vec<Arc<str>>,
    stats: Arc<ProcessStats>,
    run_stats: Arc<RunStats>,
    strict: bool,
    /// The clock of a wall-clock run: what an asynchronous unit emits becomes available when
    /// its call returns (its latency), not when the call began.
    wall: Option<Clock>,
}

impl Caller {
    /// Runs the unit once and sends what it emitted. A unit's error is counted and the run goes
    /// on (a failing input must not stop the other processes), except in a `--strict` run.
    async fn call(
        &mut self,
        now: Time,
        valid: Time,
        trigger: Trigger,
        values: &[Option<Sample>],
    ) -> Result<(), ProcessError> {
        let input = Input { now, valid, trigger, values, names: &self.names };
        let emitter = &mut self.emitter;
        emitter.begin(now, valid);
        let result = match self.unit.as_sync() {
            Some(unit) => unit.on_input(&input, emitter),
            None => {
                let result = self.unit.on_input(&input, emitter).await;
                if let Some(clock) = &self.wall {
                    let returned = clock.now();
                    for (_, sample) in &mut emitter.out {
                        sample.available = sample.available.max(returned);
                    }
                }
                result
            }
        };
        if let Err(e) = result {
            if self.strict || matches!(e, ProcessError::Stop(_)) {
                return Err(e);
            }
            self.stats.error(e.to_string());
        }
        if !emitter.unknown_ports.is_empty() {
            for port in std::mem::take(&mut emitter.unknown_ports) {
                self.stats.error(format!("emitted on `{port}`, which is not an output of this process"));
            }
        }
        self.run_stats.count_samples(emitter.out.len() as u64);
        for (port, sample) in emitter.drain() {
            self.outputs.send(port, sample).await;
        }
        Ok(())
    }

    /// Runs the unit on each released state, oldest first, its feedback inputs refreshed.
    async fn call_states(
        &mut self,
        sync: &mut StateSync,
        inputs: &mut [InputEdge],
        states: &mut Vec<SyncState>,
        now: Time,
    ) -> Result<(), ProcessError> {
        for mut state in states.drain(..) {
            refresh_feedback(sync, inputs, &mut state, now);
            self.call(now, state.valid, Trigger::State, &state.values).await?;
        }
        Ok(())
    }

    /// Every input has ended: lets the unit emit what is pending, sends it, ends the outputs.
    async fn end(mut self, now: Time) {
        self.emitter.begin(now, now);
        if let Err(e) = self.unit.on_end(&mut self.emitter).await {
            self.stats.error(e.to_string());
        }
        for (port, sample) in self.emitter.drain() {
            self.outputs.send(port, sample).await;
        }
        self.outputs.close().await;
    }
}
