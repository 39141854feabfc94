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
//! objects (the bindings are instances of one shared `kpl_mtl::ProgressorGroup`, see
//! [`bindings`]). Each binding reports *episodes*: equal verdicts decided one after the other (the
//! progression starting over at the state after each) are one episode, reported once when it ends
//! (another verdict, the binding's last state, or the end), as `{a: SYMBOL, b: SYMBOL, verdict:
//! BOOL, start: µs, end: µs}`, with the valid time at which its first verdict was decided. A `true` episode of a situation
//! formula is a recognised situation, from its first state to the state it was decided. With no
//! object there is nothing to report (a plain progression would report the vacuous `true` at
//! every state). A pair monitor whose body requires the pair to be close now (a top-level conjunct
//! `close(a, b, d)` or `xydist(a, b) < d`: `kpl_mtl::gate`) progresses only the pairs within that
//! distance (and those whose progression is open), found with its grid.
//!
//! [`MonitorVerdicts`] is the same progression for a chronicle that has a monitor's verdicts as
//! events: it gives, at each state, the verdicts that begin an episode there, instead of reporting
//! episodes when they end.

use std::sync::Arc;

use kpl_core::{Time, TimeUnit, Value};
use kpl_mtl::gate::{Horizon, PairGate};
use kpl_mtl::{Context, Formula, Progressor, SlotId, SlotState};
use kpl_semantic::hir;

mod bindings;

use bindings::{Bindings, Var};

use crate::process::{Emitter, Input, ProcessError, Unit};
use crate::registry::{BuildError, Registry};
use crate::stats::ProcessStats;

enum Role {
    Slot(usize),
    Domain(usize),
}

/// A monitor's progression over the states of a process's inputs.
struct Engine {
    roles: Vec<Role>,
    slots: usize,
    domains: usize,
    stats: Arc<ProcessStats>,
    mode: Mode,
}

/// A monitor as a process: its verdicts (episodes, per binding) are its output stream.
pub(crate) struct MonitorUnit(Engine);

/// A monitor's verdicts as they are decided, for a chronicle that has them as events
/// (`event x = monitor M(...) becomes false`; the chronicle adapter in `kpl-std` runs one per
/// monitor it uses). It progresses the monitor over the states of the chronicle's own inputs (which
/// include every stream the monitor reads), exactly as the monitor's process does, and gives at
/// each state the verdicts that begin an episode there: a binding's first verdict, or one that
/// differs from its previous verdict. What is decided when a binding closes (its object gone, the
/// streams' end) is at the binding's last state, which the chronicle has passed; it is no event.
pub struct MonitorVerdicts {
    engine: Engine,
    /// Whole formula: the last verdict decided (an episode begins when it changes).
    last: Option<bool>,
}

pub use bindings::Decision;

impl std::fmt::Debug for MonitorVerdicts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MonitorVerdicts").field("last", &self.last).finish_non_exhaustive()
    }
}

impl MonitorVerdicts {
    /// The verdicts of `monitor` over states of a process whose inputs are `inputs` (each named
    /// stream of the monitor among them).
    pub fn new(
        inputs: &[hir::Input],
        monitor: &hir::Monitor,
        registry: &Registry,
        stats: Arc<ProcessStats>,
    ) -> Result<MonitorVerdicts, String> {
        Ok(MonitorVerdicts { engine: Engine::new(inputs, monitor, registry, stats)?, last: None })
    }

