//! Monitors: a formula progressed over the state stream of the streams it names; each verdict is
//! a sample of the monitor's output stream.
//!
//! The formula is progressed from the first state. When its verdict is certain it is emitted
//! (valid time: the state at which it became certain) and the monitor starts over from the next
//! state, so `always (speed < 25.0)` reports `false` at every violation; a violation that lasts
//! over consecutive states is one decision, reported at its first state. At the end of the
//! streams the open formula is closed with finite-trace semantics and its verdict emitted at the
//! last state's time. Objects quantified over (`forall c: Car . ...`) are the records of the
//! latest snapshot of each producer of that type.
//!
//! A monitor whose formula is `forall x: T . φ` keeps one progression of φ per object of `T` (a
//! binding), started at the object's first state and closed at its last (the first state it is
//! missing from, or the end); `forall a: T . forall b: U . φ` keeps one per pair of distinct
//! objects. Each binding reports *episodes*: equal verdicts decided one after the other (the
//! progression starting over at the state after each) are one episode, reported once when it ends
//! (another verdict, the binding's last state, or the end), as `{a: SYMBOL, b: SYMBOL, verdict:
//! BOOL, start: µs, end: µs}`, with the valid time at which its first verdict was decided. A `true` episode of a situation
//! formula is a recognised situation, from its first state to the state it was decided. With no
//! object there is nothing to report (a plain progression would report the vacuous `true` at
//! every state). A pair monitor whose body requires the pair to be close ([`gate`]) progresses
//! only the pairs within that distance (and those whose progression is open), found with a grid.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;

use kpl_core::{Record, Time, TimeUnit, Value};
use kpl_mtl::{Context, Formula, Progressor, SlotState};
use kpl_semantic::hir;

mod gate;

use crate::process::{Emitter, Input, ProcessError, Unit};
use crate::registry::{BuildError, Registry};
use crate::stats::ProcessStats;

enum Role {
    Slot(usize),
    Domain(usize),
}

pub(crate) struct MonitorUnit {
    roles: Vec<Role>,
    slots: usize,
    domains: usize,
    stats: Arc<ProcessStats>,
    mode: Mode,
}

enum Mode {
    /// One progression of the whole formula.
    Whole(Open),
    /// `forall x: T . φ`: one progression of φ per object of `T`.
    PerBinding(Bindings),
}

/// A progression and the valid time of its last state (while its verdict is open).
struct Open {
    progressor: Progressor,
    last_valid: Option<Time>,
    /// The verdict decided at the previous state, if one was: the same verdict decided again at
    /// the next state (a violation that lasts) is one decision, reported once.
    repeat: Option<bool>,
}

impl Open {
    fn new(formula: &Arc<Formula>) -> Open {
        Open { progressor: Progressor::new(formula.clone()), last_valid: None, repeat: None }
    }

    /// Steps through one state: the verdict to report, when it became certain (the progression
    /// then starts over from the next state) and was not already decided at the previous state.
    fn step(&mut self, valid: Time, state: &SlotState, stats: &ProcessStats) -> Option<bool> {
        match self.progressor.step(valid, state) {
            Ok(Some(verdict)) => {
                self.progressor.reset();
                self.last_valid = None;
                let repeated = self.repeat == Some(verdict);
                self.repeat = Some(verdict);
                (!repeated).then_some(verdict)
            }
            Ok(None) => {
                self.last_valid = Some(valid);
                self.repeat = None;
                None
            }
            Err(e) => {
                stats.error(format!("at {valid}: {e}"));
                self.repeat = None;
                None
            }
        }
    }

    /// Closes the open progression (finite-trace semantics): its verdict and the time of its
    /// last state, if it had any state since its last verdict.
    fn close(&mut self) -> Option<(Time, bool)> {
        let last = self.last_valid.take()?;
        self.progressor.finish().map(|verdict| (last, verdict))
    }
}

/// A verdict that lasted: equal verdicts decided one after the other (each progression starting
/// at the state after the previous verdict) from `start` to `end`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Episode {
    verdict: bool,
    start: Time,
    end: Time,
    /// When its first verdict was decided: the valid time of the episode's sample.
    decided: Time,
}

