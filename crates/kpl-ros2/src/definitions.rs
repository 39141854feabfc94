//! The message definitions a run knows (the shipped packages and a user's own `.msg` folders) and
//! the [`Schema`] of one type: that type and every type it uses, resolved to indices, which the
//! codec, the hash and the mapping's checker walk.
//!
//! ```
//! let defs = kpl_ros2::Definitions::builtin();
//! let schema = defs.schema_of("geometry_msgs/msg/PoseStamped").unwrap();
//! assert_eq!(schema.root().fields.len(), 2);
//! assert!(schema.type_hash().starts_with("RIHS01_"));
//! ```

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::msg::{self, ArrayKind, BaseType, MessageDef, MsgError, Primitive, TypeName};

/// Message definitions by full name.
#[derive(Debug, Clone, Default)]
pub struct Definitions {
    types: BTreeMap<TypeName, Arc<MessageDef>>,
    /// Where each user definition came from (for messages).
    origins: HashMap<TypeName, PathBuf>,
}

/// A problem with a definition or a folder of them.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DefError {
    #[error("{}:{}: {}", path.display(), error.line, error.message)]
    Parse { path: PathBuf, error: MsgError },
    #[error("{}: {message}", path.display())]
    Io { path: PathBuf, message: String },
    #[error("unknown message type `{name}`")]
    Unknown { name: String, hint: Option<String> },
    #[error("`{from}` uses `{missing}`, which is not defined")]
    Missing { from: String, missing: String },
    #[error("`{name}` contains itself (through {path}); ROS 2 messages cannot")]
    Recursive { name: String, path: String },
    #[error("`{name}` uses `wstring`, which kpl does not encode (docs/ros2.md)")]
    WString { name: String },
}

impl DefError {
    /// A hint for a user: the closest known name, where there is one.
    pub fn hint(&self) -> Option<&str> {
        match self {
            DefError::Unknown { hint, .. } => hint.as_deref(),
            _ => None,
        }
    }
}

impl Definitions {
    /// The packages that ship with kpl (`msgs/`): builtin_interfaces, std_msgs, geometry_msgs,
    /// sensor_msgs, nav_msgs, visualization_msgs, vision_msgs.
    pub fn builtin() -> Definitions {
        let mut defs = Definitions::default();
        for (package, name, text) in crate::builtin::BUILTIN {
            match msg::parse(package, name, text) {
                Ok(def) => {
                    defs.types.insert(def.name.clone(), Arc::new(def));
                }
                // The shipped files are parsed by a unit test; a failure here is a build defect.
                Err(e) => debug_assert!(false, "{package}/{name}: {e}"),
            }
        }
        defs
    }

