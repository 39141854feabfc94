//! The registry of what a runtime provides: sources, computational units, link units, sinks,
//! prediction models and formula functions, each with its typed, documented parameters.
//!
//! Checking a spec only needs these signatures, not the implementations, so this crate stays
//! free of tokio. The runtime builds its registry of implementations and hands the signatures
//! over; `kpl list` prints them.
//!
//! ```
//! use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, Registry, TypeReq};
//! let mut registry = Registry::default();
//! registry.add(
//!     Entry::new(EntryKind::Source, "timer", "Emits a counter every period.")
//!         .param(Param::required("period", ParamType::Duration, "time between samples"))
//!         .output(TypeReq::Exact(kpl_core::ValueType::Int)),
//! );
//! assert!(registry.entry(EntryKind::Source, "timer").is_some());
//! ```

use std::collections::BTreeMap;
use std::fmt;

use kpl_core::{Value, ValueType};
use serde::Serialize;

/// What a registered name can be used as in a spec.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum EntryKind {
    /// `source NAME : TYPE = entry(...)`
    Source,
    /// `compute NAME : TYPE = entry(inputs..., params...)`
    Compute,
    /// `link ... via entry(...)`: computes the state of the linked-to object from the linked-from one.
    Link,
    /// `sink NAME = entry(inputs..., params...)`
    Sink,
    /// `predict TYPE = entry(...)`: how objects with no incoming link move.
    Predict,
}

impl EntryKind {
    pub const ALL: [EntryKind; 5] =
        [EntryKind::Source, EntryKind::Compute, EntryKind::Link, EntryKind::Sink, EntryKind::Predict];

    /// The word a user reads: "source", "computational unit", ...
    pub fn noun(self) -> &'static str {
        match self {
            EntryKind::Source => "source",
            EntryKind::Compute => "computational unit",
            EntryKind::Link => "link unit",
            EntryKind::Sink => "sink",
            EntryKind::Predict => "prediction model",
        }
    }
}

/// The type a parameter accepts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum ParamType {
    Bool,
    Int,
    /// Accepts integers too.
    Float,
    Str,
    /// A duration literal (`100ms`); the value is microseconds.
    Duration,
    /// One of the listed strings.
    Choice(Vec<String>),
    List(Box<ParamType>),
    Any,
}

impl fmt::Display for ParamType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamType::Bool => f.write_str("bool"),
            ParamType::Int => f.write_str("int"),
            ParamType::Float => f.write_str("float"),
            ParamType::Str => f.write_str("string"),
            ParamType::Duration => f.write_str("duration"),
            ParamType::Choice(options) => {
                let quoted: Vec<String> = options.iter().map(|o| format!("\"{o}\"")).collect();
                f.write_str(&quoted.join(" | "))
            }
            ParamType::List(item) => write!(f, "list<{item}>"),
            ParamType::Any => f.write_str("any"),
        }
    }
}

/// A named parameter of an entry.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Param {
    pub name: String,
    pub ty: ParamType,
    /// `None`: the parameter is required.
    #[serde(serialize_with = "serialize_default")]
    pub default: Option<Value>,
    pub doc: String,
    /// The attributes of the linked-to type that the parameter acts on (a link unit's): when
    /// it is given a value other than its default and the type declares none of them, it has no
    /// effect (warning W0207). Empty: it always acts.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub acts_on: Vec<String>,
}

fn serialize_default<S: serde::Serializer>(value: &Option<Value>, s: S) -> Result<S::Ok, S::Error> {
    match value {
        Some(v) => v.to_json().serialize(s),
        None => s.serialize_none(),
    }
}

impl Param {
    pub fn required(name: &str, ty: ParamType, doc: &str) -> Param {
        Param { name: name.into(), ty, default: None, doc: doc.into(), acts_on: Vec::new() }
    }
    pub fn optional(name: &str, ty: ParamType, default: Value, doc: &str) -> Param {
        Param { name: name.into(), ty, default: Some(default), doc: doc.into(), acts_on: Vec::new() }
    }
    /// Declares the linked-to type's attributes the parameter acts on ([`Param::acts_on`]).
    pub fn acting_on(mut self, attributes: &[&str]) -> Param {
        self.acts_on = attributes.iter().map(|a| a.to_string()).collect();
        self
    }
}

