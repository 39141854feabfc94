//! What the anchoring tests share: the engine of a spec's text, a vision percept, and a step with
//! a snapshot of the `tracker` source.
#![allow(dead_code, clippy::unwrap_used)] // each test uses some of these; tests fail loudly

use std::sync::Arc;

use kpl_anchor::{AnchorConfig, Anchoring, Snapshot, StepOutput};
use kpl_core::{Record, Time, Value};

/// Two link levels on the crossing (vision percept -> world object -> on-road object) with the
/// paper's conditions, `along_roads` prediction and 30 s forget time.
pub const CROSSING_SPEC: &str = r#"
type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
type WorldObject   symbol wo { pos: vec2, vel: vec2 }
type OnRoadObject  : WorldObject symbol oo { road: int, lane_offset: float }
source tracker : list<VisionPercept> = engine.input()
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
  establish   eventually[1s, inf] true
  reestablish eventually[0, 1s] (xydist(from.pos, to.pos) < 10.0 and norm(from.vel - to.vel) < 5.0)
  maintain    true
}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "crossing") {
  establish   eventually[1s, inf] always[0, 1s] on_road(from.pos)
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    always eventually[0, 10s] always[0, 1s] on_road(from.pos)
}
predict WorldObject  = constant_velocity
predict OnRoadObject = along_roads(scenario: "crossing")
forget after 30s
"#;

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