/// The progression of one binding and the episode it has not reported yet.
struct Binding {
    progressor: Progressor,
    /// The first state of the open progression.
    started: Option<Time>,
    /// The last state of the open progression.
    last_valid: Option<Time>,
    pending: Option<Episode>,
}

impl Binding {
    fn new(formula: &Arc<Formula>) -> Binding {
        Binding {
            progressor: Progressor::new(formula.clone()),
            started: None,
            last_valid: None,
            pending: None,
        }
    }

    /// Whether no progression is open (the last state decided a verdict).
    fn idle(&self) -> bool {
        self.started.is_none()
    }

    /// Adds a verdict decided at `end` by the progression that began at `start`: the episode that
    /// ended, if this verdict differs from the pending one.
    fn decided(&mut self, verdict: bool, start: Time, end: Time) -> Option<Episode> {
        match &mut self.pending {
            Some(episode) if episode.verdict == verdict => {
                episode.end = end;
                None
            }
            pending => pending.replace(Episode { verdict, start, end, decided: end }),
        }
    }

    fn step(&mut self, valid: Time, state: &SlotState, stats: &ProcessStats) -> Option<Episode> {
        match self.progressor.step(valid, state) {
            Ok(Some(verdict)) => {
                self.progressor.reset();
                let start = self.started.take().unwrap_or(valid);
                self.last_valid = None;
                self.decided(verdict, start, valid)
            }
            Ok(None) => {
                self.started.get_or_insert(valid);
                self.last_valid = Some(valid);
                None
            }
            Err(e) => {
                stats.error(format!("at {valid}: {e}"));
                None
            }
        }
    }

    /// Closes the open progression (finite-trace semantics): the episodes still to report.
    fn close(&mut self) -> Vec<Episode> {
        let mut out = Vec::new();
        if let (Some(start), Some(last)) = (self.started.take(), self.last_valid.take())
            && let Some(verdict) = self.progressor.finish()
            && let Some(done) = self.decided(verdict, start, last)
        {
            out.push(done);
        }
        out.extend(self.pending.take());
        out
    }
}

/// One variable of the bindings: its name (a field of each verdict), its slot in the state and
/// the domain of its type.
struct Var {
    name: Arc<str>,
    slot: usize,
    domain: usize,
}

/// The bindings of `forall x: T . φ` (by object symbol) or `forall a: T . forall b: U . φ` (by
/// pairs of distinct objects), ordered so that a run is reproducible.
struct Bindings {
    body: Arc<Formula>,
    vars: Vec<Var>,
    /// Pairs farther apart than this are not progressed (see [`gate`]).
    gate: Option<f64>,
    open: BTreeMap<Vec<Arc<str>>, Binding>,
}

/// The symbols and positions of one domain's objects at a state.
struct Present {
    ids: Vec<Arc<str>>,
    index: Vec<usize>,
    pos: Vec<Option<[f64; 2]>>,
}

fn present(objects: &[Value]) -> Present {
    let mut out = Present { ids: Vec::new(), index: Vec::new(), pos: Vec::new() };
    for (k, object) in objects.iter().enumerate() {
        let Value::Record(record) = object else { continue };
        let Some(id) = record.id.clone() else { continue };
        out.ids.push(id);
        out.index.push(k);
        out.pos.push(record.get("pos").and_then(Value::as_vec2));
    }
    out
}

impl Bindings {
    fn verdict(&self, ids: &[Arc<str>], episode: Episode) -> Value {
        let mut fields: Vec<(Arc<str>, Value)> =
            self.vars.iter().zip(ids).map(|(var, id)| (var.name.clone(), Value::Str(id.clone()))).collect();
        fields.push((Arc::from("verdict"), Value::Bool(episode.verdict)));
        fields.push((Arc::from("start"), Value::Int(episode.start)));
        fields.push((Arc::from("end"), Value::Int(episode.end)));
        Value::Record(Arc::new(Record { id: None, fields }))
    }

    fn report(&self, ids: &[Arc<str>], episodes: impl IntoIterator<Item = Episode>, out: &mut Emitter) {
        for episode in episodes {
            out.emit_at(episode.decided, self.verdict(ids, episode));
        }
    }

