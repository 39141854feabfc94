//! Negative information (`forget after 10s, after 1s when visible(view, this)`): a car whose
//! percept ends in plain view is given up a second after it stopped being anchored, a car that
//! goes under a bridge (the tracker's occluder) keeps its symbols for the whole forget time and is
//! reacquired when it comes out; without the condition both wait 10 s. The link processes are
//! stepped as the runtime steps them, each with the tracker's `view` sample (its footprint and
//! occluders) as the value of the stream its forget condition names.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::sync::Arc;

use kpl_anchor::{AnchorConfig, Anchoring, FromSnapshot};
use kpl_core::{Record, Time, Value};
use kpl_sim::RoadNetwork;

fn spec(sooner: &str) -> String {
    format!(
        r#"
type VisionPercept symbol vp {{ pos: vec2, vel: vec2, size: float }}
type WorldObject symbol wo {{ pos: vec2, vel: vec2 }}
type OnRoadObject : WorldObject symbol oo {{ road: int, lane_offset: float }}
type Car : OnRoadObject symbol co {{ }}
source tracker : list<VisionPercept> = sim.uav_tracker(scenario: "bridge")
stream view = tracker.view with use most recent
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {{
  establish   eventually[500ms, inf] true
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    true
}}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "bridge") {{
  establish   eventually[500ms, inf] always[0, 500ms] (from.measured and on_road(from.pos))
  reestablish eventually[0, 1s] (from.measured and xydist(from.pos, to.pos) < 10.0)
  maintain    true
}}
link onroad_car : OnRoadObject -> Car via anchor.copy {{
  establish   eventually[500ms, inf] always[0, 500ms] (from.measured and norm(from.vel) > 2.0)
  reestablish eventually[0, 1s] (from.measured and xydist(from.pos, to.pos) < 5.0)
  maintain    true
}}
predict WorldObject = constant_velocity
predict OnRoadObject = along_roads(scenario: "bridge")
forget after 10s{sooner}
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

/// The bridge scenario's view as `sim.uav_tracker`'s `view` output gives it: it sees the whole
/// network (no footprint), and the bridge hides the main road under it.
fn view(net: &RoadNetwork) -> Value {
    let occluders: Vec<Value> = net
        .occluders()
        .list()
        .iter()
        .map(|o| {
            Value::Record(Arc::new(Record {
                id: None,
                fields: vec![
                    ("area".into(), Value::List(o.area.iter().map(|p| Value::Vec2(*p)).collect())),
                    (
                        "roads".into(),
                        Value::List(o.roads.iter().map(|r| Value::Int(i64::from(r.0))).collect()),
                    ),
                ],
            }))
        })
        .collect();
    Value::Record(Arc::new(Record {
        id: None,
        fields: vec![
            ("footprint".into(), Value::List(Vec::new().into())),
            ("occluders".into(), Value::List(occluders.into())),
        ],
    }))
}

/// The symbols other than percepts after each step of 100 ms: one car driving east on the main
/// road at 14 m/s from x = -120 m, seen while `seen(x)`.
fn run(sooner: &str, seen: impl Fn(f64) -> bool) -> Vec<(Time, Vec<String>)> {
    let spec = kpl_std::check_text(&spec(sooner)).unwrap();
    let net = Arc::new(RoadNetwork::build(&kpl_roads::scenarios::bridge()).unwrap());
    let mut config = AnchorConfig::default();
    config.networks.insert("bridge", net.clone());
    config.functions = kpl_std::registry().functions().to_vec();
    let mut engine = Anchoring::from_spec(&spec, config).unwrap();
    assert_eq!(engine.env_names().len(), usize::from(sooner.contains("view")), "{:?}", engine.env_names());
    let view = view(&net);
    let links = [
        ("vision_world", "tracker", "WorldObject"),
        ("world_onroad", "vision_world", "OnRoadObject"),
        ("onroad_car", "world_onroad", "Car"),
    ];
    let mut out = Vec::new();
    for i in 0..200 {
        let time: Time = i * 100_000;
        let x = -120.0 + 14.0 * time as f64 / 1e6;
        let mut input = if seen(x) {
            Value::List(vec![percept("vp1", x)].into())
        } else {
            Value::List(Vec::new().into())
        };
        for (link, stream, ty) in links {
            let output = engine
                .step_link_env(
                    link,
                    time,
                    &[FromSnapshot { stream, valid: time, objects: &input }],
                    &[],
                    &[("view", &view)],
                )
                .unwrap();
            assert!(output.warnings.is_empty(), "{:?}", output.warnings);
            input = engine.snapshot(ty).unwrap();
        }
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

const SOONER: &str = ", after 1s when visible(view, this)";

#[test]
fn a_car_that_vanishes_in_plain_view_is_given_up_after_a_second() {
    // Seen until x = -64 m (4 s), far from the bridge: then nothing.
    let seen = |x: f64| x <= -64.0;
    let sooner = run(SOONER, seen);
    let plain = run("", seen);
    let all = ["co1", "oo1", "wo1"].map(String::from);
    assert_eq!(at(&sooner, 4_000_000), all, "anchored while seen");
    // Last anchored at 4 s (its percept is gone from 4.1 s): kept for a second...
    assert_eq!(at(&sooner, 4_900_000), all);
    // ...and gone at the step at which it has not been anchored for 1 s.
    assert!(at(&sooner, 5_000_000).is_empty(), "{:?}", at(&sooner, 5_000_000));
    // Without the condition, all three wait for `forget after 10s`.
    assert_eq!(at(&plain, 13_900_000), all);
    assert!(at(&plain, 14_000_000).is_empty());
}

#[test]
fn a_car_hidden_under_the_bridge_keeps_its_symbols() {
    // The tracker does not see it under the bridge (its predicted position is under the
    // occluder, so `visible` is false), and sees it again after it.
    let bridge = kpl_roads::scenarios::bridge();
    let net = RoadNetwork::build(&bridge).unwrap();
    let main = net.road_by_name("main").unwrap().id;
    let hidden = |x: f64| net.occluders().hiding([x, -1.75], Some(main)).is_some();
    assert!(hidden(0.0) && !hidden(-64.0), "the bridge hides x = 0 on the main road");
    let lo = (-120..120).map(f64::from).find(|&x| hidden(x)).unwrap();
    let hi = (-120..120).rev().map(f64::from).find(|&x| hidden(x)).unwrap();
    // Under it for more than a second, so that the plain condition would have given it up.
    assert!((hi - lo) / 14.0 > 1.2, "the bridge is {} m long", hi - lo);
    let sooner = run(SOONER, |x| !hidden(x));
    let all = ["co1", "oo1", "wo1"].map(String::from);
    let time_at = |x: f64| ((x + 120.0) / 14.0 * 10.0).ceil() as Time * 100_000;
    assert_eq!(at(&sooner, time_at(hi) - 100_000), all, "kept under the bridge");
    assert_eq!(at(&sooner, time_at(hi) + 1_000_000), all, "the same symbols after it");
    // The same car forgotten under the bridge with an unconditional short time.
    let short = run(", after 1s when true", |x| !hidden(x));
    assert!(
        !at(&short, time_at(hi) + 1_000_000).contains(&"co1".to_string()),
        "{:?}",
        at(&short, time_at(hi) + 1_000_000)
    );
}
