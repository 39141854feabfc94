//! ROS 2 message definitions (`.msg` files) as data: the parser and the model of a message type.
//!
//! The format is ROS 2's (rosidl's `.msg`): one field (`type name [default]`) or constant
//! (`type NAME=value`) per line, `#` comments, array suffixes `[]`, `[N]`, `[<=N]`, bounded strings
//! `string<=N`. Nested types are named `pkg/Name`, `pkg/msg/Name`, or `Name` within the same
//! package; `Header` alone is `std_msgs/msg/Header`. Parsing never panics: every problem is a
//! [`MsgError`] with its line and column.
//!
//! ```
//! let def = kpl_ros2::msg::parse("geometry_msgs", "Point", "float64 x\nfloat64 y\nfloat64 z\n").unwrap();
//! assert_eq!(def.fields.len(), 3);
//! assert_eq!(def.name.to_string(), "geometry_msgs/msg/Point");
//! ```

use std::fmt;
use std::sync::Arc;

/// A message type's full name: `package/msg/Name`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TypeName {
    pub package: Arc<str>,
    pub name: Arc<str>,
}

impl TypeName {
    pub fn new(package: &str, name: &str) -> TypeName {
        TypeName { package: package.into(), name: name.into() }
    }

    /// Reads `pkg/msg/Name` or `pkg/Name`; `None` for anything else.
    pub fn parse(text: &str) -> Option<TypeName> {
        let parts: Vec<&str> = text.split('/').collect();
        let (package, name) = match parts.as_slice() {
            [package, "msg", name] | [package, name] => (*package, *name),
            _ => return None,
        };
        (is_package_name(package) && is_type_name(name)).then(|| TypeName::new(package, name))
    }

    /// The DDS name rmw_zenoh puts in keys: `pkg::msg::dds_::Name_`.
    pub fn dds_name(&self) -> String {
        format!("{}::msg::dds_::{}_", self.package, self.name)
    }
}

impl fmt::Display for TypeName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/msg/{}", self.package, self.name)
    }
}

/// The primitive types of `.msg` files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Primitive {
    Bool,
    /// `byte`: an octet.
    Byte,
    /// `char`: an unsigned 8-bit integer in ROS 2.
    Char,
    Int8,
    UInt8,
    Int16,
    UInt16,
    Int32,
    UInt32,
    Int64,
    UInt64,
    Float32,
    Float64,
    /// `string` or `string<=N`.
    String(Option<u32>),
    /// `wstring` or `wstring<=N`: parsed and hashed, not encoded (docs/ros2.md).
    WString(Option<u32>),
}

impl Primitive {
    fn parse(word: &str) -> Option<Primitive> {
        use Primitive::*;
        Some(match word {
            "bool" => Bool,
            "byte" => Byte,
            "char" => Char,
            "int8" => Int8,
            "uint8" => UInt8,
            "int16" => Int16,
            "uint16" => UInt16,
            "int32" => Int32,
            "uint32" => UInt32,
            "int64" => Int64,
            "uint64" => UInt64,
            "float32" => Float32,
            "float64" => Float64,
            "string" => String(None),
            "wstring" => WString(None),
            _ => return None,
        })
    }

    /// The size in bytes of a fixed-size primitive (its CDR alignment too); `None` for strings.
    pub fn size(self) -> Option<usize> {
        use Primitive::*;
        match self {
            Bool | Byte | Char | Int8 | UInt8 => Some(1),
            Int16 | UInt16 => Some(2),
            Int32 | UInt32 | Float32 => Some(4),
            Int64 | UInt64 | Float64 => Some(8),
            String(_) | WString(_) => None,
        }
    }

    /// Whether an array of this type is a byte string (`uint8[]`, `byte[]`, `char[]`).
    pub fn is_octet(self) -> bool {
        matches!(self, Primitive::Byte | Primitive::Char | Primitive::UInt8)
    }

    /// The name in `.msg` syntax.
    pub fn msg_name(self) -> String {
        use Primitive::*;
        match self {
            Bool => "bool".into(),
            Byte => "byte".into(),
            Char => "char".into(),
            Int8 => "int8".into(),
            UInt8 => "uint8".into(),
            Int16 => "int16".into(),
            UInt16 => "uint16".into(),
            Int32 => "int32".into(),
            UInt32 => "uint32".into(),
            Int64 => "int64".into(),
            UInt64 => "uint64".into(),
            Float32 => "float32".into(),
            Float64 => "float64".into(),
            String(None) => "string".into(),
            String(Some(n)) => format!("string<={n}"),
            WString(None) => "wstring".into(),
            WString(Some(n)) => format!("wstring<={n}"),
        }
    }
}

/// What a field holds, before any array suffix.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum BaseType {
    Primitive(Primitive),
    Nested(TypeName),
}

