//! A link process: one link specification `<A, B, unit, establish, reestablish, maintain>` and,
//! for every object p of type A, an instance running the paper's state machine (section IV-B):
//!
//! - **unlinked**: `establish(p)` and `reestablish(p, o)` for each candidate o are progressed.
//!   Candidates are the objects of type B not linked by this link specification; an object
//!   becomes a candidate of p when it is within the gate (see [`crate::conditions`]) and stops
//!   being one when it is removed or linked from another A object. A candidate whose reestablish
//!   condition became false is dropped, and comes back only after it left the gate, or was linked
//!   and unlinked again. When `establish` becomes true a new B object is created and linked; when
//!   some `reestablish(p, o)` becomes true p is linked to o.
//! - **linked**: B's state is computed from A's by the link unit; `maintain(p, o)` is progressed;
//!   when it becomes false the link is removed and p is unlinked again (both objects remain).
//!
//! Decisions taken at one state are resolved together, so the order of objects does not matter:
//! maintain failures first; then the reestablish matches, closest pairs first (by the gate's
//! distance, then creation order), each A and B object taking part in at most one; then
//! identifications; then the establish conditions of the A objects still unlinked. Conditions
//! started by a decision (maintain after a link, establish and reestablish after an unlink) see
//! their first state at the next step.

use std::sync::Arc;

use kpl_core::{Record, RecordType, Time, Value};
use kpl_mtl::{Formula, ProgressorGroup};

use crate::change::{Cause, Change, ChangeKind};
pub use crate::conditions::Condition;
use crate::conditions::{LinkConditions, LinkState};
use crate::engine::{Anchoring, Identification, StepCtx};
use crate::handover::HandedCondition;
use crate::records::{position, value_position, velocity};
use crate::stateful::{UnitCall, UnitMemory};
use crate::status;
use crate::store::{LinkId, ObjectKey, Origin, StateOrigin, TypeId};
use crate::units::LinkUnit;
use kpl_mtl::gate::GateGrid;

/// The groups that hold the link's conditions, one per formula: every object's establish
/// condition is an instance of one group, every pair's reestablish condition of another, every
/// link's maintain condition of a third, so instances in the same situation share their work.
#[derive(Debug)]
struct Groups {
    /// establish, reestablish, maintain
    by_kind: [ProgressorGroup; 3],
}

const ESTABLISH: usize = 0;
const REESTABLISH: usize = 1;
const MAINTAIN: usize = 2;

impl Groups {
    fn new(conditions: &LinkConditions) -> Groups {
        Groups {
            by_kind: [
                ProgressorGroup::new(conditions.establish.clone()),
                ProgressorGroup::new(conditions.reestablish.clone()),
                ProgressorGroup::new(conditions.maintain.clone()),
            ],
        }
    }

    fn take(&mut self, kind: usize) -> Condition {
        Condition::start(&mut self.by_kind[kind])
    }

    fn give(&mut self, kind: usize, condition: Condition) {
        condition.release(&mut self.by_kind[kind]);
    }

    fn unlinked(&mut self) -> InstanceState {
        InstanceState::Unlinked(Unlinked {
            establish: self.take(ESTABLISH),
            candidates: Vec::new(),
            identifications: Vec::new(),
        })
    }

    fn linked(&mut self, to: ObjectKey) -> InstanceState {
        InstanceState::Linked { to, maintain: self.take(MAINTAIN) }
    }

    /// `None` only for a pending condition its group does not hold (not made by the engine).
    fn hand_over(&self, kind: usize, condition: &Condition) -> Option<HandedCondition> {
        Some(match condition {
            Condition::Pending(id) => HandedCondition::Pending(self.by_kind[kind].hand_over(*id)?),
            Condition::Decided(v) => HandedCondition::Decided(*v),
        })
    }

    fn take_over(
        &mut self,
        kind: usize,
        condition: &HandedCondition,
    ) -> Result<Condition, kpl_mtl::HandoverError> {
        Ok(match condition {
            HandedCondition::Pending(handover) => Condition::Pending(self.by_kind[kind].take_over(handover)?),
            HandedCondition::Decided(v) => Condition::Decided(*v),
        })
    }
}

