//! How fields of a ROS 2 message become a KPL value and back, as a spec declares it: compiled
//! against the message's [`Schema`] and the KPL type, so that an unknown field, a wrong type or a
//! missing attribute is an error with the position in the entry that has it.
//!
//! Into KPL ([`InMap`]): with `each` the path of an array of the message (`markers`), one record
//! per element (the stream is `list<T>`), otherwise one record per message; each entry
//! `attribute = path` reads a field of the element (or message): numbers into `float` / `int`,
//! `bool`, `string`, a message with numeric `x` and `y` (`geometry_msgs/Point`, `Vector3`, ...)
//! into `vec2`, a `builtin_interfaces/Time` into `int` microseconds, a `Duration` into
//! `duration`. `identity` names the field that identifies an object (a track id): the record's id
//! is the type's symbol and that value (`vp17`). The valid time is `header.stamp` (of the message,
//! or else of the first element) unless another path is given.
//!
//! Out of KPL ([`OutMap`]): each entry `path = source` sets a field of the element (or message);
//! a source is an attribute of the record, `symbol` (the record's id), `number` (a whole number
//! that stays with the symbol: its digits, `co12` is 12), or a literal (`"map"`, `1.0`, `3`,
//! `true`). Every `header.stamp` of the message and its elements is the sample's valid time unless
//! set; every other field not set keeps its default (zero, empty).
//!
//! The module's tests map a `MarkerArray` into percepts and cars back into one.

use std::hash::BuildHasher as _;
use std::sync::Arc;

use rustc_hash::FxHashMap;

use kpl_core::{Record, RecordType, Time, Value, ValueType};

use crate::cdr::MsgValue;
use crate::definitions::{Schema, SchemaBase};
use crate::json;
use crate::msg::{ArrayKind, Primitive};
use crate::plan::{DecodePlan, EncodePlan};

/// A mapping problem: which part of the declaration (`entry`: the index of the entry, or `None`
/// for the parameter named in `param`), the byte range inside its text, the message and a hint.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct MapError {
    pub param: &'static str,
    pub entry: Option<usize>,
    pub range: (usize, usize),
    pub message: String,
    pub hint: Option<String>,
}

impl MapError {
    fn new(param: &'static str, entry: Option<usize>, range: (usize, usize), message: String) -> MapError {
        MapError { param, entry, range, message, hint: None }
    }

    fn hint(mut self, hint: impl Into<String>) -> MapError {
        self.hint = Some(hint.into());
        self
    }
}

/// A mapping into KPL as declared.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InSpec {
    pub each: Option<String>,
    pub identity: Option<String>,
    pub stamp: Option<String>,
    /// `attribute = path`.
    pub entries: Vec<String>,
}

/// A mapping out of KPL as declared.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OutSpec {
    pub each: Option<String>,
    /// `path = source`.
    pub entries: Vec<String>,
}

/// A path resolved to field indices, and what it ends on.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Path {
    pub(crate) indices: Vec<usize>,
    pub(crate) end: End,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum End {
    Primitive(Primitive),
    /// A message with numeric `x` and `y` at these indices.
    Xy(usize, usize, Option<usize>),
    Time,
    Duration,
    /// Any other message (only as the `each` array or a header).
    Struct(usize),
    /// An array (only for `each`).
    Array(usize),
}

/// Resolves `a.b.c` from struct `start`; `range` is where the path is in its text.
fn resolve(
    schema: &Schema,
    start: usize,
    text: &str,
    param: &'static str,
    entry: Option<usize>,
    offset: usize,
) -> Result<Path, MapError> {
    let mut index = start;
    let mut indices = Vec::new();
    let mut at = offset;
    let parts: Vec<&str> = text.split('.').collect();
    for (i, part) in parts.iter().enumerate() {
        let range = (at, at + part.len());
        at += part.len() + 1;
        let def = schema.get(index);
        let Some(fi) = def.fields.iter().position(|f| &*f.name == *part) else {
            let names: Vec<&str> = def.fields.iter().map(|f| &*f.name).collect();
            let hint = closest(part, &names)
                .map(|n| format!("did you mean `{n}`?"))
                .unwrap_or_else(|| format!("`{}` has: {}", def.def.name, names.join(", ")));
            return Err(MapError::new(
                param,
                entry,
                range,
                format!("`{}` has no field `{part}`", def.def.name),
            )
            .hint(hint));
        };
        indices.push(fi);
        let field = &def.fields[fi];
        let last = i + 1 == parts.len();
        if field.array != ArrayKind::Single {
            if !last {
                return Err(MapError::new(
                    param,
                    entry,
                    range,
                    format!("`{part}` is an array ({})", field_type(schema, index, fi)),
                )
                .hint("only `each` goes into an array"));
            }
            return Ok(Path { indices, end: End::Array(fi) });
        }
        match field.base {
            SchemaBase::Primitive(p) => {
                if !last {
                    return Err(MapError::new(
                        param,
                        entry,
                        range,
                        format!("`{part}` is a {}, it has no fields", p.msg_name()),
                    ));
                }
                return Ok(Path { indices, end: End::Primitive(p) });
            }
            SchemaBase::Struct(s) => {
                index = s;
                if last {
                    return Ok(Path { indices, end: struct_end(schema, s) });
                }
            }
        }
    }
    Err(MapError::new(param, entry, (offset, offset + text.len()), "an empty path".into()))
}

fn struct_end(schema: &Schema, s: usize) -> End {
    let def = schema.get(s);
    let name = def.def.name.to_string();
    if name == "builtin_interfaces/msg/Time" {
        return End::Time;
    }
    if name == "builtin_interfaces/msg/Duration" {
        return End::Duration;
    }
    let numeric = |n: &str| {
        def.fields.iter().position(|f| {
            &*f.name == n
                && f.array == ArrayKind::Single
                && matches!(f.base, SchemaBase::Primitive(p) if p.size().is_some() && p != Primitive::Bool)
        })
    };
    match (numeric("x"), numeric("y")) {
        (Some(x), Some(y)) => End::Xy(x, y, numeric("z")),
        _ => End::Struct(s),
    }
}

