//! Conversions between KPL values and the AAPA library's types: detections, actions and camera
//! poses coming in, the world state going out and coming back through the feedback stream.
//!
//! The KPL shapes (docs/aapa.md):
//!
//! | stream | value |
//! |---|---|
//! | percepts | `list<{label: string, type: string, box: box, colour?}>`, one snapshot per frame |
//! | actions | `list<{name: string, args: list<string>, phase?: string, expected_end?: int}>` |
//! | poses | `{x: float, y: float, z: float}` |
//! | world | `{time: int, anchors: list<Anchor>, relations: list<{name, args}>, notes: list<string>}` |
//!
//! A world state's anchors carry the fields users declare (`symbol`, `type`, `box`, `confidence`,
//! `status`, ...) first, then the rest of the anchor's memory (attachment geometry, motion state,
//! type votes) where set, under the names the library's serde uses, so the world fed back into the
//! next cycle is the complete model (paper Fig. 2). [`world_to_value`] is written by hand (it runs
//! every cycle); [`world_from_value`] reads back through the library's serde, and the tests check
//! that it restores exactly what was written.

use std::sync::Arc;

use kpl_aapa::{Action, ActionPhase, Anchor, AnchorStatus, CameraPose, Percept, Relation, WorldState};
use kpl_core::{BBox, Record, Time, Value, ValueType};

/// The anchor fields every world state has, with their KPL types: what a declared anchor type may
/// name. (`camera`, `colour`, `attachment`, ... appear only when they have a value.)
pub(crate) fn anchor_fields() -> Vec<(&'static str, ValueType)> {
    use ValueType::{BBox, Bool, Float, Int, Str, Vec2};
    vec![
        ("symbol", Str),
        ("type", Str),
        ("box", BBox),
        ("confidence", Float),
        ("status", Str),
        ("for_inference", Bool),
        ("first_seen", Int),
        ("last_seen", Int),
        ("velocity", Vec2),
        ("moving", Bool),
    ]
}

/// The fields of a relation.
pub(crate) fn relation_fields() -> Vec<(&'static str, ValueType)> {
    vec![("name", ValueType::Str), ("args", ValueType::List(Box::new(ValueType::Str)))]
}

/// The fields of a world state besides its two lists.
pub(crate) fn world_scalar_fields() -> Vec<(&'static str, ValueType)> {
    vec![("time", ValueType::Int), ("notes", ValueType::List(Box::new(ValueType::Str)))]
}

/// The word a world state uses for a status.
pub(crate) fn status_name(status: AnchorStatus) -> &'static str {
    match status {
        AnchorStatus::Visible => "visible",
        AnchorStatus::Occluded => "occluded",
        AnchorStatus::OutOfView => "out_of_view",
        AnchorStatus::Attached => "attached",
        AnchorStatus::Lost => "lost",
    }
}

pub(super) fn record(fields: Vec<(&str, Value)>) -> Value {
    Value::Record(Arc::new(Record {
        id: None,
        fields: fields.into_iter().map(|(name, value)| (Arc::from(name), value)).collect(),
    }))
}

fn strings<'a>(items: impl IntoIterator<Item = &'a Arc<str>>) -> Value {
    Value::List(items.into_iter().map(|s| Value::Str(s.clone())).collect())
}

fn field<'a>(r: &'a Record, name: &str, what: &str) -> Result<&'a Value, String> {
    r.get(name).ok_or_else(|| format!("{what} has no field `{name}`"))
}

fn string_field(r: &Record, name: &str, what: &str) -> Result<Arc<str>, String> {
    match field(r, name, what)? {
        Value::Str(s) => Ok(s.clone()),
        other => Err(format!("{what}: `{name}`: expected a string, found {}", other.kind())),
    }
}

fn number(value: &Value, what: &str) -> Result<f64, String> {
    match value.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        _ => Err(format!("{what}: expected a finite number, found {value}")),
    }
}

fn list<'a>(value: &'a Value, what: &str) -> Result<&'a [Value], String> {
    match value {
        Value::List(items) => Ok(items),
        other => Err(format!("{what}: expected a list, found {}", other.kind())),
    }
}

fn as_record<'a>(value: &'a Value, what: &str) -> Result<&'a Record, String> {
    value.as_record().ok_or_else(|| format!("{what}: expected a record, found {}", value.kind()))
}

