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
        let expected = if what == "cut short" { "the file is cut short" } else { "not readable as MCAP" };
        assert!(error.starts_with(expected), "{what}: {error}");
        assert!(location.contains("after message"), "{what}: {location}");
        let good = events.iter().filter(|e| matches!(e, Event::Sample { .. })).count();
        assert_eq!(good + 1, events.len(), "{what}: one message at the end");
        if what == "cut short" {
            assert!(good > 0, "what came before the cut replays");
        }
    }
    std::fs::remove_file(&path).ok();
}

/// The speeds of a file read to its end: the samples, and the last event's error if it was not
/// a sample.
fn speeds(path: &std::path::Path) -> (Vec<Sample>, Option<String>) {
    let (events, _) = read_all(path, "", &ValueType::Float);
    let mut samples = Vec::new();
    let mut error = None;
    for event in events {
        match event {
            Event::Sample { sample, .. } => samples.push(sample),
            Event::Malformed { error: e, .. } => {
                assert!(error.is_none(), "one malformed entry at most: {e}");
                error = Some(e);
            }
        }
    }
    (samples, error)
}

/// A run killed with -9 stops the writer wherever it is: nothing of its memory reaches the file
/// (here: the recorder is forgotten, neither finished nor dropped). Every chunk closed before
/// (chunks span at most a second of available time) is on disk and reads back.
#[test]
fn a_recorder_that_never_finishes_leaves_its_closed_chunks_readable() {
    for compression in [Compression::Zstd, Compression::Lz4, Compression::None] {
        let path = temp(&format!("killed-{compression:?}"));
        let mut recorder = Recorder::create(&path, compression).unwrap();
        let speed = recorder.add_stream("speed", &ValueType::Float).unwrap();
        // 10 samples a second for 20.05 s: 20 chunks of a second are closed, the last 0.05 s not.
        let n = 201;
        for i in 0..n {
            let t = i * 100_000;
            recorder.write(speed, &Sample::new(t, t, Value::Float(i as f64))).unwrap();
        }
        std::mem::forget(recorder);
        let (samples, error) = speeds(&path);
        let error = error.expect("a cut-short file says so");
        assert!(error.starts_with("the file is cut short"), "{compression:?}: {error}");
        // The chunk closes with the sample a second after its first: 11 samples in the first
        // chunk (0 s to 1 s), 10 in each after.
        assert!(samples.len() >= 190 && samples.len() < n as usize, "{compression:?}: {}", samples.len());
        for (i, sample) in samples.iter().enumerate() {
            assert_eq!(sample.value, Value::Float(i as f64), "in order, none lost before the cut");
        }
        std::fs::remove_file(&path).ok();
    }
}

/// A file whose last chunk was never finished by a writer that seeks back to patch its header
/// (the `mcap` crate's default, and KPL's before): the chunk's length is still `u64::MAX`. The
/// reader reads the whole chunks, then decompresses what the unfinished one holds.
#[test]
fn an_unfinished_chunk_with_a_placeholder_length_is_recovered() {
    for compression in [Some(mcap::Compression::Zstd), Some(mcap::Compression::Lz4), None] {
        let path = temp(&format!("placeholder-{compression:?}"));
        let file = std::fs::File::create(&path).unwrap();
        let mut writer = mcap::WriteOptions::new()
            .compression(compression)
            .chunk_size(Some(64 * 1024))
            .create(std::io::BufWriter::with_capacity(1024, file))
            .unwrap();
        let recorder_like = |writer: &mut mcap::Writer<_>| {
            let schema = writer.add_schema("float", "jsonschema", b"{}").unwrap();
            let meta = BTreeMap::from([(kpl_mcap::SAMPLE_KEY.to_string(), "1".to_string())]);
            let channel = writer.add_channel(schema, "speed", "json", &meta).unwrap();
            for i in 0..20_000u64 {
                let body = format!("{{\"valid\":{i},\"available\":{i},\"value\":{i}.5}}");
                let header = mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: 0,
                    log_time: i,
                    publish_time: i,
                };
                writer.write_to_known_channel(&header, body.as_bytes()).unwrap();
            }
        };
        recorder_like(&mut writer);
        // What the writer wrote reached the file, as an OS keeps what a killed process wrote;
        // what it held in memory is lost.
        std::mem::forget(writer);
        let bytes = std::fs::read(&path).unwrap();
        assert!(
            bytes.windows(8).any(|w| w == [0xff; 8]),
            "{compression:?}: a placeholder length is in the file"
        );
        let (samples, error) = speeds(&path);
        let error = error.unwrap();
        assert!(error.starts_with("the file is cut short"), "{compression:?}: {error}");
        // A compressor keeps up to a block in memory; uncompressed, the unfinished chunk's
        // messages are on disk up to the last kilobyte.
        if compression.is_none() {
            assert!(error.contains("from a chunk that was not finished"), "{error}");
        }
        assert!(samples.len() > 15_000, "{compression:?}: {} of 20000", samples.len());
        for (i, sample) in samples.iter().enumerate() {
            assert_eq!(sample.value, Value::Float(i as f64 + 0.5));
        }
        std::fs::remove_file(&path).ok();
    }
}
