//! The checked spec: every name resolved, every type known, every duration in microseconds, and
//! the process graph built. The runtime builds its processes from this, never from the syntax tree.

use std::collections::BTreeMap;
use std::sync::Arc;

use kpl_core::{RecordType, Time, Value, ValueType};
use kpl_syntax::ast::{self, Span};
use petgraph::graph::{DiGraph, NodeIndex};
use serde::Serialize;

/// Index of a process in [`Spec::processes`].
pub type ProcessId = usize;

/// The time unit of a bare integer bound in a spec's formulas (the DyKnow paper's unit).
pub const SPEC_TICK: kpl_core::TimeUnit = kpl_core::TimeUnit::Ms;

#[derive(Debug, Clone)]
pub struct Spec {
    pub types: TypeTable,
    pub processes: Vec<Process>,
    /// The `stream` declarations, by name.
    pub streams: BTreeMap<String, StreamRef>,
    pub predictions: Vec<Prediction>,
    pub forget: Forget,
    /// Objects asked for by description (top-down identification).
    pub identifications: Vec<Identification>,
    /// The checked chronicles, in the order written.
    pub chronicles: Vec<Chronicle>,
    pub deploy: Option<Deploy>,
    pub graph: ProcessGraph,
}

impl Spec {
    pub fn process(&self, name: &str) -> Option<&Process> {
        self.processes.iter().find(|p| p.name == name)
    }

    /// The host a process runs on (`None` when the spec has no deploy section).
    pub fn host_of(&self, id: ProcessId) -> Option<&str> {
        let deploy = self.deploy.as_ref()?;
        deploy.hosts.iter().find(|h| h.processes.contains(&id)).map(|h| h.name.as_str())
    }
}

/// Declared object types, with inherited fields flattened in.
#[derive(Debug, Clone, Default)]
pub struct TypeTable {
    types: BTreeMap<String, Arc<RecordType>>,
    /// Declaration order.
    order: Vec<String>,
}

impl TypeTable {
    pub(crate) fn insert(&mut self, ty: Arc<RecordType>) {
        self.order.push(ty.name.to_string());
        self.types.insert(ty.name.to_string(), ty);
    }

    pub fn get(&self, name: &str) -> Option<&Arc<RecordType>> {
        self.types.get(name)
    }

    /// Types in declaration order.
    pub fn iter(&self) -> impl Iterator<Item = &Arc<RecordType>> {
        self.order.iter().filter_map(|n| self.types.get(n))
    }

    /// `sub` is `sup` or inherits from it.
    pub fn is_subtype(&self, sub: &str, sup: &str) -> bool {
        let mut current = Some(sub.to_string());
        let mut steps = 0;
        while let Some(name) = current {
            if name == sup {
                return true;
            }
            steps += 1;
            if steps > self.types.len() {
                return false; // a cycle (already reported)
            }
            current = self.types.get(&name).and_then(|t| t.parent.as_deref().map(str::to_string));
        }
        false
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.order.iter().map(String::as_str)
    }
}

#[derive(Debug, Clone)]
pub struct Process {
    pub id: ProcessId,
    pub name: String,
    pub span: Span,
    pub kind: ProcessKind,
    /// The type of the default output stream (`None` for sinks).
    pub output: Option<ValueType>,
    /// Named extra outputs (`link.changes`).
    pub ports: Vec<(String, ValueType)>,
    pub inputs: Vec<Input>,
}

impl Process {
    pub fn kind_name(&self) -> &'static str {
        match self.kind {
            ProcessKind::Source(_) => "source",
            ProcessKind::Compute(_) => "compute",
            ProcessKind::Sink(_) => "sink",
            ProcessKind::Link(_) => "link",
            ProcessKind::Monitor(_) => "monitor",
            ProcessKind::Chronicle(_) => "chronicle",
        }
    }

    /// The type of an output: the default one for `None`, else a named port.
    pub fn output_type(&self, port: Option<&str>) -> Option<&ValueType> {
        match port {
            None => self.output.as_ref(),
            Some(port) => self.ports.iter().find(|(n, _)| n == port).map(|(_, t)| t),
        }
    }
}

#[derive(Debug, Clone)]
pub enum ProcessKind {
    Source(Call),
    Compute(Call),
    Sink(Call),
    Link(Box<Link>),
    Monitor(Monitor),
    /// A chronicle's recogniser: the name of its [`Chronicle`] in [`Spec::chronicles`]. Its inputs
    /// (port `objects`) are the object streams of its parameters' types and of the chronicles it
    /// uses; its output is [`recognition_type`].
    Chronicle(String),
}

