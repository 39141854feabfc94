//! The wire format of samples between hosts: [`encode_sample`], [`encode_end`] and [`decode`]
//! are the only functions that write or read it (docs/streams.md, "On the wire").
//!
//! Every message starts with a 5-byte header, then the body of its kind; numbers are
//! little-endian:
//!
//! | bytes | field |
//! |---|---|
//! | 0..3 | magic `KPL` |
//! | 3 | format version: 2 (1 is read too: it has no packed float lists) |
//! | 4 | kind: `S` (0x53) a sample, `E` (0x45) the end of the stream |
//!
//! A sample (`S`) goes on with its valid time (i64, bytes 5..13), its available time (i64, bytes
//! 13..21), integer microseconds, and its value (bytes 21..). The end (`E`) goes on with the
//! number of samples the producer published on the stream (u64, bytes 5..13), so a subscriber can
//! tell whether it missed any.
//!
//! A value is self-describing: one tag byte, then its body.
//!
//! | tag | value | body |
//! |---|---|---|
//! | `t`, `f` | true, false | nothing |
//! | `i` | int | i64 |
//! | `d` | duration | i64 microseconds |
//! | `r` | float | f64 |
//! | `s` | string | u32 length, UTF-8 bytes |
//! | `v` | vec2 | 2 f64: x, y |
//! | `b` | box | 4 f64: x1, y1, x2, y2 |
//! | `l` | list | u32 count, the values |
//! | `F` | list of floats, packed (written for a non-empty list whose items are all floats) | u32 count, the f64s |
//! | `o` | record (object) | u32 count, then per attribute its name (u32 length, UTF-8) and value; an object's identity is the attribute `id`, a string, first |
//!
//! Numbers travel as their bits, so a float arrives exactly as it left and costs no printing or
//! parsing. On decoding, the value is checked against the stream's declared type as the JSON-lines
//! files are ([`kpl_core::Value::from_json`]): ints widen to floats and durations, a list of two
//! (four) numbers is a `vec2` (`box`) where one is declared, attributes a record type does not
//! have are dropped (except the object status attributes, `kpl_core::OBJECT_STATUS`), and a value
//! that does not fit (NaN where a number is needed, a missing attribute, bytes cut short, nesting
//! deeper than [`MAX_DEPTH`]) is an error, never a panic.

use std::sync::Arc;

use kpl_core::{BBox, Record, RecordType, Time, Value, ValueType};
use kpl_runtime::Sample;

/// The first bytes of every message.
pub const MAGIC: &[u8; 3] = b"KPL";
/// The format version this crate writes. Version 2 added packed float lists (tag `F`); version 1
/// messages (without them) are still read.
pub const VERSION: u8 = 2;
/// The oldest format version this crate reads.
pub const OLDEST_VERSION: u8 = 1;
/// The kind byte of a sample.
pub const KIND_SAMPLE: u8 = b'S';
/// The kind byte of an end of stream.
pub const KIND_END: u8 = b'E';
/// Bytes before a sample's value.
pub const SAMPLE_HEADER_LEN: usize = 21;
/// The length of an end-of-stream message.
pub const END_LEN: usize = 13;
/// How deep lists and records may nest in a value.
pub const MAX_DEPTH: usize = 128;

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
    #[error("format version {0} is not one this kpl reads (versions {OLDEST_VERSION} to {VERSION})")]
    Version(u8),
    #[error("unknown message kind 0x{0:02x}")]
    Kind(u8),
    #[error("an end-of-stream message is {END_LEN} bytes, this one is {0}")]
    EndLength(usize),
    /// The value's bytes are not a value.
    #[error("the value {0}")]
    Value(String),
    /// The value does not fit the stream's type.
    #[error("the value {0}")]
    Type(String),
}

/// Why a value cannot be encoded: a string or list longer than 4 GiB.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("cannot encode the value: {0}")]
pub struct EncodeError(String);

