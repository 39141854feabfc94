//! The wire format of samples between hosts: [`encode_sample`], [`encode_end`] and [`decode`]
//! are the only functions that write or read it (docs/streams.md, "On the wire").
//!
//! Every message starts with a 5-byte header, then the body of its kind; integers are
//! little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 0..3 | magic `KPL` |
//! | 3 | format version, 1 |
//! | 4 | kind: `S` (0x53) a sample, `E` (0x45) the end of the stream |
//!
//! A sample (`S`) goes on with its valid time (i64, bytes 5..13) and available time (i64, bytes
//! 13..21), integer microseconds, and then the value as UTF-8 JSON, encoded by its type exactly as
//! in the JSON-lines files (bytes 21..). The end (`E`) goes on with the number of samples the
//! producer published on the stream (u64, bytes 5..13), so a subscriber can tell whether it
//! missed any. In Python: `struct.unpack_from("<3sBcqq", payload)` and
//! `json.loads(payload[21:])`.
//!
//! The value is typed on decoding with the stream's declared type, so a `vec2` comes back as a
//! `vec2`, and a value that does not fit (or NaN where a number is needed) is an error, not a
//! panic.

use kpl_core::{Time, Value, ValueType};
use kpl_runtime::Sample;
use serde::ser::{SerializeMap, SerializeSeq};

/// The first bytes of every message.
pub const MAGIC: &[u8; 3] = b"KPL";
/// The format version this crate writes and reads.
pub const VERSION: u8 = 1;
/// The kind byte of a sample.
pub const KIND_SAMPLE: u8 = b'S';
/// The kind byte of an end of stream.
pub const KIND_END: u8 = b'E';
/// Bytes before a sample's JSON value.
pub const SAMPLE_HEADER_LEN: usize = 21;
/// The length of an end-of-stream message.
pub const END_LEN: usize = 13;

/// A decoded message.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    Sample(Sample),
    /// The producer ended the stream after publishing this many samples.
    End {
        published: u64,
    },
}

/// Why bytes do not decode.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("{0} bytes is too short for a KPL message")]
    TooShort(usize),
    #[error("not a KPL message (it starts with {0:02x?}, not \"KPL\")")]
    Magic([u8; 3]),
    #[error("format version {0} is not one this kpl reads (version {VERSION})")]
    Version(u8),
    #[error("unknown message kind 0x{0:02x}")]
    Kind(u8),
    #[error("an end-of-stream message is {END_LEN} bytes, this one is {0}")]
    EndLength(usize),
    #[error("the value is not JSON: {0}")]
    Json(String),
    #[error("the value {0}")]
    Type(String),
}

/// Why a value cannot be encoded (it cannot happen for values built by KPL; kept for honesty).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("cannot encode the value as JSON: {0}")]
pub struct EncodeError(String);

/// Encodes a sample into `out` (cleared first).
pub fn encode_sample(sample: &Sample, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    out.clear();
    header(out, KIND_SAMPLE);
    out.extend_from_slice(&sample.valid.to_le_bytes());
    out.extend_from_slice(&sample.available.to_le_bytes());
    serde_json::to_writer(&mut *out, &JsonValue(&sample.value)).map_err(|e| EncodeError(e.to_string()))
}

/// Encodes the end of a stream on which `published` samples were sent.
pub fn encode_end(published: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(END_LEN);
    header(&mut out, KIND_END);
    out.extend_from_slice(&published.to_le_bytes());
    out
}

fn header(out: &mut Vec<u8>, kind: u8) {
    out.extend_from_slice(MAGIC);
    out.push(VERSION);
    out.push(kind);
}

/// Decodes one message; the value is decoded following `ty` (`ValueType::Any`: by its JSON shape).
pub fn decode(bytes: &[u8], ty: &ValueType) -> Result<Message, DecodeError> {
    if bytes.len() < 5 {
        return Err(DecodeError::TooShort(bytes.len()));
    }
    if &bytes[..3] != MAGIC {
        return Err(DecodeError::Magic([bytes[0], bytes[1], bytes[2]]));
    }
    if bytes[3] != VERSION {
        return Err(DecodeError::Version(bytes[3]));
    }
    match bytes[4] {
        KIND_SAMPLE => {
            if bytes.len() < SAMPLE_HEADER_LEN {
                return Err(DecodeError::TooShort(bytes.len()));
            }
            let valid = read_i64(bytes, 5);
            let available = read_i64(bytes, 13);
            let json: serde_json::Value = serde_json::from_slice(&bytes[SAMPLE_HEADER_LEN..])
                .map_err(|e| DecodeError::Json(e.to_string()))?;
            let value = Value::from_json(&json, ty).map_err(|e| DecodeError::Type(e.to_string()))?;
            Ok(Message::Sample(Sample::new(valid, available, value)))
        }
        KIND_END => {
            if bytes.len() != END_LEN {
                return Err(DecodeError::EndLength(bytes.len()));
            }
            Ok(Message::End { published: read_i64(bytes, 5) as u64 })
        }
        other => Err(DecodeError::Kind(other)),
    }
}