/// A candidate `to` object of an unlinked instance.
#[derive(Debug)]
pub struct Candidate {
    pub to: ObjectKey,
    pub condition: Condition,
}

/// An identification this link may complete, with its formula (`reestablish and description`)
/// and the group of its conditions (one per unlinked object).
#[derive(Debug)]
pub struct LinkIdentification {
    pub ident: usize,
    pub formula: Arc<Formula>,
    group: ProgressorGroup,
}

impl LinkIdentification {
    pub fn new(ident: usize, formula: Arc<Formula>) -> LinkIdentification {
        LinkIdentification { ident, group: ProgressorGroup::new(formula.clone()), formula }
    }
}

#[derive(Debug)]
pub struct Unlinked {
    pub establish: Condition,
    pub candidates: Vec<Candidate>,
    /// (identification index, condition)
    pub identifications: Vec<(usize, Condition)>,
}

#[derive(Debug)]
pub enum InstanceState {
    Unlinked(Unlinked),
    Linked { to: ObjectKey, maintain: Condition },
}

/// The per-object process of a link process, for one A object.
#[derive(Debug)]
pub struct Instance {
    pub from: ObjectKey,
    pub state: InstanceState,
}

/// Counts for benchmarks and reports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Condition progressions (establish, reestablish, maintain, identification), all steps.
    pub condition_steps: u64,
    /// Of these, reestablish progressions of candidate pairs.
    pub candidate_steps: u64,
    /// Link unit computations.
    pub unit_computations: u64,
    /// Per-object instances created (one per A object, when it is first seen) and removed (with
    /// their object).
    pub instances_created: u64,
    pub instances_removed: u64,
}

#[derive(Debug)]
pub struct LinkProcess {
    pub name: Arc<str>,
    pub from_ty: TypeId,
    pub to_ty: TypeId,
    pub unit_name: String,
    pub unit: Arc<dyn LinkUnit>,
    pub conditions: LinkConditions,
    pub identifications: Vec<LinkIdentification>,
    pub(crate) instances: Vec<Option<Instance>>,
    groups: Groups,
    grid: GateGrid<ObjectKey>,
    pub stats: LinkStats,
    /// The valid time of the link's last step.
    pub last_time: Option<Time>,
    /// The names its `from` objects' sources go by (its input streams and their producers), so
    /// that [`crate::Anchoring::step`] gives it the percepts of its own sources.
    pub from_sources: Vec<String>,
    /// The `from` objects of the current step (reused buffer).
    stepped: Vec<ObjectKey>,
}

/// What a link unit computes from at one step: the time, the linked-from object's state, and
/// the unit's extra inputs.
struct StateIn<'a> {
    time: Time,
    from: &'a Record,
    inputs: &'a [Option<Value>],
}

/// A reestablish condition that became true.
#[derive(Debug, Clone, Copy)]
struct Match {
    distance: f64,
    from_seq: u64,
    to_seq: u64,
    from: ObjectKey,
    to: ObjectKey,
    hypothesis: u32,
    hypotheses: usize,
}

#[derive(Debug, Default)]
struct Decisions {
    unlink: Vec<(ObjectKey, ObjectKey)>,
    reestablish: Vec<Match>,
    identify: Vec<(usize, u64, ObjectKey)>,
    establish: Vec<ObjectKey>,
}

/// How far apart two object states are for pairing them: the distance of their positions plus
/// the difference of their velocities times this (metres per m/s), when both have a `vel`.
pub const VELOCITY_WEIGHT_S: f64 = 1.0;

/// The distance used to pair `p` with a candidate state (`INFINITY` without positions).
pub(crate) fn state_distance(p: &Value, o: &Value) -> f64 {
    let (Some(a), Some(b)) = (p.as_record(), o.as_record()) else { return f64::INFINITY };
    let (Some(pa), Some(pb)) = (position(a), position(b)) else { return f64::INFINITY };
    let mut d = (pa[0] - pb[0]).hypot(pa[1] - pb[1]);
    if let (Some(va), Some(vb)) = (velocity(a), velocity(b)) {
        d += VELOCITY_WEIGHT_S * (va[0] - vb[0]).hypot(va[1] - vb[1]);
    }
    d
}