fn field_type(schema: &Schema, index: usize, fi: usize) -> String {
    let f = &schema.get(index).fields[fi];
    let base = match f.base {
        SchemaBase::Primitive(p) => p.msg_name(),
        SchemaBase::Struct(s) => schema.get(s).def.name.to_string(),
    };
    match f.array {
        ArrayKind::Single => base,
        ArrayKind::Fixed(n) => format!("{base}[{n}]"),
        ArrayKind::Bounded(n) => format!("{base}[<={n}]"),
        ArrayKind::Unbounded => format!("{base}[]"),
    }
}

fn describe_end(schema: &Schema, end: End) -> String {
    match end {
        End::Primitive(p) => p.msg_name(),
        End::Xy(..) => "a message with x and y".into(),
        End::Time => "builtin_interfaces/msg/Time".into(),
        End::Duration => "builtin_interfaces/msg/Duration".into(),
        End::Struct(s) => schema.get(s).def.name.to_string(),
        End::Array(_) => "an array".into(),
    }
}

fn closest<'a>(word: &str, names: &[&'a str]) -> Option<&'a str> {
    names
        .iter()
        .copied()
        .filter(|n| edit_distance(word, n) <= 2.max(word.len() / 3))
        .min_by_key(|n| edit_distance(word, n))
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let old = row[j + 1];
            row[j + 1] = (row[j + 1] + 1).min(row[j] + 1).min(prev + usize::from(ca != *cb));
            prev = old;
        }
    }
    row[b.len()]
}

/// A side of an entry: where it starts in the entry's text, and the text.
type Part<'a> = (usize, &'a str);

/// Splits `left = right`, trimmed, with the offset of each side in the text.
fn split_entry<'a>(text: &'a str, param: &'static str, i: usize) -> Result<(Part<'a>, Part<'a>), MapError> {
    let Some(eq) = text.find('=') else {
        return Err(MapError::new(
            param,
            Some(i),
            (0, text.len()),
            format!("`{text}` is not `name = value`"),
        )
        .hint("write e.g. `pos = pose.position`"));
    };
    fn trimmed(s: &str, base: usize) -> (usize, &str) {
        (base + (s.len() - s.trim_start().len()), s.trim())
    }
    Ok((trimmed(&text[..eq], 0), trimmed(&text[eq + 1..], eq + 1)))
}

/// The `each` array: its path and the struct of its elements (`None`: whole messages).
fn each_array(schema: &Schema, each: Option<&str>) -> Result<Option<(Vec<usize>, usize)>, MapError> {
    let Some(each) = each else { return Ok(None) };
    let path = resolve(schema, schema.root_index(), each, "each", None, 0)?;
    let End::Array(fi) = path.end else {
        return Err(MapError::new(
            "each",
            None,
            (0, each.len()),
            format!("`{each}` is not an array of messages"),
        ));
    };
    let parent = parent_struct(schema, &path.indices);
    match schema.get(parent).fields[fi].base {
        SchemaBase::Struct(s) => Ok(Some((path.indices, s))),
        SchemaBase::Primitive(p) => Err(MapError::new(
            "each",
            None,
            (0, each.len()),
            format!("`{each}` is an array of {}, not of messages", p.msg_name()),
        )),
    }
}

/// The struct that holds the last field of a path.
fn parent_struct(schema: &Schema, indices: &[usize]) -> usize {
    let mut s = schema.root_index();
    for &i in &indices[..indices.len().saturating_sub(1)] {
        if let SchemaBase::Struct(next) = schema.get(s).fields[i].base {
            s = next;
        }
    }
    s
}

fn get<'a>(value: &'a MsgValue, indices: &[usize]) -> Option<&'a MsgValue> {
    indices.iter().try_fold(value, |v, &i| v.fields().get(i))
}

fn get_mut<'a>(value: &'a mut MsgValue, indices: &[usize]) -> Option<&'a mut MsgValue> {
    indices.iter().try_fold(value, |v, &i| match v {
        MsgValue::Struct(fields) => fields.get_mut(i),
        _ => None,
    })
}

/// Messages into KPL values.
#[derive(Debug, Clone)]
pub struct InMap {
    each: Option<Vec<usize>>,
    /// The record type and its symbol prefix.
    ty: Arc<RecordType>,
    /// Per attribute of the type, in its order: the path it is read from.
    attributes: Vec<(Arc<str>, Path, ValueType)>,
    identity: Option<Path>,
    /// The valid time: a path from the message root, or from the element.
    stamp: Option<(bool, Path)>,
    /// The schema, for the tree path.
    schema: Arc<Schema>,
    /// What [`InMap::decode`] runs, when the mapping has one.
    plan: Option<DecodePlan>,
}

