//! Chronicles on the runtime: the adapter of the pure recogniser (`kpl-chronicle`).
//!
//! Every `chronicle` of a spec is a process (its recogniser) whose output stream, named after the
//! chronicle, carries one sample per recognition: `{PARAM: SYMBOL, ..., verdict: true, start: µs,
//! end: µs, times: [µs, ...]}` (the objects bound to the parameters, the time of its first and
//! last event, the time of each event in the order written), at the valid time of its last event.
//! A sink records it like a monitor's episodes, and `kpl situations` scores it like them. A
//! recognition of a binding whose first event comes before the end of one already sent for that
//! binding tells of the same situation (a relation flickered) and is not sent
//! (`kpl_chronicle::merge`; the summary counts them).
//!
//! The process is synchronized over the object streams of its parameters' types (and of those of
//! the chronicles it uses, which it recognises itself, at the same instants, so that a chronicle
//! never waits for another's stream). At each state (valid time `t`) it evaluates every predicate
//! of its events and conditions for every tuple of distinct present objects of the predicate's
//! parameters' types (objects of a subtype count), and gives the recogniser the changes as events
//! at `t`: a tuple's first value counts as a change from false, and a tuple that is no longer
//! present (one of its objects is gone) becomes false. A predicate that cannot be evaluated
//! (a missing attribute) is false and counted as an error of the process. Deadlines pass with the
//! states' valid times: the recogniser is stepped at every state, with or without events.
//!
//! Gating: a predicate over two objects is evaluated for every pair of distinct present objects
//! only when nothing bounds where it can matter. Otherwise only for some pairs, which gives the
//! events of ungated evaluation wherever a recognition can use them:
//! - *Own gate*: the predicate's formula is false beyond a distance (`kpl_mtl::gate`, `Horizon::Now`,
//!   as a pair monitor's: `close(a, b, 50.0)` or `xydist(a, b) < 10.0` among its top-level
//!   conjuncts; with hysteresis, ENTER's). It is evaluated for the pairs within that distance,
//!   found with a grid, and for the pairs true at the previous state; every other pair is false.
//!   Predicates with the same gate distance over the same two object types share one grid and one
//!   list of the pairs within it per state (`pairs_within`).
//! - *A chronicle's gate*: a `hold` over the same two parameters whose own predicate has an own
//!   gate and whose `from` and `to` events come first and last in every instance (by the minimal
//!   network) keeps every event of every recognition within that distance, so the chronicle's
//!   other predicates over those two parameters (not hysteresis fluents, not holds' own) are
//!   evaluated only for the pairs within it. A pair's value beyond it is not known and no event is
//!   given there; a pair that comes within it is also evaluated on the previous state's objects,
//!   so its change at that state is exact.
//!
//! Positions are the objects' `pos`; an object without a finite one is within no gate (as for
//! monitors). `kpl bench chronicles` measures gating against evaluating every pair, and checks
//! that both recognise the same.
//!
//! Memory: the recogniser keeps at most `max_instances` (10,000) partial instances per chronicle
//! (refusals are counted in the run's summary) and the events of the last window for its
//! conditions; this adapter keeps, per predicate, the tuples true at the previous state (with a
//! chronicle's gate, every pair evaluated there) and, with a chronicle's gate, the previous
//! state's objects. Tuples are kept as numbers of objects ([`Numbers`]: a symbol has one while
//! it is present at consecutive states), so memory follows the objects present, not every object
//! the run has seen.
//!
//! Monitors' verdicts as events (`event x = monitor M(...) becomes false`): the process progresses
//! each such monitor itself, at its own states ([`MonitorVerdicts`]; its inputs include every
//! stream the monitor reads, `kpl_semantic`'s checker adds them), and a verdict that begins an
//! episode of a binding (its first, or one that differs from its last) is an event at the state
//! that decided it, with the binding's objects as its arguments. A verdict decided when a binding
//! closes is at its last state, already passed: no event.

use std::collections::{BTreeMap, HashSet};
use std::sync::Arc;

use rustc_hash::FxHashMap;
use smallvec::SmallVec;

use kpl_chronicle::fluent;
use kpl_chronicle::merge::Merge;
use kpl_chronicle::model::{Chronicle, Compiled, Event, Hold, Never, Pattern, SourceId};
use kpl_chronicle::recognise::{Config, Recogniser, Recognition};
use kpl_core::{Record, Time, TimeUnit, Value};
use kpl_mtl::gate::{GateGrid, Horizon, PairGate};

use kpl_mtl::{Context, Formula, Progressor, SlotId, State};
use kpl_runtime::Registry;
use kpl_runtime::monitor::MonitorVerdicts;
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_runtime::stats::ProcessStats;
use kpl_semantic::hir::{self, HYSTERESIS};

/// Chronicle recognisers are built by this adapter.
pub(crate) fn register(registry: &mut Registry) {
    registry.set_chronicle_processes(|ctx| process(ctx, true));
}

