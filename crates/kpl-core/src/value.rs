//! Dynamically typed values carried by samples, and the types that describe their shape.
//!
//! Values are cheap to clone: strings, lists and records sit behind `Arc`, so a sample fanned out
//! to several consumers shares one allocation. JSON conversion is typed: [`Value::from_json`]
//! follows a [`ValueType`] and reports the path of the first mismatch, so a malformed input line
//! can be counted and explained instead of crashing a run.

use std::fmt;
use std::sync::Arc;

use serde_json::{Map, Number};

/// An axis-aligned box in pixel (or world) coordinates: top-left `(x1, y1)`, bottom-right `(x2, y2)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BBox {
    pub x1: f64,
    pub y1: f64,
    pub x2: f64,
    pub y2: f64,
}

impl BBox {
    pub const fn new(x1: f64, y1: f64, x2: f64, y2: f64) -> BBox {
        BBox { x1, y1, x2, y2 }
    }
    pub fn width(&self) -> f64 {
        self.x2 - self.x1
    }
    pub fn height(&self) -> f64 {
        self.y2 - self.y1
    }
    pub fn center(&self) -> [f64; 2] {
        [(self.x1 + self.x2) / 2.0, (self.y1 + self.y2) / 2.0]
    }
}

/// The shape of a value. Record types carry their fields, inherited ones first.
#[derive(Debug, Clone, PartialEq)]
pub enum ValueType {
    /// Anything; JSON is decoded by its own shape.
    Any,
    Bool,
    Int,
    Float,
    Str,
    Vec2,
    BBox,
    /// A duration in microseconds.
    Duration,
    List(Box<ValueType>),
    Record(Arc<RecordType>),
}

impl ValueType {
    /// The record type of the objects a stream of this type carries (`list<T>` with `T` a record
    /// type: a snapshot of objects), if it carries objects.
    pub fn object_type(&self) -> Option<&RecordType> {
        match self {
            ValueType::List(item) => match item.as_ref() {
                ValueType::Record(r) => Some(r),
                _ => None,
            },
            _ => None,
        }
    }
}

/// A declared record (object) type after name resolution.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordType {
    pub name: Arc<str>,
    /// The direct supertype, if any.
    pub parent: Option<Arc<str>>,
    /// The prefix of the symbols of this type's instances (`vp`, `wo`, ...).
    pub symbol: Arc<str>,
    /// All fields, inherited ones first.
    pub fields: Vec<FieldType>,
}

impl RecordType {
    pub fn field(&self, name: &str) -> Option<&FieldType> {
        self.fields.iter().find(|f| &*f.name == name)
    }
}

/// Attributes every object record may carry besides its type's own: how anchoring knows the
/// object's state (`measured`: derived from a percept sample of this time; `predicted_since`:
/// since when it has not been, in microseconds; `likelihood` and `branch_of` on the branches of a
/// prediction). Decoders keep them, when they have these types, on records of any type; declared
/// types cannot use the names.
pub const OBJECT_STATUS: [(&str, ValueType); 4] = [
    ("measured", ValueType::Bool),
    ("predicted_since", ValueType::Int),
    ("likelihood", ValueType::Float),
    ("branch_of", ValueType::Str),
];

/// The type of an [`OBJECT_STATUS`] attribute.
pub fn object_status_type(name: &str) -> Option<&'static ValueType> {
    OBJECT_STATUS.iter().find(|(n, _)| *n == name).map(|(_, t)| t)
}

#[derive(Debug, Clone, PartialEq)]
pub struct FieldType {
    pub name: Arc<str>,
    pub ty: ValueType,
}

impl fmt::Display for ValueType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ValueType::Any => f.write_str("any"),
            ValueType::Bool => f.write_str("bool"),
            ValueType::Int => f.write_str("int"),
            ValueType::Float => f.write_str("float"),
            ValueType::Str => f.write_str("string"),
            ValueType::Vec2 => f.write_str("vec2"),
            ValueType::BBox => f.write_str("box"),
            ValueType::Duration => f.write_str("duration"),
            ValueType::List(t) => write!(f, "list<{t}>"),
            ValueType::Record(r) => f.write_str(&r.name),
        }
    }
}