impl InMap {
    /// Compiles a mapping of messages of `schema` into values of `output` (`list<T>` with
    /// `each`, `T` without).
    pub fn compile(schema: &Schema, spec: &InSpec, output: &ValueType) -> Result<InMap, MapError> {
        let each = each_array(schema, spec.each.as_deref())?;
        let record = match (output, &each) {
            (ValueType::List(inner), Some(_)) => inner.as_ref(),
            (ValueType::List(_), None) => {
                return Err(MapError::new(
                    "each",
                    None,
                    (0, 0),
                    "the stream is a list, but the mapping has no `each`".into(),
                )
                .hint("name the array whose elements are the list's objects: `each: \"markers\"`"));
            }
            (_, Some(_)) => {
                return Err(MapError::new(
                    "each",
                    None,
                    (0, 0),
                    "with `each` the stream is a list of objects".into(),
                )
                .hint("declare the source's type as `list<T>`"));
            }
            (ty, None) => ty,
        };
        let ValueType::Record(ty) = record else {
            return Err(MapError::new(
                "each",
                None,
                (0, 0),
                format!("a ROS 2 message maps onto an object type, not `{record}`"),
            ));
        };
        let element = each.as_ref().map_or(schema.root_index(), |(_, s)| *s);
        let mut attributes: Vec<(Arc<str>, Path, ValueType)> = Vec::new();
        for (i, text) in spec.entries.iter().enumerate() {
            let ((aat, attribute), (pat, path_text)) = split_entry(text, "map", i)?;
            let Some(field) = ty.field(attribute) else {
                let names: Vec<&str> = ty.fields.iter().map(|f| &*f.name).collect();
                let e = MapError::new(
                    "map",
                    Some(i),
                    (aat, aat + attribute.len()),
                    format!("`{}` has no attribute `{attribute}`", ty.name),
                );
                return Err(match closest(attribute, &names) {
                    Some(n) => e.hint(format!("did you mean `{n}`?")),
                    None => e.hint(format!("`{}` has: {}", ty.name, names.join(", "))),
                });
            };
            if attributes.iter().any(|(a, ..)| **a == *attribute) {
                return Err(MapError::new(
                    "map",
                    Some(i),
                    (aat, aat + attribute.len()),
                    format!("`{attribute}` is mapped twice"),
                ));
            }
            let path = resolve(schema, element, path_text, "map", Some(i), pat)?;
            if !converts(path.end, &field.ty) {
                return Err(MapError::new(
                    "map",
                    Some(i),
                    (pat, pat + path_text.len()),
                    format!(
                        "`{path_text}` is {}, which does not fit `{attribute}: {}`",
                        describe_end(schema, path.end),
                        field.ty
                    ),
                )
                .hint(conversion_hint(&field.ty)));
            }
            attributes.push((field.name.clone(), path, field.ty.clone()));
        }
        for field in &ty.fields {
            if !attributes.iter().any(|(a, ..)| *a == field.name)
                && kpl_core::object_status_type(&field.name).is_none()
            {
                return Err(MapError::new(
                    "map",
                    None,
                    (0, 0),
                    format!("nothing sets `{}` of `{}`", field.name, ty.name),
                )
                .hint(format!("add an entry `{} = <field of the message>`", field.name)));
            }
        }
        let identity = match &spec.identity {
            Some(text) => {
                let path = resolve(schema, element, text, "identity", None, 0)?;
                if !matches!(path.end, End::Primitive(p) if p != Primitive::Bool && !matches!(p, Primitive::Float32 | Primitive::Float64))
                {
                    return Err(MapError::new(
                        "identity",
                        None,
                        (0, text.len()),
                        format!(
                            "`{text}` is {}: an identity is an integer or a string",
                            describe_end(schema, path.end)
                        ),
                    ));
                }
                Some(path)
            }
            None => None,
        };
        let stamp_text = spec.stamp.clone().unwrap_or_else(|| "header.stamp".to_string());
        let stamp = match resolve(schema, schema.root_index(), &stamp_text, "stamp", None, 0) {
            Ok(path) if path.end == End::Time => Some((true, path)),
            root => match resolve(schema, element, &stamp_text, "stamp", None, 0) {
                Ok(path) if path.end == End::Time && each.is_some() => Some((false, path)),
                Ok(path) => {
                    return Err(MapError::new(
                        "stamp",
                        None,
                        (0, stamp_text.len()),
                        format!("`{stamp_text}` is {}, not a time", describe_end(schema, path.end)),
                    ));
                }
                // No header: the valid time is when the message arrived, unless a stamp was asked for.
                Err(e) if spec.stamp.is_some() => return Err(root.err().unwrap_or(e)),
                Err(_) => None,
            },
        };
        let each = each.map(|(p, _)| p);
        let plan =
            DecodePlan::compile(schema, each.as_ref(), ty, &attributes, identity.as_ref(), stamp.as_ref());
        let schema = Arc::new(schema.clone());
        Ok(InMap { each, ty: ty.clone(), attributes, identity, stamp, schema, plan })
    }

    /// The valid time (`None`: as [`InMap::valid_time`]) and KPL value of a message in CDR (with
    /// its encapsulation header): what `InMap::apply(cdr::decode(..))` gives, read by the
    /// mapping's decode plan (crate::plan) without building the message, or by that tree path
    /// where the plan does not cover the mapping or fails on the message (for its exact error).
    pub fn decode(&self, bytes: &[u8]) -> Result<(Option<Time>, Value), String> {
        if let Some(plan) = &self.plan
            && let Ok(decoded) = plan.decode(bytes)
        {
            return Ok(decoded);
        }
        self.decode_tree(bytes)
    }

    /// [`InMap::decode`] by the tree path: the whole message decoded, then mapped.
    pub fn decode_tree(&self, bytes: &[u8]) -> Result<(Option<Time>, Value), String> {
        let msg = crate::cdr::decode(&self.schema, bytes).map_err(|e| e.to_string())?;
        let value = self.apply(&msg)?;
        Ok((self.valid_time(&msg), value))
    }

    /// [`InMap::decode`] by the plan alone (`None`: no plan, `Some(Err(()))`: the plan refuses
    /// the message), for the differential tests.
    #[doc(hidden)]
    pub fn decode_plan_only(&self, bytes: &[u8]) -> Option<Result<(Option<Time>, Value), ()>> {
        self.plan.as_ref().map(|plan| plan.decode(bytes))
    }

    /// Whether the message has a time stamp the mapping reads (else the arrival time is used).
    pub fn has_stamp(&self) -> bool {
        self.stamp.is_some()
    }

    /// The valid time of a message (`None` if it has no stamp or its list is empty).
    pub fn valid_time(&self, msg: &MsgValue) -> Option<Time> {
        let (root, path) = self.stamp.as_ref()?;
        let holder = if *root {
            msg
        } else {
            let each = self.each.as_ref()?;
            match get(msg, each)? {
                MsgValue::List(items) => items.first()?,
                _ => return None,
            }
        };
        time_of(get(holder, &path.indices)?)
    }

