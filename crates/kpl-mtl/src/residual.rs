//! Residuals: what is left of a formula after some states, as nodes of one hash-consed arena that
//! lives as long as its owner (a progressor, a group of instances, an every-state monitor).
//!
//! A node is `true`, `false`, an `and`/`or` of other nodes, a pending temporal node (operator,
//! window relative to the last state's time, the compiled body it will instantiate), a node
//! bound to objects of quantifiers (`Bind`: the nodes below it read the objects of its
//! environment), or `Start`: a compiled node not yet instantiated (an instance before its first
//! state). Equal residuals are one node, whoever holds them, so instances in the same situation
//! share their residual and its transitions. Children always have smaller ids than their parents.
//!
//! What a node stands for never changes once it is made; a node only remembers what was worked
//! out about it (what it simplifies to, its last transition). Garbage (nodes no root reaches) is reclaimed by
//! [`Arena::compact`], which the owner calls when the arena has grown well past what was live at
//! the last collection, with every root it holds so they can be renumbered.

use std::collections::HashMap;
use std::fmt;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::Arc;

use crate::formula::{Formula, TNode, TemporalOp, TplId};
use crate::term::Binding;

pub(crate) type NodeId = u32;
pub(crate) const TRUE: NodeId = 0;
pub(crate) const FALSE: NodeId = 1;
pub(crate) const NONE: u32 = u32::MAX;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) enum Kind {
    True,
    False,
    And,
    Or,
    Temporal(TemporalOp),
    /// The child reads the objects of environment `env`.
    Bind,
    /// Compiled node `tpl`, to be instantiated at the next state.
    Start,
}

/// One residual node. Temporal nodes use `lo`, `hi` (offsets from the last state's time, `INF`
/// for unbounded) and `tpl` (the compiled temporal node); `and`/`or` use `kids..kids + n_kids`
/// of the arena's `kids`; `Bind` uses `env` and one kid; `Start` uses `tpl`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Node {
    pub kind: Kind,
    /// Whether the node's transitions depend only on the atoms in `reads` (no `Bind` below, no
    /// quantifier in a pending body, every atom in the first word).
    pub cacheable: bool,
    /// For `and`/`or`: whether this node is known to be simplified as far as the junction
    /// rules go. When it is not (a junction as first assembled), `target` is what it simplifies
    /// to once that was worked out (`NONE` before).
    pub simplified: bool,
    pub tpl: TplId,
    pub env: u32,
    pub kids: u32,
    pub n_kids: u32,
    pub target: NodeId,
    /// The node's hash (of what it stands for), kept for the interning table.
    pub hash: u32,
    /// The atoms the node's progression may read, as a bit set over the first word of atoms.
    pub reads: u64,
    pub lo: u64,
    pub hi: u64,
    /// The last transition looked up for this node (for a `cacheable` node): with atom values
    /// `last_value` (none failed), `last_d` after the previous state, it became `last_next`
    /// (`NONE`: none yet). Kept in the node so that a recurring situation is answered from the
    /// node itself, without a hash lookup.
    pub last_value: u64,
    pub last_d: u64,
    pub last_next: NodeId,
}

impl Node {
    pub fn temporal(op: TemporalOp, lo: u64, hi: u64, tpl: TplId) -> Node {
        Node { kind: Kind::Temporal(op), lo, hi, tpl, ..Node::blank(Kind::Temporal(op)) }
    }
    pub fn junction(is_and: bool) -> Node {
        Node::blank(if is_and { Kind::And } else { Kind::Or })
    }
    pub fn bind(env: u32) -> Node {
        Node { env, ..Node::blank(Kind::Bind) }
    }
    pub fn start(tpl: TplId) -> Node {
        Node { tpl, ..Node::blank(Kind::Start) }
    }
    fn blank(kind: Kind) -> Node {
        Node {
            kind,
            cacheable: false,
            simplified: false,
            tpl: 0,
            env: 0,
            kids: 0,
            n_kids: 0,
            target: NONE,
            hash: 0,
            reads: 0,
            lo: 0,
            hi: 0,
            last_value: 0,
            last_d: 0,
            last_next: NONE,
        }
    }
    fn same_key(&self, other: &Node) -> bool {
        self.kind == other.kind
            && self.lo == other.lo
            && self.hi == other.hi
            && self.tpl == other.tpl
            && self.env == other.env
            && self.n_kids == other.n_kids
    }
}