/// The hypothesis of `value`/`hypotheses` closest to the object `p` (position, and velocity when
/// both have one: at a crossing the branches start at one place but head different ways):
/// (index, value, distance).
fn closest<'v>(value: &'v Value, hypotheses: &'v [Value], p: &Value) -> (u32, &'v Value, f64) {
    if hypotheses.len() <= 1 {
        return (0, value, state_distance(p, value));
    }
    let mut best = (0u32, &hypotheses[0], state_distance(p, &hypotheses[0]));
    for (i, h) in hypotheses.iter().enumerate().skip(1) {
        let d = state_distance(p, h);
        if d < best.2 {
            best = (i as u32, h, d);
        }
    }
    best
}

impl LinkProcess {
    pub fn new(
        name: Arc<str>,
        from_ty: TypeId,
        to_ty: TypeId,
        unit_name: String,
        unit: Arc<dyn LinkUnit>,
        conditions: LinkConditions,
    ) -> LinkProcess {
        let grid = GateGrid::new(conditions.gate.unwrap_or(1.0));
        let groups = Groups::new(&conditions);
        LinkProcess {
            name,
            from_ty,
            to_ty,
            unit_name,
            unit,
            conditions,
            identifications: Vec::new(),
            instances: Vec::new(),
            groups,
            grid,
            stats: LinkStats::default(),
            last_time: None,
            from_sources: Vec::new(),
            stepped: Vec::new(),
        }
    }

    pub fn instance(&self, from: ObjectKey) -> Option<&Instance> {
        self.instances.get(from.index())?.as_ref().filter(|i| i.from == from)
    }

    /// Drops the instance of a removed A object.
    pub(crate) fn drop_instance(&mut self, from: ObjectKey) {
        if let Some(slot) = self.instances.get_mut(from.index())
            && slot.as_ref().is_some_and(|i| i.from == from)
            && let Some(instance) = slot.take()
        {
            self.stats.instances_removed += 1;
            self.give_state(instance.state);
        }
    }

    /// The instance of `from` as a handover carries it: the object it is linked to and its
    /// maintain condition, or its establish condition while unlinked (its candidates and
    /// identifications stay behind: they are about objects of this engine). `None` without one.
    pub(crate) fn hand_over_instance(&self, from: ObjectKey) -> Option<(Option<ObjectKey>, HandedCondition)> {
        let instance = self.instances.get(from.index())?.as_ref().filter(|i| i.from == from)?;
        match &instance.state {
            InstanceState::Linked { to, maintain } => {
                Some((Some(*to), self.groups.hand_over(MAINTAIN, maintain)?))
            }
            InstanceState::Unlinked(u) => Some((None, self.groups.hand_over(ESTABLISH, &u.establish)?)),
        }
    }

    /// Makes the instance of `from` (an object just taken over) go on from a handed-over one.
    pub(crate) fn take_over_instance(
        &mut self,
        from: ObjectKey,
        to: Option<ObjectKey>,
        condition: &HandedCondition,
    ) -> Result<(), kpl_mtl::HandoverError> {
        let state = match to {
            Some(to) => InstanceState::Linked { to, maintain: self.groups.take_over(MAINTAIN, condition)? },
            None => InstanceState::Unlinked(Unlinked {
                establish: self.groups.take_over(ESTABLISH, condition)?,
                candidates: Vec::new(),
                identifications: Vec::new(),
            }),
        };
        self.stats.instances_created += 1;
        self.set_state(from, state);
        Ok(())
    }

    /// Puts the instance of `from` back to unlinked (its linked-to object was removed).
    pub(crate) fn reset_instance(&mut self, from: ObjectKey) {
        if let Some(Some(instance)) = self.instances.get_mut(from.index())
            && instance.from == from
        {
            let fresh = self.groups.unlinked();
            let old = std::mem::replace(&mut instance.state, fresh);
            self.give_state(old);
        }
    }

    fn set_state(&mut self, from: ObjectKey, state: InstanceState) {
        let i = from.index();
        if self.instances.len() <= i {
            self.instances.resize_with(i + 1, || None);
        }
        if let Some(old) = self.instances[i].replace(Instance { from, state }) {
            self.give_state(old.state);
        }
    }

