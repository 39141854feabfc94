//! A dynamic CDR codec driven by a [`Schema`]: ROS 2's serialization (XCDR1, as Fast-CDR and
//! rmw_zenoh write it) of any message type known at run time, with its 4-byte encapsulation
//! header, to and from a [`MsgValue`] tree.
//!
//! Layout: after the header (`00 01 00 00`, little endian; `00 00 00 00` big endian is read too),
//! each primitive is aligned to its size (up to 8) counted from the end of the header; a string is
//! a `uint32` length counting its terminating NUL, its UTF-8 bytes and the NUL; a sequence
//! (`T[]`, `T[<=N]`) is a `uint32` count and its elements; a fixed array (`T[N]`) has no count;
//! nested messages are their fields in order; an empty message is one `uint8`. Nothing pads the
//! end.
//!
//! The padding bytes carry nothing: kpl writes zeros, Fast-CDR (rclpy, rmw_zenoh) leaves whatever
//! its buffer held, so two encodings of one message are equal once their padding is zeroed
//! ([`canonical`]).
//!
//! Decoding never panics and never allocates more than the input can hold: a count larger than
//! the bytes left, a string without its NUL or not UTF-8, a bool other than 0 or 1, a bounded
//! sequence over its bound, or a truncated message is a [`CdrError`].
//!
//! ```
//! use kpl_ros2::cdr::{self, MsgValue};
//! let defs = kpl_ros2::Definitions::builtin();
//! let schema = defs.schema_of("geometry_msgs/msg/Point").unwrap();
//! let point = MsgValue::Struct(vec![MsgValue::Float(1.0), MsgValue::Float(2.0), MsgValue::Float(3.0)]);
//! let bytes = cdr::encode(&schema, &point).unwrap();
//! assert_eq!(bytes.len(), 4 + 24);
//! assert_eq!(cdr::decode(&schema, &bytes).unwrap(), point);
//! ```

use crate::definitions::{Schema, SchemaBase, SchemaField};
use crate::msg::{ArrayKind, Primitive};

/// A message's value: fields of a struct in definition order.
#[derive(Debug, Clone, PartialEq)]
pub enum MsgValue {
    Bool(bool),
    /// `int8` .. `int64`.
    Int(i64),
    /// `uint8` .. `uint64`, `byte`, `char`.
    UInt(u64),
    /// `float32` (held exactly) or `float64`.
    Float(f64),
    Str(String),
    /// A `uint8`, `byte` or `char` array or sequence.
    Bytes(Vec<u8>),
    /// Any other array or sequence.
    List(Vec<MsgValue>),
    Struct(Vec<MsgValue>),
}

impl MsgValue {
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            MsgValue::Float(x) => Some(x),
            MsgValue::Int(i) => Some(i as f64),
            MsgValue::UInt(u) => Some(u as f64),
            _ => None,
        }
    }

    pub fn fields(&self) -> &[MsgValue] {
        match self {
            MsgValue::Struct(fields) => fields,
            _ => &[],
        }
    }
}

/// What is wrong with a CDR message (decoding) or a value (encoding).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CdrError {
    #[error("the message is shorter than its encapsulation header")]
    NoHeader,
    #[error("unknown encapsulation `{0:02x}{1:02x}` (CDR little or big endian expected)")]
    Encapsulation(u8, u8),
    #[error("at `{path}` (byte {offset}): {message}")]
    Malformed { path: String, offset: usize, message: String },
    #[error("at `{path}`: {message}")]
    Value { path: String, message: String },
}

const HEADER_LE: [u8; 4] = [0, 1, 0, 0];

/// Encodes a value of the schema's type, with the little-endian encapsulation header.
pub fn encode(schema: &Schema, value: &MsgValue) -> Result<Vec<u8>, CdrError> {
    let mut out = Vec::with_capacity(64);
    encode_into(schema, value, &mut out)?;
    Ok(out)
}

/// As [`encode`], appending to `out` (cleared first).
pub fn encode_into(schema: &Schema, value: &MsgValue, out: &mut Vec<u8>) -> Result<(), CdrError> {
    out.clear();
    out.extend_from_slice(&HEADER_LE);
    let mut w = Writer { out, path: Vec::new() };
    w.write_struct(schema, schema.root_index(), value)
}

/// Decodes a message with its encapsulation header.
pub fn decode(schema: &Schema, bytes: &[u8]) -> Result<MsgValue, CdrError> {
    Reader::after_header(bytes, None)?.read_struct(schema, schema.root_index())
}

/// The message with its padding bytes zeroed (and the decoded value), so that encodings by
/// different writers compare byte for byte.
pub fn canonical(schema: &Schema, bytes: &[u8]) -> Result<(Vec<u8>, MsgValue), CdrError> {
    let (pads, value) = padding(schema, bytes)?;
    let mut out = bytes.to_vec();
    for (at, len) in pads {
        out[at..at + len].fill(0);
    }
    Ok((out, value))
}