    /// The shipped packages, parsed once per process.
    pub fn shipped() -> &'static Definitions {
        static SHIPPED: std::sync::OnceLock<Definitions> = std::sync::OnceLock::new();
        SHIPPED.get_or_init(Definitions::builtin)
    }

    /// Adds a parsed definition (replacing one of the same name).
    pub fn insert(&mut self, def: MessageDef) {
        self.types.insert(def.name.clone(), Arc::new(def));
    }

    /// Adds the `.msg` files of a folder: `<folder>/<package>/msg/<Name>.msg` or
    /// `<folder>/<package>/<Name>.msg`, or, for a folder that is itself a package,
    /// `<folder>/msg/<Name>.msg` or `<folder>/<Name>.msg` (the package is the folder's name).
    /// Returns how many it added, or every problem it found.
    pub fn add_folder(&mut self, folder: &Path) -> Result<usize, Vec<DefError>> {
        let mut files = Vec::new();
        let mut errors = Vec::new();
        collect_msg_files(folder, 0, &mut files, &mut errors);
        files.sort();
        let mut added = 0;
        for path in files {
            let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_string();
            let Some(package) = package_of(&path) else {
                errors.push(DefError::Io {
                    path: path.clone(),
                    message: "cannot tell its package: put it in `<package>/msg/`".into(),
                });
                continue;
            };
            // A message definition is a few KiB; a file past 1 MiB (or `/dev/zero`) is refused.
            let text = match kpl_core::read::read_file(&path, 1 << 20) {
                Ok(bytes) => match String::from_utf8(bytes) {
                    Ok(text) => text,
                    Err(_) => {
                        errors.push(DefError::Io { path, message: "not UTF-8 text".into() });
                        continue;
                    }
                },
                Err(e) => {
                    errors.push(DefError::Io { path, message: std::io::Error::from(e).to_string() });
                    continue;
                }
            };
            match msg::parse(&package, &name, &text) {
                Ok(def) => {
                    self.origins.insert(def.name.clone(), path);
                    self.insert(def);
                    added += 1;
                }
                Err(error) => errors.push(DefError::Parse { path, error }),
            }
        }
        if errors.is_empty() { Ok(added) } else { Err(errors) }
    }

    /// The schema of a recording's channel as rosbag2 and Foxglove write it (schema encoding
    /// `ros2msg`): the `.msg` text of `name`, then for each type it uses a line of `=`, a line
    /// `MSG: pkg/Name` (or `pkg/msg/Name`) and that type's text. The recording's definitions
    /// take the place of shipped ones of the same name; a type it does not define must be
    /// shipped.
    pub fn schema_of_ros2msg(&self, name: &str, text: &str) -> Result<Arc<Schema>, String> {
        let root = TypeName::parse(name).ok_or_else(|| format!("`{name}` is not a message type name"))?;
        let mut defs = self.clone();
        let mut current = root.clone();
        let mut section = String::new();
        let add = |defs: &mut Definitions, ty: &TypeName, text: &str| {
            msg::parse(&ty.package, &ty.name, text)
                .map(|def| defs.insert(def))
                .map_err(|e| format!("the definition of `{ty}`, line {}: {}", e.line, e.message))
        };
        let mut lines = text.lines().peekable();
        while let Some(line) = lines.next() {
            let trimmed = line.trim();
            if trimmed.len() >= 3 && trimmed.bytes().all(|b| b == b'=') {
                add(&mut defs, &current, &section)?;
                section.clear();
                let header = lines.next().unwrap_or("").trim();
                let named = header.strip_prefix("MSG:").map(str::trim).and_then(TypeName::parse);
                current =
                    named.ok_or_else(|| format!("after a line of `=`, `{header}` is not `MSG: pkg/Name`"))?;
                continue;
            }
            section.push_str(line);
            section.push('\n');
        }
        add(&mut defs, &current, &section)?;
        defs.schema(&root).map_err(|e| e.to_string())
    }

    pub fn get(&self, name: &TypeName) -> Option<&Arc<MessageDef>> {
        self.types.get(name)
    }

    /// Every known type, by name.
    pub fn names(&self) -> impl Iterator<Item = &TypeName> {
        self.types.keys()
    }

    /// Where a user's definition was read from.
    pub fn origin(&self, name: &TypeName) -> Option<&Path> {
        self.origins.get(name).map(PathBuf::as_path)
    }

    /// The schema of a type named `pkg/msg/Name` (or `pkg/Name`).
    pub fn schema_of(&self, name: &str) -> Result<Arc<Schema>, DefError> {
        let type_name = TypeName::parse(name).ok_or_else(|| self.unknown(name))?;
        self.schema(&type_name)
    }

    /// The schema of a type: it and every type it uses, each once.
    pub fn schema(&self, name: &TypeName) -> Result<Arc<Schema>, DefError> {
        if !self.types.contains_key(name) {
            return Err(self.unknown(&name.to_string()));
        }
        let mut builder =
            SchemaBuilder { defs: self, index: HashMap::new(), structs: Vec::new(), stack: Vec::new() };
        let root = builder.add(name)?;
        Ok(Arc::new(Schema { root, structs: builder.structs }))
    }

    fn unknown(&self, name: &str) -> DefError {
        let short = name.rsplit('/').next().unwrap_or(name);
        let hint =
            self.types.keys().find(|t| &*t.name == short).map(|t| format!("did you mean `{t}`?")).or_else(
                || (!name.contains('/')).then(|| "name a message type as `package/msg/Name`".to_string()),
            );
        DefError::Unknown { name: name.to_string(), hint }
    }
}