/// A box: a `box` value, or (from an untyped stream) a list of four numbers.
fn bbox(value: &Value, what: &str) -> Result<BBox, String> {
    match value {
        Value::BBox(b) => Ok(**b),
        Value::List(items) if items.len() == 4 => {
            let n = |i: usize| number(&items[i], what);
            Ok(BBox::new(n(0)?, n(1)?, n(2)?, n(3)?))
        }
        other => Err(format!("{what}: expected a box [x1, y1, x2, y2], found {}", other.kind())),
    }
}

/// A colour: absent or empty (none), `[r, g, b]` in [0, 1], or a string `#rrggbb`.
fn colour(value: Option<&Value>, what: &str) -> Result<Option<[f64; 3]>, String> {
    match value {
        None => Ok(None),
        Some(Value::Str(s)) if s.is_empty() => Ok(None),
        Some(Value::Str(s)) => {
            let hex = s.strip_prefix('#').filter(|h| h.len() == 6 && h.is_ascii());
            let channel = |i: usize| {
                hex.and_then(|h| u8::from_str_radix(&h[2 * i..2 * i + 2], 16).ok())
                    .map(|c| f64::from(c) / 255.0)
            };
            match (channel(0), channel(1), channel(2)) {
                (Some(r), Some(g), Some(b)) => Ok(Some([r, g, b])),
                _ => Err(format!("{what}: `colour`: expected [r, g, b] or \"#rrggbb\", found \"{s}\"")),
            }
        }
        Some(Value::List(items)) if items.is_empty() => Ok(None),
        Some(Value::List(items)) if items.len() == 3 => {
            let mut rgb = [0.0; 3];
            for (slot, item) in rgb.iter_mut().zip(items.iter()) {
                *slot = number(item, &format!("{what}: a colour channel"))?;
            }
            Ok(Some(rgb))
        }
        Some(other) => Err(format!("{what}: `colour`: expected [r, g, b] or \"#rrggbb\", found {other}")),
    }
}

/// The detections of one frame.
pub(crate) fn percepts_from_value(value: &Value) -> Result<Vec<Percept>, String> {
    let items = list(value, "the percepts")?;
    let mut percepts = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let what = format!("detection {i}");
        let r = as_record(item, &what)?;
        percepts.push(Percept {
            label: string_field(r, "label", &what)?,
            object_type: string_field(r, "type", &what)?,
            bbox: bbox(field(r, "box", &what)?, &format!("{what}: `box`"))?,
            colour: colour(r.get("colour"), &what)?,
        });
    }
    Ok(percepts)
}

/// A detection as a record (what `sim.gearbox` and `cater.video` emit).
pub(crate) fn percept_value(p: &Percept) -> Value {
    let mut fields = vec![
        ("label", Value::Str(p.label.clone())),
        ("type", Value::Str(p.object_type.clone())),
        ("box", Value::bbox(p.bbox)),
    ];
    if let Some(rgb) = p.colour {
        fields.push(("colour", Value::List(rgb.iter().map(|c| Value::Float(*c)).collect())));
    }
    record(fields)
}

/// The actions of one sample.
pub(crate) fn actions_from_value(value: &Value) -> Result<Vec<Action>, String> {
    let items = list(value, "the actions")?;
    let mut actions = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let what = format!("action {i}");
        let r = as_record(item, &what)?;
        let name = string_field(r, "name", &what)?;
        let mut args = Vec::new();
        for arg in list(field(r, "args", &what)?, &format!("{what}: `args`"))? {
            match arg {
                Value::Str(s) => args.push(s.clone()),
                other => {
                    return Err(format!("{what}: an argument: expected a string, found {}", other.kind()));
                }
            }
        }
        let phase = match r.get("phase") {
            None => ActionPhase::Completed,
            Some(Value::Str(s)) if &**s == "completed" || s.is_empty() => ActionPhase::Completed,
            Some(Value::Str(s)) if &**s == "started" => ActionPhase::Started,
            Some(other) => {
                return Err(format!("{what}: `phase`: expected \"started\" or \"completed\", found {other}"));
            }
        };
        let expected_end = match r.get("expected_end") {
            None => None,
            Some(Value::Int(t) | Value::Duration(t)) => Some(*t),
            Some(other) => {
                return Err(format!("{what}: `expected_end`: expected microseconds, found {}", other.kind()));
            }
        };
        actions.push(Action { name, args, phase, expected_end });
    }
    Ok(actions)
}

