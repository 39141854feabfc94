//! A user's own computational units, in their own crate.
//!
//! `demo.accumulate` keeps a running sum. It reads its own previous output through a `feedback`
//! stream (as AAPA reads its previous world model), so it asks the runtime for synchronized
//! inputs: at each valid time it gets the new value and the sum emitted before it.
//!
//! `demo.scale` multiplies a number by a factor given in the spec.
//!
//! `src/main.rs` builds a `kpl` command with these registered (`kpl::main_with(register)`), so
//! `cargo run -p custom-unit -- run examples/custom-unit/accumulate.kpl` runs a spec that uses
//! them, and `cargo run -p custom-unit -- list` shows them with their parameters.

use kpl_core::{Value, ValueType};
use kpl_runtime::Registry;
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

/// Running sum: input 0 is the value, input 1 the sum fed back.
struct Accumulate;

impl Unit for Accumulate {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let Some(value) = input.value(0) else { return Ok(()) };
        let previous = input.value(1).and_then(Value::as_f64).unwrap_or(0.0);
        let x = value
            .as_f64()
            .ok_or_else(|| ProcessError::failed(format!("expected a number, got {}", value.kind())))?;
        out.emit(Value::Float(previous + x));
        Ok(())
    }
}

struct Scale {
    factor: f64,
}

impl Unit for Scale {
    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        if let Some(x) = input.trigger_value().and_then(Value::as_f64) {
            out.emit(Value::Float(x * self.factor));
        }
        Ok(())
    }
}

/// Registers this crate's units.
pub fn register(registry: &mut Registry) {
    registry.add_unit(
        Entry::new(
            EntryKind::Compute,
            "demo.accumulate",
            "Running sum of a number stream (reads its previous sum back).",
        )
        .input("value", TypeReq::Any, "the numbers to add")
        .input(
            "previous",
            TypeReq::Exact(ValueType::Float),
            "this unit's own output, through a `feedback` stream",
        )
        .output(TypeReq::Exact(ValueType::Float)),
        |_| Ok(Box::new(SyncUnit(Accumulate))),
    );
    registry.add_unit(
        Entry::new(EntryKind::Compute, "demo.scale", "Multiplies each number by a factor.")
            .input("in", TypeReq::Any, "numbers")
            .param(Param::optional("factor", ParamType::Float, Value::Float(2.0), "what to multiply by"))
            .output(TypeReq::Exact(ValueType::Float)),
        |ctx| {
            let factor = ctx.param("factor").and_then(Value::as_f64).unwrap_or(2.0);
            Ok(Box::new(SyncUnit(Scale { factor })))
        },
    );
}