    /// Frees the conditions of an instance's state that is left.
    fn give_state(&mut self, state: InstanceState) {
        match state {
            InstanceState::Unlinked(u) => {
                self.groups.give(ESTABLISH, u.establish);
                for candidate in u.candidates {
                    self.groups.give(REESTABLISH, candidate.condition);
                }
                for (ident, condition) in u.identifications {
                    if let Some(li) = self.identifications.iter_mut().find(|li| li.ident == ident) {
                        condition.release(&mut li.group);
                    }
                }
            }
            InstanceState::Linked { maintain, .. } => self.groups.give(MAINTAIN, maintain),
        }
    }

    fn set_unlinked(&mut self, from: ObjectKey) {
        let state = self.groups.unlinked();
        self.set_state(from, state);
    }

    fn set_linked(&mut self, from: ObjectKey, to: ObjectKey) {
        let state = self.groups.linked(to);
        self.set_state(from, state);
    }

    /// Builds the gate grid over the objects of type B not linked by this link.
    fn build_grid(&mut self, id: LinkId, cx: &StepCtx<'_>) {
        self.grid.clear();
        let gated = self.conditions.gate.is_some();
        for key in cx.store.objects_of(self.to_ty) {
            let Some(o) = cx.store.get(key) else { continue };
            // Partial objects have no state; branch objects are reacquired through their root.
            if o.is_partial() || o.branch_of.is_some() || o.incoming_via(id).is_some() {
                continue;
            }
            if !gated {
                self.grid.insert_unplaced(key);
            } else if o.hypotheses.len() > 1 {
                for (h, v) in o.hypotheses.iter().enumerate() {
                    match value_position(v) {
                        Some(p) => self.grid.insert(key, h as u32, p),
                        None => self.grid.insert_unplaced(key),
                    }
                }
            } else {
                match value_position(&o.value) {
                    Some(p) => self.grid.insert(key, 0, p),
                    None => self.grid.insert_unplaced(key),
                }
            }
        }
        self.grid.finish();
    }

