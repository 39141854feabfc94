//! Many instances of one formula, each progressed through its own stream of states, sharing one
//! engine: a link process's condition for each of its objects or pairs, a monitor's formula for
//! each binding.
//!
//! Instances in the same situation (the same residual, the same time since their last state,
//! the same values of the atoms it reads) share one transition of the cache, so the residual is
//! progressed once for all of them and each further instance costs its atoms and one lookup;
//! residuals equal across instances are one node of the shared arena.

use std::sync::Arc;

use kpl_core::Time;

use crate::engine::{Engine, EngineConfig, EngineStats};
use crate::error::EvalError;
use crate::formula::Formula;
use crate::handover::{self, Handover, HandoverError};
use crate::progress::elapsed;
use crate::residual::{FALSE, NodeId, TRUE};
use crate::state::State;

/// An instance of a [`ProgressorGroup`]. It stays valid until [`ProgressorGroup::remove`]; a
/// removed instance's id is refused afterwards, even once its slot is reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct InstanceId {
    index: u32,
    generation: u32,
}

#[derive(Debug, Clone)]
struct Slot {
    generation: u32,
    live: bool,
    root: NodeId,
    last_time: Option<Time>,
    verdict: Option<bool>,
    decided_at: Option<Time>,
}

/// Instances of one formula, each with its own stream of states, sharing their work.
///
/// ```
/// use std::sync::Arc;
/// use kpl_core::TimeUnit;
/// use kpl_mtl::{Context, Formula, Mtl, ProgressorGroup, SlotState, Term, Window};
///
/// let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
/// let p = ctx.declare_value("p");
/// let f = Formula::new(&Mtl::eventually(Window::bounded(0, 100), Mtl::atom(Term::slot(p))), &ctx).unwrap();
/// let mut group = ProgressorGroup::new(Arc::new(f));
/// let ids: Vec<_> = (0..1000).map(|_| group.start()).collect();
/// for (i, id) in ids.iter().enumerate() {
///     // Every instance is in the same situation: the residual is progressed once.
///     assert_eq!(group.step(*id, 0, &SlotState::bools(&[i == 7])).unwrap(), (i == 7).then_some(true));
/// }
/// assert_eq!(group.step(ids[0], 200, &SlotState::bools(&[false])).unwrap(), Some(false));
/// ```
#[derive(Debug)]
pub struct ProgressorGroup {
    engine: Engine,
    start: NodeId,
    slots: Vec<Slot>,
    free: Vec<u32>,
    live: usize,
}

impl ProgressorGroup {
    pub fn new(formula: Arc<Formula>) -> ProgressorGroup {
        ProgressorGroup::with_config(formula, EngineConfig::default())
    }

    pub fn with_config(formula: Arc<Formula>, config: EngineConfig) -> ProgressorGroup {
        let mut engine = Engine::new(formula, config);
        let start = engine.start();
        ProgressorGroup { engine, start, slots: Vec::new(), free: Vec::new(), live: 0 }
    }

    pub fn formula(&self) -> &Arc<Formula> {
        &self.engine.formula
    }

    /// A new instance, before its first state.
    pub fn start(&mut self) -> InstanceId {
        self.live += 1;
        let fresh = |generation| Slot {
            generation,
            live: true,
            root: 0,
            last_time: None,
            verdict: None,
            decided_at: None,
        };
        match self.free.pop() {
            Some(index) => {
                let slot = &mut self.slots[index as usize];
                *slot = Slot { root: self.start, ..fresh(slot.generation.wrapping_add(1)) };
                InstanceId { index, generation: slot.generation }
            }
            None => {
                self.slots.push(Slot { root: self.start, ..fresh(0) });
                InstanceId { index: (self.slots.len() - 1) as u32, generation: 0 }
            }
        }
    }

    /// Drops an instance; its id is refused from now on.
    pub fn remove(&mut self, id: InstanceId) {
        if self.slot(id).is_some() {
            self.slots[id.index as usize].live = false;
            self.free.push(id.index);
            self.live -= 1;
        }
    }

    /// Starts an instance over, as if it had seen no state.
    pub fn restart(&mut self, id: InstanceId) {
        let start = self.start;
        if let Some(slot) = self.slot_mut(id) {
            *slot = Slot { root: start, last_time: None, verdict: None, decided_at: None, ..slot.clone() };
        }
    }

    /// Number of instances.
    pub fn len(&self) -> usize {
        self.live
    }

    pub fn is_empty(&self) -> bool {
        self.live == 0
    }

    fn slot(&self, id: InstanceId) -> Option<&Slot> {
        self.slots.get(id.index as usize).filter(|s| s.live && s.generation == id.generation)
    }

    fn slot_mut(&mut self, id: InstanceId) -> Option<&mut Slot> {
        self.slots.get_mut(id.index as usize).filter(|s| s.live && s.generation == id.generation)
    }