fn collect_msg_files(dir: &Path, depth: usize, files: &mut Vec<PathBuf>, errors: &mut Vec<DefError>) {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) => {
            errors.push(DefError::Io { path: dir.to_path_buf(), message: e.to_string() });
            return;
        }
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() && depth < 3 {
            collect_msg_files(&path, depth + 1, files, errors);
        } else if path.extension().is_some_and(|e| e == "msg") {
            files.push(path);
        }
    }
}

/// `<package>/msg/X.msg` or `<package>/X.msg`.
fn package_of(path: &Path) -> Option<String> {
    let parent = path.parent()?;
    let dir = parent.file_name()?.to_str()?;
    let package = if dir == "msg" { parent.parent()?.file_name()?.to_str()? } else { dir };
    msg::is_package_name(package).then(|| package.to_string())
}

/// A type and every type it uses, resolved: `structs[root]` is the type itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Schema {
    root: usize,
    structs: Vec<StructDef>,
}

/// One message type of a schema.
#[derive(Debug, Clone, PartialEq)]
pub struct StructDef {
    pub def: Arc<MessageDef>,
    pub fields: Vec<SchemaField>,
}

/// A field whose nested type is an index into the schema's structs.
#[derive(Debug, Clone, PartialEq)]
pub struct SchemaField {
    pub name: Arc<str>,
    pub base: SchemaBase,
    pub array: ArrayKind,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SchemaBase {
    Primitive(Primitive),
    Struct(usize),
}

impl Schema {
    pub fn root(&self) -> &StructDef {
        &self.structs[self.root]
    }

    pub fn root_index(&self) -> usize {
        self.root
    }

    pub fn get(&self, index: usize) -> &StructDef {
        &self.structs[index]
    }

    pub fn structs(&self) -> &[StructDef] {
        &self.structs
    }

    pub fn name(&self) -> &TypeName {
        &self.root().def.name
    }

    /// The RIHS01 hash of the type (`RIHS01_<sha256 hex>`).
    pub fn type_hash(&self) -> String {
        crate::hash::rihs01(self)
    }

    /// The type's definition as rosbag2 writes it in a recording's schema (encoding `ros2msg`):
    /// the type's `.msg` text, then each type it uses once, in the order a depth-first walk of
    /// the fields meets them, as a line of 80 `=`, a line `MSG: pkg/Name` and that type's text.
    /// [`Definitions::schema_of_ros2msg`] reads it back.
    pub fn ros2msg(&self) -> String {
        let mut out = String::new();
        let mut seen = vec![false; self.structs.len()];
        let mut stack = vec![self.root];
        while let Some(i) = stack.pop() {
            if std::mem::replace(&mut seen[i], true) {
                continue;
            }
            let def = &self.structs[i].def;
            if i != self.root {
                if !out.ends_with('\n') {
                    out.push('\n');
                }
                out.push_str(&"=".repeat(80));
                out.push_str(&format!("\nMSG: {}/{}\n", def.name.package, def.name.name));
            }
            out.push_str(&def.text);
            // Pushed in reverse, so the first field's type is walked first.
            for field in self.structs[i].fields.iter().rev() {
                if let SchemaBase::Struct(j) = field.base
                    && !seen[j]
                {
                    stack.push(j);
                }
            }
        }
        out
    }
}

struct SchemaBuilder<'a> {
    defs: &'a Definitions,
    index: HashMap<TypeName, usize>,
    structs: Vec<StructDef>,
    stack: Vec<TypeName>,
}

