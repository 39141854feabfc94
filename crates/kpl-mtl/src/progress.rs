//! Progression: rewriting a formula through one timed state at a time.
//!
//! A *residual* is what is left of a formula after some states: a DAG of `and`/`or` nodes over
//! pending temporal nodes (`eventually`, `always`, `until`, `release`), each with a window
//! relative to the time of the last state and a reference to the compiled body that it will
//! instantiate at the states that fall in that window. Atoms never appear in a residual: they are
//! evaluated at the state where they are reached.
//!
//! Each step builds the new residual in a fresh arena with hash-consing (equal sub-residuals get
//! one node), and every `and`/`or` is simplified as it is built (constants, flattening,
//! duplicates, window merging and subsumption; see `docs/mtl.md`). The old arena is then
//! dropped whole, so there is no garbage to collect and the arena's size is the residual's.
//! Every simplification keeps the Kleene (three-valued) value of the residual over every future,
//! which is why a residual becomes `true` or `false` exactly when the three-valued prefix
//! semantics decides the formula (the property the differential tests check).

use std::collections::HashMap;
use std::fmt;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::Arc;

use kpl_core::Time;

use crate::error::EvalError;
use crate::formula::{Formula, INF, TNode, TemporalOp, TplId};
use crate::state::State;
use crate::term::{Binding, TermEnv, name_of};

pub(crate) const TRUE: u32 = 0;
pub(crate) const FALSE: u32 = 1;
const NONE: u32 = u32::MAX;
/// `and`/`or` nodes with more children than this skip the pairwise implication check (it is
/// quadratic); window merging and duplicate removal still apply.
const IMPLICATION_CHECK_LIMIT: usize = 24;
/// How deep the syntactic implication check looks.
const IMPLICATION_DEPTH: u32 = 3;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum Kind {
    True,
    False,
    And,
    Or,
    Temporal(TemporalOp),
}

/// One residual node. Temporal nodes use `op`, `lo`, `hi` (relative to the last state's time,
/// `hi == INF` for unbounded), `tpl` (the compiled temporal node) and `env` (the objects bound by
/// enclosing quantifiers); `and`/`or` nodes use `kids..kids + n_kids` in the arena's `kids`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Node {
    kind: Kind,
    lo: Time,
    hi: Time,
    tpl: TplId,
    env: u32,
    kids: u32,
    n_kids: u32,
}

impl Node {
    fn temporal(op: TemporalOp, lo: Time, hi: Time, tpl: TplId, env: u32) -> Node {
        Node { kind: Kind::Temporal(op), lo, hi, tpl, env, kids: 0, n_kids: 0 }
    }
    fn constant(value: bool) -> Node {
        Node {
            kind: if value { Kind::True } else { Kind::False },
            lo: 0,
            hi: 0,
            tpl: 0,
            env: 0,
            kids: 0,
            n_kids: 0,
        }
    }
}

/// Keys of the interning table are already well mixed hashes.
#[derive(Default)]
struct IdHasher(u64);

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(*b)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = n;
    }
}

fn mix(h: u64, x: u64) -> u64 {
    (h.rotate_left(5) ^ x).wrapping_mul(0x517C_C1B7_2722_0A95)
}

type Env = Arc<[Binding]>;

/// Hash-consed residual nodes of one generation.
#[derive(Default)]
pub(crate) struct Arena {
    nodes: Vec<Node>,
    /// Per node: the previous node with the same hash (`NONE` if none).
    chain: Vec<u32>,
    kids: Vec<u32>,
    table: HashMap<u64, u32, BuildHasherDefault<IdHasher>>,
    envs: Vec<Env>,
    env_table: HashMap<Env, u32>,
}

impl fmt::Debug for Arena {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Arena").field("nodes", &self.nodes.len()).field("envs", &self.envs.len()).finish()
    }
}

impl Arena {
    fn new() -> Arena {
        let mut arena = Arena::default();
        arena.reset();
        arena
    }

    fn reset(&mut self) {
        self.nodes.clear();
        self.chain.clear();
        self.kids.clear();
        // Keep the table's memory unless one large residual left it mostly empty.
        if self.table.capacity() > 4096 && self.table.len() * 8 < self.table.capacity() {
            self.table = HashMap::default();
        } else {
            self.table.clear();
        }
        self.nodes.push(Node::constant(true));
        self.chain.push(NONE);
        self.nodes.push(Node::constant(false));
        self.chain.push(NONE);
        // envs[0] is the empty environment; it is never in `env_table` (see `intern_env`).
        if self.envs.is_empty() {
            self.envs.push(Arc::from(Vec::new()));
        }
        self.envs.truncate(1);
        if !self.env_table.is_empty() {
            self.env_table.clear();
        }
    }