/// A predicate over some parameters of a chronicle, evaluated for tuples of objects.
struct Predicate {
    /// The sources of its events: one per event or condition that names it, each an alias of the
    /// first, so that a predicate written several times (the weaving chronicle's six lane
    /// departures and returns) is evaluated once per tuple.
    sources: Vec<SourceId>,
    progressor: Progressor,
    /// `hysteresis(ENTER, LEAVE)`: `progressor` is ENTER, this is LEAVE (`kpl_chronicle::fluent`).
    leave: Option<Progressor>,
    /// Per position: the slot the object goes into and the object type of the parameter.
    slots: Vec<(usize, String)>,
    /// The chronicle parameters it is over (indices, in order).
    args: Vec<usize>,
    /// Which tuples are evaluated ([`Gate`]).
    gate: Gate,
    /// The tuples that were true at the previous state (with [`Gate::Chronicle`]: every tuple
    /// evaluated there, with its value), sorted by key: a state's candidate tuples come sorted the
    /// same way, so the two are merged in one pass, with no hashing per tuple.
    last: Vec<(Key, bool)>,
}

/// A present object's number ([`Numbers`]).
type Num = u64;

/// A tuple of objects by their numbers, one per slot (inline for up to two).
type Key = SmallVec<[Num; 2]>;

/// Numbers for the symbols of the present objects. A symbol keeps its number while it is present
/// at consecutive states; one absent at a state is forgotten and gets a new number should it come
/// back. Numbers are never reused, so the previous state's tuples (`Predicate::last`) never take
/// one object for another, and what is kept is bounded by the objects of two states.
#[derive(Default)]
struct Numbers {
    now: FxHashMap<Arc<str>, Num>,
    before: FxHashMap<Arc<str>, Num>,
    /// Number -> symbol, for this state's and the previous state's objects.
    names_now: FxHashMap<Num, Arc<str>>,
    names_before: FxHashMap<Num, Arc<str>>,
    next: Num,
}

impl Numbers {
    /// Starts a state: this state's numbers become the previous state's.
    fn begin(&mut self) {
        std::mem::swap(&mut self.now, &mut self.before);
        std::mem::swap(&mut self.names_now, &mut self.names_before);
        self.now.clear();
        self.names_now.clear();
    }

    /// The number of a symbol present at this state.
    fn number(&mut self, symbol: &Arc<str>) -> Num {
        if let Some(&n) = self.now.get(symbol) {
            return n;
        }
        let n = self.before.get(symbol).copied().unwrap_or_else(|| {
            self.next += 1;
            self.next
        });
        self.now.insert(symbol.clone(), n);
        self.names_now.insert(n, symbol.clone());
        n
    }

    /// The symbol of a number of this state or the previous one.
    fn name(&self, n: Num) -> Option<&Arc<str>> {
        self.names_now.get(&n).or_else(|| self.names_before.get(&n))
    }
}

/// Which tuples of a predicate over two objects are evaluated at a state (module doc, "Gating").
#[derive(Debug, Clone, Copy, PartialEq)]
enum Gate {
    /// Every tuple.
    None,
    /// The pairs within this distance (and those true at the previous state): beyond it the
    /// predicate is false (`kpl_mtl::gate`, read off its formula).
    Own(f64),
    /// The pairs within this distance: beyond it the predicate's value matters to no
    /// recognition, since every recognition holds a predicate gated so from its first event to
    /// its last.
    Chronicle(f64),
}

/// Numbers event sources and compiles the predicates of a set of chronicles.
struct Builder<'a> {
    registry: &'a Registry,
    /// Whether predicates are gated (module doc); off, every tuple is evaluated.
    gated: bool,
    predicates: Vec<Predicate>,
    next: u32,
    /// Chronicle name -> the source of its recognitions.
    chronicle_sources: BTreeMap<String, SourceId>,
    /// Monitor name -> the source of its verdicts.
    monitor_sources: BTreeMap<String, SourceId>,
    /// (Chronicle, predicate as `kpl fmt` writes it, parameters) -> its index in `predicates`.
    written: BTreeMap<(String, String, Vec<usize>), usize>,
}

