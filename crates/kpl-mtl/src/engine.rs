//! The progression engine: one arena of residuals, the transition cache and the working memory,
//! shared by every residual its owner holds ([`crate::Progressor`] holds one,
//! [`crate::ProgressorGroup`] one per instance, [`crate::EveryMonitor`] one per open start).
//!
//! One step rewrites a residual through one state, `d` time units after the state before:
//!
//! 1. every pending window shifts by `d`; a window whose upper end is now below 0 was jumped over
//!    and resolves (`eventually`/`until` false, `always`/`release` true);
//! 2. a window containing 0 instantiates its body at this state (`eventually`: `body or rest`,
//!    `always`: `body and rest`, `until` from an earlier state: `ψ or (φ and rest)`; an `until`
//!    instantiated at this very state does not ask φ here);
//! 3. the rest is kept for later states only if its window reaches past 0;
//! 4. every `and`/`or` is simplified as it is built (see `docs/mtl.md`), and how a junction of
//!    given children simplifies is worked out once and remembered on the node.
//!
//! What makes a step cheap:
//!
//! - Nodes live as long as the arena, so a junction whose children all come out unchanged is
//!   itself unchanged, with nothing built.
//! - The **transition cache**: a residual's next residual depends only on the residual, the time
//!   since the last state and the values of the atoms it may read. For residuals without bound
//!   objects below them (`cacheable`), that triple is looked up before anything is computed, so
//!   a situation that recurs (the same residual, the same atom values, the same sampling period)
//!   costs one lookup. Windows are relative to the last state, so a situation recurs whatever
//!   its absolute time. Instances that share a residual share its cached transitions, and so do
//!   objects of a quantifier (`Bind` nodes look up their body without their objects).
//! - Atoms are read once per state (and per bound environment), into bit sets.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hash, Hasher};
use std::sync::Arc;

use crate::atoms::AtomMemo;
use crate::error::EvalError;
use crate::formula::{Formula, INF, Literals, TNode, TemporalOp, TplId};
use crate::residual::{Arena, FALSE, IdHasher, Kind, NONE, Node, NodeId, TRUE, mix};
use crate::state::State;
use crate::term::{Binding, name_of};

/// `and`/`or` nodes with more children than this skip the pairwise implication check (it is
/// quadratic); window merging and duplicate removal still apply.
const IMPLICATION_CHECK_LIMIT: usize = 24;
/// How deep the syntactic implication check looks.
const IMPLICATION_DEPTH: u32 = 3;
/// Most entries of the transition cache; past this it starts over (and the nodes only it kept
/// are reclaimed by the next collection).
const CACHE_LIMIT: usize = 1 << 17;
/// Recent instantiations kept per compiled node.
const INSTANTIATIONS: usize = 4;

/// How an engine works. The verdicts are the same whatever the configuration (the differential
/// tests check it); only the cost changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EngineConfig {
    /// Look each transition up in the transition cache before computing it. On by default.
    pub transition_cache: bool,
    /// The arena is collected when it holds this many nodes more than were live after the last
    /// collection (or twice as many, if that is more). 4,096 by default.
    pub collect_slack: usize,
}

impl Default for EngineConfig {
    fn default() -> EngineConfig {
        EngineConfig { transition_cache: true, collect_slack: 4096 }
    }
}

/// A cached transition: residual `node`, `d` time units after the last state, with these atom
/// values (and failures) among the atoms the node reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct CacheKey {
    node: NodeId,
    d: u64,
    value: u64,
    failed: u64,
}

impl Hash for CacheKey {
    fn hash<H: Hasher>(&self, state: &mut H) {
        state.write_u64(mix(mix(mix(u64::from(self.node), self.d), self.value), self.failed));
    }
}

type Cache = HashMap<CacheKey, NodeId, BuildHasherDefault<IdHasher>>;

/// Working memory reused from step to step.
#[derive(Debug, Default)]
struct Scratch {
    /// Per residual node: (epoch, result) of its progression at the current state.
    memo: Vec<(u32, NodeId)>,
    memo_env: HashMap<(NodeId, u32), NodeId>,
    /// Per compiled node: (epoch, result) of its instantiation at the current state.
    inst: Vec<(u32, NodeId)>,
    inst_env: HashMap<(TplId, u32), NodeId>,
    /// Children of the junctions being built, as a stack.
    buf: Vec<NodeId>,
    tmp: Vec<NodeId>,
    windows: Vec<WindowItem>,
    dropped: Vec<bool>,
    bindings: Vec<Binding>,
}

