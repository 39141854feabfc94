//! Tests of the `aapa.anchor` unit driven state by state as the runtime drives it, against the
//! library run directly.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::sync::Arc;

use kpl_aapa::gearbox;
use kpl_core::{FieldType, RecordType};
use kpl_runtime::process::Trigger;

use super::values::{action_value, percept_value, pose_value};
use super::*;

fn names() -> Vec<Arc<str>> {
    ["percepts", "actions", "poses", "previous"].into_iter().map(Arc::from).collect()
}

/// Runs the unit on one state and returns what it emitted.
fn state(unit: &mut AnchorUnit, valid: Time, values: &[Option<Sample>]) -> Vec<Value> {
    let names = names();
    let input = Input { now: valid, valid, trigger: Trigger::State, values, names: &names };
    let mut out = Emitter::new(Arc::from(Vec::<String>::new()));
    unit.on_input(&input, &mut out).unwrap();
    out.take()
        .into_iter()
        .map(|(port, s)| {
            assert_eq!(port, 0);
            s.value
        })
        .collect()
}

/// Runs the unit on one state that must fail, and returns the error.
fn failing_state(unit: &mut AnchorUnit, valid: Time, values: &[Option<Sample>]) -> String {
    let names = names();
    let input = Input { now: valid, valid, trigger: Trigger::State, values, names: &names };
    let mut out = Emitter::new(Arc::from(Vec::<String>::new()));
    unit.on_input(&input, &mut out).unwrap_err().to_string()
}

fn s(valid: Time, value: Value) -> Option<Sample> {
    Some(Sample::new(valid, valid, value))
}

fn frame(c: &gearbox::Cycle) -> Value {
    Value::List(c.percepts.iter().map(percept_value).collect())
}

fn actions(list: &[Action]) -> Value {
    Value::List(list.iter().map(|a| action_value(a, 0)).collect())
}

/// The unit's four inputs for a frame of the scenario: its percepts, these actions and this pose at
/// the frame's time, and the fed-back world.
fn inputs(
    c: &gearbox::Cycle,
    list: &[Action],
    pose: &CameraPose,
    fed_back: Option<Sample>,
) -> [Option<Sample>; 4] {
    [s(c.time, frame(c)), s(c.time, actions(list)), s(c.time, pose_value(pose)), fed_back]
}

fn gearbox_unit() -> AnchorUnit {
    AnchorUnit::new(Aapa::new(gearbox::params()).unwrap())
}

#[test]
fn the_unit_with_its_feedback_reproduces_the_library_run() {
    // The whole gearbox scenario, each state carrying the unit's previous output as the fed-back
    // world: the same world states as calling the library in a loop, and no fallback notes.
    let cycles = gearbox::scenario();
    let aapa = Aapa::new(gearbox::params()).unwrap();
    let mut unit = gearbox_unit();
    let mut expected = WorldState::default();
    let mut fed_back: Option<Sample> = None;
    for c in &cycles {
        expected = aapa.step(c.time, &c.percepts, &c.actions, Some(&c.camera), &expected).unwrap();
        let values = inputs(c, &c.actions, &c.camera, fed_back.clone());
        let out = state(&mut unit, c.time, &values);
        assert_eq!(out.len(), 1);
        assert_eq!(world_from_value(&out[0]).unwrap(), expected, "t={}", c.time);
        fed_back = s(c.time, out[0].clone());
    }
    assert!(expected.has_relation("mounted", "case0", "case1"));
}

#[test]
fn actions_between_frames_apply_once_at_the_next_frame() {
    let cycles = gearbox::scenario();
    let aapa = Aapa::new(gearbox::params()).unwrap();
    // Anchor everything first (the scenario's opening cycles have no actions).
    let mut unit = gearbox_unit();
    let mut expected = WorldState::default();
    let mut fed_back = None;
    let opening = &cycles[..20];
    for c in opening {
        assert!(c.actions.is_empty());
        expected = aapa.step(c.time, &c.percepts, &[], Some(&c.camera), &expected).unwrap();
        let values = inputs(c, &[], &c.camera, fed_back);
        fed_back = s(c.time, state(&mut unit, c.time, &values).remove(0));
    }
    let last = &opening[opening.len() - 1];
    // Applying either twice would show: `pick_up` attaches, `move` (started) stamps when the move
    // began.
    let pick = vec![
        Action::completed("pick_up", &["gripper0", "hub_cover0"]),
        Action::started("move", &["human", "plug0"], Some(last.time + 2_000_000)),
    ];
    // A state with only an action (the frame is the previous one, approximated): no cycle.
    let between = last.time + 50_000;
    let values = [
        s(last.time, frame(last)),
        s(between, actions(&pick)),
        s(last.time, pose_value(&last.camera)),
        fed_back.clone(),
    ];
    assert!(state(&mut unit, between, &values).is_empty());
    // The next two frames: the action applies at the first, and is not applied again at the second
    // though the state repeats it as the most recent actions sample.
    for (k, c) in cycles[20..22].iter().enumerate() {
        let applied: &[Action] = if k == 0 { &pick } else { &[] };
        expected = aapa.step(c.time, &c.percepts, applied, Some(&c.camera), &expected).unwrap();
        let values =
            [s(c.time, frame(c)), s(between, actions(&pick)), s(c.time, pose_value(&c.camera)), fed_back];
        let out = state(&mut unit, c.time, &values);
        assert_eq!(world_from_value(&out[0]).unwrap(), expected);
        fed_back = s(c.time, out[0].clone());
    }
    assert!(expected.has_relation("holding", "gripper0", "hub_cover0"));
    assert_eq!(expected.anchor("plug0").unwrap().moving_since, Some(cycles[20].time));
}