/// Encodes a sample into `out` (cleared first).
pub fn encode_sample(sample: &Sample, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    out.clear();
    header(out, KIND_SAMPLE);
    out.extend_from_slice(&sample.valid.to_le_bytes());
    out.extend_from_slice(&sample.available.to_le_bytes());
    write_value(&sample.value, out)
}

/// Encodes the end of a stream on which `published` samples were sent.
pub fn encode_end(published: u64) -> Vec<u8> {
    let mut out = Vec::with_capacity(END_LEN);
    header(&mut out, KIND_END);
    out.extend_from_slice(&published.to_le_bytes());
    out
}

/// Whether `payload` is an end message (by its header alone, without decoding it).
pub fn is_end(payload: &[u8]) -> bool {
    payload.len() == END_LEN
        && payload.starts_with(MAGIC)
        && matches!(payload[3], 1 | 2)
        && payload[4] == KIND_END
}

fn header(out: &mut Vec<u8>, kind: u8) {
    out.extend_from_slice(MAGIC);
    out.push(VERSION);
    out.push(kind);
}

/// Decodes one message; the value is checked against `ty` (`ValueType::Any`: taken as it is).
pub fn decode(bytes: &[u8], ty: &ValueType) -> Result<Message, DecodeError> {
    if bytes.len() < 5 {
        return Err(DecodeError::TooShort(bytes.len()));
    }
    if &bytes[..3] != MAGIC {
        return Err(DecodeError::Magic([bytes[0], bytes[1], bytes[2]]));
    }
    if !(OLDEST_VERSION..=VERSION).contains(&bytes[3]) {
        return Err(DecodeError::Version(bytes[3]));
    }
    match bytes[4] {
        KIND_SAMPLE => {
            if bytes.len() < SAMPLE_HEADER_LEN {
                return Err(DecodeError::TooShort(bytes.len()));
            }
            let mut reader = Reader { bytes, at: SAMPLE_HEADER_LEN };
            let value = reader.value(0).map_err(DecodeError::Value)?;
            if reader.at != bytes.len() {
                return Err(DecodeError::Value(format!(
                    "ends at byte {}, but the message has {}",
                    reader.at,
                    bytes.len()
                )));
            }
            let value = conform(value, ty).map_err(|e| DecodeError::Type(e.to_string()))?;
            Ok(Message::Sample(Sample::new(read_i64(bytes, 5), read_i64(bytes, 13), value)))
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

fn write_value(value: &Value, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    match value {
        Value::Bool(true) => out.push(b't'),
        Value::Bool(false) => out.push(b'f'),
        Value::Int(i) => {
            out.push(b'i');
            out.extend_from_slice(&i.to_le_bytes());
        }
        Value::Duration(us) => {
            out.push(b'd');
            out.extend_from_slice(&us.to_le_bytes());
        }
        Value::Float(x) => {
            out.push(b'r');
            out.extend_from_slice(&x.to_le_bytes());
        }
        Value::Str(text) => {
            out.push(b's');
            write_text(text, out)?;
        }
        Value::Vec2([x, y]) => {
            out.push(b'v');
            for z in [x, y] {
                out.extend_from_slice(&z.to_le_bytes());
            }
        }
        Value::BBox(b) => {
            out.push(b'b');
            for z in [b.x1, b.y1, b.x2, b.y2] {
                out.extend_from_slice(&z.to_le_bytes());
            }
        }
        Value::List(items) if !items.is_empty() && items.iter().all(|x| matches!(x, Value::Float(_))) => {
            // Packed: numbers dominate KPL's streams, and a list of them decodes in one pass.
            out.push(b'F');
            write_count(items.len(), out)?;
            out.reserve(8 * items.len());
            for item in items.iter() {
                if let Value::Float(x) = item {
                    out.extend_from_slice(&x.to_le_bytes());
                }
            }
        }
        Value::List(items) => {
            out.push(b'l');
            write_count(items.len(), out)?;
            for item in items.iter() {
                write_value(item, out)?;
            }
        }
        Value::Record(record) => {
            out.push(b'o');
            write_count(record.fields.len() + usize::from(record.id.is_some()), out)?;
            if let Some(id) = &record.id {
                write_text("id", out)?;
                out.push(b's');
                write_text(id, out)?;
            }
            for (name, value) in &record.fields {
                write_text(name, out)?;
                write_value(value, out)?;
            }
        }
    }
    Ok(())
}

fn write_count(n: usize, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    let n = u32::try_from(n).map_err(|_| EncodeError(format!("{n} items do not fit a u32 count")))?;
    out.extend_from_slice(&n.to_le_bytes());
    Ok(())
}

fn write_text(text: &str, out: &mut Vec<u8>) -> Result<(), EncodeError> {
    write_count(text.len(), out)?;
    out.extend_from_slice(text.as_bytes());
    Ok(())
}

/// Reads a value as it was written: no type yet, numbers as their bits.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        match self.at.checked_add(n) {
            Some(end) if end <= self.bytes.len() => {
                let slice = &self.bytes[self.at..end];
                self.at = end;
                Ok(slice)
            }
            _ => Err(format!("is cut short: {n} more byte(s) needed at byte {}", self.at)),
        }
    }

    fn word(&mut self) -> Result<[u8; 8], String> {
        let mut word = [0u8; 8];
        word.copy_from_slice(self.take(8)?);
        Ok(word)
    }

    fn float(&mut self) -> Result<f64, String> {
        let at = self.at;
        let x = f64::from_le_bytes(self.word()?);
        if x.is_finite() { Ok(x) } else { Err(format!("has a float that is not finite ({x}) at byte {at}")) }
    }

    /// A packed list of floats: the count, then the numbers. Checked first, then built in one
    /// allocation of exactly its size.
    fn floats(&mut self) -> Result<Value, String> {
        let n = self.count()?;
        let at = self.at;
        let bytes = self.take(n.checked_mul(8).ok_or_else(|| format!("has {n} floats at byte {at}"))?)?;
        let words = bytes.chunks_exact(8).map(|c| {
            let mut word = [0u8; 8];
            word.copy_from_slice(c);
            f64::from_le_bytes(word)
        });
        if let Some(i) = words.clone().position(|x| !x.is_finite()) {
            return Err(format!("has a float that is not finite at byte {}", at + 8 * i));
        }
        Ok(Value::List(words.map(Value::Float).collect()))
    }

    fn count(&mut self) -> Result<usize, String> {
        let mut word = [0u8; 4];
        word.copy_from_slice(self.take(4)?);
        Ok(u32::from_le_bytes(word) as usize)
    }

    fn text(&mut self) -> Result<&'a str, String> {
        let n = self.count()?;
        let at = self.at;
        std::str::from_utf8(self.take(n)?).map_err(|_| format!("has text that is not UTF-8 at byte {at}"))
    }

    fn value(&mut self, depth: usize) -> Result<Value, String> {
        if depth > MAX_DEPTH {
            return Err(format!("nests deeper than {MAX_DEPTH} lists or records"));
        }
        let at = self.at;
        let tag = self.take(1)?[0];
        Ok(match tag {
            b't' => Value::Bool(true),
            b'f' => Value::Bool(false),
            b'i' => Value::Int(i64::from_le_bytes(self.word()?)),
            b'd' => Value::Duration(i64::from_le_bytes(self.word()?)),
            b'r' => Value::Float(self.float()?),
            b's' => Value::str(self.text()?),
            b'v' => Value::Vec2([self.float()?, self.float()?]),
            b'b' => Value::bbox(BBox::new(self.float()?, self.float()?, self.float()?, self.float()?)),
            b'F' => self.floats()?,
            b'l' => {
                let n = self.count()?;
                // Every item takes at least a byte: a count cannot make us reserve more than that.
                let mut items = Vec::with_capacity(n.min(self.bytes.len() - self.at));
                for _ in 0..n {
                    // Lists of numbers are common: read floats without recursing.
                    if self.bytes.get(self.at) == Some(&b'r') {
                        self.at += 1;
                        items.push(Value::Float(self.float()?));
                    } else {
                        items.push(self.value(depth + 1)?);
                    }
                }
                Value::List(items.into())
            }
            b'o' => {
                let n = self.count()?;
                let mut record = Record::default();
                for _ in 0..n {
                    let name = self.text()?;
                    let value = self.value(depth + 1)?;
                    match (name, value) {
                        ("id", Value::Str(id)) => record.id = Some(id),
                        (name, value) => match record.fields.iter_mut().find(|(n, _)| &**n == name) {
                            Some(slot) => slot.1 = value,
                            None => record.fields.push((Arc::from(name), value)),
                        },
                    }
                }
                Value::Record(Arc::new(record))
            }
            other => return Err(format!("has an unknown tag 0x{other:02x} at byte {at}")),
        })
    }
}

