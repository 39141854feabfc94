//! Top-down identification (the paper's future work, `identify NAME : TYPE where FORMULA`): a
//! partial object is added and completed from incoming percepts when an object linked into its
//! type satisfies the description together with the link's reestablish condition; a running
//! system can ask the same, and an existing object that satisfies the description resolves it.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use std::sync::Arc;

use kpl_anchor::{Anchoring, Cause, ChangeKind, IdentifyError, Status};
use kpl_core::Value;

const SPEC: &str = r#"
type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
type WorldObject   symbol wo { pos: vec2, vel: vec2 }
type OnRoadObject  : WorldObject symbol oo { road: int, lane_offset: float }
type Car           : OnRoadObject symbol co { }

source tracker : list<VisionPercept> = engine.input()

link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
  establish   eventually[1s, inf] true
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    true
}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "bridge") {
  establish   eventually[1s, inf] always[0, 1s] on_road(from.pos)
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    always eventually[0, 10s] always[0, 1s] on_road(from.pos)
}
link onroad_car : OnRoadObject -> Car via anchor.copy {
  establish   eventually[2s, inf] always[0, 2s] norm(from.vel) > 2.0
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 5.0
  maintain    true
}
predict WorldObject  = constant_velocity
predict OnRoadObject = along_roads(scenario: "bridge")
forget after 30s
identify suspect : Car where xydist(this.pos, vec2(-110.0, -1.75)) < 20.0 and this.vel.x > 0.0
"#;

fn percept(id: &str, x: f64, y: f64, vx: f64) -> Value {
    common::percept(id, [x, y], [vx, 0.0], 4.5)
}

/// Two cars on `main`: vp1 eastbound from x = -150 at 12 m/s (it passes (-110, -1.75) after
/// about 3 s), vp2 westbound from x = 150.
fn snapshot(i: i64) -> Value {
    let t = i as f64 / 10.0;
    Value::List(
        vec![percept("vp1", -150.0 + 12.0 * t, -1.75, 12.0), percept("vp2", 150.0 - 12.0 * t, 1.75, -12.0)]
            .into(),
    )
}

fn engine() -> Anchoring {
    common::engine(SPEC)
}

fn step(engine: &mut Anchoring, i: i64) -> kpl_anchor::StepOutput {
    common::step(engine, i * 100_000, &snapshot(i))
}

#[test]
fn a_spec_identification_is_completed_through_a_link() {
    let mut engine = engine();
    let mut identified_at = None;
    for i in 0..=80 {
        let output = step(&mut engine, i);
        if i == 0 {
            // The partial object exists from the start, with a Car symbol and the name asked for.
            let created: Vec<String> = output.changes.iter().map(ToString::to_string).collect();
            assert!(created.contains(&"created co1 (identify, suspect)".to_string()), "{created:?}");
            let view = engine.object("Car", "co1").unwrap();
            assert_eq!(view.status, Status::Partial);
            assert_eq!(view.names, vec![Arc::from("suspect")]);
            assert!(
                engine.snapshot("Car").unwrap() == Value::List(Vec::new().into()),
                "a partial object has no state"
            );
        }
        for change in &output.changes {
            if change.kind == ChangeKind::Identified {
                assert_eq!(change.to_string(), "identified co1 <- oo1 (identify, onroad_car, suspect)");
                assert!(identified_at.is_none());
                identified_at = Some(i);
            }
        }
    }
    // oo1 is made at 3.0 s, 2 m past the point: the identification takes it at once, before
    // its establish condition (2 s of motion) could make a new car of it.
    assert_eq!(identified_at, Some(30));
    assert_eq!(engine.identified("suspect"), Some(Arc::from("co1")));
    assert_eq!(
        engine.chain("vp1"),
        vec![
            (Arc::from("WorldObject"), Arc::from("wo1")),
            (Arc::from("OnRoadObject"), Arc::from("oo1")),
            (Arc::from("Car"), Arc::from("co1")),
        ]
    );
    let co1 = engine.object("Car", "co1").unwrap();
    assert_eq!(co1.status, Status::Anchored);
    assert_eq!(co1.names, vec![Arc::from("suspect")]);
    // The westbound car does not fit the description: it became an ordinary car.
    let other = engine.chain("vp2");
    assert_eq!(other.last().unwrap().0, Arc::from("Car"));
    assert_ne!(other.last().unwrap().1, Arc::from("co1"));
    assert!(engine.describe().contains("co1 anchored [suspect]"), "{}", engine.describe());
}