fn read_i64(bytes: &[u8], at: usize) -> Time {
    let mut word = [0u8; 8];
    word.copy_from_slice(&bytes[at..at + 8]);
    i64::from_le_bytes(word)
}

/// Serializes a value as `Value::to_json` does, without building a `serde_json::Value` first.
struct JsonValue<'a>(&'a Value);

impl serde::Serialize for JsonValue<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            Value::Bool(b) => s.serialize_bool(*b),
            Value::Int(i) | Value::Duration(i) => s.serialize_i64(*i),
            Value::Float(x) => finite(*x, s),
            Value::Str(text) => s.serialize_str(text),
            Value::Vec2(xy) => {
                let mut seq = s.serialize_seq(Some(2))?;
                for x in xy {
                    seq.serialize_element(&Finite(*x))?;
                }
                seq.end()
            }
            Value::BBox(b) => {
                let mut seq = s.serialize_seq(Some(4))?;
                for x in [b.x1, b.y1, b.x2, b.y2] {
                    seq.serialize_element(&Finite(x))?;
                }
                seq.end()
            }
            Value::List(items) => {
                let mut seq = s.serialize_seq(Some(items.len()))?;
                for item in items.iter() {
                    seq.serialize_element(&JsonValue(item))?;
                }
                seq.end()
            }
            Value::Record(record) => {
                let mut map = s.serialize_map(None)?;
                if let Some(id) = &record.id {
                    map.serialize_entry("id", &**id)?;
                }
                for (name, value) in &record.fields {
                    map.serialize_entry(&**name, &JsonValue(value))?;
                }
                map.end()
            }
        }
    }
}

/// A float as `Value::to_json` writes it: `null` when it is not finite.
struct Finite(f64);

impl serde::Serialize for Finite {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        finite(self.0, s)
    }
}

