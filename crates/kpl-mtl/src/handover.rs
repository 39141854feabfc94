//! Handing an instance of a [`crate::ProgressorGroup`] over to another group of the same formula:
//! in another part of a process, another process or another host. What an instance is, is its
//! residual (what is left of the formula after its states), the time of its last state and its
//! verdict; the residual's nodes live in the arena of their group, numbered by it and shared with
//! its other instances, so a [`Handover`] writes them out as a list that refers to nothing but
//! itself and the compiled formula (its templates, by index), which both groups compiled from the
//! same text. The group that takes it over interns the nodes into its own arena: an instance in
//! the same situation as one of its own shares its residual at once, and the instance goes on as
//! if it had never moved (the same verdicts at the same states; `tests/handover.rs` holds this
//! against instances that stayed, on random formulas and traces).
//!
//! A handover may come from the network: [`crate::ProgressorGroup::take_over`] checks every node
//! (indices only backwards, a temporal node's operator that of its template, windows not empty,
//! bound objects of the formula's domains, the verdict consistent with the residual) and refuses
//! with a [`HandoverError`] instead of trusting it; a checked handover cannot make the engine
//! panic. One of another formula is refused by the formula's fingerprint.

use std::collections::HashSet;
use std::sync::Arc;

use kpl_core::Time;
use serde::{Deserialize, Serialize};

use crate::formula::{Formula, INF, TNode, TemporalOp};
use crate::residual::{Arena, FALSE, Kind, Node, NodeId, TRUE};
use crate::term::{Binding, DomainId};

/// An instance's progress, taken out of its group ([`crate::ProgressorGroup::hand_over`]) to be
/// taken over by a group of the same formula ([`crate::ProgressorGroup::take_over`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Handover {
    /// [`Formula::fingerprint`] of the formula it is an instance of.
    pub formula: u64,
    /// The time of the instance's last state (`None` before its first).
    pub last_time: Option<Time>,
    /// Its verdict, once certain, and the time of the state that made it so.
    pub verdict: Option<bool>,
    pub decided_at: Option<Time>,
    /// The residual's nodes, each after the nodes it refers to; the last one is the root.
    pub nodes: Vec<HandedNode>,
}

/// One node of a handed-over residual; children are indices of earlier nodes of the list.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub enum HandedNode {
    True,
    False,
    /// A conjunction or disjunction; `simplified` as the engine keeps it (known to be as simple
    /// as its rules make it).
    And {
        kids: Vec<u32>,
        simplified: bool,
    },
    Or {
        kids: Vec<u32>,
        simplified: bool,
    },
    /// A pending temporal operator: compiled node `template` (the formula's), with its window
    /// relative to the last state's time (`hi` `None`: unbounded).
    Temporal {
        op: HandedOp,
        lo: u64,
        hi: Option<u64>,
        template: u32,
    },
    /// `kid` reads the objects bound by quantifiers: (domain, id) each.
    Bind {
        objects: Vec<(DomainId, Arc<str>)>,
        kid: u32,
    },
    /// The whole formula, before the instance's first state.
    Start,
}

/// The temporal operators of a residual (negation normal form).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum HandedOp {
    Eventually,
    Always,
    Until,
    Release,
}

impl HandedOp {
    fn of(op: TemporalOp) -> HandedOp {
        match op {
            TemporalOp::Eventually => HandedOp::Eventually,
            TemporalOp::Always => HandedOp::Always,
            TemporalOp::Until => HandedOp::Until,
            TemporalOp::Release => HandedOp::Release,
        }
    }

    fn op(self) -> TemporalOp {
        match self {
            HandedOp::Eventually => TemporalOp::Eventually,
            HandedOp::Always => TemporalOp::Always,
            HandedOp::Until => TemporalOp::Until,
            HandedOp::Release => TemporalOp::Release,
        }
    }
}

/// Why a group refused a [`Handover`]; the group is unchanged.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HandoverError {
    #[error(
        "the handover is an instance of another formula (fingerprint {found:016x}, this group's {expected:016x})"
    )]
    OtherFormula { expected: u64, found: u64 },
    #[error("node {node} of the handover: {problem}")]
    BadNode { node: usize, problem: String },
    #[error("the handover {0}")]
    Inconsistent(&'static str),
}

