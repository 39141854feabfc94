//! Anchoring on the stream runtime (`kpl run`): [`register`] adds the signatures of the link
//! units and prediction models, the `anchor.world_model` unit, and the factory of link processes
//! to a runtime registry, and `anchor.identify`, through which a running system asks for an
//! object by description (top-down identification).
//!
//! The link processes of one run (on one host) share one [`Anchoring`] engine, kept in the run's
//! shared extensions: the object store is shared, as several links may lead into one type and
//! chains of links build the hierarchy. The engine is built at the first sample, from the links
//! that were built for this run; a type no local link leads into is fed by its snapshots (the
//! percepts, or objects made on another host).
//!
//! A link process whose `from` objects are fed by snapshots (vision_world, from the tracker) steps
//! the engine with each snapshot it receives, at the snapshot's valid time: that one step runs
//! every local link (the engine's step). The engine then leaves, for every local link, its output
//! at that time in the link's queue: the snapshot of its `to` type and its change records. Each
//! link process emits its queue when its own input arrives (a link downstream, such as
//! world_onroad, is triggered by the upstream link's output of the same time) and when its inputs
//! end. So the samples every link emits are the engine's, in order, whatever the scheduling.
//!
//! Snapshots of two sources with the same valid time are taken as two steps one microsecond
//! apart (the engine steps in strictly increasing time); a snapshot older than the engine's last
//! step is refused and counted as an error of the link process. Per-object instances (the
//! paper's process per object) are state machines inside the engine, not tasks.

use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex, MutexGuard};

use kpl_core::{Time, Value};
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Trigger, Unit};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_semantic::hir;
use kpl_semantic::registry::{Entry, EntryKind, TypeReq};

use crate::engine::{AnchorConfig, Anchoring, Snapshot};
use crate::error::IdentifyError;
use crate::networks::Networks;

/// Adds anchoring to a runtime registry: the signatures of the link units and prediction models,
/// `anchor.world_model`, and link processes.
pub fn register(registry: &mut kpl_runtime::Registry) {
    for entry in crate::registry::entries() {
        registry.add_signature(entry);
    }
    registry.add_unit(world_model_entry(), build_world_model);
    registry.add_unit(identify_entry(), build_identify);
    registry.set_link_processes(build_link);
}

fn world_model_entry() -> Entry {
    Entry::new(
        EntryKind::Compute,
        "anchor.world_model",
        "The world model of the run's anchoring (every object with its state and status), at each time its trigger (a link's output) has a sample.",
    )
    .variadic(1, "trigger", TypeReq::Any, "a link's output: one world model per time it has a sample")
    .output(TypeReq::Any)
}

fn identify_entry() -> Entry {
    let field = |name: &str| (name.to_string(), kpl_core::ValueType::Str);
    Entry::new(
        EntryKind::Compute,
        "anchor.identify",
        "Asks the run's anchoring for objects by description (top-down identification): one answer per request, with the symbol of the partial object or why it was refused.",
    )
    .input(
        "requests",
        TypeReq::Fields(vec![field("name"), field("type"), field("description")]),
        "a request: the name to give the object, its type, and a formula over `this`",
    )
    .output(TypeReq::Any)
}

/// One link's output at one time.
#[derive(Debug)]
struct LinkOutput {
    time: Time,
    objects: Value,
    changes: Value,
}

/// What the link processes of a run share.
#[derive(Debug)]
struct Shared {
    spec: hir::Spec,
    spec_dir: std::path::PathBuf,
    /// The links built for this run.
    links: Vec<String>,
    engine: Option<Anchoring>,
    /// Outputs not yet emitted, by link.
    queues: BTreeMap<String, VecDeque<LinkOutput>>,
    /// World models not yet emitted, by `anchor.world_model` unit.
    worlds: Vec<VecDeque<(Time, Value)>>,
    /// The last (stream, valid time) a snapshot was taken from, so that two links reading the
    /// same stream step the engine once.
    taken: BTreeMap<String, Time>,
    /// What each link achieved so far, by link.
    tallies: BTreeMap<String, Tally>,
}

