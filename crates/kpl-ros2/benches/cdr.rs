//! A ROS 2 message into KPL values and back, against the same values as JSON (what a KPL
//! recording line of them is, and what `Value::from_json` reads), in the same run:
//! - `decode/cdr+map`: a 100-marker `visualization_msgs/MarkerArray` in CDR decoded (`cdr::decode`)
//!   and mapped into 100 percepts (`InMap::apply`, specs/ros2/markers.kpl's mapping), against
//!   `decode/json`: the JSON text of those 100 percepts parsed and typed;
//! - `encode/map+cdr`: 100 cars mapped into a MarkerArray (`OutMap::apply`, markers.kpl's
//!   `/kpl/cars` mapping) and encoded, against `encode/json`: the cars written as JSON;
//! - `decode/plan` and `encode/plan`: the same by the mappings' compiled plans (`InMap::decode`,
//!   `OutMap::encode_into`: what `ros2.subscribe` and `ros2.publish` run), which give the same
//!   values and bytes without building the message (crates/kpl-ros2/tests/plans.rs).
//!
//! `cargo bench -p kpl-ros2 --bench cdr`; docs/performance.md has the figures as ratios.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)] // a benchmark

use std::sync::Arc;

use criterion::{Criterion, black_box, criterion_group, criterion_main};
use kpl_core::{FieldType, Record, RecordType, Value, ValueType};
use kpl_ros2::mapping::{InMap, InSpec, OutMap, OutSpec, workloads};
use kpl_ros2::{Definitions, cdr};

fn list_of(name: &str, symbol: &str) -> ValueType {
    let fields = vec![
        FieldType { name: "pos".into(), ty: ValueType::Vec2 },
        FieldType { name: "size".into(), ty: ValueType::Float },
    ];
    let ty = RecordType { name: name.into(), parent: None, symbol: symbol.into(), fields };
    ValueType::List(Box::new(ValueType::Record(ty.into())))
}

fn bench(c: &mut Criterion) {
    let defs = Definitions::builtin();
    let schema = defs.schema_of("visualization_msgs/msg/MarkerArray").unwrap();
    let cars_ty = list_of("Car", "co");
    let cars: Vec<Value> = (0..100)
        .map(|i| {
            let fields = vec![
                (Arc::from("pos"), Value::Vec2([100.0 + i as f64 * 3.5, -40.0 + i as f64 * 0.25])),
                (Arc::from("size"), Value::Float(4.5 + (i % 3) as f64)),
            ];
            Value::Record(Arc::new(Record { id: Some(format!("co{i}").into()), fields }))
        })
        .collect();
    let cars = Value::List(cars.into());
    let out_spec = OutSpec {
        each: Some("markers".into()),
        entries: workloads::MARKERS_OF_CARS.iter().map(|e| e.to_string()).collect(),
    };
    let mut out = OutMap::compile(schema.clone(), &out_spec, &cars_ty).unwrap();
    let valid = 1_700_000_000_000_000;
    let bytes = cdr::encode(&schema, &out.apply(valid, &cars).unwrap()).unwrap();

    let percept_ty = list_of("VisionPercept", "vp");
    let in_spec = InSpec {
        each: Some("markers".into()),
        identity: Some("id".into()),
        stamp: None,
        entries: workloads::PERCEPTS_OF_MARKERS.iter().map(|e| e.to_string()).collect(),
    };
    let map = InMap::compile(&schema, &in_spec, &percept_ty).unwrap();
    let percepts = map.apply(&cdr::decode(&schema, &bytes).unwrap()).unwrap();
    let json = serde_json::to_vec(&percepts.to_json()).unwrap();

    let mut group = c.benchmark_group("decode");
    group.bench_function("cdr+map", |b| {
        b.iter(|| {
            let msg = cdr::decode(&schema, black_box(&bytes)).unwrap();
            (map.valid_time(&msg), map.apply(&msg).unwrap())
        })
    });
    group.bench_function("plan", |b| b.iter(|| map.decode(black_box(&bytes)).unwrap()));
    group.bench_function("json", |b| {
        b.iter(|| {
            let parsed: serde_json::Value = serde_json::from_slice(black_box(&json)).unwrap();
            Value::from_json(&parsed, &percept_ty).unwrap()
        })
    });
    group.finish();

    let mut group = c.benchmark_group("encode");
    let mut buffer = Vec::new();
    group.bench_function("map+cdr", |b| {
        b.iter(|| {
            let msg = out.apply(valid, black_box(&cars)).unwrap();
            cdr::encode_into(&schema, &msg, &mut buffer).unwrap();
            buffer.len()
        })
    });
    group.bench_function("plan", |b| {
        b.iter(|| {
            out.encode_into(valid, black_box(&cars), &mut buffer).unwrap();
            buffer.len()
        })
    });
    group.bench_function("json", |b| b.iter(|| serde_json::to_vec(black_box(&cars)).unwrap().len()));
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