/// An object's or a message's attributes. `id` is the identity of an object (`vp3`, `wo1`) when
/// the record describes one.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Record {
    pub id: Option<Arc<str>>,
    pub fields: Vec<(Arc<str>, Value)>,
}

impl Record {
    pub fn get(&self, name: &str) -> Option<&Value> {
        self.fields.iter().find(|(n, _)| same_name(n, name)).map(|(_, v)| v)
    }

    /// [`Record::get`] that first looks where `hint` last found `name`: records of one type have
    /// their fields in one order, so a place that reads one attribute of many objects (a formula's
    /// `a.speed`, a relation's `lane_pos`) compares one name instead of searching the fields.
    /// Always the same result as `get`; the hint only says where to look first.
    #[inline]
    pub fn get_hinted(&self, name: &str, hint: &FieldHint) -> Option<&Value> {
        let at = hint.0.load(std::sync::atomic::Ordering::Relaxed) as usize;
        if let Some((n, v)) = self.fields.get(at)
            && same_name(n, name)
        {
            return Some(v);
        }
        let (k, (_, v)) = self.fields.iter().enumerate().find(|(_, (n, _))| same_name(n, name))?;
        hint.0.store(u32::try_from(k).unwrap_or(0), std::sync::atomic::Ordering::Relaxed);
        Some(v)
    }
}

/// Names are short: compared byte by byte, which costs less than a call to `memcmp` (this is on
/// the path of every attribute a formula reads).
#[inline]
fn same_name(a: &str, b: &str) -> bool {
    a.len() == b.len() && a.as_bytes().iter().zip(b.as_bytes()).all(|(x, y)| x == y)
}

/// Where an attribute was last found in a record ([`Record::get_hinted`]). Shared by threads
/// (relaxed: a stale hint costs a search, never a wrong value); clones copy it, and every hint
/// equals every other, so a term that holds one compares as before.
#[derive(Debug, Default)]
pub struct FieldHint(std::sync::atomic::AtomicU32);

impl FieldHint {
    pub const fn new() -> FieldHint {
        FieldHint(std::sync::atomic::AtomicU32::new(0))
    }
}

impl Clone for FieldHint {
    fn clone(&self) -> FieldHint {
        FieldHint(std::sync::atomic::AtomicU32::new(self.0.load(std::sync::atomic::Ordering::Relaxed)))
    }
}

impl PartialEq for FieldHint {
    fn eq(&self, _: &FieldHint) -> bool {
        true
    }
}

/// A value carried by a sample or computed by a formula. 24 bytes: a box sits behind an `Arc`
/// so that the common values (numbers, vectors, strings) are small, and a list of a thousand
/// floats is 24 KB rather than 40.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Bool(bool),
    Int(i64),
    /// Always finite: decoding rejects NaN and infinities.
    Float(f64),
    Str(Arc<str>),
    Vec2([f64; 2]),
    /// Build with [`Value::bbox`].
    BBox(Arc<BBox>),
    Duration(i64),
    List(Arc<[Value]>),
    Record(Arc<Record>),
}

/// Why a JSON value does not fit a type; `path` points into the JSON (`.pos[1]`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("at `{path}`: expected {expected}, found {found}")]
pub struct JsonError {
    pub path: String,
    pub expected: String,
    pub found: String,
}

impl Value {
    pub fn vec2(x: f64, y: f64) -> Value {
        Value::Vec2([x, y])
    }

    pub fn str(s: &str) -> Value {
        Value::Str(Arc::from(s))
    }

    pub fn bbox(b: BBox) -> Value {
        Value::BBox(Arc::new(b))
    }

