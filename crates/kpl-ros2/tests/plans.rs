//! The compiled plans against the tree path they replace (crates/kpl-ros2/src/plan.rs):
//!
//! - encoding: `OutMap::encode_into` (the encode plan) gives the bytes of
//!   `cdr::encode(OutMap::apply(..))` (`OutMap::encode_tree`), and the plan alone refuses exactly
//!   the samples the tree path refuses;
//! - decoding: `InMap::decode` (the decode plan) gives the valid time and KPL value of
//!   `InMap::apply(cdr::decode(..))` (`InMap::decode_tree`), and the plan alone refuses exactly
//!   the messages the tree path refuses, on valid messages and on mutated and truncated ones.
//!
//! On the shipped mappings (specs/ros2/markers.kpl, the `kpl bench ros2` messages), and on random
//! mappings of every shipped message type with random values and messages.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

use std::sync::Arc;

use kpl_core::{FieldType, Record, RecordType, Time, Value, ValueType};
use kpl_ros2::cdr::{self, MsgValue};
use kpl_ros2::definitions::{SchemaBase, SchemaField};
use kpl_ros2::mapping::{InMap, InSpec, OutMap, OutSpec, workloads};
use kpl_ros2::msg::{ArrayKind, Primitive};
use kpl_ros2::{Definitions, Schema};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn record_type(name: &str, symbol: &str, fields: &[(&str, ValueType)]) -> Arc<RecordType> {
    let fields = fields.iter().map(|(n, ty)| FieldType { name: (*n).into(), ty: ty.clone() }).collect();
    Arc::new(RecordType { name: name.into(), parent: None, symbol: symbol.into(), fields })
}

fn record(id: Option<&str>, fields: Vec<(&str, Value)>) -> Value {
    Value::Record(Arc::new(Record {
        id: id.map(Arc::from),
        fields: fields.into_iter().map(|(n, v)| (Arc::from(n), v)).collect(),
    }))
}