/// A registry entry with its parameters resolved (defaults filled in; durations in microseconds).
#[derive(Debug, Clone, PartialEq)]
pub struct Call {
    pub entry: String,
    pub params: BTreeMap<String, Value>,
}

/// One input of a process: which registry port it feeds, and the stream that feeds it.
#[derive(Debug, Clone)]
pub struct Input {
    /// The port's name in the registry (`from` for a link's objects, `state` for a monitor).
    pub port: String,
    pub stream: StreamRef,
}

/// A stream as a consumer sees it: its producer, the policy applied for this consumer and the
/// type of its samples.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamRef {
    /// The name the spec uses: a declared stream, or the producer (`tracker`, `link.changes`).
    pub name: String,
    pub producer: ProcessId,
    /// A named output of the producer, or `None` for its default output.
    pub port: Option<String>,
    pub policy: Policy,
    pub ty: ValueType,
}

/// A link process: `<from type, to type, unit, establish, reestablish, maintain>`.
#[derive(Debug, Clone)]
pub struct Link {
    pub from_type: String,
    pub to_type: String,
    pub via: Call,
    pub establish: ast::Expr,
    pub reestablish: ast::Expr,
    pub maintain: ast::Expr,
}

/// A monitor: a formula over the named streams it mentions and the objects of the types it
/// quantifies over. Its verdicts form its output stream.
#[derive(Debug, Clone)]
pub struct Monitor {
    pub formula: ast::Expr,
    /// Stream names used in the formula, each the name of one of the process's inputs.
    pub streams: Vec<String>,
    /// Object types the formula quantifies over.
    pub object_types: Vec<String>,
}

impl Monitor {
    /// For a formula `forall x: T . φ`: the variable, the type and φ. Such a monitor keeps one
    /// progression of φ per object of type `T` (a binding), from the object's first state to its
    /// last, and each verdict names the object (see [`binding_verdict_type`]).
    pub fn binding(&self) -> Option<(&str, &str, &ast::Expr)> {
        monitor_binding(&self.formula)
    }
}

/// The binding of a monitor's formula, if it is `forall x: T . φ` (see [`Monitor::binding`]).
pub fn monitor_binding(formula: &ast::Expr) -> Option<(&str, &str, &ast::Expr)> {
    match &formula.kind {
        ast::ExprKind::Quantified { quantifier: ast::Quantifier::Forall, var, ty, body } => {
            Some((var.name.as_str(), ty.name.as_str(), body))
        }
        _ => None,
    }
}

/// The bindings of a monitor's formula: the variables and types of the `forall`s it starts with
/// (`forall a: Car . forall b: Car . φ` gives `a` and `b`), at most [`MAX_BINDINGS`], and the body
/// φ under them. Such a monitor keeps one progression of φ per tuple of objects.
pub fn monitor_bindings(formula: &ast::Expr) -> (Vec<(&str, &str)>, &ast::Expr) {
    let mut vars = Vec::new();
    let mut body = formula;
    while vars.len() < MAX_BINDINGS
        && let Some((var, ty, inner)) = monitor_binding(body)
        && !vars.iter().any(|(v, _)| *v == var)
    {
        vars.push((var, ty));
        body = inner;
    }
    (vars, body)
}

/// The most `forall`s at the head of a monitor's formula that get a binding each (pairs of
/// objects: overtakes, tailgating).
pub const MAX_BINDINGS: usize = 2;

/// The type of a verdict of a monitor with bindings: `{ VAR: string, ..., verdict: bool, start:
/// int, end: int }`, the objects' symbols, the verdict for them, and the episode's first and last
/// state (valid times in microseconds).
pub fn binding_verdict_type(monitor: &str, vars: &[&str]) -> ValueType {
    let field = |name: &str, ty: ValueType| kpl_core::FieldType { name: Arc::from(name), ty };
    let mut fields: Vec<kpl_core::FieldType> = vars.iter().map(|var| field(var, ValueType::Str)).collect();
    fields.push(field("verdict", ValueType::Bool));
    fields.push(field("start", ValueType::Int));
    fields.push(field("end", ValueType::Int));
    ValueType::Record(Arc::new(RecordType {
        name: Arc::from(format!("{monitor}.verdict")),
        parent: None,
        symbol: Arc::from(""),
        fields,
    }))
}