    pub fn as_bbox(&self) -> Option<BBox> {
        match self {
            Value::BBox(b) => Some(**b),
            _ => None,
        }
    }

    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Value::Bool(b) => Some(*b),
            _ => None,
        }
    }

    /// Numbers widen: an `Int` reads as a float.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Value::Float(x) => Some(*x),
            Value::Int(i) => Some(*i as f64),
            _ => None,
        }
    }

    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Value::Int(i) => Some(*i),
            _ => None,
        }
    }

    pub fn as_vec2(&self) -> Option<[f64; 2]> {
        match self {
            Value::Vec2(v) => Some(*v),
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            Value::Str(s) => Some(s),
            _ => None,
        }
    }

    pub fn as_record(&self) -> Option<&Record> {
        match self {
            Value::Record(r) => Some(r),
            _ => None,
        }
    }

    /// The name of this value's kind, as used in messages.
    pub fn kind(&self) -> &'static str {
        match self {
            Value::Bool(_) => "bool",
            Value::Int(_) => "int",
            Value::Float(_) => "float",
            Value::Str(_) => "string",
            Value::Vec2(_) => "vec2",
            Value::BBox(_) => "box",
            Value::Duration(_) => "duration",
            Value::List(_) => "list",
            Value::Record(_) => "record",
        }
    }

    /// Attribute access: a record field, or `x`/`y` of a vector, or a box's corners and size.
    pub fn field(&self, name: &str) -> Option<Value> {
        match self {
            Value::Record(r) => match name {
                "id" => r.id.as_deref().map(Value::str).or_else(|| r.get(name).cloned()),
                _ => r.get(name).cloned(),
            },
            Value::Vec2([x, y]) => match name {
                "x" => Some(Value::Float(*x)),
                "y" => Some(Value::Float(*y)),
                _ => None,
            },
            Value::BBox(b) => match name {
                "x1" => Some(Value::Float(b.x1)),
                "y1" => Some(Value::Float(b.y1)),
                "x2" => Some(Value::Float(b.x2)),
                "y2" => Some(Value::Float(b.y2)),
                "width" => Some(Value::Float(b.width())),
                "height" => Some(Value::Float(b.height())),
                "center" => Some(Value::Vec2(b.center())),
                _ => None,
            },
            _ => None,
        }
    }

    /// Encodes as JSON: vectors as `[x, y]`, boxes as `[x1, y1, x2, y2]`, durations as integer
    /// microseconds, records as objects with their `id` first.
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::Value as J;
        match self {
            Value::Bool(b) => J::Bool(*b),
            Value::Int(i) => J::Number((*i).into()),
            Value::Float(x) => Number::from_f64(*x).map_or(J::Null, J::Number),
            Value::Str(s) => J::String(s.to_string()),
            Value::Vec2([x, y]) => J::Array(vec![f64_json(*x), f64_json(*y)]),
            Value::BBox(b) => J::Array(vec![f64_json(b.x1), f64_json(b.y1), f64_json(b.x2), f64_json(b.y2)]),
            Value::Duration(us) => J::Number((*us).into()),
            Value::List(items) => J::Array(items.iter().map(Value::to_json).collect()),
            Value::Record(r) => {
                let mut map = Map::new();
                if let Some(id) = &r.id {
                    map.insert("id".to_string(), J::String(id.to_string()));
                }
                for (name, value) in &r.fields {
                    map.insert(name.to_string(), value.to_json());
                }
                J::Object(map)
            }
        }
    }

    /// Decodes JSON following `ty`. Ints widen to floats; a float where an int is needed, a
    /// missing field, `null`, or a string such as `"NaN"` where a number is needed is an error.
    /// Records may carry an `"id"` string and the [`OBJECT_STATUS`] attributes; other fields not
    /// in the type are ignored.
    pub fn from_json(json: &serde_json::Value, ty: &ValueType) -> Result<Value, JsonError> {
        let mut path = String::new();
        decode(json, ty, &mut path)
    }

    /// Decodes JSON by its own shape (numbers with a fraction or exponent become floats).
    pub fn from_json_untyped(json: &serde_json::Value) -> Result<Value, JsonError> {
        Value::from_json(json, &ValueType::Any)
    }
}