/// What a link process achieved, counted from its changes: the run's result (`kpl run` prints
/// it; summary.json has it under each link's `results`).
#[derive(Debug, Default, Clone, Copy)]
struct Tally {
    /// New objects created by the establish condition.
    established: u64,
    /// Links to a waiting object made by the reestablish condition: the object kept its symbol.
    reestablished: u64,
    /// Links dropped because the maintain condition became false.
    dropped: u64,
}

impl Tally {
    fn count(&mut self, change: &crate::change::Change) {
        use crate::change::{Cause, ChangeKind};
        match (change.kind, change.cause) {
            (ChangeKind::Created, Cause::Establish) => self.established += 1,
            (ChangeKind::Linked, Cause::Reestablish) => self.reestablished += 1,
            (ChangeKind::Unlinked, Cause::Maintain) => self.dropped += 1,
            _ => {}
        }
    }
}

#[derive(Debug, Clone)]
struct SharedHandle(Arc<Mutex<Shared>>);

impl SharedHandle {
    fn get(ctx: &mut BuildContext<'_>) -> SharedHandle {
        let (spec, spec_dir) = (ctx.spec, ctx.spec_dir);
        ctx.shared
            .get_or_insert_with(|| {
                SharedHandle(Arc::new(Mutex::new(Shared {
                    spec: spec.clone(),
                    spec_dir: spec_dir.to_path_buf(),
                    links: Vec::new(),
                    engine: None,
                    queues: BTreeMap::new(),
                    worlds: Vec::new(),
                    taken: BTreeMap::new(),
                    tallies: BTreeMap::new(),
                })))
            })
            .clone()
    }

    fn lock(&self) -> Result<MutexGuard<'_, Shared>, ProcessError> {
        self.0.lock().map_err(|_| ProcessError::failed("the anchoring engine was poisoned by a panic"))
    }
}

impl Shared {
    fn engine(&mut self) -> Result<&mut Anchoring, ProcessError> {
        if self.engine.is_none() {
            let config = AnchorConfig {
                networks: Networks::default().with_base_dir(&self.spec_dir),
                ..AnchorConfig::default()
            };
            let engine = Anchoring::from_spec_links(&self.spec, config, Some(&self.links))
                .map_err(|e| ProcessError::failed(format!("anchoring: {e}")))?;
            self.engine = Some(engine);
        }
        match &mut self.engine {
            Some(engine) => Ok(engine),
            None => Err(ProcessError::failed("anchoring: no engine")),
        }
    }

    /// One engine step with a snapshot; the outputs go to the queues.
    fn step(&mut self, stream: &str, ty: &str, valid: Time, objects: &Value) -> Result<(), ProcessError> {
        if self.taken.get(stream) == Some(&valid) {
            return Ok(());
        }
        self.engine()?;
        let Shared { engine: Some(engine), links, queues, worlds, taken, tallies, .. } = self else {
            return Err(ProcessError::failed("anchoring: no engine"));
        };
        let time = match engine.time() {
            Some(last) if valid < last => {
                return Err(ProcessError::failed(format!(
                    "snapshot of `{stream}` at {valid} is older than the anchoring's last step ({last}); skipped"
                )));
            }
            Some(last) if valid == last => last + 1,
            _ => valid,
        };
        let output = engine
            .step(time, &[Snapshot { source: stream, ty, objects }])
            .map_err(|e| ProcessError::failed(format!("anchoring: {e}")))?;
        let mut changes: BTreeMap<&str, Vec<Value>> = BTreeMap::new();
        for change in &output.changes {
            if let Some(link) = engine.link_of_change(change) {
                tallies.entry(link.to_string()).or_default().count(change);
                changes.entry(link).or_default().push(change.to_value());
            }
        }
        let mut outputs = Vec::new();
        for link in links.iter() {
            let objects = engine
                .link_to_type(link)
                .and_then(|ty| engine.snapshot(ty))
                .unwrap_or_else(|| Value::List(Vec::new().into()));
            let changes = Value::List(changes.remove(link.as_str()).unwrap_or_default().into());
            outputs.push((link.clone(), LinkOutput { time, objects, changes }));
        }
        let world = (!worlds.is_empty()).then(|| engine.world_model());
        for (link, output) in outputs {
            queues.entry(link).or_default().push_back(output);
        }
        if let Some(world) = world {
            for queue in worlds.iter_mut() {
                queue.push_back((time, world.clone()));
            }
        }
        taken.insert(stream.to_string(), valid);
        Ok(())
    }
}

