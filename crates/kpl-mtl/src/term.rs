//! Terms: the non-temporal expressions inside atoms (`x > 3.5`, `xydist(from.pos, to.pos) < 10`,
//! `on_road(from.pos)`), the functions they may call, and their evaluation over one state.
//!
//! Numbers follow one rule everywhere: `int op int` stays an `int` for `+ - * %` (overflow is an
//! error), `/` always gives a `float`, and anything mixed with a `float` is a `float`. A result
//! that is not finite (division by zero) is an [`EvalError::Arithmetic`], never a NaN.

use std::borrow::Cow;
use std::fmt;
use std::sync::Arc;

use kpl_core::{FieldHint, Record, Value};

use crate::error::EvalError;
use crate::state::State;

/// The index of a name of the state (a field, or a variable such as `from`), assigned by the
/// [`crate::Context`] the formula is compiled against.
pub type SlotId = u32;
/// The index of an object type that `forall`/`exists` range over.
pub type DomainId = u32;
/// A variable bound by `forall`/`exists`: its nesting depth, 0 for the outermost quantifier.
pub type VarId = u32;
/// The index of a function in the [`crate::Context`].
pub type FuncId = u32;

/// A term, as built by the lowering or by hand.
#[derive(Debug, Clone, PartialEq)]
pub enum Term {
    Const(Value),
    /// A named value of the state.
    Slot(SlotId),
    /// The object bound by an enclosing quantifier.
    Var(VarId),
    /// Attribute access: a record field, `x`/`y` of a vector, a box's corners.
    Field(Box<Term>, FieldName),
    Neg(Box<Term>),
    Not(Box<Term>),
    Binary(BinOp, Box<Term>, Box<Term>),
    Call(FuncId, Vec<Term>),
}

/// The name of an attribute a term reads, with where it was last found in a record
/// ([`FieldHint`]: the objects a formula reads are mostly of one type, their fields in one order).
/// Compares, prints and dereferences as its name.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldName {
    name: Arc<str>,
    hint: FieldHint,
}

impl FieldName {
    pub fn new(name: &str) -> FieldName {
        FieldName { name: Arc::from(name), hint: FieldHint::new() }
    }

    /// The attribute of `record`, as [`Record::get`] finds it.
    #[inline]
    pub fn of<'r>(&self, record: &'r Record) -> Option<&'r Value> {
        record.get_hinted(&self.name, &self.hint)
    }
}

impl std::ops::Deref for FieldName {
    type Target = str;
    fn deref(&self) -> &str {
        &self.name
    }
}

impl fmt::Display for FieldName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.name)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum BinOp {
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
    And,
    Or,
}

impl BinOp {
    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Rem => "%",
            BinOp::Lt => "<",
            BinOp::Le => "<=",
            BinOp::Gt => ">",
            BinOp::Ge => ">=",
            BinOp::Eq => "==",
            BinOp::Ne => "!=",
            BinOp::And => "and",
            BinOp::Or => "or",
        }
    }
}

impl Term {
    pub fn slot(slot: SlotId) -> Term {
        Term::Slot(slot)
    }
    pub fn num(x: f64) -> Term {
        Term::Const(Value::Float(x))
    }
    pub fn int(i: i64) -> Term {
        Term::Const(Value::Int(i))
    }
    pub fn field(self, name: &str) -> Term {
        Term::Field(Box::new(self), FieldName::new(name))
    }
    pub fn binary(op: BinOp, lhs: Term, rhs: Term) -> Term {
        Term::Binary(op, Box::new(lhs), Box::new(rhs))
    }
    pub fn call(func: FuncId, args: Vec<Term>) -> Term {
        Term::Call(func, args)
    }
}

/// The body of a function: its arguments in, a value or a message out.
pub type FunctionBody = Arc<dyn Fn(&[Value]) -> Result<Value, String> + Send + Sync>;

