//! KPL's wire codec against CBOR (RFC 8949, through the `ciborium` crate), encoding and decoding
//! the same samples: the measurement behind the choice of wire format in docs/streams.md ("Why
//! not CBOR"). Run with `cargo bench -p kpl-zenoh --bench codec`; it prints each encoding's size
//! first.
//!
//! The CBOR form is what a CBOR wire format would carry: an array `[valid, available, value]`,
//! records as maps (`id` first), vectors and boxes as arrays of numbers, floats as CBOR floats.
//! CBOR decoding here builds the value by its own shape (a lower bound: checking it against the
//! stream's type would come on top), KPL's decoding checks it against the stream's type as a
//! receiving host does.
#![allow(clippy::unwrap_used, clippy::print_stderr)] // a benchmark: it panics and prints

use std::sync::Arc;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use kpl_core::{FieldType, Record, RecordType, Value, ValueType};
use kpl_runtime::Sample;
use kpl_zenoh::codec;
use serde::de::{Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::ser::{Serialize, SerializeMap, Serializer};

/// A value as CBOR.
struct Cbor<'a>(&'a Value);

impl Serialize for Cbor<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            Value::Bool(b) => s.serialize_bool(*b),
            Value::Int(i) | Value::Duration(i) => s.serialize_i64(*i),
            Value::Float(x) => s.serialize_f64(*x),
            Value::Str(t) => s.serialize_str(t),
            Value::Vec2(v) => v.serialize(s),
            Value::BBox(b) => [b.x1, b.y1, b.x2, b.y2].serialize(s),
            Value::List(items) => s.collect_seq(items.iter().map(Cbor)),
            Value::Record(r) => {
                let mut map = s.serialize_map(Some(r.fields.len() + usize::from(r.id.is_some())))?;
                if let Some(id) = &r.id {
                    map.serialize_entry("id", &**id)?;
                }
                for (name, value) in &r.fields {
                    map.serialize_entry(&**name, &Cbor(value))?;
                }
                map.end()
            }
        }
    }
}

/// A value read from CBOR by its shape.
struct Decoded(Value);

impl<'de> Deserialize<'de> for Decoded {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Decoded, D::Error> {
        d.deserialize_any(ValueVisitor).map(Decoded)
    }
}

struct ValueVisitor;

impl<'de> Visitor<'de> for ValueVisitor {
    type Value = Value;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("a KPL value")
    }
    fn visit_bool<E>(self, b: bool) -> Result<Value, E> {
        Ok(Value::Bool(b))
    }
    fn visit_i64<E>(self, i: i64) -> Result<Value, E> {
        Ok(Value::Int(i))
    }
    fn visit_u64<E: serde::de::Error>(self, i: u64) -> Result<Value, E> {
        i64::try_from(i).map(Value::Int).map_err(E::custom)
    }
    fn visit_f64<E>(self, x: f64) -> Result<Value, E> {
        Ok(Value::Float(x))
    }
    fn visit_str<E>(self, s: &str) -> Result<Value, E> {
        Ok(Value::str(s))
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(4096));
        while let Some(Decoded(item)) = seq.next_element()? {
            items.push(item);
        }
        Ok(Value::List(items.into()))
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut record = Record::default();
        while let Some(name) = map.next_key::<String>()? {
            let Decoded(value) = map.next_value()?;
            match (name.as_str(), value) {
                ("id", Value::Str(id)) => record.id = Some(id),
                (_, value) => record.fields.push((name.as_str().into(), value)),
            }
        }
        Ok(Value::Record(Arc::new(record)))
    }
}

fn cbor_encode(sample: &Sample, out: &mut Vec<u8>) {
    out.clear();
    ciborium::into_writer(&(sample.valid, sample.available, Cbor(&sample.value)), &mut *out).unwrap();
}

fn cbor_decode(bytes: &[u8]) -> Sample {
    let (valid, available, Decoded(value)): (i64, i64, Decoded) = ciborium::from_reader(bytes).unwrap();
    Sample::new(valid, available, value)
}

fn percept_type() -> ValueType {
    let field = |name: &str, ty| FieldType { name: name.into(), ty };
    ValueType::List(Box::new(ValueType::Record(Arc::new(RecordType {
        name: "VisionPercept".into(),
        parent: None,
        symbol: "vp".into(),
        fields: vec![
            field("pos", ValueType::Vec2),
            field("vel", ValueType::Vec2),
            field("size", ValueType::Float),
        ],
    }))))
}

/// The cases: name, sample, declared type.
fn cases() -> Vec<(&'static str, Sample, ValueType)> {
    let floats = |n: usize| Value::List((0..n).map(|i| Value::Float(i as f64 * 0.37 - 41.3)).collect());
    let text = |n: usize| Value::str(&"abcdefghijklmnopqrstuvwxyz".repeat(n / 26 + 1)[..n]);
    let percepts = Value::List(
        (0..20)
            .map(|i| {
                let x = f64::from(i);
                Value::Record(Arc::new(Record {
                    id: Some(format!("vp{i}").into()),
                    fields: vec![
                        ("pos".into(), Value::vec2(12.5 * x, -3.25 + x)),
                        ("vel".into(), Value::vec2(13.9, 0.1 * x)),
                        ("size".into(), Value::Float(4.2)),
                    ],
                }))
            })
            .collect(),
    );
    let float_list = ValueType::List(Box::new(ValueType::Float));
    vec![
        ("floats 8", Sample::new(1, 2, floats(8)), float_list.clone()),
        ("floats 512", Sample::new(1, 2, floats(512)), float_list),
        ("string 64", Sample::new(1, 2, text(64)), ValueType::Str),
        ("string 4096", Sample::new(1, 2, text(4096)), ValueType::Str),
        ("20 percepts", Sample::new(1, 2, percepts), percept_type()),
    ]
}

fn bench(c: &mut Criterion) {
    let mut kpl = Vec::new();
    let mut cbor = Vec::new();
    for (name, sample, ty) in cases() {
        codec::encode_sample(&sample, &mut kpl).unwrap();
        cbor_encode(&sample, &mut cbor);
        // Both decode to the sample that was sent (CBOR by its shape: compared as JSON).
        assert_eq!(codec::decode(&kpl, &ty).unwrap(), codec::Message::Sample(sample.clone()));
        assert_eq!(cbor_decode(&cbor).value.to_json(), sample.value.to_json());
        eprintln!("{name}: kpl {} bytes, cbor {} bytes", kpl.len(), cbor.len());

        let mut group = c.benchmark_group(name);
        group.bench_function(BenchmarkId::new("encode", "kpl"), |b| {
            b.iter(|| codec::encode_sample(&sample, &mut kpl).unwrap());
        });
        group.bench_function(BenchmarkId::new("encode", "cbor"), |b| {
            b.iter(|| cbor_encode(&sample, &mut cbor))
        });
        codec::encode_sample(&sample, &mut kpl).unwrap();
        cbor_encode(&sample, &mut cbor);
        group.bench_function(BenchmarkId::new("decode", "kpl"), |b| {
            b.iter(|| codec::decode(&kpl, &ty).unwrap())
        });
        group.bench_function(BenchmarkId::new("decode", "cbor"), |b| b.iter(|| cbor_decode(&cbor)));
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