    fn kids_of(&self, node: &Node) -> &[u32] {
        &self.kids[node.kids as usize..(node.kids + node.n_kids) as usize]
    }

    fn hash(node: &Node, kids: &[u32]) -> u64 {
        let kind = match node.kind {
            Kind::True => 1,
            Kind::False => 2,
            Kind::And => 3,
            Kind::Or => 4,
            Kind::Temporal(op) => 5 + op as u64,
        };
        let mut h = mix(
            mix(mix(mix(kind, node.lo as u64), node.hi as u64), u64::from(node.tpl)),
            u64::from(node.env),
        );
        for k in kids {
            h = mix(h, u64::from(*k));
        }
        h
    }

    /// The node equal to `node` with these children, created if new.
    fn intern(&mut self, mut node: Node, kids: &[u32]) -> u32 {
        let h = Arena::hash(&node, kids);
        let id = self.nodes.len() as u32;
        let head = match self.table.entry(h) {
            std::collections::hash_map::Entry::Vacant(slot) => {
                slot.insert(id);
                NONE
            }
            std::collections::hash_map::Entry::Occupied(mut slot) => {
                let head = *slot.get();
                let mut candidate = head;
                while candidate != NONE {
                    let other = &self.nodes[candidate as usize];
                    if other.kind == node.kind
                        && other.lo == node.lo
                        && other.hi == node.hi
                        && other.tpl == node.tpl
                        && other.env == node.env
                        && other.n_kids as usize == kids.len()
                        && self.kids[other.kids as usize..(other.kids + other.n_kids) as usize]
                            .iter()
                            .zip(kids)
                            .all(|(a, b)| a == b)
                    {
                        return candidate;
                    }
                    candidate = self.chain[candidate as usize];
                }
                slot.insert(id);
                head
            }
        };
        node.kids = self.kids.len() as u32;
        node.n_kids = kids.len() as u32;
        self.kids.extend_from_slice(kids);
        self.nodes.push(node);
        self.chain.push(head);
        id
    }

    fn intern_env(&mut self, env: &Env) -> u32 {
        if env.is_empty() {
            return 0;
        }
        if let Some(id) = self.env_table.get(env) {
            return *id;
        }
        let id = self.envs.len() as u32;
        self.envs.push(env.clone());
        self.env_table.insert(env.clone(), id);
        id
    }

    /// Closes a residual at the end of the stream: what is still open never happens, so an
    /// `eventually` or `until` is false and an `always` or `release` is true.
    fn close(&self, id: u32) -> bool {
        let node = &self.nodes[id as usize];
        match node.kind {
            Kind::True => true,
            Kind::False => false,
            Kind::And => self.kids_of(node).iter().all(|k| self.close(*k)),
            Kind::Or => self.kids_of(node).iter().any(|k| self.close(*k)),
            Kind::Temporal(op) => matches!(op, TemporalOp::Always | TemporalOp::Release),
        }
    }

    /// Number of distinct nodes reachable from the roots.
    fn size(&self, roots: impl Iterator<Item = u32>) -> usize {
        let mut seen = vec![false; self.nodes.len()];
        let mut stack: Vec<u32> = roots.collect();
        let mut count = 0;
        while let Some(id) = stack.pop() {
            if std::mem::replace(&mut seen[id as usize], true) {
                continue;
            }
            count += 1;
            let node = &self.nodes[id as usize];
            stack.extend_from_slice(self.kids_of(node));
        }
        count
    }

