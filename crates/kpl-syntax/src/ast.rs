//! The syntax tree of a KPL file, exactly as written: names are not resolved, units are not
//! converted, and every node keeps the byte span it came from.
//!
//! Spans are skipped when a tree is serialized, so two trees that differ only in layout serialize
//! the same; `kpl fmt` relies on that for its round-trip property (`parse(fmt(x)) == parse(x)`).
//!
//! Expressions and formulas share one type, [`Expr`]: a formula is an expression of type `bool`.
//! `and` / `or` chains are n-ary ([`ExprKind::And`], [`ExprKind::Or`]) so long chains stay flat.

use kpl_core::TimeUnit;
use serde::Serialize;

/// A byte range `start..end` in the source file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, PartialOrd, Ord)]
pub struct Span {
    pub start: u32,
    pub end: u32,
}

impl Span {
    pub const fn new(start: u32, end: u32) -> Span {
        Span { start, end }
    }
    /// The smallest span covering both.
    pub fn to(self, other: Span) -> Span {
        Span { start: self.start.min(other.start), end: self.end.max(other.end) }
    }
    pub fn range(self) -> std::ops::Range<usize> {
        self.start as usize..self.end as usize
    }
}

/// A name with the span it was written at.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct Ident {
    pub name: String,
    #[serde(skip)]
    pub span: Span,
}

/// A dotted name: `tracker`, `vision_world.changes`, `from.pos`, `sim.uav_tracker`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub struct Path {
    pub segments: Vec<Ident>,
    #[serde(skip)]
    pub span: Span,
}

impl Path {
    /// The path as written, segments joined by dots.
    pub fn dotted(&self) -> String {
        let names: Vec<&str> = self.segments.iter().map(|s| s.name.as_str()).collect();
        names.join(".")
    }
}

/// A whole file.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Spec {
    pub items: Vec<Item>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Item {
    Type(TypeDecl),
    /// `source`, `compute` and `sink` declarations.
    Process(ProcessDecl),
    Stream(StreamDecl),
    Link(LinkDecl),
    Predict(PredictDecl),
    Forget(ForgetDecl),
    Identify(IdentifyDecl),
    Monitor(MonitorDecl),
    Chronicle(ChronicleDecl),
    Deploy(DeployDecl),
}

impl Item {
    pub fn span(&self) -> Span {
        match self {
            Item::Type(d) => d.span,
            Item::Process(d) => d.span,
            Item::Stream(d) => d.span,
            Item::Link(d) => d.span,
            Item::Predict(d) => d.span,
            Item::Forget(d) => d.span,
            Item::Identify(d) => d.span,
            Item::Monitor(d) => d.span,
            Item::Chronicle(d) => d.span,
            Item::Deploy(d) => d.span,
        }
    }
}

