//! Anchoring on the stream runtime (`kpl run`), the runtime adapter of `kpl-anchor`'s engine: [`register`] adds the signatures of the link
//! units and prediction models, the `anchor.world_model` unit, and the factory of link processes
//! to a runtime registry, and `anchor.identify`, through which a running system asks for an
//! object by description (top-down identification).
//!
//! Every link process is a knowledge process of its own, as in DyKnow: it subscribes to its input
//! streams (its `from` streams and its unit's extra inputs), each with the policy the spec gives
//! it, and the runtime's state synchronization merges them into one state per valid time (`max
//! delay` and approximation honoured; a stream with no sample at that time and no approximation
//! is missing, and its objects are not stepped then). At each state the link process takes one
//! step of the engine ([`Anchoring::step_link`]) and emits, at the state's valid time, the
//! snapshot of its `to` type and the changes the step made. So a link downstream (world_onroad)
//! runs at the states of its own input: `stream wos = vision_world with sample every 2s` makes it
//! step every 2 s.
//!
//! The link processes of one run (on one host) share one [`Anchoring`] engine, kept in the run's
//! shared extensions: the object store is shared, as several links may lead into one type and
//! chains of links build the hierarchy. The engine is built at the first state, from the links
//! that were built for this run; a type no local link leads into is fed by its snapshots (the
//! percepts, or objects made on another host). Per-object instances (the paper's process per
//! object) are state machines inside the engine, not tasks.

use std::sync::{Arc, Mutex, MutexGuard};

use kpl_core::Value;
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Trigger, Unit};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_semantic::hir;
use kpl_semantic::registry::{Entry, EntryKind, TypeReq};

use kpl_anchor::implementations::Params;
use kpl_anchor::networks::Networks;
use kpl_anchor::predict::PredictionModel;
use kpl_anchor::units::LinkUnit;
use kpl_anchor::{AnchorConfig, Anchoring, FromSnapshot, IdentifyError, Implementations};

/// Adds anchoring to a runtime registry: the signatures of the link units and prediction models
/// (their implementations, [`Implementations::default`] and what [`add_link_unit`] and
/// [`add_model`] add, are kept in the registry), the traffic relations, `anchor.world_model`,
/// `anchor.identify`, and link processes.
pub fn register(registry: &mut kpl_runtime::Registry) {
    for entry in kpl_anchor::registry::entries() {
        registry.add_signature(entry);
    }
    registry.extension_mut::<Implementations>();
    let relations = kpl_anchor::relations::functions();
    for signature in kpl_anchor::relations::signatures() {
        if let Some(function) = relations.iter().find(|f| *f.name == *signature.name) {
            registry.add_function(signature, function.clone());
        }
    }
    registry.add_unit(world_model_entry(), build_world_model);
    registry.add_unit(identify_entry(), build_identify);
    registry.set_link_processes(build_link);
}

/// Adds a link unit of a user's crate: its signature (`EntryKind::Link`, for `kpl check`) and how
/// to build it from a link's parameters, for the link processes of `kpl run`.
pub fn add_link_unit(
    registry: &mut kpl_runtime::Registry,
    entry: Entry,
    factory: impl Fn(&Params, &mut Networks) -> Result<Arc<dyn LinkUnit>, String> + Send + Sync + 'static,
) {
    registry.extension_mut::<Implementations>().add_link_unit(&entry.name, factory);
    registry.add_signature(entry);
}