/// The body of a function that reads its arguments borrowed ([`Function::borrowing`]).
pub type BorrowedBody = Arc<dyn Fn(&[&Value]) -> Result<Value, String> + Send + Sync>;

/// A function a formula may call: a built-in or one the host registered (`on_road`).
#[derive(Clone)]
pub struct Function {
    pub name: Arc<str>,
    /// Smallest and largest number of arguments (`None`: no upper limit).
    pub arity: (usize, Option<usize>),
    pub body: FunctionBody,
    /// For the distance built-ins: computed by the evaluator on borrowed arguments, with the same
    /// result as `body` (which a host's function of the same name replaces, and this with it).
    pub(crate) native: Option<Native>,
    /// The same as `body` on borrowed arguments: what the evaluator calls when there is one, so
    /// a relation of two objects called for every pair copies no record (`Function::borrowing`).
    pub(crate) borrowed: Option<BorrowedBody>,
    /// For a predicate `f(a, b, d)` of two objects: true only when they are within `d + margin` of
    /// each other in the plane, which gates pairs ([`crate::gate`]).
    pub within_margin: Option<f64>,
}

/// Built-ins the evaluator computes itself, without copying arguments or calling `body`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Native {
    XyDist,
    Dist,
}

impl fmt::Debug for Function {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Function").field("name", &self.name).field("arity", &self.arity).finish()
    }
}

impl Function {
    pub fn new(
        name: &str,
        arity: (usize, Option<usize>),
        body: impl Fn(&[Value]) -> Result<Value, String> + Send + Sync + 'static,
    ) -> Function {
        Function {
            name: Arc::from(name),
            arity,
            body: Arc::new(body),
            native: None,
            borrowed: None,
            within_margin: None,
        }
    }

    /// A function whose body reads its arguments borrowed: the evaluator passes references to
    /// the values the state holds instead of copies (for the relations called on every pair of
    /// objects); `body` is the same function on owned arguments.
    pub fn borrowing(
        name: &str,
        arity: (usize, Option<usize>),
        body: impl Fn(&[&Value]) -> Result<Value, String> + Send + Sync + 'static,
    ) -> Function {
        let borrowed: BorrowedBody = Arc::new(body);
        let by_value = borrowed.clone();
        Function {
            name: Arc::from(name),
            arity,
            body: Arc::new(move |args: &[Value]| by_value(&args.iter().collect::<Vec<&Value>>())),
            native: None,
            borrowed: Some(borrowed),
            within_margin: None,
        }
    }

    /// Declares `f(a, b, d)` true only when `a` and `b` are within `d + margin` of each other in
    /// the plane, so pair monitors and link conditions using it are gated ([`crate::gate`]).
    pub fn within(self, margin: f64) -> Function {
        Function { within_margin: Some(margin), ..self }
    }

    fn native(self, native: Native) -> Function {
        Function { native: Some(native), ..self }
    }

    pub fn accepts(&self, n: usize) -> bool {
        n >= self.arity.0 && self.arity.1.is_none_or(|max| n <= max)
    }

    pub fn arity_text(&self) -> String {
        match self.arity {
            (lo, Some(hi)) if lo == hi => lo.to_string(),
            (lo, Some(hi)) => format!("{lo} to {hi}"),
            (lo, None) => format!("at least {lo}"),
        }
    }
}

fn number(v: &Value, func: &str) -> Result<f64, String> {
    v.as_f64().ok_or_else(|| format!("{func} needs numbers, found {}", v.kind()))
}

fn point(v: &Value, func: &str) -> Result<[f64; 2], String> {
    match v {
        Value::Vec2(p) => Ok(*p),
        // A record with a `pos` attribute stands for its position (`xydist(from, to)`).
        Value::Record(r) => match r.get("pos") {
            Some(Value::Vec2(p)) => Ok(*p),
            _ => Err(format!("{func} needs vec2 positions, found a record without a vec2 `pos`")),
        },
        other => Err(format!("{func} needs vec2 positions, found {}", other.kind())),
    }
}