    /// One step of the link process at `cx.time` on the objects of its state (`from`: each A
    /// object's key and its state now): the link unit for every linked pair, every instance's
    /// conditions, then the decisions. Linked-to objects whose `from` object is not in the state
    /// keep their state, no longer measured.
    pub(crate) fn run(
        &mut self,
        id: LinkId,
        cx: &mut StepCtx<'_>,
        from: &[(ObjectKey, Value)],
        extra: &[Option<Value>],
    ) {
        let to_type = cx.types[self.to_ty as usize].record.clone();
        let mut decisions = Decisions::default();
        let mut grid_ready = false;
        let mut near: Vec<ObjectKey> = Vec::new();
        // Maintain conditions are progressed after the loop, all together: stepping them between
        // link-unit computations made each step miss the caches the other left.
        let mut maintains: Vec<(usize, ObjectKey, ObjectKey, Value, Value)> = Vec::new();
        self.stepped.clear();
        for (p, p_value) in from {
            let p = *p;
            let Some(p_obj) = cx.store.get(p) else { continue };
            // A partial object has no state yet.
            if p_obj.is_partial() {
                continue;
            }
            let p_value = p_value.clone();
            let origin = origin_of(&p_value, p_obj.predicted);
            let p_seq = p_obj.seq;
            let Some(p_record) = p_value.as_record().cloned() else { continue };
            let p_pos = value_position(&p_value);

            // The instance of p, created when p is first seen.
            let i = p.index();
            if self.instances.len() <= i {
                self.instances.resize_with(i + 1, || None);
            }
            if self.instances[i].as_ref().is_none_or(|inst| inst.from != p) {
                self.stats.instances_created += 1;
                self.set_unlinked(p);
            }
            self.stepped.push(p);
            let linked_to = match &self.instances[i] {
                Some(Instance { state: InstanceState::Linked { to, .. }, .. }) => Some(*to),
                _ => None,
            };

            if let Some(to) = linked_to {
                // Linked: the unit computes B's state, then maintain.
                if cx.store.get(to).is_none() {
                    self.set_unlinked(p);
                    continue;
                }
                let on_path = Anchoring::on_prediction_path(cx.store, to);
                let Some(o) = cx.store.get_mut(to) else { continue };
                let fresher = match o.computed {
                    Some((time, measured)) if time == cx.time => origin.measured >= measured,
                    _ => true,
                };
                if !on_path && fresher {
                    let previous = o.record().cloned();
                    let symbol = o.symbol.clone();
                    let mut scratch = UnitMemory::default();
                    let memory = match self.unit.memory_key().cloned() {
                        Some(key) => o.memory_mut(&key),
                        None => &mut scratch,
                    };
                    let state = StateIn { time: cx.time, from: &p_record, inputs: extra };
                    let result = self.compute(&state, previous.as_deref(), &to_type, &symbol, memory);
                    // Let go of the last state, so that the new one is written into its place.
                    drop(previous);
                    match result {
                        Ok(record) => {
                            o.set_state(record, cx.time, origin);
                            o.hypotheses.clear();
                            o.computed = Some((cx.time, origin.measured));
                        }
                        Err(message) => cx
                            .out
                            .warn(cx.time, format!("link `{}` ({}): {message}", self.name, self.unit_name)),
                    }
                }
                let o_value = o.value.clone();
                if matches!(
                    &self.instances[i],
                    Some(Instance {
                        state: InstanceState::Linked { maintain: Condition::Pending(_), .. },
                        ..
                    })
                ) {
                    maintains.push((i, p, to, p_value, o_value));
                }
                continue;
            }

            // Unlinked: establish, the candidates, the identifications.
            if !grid_ready {
                self.build_grid(id, cx);
                grid_ready = true;
            }
            self.grid.near(p_pos, &mut near);
            let Some(Instance { state: InstanceState::Unlinked(u), .. }) = &mut self.instances[i] else {
                continue;
            };
            if let Condition::Pending(_) = u.establish {
                self.stats.condition_steps += 1;
                let state = LinkState { from: &p_value, to: None, this: None, env: cx.env };
                match u.establish.step(&mut self.groups.by_kind[ESTABLISH], cx.time, &state) {
                    Ok(Some(verdict)) => {
                        if verdict {
                            decisions.establish.push(p);
                        }
                    }
                    Ok(None) => {}
                    Err(e) => cx.out.warn(
                        cx.time,
                        format!(
                            "link `{}`: establish({}): {e}; the state was skipped",
                            self.name,
                            p_value_symbol(&p_value)
                        ),
                    ),
                }
            }
            let store = &*cx.store;
            let mut k = 0;
            while k < u.candidates.len() {
                let c = &u.candidates[k];
                let keep = store.get(c.to).is_some_and(|o| o.incoming_via(id).is_none())
                    && (matches!(c.condition, Condition::Pending(_)) || near.contains(&c.to));
                if keep {
                    k += 1;
                } else {
                    let dropped = u.candidates.swap_remove(k);
                    self.groups.give(REESTABLISH, dropped.condition);
                }
            }
            u.candidates.sort_by_key(|c| c.to);
            for &o in &near {
                if !u.candidates.iter().any(|c| c.to == o) {
                    u.candidates.push(Candidate { to: o, condition: self.groups.take(REESTABLISH) });
                }
            }
            let reestablish = &mut self.groups.by_kind[REESTABLISH];
            for candidate in &mut u.candidates {
                let Condition::Pending(_) = candidate.condition else { continue };
                let Some(o) = store.get(candidate.to) else { continue };
                let (hypothesis, to_value, distance) = closest(&o.value, &o.hypotheses, &p_value);
                self.stats.condition_steps += 1;
                self.stats.candidate_steps += 1;
                let state = LinkState { from: &p_value, to: Some(to_value), this: None, env: cx.env };
                match candidate.condition.step(reestablish, cx.time, &state) {
                    Ok(Some(verdict)) => {
                        if verdict {
                            decisions.reestablish.push(Match {
                                distance,
                                from_seq: p_seq,
                                to_seq: o.seq,
                                from: p,
                                to: candidate.to,
                                hypothesis,
                                hypotheses: o.hypotheses.len().max(1),
                            });
                        }
                    }
                    Ok(None) => {}
                    Err(e) => {
                        let message = format!(
                            "link `{}`: reestablish({}, {}): {e}; the state was skipped",
                            self.name,
                            p_value_symbol(&p_value),
                            o.symbol
                        );
                        cx.out.warn(cx.time, message);
                    }
                }
            }
            // Identifications this link may complete: `to` and `this` are what the unit makes of p.
            let idents: &[Identification] = &*cx.identifications;
            u.identifications.retain(|(ident, condition)| {
                let done = idents[*ident].done;
                if done && let Some(li) = self.identifications.iter_mut().find(|li| li.ident == *ident) {
                    condition.release(&mut li.group);
                }
                !done
            });
            for link_ident in &mut self.identifications {
                let ident = &idents[link_ident.ident];
                if ident.done {
                    continue;
                }
                let position = match u.identifications.iter().position(|(k, _)| *k == link_ident.ident) {
                    Some(k) => k,
                    None => {
                        let condition = Condition::start(&mut link_ident.group);
                        u.identifications.push((link_ident.ident, condition));
                        u.identifications.len() - 1
                    }
                };
                let Condition::Pending(_) = u.identifications[position].1 else { continue };
                self.stats.unit_computations += 1;
                let mut scratch = UnitMemory::default();
                let mut call = UnitCall {
                    time: cx.time,
                    from: &p_record,
                    previous: None,
                    to: &to_type,
                    symbol: &ident.symbol,
                    inputs: extra,
                    memory: &mut scratch,
                };
                let made = match self.unit.compute_with(&mut call) {
                    Ok(record) => Value::Record(Arc::new(record)),
                    Err(message) => {
                        cx.out.warn(cx.time, format!("link `{}` ({}): {message}", self.name, self.unit_name));
                        continue;
                    }
                };
                self.stats.condition_steps += 1;
                let state = LinkState { from: &p_value, to: Some(&made), this: Some(&made), env: cx.env };
                match u.identifications[position].1.step(&mut link_ident.group, cx.time, &state) {
                    Ok(Some(verdict)) => {
                        if verdict {
                            decisions.identify.push((link_ident.ident, p_seq, p));
                        }
                    }
                    Ok(None) => {}
                    Err(e) => cx.out.warn(
                        cx.time,
                        format!(
                            "link `{}`: identification `{}` for {}: {e}; the state was skipped",
                            self.name,
                            ident.name,
                            p_value_symbol(&p_value)
                        ),
                    ),
                }
            }
        }
        for (i, p, to, p_value, o_value) in maintains {
            let Some(Instance { state: InstanceState::Linked { maintain, .. }, .. }) = &mut self.instances[i]
            else {
                continue;
            };
            let Condition::Pending(_) = maintain else { continue };
            self.stats.condition_steps += 1;
            let state = LinkState { from: &p_value, to: Some(&o_value), this: None, env: cx.env };
            match maintain.step(&mut self.groups.by_kind[MAINTAIN], cx.time, &state) {
                Ok(Some(verdict)) => {
                    if !verdict {
                        decisions.unlink.push((p, to));
                    }
                }
                Ok(None) => {}
                Err(e) => cx.out.warn(
                    cx.time,
                    format!(
                        "link `{}`: maintain({}, {}): {e}; the state was skipped",
                        self.name,
                        p_value_symbol(&p_value),
                        p_value_symbol(&o_value)
                    ),
                ),
            }
        }
        self.keep_unstepped(cx);
        self.apply(id, cx, decisions, &to_type, from, extra);
    }