#[test]
fn a_world_that_has_not_come_back_is_replaced_by_the_units_copy_with_a_note() {
    let cycles = gearbox::scenario();
    let aapa = Aapa::new(gearbox::params()).unwrap();
    let mut unit = gearbox_unit();
    let (c0, c1, c2) = (&cycles[0], &cycles[1], &cycles[2]);
    let w0 = aapa.step(c0.time, &c0.percepts, &[], Some(&c0.camera), &WorldState::default()).unwrap();
    let w1 = aapa.step(c1.time, &c1.percepts, &[], Some(&c1.camera), &w0).unwrap();
    let run = |unit: &mut AnchorUnit, c: &gearbox::Cycle, fed_back: Option<Sample>| {
        let values = inputs(c, &[], &c.camera, fed_back);
        world_from_value(&state(unit, c.time, &values)[0]).unwrap()
    };
    assert_eq!(run(&mut unit, c0, None), w0);
    // The feedback of cycle 0 has not arrived: the unit uses its own copy, and says so.
    let got = run(&mut unit, c1, None);
    assert_eq!(got.anchors, w1.anchors);
    assert_eq!(got.notes.len(), w1.notes.len() + 1);
    assert!(got.notes.last().unwrap().contains("had not come back"), "{:?}", got.notes);
    // A stale world (cycle 0's, when cycle 1 was the last) is not used either.
    let stale = s(c0.time, world_to_value(&w0));
    let w2 = aapa.step(c2.time, &c2.percepts, &[], Some(&c2.camera), &got).unwrap();
    let got2 = run(&mut unit, c2, stale);
    assert_eq!(got2.anchors, w2.anchors);
    assert!(got2.notes.last().unwrap().contains("had not come back"));
}

#[test]
fn a_bad_input_fails_one_cycle_and_the_next_goes_on() {
    let cycles = gearbox::scenario();
    let mut unit = gearbox_unit();
    let c = &cycles[0];
    let mut values = inputs(c, &[], &c.camera, None);
    values[PERCEPTS] = s(c.time, Value::Int(3));
    let err = failing_state(&mut unit, c.time, &values);
    assert!(err.contains("t=0: the percepts: expected a list"), "{err}");
    let values = inputs(c, &[], &c.camera, None);
    assert_eq!(state(&mut unit, c.time, &values).len(), 1);
}

fn record_type(name: &str, fields: &[(&str, ValueType)]) -> ValueType {
    ValueType::Record(Arc::new(RecordType {
        name: name.into(),
        parent: None,
        symbol: name.to_lowercase().into(),
        fields: fields.iter().map(|(n, t)| FieldType { name: (*n).into(), ty: t.clone() }).collect(),
    }))
}

fn list_of(t: ValueType) -> ValueType {
    ValueType::List(Box::new(t))
}

#[test]
fn declared_output_types_are_checked_against_the_world_state() {
    use ValueType::{BBox, Bool, Float, Int, Str};
    let anchor = record_type(
        "Anchor",
        &[
            ("symbol", Str),
            ("type", Str),
            ("box", BBox),
            ("confidence", Float),
            ("status", Str),
            ("for_inference", Bool),
        ],
    );
    let relation = record_type("Relation", &[("name", Str), ("args", list_of(Str))]);
    let world = |anchor: ValueType, extra: &[(&str, ValueType)]| {
        let mut fields =
            vec![("time", Int), ("anchors", list_of(anchor)), ("relations", list_of(relation.clone()))];
        fields.extend(extra.iter().cloned());
        record_type("World", &fields)
    };
    check_output_type(&world(anchor.clone(), &[])).unwrap();
    check_output_type(&world(ValueType::Any, &[("notes", list_of(Str))])).unwrap();
    // `first_seen` is an int; declaring it float is fine (ints widen), string is not.
    check_output_type(&world(record_type("A", &[("first_seen", Float)]), &[])).unwrap();
    let err = check_output_type(&world(record_type("A", &[("first_seen", Str)]), &[])).unwrap_err();
    assert!(err.contains("`A.first_seen` is declared string"), "{err}");
    let err = check_output_type(&world(record_type("A", &[("colour", Str)]), &[])).unwrap_err();
    assert!(err.contains("declares `colour`") && err.contains("symbol: string"), "{err}");
    let err = check_output_type(&world(anchor.clone(), &[("weather", Str)])).unwrap_err();
    assert!(err.contains("declares `weather`"), "{err}");
    let err = check_output_type(&world(Str, &[])).unwrap_err();
    assert!(err.contains("list<string>"), "{err}");
}