/// A link process of the runtime.
struct LinkProcess {
    name: String,
    from_type: String,
    /// For each input port: the stream's name if it carries `from` objects.
    from_ports: Vec<Option<String>>,
    shared: SharedHandle,
    /// The run's counters for this process: the per-object instances the link process created
    /// and removed are reported there.
    stats: Arc<kpl_runtime::stats::ProcessStats>,
}

impl LinkProcess {
    /// Copies the engine's count of per-object instances and what the link achieved into the
    /// run's statistics.
    fn count_instances(&self, shared: &Shared) {
        use std::sync::atomic::Ordering;
        let Some(engine) = shared.engine.as_ref() else { return };
        if let Some(stats) = engine.link_stats(&self.name) {
            self.stats.instances_created.store(stats.instances_created, Ordering::Relaxed);
            self.stats.instances_removed.store(stats.instances_removed, Ordering::Relaxed);
        }
        let tally = shared.tallies.get(&self.name).copied().unwrap_or_default();
        let to = engine.link_to_type(&self.name).unwrap_or("linked");
        self.stats.result(&format!("new {to} objects (establish)"), tally.established);
        self.stats
            .result(&format!("links reestablished: a waiting {to} kept its symbol"), tally.reestablished);
        self.stats.result("links dropped (maintain became false)", tally.dropped);
    }

    fn emit_queue(&self, shared: &mut Shared, out: &mut Emitter) {
        let Some(queue) = shared.queues.get_mut(&self.name) else { return };
        for output in queue.drain(..) {
            out.emit_at(output.time, output.objects);
            if matches!(&output.changes, Value::List(items) if !items.is_empty()) {
                out.emit_port("changes", output.time, output.changes);
            }
        }
    }
}

impl Unit for LinkProcess {
    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let Trigger::Sample(port) = input.trigger else { return Ok(()) };
        let Some(Some(stream)) = self.from_ports.get(port) else { return Ok(()) };
        let Some(objects) = input.value(port) else { return Ok(()) };
        let mut shared = self.shared.lock()?;
        let fed = shared.engine()?.is_fed_by_snapshots(&self.from_type);
        let result = if fed { shared.step(stream, &self.from_type, input.valid, objects) } else { Ok(()) };
        self.emit_queue(&mut shared, out);
        self.count_instances(&shared);
        result
    }

    fn on_end(&mut self, out: &mut Emitter) -> Result<(), ProcessError> {
        let mut shared = self.shared.lock()?;
        self.emit_queue(&mut shared, out);
        Ok(())
    }
}

fn build_link(ctx: &mut BuildContext<'_>) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    let hir::ProcessKind::Link(link) = &ctx.process.kind else {
        return Err(ctx.error("not a link"));
    };
    let from_type = link.from_type.clone();
    let name = ctx.process.name.clone();
    let from_ports =
        ctx.process.inputs.iter().map(|i| (i.port == "from").then(|| i.stream.name.clone())).collect();
    if crate::Implementations::default().link_unit(&link.via.entry).is_none() {
        return Err(ctx.error(format!("no implementation of the link unit `{}`", link.via.entry)));
    }
    let shared = SharedHandle::get(ctx);
    match shared.0.lock() {
        Ok(mut s) => {
            if s.engine.is_some() {
                return Err(ctx.error("link processes must all be built before the run starts"));
            }
            s.links.push(name.clone());
        }
        Err(_) => return Err(ctx.error("the anchoring engine was poisoned by a panic")),
    }
    let stats = ctx.stats.clone();
    Ok(Box::new(SyncUnit(LinkProcess { name, from_type, from_ports, shared, stats })))
}

/// `anchor.world_model`: emits the world models the engine left for it when its trigger arrives.
struct WorldModel {
    index: usize,
    shared: SharedHandle,
}

impl WorldModel {
    fn emit(&self, out: &mut Emitter) -> Result<(), ProcessError> {
        let mut shared = self.shared.lock()?;
        if let Some(queue) = shared.worlds.get_mut(self.index) {
            for (time, world) in queue.drain(..) {
                out.emit_at(time, world);
            }
        }
        Ok(())
    }
}

