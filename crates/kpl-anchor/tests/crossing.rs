//! Prediction along the road network through a crossing: a car is lost before a four-way
//! crossing, its on-road object (and the world object with it) is predicted along the road and
//! splits into three hypotheses past the crossing (left, straight on, right), each an on-road
//! object of its own (oo1 straight on, two branch objects `branch_of: oo1`), in the type's
//! snapshot and seen by `exists`; the car comes back after turning left, the new percept is linked
//! to the waiting world object through the left hypothesis, the two branch objects are pruned,
//! and oo1 keeps the branch that was reacquired: it is on the north road again.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use std::sync::Arc;

use kpl_anchor::{Anchoring, ChangeKind, Status};
use kpl_core::Value;

const SPEC: &str = common::CROSSING_SPEC;

fn percept(id: &str, pos: [f64; 2], vel: [f64; 2]) -> Value {
    common::percept(id, pos, vel, 4.5)
}

fn step(engine: &mut Anchoring, i: i64, items: Vec<Value>) -> kpl_anchor::StepOutput {
    common::step(engine, i * 100_000, &Value::List(items.into()))
}

/// Whether `exists o: OnRoadObject . o.vel.y > 9.0` holds over this snapshot of on-road objects.
fn heads_north(snapshot: &Value) -> bool {
    let mut context = kpl_mtl::Context::new(kpl_core::TimeUnit::Us, kpl_core::TimeUnit::Ms);
    let domain = context.declare_object_type("OnRoadObject");
    let expr = kpl_syntax::parse_formula("exists o: OnRoadObject . o.vel.y > 9.0").unwrap();
    let formula = kpl_mtl::Formula::from_ast(&expr, &mut context).unwrap();
    let mut progressor = kpl_mtl::Progressor::new(Arc::new(formula));
    let Value::List(items) = snapshot else { panic!("{snapshot:?}") };
    let mut objects = vec![Vec::new(); domain as usize + 1];
    objects[domain as usize] = items.to_vec();
    let state = kpl_mtl::SlotState { values: Vec::new(), objects };
    progressor.step(0, &state).unwrap().unwrap()
}

fn record_field(value: &Value, name: &str) -> Value {
    value.as_record().unwrap().get(name).unwrap().clone()
}

#[test]
fn the_reacquired_branch_is_kept() {
    let mut engine = common::engine(SPEC);
    let network = kpl_roads::RoadNetwork::build(&kpl_roads::scenarios::crossing()).unwrap();
    let north = i64::from(network.road_by_name("north").unwrap().id.0);
    let west = i64::from(network.road_by_name("west").unwrap().id.0);

    // Eastbound on `west` (lane at y = -1.75) at 10 m/s from x = -90; seen until 4.9 s (x = -41).
    for i in 0..50 {
        step(&mut engine, i, vec![percept("vp1", [-90.0 + i as f64, -1.75], [10.0, 0.0])]);
        assert!(!heads_north(&engine.snapshot("OnRoadObject").unwrap()));
    }
    assert_eq!(engine.chain("vp1").len(), 2, "vp1 -> wo1 -> oo1");
    assert_eq!(record_field(&engine.object("OnRoadObject", "oo1").unwrap().state, "road"), Value::Int(west));

    // Unseen for 5 s: 50 m along the road, through the crossing onto three roads.
    let mut splits = Vec::new();
    for i in 50..100 {
        let output = step(&mut engine, i, vec![]);
        for c in &output.changes {
            if c.kind == ChangeKind::Predicted {
                splits.push((i, c.to_string()));
            }
        }
    }
    assert_eq!(splits[0], (50, "predicted wo1 (no_incoming_link, along_roads)".to_string()));
    assert_eq!(splits.last().unwrap().1, "predicted wo1 (branch, along_roads, 3 hypotheses)");
    // Three on-road objects, one per branch: oo1 straight on, the two others branch objects.
    let Value::List(onroad) = engine.snapshot("OnRoadObject").unwrap() else { panic!() };
    assert_eq!(onroad.len(), 3, "{onroad:?}");
    let field = |o: &Value, name: &str| o.as_record().unwrap().get(name).cloned();
    assert_eq!(field(&onroad[0], "branch_of"), None);
    assert!(record_field(&onroad[0], "vel").as_vec2().unwrap()[0] > 9.0, "oo1 goes straight on");
    for branch in &onroad[1..] {
        assert_eq!(field(branch, "branch_of"), Some(Value::str("oo1")));
        assert_eq!(field(branch, "measured"), Some(Value::Bool(false)));
    }
    let likelihoods: Vec<f64> =
        onroad.iter().map(|o| field(o, "likelihood").unwrap().as_f64().unwrap()).collect();
    assert!((likelihoods.iter().sum::<f64>() - 1.0).abs() < 1e-9, "{likelihoods:?}");
    assert!(likelihoods[0] > likelihoods[1] && likelihoods[0] > likelihoods[2], "{likelihoods:?}");
    // `exists o: OnRoadObject` sees them: one heads north (the left branch), as no object did before.
    assert!(heads_north(&Value::List(onroad.clone())));
    let branches: Vec<String> =
        onroad[1..].iter().map(|o| o.as_record().unwrap().id.as_deref().unwrap().to_string()).collect();
    let wo1 = engine.object("WorldObject", "wo1").unwrap();
    assert_eq!(wo1.status, Status::Predicted);
    assert_eq!(wo1.hypotheses.len(), 3);
    // The first hypothesis is straight on (east); the left turn heads north.
    assert!(record_field(&wo1.hypotheses[0], "vel").as_vec2().unwrap()[0] > 9.0);
    let (left, left_state) = wo1
        .hypotheses
        .iter()
        .enumerate()
        .find(|(_, h)| record_field(h, "vel").as_vec2().unwrap()[1] > 9.0)
        .unwrap();
    let left_pos = record_field(left_state, "pos").as_vec2().unwrap();
    assert!(left_pos[1] > 5.0, "{left_pos:?}");

    // The car comes back on the north road, heading north, 3 m ahead of the left hypothesis.
    let output = step(&mut engine, 100, vec![percept("vp2", [left_pos[0], left_pos[1] + 3.0], [0.0, 10.0])]);
    let text: Vec<String> = output.changes.iter().map(ToString::to_string).collect();
    assert!(
        text.contains(&format!(
            "linked wo1 <- vp2 (reestablish, vision_world, hypothesis {} of 3)",
            left + 1
        )),
        "{text:?}"
    );
    // The two branch objects are pruned; oo1 continues on the reacquired branch.
    let pruned: Vec<String> =
        output.changes.iter().filter(|c| c.kind == ChangeKind::Removed).map(|c| c.to_string()).collect();
    let expected: Vec<String> =
        branches.iter().map(|b| format!("removed {b} (pruned, branch of oo1)")).collect();
    assert_eq!(pruned, expected);
    let wo1 = engine.object("WorldObject", "wo1").unwrap();
    assert_eq!(wo1.status, Status::Anchored);
    assert!(wo1.hypotheses.is_empty());
    let oo1 = engine.object("OnRoadObject", "oo1").unwrap();
    assert_eq!(oo1.status, Status::Anchored);
    assert_eq!(record_field(&oo1.state, "road"), Value::Int(north));
    assert_eq!(
        engine.chain("vp2"),
        vec![(Arc::from("WorldObject"), Arc::from("wo1")), (Arc::from("OnRoadObject"), Arc::from("oo1")),]
    );
}