#[test]
fn a_declared_colour_must_be_a_string_or_a_list_of_floats() {
    use ValueType::{BBox, Int, Str};
    let detection = |colour: ValueType| {
        list_of(record_type("Detection", &[("label", Str), ("type", Str), ("box", BBox), ("colour", colour)]))
    };
    check_percepts_type(&detection(Str)).unwrap();
    check_percepts_type(&detection(list_of(ValueType::Float))).unwrap();
    assert!(check_percepts_type(&detection(Int)).unwrap_err().contains("`Detection.colour` is declared int"));
}

#[test]
fn the_entry_documents_every_parameter_with_the_papers_defaults() {
    let entry = anchor_entry();
    for p in &entry.params {
        assert!(p.default.is_some() && !p.doc.is_empty(), "{}", p.name);
    }
    let default =
        |name: &str| entry.param_named(name).and_then(|p| p.default.clone()).and_then(|v| v.as_f64());
    // Paper section IV-B (LA-CATER).
    assert_eq!(default("theta"), Some(6500.0));
    assert_eq!(default("theta_anch"), Some(0.1));
    assert_eq!(default("conf_plus"), Some(0.1));
    assert_eq!(default("conf_minus"), Some(0.1));
    assert!(default("type_mismatch").is_some() && default("theta_inf").is_some());
}

#[test]
fn without_a_camera_model_the_camera_must_stay_still() {
    // A fixed camera (CATER) needs no model: the same pose every cycle runs the library without one.
    let cycles = gearbox::scenario();
    let aapa = Aapa::new(Params::default()).unwrap();
    let mut unit = AnchorUnit::new(aapa.clone());
    let still = CameraPose { x: 0.1, y: 0.2, z: 0.0 };
    let mut expected = WorldState::default();
    let mut fed_back = None;
    for c in &cycles[..3] {
        expected = aapa.step(c.time, &c.percepts, &[], None, &expected).unwrap();
        let values = inputs(c, &[], &still, fed_back);
        let out = state(&mut unit, c.time, &values);
        assert_eq!(world_from_value(&out[0]).unwrap(), expected);
        fed_back = s(c.time, out[0].clone());
    }
    // A pose that moves cannot be compensated: the cycle fails and says what to set.
    let c = &cycles[3];
    let moved = CameraPose { x: 0.15, ..still };
    let err = failing_state(&mut unit, c.time, &inputs(c, &[], &moved, fed_back));
    assert!(err.contains("the camera moved") && err.contains("set `focal_px`"), "{err}");
}

#[test]
fn a_world_edited_on_its_way_back_is_the_one_used() {
    // The feedback may pass through another process (a world model editor): the unit continues
    // from the world that comes back, not from the one it sent.
    let cycles = gearbox::scenario();
    let aapa = Aapa::new(gearbox::params()).unwrap();
    let mut unit = gearbox_unit();
    let run = |unit: &mut AnchorUnit, c: &gearbox::Cycle, fed_back: Option<Sample>| {
        state(unit, c.time, &inputs(c, &c.actions, &c.camera, fed_back)).remove(0)
    };
    let mut fed_back = None;
    for c in &cycles[..30] {
        fed_back = s(c.time, run(&mut unit, c, fed_back));
    }
    let sent = world_from_value(&fed_back.as_ref().unwrap().value).unwrap();
    let mut edited = sent.clone();
    edited.anchors.retain(|a| &*a.symbol != "plug0");
    assert_eq!(edited.anchors.len() + 1, sent.anchors.len());
    let c = &cycles[30];
    let got = world_from_value(&run(&mut unit, c, s(cycles[29].time, world_to_value(&edited)))).unwrap();
    let want = aapa.step(c.time, &c.percepts, &c.actions, Some(&c.camera), &edited).unwrap();
    assert_eq!(got, want);
    // The edit shows: the anchor `plug0` had been there for 30 cycles, and is not any more.
    let unedited = aapa.step(c.time, &c.percepts, &c.actions, Some(&c.camera), &sent).unwrap();
    assert!(unedited.anchor("plug0").is_some_and(|a| a.first_seen == 0));
    assert!(got.anchor("plug0").is_none_or(|a| a.first_seen == c.time), "{:?}", got.anchor("plug0"));
    // An equal copy (decoded, not the very value sent) gives what the value sent gives.
    let copy = s(cycles[29].time, world_to_value(&sent));
    let mut other = gearbox_unit();
    let mut fed = None;
    for c in &cycles[..30] {
        fed = s(c.time, run(&mut other, c, fed));
    }
    let from_copy = world_from_value(&run(&mut other, c, copy)).unwrap();
    assert_eq!(from_copy, unedited);
}