/// What a stream (input or output) must carry. Serializes as its text (`{ pos: vec2 }`).
#[derive(Debug, Clone, PartialEq)]
pub enum TypeReq {
    /// Anything.
    Any,
    /// Exactly this type (ints widen to floats).
    Exact(ValueType),
    /// A record with at least these fields.
    Fields(Vec<(String, ValueType)>),
    /// An object stream: a list of records with at least these fields (one per object present).
    Objects(Vec<(String, ValueType)>),
}

impl Serialize for TypeReq {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

fn serialize_display<S: serde::Serializer, T: fmt::Display>(value: &T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(value)
}

impl fmt::Display for TypeReq {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TypeReq::Any => f.write_str("any"),
            TypeReq::Exact(t) => write!(f, "{t}"),
            TypeReq::Fields(fields) => {
                let parts: Vec<String> = fields.iter().map(|(n, t)| format!("{n}: {t}")).collect();
                write!(f, "{{ {} }}", parts.join(", "))
            }
            TypeReq::Objects(fields) => {
                let parts: Vec<String> = fields.iter().map(|(n, t)| format!("{n}: {t}")).collect();
                write!(f, "list<{{ {} }}>", parts.join(", "))
            }
        }
    }
}

/// An input stream of an entry.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Port {
    pub name: String,
    pub ty: TypeReq,
    pub doc: String,
}

/// The input streams an entry takes, positionally.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Inputs {
    Fixed(Vec<Port>),
    /// Any number from `min` on, all of the same requirement.
    Variadic {
        min: usize,
        port: Port,
    },
}

impl Inputs {
    pub fn none() -> Inputs {
        Inputs::Fixed(Vec::new())
    }
}

/// A registered source, computational unit, link unit, sink or prediction model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Entry {
    pub kind: EntryKind,
    /// Dotted name as written in specs (`sim.uav_tracker`).
    pub name: String,
    /// One line: what it does.
    pub summary: String,
    pub params: Vec<Param>,
    pub inputs: Inputs,
    /// What the declared output type must satisfy (sources and computational units).
    pub output: TypeReq,
    /// Named extra outputs besides the default one, referenced as `process.port`.
    pub ports: Vec<Port>,
    /// Predicates and functions this entry makes available to the conditions of the links that
    /// use it (`on_road` for a unit that knows the road network).
    pub provides: Vec<Function>,
    /// Which attributes of the objects it produces this entry sets (link units); the checker
    /// warns about an attribute that nothing sets (W0204).
    pub computes: Computes,
    /// A check of the call's parameters against each other and the stream types, beyond each
    /// parameter's own type (a message mapping against its message definition): what it finds
    /// `kpl check` reports with the parameter's span (E0118).
    #[serde(skip)]
    pub check: Option<ParamCheck>,
    /// Named parameters beyond `params` are accepted (any literal) and given to the
    /// implementation as they are; this says what they are for (`python.unit`: the Python
    /// function's own keyword arguments). `None`: an unknown name is an error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extra_params: Option<String>,
}

/// What a parameter check sees of one call: its parameters (defaults filled in), the declared
/// output type (sources, units), the types of its input streams, in order, and the spec's folder,
/// where a parameter's relative path is read from (`None` for a spec without a file: standard
/// input, a string).
#[derive(Debug, Clone, Copy)]
pub struct CallTypes<'a> {
    pub params: &'a BTreeMap<String, Value>,
    pub output: Option<&'a ValueType>,
    pub inputs: &'a [ValueType],
    pub dir: Option<&'a std::path::Path>,
}

