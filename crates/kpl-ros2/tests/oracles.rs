//! kpl-ros2 against ROS 2's own libraries (the Python of `scripts/test`, `KPL_PYTHON`):
//!
//! - CDR, both ways, against `rclpy.serialization` (ROS 2's C type support of the message wheels)
//!   for every shipped type those wheels have: 1,000 random messages per type made by kpl are
//!   serialized by rclpy from their fields (byte-identical) and deserialized by it (the same
//!   fields); 1,000 random messages per type made by rclpy are decoded by kpl (the same fields)
//!   and re-encoded (byte-identical). (`tests/oracle/rclpy_cdr.py`)
//! - Type hashes against `rosbags` (its own parser and hash) for every shipped type and a user's
//!   folder, and against the hashes rosidl wrote into the installed packages; CDR against rosbags
//!   for the types without an rclpy wheel (vision_msgs, the user's). (`tests/oracle/rosbags_types.py`)
//!
//! Skipped without `KPL_PYTHON` unless `KPL_REQUIRE_ORACLES=1`. `KPL_ROS2_CASES` changes the 1,000.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // tests

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use kpl_ros2::cdr::{self, MsgValue};
use kpl_ros2::definitions::{SchemaBase, SchemaField};
use kpl_ros2::msg::{ArrayKind, Primitive};
use kpl_ros2::{Definitions, Schema, json};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value as Json;

fn python() -> Option<String> {
    match std::env::var("KPL_PYTHON") {
        Ok(p) => Some(p),
        Err(_) => {
            let required = std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1");
            assert!(!required, "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set: run scripts/test");
            eprintln!("skipped: KPL_PYTHON is not set (scripts/test sets it up with rclpy and rosbags)");
            None
        }
    }
}

fn cases() -> usize {
    std::env::var("KPL_ROS2_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(1000)
}

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const ALPHABET: &[&str] = &["a", "Z", "0", " ", "_", "/", ".", "é", "漢", "🙂", "x", "y"];

fn random_string(rng: &mut ChaCha8Rng, bound: Option<u32>) -> String {
    let mut s = String::new();
    for _ in 0..rng.random_range(0..10) {
        let c = ALPHABET[rng.random_range(0..ALPHABET.len())];
        if bound.is_some_and(|b| s.len() + c.len() > b as usize) {
            break;
        }
        s.push_str(c);
    }
    s
}

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
        Float32 => loop {
            let x = f32::from_bits(rng.random());
            if x.is_finite() {
                break MsgValue::Float(f64::from(x));
            }
        },
        Float64 => loop {
            let x = f64::from_bits(rng.random());
            if x.is_finite() {
                break MsgValue::Float(x);
            }
        },
        String(bound) | WString(bound) => MsgValue::Str(random_string(rng, bound)),
    }
}

fn random_base(rng: &mut ChaCha8Rng, schema: &Schema, base: SchemaBase, depth: usize) -> MsgValue {
    match base {
        SchemaBase::Primitive(p) => random_primitive(rng, p),
        SchemaBase::Struct(i) => random_struct(rng, schema, i, depth + 1),
    }
}

fn random_field(rng: &mut ChaCha8Rng, schema: &Schema, field: &SchemaField, depth: usize) -> MsgValue {
    let octet = matches!(field.base, SchemaBase::Primitive(p) if p.is_octet());
    let primitive = matches!(field.base, SchemaBase::Primitive(_));
    let len = match field.array {
        ArrayKind::Single => return random_base(rng, schema, field.base, depth),
        ArrayKind::Fixed(n) => n as usize,
        ArrayKind::Bounded(n) => rng.random_range(0..=n.min(3) as usize),
        ArrayKind::Unbounded if primitive => rng.random_range(0..=12),
        ArrayKind::Unbounded if depth < 3 => rng.random_range(0..=2),
        ArrayKind::Unbounded => 0,
    };
    if octet {
        return MsgValue::Bytes((0..len).map(|_| rng.random()).collect());
    }
    MsgValue::List((0..len).map(|_| random_base(rng, schema, field.base, depth)).collect())
}

fn random_struct(rng: &mut ChaCha8Rng, schema: &Schema, index: usize, depth: usize) -> MsgValue {
    MsgValue::Struct(schema.get(index).fields.iter().map(|f| random_field(rng, schema, f, depth)).collect())
}

fn hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        let _ = write!(s, "{b:02x}");
    }
    s
}

fn unhex(text: &str) -> Vec<u8> {
    (0..text.len()).step_by(2).map(|i| u8::from_str_radix(&text[i..i + 2], 16).unwrap()).collect()
}

