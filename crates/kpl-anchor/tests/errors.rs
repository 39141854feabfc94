//! Bad input gets a clear error or warning and loses nothing else: snapshots that are not lists,
//! objects without ids or with wrong attributes, ids listed twice, snapshots for types that links
//! make, time going backwards, conditions that cannot be evaluated. Arbitrary values as snapshots
//! never make the engine panic.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use std::sync::Arc;

use kpl_anchor::{Anchoring, Snapshot, StepError};
use kpl_core::{Record, Value};
use proptest::prelude::*;

const SPEC: &str = r#"
type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
type WorldObject   symbol wo { pos: vec2, vel: vec2 }
source tracker : list<VisionPercept> = engine.input()
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
  establish   eventually[200ms, inf] true
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    always 1.0 / (from.size - 3.0) > -100.0
}
predict WorldObject = constant_velocity
forget after 1s
"#;

fn engine() -> Anchoring {
    common::engine(SPEC)
}

fn percept(id: Option<&str>, fields: Vec<(&str, Value)>) -> Value {
    Value::Record(Arc::new(Record {
        id: id.map(Arc::from),
        fields: fields.into_iter().map(|(n, v)| (Arc::from(n), v)).collect(),
    }))
}

fn good(id: &str, x: f64, size: f64) -> Value {
    percept(
        Some(id),
        vec![("pos", Value::vec2(x, 0.0)), ("vel", Value::vec2(1.0, 0.0)), ("size", Value::Float(size))],
    )
}

fn step(engine: &mut Anchoring, time: i64, objects: Value) -> kpl_anchor::StepOutput {
    engine.step(time, &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }]).unwrap()
}

#[test]
fn bad_objects_are_skipped_with_a_warning_and_the_rest_goes_on() {
    let mut engine = engine();
    let objects = Value::List(
        vec![
            good("vp1", 0.0, 4.0),
            percept(None, vec![("pos", Value::vec2(1.0, 1.0))]),
            percept(
                Some("vp2"),
                vec![("pos", Value::Float(3.0)), ("vel", Value::vec2(0.0, 0.0)), ("size", Value::Float(1.0))],
            ),
            percept(Some("vp3"), vec![("pos", Value::vec2(3.0, 0.0))]),
            good("vp1", 5.0, 4.0),
            Value::Int(7),
        ]
        .into(),
    );
    let out = step(&mut engine, 0, objects);
    let messages: Vec<&str> = out.warnings.iter().map(|w| w.message.as_str()).collect();
    assert_eq!(messages.len(), 5, "{messages:?}");
    assert!(messages[0].contains("without an `id`"), "{}", messages[0]);
    assert!(messages[1].contains("vp2 field `pos` is float, expected vec2"), "{}", messages[1]);
    assert!(messages[2].contains("vp3 has no field `vel`"), "{}", messages[2]);
    assert!(messages[3].contains("vp1 is listed twice"), "{}", messages[3]);
    assert!(messages[4].contains("an item is an int, not an object"), "{}", messages[4]);
    // The good percept is there, with its first state.
    let vp1 = engine.object("VisionPercept", "vp1").unwrap();
    assert_eq!(vp1.state.as_record().unwrap().get("pos"), Some(&Value::vec2(0.0, 0.0)));
    assert_eq!(engine.n_objects(), 1);

    let out = step(&mut engine, 100_000, Value::Int(3));
    assert!(out.warnings[0].message.contains("is an int, expected a list of objects"), "{:?}", out.warnings);
    // An unreadable snapshot changes nothing: vp1 is still there.
    assert!(engine.object("VisionPercept", "vp1").is_some());
}

