//! What the envelope costs per message (`kpl_zenoh::envelope`), against what the message itself
//! costs to encode and decode (`kpl_zenoh::codec`): sealing on the producing host and opening on
//! the consuming one, without keys (host, incarnation, sequence) and with keys (plus an
//! HMAC-SHA256 tag over the key, the envelope and the payload).
//!
//! Run: `cargo bench -p kpl-zenoh --bench envelope`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use kpl_core::{Value, ValueType};
use kpl_runtime::Sample;
use kpl_zenoh::codec;
use kpl_zenoh::credentials::Secret;
use kpl_zenoh::envelope::Envelope;

const KEY: &str = "kpl/default/bench/throughput";

fn messages() -> Vec<(&'static str, Sample, ValueType)> {
    let text = Value::str(&"x".repeat(64));
    let floats: Vec<Value> = (0..512).map(|i| Value::Float(f64::from(i) * 0.5)).collect();
    vec![
        ("string 64 B", Sample::new(1, 2, text), ValueType::Str),
        (
            "512 floats",
            Sample::new(1, 2, Value::List(floats.into())),
            ValueType::List(Box::new(ValueType::Float)),
        ),
    ]
}

fn envelope(c: &mut Criterion) {
    let secret = Secret::from_bytes(&[7; 32]);
    for (name, sample, ty) in messages() {
        let mut payload = Vec::new();
        codec::encode_sample(&sample, &mut payload).expect("encodable");
        let mut group = c.benchmark_group(name);
        group.bench_function("message: encode + decode", |b| {
            b.iter(|| {
                let mut bytes = Vec::with_capacity(payload.len() + 16);
                codec::encode_sample(black_box(&sample), &mut bytes).expect("encodable");
                black_box(codec::decode(&bytes, &ty).expect("decodable"))
            })
        });
        for (label, key) in
            [("envelope: seal + open", None), ("envelope with keys: seal + open", Some(&secret))]
        {
            let mut sequence = 0u64;
            group.bench_function(label, |b| {
                b.iter(|| {
                    sequence += 1;
                    let e = Envelope { host: "uav".into(), incarnation: 42, sequence, unfinished: false };
                    let sealed = e.seal(KEY, black_box(&payload), key);
                    black_box(Envelope::open(Some(&sealed), KEY, &payload, key).expect("opens"))
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, envelope);
criterion_main!(benches);