impl Builder<'_> {
    fn fresh(&mut self) -> SourceId {
        self.next += 1;
        SourceId(self.next - 1)
    }

    fn predicate(
        &mut self,
        c: &hir::Chronicle,
        expr: &kpl_syntax::ast::Expr,
        args: &[usize],
    ) -> Result<SourceId, String> {
        let mut text = String::new();
        kpl_syntax::format::expr(&mut text, expr, 0);
        let written = (c.name.clone(), text, args.to_vec());
        if let Some(&k) = self.written.get(&written) {
            let source = self.fresh();
            self.predicates[k].sources.push(source);
            return Ok(source);
        }
        let mut ctx = Context::new(TimeUnit::Us, hir::SPEC_TICK);
        for function in self.registry.functions() {
            ctx.register_function(function.clone());
        }
        let slots: Vec<(usize, String)> = args
            .iter()
            .map(|&a| (ctx.declare_value(&c.params[a].0) as usize, c.params[a].1.clone()))
            .collect();
        // The gate of ENTER (of the whole predicate without hysteresis): false beyond it.
        let mut gate = None;
        let mut compile = |expr: &kpl_syntax::ast::Expr, gated: bool| {
            let error = |errors: Vec<kpl_mtl::CompileError>| {
                let messages: Vec<String> = errors.iter().map(ToString::to_string).collect();
                format!("chronicle `{}`: {}", c.name, messages.join("; "))
            };
            let mtl = kpl_mtl::lower(expr, &mut ctx).map_err(error)?;
            if gated && let [a, b] = slots.as_slice() {
                gate = PairGate::new(&ctx, a.0 as SlotId, b.0 as SlotId).distance(&mtl, Horizon::Now);
            }
            let formula = Formula::new(&mtl, &ctx).map_err(|e| format!("chronicle `{}`: {e}", c.name))?;
            Ok::<_, String>(Progressor::new(Arc::new(formula)))
        };
        let (progressor, leave) = match &expr.kind {
            kpl_syntax::ast::ExprKind::Call { func, args } if func.name == HYSTERESIS && args.len() == 2 => {
                (compile(&args[0], true)?, Some(compile(&args[1], false)?))
            }
            _ => (compile(expr, true)?, None),
        };
        let source = self.fresh();
        self.written.insert(written, self.predicates.len());
        self.predicates.push(Predicate {
            sources: vec![source],
            progressor,
            leave,
            slots,
            args: args.to_vec(),
            gate: if self.gated { gate.map_or(Gate::None, Gate::Own) } else { Gate::None },
            last: Vec::new(),
        });
        Ok(source)
    }

    fn source(
        &mut self,
        c: &hir::Chronicle,
        source: &hir::EventSource,
        args: &[usize],
    ) -> Result<SourceId, String> {
        match source {
            hir::EventSource::Predicate(expr) => self.predicate(c, expr, args),
            hir::EventSource::Monitor(name) => match self.monitor_sources.get(name) {
                Some(&source) => Ok(source),
                None => {
                    let source = self.fresh();
                    self.monitor_sources.insert(name.clone(), source);
                    Ok(source)
                }
            },
            hir::EventSource::Chronicle(name) => self
                .chronicle_sources
                .get(name)
                .copied()
                .ok_or_else(|| format!("chronicle `{}` uses `{name}`, which is not built", c.name)),
        }
    }

    fn chronicle(&mut self, c: &hir::Chronicle) -> Result<Chronicle, String> {
        let own = self.fresh();
        let mut events = Vec::new();
        for e in &c.events {
            let source = self.source(c, &e.source, &e.args)?;
            events.push(Pattern { source, args: e.args.clone(), value: e.value });
        }
        let mut holds = Vec::new();
        for h in &c.holds {
            let source = self.predicate(c, &h.formula, &h.args)?;
            holds.push(Hold { source, args: h.args.clone(), from: h.from, to: h.to });
        }
        let mut nevers = Vec::new();
        for n in &c.nevers {
            let source = self.source(c, &n.source, &n.args)?;
            nevers.push(Never {
                pattern: Pattern { source, args: n.args.clone(), value: n.value },
                from: n.from,
                to: n.to,
            });
        }
        self.chronicle_sources.insert(c.name.clone(), own);
        Ok(Chronicle {
            name: c.name.clone(),
            source: own,
            params: c.params.len(),
            events,
            constraints: c.constraints.clone(),
            holds,
            nevers,
        })
    }
}

/// `name` and the chronicles it uses, each after those it uses.
fn closure<'s>(spec: &'s hir::Spec, name: &str) -> Result<Vec<&'s hir::Chronicle>, String> {
    fn visit<'s>(
        spec: &'s hir::Spec,
        name: &str,
        out: &mut Vec<&'s hir::Chronicle>,
        depth: usize,
    ) -> Result<(), String> {
        if out.iter().any(|c| c.name == name) {
            return Ok(());
        }
        if depth > spec.chronicles.len() {
            return Err(format!("chronicle `{name}` uses itself"));
        }
        let c = spec
            .chronicles
            .iter()
            .find(|c| c.name == name)
            .ok_or_else(|| format!("chronicle `{name}` is not in the checked spec"))?;
        let used = c.events.iter().map(|e| &e.source).chain(c.nevers.iter().map(|n| &n.source));
        for source in used {
            if let hir::EventSource::Chronicle(u) = source {
                visit(spec, u, out, depth + 1)?;
            }
        }
        out.push(c);
        Ok(())
    }
    let mut out = Vec::new();
    visit(spec, name, &mut out, 0)?;
    Ok(out)
}