/// Why a value does not fit a type: where (`.pos[1]`), what was expected and what was found.
#[derive(Debug, Clone, PartialEq, Eq)]
struct Mismatch {
    /// Path segments, innermost last once complete (collected while unwinding).
    path: Vec<String>,
    expected: String,
    found: String,
}

impl std::fmt::Display for Mismatch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let path: String = self.path.iter().rev().map(String::as_str).collect();
        let path = if path.is_empty() { ".".to_string() } else { path };
        write!(f, "at `{path}`: expected {}, found {}", self.expected, self.found)
    }
}

fn mismatch(expected: impl Into<String>, found: &Value) -> Mismatch {
    Mismatch { path: Vec::new(), expected: expected.into(), found: describe(found) }
}

fn describe(value: &Value) -> String {
    match value {
        Value::Bool(_) => "a boolean".into(),
        Value::Int(_) => "an integer".into(),
        Value::Float(_) => "a float".into(),
        Value::Duration(_) => "a duration".into(),
        Value::Str(s) if s.len() <= 16 => format!("the string {s:?}"),
        Value::Str(_) => "a string".into(),
        Value::Vec2(_) => "a vec2".into(),
        Value::BBox(_) => "a box".into(),
        Value::List(items) => format!("a list of {}", items.len()),
        Value::Record(_) => "an object".into(),
    }
}