    fn write(&self, formula: &Formula, f: &mut impl fmt::Write, id: u32) -> fmt::Result {
        let node = &self.nodes[id as usize];
        match node.kind {
            Kind::True => f.write_str("true"),
            Kind::False => f.write_str("false"),
            Kind::And | Kind::Or => {
                let sep = if node.kind == Kind::And { " and " } else { " or " };
                f.write_char('(')?;
                for (i, k) in self.kids_of(node).iter().enumerate() {
                    if i > 0 {
                        f.write_str(sep)?;
                    }
                    self.write(formula, f, *k)?;
                }
                f.write_char(')')
            }
            Kind::Temporal(op) => {
                let window = if node.hi == INF {
                    format!("[{}, inf]", node.lo)
                } else {
                    format!("[{}, {}]", node.lo, node.hi)
                };
                let TNode::Temporal { lhs, rhs, .. } = formula.nodes[node.tpl as usize] else {
                    return f.write_str("?");
                };
                let env = &self.envs[node.env as usize];
                if !env.is_empty() {
                    f.write_char('{')?;
                    for (i, b) in env.iter().enumerate() {
                        if i > 0 {
                            f.write_str(", ")?;
                        }
                        write!(f, "${i}={}", b.id)?;
                    }
                    f.write_str("} ")?;
                }
                match op {
                    TemporalOp::Eventually => write!(f, "eventually{window} ")?,
                    TemporalOp::Always => write!(f, "always{window} ")?,
                    TemporalOp::Until | TemporalOp::Release => {
                        f.write_char('(')?;
                        formula.write_node(f, lhs)?;
                        let kw = if op == TemporalOp::Until { "until" } else { "release" };
                        write!(f, " {kw}{window} ")?;
                        formula.write_node(f, rhs)?;
                        return f.write_char(')');
                    }
                }
                formula.write_node(f, rhs)
            }
        }
    }
}

/// Working memory reused from step to step.
#[derive(Debug, Default)]
pub(crate) struct Scratch {
    memo_old: Vec<u32>,
    memo_inst: Vec<u32>,
    memo_inst_env: HashMap<(TplId, u32), u32>,
    buf: Vec<u32>,
    tmp: Vec<u32>,
    windows: Vec<WindowItem>,
    dropped: Vec<bool>,
}

#[derive(Debug, Clone, Copy)]
struct WindowItem {
    op: TemporalOp,
    tpl: TplId,
    env: u32,
    lo: Time,
    hi: Time,
    id: u32,
}

impl Scratch {
    fn prepare(&mut self, old_len: usize, template_len: usize) {
        self.memo_old.clear();
        self.memo_old.resize(old_len, NONE);
        self.memo_inst.clear();
        self.memo_inst.resize(template_len, NONE);
        self.memo_inst_env.clear();
        self.buf.clear();
    }
}

fn shift(x: Time, d: Time) -> Time {
    if x == INF { INF } else { x.saturating_sub(d) }
}

fn is_existential(op: TemporalOp) -> bool {
    matches!(op, TemporalOp::Eventually | TemporalOp::Until)
}

/// One progression step: reads the old arena, builds the new one.
struct Stepper<'a, S: State + ?Sized> {
    formula: &'a Formula,
    old: &'a Arena,
    new: &'a mut Arena,
    scratch: &'a mut Scratch,
    state: &'a S,
    /// Time since the previous state (0 at the first).
    d: Time,
}