    /// Steps through the state of `input`: the verdicts that began an episode at it, in the order
    /// of their objects' symbols. A monitor without `forall` has one binding of no objects.
    pub fn step(&mut self, input: &Input<'_>) -> Vec<Decision> {
        let state = self.engine.state(input);
        match &mut self.engine.mode {
            Mode::Whole(open) => match open.step(input.valid, &state, &self.engine.stats) {
                Some(verdict) if self.last != Some(verdict) => {
                    self.last = Some(verdict);
                    vec![Decision { ids: Box::new([]), verdict }]
                }
                _ => Vec::new(),
            },
            Mode::PerBinding(bindings) => {
                bindings.step(input.valid, &state, &self.engine.stats, &mut |_, _| {})
            }
        }
    }
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

pub(crate) fn build(
    process: &hir::Process,
    monitor: &hir::Monitor,
    registry: &Registry,
    stats: Arc<ProcessStats>,
) -> Result<MonitorUnit, BuildError> {
    Engine::new(&process.inputs, monitor, registry, stats)
        .map(MonitorUnit)
        .map_err(|message| BuildError { process: process.name.clone(), message })
}

/// The message of a monitor formula that does not compile.
fn formula_error(errors: &[impl std::fmt::Display]) -> String {
    let messages: Vec<String> = errors.iter().map(ToString::to_string).collect();
    format!("formula: {}", messages.join("; "))
}

impl Engine {
    fn new(
        inputs: &[hir::Input],
        monitor: &hir::Monitor,
        registry: &Registry,
        stats: Arc<ProcessStats>,
    ) -> Result<Engine, String> {
        // Time stamps are microseconds; bare interval bounds in a spec are milliseconds.
        let mut ctx = Context::new(TimeUnit::Us, hir::SPEC_TICK);
        for function in registry.functions() {
            ctx.register_function(function.clone());
        }
        let mut roles = Vec::with_capacity(inputs.len());
        for input in inputs {
            if input.port == "objects" {
                let ty = input
                    .stream
                    .ty
                    .object_type()
                    .ok_or_else(|| format!("stream `{}` does not carry objects", input.stream.name))?
                    .name
                    .to_string();
                let domain = ctx.domain(&ty).unwrap_or_else(|| ctx.declare_object_type(&ty));
                roles.push(Role::Domain(domain as usize));
            } else {
                let slot =
                    ctx.slot(&input.stream.name).unwrap_or_else(|| ctx.declare_value(&input.stream.name));
                roles.push(Role::Slot(slot as usize));
            }
        }
        for ty in &monitor.object_types {
            if ctx.domain(ty).is_none() {
                ctx.declare_object_type(ty);
            }
        }
        let compile = |expr: &kpl_syntax::ast::Expr, ctx: &mut Context| {
            Formula::from_ast(expr, ctx).map(Arc::new).map_err(|errors| formula_error(&errors))
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
            let mtl = kpl_mtl::lower(body, &mut ctx).map_err(|errors| formula_error(&errors))?;
            let gate = match vars.as_slice() {
                [a, b] => {
                    PairGate::new(&ctx, a.slot as SlotId, b.slot as SlotId).distance(&mtl, Horizon::Now)
                }
                _ => None,
            };
            let body = Formula::new(&mtl, &ctx).map_err(|e| format!("formula: {e}"))?;
            Mode::PerBinding(Bindings::new(Arc::new(body), vars, gate))
        } else {
            Mode::Whole(Open::new(&compile(&monitor.formula, &mut ctx)?))
        };
        Ok(Engine { roles, slots: ctx.slot_names().len(), domains: ctx.domain_names().len(), stats, mode })
    }

    /// The state of one synchronized input: the named streams' values and the objects by type.
    fn state(&self, input: &Input<'_>) -> SlotState {
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
        state
    }
}

impl Unit for MonitorUnit {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let engine = &mut self.0;
        let state = engine.state(input);
        match &mut engine.mode {
            Mode::Whole(open) => {
                if let Some(verdict) = open.step(input.valid, &state, &engine.stats) {
                    out.emit(Value::Bool(verdict));
                }
            }
            Mode::PerBinding(bindings) => {
                bindings.step(input.valid, &state, &engine.stats, &mut |at, value| out.emit_at(at, value));
            }
        }
        Ok(())
    }

    fn on_end(&mut self, out: &mut Emitter) -> Result<(), ProcessError> {
        match &mut self.0.mode {
            Mode::Whole(open) => {
                if let Some((last, verdict)) = open.close() {
                    out.emit_at(last, Value::Bool(verdict));
                }
            }
            Mode::PerBinding(bindings) => bindings.close(&mut |at, value| out.emit_at(at, value)),
        }
        Ok(())
    }
}