    /// The KPL value of a message.
    pub fn apply(&self, msg: &MsgValue) -> Result<Value, String> {
        match &self.each {
            None => self.record(msg),
            Some(each) => {
                let Some(MsgValue::List(items)) = get(msg, each) else {
                    return Err("the array is missing".into());
                };
                let records: Result<Vec<Value>, String> = items.iter().map(|m| self.record(m)).collect();
                Ok(Value::List(records?.into()))
            }
        }
    }

    fn record(&self, msg: &MsgValue) -> Result<Value, String> {
        let mut fields = Vec::with_capacity(self.attributes.len());
        for (name, path, ty) in &self.attributes {
            let v = get(msg, &path.indices).ok_or("a field is missing")?;
            fields.push((name.clone(), convert(v, path.end, ty).map_err(|e| format!("`{name}`: {e}"))?));
        }
        let id = match &self.identity {
            Some(path) => Some(match get(msg, &path.indices) {
                Some(MsgValue::Int(i)) => format!("{}{i}", self.ty.symbol).into(),
                Some(MsgValue::UInt(u)) => format!("{}{u}", self.ty.symbol).into(),
                Some(MsgValue::Str(s)) => format!("{}{s}", self.ty.symbol).into(),
                _ => return Err("the identity is missing".into()),
            }),
            None => None,
        };
        Ok(Value::Record(Arc::new(Record { id, fields })))
    }
}

fn time_of(v: &MsgValue) -> Option<Time> {
    let f = v.fields();
    let sec = match f.first()? {
        MsgValue::Int(s) => *s,
        _ => return None,
    };
    let nanosec = match f.get(1)? {
        MsgValue::UInt(n) => *n as i64,
        _ => return None,
    };
    sec.checked_mul(1_000_000)?.checked_add(nanosec / 1000)
}

fn converts(end: End, ty: &ValueType) -> bool {
    use Primitive::*;
    match (end, ty) {
        (_, ValueType::Any) => !matches!(end, End::Struct(_) | End::Array(_)),
        (
            End::Primitive(
                Float32 | Float64 | Int8 | Int16 | Int32 | Int64 | UInt8 | UInt16 | UInt32 | UInt64 | Byte
                | Char,
            ),
            ValueType::Float,
        ) => true,
        (
            End::Primitive(Int8 | Int16 | Int32 | Int64 | UInt8 | UInt16 | UInt32 | UInt64 | Byte | Char),
            ValueType::Int,
        ) => true,
        (End::Primitive(Bool), ValueType::Bool) => true,
        (End::Primitive(String(_)), ValueType::Str) => true,
        (End::Xy(..), ValueType::Vec2) => true,
        (End::Time, ValueType::Int) => true,
        (End::Duration, ValueType::Duration) => true,
        _ => false,
    }
}

fn conversion_hint(ty: &ValueType) -> String {
    match ty {
        ValueType::Vec2 => {
            "a vec2 reads a message with `x` and `y` (a geometry_msgs/Point, Vector3, ...)".into()
        }
        ValueType::Float => "a float reads a number field".into(),
        ValueType::Int => "an int reads an integer field or a builtin_interfaces/Time (microseconds)".into(),
        ValueType::Str => "a string reads a string field".into(),
        ValueType::Duration => "a duration reads a builtin_interfaces/Duration".into(),
        _ => "map numbers, strings, bools, points and times".into(),
    }
}

fn convert(v: &MsgValue, end: End, ty: &ValueType) -> Result<Value, String> {
    let finite = |x: f64| if x.is_finite() { Ok(x) } else { Err(format!("{x} is not a finite number")) };
    Ok(match (end, ty, v) {
        (End::Xy(x, y, _), _, MsgValue::Struct(f)) => Value::Vec2([
            finite(f.get(x).and_then(MsgValue::as_f64).ok_or("no x")?)?,
            finite(f.get(y).and_then(MsgValue::as_f64).ok_or("no y")?)?,
        ]),
        (End::Time, _, v) => Value::Int(time_of(v).ok_or("not a time")?),
        (End::Duration, _, v) => Value::Duration(time_of(v).ok_or("not a duration")?),
        (_, ValueType::Float, v) => Value::Float(finite(v.as_f64().ok_or("not a number")?)?),
        (_, ValueType::Int | ValueType::Any, MsgValue::Int(i)) => Value::Int(*i),
        (_, ValueType::Int | ValueType::Any, MsgValue::UInt(u)) => {
            Value::Int(i64::try_from(*u).map_err(|_| format!("{u} is too large"))?)
        }
        (_, ValueType::Any, MsgValue::Float(x)) => Value::Float(finite(*x)?),
        (_, _, MsgValue::Bool(b)) => Value::Bool(*b),
        (_, _, MsgValue::Str(s)) => Value::str(s),
        _ => return Err("a value of another type".into()),
    })
}

/// Where a field of the output message gets its value.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Source {
    Attribute(Arc<str>),
    Symbol,
    Number,
    Literal(MsgValue),
}

/// KPL values into messages.
#[derive(Debug, Clone)]
pub struct OutMap {
    schema: Arc<Schema>,
    each: Option<(Vec<usize>, usize)>,
    entries: Vec<(Path, Source)>,
    /// The header stamps the valid time goes into: from the root, and in each element.
    root_stamp: Option<Vec<usize>>,
    element_stamp: Option<Vec<usize>>,
    numbers: FxHashMap<Arc<str>, i64>,
    /// What [`OutMap::encode_into`] runs, when the mapping has one.
    plan: Option<EncodePlan>,
}