impl<S: State + ?Sized> Stepper<'_, S> {
    /// Progresses a node of the old residual through the current state.
    fn progress(&mut self, id: u32) -> Result<u32, EvalError> {
        if id <= FALSE {
            return Ok(id);
        }
        let memo = self.scratch.memo_old[id as usize];
        if memo != NONE {
            return Ok(memo);
        }
        let old = self.old;
        let node = old.nodes[id as usize];
        let result = match node.kind {
            Kind::True => TRUE,
            Kind::False => FALSE,
            Kind::And | Kind::Or => {
                let is_and = node.kind == Kind::And;
                let start = self.scratch.buf.len();
                for &kid in old.kids_of(&node) {
                    let v = self.progress(kid)?;
                    if self.push_child(is_and, start, v) {
                        break;
                    }
                }
                self.junction(is_and, start)
            }
            Kind::Temporal(op) => {
                let env = if node.env == 0 { 0 } else { self.new.intern_env(&old.envs[node.env as usize]) };
                self.temporal(op, shift(node.lo, self.d), shift(node.hi, self.d), node.tpl, env, false)?
            }
        };
        self.scratch.memo_old[id as usize] = result;
        Ok(result)
    }

    /// A temporal node whose window is `[lo, hi]` relative to the current state. `fresh` is set
    /// when the operator is instantiated at this state (so the strict until does not ask for its
    /// left side here) and clear when it is a residual from earlier states.
    fn temporal(
        &mut self,
        op: TemporalOp,
        lo: Time,
        hi: Time,
        tpl: TplId,
        env: u32,
        fresh: bool,
    ) -> Result<u32, EvalError> {
        let TNode::Temporal { lhs, rhs, .. } = self.formula.nodes[tpl as usize] else {
            return Err(EvalError::Arithmetic("internal: residual refers to a non-temporal node".into()));
        };
        let existential = is_existential(op);
        // `or` for eventually/until, `and` for always/release.
        let (absorbing, neutral) = if existential { (TRUE, FALSE) } else { (FALSE, TRUE) };
        if hi < 0 {
            // The window was jumped over entirely.
            return Ok(neutral);
        }
        let start = self.scratch.buf.len();
        if lo <= 0 {
            let now = self.instantiate(rhs, env)?;
            if now == absorbing {
                self.scratch.buf.truncate(start);
                return Ok(absorbing);
            }
            if now != neutral {
                self.scratch.buf.push(now);
            }
        }
        let rest = self.residual(op, lo, hi, tpl, env);
        if rest != neutral {
            let cont = match op {
                TemporalOp::Until | TemporalOp::Release if !fresh => {
                    let left = self.instantiate(lhs, env)?;
                    if left == neutral {
                        neutral
                    } else if left == absorbing {
                        // φ holds here: the until goes on unchanged.
                        rest
                    } else {
                        let inner = self.scratch.buf.len();
                        self.scratch.buf.push(left);
                        self.scratch.buf.push(rest);
                        self.junction(existential, inner)
                    }
                }
                _ => rest,
            };
            if cont != neutral {
                self.scratch.buf.push(cont);
            }
        }
        Ok(self.junction(!existential, start))
    }

    /// The pending part of a temporal node after the current state, for states at least one time
    /// unit later: gone when its window ends here.
    fn residual(&mut self, op: TemporalOp, lo: Time, hi: Time, tpl: TplId, env: u32) -> u32 {
        if hi <= 0 {
            return if is_existential(op) { FALSE } else { TRUE };
        }
        self.new.intern(Node::temporal(op, lo.max(0), hi, tpl, env), &[])
    }

    /// Instantiates a compiled node at the current state.
    fn instantiate(&mut self, tpl: TplId, env: u32) -> Result<u32, EvalError> {
        let memo = if env == 0 {
            self.scratch.memo_inst[tpl as usize]
        } else {
            self.scratch.memo_inst_env.get(&(tpl, env)).copied().unwrap_or(NONE)
        };
        if memo != NONE {
            return Ok(memo);
        }
        let formula = self.formula;
        let result = match &formula.nodes[tpl as usize] {
            TNode::Const(b) => {
                if *b {
                    TRUE
                } else {
                    FALSE
                }
            }
            TNode::Atom { term, negated } => {
                let term_env = TermEnv {
                    state: self.state,
                    bindings: &self.new.envs[env as usize],
                    functions: &formula.functions,
                    slot_names: &formula.slot_names,
                    domain_names: &formula.domain_names,
                };
                if term_env.eval_bool(&formula.terms[*term as usize])? != *negated { TRUE } else { FALSE }
            }
            TNode::And(kids) | TNode::Or(kids) => {
                let is_and = matches!(formula.nodes[tpl as usize], TNode::And(_));
                let start = self.scratch.buf.len();
                for &kid in kids {
                    let v = self.instantiate(kid, env)?;
                    if self.push_child(is_and, start, v) {
                        break;
                    }
                }
                self.junction(is_and, start)
            }
            TNode::Temporal { op, lo, hi, .. } => self.temporal(*op, *lo, *hi, tpl, env, true)?,
            TNode::Quant { forall, domain, body } => {
                let start = self.scratch.buf.len();
                let base = self.new.envs[env as usize].clone();
                for object in self.state.objects(*domain) {
                    let id = match object {
                        kpl_core::Value::Record(r) => r.id.clone(),
                        _ => None,
                    };
                    let Some(id) = id else {
                        return Err(EvalError::ObjectWithoutId {
                            domain: name_of(&formula.domain_names, *domain),
                        });
                    };
                    let mut bindings: Vec<Binding> = base.to_vec();
                    bindings.push(Binding { domain: *domain, id });
                    let inner_env = self.new.intern_env(&Arc::from(bindings));
                    let v = self.instantiate(*body, inner_env)?;
                    if self.push_child(*forall, start, v) {
                        break;
                    }
                }
                self.junction(*forall, start)
            }
        };
        if env == 0 {
            self.scratch.memo_inst[tpl as usize] = result;
        } else {
            self.scratch.memo_inst_env.insert((tpl, env), result);
        }
        Ok(result)
    }

    /// Pushes the value of a child of the `and` (or `or`) whose children start at `buf[start]`.
    /// Returns true when the value decides it (`false` for `and`): the value then replaces the
    /// children pushed so far, and the caller evaluates no more of them.
    fn push_child(&mut self, is_and: bool, start: usize, v: u32) -> bool {
        let decides = v == if is_and { FALSE } else { TRUE };
        if decides {
            self.scratch.buf.truncate(start);
        }
        self.scratch.buf.push(v);
        decides
    }

    /// Builds the `and` (or `or`) of `buf[start..]`, simplified, and pops those children.
    fn junction(&mut self, is_and: bool, start: usize) -> u32 {
        let (absorbing, neutral) = if is_and { (FALSE, TRUE) } else { (TRUE, FALSE) };
        let kind = if is_and { Kind::And } else { Kind::Or };
        let mut items = std::mem::take(&mut self.scratch.tmp);
        items.clear();
        let mut absorbed = false;
        for &id in &self.scratch.buf[start..] {
            if id == neutral {
                continue;
            }
            if id == absorbing {
                absorbed = true;
                break;
            }
            let node = &self.new.nodes[id as usize];
            if node.kind == kind {
                items.extend_from_slice(self.new.kids_of(node));
            } else {
                items.push(id);
            }
        }
        self.scratch.buf.truncate(start);
        if absorbed {
            self.scratch.tmp = items;
            return absorbing;
        }
        items.sort_unstable();
        items.dedup();
        // Children stay sorted (the canonical order for hash-consing) unless windows merged.
        let merged = items.len() > 1 && self.merge_windows(is_and, &mut items);
        if items.len() > 1 && items.len() <= IMPLICATION_CHECK_LIMIT {
            self.drop_implied(is_and, &mut items);
        }
        let result = match items.len() {
            0 => neutral,
            1 => items[0],
            _ => {
                if merged {
                    items.sort_unstable();
                }
                let node = Node { kind, lo: 0, hi: 0, tpl: 0, env: 0, kids: 0, n_kids: 0 };
                self.new.intern(node, &items)
            }
        };
        self.scratch.tmp = items;
        result
    }

    /// Merges temporal children of one operator, body and bindings by their windows:
    /// in an `and`, `always`/`release` windows that overlap or touch become their union and an
    /// `eventually`/`until` whose window contains another's is dropped (it is implied); in an
    /// `or`, the duals.
    /// Returns whether `items` changed (and so needs sorting again).
    fn merge_windows(&mut self, is_and: bool, items: &mut Vec<u32>) -> bool {
        let mut windows = std::mem::take(&mut self.scratch.windows);
        windows.clear();
        for &id in items.iter() {
            let node = &self.new.nodes[id as usize];
            if let Kind::Temporal(op) = node.kind {
                windows.push(WindowItem { op, tpl: node.tpl, env: node.env, lo: node.lo, hi: node.hi, id });
            }
        }
        if windows.len() < 2 {
            self.scratch.windows = windows;
            return false;
        }
        windows.sort_unstable_by_key(|w| (w.op, w.tpl, w.env, w.lo, w.hi));
        let shares_body =
            windows.windows(2).any(|p| (p[0].op, p[0].tpl, p[0].env) == (p[1].op, p[1].tpl, p[1].env));
        if !shares_body {
            self.scratch.windows = windows;
            return false;
        }
        items.retain(|id| !matches!(self.new.nodes[*id as usize].kind, Kind::Temporal(_)));
        let mut group_start = 0;
        while group_start < windows.len() {
            let key = (windows[group_start].op, windows[group_start].tpl, windows[group_start].env);
            let mut group_end = group_start + 1;
            while group_end < windows.len()
                && (windows[group_end].op, windows[group_end].tpl, windows[group_end].env) == key
            {
                group_end += 1;
            }
            let group = &mut windows[group_start..group_end];
            let union = is_and != is_existential(key.0);
            if union {
                // Sorted by lo: sweep, merging windows that overlap or touch (time is integer).
                let mut current = group[0];
                for w in group[1..].iter() {
                    if w.lo <= current.hi.saturating_add(1) {
                        if w.hi > current.hi {
                            current.hi = w.hi;
                            current.id = NONE;
                        }
                    } else {
                        items.push(self.window_node(current));
                        current = *w;
                    }
                }
                items.push(self.window_node(current));
            } else {
                // Keep only windows that contain no other window of the group.
                group.sort_unstable_by(|a, b| b.lo.cmp(&a.lo).then(a.hi.cmp(&b.hi)));
                let mut min_hi = Time::MAX;
                let mut first = true;
                for w in group.iter() {
                    if first || w.hi < min_hi {
                        items.push(w.id);
                        min_hi = min_hi.min(w.hi);
                        first = false;
                    }
                }
            }
            group_start = group_end;
        }
        self.scratch.windows = windows;
        true
    }

    fn window_node(&mut self, w: WindowItem) -> u32 {
        if w.id != NONE {
            return w.id;
        }
        self.new.intern(Node::temporal(w.op, w.lo, w.hi, w.tpl, w.env), &[])
    }

    /// Drops children implied by a sibling: in an `and`, a child that another implies; in an
    /// `or`, a child that implies another. Only runs when some child is itself a junction (plain
    /// temporal siblings were handled by `merge_windows`).
    fn drop_implied(&mut self, is_and: bool, items: &mut Vec<u32>) {
        let arena = &*self.new;
        if !items.iter().any(|id| matches!(arena.nodes[*id as usize].kind, Kind::And | Kind::Or)) {
            return;
        }
        let mut dropped = std::mem::take(&mut self.scratch.dropped);
        dropped.clear();
        dropped.resize(items.len(), false);
        for i in 0..items.len() {
            for j in 0..items.len() {
                if i == j || dropped[j] {
                    continue;
                }
                let (stronger, weaker) = if is_and { (items[j], items[i]) } else { (items[i], items[j]) };
                if implies(arena, stronger, weaker, IMPLICATION_DEPTH) {
                    dropped[i] = true;
                    break;
                }
            }
        }
        let mut k = 0;
        items.retain(|_| {
            k += 1;
            !dropped[k - 1]
        });
        self.scratch.dropped = dropped;
    }
}

