//! A car's structure handed from the engine of one region to the engine of the next
//! (`Anchoring::hand_over` / `take_over`): on the crossing's west road, region A (x < -40) and
//! region B, each engine with its own percept ids and its own residue class of symbols. The car
//! keeps its world-object and on-road symbols in B, B's percept of it is linked to the handed
//! world object by reestablish, the on-road link goes on with its maintain residual (no
//! `unlinked`), and from then on B's on-road state is the one a single engine that saw the car
//! all along computes. A structure handed over while predicted keeps predicting where it was.
//! Malformed handovers are refused and change nothing.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use kpl_anchor::store::Numbering;
use kpl_anchor::{AnchorConfig, Anchoring, Cause, ChangeKind, HandoverError, InstanceView, StepOutput};
use kpl_core::Value;

const SPEC: &str = common::CROSSING_SPEC;

fn region(index: u64) -> Anchoring {
    let spec = kpl_anchor::registry::check_text(SPEC).unwrap();
    Anchoring::from_spec(
        &spec,
        AnchorConfig { numbering: Numbering::region(index, 2), ..AnchorConfig::default() },
    )
    .unwrap()
}

/// The car at step i (0.1 s): eastbound on `west` (lane centre y = -1.75) at 10 m/s from x = -90,
/// with a little noise across the lane.
fn car(id: &str, i: i64) -> Value {
    let wobble = [0.0, 0.3, -0.2, 0.1, -0.3][(i % 5) as usize];
    common::percept(id, [-90.0 + i as f64, -1.75 + wobble], [10.0, 0.0], 4.5)
}

fn step(engine: &mut Anchoring, i: i64, items: Vec<Value>) -> StepOutput {
    common::step(engine, i * 100_000, &Value::List(items.into()))
}

fn field(engine: &Anchoring, ty: &str, symbol: &str, name: &str) -> Value {
    engine.object(ty, symbol).unwrap().state.as_record().unwrap().get(name).unwrap().clone()
}

/// Symbols and links of the changes of one kind.
fn changes(out: &StepOutput, kind: ChangeKind) -> Vec<(String, Cause)> {
    out.changes.iter().filter(|c| c.kind == kind).map(|c| (c.symbol.to_string(), c.cause)).collect()
}

