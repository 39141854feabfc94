//! Qualitative relations between objects on the road network (the DyKnow traffic relations), as
//! functions formulas may call: `behind(a, b)`, `in_front(a, b)`, `beside(a, b)`,
//! `beside_left(a, b)`, `beside_right(a, b)`, `left_of(a, b)`, `same_lane(a, b)`,
//! `same_road(a, b)`, `close(a, b, d)`, `gap(a, b)`, `ahead_of(a, b)`, `approaching(a, b)`, `time_gap(a, b)`,
//! `wrong_way(a)` and `angle_diff(h1, h2)`. A chronicle gives any of them hysteresis with
//! `hysteresis(ENTER, LEAVE)` (docs/situations.md#qualitative-relations).
//!
//! They are pure functions of the attributes the link units computed
//! ([`crate::attributes`]: `road`, `lane`, `lane_pos`, `heading`, `lane_heading`, `speed`) and
//! of `pos`, `vel` and `size`: they need no road network of their own, so a monitor on another
//! host, or one reading a recording, computes them from the objects' records alone. Distances
//! "along the road" compare `lane_pos` of objects on the same road (the lanes of one road have
//! one length, as SUMO's lanes of one edge do); objects on different roads are never behind,
//! beside or close to each other. An object's length is its `size` attribute, or
//! [`DEFAULT_LENGTH_M`] without one.

use std::f64::consts::PI;

use kpl_core::{FieldHint, Record, Value, ValueType};
use kpl_mtl::Function;
use kpl_roads::geom;
use kpl_semantic::registry;

/// What `gap` gives for two objects not on the same road: no room at all, so `gap(a, b) > x` is
/// false for any sensible `x` (formulas refuse non-finite numbers).
pub const NO_GAP_M: f64 = -1e9;
/// The length of an object without a `size` attribute (a car), in metres.
pub const DEFAULT_LENGTH_M: f64 = 4.5;
/// The speed below which an object's direction of travel is not known (m/s): such an object is
/// never driving the wrong way.
pub const WRONG_WAY_MIN_SPEED_MPS: f64 = 2.0;
/// What `time_gap` gives when there is no gap to speak of (the objects are not one behind the
/// other on a road, or the follower stands still): a time no situation waits for (s).
pub const NO_TIME_GAP_S: f64 = 1e9;

/// What the relations read of one object.
#[derive(Debug, Clone, Copy)]
struct OnRoad<'a> {
    record: &'a Record,
    road: i64,
    lane_pos: f64,
    heading: Option<f64>,
    length: f64,
}

fn object<'a>(value: &'a Value, func: &str) -> Result<&'a Record, String> {
    match value {
        Value::Record(r) => Ok(r),
        other => Err(format!("{func} needs objects, found {}", other.kind())),
    }
}

/// A hint of its own for the call site (`Record::get_hinted`): the relations read the same few
/// attributes of every pair of objects, most of one type.
macro_rules! hint {
    () => {{
        static HINT: FieldHint = FieldHint::new();
        &HINT
    }};
}

fn float(record: &Record, name: &str, hint: &FieldHint, func: &str) -> Result<f64, String> {
    record
        .get_hinted(name, hint)
        .and_then(Value::as_f64)
        .ok_or_else(|| format!("{func} needs the attribute `{name}` (a number) of {}", who(record)))
}

fn who(record: &Record) -> String {
    record.id.as_deref().map_or_else(|| "an object".to_string(), |id| format!("`{id}`"))
}

fn on_road<'a>(value: &'a Value, func: &str) -> Result<OnRoad<'a>, String> {
    let record = object(value, func)?;
    let road = match record.get_hinted("road", hint!()) {
        Some(Value::Int(road)) => *road,
        _ => return Err(format!("{func} needs the attribute `road` (an int) of {}", who(record))),
    };
    Ok(OnRoad {
        record,
        road,
        lane_pos: float(record, "lane_pos", hint!(), func)?,
        heading: record.get_hinted("heading", hint!()).and_then(Value::as_f64),
        length: record
            .get_hinted("size", hint!())
            .and_then(Value::as_f64)
            .filter(|s| *s > 0.0)
            .unwrap_or(DEFAULT_LENGTH_M),
    })
}

/// The smallest angle between two headings, in [0, π].
pub fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(2.0 * PI);
    if d > PI { 2.0 * PI - d } else { d }
}

/// Both on one road (not in a junction) and going one way.
fn same_road(a: &OnRoad<'_>, b: &OnRoad<'_>) -> bool {
    a.road >= 0
        && a.road == b.road
        && match (a.heading, b.heading) {
            (Some(ha), Some(hb)) => angle_between(ha, hb) < PI / 2.0,
            _ => true,
        }
}