impl OutMap {
    /// Compiles a mapping of values of `input` (`list<T>` with `each`) into messages of `schema`.
    pub fn compile(schema: Arc<Schema>, spec: &OutSpec, input: &ValueType) -> Result<OutMap, MapError> {
        let each = each_array(&schema, spec.each.as_deref())?;
        let record = match (input, &each) {
            (ValueType::List(inner), Some(_)) => inner.as_ref().clone(),
            (ValueType::List(_), None) => {
                return Err(MapError::new(
                    "each",
                    None,
                    (0, 0),
                    "the stream is a list, but the mapping has no `each`".into(),
                )
                .hint("name the array that gets one element per object: `each: \"markers\"`"));
            }
            (ValueType::Any, _) => ValueType::Any,
            (ty, _) => ty.clone(),
        };
        let element = each.as_ref().map_or(schema.root_index(), |(_, s)| *s);
        let mut entries: Vec<(Path, Source)> = Vec::new();
        let mut set_texts: Vec<String> = Vec::new();
        for (i, text) in spec.entries.iter().enumerate() {
            let ((pat, path_text), (sat, source_text)) = split_entry(text, "map", i)?;
            let path = resolve(&schema, element, path_text, "map", Some(i), pat)?;
            let srange = (sat, sat + source_text.len());
            let source = parse_source(source_text);
            let ok = match (&source, path.end) {
                (Source::Symbol, End::Primitive(Primitive::String(_))) => true,
                (Source::Number, End::Primitive(p)) => p.size().is_some() && !matches!(p, Primitive::Bool),
                (Source::Literal(lit), end) => literal_fits(lit, end),
                (Source::Attribute(a), end) => match &record {
                    ValueType::Record(ty) => {
                        match ty.field(a).map(|f| &f.ty).or_else(|| kpl_core::object_status_type(a)) {
                            Some(aty) => fits(aty, end),
                            None => {
                                let names: Vec<&str> = ty.fields.iter().map(|f| &*f.name).collect();
                                let e = MapError::new(
                                    "map",
                                    Some(i),
                                    srange,
                                    format!("`{}` has no attribute `{a}`", ty.name),
                                );
                                return Err(match closest(a, &names) {
                                Some(n) => e.hint(format!("did you mean `{n}`?")),
                                None => e.hint("a value is an attribute, `symbol`, `number` or a literal (\"map\", 1.0, true)"),
                            });
                            }
                        }
                    }
                    _ => true,
                },
                _ => false,
            };
            if !ok {
                return Err(MapError::new(
                    "map",
                    Some(i),
                    srange,
                    format!(
                        "`{source_text}` does not fit `{path_text}`, which is {}",
                        describe_end(&schema, path.end)
                    ),
                )
                .hint(
                    "`symbol` fills a string, `number` an integer or float, a vec2 a message with x and y",
                ));
            }
            let source = match (source, path.end) {
                (
                    Source::Literal(MsgValue::Int(n)),
                    End::Primitive(Primitive::Float32 | Primitive::Float64),
                ) => Source::Literal(MsgValue::Float(n as f64)),
                (Source::Literal(MsgValue::Int(n)), End::Primitive(p)) if is_unsigned(p) => {
                    match u64::try_from(n) {
                        Ok(u) => Source::Literal(MsgValue::UInt(u)),
                        Err(_) => {
                            return Err(MapError::new(
                                "map",
                                Some(i),
                                srange,
                                format!("`{path_text}` is a {}: {n} is negative", p.msg_name()),
                            ));
                        }
                    }
                }
                (source, _) => source,
            };
            set_texts.push(path_text.to_string());
            entries.push((path, source));
        }
        let header_stamp = |start: usize| {
            resolve(&schema, start, "header.stamp", "map", None, 0)
                .ok()
                .filter(|p| p.end == End::Time)
                .map(|p| p.indices)
        };
        let root_stamp = header_stamp(schema.root_index());
        let element_stamp = each
            .as_ref()
            .and_then(|(_, s)| header_stamp(*s))
            .filter(|_| !set_texts.iter().any(|t| t == "header.stamp" || t == "header"));
        let plan = EncodePlan::compile(
            &schema,
            each.as_ref(),
            &entries,
            root_stamp.as_ref(),
            element_stamp.as_ref(),
        );
        Ok(OutMap { schema, each, entries, root_stamp, element_stamp, numbers: FxHashMap::default(), plan })
    }

    /// The message of one sample in CDR (with its encapsulation header), into `out` (cleared
    /// first): the bytes of `cdr::encode(OutMap::apply(..))`, written by the mapping's encode plan
    /// (crate::plan) without building the message, or by that tree path where the plan does not
    /// cover the mapping or fails on the sample (for its exact error).
    pub fn encode_into(&mut self, valid: Time, value: &Value, out: &mut Vec<u8>) -> Result<(), String> {
        if let Some(plan) = &self.plan
            && plan.encode(&self.entries, &mut self.numbers, valid, value, out).is_ok()
        {
            return Ok(());
        }
        self.encode_tree(valid, value, out)
    }

    /// [`OutMap::encode_into`] by the tree path: the message built, then encoded.
    pub fn encode_tree(&mut self, valid: Time, value: &Value, out: &mut Vec<u8>) -> Result<(), String> {
        let msg = self.apply(valid, value)?;
        crate::cdr::encode_into(&self.schema, &msg, out).map_err(|e| e.to_string())
    }

    /// [`OutMap::encode_into`] by the plan alone (`None`: no plan, `Some(false)`: the plan
    /// refuses the sample), for the differential tests.
    #[doc(hidden)]
    pub fn encode_plan_only(&mut self, valid: Time, value: &Value, out: &mut Vec<u8>) -> Option<bool> {
        let plan = self.plan.as_ref()?;
        Some(plan.encode(&self.entries, &mut self.numbers, valid, value, out).is_ok())
    }