/// An action as a record; `shift` moves its expected end onto the run's clock.
pub(crate) fn action_value(a: &Action, shift: Time) -> Value {
    let phase = match a.phase {
        ActionPhase::Started => "started",
        ActionPhase::Completed => "completed",
    };
    let mut fields =
        vec![("name", Value::Str(a.name.clone())), ("args", strings(&a.args)), ("phase", Value::str(phase))];
    if let Some(end) = a.expected_end {
        fields.push(("expected_end", Value::Int(end.saturating_add(shift))));
    }
    record(fields)
}

pub(crate) fn pose_from_value(value: &Value) -> Result<CameraPose, String> {
    let r = as_record(value, "the camera pose")?;
    let coordinate = |name: &str| number(field(r, name, "the camera pose")?, &format!("the pose's `{name}`"));
    Ok(CameraPose { x: coordinate("x")?, y: coordinate("y")?, z: coordinate("z")? })
}

pub(crate) fn pose_value(pose: &CameraPose) -> Value {
    record(vec![("x", Value::Float(pose.x)), ("y", Value::Float(pose.y)), ("z", Value::Float(pose.z))])
}

/// The fields every anchor record starts with, in order.
#[cfg(test)]
const ANCHOR_OWN_FIELDS: [&str; 10] = [
    "symbol",
    "type",
    "box",
    "confidence",
    "status",
    "for_inference",
    "first_seen",
    "last_seen",
    "velocity",
    "moving",
];

macro_rules! field_names {
    ($($field:ident = $text:literal),* $(,)?) => {
        /// Field names of world states, allocated once and shared by every record built here.
        struct Names { $($field: Arc<str>),* }
        impl Names {
            fn new() -> Names {
                Names { $($field: Arc::from($text)),* }
            }
        }
    };
}

field_names! {
    symbol = "symbol", object_type = "type", bbox = "box", confidence = "confidence", status = "status",
    for_inference = "for_inference", first_seen = "first_seen", last_seen = "last_seen",
    velocity = "velocity", moving = "moving", colour = "colour", moving_until = "moving_until",
    moving_since = "moving_since", full_size = "full_size", last_percept_box = "last_percept_box",
    partial = "partial", attachment = "attachment", parent = "parent", relation = "relation",
    offset = "offset", size = "size", parent_scale = "parent_scale", type_votes = "type_votes",
    name = "name", args = "args", time = "time", camera = "camera", anchors = "anchors",
    relations = "relations", notes = "notes", bindings = "bindings", hidden = "hidden",
    still = "still", mean = "mean", count = "count", provisional = "provisional",
    parent_size = "parent_size", turning = "turning", move_track = "move_track", settling = "settling",
    strays = "strays", last_moved = "last_moved",
}

static NAMES: std::sync::LazyLock<Names> = std::sync::LazyLock::new(Names::new);

fn named(fields: Vec<(Arc<str>, Value)>) -> Value {
    Value::Record(Arc::new(Record { id: None, fields }))
}

fn floats(values: &[f64]) -> Value {
    Value::List(values.iter().map(|x| Value::Float(*x)).collect())
}

fn relation_value(r: &Relation) -> Value {
    let n = &*NAMES;
    named(vec![(n.name.clone(), Value::Str(r.name.clone())), (n.args.clone(), strings(&r.args))])
}