fn within(mut e: Mismatch, segment: String) -> Mismatch {
    e.path.push(segment);
    e
}

/// A number as a float (ints widen).
fn number(value: &Value) -> Option<f64> {
    match value {
        Value::Float(x) => Some(*x),
        Value::Int(i) | Value::Duration(i) => Some(*i as f64),
        _ => None,
    }
}

/// `N` numbers from a vec2, a box or a list of numbers.
fn numbers<const N: usize>(value: &Value, shape: &str) -> Result<[f64; N], Mismatch> {
    let expected = || format!("{shape} with finite numbers");
    let list: Vec<f64> = match value {
        Value::Vec2(xy) => xy.to_vec(),
        Value::BBox(b) => vec![b.x1, b.y1, b.x2, b.y2],
        Value::List(items) => items
            .iter()
            .map(number)
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| mismatch(expected(), value))?,
        _ => return Err(mismatch(expected(), value)),
    };
    <[f64; N]>::try_from(list).map_err(|_| mismatch(expected(), value))
}

/// Whether a value already has exactly the declared shape (what a KPL producer sends), so that
/// [`conform`] can keep it as it is.
fn fits(value: &Value, ty: &ValueType) -> bool {
    match (ty, value) {
        (ValueType::Any, _)
        | (ValueType::Bool, Value::Bool(_))
        | (ValueType::Int, Value::Int(_))
        | (ValueType::Duration, Value::Duration(_))
        | (ValueType::Float, Value::Float(_))
        | (ValueType::Str, Value::Str(_))
        | (ValueType::Vec2, Value::Vec2(_))
        | (ValueType::BBox, Value::BBox(_)) => true,
        // Lists of floats are the bulk of numeric streams: a tight loop instead of a call each.
        (ValueType::List(item), Value::List(items)) if **item == ValueType::Float => {
            items.iter().all(|x| matches!(x, Value::Float(_)))
        }
        (ValueType::List(item), Value::List(items)) => items.iter().all(|x| fits(x, item)),
        (ValueType::Record(record), Value::Record(value)) => {
            value.fields.len() == record.fields.len()
                && value
                    .fields
                    .iter()
                    .zip(&record.fields)
                    .all(|((name, x), field)| **name == *field.name && &**name != "id" && fits(x, &field.ty))
        }
        _ => false,
    }
}