    /// The tuples to progress at this state (ordered): every object (one variable), or the pairs
    /// of distinct objects within the gate (two).
    fn candidates(&self, present: &[Present]) -> BTreeSet<Vec<(usize, usize)>> {
        let mut out = BTreeSet::new();
        match self.vars.as_slice() {
            [_] => out.extend((0..present[0].ids.len()).map(|i| vec![(0, i)])),
            [a, b] => {
                let (pa, pb) = (&present[0], &present[1]);
                let distinct = |i: usize, j: usize| a.domain != b.domain || pa.ids[i] != pb.ids[j];
                match self.gate {
                    Some(radius) => {
                        let mut grid = gate::Grid::new(radius);
                        for (j, pos) in pb.pos.iter().enumerate() {
                            if let Some(p) = pos {
                                grid.insert(j, *p);
                            }
                        }
                        let mut near = Vec::new();
                        for (i, pos) in pa.pos.iter().enumerate() {
                            let Some(p) = pos else { continue };
                            near.clear();
                            grid.near(*p, |j| pb.pos.get(j).copied().flatten(), &mut near);
                            out.extend(
                                near.iter().filter(|&&j| distinct(i, j)).map(|&j| vec![(0, i), (1, j)]),
                            );
                        }
                    }
                    None => {
                        for i in 0..pa.ids.len() {
                            out.extend(
                                (0..pb.ids.len()).filter(|&j| distinct(i, j)).map(|j| vec![(0, i), (1, j)]),
                            );
                        }
                    }
                }
            }
            _ => {}
        }
        out
    }

    /// Steps the bindings of the objects present (those within the gate, and those with an open
    /// progression); closes those of objects that are gone, and idle pairs that left the gate.
    fn step(&mut self, valid: Time, mut state: SlotState, stats: &ProcessStats, out: &mut Emitter) {
        let present: Vec<Present> = self.vars.iter().map(|v| present(&state.objects[v.domain])).collect();
        let lookup: Vec<HashMap<&Arc<str>, usize>> =
            present.iter().map(|p| p.ids.iter().enumerate().map(|(i, id)| (id, i)).collect()).collect();
        let mut keys: BTreeMap<Vec<Arc<str>>, Vec<usize>> = BTreeMap::new();
        for tuple in self.candidates(&present) {
            let ids = tuple.iter().map(|&(v, i)| present[v].ids[i].clone()).collect();
            keys.insert(ids, tuple.iter().map(|&(_, i)| i).collect());
        }
        // The bindings that end first: their episodes are older than this state.
        let mut ended = Vec::new();
        for (ids, binding) in &self.open {
            if keys.contains_key(ids) {
                continue;
            }
            let positions: Option<Vec<usize>> =
                ids.iter().enumerate().map(|(v, id)| lookup[v].get(id).copied()).collect();
            match positions {
                // Present but out of the gate: progressed while its progression is open.
                Some(positions) if !binding.idle() => {
                    keys.insert(ids.clone(), positions);
                }
                _ => ended.push(ids.clone()),
            }
        }
        for ids in ended {
            if let Some(mut binding) = self.open.remove(&ids) {
                let episodes = binding.close();
                self.report(&ids, episodes, out);
            }
        }
        for (ids, positions) in keys {
            for (v, &i) in positions.iter().enumerate() {
                let var = &self.vars[v];
                state.values[var.slot] = Some(state.objects[var.domain][present[v].index[i]].clone());
            }
            let binding = self.open.entry(ids.clone()).or_insert_with(|| Binding::new(&self.body));
            if let Some(episode) = binding.step(valid, &state, stats) {
                self.report(&ids, [episode], out);
            }
        }
    }

    fn close(&mut self, out: &mut Emitter) {
        for (ids, mut binding) in std::mem::take(&mut self.open) {
            let episodes = binding.close();
            self.report(&ids, episodes, out);
        }
    }
}