    /// The message of one sample: `value` at valid time `valid`.
    pub fn apply(&mut self, valid: Time, value: &Value) -> Result<MsgValue, String> {
        let mut msg = json::default_value(&self.schema);
        if let Some(stamp) = &self.root_stamp {
            set_time(&mut msg, stamp, valid);
        }
        match self.each.clone() {
            None => self.fill(&mut msg, valid, value)?,
            Some((path, element)) => {
                let items = match value {
                    Value::List(items) => items.clone(),
                    other => Arc::from(vec![other.clone()]),
                };
                let mut out = Vec::with_capacity(items.len());
                for item in items.iter() {
                    let mut m = json::default_struct(&self.schema, element);
                    self.fill(&mut m, valid, item)?;
                    out.push(m);
                }
                if let Some(slot) = get_mut(&mut msg, &path) {
                    *slot = MsgValue::List(out);
                }
            }
        }
        Ok(msg)
    }

    fn fill(&mut self, msg: &mut MsgValue, valid: Time, value: &Value) -> Result<(), String> {
        if let Some(stamp) = &self.element_stamp
            && self.each.is_some()
        {
            set_time(msg, stamp, valid);
        }
        let record = value.as_record();
        for (path, source) in &self.entries {
            let v = match source {
                Source::Literal(lit) => lit.clone(),
                Source::Symbol => {
                    MsgValue::Str(record.and_then(|r| r.id.as_deref()).unwrap_or_default().to_string())
                }
                Source::Number => {
                    let n = number_of(record.and_then(|r| r.id.as_deref()).unwrap_or(""), &mut self.numbers);
                    number_value(n as f64, path.end)
                }
                Source::Attribute(a) => {
                    let v = value.field(a).ok_or_else(|| format!("no attribute `{a}`"))?;
                    to_msg(&v, path.end).ok_or_else(|| format!("`{a}` does not fit its field"))?
                }
            };
            let slot = get_mut(msg, &path.indices).ok_or("a field is missing")?;
            match (path.end, v) {
                (End::Xy(x, y, _), MsgValue::List(xy)) => {
                    if let MsgValue::Struct(f) = slot {
                        let kind = |f: &MsgValue| matches!(f, MsgValue::Float(_));
                        for (i, value) in [(x, &xy[0]), (y, &xy[1])] {
                            if let Some(field) = f.get_mut(i) {
                                *field = if kind(field) {
                                    value.clone()
                                } else {
                                    MsgValue::Int(value.as_f64().unwrap_or(0.0) as i64)
                                };
                            }
                        }
                    }
                }
                (_, v) => *slot = v,
            }
        }
        Ok(())
    }
}

/// How many symbols without trailing digits [`number_of`] remembers; later ones are numbered by
/// their text's hash, so that the map never grows past this on any input.
pub(crate) const NUMBERED_MAX: usize = 65_536;

/// A number that stays with a symbol: its trailing digits (`co12` is 12; nothing is remembered),
/// or else the next free number from 1,000,000 in order of appearance (the first
/// [`NUMBERED_MAX`] such symbols), or else a number from 1,000,000 + `NUMBERED_MAX` up to
/// `i32::MAX` (an `int32` field takes it) picked by the symbol's hash: the same in every run,
/// shared by two symbols now and then.
pub(crate) fn number_of(symbol: &str, numbers: &mut FxHashMap<Arc<str>, i64>) -> i64 {
    let digits = symbol.len() - symbol.bytes().rev().take_while(u8::is_ascii_digit).count();
    if let Some(n) = symbol[digits..].parse::<i64>().ok().filter(|n| *n <= i64::from(i32::MAX)) {
        return n;
    }
    if let Some(&n) = numbers.get(symbol) {
        return n;
    }
    const FIRST: i64 = 1_000_000;
    if numbers.len() < NUMBERED_MAX {
        let n = FIRST + numbers.len() as i64;
        numbers.insert(Arc::from(symbol), n);
        return n;
    }
    let hashed = FIRST + NUMBERED_MAX as i64;
    let hash = rustc_hash::FxBuildHasher.hash_one(symbol);
    hashed + (hash % (i64::from(i32::MAX) - hashed + 1) as u64) as i64
}

pub(crate) fn number_value(n: f64, end: End) -> MsgValue {
    match end {
        End::Primitive(Primitive::Float32 | Primitive::Float64) => MsgValue::Float(n),
        End::Primitive(Primitive::Int8 | Primitive::Int16 | Primitive::Int32 | Primitive::Int64) => {
            MsgValue::Int(n as i64)
        }
        _ => MsgValue::UInt(n as u64),
    }
}

fn set_time(msg: &mut MsgValue, path: &[usize], t: Time) {
    if let Some(slot) = get_mut(msg, path) {
        *slot = time_value(t);
    }
}

pub(crate) fn time_value(t: Time) -> MsgValue {
    let sec = t.div_euclid(1_000_000);
    let nanosec = t.rem_euclid(1_000_000) * 1000;
    MsgValue::Struct(vec![
        MsgValue::Int(sec.clamp(i64::from(i32::MIN), i64::from(i32::MAX))),
        MsgValue::UInt(nanosec as u64),
    ])
}

fn parse_source(text: &str) -> Source {
    match text {
        "symbol" => Source::Symbol,
        "number" => Source::Number,
        "true" => Source::Literal(MsgValue::Bool(true)),
        "false" => Source::Literal(MsgValue::Bool(false)),
        _ if text.len() >= 2
            && (text.starts_with('"') && text.ends_with('"')
                || text.starts_with('\'') && text.ends_with('\'')) =>
        {
            Source::Literal(MsgValue::Str(text[1..text.len() - 1].to_string()))
        }
        _ => match (text.parse::<i64>(), text.parse::<f64>()) {
            (Ok(i), _) => Source::Literal(MsgValue::Int(i)),
            (_, Ok(x)) => Source::Literal(MsgValue::Float(x)),
            _ => Source::Attribute(text.into()),
        },
    }
}

fn is_unsigned(p: Primitive) -> bool {
    matches!(
        p,
        Primitive::Byte
            | Primitive::Char
            | Primitive::UInt8
            | Primitive::UInt16
            | Primitive::UInt32
            | Primitive::UInt64
    )
}