/// Keys of the interning table are already well mixed hashes.
#[derive(Default)]
pub(crate) struct IdHasher(u64);

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
    fn write_u32(&mut self, n: u32) {
        self.0 = u64::from(n).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

pub(crate) fn mix(h: u64, x: u64) -> u64 {
    (h.rotate_left(5) ^ x).wrapping_mul(0x517C_C1B7_2722_0A95)
}

pub(crate) type Env = Arc<[Binding]>;

/// The hash-consed nodes of one owner's residuals.
pub(crate) struct Arena {
    pub nodes: Vec<Node>,
    pub kids: Vec<NodeId>,
    /// The interning table: node ids by hash, open addressing with linear probing, at most half
    /// full (`NONE`: empty slot). Its length is a power of two.
    table: Vec<NodeId>,
    /// Environments of `Bind` nodes; `envs[0]` is the empty one.
    pub envs: Vec<Env>,
    env_table: HashMap<Env, u32>,
    /// Buffers that compaction fills and swaps in, kept to be reused.
    spare_nodes: Vec<Node>,
    spare_kids: Vec<NodeId>,
    stack: Vec<NodeId>,
}

impl fmt::Debug for Arena {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Arena").field("nodes", &self.nodes.len()).field("envs", &self.envs.len()).finish()
    }
}

impl Arena {
    pub fn new() -> Arena {
        let mut arena = Arena {
            nodes: Vec::new(),
            kids: Vec::new(),
            table: vec![NONE; 64],
            envs: vec![Arc::from(Vec::new())],
            env_table: HashMap::new(),
            spare_nodes: Vec::new(),
            spare_kids: Vec::new(),
            stack: Vec::new(),
        };
        for kind in [Kind::True, Kind::False] {
            arena.nodes.push(Node { cacheable: true, simplified: true, ..Node::blank(kind) });
        }
        arena
    }

    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn kids_of(&self, node: &Node) -> &[NodeId] {
        &self.kids[node.kids as usize..(node.kids + node.n_kids) as usize]
    }

    fn hash(node: &Node, kids: &[NodeId]) -> u64 {
        let kind = match node.kind {
            Kind::True => 1,
            Kind::False => 2,
            Kind::And => 3,
            Kind::Or => 4,
            Kind::Temporal(op) => 5 + op as u64,
            Kind::Bind => 9,
            Kind::Start => 10,
        };
        let mut h = mix(mix(mix(mix(kind, node.lo), node.hi), u64::from(node.tpl)), u64::from(node.env));
        for k in kids {
            h = mix(h, u64::from(*k));
        }
        h
    }

