//! Writing and reading MCAP files: typed samples come back exactly (property test), the stream
//! filter skips other channels before decoding them, JSON channels of other tools replay, and
//! files that are not whole MCAP files end a replay with a message instead of a panic.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use kpl_core::{BBox, FieldType, Record, RecordType, Value, ValueType};
use kpl_mcap::read::{Event, Reader};
use kpl_mcap::write::{Compression, Recorder};
use kpl_runtime::Sample;
use kpl_runtime::builtins::StreamFilter;
use proptest::prelude::*;

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("kpl-mcap-{name}-{}.mcap", std::process::id()))
}

/// Every event of a file, with the filter's warning at the end.
fn read_all(path: &std::path::Path, stream: &str, ty: &ValueType) -> (Vec<Event>, Option<String>) {
    let mut reader = Reader::open(path).unwrap();
    let mut filter = StreamFilter::new(stream);
    let mut events = Vec::new();
    while let Some(event) = reader.next_event(&mut filter, ty) {
        events.push(event);
    }
    (events, filter.warning("f.mcap"))
}

fn samples(events: &[Event]) -> Vec<(String, Sample)> {
    events
        .iter()
        .map(|e| match e {
            Event::Sample { stream, sample, .. } => (stream.to_string(), sample.clone()),
            Event::Malformed { location, error } => panic!("{location}: {error}"),
        })
        .collect()
}

fn car_type() -> ValueType {
    ValueType::Record(Arc::new(RecordType {
        name: "Car".into(),
        parent: None,
        symbol: "co".into(),
        fields: vec![
            FieldType { name: "pos".into(), ty: ValueType::Vec2 },
            FieldType { name: "box".into(), ty: ValueType::BBox },
            FieldType { name: "age".into(), ty: ValueType::Duration },
            FieldType { name: "label".into(), ty: ValueType::Str },
        ],
    }))
}