/// Gives the ungated predicates of a chronicle over two parameters the gate of a `hold` over the
/// same two that spans every event (module doc, "Gating"). Hysteresis fluents keep no gate (their
/// value depends on states that were not evaluated), nor do the holds' own predicates (a hold reads
/// a fluent's value, which must be known before its `from` event).
fn gate_by_holds(model: &Compiled, predicates: &mut [Predicate]) {
    let chronicle = &model.chronicle;
    let nodes = chronicle.events.len();
    let spans = |from: usize, to: usize| {
        (0..nodes).all(|k| {
            model.minimal.lower(from, k).is_some_and(|lo| lo >= 0)
                && model.minimal.lower(k, to).is_some_and(|lo| lo >= 0)
        })
    };
    let hold_sources: HashSet<SourceId> = chronicle.holds.iter().map(|h| h.source).collect();
    let is_hold = |p: &Predicate| p.sources.iter().any(|s| hold_sources.contains(s));
    let mut radius: Option<(f64, [usize; 2])> = None;
    for hold in chronicle.holds.iter().filter(|h| spans(h.from, h.to)) {
        let Some(p) = predicates.iter().find(|p| p.sources.contains(&hold.source)) else { continue };
        if let (Gate::Own(r), [a, b]) = (p.gate, p.args.as_slice())
            && radius.is_none_or(|(best, _)| r < best)
        {
            radius = Some((r, [*a, *b]));
        }
    }
    let Some((r, pair)) = radius else { return };
    for p in predicates.iter_mut() {
        if p.gate == Gate::None && p.leave.is_none() && !is_hold(p) && p.args == pair {
            p.gate = Gate::Chronicle(r);
        }
    }
}

/// Builds the recogniser process of a chronicle; `gated: false` evaluates every tuple of objects
/// (the baseline of `kpl bench chronicles`).
pub fn process(
    ctx: &mut BuildContext<'_>,
    gated: bool,
) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    Ok(Box::new(SyncUnit(build(ctx, gated)?)))
}

fn build(ctx: &mut BuildContext<'_>, gated: bool) -> Result<ChronicleUnit, BuildError> {
    let hir::ProcessKind::Chronicle(name) = &ctx.process.kind else {
        return Err(ctx.error("planned as a chronicle, but it is not one"));
    };
    let chronicles = closure(ctx.spec, name).map_err(|e| ctx.error(e))?;
    let mut builder = Builder {
        registry: ctx.registry,
        gated,
        predicates: Vec::new(),
        next: 0,
        chronicle_sources: BTreeMap::new(),
        monitor_sources: BTreeMap::new(),
        written: BTreeMap::new(),
    };
    let mut compiled = Vec::new();
    for c in &chronicles {
        let first = builder.predicates.len();
        let model = builder
            .chronicle(c)
            .map_err(|e| ctx.error(e))?
            .compile()
            .map_err(|e| ctx.error(e.to_string()))?;
        gate_by_holds(&model, &mut builder.predicates[first..]);
        compiled.push(model);
    }
    let own = compiled.len() - 1;
    let window = compiled.iter().map(|c| c.window).max().unwrap_or(0);
    let recogniser = Recogniser::new(compiled, Config::default()).map_err(|e| ctx.error(e.to_string()))?;
    // Which inputs carry objects of which type.
    let input_types: Vec<Option<String>> = ctx
        .process
        .inputs
        .iter()
        .map(|i| match i.port.as_str() {
            "objects" => i.stream.ty.object_type().map(|r| r.name.to_string()),
            // A stream a monitor reads as a value (not as objects) is the monitor's.
            _ => None,
        })
        .collect();
    let mut param_types: Vec<String> =
        builder.predicates.iter().flat_map(|p| p.slots.iter().map(|s| s.1.clone())).collect();
    param_types.sort();
    param_types.dedup();
    let feeds: BTreeMap<String, Vec<usize>> = param_types
        .iter()
        .map(|ty| {
            let inputs = input_types
                .iter()
                .enumerate()
                .filter(|(_, t)| t.as_deref().is_some_and(|t| ctx.spec.types.is_subtype(t, ty)))
                .map(|(i, _)| i)
                .collect();
            (ty.clone(), inputs)
        })
        .collect();
    let mut monitors = Vec::new();
    for (name, &source) in &builder.monitor_sources {
        let monitor = ctx
            .spec
            .processes
            .iter()
            .find_map(|p| match &p.kind {
                hir::ProcessKind::Monitor(m) if p.name == *name => Some(m),
                _ => None,
            })
            .ok_or_else(|| ctx.error(format!("monitor `{name}` is not in the checked spec")))?;
        let verdicts = MonitorVerdicts::new(&ctx.process.inputs, monitor, ctx.registry, ctx.stats.clone())
            .map_err(|e| ctx.error(format!("monitor `{name}`: {e}")))?;
        monitors.push((source, verdicts));
    }
    let params = chronicles[own].params.iter().map(|(p, _)| Arc::from(p.as_str())).collect();
    Ok(ChronicleUnit {
        monitors,
        predicates: builder.predicates,
        recogniser,
        own,
        params,
        feeds,
        stats: ctx.stats.clone(),
        undecided_warned: false,
        previous: None,
        numbers: Numbers::default(),
        merge: Merge::new(window),
    })
}