/// An anchor: the fields users declare, then its memory where set, named as the library's serde
/// names them (so [`world_from_value`] reads it back with serde).
fn anchor_value(a: &Anchor) -> Value {
    let n = &*NAMES;
    // Every field, so that a field added to the library's anchor is a compile error here.
    let Anchor {
        symbol,
        object_type,
        bbox,
        confidence,
        status,
        colour,
        first_seen,
        last_seen,
        velocity,
        moving,
        moving_until,
        full_size,
        last_percept_box,
        partial,
        moving_since,
        move_track,
        turning,
        last_moved,
        attachment,
        for_inference,
        type_votes,
        still,
    } = a;
    let mut fields = vec![
        (n.symbol.clone(), Value::Str(symbol.clone())),
        (n.object_type.clone(), Value::Str(object_type.clone())),
        (n.bbox.clone(), Value::bbox(*bbox)),
        (n.confidence.clone(), Value::Float(*confidence)),
        (n.status.clone(), Value::str(status_name(*status))),
        (n.for_inference.clone(), Value::Bool(*for_inference)),
        (n.first_seen.clone(), Value::Int(*first_seen)),
        (n.last_seen.clone(), Value::Int(*last_seen)),
        (n.velocity.clone(), Value::Vec2(*velocity)),
        (n.moving.clone(), Value::Bool(*moving)),
    ];
    if let Some(rgb) = colour {
        fields.push((n.colour.clone(), floats(rgb)));
    }
    if let Some(t) = moving_until {
        fields.push((n.moving_until.clone(), Value::Int(*t)));
    }
    if let Some(t) = moving_since {
        fields.push((n.moving_since.clone(), Value::Int(*t)));
    }
    if !move_track.is_empty() {
        fields.push((n.move_track.clone(), Value::List(move_track.iter().map(|p| floats(p)).collect())));
    }
    if *turning {
        fields.push((n.turning.clone(), Value::Bool(true)));
    }
    if let Some(t) = last_moved {
        fields.push((n.last_moved.clone(), Value::Int(*t)));
    }
    if let Some(wh) = full_size {
        fields.push((n.full_size.clone(), floats(wh)));
    }
    if let Some(b) = last_percept_box {
        fields.push((n.last_percept_box.clone(), floats(b)));
    }
    if *partial {
        fields.push((n.partial.clone(), Value::Bool(true)));
    }
    if let Some(att) = attachment {
        let mut geometry = vec![(n.parent.clone(), Value::Str(att.parent.clone()))];
        if let Some(r) = &att.relation {
            geometry.push((n.relation.clone(), relation_value(r)));
        }
        geometry.push((n.offset.clone(), floats(&att.offset)));
        geometry.push((n.size.clone(), floats(&att.size)));
        geometry.push((n.parent_scale.clone(), Value::Float(att.parent_scale)));
        geometry.push((n.parent_size.clone(), floats(&att.parent_size)));
        if att.hidden {
            geometry.push((n.hidden.clone(), Value::Bool(true)));
        }
        if att.provisional {
            geometry.push((n.provisional.clone(), Value::Bool(true)));
        }
        if att.settling {
            geometry.push((n.settling.clone(), Value::Bool(true)));
        }
        fields.push((n.attachment.clone(), named(geometry)));
    }
    if let Some(still) = still {
        let mut mean = vec![
            (n.mean.clone(), floats(&still.mean)),
            (n.count.clone(), Value::Int(i64::from(still.count))),
        ];
        if still.strays > 0 {
            mean.push((n.strays.clone(), Value::Int(i64::from(still.strays))));
        }
        fields.push((n.still.clone(), named(mean)));
    }
    if !type_votes.is_empty() {
        let votes = type_votes
            .iter()
            .map(|(t, count)| Value::List(vec![Value::Str(t.clone()), Value::Int(i64::from(*count))].into()))
            .collect();
        fields.push((n.type_votes.clone(), Value::List(votes)));
    }
    named(fields)
}

/// A world state as a record value.
pub(crate) fn world_to_value(w: &WorldState) -> Value {
    let n = &*NAMES;
    let mut fields = Vec::with_capacity(5);
    if let Some(time) = w.time {
        fields.push((n.time.clone(), Value::Int(time)));
    }
    if let Some(camera) = &w.camera {
        fields.push((n.camera.clone(), pose_value(camera)));
    }
    fields.push((n.anchors.clone(), Value::List(w.anchors.iter().map(anchor_value).collect())));
    fields.push((n.relations.clone(), Value::List(w.relations.iter().map(relation_value).collect())));
    fields.push((n.notes.clone(), Value::List(w.notes.iter().map(|note| Value::str(note)).collect())));
    if !w.bindings.is_empty() {
        // Open actions on one of several identical objects: memory, carried as the library's serde
        // form (read back by `world_from_value`).
        let json = serde_json::to_value(&w.bindings).unwrap_or_default();
        if let Ok(value) = Value::from_json_untyped(&json) {
            fields.push((n.bindings.clone(), value));
        }
    }
    named(fields)
}