/// A syntactic, sound and incomplete check that `a` implies `b` on every future. Each rule also
/// keeps the three-valued order (the value of `a` is never above that of `b`), so dropping an
/// implied sibling never decides a formula earlier or later than the prefix semantics.
fn implies(arena: &Arena, a: u32, b: u32, depth: u32) -> bool {
    if a == b || a == FALSE || b == TRUE {
        return true;
    }
    if a == TRUE || b == FALSE {
        return false;
    }
    let na = &arena.nodes[a as usize];
    let nb = &arena.nodes[b as usize];
    if let (Kind::Temporal(op_a), Kind::Temporal(op_b)) = (na.kind, nb.kind) {
        if op_a != op_b || na.tpl != nb.tpl || na.env != nb.env {
            return false;
        }
        let a_inside_b = nb.lo <= na.lo && na.hi <= nb.hi;
        let b_inside_a = na.lo <= nb.lo && nb.hi <= na.hi;
        // Existential: a smaller window is stronger. Universal: a larger window is stronger.
        return if is_existential(op_a) { a_inside_b } else { b_inside_a };
    }
    if depth == 0 {
        return false;
    }
    if nb.kind == Kind::And {
        return arena.kids_of(nb).iter().all(|k| implies(arena, a, *k, depth - 1));
    }
    if na.kind == Kind::Or {
        return arena.kids_of(na).iter().all(|k| implies(arena, *k, b, depth - 1));
    }
    if nb.kind == Kind::Or && arena.kids_of(nb).iter().any(|k| implies(arena, a, *k, depth - 1)) {
        return true;
    }
    na.kind == Kind::And && arena.kids_of(na).iter().any(|k| implies(arena, *k, b, depth - 1))
}