/// How far `b`'s centre is ahead of `a`'s along the road (negative: behind).
fn ahead(a: &OnRoad<'_>, b: &OnRoad<'_>) -> f64 {
    b.lane_pos - a.lane_pos
}

/// Half the summed lengths: closer than this along the road, the two overlap side by side.
fn overlap(a: &OnRoad<'_>, b: &OnRoad<'_>) -> f64 {
    (a.length + b.length) / 2.0
}

fn same_lane(a: &Record, b: &Record) -> bool {
    match (a.get_hinted("lane", hint!()), b.get_hinted("lane", hint!())) {
        (Some(Value::Str(x)), Some(Value::Str(y))) => !x.is_empty() && x == y,
        (Some(Value::Int(x)), Some(Value::Int(y))) => *x >= 0 && x == y,
        _ => false,
    }
}

fn behind(a: &OnRoad<'_>, b: &OnRoad<'_>) -> bool {
    same_road(a, b) && ahead(a, b) > overlap(a, b)
}

fn beside(a: &OnRoad<'_>, b: &OnRoad<'_>) -> bool {
    same_road(a, b) && !same_lane(a.record, b.record) && ahead(a, b).abs() <= overlap(a, b)
}

/// Whether `a` is to the left of `b`, looking in `b`'s direction of travel.
/// Whether `a`'s centre is left of `b`'s, looking in `b`'s heading (`a` on a road or not).
fn left_of(a: &Record, b: &OnRoad<'_>, func: &str) -> Result<bool, String> {
    let pa = point(a, func)?;
    let pb = point(b.record, func)?;
    let heading =
        b.heading.ok_or_else(|| format!("{func} needs the attribute `heading` of {}", who(b.record)))?;
    Ok(geom::cross(geom::unit(heading), geom::sub(pa, pb)) > 0.0)
}

fn point(record: &Record, func: &str) -> Result<[f64; 2], String> {
    record
        .get_hinted("pos", hint!())
        .and_then(Value::as_vec2)
        .ok_or_else(|| format!("{func} needs the `pos` (vec2) of {}", who(record)))
}

fn vel(record: &Record, func: &str) -> Result<[f64; 2], String> {
    record
        .get_hinted("vel", hint!())
        .and_then(Value::as_vec2)
        .ok_or_else(|| format!("{func} needs the `vel` (vec2) of {}", who(record)))
}

type Pair = fn(&OnRoad<'_>, &OnRoad<'_>, &str) -> Result<bool, String>;

fn pair(name: &'static str, relation: Pair) -> Function {
    Function::borrowing(name, (2, Some(2)), move |args| {
        let a = on_road(args[0], name)?;
        let b = on_road(args[1], name)?;
        relation(&a, &b, name).map(Value::Bool)
    })
}

/// What `close(a, b, d)` adds to `d` for a gate in the plane: `close` measures along the road,
/// between the centres of lanes that may lie side by side.
pub const CLOSE_LATERAL_MARGIN_M: f64 = 15.0;

