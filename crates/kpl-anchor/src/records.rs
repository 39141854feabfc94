//! Small helpers over object records (`kpl_core::Record`): reading a position, filling a record
//! of one type from a record of another, checking that a record has the fields of its type, and
//! the default value of each field type.

use std::sync::Arc;

use kpl_core::{Record, RecordType, Value, ValueType};

/// The `pos` attribute of a record, when it is a `vec2`.
pub fn position(record: &Record) -> Option<[f64; 2]> {
    record.get("pos").and_then(Value::as_vec2)
}

/// The `pos` attribute of an object value.
pub fn value_position(value: &Value) -> Option<[f64; 2]> {
    value.as_record().and_then(position)
}

/// The `vel` attribute of a record, when it is a `vec2`.
pub fn velocity(record: &Record) -> Option<[f64; 2]> {
    record.get("vel").and_then(Value::as_vec2)
}

/// The value a field of this type has when nothing sets it.
pub fn default_value(ty: &ValueType) -> Value {
    match ty {
        ValueType::Any | ValueType::Bool => Value::Bool(false),
        ValueType::Int => Value::Int(0),
        ValueType::Float => Value::Float(0.0),
        ValueType::Str => Value::str(""),
        ValueType::Vec2 => Value::Vec2([0.0, 0.0]),
        ValueType::BBox => Value::bbox(kpl_core::BBox::default()),
        ValueType::Duration => Value::Duration(0),
        ValueType::List(_) => Value::List(Arc::from(Vec::new())),
        ValueType::Record(_) => Value::Record(Arc::new(Record::default())),
    }
}

/// `value` as a field of type `ty`: itself when it fits, an int widened to a float, else `None`.
pub fn fit(value: &Value, ty: &ValueType) -> Option<Value> {
    match (ty, value) {
        (ValueType::Any, v) => Some(v.clone()),
        (ValueType::Bool, Value::Bool(_))
        | (ValueType::Int, Value::Int(_))
        | (ValueType::Float, Value::Float(_))
        | (ValueType::Str, Value::Str(_))
        | (ValueType::Vec2, Value::Vec2(_))
        | (ValueType::BBox, Value::BBox(_))
        | (ValueType::Duration, Value::Duration(_))
        | (ValueType::List(_), Value::List(_))
        | (ValueType::Record(_), Value::Record(_)) => Some(value.clone()),
        (ValueType::Float, Value::Int(i)) => Some(Value::Float(*i as f64)),
        _ => None,
    }
}

/// A record of type `to` with id `symbol`: each field is taken from `source` when it has a
/// field of that name that fits, else from `previous` (the object's last state), else the default.
pub fn fill(to: &RecordType, symbol: &Arc<str>, source: &Record, previous: Option<&Record>) -> Record {
    // Room for the status attributes the engine adds to an object's state.
    let mut fields = Vec::with_capacity(to.fields.len() + 2);
    fields.extend(to.fields.iter().map(|field| {
        let value = source
            .get(&field.name)
            .and_then(|v| fit(v, &field.ty))
            .or_else(|| previous.and_then(|p| p.get(&field.name)).and_then(|v| fit(v, &field.ty)))
            .unwrap_or_else(|| default_value(&field.ty));
        (field.name.clone(), value)
    }));
    Record { id: Some(symbol.clone()), fields }
}

/// `record` with the fields of `update` that it also has (same name, fitting type) replaced.
/// Used to carry a more specific object's predicted state back to the objects it came from.
pub fn overlay(record: &Record, update: &Record) -> Record {
    let fields = record
        .fields
        .iter()
        .map(|(name, value)| {
            let replaced =
                update.get(name).filter(|u| std::mem::discriminant(*u) == std::mem::discriminant(value));
            (name.clone(), replaced.cloned().unwrap_or_else(|| value.clone()))
        })
        .collect();
    Record { id: record.id.clone(), fields }
}

/// `record` with some fields set (fields it does not have are left out).
pub fn with_fields(record: &Record, updates: &[(&str, Value)]) -> Record {
    let fields = record
        .fields
        .iter()
        .map(|(name, value)| {
            let new = updates.iter().find(|(n, _)| *n == &**name).map(|(_, v)| v.clone());
            (name.clone(), new.unwrap_or_else(|| value.clone()))
        })
        .collect();
    Record { id: record.id.clone(), fields }
}

/// Why a record cannot be an object of type `ty`: a missing field or one of the wrong kind.
pub fn check_fields(record: &Record, ty: &RecordType) -> Result<(), String> {
    for field in &ty.fields {
        match record.get(&field.name) {
            None => return Err(format!("has no field `{}` ({})", field.name, field.ty)),
            Some(v) if fit(v, &field.ty).is_none() => {
                return Err(format!("field `{}` is {}, expected {}", field.name, v.kind(), field.ty));
            }
            Some(_) => {}
        }
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use kpl_core::FieldType;

    fn ty(fields: &[(&str, ValueType)]) -> RecordType {
        RecordType {
            name: "T".into(),
            parent: None,
            symbol: "t".into(),
            fields: fields.iter().map(|(n, t)| FieldType { name: (*n).into(), ty: t.clone() }).collect(),
        }
    }

    #[test]
    fn fill_takes_source_then_previous_then_default() {
        let to = ty(&[("pos", ValueType::Vec2), ("speed", ValueType::Float), ("road", ValueType::Int)]);
        let source = Record {
            id: None,
            fields: vec![("pos".into(), Value::vec2(1.0, 2.0)), ("speed".into(), Value::Int(3))],
        };
        let previous = Record { id: None, fields: vec![("road".into(), Value::Int(7))] };
        let out = fill(&to, &Arc::from("t1"), &source, Some(&previous));
        assert_eq!(out.id.as_deref(), Some("t1"));
        assert_eq!(out.get("pos"), Some(&Value::vec2(1.0, 2.0)));
        assert_eq!(out.get("speed"), Some(&Value::Float(3.0)));
        assert_eq!(out.get("road"), Some(&Value::Int(7)));
        let out = fill(&to, &Arc::from("t1"), &source, None);
        assert_eq!(out.get("road"), Some(&Value::Int(0)));
    }

    #[test]
    fn check_fields_names_the_problem() {
        let t = ty(&[("pos", ValueType::Vec2)]);
        let bad = Record { id: None, fields: vec![("pos".into(), Value::Float(1.0))] };
        assert!(check_fields(&bad, &t).unwrap_err().contains("`pos`"));
        assert!(check_fields(&Record::default(), &t).unwrap_err().contains("no field"));
    }

    #[test]
    fn overlay_replaces_shared_fields_of_the_same_kind() {
        let r = Record { id: Some("wo1".into()), fields: vec![("pos".into(), Value::vec2(0.0, 0.0))] };
        let u = Record {
            id: Some("oo1".into()),
            fields: vec![("pos".into(), Value::vec2(5.0, 1.0)), ("road".into(), Value::Int(2))],
        };
        let out = overlay(&r, &u);
        assert_eq!(out.id.as_deref(), Some("wo1"));
        assert_eq!(out.fields.len(), 1);
        assert_eq!(out.get("pos"), Some(&Value::vec2(5.0, 1.0)));
    }
}