    /// The objects this link is linked to from an object that is not in this state (its source
    /// did not report) keep their state, no longer measured, unless something else set it now.
    fn keep_unstepped(&mut self, cx: &mut StepCtx<'_>) {
        self.stepped.sort_unstable();
        for instance in self.instances.iter().flatten() {
            let InstanceState::Linked { to, .. } = instance.state else { continue };
            if self.stepped.binary_search(&instance.from).is_ok() {
                continue;
            }
            if let Some(o) = cx.store.get_mut(to)
                && o.state_time < cx.time
            {
                o.keep_state_unmeasured(cx.time);
            }
        }
    }

    /// The linked-to object's state computed by the link unit.
    fn compute(
        &mut self,
        state: &StateIn<'_>,
        previous: Option<&Record>,
        to: &RecordType,
        symbol: &Arc<str>,
        memory: &mut UnitMemory,
    ) -> Result<Record, String> {
        self.stats.unit_computations += 1;
        let mut call = UnitCall {
            time: state.time,
            from: state.from,
            previous,
            to,
            symbol,
            inputs: state.inputs,
            memory,
        };
        self.unit.compute_with(&mut call)
    }

    fn is_unlinked(&self, p: ObjectKey) -> bool {
        matches!(self.instance(p), Some(Instance { state: InstanceState::Unlinked(_), .. }))
    }