#[test]
fn a_running_system_asks_for_an_existing_object() {
    let mut engine = engine();
    for i in 0..=80 {
        step(&mut engine, i);
    }
    // Both cars exist (classified by 7 s); ask for the one moving west.
    let symbol = engine.identify_text("westbound", "Car", "this.vel.x < -5.0").unwrap();
    assert_eq!(engine.object("Car", &symbol).unwrap().status, Status::Partial);
    assert_eq!(engine.identified("westbound"), None);
    let output = step(&mut engine, 81);
    let text: Vec<String> = output.changes.iter().map(ToString::to_string).collect();
    let westbound = engine.chain("vp2").last().unwrap().1.clone();
    assert!(text.contains(&format!("created {symbol} (identify, westbound)")), "{text:?}");
    assert!(text.contains(&format!("removed {symbol} (resolved)")), "{text:?}");
    assert!(text.contains(&format!("identified {westbound} (description, westbound)")), "{text:?}");
    assert_eq!(engine.identified("westbound"), Some(westbound.clone()));
    assert!(engine.object("Car", &symbol).is_none(), "the partial object is gone");
    assert_eq!(engine.object("Car", &westbound).unwrap().names, vec![Arc::from("westbound")]);
    let changes = output.changes.iter().filter(|c| c.kind == ChangeKind::Identified).collect::<Vec<_>>();
    assert_eq!(changes.len(), 1);
    assert_eq!(changes[0].cause, Cause::Description);
}

#[test]
fn an_identification_that_never_fits_stays_partial() {
    let mut engine = engine();
    engine.identify_text("ghost", "Car", "this.vel.x > 100.0").unwrap();
    for i in 0..=400 {
        step(&mut engine, i);
    }
    // 40 s later (past the 30 s forget time) the partial object is still waiting.
    let symbol = engine.objects().into_iter().find(|v| v.names.contains(&Arc::from("ghost"))).unwrap().symbol;
    assert_eq!(engine.object("Car", &symbol).unwrap().status, Status::Partial);
    assert_eq!(engine.identified("ghost"), None);
}

#[test]
fn bad_requests_are_refused_with_a_reason() {
    let mut engine = engine();
    assert_eq!(engine.identify_text("x", "Truck", "true"), Err(IdentifyError::UnknownType("Truck".into())));
    assert_eq!(
        engine.identify_text("x", "VisionPercept", "true"),
        Err(IdentifyError::NoLinkInto("VisionPercept".into()))
    );
    assert_eq!(
        engine.identify_text("suspect", "Car", "true"),
        Err(IdentifyError::NameInUse("suspect".into()))
    );
    let Err(IdentifyError::Description(messages)) = engine.identify_text("x", "Car", "this.speeed >") else {
        panic!("a syntax error is refused");
    };
    assert!(!messages.is_empty());
    let Err(IdentifyError::Description(messages)) = engine.identify_text("x", "Car", "that.pos.x > 0.0")
    else {
        panic!("an unknown name is refused");
    };
    assert!(messages.iter().any(|m| m.contains("that")), "{messages:?}");
    // Nothing was added by the refused requests.
    assert_eq!(engine.n_objects(), 1);
}

#[test]
fn a_running_system_asks_before_the_object_is_classified() {
    let mut engine = engine();
    for i in 0..=60 {
        step(&mut engine, i);
    }
    // At 6 s the westbound on-road object is not a car yet (it needs 2 s of motion after its
    // first 2 s): the request is completed through the link, before establish would make a car.
    let symbol = engine.identify_text("westbound", "Car", "this.vel.x < -5.0").unwrap();
    let output = step(&mut engine, 61);
    let text: Vec<String> = output.changes.iter().map(ToString::to_string).collect();
    let oo = engine.chain("vp2")[1].1.clone();
    assert_eq!(
        text,
        vec![
            format!("created {symbol} (identify, westbound)"),
            format!("linked {symbol} <- {oo} (identify, onroad_car, westbound)"),
            format!("identified {symbol} <- {oo} (identify, onroad_car, westbound)"),
        ]
    );
    assert_eq!(engine.identified("westbound"), Some(symbol.clone()));
    assert_eq!(engine.chain("vp2").last().unwrap().1, symbol);
}
