//! Formulas: [`Mtl`], the tree a caller builds (or the lowering produces from `ast::Expr`), and
//! [`Formula`], its compiled form in negation normal form that progressors share.
//!
//! Compiling pushes every `not` down to the atoms (`not eventually φ` = `always not φ`,
//! `not (φ until ψ)` = `(not φ) release (not ψ)`) and turns `a -> b` into `not a or b`, so the
//! progressor only ever sees `and`, `or`, four temporal operators and atoms.

use std::fmt;
use std::sync::Arc;

use kpl_core::Time;

use crate::context::Context;
use crate::error::FormulaError;
use crate::term::{DomainId, Function, Term};

/// `[lo, hi]` in the time unit of the time stamps the formula is progressed with; `hi: None` is
/// `inf`. Both ends are closed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Window {
    pub lo: Time,
    pub hi: Option<Time>,
}

impl Window {
    pub const UNBOUNDED: Window = Window { lo: 0, hi: None };

    pub fn new(lo: Time, hi: Option<Time>) -> Window {
        Window { lo, hi }
    }
    pub fn bounded(lo: Time, hi: Time) -> Window {
        Window { lo, hi: Some(hi) }
    }
}

impl fmt::Display for Window {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.hi {
            Some(hi) => write!(f, "[{}, {hi}]", self.lo),
            None => write!(f, "[{}, inf]", self.lo),
        }
    }
}

/// A metric temporal logic formula as built by hand or by the lowering. Quantifiers bind
/// variables by depth: inside the body of the outermost `Forall`/`Exists`, `Term::Var(0)` is its
/// object; one level deeper, `Term::Var(1)`, and so on.
#[derive(Debug, Clone, PartialEq)]
pub enum Mtl {
    Const(bool),
    /// A term of type `bool`, evaluated at the state where the atom is reached.
    Atom(Term),
    Not(Box<Mtl>),
    And(Vec<Mtl>),
    Or(Vec<Mtl>),
    Implies(Box<Mtl>, Box<Mtl>),
    Eventually(Window, Box<Mtl>),
    Always(Window, Box<Mtl>),
    /// `φ until[a, b] ψ`: ψ at some state in the window, φ at every state strictly between the
    /// current one and that one (DyKnow's definition; see `docs/mtl.md`).
    Until(Window, Box<Mtl>, Box<Mtl>),
    Forall(DomainId, Box<Mtl>),
    Exists(DomainId, Box<Mtl>),
}

#[allow(clippy::should_implement_trait)] // `not` builds a formula; `std::ops::Not` would hide that
impl Mtl {
    pub fn atom(term: Term) -> Mtl {
        Mtl::Atom(term)
    }
    pub fn not(f: Mtl) -> Mtl {
        Mtl::Not(Box::new(f))
    }
    pub fn and(fs: Vec<Mtl>) -> Mtl {
        Mtl::And(fs)
    }
    pub fn or(fs: Vec<Mtl>) -> Mtl {
        Mtl::Or(fs)
    }
    pub fn implies(a: Mtl, b: Mtl) -> Mtl {
        Mtl::Implies(Box::new(a), Box::new(b))
    }
    pub fn eventually(window: Window, f: Mtl) -> Mtl {
        Mtl::Eventually(window, Box::new(f))
    }
    pub fn always(window: Window, f: Mtl) -> Mtl {
        Mtl::Always(window, Box::new(f))
    }
    pub fn until(window: Window, lhs: Mtl, rhs: Mtl) -> Mtl {
        Mtl::Until(window, Box::new(lhs), Box::new(rhs))
    }
}

/// A node of a compiled formula.
pub(crate) type TplId = u32;

/// The four temporal operators of negation normal form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) enum TemporalOp {
    Eventually,
    Always,
    /// DyKnow's until; in a residual, the strict part is already done (see `progress`).
    Until,
    /// The dual of until: `φ release ψ` = `not (not φ until not ψ)`.
    Release,
}

/// Upper bounds use `INF` for `inf`; shifting keeps it.
pub(crate) const INF: Time = Time::MAX;

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum TNode {
    Const(bool),
    Atom {
        term: u32,
        negated: bool,
    },
    And(Vec<TplId>),
    Or(Vec<TplId>),
    /// For `Eventually`/`Always` only `rhs` is used.
    Temporal {
        op: TemporalOp,
        lo: Time,
        hi: Time,
        lhs: TplId,
        rhs: TplId,
    },
    Quant {
        forall: bool,
        domain: DomainId,
        body: TplId,
    },
}

/// A compiled formula: immutable, shared by any number of progressors (`Arc<Formula>`).
#[derive(Debug, Clone)]
pub struct Formula {
    pub(crate) nodes: Vec<TNode>,
    pub(crate) terms: Vec<Term>,
    pub(crate) root: TplId,
    pub(crate) functions: Arc<[Function]>,
    pub(crate) slot_names: Arc<[Arc<str>]>,
    pub(crate) domain_names: Arc<[Arc<str>]>,
    source: Mtl,
}