#[derive(Debug, Clone, Copy)]
struct WindowItem {
    op: TemporalOp,
    tpl: TplId,
    lo: u64,
    hi: u64,
    id: NodeId,
}

/// Counters of the engine's work, for benchmarks and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EngineStats {
    /// Progressions of a whole residual through one state (one per instance and state).
    pub steps: u64,
    /// Of these and of the nested lookups, answered by the transition cache.
    pub cache_hits: u64,
    /// Lookups the transition cache could not answer (the transition was then computed).
    pub cache_misses: u64,
    /// Collections of the arena.
    pub collections: u64,
}

#[derive(Debug)]
pub(crate) struct Engine {
    pub formula: Arc<Formula>,
    pub arena: Arena,
    cache: Cache,
    scratch: Scratch,
    atoms: AtomMemo,
    /// Per compiled node, `INSTANTIATIONS` recent instantiations: (atom values, result).
    instantiations: Vec<(u64, NodeId)>,
    epoch: u32,
    /// Collect when the arena reaches this many nodes.
    next_collect: usize,
    config: EngineConfig,
    pub stats: EngineStats,
}

impl Engine {
    pub fn new(formula: Arc<Formula>, config: EngineConfig) -> Engine {
        Engine {
            instantiations: vec![(0, NONE); formula.nodes.len() * INSTANTIATIONS],
            formula,
            arena: Arena::new(),
            cache: Cache::default(),
            scratch: Scratch::default(),
            atoms: AtomMemo::default(),
            epoch: 0,
            next_collect: config.collect_slack.max(1),
            config,
            stats: EngineStats::default(),
        }
    }

    /// The residual of an instance that has seen no state yet.
    pub fn start(&mut self) -> NodeId {
        let root = self.formula.root;
        let info = self.formula.info[root as usize];
        self.arena.intern(Node { reads: info.reads, cacheable: info.cacheable, ..Node::start(root) }, &[])
    }

    /// Prepares for a new state: forgets the atoms and results of the previous one.
    pub fn begin_state(&mut self) {
        if self.epoch == u32::MAX {
            self.epoch = 0;
            self.scratch.memo.clear();
            self.scratch.inst.clear();
        }
        self.epoch += 1;
        self.atoms.begin(self.formula.atoms.len(), self.epoch);
        if !self.scratch.memo_env.is_empty() {
            self.scratch.memo_env.clear();
        }
        if !self.scratch.inst_env.is_empty() {
            self.scratch.inst_env.clear();
        }
        if self.scratch.memo.len() < self.arena.len() {
            self.scratch.memo.resize(self.arena.len(), (0, NONE));
        }
        if self.scratch.inst.len() < self.formula.nodes.len() {
            self.scratch.inst.resize(self.formula.nodes.len(), (0, NONE));
        }
    }

    /// Progresses `root` through `state`, `d` time units after the previous state (ignored for
    /// a residual that has seen no state yet). Several roots may be progressed through one state
    /// after one [`Engine::begin_state`] if they share it and `d`.
    pub fn progress<S: State + ?Sized>(
        &mut self,
        root: NodeId,
        d: u64,
        state: &S,
    ) -> Result<NodeId, EvalError> {
        self.stats.steps += 1;
        let mut stepper = Stepper {
            formula: &self.formula,
            arena: &mut self.arena,
            cache: &mut self.cache,
            scratch: &mut self.scratch,
            atoms: &mut self.atoms,
            instantiations: &mut self.instantiations,
            stats: &mut self.stats,
            use_cache: self.config.transition_cache,
            epoch: self.epoch,
            state,
            d,
        };
        stepper.progress_cached(root, 0)
    }

    /// Closes a residual at the end of the stream (finite-trace semantics).
    pub fn close(&self, root: NodeId) -> bool {
        self.arena.close(root)
    }

    /// Whether enough garbage may have piled up to collect.
    pub fn should_collect(&self) -> bool {
        self.arena.len() >= self.next_collect
    }