/// Progresses one formula through a stream of states, as a link process does for each object's
/// establish / reestablish / maintain condition, or a monitor does for its formula.
///
/// ```
/// use std::sync::Arc;
/// use kpl_core::TimeUnit;
/// use kpl_mtl::{Context, Formula, Mtl, Progressor, SlotState, Term, Window};
///
/// let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
/// let p = ctx.declare_value("p");
/// // eventually[0, 100] p
/// let f = Formula::new(&Mtl::eventually(Window::bounded(0, 100), Mtl::atom(Term::slot(p))), &ctx).unwrap();
/// let mut progressor = Progressor::new(Arc::new(f));
/// assert_eq!(progressor.step(0, &SlotState::bools(&[false])).unwrap(), None);
/// // Time jumps past the window: decided at once.
/// assert_eq!(progressor.step(250, &SlotState::bools(&[true])).unwrap(), Some(false));
/// assert_eq!(progressor.decided_at(), Some(250));
/// ```
#[derive(Debug)]
pub struct Progressor {
    formula: Arc<Formula>,
    current: Arena,
    next: Arena,
    scratch: Scratch,
    /// `None` before the first state.
    root: Option<u32>,
    last_time: Option<Time>,
    verdict: Option<bool>,
    decided_at: Option<Time>,
}