impl Unit for WorldModel {
    fn on_input(&mut self, _input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        self.emit(out)
    }

    fn on_end(&mut self, out: &mut Emitter) -> Result<(), ProcessError> {
        self.emit(out)
    }
}

fn build_world_model(
    ctx: &mut BuildContext<'_>,
) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    let shared = SharedHandle::get(ctx);
    let index = match shared.0.lock() {
        Ok(mut s) => {
            s.worlds.push(VecDeque::new());
            s.worlds.len() - 1
        }
        Err(_) => return Err(ctx.error("the anchoring engine was poisoned by a panic")),
    };
    Ok(Box::new(SyncUnit(WorldModel { index, shared })))
}

/// `anchor.identify`: hands each request to the run's anchoring engine
/// ([`Anchoring::identify`]) and answers it. The partial object is created in the engine's next
/// step and completed by the link processes; `created`, `linked` and `identified` with the
/// request's name appear on the links' change streams.
struct Identify {
    shared: SharedHandle,
    /// The built-in functions: a description is checked as an `identify` item of the spec is
    /// (against the spec's types), so that a misspelt attribute is refused rather than never true.
    functions: kpl_semantic::registry::Registry,
}

impl Identify {
    /// Checks and hands a request to the engine; the symbol of the partial object, or why not.
    fn ask(&self, name: &str, ty: &str, description: &str) -> Result<Arc<str>, String> {
        let expr = kpl_syntax::parse_formula(description).map_err(|d| description_error(&d))?;
        let mut shared = self.shared.lock().map_err(|e| e.to_string())?;
        // An undeclared type is left to the engine, which says so.
        if shared.spec.types.get(ty).is_some() {
            let errors = kpl_semantic::check_identification(&self.functions, &shared.spec.types, ty, &expr);
            if !errors.is_empty() {
                return Err(description_error(&errors));
            }
        }
        let engine = shared.engine().map_err(|e| e.to_string())?;
        engine.identify(name, ty, &expr).map_err(|e| e.to_string())
    }
}

/// Diagnostics of a description, with their hints, as the engine words a description that does
/// not compile ([`IdentifyError::Description`]).
fn description_error(diagnostics: &[kpl_syntax::Diagnostic]) -> String {
    let messages = diagnostics
        .iter()
        .map(|d| match &d.hint {
            Some(hint) => format!("{} ({hint})", d.message),
            None => d.message.clone(),
        })
        .collect();
    IdentifyError::Description(messages).to_string()
}

impl Unit for Identify {
    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let Some(request) = input.trigger_value() else { return Ok(()) };
        let text = |name: &str| request.field(name).and_then(|v| v.as_str().map(str::to_string));
        let (Some(name), Some(ty), Some(description)) = (text("name"), text("type"), text("description"))
        else {
            return Err(ProcessError::failed(
                "an identification request needs `name`, `type` and `description`",
            ));
        };
        let result = self.ask(&name, &ty, &description);
        let mut fields: Vec<(Arc<str>, Value)> =
            vec![(Arc::from("name"), Value::str(&name)), (Arc::from("type"), Value::str(&ty))];
        let refused = match result {
            Ok(symbol) => {
                fields.push((Arc::from("accepted"), Value::Bool(true)));
                fields.push((Arc::from("symbol"), Value::Str(symbol)));
                None
            }
            Err(e) => {
                fields.push((Arc::from("accepted"), Value::Bool(false)));
                fields.push((Arc::from("error"), Value::str(&e)));
                Some(e)
            }
        };
        out.emit(Value::Record(Arc::new(kpl_core::Record { id: None, fields })));
        match refused {
            None => Ok(()),
            Some(e) => Err(ProcessError::failed(format!("identification `{name}` refused: {e}"))),
        }
    }
}

fn build_identify(
    ctx: &mut BuildContext<'_>,
) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    let shared = SharedHandle::get(ctx);
    let functions = kpl_runtime::Registry::with_builtins().signatures().clone();
    Ok(Box::new(SyncUnit(Identify { shared, functions })))
}