    /// Reclaims the nodes no root (nor the cache) reaches; every root is renumbered in place.
    pub fn collect(&mut self, roots: &mut [NodeId]) {
        self.stats.collections += 1;
        if self.cache.len() > CACHE_LIMIT / 2 {
            self.cache = Cache::default();
        }
        let cached = self.cache.iter().flat_map(|(k, v)| [k.node, *v]);
        let map = self.arena.compact(roots, cached.collect::<Vec<_>>().into_iter());
        let old = std::mem::take(&mut self.cache);
        self.cache.reserve(old.len());
        for (key, value) in old {
            let (node, value) = (map[key.node as usize], map[value as usize]);
            if node != NONE && value != NONE {
                self.cache.insert(CacheKey { node, ..key }, value);
            }
        }
        self.scratch.memo.clear();
        self.scratch.inst.clear();
        self.instantiations.iter_mut().for_each(|e| *e = (0, NONE));
        self.atoms.forget_envs();
        let live = self.arena.len();
        self.next_collect = (2 * live).max(live + self.config.collect_slack.max(1));
    }
}

/// One progression through one state.
struct Stepper<'a, S: State + ?Sized> {
    formula: &'a Formula,
    arena: &'a mut Arena,
    cache: &'a mut Cache,
    scratch: &'a mut Scratch,
    atoms: &'a mut AtomMemo,
    /// Per compiled node, `INSTANTIATIONS` recent instantiations: (atom values, result).
    instantiations: &'a mut [(u64, NodeId)],
    stats: &'a mut EngineStats,
    use_cache: bool,
    epoch: u32,
    state: &'a S,
    /// Time since the previous state.
    d: u64,
}

