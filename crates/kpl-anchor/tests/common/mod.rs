//! What the anchoring tests share: the engine of a spec's text, a vision percept, and a step with
//! a snapshot of the `tracker` source.
#![allow(dead_code, clippy::unwrap_used)] // each test uses some of these; tests fail loudly

use std::sync::Arc;

use kpl_anchor::{AnchorConfig, Anchoring, Snapshot, StepOutput};
use kpl_core::{Record, Time, Value};

/// The engine of a spec, checked as `kpl` checks it.
pub fn engine(spec: &str) -> Anchoring {
    let spec = kpl_anchor::registry::check_text(spec).unwrap();
    Anchoring::from_spec(&spec, AnchorConfig::default()).unwrap()
}

/// A `VisionPercept` (`pos`, `vel`, `size`) with the id its source gave it.
pub fn percept(id: &str, pos: [f64; 2], vel: [f64; 2], size: f64) -> Value {
    Value::Record(Arc::new(Record {
        id: Some(id.into()),
        fields: vec![
            ("pos".into(), Value::Vec2(pos)),
            ("vel".into(), Value::Vec2(vel)),
            ("size".into(), Value::Float(size)),
        ],
    }))
}

/// One step at `time` with the `tracker`'s snapshot of vision percepts; no warnings.
pub fn step(engine: &mut Anchoring, time: Time, objects: &Value) -> StepOutput {
    let output = engine.step(time, &[Snapshot { source: "tracker", ty: "VisionPercept", objects }]).unwrap();
    assert!(output.warnings.is_empty(), "{:?}", output.warnings);
    output
}