/// Where a message's padding bytes are: (offset from the start, length), and the decoded value.
pub fn padding(schema: &Schema, bytes: &[u8]) -> Result<(Vec<(usize, usize)>, MsgValue), CdrError> {
    let mut r = Reader::after_header(bytes, Some(Vec::new()))?;
    let value = r.read_struct(schema, schema.root_index())?;
    let pads = r.pads.unwrap_or_default().into_iter().map(|(at, len)| (at + 4, len)).collect();
    Ok((pads, value))
}

struct Writer<'a> {
    out: &'a mut Vec<u8>,
    path: Vec<String>,
}

impl Writer<'_> {
    fn align(&mut self, n: usize) {
        let pos = self.out.len() - 4;
        let pad = (n - pos % n) % n;
        self.out.resize(self.out.len() + pad, 0);
    }

    fn error(&self, message: String) -> CdrError {
        CdrError::Value { path: self.path.join("."), message }
    }

    fn write_struct(&mut self, schema: &Schema, index: usize, value: &MsgValue) -> Result<(), CdrError> {
        let def = schema.get(index);
        let MsgValue::Struct(values) = value else {
            return Err(self.error(format!("expected a `{}` message", def.def.name)));
        };
        if def.fields.is_empty() {
            self.out.push(0);
            return Ok(());
        }
        if values.len() != def.fields.len() {
            return Err(self.error(format!(
                "`{}` has {} fields, the value {}",
                def.def.name,
                def.fields.len(),
                values.len()
            )));
        }
        for (field, value) in def.fields.iter().zip(values) {
            self.path.push(field.name.to_string());
            self.write_field(schema, field, value)?;
            self.path.pop();
        }
        Ok(())
    }

    fn write_field(
        &mut self,
        schema: &Schema,
        field: &SchemaField,
        value: &MsgValue,
    ) -> Result<(), CdrError> {
        match field.array {
            ArrayKind::Single => self.write_base(schema, field.base, value),
            ArrayKind::Fixed(n) => self.write_elements(schema, field.base, value, Some(n as usize), None),
            ArrayKind::Bounded(n) => self.write_elements(schema, field.base, value, None, Some(n as usize)),
            ArrayKind::Unbounded => self.write_elements(schema, field.base, value, None, None),
        }
    }

    fn write_elements(
        &mut self,
        schema: &Schema,
        base: SchemaBase,
        value: &MsgValue,
        fixed: Option<usize>,
        bound: Option<usize>,
    ) -> Result<(), CdrError> {
        let len = match value {
            MsgValue::Bytes(b) => b.len(),
            MsgValue::List(l) => l.len(),
            _ => return Err(self.error("expected an array".into())),
        };
        if let Some(n) = fixed
            && len != n
        {
            return Err(self.error(format!("expected {n} elements, found {len}")));
        }
        if let Some(n) = bound
            && len > n
        {
            return Err(self.error(format!("at most {n} elements, found {len}")));
        }
        if fixed.is_none() {
            self.align(4);
            self.out.extend_from_slice(&(len as u32).to_le_bytes());
        }
        match (value, base) {
            (MsgValue::Bytes(bytes), SchemaBase::Primitive(p)) if p.is_octet() => {
                self.out.extend_from_slice(bytes);
                Ok(())
            }
            (MsgValue::List(items), _) => {
                for item in items {
                    self.write_base(schema, base, item)?;
                }
                Ok(())
            }
            _ => Err(self.error("expected a list".into())),
        }
    }

    fn write_base(&mut self, schema: &Schema, base: SchemaBase, value: &MsgValue) -> Result<(), CdrError> {
        match base {
            SchemaBase::Struct(index) => self.write_struct(schema, index, value),
            SchemaBase::Primitive(p) => self.write_primitive(p, value),
        }
    }

    fn write_primitive(&mut self, p: Primitive, value: &MsgValue) -> Result<(), CdrError> {
        use Primitive::*;
        if let String(bound) = p {
            let MsgValue::Str(s) = value else {
                return Err(self.error("expected a string".into()));
            };
            if let Some(n) = bound
                && s.len() > n as usize
            {
                return Err(self.error(format!("at most {n} bytes, found {}", s.len())));
            }
            if s.contains('\0') {
                return Err(self.error("a string cannot contain NUL".into()));
            }
            self.align(4);
            self.out.extend_from_slice(&(s.len() as u32 + 1).to_le_bytes());
            self.out.extend_from_slice(s.as_bytes());
            self.out.push(0);
            return Ok(());
        }
        let size = p.size().unwrap_or(1);
        self.align(size);
        let out_of_range = |w: &Self| w.error(format!("{value:?} is not a {}", p.msg_name()));
        match (p, value) {
            (Bool, MsgValue::Bool(b)) => self.out.push(u8::from(*b)),
            (Float32, MsgValue::Float(x)) => self.out.extend_from_slice(&(*x as f32).to_le_bytes()),
            (Float64, MsgValue::Float(x)) => self.out.extend_from_slice(&x.to_le_bytes()),
            (Int8 | Int16 | Int32 | Int64, MsgValue::Int(i)) => {
                let bits = size as u32 * 8;
                if bits < 64 && (*i < -(1i64 << (bits - 1)) || *i >= 1i64 << (bits - 1)) {
                    return Err(out_of_range(self));
                }
                self.out.extend_from_slice(&i.to_le_bytes()[..size]);
            }
            (Byte | Char | UInt8 | UInt16 | UInt32 | UInt64, MsgValue::UInt(u)) => {
                let bits = size as u32 * 8;
                if bits < 64 && *u >= 1u64 << bits {
                    return Err(out_of_range(self));
                }
                self.out.extend_from_slice(&u.to_le_bytes()[..size]);
            }
            _ => return Err(out_of_range(self)),
        }
        Ok(())
    }
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    little: bool,
    path: Vec<&'a str>,
    /// Where the padding is (offset, length), when asked for.
    pads: Option<Vec<(usize, usize)>>,
}