impl Progressor {
    pub fn new(formula: Arc<Formula>) -> Progressor {
        Progressor {
            formula,
            current: Arena::new(),
            next: Arena::new(),
            scratch: Scratch::default(),
            root: None,
            last_time: None,
            verdict: None,
            decided_at: None,
        }
    }

    pub fn formula(&self) -> &Arc<Formula> {
        &self.formula
    }

    /// Progresses through the state at `time` (strictly after the previous state's). Returns the
    /// verdict once it is certain; afterwards further states change nothing. On error nothing
    /// changes: the state was not consumed.
    pub fn step<S: State + ?Sized>(&mut self, time: Time, state: &S) -> Result<Option<bool>, EvalError> {
        let d = match self.last_time {
            None => 0,
            Some(previous) if time <= previous => {
                return Err(EvalError::TimeNotIncreasing { time, previous });
            }
            Some(previous) => time.saturating_sub(previous),
        };
        if self.verdict.is_some() {
            self.last_time = Some(time);
            return Ok(self.verdict);
        }
        self.next.reset();
        self.scratch.prepare(self.current.nodes.len(), self.formula.nodes.len());
        let mut stepper = Stepper {
            formula: &self.formula,
            old: &self.current,
            new: &mut self.next,
            scratch: &mut self.scratch,
            state,
            d,
        };
        let root = match self.root {
            None => stepper.instantiate(self.formula.root, 0)?,
            Some(root) => stepper.progress(root)?,
        };
        std::mem::swap(&mut self.current, &mut self.next);
        self.root = Some(root);
        self.last_time = Some(time);
        if root <= FALSE {
            self.verdict = Some(root == TRUE);
            self.decided_at = Some(time);
        }
        Ok(self.verdict)
    }

    /// Ends the stream: what is still open is closed with finite-trace semantics (an
    /// `eventually` or `until` not yet satisfied is false, an `always` not yet violated is true).
    /// `None` when no state was ever given.
    pub fn finish(&mut self) -> Option<bool> {
        if self.verdict.is_none() {
            let root = self.root?;
            self.verdict = Some(self.current.close(root));
        }
        self.verdict
    }

    /// The verdict, once certain (or once [`Progressor::finish`] closed the stream).
    pub fn verdict(&self) -> Option<bool> {
        self.verdict
    }

    /// The time of the state at which the verdict became certain; `None` before that, and when
    /// it was decided only by the end of the stream.
    pub fn decided_at(&self) -> Option<Time> {
        self.decided_at
    }

    /// The time of the last state progressed through.
    pub fn last_time(&self) -> Option<Time> {
        self.last_time
    }

    /// Number of distinct nodes of the residual (hash-consed: a shared sub-residual counts once;
    /// a decided formula has size 1).
    pub fn residual_size(&self) -> usize {
        match self.root {
            None => 0,
            Some(root) => self.current.size(std::iter::once(root)),
        }
    }

    /// The residual as text, windows relative to the last state's time.
    pub fn residual(&self) -> String {
        let mut out = String::new();
        match self.root {
            None => {
                let _ = self.formula.write_node(&mut out, self.formula.root);
            }
            Some(root) => {
                let _ = self.current.write(&self.formula, &mut out, root);
            }
        }
        out
    }

    /// Starts over, as if no state had been given.
    pub fn reset(&mut self) {
        self.current.reset();
        self.root = None;
        self.last_time = None;
        self.verdict = None;
        self.decided_at = None;
    }
}