/// The type of a chronicle's recognitions: `{PARAM: SYMBOL, ..., verdict: true, start: µs, end:
/// µs, times: [µs, ...]}`, the objects bound to its parameters, the time of its first and last
/// event (the last is the valid time) and the time of each event in the order written. `verdict`,
/// `start` and `end` are the fields of a monitor's `true` episodes, so `kpl situations` scores
/// recognitions like situation monitors' episodes.
pub fn recognition_type(chronicle: &str, params: &[&str]) -> ValueType {
    let field = |name: &str, ty: ValueType| kpl_core::FieldType { name: Arc::from(name), ty };
    let mut fields: Vec<kpl_core::FieldType> = params.iter().map(|p| field(p, ValueType::Str)).collect();
    fields.push(field("verdict", ValueType::Bool));
    fields.push(field("start", ValueType::Int));
    fields.push(field("end", ValueType::Int));
    fields.push(field("times", ValueType::List(Box::new(ValueType::Int))));
    ValueType::Record(Arc::new(RecordType {
        name: Arc::from(format!("{chronicle}.recognition")),
        parent: None,
        symbol: Arc::from(""),
        fields,
    }))
}

/// The policy of a stream for one consumer, with every default made explicit.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Policy {
    pub approximation: Approximation,
    pub change: Change,
    /// `max delay`: samples later than this after their valid time are late.
    pub max_delay: Option<Time>,
    /// `from T to T`: only samples with valid times in this window (`None` = unbounded end).
    pub window: Option<(Time, Option<Time>)>,
    pub order: Order,
    pub queue: Queue,
    /// The edge may close a cycle: the consumer reads the producer's previous sample.
    pub feedback: bool,
}