fn finite(x: f64, func: &str) -> Result<Value, String> {
    if x.is_finite() { Ok(Value::Float(x)) } else { Err(format!("{func} gives a non-finite result")) }
}

/// The Euclidean distance of two positions (see [`point`]).
fn distance(a: &Value, b: &Value, func: &str) -> Result<Value, String> {
    let [x1, y1] = point(a, func)?;
    let [x2, y2] = point(b, func)?;
    finite((x1 - x2).hypot(y1 - y2), func)
}

/// A box in pixels as `[left, top, right, bottom]`: from a list of four numbers `[left, top,
/// width, height]` (MOTChallenge's convention, what trackers' files give), a `box` value
/// (`[x1, y1, x2, y2]`), or a record with either as its `box` attribute.
fn pixel_box(v: &Value, func: &str) -> Result<[f64; 4], String> {
    match v {
        Value::List(items) if items.len() == 4 => {
            let n: Vec<f64> = items.iter().map(|x| number(x, func)).collect::<Result<_, _>>()?;
            Ok([n[0], n[1], n[0] + n[2], n[1] + n[3]])
        }
        Value::BBox(b) => Ok([b.x1, b.y1, b.x2, b.y2]),
        Value::Record(r) => match r.get("box") {
            Some(b) => pixel_box(b, func),
            None => Err(format!("{func} needs boxes, found a record without a `box`")),
        },
        other => Err(format!(
            "{func} needs boxes ([left, top, width, height], a box, or an object's `box`), found {}",
            other.kind()
        )),
    }
}

/// Intersection over union of two boxes as py-motmetrics' `boxiou` computes it (0 without
/// overlap or area).
fn iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let intersection = w * h;
    if intersection == 0.0 {
        return 0.0;
    }
    let area = |r: [f64; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let union = area(a) + area(b) - intersection;
    if union > 0.0 { intersection / union } else { 0.0 }
}

/// The built-in functions: `abs`, `sqrt`, `min`, `max`, `floor`, `ceil`, `norm` (length of a
/// vec2), `vec2(x, y)`, `dist` and `xydist` (Euclidean distance of two vec2 positions, or of two
/// records' `pos`; `dist` of two numbers is `|a - b|`), and for boxes in pixels `iou(a, b)`
/// (intersection over union) and `box_dist(a, b)` (the distance of their centres).
pub fn builtins() -> Vec<Function> {
    vec![
        Function::new("abs", (1, Some(1)), |a| match &a[0] {
            Value::Int(i) => i.checked_abs().map(Value::Int).ok_or_else(|| "abs overflows".to_string()),
            v => Ok(Value::Float(number(v, "abs")?.abs())),
        }),
        Function::new("sqrt", (1, Some(1)), |a| {
            let x = number(&a[0], "sqrt")?;
            if x < 0.0 { Err(format!("sqrt of a negative number ({x})")) } else { Ok(Value::Float(x.sqrt())) }
        }),
        Function::new("min", (1, None), |a| fold_numbers(a, "min", |x, y| x < y)),
        Function::new("max", (1, None), |a| fold_numbers(a, "max", |x, y| x > y)),
        Function::new("floor", (1, Some(1)), |a| finite(number(&a[0], "floor")?.floor(), "floor")),
        Function::new("ceil", (1, Some(1)), |a| finite(number(&a[0], "ceil")?.ceil(), "ceil")),
        Function::new("norm", (1, Some(1)), |a| {
            let [x, y] = point(&a[0], "norm")?;
            finite(x.hypot(y), "norm")
        }),
        Function::new("vec2", (2, Some(2)), |a| {
            let (x, y) = (number(&a[0], "vec2")?, number(&a[1], "vec2")?);
            Ok(Value::Vec2([x, y]))
        }),
        Function::new("xydist", (2, Some(2)), |a| distance(&a[0], &a[1], "xydist")).native(Native::XyDist),
        Function::new("dist", (2, Some(2)), |a| dist(&a[0], &a[1])).native(Native::Dist),
        Function::new("iou", (2, Some(2)), |a| {
            Ok(Value::Float(iou(pixel_box(&a[0], "iou")?, pixel_box(&a[1], "iou")?)))
        }),
        Function::new("box_dist", (2, Some(2)), |a| {
            let (p, q) = (pixel_box(&a[0], "box_dist")?, pixel_box(&a[1], "box_dist")?);
            let centre = |r: [f64; 4]| [(r[0] + r[2]) / 2.0, (r[1] + r[3]) / 2.0];
            let (c, d) = (centre(p), centre(q));
            finite((c[0] - d[0]).hypot(c[1] - d[1]), "box_dist")
        }),
    ]
}