    fn apply(
        &mut self,
        id: LinkId,
        cx: &mut StepCtx<'_>,
        mut decisions: Decisions,
        to_type: &Arc<RecordType>,
        from: &[(ObjectKey, Value)],
        extra: &[Option<Value>],
    ) {
        // The state of a linked-from object in this step's state.
        let state_of = |p: ObjectKey| from.iter().find(|(k, _)| *k == p).map(|(_, v)| v);
        let b_name = cx.types[self.to_ty as usize].name.clone();
        // Maintain conditions that became false.
        for (p, o) in decisions.unlink {
            if cx.store.unlink(id, p, o) {
                self.set_unlinked(p);
                if let (Some(po), Some(oo)) = (cx.store.get(p), cx.store.get(o)) {
                    let change = Change::new(
                        cx.time,
                        ChangeKind::Unlinked,
                        oo.symbol.clone(),
                        b_name.clone(),
                        Cause::Maintain,
                    )
                    .link(&self.name)
                    .from(&po.symbol);
                    cx.out.changes.push(change);
                }
            }
        }
        // Reestablish: closest pairs first.
        decisions.reestablish.sort_by(|a, b| {
            a.distance.total_cmp(&b.distance).then(a.from_seq.cmp(&b.from_seq)).then(a.to_seq.cmp(&b.to_seq))
        });
        for m in decisions.reestablish {
            let free = cx.store.get(m.to).is_some_and(|o| o.incoming_via(id).is_none() && !o.is_partial());
            if !free || !self.is_unlinked(m.from) {
                continue;
            }
            self.link_existing(id, cx, (m.from, state_of(m.from)), m.to, to_type, extra);
            let (Some(po), Some(oo)) = (cx.store.get(m.from), cx.store.get(m.to)) else { continue };
            let mut change = Change::new(
                cx.time,
                ChangeKind::Linked,
                oo.symbol.clone(),
                b_name.clone(),
                Cause::Reestablish,
            )
            .link(&self.name)
            .from(&po.symbol);
            if m.hypotheses > 1 {
                change = change.hypotheses(m.hypotheses).hypothesis(m.hypothesis);
            }
            cx.out.changes.push(change);
        }
        // Identifications completed through this link.
        decisions.identify.sort_by_key(|(ident, seq, _)| (*ident, *seq));
        for (ident, _, p) in decisions.identify {
            if cx.identifications[ident].done || !self.is_unlinked(p) {
                continue;
            }
            let partial = cx.identifications[ident].partial;
            let Some(obj) = cx.store.get_mut(partial) else { continue };
            obj.origin = Origin::Derived;
            self.link_existing(id, cx, (p, state_of(p)), partial, to_type, extra);
            let ident_name = cx.identifications[ident].name.clone();
            cx.identifications[ident].done = true;
            cx.identifications[ident].object = Some(partial);
            let (Some(po), Some(oo)) = (cx.store.get(p), cx.store.get(partial)) else { continue };
            let linked =
                Change::new(cx.time, ChangeKind::Linked, oo.symbol.clone(), b_name.clone(), Cause::Identify)
                    .link(&self.name)
                    .from(&po.symbol)
                    .name(&ident_name);
            let identified = Change::new(
                cx.time,
                ChangeKind::Identified,
                oo.symbol.clone(),
                b_name.clone(),
                Cause::Identify,
            )
            .link(&self.name)
            .from(&po.symbol)
            .name(&ident_name);
            cx.out.changes.push(linked);
            cx.out.changes.push(identified);
        }
        // Establish: a new B object for each A object still unlinked.
        for p in decisions.establish {
            if !self.is_unlinked(p) {
                continue;
            }
            let Some(po) = cx.store.get(p) else { continue };
            let p_symbol = po.symbol.clone();
            let Some(p_value) = state_of(p) else { continue };
            let Some(p_record) = p_value.as_record() else { continue };
            let origin = origin_of(p_value, po.predicted);
            let symbol = cx.store.new_symbol(self.to_ty);
            let mut memory = UnitMemory::default();
            let state = StateIn { time: cx.time, from: p_record, inputs: extra };
            let record = match self.compute(&state, None, to_type, &symbol, &mut memory) {
                Ok(record) => record,
                Err(message) => {
                    cx.out.warn(
                        cx.time,
                        format!(
                            "link `{}` ({}): cannot create an object from {p_symbol}: {message}",
                            self.name, self.unit_name
                        ),
                    );
                    // Try again from the next state on.
                    self.set_unlinked(p);
                    continue;
                }
            };
            let key =
                cx.store.insert(self.to_ty, symbol.clone(), Origin::Derived, Record::default(), cx.time);
            if let Some(o) = cx.store.get_mut(key) {
                o.set_state(record, cx.time, origin);
                o.computed = Some((cx.time, origin.measured));
                if let Some(key) = self.unit.memory_key() {
                    *o.memory_mut(key) = memory;
                }
            }
            cx.store.link(id, p, key);
            self.set_linked(p, key);
            cx.out.changes.push(
                Change::new(cx.time, ChangeKind::Created, symbol.clone(), b_name.clone(), Cause::Establish)
                    .link(&self.name)
                    .from(&p_symbol),
            );
            cx.out.changes.push(
                Change::new(cx.time, ChangeKind::Linked, symbol, b_name.clone(), Cause::Establish)
                    .link(&self.name)
                    .from(&p_symbol),
            );
        }
    }

