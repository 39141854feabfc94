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
//! missing from, or the end): each verdict is reported once, for its object, as
//! `{x: SYMBOL, verdict: BOOL}`. With no object there is nothing to report (a plain progression
//! would report the vacuous `true` at every state).

use std::collections::BTreeMap;
use std::sync::Arc;

use kpl_core::{Record, Time, TimeUnit, Value};
use kpl_mtl::{Context, Formula, Progressor, SlotState};
use kpl_semantic::hir;

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

/// The bindings of `forall x: T . φ`, by object symbol (ordered, so a run is reproducible).
struct Bindings {
    body: Arc<Formula>,
    /// The variable's name (a field of each verdict) and its slot in the state.
    var: Arc<str>,
    slot: usize,
    /// The domain of `T` in the state.
    domain: usize,
    open: BTreeMap<Arc<str>, Open>,
}

impl Bindings {
    fn verdict(&self, id: &Arc<str>, verdict: bool) -> Value {
        Value::Record(Arc::new(Record {
            id: None,
            fields: vec![
                (self.var.clone(), Value::Str(id.clone())),
                (Arc::from("verdict"), Value::Bool(verdict)),
            ],
        }))
    }

    /// Steps the binding of every object present; closes those of objects that are gone.
    fn step(&mut self, valid: Time, mut state: SlotState, stats: &ProcessStats, out: &mut Emitter) {
        let objects = std::mem::take(&mut state.objects[self.domain]);
        let mut present = Vec::with_capacity(objects.len());
        for object in &objects {
            let Value::Record(record) = object else { continue };
            let Some(id) = record.id.clone() else { continue };
            present.push(id.clone());
        }
        state.objects[self.domain] = objects;
        // The objects that are gone first: their last verdicts are older than this state.
        let gone: Vec<Arc<str>> = self.open.keys().filter(|id| !present.contains(id)).cloned().collect();
        for id in gone {
            if let Some(mut open) = self.open.remove(&id)
                && let Some((last, verdict)) = open.close()
            {
                out.emit_at(last, self.verdict(&id, verdict));
            }
        }
        for (k, id) in present.iter().enumerate() {
            state.values[self.slot] = Some(state.objects[self.domain][k].clone());
            let open = self.open.entry(id.clone()).or_insert_with(|| Open::new(&self.body));
            if let Some(verdict) = open.step(valid, &state, stats) {
                let value = self.verdict(id, verdict);
                out.emit(value);
            }
        }
    }

    fn close(&mut self, out: &mut Emitter) {
        for (id, mut open) in std::mem::take(&mut self.open) {
            if let Some((last, verdict)) = open.close() {
                out.emit_at(last, self.verdict(&id, verdict));
            }
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
    let mode = match monitor.binding() {
        // The variable becomes a named value of the state, set to each object in turn.
        Some((var, ty, body)) if ctx.slot(var).is_none() => {
            let domain = ctx.domain(ty).unwrap_or_else(|| ctx.declare_object_type(ty)) as usize;
            let slot = ctx.declare_value(var) as usize;
            let body = compile(body, &mut ctx)?;
            Mode::PerBinding(Bindings { body, var: Arc::from(var), slot, domain, open: BTreeMap::new() })
        }
        _ => Mode::Whole(Open::new(&compile(&monitor.formula, &mut ctx)?)),
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