/// `dist`: `|a - b|` of two numbers, else the distance of two positions.
fn dist(l: &Value, r: &Value) -> Result<Value, String> {
    match (l, r) {
        (l, r) if l.as_f64().is_some() && r.as_f64().is_some() => {
            finite((number(l, "dist")? - number(r, "dist")?).abs(), "dist")
        }
        (l, r) => distance(l, r, "dist"),
    }
}

/// `min`/`max`: ints stay ints when all arguments are ints.
fn fold_numbers(args: &[Value], func: &str, better: fn(f64, f64) -> bool) -> Result<Value, String> {
    let mut best = args[0].clone();
    let mut best_f = number(&best, func)?;
    for v in &args[1..] {
        let x = number(v, func)?;
        if better(x, best_f) {
            best = v.clone();
            best_f = x;
        }
    }
    if args.iter().all(|v| matches!(v, Value::Int(_))) { Ok(best) } else { Ok(Value::Float(best_f)) }
}

/// What a term is evaluated against: the state, the objects bound by quantifiers, and the
/// formula's functions and names (for messages).
pub(crate) struct TermEnv<'a, S: State + ?Sized> {
    pub state: &'a S,
    pub bindings: &'a [Binding],
    pub functions: &'a [Function],
    pub slot_names: &'a [Arc<str>],
    pub domain_names: &'a [Arc<str>],
}

/// An object bound by `forall`/`exists`: its type and its identity.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Binding {
    pub domain: DomainId,
    pub id: Arc<str>,
}

impl<'a, S: State + ?Sized> TermEnv<'a, S> {
    fn slot_name(&self, slot: SlotId) -> String {
        name_of(self.slot_names, slot)
    }

    /// Evaluates an atom: a term that must give a `bool`.
    pub fn eval_bool(&self, term: &Term) -> Result<bool, EvalError> {
        // The commonest atoms, a boolean field and a comparison, skip the `Value` round trip.
        match term {
            Term::Slot(slot) => match self.state.value(*slot) {
                Some(Value::Bool(b)) => Ok(*b),
                Some(other) => Err(EvalError::Type {
                    context: format!("`{}`", self.slot_name(*slot)),
                    expected: "bool".into(),
                    found: other.kind().into(),
                }),
                None => Err(EvalError::Missing { name: self.slot_name(*slot) }),
            },
            _ => match &*self.eval_ref(term).map_err(|e| *e)? {
                Value::Bool(b) => Ok(*b),
                other => Err(EvalError::Type {
                    context: "a condition".into(),
                    expected: "bool".into(),
                    found: other.kind().into(),
                }),
            },
        }
    }

