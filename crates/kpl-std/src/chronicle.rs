//! Chronicles on the runtime: the adapter of the pure recogniser (`kpl-chronicle`).
//!
//! Every `chronicle` of a spec is a process (its recogniser) whose output stream, named after the
//! chronicle, carries one sample per recognition: `{PARAM: SYMBOL, ..., verdict: true, start: µs,
//! end: µs, times: [µs, ...]}` (the objects bound to the parameters, the time of its first and
//! last event, the time of each event in the order written), at the valid time of its last event.
//! A sink records it like a monitor's episodes, and `kpl situations` scores it like them.
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
//! Memory: the recogniser keeps at most `max_instances` (10,000) partial instances per chronicle
//! (refusals are counted in the run's summary) and the events of the last window for its
//! conditions; this adapter keeps one bit per predicate and tuple of present objects (`n^k` for
//! `n` objects and a predicate over `k` parameters). Monitors' verdicts as events are not fed yet
//! (`kpl check` says so with W0205): such an event never occurs.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::sync::Arc;

use kpl_chronicle::fluent;
use kpl_chronicle::model::{Chronicle, Event, Hold, Never, Pattern, SourceId};
use kpl_chronicle::recognise::{Config, Recogniser, Recognition};
use kpl_core::{Record, Time, TimeUnit, Value, ValueType};
use kpl_mtl::{Context, Formula, Progressor, SlotState};
use kpl_runtime::Registry;
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_runtime::stats::ProcessStats;
use kpl_semantic::hir::{self, HYSTERESIS};

/// Chronicle recognisers are built by this adapter.
pub(crate) fn register(registry: &mut Registry) {
    registry.set_chronicle_processes(|ctx| Ok(Box::new(SyncUnit(build(ctx)?))));
}

/// A predicate over some parameters of a chronicle, evaluated for tuples of objects.
struct Predicate {
    source: SourceId,
    progressor: Progressor,
    /// `hysteresis(ENTER, LEAVE)`: `progressor` is ENTER, this is LEAVE (`kpl_chronicle::fluent`).
    leave: Option<Progressor>,
    /// Per position: the slot the object goes into and the object type of the parameter.
    slots: Vec<(usize, String)>,
    slot_count: usize,
    /// The value of each tuple of present objects at the previous state.
    last: HashMap<Vec<Arc<str>>, bool>,
}