/// A field's array suffix.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ArrayKind {
    Single,
    /// `T[N]`
    Fixed(u32),
    /// `T[<=N]`
    Bounded(u32),
    /// `T[]`
    Unbounded,
}

/// A field's full type.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct FieldType {
    pub base: BaseType,
    pub array: ArrayKind,
}

impl fmt::Display for FieldType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.base {
            BaseType::Primitive(p) => write!(f, "{}", p.msg_name())?,
            BaseType::Nested(t) => write!(f, "{t}")?,
        }
        match self.array {
            ArrayKind::Single => Ok(()),
            ArrayKind::Fixed(n) => write!(f, "[{n}]"),
            ArrayKind::Bounded(n) => write!(f, "[<={n}]"),
            ArrayKind::Unbounded => write!(f, "[]"),
        }
    }
}

/// One field of a message.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    pub name: Arc<str>,
    pub ty: FieldType,
    /// The default value's text, as written (defaults are not on the wire nor in the hash).
    pub default: Option<String>,
    /// 1-based line in the definition's text.
    pub line: u32,
}

/// One constant of a message (`int32 ADD=0`): not on the wire nor in the hash.
#[derive(Debug, Clone, PartialEq)]
pub struct Constant {
    pub name: Arc<str>,
    pub ty: Primitive,
    pub value: String,
}

/// A parsed message definition.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageDef {
    pub name: TypeName,
    pub fields: Vec<Field>,
    pub constants: Vec<Constant>,
    /// The definition's text as read (rosbag2 schemas carry it).
    pub text: Arc<str>,
}

impl MessageDef {
    pub fn field(&self, name: &str) -> Option<(usize, &Field)> {
        self.fields.iter().enumerate().find(|(_, f)| &*f.name == name)
    }

    /// The message types this one names in its fields, in field order.
    pub fn dependencies(&self) -> impl Iterator<Item = &TypeName> {
        self.fields.iter().filter_map(|f| match &f.ty.base {
            BaseType::Nested(t) => Some(t),
            BaseType::Primitive(_) => None,
        })
    }
}

/// A problem in a `.msg` text, at a 1-based line and column.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{line}:{column}: {message}")]
pub struct MsgError {
    pub line: u32,
    pub column: u32,
    pub message: String,
}

/// Parses the text of `package/msg/name`.
pub fn parse(package: &str, name: &str, text: &str) -> Result<MessageDef, MsgError> {
    let err = |line: usize, column: usize, message: String| MsgError {
        line: line as u32 + 1,
        column: column as u32 + 1,
        message,
    };
    if !is_package_name(package) {
        return Err(err(
            0,
            0,
            format!("`{package}` is not a package name (lower case letters, digits, `_`)"),
        ));
    }
    if !is_type_name(name) {
        return Err(err(
            0,
            0,
            format!("`{name}` is not a message name (starts upper case; letters and digits)"),
        ));
    }
    let mut def = MessageDef {
        name: TypeName::new(package, name),
        fields: Vec::new(),
        constants: Vec::new(),
        text: text.into(),
    };
    for (index, raw) in text.lines().enumerate() {
        let indent = raw.len() - raw.trim_start().len();
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (type_word, rest) = match line.split_once(char::is_whitespace) {
            Some((t, r)) => (t, r.trim_start()),
            None => return Err(err(index, indent, format!("`{line}` has a type but no field name"))),
        };
        let rest_column = indent + line.len() - rest.len();
        let ty = parse_type(package, type_word).map_err(|m| err(index, indent, m))?;
        if let Some((constant, value)) = rest.split_once('=') {
            let BaseType::Primitive(p) = ty.base else {
                return Err(err(index, indent, "a constant must have a primitive type".into()));
            };
            if ty.array != ArrayKind::Single {
                return Err(err(index, indent, "a constant cannot be an array".into()));
            }
            let constant = constant.trim();
            if !is_constant_name(constant) {
                return Err(err(
                    index,
                    rest_column,
                    format!("`{constant}` is not a constant name (upper case letters, digits, `_`)"),
                ));
            }
            let value = match p {
                Primitive::String(_) | Primitive::WString(_) => value.trim(),
                _ => strip_comment(value).trim(),
            };
            def.constants.push(Constant { name: constant.into(), ty: p, value: value.to_string() });
            continue;
        }
        let rest = strip_comment(rest).trim();
        let (field, default) = match rest.split_once(char::is_whitespace) {
            Some((f, d)) => (f, Some(d.trim().to_string())),
            None => (rest, None),
        };
        if !is_field_name(field) {
            return Err(err(
                index,
                rest_column,
                format!(
                    "`{field}` is not a field name (lower case letter first; lower case letters, digits, single `_`)"
                ),
            ));
        }
        if def.fields.iter().any(|f| &*f.name == field) {
            return Err(err(index, rest_column, format!("field `{field}` is declared twice")));
        }
        def.fields.push(Field { name: field.into(), ty, default, line: index as u32 + 1 });
    }
    Ok(def)
}