impl Formula {
    /// Compiles a formula against the context that assigned its slots, domains and functions.
    pub fn new(mtl: &Mtl, context: &Context) -> Result<Formula, FormulaError> {
        let functions: Arc<[Function]> = context.functions().to_vec().into();
        let mut compiler = Compiler { nodes: Vec::new(), terms: Vec::new(), functions: &functions };
        let root = compiler.compile(mtl, false, 0)?;
        let Compiler { nodes, terms, .. } = compiler;
        Ok(Formula {
            nodes,
            terms,
            root,
            functions: functions.clone(),
            slot_names: context.slot_names().into(),
            domain_names: context.domain_names().into(),
            source: mtl.clone(),
        })
    }

    /// The formula as it was given.
    pub fn source(&self) -> &Mtl {
        &self.source
    }

    /// Number of nodes of the compiled (negation normal form) formula.
    pub fn size(&self) -> usize {
        self.nodes.len()
    }

    /// The names of the slots, by slot index.
    pub fn slot_names(&self) -> &[Arc<str>] {
        &self.slot_names
    }

    /// The largest time, relative to the state a verdict is for, that the verdict can depend on
    /// (`None`: unbounded). `eventually[0, 5] always[0, 2] p` has horizon 7.
    pub fn horizon(&self) -> Option<Time> {
        self.horizon_of(self.root)
    }

    fn horizon_of(&self, id: TplId) -> Option<Time> {
        match &self.nodes[id as usize] {
            TNode::Const(_) | TNode::Atom { .. } => Some(0),
            TNode::And(ks) | TNode::Or(ks) => {
                ks.iter().try_fold(0, |acc, k| self.horizon_of(*k).map(|h| acc.max(h)))
            }
            TNode::Temporal { op, hi, lhs, rhs, .. } => {
                if *hi == INF {
                    return None;
                }
                let body = match op {
                    TemporalOp::Until | TemporalOp::Release => {
                        self.horizon_of(*lhs)?.max(self.horizon_of(*rhs)?)
                    }
                    _ => self.horizon_of(*rhs)?,
                };
                hi.checked_add(body)
            }
            TNode::Quant { body, .. } => self.horizon_of(*body),
        }
    }

    /// Writes a compiled node as text (used to show residuals).
    pub(crate) fn write_node(&self, f: &mut impl fmt::Write, id: TplId) -> fmt::Result {
        match &self.nodes[id as usize] {
            TNode::Const(b) => write!(f, "{b}"),
            TNode::Atom { term, negated } => {
                if *negated {
                    f.write_str("not ")?;
                }
                self.write_term(f, &self.terms[*term as usize])
            }
            TNode::And(ks) | TNode::Or(ks) => {
                let sep = if matches!(self.nodes[id as usize], TNode::And(_)) { " and " } else { " or " };
                f.write_char('(')?;
                for (i, k) in ks.iter().enumerate() {
                    if i > 0 {
                        f.write_str(sep)?;
                    }
                    self.write_node(f, *k)?;
                }
                f.write_char(')')
            }
            TNode::Temporal { op, lo, hi, lhs, rhs } => {
                let window = Window::new(*lo, (*hi != INF).then_some(*hi));
                match op {
                    TemporalOp::Eventually | TemporalOp::Always => {
                        let kw = if *op == TemporalOp::Eventually { "eventually" } else { "always" };
                        write!(f, "{kw}{window} ")?;
                        self.write_node(f, *rhs)
                    }
                    TemporalOp::Until | TemporalOp::Release => {
                        let kw = if *op == TemporalOp::Until { "until" } else { "release" };
                        f.write_char('(')?;
                        self.write_node(f, *lhs)?;
                        write!(f, " {kw}{window} ")?;
                        self.write_node(f, *rhs)?;
                        f.write_char(')')
                    }
                }
            }
            TNode::Quant { forall, domain, body } => {
                let name = self.domain_names.get(*domain as usize).map_or("?", |n| n);
                write!(f, "({} {name} . ", if *forall { "forall" } else { "exists" })?;
                self.write_node(f, *body)?;
                f.write_char(')')
            }
        }
    }

    fn write_term(&self, f: &mut impl fmt::Write, term: &Term) -> fmt::Result {
        match term {
            Term::Const(v) => write!(f, "{v}"),
            Term::Slot(s) => f.write_str(self.slot_names.get(*s as usize).map_or("?", |n| n)),
            Term::Var(v) => write!(f, "${v}"),
            Term::Field(base, name) => {
                self.write_term(f, base)?;
                write!(f, ".{name}")
            }
            Term::Neg(t) => {
                f.write_char('-')?;
                self.write_term(f, t)
            }
            Term::Not(t) => {
                f.write_str("not ")?;
                self.write_term(f, t)
            }
            Term::Binary(op, l, r) => {
                f.write_char('(')?;
                self.write_term(f, l)?;
                write!(f, " {} ", op.symbol())?;
                self.write_term(f, r)?;
                f.write_char(')')
            }
            Term::Call(func, args) => {
                f.write_str(self.functions.get(*func as usize).map_or("?", |g| &g.name))?;
                f.write_char('(')?;
                for (i, a) in args.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    self.write_term(f, a)?;
                }
                f.write_char(')')
            }
        }
    }
}

