//! RIHS01 type hashes: the SHA-256 of a type's description (ROS 2's
//! `type_description_interfaces/TypeDescription`, REP 2011), as rosidl's
//! `rosidl_generator_type_description` computes it.
//!
//! The description is the type's fields (name, type id, capacity, string capacity, nested type
//! name; no defaults, no constants, no comments) and those of every type it references, sorted by
//! name, written as JSON with Python's default separators (`", "`, `": "`); an empty message has
//! the one field `structure_needs_at_least_one_member` (uint8), as on the wire.

use std::fmt::Write;

use ring::digest;

use crate::definitions::{Schema, SchemaBase, StructDef};
use crate::msg::{ArrayKind, Primitive};

/// The type's RIHS01 hash, `RIHS01_` and 64 hex digits.
pub fn rihs01(schema: &Schema) -> String {
    let json = description_json(schema);
    let digest = digest::digest(&digest::SHA256, json.as_bytes());
    let mut out = String::from("RIHS01_");
    for byte in digest.as_ref() {
        let _ = write!(out, "{byte:02x}");
    }
    out
}

/// The JSON text that is hashed.
pub fn description_json(schema: &Schema) -> String {
    let mut referenced: Vec<&StructDef> =
        (0..schema.structs().len()).filter(|&i| i != schema.root_index()).map(|i| schema.get(i)).collect();
    referenced.sort_by_key(|s| s.def.name.to_string());
    let mut out = String::from("{\"type_description\": ");
    write_struct(&mut out, schema, schema.root());
    out.push_str(", \"referenced_type_descriptions\": [");
    for (i, s) in referenced.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        write_struct(&mut out, schema, s);
    }
    out.push_str("]}");
    out
}

fn write_struct(out: &mut String, schema: &Schema, s: &StructDef) {
    let _ = write!(out, "{{\"type_name\": \"{}\", \"fields\": [", s.def.name);
    if s.fields.is_empty() {
        write_field(out, "structure_needs_at_least_one_member", 3, 0, 0, "");
    }
    for (i, field) in s.fields.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        let (base_id, string_capacity, nested) = match field.base {
            SchemaBase::Struct(j) => (1, 0, schema.get(j).def.name.to_string()),
            SchemaBase::Primitive(p) => {
                let (id, cap) = primitive_id(p);
                (id, cap, String::new())
            }
        };
        let (offset, capacity) = match field.array {
            ArrayKind::Single => (0, 0),
            ArrayKind::Fixed(n) => (48, n),
            ArrayKind::Bounded(n) => (96, n),
            ArrayKind::Unbounded => (144, 0),
        };
        write_field(out, &field.name, base_id + offset, capacity, string_capacity, &nested);
    }
    out.push_str("]}");
}

fn write_field(
    out: &mut String,
    name: &str,
    type_id: u32,
    capacity: u32,
    string_capacity: u32,
    nested: &str,
) {
    let _ = write!(
        out,
        "{{\"name\": \"{name}\", \"type\": {{\"type_id\": {type_id}, \"capacity\": {capacity}, \"string_capacity\": {string_capacity}, \"nested_type_name\": \"{nested}\"}}}}"
    );
}

/// `type_description_interfaces/FieldType`'s id of a primitive, and its string capacity.
/// `char` is a uint8 in ROS 2 (rosidl maps it so); `byte` is an octet.
fn primitive_id(p: Primitive) -> (u32, u32) {
    use Primitive::*;
    match p {
        Int8 => (2, 0),
        UInt8 | Char => (3, 0),
        Int16 => (4, 0),
        UInt16 => (5, 0),
        Int32 => (6, 0),
        UInt32 => (7, 0),
        Int64 => (8, 0),
        UInt64 => (9, 0),
        Float32 => (10, 0),
        Float64 => (11, 0),
        Bool => (15, 0),
        Byte => (16, 0),
        String(None) => (17, 0),
        WString(None) => (18, 0),
        String(Some(n)) => (21, n),
        WString(Some(n)) => (22, n),
    }
}

#[cfg(test)]
mod tests {
    use crate::Definitions;

    /// Hashes rosidl wrote into the ROS 2 packages' `share/<pkg>/msg/<Type>.json` (5.5.1).
    #[test]
    fn known_hashes() {
        let defs = Definitions::builtin();
        for (name, hash) in [
            ("std_msgs/msg/Char", "RIHS01_3ad2d04dd29ba19d04b16659afa3ccaedd691914b02a64e82e252f2fa6a586a9"),
            ("std_msgs/msg/Byte", "RIHS01_41e1a3345f73fe93ede006da826a6ee274af23dd4653976ff249b0f44e3e798f"),
            ("std_msgs/msg/Empty", "RIHS01_20b625256f32d5dbc0d04fee44f43c41e51c70d3502f84b4a08e7a9c26a96312"),
        ] {
            assert_eq!(defs.schema_of(name).unwrap().type_hash(), hash, "{name}");
        }
    }
}
