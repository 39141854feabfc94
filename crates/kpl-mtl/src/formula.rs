//! Formulas: [`Mtl`], the tree a caller builds (or the lowering produces from `ast::Expr`), and
//! [`Formula`], its compiled form in negation normal form that progressors share.
//!
//! Compiling pushes every `not` down to the atoms (`not eventually φ` = `always not φ`,
//! `not (φ until ψ)` = `(not φ) release (not ψ)`), turns `a -> b` into `not a or b`, folds
//! constants (`always[2, 4] true` is `true`, so its verdict comes at the first state), and numbers
//! the distinct atoms so that each is read once per state. The progressor only ever sees `and`,
//! `or`, four temporal operators, quantifiers and atoms.

use std::collections::HashMap;
use std::fmt;
use std::sync::Arc;

use kpl_core::Time;

use crate::atoms::AtomPlan;
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
/// An atom of a compiled formula: an index into [`Formula::atoms`].
pub(crate) type AtomId = u32;

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

impl TemporalOp {
    /// `eventually` and `until` are satisfied by one state; `always` and `release` need all.
    pub(crate) fn is_existential(self) -> bool {
        matches!(self, TemporalOp::Eventually | TemporalOp::Until)
    }
}

/// Window ends inside the engine are offsets from a state's time: non-negative, so they are kept
/// as `u64`, and `INF` (above every finite bound, which is at most `i64::MAX`) is `inf`. A finite
/// bound of `i64::MAX` stays finite.
pub(crate) const INF: u64 = u64::MAX;

/// Atoms with an index below this are read into one machine word per state, and residuals that
/// read only such atoms can use the transition cache.
pub(crate) const WORD_ATOMS: u32 = 64;

#[derive(Debug, Clone, PartialEq)]
pub(crate) enum TNode {
    Const(bool),
    Atom {
        atom: AtomId,
        negated: bool,
    },
    And(Vec<TplId>),
    Or(Vec<TplId>),
    /// For `Eventually`/`Always` only `rhs` is used.
    Temporal {
        op: TemporalOp,
        lo: u64,
        hi: u64,
        lhs: TplId,
        rhs: TplId,
    },
    Quant {
        forall: bool,
        domain: DomainId,
        body: TplId,
    },
}

/// What the progression needs to know about a compiled node without walking it.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct TplInfo {
    /// The atoms (below [`WORD_ATOMS`]) that instantiating this node may read, as a bit set.
    pub reads: u64,
    /// No quantifier below and every atom below [`WORD_ATOMS`]: what instantiating it gives
    /// depends only on the values of the atoms in `reads`, so transitions can be cached.
    pub cacheable: bool,
    /// For an `and`/`or` of atoms only: its literals as bit masks (see [`Literals`]).
    pub literals: Option<Literals>,
}

/// An `and` (or `or`) of atoms and negated atoms, decided with bit operations on the atom
/// values of a state: `mask` holds its atoms, `negated` those that appear negated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Literals {
    pub mask: u64,
    pub negated: u64,
}

/// A compiled formula: immutable, shared by any number of progressors (`Arc<Formula>`).
#[derive(Debug, Clone)]
pub struct Formula {
    pub(crate) nodes: Vec<TNode>,
    pub(crate) info: Vec<TplInfo>,
    /// The distinct atoms, each read at most once per state.
    pub(crate) atoms: Vec<Term>,
    /// Per atom, how it is read.
    pub(crate) plans: Vec<AtomPlan>,
    pub(crate) root: TplId,
    pub(crate) functions: Arc<[Function]>,
    pub(crate) slot_names: Arc<[Arc<str>]>,
    pub(crate) domain_names: Arc<[Arc<str>]>,
    source: Mtl,
    /// Worked out when a handover first asks for it.
    fingerprint: std::sync::OnceLock<u64>,
}