/// The value as the type declares it (as `Value::from_json` would read its JSON).
fn conform(value: Value, ty: &ValueType) -> Result<Value, Mismatch> {
    if fits(&value, ty) {
        return Ok(value);
    }
    Ok(match (ty, value) {
        (ValueType::Any, value) => value,
        (ValueType::Bool, value @ Value::Bool(_)) => value,
        (ValueType::Int, Value::Int(i) | Value::Duration(i)) => Value::Int(i),
        (ValueType::Duration, Value::Int(i) | Value::Duration(i)) => Value::Duration(i),
        (ValueType::Float, Value::Float(x)) => Value::Float(x),
        (ValueType::Float, Value::Int(i) | Value::Duration(i)) => Value::Float(i as f64),
        (ValueType::Str, value @ Value::Str(_)) => value,
        (ValueType::Vec2, value) => Value::Vec2(numbers::<2>(&value, "[x, y]")?),
        (ValueType::BBox, value) => {
            let [x1, y1, x2, y2] = numbers::<4>(&value, "[x1, y1, x2, y2]")?;
            Value::bbox(BBox { x1, y1, x2, y2 })
        }
        (ValueType::List(item), value) => {
            let items: Vec<Value> = match value {
                Value::List(items) => items.iter().cloned().collect(),
                Value::Vec2(xy) => xy.iter().map(|x| Value::Float(*x)).collect(),
                Value::BBox(b) => [b.x1, b.y1, b.x2, b.y2].into_iter().map(Value::Float).collect(),
                other => return Err(mismatch("an array", &other)),
            };
            let mut out = Vec::with_capacity(items.len());
            for (i, x) in items.into_iter().enumerate() {
                out.push(conform(x, item).map_err(|e| within(e, format!("[{i}]")))?);
            }
            Value::List(out.into())
        }
        (ValueType::Record(record), Value::Record(value)) => conform_record(&value, record)?,
        (ValueType::Record(record), other) => {
            return Err(mismatch(format!("an object of type {}", record.name), &other));
        }
        (ValueType::Bool, other) => return Err(mismatch("a boolean", &other)),
        (ValueType::Int, other) => return Err(mismatch("an integer", &other)),
        (ValueType::Duration, other) => return Err(mismatch("an integer number of microseconds", &other)),
        (ValueType::Float, other) => return Err(mismatch("a finite number", &other)),
        (ValueType::Str, other) => return Err(mismatch("a string", &other)),
    })
}