impl fmt::Display for Formula {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write_node(f, self.root)
    }
}

struct Compiler<'a> {
    nodes: Vec<TNode>,
    terms: Vec<Term>,
    functions: &'a [Function],
}

impl Compiler<'_> {
    fn push(&mut self, node: TNode) -> TplId {
        self.nodes.push(node);
        (self.nodes.len() - 1) as TplId
    }

    fn window(&self, w: &Window) -> Result<(Time, Time), FormulaError> {
        if w.lo < 0 {
            return Err(FormulaError::NegativeBound(w.lo));
        }
        match w.hi {
            Some(hi) if hi < 0 => Err(FormulaError::NegativeBound(hi)),
            Some(hi) if hi < w.lo => Err(FormulaError::EmptyInterval { lo: w.lo, hi }),
            // `Time::MAX` itself is the marker for `inf`; a finite bound that large is the same.
            Some(hi) => Ok((w.lo, hi)),
            None => Ok((w.lo, INF)),
        }
    }

    fn check_term(&self, term: &Term, depth: u32) -> Result<(), FormulaError> {
        match term {
            Term::Const(_) | Term::Slot(_) => Ok(()),
            Term::Var(v) if *v < depth => Ok(()),
            Term::Var(v) => Err(FormulaError::UnboundVariable { var: *v }),
            Term::Field(t, _) | Term::Neg(t) | Term::Not(t) => self.check_term(t, depth),
            Term::Binary(_, l, r) => {
                self.check_term(l, depth)?;
                self.check_term(r, depth)
            }
            Term::Call(func, args) => {
                let function = self
                    .functions
                    .get(*func as usize)
                    .ok_or(FormulaError::UnknownFunction { func: *func })?;
                if !function.accepts(args.len()) {
                    return Err(FormulaError::Arity {
                        name: function.name.to_string(),
                        expected: function.arity_text(),
                        found: args.len(),
                    });
                }
                args.iter().try_for_each(|a| self.check_term(a, depth))
            }
        }
    }

    /// Compiles `mtl`, negated when `negate` is set, with `depth` enclosing quantifiers.
    fn compile(&mut self, mtl: &Mtl, negate: bool, depth: u32) -> Result<TplId, FormulaError> {
        Ok(match mtl {
            Mtl::Const(b) => self.push(TNode::Const(*b != negate)),
            Mtl::Atom(term) => {
                self.check_term(term, depth)?;
                // A constant atom folds away; a negated `not t` atom is `t`.
                let (term, negated) = match term {
                    Term::Const(kpl_core::Value::Bool(b)) => return Ok(self.push(TNode::Const(*b != negate))),
                    Term::Not(inner) => ((**inner).clone(), !negate),
                    t => (t.clone(), negate),
                };
                self.terms.push(term);
                self.push(TNode::Atom { term: (self.terms.len() - 1) as u32, negated })
            }
            Mtl::Not(f) => self.compile(f, !negate, depth)?,
            Mtl::And(fs) | Mtl::Or(fs) => {
                let is_and = matches!(mtl, Mtl::And(_)) != negate;
                if fs.is_empty() {
                    return Ok(self.push(TNode::Const(is_and)));
                }
                let mut kids = Vec::with_capacity(fs.len());
                for f in fs {
                    kids.push(self.compile(f, negate, depth)?);
                }
                if kids.len() == 1 {
                    kids[0]
                } else if is_and {
                    self.push(TNode::And(kids))
                } else {
                    self.push(TNode::Or(kids))
                }
            }
            Mtl::Implies(a, b) => {
                // a -> b = not a or b;  not (a -> b) = a and not b
                let lhs = self.compile(a, !negate, depth)?;
                let rhs = self.compile(b, negate, depth)?;
                if negate {
                    self.push(TNode::And(vec![lhs, rhs]))
                } else {
                    self.push(TNode::Or(vec![lhs, rhs]))
                }
            }
            Mtl::Eventually(w, f) | Mtl::Always(w, f) => {
                let (lo, hi) = self.window(w)?;
                let body = self.compile(f, negate, depth)?;
                let eventually = matches!(mtl, Mtl::Eventually(..)) != negate;
                let op = if eventually { TemporalOp::Eventually } else { TemporalOp::Always };
                self.push(TNode::Temporal { op, lo, hi, lhs: body, rhs: body })
            }
            Mtl::Until(w, a, b) => {
                let (lo, hi) = self.window(w)?;
                let lhs = self.compile(a, negate, depth)?;
                let rhs = self.compile(b, negate, depth)?;
                let op = if negate { TemporalOp::Release } else { TemporalOp::Until };
                self.push(TNode::Temporal { op, lo, hi, lhs, rhs })
            }
            Mtl::Forall(domain, f) | Mtl::Exists(domain, f) => {
                let body = self.compile(f, negate, depth + 1)?;
                let forall = matches!(mtl, Mtl::Forall(..)) != negate;
                self.push(TNode::Quant { forall, domain: *domain, body })
            }
        })
    }
}