struct ChronicleUnit {
    predicates: Vec<Predicate>,
    /// The monitors whose verdicts are events, each progressed here at this process's states.
    monitors: Vec<(SourceId, MonitorVerdicts)>,
    recogniser: Recogniser<Arc<str>>,
    /// The index of this process's chronicle in the recogniser (the others are those it uses).
    own: usize,
    params: Vec<Arc<str>>,
    /// Object type -> the inputs whose objects are of it (or of a subtype).
    feeds: BTreeMap<String, Vec<usize>>,
    stats: Arc<ProcessStats>,
    undecided_warned: bool,
    /// The previous state's valid time and objects by type and symbol, kept when a predicate has a
    /// chronicle's gate (a pair that comes within it is evaluated on them too).
    previous: Option<(Time, ObjectsByNumber)>,
    numbers: Numbers,
    /// One output sample per situation (`kpl_chronicle::merge`).
    merge: Merge<Arc<str>>,
}

/// A gate distance (its bits) and the object types of a predicate's two slots: the predicates
/// with the same one share their pairs within the gate at a state.
type GateKey<'t> = (u64, &'t str, &'t str);

/// Objects by type and number.
type ObjectsByNumber = BTreeMap<String, FxHashMap<Num, Value>>;

/// The present objects of one type (those with a symbol, each symbol once), with their numbers,
/// sorted by number.
type Objects<'v> = Vec<(Num, &'v Value)>;

impl ChronicleUnit {
    fn objects<'v>(
        &mut self,
        values: &'v [Option<kpl_runtime::sample::Sample>],
    ) -> BTreeMap<String, Objects<'v>> {
        self.numbers.begin();
        let mut out = BTreeMap::new();
        for (ty, inputs) in &self.feeds {
            let mut objects: Objects<'v> = Vec::new();
            for &i in inputs {
                let Some(sample) = values.get(i).and_then(Option::as_ref) else { continue };
                let Value::List(items) = &sample.value else { continue };
                for item in items.iter() {
                    let Value::Record(record) = item else { continue };
                    let Some(id) = &record.id else { continue };
                    objects.push((self.numbers.number(id), item));
                }
            }
            // Sorted by number (stable: a symbol's first object is kept), so that tuples of
            // indices in lexicographic order are tuples of numbers in lexicographic order.
            objects.sort_by_key(|(n, _)| *n);
            objects.dedup_by_key(|(n, _)| *n);
            out.insert(ty.clone(), objects);
        }
        out
    }

    /// The events of every predicate at `valid`: its changes since the previous state.
    fn events(&mut self, valid: Time, objects: &BTreeMap<String, Objects<'_>>) -> Vec<Event<Arc<str>>> {
        let mut events = Vec::new();
        let mut undecided = 0u64;
        let previous = self.previous.take();
        // What only a chronicle's gate needs, made only then (this runs at every state).
        let keep_previous = self.predicates.iter().any(|p| p.gate.unknown_beyond());
        let domain = |ty: &str| objects.get(ty).map_or(&[][..], Vec::as_slice);
        let (shared, within) = gate_pairs(&self.predicates, &domain);
        let mut eval =
            Evaluation { valid, previous: previous.as_ref(), undecided: &mut undecided, stats: &self.stats };
        for (p, within) in self.predicates.iter_mut().zip(within) {
            let domains: Vec<&[(Num, &Value)]> = p.slots.iter().map(|(_, ty)| domain(ty)).collect();
            let within = within.map(|k| shared[k].as_slice());
            let changes = p.changes(&domains, within, &mut eval);
            // By the objects' symbols, as the events of one state have always been ordered.
            let numbers = &self.numbers;
            let mut named: Vec<(Vec<Arc<str>>, bool)> = changes
                .into_iter()
                .filter_map(|(key, value)| {
                    let args: Option<Vec<Arc<str>>> = key.iter().map(|&n| numbers.name(n).cloned()).collect();
                    args.map(|args| (args, value))
                })
                .collect();
            named.sort();
            for &source in &p.sources {
                events.extend(named.iter().map(|(args, value)| Event {
                    source,
                    args: args.clone(),
                    value: *value,
                    time: valid,
                }));
            }
        }
        // By source (stable), as when each alias was a predicate of its own.
        events.sort_by_key(|e| e.source);
        if keep_previous {
            let kept = objects
                .iter()
                .map(|(ty, o)| (ty.clone(), o.iter().map(|(n, v)| (*n, (*v).clone())).collect()))
                .collect();
            self.previous = Some((valid, kept));
        }
        if undecided > 0 && !self.undecided_warned {
            self.undecided_warned = true;
            self.stats.warn(
                "a chronicle predicate was not decided by one state (temporal operators?): taken as false"
                    .into(),
            );
        }
        events
    }

    fn recognition(&self, r: &Recognition<Arc<str>>) -> Value {
        let mut fields: Vec<(Arc<str>, Value)> =
            self.params.iter().zip(&r.binding).map(|(p, o)| (p.clone(), Value::Str(o.clone()))).collect();
        fields.push((Arc::from("verdict"), Value::Bool(true)));
        let start = r.times.iter().copied().min().unwrap_or(r.valid_time);
        fields.push((Arc::from("start"), Value::Int(start)));
        fields.push((Arc::from("end"), Value::Int(r.valid_time)));
        let times: Arc<[Value]> = r.times.iter().map(|&t| Value::Int(t)).collect();
        fields.push((Arc::from("times"), Value::List(times)));
        Value::Record(Arc::new(Record { id: None, fields }))
    }

    fn report(&self) {
        let s = self.recogniser.stats();
        self.stats.result("recognitions", s.recognitions);
        self.stats
            .result("recognitions merged into an earlier one of the same situation", self.merge.merged());
        self.stats.result("partial instances at most", s.peak_instances as u64);
        self.stats.result("partial instances expired", s.expired);
        self.stats.result("partial instances dropped (a hold failed, or a never's event came)", s.broken);
        self.stats.result("instances refused (max_instances reached)", s.refused);
        self.stats.result("complete instances failing a hold/never condition", s.failed_conditions);
    }
}