impl Default for Policy {
    fn default() -> Policy {
        Policy {
            approximation: Approximation::None,
            change: Change::AnyUpdate,
            max_delay: None,
            window: None,
            order: Order::Any,
            queue: Queue::default(),
            feedback: false,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Approximation {
    None,
    UseMostRecent,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Change {
    AnyUpdate,
    AnyChange,
    SampleEvery(Time),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Order {
    Any,
    Monotone,
    Strict,
}

/// The bound of the queue in front of a consumer and what happens when it is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Queue {
    pub capacity: u64,
    pub overflow: ast::Overflow,
}

impl Queue {
    /// Default bound of a stream's queue.
    pub const DEFAULT_CAPACITY: u64 = 1024;
}

impl Default for Queue {
    fn default() -> Queue {
        Queue { capacity: Queue::DEFAULT_CAPACITY, overflow: ast::Overflow::Block }
    }
}

impl Policy {
    /// The policy as KPL text, defaults included (`no approximation, any update, any order, queue 1024 block`).
    pub fn describe(&self) -> String {
        self.parts().into_iter().map(|(text, _)| text).collect::<Vec<_>>().join(", ")
    }

    /// Only what differs from the default policy, as KPL text (`sample every 1s, strict order`);
    /// empty for a stream with the default policy. The defaults that `sample every` implies
    /// (`use most recent`, `monotone order`) count as defaults.
    pub fn describe_changes(&self) -> String {
        self.parts()
            .into_iter()
            .filter(|(_, default)| !default)
            .map(|(text, _)| text)
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The policy's parts as KPL text, each with whether it is what the stream gets by default.
    fn parts(&self) -> Vec<(String, bool)> {
        use kpl_core::format_micros as d;
        let sampled = matches!(self.change, Change::SampleEvery(_));
        let mut parts = vec![
            match self.approximation {
                Approximation::None => ("no approximation".to_string(), !sampled),
                Approximation::UseMostRecent => ("use most recent".to_string(), sampled),
            },
            match self.change {
                Change::AnyUpdate => ("any update".to_string(), true),
                Change::AnyChange => ("any change".to_string(), false),
                Change::SampleEvery(t) => (format!("sample every {}", d(t)), false),
            },
        ];
        if let Some(t) = self.max_delay {
            parts.push((format!("max delay {}", d(t)), false));
        }
        if let Some((from, to)) = self.window {
            parts.push((format!("from {} to {}", d(from), to.map_or("inf".to_string(), d)), false));
        }
        parts.push(match self.order {
            Order::Any => ("any order".to_string(), !sampled),
            Order::Monotone => ("monotone order".to_string(), sampled),
            Order::Strict => ("strict order".to_string(), false),
        });
        let overflow = match self.queue.overflow {
            ast::Overflow::Block => "block",
            ast::Overflow::DropOldest => "drop oldest",
        };
        parts.push((format!("queue {} {overflow}", self.queue.capacity), self.queue == Queue::default()));
        if self.feedback {
            parts.push(("feedback".to_string(), false));
        }
        parts
    }
}

#[derive(Debug, Clone)]
pub struct Prediction {
    pub ty: String,
    pub model: Call,
}

/// `identify NAME : TYPE where FORMULA`: a partial object of `ty` named `name`, to be anchored to
/// an object that satisfies the description (`this` is the candidate, of type `ty`).
#[derive(Debug, Clone)]
pub struct Identification {
    pub name: String,
    pub ty: String,
    pub description: ast::Expr,
}

/// When objects that are not anchored are removed.
#[derive(Debug, Clone, Default)]
pub struct Forget {
    pub default: Option<Time>,
    pub per_type: BTreeMap<String, Time>,
    /// The shorter times with their conditions (`forget after 5s, after 1s when C`), by the
    /// declaration they belong to: `None` the default one, else the type's own.
    pub sooner: BTreeMap<Option<String>, Sooner>,
}

/// `after T when C` of a forget declaration: an object that has not been anchored for `T` and
/// whose state at a step satisfies `C` is forgotten at that step.
#[derive(Debug, Clone)]
pub struct Sooner {
    pub after: Time,
    /// A formula about `this` (the object, as a record of its type) and the streams it names.
    pub condition: ast::Expr,
    /// The stream names the condition reads: inputs (port `env`) of every link into the types
    /// it applies to.
    pub streams: Vec<String>,
}

impl Forget {
    /// The forget time of a type: its own, else the default.
    pub fn after(&self, ty: &str) -> Option<Time> {
        self.per_type.get(ty).copied().or(self.default)
    }

    /// The shorter time and condition of a type: those of its own declaration when it has one,
    /// else the default declaration's.
    pub fn sooner(&self, ty: &str) -> Option<&Sooner> {
        if self.per_type.contains_key(ty) {
            self.sooner.get(&Some(ty.to_string()))
        } else {
            self.sooner.get(&None)
        }
    }
}

#[derive(Debug, Clone)]
pub struct Deploy {
    /// The deployment's name (`deploy NAME { ... }`), part of every key between its hosts.
    pub name: Option<String>,
    pub hosts: Vec<Host>,
}

#[derive(Debug, Clone)]
pub struct Host {
    pub name: String,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    pub processes: Vec<ProcessId>,
}

/// The process graph: a node per process, an edge per input stream (producer to consumer).
#[derive(Debug, Clone, Default)]
pub struct ProcessGraph {
    pub graph: DiGraph<ProcessId, Edge>,
    /// The node of each process, indexed by [`ProcessId`].
    pub nodes: Vec<NodeIndex>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Edge {
    pub stream: String,
    pub port: Option<String>,
    /// The consumer's input port.
    pub input: String,
    pub policy: Policy,
}

/// A checked chronicle: parameters with their types, event nodes over event sources, metric
/// constraints between node indices (microseconds) and conditions. Its network is consistent and
/// bounded: `window` is the longest time between two of its events.
#[derive(Debug, Clone, PartialEq)]
pub struct Chronicle {
    pub name: String,
    pub span: Span,
    /// `(name, object type)`.
    pub params: Vec<(String, String)>,
    pub events: Vec<ChronicleEvent>,
    pub constraints: Vec<kpl_chronicle::stn::Constraint>,
    pub holds: Vec<ChronicleHold>,
    pub nevers: Vec<ChronicleNever>,
    pub window: Time,
}

/// The chronicle-only function that makes a whole predicate a fluent with hysteresis,
/// `hysteresis(ENTER, LEAVE)` (`kpl_chronicle::fluent`): its recogniser keeps the state.
pub const HYSTERESIS: &str = "hysteresis";

/// What a chronicle's event is an occurrence of.
#[derive(Debug, Clone, PartialEq)]
pub enum EventSource {
    /// A predicate over the parameters `args` (those it mentions, in parameter order).
    Predicate(ast::Expr),
    /// The verdict of the named monitor for the objects bound to its `forall`s.
    Monitor(String),
    /// The recognitions of the named chronicle.
    Chronicle(String),
}

/// A node: `source` on the parameters `args` (indices) becomes `value` (recognitions: `true`).
#[derive(Debug, Clone, PartialEq)]
pub struct ChronicleEvent {
    pub name: String,
    pub source: EventSource,
    pub args: Vec<usize>,
    pub value: bool,
}

/// `hold FORMULA from e1 to e2`: the predicate over `args` is true from node `from` to node `to`.
#[derive(Debug, Clone, PartialEq)]
pub struct ChronicleHold {
    pub formula: ast::Expr,
    pub args: Vec<usize>,
    pub from: usize,
    pub to: usize,
}

/// `never EVENT from e1 to e2`: no such event strictly between nodes `from` and `to`.
#[derive(Debug, Clone, PartialEq)]
pub struct ChronicleNever {
    pub source: EventSource,
    pub args: Vec<usize>,
    pub value: bool,
    pub from: usize,
    pub to: usize,
}