fn literal_fits(lit: &MsgValue, end: End) -> bool {
    use Primitive::*;
    match (lit, end) {
        (MsgValue::Bool(_), End::Primitive(Bool)) => true,
        (MsgValue::Str(_), End::Primitive(String(_))) => true,
        (MsgValue::Int(_), End::Primitive(p)) => p.size().is_some() && p != Bool,
        (MsgValue::Float(_), End::Primitive(Float32 | Float64)) => true,
        _ => false,
    }
}

fn fits(ty: &ValueType, end: End) -> bool {
    use Primitive::*;
    match (ty, end) {
        (ValueType::Vec2, End::Xy(..)) => true,
        (ValueType::Float, End::Primitive(Float32 | Float64)) => true,
        (ValueType::Int, End::Primitive(p)) => p.size().is_some() && p != Bool,
        (ValueType::Int, End::Time) => true,
        (ValueType::Duration, End::Duration) => true,
        (ValueType::Bool, End::Primitive(Bool)) => true,
        (ValueType::Str, End::Primitive(String(_))) => true,
        (ValueType::Any, _) => true,
        _ => false,
    }
}

/// A KPL value into the field at `end` (and for literal use, the stored value).
fn to_msg(v: &Value, end: End) -> Option<MsgValue> {
    Some(match (end, v) {
        (End::Xy(..), Value::Vec2([x, y])) => MsgValue::List(vec![MsgValue::Float(*x), MsgValue::Float(*y)]),
        (End::Time, Value::Int(t)) => time_value(*t),
        (End::Duration, Value::Duration(t)) => time_value(*t),
        (End::Primitive(Primitive::Float32 | Primitive::Float64), v) => MsgValue::Float(v.as_f64()?),
        (
            End::Primitive(Primitive::Int8 | Primitive::Int16 | Primitive::Int32 | Primitive::Int64),
            Value::Int(i),
        ) => MsgValue::Int(*i),
        (End::Primitive(p), Value::Int(i)) if p.size().is_some() => MsgValue::UInt(u64::try_from(*i).ok()?),
        (End::Primitive(Primitive::Bool), Value::Bool(b)) => MsgValue::Bool(*b),
        (End::Primitive(Primitive::String(_)), Value::Str(s)) => MsgValue::Str(s.to_string()),
        _ => return None,
    })
}

/// The mappings the benchmarks run and the differential tests check (`kpl bench ros2`,
/// `benches/cdr.rs`, `tests/plans.rs`), in one place.
pub mod workloads {
    /// specs/ros2/markers.kpl's `/kpl/cars` publication: a car as a marker of a
    /// `visualization_msgs/msg/MarkerArray` (`each: "markers"`). `tests/plans.rs` checks that it
    /// is the spec's text.
    pub const MARKERS_OF_CARS: &[&str] = &[
        "header.frame_id = 'map'",
        "ns = symbol",
        "id = number",
        "type = 1",
        "pose.position = pos",
        "pose.orientation.w = 1.0",
        "scale.x = size",
        "scale.y = 1.8",
        "scale.z = 1.5",
        "color.g = 0.8",
        "color.a = 1.0",
        "lifetime.nanosec = 500000000",
    ];
    /// specs/ros2/markers.kpl's `/tracker/markers` subscription: a percept per marker
    /// (`each: "markers"`, `identity: "id"`).
    pub const PERCEPTS_OF_MARKERS: &[&str] = &["pos = pose.position", "size = scale.x"];
    /// A pose as a `geometry_msgs/msg/PoseStamped`: a later entry sets a field (`z`) that an
    /// earlier one (`pos`) set too.
    pub const POSE_STAMPED: &[&str] = &[
        "header.frame_id = 'map'",
        "pose.position = pos",
        "pose.position.z = z",
        "pose.orientation.z = yaw_z",
        "pose.orientation.w = yaw_w",
    ];
    /// The pose read back from the `PoseStamped`.
    pub const POSE_OF_POSE_STAMPED: &[&str] = &[
        "pos = pose.position",
        "z = pose.position.z",
        "yaw_z = pose.orientation.z",
        "yaw_w = pose.orientation.w",
    ];
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Definitions;

    fn record_list(name: &str, symbol: &str) -> ValueType {
        let fields = [("pos", ValueType::Vec2), ("size", ValueType::Float)]
            .map(|(n, ty)| kpl_core::FieldType { name: n.into(), ty })
            .to_vec();
        let ty = RecordType { name: name.into(), parent: None, symbol: symbol.into(), fields };
        ValueType::List(Box::new(ValueType::Record(ty.into())))
    }

    fn percept() -> ValueType {
        record_list("VisionPercept", "vp")
    }

    fn markers_in(entries: &[&str]) -> Result<InMap, MapError> {
        let defs = Definitions::builtin();
        let schema = defs.schema_of("visualization_msgs/msg/MarkerArray").unwrap();
        let spec = InSpec {
            each: Some("markers".into()),
            identity: Some("id".into()),
            stamp: None,
            entries: entries.iter().map(|s| s.to_string()).collect(),
        };
        InMap::compile(&schema, &spec, &percept())
    }