impl<'a> Reader<'a> {
    /// A reader of the message after its encapsulation header (CDR, little or big endian).
    fn after_header(bytes: &'a [u8], pads: Option<Vec<(usize, usize)>>) -> Result<Reader<'a>, CdrError> {
        let little = match bytes {
            [0, 1, _, _, ..] => true,
            [0, 0, _, _, ..] => false,
            [a, b, _, _, ..] => return Err(CdrError::Encapsulation(*a, *b)),
            _ => return Err(CdrError::NoHeader),
        };
        Ok(Reader { data: &bytes[4..], pos: 0, little, path: Vec::new(), pads })
    }

    fn malformed(&self, message: impl Into<String>) -> CdrError {
        CdrError::Malformed { path: self.path.join("."), offset: self.pos + 4, message: message.into() }
    }

    fn align(&mut self, n: usize) -> Result<(), CdrError> {
        let pad = (n - self.pos % n) % n;
        if self.pos + pad > self.data.len() {
            return Err(self.malformed("the message ends early"));
        }
        if pad > 0
            && let Some(pads) = &mut self.pads
        {
            pads.push((self.pos, pad));
        }
        self.pos += pad;
        Ok(())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], CdrError> {
        if n > self.data.len() - self.pos {
            return Err(self.malformed("the message ends early"));
        }
        let bytes = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    fn fixed<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        self.align(N)?;
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N)?);
        if !self.little {
            out.reverse();
        }
        Ok(out)
    }

    fn read_u32(&mut self) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.fixed::<4>()?))
    }

    fn read_struct(&mut self, schema: &'a Schema, index: usize) -> Result<MsgValue, CdrError> {
        let def = schema.get(index);
        if def.fields.is_empty() {
            self.take(1)?;
            return Ok(MsgValue::Struct(Vec::new()));
        }
        let mut values = Vec::with_capacity(def.fields.len());
        for field in &def.fields {
            self.path.push(&field.name);
            values.push(self.read_field(schema, field)?);
            self.path.pop();
        }
        Ok(MsgValue::Struct(values))
    }

    fn read_field(&mut self, schema: &'a Schema, field: &'a SchemaField) -> Result<MsgValue, CdrError> {
        let count = match field.array {
            ArrayKind::Single => return self.read_base(schema, field.base),
            ArrayKind::Fixed(n) => n as usize,
            ArrayKind::Bounded(n) => {
                let count = self.read_u32()? as usize;
                if count > n as usize {
                    return Err(self.malformed(format!("{count} elements in a sequence of at most {n}")));
                }
                count
            }
            ArrayKind::Unbounded => self.read_u32()? as usize,
        };
        // Every element takes at least one byte: a count beyond what is left is malformed, and
        // nothing is allocated for it.
        if count > self.data.len() - self.pos {
            return Err(
                self.malformed(format!("{count} elements, but {} bytes left", self.data.len() - self.pos))
            );
        }
        if let SchemaBase::Primitive(p) = field.base
            && p.is_octet()
        {
            return Ok(MsgValue::Bytes(self.take(count)?.to_vec()));
        }
        let mut items = Vec::with_capacity(count);
        for _ in 0..count {
            items.push(self.read_base(schema, field.base)?);
        }
        Ok(MsgValue::List(items))
    }

    fn read_base(&mut self, schema: &'a Schema, base: SchemaBase) -> Result<MsgValue, CdrError> {
        use Primitive::*;
        let p = match base {
            SchemaBase::Struct(index) => return self.read_struct(schema, index),
            SchemaBase::Primitive(p) => p,
        };
        Ok(match p {
            Bool => match self.take(1)?[0] {
                0 => MsgValue::Bool(false),
                1 => MsgValue::Bool(true),
                b => return Err(self.malformed(format!("a bool of {b}"))),
            },
            Byte | Char | UInt8 => MsgValue::UInt(u64::from(self.take(1)?[0])),
            Int8 => MsgValue::Int(i64::from(self.take(1)?[0] as i8)),
            Int16 => MsgValue::Int(i64::from(i16::from_le_bytes(self.fixed()?))),
            UInt16 => MsgValue::UInt(u64::from(u16::from_le_bytes(self.fixed()?))),
            Int32 => MsgValue::Int(i64::from(i32::from_le_bytes(self.fixed()?))),
            UInt32 => MsgValue::UInt(u64::from(u32::from_le_bytes(self.fixed()?))),
            Int64 => MsgValue::Int(i64::from_le_bytes(self.fixed()?)),
            UInt64 => MsgValue::UInt(u64::from_le_bytes(self.fixed()?)),
            Float32 => MsgValue::Float(f64::from(f32::from_le_bytes(self.fixed()?))),
            Float64 => MsgValue::Float(f64::from_le_bytes(self.fixed()?)),
            String(bound) => {
                let len = self.read_u32()? as usize;
                if len == 0 {
                    return Err(self.malformed("a string of length 0 (without its NUL)"));
                }
                let bytes = self.take(len)?;
                let (text, nul) = bytes.split_at(len - 1);
                if nul != [0] {
                    return Err(self.malformed("a string without its terminating NUL"));
                }
                if text.contains(&0) {
                    return Err(self.malformed("a string with a NUL inside"));
                }
                if let Some(n) = bound
                    && text.len() > n as usize
                {
                    return Err(self.malformed(format!("a string of {} bytes, bounded to {n}", text.len())));
                }
                match std::str::from_utf8(text) {
                    Ok(s) => MsgValue::Str(s.to_string()),
                    Err(_) => return Err(self.malformed("a string that is not UTF-8")),
                }
            }
            WString(_) => return Err(self.malformed("wstring is not supported")),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Definitions;

    #[test]
    fn truncations_and_garbage_are_errors_not_panics() {
        let defs = Definitions::builtin();
        let schema = defs.schema_of("visualization_msgs/msg/MarkerArray").unwrap();
        let marker = defs.schema_of("visualization_msgs/msg/Marker").unwrap();
        let value = crate::json::default_value(&marker);
        let array = MsgValue::Struct(vec![MsgValue::List(vec![value.clone(), value])]);
        let bytes = encode(&schema, &array).unwrap();
        assert_eq!(decode(&schema, &bytes).unwrap(), array);
        for cut in 0..bytes.len() {
            assert!(decode(&schema, &bytes[..cut]).is_err(), "{cut}");
        }
        let mut huge = bytes.clone();
        huge[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(decode(&schema, &huge), Err(CdrError::Malformed { .. })));
        assert!(matches!(decode(&schema, &[7, 7, 0, 0, 0]), Err(CdrError::Encapsulation(7, 7))));
    }

    /// Random bytes and random mutations of a valid message, for the types with the most kinds of
    /// fields: decoding returns, and what decodes re-encodes (fuzz/fuzz_targets/ros2_wire.rs goes
    /// further).
    #[test]
    fn random_bytes_never_panic() {
        use rand::{Rng, SeedableRng};
        let defs = Definitions::builtin();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for name in
            ["visualization_msgs/msg/MarkerArray", "sensor_msgs/msg/PointCloud2", "nav_msgs/msg/Odometry"]
        {
            let schema = defs.schema_of(name).unwrap();
            let valid = encode(&schema, &crate::json::default_value(&schema)).unwrap();
            for _ in 0..5000 {
                let mut bytes = if rng.random_bool(0.5) {
                    let len = rng.random_range(0..200);
                    let mut b: Vec<u8> = (0..len).map(|_| rng.random()).collect();
                    if b.len() >= 2 {
                        b[0] = 0;
                        b[1] = 1;
                    }
                    b
                } else {
                    valid.clone()
                };
                for _ in 0..rng.random_range(0..4) {
                    if !bytes.is_empty() {
                        let i = rng.random_range(0..bytes.len());
                        bytes[i] = rng.random();
                    }
                }
                if let Ok(value) = decode(&schema, &bytes) {
                    let again = encode(&schema, &value).unwrap();
                    assert_eq!(decode(&schema, &again).unwrap(), value);
                }
            }
        }
    }
}