    /// Evaluates a term, borrowing what the state or the term holds instead of copying it (a
    /// record's attribute, a constant), so that `xydist(from.pos, to.pos) < 10` copies no record.
    fn eval_ref<'t>(&self, term: &'t Term) -> Result<Cow<'t, Value>, Box<EvalError>>
    where
        'a: 't,
    {
        let state: &'a S = self.state;
        Ok(match term {
            Term::Const(v) => Cow::Borrowed(v),
            Term::Slot(slot) => Cow::Borrowed(
                state
                    .value(*slot)
                    .ok_or_else(|| Box::new(EvalError::Missing { name: self.slot_name(*slot) }))?,
            ),
            Term::Var(var) => {
                let binding = self.bindings.get(*var as usize).ok_or_else(|| {
                    Box::new(EvalError::Missing { name: format!("quantified variable #{var}") })
                })?;
                Cow::Borrowed(state.object(binding.domain, &binding.id).ok_or_else(|| {
                    Box::new(EvalError::MissingObject {
                        domain: name_of(self.domain_names, binding.domain),
                        id: binding.id.to_string(),
                    })
                })?)
            }
            Term::Field(base, field) => {
                let no_field = || {
                    Box::new(EvalError::NoField {
                        path: describe(base, self.slot_names),
                        field: field.to_string(),
                    })
                };
                match self.eval_ref(base)? {
                    // An attribute of a record the state holds is borrowed (`id` is computed).
                    Cow::Borrowed(Value::Record(r)) if &**field != "id" => {
                        Cow::Borrowed(field.of(r).ok_or_else(no_field)?)
                    }
                    value => Cow::Owned(value.field(field).ok_or_else(no_field)?),
                }
            }
            Term::Neg(inner) => Cow::Owned(match &*self.eval_ref(inner)? {
                Value::Int(i) => i
                    .checked_neg()
                    .map(Value::Int)
                    .ok_or_else(|| Box::new(EvalError::Arithmetic("integer overflow".into())))?,
                Value::Float(x) => Value::Float(-x),
                Value::Vec2([x, y]) => Value::Vec2([-x, -y]),
                other => return Err(Box::new(type_error("`-`", "a number or vec2", other))),
            }),
            Term::Not(inner) => match &*self.eval_ref(inner)? {
                Value::Bool(b) => Cow::Owned(Value::Bool(!b)),
                other => return Err(Box::new(type_error("`not`", "bool", other))),
            },
            Term::Binary(op, lhs, rhs) => {
                // `and`/`or` inside a term short-circuit like the connectives of formulas.
                if matches!(op, BinOp::And | BinOp::Or) {
                    let l = match &*self.eval_ref(lhs)? {
                        Value::Bool(l) => *l,
                        other => return Err(Box::new(type_error(op.symbol(), "bool", other))),
                    };
                    if (*op == BinOp::And && !l) || (*op == BinOp::Or && l) {
                        return Ok(Cow::Owned(Value::Bool(l)));
                    }
                    return match &*self.eval_ref(rhs)? {
                        Value::Bool(r) => Ok(Cow::Owned(Value::Bool(*r))),
                        other => Err(Box::new(type_error(op.symbol(), "bool", other))),
                    };
                }
                let l = self.eval_ref(lhs)?;
                let r = self.eval_ref(rhs)?;
                Cow::Owned(binary(*op, &l, &r).map_err(Box::new)?)
            }
            Term::Call(func, args) => Cow::Owned(self.call(*func, args)?),
        })
    }

    /// Calls a function with its arguments evaluated (on the stack for up to three).
    fn call(&self, func: FuncId, args: &[Term]) -> Result<Value, Box<EvalError>> {
        let function = self.functions.get(func as usize).ok_or_else(|| {
            Box::new(EvalError::Function { func: format!("#{func}"), message: "no such function".into() })
        })?;
        if let (Some(native), [a, b]) = (function.native, args) {
            // On borrowed arguments: `xydist(from.pos, to.pos)` copies nothing.
            let (a, b) = (self.eval_ref(a)?, self.eval_ref(b)?);
            let result = match native {
                Native::XyDist => distance(&a, &b, "xydist"),
                Native::Dist => dist(&a, &b),
            };
            return result.map_err(|message| {
                Box::new(EvalError::Function { func: function.name.to_string(), message })
            });
        }
        let result = match &function.borrowed {
            Some(body) => self.call_borrowed(body, args)?,
            None => self.call_owned(&function.body, args)?,
        };
        match result {
            Ok(Value::Float(x)) if !x.is_finite() => Err(Box::new(EvalError::Function {
                func: function.name.to_string(),
                message: "returned a non-finite number".into(),
            })),
            Ok(v) => Ok(v),
            Err(message) => Err(Box::new(EvalError::Function { func: function.name.to_string(), message })),
        }
    }

    /// A body on borrowed arguments ([`Function::borrowing`]), on the stack for up to three.
    fn call_borrowed(
        &self,
        body: &BorrowedBody,
        args: &[Term],
    ) -> Result<Result<Value, String>, Box<EvalError>> {
        Ok(match args {
            [a] => body(&[&*self.eval_ref(a)?]),
            [a, b] => {
                let (a, b) = (self.eval_ref(a)?, self.eval_ref(b)?);
                body(&[&*a, &*b])
            }
            [a, b, c] => {
                let (a, b, c) = (self.eval_ref(a)?, self.eval_ref(b)?, self.eval_ref(c)?);
                body(&[&*a, &*b, &*c])
            }
            _ => {
                let values = args.iter().map(|a| self.eval_ref(a)).collect::<Result<Vec<_>, _>>()?;
                body(&values.iter().map(|v| &**v).collect::<Vec<&Value>>())
            }
        })
    }

    /// A body on owned arguments (copies of what the state holds), on the stack for up to three.
    fn call_owned(
        &self,
        body: &FunctionBody,
        args: &[Term],
    ) -> Result<Result<Value, String>, Box<EvalError>> {
        let arg = |i: usize| self.eval_ref(&args[i]).map(Cow::into_owned);
        Ok(match args.len() {
            1 => body(&[arg(0)?]),
            2 => body(&[arg(0)?, arg(1)?]),
            3 => body(&[arg(0)?, arg(1)?, arg(2)?]),
            n => {
                let values = (0..n).map(arg).collect::<Result<Vec<Value>, Box<EvalError>>>()?;
                body(&values)
            }
        })
    }
}