/// The implementations, for monitors and link conditions.
pub fn functions() -> Vec<Function> {
    vec![
        pair("same_road", |a, b, _| Ok(same_road(a, b))),
        Function::borrowing("same_lane", (2, Some(2)), |args| {
            Ok(Value::Bool(same_lane(object(args[0], "same_lane")?, object(args[1], "same_lane")?)))
        }),
        pair("behind", |a, b, _| Ok(behind(a, b))),
        pair("in_front", |a, b, _| Ok(behind(b, a))),
        pair("beside", |a, b, _| Ok(beside(a, b))),
        pair("beside_left", |a, b, f| Ok(beside(a, b) && left_of(a.record, b, f)?)),
        Function::borrowing("left_of", (2, Some(2)), |args| {
            let a = object(args[0], "left_of")?;
            let b = on_road(args[1], "left_of")?;
            left_of(a, &b, "left_of").map(Value::Bool)
        }),
        Function::borrowing("gap", (2, Some(2)), |args| {
            let a = on_road(args[0], "gap")?;
            let b = on_road(args[1], "gap")?;
            if !same_road(&a, &b) {
                return Ok(Value::Float(NO_GAP_M));
            }
            Ok(Value::Float(ahead(&a, &b) - overlap(&a, &b)))
        }),
        pair("beside_right", |a, b, f| Ok(beside(a, b) && !left_of(a.record, b, f)?)),
        Function::borrowing("close", (3, Some(3)), |args| {
            let a = on_road(args[0], "close")?;
            let b = on_road(args[1], "close")?;
            let d = args[2]
                .as_f64()
                .ok_or_else(|| format!("close needs a distance, found {}", args[2].kind()))?;
            Ok(Value::Bool(same_road(&a, &b) && ahead(&a, &b).abs() <= d))
        })
        // Measured along the road, between lane centres that may lie side by side: in the plane
        // the two are within `d` plus this much (the gate of a pair monitor, `kpl_mtl::gate`).
        .within(CLOSE_LATERAL_MARGIN_M),
        Function::borrowing("ahead_of", (2, Some(2)), |args| {
            let a = object(args[0], "ahead_of")?;
            let b = object(args[1], "ahead_of")?;
            let heading = float(a, "heading", hint!(), "ahead_of")?;
            let towards = geom::sub(point(b, "ahead_of")?, point(a, "ahead_of")?);
            Ok(Value::Float(geom::dot(geom::unit(heading), towards)))
        }),
        Function::borrowing("approaching", (2, Some(2)), |args| {
            let a = object(args[0], "approaching")?;
            let b = object(args[1], "approaching")?;
            let towards = geom::sub(point(b, "approaching")?, point(a, "approaching")?);
            let closing = geom::sub(vel(a, "approaching")?, vel(b, "approaching")?);
            Ok(Value::Bool(geom::dot(towards, closing) > 0.0))
        }),
        Function::borrowing("time_gap", (2, Some(2)), |args| {
            let a = on_road(args[0], "time_gap")?;
            let b = on_road(args[1], "time_gap")?;
            let speed = float(a.record, "speed", hint!(), "time_gap")?;
            let gap = ahead(&a, &b) - overlap(&a, &b);
            if !behind(&a, &b) || speed < 0.1 {
                return Ok(Value::Float(NO_TIME_GAP_S));
            }
            Ok(Value::Float(gap / speed))
        }),
        Function::new("wrong_way", (1, Some(1)), |args| {
            let a = object(&args[0], "wrong_way")?;
            let speed = float(a, "speed", hint!(), "wrong_way")?;
            let heading = float(a, "heading", hint!(), "wrong_way")?;
            let lane = float(a, "lane_heading", hint!(), "wrong_way")?;
            Ok(Value::Bool(speed >= WRONG_WAY_MIN_SPEED_MPS && angle_between(heading, lane) > PI / 2.0))
        }),
        Function::new("angle_diff", (2, Some(2)), |args| {
            let number =
                |v: &Value| v.as_f64().ok_or_else(|| format!("angle_diff needs numbers, found {}", v.kind()));
            Ok(Value::Float(angle_between(number(&args[0])?, number(&args[1])?)))
        }),
    ]
}

