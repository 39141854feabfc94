//! A user's own computational units, in their own crate.
//!
//! `demo.accumulate` keeps a running sum. It reads its own previous output through a `feedback`
//! stream (as AAPA reads its previous world model), so it asks the runtime for synchronized
//! inputs: at each valid time it gets the new value and the sum emitted before it.
//!
//! `demo.scale` multiplies a number by a factor given in the spec.
//!
//! `demo.braking` is a prediction model for the anchoring (`predict WorldObject =
//! demo.braking(...)`): an object that nothing is linked to any more keeps slowing down at a
//! constant deceleration until it stands, as a car braking when it went out of sight would.
//!
//! `src/main.rs` builds a `kpl` command with these registered (`kpl::main_with(register)`), so
//! `cargo run -p custom-unit -- run examples/custom-unit/accumulate.kpl` runs a spec that uses
//! them, and `cargo run -p custom-unit -- list` shows them with their parameters.

use std::sync::Arc;

use kpl_anchor::predict::{PredictionModel, PredictionStart};
use kpl_anchor::records::{position, velocity, with_fields};
use kpl_core::{Record, Time, Value, ValueType};
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

/// Slows down from the last known velocity at `deceleration` (m/s²) until it stands.
#[derive(Debug)]
struct Braking {
    deceleration: f64,
}

impl PredictionModel for Braking {
    fn name(&self) -> &str {
        "demo.braking"
    }

    fn predict(&self, start: &PredictionStart, time: Time, out: &mut Vec<Record>) {
        let (Some(p), Some(v)) = (position(&start.state), velocity(&start.state)) else {
            out.push((*start.state).clone());
            return;
        };
        let speed = v[0].hypot(v[1]);
        let dt = (time - start.time).max(0) as f64 / 1e6;
        // Braking stops after speed / deceleration seconds; it stands from then on.
        let t = dt.min(speed / self.deceleration);
        let (along, now) = (speed * t - 0.5 * self.deceleration * t * t, speed - self.deceleration * t);
        let unit = if speed > 0.0 { [v[0] / speed, v[1] / speed] } else { [0.0, 0.0] };
        out.push(with_fields(
            &start.state,
            &[
                ("pos", Value::vec2(p[0] + unit[0] * along, p[1] + unit[1] * along)),
                ("vel", Value::vec2(unit[0] * now, unit[1] * now)),
            ],
        ));
    }
}

/// Registers this crate's units and its prediction model.
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
    kpl_std::anchor::add_model(
        registry,
        Entry::new(
            EntryKind::Predict,
            "demo.braking",
            "Slows down at a constant deceleration until it stands.",
        )
        .param(Param::optional("deceleration", ParamType::Float, Value::Float(3.0), "m/s²"))
        .output(TypeReq::Fields(vec![("pos".into(), ValueType::Vec2), ("vel".into(), ValueType::Vec2)])),
        |params, _networks| match params.get("deceleration").and_then(Value::as_f64) {
            Some(a) if a.is_finite() && a > 0.0 => Ok(Arc::new(Braking { deceleration: a })),
            _ => Err("`deceleration` must be a positive number (m/s²)".to_string()),
        },
    );
}