#[test]
fn steps_that_cannot_be_taken_change_nothing() {
    let mut engine = engine();
    step(&mut engine, 1_000, Value::List(vec![good("vp1", 0.0, 4.0)].into()));
    let before = engine.describe();
    let objects = Value::List(Vec::new().into());
    assert_eq!(
        engine
            .step(1_000, &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }])
            .unwrap_err(),
        StepError::TimeNotIncreasing { time: 1_000, previous: 1_000 }
    );
    let err = engine
        .step(2_000, &[Snapshot { source: "tracker", ty: "WorldObject", objects: &objects }])
        .unwrap_err();
    assert!(err.to_string().contains("made by link `vision_world`"), "{err}");
    let err =
        engine.step(2_000, &[Snapshot { source: "tracker", ty: "Truck", objects: &objects }]).unwrap_err();
    assert_eq!(err, StepError::UnknownType { source_name: "tracker".into(), ty: "Truck".into() });
    assert_eq!(engine.describe(), before);
    assert_eq!(engine.time(), Some(1_000));
}

#[test]
fn a_condition_that_cannot_be_evaluated_skips_the_state() {
    let mut engine = engine();
    // The maintain condition divides by (size - 3): with size 3 that state cannot be evaluated.
    for i in 0..=3 {
        let out = step(&mut engine, i * 100_000, Value::List(vec![good("vp1", 0.0, 4.0)].into()));
        assert!(out.warnings.is_empty());
    }
    assert!(
        engine.describe().contains("vp1 anchored | vision_world: -> wo1 maintain ?"),
        "{}",
        engine.describe()
    );
    let out = step(&mut engine, 400_000, Value::List(vec![good("vp1", 0.0, 3.0)].into()));
    assert_eq!(out.warnings.len(), 1);
    assert!(out.warnings[0].message.contains("maintain(vp1, wo1)"), "{}", out.warnings[0].message);
    assert!(out.warnings[0].message.contains("the state was skipped"));
    // The link stands and the next state is progressed as usual.
    let out = step(&mut engine, 500_000, Value::List(vec![good("vp1", 0.0, 4.0)].into()));
    assert!(out.warnings.is_empty());
    assert!(engine.describe().contains("-> wo1 maintain ?"));
}

fn arbitrary_value() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(Value::Int),
        (-1e6f64..1e6).prop_map(Value::Float),
        "[a-z]{0,4}".prop_map(|s| Value::str(&s)),
        ((-1e6f64..1e6), (-1e6f64..1e6)).prop_map(|(x, y)| Value::vec2(x, y)),
    ];
    leaf.prop_recursive(3, 24, 6, |inner| {
        prop_oneof![
            proptest::collection::vec(inner.clone(), 0..6).prop_map(|v| Value::List(v.into())),
            (
                proptest::option::of(prop_oneof![
                    Just("vp1".to_string()),
                    Just("vp2".to_string()),
                    "[a-z]{1,3}"
                ]),
                proptest::collection::vec(
                    (prop_oneof![Just("pos"), Just("vel"), Just("size"), Just("x")], inner),
                    0..5
                )
            )
                .prop_map(|(id, fields)| Value::Record(Arc::new(Record {
                    id: id.map(|s| Arc::from(s.as_str())),
                    fields: fields.into_iter().map(|(n, v)| (Arc::from(n), v)).collect(),
                }))),
        ]
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Arbitrary values (mixed with good percepts) as snapshots never panic, and every step
    /// either succeeds or reports why.
    #[test]
    fn arbitrary_snapshots_do_not_panic(snapshots in proptest::collection::vec(arbitrary_value(), 1..12)) {
        let mut engine = engine();
        for (i, snapshot) in snapshots.into_iter().enumerate() {
            let objects = match (i % 3, snapshot) {
                (0, Value::List(items)) => {
                    let mut items = items.to_vec();
                    items.push(good("vp9", i as f64, 4.0));
                    Value::List(items.into())
                }
                (_, other) => other,
            };
            let _ = step(&mut engine, i as i64 * 100_000, objects);
            let _ = engine.world_model();
            let _ = engine.describe();
        }
    }
}