/// Adds a prediction model of a user's crate: its signature (`EntryKind::Predict`) and how to
/// build it from a `predict` item's parameters.
pub fn add_model(
    registry: &mut kpl_runtime::Registry,
    entry: Entry,
    factory: impl Fn(&Params, &mut Networks) -> Result<Arc<dyn PredictionModel>, String> + Send + Sync + 'static,
) {
    registry.extension_mut::<Implementations>().add_model(&entry.name, factory);
    registry.add_signature(entry);
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

/// What the link processes of a run share.
#[derive(Debug)]
struct Shared {
    spec: hir::Spec,
    spec_dir: std::path::PathBuf,
    /// The link units and prediction models of the registry the run was built from.
    implementations: Implementations,
    /// The registry's formula functions (the camera's `in_view`, ...) for conditions.
    functions: Vec<kpl_mtl::Function>,
    /// The links built for this run.
    links: Vec<String>,
    engine: Option<Anchoring>,
}

#[derive(Debug, Clone)]
struct SharedHandle(Arc<Mutex<Shared>>);

impl SharedHandle {
    fn get(ctx: &mut BuildContext<'_>) -> SharedHandle {
        let (spec, spec_dir) = (ctx.spec, ctx.spec_dir);
        let implementations = ctx.registry.extension::<Implementations>().cloned().unwrap_or_default();
        let functions = ctx.registry.functions().to_vec();
        ctx.shared
            .get_or_insert_with(|| {
                SharedHandle(Arc::new(Mutex::new(Shared {
                    spec: spec.clone(),
                    spec_dir: spec_dir.to_path_buf(),
                    implementations,
                    functions,
                    links: Vec::new(),
                    engine: None,
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
                implementations: self.implementations.clone(),
                networks: Networks::default().with_base_dir(&self.spec_dir),
                functions: self.functions.clone(),
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
}

/// What a link process achieved, counted from the changes of its own decisions: the run's result
/// (`kpl run` prints it; summary.json has it under each link's `results`).
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
    fn count(&mut self, change: &kpl_anchor::Change) {
        use kpl_anchor::{Cause, ChangeKind};
        match (change.kind, change.cause) {
            (ChangeKind::Created, Cause::Establish) => self.established += 1,
            (ChangeKind::Linked, Cause::Reestablish) => self.reestablished += 1,
            (ChangeKind::Unlinked, Cause::Maintain) => self.dropped += 1,
            _ => {}
        }
    }
}

/// What an input port of a link process carries.
#[derive(Debug, Clone)]
enum Port {
    /// `from` objects, from the stream of this name.
    From(Arc<str>),
    /// The link unit's extra input of this index.
    Extra(usize),
    /// A stream its conditions or the forget conditions of its type name, by that name.
    Env(Arc<str>),
}

/// A link process of the runtime: a synchronized unit over its input streams.
struct RuntimeLinkProcess {
    name: String,
    ports: Vec<Port>,
    n_extra: usize,
    shared: SharedHandle,
    /// The run's counters for this process: the per-object instances the link process created
    /// and removed are reported there, and the engine's warnings are counted as its errors.
    stats: Arc<kpl_runtime::stats::ProcessStats>,
    /// What its decisions achieved so far.
    tally: Tally,
}

impl RuntimeLinkProcess {
    /// Copies the engine's count of per-object instances and what the link achieved into the
    /// run's statistics.
    fn count_instances(&self, engine: &Anchoring) {
        use std::sync::atomic::Ordering;
        if let Some(stats) = engine.link_stats(&self.name) {
            self.stats.instances_created.store(stats.instances_created, Ordering::Relaxed);
            self.stats.instances_removed.store(stats.instances_removed, Ordering::Relaxed);
        }
        let tally = self.tally;
        let to = engine.link_to_type(&self.name).unwrap_or("linked");
        self.stats.result(&format!("new {to} objects (establish)"), tally.established);
        self.stats
            .result(&format!("links reestablished: a waiting {to} kept its symbol"), tally.reestablished);
        self.stats.result("links dropped (maintain became false)", tally.dropped);
    }
}

impl Unit for RuntimeLinkProcess {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let Trigger::State = input.trigger else { return Ok(()) };
        let mut from = Vec::new();
        let mut extra = vec![None; self.n_extra];
        let mut env = Vec::new();
        for (port, sample) in self.ports.iter().zip(input.values) {
            let Some(sample) = sample else { continue };
            match port {
                Port::From(stream) => {
                    from.push(FromSnapshot { stream, valid: sample.valid, objects: &sample.value })
                }
                Port::Extra(i) => extra[*i] = Some(sample.value.clone()),
                Port::Env(name) => env.push((&**name, &sample.value)),
            }
        }
        let mut shared = self.shared.lock()?;
        let engine = shared.engine()?;
        let output = engine
            .step_link_env(&self.name, input.valid, &from, &extra, &env)
            .map_err(|e| ProcessError::failed(format!("anchoring: {e}")))?;
        let objects = engine
            .link_to_type(&self.name)
            .and_then(|ty| engine.snapshot(ty))
            .unwrap_or_else(|| Value::List(Vec::new().into()));
        out.emit_at(input.valid, objects);
        if !output.changes.is_empty() {
            out.emit_port("changes", input.valid, output.changes_value());
        }
        for change in output.changes.iter().filter(|c| c.link.as_deref() == Some(self.name.as_str())) {
            self.tally.count(change);
        }
        for warning in &output.warnings {
            self.stats.error(format!("at {}: {}", warning.time, warning.message));
        }
        if output.suppressed_warnings > 0 {
            self.stats.error(format!(
                "at {}: {} more warnings of this step",
                input.valid, output.suppressed_warnings
            ));
        }
        self.count_instances(engine);
        Ok(())
    }
}

fn build_link(ctx: &mut BuildContext<'_>) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    let hir::ProcessKind::Link(link) = &ctx.process.kind else {
        return Err(ctx.error("not a link"));
    };
    let name = ctx.process.name.clone();
    let mut n_extra = 0;
    let ports = ctx
        .process
        .inputs
        .iter()
        .map(|i| {
            if i.port == "from" {
                Port::From(Arc::from(i.stream.name.as_str()))
            } else if i.port == "env" {
                Port::Env(Arc::from(i.stream.name.as_str()))
            } else {
                n_extra += 1;
                Port::Extra(n_extra - 1)
            }
        })
        .collect();
    let known = ctx.registry.extension::<Implementations>().and_then(|i| i.link_unit(&link.via.entry));
    if known.is_none() {
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
    Ok(Box::new(SyncUnit(RuntimeLinkProcess {
        name,
        ports,
        n_extra,
        shared,
        stats,
        tally: Tally::default(),
    })))
}

/// `anchor.world_model`: emits the run's world model, at the valid time of each sample of its
/// trigger (a link's output: the world model once that link has stepped).
struct WorldModel {
    shared: SharedHandle,
}

impl Unit for WorldModel {
    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let Trigger::Sample(_) = input.trigger else { return Ok(()) };
        let mut shared = self.shared.lock()?;
        let world = shared.engine()?.world_model();
        out.emit_at(input.valid, world);
        Ok(())
    }
}

fn build_world_model(
    ctx: &mut BuildContext<'_>,
) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    let shared = SharedHandle::get(ctx);
    Ok(Box::new(SyncUnit(WorldModel { shared })))
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
    let functions = kpl_semantic::registry::Registry::with_builtin_functions();
    Ok(Box::new(SyncUnit(Identify { shared, functions })))
}