fn strings(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

/// Encodes `value` both ways (two maps compiled alike, so that `number` counts alike) and checks
/// they agree; returns whether the plan was used (the mapping has one and the sample encodes).
fn same_encoding(a: &mut OutMap, b: &mut OutMap, c: &mut OutMap, valid: Time, value: &Value) -> bool {
    let mut tree = Vec::new();
    let mut plan = Vec::new();
    let mut public = Vec::new();
    let by_tree = a.encode_tree(valid, value, &mut tree);
    let by_plan = b.encode_plan_only(valid, value, &mut plan);
    let by_public = c.encode_into(valid, value, &mut public);
    assert_eq!(by_public, by_tree.clone().map(|_| ()), "{value:?}");
    if by_tree.is_ok() {
        assert_eq!(public, tree);
    }
    match by_plan {
        None => false,
        Some(true) => {
            assert!(by_tree.is_ok(), "the plan encodes what the tree path refuses: {by_tree:?} {value:?}");
            assert_eq!(plan, tree, "{value:?}");
            true
        }
        Some(false) => {
            assert!(by_tree.is_err(), "the plan refuses what the tree path encodes: {value:?}");
            // As `encode_into` does: the tree path gives the error, and numbers the symbols the
            // tree path numbers before its error.
            assert!(b.encode_tree(valid, value, &mut plan).is_err());
            false
        }
    }
}

/// Decodes `bytes` both ways and checks they agree; returns whether the plan decoded it.
fn same_decoding(map: &InMap, bytes: &[u8]) -> bool {
    let tree = map.decode_tree(bytes);
    assert_eq!(map.decode(bytes), tree);
    match map.decode_plan_only(bytes) {
        None => false,
        Some(Ok(decoded)) => {
            assert_eq!(Ok(decoded), tree, "the plan decodes differently from the tree path");
            true
        }
        Some(Err(())) => {
            assert!(tree.is_err(), "the plan refuses what the tree path decodes: {tree:?}");
            false
        }
    }
}

#[test]
fn shipped_mappings_encode_and_decode_alike() {
    let defs = Definitions::builtin();
    let spec = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../specs/ros2/markers.kpl"))
        .unwrap();
    let cars_map = workloads::MARKERS_OF_CARS;
    let detections_map = [
        "header.frame_id = 'map'",
        "id = symbol",
        "bbox.center.position = pos",
        "bbox.center.orientation.w = 1.0",
        "bbox.size.x = size",
        "bbox.size.y = 1.8",
        "bbox.size.z = 1.5",
    ];
    // The mappings are the spec's, as written there.
    let percepts_map = workloads::PERCEPTS_OF_MARKERS;
    for map in [cars_map, &detections_map[..], percepts_map] {
        let quoted: Vec<String> = map.iter().map(|e| format!("\"{e}\"")).collect();
        assert!(spec.contains(&format!("map: [{}]", quoted.join(", "))), "{map:?} is not markers.kpl's");
    }
    let car = record_type("Car", "co", &[("pos", ValueType::Vec2), ("size", ValueType::Float)]);
    let cars_ty = ValueType::List(Box::new(ValueType::Record(car)));
    let mut rng = ChaCha8Rng::seed_from_u64(26);
    for (type_name, each, entries) in [
        ("visualization_msgs/msg/MarkerArray", "markers", cars_map),
        ("vision_msgs/msg/Detection3DArray", "detections", &detections_map[..]),
    ] {
        let schema = defs.schema_of(type_name).unwrap();
        let out = OutSpec { each: Some(each.into()), entries: strings(entries) };
        let compile = || OutMap::compile(schema.clone(), &out, &cars_ty).unwrap();
        let (mut a, mut b, mut c) = (compile(), compile(), compile());
        for n in [0usize, 1, 2, 7, 100] {
            let cars: Vec<Value> = (0..n)
                .map(|i| {
                    let id = format!("co{}", rng.random_range(0..1000));
                    let pos = Value::Vec2([rng.random_range(-1e3..1e3), rng.random_range(-1e3..1e3)]);
                    record(Some(&id), vec![("pos", pos), ("size", Value::Float(4.5 + i as f64 / 7.0))])
                })
                .collect();
            let valid = rng.random_range(0..2_000_000_000_000_000);
            assert!(same_encoding(&mut a, &mut b, &mut c, valid, &Value::List(cars.into())), "{type_name}");
        }
    }
    // markers.kpl's subscription, on what its publication writes.
    let schema = defs.schema_of("visualization_msgs/msg/MarkerArray").unwrap();
    let percept = record_type("VisionPercept", "vp", &[("pos", ValueType::Vec2), ("size", ValueType::Float)]);
    let into = InSpec {
        each: Some("markers".into()),
        identity: Some("id".into()),
        stamp: None,
        entries: strings(percepts_map),
    };
    let map = InMap::compile(&schema, &into, &ValueType::List(Box::new(ValueType::Record(percept)))).unwrap();
    let mut out = OutMap::compile(
        schema.clone(),
        &OutSpec { each: Some("markers".into()), entries: strings(cars_map) },
        &cars_ty,
    )
    .unwrap();
    let cars: Vec<Value> = (0..100)
        .map(|i| {
            record(
                Some(&format!("co{i}")),
                vec![("pos", Value::vec2(i as f64, -1.5)), ("size", Value::Float(4.5))],
            )
        })
        .collect();
    let mut bytes = Vec::new();
    out.encode_into(1_700_000_000_000_000, &Value::List(cars.into()), &mut bytes).unwrap();
    assert!(same_decoding(&map, &bytes));
    let (valid, Value::List(percepts)) = map.decode(&bytes).unwrap() else { panic!() };
    assert_eq!(valid, Some(1_700_000_000_000_000));
    assert_eq!(percepts.len(), 100);
    assert_eq!(percepts[12].as_record().unwrap().id.as_deref(), Some("vp12"));
    assert_eq!(percepts[12].as_record().unwrap().get("pos"), Some(&Value::vec2(12.0, -1.5)));
}

/// `kpl bench ros2`'s PoseStamped (crates/kpl-zenoh/src/bench/ros2.rs): `pose.position.z` is set
/// after `pose.position`, which sets x and y.
#[test]
fn the_bench_pose_encodes_and_decodes_alike() {
    let defs = Definitions::builtin();
    let schema = defs.schema_of("geometry_msgs/msg/PoseStamped").unwrap();
    let ty = record_type(
        "Pose",
        "po",
        &[
            ("pos", ValueType::Vec2),
            ("z", ValueType::Float),
            ("yaw_z", ValueType::Float),
            ("yaw_w", ValueType::Float),
        ],
    );
    let out = OutSpec { each: None, entries: strings(workloads::POSE_STAMPED) };
    let into =
        InSpec { each: None, identity: None, stamp: None, entries: strings(workloads::POSE_OF_POSE_STAMPED) };
    let compile = || OutMap::compile(schema.clone(), &out, &ValueType::Record(ty.clone())).unwrap();
    let (mut a, mut b, mut c) = (compile(), compile(), compile());
    let map = InMap::compile(&schema, &into, &ValueType::Record(ty.clone())).unwrap();
    let value = record(
        None,
        vec![
            ("pos", Value::vec2(12.5, -3.25)),
            ("z", Value::Float(1.25)),
            ("yaw_z", Value::Float(0.3826834)),
            ("yaw_w", Value::Float(0.9238795)),
        ],
    );
    for valid in [0, 1, -1, 1_700_000_000_123_456, i64::MAX / 2, i64::MIN / 2] {
        assert!(same_encoding(&mut a, &mut b, &mut c, valid, &value));
        let mut bytes = Vec::new();
        c.encode_into(valid, &value, &mut bytes).unwrap();
        assert_eq!(bytes.len(), 76);
        assert!(same_decoding(&map, &bytes));
    }
}

// ---------------------------------------------------------------------------------------------
// Random mappings.

/// What a path of a message ends on, for choosing a source or an attribute type.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Float,
    Signed,
    Unsigned,
    Bool,
    Str,
    Xy,
    Time,
    Duration,
}