impl Formula {
    /// Compiles a formula against the context that assigned its slots, domains and functions.
    pub fn new(mtl: &Mtl, context: &Context) -> Result<Formula, FormulaError> {
        let functions: Arc<[Function]> = context.functions().to_vec().into();
        let mut compiler = Compiler {
            nodes: Vec::new(),
            atoms: Vec::new(),
            atom_index: HashMap::new(),
            functions: &functions,
        };
        let root = compiler.compile(mtl, false, 0)?;
        let Compiler { nodes, atoms, .. } = compiler;
        let info = template_info(&nodes);
        let plans = atoms.iter().map(|atom| AtomPlan::of(atom, &functions)).collect();
        Ok(Formula {
            nodes,
            info,
            atoms,
            plans,
            root,
            functions: functions.clone(),
            slot_names: context.slot_names().into(),
            domain_names: context.domain_names().into(),
            source: mtl.clone(),
            fingerprint: std::sync::OnceLock::new(),
        })
    }

    /// A 64-bit FNV-1a hash of the compiled formula (its nodes, its text with the atoms, the
    /// names of its slots and domains): equal for the same formula compiled against the same
    /// names, in any process of the same build, so that a [`crate::Handover`] finds out whether
    /// it is taken over by a group of its own formula.
    pub fn fingerprint(&self) -> u64 {
        *self.fingerprint.get_or_init(|| self.compute_fingerprint())
    }

    fn compute_fingerprint(&self) -> u64 {
        let text = format!("{:?}\n{self}\n{:?}\n{:?}", self.nodes, self.slot_names, self.domain_names);
        text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
    }

    /// The formula as it was given.
    pub fn source(&self) -> &Mtl {
        &self.source
    }

    /// Number of nodes of the compiled (negation normal form, constants folded) formula.
    pub fn size(&self) -> usize {
        self.nodes.len()
    }

    /// Number of distinct atoms (conditions read from a state).
    pub fn atom_count(&self) -> usize {
        self.atoms.len()
    }

    /// The names of the slots, by slot index.
    pub fn slot_names(&self) -> &[Arc<str>] {
        &self.slot_names
    }

    /// The compiled formula's verdict if it does not depend on any state (`always[0, 5] true`).
    pub fn constant(&self) -> Option<bool> {
        match self.nodes[self.root as usize] {
            TNode::Const(b) => Some(b),
            _ => None,
        }
    }

    /// The largest time, relative to the state a verdict is for, that the verdict can depend on
    /// (`None`: unbounded). `eventually[0, 5] always[0, 2] p` has horizon 7.
    pub fn horizon(&self) -> Option<Time> {
        self.horizon_of(self.root).and_then(|h| Time::try_from(h).ok())
    }

