//! `along_roads(..., forget_at_end: true)`: a car that drives off the map is forgotten (world
//! object, on-road object and car) as soon as its percept is gone and its prediction reaches the
//! network's border, instead of waiting at the border for the spec's `forget` time; a car that is
//! seen again before its prediction ends keeps its symbols.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::sync::Arc;

use kpl_anchor::{AnchorConfig, Anchoring, Snapshot};
use kpl_core::{Record, Time, Value};
use kpl_sim::RoadNetwork;

fn spec(forget_at_end: bool) -> String {
    format!(
        r#"
type VisionPercept symbol vp {{ pos: vec2, vel: vec2, size: float }}
type WorldObject symbol wo {{ pos: vec2, vel: vec2 }}
type OnRoadObject : WorldObject symbol oo {{ road: int, lane_offset: float }}
type Car : OnRoadObject symbol co {{ }}
source tracker : list<VisionPercept> = sim.uav_tracker(scenario: "bridge")
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {{
  establish   eventually[500ms, inf] true
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    true
}}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "bridge") {{
  establish   eventually[500ms, inf] always[0, 500ms] (from.measured and on_road(from.pos))
  reestablish eventually[0, 1s] (from.measured and xydist(from.pos, to.pos) < 10.0)
  maintain    always eventually[0, 10s] (from.measured and always[0, 1s] (from.measured -> on_road(from.pos)))
}}
link onroad_car : OnRoadObject -> Car via anchor.copy {{
  establish   eventually[500ms, inf] always[0, 500ms] (from.measured and norm(from.vel) > 2.0)
  reestablish eventually[0, 1s] (from.measured and xydist(from.pos, to.pos) < 5.0)
  maintain    true
}}
predict WorldObject = constant_velocity
predict OnRoadObject = along_roads(scenario: "bridge", forget_at_end: {forget_at_end})
forget after 10s
"#
    )
}

fn percept(id: &str, x: f64) -> Value {
    Value::Record(Arc::new(Record {
        id: Some(id.into()),
        fields: vec![
            ("pos".into(), Value::Vec2([x, -1.75])),
            ("vel".into(), Value::Vec2([14.0, 0.0])),
            ("size".into(), Value::Float(4.5)),
        ],
    }))
}

/// The symbols of each anchoring type present after each step, with the car seen from x = 140 m
/// eastwards from x = 100 m at 14 m/s while `seen(time)` (the road ends at x = 200 m, at 7.1 s).
fn run(forget_at_end: bool, seen: impl Fn(Time) -> bool) -> Vec<(Time, Vec<String>)> {
    let spec = kpl_std::check_text(&spec(forget_at_end)).unwrap();
    let mut config = AnchorConfig::default();
    config.networks.insert("bridge", Arc::new(RoadNetwork::build(&kpl_roads::scenarios::bridge()).unwrap()));
    let mut engine = Anchoring::from_spec(&spec, config).unwrap();
    let mut out = Vec::new();
    for i in 0..160 {
        let time: Time = i * 100_000;
        let x = 100.0 + 14.0 * time as f64 / 1e6;
        let objects = if seen(time) && x < 200.0 {
            Value::List(vec![percept("vp1", x)].into())
        } else {
            Value::List(Vec::new().into())
        };
        engine.step(time, &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }]).unwrap();
        let mut symbols: Vec<String> = engine
            .objects()
            .iter()
            .filter(|v| &*v.ty != "VisionPercept")
            .map(|v| v.symbol.to_string())
            .collect();
        symbols.sort();
        out.push((time, symbols));
    }
    out
}

fn at(run: &[(Time, Vec<String>)], time: Time) -> &[String] {
    &run.iter().find(|(t, _)| *t == time).unwrap().1
}

#[test]
fn a_car_that_left_the_map_is_forgotten_at_once_with_forget_at_end() {
    // Seen until 5 s (x = 170 m): the prediction reaches the border at about 7.1 s.
    let seen = |t: Time| t <= 5_000_000;
    let forgetting = run(true, seen);
    let waiting = run(false, seen);
    let all = ["co1", "oo1", "wo1"].map(String::from);
    assert_eq!(at(&forgetting, 5_000_000), all, "anchored while seen");
    assert_eq!(at(&forgetting, 6_500_000), all, "predicted on the map");
    assert!(at(&forgetting, 7_500_000).is_empty(), "{:?}", at(&forgetting, 7_500_000));
    // Without it the structure waits at the border until `forget` (10 s after it was last seen).
    assert_eq!(at(&waiting, 7_500_000), all);
    assert_eq!(at(&waiting, 14_900_000), all);
}

#[test]
fn a_car_seen_again_before_its_prediction_ends_keeps_its_symbols() {
    // Lost from 3 s to 4.5 s, seen again, then gone for good after 5 s.
    let forgetting = run(true, |t| t <= 3_000_000 || (4_500_000..=5_000_000).contains(&t));
    let all = ["co1", "oo1", "wo1"].map(String::from);
    assert_eq!(at(&forgetting, 3_000_000), all);
    assert_eq!(at(&forgetting, 5_000_000), all, "the same symbols after the gap");
    assert!(at(&forgetting, 7_500_000).is_empty());
}