fn finite<S: serde::Serializer>(x: f64, s: S) -> Result<S::Ok, S::Error> {
    if x.is_finite() { s.serialize_f64(x) } else { s.serialize_unit() }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use std::sync::Arc;

    use kpl_core::{BBox, Record};
    use proptest::prelude::*;

    use super::*;

    fn encode(sample: &Sample) -> Vec<u8> {
        let mut out = Vec::new();
        encode_sample(sample, &mut out).unwrap();
        out
    }

    #[test]
    fn the_documented_layout() {
        let bytes = encode(&Sample::new(100, -7, Value::vec2(1.5, -2.0)));
        assert_eq!(&bytes[..5], b"KPL\x01S");
        assert_eq!(&bytes[5..13], &100i64.to_le_bytes());
        assert_eq!(&bytes[13..21], &(-7i64).to_le_bytes());
        assert_eq!(&bytes[21..], b"[1.5,-2.0]");
        assert_eq!(encode_end(3), b"KPL\x01E\x03\0\0\0\0\0\0\0");
        assert_eq!(decode(&encode_end(3), &ValueType::Any), Ok(Message::End { published: 3 }));
    }

    #[test]
    fn malformed_bytes_say_what_is_wrong() {
        let good = encode(&Sample::new(1, 2, Value::Float(0.5)));
        let cases: Vec<(Vec<u8>, DecodeError)> = vec![
            (vec![], DecodeError::TooShort(0)),
            (b"KPL\x01".to_vec(), DecodeError::TooShort(4)),
            (b"{\"valid\": 1}".to_vec(), DecodeError::Magic(*b"{\"v")),
            (b"KPL\x02S".to_vec(), DecodeError::Version(2)),
            (b"KPL\x01X".to_vec(), DecodeError::Kind(b'X')),
            (good[..20].to_vec(), DecodeError::TooShort(20)),
            (b"KPL\x01E\x01".to_vec(), DecodeError::EndLength(6)),
        ];
        for (bytes, expected) in cases {
            assert_eq!(decode(&bytes, &ValueType::Float), Err(expected), "{bytes:?}");
        }
        let mut not_json = good[..21].to_vec();
        not_json.extend_from_slice(b"[1,");
        assert!(matches!(decode(&not_json, &ValueType::Float), Err(DecodeError::Json(_))));
        let mut nan = good[..21].to_vec();
        nan.extend_from_slice(b"\"NaN\"");
        let err = decode(&nan, &ValueType::Float).unwrap_err();
        assert!(err.to_string().contains("finite number"), "{err}");
        let wrong_type = decode(&good, &ValueType::Str).unwrap_err();
        assert!(matches!(wrong_type, DecodeError::Type(_)), "{wrong_type}");
    }

    #[test]
    fn records_and_objects_round_trip_with_their_type() {
        let ty = ValueType::Record(Arc::new(kpl_core::RecordType {
            name: "Car".into(),
            parent: None,
            symbol: "co".into(),
            fields: vec![
                kpl_core::FieldType { name: "pos".into(), ty: ValueType::Vec2 },
                kpl_core::FieldType { name: "box".into(), ty: ValueType::BBox },
                kpl_core::FieldType { name: "age".into(), ty: ValueType::Duration },
            ],
        }));
        let car = Value::Record(Arc::new(Record {
            id: Some("co1".into()),
            fields: vec![
                ("pos".into(), Value::vec2(1.0, 2.0)),
                ("box".into(), Value::BBox(BBox::new(0.0, 1.0, 2.0, 3.5))),
                ("age".into(), Value::Duration(1_500_000)),
            ],
        }));
        let list = ValueType::List(Box::new(ty));
        let sample = Sample::new(10, 20, Value::List(vec![car.clone(), car].into()));
        assert_eq!(decode(&encode(&sample), &list), Ok(Message::Sample(sample)));
    }

    fn value() -> impl Strategy<Value = Value> {
        let leaf = prop_oneof![
            any::<bool>().prop_map(Value::Bool),
            any::<i64>().prop_map(Value::Int),
            (-1e300f64..1e300).prop_map(Value::Float),
            "\\PC{0,12}".prop_map(|s| Value::str(&s)),
            (-1e6f64..1e6, -1e6f64..1e6).prop_map(|(x, y)| Value::vec2(x, y)),
            any::<i64>().prop_map(Value::Duration),
        ];
        leaf.prop_recursive(3, 24, 4, |inner| {
            prop_oneof![
                prop::collection::vec(inner.clone(), 0..4).prop_map(|v| Value::List(v.into())),
                (proptest::option::of("[a-z]{1,3}"), prop::collection::vec(("[a-z]{1,4}", inner), 0..4))
                    .prop_map(|(id, fields)| {
                        let mut seen = std::collections::BTreeSet::new();
                        let fields = fields
                            .into_iter()
                            .filter(|(n, _)| n != "id" && seen.insert(n.clone()))
                            .map(|(n, v)| (Arc::from(n.as_str()), v))
                            .collect();
                        Value::Record(Arc::new(Record { id: id.map(|s| Arc::from(s.as_str())), fields }))
                    }),
            ]
        })
    }

    proptest! {
        /// The value part is the JSON of the files (kpl-core's `to_json`), and decoding it as
        /// the files do gives the same sample back.
        #[test]
        fn the_value_is_the_json_of_the_files(valid: i64, available: i64, value in value()) {
            let sample = Sample::new(valid, available, value);
            let bytes = encode(&sample);
            let json: serde_json::Value = serde_json::from_slice(&bytes[SAMPLE_HEADER_LEN..]).unwrap();
            prop_assert_eq!(&json, &sample.value.to_json());
            let expected = Value::from_json(&sample.value.to_json(), &ValueType::Any).unwrap();
            prop_assert_eq!(
                decode(&bytes, &ValueType::Any),
                Ok(Message::Sample(Sample::new(valid, available, expected)))
            );
        }

        /// No byte string makes decoding panic.
        #[test]
        fn arbitrary_bytes_never_panic(mut bytes in prop::collection::vec(any::<u8>(), 0..64), header in any::<bool>()) {
            if header && bytes.len() >= 5 {
                bytes[..5].copy_from_slice(b"KPL\x01S");
            }
            let _ = decode(&bytes, &ValueType::Any);
        }
    }
}
