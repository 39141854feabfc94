//! Messages as JSON objects with their field names (`{"header": {"stamp": {...}, ...}, ...}`),
//! the form `ros2 topic echo --json`-like tools and the tests' oracles use, and each type's
//! default value (zeros, empty strings and sequences, fixed arrays filled).

use serde_json::{Map, Number, Value as Json};

use crate::cdr::MsgValue;
use crate::definitions::{Schema, SchemaBase, SchemaField};
use crate::msg::{ArrayKind, Primitive};

/// A message as JSON; `uint8`/`byte`/`char` arrays are lists of numbers, non-finite floats
/// `null`.
pub fn to_json(schema: &Schema, value: &MsgValue) -> Json {
    struct_to_json(schema, schema.root_index(), value)
}

fn struct_to_json(schema: &Schema, index: usize, value: &MsgValue) -> Json {
    let def = schema.get(index);
    let mut map = Map::new();
    for (field, v) in def.fields.iter().zip(value.fields()) {
        map.insert(field.name.to_string(), field_to_json(schema, field, v));
    }
    Json::Object(map)
}

fn field_to_json(schema: &Schema, field: &SchemaField, value: &MsgValue) -> Json {
    match value {
        MsgValue::List(items) => {
            Json::Array(items.iter().map(|v| base_to_json(schema, field.base, v)).collect())
        }
        MsgValue::Bytes(bytes) => Json::Array(bytes.iter().map(|&b| Json::from(b)).collect()),
        _ => base_to_json(schema, field.base, value),
    }
}

fn base_to_json(schema: &Schema, base: SchemaBase, value: &MsgValue) -> Json {
    match (base, value) {
        (SchemaBase::Struct(i), v) => struct_to_json(schema, i, v),
        (_, MsgValue::Bool(b)) => Json::Bool(*b),
        (_, MsgValue::Int(i)) => Json::from(*i),
        (_, MsgValue::UInt(u)) => Json::from(*u),
        (_, MsgValue::Float(x)) => Number::from_f64(*x).map_or(Json::Null, Json::Number),
        (_, MsgValue::Str(s)) => Json::String(s.clone()),
        _ => Json::Null,
    }
}

/// A message from JSON: every field must be there with a value of its type.
pub fn from_json(schema: &Schema, json: &Json) -> Result<MsgValue, String> {
    struct_from_json(schema, schema.root_index(), json, "")
}

fn struct_from_json(schema: &Schema, index: usize, json: &Json, path: &str) -> Result<MsgValue, String> {
    let def = schema.get(index);
    let Json::Object(map) = json else {
        return Err(format!("at `{path}`: expected an object for `{}`", def.def.name));
    };
    let mut values = Vec::with_capacity(def.fields.len());
    for field in &def.fields {
        let path = if path.is_empty() { field.name.to_string() } else { format!("{path}.{}", field.name) };
        let v = map.get(&*field.name).ok_or_else(|| format!("missing field `{path}`"))?;
        values.push(field_from_json(schema, field, v, &path)?);
    }
    Ok(MsgValue::Struct(values))
}

fn field_from_json(
    schema: &Schema,
    field: &SchemaField,
    json: &Json,
    path: &str,
) -> Result<MsgValue, String> {
    if field.array == ArrayKind::Single {
        return base_from_json(schema, field.base, json, path);
    }
    let Json::Array(items) = json else {
        return Err(format!("at `{path}`: expected an array"));
    };
    if let SchemaBase::Primitive(p) = field.base
        && p.is_octet()
    {
        let bytes: Option<Vec<u8>> =
            items.iter().map(|j| j.as_u64().and_then(|u| u8::try_from(u).ok())).collect();
        return bytes.map(MsgValue::Bytes).ok_or_else(|| format!("at `{path}`: expected bytes"));
    }
    let items: Result<Vec<MsgValue>, String> = items
        .iter()
        .enumerate()
        .map(|(i, j)| base_from_json(schema, field.base, j, &format!("{path}[{i}]")))
        .collect();
    Ok(MsgValue::List(items?))
}

fn base_from_json(schema: &Schema, base: SchemaBase, json: &Json, path: &str) -> Result<MsgValue, String> {
    use Primitive::*;
    let p = match base {
        SchemaBase::Struct(i) => return struct_from_json(schema, i, json, path),
        SchemaBase::Primitive(p) => p,
    };
    let wrong = || format!("at `{path}`: expected a {}, found {json}", p.msg_name());
    Ok(match p {
        Bool => MsgValue::Bool(json.as_bool().ok_or_else(wrong)?),
        Int8 | Int16 | Int32 | Int64 => MsgValue::Int(json.as_i64().ok_or_else(wrong)?),
        Byte | Char | UInt8 | UInt16 | UInt32 | UInt64 => MsgValue::UInt(json.as_u64().ok_or_else(wrong)?),
        Float32 | Float64 => MsgValue::Float(match json {
            Json::Null => f64::NAN,
            j => j.as_f64().ok_or_else(wrong)?,
        }),
        String(_) | WString(_) => MsgValue::Str(json.as_str().ok_or_else(wrong)?.to_string()),
    })
}

/// The type's default value: zeros, `false`, empty strings and sequences, fixed arrays of
/// defaults.
pub fn default_value(schema: &Schema) -> MsgValue {
    default_struct(schema, schema.root_index())
}

/// The default value of one struct of a schema.
pub fn default_struct(schema: &Schema, index: usize) -> MsgValue {
    let def = schema.get(index);
    MsgValue::Struct(def.fields.iter().map(|f| default_field(schema, f)).collect())
}

fn default_field(schema: &Schema, field: &SchemaField) -> MsgValue {
    let octet = matches!(field.base, SchemaBase::Primitive(p) if p.is_octet());
    match field.array {
        ArrayKind::Single => default_base(schema, field.base),
        ArrayKind::Fixed(n) if octet => MsgValue::Bytes(vec![0; n as usize]),
        ArrayKind::Fixed(n) => MsgValue::List((0..n).map(|_| default_base(schema, field.base)).collect()),
        ArrayKind::Bounded(_) | ArrayKind::Unbounded if octet => MsgValue::Bytes(Vec::new()),
        ArrayKind::Bounded(_) | ArrayKind::Unbounded => MsgValue::List(Vec::new()),
    }
}

fn default_base(schema: &Schema, base: SchemaBase) -> MsgValue {
    use Primitive::*;
    match base {
        SchemaBase::Struct(i) => default_struct(schema, i),
        SchemaBase::Primitive(p) => match p {
            Bool => MsgValue::Bool(false),
            Int8 | Int16 | Int32 | Int64 => MsgValue::Int(0),
            Byte | Char | UInt8 | UInt16 | UInt32 | UInt64 => MsgValue::UInt(0),
            Float32 | Float64 => MsgValue::Float(0.0),
            String(_) | WString(_) => MsgValue::Str(std::string::String::new()),
        },
    }
}