/// A world state from a record value (the fed-back world of the previous cycle).
pub(crate) fn world_from_value(value: &Value) -> Result<WorldState, String> {
    serde_json::from_value(value.to_json()).map_err(|e| format!("the fed-back world state: {e}"))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "tests")]
    use super::*;

    use kpl_aapa::{Aapa, gearbox};

    fn rec(fields: Vec<(&str, Value)>) -> Value {
        record(fields)
    }

    /// Equal JSON, numbers to a relative 1e-12.
    fn close(a: &serde_json::Value, b: &serde_json::Value) -> bool {
        use serde_json::Value as J;
        match (a, b) {
            (J::Number(x), J::Number(y)) => {
                let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
                (x - y).abs() <= 1e-12 * x.abs().max(y.abs()).max(1.0)
            }
            (J::Array(x), J::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(x, y)| close(x, y)),
            (J::Object(x), J::Object(y)) => {
                x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| close(v, w)))
            }
            _ => a == b,
        }
    }

    #[test]
    fn every_world_state_of_the_gearbox_run_round_trips() {
        // Every state the scenario produces (attachments, motion, type votes, camera, notes) comes
        // back unchanged from its KPL value, also through JSON text as a file sink writes it.
        let aapa = Aapa::new(gearbox::params()).unwrap();
        let mut world = WorldState::default();
        let mut attached = 0;
        for cycle in gearbox::scenario() {
            world =
                aapa.step(cycle.time, &cycle.percepts, &cycle.actions, Some(&cycle.camera), &world).unwrap();
            let value = world_to_value(&world);
            assert_eq!(world_from_value(&value).unwrap(), world);
            // Without serde_json's `float_roundtrip` feature, parsing may be off by an ulp, so the
            // text path is compared to 1e-12.
            let text = value.to_json().to_string();
            let reread = Value::from_json_untyped(&serde_json::from_str(&text).unwrap()).unwrap();
            let reread = serde_json::to_value(world_from_value(&reread).unwrap()).unwrap();
            assert!(close(&reread, &serde_json::to_value(&world).unwrap()), "t={}", cycle.time);
            attached += world.anchors.iter().filter(|a| a.attachment.is_some()).count();
        }
        assert!(attached > 0, "the scenario must exercise attachment memory");
    }

    #[test]
    fn anchors_lead_with_the_declared_fields_in_their_kpl_types() {
        let aapa = Aapa::new(gearbox::params()).unwrap();
        let cycle = &gearbox::scenario()[0];
        let world = aapa.step(cycle.time, &cycle.percepts, &[], None, &WorldState::default()).unwrap();
        let value = world_to_value(&world);
        let anchors = value.field("anchors").unwrap();
        let first = list(&anchors, "anchors").unwrap()[0].as_record().unwrap().clone();
        let names: Vec<&str> = first.fields.iter().map(|(n, _)| &**n).take(10).collect();
        assert_eq!(names, ANCHOR_OWN_FIELDS);
        for ((name, ty), (_, value)) in anchor_fields().iter().zip(&first.fields) {
            let ok = matches!(
                (ty, value),
                (ValueType::Str, Value::Str(_))
                    | (ValueType::BBox, Value::BBox(_))
                    | (ValueType::Float, Value::Float(_))
                    | (ValueType::Bool, Value::Bool(_))
                    | (ValueType::Int, Value::Int(_))
                    | (ValueType::Vec2, Value::Vec2(_))
            );
            assert!(ok, "`{name}` is {value:?}, declared {ty}");
        }
        assert_eq!(value.field("time"), Some(Value::Int(0)));
    }

    #[test]
    fn detections_decode_from_typed_and_untyped_values() {
        let typed = Value::List(
            vec![rec(vec![
                ("label", Value::str("gear0")),
                ("type", Value::str("gear")),
                ("box", Value::bbox(BBox::new(1.0, 2.0, 3.0, 4.0))),
                ("colour", Value::str("#ff8000")),
            ])]
            .into(),
        );
        let p = &percepts_from_value(&typed).unwrap()[0];
        assert_eq!((&*p.label, &*p.object_type, p.bbox), ("gear0", "gear", BBox::new(1.0, 2.0, 3.0, 4.0)));
        let [r, g, b] = p.colour.unwrap();
        assert!((r - 1.0).abs() < 1e-12 && (g - 128.0 / 255.0).abs() < 1e-12 && b == 0.0);
        // From a replayed `any` stream the box is a list and the colour [r, g, b].
        let json =
            serde_json::json!([{"label": "a", "type": "t", "box": [0, 0, 5, 5], "colour": [0.1, 0.2, 0.3]}]);
        let p = &percepts_from_value(&Value::from_json_untyped(&json).unwrap()).unwrap()[0];
        assert_eq!((p.bbox, p.colour), (BBox::new(0.0, 0.0, 5.0, 5.0), Some([0.1, 0.2, 0.3])));
        // And back: what the sources emit decodes to the same percept.
        assert_eq!(percepts_from_value(&Value::List(vec![percept_value(p)].into())).unwrap()[0], *p);
    }

    #[test]
    fn malformed_detections_say_what_is_wrong() {
        let cases = [
            (serde_json::json!({"label": "a"}), "the percepts: expected a list, found record"),
            (serde_json::json!([3]), "detection 0: expected a record, found int"),
            (serde_json::json!([{"type": "t", "box": [0, 0, 1, 1]}]), "detection 0 has no field `label`"),
            (serde_json::json!([{"label": "a", "type": "t", "box": [0, 0, 1]}]), "expected a box"),
            (
                serde_json::json!([{"label": "a", "type": 4, "box": [0, 0, 1, 1]}]),
                "`type`: expected a string, found int",
            ),
            (
                serde_json::json!([{"label": "a", "type": "t", "box": [0, 0, 1, 1], "colour": "red"}]),
                "found \"red\"",
            ),
            (
                serde_json::json!([{"label": "a", "type": "t", "box": [0, 0, 1, 1], "colour": [1, 2]}]),
                "found [1,2]",
            ),
        ];
        for (json, expected) in cases {
            let err = percepts_from_value(&Value::from_json_untyped(&json).unwrap()).unwrap_err();
            assert!(err.contains(expected), "{json}: {err}");
        }
    }

    #[test]
    fn actions_decode_with_phase_and_expected_end() {
        let json = serde_json::json!([
            {"name": "pick_up", "args": ["gripper0", "gear0"]},
            {"name": "move", "args": ["human", "case1"], "phase": "started", "expected_end": 2500000},
        ]);
        let actions = actions_from_value(&Value::from_json_untyped(&json).unwrap()).unwrap();
        assert_eq!(actions[0], Action::completed("pick_up", &["gripper0", "gear0"]));
        assert_eq!(actions[1], Action::started("move", &["human", "case1"], Some(2_500_000)));
        let shifted = action_value(&actions[1], 100);
        assert_eq!(
            actions_from_value(&Value::List(vec![shifted].into())).unwrap()[0].expected_end,
            Some(2_500_100)
        );
        let bad = serde_json::json!([{"name": "move", "args": ["a"], "phase": "halfway"}]);
        let err = actions_from_value(&Value::from_json_untyped(&bad).unwrap()).unwrap_err();
        assert!(err.contains("`phase`"), "{err}");
        let bad = serde_json::json!([{"name": "move", "args": [1]}]);
        assert!(
            actions_from_value(&Value::from_json_untyped(&bad).unwrap()).unwrap_err().contains("argument")
        );
    }

    #[test]
    fn poses_decode_and_reject_missing_coordinates() {
        let pose = CameraPose { x: 0.1, y: -0.2, z: 0.3 };
        assert_eq!(pose_from_value(&pose_value(&pose)).unwrap(), pose);
        let json = serde_json::json!({"x": 1, "y": 2});
        assert!(pose_from_value(&Value::from_json_untyped(&json).unwrap()).unwrap_err().contains("`z`"));
    }

    #[test]
    fn a_fed_back_value_that_is_no_world_state_is_an_error() {
        let err = world_from_value(&Value::Int(3)).unwrap_err();
        assert!(err.starts_with("the fed-back world state"), "{err}");
        // A minimal world a user could write by hand is accepted.
        let json = serde_json::json!({"time": 5, "anchors": [{"symbol": "a", "type": "t", "box": [0, 0, 1, 1],
            "confidence": 0.5, "status": "visible", "first_seen": 0, "last_seen": 5, "for_inference": true}],
            "relations": [{"name": "attached", "args": ["a", "b"]}]});
        let w = world_from_value(&Value::from_json_untyped(&json).unwrap()).unwrap();
        assert_eq!(
            (w.time, w.anchors.len(), w.relations[0].clone()),
            (Some(5), 1, Relation::new("attached", "a", "b"))
        );
    }
}