pub(crate) fn build(
    process: &hir::Process,
    monitor: &hir::Monitor,
    registry: &Registry,
    stats: Arc<ProcessStats>,
) -> Result<MonitorUnit, BuildError> {
    let error = |message: String| BuildError { process: process.name.clone(), message };
    // Time stamps are microseconds; bare interval bounds in a spec are milliseconds.
    let mut ctx = Context::new(TimeUnit::Us, hir::SPEC_TICK);
    for function in registry.functions() {
        ctx.register_function(function.clone());
    }
    let mut roles = Vec::with_capacity(process.inputs.len());
    for input in &process.inputs {
        if input.port == "objects" {
            let ty = match &input.stream.ty {
                kpl_core::ValueType::List(item) => match item.as_ref() {
                    kpl_core::ValueType::Record(r) => r.name.to_string(),
                    _ => return Err(error(format!("stream `{}` does not carry objects", input.stream.name))),
                },
                _ => return Err(error(format!("stream `{}` does not carry objects", input.stream.name))),
            };
            let domain = ctx.domain(&ty).unwrap_or_else(|| ctx.declare_object_type(&ty));
            roles.push(Role::Domain(domain as usize));
        } else {
            let slot = ctx.slot(&input.stream.name).unwrap_or_else(|| ctx.declare_value(&input.stream.name));
            roles.push(Role::Slot(slot as usize));
        }
    }
    for ty in &monitor.object_types {
        if ctx.domain(ty).is_none() {
            ctx.declare_object_type(ty);
        }
    }
    let compile = |expr: &kpl_syntax::ast::Expr, ctx: &mut Context| {
        Formula::from_ast(expr, ctx).map(Arc::new).map_err(|errors| {
            let messages: Vec<String> = errors.iter().map(ToString::to_string).collect();
            error(format!("formula: {}", messages.join("; ")))
        })
    };
    let (vars, body) = hir::monitor_bindings(&monitor.formula);
    let mode = if !vars.is_empty() && vars.iter().all(|(var, _)| ctx.slot(var).is_none()) {
        // Each variable becomes a named value of the state, set to each object in turn.
        let vars: Vec<Var> = vars
            .iter()
            .map(|(var, ty)| {
                let domain = ctx.domain(ty).unwrap_or_else(|| ctx.declare_object_type(ty)) as usize;
                Var { name: Arc::from(*var), slot: ctx.declare_value(var) as usize, domain }
            })
            .collect();
        let gate = match vars.as_slice() {
            [a, b] => gate::pair_gate(body, &a.name, &b.name),
            _ => None,
        };
        let body = compile(body, &mut ctx)?;
        Mode::PerBinding(Bindings { body, vars, gate, open: BTreeMap::new() })
    } else {
        Mode::Whole(Open::new(&compile(&monitor.formula, &mut ctx)?))
    };
    Ok(MonitorUnit { roles, slots: ctx.slot_names().len(), domains: ctx.domain_names().len(), stats, mode })
}

impl Unit for MonitorUnit {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let mut state = SlotState { values: vec![None; self.slots], objects: vec![Vec::new(); self.domains] };
        for (role, value) in self.roles.iter().zip(input.values) {
            let Some(sample) = value else { continue };
            match role {
                Role::Slot(slot) => state.values[*slot] = Some(sample.value.clone()),
                Role::Domain(domain) => match &sample.value {
                    Value::List(items) => state.objects[*domain].extend(items.iter().cloned()),
                    record @ Value::Record(_) => state.objects[*domain].push(record.clone()),
                    _ => {}
                },
            }
        }
        match &mut self.mode {
            Mode::Whole(open) => {
                if let Some(verdict) = open.step(input.valid, &state, &self.stats) {
                    out.emit(Value::Bool(verdict));
                }
            }
            Mode::PerBinding(bindings) => bindings.step(input.valid, state, &self.stats, out),
        }
        Ok(())
    }

    fn on_end(&mut self, out: &mut Emitter) -> Result<(), ProcessError> {
        match &mut self.mode {
            Mode::Whole(open) => {
                if let Some((last, verdict)) = open.close() {
                    out.emit_at(last, Value::Bool(verdict));
                }
            }
            Mode::PerBinding(bindings) => bindings.close(out),
        }
        Ok(())
    }
}