    fn horizon_of(&self, id: TplId) -> Option<u64> {
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
                hi.checked_add(body).filter(|h| *h <= i64::MAX as u64)
            }
            TNode::Quant { body, .. } => self.horizon_of(*body),
        }
    }

    /// Writes a window as text (`[0, 5]`, `[2, inf]`).
    pub(crate) fn write_window(f: &mut impl fmt::Write, lo: u64, hi: u64) -> fmt::Result {
        if hi == INF { write!(f, "[{lo}, inf]") } else { write!(f, "[{lo}, {hi}]") }
    }

    /// Writes a compiled node as text (used to show residuals).
    pub(crate) fn write_node(&self, f: &mut impl fmt::Write, id: TplId) -> fmt::Result {
        match &self.nodes[id as usize] {
            TNode::Const(b) => write!(f, "{b}"),
            TNode::Atom { atom, negated } => {
                if *negated {
                    f.write_str("not ")?;
                }
                self.write_term(f, &self.atoms[*atom as usize])
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
            TNode::Temporal { op, lo, hi, lhs, rhs } => match op {
                TemporalOp::Eventually | TemporalOp::Always => {
                    f.write_str(if *op == TemporalOp::Eventually { "eventually" } else { "always" })?;
                    Formula::write_window(f, *lo, *hi)?;
                    f.write_char(' ')?;
                    self.write_node(f, *rhs)
                }
                TemporalOp::Until | TemporalOp::Release => {
                    f.write_char('(')?;
                    self.write_node(f, *lhs)?;
                    f.write_str(if *op == TemporalOp::Until { " until" } else { " release" })?;
                    Formula::write_window(f, *lo, *hi)?;
                    f.write_char(' ')?;
                    self.write_node(f, *rhs)?;
                    f.write_char(')')
                }
            },
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

/// The [`TplInfo`] of every node; children come before their parents in `nodes`.
fn template_info(nodes: &[TNode]) -> Vec<TplInfo> {
    let mut info: Vec<TplInfo> = Vec::with_capacity(nodes.len());
    for node in nodes {
        let of = |k: &TplId| info[*k as usize];
        let item = match node {
            TNode::Const(_) => TplInfo { reads: 0, cacheable: true, literals: None },
            TNode::Atom { atom, .. } => {
                let word = *atom < WORD_ATOMS;
                TplInfo { reads: if word { 1 << atom } else { 0 }, cacheable: word, literals: None }
            }
            TNode::And(ks) | TNode::Or(ks) => {
                let reads = ks.iter().fold(0, |acc, k| acc | of(k).reads);
                let cacheable = ks.iter().all(|k| of(k).cacheable);
                let mut literals = Some(Literals { mask: 0, negated: 0 });
                for k in ks {
                    match (&nodes[*k as usize], literals.as_mut()) {
                        (TNode::Atom { atom, negated }, Some(l)) if *atom < WORD_ATOMS => {
                            let bit = 1u64 << atom;
                            // `p and not p`: the bit sets cannot say it; evaluate it one by one.
                            if l.mask & bit != 0 && (l.negated & bit != 0) != *negated {
                                literals = None;
                                continue;
                            }
                            l.mask |= bit;
                            if *negated {
                                l.negated |= bit;
                            }
                        }
                        _ => literals = None,
                    }
                }
                TplInfo { reads, cacheable, literals }
            }
            TNode::Temporal { lhs, rhs, .. } => TplInfo {
                reads: of(lhs).reads | of(rhs).reads,
                cacheable: of(lhs).cacheable && of(rhs).cacheable,
                literals: None,
            },
            TNode::Quant { body, .. } => TplInfo { reads: of(body).reads, cacheable: false, literals: None },
        };
        info.push(item);
    }
    info
}

struct Compiler<'a> {
    nodes: Vec<TNode>,
    atoms: Vec<Term>,
    /// Atoms by their text (`Term` has floats, so no `Hash`; its debug text is exact).
    atom_index: HashMap<String, AtomId>,
    functions: &'a [Function],
}

impl Compiler<'_> {
    fn push(&mut self, node: TNode) -> TplId {
        self.nodes.push(node);
        (self.nodes.len() - 1) as TplId
    }

    fn constant(&self, id: TplId) -> Option<bool> {
        match self.nodes[id as usize] {
            TNode::Const(b) => Some(b),
            _ => None,
        }
    }

    fn window(&self, w: &Window) -> Result<(u64, u64), FormulaError> {
        if w.lo < 0 {
            return Err(FormulaError::NegativeBound(w.lo));
        }
        match w.hi {
            Some(hi) if hi < 0 => Err(FormulaError::NegativeBound(hi)),
            Some(hi) if hi < w.lo => Err(FormulaError::EmptyInterval { lo: w.lo, hi }),
            // Both are non-negative here, so they fit; a finite `i64::MAX` stays below `INF`.
            Some(hi) => Ok((w.lo as u64, hi as u64)),
            None => Ok((w.lo as u64, INF)),
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

    fn atom(&mut self, term: Term) -> AtomId {
        let key = format!("{term:?}");
        if let Some(id) = self.atom_index.get(&key) {
            return *id;
        }
        let id = self.atoms.len() as AtomId;
        self.atoms.push(term);
        self.atom_index.insert(key, id);
        id
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
                let atom = self.atom(term);
                self.push(TNode::Atom { atom, negated })
            }
            Mtl::Not(f) => self.compile(f, !negate, depth)?,
            Mtl::And(fs) | Mtl::Or(fs) => {
                let is_and = matches!(mtl, Mtl::And(_)) != negate;
                let mut kids = Vec::with_capacity(fs.len());
                for f in fs {
                    kids.push(self.compile(f, negate, depth)?);
                }
                self.junction(is_and, kids)
            }
            Mtl::Implies(a, b) => {
                // a -> b = not a or b;  not (a -> b) = a and not b
                let lhs = self.compile(a, !negate, depth)?;
                let rhs = self.compile(b, negate, depth)?;
                self.junction(negate, vec![lhs, rhs])
            }
            Mtl::Eventually(w, f) | Mtl::Always(w, f) => {
                let (lo, hi) = self.window(w)?;
                let body = self.compile(f, negate, depth)?;
                let eventually = matches!(mtl, Mtl::Eventually(..)) != negate;
                let op = if eventually { TemporalOp::Eventually } else { TemporalOp::Always };
                self.temporal(op, lo, hi, body, body)
            }
            Mtl::Until(w, a, b) => {
                let (lo, hi) = self.window(w)?;
                let lhs = self.compile(a, negate, depth)?;
                let rhs = self.compile(b, negate, depth)?;
                let op = if negate { TemporalOp::Release } else { TemporalOp::Until };
                self.temporal(op, lo, hi, lhs, rhs)
            }
            Mtl::Forall(domain, f) | Mtl::Exists(domain, f) => {
                let body = self.compile(f, negate, depth + 1)?;
                let forall = matches!(mtl, Mtl::Forall(..)) != negate;
                // Whatever the objects: `forall c . true` holds and `exists c . false` fails.
                match self.constant(body) {
                    Some(b) if b == forall => return Ok(body),
                    _ => self.push(TNode::Quant { forall, domain: *domain, body }),
                }
            }
        })
    }

    /// An `and` (or `or`) with constants folded: `false and x` is `false`, `true and x` is `x`.
    fn junction(&mut self, is_and: bool, kids: Vec<TplId>) -> TplId {
        let mut kept = Vec::with_capacity(kids.len());
        for k in kids {
            match self.constant(k) {
                Some(b) if b == is_and => {}
                Some(b) => return self.push(TNode::Const(b)),
                None => kept.push(k),
            }
        }
        match kept.len() {
            0 => self.push(TNode::Const(is_and)),
            1 => kept[0],
            _ if is_and => self.push(TNode::And(kept)),
            _ => self.push(TNode::Or(kept)),
        }
    }

    /// A temporal node with constant bodies folded, so that their verdicts come at once:
    /// `always[a, b] true` and `φ release[a, b] true` hold, `eventually[a, b] false` and
    /// `φ until[a, b] false` fail, whatever the states; with a lower bound 0 the current state is
    /// in the window, so `eventually[0, b] true` holds and `always[0, b] false` fails (and the
    /// same for until and release). `true until ψ` is `eventually ψ`, `false release ψ` is
    /// `always ψ`.
    fn temporal(&mut self, op: TemporalOp, lo: u64, hi: u64, lhs: TplId, rhs: TplId) -> TplId {
        let existential = op.is_existential();
        match self.constant(rhs) {
            Some(b) if b != existential => return rhs,
            Some(_) if lo == 0 => return rhs,
            _ => {}
        }
        let op = match (op, self.constant(lhs)) {
            (TemporalOp::Until, Some(true)) => TemporalOp::Eventually,
            (TemporalOp::Release, Some(false)) => TemporalOp::Always,
            (op, _) => op,
        };
        let lhs = if matches!(op, TemporalOp::Eventually | TemporalOp::Always) { rhs } else { lhs };
        self.push(TNode::Temporal { op, lo, hi, lhs, rhs })
    }
}