#[test]
fn a_car_crossing_a_region_border_keeps_its_symbols_and_its_conditions() {
    let (mut a, mut b, mut single) = (region(0), region(1), region(0));
    // Another car in region B first, so that B's store and condition groups hold their own.
    for i in 0..40 {
        step(&mut a, i, vec![car("vp7", i)]);
        step(&mut single, i, vec![car("vp7", i)]);
        step(&mut b, i, vec![common::percept("vp3", [-1.75, 60.0 - i as f64], [0.0, -10.0], 4.5)]);
    }
    // A numbers 1, 3, 5, ...; B 2, 4, ...
    assert_eq!(a.chain("vp7").iter().map(|(_, s)| s.to_string()).collect::<Vec<_>>(), ["wo1", "oo1"]);
    assert_eq!(b.chain("vp3").iter().map(|(_, s)| s.to_string()).collect::<Vec<_>>(), ["wo2", "oo2"]);
    let maintain_before = a.instance("world_onroad", "wo1");
    assert_eq!(maintain_before, Some(InstanceView::Linked { to: "oo1".into(), maintain: None }));

    // At 3.9 s (x = -51) the car's world object leaves A for B.
    let (handover, out) = a.hand_over("WorldObject", "wo1").unwrap();
    assert_eq!(handover.objects.len(), 2);
    assert_eq!(handover.instances.len(), 1, "world_onroad's instance of wo1; vp7's stays in A");
    assert_eq!(
        changes(&out, ChangeKind::Removed),
        [("wo1".into(), Cause::HandedOver), ("oo1".into(), Cause::HandedOver)]
    );
    assert_eq!(changes(&out, ChangeKind::Unlinked), [("wo1".into(), Cause::HandedOver)]);
    assert!(a.object("WorldObject", "wo1").is_none() && a.object("OnRoadObject", "oo1").is_none());
    assert!(matches!(a.instance("vision_world", "vp7"), Some(InstanceView::Unlinked { .. })));

    let out = b.take_over(&handover).unwrap();
    assert_eq!(
        changes(&out, ChangeKind::Created),
        [("wo1".into(), Cause::HandedOver), ("oo1".into(), Cause::HandedOver)]
    );
    assert_eq!(changes(&out, ChangeKind::Linked), [("oo1".into(), Cause::HandedOver)]);
    assert_eq!(b.instance("world_onroad", "wo1"), maintain_before);
    // The same structure is refused a second time: its symbols are in use.
    assert!(matches!(b.take_over(&handover), Err(HandoverError::SymbolInUse(_))));

    // From 4.0 s B's tracker sees the car under its own id; the single engine goes on with A's.
    for i in 40..120 {
        let other = common::percept("vp3", [-1.75, 60.0 - i as f64], [0.0, -10.0], 4.5);
        let out = step(&mut b, i, vec![car("vp11", i), other]);
        step(&mut single, i, vec![car("vp7", i)]);
        assert!(
            out.changes.iter().all(|c| c.kind != ChangeKind::Created || c.symbol.starts_with("vp")),
            "step {i}: B made a new object for the car: {:?}",
            out.changes
        );
        let car_unlinked =
            changes(&out, ChangeKind::Unlinked).into_iter().any(|(s, _)| s == "wo1" || s == "oo1");
        assert!(!car_unlinked, "step {i}: {:?}", out.changes);
        if i == 40 {
            assert_eq!(changes(&out, ChangeKind::Linked), [("wo1".into(), Cause::Reestablish)]);
        }
        if i > 40 {
            for name in ["pos", "vel", "road", "lane_offset"] {
                assert_eq!(
                    field(&b, "OnRoadObject", "oo1", name),
                    field(&single, "OnRoadObject", "oo1", name),
                    "step {i}: oo1.{name}"
                );
            }
        }
    }
    assert_eq!(b.chain("vp11").iter().map(|(_, s)| s.to_string()).collect::<Vec<_>>(), ["wo1", "oo1"]);
    assert_eq!(b.instance("world_onroad", "wo1"), single.instance("world_onroad", "wo1"));
    assert_eq!(
        b.object("OnRoadObject", "oo1").unwrap().status,
        single.object("OnRoadObject", "oo1").unwrap().status
    );
}

#[test]
fn a_predicted_structure_goes_on_predicting_where_it_was() {
    let (mut a, mut b, mut single) = (region(0), region(1), region(0));
    // Seen for 4 s, then lost: its on-road object is predicted along the road.
    for i in 0..40 {
        step(&mut a, i, vec![car("vp1", i)]);
        step(&mut single, i, vec![car("vp1", i)]);
    }
    for i in 40..45 {
        step(&mut a, i, vec![]);
        step(&mut single, i, vec![]);
        step(&mut b, i, vec![]);
    }
    assert!(a.object("OnRoadObject", "oo1").unwrap().predicted);
    let (handover, _) = a.hand_over("WorldObject", "wo1").unwrap();
    assert!(handover.objects[0].prediction.is_some(), "the prediction goes with the structure");
    b.take_over(&handover).unwrap();
    for i in 45..60 {
        step(&mut b, i, vec![]);
        step(&mut single, i, vec![]);
        assert_eq!(
            field(&b, "OnRoadObject", "oo1", "pos"),
            field(&single, "OnRoadObject", "oo1", "pos"),
            "step {i}"
        );
        assert_eq!(b.object("WorldObject", "wo1").unwrap().predicted_since, Some(4_000_000));
    }
}