/// Writes `count` random messages of each type as JSON lines `{type, json, cdr}`.
fn write_cases(defs: &Definitions, types: &[String], count: usize, seed: u64, path: &Path) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    for name in types {
        let schema = defs.schema_of(name).unwrap();
        for _ in 0..count {
            let value = random_struct(&mut rng, &schema, schema.root_index(), 0);
            let bytes = cdr::encode(&schema, &value).unwrap();
            assert_eq!(cdr::decode(&schema, &bytes).unwrap(), value, "{name}: kpl's own round trip");
            let (pads, _) = cdr::padding(&schema, &bytes).unwrap();
            let line = serde_json::json!({"type": name, "json": json::to_json(&schema, &value), "cdr": hex(&bytes), "pads": pads});
            writeln!(out, "{line}").unwrap();
        }
    }
}

fn run(python: &str, script: &str, args: &[&Path], extra: &[String]) {
    let status = Command::new(python)
        .arg(crate_dir().join("tests/oracle").join(script))
        .args(args)
        .args(extra)
        .status()
        .unwrap();
    assert!(status.success(), "{script} failed");
}

#[test]
fn cdr_matches_rclpy_both_ways() {
    let Some(python) = python() else { return };
    let defs = Definitions::builtin();
    // vision_msgs has no wheel for rclpy: rosbags checks it (below).
    let types: Vec<String> =
        defs.names().filter(|t| &*t.package != "vision_msgs").map(ToString::to_string).collect();
    let dir = scratch("rclpy_cdr");
    let (ours, theirs) = (dir.join("kpl.jsonl"), dir.join("rclpy.jsonl"));
    let count = cases();
    write_cases(&defs, &types, count, 26, &ours);
    run(&python, "rclpy_cdr.py", &[&ours, &theirs], &[count.to_string(), "26".into()]);

    let text = std::fs::read_to_string(&theirs).unwrap();
    let mut lines: Vec<&str> = text.lines().collect();
    let summary: Json = serde_json::from_str(lines.pop().unwrap()).unwrap();
    let summary = &summary["summary"];
    assert_eq!(summary["checked"], count * types.len(), "rclpy checked every message of kpl");
    assert_eq!(summary["mismatch_count"], 0, "kpl -> rclpy: {:#}", summary["mismatches"]);
    let mut per_type: BTreeMap<String, usize> = BTreeMap::new();
    for line in lines {
        let case: Json = serde_json::from_str(line).unwrap();
        let name = case["type"].as_str().unwrap();
        let schema = defs.schema_of(name).unwrap();
        // Fast-CDR leaves its padding bytes as its buffer had them; kpl writes zeros.
        let (bytes, decoded) = cdr::canonical(&schema, &unhex(case["cdr"].as_str().unwrap()))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(json::to_json(&schema, &decoded), case["json"], "{name}: kpl decodes rclpy's bytes");
        assert_eq!(json::from_json(&schema, &case["json"]).unwrap(), decoded, "{name}");
        // rclpy's buffer may run past the message (rmw_fastrtps sizes it by an estimate).
        let encoded = cdr::encode(&schema, &decoded).unwrap();
        assert!(encoded.len() <= bytes.len(), "{name}");
        assert_eq!(encoded, bytes[..encoded.len()], "{name}: kpl re-encodes rclpy's bytes");
        *per_type.entry(name.to_string()).or_default() += 1;
    }
    assert_eq!(per_type.len(), types.len());
    assert!(per_type.values().all(|&n| n == count));
}

#[test]
fn hashes_and_cdr_match_rosbags() {
    let Some(python) = python() else { return };
    let dir = scratch("rosbags_types");
    let root = dir.join("msgs");
    copy_tree(&crate_dir().join("msgs"), &root);
    copy_tree(&crate_dir().join("tests/data"), &root);
    let mut defs = Definitions::builtin();
    assert_eq!(defs.add_folder(&crate_dir().join("tests/data")).unwrap(), 3);
    let checked: Vec<String> = defs
        .names()
        .filter(|t| ["vision_msgs", "robot_msgs"].contains(&&*t.package))
        .map(ToString::to_string)
        .collect();
    let ours = dir.join("kpl.jsonl");
    let out = dir.join("rosbags.json");
    let count = cases();
    write_cases(&defs, &checked, count, 11, &ours);
    run(&python, "rosbags_types.py", &[&root, &ours, &out], &[]);
    let result: Json = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(result["checked"], count * checked.len());
    assert_eq!(result["mismatch_count"], 0, "{:#}", result["mismatches"]);

    let mut compared_official = 0;
    for name in defs.names() {
        let ours = defs.schema(name).unwrap().type_hash();
        let key = name.to_string();
        if ROSBAGS_CHAR.contains(&key.as_str()) {
            // rosbags gives `char` the type id of IDL's char (13); rosidl maps a .msg `char` to
            // uint8 (3), and its hash is the one ROS 2 uses (checked below).
            assert_ne!(
                result["hashes"][&key].as_str(),
                Some(ours.as_str()),
                "rosbags now agrees on {key}: drop it from ROSBAGS_CHAR"
            );
            assert!(result["official"][&key].is_string(), "{key} needs rosidl's hash");
        } else {
            assert_eq!(result["hashes"][&key].as_str(), Some(ours.as_str()), "rosbags' hash of {key}");
        }
        if let Some(official) = result["official"][&key].as_str() {
            assert_eq!(official, ours, "rosidl's hash of {key}");
            compared_official += 1;
        }
    }
    assert!(defs.names().any(|n| n.to_string() == "robot_msgs/msg/Track"));
    // Every shipped package but vision_msgs is installed with its rosidl hashes.
    let installed = defs.names().filter(|t| !["vision_msgs", "robot_msgs"].contains(&&*t.package)).count();
    assert_eq!(compared_official, installed, "rosidl's hashes compared");
}