/// Serializes as [`Value::to_json`] would, without building the JSON tree first (the same text
/// with `serde_json`: a record's keys in the sorted order of a JSON object, the last of equal keys
/// kept, non-finite floats as `null`). Writers of many values (the `file.jsonl` sink) use it.
impl serde::Serialize for Value {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{SerializeMap, SerializeSeq};
        let float = |x: f64| if x.is_finite() { Some(x) } else { None };
        match self {
            Value::Bool(b) => serializer.serialize_bool(*b),
            Value::Int(i) | Value::Duration(i) => serializer.serialize_i64(*i),
            Value::Float(x) => serializer.serialize_some(&float(*x)),
            Value::Str(s) => serializer.serialize_str(s),
            Value::Vec2(v) => {
                let mut seq = serializer.serialize_seq(Some(2))?;
                for x in v {
                    seq.serialize_element(&float(*x))?;
                }
                seq.end()
            }
            Value::BBox(b) => {
                let mut seq = serializer.serialize_seq(Some(4))?;
                for x in [b.x1, b.y1, b.x2, b.y2] {
                    seq.serialize_element(&float(x))?;
                }
                seq.end()
            }
            Value::List(items) => {
                let mut seq = serializer.serialize_seq(Some(items.len()))?;
                for item in items.iter() {
                    seq.serialize_element(item)?;
                }
                seq.end()
            }
            Value::Record(r) => {
                enum Entry<'a> {
                    Id(&'a str),
                    Field(&'a Value),
                }
                let mut entries: Vec<(&str, Entry<'_>)> = Vec::with_capacity(r.fields.len() + 1);
                if let Some(id) = &r.id {
                    entries.push(("id", Entry::Id(id)));
                }
                entries.extend(r.fields.iter().map(|(name, value)| (&**name, Entry::Field(value))));
                // As a JSON object (a sorted map) holds them: sorted by key, the last of equal keys.
                entries.sort_by(|a, b| a.0.cmp(b.0));
                let mut map = serializer.serialize_map(None)?;
                for (i, (key, entry)) in entries.iter().enumerate() {
                    if entries.get(i + 1).is_some_and(|next| next.0 == *key) {
                        continue;
                    }
                    match entry {
                        Entry::Id(id) => map.serialize_entry(key, id)?,
                        Entry::Field(value) => map.serialize_entry(key, value)?,
                    }
                }
                map.end()
            }
        }
    }
}

fn f64_json(x: f64) -> serde_json::Value {
    Number::from_f64(x).map_or(serde_json::Value::Null, serde_json::Value::Number)
}

fn json_kind(json: &serde_json::Value) -> String {
    use serde_json::Value as J;
    match json {
        J::Null => "null".into(),
        J::Bool(_) => "a boolean".into(),
        J::Number(_) => "a number".into(),
        J::String(s) if s.len() <= 16 => format!("the string {s:?}"),
        J::String(_) => "a string".into(),
        J::Array(a) => format!("an array of {}", a.len()),
        J::Object(_) => "an object".into(),
    }
}

fn mismatch(json: &serde_json::Value, expected: &str, path: &str) -> JsonError {
    JsonError {
        path: if path.is_empty() { ".".to_string() } else { path.to_string() },
        expected: expected.to_string(),
        found: json_kind(json),
    }
}

fn finite_f64(json: &serde_json::Value, path: &str) -> Result<f64, JsonError> {
    match json.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        _ => Err(mismatch(json, "a finite number", path)),
    }
}