/// The pairs within a gate, found once per gate distance and pair of object types for every
/// predicate gated so: `pairs[within[k]]` is predicate k's (`None`: not gated over two objects).
fn gate_pairs<'v>(
    predicates: &[Predicate],
    domain: &dyn Fn(&str) -> &'v [(Num, &'v Value)],
) -> (Vec<Vec<[usize; 2]>>, Vec<Option<usize>>) {
    let mut shared: Vec<(GateKey<'_>, Vec<[usize; 2]>)> = Vec::new();
    let mut within: Vec<Option<usize>> = Vec::with_capacity(predicates.len());
    for p in predicates {
        let radius = match p.gate {
            Gate::Own(r) | Gate::Chronicle(r) => Some(r),
            Gate::None => None,
        };
        let (Some(radius), [(_, ta), (_, tb)]) = (radius, p.slots.as_slice()) else {
            within.push(None);
            continue;
        };
        let key = (radius.to_bits(), ta.as_str(), tb.as_str());
        let k = match shared.iter().position(|(k, _)| *k == key) {
            Some(k) => k,
            None => {
                shared.push((key, pairs_within(radius, domain(ta), domain(tb))));
                shared.len() - 1
            }
        };
        within.push(Some(k));
    }
    (shared.into_iter().map(|(_, pairs)| pairs).collect(), within)
}

/// What evaluating the predicates at a state needs besides their objects: its valid time, the
/// previous state (its time and objects, kept when a predicate has a chronicle's gate), and
/// where to count undecided predicates and report errors.
struct Evaluation<'a> {
    valid: Time,
    previous: Option<&'a (Time, ObjectsByNumber)>,
    undecided: &'a mut u64,
    stats: &'a ProcessStats,
}