/// Every path from struct `index` through nested messages (not arrays) that a mapping can name,
/// with what it ends on; and the arrays of messages (for `each`).
fn paths(
    schema: &Schema,
    index: usize,
    prefix: &str,
    out: &mut Vec<(String, Kind)>,
    arrays: &mut Vec<String>,
) {
    for field in &schema.get(index).fields {
        let path =
            if prefix.is_empty() { field.name.to_string() } else { format!("{prefix}.{}", field.name) };
        match (field.array, field.base) {
            (ArrayKind::Single, SchemaBase::Primitive(p)) => {
                use Primitive::*;
                let kind = match p {
                    Float32 | Float64 => Kind::Float,
                    Int8 | Int16 | Int32 | Int64 => Kind::Signed,
                    Byte | Char | UInt8 | UInt16 | UInt32 | UInt64 => Kind::Unsigned,
                    Bool => Kind::Bool,
                    String(_) => Kind::Str,
                    WString(_) => continue,
                };
                out.push((path, kind));
            }
            (ArrayKind::Single, SchemaBase::Struct(s)) => {
                let def = schema.get(s);
                match &*def.def.name.to_string() {
                    "builtin_interfaces/msg/Time" => out.push((path.clone(), Kind::Time)),
                    "builtin_interfaces/msg/Duration" => out.push((path.clone(), Kind::Duration)),
                    _ => {
                        let numeric = |n: &str| {
                            def.fields.iter().any(|f| {
                                &*f.name == n
                                    && f.array == ArrayKind::Single
                                    && matches!(f.base, SchemaBase::Primitive(p) if p.size().is_some() && p != Primitive::Bool)
                            })
                        };
                        if numeric("x") && numeric("y") {
                            out.push((path.clone(), Kind::Xy));
                        }
                    }
                }
                paths(schema, s, &path, out, arrays);
            }
            (_, SchemaBase::Struct(_)) => arrays.push(path),
            _ => {}
        }
    }
}

fn attribute_type(kind: Kind) -> ValueType {
    match kind {
        Kind::Float => ValueType::Float,
        Kind::Signed | Kind::Unsigned | Kind::Time => ValueType::Int,
        Kind::Bool => ValueType::Bool,
        Kind::Str => ValueType::Str,
        Kind::Xy => ValueType::Vec2,
        Kind::Duration => ValueType::Duration,
    }
}