fn type_error(context: &str, expected: &str, found: &Value) -> EvalError {
    EvalError::Type {
        context: context.to_string(),
        expected: expected.to_string(),
        found: found.kind().into(),
    }
}

/// The name of slot or object type `i` for messages, or `#i` when there is none.
pub(crate) fn name_of(names: &[Arc<str>], i: u32) -> String {
    names.get(i as usize).map_or_else(|| format!("#{i}"), |n| n.to_string())
}

/// A short text for a term, used in messages (`from.pos`).
fn describe(term: &Term, slot_names: &[Arc<str>]) -> String {
    match term {
        Term::Slot(s) => name_of(slot_names, *s),
        Term::Var(v) => format!("variable #{v}"),
        Term::Field(base, f) => format!("{}.{f}", describe(base, slot_names)),
        _ => "the value".to_string(),
    }
}

fn arithmetic(message: &str) -> EvalError {
    EvalError::Arithmetic(message.to_string())
}

fn float_result(x: f64, op: BinOp) -> Result<Value, EvalError> {
    if x.is_finite() {
        Ok(Value::Float(x))
    } else {
        Err(EvalError::Arithmetic(format!("`{}` gives a non-finite result (division by zero?)", op.symbol())))
    }
}

/// Applies an arithmetic or comparison operator to two values.
pub(crate) fn binary(op: BinOp, l: &Value, r: &Value) -> Result<Value, EvalError> {
    use BinOp::*;
    // The commonest atom compares two floats (`xydist(from.pos, to.pos) < 10.0`).
    if let (Value::Float(a), Value::Float(b)) = (l, r)
        && !a.is_nan()
        && !b.is_nan()
    {
        match op {
            Lt => return Ok(Value::Bool(a < b)),
            Le => return Ok(Value::Bool(a <= b)),
            Gt => return Ok(Value::Bool(a > b)),
            Ge => return Ok(Value::Bool(a >= b)),
            _ => {}
        }
    }
    match op {
        Eq | Ne => {
            let equal = match (l, r) {
                (Value::Int(a), Value::Int(b)) => a == b,
                (a, b) if a.as_f64().is_some() && b.as_f64().is_some() => a.as_f64() == b.as_f64(),
                (a, b) if std::mem::discriminant(a) == std::mem::discriminant(b) => a == b,
                (a, b) => {
                    return Err(EvalError::Type {
                        context: format!("`{}`", op.symbol()),
                        expected: format!("two values of one kind ({} on the left)", a.kind()),
                        found: b.kind().into(),
                    });
                }
            };
            Ok(Value::Bool(if op == Eq { equal } else { !equal }))
        }
        Lt | Le | Gt | Ge => {
            let ordering = match (l, r) {
                (Value::Int(a), Value::Int(b)) => a.cmp(b),
                (Value::Str(a), Value::Str(b)) => a.cmp(b),
                (Value::Duration(a), Value::Duration(b)) => a.cmp(b),
                (a, b) => match (a.as_f64(), b.as_f64()) {
                    (Some(x), Some(y)) => {
                        x.partial_cmp(&y).ok_or_else(|| arithmetic("comparison with NaN"))?
                    }
                    _ => {
                        let bad = if a.as_f64().is_none() { a } else { b };
                        return Err(type_error(&format!("`{}`", op.symbol()), "numbers", bad));
                    }
                },
            };
            use std::cmp::Ordering::*;
            Ok(Value::Bool(match op {
                Lt => ordering == Less,
                Le => ordering != Greater,
                Gt => ordering == Greater,
                _ => ordering != Less,
            }))
        }
        Add | Sub | Mul | Div | Rem => match (l, r) {
            (Value::Int(a), Value::Int(b)) if op != Div => {
                let result = match op {
                    Add => a.checked_add(*b),
                    Sub => a.checked_sub(*b),
                    Mul => a.checked_mul(*b),
                    _ => {
                        if *b == 0 {
                            return Err(arithmetic("`%` by zero"));
                        }
                        a.checked_rem(*b)
                    }
                };
                result.map(Value::Int).ok_or_else(|| arithmetic("integer overflow"))
            }
            (Value::Vec2([x1, y1]), Value::Vec2([x2, y2])) if matches!(op, Add | Sub) => {
                let s = if op == Add { 1.0 } else { -1.0 };
                Ok(Value::Vec2([x1 + s * x2, y1 + s * y2]))
            }
            (Value::Vec2([x, y]), k) | (k, Value::Vec2([x, y])) if op == Mul && k.as_f64().is_some() => {
                let k = k.as_f64().unwrap_or(0.0);
                Ok(Value::Vec2([x * k, y * k]))
            }
            (Value::Duration(a), Value::Duration(b)) if matches!(op, Add | Sub) => {
                let result = if op == Add { a.checked_add(*b) } else { a.checked_sub(*b) };
                result.map(Value::Duration).ok_or_else(|| arithmetic("duration overflow"))
            }
            (a, b) => match (a.as_f64(), b.as_f64()) {
                (Some(x), Some(y)) => float_result(
                    match op {
                        Add => x + y,
                        Sub => x - y,
                        Mul => x * y,
                        Div => x / y,
                        _ => x % y,
                    },
                    op,
                ),
                _ => {
                    let bad = if a.as_f64().is_none() { a } else { b };
                    Err(type_error(&format!("`{}`", op.symbol()), "numbers", bad))
                }
            },
        },
        And | Or => match (l, r) {
            (Value::Bool(a), Value::Bool(b)) => Ok(Value::Bool(if op == And { *a && *b } else { *a || *b })),
            (a, b) => Err(type_error(op.symbol(), "bool", if a.as_bool().is_none() { a } else { b })),
        },
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing test should fail loudly
mod tests {
    use super::*;

    #[test]
    fn numbers_follow_one_rule() {
        assert_eq!(binary(BinOp::Add, &Value::Int(2), &Value::Int(3)), Ok(Value::Int(5)));
        assert_eq!(binary(BinOp::Div, &Value::Int(3), &Value::Int(2)), Ok(Value::Float(1.5)));
        assert_eq!(binary(BinOp::Mul, &Value::Int(2), &Value::Float(0.5)), Ok(Value::Float(1.0)));
        assert!(matches!(binary(BinOp::Div, &Value::Int(1), &Value::Int(0)), Err(EvalError::Arithmetic(_))));
        assert!(matches!(
            binary(BinOp::Add, &Value::Int(i64::MAX), &Value::Int(1)),
            Err(EvalError::Arithmetic(_))
        ));
        assert_eq!(binary(BinOp::Lt, &Value::Int(2), &Value::Float(2.5)), Ok(Value::Bool(true)));
        assert_eq!(binary(BinOp::Eq, &Value::Int(2), &Value::Float(2.0)), Ok(Value::Bool(true)));
        assert!(matches!(binary(BinOp::Lt, &Value::Bool(true), &Value::Int(1)), Err(EvalError::Type { .. })));
    }

    #[test]
    fn builtins_compute_distances() {
        let f = builtins();
        let xydist = f.iter().find(|f| &*f.name == "xydist").unwrap();
        assert_eq!((xydist.body)(&[Value::vec2(0.0, 0.0), Value::vec2(3.0, 4.0)]), Ok(Value::Float(5.0)));
        let vec2 = f.iter().find(|f| &*f.name == "vec2").unwrap();
        assert_eq!((vec2.body)(&[Value::Int(3), Value::Float(4.5)]), Ok(Value::vec2(3.0, 4.5)));
        assert!((xydist.body)(&[Value::Int(1), Value::vec2(3.0, 4.0)]).is_err());
        let max = f.iter().find(|f| &*f.name == "max").unwrap();
        assert_eq!((max.body)(&[Value::Int(1), Value::Int(7), Value::Int(3)]), Ok(Value::Int(7)));
        assert_eq!((max.body)(&[Value::Int(1), Value::Float(0.5)]), Ok(Value::Float(1.0)));
    }

    #[test]
    fn builtins_compare_boxes() {
        let f = builtins();
        let call = |name: &str, args: &[Value]| (f.iter().find(|f| &*f.name == name).unwrap().body)(args);
        let list = |v: [f64; 4]| Value::List(v.iter().map(|x| Value::Float(*x)).collect::<Vec<_>>().into());
        // [left, top, width, height]: overlap 2 x 1 = 2, union 8 + 8 - 2.
        let (a, b) = (list([0.0, 0.0, 4.0, 2.0]), list([2.0, 1.0, 4.0, 2.0]));
        assert_eq!(call("iou", &[a.clone(), b.clone()]), Ok(Value::Float(2.0 / 14.0)));
        assert_eq!(call("iou", &[a.clone(), list([4.0, 0.0, 4.0, 2.0])]), Ok(Value::Float(0.0)));
        // A `box` value is [x1, y1, x2, y2]; an object stands for its `box`.
        let bbox = Value::bbox(kpl_core::BBox::new(2.0, 1.0, 6.0, 3.0));
        let object = Value::Record(Arc::new(Record {
            id: Some("t1".into()),
            fields: vec![("box".into(), b.clone())],
        }));
        assert_eq!(call("iou", &[a.clone(), bbox]), Ok(Value::Float(2.0 / 14.0)));
        assert_eq!(call("iou", &[object, a.clone()]), Ok(Value::Float(2.0 / 14.0)));
        assert_eq!(call("box_dist", &[a.clone(), b]), Ok(Value::Float(5f64.sqrt())));
        assert!(call("iou", &[a, Value::Int(3)]).unwrap_err().contains("needs boxes"));
    }
}