fn conform_record(value: &Record, ty: &RecordType) -> Result<Value, Mismatch> {
    if let Some((_, id)) = value.fields.iter().find(|(n, _)| &**n == "id") {
        return Err(within(mismatch("a string", id), ".id".into()));
    }
    let mut fields = Vec::with_capacity(ty.fields.len());
    for field in &ty.fields {
        let segment = format!(".{}", field.name);
        let found = value.fields.iter().find(|(n, _)| **n == *field.name).map(|(_, v)| v.clone());
        let Some(found) = found else {
            return Err(Mismatch {
                path: vec![segment],
                expected: format!("field `{}` of type {}", field.name, field.ty),
                found: "nothing".into(),
            });
        };
        fields.push((field.name.clone(), conform(found, &field.ty).map_err(|e| within(e, segment))?));
    }
    // How anchoring knows the object's state travels with it (`kpl_core::OBJECT_STATUS`).
    for (name, status_ty) in &kpl_core::OBJECT_STATUS {
        if ty.field(name).is_some() {
            continue;
        }
        if let Some((_, found)) = value.fields.iter().find(|(n, _)| &**n == *name) {
            let status = conform(found.clone(), status_ty).map_err(|e| within(e, format!(".{name}")))?;
            fields.push((Arc::from(*name), status));
        }
    }
    Ok(Value::Record(Arc::new(Record { id: value.id.clone(), fields })))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use kpl_core::FieldType;
    use proptest::prelude::*;

    use super::*;

    fn encode(sample: &Sample) -> Vec<u8> {
        let mut out = Vec::new();
        encode_sample(sample, &mut out).unwrap();
        out
    }

    fn record_type(fields: &[(&str, ValueType)]) -> ValueType {
        ValueType::Record(Arc::new(RecordType {
            name: "Car".into(),
            parent: None,
            symbol: "co".into(),
            fields: fields.iter().map(|(n, t)| FieldType { name: (*n).into(), ty: t.clone() }).collect(),
        }))
    }

    #[test]
    fn the_documented_layout() {
        let bytes = encode(&Sample::new(100, -7, Value::vec2(1.5, -2.0)));
        assert_eq!(&bytes[..5], b"KPL\x02S");
        assert_eq!(&bytes[5..13], &100i64.to_le_bytes());
        assert_eq!(&bytes[13..21], &(-7i64).to_le_bytes());
        assert_eq!(bytes[21], b'v');
        assert_eq!(&bytes[22..30], &1.5f64.to_le_bytes());
        assert_eq!(&bytes[30..], &(-2.0f64).to_le_bytes());
        let record = Value::Record(Arc::new(Record {
            id: Some("co1".into()),
            fields: vec![("n".into(), Value::List(vec![Value::Int(3), Value::str("é")].into()))],
        }));
        let bytes = encode(&Sample::new(0, 0, record));
        let mut expected = b"o\x02\0\0\0\x02\0\0\0ids\x03\0\0\0co1\x01\0\0\0nl\x02\0\0\0i".to_vec();
        expected.extend_from_slice(&3i64.to_le_bytes());
        expected.extend_from_slice(b"s\x02\0\0\0\xc3\xa9");
        assert_eq!(&bytes[21..], &expected[..]);
        assert_eq!(encode_end(3), b"KPL\x02E\x03\0\0\0\0\0\0\0");
        assert_eq!(decode(&encode_end(3), &ValueType::Any), Ok(Message::End { published: 3 }));
    }

    #[test]
    fn float_lists_are_packed_and_version_1_lists_still_read() {
        let floats = Value::List(vec![Value::Float(1.5), Value::Float(-2.0)].into());
        let bytes = encode(&Sample::new(0, 0, floats.clone()));
        let mut expected = b"F\x02\0\0\0".to_vec();
        expected.extend_from_slice(&1.5f64.to_le_bytes());
        expected.extend_from_slice(&(-2.0f64).to_le_bytes());
        assert_eq!(&bytes[21..], &expected[..]);
        assert_eq!(decode(&bytes, &ValueType::Any), Ok(Message::Sample(Sample::new(0, 0, floats.clone()))));
        // Mixed or empty lists are not packed.
        let mixed = encode(&Sample::new(0, 0, Value::List(vec![Value::Float(1.0), Value::Int(2)].into())));
        assert_eq!(mixed[21], b'l');
        assert_eq!(encode(&Sample::new(0, 0, Value::List(Vec::new().into())))[21..], *b"l\0\0\0\0");
        // A version 1 message (what tests/zenoh_client.py's encoder sends) lists each float.
        let mut v1 = b"KPL\x01S".to_vec();
        v1.extend_from_slice(&[0; 16]);
        v1.extend_from_slice(b"l\x02\0\0\0r");
        v1.extend_from_slice(&1.5f64.to_le_bytes());
        v1.push(b'r');
        v1.extend_from_slice(&(-2.0f64).to_le_bytes());
        assert_eq!(
            decode(&v1, &ValueType::List(Box::new(ValueType::Float))),
            Ok(Message::Sample(Sample::new(0, 0, floats)))
        );
        // A NaN among packed floats, or a count past the end, is an error.
        let mut nan = bytes.clone();
        nan[34..42].copy_from_slice(&f64::NAN.to_le_bytes());
        assert!(
            matches!(decode(&nan, &ValueType::Any), Err(DecodeError::Value(e)) if e.contains("not finite at byte 34"))
        );
        let mut huge = bytes[..22].to_vec();
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(
            matches!(decode(&huge, &ValueType::Any), Err(DecodeError::Value(e)) if e.contains("cut short"))
        );
    }

    #[test]
    fn malformed_bytes_say_what_is_wrong() {
        let good = encode(&Sample::new(1, 2, Value::Float(0.5)));
        let cases: Vec<(Vec<u8>, DecodeError)> = vec![
            (vec![], DecodeError::TooShort(0)),
            (b"KPL\x01".to_vec(), DecodeError::TooShort(4)),
            (b"{\"valid\": 1}".to_vec(), DecodeError::Magic(*b"{\"v")),
            (b"KPL\x03S".to_vec(), DecodeError::Version(3)),
            (b"KPL\x00S".to_vec(), DecodeError::Version(0)),
            (b"KPL\x01X".to_vec(), DecodeError::Kind(b'X')),
            (good[..20].to_vec(), DecodeError::TooShort(20)),
            (b"KPL\x01E\x01".to_vec(), DecodeError::EndLength(6)),
        ];
        for (bytes, expected) in cases {
            assert_eq!(decode(&bytes, &ValueType::Float), Err(expected), "{bytes:?}");
        }
        let value_error = |body: &[u8]| {
            let mut bytes = good[..21].to_vec();
            bytes.extend_from_slice(body);
            match decode(&bytes, &ValueType::Any) {
                Err(DecodeError::Value(e)) => e,
                other => panic!("{body:?}: {other:?}"),
            }
        };
        assert!(value_error(b"").contains("cut short"));
        assert!(value_error(b"r\0\0").contains("cut short"));
        assert!(value_error(b"x").contains("unknown tag 0x78 at byte 21"));
        assert!(value_error(b"s\x02\0\0\0\xff\xfe").contains("not UTF-8"));
        assert!(value_error(b"l\xff\xff\xff\xff").contains("cut short"), "a huge count reserves nothing");
        assert!(value_error(b"tt").contains("ends at byte 22"));
        let mut nan = b"r".to_vec();
        nan.extend_from_slice(&f64::NAN.to_le_bytes());
        assert!(value_error(&nan).contains("not finite"));
        let deep: Vec<u8> =
            std::iter::repeat_n(&b"l\x01\0\0\0"[..], MAX_DEPTH + 2).flatten().copied().collect();
        assert!(value_error(&deep).contains("nests deeper"));
        let wrong_type = decode(&good, &ValueType::Str).unwrap_err();
        assert_eq!(wrong_type, DecodeError::Type("at `.`: expected a string, found a float".into()));
    }

    #[test]
    fn values_are_checked_against_the_declared_type() {
        let ty = record_type(&[
            ("pos", ValueType::Vec2),
            ("speed", ValueType::Float),
            ("age", ValueType::Duration),
        ]);
        let sent = Value::Record(Arc::new(Record {
            id: Some("co1".into()),
            fields: vec![
                ("extra".into(), Value::Bool(true)),
                ("speed".into(), Value::Int(3)),
                ("age".into(), Value::Int(5)),
                ("pos".into(), Value::List(vec![Value::Int(1), Value::Float(2.5)].into())),
                ("measured".into(), Value::Bool(false)),
                ("predicted_since".into(), Value::Int(400)),
            ],
        }));
        let got = decode(&encode(&Sample::new(1, 1, sent)), &ty).unwrap();
        // Attributes the type does not have are dropped, except how anchoring knows the state.
        let expected = Value::Record(Arc::new(Record {
            id: Some("co1".into()),
            fields: vec![
                ("pos".into(), Value::vec2(1.0, 2.5)),
                ("speed".into(), Value::Float(3.0)),
                ("age".into(), Value::Duration(5)),
                ("measured".into(), Value::Bool(false)),
                ("predicted_since".into(), Value::Int(400)),
            ],
        }));
        assert_eq!(got, Message::Sample(Sample::new(1, 1, expected)));
        let missing =
            Value::Record(Arc::new(Record { id: None, fields: vec![("pos".into(), Value::vec2(0.0, 0.0))] }));
        let err = decode(
            &encode(&Sample::new(1, 1, Value::List(vec![missing].into()))),
            &ValueType::List(Box::new(ty)),
        );
        assert_eq!(
            err,
            Err(DecodeError::Type(
                "at `[0].speed`: expected field `speed` of type float, found nothing".into()
            ))
        );
    }

    fn value() -> impl Strategy<Value = Value> {
        let leaf = prop_oneof![
            any::<bool>().prop_map(Value::Bool),
            any::<i64>().prop_map(Value::Int),
            (-1e300f64..1e300).prop_map(Value::Float),
            prop::collection::vec(any::<char>(), 0..12)
                .prop_map(|c| Value::str(&c.into_iter().collect::<String>())),
            (-1e6f64..1e6, -1e6f64..1e6).prop_map(|(x, y)| Value::vec2(x, y)),
            (-1e6f64..1e6, -1e6f64..1e6).prop_map(|(x, y)| Value::bbox(BBox::new(x, y, x + 1.0, y + 2.0))),
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

    fn value_type() -> impl Strategy<Value = ValueType> {
        let leaf = prop_oneof![
            Just(ValueType::Any),
            Just(ValueType::Bool),
            Just(ValueType::Int),
            Just(ValueType::Float),
            Just(ValueType::Str),
            Just(ValueType::Vec2),
            Just(ValueType::BBox),
            Just(ValueType::Duration),
        ];
        leaf.prop_recursive(2, 8, 3, |inner| {
            prop_oneof![
                inner.clone().prop_map(|t| ValueType::List(Box::new(t))),
                prop::collection::vec(("[a-c]", inner), 0..3).prop_map(|fields| {
                    let mut seen = std::collections::BTreeSet::new();
                    let fields: Vec<(String, ValueType)> =
                        fields.into_iter().filter(|(n, _)| seen.insert(n.clone())).collect();
                    let fields: Vec<(&str, ValueType)> =
                        fields.iter().map(|(n, t)| (n.as_str(), t.clone())).collect();
                    record_type(&fields)
                }),
            ]
        })
    }

    proptest! {
        /// Untyped, every value comes back exactly, with its times.
        #[test]
        fn values_round_trip_bit_for_bit(valid: i64, available: i64, value in value()) {
            let sample = Sample::new(valid, available, value);
            prop_assert_eq!(decode(&encode(&sample), &ValueType::Any), Ok(Message::Sample(sample)));
        }

        /// Typed, the wire agrees with the JSON-lines files: a value fits a type on the wire
        /// exactly when its JSON fits it in a file, and means the same (compared as JSON).
        #[test]
        fn typed_decoding_agrees_with_the_json_files(value in value(), ty in value_type()) {
            let wire = decode(&encode(&Sample::new(0, 0, value.clone())), &ty);
            let file = Value::from_json(&value.to_json(), &ty);
            match (wire, file) {
                (Ok(Message::Sample(s)), Ok(v)) => prop_assert_eq!(s.value.to_json(), v.to_json()),
                (Err(DecodeError::Type(_)), Err(_)) => {}
                (wire, file) => prop_assert!(false, "wire {:?}, file {:?}", wire, file),
            }
        }

        /// No byte string makes decoding panic.
        #[test]
        fn arbitrary_bytes_never_panic(mut bytes in prop::collection::vec(any::<u8>(), 0..64), header in any::<bool>()) {
            if header && bytes.len() >= 21 {
                bytes[..5].copy_from_slice(b"KPL\x02S");
            }
            let _ = decode(&bytes, &ValueType::Any);
        }
    }
}