/// `type OnRoadObject : WorldObject symbol oo { road: int, lane_offset: float }`
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TypeDecl {
    pub name: Ident,
    pub parent: Option<Ident>,
    pub symbol: Option<Ident>,
    pub fields: Vec<Field>,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Field {
    pub name: Ident,
    pub ty: TypeExpr,
    #[serde(skip)]
    pub span: Span,
}

/// `float`, `vec2`, `WorldObject`, `list<Detection>`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum TypeExpr {
    Named(Ident),
    List(Box<TypeExpr>, #[serde(skip)] Span),
}

impl TypeExpr {
    pub fn span(&self) -> Span {
        match self {
            TypeExpr::Named(id) => id.span,
            TypeExpr::List(_, span) => *span,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum ProcessKind {
    Source,
    Compute,
    Sink,
}

impl ProcessKind {
    pub fn keyword(self) -> &'static str {
        match self {
            ProcessKind::Source => "source",
            ProcessKind::Compute => "compute",
            ProcessKind::Sink => "sink",
        }
    }
}

/// `source tracker : VisionPercept = sim.uav_tracker(scenario: "crossing", seed: 7)`,
/// `compute world : WorldState = aapa.anchor(frames, actions, prior_world, theta: 6500.0)`,
/// `sink cars = file.jsonl(world_onroad, path: "out/cars.jsonl")`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProcessDecl {
    pub kind: ProcessKind,
    pub name: Ident,
    /// The type of the samples the process produces (`None` for sinks).
    pub output: Option<TypeExpr>,
    pub call: Call,
    #[serde(skip)]
    pub span: Span,
}

/// `name(inputs..., param: value, ...)`: positional arguments are input streams, named ones are
/// parameters. A call without parentheses (`constant_velocity`) has no arguments.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Call {
    pub callee: Path,
    pub args: Vec<Arg>,
    #[serde(skip)]
    pub span: Span,
}

impl Call {
    pub fn inputs(&self) -> impl Iterator<Item = &Path> {
        self.args.iter().filter_map(|a| match a {
            Arg::Input(p) => Some(p),
            Arg::Param { .. } => None,
        })
    }
    pub fn params(&self) -> impl Iterator<Item = (&Ident, &Literal)> {
        self.args.iter().filter_map(|a| match a {
            Arg::Param { name, value } => Some((name, value)),
            Arg::Input(_) => None,
        })
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum Arg {
    Input(Path),
    Param { name: Ident, value: Literal },
}

/// A number as written: integers stay integers so that `fmt` prints them back the same.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Number {
    Int(i64),
    Float(f64),
}

impl Number {
    pub fn as_f64(self) -> f64 {
        match self {
            Number::Int(i) => i as f64,
            Number::Float(x) => x,
        }
    }
}

/// `100ms`, `1.5s`, `2min`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DurationLit {
    pub value: Number,
    pub unit: TimeUnit,
    #[serde(skip)]
    pub span: Span,
}

impl DurationLit {
    /// The duration in microseconds, or `None` if negative, fractional below a microsecond in a
    /// way that rounds away, or out of range.
    pub fn micros(&self) -> Option<i64> {
        match self.value {
            Number::Int(i) if i >= 0 => self.unit.to_micros(i),
            Number::Int(_) => None,
            Number::Float(x) => self.unit.float_to_micros(x),
        }
    }
}

/// A constant in a parameter position.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Literal {
    pub kind: LitKind,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum LitKind {
    Bool(bool),
    Number(Number),
    Str(String),
    Duration(DurationLit),
    List(Vec<Literal>),
}

/// `stream percepts = tracker with sample every 100ms, max delay 50ms, strict order`
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StreamDecl {
    pub name: Ident,
    /// The producing process (or process output, `link.changes`) or another stream.
    pub source: Path,
    pub policies: Vec<Policy>,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Policy {
    pub kind: PolicyKind,
    #[serde(skip)]
    pub span: Span,
}

/// The five DyKnow policy kinds, plus the edge's queue and the feedback marker.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum PolicyKind {
    // approximation
    NoApproximation,
    UseMostRecent,
    // change
    AnyUpdate,
    AnyChange,
    SampleEvery(DurationLit),
    // delay
    MaxDelay(DurationLit),
    // duration: valid times from `from` to `to` (`None` = unbounded end)
    Duration {
        from: DurationLit,
        to: Option<DurationLit>,
    },
    // order
    AnyOrder,
    MonotoneOrder,
    StrictOrder,
    /// `queue 64 drop oldest` / `queue 1024 block`
    Queue {
        capacity: u64,
        overflow: Overflow,
    },
    /// `feedback`: the consumer reads the producer's previous sample, so the edge may close a cycle.
    Feedback,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum Overflow {
    Block,
    DropOldest,
}

/// The policy kind a [`PolicyKind`] belongs to; a stream has at most one of each.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub enum PolicyClass {
    Approximation,
    Change,
    Delay,
    Duration,
    Order,
    Queue,
    Feedback,
}

impl PolicyKind {
    pub fn class(&self) -> PolicyClass {
        match self {
            PolicyKind::NoApproximation | PolicyKind::UseMostRecent => PolicyClass::Approximation,
            PolicyKind::AnyUpdate | PolicyKind::AnyChange | PolicyKind::SampleEvery(_) => PolicyClass::Change,
            PolicyKind::MaxDelay(_) => PolicyClass::Delay,
            PolicyKind::Duration { .. } => PolicyClass::Duration,
            PolicyKind::AnyOrder | PolicyKind::MonotoneOrder | PolicyKind::StrictOrder => PolicyClass::Order,
            PolicyKind::Queue { .. } => PolicyClass::Queue,
            PolicyKind::Feedback => PolicyClass::Feedback,
        }
    }
}

/// `link vision_world : VisionPercept -> WorldObject via geo.camera_to_world { ... }`
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LinkDecl {
    pub name: Ident,
    pub from_type: Ident,
    pub to_type: Ident,
    pub via: Call,
    pub clauses: Vec<LinkClause>,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum LinkClause {
    /// `input percepts`: the stream of `from` objects (default: the unique producer of that type).
    Input(Path, #[serde(skip)] Span),
    Condition(Condition),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum ConditionKind {
    Establish,
    Reestablish,
    Maintain,
}

impl ConditionKind {
    pub fn keyword(self) -> &'static str {
        match self {
            ConditionKind::Establish => "establish",
            ConditionKind::Reestablish => "reestablish",
            ConditionKind::Maintain => "maintain",
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Condition {
    pub kind: ConditionKind,
    pub formula: Expr,
    #[serde(skip)]
    pub span: Span,
}

/// `predict OnRoadObject = along_roads(roads)`
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PredictDecl {
    pub ty: Ident,
    pub model: Call,
    #[serde(skip)]
    pub span: Span,
}

/// `forget after 30s` (all types) or `forget WorldObject after 10s`, optionally with a shorter
/// time while a condition about the object holds (`forget after 5s, after 1s when C`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ForgetDecl {
    pub ty: Option<Ident>,
    pub after: DurationLit,
    /// `after T when C`: an object whose state satisfies `C` (a formula about `this`, the object,
    /// and named streams) is forgotten once it has not been anchored for `T`.
    pub sooner: Option<ForgetSooner>,
    #[serde(skip)]
    pub span: Span,
}

/// The `after T when C` part of a forget declaration.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ForgetSooner {
    pub after: DurationLit,
    pub condition: Expr,
    #[serde(skip)]
    pub span: Span,
}

/// `identify suspect : Car where xydist(this.pos, vec2(120.0, 40.0)) < 20.0 and this.vel.y > 0.0`:
/// top-down identification. A partial object of the type is added, and anchoring tries to
/// complete it from incoming percepts; `this` is the candidate object of that type.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdentifyDecl {
    pub name: Ident,
    pub ty: Ident,
    pub description: Expr,
    #[serde(skip)]
    pub span: Span,
}

/// `monitor too_fast = forall c: Car . always (c.speed < 25.0)`
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MonitorDecl {
    pub name: Ident,
    pub formula: Expr,
    #[serde(skip)]
    pub span: Span,
}

/// `chronicle reckless_overtake(a: Car, b: Car) { event pass = beside(a, b) becomes true ... }`:
/// a parameterised class of complex events, a simple temporal network whose nodes are event
/// occurrences and whose edges are metric constraints between their times.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChronicleDecl {
    pub name: Ident,
    pub params: Vec<ChronicleParam>,
    /// The clauses in the order written (`fmt` keeps it).
    pub clauses: Vec<ChronicleClause>,
    #[serde(skip)]
    pub span: Span,
}

impl ChronicleDecl {
    pub fn events(&self) -> impl Iterator<Item = &ChronicleEvent> {
        self.clauses.iter().filter_map(|c| match c {
            ChronicleClause::Event(e) => Some(e),
            _ => None,
        })
    }
    pub fn constraints(&self) -> impl Iterator<Item = &TimeConstraint> {
        self.clauses.iter().filter_map(|c| match c {
            ChronicleClause::Constraint(c) => Some(c),
            _ => None,
        })
    }
}

/// `a: Car`: an object the chronicle is about.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChronicleParam {
    pub name: Ident,
    pub ty: Ident,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum ChronicleClause {
    Event(ChronicleEvent),
    Constraint(TimeConstraint),
    Hold(HoldCondition),
    Never(NeverCondition),
}

impl ChronicleClause {
    pub fn span(&self) -> Span {
        match self {
            ChronicleClause::Event(c) => c.span,
            ChronicleClause::Constraint(c) => c.span,
            ChronicleClause::Hold(c) => c.span,
            ChronicleClause::Never(c) => c.span,
        }
    }
}

/// `event pass = beside(a, b) becomes true`: a node of the network, named for the constraints.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChronicleEvent {
    pub name: Ident,
    pub pattern: EventPattern,
    #[serde(skip)]
    pub span: Span,
}

/// What an event is an occurrence of.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventPattern {
    pub kind: EventPatternKind,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum EventPatternKind {
    /// `close(a, b) becomes false`: a predicate over the parameters changes its value.
    Change { predicate: Expr, becomes: bool },
    /// `monitor speeding(a) becomes false`: a monitor's verdict for a tuple of objects changes.
    Monitor { monitor: Ident, args: Vec<Ident>, becomes: bool },
    /// `recognised overtake(a, b)`: another chronicle is recognised for a tuple of objects.
    Recognised { chronicle: Ident, args: Vec<Ident> },
}

/// `cut_in - pass in [500ms, 8s]`: `lo <= time(later) - time(earlier) <= hi`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TimeConstraint {
    pub later: Ident,
    pub earlier: Ident,
    pub lo: StnBound,
    pub hi: StnBound,
    #[serde(skip)]
    pub span: Span,
}