/// The verdict of the formula evaluated from one state of the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StartVerdict {
    /// The index of the state the formula is evaluated from (0 for the first state).
    pub start: usize,
    pub verdict: bool,
    /// The time of the state at which the verdict became certain; `None` when only the end of the
    /// stream decided it.
    pub decided_at: Option<Time>,
}

/// Evaluates a formula from every state of a stream (`kpl mtl eval --every`, and monitors that
/// emit one verdict per state). All instances share one arena, so instances whose residuals
/// are equal (as for `always p` started at different states) are one node and are progressed
/// once.
#[derive(Debug)]
pub struct EveryMonitor {
    formula: Arc<Formula>,
    current: Arena,
    next: Arena,
    scratch: Scratch,
    /// Undecided instances, grouped by residual.
    groups: Vec<(u32, Vec<usize>)>,
    states: usize,
    last_time: Option<Time>,
    new_roots: Vec<u32>,
}

impl EveryMonitor {
    pub fn new(formula: Arc<Formula>) -> EveryMonitor {
        EveryMonitor {
            formula,
            current: Arena::new(),
            next: Arena::new(),
            scratch: Scratch::default(),
            groups: Vec::new(),
            states: 0,
            last_time: None,
            new_roots: Vec::new(),
        }
    }

    /// Progresses every open instance through the state at `time` and starts one at it; pushes
    /// the verdicts that became certain to `decided`. On error nothing changes.
    pub fn step<S: State + ?Sized>(
        &mut self,
        time: Time,
        state: &S,
        decided: &mut Vec<StartVerdict>,
    ) -> Result<(), EvalError> {
        let d = match self.last_time {
            None => 0,
            Some(previous) if time <= previous => {
                return Err(EvalError::TimeNotIncreasing { time, previous });
            }
            Some(previous) => time.saturating_sub(previous),
        };
        self.next.reset();
        self.scratch.prepare(self.current.nodes.len(), self.formula.nodes.len());
        let mut stepper = Stepper {
            formula: &self.formula,
            old: &self.current,
            new: &mut self.next,
            scratch: &mut self.scratch,
            state,
            d,
        };
        self.new_roots.clear();
        for (root, _) in &self.groups {
            self.new_roots.push(stepper.progress(*root)?);
        }
        let fresh = stepper.instantiate(self.formula.root, 0)?;
        std::mem::swap(&mut self.current, &mut self.next);

        let mut groups = std::mem::take(&mut self.groups);
        groups.push((NONE, vec![self.states]));
        self.new_roots.push(fresh);
        let mut index: HashMap<u32, usize> = HashMap::new();
        let mut kept: Vec<(u32, Vec<usize>)> = Vec::with_capacity(groups.len());
        for ((_, mut starts), root) in groups.into_iter().zip(self.new_roots.iter().copied()) {
            if root <= FALSE {
                decided.extend(starts.iter().map(|&start| StartVerdict {
                    start,
                    verdict: root == TRUE,
                    decided_at: Some(time),
                }));
                continue;
            }
            match index.get(&root) {
                Some(&i) => {
                    // Merge the smaller list into the larger one.
                    if kept[i].1.len() < starts.len() {
                        std::mem::swap(&mut kept[i].1, &mut starts);
                    }
                    kept[i].1.extend_from_slice(&starts);
                }
                None => {
                    index.insert(root, kept.len());
                    kept.push((root, starts));
                }
            }
        }
        self.groups = kept;
        self.states += 1;
        self.last_time = Some(time);
        Ok(())
    }

    /// Ends the stream: closes every open instance with finite-trace semantics and pushes its
    /// verdict. The monitor is then empty (and may go on with later states as a new stream would
    /// not; create a new one for that).
    pub fn finish(&mut self, decided: &mut Vec<StartVerdict>) {
        for (root, starts) in self.groups.drain(..) {
            let verdict = self.current.close(root);
            decided.extend(starts.iter().map(|&start| StartVerdict { start, verdict, decided_at: None }));
        }
    }

    /// Number of distinct residual nodes over all open instances.
    pub fn residual_size(&self) -> usize {
        self.current.size(self.groups.iter().map(|(root, _)| *root))
    }

    /// Number of open (undecided) instances.
    pub fn open_instances(&self) -> usize {
        self.groups.iter().map(|(_, s)| s.len()).sum()
    }
}