/// A random value of an attribute: mostly in range, sometimes not (negative for an unsigned
/// field, a NUL in a string, beyond 32 bits).
fn attribute_value(rng: &mut ChaCha8Rng, ty: &ValueType) -> Value {
    match ty {
        ValueType::Float => Value::Float(rng.random_range(-1e6..1e6)),
        ValueType::Int => Value::Int(match rng.random_range(0..10) {
            0 => -rng.random_range(1..1000),
            1 => rng.random::<i64>(),
            2 => rng.random_range(0..1i64 << 40),
            _ => rng.random_range(0..128),
        }),
        ValueType::Bool => Value::Bool(rng.random()),
        ValueType::Str => Value::str(match rng.random_range(0..12) {
            0 => "nul\0inside",
            1 => "",
            2 => "漢字 🙂",
            _ => "map",
        }),
        ValueType::Vec2 => Value::Vec2([rng.random_range(-1e4..1e4), rng.random_range(-1e4..1e4)]),
        ValueType::Duration => Value::Duration(rng.random_range(-1_000_000_000..1_000_000_000)),
        _ => Value::Int(0),
    }
}

/// A random source for a path of `kind`; `Some(type)` when it is an attribute.
fn random_source(rng: &mut ChaCha8Rng, kind: Kind, attribute: &str) -> (String, Option<ValueType>) {
    let attribute_source = (attribute.to_string(), Some(attribute_type(kind)));
    match (kind, rng.random_range(0..4)) {
        (Kind::Float, 0) => ("2.5".into(), None),
        (Kind::Float, 1) => ("3".into(), None),
        (Kind::Float | Kind::Signed | Kind::Unsigned, 2) => ("number".into(), None),
        (Kind::Signed, 0) => ("-7".into(), None),
        (Kind::Unsigned, 0) => ("200".into(), None),
        (Kind::Unsigned | Kind::Signed, 1) => ("70000".into(), None),
        (Kind::Str, 0 | 1) => ("symbol".into(), None),
        (Kind::Str, 2) => ("'frame'".into(), None),
        (Kind::Bool, 0) => ("true".into(), None),
        _ => attribute_source,
    }
}

fn random_id(rng: &mut ChaCha8Rng) -> Option<String> {
    match rng.random_range(0..6) {
        0 => None,
        1 => Some("x".into()),
        2 => Some(format!("co{}", rng.random::<u32>())),
        _ => Some(format!("co{}", rng.random_range(0..50))),
    }
}

/// Random mappings out of KPL for every shipped type, random samples: the plan encodes alike.
#[test]
fn random_out_mappings_encode_alike() {
    let defs = Definitions::builtin();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut names: Vec<String> = defs.names().map(|n| n.to_string()).collect();
    names.sort();
    let (mut planned, mut samples) = (0, 0);
    for name in &names {
        let schema = defs.schema_of(name).unwrap();
        let (mut root_paths, mut arrays) = (Vec::new(), Vec::new());
        paths(&schema, schema.root_index(), "", &mut root_paths, &mut arrays);
        for _ in 0..12 {
            let each = (!arrays.is_empty() && rng.random_bool(0.5))
                .then(|| arrays[rng.random_range(0..arrays.len())].clone());
            let element_paths = match &each {
                None => root_paths.clone(),
                Some(array) => {
                    let element = element_struct(&schema, array);
                    let mut p = Vec::new();
                    paths(&schema, element, "", &mut p, &mut Vec::new());
                    p
                }
            };
            if element_paths.is_empty() {
                continue;
            }
            let mut entries = Vec::new();
            let mut fields = Vec::new();
            for k in 0..rng.random_range(1..7) {
                let (path, kind) = element_paths[rng.random_range(0..element_paths.len())].clone();
                let (source, ty) = random_source(&mut rng, kind, &format!("a{k}"));
                if let Some(ty) = ty {
                    fields.push((format!("a{k}"), ty));
                }
                entries.push(format!("{path} = {source}"));
            }
            let field_refs: Vec<(&str, ValueType)> =
                fields.iter().map(|(n, t)| (n.as_str(), t.clone())).collect();
            let ty = record_type("Thing", "th", &field_refs);
            let input = match &each {
                Some(_) => ValueType::List(Box::new(ValueType::Record(ty.clone()))),
                None => ValueType::Record(ty.clone()),
            };
            let out = OutSpec { each: each.clone(), entries };
            let Ok(mut a) = OutMap::compile(schema.clone(), &out, &input) else { continue };
            let mut b = OutMap::compile(schema.clone(), &out, &input).unwrap();
            let mut c = OutMap::compile(schema.clone(), &out, &input).unwrap();
            for _ in 0..6 {
                let make = |rng: &mut ChaCha8Rng| {
                    let values: Vec<(&str, Value)> =
                        fields.iter().map(|(n, t)| (n.as_str(), attribute_value(rng, t))).collect();
                    record(random_id(rng).as_deref(), values)
                };
                let value = match &each {
                    Some(_) => Value::List(
                        (0..rng.random_range(0..5)).map(|_| make(&mut rng)).collect::<Vec<_>>().into(),
                    ),
                    None => make(&mut rng),
                };
                let valid = rng.random_range(-1_000_000_000_000_000..4_000_000_000_000_000);
                samples += 1;
                planned += usize::from(same_encoding(&mut a, &mut b, &mut c, valid, &value));
            }
        }
    }
    // The plans cover nearly every mapping and sample (not those the tree path refuses).
    assert!(samples > 1000 && planned * 2 > samples, "{planned} of {samples} samples by the plan");
}