/// The signatures, for checking (`kpl list` shows them).
pub fn signatures() -> Vec<registry::Function> {
    use ValueType::{Any, Bool, Float};
    let f = |name: &str, params: Vec<ValueType>, returns: ValueType, summary: &str| {
        registry::Function::new(name, params, returns, summary)
    };
    vec![
        f("same_road", vec![Any, Any], Bool, "both objects on one road (not in a junction), going one way"),
        f("same_lane", vec![Any, Any], Bool, "both objects on one lane"),
        f(
            "behind",
            vec![Any, Any],
            Bool,
            "a behind b on the same road: b's centre more than half their summed lengths ahead along the road",
        ),
        f("in_front", vec![Any, Any], Bool, "a in front of b on the same road (behind(b, a))"),
        f("beside", vec![Any, Any], Bool, "a beside b: same road, another lane, overlapping along the road"),
        f("beside_left", vec![Any, Any], Bool, "a beside b, on b's left"),
        f("left_of", vec![Any, Any], Bool, "a's centre left of b's, looking in b's heading (any road)"),
        f(
            "gap",
            vec![Any, Any],
            Float,
            "metres from a's front to b's back along the road (positive: a behind b with room; -1e9: not on the same road)",
        ),
        f("beside_right", vec![Any, Any], Bool, "a beside b, on b's right"),
        f("close", vec![Any, Any, Float], Bool, "same road and within d metres along it"),
        f(
            "ahead_of",
            vec![Any, Any],
            Float,
            "metres b's centre lies ahead of a's along a's heading, in the plane (any road, in a junction too; negative: behind)",
        ),
        f("approaching", vec![Any, Any], Bool, "the distance between a and b shrinks (from `pos` and `vel`)"),
        f(
            "time_gap",
            vec![Any, Any],
            Float,
            "seconds until a reaches where b's back is now (a behind b on the same road), else 1e9",
        ),
        f(
            "wrong_way",
            vec![Any],
            Bool,
            "moving (speed >= 2 m/s) against the direction of the lane it is on (`heading` vs `lane_heading`)",
        ),
        f(
            "angle_diff",
            vec![Float, Float],
            Float,
            "the smallest angle between two headings (radians, 0 to pi)",
        ),
    ]
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use std::sync::Arc;

    fn car(id: &str, lane: &str, lane_pos: f64, x: f64, y: f64, speed: f64) -> Value {
        let fields = vec![
            (Arc::from("pos"), Value::vec2(x, y)),
            (Arc::from("vel"), Value::vec2(speed, 0.0)),
            (Arc::from("size"), Value::Float(4.0)),
            (Arc::from("road"), Value::Int(0)),
            (Arc::from("lane"), Value::str(lane)),
            (Arc::from("lane_pos"), Value::Float(lane_pos)),
            (Arc::from("speed"), Value::Float(speed)),
            (Arc::from("heading"), Value::Float(0.0)),
            (Arc::from("lane_heading"), Value::Float(0.0)),
        ];
        Value::Record(Arc::new(Record { id: Some(id.into()), fields }))
    }

    fn call(name: &str, args: &[Value]) -> Value {
        let functions = functions();
        let f = functions.iter().find(|f| &*f.name == name).unwrap();
        (f.body)(args).unwrap()
    }

    #[test]
    fn relations_of_two_cars_on_an_eastbound_road() {
        // Lane 0 at y = -4.8 (right), lane 1 at y = -1.6 (left), both eastbound.
        let a = car("co1", "e_0", 100.0, 100.0, -4.8, 30.0);
        let b = car("co2", "e_0", 120.0, 120.0, -4.8, 20.0);
        let c = car("co3", "e_1", 102.0, 102.0, -1.6, 25.0);
        assert_eq!(call("behind", &[a.clone(), b.clone()]), Value::Bool(true));
        assert_eq!(call("in_front", &[b.clone(), a.clone()]), Value::Bool(true));
        assert_eq!(call("behind", &[b.clone(), a.clone()]), Value::Bool(false));
        assert_eq!(call("same_lane", &[a.clone(), b.clone()]), Value::Bool(true));
        assert_eq!(call("same_lane", &[a.clone(), c.clone()]), Value::Bool(false));
        assert_eq!(call("beside", &[a.clone(), c.clone()]), Value::Bool(true));
        assert_eq!(call("beside_left", &[c.clone(), a.clone()]), Value::Bool(true));
        assert_eq!(call("beside_right", &[a.clone(), c.clone()]), Value::Bool(true));
        assert_eq!(call("beside_left", &[a.clone(), c.clone()]), Value::Bool(false));
        assert_eq!(call("behind", &[a.clone(), c.clone()]), Value::Bool(false), "side by side is not behind");
        assert_eq!(call("close", &[a.clone(), b.clone(), Value::Float(25.0)]), Value::Bool(true));
        assert_eq!(call("close", &[a.clone(), b.clone(), Value::Float(15.0)]), Value::Bool(false));
        assert_eq!(call("approaching", &[a.clone(), b.clone()]), Value::Bool(true));
        assert_eq!(call("approaching", &[b.clone(), a.clone()]), Value::Bool(true), "symmetric");
        // left_of looks along b's heading (east): lane 1 (y = -1.6) is left of lane 0 (y = -4.8).
        assert_eq!(call("left_of", &[c.clone(), a.clone()]), Value::Bool(true));
        assert_eq!(call("left_of", &[a.clone(), c.clone()]), Value::Bool(false));
        // gap: 20 m between centres less half of 4 m + 4 m; negative the other way round.
        assert_eq!(call("gap", &[a.clone(), b.clone()]).as_f64(), Some(16.0));
        assert_eq!(call("gap", &[b.clone(), a.clone()]).as_f64(), Some(-24.0));
        assert_eq!(call("gap", &[a.clone(), c.clone()]).as_f64(), Some(-2.0), "side by side: overlapping");
        let mut other_road = b.clone();
        if let Value::Record(r) = &mut other_road {
            let r = Arc::make_mut(r);
            r.fields.iter_mut().filter(|(n, _)| &**n == "road").for_each(|(_, v)| *v = Value::Int(7));
        }
        assert_eq!(call("gap", &[a.clone(), other_road.clone()]).as_f64(), Some(NO_GAP_M));
        // ahead_of: in the plane, along a's heading, whatever the roads (a junction: road -1).
        assert_eq!(call("ahead_of", &[a.clone(), b.clone()]).as_f64(), Some(20.0));
        assert_eq!(call("ahead_of", &[a.clone(), other_road]).as_f64(), Some(20.0), "another road");
        assert_eq!(call("ahead_of", &[b.clone(), c.clone()]).as_f64(), Some(-18.0));
        let mut north = c.clone();
        if let Value::Record(r) = &mut north {
            let r = Arc::make_mut(r);
            r.fields
                .iter_mut()
                .filter(|(n, _)| &**n == "heading")
                .for_each(|(_, v)| *v = Value::Float(PI / 2.0));
        }
        let along = call("ahead_of", &[north, a.clone()]).as_f64().unwrap();
        assert!((along + 3.2).abs() < 1e-9, "looking north from y = -1.6, y = -4.8 is 3.2 m behind: {along}");
        // Gap 16 m (20 m between centres, 4 m of lengths) at 30 m/s.
        let gap = call("time_gap", &[a.clone(), b.clone()]).as_f64().unwrap();
        assert!((gap - 16.0 / 30.0).abs() < 1e-9, "{gap}");
        assert_eq!(call("time_gap", &[b.clone(), a.clone()]), Value::Float(NO_TIME_GAP_S));
        assert_eq!(call("wrong_way", &[a]), Value::Bool(false));
    }

    #[test]
    fn other_roads_and_directions_are_never_related() {
        let a = car("co1", "e_0", 100.0, 100.0, -4.8, 30.0);
        let Value::Record(r) = car("co2", "w_0", 110.0, 110.0, 4.8, 30.0) else { unreachable!() };
        let mut other = (*r).clone();
        for (name, value) in &mut other.fields {
            match &**name {
                "road" => *value = Value::Int(1),
                "heading" => *value = Value::Float(PI),
                _ => {}
            }
        }
        let b = Value::Record(Arc::new(other.clone()));
        for relation in ["behind", "in_front", "beside", "same_road"] {
            assert_eq!(call(relation, &[a.clone(), b.clone()]), Value::Bool(false), "{relation}");
        }
        assert_eq!(call("close", &[a.clone(), b.clone(), Value::Float(100.0)]), Value::Bool(false));
        // Inside a junction (road -1) nothing is on the same road.
        let mut junction = other;
        for (name, value) in &mut junction.fields {
            if &**name == "road" {
                *value = Value::Int(-1);
            }
        }
        let j = Value::Record(Arc::new(junction));
        assert_eq!(call("same_road", &[j.clone(), j]), Value::Bool(false));
    }

    #[test]
    fn wrong_way_compares_travel_with_the_lane() {
        let Value::Record(r) = car("co1", "e_0", 100.0, 100.0, -4.8, 30.0) else { unreachable!() };
        let mut record = (*r).clone();
        for (name, value) in &mut record.fields {
            if &**name == "heading" {
                *value = Value::Float(PI - 0.1);
            }
        }
        assert_eq!(call("wrong_way", &[Value::Record(Arc::new(record.clone()))]), Value::Bool(true));
        for (name, value) in &mut record.fields {
            if &**name == "speed" {
                *value = Value::Float(0.5);
            }
        }
        assert_eq!(call("wrong_way", &[Value::Record(Arc::new(record))]), Value::Bool(false), "standing");
        assert!(
            (call("angle_diff", &[Value::Float(3.0), Value::Float(-3.0)]).as_f64().unwrap()
                - (2.0 * PI - 6.0))
                .abs()
                < 1e-12
        );
    }

    #[test]
    fn missing_attributes_are_named() {
        let bare = Value::Record(Arc::new(Record { id: Some("wo1".into()), fields: vec![] }));
        let functions = functions();
        let behind = functions.iter().find(|f| &*f.name == "behind").unwrap();
        let err = (behind.body)(&[bare.clone(), bare]).unwrap_err();
        assert!(err.contains("`road`") && err.contains("`wo1`"), "{err}");
    }

    #[test]
    fn every_function_has_a_signature() {
        let mut a: Vec<String> = functions().iter().map(|f| f.name.to_string()).collect();
        let mut b: Vec<String> = signatures().iter().map(|f| f.name.clone()).collect();
        a.sort();
        b.sort();
        assert_eq!(a, b);
        for f in functions() {
            let s = signatures().into_iter().find(|s| *s.name == *f.name).unwrap();
            assert!(f.accepts(s.params.len()), "{}", f.name);
        }
    }
}