impl Predicate {
    /// Evaluates the predicate on this state's candidate tuples ([`candidates`] of `domains` and
    /// `within`) and returns its changes since the previous state, by key; `last` becomes this
    /// state's. The candidates and `last` are both sorted by key and merged in one pass:
    /// - a tuple in both: its value before is the kept one;
    /// - a candidate only: not evaluated at the previous state, so false before (beyond an own
    ///   gate, or absent), or beyond a chronicle's gate not known and evaluated now on the
    ///   previous state's objects;
    /// - kept only: true before with an own gate and its objects present, it is evaluated (with
    ///   hysteresis it may still hold beyond ENTER's gate); beyond a chronicle's gate it is not
    ///   known and no recognition needs it; otherwise an object is gone, and it becomes false.
    fn changes(
        &mut self,
        domains: &[&[(Num, &Value)]],
        within: Option<&[[usize; 2]]>,
        eval: &mut Evaluation<'_>,
    ) -> Vec<(Key, bool)> {
        use std::cmp::Ordering;
        let mut tuples = Vec::new();
        let count = candidates(domains, within, &mut tuples);
        let arity = domains.len();
        let last = std::mem::take(&mut self.last);
        let mut now: Vec<(Key, bool)> = Vec::with_capacity(count);
        let mut changes: Vec<(Key, bool)> = Vec::new();
        let mut indices: Vec<usize> = Vec::with_capacity(arity);
        let mut items: Vec<&Value> = Vec::with_capacity(arity);
        let (mut t, mut l) = (0, 0);
        while t < count || l < last.len() {
            let tuple = if t < count { &tuples[t * arity..(t + 1) * arity] } else { &[][..] };
            let key = key_of(tuple, domains);
            let order = match (t < count, last.get(l)) {
                (true, Some((kept, _))) => key.cmp(kept),
                (true, None) => Ordering::Less,
                (false, _) => Ordering::Greater,
            };
            let (key, before) = match order {
                Ordering::Equal => {
                    t += 1;
                    l += 1;
                    indices.clear();
                    indices.extend_from_slice(tuple);
                    (key, last[l - 1].1)
                }
                Ordering::Less => {
                    t += 1;
                    indices.clear();
                    indices.extend_from_slice(tuple);
                    let before = match (self.gate, eval.previous) {
                        (Gate::Chronicle(_), Some((t, before))) => {
                            let kept: Option<Vec<&Value>> = key
                                .iter()
                                .zip(&self.slots)
                                .map(|(n, (_, ty))| before.get(ty).and_then(|m| m.get(n)))
                                .collect();
                            kept.is_some_and(|kept| evaluate(self, *t, &kept, eval.undecided, eval.stats).0)
                        }
                        _ => false,
                    };
                    (key, before)
                }
                Ordering::Greater => {
                    let (key, before) = last[l].clone();
                    l += 1;
                    indices.clear();
                    let present =
                        key.iter().zip(domains).all(|(n, d)| match d.binary_search_by_key(n, |o| o.0) {
                            Ok(k) => {
                                indices.push(k);
                                true
                            }
                            Err(_) => false,
                        });
                    match (self.gate, present) {
                        (Gate::Own(_), true) if before => (key, before),
                        (Gate::Chronicle(_), true) => continue,
                        _ => {
                            if before {
                                changes.push((key, false));
                            }
                            continue;
                        }
                    }
                }
            };
            items.clear();
            items.extend(indices.iter().zip(domains).map(|(&k, d)| d[k].1));
            let (enter, leave) = evaluate(self, eval.valid, &items, eval.undecided, eval.stats);
            let value = match leave {
                None => enter,
                Some(leave) => fluent::step(before, enter, leave),
            };
            if value != before {
                changes.push((key.clone(), value));
            }
            if value || self.gate.unknown_beyond() {
                now.push((key, value));
            }
        }
        self.last = now;
        changes
    }
}

impl Gate {
    /// Whether a tuple's value beyond the gate is not known (a chronicle's gate): then the tuples
    /// evaluated false are kept for the next state ("not kept" cannot mean false), a tuple that
    /// leaves the gate gives no event, and the previous state's objects are kept.
    fn unknown_beyond(self) -> bool {
        matches!(self, Gate::Chronicle(_))
    }
}

/// The objects of one tuple as the state a predicate's formula reads: slot `slots[k].0` holds
/// `items[k]`, every other slot nothing. Borrowed, so evaluating a tuple copies no value.
struct TupleState<'a, 'v> {
    slots: &'a [(usize, String)],
    items: &'a [&'v Value],
}

impl State for TupleState<'_, '_> {
    #[inline]
    fn value(&self, slot: SlotId) -> Option<&Value> {
        let k = self.slots.iter().position(|(s, _)| *s == slot as usize)?;
        self.items.get(k).copied()
    }
}

/// ENTER's value (the predicate's) for these objects at `valid`, and LEAVE's with hysteresis. A
/// predicate that one state does not decide, or that fails, is false.
fn evaluate(
    p: &mut Predicate,
    valid: Time,
    items: &[&Value],
    undecided: &mut u64,
    stats: &ProcessStats,
) -> (bool, Option<bool>) {
    let state = TupleState { slots: &p.slots, items };
    let mut eval = |progressor: &mut Progressor| {
        progressor.reset();
        match progressor.step(valid, &state) {
            Ok(Some(v)) => v,
            Ok(None) => {
                *undecided += 1;
                false
            }
            Err(e) => {
                stats.error(format!("at {valid}: {e}"));
                false
            }
        }
    };
    let enter = eval(&mut p.progressor);
    let leave = p.leave.as_mut().map(&mut eval);
    (enter, leave)
}

/// The key of a tuple of indices into `domains`: its objects' numbers (built directly for one or
/// two objects, the common cases: this runs for every candidate tuple).
#[inline]
fn key_of(tuple: &[usize], domains: &[&[(Num, &Value)]]) -> Key {
    match (tuple, domains) {
        ([i], [da]) => Key::from_slice(&[da[*i].0]),
        ([i, j], [da, db]) => Key::from_buf([da[*i].0, db[*j].0]),
        _ => tuple.iter().zip(domains).map(|(&k, d)| d[k].0).collect(),
    }
}

/// The tuples of objects (indices into `domains`, one per slot, one tuple after the other in
/// `out`) to evaluate a predicate for at this state (module doc, "Gating"): every tuple of distinct
/// objects, or with a gate over two slots the pairs within it (`within`, [`pairs_within`] of its
/// distance and domains). Sorted, so by key, since the domains are sorted by number. Returns the
/// number of tuples (a predicate over no object has one, the empty tuple).
fn candidates(domains: &[&[(Num, &Value)]], within: Option<&[[usize; 2]]>, out: &mut Vec<usize>) -> usize {
    out.clear();
    if let (Some(within), 2) = (within, domains.len()) {
        out.extend(within.iter().flatten());
        return within.len();
    }
    let mut count = 0;
    for_each_tuple(domains, &mut |t| {
        out.extend_from_slice(t);
        count += 1;
    });
    count
}