/// The shipped types with a `char` field, whose hash rosbags (0.11) computes with IDL's `char`.
const ROSBAGS_CHAR: &[&str] = &["std_msgs/msg/Char"];

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_tree(&entry.path(), &target);
        } else if entry.path().extension().is_some_and(|e| e == "msg") {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// Keys, tokens, QoS and attachments against zenoh-ros2-sdk and pamoja-ros2
/// (`tests/oracle/rmw_zenoh_wire.py`).
#[test]
fn wire_matches_independent_rmw_zenoh_implementations() {
    use kpl_ros2::wire::{self, Attachment, EntityKind, Node, Qos};
    let Some(python) = python() else { return };
    let defs = Definitions::builtin();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let topics = ["/tracker/markers", "/kpl/cars", "/chatter", "/robot_1/camera/detections"];
    let types = [
        "visualization_msgs/msg/MarkerArray",
        "geometry_msgs/msg/PoseStamped",
        "std_msgs/msg/String",
        "vision_msgs/msg/Detection2DArray",
    ];
    let namespaces = ["/", "/robot_1", "/a/b"];
    let mut cases = Vec::new();
    let mut ours = Vec::new();
    for i in 0..40 {
        let ty = types[i % types.len()];
        let schema = defs.schema_of(ty).unwrap();
        let hash = schema.type_hash();
        let node = Node {
            domain: rng.random_range(0..233),
            session_id: hex(&rng.random::<[u8; 16]>()),
            node_id: rng.random_range(0..100),
            namespace: namespaces[i % namespaces.len()].to_string(),
            name: format!("kpl_{i}"),
        };
        let qos = Qos {
            reliable: rng.random(),
            transient_local: rng.random(),
            depth: if rng.random_bool(0.8) { Some(rng.random_range(1..100)) } else { None },
        };
        let kind = if i % 2 == 0 { EntityKind::Publisher } else { EntityKind::Subscription };
        let topic = topics[i % topics.len()];
        let entity_id = node.node_id + 1 + rng.random_range(0..10);
        let attachment = Attachment {
            sequence_number: rng.random_range(0..i64::MAX),
            source_timestamp: rng.random_range(0..i64::MAX),
            gid: rng.random(),
        };
        cases.push(serde_json::json!({
            "domain": node.domain, "session": node.session_id, "node_id": node.node_id,
            "namespace": node.namespace, "node": node.name, "entity_id": entity_id, "kind": kind.code(),
            "topic": topic, "type": ty, "hash": hash,
            "qos": {"reliable": qos.reliable, "transient_local": qos.transient_local, "depth": qos.depth},
            "seq": attachment.sequence_number, "stamp_ns": attachment.source_timestamp, "gid": attachment.gid.to_vec(),
        }));
        let dds = schema.name().dds_name();
        ours.push((
            wire::topic_key(node.domain, topic, &dds, &hash),
            dds.clone(),
            hash.trim_start_matches("RIHS01_").to_string(),
            node.token(),
            node.endpoint_token(entity_id, kind, topic, &dds, &hash, &qos),
            qos.encode(),
            hex(&attachment.encode()),
        ));
    }
    let dir = scratch("rmw_zenoh_wire");
    let (input, output) = (dir.join("cases.json"), dir.join("theirs.json"));
    std::fs::write(&input, serde_json::to_vec(&cases).unwrap()).unwrap();
    run(&python, "rmw_zenoh_wire.py", &[&input, &output], &[]);
    let theirs: Vec<Json> = serde_json::from_slice(&std::fs::read(&output).unwrap()).unwrap();
    assert_eq!(theirs.len(), ours.len());
    for (t, (key, dds, digest, node_token, endpoint_token, qos, attachment)) in theirs.iter().zip(&ours) {
        assert_eq!(t["key"], *key);
        assert_eq!(t["key_pamoja"], *key);
        assert_eq!(t["dds_pamoja"], *dds);
        assert_eq!(t["digest_pamoja"], *digest);
        assert_eq!(t["node_token"], *node_token);
        assert_eq!(t["endpoint_token"], *endpoint_token);
        assert_eq!(t["qos"], *qos);
        assert_eq!(t["attachment"], *attachment);
        assert_eq!(attachment.len(), 66);
    }
}