/// A bound of a metric constraint: a signed duration or an infinite end.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum StnBound {
    Duration { negative: bool, value: DurationLit },
    Inf { negative: bool },
}

/// `hold on_road(a) from start to cut_in`: the predicate is true throughout the two events' times.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HoldCondition {
    pub formula: Expr,
    pub from: Ident,
    pub to: Ident,
    #[serde(skip)]
    pub span: Span,
}

/// `never same_lane(a, b) becomes true from start to cut_in`: no such event strictly between.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NeverCondition {
    pub pattern: EventPattern,
    pub from: Ident,
    pub to: Ident,
    #[serde(skip)]
    pub span: Span,
}

/// `deploy { host uav listen ["tcp/127.0.0.1:7447"] { tracker, vision_world } ... }`, or with the
/// deployment's name: `deploy trial { ... }`, `deploy "site-3" { ... }`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DeployDecl {
    /// The deployment's name, a string (written as a name or a quoted string).
    pub name: Option<Literal>,
    pub hosts: Vec<HostDecl>,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct HostDecl {
    pub name: Ident,
    /// zenoh endpoints this host listens on (`tcp/127.0.0.1:7447`).
    pub listen: Vec<Literal>,
    /// zenoh endpoints this host connects to.
    pub connect: Vec<Literal>,
    pub processes: Vec<Ident>,
    #[serde(skip)]
    pub span: Span,
}