    /// Progresses instance `id` through its state at `time` (strictly after its previous
    /// state's), as [`crate::Progressor::step`] does. On error nothing changes.
    pub fn step<S: State + ?Sized>(
        &mut self,
        id: InstanceId,
        time: Time,
        state: &S,
    ) -> Result<Option<bool>, EvalError> {
        let Some(slot) =
            self.slots.get_mut(id.index as usize).filter(|s| s.live && s.generation == id.generation)
        else {
            return Err(EvalError::NoInstance);
        };
        let d = elapsed(slot.last_time, time)?;
        if slot.verdict.is_some() {
            slot.last_time = Some(time);
            return Ok(slot.verdict);
        }
        self.engine.begin_state();
        let root = self.engine.progress(slot.root, d, state)?;
        slot.root = root;
        slot.last_time = Some(time);
        if root <= FALSE {
            slot.verdict = Some(root == TRUE);
            slot.decided_at = Some(time);
        }
        let verdict = slot.verdict;
        if self.engine.should_collect() {
            self.collect();
        }
        Ok(verdict)
    }

    fn collect(&mut self) {
        let mut roots: Vec<NodeId> = self.slots.iter().filter(|s| s.live).map(|s| s.root).collect();
        roots.push(self.start);
        self.engine.collect(&mut roots);
        self.start = roots[roots.len() - 1];
        for (slot, root) in self.slots.iter_mut().filter(|s| s.live).zip(roots) {
            slot.root = root;
        }
    }

    /// Ends instance `id`'s stream (finite-trace semantics); `None` if it saw no state.
    pub fn finish(&mut self, id: InstanceId) -> Option<bool> {
        let slot =
            self.slots.get_mut(id.index as usize).filter(|s| s.live && s.generation == id.generation)?;
        if slot.verdict.is_none() {
            slot.last_time?;
            slot.verdict = Some(self.engine.close(slot.root));
        }
        slot.verdict
    }

    /// The instance's verdict, once certain.
    pub fn verdict(&self, id: InstanceId) -> Option<bool> {
        self.slot(id)?.verdict
    }

    /// The time of the state at which the instance's verdict became certain.
    pub fn decided_at(&self, id: InstanceId) -> Option<Time> {
        self.slot(id)?.decided_at
    }

    /// The time of the instance's last state.
    pub fn last_time(&self, id: InstanceId) -> Option<Time> {
        self.slot(id)?.last_time
    }

    /// Number of distinct nodes of the instance's residual.
    pub fn residual_size(&self, id: InstanceId) -> usize {
        self.slot(id).map_or(0, |s| self.engine.arena.size(std::iter::once(s.root)))
    }

    /// Number of distinct residual nodes over all instances (shared nodes count once).
    pub fn total_residual_size(&self) -> usize {
        self.engine.arena.size(self.slots.iter().filter(|s| s.live).map(|s| s.root))
    }

    /// The instance's residual as text.
    pub fn residual(&self, id: InstanceId) -> String {
        let mut out = String::new();
        if let Some(slot) = self.slot(id) {
            let _ = self.engine.arena.write(&self.engine.formula, &mut out, slot.root);
        }
        out
    }

    /// Instance `id`'s progress, to be taken over by a group of the same formula
    /// ([`ProgressorGroup::take_over`], possibly in another process); the instance stays here
    /// until [`ProgressorGroup::remove`]. `None` for an id the group does not hold.
    pub fn hand_over(&self, id: InstanceId) -> Option<Handover> {
        let slot = self.slot(id)?;
        Some(Handover {
            formula: self.engine.formula.fingerprint(),
            last_time: slot.last_time,
            verdict: slot.verdict,
            decided_at: slot.decided_at,
            nodes: handover::write_out(&self.engine.arena, slot.root),
        })
    }

    /// A new instance that goes on from where a handed-over one was: its next state must be
    /// after the handover's last, and it reaches the verdicts the instance would have reached in
    /// its own group. A handover of another formula, or one that is not well formed (it may come
    /// from the network), is refused and the group is unchanged (but for residual nodes that
    /// nothing refers to).
    pub fn take_over(&mut self, handover: &Handover) -> Result<InstanceId, HandoverError> {
        let expected = self.engine.formula.fingerprint();
        if handover.formula != expected {
            return Err(HandoverError::OtherFormula { expected, found: handover.formula });
        }
        let formula = self.engine.formula.clone();
        let root = handover::read_in(&mut self.engine.arena, &formula, self.start, &handover.nodes)?;
        let decided = root <= FALSE;
        match handover.verdict {
            Some(v) if !decided || v != (root == TRUE) => {
                return Err(HandoverError::Inconsistent("has a verdict its residual does not have"));
            }
            None if decided => {
                return Err(HandoverError::Inconsistent("has a decided residual but no verdict"));
            }
            _ => {}
        }
        if handover.verdict.is_some() != handover.decided_at.is_some() {
            return Err(HandoverError::Inconsistent(
                "has a verdict without the time it was decided, or the reverse",
            ));
        }
        if (root == self.start) != handover.last_time.is_none() {
            return Err(HandoverError::Inconsistent(
                "has seen states but has the whole formula as its residual, or the reverse",
            ));
        }
        let id = self.start();
        let slot = &mut self.slots[id.index as usize];
        slot.root = root;
        slot.last_time = handover.last_time;
        slot.verdict = handover.verdict;
        slot.decided_at = handover.decided_at;
        Ok(id)
    }

    /// What the engine did so far.
    pub fn stats(&self) -> EngineStats {
        self.engine.stats
    }
}
