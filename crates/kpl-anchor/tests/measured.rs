//! Measured or predicted: every object record says whether its state was measured at this state
//! (`measured`) and, when not, since when (`predicted_since`); conditions ask for it with
//! `from.measured` / `to.measured`. An object that has only been predicted is not "detected on a
//! road" (the paper's establish condition of on-road objects), so no on-road object is made of it.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use kpl_anchor::{Anchoring, ChangeKind};
use kpl_core::Value;

fn spec(onroad_establish: &str) -> String {
    format!(
        r#"
type VisionPercept symbol vp {{ pos: vec2, vel: vec2, size: float }}
type WorldObject   symbol wo {{ pos: vec2, vel: vec2 }}
type OnRoadObject  : WorldObject symbol oo {{ road: int, lane_offset: float }}
source tracker : list<VisionPercept> = engine.input()
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {{
  establish   eventually[300ms, inf] true
  reestablish eventually[0, 1s] (xydist(from.pos, to.pos) < 10.0)
  maintain    true
}}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "bridge") {{
  establish   {onroad_establish}
  reestablish eventually[0, 1s] (from.measured and xydist(from.pos, to.pos) < 10.0)
  maintain    always eventually[0, 10s] (from.measured and on_road(from.pos))
}}
predict WorldObject = constant_velocity
forget after 30s
"#
    )
}

/// vp1 drives east on `main`'s lane for 0.5 s and is lost; for 5 s more nothing is seen. Returns
/// the engine and the on-road objects created.
fn run(engine: &mut Anchoring) -> Vec<String> {
    let mut created = Vec::new();
    for i in 0..=55 {
        let t = i * 100_000;
        let items = if i < 5 {
            vec![common::percept("vp1", [-100.0 + i as f64, -1.75], [10.0, 0.0], 4.5)]
        } else {
            vec![]
        };
        let output = common::step(engine, t, &Value::List(items.into()));
        for c in &output.changes {
            if c.kind == ChangeKind::Created && &*c.ty == "OnRoadObject" {
                created.push(format!("{c}"));
            }
        }
        // While wo1 is predicted, its record says so, and since when.
        if i >= 5 {
            let snapshot = engine.snapshot("WorldObject").unwrap();
            let Value::List(items) = &snapshot else { panic!("{snapshot:?}") };
            let wo1 = items[0].as_record().unwrap();
            assert_eq!(wo1.get("measured"), Some(&Value::Bool(false)), "at {t}");
            assert_eq!(wo1.get("predicted_since"), Some(&Value::Int(500_000)), "at {t}");
            let view = engine.object("WorldObject", "wo1").unwrap();
            assert!(!view.measured && view.predicted && view.predicted_since == Some(500_000));
        }
    }
    created
}

#[test]
fn no_on_road_object_is_established_from_a_predicted_only_world_object() {
    // "Detected on a road for at least one second": the predicted world object is on the road
    // (it moves along the lane) but never detected there for a second.
    let mut engine =
        common::engine(&spec("eventually[1s, inf] always[0, 1s] (from.measured and on_road(from.pos))"));
    assert_eq!(run(&mut engine), Vec::<String>::new());
    assert!(engine.object("WorldObject", "wo1").is_some());

    // Without asking for detections, the prediction alone makes an on-road object.
    let mut engine = common::engine(&spec("eventually[1s, inf] always[0, 1s] on_road(from.pos)"));
    let created = run(&mut engine);
    assert_eq!(created, vec!["created oo1 <- wo1 (establish, world_onroad)".to_string()]);
}

/// The record shapes: a measured object has `measured: true` and no `predicted_since`; the world
/// model has both at the top and keeps its `state` to the type's attributes.
#[test]
fn records_say_measured_or_since_when_predicted() {
    let mut engine =
        common::engine(&spec("eventually[1s, inf] always[0, 1s] (from.measured and on_road(from.pos))"));
    for i in 0..=3 {
        let items = vec![common::percept("vp1", [-100.0 + i as f64, -1.75], [10.0, 0.0], 4.5)];
        common::step(&mut engine, i * 100_000, &Value::List(items.into()));
    }
    let snapshot = engine.snapshot("WorldObject").unwrap().to_json();
    assert_eq!(snapshot[0]["measured"], true);
    assert!(snapshot[0].get("predicted_since").is_none(), "{snapshot}");
    common::step(&mut engine, 400_000, &Value::List(Vec::new().into()));
    common::step(&mut engine, 500_000, &Value::List(Vec::new().into()));
    let world = engine.world_model().to_json();
    let wo1 = world.as_array().unwrap().iter().find(|o| o["id"] == "wo1").unwrap();
    assert_eq!(wo1["measured"], false);
    assert_eq!(wo1["predicted"], true);
    assert_eq!(wo1["predicted_since"], 400_000);
    assert_eq!(wo1["state"].as_object().unwrap().keys().collect::<Vec<_>>(), vec!["pos", "vel"]);
}