#[test]
fn malformed_handovers_are_refused_and_change_nothing() {
    let (mut a, mut b) = (region(0), region(1));
    for i in 0..40 {
        step(&mut a, i, vec![car("vp1", i)]);
        step(&mut b, i, vec![]);
    }
    assert!(matches!(a.hand_over("WorldObject", "wo9"), Err(HandoverError::NoObject { .. })));
    let (good, _) = a.hand_over("WorldObject", "wo1").unwrap();
    assert_eq!((good.objects.len(), good.instances[0].to), (2, Some(1)), "wo1 -> oo1");
    let before = b.describe();
    let refused = |b: &mut Anchoring, edit: &dyn Fn(&mut kpl_anchor::StructureHandover)| {
        let mut bad = good.clone();
        edit(&mut bad);
        let error = b.take_over(&bad).expect_err("a malformed handover");
        assert_eq!(b.describe(), before, "{error}");
        error
    };
    assert!(matches!(refused(&mut b, &|h| h.objects[0].ty = "Car".into()), HandoverError::UnknownType(_)));
    assert!(matches!(
        refused(&mut b, &|h| h.instances[0].link = "nowhere".into()),
        HandoverError::UnknownLink(_)
    ));
    assert!(matches!(refused(&mut b, &|h| h.instances[0].to = Some(9)), HandoverError::Malformed(_)));
    let wrong_type = refused(&mut b, &|h| h.instances[0].from = 1);
    assert!(matches!(wrong_type, HandoverError::UnknownLink(_)), "{wrong_type}");
    assert!(matches!(refused(&mut b, &|h| h.objects[1].symbol = "oo7".into()), HandoverError::Malformed(_)));
    let broken_residual = |h: &mut kpl_anchor::StructureHandover| {
        if let kpl_anchor::handover::HandedCondition::Pending(residual) = &mut h.instances[0].condition {
            residual.formula ^= 1;
        }
    };
    assert!(matches!(refused(&mut b, &broken_residual), HandoverError::Condition { .. }));
    b.take_over(&good).unwrap();
}

/// The step at which an object of type `ty` is first created, in steps `range` of a run.
fn first_created(outs: &[(i64, StepOutput)], ty: &str) -> Option<i64> {
    outs.iter()
        .find(|(_, out)| out.changes.iter().any(|c| c.kind == ChangeKind::Created && &*c.ty == ty))
        .map(|(i, _)| *i)
}

#[test]
fn a_pending_establish_goes_on_where_it_was() {
    let (mut a, mut b, mut single) = (region(0), region(1), region(0));
    // 1.6 s: the world object exists, its on-road object not yet (the on-road establish needs the
    // car on the road for 1 s after 1 s).
    for i in 0..16 {
        step(&mut a, i, vec![car("vp1", i)]);
        step(&mut single, i, vec![car("vp1", i)]);
        step(&mut b, i, vec![]);
    }
    assert!(a.object("WorldObject", "wo1").is_some() && a.object("OnRoadObject", "oo1").is_none());
    let (handover, _) = a.hand_over("WorldObject", "wo1").unwrap();
    assert!(matches!(
        handover.instances[..],
        [kpl_anchor::handover::HandedInstance {
            to: None,
            condition: kpl_anchor::handover::HandedCondition::Pending(_),
            ..
        }]
    ));
    b.take_over(&handover).unwrap();
    let mut there = Vec::new();
    let mut stayed = Vec::new();
    for i in 16..40 {
        there.push((i, step(&mut b, i, vec![car("vp11", i)])));
        stayed.push((i, step(&mut single, i, vec![car("vp1", i)])));
    }
    let created = first_created(&stayed, "OnRoadObject");
    assert!(created.is_some());
    assert_eq!(first_created(&there, "OnRoadObject"), created, "the establish condition went on, not over");
    assert_eq!(b.chain("vp11").iter().map(|(_, s)| s.to_string()).collect::<Vec<_>>(), ["wo1", "oo2"]);
}