fn strip_comment(text: &str) -> &str {
    match text.find('#') {
        Some(at) => &text[..at],
        None => text,
    }
}

/// Reads a field's type word (`float64`, `string<=5`, `geometry_msgs/Point[]`, `Header`, ...).
fn parse_type(package: &str, word: &str) -> Result<FieldType, String> {
    let (base_word, array) = match word.find('[') {
        Some(at) => {
            let Some(inner) = word[at + 1..].strip_suffix(']') else {
                return Err(format!("`{word}`: an array suffix ends with `]`"));
            };
            let array = if inner.is_empty() {
                ArrayKind::Unbounded
            } else if let Some(bound) = inner.strip_prefix("<=") {
                ArrayKind::Bounded(parse_bound(word, bound)?)
            } else {
                ArrayKind::Fixed(parse_bound(word, inner)?)
            };
            (&word[..at], array)
        }
        None => (word, ArrayKind::Single),
    };
    let base = if let Some((string, bound)) = base_word.split_once("<=") {
        let bound = Some(parse_bound(word, bound)?);
        match string {
            "string" => BaseType::Primitive(Primitive::String(bound)),
            "wstring" => BaseType::Primitive(Primitive::WString(bound)),
            _ => return Err(format!("`{word}`: only strings have a bound `<=N`")),
        }
    } else if let Some(p) = Primitive::parse(base_word) {
        BaseType::Primitive(p)
    } else {
        BaseType::Nested(resolve_type_name(package, base_word).ok_or_else(|| {
            format!("`{base_word}` is not a type: a primitive (`float64`, `string`, ...) or a message (`pkg/Name`)")
        })?)
    };
    Ok(FieldType { base, array })
}

fn parse_bound(word: &str, text: &str) -> Result<u32, String> {
    match text.parse::<u32>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!("`{word}`: `{text}` is not a size (a whole number from 1)")),
    }
}

/// A message type named in a field of `package`'s definition.
pub fn resolve_type_name(package: &str, word: &str) -> Option<TypeName> {
    match word {
        "Header" => Some(TypeName::new("std_msgs", "Header")),
        // ROS 1's time types, still accepted by rosidl.
        "time" => Some(TypeName::new("builtin_interfaces", "Time")),
        "duration" => Some(TypeName::new("builtin_interfaces", "Duration")),
        _ if word.contains('/') => TypeName::parse(word),
        _ => is_type_name(word).then(|| TypeName::new(package, word)),
    }
}

pub(crate) fn is_package_name(text: &str) -> bool {
    let mut chars = text.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_lowercase())
        && chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

pub(crate) fn is_type_name(text: &str) -> bool {
    let mut chars = text.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_uppercase()) && chars.all(|c| c.is_ascii_alphanumeric())
}

fn is_field_name(text: &str) -> bool {
    let mut chars = text.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_lowercase())
        && text.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !text.contains("__")
        && !text.ends_with('_')
}

fn is_constant_name(text: &str) -> bool {
    let mut chars = text.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_uppercase())
        && text.chars().all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_constants_arrays_and_bounds() {
        let text = "# comment\nint32 ADD=0 # add\nstring S= a # b\nHeader header\nPoint[] points\nstring<=5 name \"x\"\nfloat64[9] covariance\nint8[<=3] small 1\n";
        let def = parse("pkg", "Thing", text).unwrap();
        assert_eq!(def.constants.len(), 2);
        assert_eq!(def.constants[0].value, "0");
        assert_eq!(def.constants[1].value, "a # b");
        let types: Vec<String> = def.fields.iter().map(|f| f.ty.to_string()).collect();
        assert_eq!(types, ["std_msgs/msg/Header", "pkg/msg/Point[]", "string<=5", "float64[9]", "int8[<=3]"]);
        assert_eq!(def.fields[2].default.as_deref(), Some("\"x\""));
        assert_eq!(def.fields[1].line, 5);
    }

    #[test]
    fn errors_have_positions() {
        for (text, line, column) in [
            ("float64\n", 1, 1),
            ("float64 x\nflot64 y\n", 2, 1),
            ("float64 X\n", 1, 9),
            ("float64 x\nfloat64 x\n", 2, 9),
            ("float64[0] x\n", 1, 1),
            ("float64[ x\n", 1, 1),
            ("int32 lower=1\n", 1, 7),
            ("  pkg/Thing[] A=1\n", 1, 3),
        ] {
            let e = parse("pkg", "T", text).unwrap_err();
            assert_eq!((e.line, e.column), (line, column), "{text:?}: {e}");
        }
    }
}