/// Writes the residual rooted at `root` as a handover's nodes.
pub(crate) fn write_out(arena: &Arena, root: NodeId) -> Vec<HandedNode> {
    // Children have smaller ids than their parents, so the reachable nodes in increasing id are
    // in an order where each comes after its children.
    let mut reachable = Vec::new();
    let mut seen: HashSet<NodeId> = HashSet::new();
    let mut stack = vec![root];
    while let Some(id) = stack.pop() {
        if seen.insert(id) {
            reachable.push(id);
            stack.extend_from_slice(arena.kids_of(&arena.nodes[id as usize]));
        }
    }
    reachable.sort_unstable();
    // A child's index in the list: where it is in the sorted ids (it is there: it was reached).
    let index = |id: &NodeId| reachable.binary_search(id).unwrap_or_default() as u32;
    reachable
        .iter()
        .map(|id| {
            let node = &arena.nodes[*id as usize];
            let kids = arena.kids_of(node);
            match node.kind {
                Kind::True => HandedNode::True,
                Kind::False => HandedNode::False,
                Kind::And => {
                    HandedNode::And { kids: kids.iter().map(index).collect(), simplified: node.simplified }
                }
                Kind::Or => {
                    HandedNode::Or { kids: kids.iter().map(index).collect(), simplified: node.simplified }
                }
                Kind::Temporal(op) => HandedNode::Temporal {
                    op: HandedOp::of(op),
                    lo: node.lo,
                    hi: (node.hi != INF).then_some(node.hi),
                    template: node.tpl,
                },
                Kind::Bind => HandedNode::Bind {
                    objects: arena.envs[node.env as usize].iter().map(|b| (b.domain, b.id.clone())).collect(),
                    kid: index(&kids[0]),
                },
                Kind::Start => HandedNode::Start,
            }
        })
        .collect()
}

/// Interns a handover's nodes into `arena` after checking them; returns the root. `start` is
/// the group's node for the formula before any state. On error the arena may hold new nodes that
/// nothing refers to (its next collection drops them).
pub(crate) fn read_in(
    arena: &mut Arena,
    formula: &Formula,
    start: NodeId,
    nodes: &[HandedNode],
) -> Result<NodeId, HandoverError> {
    if nodes.is_empty() {
        return Err(HandoverError::Inconsistent("has no residual"));
    }
    let mut ids: Vec<NodeId> = Vec::with_capacity(nodes.len());
    let mut kids_buf: Vec<NodeId> = Vec::new();
    for (n, handed) in nodes.iter().enumerate() {
        let bad = |problem: String| HandoverError::BadNode { node: n, problem };
        let earlier = |k: u32| -> Result<NodeId, HandoverError> {
            ids.get(k as usize)
                .copied()
                .ok_or_else(|| bad(format!("refers to node {k}, which is not before it")))
        };
        let id = match handed {
            HandedNode::True => TRUE,
            HandedNode::False => FALSE,
            HandedNode::And { kids, simplified } | HandedNode::Or { kids, simplified } => {
                let is_and = matches!(handed, HandedNode::And { .. });
                let (absorbing, neutral) = if is_and { (FALSE, TRUE) } else { (TRUE, FALSE) };
                kids_buf.clear();
                let mut absorbed = false;
                for k in kids {
                    match earlier(*k)? {
                        id if id == absorbing => absorbed = true,
                        id if id == neutral => {}
                        id => kids_buf.push(id),
                    }
                }
                // The arena keeps a junction's children in increasing id, without repeats.
                kids_buf.sort_unstable();
                kids_buf.dedup();
                match kids_buf.len() {
                    _ if absorbed => absorbing,
                    0 => neutral,
                    1 => kids_buf[0],
                    _ => {
                        let node = Node { simplified: *simplified, ..Node::junction(is_and) };
                        arena.intern(node, &kids_buf)
                    }
                }
            }
            HandedNode::Temporal { op, lo, hi, template } => {
                let op = op.op();
                match formula.nodes.get(*template as usize) {
                    Some(TNode::Temporal { op: compiled, .. }) if *compiled == op => {}
                    Some(_) => {
                        return Err(bad(format!("template {template} is not a {op:?} of the formula")));
                    }
                    None => return Err(bad(format!("template {template} is not in the formula"))),
                }
                let hi = hi.unwrap_or(INF);
                let finite = |b: u64| b <= i64::MAX as u64;
                if *lo > hi || !finite(*lo) || (hi != INF && !finite(hi)) {
                    return Err(bad(format!("window [{lo}, {hi}] is empty or out of range")));
                }
                let info = formula.info[*template as usize];
                let node = Node {
                    reads: info.reads,
                    cacheable: info.cacheable,
                    ..Node::temporal(op, *lo, hi, *template)
                };
                arena.intern(node, &[])
            }
            HandedNode::Bind { objects, kid } => {
                let inner = earlier(*kid)?;
                if objects.is_empty() {
                    return Err(bad("binds no object".to_string()));
                }
                if let Some((domain, _)) =
                    objects.iter().find(|(d, _)| *d as usize >= formula.domain_names.len())
                {
                    return Err(bad(format!(
                        "binds an object of domain {domain}, which the formula does not have"
                    )));
                }
                if inner <= FALSE {
                    inner
                } else {
                    let bindings: Vec<Binding> = objects
                        .iter()
                        .map(|(domain, id)| Binding { domain: *domain, id: id.clone() })
                        .collect();
                    let env = arena.intern_env(&bindings);
                    arena.intern(Node::bind(env), &[inner])
                }
            }
            HandedNode::Start => {
                if n + 1 != nodes.len() {
                    return Err(bad("the whole formula can only be the root".to_string()));
                }
                start
            }
        };
        ids.push(id);
    }
    Ok(ids[ids.len() - 1])
}