fn element_struct(schema: &Schema, array: &str) -> usize {
    let mut s = schema.root_index();
    for part in array.split('.') {
        let field = schema.get(s).fields.iter().find(|f| &*f.name == part).unwrap();
        let SchemaBase::Struct(next) = field.base else { panic!() };
        s = next;
    }
    s
}

// Random messages, as the oracle tests make them (tests/oracles.rs).

fn random_primitive(rng: &mut ChaCha8Rng, p: Primitive) -> MsgValue {
    use Primitive::*;
    match p {
        Bool => MsgValue::Bool(rng.random()),
        Int8 => MsgValue::Int(i64::from(rng.random::<i8>())),
        Int16 => MsgValue::Int(i64::from(rng.random::<i16>())),
        Int32 => MsgValue::Int(i64::from(rng.random::<i32>())),
        Int64 => MsgValue::Int(rng.random()),
        Byte | Char | UInt8 => MsgValue::UInt(u64::from(rng.random::<u8>())),
        UInt16 => MsgValue::UInt(u64::from(rng.random::<u16>())),
        UInt32 => MsgValue::UInt(u64::from(rng.random::<u32>())),
        UInt64 => MsgValue::UInt(rng.random()),
        // Mostly finite; sometimes not (the mapping refuses a non-finite number).
        Float32 => MsgValue::Float(f64::from(if rng.random_bool(0.02) {
            f32::NAN
        } else {
            rng.random_range(-1e6f32..1e6)
        })),
        Float64 => {
            MsgValue::Float(if rng.random_bool(0.02) { f64::INFINITY } else { rng.random_range(-1e9..1e9) })
        }
        String(bound) | WString(bound) => {
            let n = rng.random_range(0..8).min(bound.unwrap_or(8) as usize);
            MsgValue::Str(
                ["a", "é", "漢", "🙂", "z"]
                    .iter()
                    .cycle()
                    .skip(rng.random_range(0..5))
                    .take(n)
                    .copied()
                    .collect::<std::string::String>()
                    .chars()
                    .take(n)
                    .collect(),
            )
        }
    }
}

fn random_field(rng: &mut ChaCha8Rng, schema: &Schema, field: &SchemaField, depth: usize) -> MsgValue {
    let octet = matches!(field.base, SchemaBase::Primitive(p) if p.is_octet());
    let random_base = |rng: &mut ChaCha8Rng| match field.base {
        SchemaBase::Primitive(p) => random_primitive(rng, p),
        SchemaBase::Struct(i) => random_struct(rng, schema, i, depth + 1),
    };
    let len = match field.array {
        ArrayKind::Single => return random_base(rng),
        ArrayKind::Fixed(n) => n as usize,
        ArrayKind::Bounded(n) => rng.random_range(0..=n.min(3) as usize),
        ArrayKind::Unbounded if depth < 3 => rng.random_range(0..=4),
        ArrayKind::Unbounded => 0,
    };
    if octet {
        return MsgValue::Bytes((0..len).map(|_| rng.random()).collect());
    }
    MsgValue::List((0..len).map(|_| random_base(rng)).collect())
}