    /// Links `p` (with its state now) to the existing object `o`: o's state is computed from p,
    /// its prediction ends.
    fn link_existing(
        &mut self,
        id: LinkId,
        cx: &mut StepCtx<'_>,
        (p, p_value): (ObjectKey, Option<&Value>),
        o: ObjectKey,
        to_type: &Arc<RecordType>,
        extra: &[Option<Value>],
    ) {
        cx.store.link(id, p, o);
        self.set_linked(p, o);
        let Some(po) = cx.store.get(p) else { return };
        let p_predicted = po.predicted;
        let Some(p_value) = p_value else { return };
        let origin = origin_of(p_value, p_predicted);
        let Some(oo) = cx.store.get_mut(o) else { return };
        let previous = if oo.value.as_record().is_some_and(|r| !r.fields.is_empty()) {
            oo.record().cloned()
        } else {
            None
        };
        if let Some(p_record) = p_value.as_record() {
            let symbol = oo.symbol.clone();
            let mut scratch = UnitMemory::default();
            let memory = match self.unit.memory_key().cloned() {
                Some(key) => oo.memory_mut(&key),
                None => &mut scratch,
            };
            let state = StateIn { time: cx.time, from: p_record, inputs: extra };
            match self.compute(&state, previous.as_deref(), to_type, &symbol, memory) {
                Ok(record) => oo.set_state(record, cx.time, origin),
                Err(message) => {
                    cx.out.warn(cx.time, format!("link `{}` ({}): {message}", self.name, self.unit_name))
                }
            }
        }
        oo.computed = Some((cx.time, origin.measured));
        oo.hypotheses.clear();
        oo.prediction_root = None;
        if let Some(run) = oo.prediction.take() {
            for k in run.path {
                if let Some(x) = cx.store.get_mut(k) {
                    x.prediction_root = None;
                    x.hypotheses.clear();
                }
            }
            cx.pruned.extend(run.branches);
        }
    }
}

/// How a state computed from the linked-from object's `value` is known.
fn origin_of(value: &Value, predicted: bool) -> StateOrigin {
    let measured = status::is_measured(value);
    StateOrigin { measured, predicted: predicted && !measured }
}

fn p_value_symbol(value: &Value) -> String {
    value.as_record().and_then(|r| r.id.as_deref()).unwrap_or("?").to_string()
}