/// An expression or formula.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Expr {
    pub kind: ExprKind,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum ExprKind {
    Bool(bool),
    Number(Number),
    Str(String),
    Duration(DurationLit),
    /// A name or attribute access: `p`, `from.pos`, `c.speed`.
    Path(Path),
    /// A function or predicate call: `xydist(from.pos, to.pos)`, `on_road(from.pos)`.
    Call {
        func: Ident,
        args: Vec<Expr>,
    },
    Unary {
        op: UnaryOp,
        expr: Box<Expr>,
    },
    Binary {
        op: BinaryOp,
        lhs: Box<Expr>,
        rhs: Box<Expr>,
    },
    /// `a and b and c`, at least two operands.
    And(Vec<Expr>),
    /// `a or b or c`, at least two operands.
    Or(Vec<Expr>),
    /// `eventually[a, b] φ`, `always φ` (no interval: `[0, inf]`).
    Temporal {
        op: TemporalOp,
        interval: Option<Interval>,
        body: Box<Expr>,
    },
    /// `φ until[a, b] ψ`
    Until {
        interval: Option<Interval>,
        lhs: Box<Expr>,
        rhs: Box<Expr>,
    },
    /// `forall c: Car . φ`, `exists o: WorldObject . φ`
    Quantified {
        quantifier: Quantifier,
        var: Ident,
        ty: Ident,
        body: Box<Expr>,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum UnaryOp {
    Not,
    Neg,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum BinaryOp {
    Add,
    Sub,
    Mul,
    Div,
    Rem,
    Lt,
    Le,
    Gt,
    Ge,
    Eq,
    Ne,
    /// `->`, right associative.
    Implies,
}

impl BinaryOp {
    pub fn symbol(self) -> &'static str {
        match self {
            BinaryOp::Add => "+",
            BinaryOp::Sub => "-",
            BinaryOp::Mul => "*",
            BinaryOp::Div => "/",
            BinaryOp::Rem => "%",
            BinaryOp::Lt => "<",
            BinaryOp::Le => "<=",
            BinaryOp::Gt => ">",
            BinaryOp::Ge => ">=",
            BinaryOp::Eq => "==",
            BinaryOp::Ne => "!=",
            BinaryOp::Implies => "->",
        }
    }
    pub fn is_comparison(self) -> bool {
        matches!(
            self,
            BinaryOp::Lt | BinaryOp::Le | BinaryOp::Gt | BinaryOp::Ge | BinaryOp::Eq | BinaryOp::Ne
        )
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum TemporalOp {
    Eventually,
    Always,
}

impl TemporalOp {
    pub fn keyword(self) -> &'static str {
        match self {
            TemporalOp::Eventually => "eventually",
            TemporalOp::Always => "always",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum Quantifier {
    Forall,
    Exists,
}

/// `[lo, hi]`, both ends closed.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Interval {
    pub lo: Bound,
    pub hi: Bound,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub enum Bound {
    /// A bare integer: counts in the time unit of the context (ms in a spec, `--time-unit` on the
    /// command line).
    Ticks(u64),
    Duration(DurationLit),
    Inf,
}
