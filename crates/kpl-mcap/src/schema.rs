//! JSON schemas (the `jsonschema` schema encoding of MCAP) of KPL types, so that a tool opening a
//! recording knows each stream's fields without KPL: records are objects with their attributes
//! (and the symbol `id`), vectors and boxes arrays of 2 and 4 numbers, durations integer
//! microseconds.

use kpl_core::ValueType;
use serde_json::{Map, Value as Json, json};

/// The schema of a value of type `ty`, as `Value::to_json` writes it.
pub fn value_schema(ty: &ValueType) -> Json {
    match ty {
        ValueType::Any => json!({}),
        ValueType::Bool => json!({"type": "boolean"}),
        ValueType::Int => json!({"type": "integer"}),
        ValueType::Float => json!({"type": "number"}),
        ValueType::Str => json!({"type": "string"}),
        ValueType::Duration => json!({"type": "integer", "description": "duration, microseconds"}),
        ValueType::Vec2 => numbers(2, "vec2: [x, y]"),
        ValueType::BBox => numbers(4, "box: [x1, y1, x2, y2]"),
        ValueType::List(item) => json!({"type": "array", "items": value_schema(item)}),
        ValueType::Record(record) => {
            let mut properties = Map::new();
            properties.insert("id".into(), json!({"type": "string", "description": "the object's symbol"}));
            for field in &record.fields {
                properties.insert(field.name.to_string(), value_schema(&field.ty));
            }
            let required: Vec<&str> = record.fields.iter().map(|f| &*f.name).collect();
            json!({
                "title": &*record.name,
                "type": "object",
                "properties": properties,
                "required": required,
            })
        }
    }
}

fn numbers(n: usize, description: &str) -> Json {
    json!({
        "type": "array",
        "items": {"type": "number"},
        "minItems": n,
        "maxItems": n,
        "description": description,
    })
}

/// The schema of a message of a KPL channel: a sample of type `ty` with its times.
pub fn sample_schema(ty: &ValueType) -> Json {
    json!({
        "title": format!("KPL sample of {ty}"),
        "type": "object",
        "properties": {
            "valid": {"type": "integer", "description": "valid time, microseconds"},
            "available": {"type": "integer", "description": "available time, microseconds"},
            "value": value_schema(ty),
        },
        "required": ["valid", "available", "value"],
    })
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use kpl_core::{FieldType, RecordType};

    use super::*;

    #[test]
    fn records_are_objects_with_their_attributes() {
        let percept = ValueType::Record(Arc::new(RecordType {
            name: "VisionPercept".into(),
            parent: None,
            symbol: "vp".into(),
            fields: vec![
                FieldType { name: "pos".into(), ty: ValueType::Vec2 },
                FieldType { name: "size".into(), ty: ValueType::Float },
            ],
        }));
        let schema = sample_schema(&ValueType::List(Box::new(percept)));
        assert_eq!(schema["title"], "KPL sample of list<VisionPercept>");
        let item = &schema["properties"]["value"]["items"];
        assert_eq!(item["title"], "VisionPercept");
        assert_eq!(item["required"], json!(["pos", "size"]));
        assert_eq!(item["properties"]["pos"]["maxItems"], 2);
        assert_eq!(item["properties"]["size"], json!({"type": "number"}));
        assert_eq!(item["properties"]["id"]["type"], "string");
    }
}