    /// The node equal to `node` with these children, created if new. `node`'s `cacheable` and
    /// `reads` are given by the caller for leaves and computed here for `and`/`or`/`Bind`.
    pub fn intern(&mut self, mut node: Node, kids: &[NodeId]) -> NodeId {
        node.n_kids = kids.len() as u32;
        let h = Arena::hash(&node, kids);
        node.hash = h as u32;
        let mask = self.table.len() - 1;
        let mut slot = (node.hash as usize) & mask;
        loop {
            let candidate = self.table[slot];
            if candidate == NONE {
                break;
            }
            let other = &self.nodes[candidate as usize];
            // (Children compared one by one: a call to `memcmp` for these short slices cost more
            // than the rest of the lookup.)
            if other.hash == node.hash
                && other.same_key(&node)
                && self.kids[other.kids as usize..(other.kids + other.n_kids) as usize]
                    .iter()
                    .zip(kids)
                    .all(|(a, b)| a == b)
            {
                return candidate;
            }
            slot = (slot + 1) & mask;
        }
        match node.kind {
            Kind::And | Kind::Or => {
                node.cacheable = kids.iter().all(|k| self.nodes[*k as usize].cacheable);
                node.reads = kids.iter().fold(0, |acc, k| acc | self.nodes[*k as usize].reads);
            }
            Kind::Bind => {
                node.cacheable = false;
                node.reads = 0;
            }
            _ => {}
        }
        let id = self.nodes.len() as NodeId;
        node.kids = self.kids.len() as u32;
        self.kids.extend_from_slice(kids);
        self.nodes.push(node);
        self.table[slot] = id;
        if 2 * self.nodes.len() > self.table.len() {
            self.rebuild_table(self.table.len() * 2);
        }
        id
    }

    /// Refills the interning table (of `len` slots) from the nodes' stored hashes.
    fn rebuild_table(&mut self, len: usize) {
        self.table.clear();
        self.table.resize(len, NONE);
        let mask = len - 1;
        for (id, node) in self.nodes.iter().enumerate().skip(2) {
            let mut slot = (node.hash as usize) & mask;
            while self.table[slot] != NONE {
                slot = (slot + 1) & mask;
            }
            self.table[slot] = id as NodeId;
        }
    }

    pub fn intern_env(&mut self, env: &[Binding]) -> u32 {
        if env.is_empty() {
            return 0;
        }
        if let Some(id) = self.env_table.get(env) {
            return *id;
        }
        let env: Env = Arc::from(env);
        let id = self.envs.len() as u32;
        self.envs.push(env.clone());
        self.env_table.insert(env, id);
        id
    }

    /// Closes a residual at the end of the stream: what is still open never happens, so an
    /// `eventually` or `until` is false and an `always` or `release` is true.
    pub fn close(&self, id: NodeId) -> bool {
        let node = &self.nodes[id as usize];
        match node.kind {
            Kind::True => true,
            Kind::False => false,
            Kind::And => self.kids_of(node).iter().all(|k| self.close(*k)),
            Kind::Or => self.kids_of(node).iter().any(|k| self.close(*k)),
            Kind::Bind => self.close(self.kids_of(node)[0]),
            Kind::Temporal(op) => !op.is_existential(),
            // Never reached: an instance that saw no state has no verdict to close.
            Kind::Start => true,
        }
    }

    /// Number of distinct nodes reachable from the roots (a `Start` counts 0: nothing is
    /// pending yet).
    pub fn size(&self, roots: impl Iterator<Item = NodeId>) -> usize {
        // Residuals are small next to the arena (which keeps what the transition cache refers
        // to): the set of seen nodes is kept by node, not by arena slot.
        let mut seen: std::collections::HashSet<NodeId, BuildHasherDefault<IdHasher>> = Default::default();
        let mut stack: Vec<NodeId> = roots.collect();
        let mut count = 0;
        while let Some(id) = stack.pop() {
            if !seen.insert(id) {
                continue;
            }
            let node = &self.nodes[id as usize];
            if node.kind != Kind::Start {
                count += 1;
            }
            stack.extend_from_slice(self.kids_of(node));
        }
        count
    }