impl SchemaBuilder<'_> {
    fn add(&mut self, name: &TypeName) -> Result<usize, DefError> {
        if let Some(&i) = self.index.get(name) {
            return Ok(i);
        }
        if self.stack.contains(name) {
            let path: Vec<String> = self.stack.iter().map(ToString::to_string).collect();
            return Err(DefError::Recursive { name: name.to_string(), path: path.join(" -> ") });
        }
        let def = match self.defs.types.get(name) {
            Some(def) => def.clone(),
            None => {
                let from = self.stack.last().map(ToString::to_string).unwrap_or_default();
                return Err(DefError::Missing { from, missing: name.to_string() });
            }
        };
        self.stack.push(name.clone());
        let mut fields = Vec::with_capacity(def.fields.len());
        for field in &def.fields {
            let base = match &field.ty.base {
                BaseType::Primitive(Primitive::WString(_)) => {
                    return Err(DefError::WString { name: name.to_string() });
                }
                BaseType::Primitive(p) => SchemaBase::Primitive(*p),
                BaseType::Nested(t) => SchemaBase::Struct(self.add(t)?),
            };
            fields.push(SchemaField { name: field.name.clone(), base, array: field.ty.array });
        }
        self.stack.pop();
        let i = self.structs.len();
        self.structs.push(StructDef { def, fields });
        self.index.insert(name.clone(), i);
        Ok(i)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_shipped_definition_parses_and_resolves() {
        assert_eq!(crate::builtin::BUILTIN.len(), Definitions::builtin().types.len());
        let defs = Definitions::builtin();
        for name in defs.names() {
            let schema = defs.schema(name).unwrap();
            assert_eq!(schema.name(), name);
        }
        for package in [
            "builtin_interfaces",
            "std_msgs",
            "geometry_msgs",
            "sensor_msgs",
            "nav_msgs",
            "visualization_msgs",
            "vision_msgs",
        ] {
            assert!(defs.names().any(|n| &*n.package == package), "{package}");
        }
    }

    #[test]
    fn a_schema_as_rosbag2_writes_it_reads_back_as_the_same_type() {
        let defs = Definitions::builtin();
        let empty = Definitions::default();
        for name in defs.names() {
            let schema = defs.schema(name).unwrap();
            let text = schema.ros2msg();
            // Every type it uses is in the text, once.
            let sections = text.matches("\nMSG: ").count();
            assert_eq!(sections, schema.structs().len() - 1, "{name}");
            let back = empty.schema_of_ros2msg(&name.to_string(), &text).unwrap();
            assert_eq!(back.type_hash(), schema.type_hash(), "{name}");
        }
        let text = defs.schema_of("geometry_msgs/msg/PoseStamped").unwrap().ros2msg();
        let order: Vec<&str> = text.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
        assert_eq!(
            order,
            [
                "std_msgs/Header",
                "builtin_interfaces/Time",
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion"
            ]
        );
    }

    #[test]
    fn unknown_missing_and_recursive_types_are_errors() {
        let defs = Definitions::builtin();
        let e = defs.schema_of("geometry_msgs/msg/Pose3").unwrap_err();
        assert!(matches!(e, DefError::Unknown { .. }));
        let e = defs.schema_of("PoseStamped").unwrap_err();
        assert_eq!(e.hint(), Some("did you mean `geometry_msgs/msg/PoseStamped`?"));
        let mut defs = Definitions::builtin();
        defs.insert(msg::parse("my", "A", "B b\n").unwrap());
        defs.insert(msg::parse("my", "B", "A[] a\n").unwrap());
        defs.insert(msg::parse("my", "C", "D d\n").unwrap());
        assert!(matches!(defs.schema_of("my/msg/A").unwrap_err(), DefError::Recursive { .. }));
        assert!(matches!(defs.schema_of("my/msg/C").unwrap_err(), DefError::Missing { .. }));
    }
}