impl<S: State + ?Sized> Stepper<'_, S> {
    /// Progresses a node through the current state, through the transition cache when the node
    /// allows it.
    fn progress_cached(&mut self, id: NodeId, env: u32) -> Result<NodeId, EvalError> {
        if id <= FALSE {
            return Ok(id);
        }
        let node = &self.arena.nodes[id as usize];
        if !(self.use_cache && node.cacheable) {
            return self.progress(id, env);
        }
        let (kind, reads) = (node.kind, node.reads);
        let (value, failed) = self.atoms.word(reads, env, &self.arena.envs, self.formula, self.state);
        // Instantiating a compiled node does not depend on the time since the previous state.
        let d = if kind == Kind::Start { 0 } else { self.d };
        let node = &mut self.arena.nodes[id as usize];
        if failed == 0 && node.last_next != NONE && node.last_value == value && node.last_d == d {
            self.stats.cache_hits += 1;
            return Ok(node.last_next);
        }
        let key = CacheKey { node: id, d, value, failed };
        let next = match self.cache.get(&key) {
            Some(next) => {
                self.stats.cache_hits += 1;
                *next
            }
            None => {
                self.stats.cache_misses += 1;
                let next = self.progress(id, env)?;
                if self.cache.len() >= CACHE_LIMIT {
                    self.cache.clear();
                }
                self.cache.insert(key, next);
                next
            }
        };
        if failed == 0 {
            let node = &mut self.arena.nodes[id as usize];
            (node.last_value, node.last_d, node.last_next) = (value, d, next);
        }
        Ok(next)
    }

    /// Progresses a node of a residual through the current state.
    fn progress(&mut self, id: NodeId, env: u32) -> Result<NodeId, EvalError> {
        if id <= FALSE {
            return Ok(id);
        }
        if env == 0 {
            if let Some(&(epoch, memo)) = self.scratch.memo.get(id as usize)
                && epoch == self.epoch
            {
                return Ok(memo);
            }
        } else if let Some(memo) = self.scratch.memo_env.get(&(id, env)) {
            return Ok(*memo);
        }
        let node = self.arena.nodes[id as usize];
        let result = match node.kind {
            Kind::True => TRUE,
            Kind::False => FALSE,
            Kind::And | Kind::Or => {
                let is_and = node.kind == Kind::And;
                let absorbing = if is_and { FALSE } else { TRUE };
                let start = self.scratch.buf.len();
                let mut changed = false;
                let mut absorbed = false;
                for i in 0..node.n_kids {
                    let kid = self.arena.kids[(node.kids + i) as usize];
                    let kind = self.arena.nodes[kid as usize].kind;
                    let v = if matches!(kind, Kind::And | Kind::Or) {
                        self.progress_cached(kid, env)
                    } else {
                        self.progress(kid, env)
                    };
                    let v = match v {
                        Ok(v) => v,
                        Err(e) => {
                            self.scratch.buf.truncate(start);
                            return Err(e);
                        }
                    };
                    if v == absorbing {
                        absorbed = true;
                        break;
                    }
                    changed |= v != kid;
                    self.scratch.buf.push(v);
                }
                if absorbed {
                    self.scratch.buf.truncate(start);
                    absorbing
                } else if !changed {
                    self.scratch.buf.truncate(start);
                    id
                } else {
                    self.junction(is_and, start)
                }
            }
            Kind::Temporal(op) => {
                let hi = if node.hi == INF {
                    INF
                } else if self.d > node.hi {
                    // The window was jumped over entirely.
                    return Ok(self.remember(id, env, if op.is_existential() { FALSE } else { TRUE }));
                } else {
                    node.hi - self.d
                };
                let lo = node.lo.saturating_sub(self.d);
                // The node's last transition, if it recurs (no table lookup below the root).
                let inline = self.use_cache && node.cacheable;
                let value = if inline {
                    let (value, failed) =
                        self.atoms.word(node.reads, env, &self.arena.envs, self.formula, self.state);
                    if failed == 0
                        && node.last_next != NONE
                        && node.last_value == value
                        && node.last_d == self.d
                    {
                        return Ok(self.remember(id, env, node.last_next));
                    }
                    (failed == 0).then_some(value)
                } else {
                    None
                };
                let next = self.temporal(op, lo, hi, node.tpl, env, false)?;
                if let Some(value) = value {
                    let node = &mut self.arena.nodes[id as usize];
                    (node.last_value, node.last_d, node.last_next) = (value, self.d, next);
                }
                next
            }
            Kind::Bind => {
                let inner = self.arena.kids[node.kids as usize];
                let next = self.progress_cached(inner, node.env)?;
                if next <= FALSE {
                    next
                } else if next == inner {
                    id
                } else {
                    self.bind(node.env, next)
                }
            }
            Kind::Start => self.instantiate(node.tpl, env)?,
        };
        Ok(self.remember(id, env, result))
    }

    fn remember(&mut self, id: NodeId, env: u32, result: NodeId) -> NodeId {
        if env == 0 {
            let memo = &mut self.scratch.memo;
            if memo.len() <= id as usize {
                memo.resize(id as usize + 1, (0, NONE));
            }
            memo[id as usize] = (self.epoch, result);
        } else {
            self.scratch.memo_env.insert((id, env), result);
        }
        result
    }

    /// `Bind(env, inner)`, or `inner` itself when it is a constant.
    fn bind(&mut self, env: u32, inner: NodeId) -> NodeId {
        if inner <= FALSE || env == 0 {
            return inner;
        }
        self.arena.intern(Node::bind(env), &[inner])
    }

    /// A temporal node whose window is `[lo, hi]` relative to the current state. `fresh` is set
    /// when the operator is instantiated at this state (so the strict until does not ask for its
    /// left side here) and clear when it is a residual from earlier states.
    fn temporal(
        &mut self,
        op: TemporalOp,
        lo: u64,
        hi: u64,
        tpl: TplId,
        env: u32,
        fresh: bool,
    ) -> Result<NodeId, EvalError> {
        let TNode::Temporal { lhs, rhs, .. } = self.formula.nodes[tpl as usize] else {
            return Err(EvalError::Arithmetic("internal: residual refers to a non-temporal node".into()));
        };
        let existential = op.is_existential();
        // `or` for eventually/until, `and` for always/release.
        let (absorbing, neutral) = if existential { (TRUE, FALSE) } else { (FALSE, TRUE) };
        let now = if lo == 0 { self.instantiate(rhs, env)? } else { neutral };
        if now == absorbing {
            return Ok(absorbing);
        }
        // The pending part, for states at least one time unit later: gone when the window ends
        // here.
        let rest = if hi == 0 {
            neutral
        } else {
            let info = self.formula.info[tpl as usize];
            let node =
                Node { reads: info.reads, cacheable: info.cacheable, ..Node::temporal(op, lo, hi, tpl) };
            self.arena.intern(node, &[])
        };
        let cont = match op {
            TemporalOp::Until | TemporalOp::Release if !fresh && rest != neutral => {
                let left = self.instantiate(lhs, env)?;
                if left == neutral {
                    neutral
                } else if left == absorbing {
                    // φ holds here: the until goes on unchanged.
                    rest
                } else {
                    let start = self.scratch.buf.len();
                    self.scratch.buf.push(left);
                    self.scratch.buf.push(rest);
                    self.junction(existential, start)
                }
            }
            _ => rest,
        };
        if now == neutral {
            return Ok(cont);
        }
        if cont == neutral {
            return Ok(now);
        }
        let start = self.scratch.buf.len();
        self.scratch.buf.push(now);
        self.scratch.buf.push(cont);
        Ok(self.junction(!existential, start))
    }

    /// Instantiates a compiled node at the current state.
    fn instantiate(&mut self, tpl: TplId, env: u32) -> Result<NodeId, EvalError> {
        if env == 0 {
            let (epoch, memo) = self.scratch.inst[tpl as usize];
            if epoch == self.epoch {
                return Ok(memo);
            }
        } else if let Some(memo) = self.scratch.inst_env.get(&(tpl, env)) {
            return Ok(*memo);
        }
        let formula = self.formula;
        let info = formula.info[tpl as usize];
        // What a compiled node without quantifiers gives at a state depends only on the values of
        // its atoms: a few recent instantiations are kept per node.
        let slot = if self.use_cache && info.cacheable && env == 0 && info.reads != 0 {
            let (value, failed) = self.atoms.word(info.reads, 0, &self.arena.envs, formula, self.state);
            if failed == 0 {
                let slot = tpl as usize * INSTANTIATIONS
                    + (value.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 62) as usize;
                if let Some(&(v, result)) = self.instantiations.get(slot)
                    && v == value
                    && result != NONE
                {
                    self.scratch.inst[tpl as usize] = (self.epoch, result);
                    return Ok(result);
                }
                Some((slot, value))
            } else {
                None
            }
        } else {
            None
        };
        let result = match &formula.nodes[tpl as usize] {
            TNode::Const(b) => {
                if *b {
                    TRUE
                } else {
                    FALSE
                }
            }
            TNode::Atom { atom, negated } => {
                let v = self.atoms.get(*atom, env, &self.arena.envs, formula, self.state)?;
                if v != *negated { TRUE } else { FALSE }
            }
            TNode::And(kids) | TNode::Or(kids) => {
                let is_and = matches!(formula.nodes[tpl as usize], TNode::And(_));
                match formula.info[tpl as usize].literals {
                    Some(literals) => self.literals(is_and, literals, kids, env)?,
                    None => self.instantiate_junction(is_and, kids, env)?,
                }
            }
            TNode::Temporal { op, lo, hi, .. } => self.temporal(*op, *lo, *hi, tpl, env, true)?,
            TNode::Quant { forall, domain, body } => self.quantifier(*forall, *domain, *body, env)?,
        };
        if env == 0 {
            self.scratch.inst[tpl as usize] = (self.epoch, result);
        } else {
            self.scratch.inst_env.insert((tpl, env), result);
        }
        if let Some((slot, value)) = slot
            && let Some(entry) = self.instantiations.get_mut(slot)
        {
            *entry = (value, result);
        }
        Ok(result)
    }

    /// An `and`/`or` of atoms, from the bits of the state's atoms; one by one only when some
    /// atom failed (so that the error is the one the left-to-right evaluation meets first).
    fn literals(&mut self, is_and: bool, l: Literals, kids: &[TplId], env: u32) -> Result<NodeId, EvalError> {
        let (value, failed) = self.atoms.word(l.mask, env, &self.arena.envs, self.formula, self.state);
        if failed != 0 {
            return self.instantiate_junction(is_and, kids, env);
        }
        let true_literals = (value ^ l.negated) & l.mask;
        let holds = if is_and { true_literals == l.mask } else { true_literals != 0 };
        Ok(if holds { TRUE } else { FALSE })
    }

    /// An `and`/`or` of compiled nodes, left to right, stopping at the first that decides it.
    fn instantiate_junction(&mut self, is_and: bool, kids: &[TplId], env: u32) -> Result<NodeId, EvalError> {
        let absorbing = if is_and { FALSE } else { TRUE };
        let start = self.scratch.buf.len();
        for &kid in kids {
            let v = match self.instantiate(kid, env) {
                Ok(v) => v,
                Err(e) => {
                    self.scratch.buf.truncate(start);
                    return Err(e);
                }
            };
            if v == absorbing {
                self.scratch.buf.truncate(start);
                return Ok(absorbing);
            }
            self.scratch.buf.push(v);
        }
        Ok(self.junction(is_and, start))
    }

    /// `forall`/`exists` over the objects of a type in this state: the body instantiated for
    /// each object, bound to it.
    fn quantifier(&mut self, forall: bool, domain: u32, body: TplId, env: u32) -> Result<NodeId, EvalError> {
        let (formula, state) = (self.formula, self.state);
        let absorbing = if forall { FALSE } else { TRUE };
        let start = self.scratch.buf.len();
        let fail = |scratch: &mut Scratch, e: EvalError| {
            scratch.buf.truncate(start);
            Err(e)
        };
        for object in state.objects(domain) {
            let id = match object {
                kpl_core::Value::Record(r) => r.id.clone(),
                _ => None,
            };
            let Some(id) = id else {
                let e = EvalError::ObjectWithoutId { domain: name_of(&formula.domain_names, domain) };
                return fail(self.scratch, e);
            };
            let mut bindings = std::mem::take(&mut self.scratch.bindings);
            bindings.clear();
            bindings.extend_from_slice(&self.arena.envs[env as usize]);
            bindings.push(Binding { domain, id });
            let inner_env = self.arena.intern_env(&bindings);
            self.scratch.bindings = bindings;
            let v = match self.instantiate(body, inner_env) {
                Ok(v) => self.bind(inner_env, v),
                Err(e) => return fail(self.scratch, e),
            };
            if v == absorbing {
                self.scratch.buf.truncate(start);
                return Ok(absorbing);
            }
            self.scratch.buf.push(v);
        }
        Ok(self.junction(forall, start))
    }

    /// Builds the `and` (or `or`) of `buf[start..]`, simplified, and pops those children.
    fn junction(&mut self, is_and: bool, start: usize) -> NodeId {
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
            let node = &self.arena.nodes[id as usize];
            if node.kind == kind {
                items.extend_from_slice(self.arena.kids_of(node));
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
        if items.len() > 1 {
            self.group_binds(is_and, &mut items);
        }
        let result = match items.len() {
            0 => neutral,
            1 => items[0],
            _ => {
                let raw = self.arena.intern(Node::junction(is_and), &items);
                let node = self.arena.nodes[raw as usize];
                if node.simplified {
                    raw
                } else if node.target != NONE {
                    node.target
                } else {
                    self.simplify(is_and, raw, &mut items)
                }
            }
        };
        self.scratch.tmp = items;
        result
    }

    /// Works out what the junction `raw` of `items` simplifies to and remembers it on `raw`.
    fn simplify(&mut self, is_and: bool, raw: NodeId, items: &mut Vec<NodeId>) -> NodeId {
        let merged = self.merge_windows(is_and, items);
        let before = items.len();
        if items.len() > 1 && items.len() <= IMPLICATION_CHECK_LIMIT {
            self.drop_implied(is_and, items);
        }
        let result = if !merged && items.len() == before {
            raw
        } else {
            match items.len() {
                0 => {
                    if is_and {
                        TRUE
                    } else {
                        FALSE
                    }
                }
                1 => items[0],
                _ => {
                    items.sort_unstable();
                    let simplified = self.arena.intern(Node::junction(is_and), items);
                    self.arena.nodes[simplified as usize].simplified = true;
                    simplified
                }
            }
        };
        if result == raw {
            self.arena.nodes[raw as usize].simplified = true;
        } else {
            self.arena.nodes[raw as usize].target = result;
        }
        result
    }

    /// Children bound to the same objects become one: `{c} x and {c} y` is `{c} (x and y)`, so
    /// that the junction rules apply between them (instances started at different states for
    /// the same object merge as they do without quantifiers).
    fn group_binds(&mut self, is_and: bool, items: &mut Vec<NodeId>) {
        let arena = &*self.arena;
        if items.iter().filter(|id| arena.nodes[**id as usize].kind == Kind::Bind).nth(1).is_none() {
            return;
        }
        let mut binds: Vec<(u32, NodeId, NodeId)> = items
            .iter()
            .filter_map(|id| {
                let node = &arena.nodes[*id as usize];
                (node.kind == Kind::Bind).then(|| (node.env, arena.kids_of(node)[0], *id))
            })
            .collect();
        if binds.len() < 2 {
            return;
        }
        binds.sort_unstable();
        if !binds.windows(2).any(|w| w[0].0 == w[1].0) {
            return;
        }
        items.retain(|id| arena.nodes[*id as usize].kind != Kind::Bind);
        let mut i = 0;
        while i < binds.len() {
            let env = binds[i].0;
            let mut j = i + 1;
            while j < binds.len() && binds[j].0 == env {
                j += 1;
            }
            if j - i == 1 {
                items.push(binds[i].2);
            } else {
                let start = self.scratch.buf.len();
                for b in &binds[i..j] {
                    self.scratch.buf.push(b.1);
                }
                // (`items` is the outer junction's `tmp`, taken: the inner one gets its own.)
                let inner = self.junction(is_and, start);
                let bound = self.bind(env, inner);
                items.push(bound);
            }
            i = j;
        }
        items.sort_unstable();
        items.dedup();
    }

    /// Merges temporal children of one operator and body by their windows: in an `and`,
    /// `always`/`release` windows that overlap or touch become their union and an
    /// `eventually`/`until` whose window contains another's is dropped (it is implied); in an
    /// `or`, the duals. Returns whether `items` changed (and so needs sorting again).
    fn merge_windows(&mut self, is_and: bool, items: &mut Vec<NodeId>) -> bool {
        let mut windows = std::mem::take(&mut self.scratch.windows);
        windows.clear();
        for &id in items.iter() {
            let node = &self.arena.nodes[id as usize];
            if let Kind::Temporal(op) = node.kind {
                windows.push(WindowItem { op, tpl: node.tpl, lo: node.lo, hi: node.hi, id });
            }
        }
        if windows.len() < 2 {
            self.scratch.windows = windows;
            return false;
        }
        windows.sort_unstable_by_key(|w| (w.op, w.tpl, w.lo, w.hi));
        let shares_body = windows.windows(2).any(|p| (p[0].op, p[0].tpl) == (p[1].op, p[1].tpl));
        if !shares_body {
            self.scratch.windows = windows;
            return false;
        }
        items.retain(|id| !matches!(self.arena.nodes[*id as usize].kind, Kind::Temporal(_)));
        let mut group_start = 0;
        while group_start < windows.len() {
            let key = (windows[group_start].op, windows[group_start].tpl);
            let mut group_end = group_start + 1;
            while group_end < windows.len() && (windows[group_end].op, windows[group_end].tpl) == key {
                group_end += 1;
            }
            let group = &mut windows[group_start..group_end];
            let union = is_and != key.0.is_existential();
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
                let mut min_hi = u64::MAX;
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

    fn window_node(&mut self, w: WindowItem) -> NodeId {
        if w.id != NONE {
            return w.id;
        }
        let info = self.formula.info[w.tpl as usize];
        let node =
            Node { reads: info.reads, cacheable: info.cacheable, ..Node::temporal(w.op, w.lo, w.hi, w.tpl) };
        self.arena.intern(node, &[])
    }

    /// Drops children implied by a sibling: in an `and`, a child that another implies; in an
    /// `or`, a child that implies another. Only runs when some child is itself a junction or
    /// bound (plain temporal siblings were handled by `merge_windows`).
    fn drop_implied(&mut self, is_and: bool, items: &mut Vec<NodeId>) {
        let arena = &*self.arena;
        if !items.iter().any(|id| matches!(arena.nodes[*id as usize].kind, Kind::And | Kind::Or | Kind::Bind))
        {
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
fn implies(arena: &Arena, a: NodeId, b: NodeId, depth: u32) -> bool {
    if a == b || a == FALSE || b == TRUE {
        return true;
    }
    if a == TRUE || b == FALSE {
        return false;
    }
    let na = &arena.nodes[a as usize];
    let nb = &arena.nodes[b as usize];
    if let (Kind::Temporal(op_a), Kind::Temporal(op_b)) = (na.kind, nb.kind) {
        if op_a != op_b || na.tpl != nb.tpl {
            return false;
        }
        let a_inside_b = nb.lo <= na.lo && na.hi <= nb.hi;
        let b_inside_a = na.lo <= nb.lo && nb.hi <= na.hi;
        // Existential: a smaller window is stronger. Universal: a larger window is stronger.
        return if op_a.is_existential() { a_inside_b } else { b_inside_a };
    }
    if na.kind == Kind::Bind && nb.kind == Kind::Bind {
        return na.env == nb.env && implies(arena, arena.kids_of(na)[0], arena.kids_of(nb)[0], depth);
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