    /// Keeps only the nodes reachable from `roots` (and from `extra`, which the owner may use for
    /// nodes a cache refers to), renumbered; every root is rewritten in place. Returns the
    /// mapping from old to new ids (`NONE` for nodes that were dropped).
    pub fn compact(&mut self, roots: &mut [NodeId], extra: impl Iterator<Item = NodeId>) -> Vec<NodeId> {
        let n = self.nodes.len();
        // `map` first marks the live nodes (0: dead, 1: live), then holds their new ids.
        let mut map = vec![0u32; n];
        map[TRUE as usize] = 1;
        map[FALSE as usize] = 1;
        let mut stack = std::mem::take(&mut self.stack);
        stack.clear();
        stack.extend(roots.iter().copied().chain(extra));
        while let Some(id) = stack.pop() {
            if std::mem::replace(&mut map[id as usize], 1) == 1 {
                continue;
            }
            let node = &self.nodes[id as usize];
            stack.extend_from_slice(self.kids_of(node));
            if node.target != NONE {
                stack.push(node.target);
            }
        }
        self.stack = stack;
        // Environments still bound somewhere.
        let mut env_map = vec![NONE; self.envs.len()];
        env_map[0] = 0;
        let mut envs: Vec<Env> = vec![self.envs[0].clone()];
        let mut nodes = std::mem::take(&mut self.spare_nodes);
        let mut kids = std::mem::take(&mut self.spare_kids);
        nodes.clear();
        kids.clear();
        for id in 0..n {
            if map[id] == 0 {
                map[id] = NONE;
                continue;
            }
            let mut node = self.nodes[id];
            let start = kids.len() as u32;
            // Children have smaller ids, so they are already renumbered.
            for k in self.kids_of(&node) {
                kids.push(map[*k as usize]);
            }
            node.kids = start;
            if node.kind == Kind::Bind {
                let e = node.env as usize;
                if env_map[e] == NONE {
                    env_map[e] = envs.len() as u32;
                    envs.push(self.envs[e].clone());
                }
                node.env = env_map[e];
            }
            map[id] = nodes.len() as NodeId;
            nodes.push(node);
        }
        // Targets may point to later nodes (a junction as assembled points to its simplified
        // form, which is made after it); a remembered transition may point to a node no longer
        // kept, and is then forgotten.
        for node in &mut nodes {
            if node.target != NONE {
                node.target = map[node.target as usize];
            }
            if node.last_next != NONE {
                node.last_next = map[node.last_next as usize];
            }
        }
        self.spare_nodes = std::mem::replace(&mut self.nodes, nodes);
        self.spare_kids = std::mem::replace(&mut self.kids, kids);
        self.envs = envs;
        self.env_table = self.envs.iter().enumerate().skip(1).map(|(i, e)| (e.clone(), i as u32)).collect();
        let len = (2 * self.nodes.len()).next_power_of_two().max(64);
        self.rebuild_table(len);
        for root in roots.iter_mut() {
            *root = map[*root as usize];
        }
        map
    }

    pub fn write(&self, formula: &Formula, f: &mut impl fmt::Write, id: NodeId) -> fmt::Result {
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
            Kind::Bind => {
                f.write_char('{')?;
                for (i, b) in self.envs[node.env as usize].iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "${i}={}", b.id)?;
                }
                f.write_str("} ")?;
                self.write(formula, f, self.kids_of(node)[0])
            }
            Kind::Start => formula.write_node(f, node.tpl),
            Kind::Temporal(op) => {
                let TNode::Temporal { lhs, rhs, .. } = formula.nodes[node.tpl as usize] else {
                    return f.write_str("?");
                };
                match op {
                    TemporalOp::Eventually | TemporalOp::Always => {
                        f.write_str(if op == TemporalOp::Eventually { "eventually" } else { "always" })?;
                        Formula::write_window(f, node.lo, node.hi)?;
                        f.write_char(' ')?;
                        formula.write_node(f, rhs)
                    }
                    TemporalOp::Until | TemporalOp::Release => {
                        f.write_char('(')?;
                        formula.write_node(f, lhs)?;
                        f.write_str(if op == TemporalOp::Until { " until" } else { " release" })?;
                        Formula::write_window(f, node.lo, node.hi)?;
                        f.write_char(' ')?;
                        formula.write_node(f, rhs)?;
                        f.write_char(')')
                    }
                }
            }
        }
    }
}