/// Numbers event sources and compiles the predicates of a set of chronicles.
struct Builder<'a> {
    registry: &'a Registry,
    predicates: Vec<Predicate>,
    next: u32,
    /// Chronicle name -> the source of its recognitions.
    chronicle_sources: BTreeMap<String, SourceId>,
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
        let mut ctx = Context::new(TimeUnit::Us, hir::SPEC_TICK);
        for function in self.registry.functions() {
            ctx.register_function(function.clone());
        }
        let slots: Vec<(usize, String)> = args
            .iter()
            .map(|&a| (ctx.declare_value(&c.params[a].0) as usize, c.params[a].1.clone()))
            .collect();
        let mut compile = |expr: &kpl_syntax::ast::Expr| {
            Formula::from_ast(expr, &mut ctx).map(|f| Progressor::new(Arc::new(f))).map_err(|errors| {
                let messages: Vec<String> = errors.iter().map(ToString::to_string).collect();
                format!("chronicle `{}`: {}", c.name, messages.join("; "))
            })
        };
        let (progressor, leave) = match &expr.kind {
            kpl_syntax::ast::ExprKind::Call { func, args } if func.name == HYSTERESIS && args.len() == 2 => {
                (compile(&args[0])?, Some(compile(&args[1])?))
            }
            _ => (compile(expr)?, None),
        };
        let source = self.fresh();
        self.predicates.push(Predicate {
            source,
            progressor,
            leave,
            slots,
            slot_count: ctx.slot_names().len(),
            last: HashMap::new(),
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
            // Never fed (W0205): a source no event comes from.
            hir::EventSource::Monitor(_) => Ok(self.fresh()),
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

fn build(ctx: &mut BuildContext<'_>) -> Result<ChronicleUnit, BuildError> {
    let hir::ProcessKind::Chronicle(name) = &ctx.process.kind else {
        return Err(ctx.error("planned as a chronicle, but it is not one"));
    };
    let chronicles = closure(ctx.spec, name).map_err(|e| ctx.error(e))?;
    let mut builder = Builder {
        registry: ctx.registry,
        predicates: Vec::new(),
        next: 0,
        chronicle_sources: BTreeMap::new(),
    };
    let mut compiled = Vec::new();
    for c in &chronicles {
        let model = builder.chronicle(c).map_err(|e| ctx.error(e))?;
        compiled.push(model.compile().map_err(|e| ctx.error(e.to_string()))?);
    }
    let own = compiled.len() - 1;
    let recogniser = Recogniser::new(compiled, Config::default()).map_err(|e| ctx.error(e.to_string()))?;
    // Which inputs carry objects of which type.
    let input_types: Vec<Option<String>> = ctx
        .process
        .inputs
        .iter()
        .map(|i| match &i.stream.ty {
            ValueType::List(item) => match item.as_ref() {
                ValueType::Record(r) => Some(r.name.to_string()),
                _ => None,
            },
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
    let params = chronicles[own].params.iter().map(|(p, _)| Arc::from(p.as_str())).collect();
    Ok(ChronicleUnit {
        predicates: builder.predicates,
        recogniser,
        own,
        params,
        feeds,
        stats: ctx.stats.clone(),
        undecided_warned: false,
    })
}

struct ChronicleUnit {
    predicates: Vec<Predicate>,
    recogniser: Recogniser<Arc<str>>,
    /// The index of this process's chronicle in the recogniser (the others are those it uses).
    own: usize,
    params: Vec<Arc<str>>,
    /// Object type -> the inputs whose objects are of it (or of a subtype).
    feeds: BTreeMap<String, Vec<usize>>,
    stats: Arc<ProcessStats>,
    undecided_warned: bool,
}

/// The present objects of one type (those with a symbol, each symbol once).
type Objects<'v> = Vec<(Arc<str>, &'v Value)>;

impl ChronicleUnit {
    fn objects<'v>(
        &self,
        values: &'v [Option<kpl_runtime::sample::Sample>],
    ) -> BTreeMap<String, Objects<'v>> {
        let mut out = BTreeMap::new();
        for (ty, inputs) in &self.feeds {
            let mut objects: Objects<'v> = Vec::new();
            let mut seen: HashSet<&'v str> = HashSet::new();
            for &i in inputs {
                let Some(sample) = values.get(i).and_then(Option::as_ref) else { continue };
                let Value::List(items) = &sample.value else { continue };
                for item in items.iter() {
                    let Value::Record(record) = item else { continue };
                    let Some(id) = &record.id else { continue };
                    if seen.insert(id) {
                        objects.push((id.clone(), item));
                    }
                }
            }
            out.insert(ty.clone(), objects);
        }
        out
    }

    /// The events of every predicate at `valid`: its changes since the previous state.
    fn events(&mut self, valid: Time, objects: &BTreeMap<String, Objects<'_>>) -> Vec<Event<Arc<str>>> {
        let mut events = Vec::new();
        let mut undecided = 0u64;
        for p in &mut self.predicates {
            let domains: Vec<&[(Arc<str>, &Value)]> =
                p.slots.iter().map(|(_, ty)| objects.get(ty).map_or(&[][..], Vec::as_slice)).collect();
            let mut now: HashMap<Vec<Arc<str>>, bool> = HashMap::with_capacity(p.last.len());
            let mut state = SlotState { values: vec![None; p.slot_count], objects: Vec::new() };
            for_each_tuple(&domains, &mut |tuple: &[usize]| {
                let ids: Vec<Arc<str>> = tuple.iter().zip(&domains).map(|(&k, d)| d[k].0.clone()).collect();
                for ((slot, _), (&k, d)) in p.slots.iter().zip(tuple.iter().zip(&domains)) {
                    state.values[*slot] = Some(d[k].1.clone());
                }
                let mut eval = |progressor: &mut Progressor| {
                    progressor.reset();
                    match progressor.step(valid, &state) {
                        Ok(Some(v)) => v,
                        Ok(None) => {
                            undecided += 1;
                            false
                        }
                        Err(e) => {
                            self.stats.error(format!("at {valid}: {e}"));
                            false
                        }
                    }
                };
                let enter = eval(&mut p.progressor);
                let value = match &mut p.leave {
                    None => enter,
                    Some(leave) => {
                        let previous = p.last.get(&ids).copied().unwrap_or(false);
                        fluent::step(previous, enter, eval(leave))
                    }
                };
                now.insert(ids, value);
            });
            let mut changes: Vec<(Vec<Arc<str>>, bool)> = Vec::new();
            for (ids, &value) in &now {
                if p.last.get(ids).copied().unwrap_or(false) != value {
                    changes.push((ids.clone(), value));
                }
            }
            for (ids, &value) in &p.last {
                if value && !now.contains_key(ids) {
                    changes.push((ids.clone(), false));
                }
            }
            changes.sort();
            events.extend(changes.into_iter().map(|(args, value)| Event {
                source: p.source,
                args,
                value,
                time: valid,
            }));
            p.last = now;
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
        self.stats.result("partial instances at most", s.peak_instances as u64);
        self.stats.result("partial instances expired", s.expired);
        self.stats.result("instances refused (max_instances reached)", s.refused);
        self.stats.result("complete instances failing a hold/never condition", s.failed_conditions);
    }
}

/// Calls `f` with every tuple of indices into `domains` whose objects are distinct.
fn for_each_tuple(domains: &[&[(Arc<str>, &Value)]], f: &mut dyn FnMut(&[usize])) {
    fn go(domains: &[&[(Arc<str>, &Value)]], tuple: &mut Vec<usize>, f: &mut dyn FnMut(&[usize])) {
        let depth = tuple.len();
        if depth == domains.len() {
            f(tuple);
            return;
        }
        for k in 0..domains[depth].len() {
            let id = &domains[depth][k].0;
            if tuple.iter().enumerate().any(|(d, &j)| domains[d][j].0 == *id) {
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
        let events = self.events(input.valid, &objects);
        match self.recogniser.step(input.valid, events) {
            Ok(found) => {
                for r in found.iter().filter(|r| r.chronicle == self.own) {
                    out.emit_at(r.valid_time, self.recognition(r));
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