fn decode(json: &serde_json::Value, ty: &ValueType, path: &mut String) -> Result<Value, JsonError> {
    use serde_json::Value as J;
    match ty {
        ValueType::Any => match json {
            J::Bool(b) => Ok(Value::Bool(*b)),
            J::Number(n) => match n.as_i64() {
                Some(i) => Ok(Value::Int(i)),
                None => finite_f64(json, path).map(Value::Float),
            },
            J::String(s) => Ok(Value::str(s)),
            J::Array(items) => decode_list(items, ty, path),
            J::Object(map) => {
                let id = map.get("id").and_then(J::as_str).map(Arc::from);
                let mut fields = Vec::with_capacity(map.len());
                for (name, v) in map {
                    if name == "id" && id.is_some() {
                        continue;
                    }
                    let len = path.len();
                    path.push('.');
                    path.push_str(name);
                    let value = decode(v, ty, path)?;
                    path.truncate(len);
                    fields.push((Arc::from(name.as_str()), value));
                }
                Ok(Value::Record(Arc::new(Record { id, fields })))
            }
            J::Null => Err(mismatch(json, "a value", path)),
        },
        ValueType::Bool => json.as_bool().map(Value::Bool).ok_or_else(|| mismatch(json, "a boolean", path)),
        ValueType::Int => json.as_i64().map(Value::Int).ok_or_else(|| mismatch(json, "an integer", path)),
        ValueType::Duration => json
            .as_i64()
            .map(Value::Duration)
            .ok_or_else(|| mismatch(json, "an integer number of microseconds", path)),
        ValueType::Float => finite_f64(json, path).map(Value::Float),
        ValueType::Str => json.as_str().map(Value::str).ok_or_else(|| mismatch(json, "a string", path)),
        ValueType::Vec2 => {
            let [x, y] = numbers::<2>(json, "[x, y]", path)?;
            Ok(Value::Vec2([x, y]))
        }
        ValueType::BBox => {
            let [x1, y1, x2, y2] = numbers::<4>(json, "[x1, y1, x2, y2]", path)?;
            Ok(Value::bbox(BBox { x1, y1, x2, y2 }))
        }
        ValueType::List(item) => match json {
            J::Array(items) => decode_list(items, item, path),
            _ => Err(mismatch(json, "an array", path)),
        },
        ValueType::Record(record) => {
            let J::Object(map) = json else {
                return Err(mismatch(json, &format!("an object of type {}", record.name), path));
            };
            let id = match map.get("id") {
                None => None,
                Some(J::String(s)) => Some(Arc::from(s.as_str())),
                Some(other) => return Err(mismatch(other, "a string", &format!("{path}.id"))),
            };
            let mut fields = Vec::with_capacity(record.fields.len());
            for field in &record.fields {
                let len = path.len();
                path.push('.');
                path.push_str(&field.name);
                let value = match map.get(&*field.name) {
                    Some(v) => decode(v, &field.ty, path)?,
                    None => {
                        return Err(JsonError {
                            path: path.clone(),
                            expected: format!("field `{}` of type {}", field.name, field.ty),
                            found: "nothing".into(),
                        });
                    }
                };
                path.truncate(len);
                fields.push((field.name.clone(), value));
            }
            for (name, status_ty) in &OBJECT_STATUS {
                if let Some(v) = map.get(*name).filter(|_| record.field(name).is_none()) {
                    let len = path.len();
                    path.push('.');
                    path.push_str(name);
                    let value = decode(v, status_ty, path)?;
                    path.truncate(len);
                    fields.push((Arc::from(*name), value));
                }
            }
            Ok(Value::Record(Arc::new(Record { id, fields })))
        }
    }
}

fn decode_list(
    items: &[serde_json::Value],
    item_ty: &ValueType,
    path: &mut String,
) -> Result<Value, JsonError> {
    let mut out = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let len = path.len();
        path.push_str(&format!("[{i}]"));
        out.push(decode(item, item_ty, path)?);
        path.truncate(len);
    }
    Ok(Value::List(out.into()))
}