fn random_struct(rng: &mut ChaCha8Rng, schema: &Schema, index: usize, depth: usize) -> MsgValue {
    MsgValue::Struct(schema.get(index).fields.iter().map(|f| random_field(rng, schema, f, depth)).collect())
}

/// Random mappings into KPL for every shipped type, random messages and mutations of them: the
/// plan decodes alike and refuses alike.
#[test]
fn random_in_mappings_decode_alike() {
    let defs = Definitions::builtin();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut names: Vec<String> = defs.names().map(|n| n.to_string()).collect();
    names.sort();
    let (mut planned, mut messages) = (0, 0);
    for name in &names {
        let schema = defs.schema_of(name).unwrap();
        let (mut root_paths, mut arrays) = (Vec::new(), Vec::new());
        paths(&schema, schema.root_index(), "", &mut root_paths, &mut arrays);
        let encoded: Vec<Vec<u8>> = (0..6)
            .filter_map(|_| {
                cdr::encode(&schema, &random_struct(&mut rng, &schema, schema.root_index(), 0)).ok()
            })
            .collect();
        if encoded.is_empty() {
            continue;
        }
        for _ in 0..8 {
            let each = (!arrays.is_empty() && rng.random_bool(0.6))
                .then(|| arrays[rng.random_range(0..arrays.len())].clone());
            let element_paths = match &each {
                None => root_paths.clone(),
                Some(array) => {
                    let mut p = Vec::new();
                    paths(&schema, element_struct(&schema, array), "", &mut p, &mut Vec::new());
                    p
                }
            };
            if element_paths.is_empty() {
                continue;
            }
            let mut entries = Vec::new();
            let mut fields = Vec::new();
            for k in 0..rng.random_range(1..5) {
                let (path, kind) = element_paths[rng.random_range(0..element_paths.len())].clone();
                let ty = match kind {
                    Kind::Signed | Kind::Unsigned if rng.random_bool(0.3) => ValueType::Float,
                    Kind::Float | Kind::Signed | Kind::Unsigned if rng.random_bool(0.2) => ValueType::Any,
                    kind => attribute_type(kind),
                };
                fields.push((format!("a{k}"), ty));
                entries.push(format!("a{k} = {path}"));
            }
            let identity = element_paths
                .iter()
                .filter(|(_, k)| matches!(k, Kind::Signed | Kind::Unsigned | Kind::Str))
                .nth(rng.random_range(0..3))
                .map(|(p, _)| p.clone());
            let field_refs: Vec<(&str, ValueType)> =
                fields.iter().map(|(n, t)| (n.as_str(), t.clone())).collect();
            let ty = record_type("Thing", "th", &field_refs);
            let output = match &each {
                Some(_) => ValueType::List(Box::new(ValueType::Record(ty))),
                None => ValueType::Record(ty),
            };
            let into = InSpec { each, identity, stamp: None, entries };
            let Ok(map) = InMap::compile(&schema, &into, &output) else { continue };
            for bytes in &encoded {
                messages += 1;
                planned += usize::from(same_decoding(&map, bytes));
                for _ in 0..4 {
                    let mut mutated = bytes.clone();
                    for _ in 0..rng.random_range(1..4) {
                        let i = rng.random_range(0..mutated.len());
                        mutated[i] = rng.random();
                    }
                    same_decoding(&map, &mutated);
                }
                same_decoding(&map, &bytes[..rng.random_range(0..bytes.len())]);
                let mut big = bytes.clone();
                big[1] = 0;
                same_decoding(&map, &big);
            }
        }
    }
    assert!(messages > 1000 && planned * 2 > messages, "{planned} of {messages} messages by the plan");
}