    #[test]
    fn markers_to_percepts_and_back() {
        let defs = Definitions::builtin();
        let schema = defs.schema_of("visualization_msgs/msg/MarkerArray").unwrap();
        let map = markers_in(&["pos = pose.position", "size = scale.x"]).unwrap();
        let car = record_list("Car", "co");
        let out_spec = OutSpec {
            each: Some("markers".into()),
            entries: [
                "ns = symbol",
                "id = number",
                "pose.position = pos",
                "scale.x = size",
                "header.frame_id = \"map\"",
                "pose.orientation.w = 1.0",
            ]
            .map(String::from)
            .to_vec(),
        };
        let mut out = OutMap::compile(schema.clone(), &out_spec, &car).unwrap();
        let cars = Value::List(
            vec![Value::Record(Arc::new(Record {
                id: Some("co12".into()),
                fields: vec![("pos".into(), Value::vec2(3.5, -2.0)), ("size".into(), Value::Float(4.5))],
            }))]
            .into(),
        );
        let msg = out.apply(1_500_000, &cars).unwrap();
        let bytes = crate::cdr::encode(&schema, &msg).unwrap();
        let back = crate::cdr::decode(&schema, &bytes).unwrap();
        assert_eq!(map.valid_time(&back), Some(1_500_000));
        let Value::List(percepts) = map.apply(&back).unwrap() else { panic!() };
        let r = percepts[0].as_record().unwrap();
        assert_eq!(r.id.as_deref(), Some("vp12"));
        assert_eq!(r.get("pos"), Some(&Value::vec2(3.5, -2.0)));
        assert_eq!(r.get("size"), Some(&Value::Float(4.5)));
        let j = json::to_json(&schema, &back);
        assert_eq!(j["markers"][0]["ns"], "co12");
        assert_eq!(j["markers"][0]["header"]["frame_id"], "map");
        assert_eq!(j["markers"][0]["pose"]["orientation"]["w"], 1.0);
    }

    /// `number`: the digits of a symbol that ends in them, remembering nothing; a number of its own
    /// for another symbol, the same every time, and no more than `NUMBERED_MAX` remembered.
    #[test]
    fn numbers_stay_with_symbols_in_bounded_memory() {
        let mut numbers = FxHashMap::default();
        let mut number = |s: &str| number_of(s, &mut numbers);
        assert_eq!(
            (number("co12"), number("wo7"), number("7"), number("co99999999999")),
            (12, 7, 7, 1_000_000)
        );
        assert_eq!((number("x"), number("co99999999999"), number("x")), (1_000_001, 1_000_000, 1_000_001));
        let mut first = Vec::new();
        for i in 0..NUMBERED_MAX + 100 {
            let s = format!("car-{i}-x");
            let n = number(&s);
            assert!((1_000_000..=i64::from(i32::MAX)).contains(&n), "{s}: {n}");
            assert_eq!(number(&s), n, "{s} changed its number");
            first.push(n);
        }
        assert_eq!(numbers.len(), NUMBERED_MAX);
        let again: Vec<i64> =
            (0..NUMBERED_MAX + 100).map(|i| number_of(&format!("car-{i}-x"), &mut numbers)).collect();
        assert_eq!(again, first);
    }

    /// A tracker's ids come again in every message: the decode plan makes each one's symbol
    /// once and hands out the same one after, and keeps no more than `Symbols::MAX` of them.
    #[test]
    fn the_decode_plan_keeps_symbols_of_ids_bounded() {
        let defs = Definitions::builtin();
        let schema = defs.schema_of("visualization_msgs/msg/MarkerArray").unwrap();
        let map = markers_in(&["pos = pose.position", "size = scale.x"]).unwrap();
        let plan = map.plan.as_ref().expect("markers.kpl's mapping has a plan");
        let spec = OutSpec {
            each: Some("markers".into()),
            entries: ["id = number", "pose.position = pos", "scale.x = size"].map(String::from).to_vec(),
        };
        let mut out = OutMap::compile(schema.clone(), &spec, &record_list("Car", "co")).unwrap();
        let mut message = |ids: &[u32]| {
            let cars: Vec<Value> = ids
                .iter()
                .map(|i| {
                    let fields =
                        vec![("pos".into(), Value::vec2(1.0, 2.0)), ("size".into(), Value::Float(4.0))];
                    Value::Record(Arc::new(Record { id: Some(format!("co{i}").into()), fields }))
                })
                .collect();
            let mut bytes = Vec::new();
            out.encode_into(0, &Value::List(cars.into()), &mut bytes).unwrap();
            bytes
        };
        let symbols = |bytes: &[u8]| -> Vec<Arc<str>> {
            let (_, Value::List(list)) = map.decode(bytes).unwrap() else { panic!("not a list") };
            list.iter().map(|v| v.as_record().unwrap().id.clone().unwrap()).collect()
        };
        let first = symbols(&message(&[7, 8]));
        let again = symbols(&message(&[8, 7]));
        assert_eq!((&*first[0], &*first[1], &*again[0], &*again[1]), ("vp7", "vp8", "vp8", "vp7"));
        assert!(Arc::ptr_eq(&first[0], &again[1]) && Arc::ptr_eq(&first[1], &again[0]));
        assert_eq!(plan.symbols_held(), 2);
        for start in (0..2 * crate::plan::Symbols::MAX as u32).step_by(100) {
            let ids: Vec<u32> = (start..start + 100).collect();
            let got = symbols(&message(&ids));
            assert!(got.iter().zip(&ids).all(|(s, i)| **s == *format!("vp{i}")));
            assert!(plan.symbols_held() <= crate::plan::Symbols::MAX);
        }
    }

    #[test]
    fn errors_point_into_the_entry() {
        let e = markers_in(&["pos = pose.positon", "size = scale.x"]).unwrap_err();
        assert_eq!((e.entry, e.range), (Some(0), (11, 18)));
        assert_eq!(e.hint.as_deref(), Some("did you mean `position`?"));
        let e = markers_in(&["pos = pose.position", "size = ns"]).unwrap_err();
        assert_eq!((e.entry, e.range), (Some(1), (7, 9)));
        let e = markers_in(&["pos = pose.position"]).unwrap_err();
        assert!(e.message.contains("nothing sets `size`"), "{e}");
        let e = markers_in(&["pos = pose.position", "siz = scale.x"]).unwrap_err();
        assert_eq!(e.hint.as_deref(), Some("did you mean `size`?"));
        let e = markers_in(&["pos pose.position"]).unwrap_err();
        assert_eq!(e.entry, Some(0));
    }
}