fn numbers<const N: usize>(json: &serde_json::Value, shape: &str, path: &str) -> Result<[f64; N], JsonError> {
    let Some(items) = json.as_array().filter(|a| a.len() == N) else {
        return Err(mismatch(json, &format!("{shape} with finite numbers"), path));
    };
    let mut out = [0.0; N];
    for (i, (slot, item)) in out.iter_mut().zip(items).enumerate() {
        *slot = finite_f64(item, &format!("{path}[{i}]"))?;
    }
    Ok(out)
}

impl fmt::Display for Value {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.to_json())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn percept_type() -> ValueType {
        ValueType::Record(Arc::new(RecordType {
            name: "VisionPercept".into(),
            parent: None,
            symbol: "vp".into(),
            fields: vec![
                FieldType { name: "pos".into(), ty: ValueType::Vec2 },
                FieldType { name: "size".into(), ty: ValueType::Float },
            ],
        }))
    }

    #[test]
    fn typed_record_round_trips() {
        let json = json!({"id": "vp3", "pos": [1.5, -2], "size": 4});
        let value = Value::from_json(&json, &percept_type()).unwrap();
        let record = value.as_record().unwrap();
        assert_eq!(record.id.as_deref(), Some("vp3"));
        assert_eq!(record.get("pos"), Some(&Value::vec2(1.5, -2.0)));
        assert_eq!(record.get("size"), Some(&Value::Float(4.0)));
        assert_eq!(value.to_json(), json!({"id": "vp3", "pos": [1.5, -2.0], "size": 4.0}));
    }

    #[test]
    fn object_status_attributes_are_kept_others_dropped() {
        let json =
            json!({"id": "wo1", "pos": [1, 2], "size": 4, "measured": false, "predicted_since": 700, "x": 1});
        let value = Value::from_json(&json, &percept_type()).unwrap();
        assert_eq!(
            value.to_json(),
            json!({"id": "wo1", "pos": [1.0, 2.0], "size": 4.0, "measured": false, "predicted_since": 700})
        );
        let err =
            Value::from_json(&json!({"pos": [1, 2], "size": 4, "measured": 1}), &percept_type()).unwrap_err();
        assert_eq!(err.path, ".measured");
    }

    #[test]
    fn mismatches_name_the_path() {
        let err = Value::from_json(&json!({"pos": [1, "NaN"], "size": 1}), &percept_type()).unwrap_err();
        assert_eq!(err.path, ".pos[1]");
        assert_eq!(err.to_string(), "at `.pos[1]`: expected a finite number, found the string \"NaN\"");
        let err = Value::from_json(&json!({"pos": [1], "size": 1}), &percept_type()).unwrap_err();
        assert_eq!(err.path, ".pos");
        let err = Value::from_json(&json!({"pos": [1, 2]}), &percept_type()).unwrap_err();
        assert_eq!(err.path, ".size");
        let err = Value::from_json(&json!(1.5), &ValueType::Int).unwrap_err();
        assert_eq!(err.expected, "an integer");
    }

    #[test]
    fn values_stay_small() {
        // Every list element and record attribute is a `Value`: its size is the memory (and the
        // decoding work) of every number of a stream.
        assert_eq!(size_of::<Value>(), 24);
        assert_eq!(Value::bbox(BBox::new(1.0, 2.0, 3.0, 4.0)).as_bbox(), Some(BBox::new(1.0, 2.0, 3.0, 4.0)));
    }

    #[test]
    fn untyped_decoding_follows_the_json() {
        let v = Value::from_json_untyped(&json!({"id": "x", "a": [1, 2.5, true]})).unwrap();
        let r = v.as_record().unwrap();
        assert_eq!(r.id.as_deref(), Some("x"));
        assert_eq!(
            r.get("a"),
            Some(&Value::List(vec![Value::Int(1), Value::Float(2.5), Value::Bool(true)].into()))
        );
        assert!(Value::from_json_untyped(&json!(null)).is_err());
    }
}