/// What is wrong with a call's parameters: the parameter, the element of a list parameter, the
/// byte range inside that string (empty: all of it), what is wrong and how to fix it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamProblem {
    pub param: String,
    pub element: Option<usize>,
    pub range: (usize, usize),
    pub message: String,
    pub hint: Option<String>,
}

/// A check of an entry's parameters at `kpl check` time ([`Entry::checked_by`]).
#[derive(Clone, Copy)]
pub struct ParamCheck(pub fn(&CallTypes<'_>) -> Vec<ParamProblem>);

impl fmt::Debug for ParamCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("ParamCheck")
    }
}

impl PartialEq for ParamCheck {
    fn eq(&self, other: &ParamCheck) -> bool {
        std::ptr::fn_addr_eq(self.0, other.0)
    }
}

/// Which attributes of its objects a unit sets.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Computes {
    /// Not declared (sources replaying data, units that fill in whatever they are given): every
    /// attribute counts as set.
    #[default]
    Unknown,
    /// These attributes, and with `copies_shared` every attribute that the linked-from object
    /// also has (same name).
    Attributes { names: Vec<String>, copies_shared: bool },
}

impl Computes {
    /// Whether an attribute is set for objects linked from objects with `from_attributes`.
    pub fn sets(&self, attribute: &str, from_attributes: &[&str]) -> bool {
        match self {
            Computes::Unknown => true,
            Computes::Attributes { names, copies_shared } => {
                names.iter().any(|n| n == attribute)
                    || (*copies_shared && from_attributes.contains(&attribute))
            }
        }
    }
}

impl Entry {
    pub fn new(kind: EntryKind, name: &str, summary: &str) -> Entry {
        Entry {
            kind,
            name: name.into(),
            summary: summary.into(),
            params: Vec::new(),
            inputs: Inputs::none(),
            output: TypeReq::Any,
            ports: Vec::new(),
            provides: Vec::new(),
            computes: Computes::Unknown,
            check: None,
            extra_params: None,
        }
    }

    /// Accepts named parameters beyond the declared ones and passes them on (a unit implemented
    /// elsewhere, whose own parameters the registry does not know); `doc` says what they are for.
    pub fn extra_params(mut self, doc: &str) -> Entry {
        self.extra_params = Some(doc.into());
        self
    }

    /// Checks the call's parameters with `check` when a spec is checked (E0118), so that what
    /// the implementation would refuse when the run starts is a diagnostic of `kpl check`.
    pub fn checked_by(mut self, check: fn(&CallTypes<'_>) -> Vec<ParamProblem>) -> Entry {
        self.check = Some(ParamCheck(check));
        self
    }

    /// Declares the attributes this entry sets: `names`, and with `copies_shared` those the
    /// linked-from object also has. A unit that computes more (`speed`) lists it here.
    pub fn computes(mut self, names: &[&str], copies_shared: bool) -> Entry {
        self.computes =
            Computes::Attributes { names: names.iter().map(|n| n.to_string()).collect(), copies_shared };
        self
    }
    pub fn provides(mut self, function: Function) -> Entry {
        self.provides.push(function);
        self
    }
    pub fn param(mut self, param: Param) -> Entry {
        self.params.push(param);
        self
    }
    pub fn input(mut self, name: &str, ty: TypeReq, doc: &str) -> Entry {
        let port = Port { name: name.into(), ty, doc: doc.into() };
        match &mut self.inputs {
            Inputs::Fixed(ports) => ports.push(port),
            Inputs::Variadic { .. } => self.inputs = Inputs::Fixed(vec![port]),
        }
        self
    }
    pub fn variadic(mut self, min: usize, name: &str, ty: TypeReq, doc: &str) -> Entry {
        self.inputs = Inputs::Variadic { min, port: Port { name: name.into(), ty, doc: doc.into() } };
        self
    }
    pub fn output(mut self, output: TypeReq) -> Entry {
        self.output = output;
        self
    }
    pub fn port(mut self, name: &str, ty: TypeReq, doc: &str) -> Entry {
        self.ports.push(Port { name: name.into(), ty, doc: doc.into() });
        self
    }
    pub fn param_named(&self, name: &str) -> Option<&Param> {
        self.params.iter().find(|p| p.name == name)
    }
}

/// A function or predicate usable in formulas.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Function {
    pub name: String,
    #[serde(serialize_with = "serialize_types")]
    pub params: Vec<ValueType>,
    /// The last parameter may repeat (`max(a, b, c)`).
    pub variadic: bool,
    #[serde(serialize_with = "serialize_display")]
    pub returns: ValueType,
    pub summary: String,
}