/// The pairs of distinct objects `(i, j)` (indices into `da` and `db`) within `radius` of each
/// other, found with a grid (an object without a finite `pos` is within no gate), sorted.
fn pairs_within(radius: f64, da: &[(Num, &Value)], db: &[(Num, &Value)]) -> Vec<[usize; 2]> {
    let pos = |v: &Value| match v {
        Value::Record(r) => {
            r.get("pos").and_then(Value::as_vec2).filter(|q| q[0].is_finite() && q[1].is_finite())
        }
        _ => None,
    };
    let mut grid = GateGrid::new(radius);
    for (j, (_, v)) in db.iter().enumerate() {
        if let Some(q) = pos(v) {
            grid.insert(j, 0, q);
        }
    }
    grid.finish();
    let mut near = Vec::new();
    let mut out = Vec::new();
    for (i, (n, v)) in da.iter().enumerate() {
        let Some(q) = pos(v) else { continue };
        // Sorted: `near` gives the indices in order.
        grid.near(Some(q), &mut near);
        out.extend(near.iter().filter(|&&j| db[j].0 != *n).map(|&j| [i, j]));
    }
    out
}

/// Calls `f` with every tuple of indices into `domains` whose objects are distinct.
fn for_each_tuple(domains: &[&[(Num, &Value)]], f: &mut dyn FnMut(&[usize])) {
    fn go(domains: &[&[(Num, &Value)]], tuple: &mut Vec<usize>, f: &mut dyn FnMut(&[usize])) {
        let depth = tuple.len();
        if depth == domains.len() {
            f(tuple);
            return;
        }
        for k in 0..domains[depth].len() {
            let n = domains[depth][k].0;
            if tuple.iter().enumerate().any(|(d, &j)| domains[d][j].0 == n) {
                continue;
            }
            tuple.push(k);
            go(domains, tuple, f);
            tuple.pop();
        }
    }
    go(domains, &mut Vec::with_capacity(domains.len()), f);
}

impl Unit for ChronicleUnit {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let objects = self.objects(input.values);
        let mut events = self.events(input.valid, &objects);
        for (source, verdicts) in &mut self.monitors {
            events.extend(verdicts.step(input).into_iter().map(|d| Event {
                source: *source,
                args: d.ids.into_vec(),
                value: d.verdict,
                time: input.valid,
            }));
        }
        match self.recogniser.step(input.valid, events) {
            Ok(found) => {
                for r in found.iter().filter(|r| r.chronicle == self.own) {
                    if self.merge.admit(r) {
                        out.emit_at(r.valid_time, self.recognition(r));
                    }
                }
            }
            Err(late) => self.stats.error(late.to_string()),
        }
        self.report();
        Ok(())
    }

    fn on_end(&mut self, _out: &mut Emitter) -> Result<(), ProcessError> {
        self.report();
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    fn car(x: f64, y: f64) -> Value {
        let fields = vec![(Arc::from("pos"), Value::Vec2([x, y]))];
        Value::Record(Arc::new(Record { id: Some(Arc::from(format!("c{x}_{y}"))), fields }))
    }

    /// The pairs shared by the predicates of one gate are those every pair within the distance
    /// gives (an object never with itself, one without a finite `pos` with none), sorted as
    /// `candidates` needs them to find the pairs true before among them.
    #[test]
    fn pairs_within_a_gate_are_every_close_pair_of_distinct_objects_sorted() {
        let mut values: Vec<Value> =
            (0..60).map(|k| car(f64::from(k % 12) * 7.3, f64::from(k / 12) * 11.0)).collect();
        values.push(Value::Record(Arc::new(Record { id: Some(Arc::from("nowhere")), fields: Vec::new() })));
        values.push(car(f64::NAN, 3.0));
        let objects: Vec<(Num, &Value)> = values.iter().enumerate().map(|(k, v)| (k as Num + 1, v)).collect();
        let radius = 20.0;
        let pos = |v: &Value| match v {
            Value::Record(r) => {
                r.get("pos").and_then(Value::as_vec2).filter(|q| q[0].is_finite() && q[1].is_finite())
            }
            _ => None,
        };
        let mut expected = Vec::new();
        for (i, (n, a)) in objects.iter().enumerate() {
            for (j, (m, b)) in objects.iter().enumerate() {
                if let (Some(p), Some(q)) = (pos(a), pos(b))
                    && n != m
                    && (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) <= radius * radius
                {
                    expected.push([i, j]);
                }
            }
        }
        let found = pairs_within(radius, &objects, &objects);
        assert!(expected.len() > 60, "too few pairs to compare: {}", expected.len());
        assert_eq!(found, expected);
    }
}