fn car() -> impl Strategy<Value = Value> {
    (
        "[a-z]{1,3}[0-9]{0,2}",
        prop::array::uniform2(-1e9f64..1e9),
        prop::array::uniform4(-1e6f64..1e6),
        any::<i64>(),
        "\\PC{0,8}",
    )
        .prop_map(|(id, pos, b, age, label)| {
            Value::Record(Arc::new(Record {
                id: Some(id.as_str().into()),
                fields: vec![
                    ("pos".into(), Value::Vec2(pos)),
                    ("box".into(), Value::bbox(BBox::new(b[0], b[1], b[2], b[3]))),
                    ("age".into(), Value::Duration(age)),
                    ("label".into(), Value::str(&label)),
                ],
            }))
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// Samples of two streams come back exactly, each stream in order, whatever the compression.
    #[test]
    fn typed_samples_round_trip(
        cars in prop::collection::vec((any::<i64>(), any::<i64>(), prop::collection::vec(car(), 0..4)), 0..20),
        floats in prop::collection::vec((-1_000_000i64..1_000_000, prop::num::f64::NORMAL | prop::num::f64::ZERO), 0..20),
        compression in prop::sample::select(vec![Compression::Zstd, Compression::Lz4, Compression::None]),
    ) {
        let path = temp("round-trip");
        let cars_ty = ValueType::List(Box::new(car_type()));
        let mut recorder = Recorder::create(&path, compression).unwrap();
        let a = recorder.add_stream("cars", &cars_ty).unwrap();
        let b = recorder.add_stream("speed", &ValueType::Float).unwrap();
        let mut expected_cars = Vec::new();
        for (valid, available, list) in &cars {
            let sample = Sample::new(*valid, *available, Value::List(list.clone().into()));
            recorder.write(a, &sample).unwrap();
            expected_cars.push(("cars".to_string(), sample));
        }
        let mut expected_speed = Vec::new();
        for (t, x) in &floats {
            let sample = Sample::new(*t, *t, Value::Float(*x));
            recorder.write(b, &sample).unwrap();
            expected_speed.push(("speed".to_string(), sample));
        }
        recorder.finish().unwrap();
        prop_assert_eq!(samples(&read_all(&path, "cars", &cars_ty).0), expected_cars);
        prop_assert_eq!(samples(&read_all(&path, "speed", &ValueType::Float).0), expected_speed);
        std::fs::remove_file(&path).ok();
    }
}

#[test]
fn the_filter_skips_other_streams_before_decoding_and_warns_when_nothing_matched() {
    let path = temp("filter");
    let mut recorder = Recorder::create(&path, Compression::Zstd).unwrap();
    let speed = recorder.add_stream("speed", &ValueType::Float).unwrap();
    let label = recorder.add_stream("label", &ValueType::Str).unwrap();
    for t in 0..3 {
        recorder.write(speed, &Sample::new(t, t, Value::Float(t as f64))).unwrap();
        recorder.write(label, &Sample::new(t, t, Value::str("not a number"))).unwrap();
    }
    recorder.finish().unwrap();
    let (events, warning) = read_all(&path, "speed", &ValueType::Float);
    assert_eq!(samples(&events).len(), 3, "the labels are not malformed floats");
    assert_eq!(warning, None);
    let (events, warning) = read_all(&path, "sped", &ValueType::Float);
    assert!(events.is_empty());
    assert_eq!(
        warning.unwrap(),
        "no sample of f.mcap is of stream \"sped\", so this source is empty: its streams are \"label\" (3), \
         \"speed\" (3); did you mean \"speed\"?"
    );
    // Without a filter, the labels are malformed for a float source, with where they are.
    let (events, _) = read_all(&path, "", &ValueType::Float);
    let Event::Malformed { location, error } = &events[1] else { panic!("{events:?}") };
    assert!(location.ends_with("message 2"), "{location}");
    assert_eq!(error, "value at `.`: expected a finite number, found the string \"not a number\"");
    std::fs::remove_file(&path).ok();
}

#[test]
fn json_channels_of_other_tools_replay_and_other_encodings_are_malformed() {
    let path = temp("foreign");
    {
        let mut writer =
            mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&path).unwrap())).unwrap();
        let schema = writer.add_schema("Pose", "jsonschema", br#"{"type": "object"}"#).unwrap();
        let pose = writer.add_channel(schema, "/pose", "json", &BTreeMap::new()).unwrap();
        let cdr = writer.add_channel(0, "/scan", "cdr", &BTreeMap::new()).unwrap();
        let header = |channel_id, sequence, t| mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: t + 5_000,
            publish_time: t,
        };
        writer.write_to_known_channel(&header(pose, 1, 1_000_000_123), br#"{"x": 1.5, "y": -2}"#).unwrap();
        writer.write_to_known_channel(&header(cdr, 1, 1_000_000_200), &[0, 1, 0, 0]).unwrap();
        writer.write_to_known_channel(&header(pose, 2, 2_000_000_000), b"{not json").unwrap();
        writer.finish().unwrap();
    }
    let (events, _) = read_all(&path, "", &ValueType::Any);
    assert_eq!(events.len(), 3);
    let Event::Sample { stream, sample, .. } = &events[0] else { panic!("{events:?}") };
    assert_eq!(&**stream, "/pose");
    // Publish time is the valid time, log time the available time, in microseconds.
    assert_eq!((sample.valid, sample.available), (1_000_000, 1_000_005));
    assert_eq!(sample.value.field("x"), Some(Value::Float(1.5)));
    let Event::Malformed { error, .. } = &events[1] else { panic!("{events:?}") };
    assert!(error.contains("message encoding `cdr`"), "{error}");
    let Event::Malformed { error, .. } = &events[2] else { panic!("{events:?}") };
    assert!(error.starts_with("not a JSON message"), "{error}");
    std::fs::remove_file(&path).ok();
}

#[test]
fn files_that_are_not_whole_mcap_end_the_replay_with_a_message() {
    let path = temp("cut");
    let mut recorder = Recorder::create(&path, Compression::None).unwrap();
    let speed = recorder.add_stream("speed", &ValueType::Float).unwrap();
    // Several chunks (of 1 MiB), so that a file cut in the middle has whole chunks before the cut.
    for t in 0..40_000 {
        recorder.write(speed, &Sample::new(t, t, Value::Float(0.5))).unwrap();
    }
    recorder.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("cut short", bytes[..bytes.len() / 2].to_vec()),
        ("JSON lines", b"{\"stream\": \"speed\", \"valid\": 0, \"value\": 1.0}\n".to_vec()),
        ("empty", Vec::new()),
        ("zeros", vec![0; 4096]),
    ];
    for (what, bytes) in cases {
        std::fs::write(&path, &bytes).unwrap();
        let (events, _) = read_all(&path, "", &ValueType::Float);
        let Some(Event::Malformed { location, error }) = events.last() else { panic!("{what}: {events:?}") };
        assert!(error.starts_with("not readable as MCAP"), "{what}: {error}");
        assert!(location.contains("after message"), "{what}: {location}");
        let good = events.iter().filter(|e| matches!(e, Event::Sample { .. })).count();
        assert_eq!(good + 1, events.len(), "{what}: one message at the end");
        if what == "cut short" {
            assert!(good > 0, "what came before the cut replays");
        }
    }
    std::fs::remove_file(&path).ok();
}
