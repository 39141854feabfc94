//! Monitors: a formula progressed over the state stream of the streams it names; each verdict is
//! a sample of the monitor's output stream.
//!
//! The formula is progressed from the first state. When its verdict is certain it is emitted
//! (valid time: the state at which it became certain) and the monitor starts over from the next
//! state, so `always (speed < 25.0)` reports `false` at every violation. At the end of the
//! streams the open formula is closed with finite-trace semantics and its verdict emitted at the
//! last state's time. Objects quantified over (`forall c: Car . ...`) are the records of the
//! latest snapshot of each producer of that type.
//!
//! One `Progressor` serves the monitor's whole life: starting over keeps what its engine learnt
//! (the residuals and their cached transitions), and the objects of a quantifier that are in the
//! same situation share one residual and its transitions (see `kpl_mtl`), so a monitor over
//! thousands of cars progresses each distinct situation once per state.

use std::sync::Arc;

use kpl_core::{TimeUnit, Value};
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
    progressor: Progressor,
    roles: Vec<Role>,
    /// The state handed to the progressor, refilled at every input.
    state: SlotState,
    stats: Arc<ProcessStats>,
    last_valid: Option<kpl_core::Time>,
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
    let formula = Formula::from_ast(&monitor.formula, &mut ctx).map_err(|errors| {
        let messages: Vec<String> = errors.iter().map(ToString::to_string).collect();
        error(format!("formula: {}", messages.join("; ")))
    })?;
    Ok(MonitorUnit {
        progressor: Progressor::new(Arc::new(formula)),
        roles,
        state: SlotState {
            values: vec![None; ctx.slot_names().len()],
            objects: vec![Vec::new(); ctx.domain_names().len()],
        },
        stats,
        last_valid: None,
    })
}

impl Unit for MonitorUnit {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let state = &mut self.state;
        state.values.iter_mut().for_each(|v| *v = None);
        state.objects.iter_mut().for_each(Vec::clear);
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
        match self.progressor.step(input.valid, &self.state) {
            Ok(Some(verdict)) => {
                out.emit(Value::Bool(verdict));
                self.progressor.reset();
                self.last_valid = None;
            }
            Ok(None) => self.last_valid = Some(input.valid),
            Err(e) => self.stats.error(format!("at {}: {e}", input.valid)),
        }
        Ok(())
    }

    fn on_end(&mut self, out: &mut Emitter) -> Result<(), ProcessError> {
        if let (Some(last), Some(verdict)) = (self.last_valid, self.progressor.finish()) {
            out.emit_at(last, Value::Bool(verdict));
        }
        Ok(())
    }
}