fn serialize_types<S: serde::Serializer>(types: &[ValueType], s: S) -> Result<S::Ok, S::Error> {
    s.collect_seq(types.iter().map(ToString::to_string))
}

impl Function {
    pub fn new(name: &str, params: Vec<ValueType>, returns: ValueType, summary: &str) -> Function {
        Function { name: name.into(), params, variadic: false, returns, summary: summary.into() }
    }
    pub fn variadic(mut self) -> Function {
        self.variadic = true;
        self
    }
    /// Whether `n` arguments fit.
    pub fn accepts(&self, n: usize) -> bool {
        if self.variadic { n >= self.params.len().saturating_sub(1).max(1) } else { n == self.params.len() }
    }
    /// The expected type of argument `i`.
    pub fn param(&self, i: usize) -> &ValueType {
        self.params.get(i).or(self.params.last()).unwrap_or(&ValueType::Any)
    }
    /// `xydist(vec2, vec2) -> float`
    pub fn signature(&self) -> String {
        let params: Vec<String> = self.params.iter().map(ToString::to_string).collect();
        let dots = if self.variadic { ", ..." } else { "" };
        format!("{}({}{dots}) -> {}", self.name, params.join(", "), self.returns)
    }
}

/// Everything a spec may name, by kind.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Registry {
    entries: BTreeMap<(EntryKind, String), Entry>,
    functions: BTreeMap<String, Function>,
    /// The link protocols of the transport between hosts (`tcp`, `tls`): the protocols a deploy
    /// section's endpoints may use. Empty: no transport is known, endpoints are checked for their
    /// form only.
    link_protocols: Vec<String>,
}

impl Registry {
    /// Sets the link protocols the transport between hosts has, so that `kpl check` refuses an
    /// endpoint `kpl run` could not open.
    pub fn set_link_protocols(&mut self, protocols: &[&str]) {
        self.link_protocols = protocols.iter().map(|p| p.to_string()).collect();
    }

    pub fn link_protocols(&self) -> &[String] {
        &self.link_protocols
    }

    /// Adds (or replaces) an entry.
    pub fn add(&mut self, entry: Entry) {
        self.entries.insert((entry.kind, entry.name.clone()), entry);
    }

    pub fn add_function(&mut self, function: Function) {
        self.functions.insert(function.name.clone(), function);
    }

    pub fn entry(&self, kind: EntryKind, name: &str) -> Option<&Entry> {
        self.entries.get(&(kind, name.to_string()))
    }

    /// Entries of every kind with this name (to say "`console` is a sink, not a source").
    pub fn entries_named<'a>(&'a self, name: &'a str) -> impl Iterator<Item = &'a Entry> + 'a {
        self.entries.values().filter(move |e| e.name == name)
    }

    pub fn entries(&self) -> impl Iterator<Item = &Entry> {
        self.entries.values()
    }

    pub fn entries_of(&self, kind: EntryKind) -> impl Iterator<Item = &Entry> {
        self.entries.values().filter(move |e| e.kind == kind)
    }

    pub fn function(&self, name: &str) -> Option<&Function> {
        self.functions.get(name)
    }

    pub fn functions(&self) -> impl Iterator<Item = &Function> {
        self.functions.values()
    }

    /// Merges another registry into this one.
    pub fn extend(&mut self, other: Registry) {
        self.entries.extend(other.entries);
        self.functions.extend(other.functions);
    }
}
