//! The object store: every object of a spec (percepts, world objects, on-road objects, ...) with
//! its type, symbol and state, and the links between them, which make the object linkage
//! structures. All link processes of a spec share one store, so several links may lead into one
//! type and chains of links build the hierarchy.
//!
//! Keys carry a generation, so a key kept by a link instance never reaches an object that
//! replaced a removed one in the same slot. Symbols are made of the type's prefix and a counter
//! (`wo1`, `wo2`, ...) and never reused within a type; percepts keep the ids their source gave.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use kpl_core::{Record, Time, Value};

use crate::predict::PredictionStart;
use crate::stateful::UnitMemory;
use crate::status::{ObjectStatus, set_status, with_status, with_status_of, write_status_of};

/// Index of a link specification in the engine.
pub type LinkId = u32;
/// Index of an object type in the engine.
pub type TypeId = u32;

/// An object's place in the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ObjectKey {
    index: u32,
    generation: u32,
}

impl ObjectKey {
    pub fn index(self) -> usize {
        self.index as usize
    }
}

/// Where an object comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// Reported by a source (a percept); present while its source's snapshots list it.
    Percept { source: u32 },
    /// Created by a link process (or completed from an identification).
    Derived,
    /// Asked for by an identification and not yet linked: no state.
    Partial,
}

/// A prediction in progress for the root of a structure that is not linked to anything.
#[derive(Debug, Clone)]
pub struct PredictionRun {
    /// The object whose type's model predicts the structure (the root or a more specific object
    /// linked from it).
    pub owner: ObjectKey,
    /// From the root to the owner.
    pub path: Vec<ObjectKey>,
    pub start: PredictionStart,
    pub n_hypotheses: usize,
    /// The model said the prediction ended ([`crate::predict::PredictionModel::ended`]).
    pub ended: bool,
    /// The branch objects following the hypotheses the owner does not (`crate::branches`).
    pub branches: Vec<ObjectKey>,
}

#[derive(Debug, Clone)]
pub struct Object {
    pub key: ObjectKey,
    pub symbol: Arc<str>,
    pub ty: TypeId,
    /// Creation order, for deterministic iteration and output.
    pub seq: u64,
    pub origin: Origin,
    pub created: Time,
    /// The state: a `Value::Record` whose `id` is the symbol (no fields for a partial object).
    pub value: Value,
    /// With more than one prediction hypothesis: all of them, most likely first (`value` is the
    /// first). Empty otherwise.
    pub hypotheses: Vec<Value>,
    /// The valid time of the state.
    pub state_time: Time,
    /// The state derives, through links, from a percept sample of its valid time.
    pub measured: bool,
    /// The state comes from a prediction model (directly or through links).
    pub predicted: bool,
    /// When the state was last measured, since when it has not been: the valid time of the
    /// first state after that (predicted, or held at its last value). `None` while measured.
    pub predicted_since: Option<Time>,
    /// The root of the predicted structure this object is on (its state then comes from the
    /// root's prediction, not from its link unit); stale once the root's prediction ended.
    pub(crate) prediction_root: Option<ObjectKey>,
    /// A branch object: the object whose prediction it branches from (`crate::branches`).
    pub branch_of: Option<ObjectKey>,
    /// Links into this object: (link, from object).
    pub incoming: Vec<(LinkId, ObjectKey)>,
    /// Links out of this object: (link, to object).
    pub outgoing: Vec<(LinkId, ObjectKey)>,
    /// Grounded in at least one percept through its incoming links.
    pub anchored: bool,
    /// When it was last anchored (its creation time if never).
    pub last_anchored: Time,
    /// Its structure's prediction ended and the model forgets such structures at once
    /// ([`crate::predict::PredictionModel::forget_when_ended`]): removed at the next forget sweep.
    pub forget_now: bool,
    /// Names given by identifications.
    pub names: Vec<Arc<str>>,
    pub(crate) prediction: Option<Box<PredictionRun>>,
    /// Step at which a source last listed this percept.
    pub(crate) seen_step: u64,
    /// A percept listed by the last snapshot of its source (always true for other objects). An
    /// absent percept keeps its identity and links until its type's forget time has passed.
    pub present: bool,
    /// When a source last listed this percept (its creation time for other objects).
    pub last_seen: Time,
    /// Time of the last link-unit computation and whether it was measured (several links into
    /// one object at one time: a measured state is not replaced by one that is not).
    pub(crate) computed: Option<(Time, bool)>,
    /// What stateful link units keep about this object (a Kalman filter's estimate), by the key
    /// the unit names, so that every link into the object with such a unit shares it.
    pub(crate) memory: Vec<(Arc<str>, UnitMemory)>,
}

/// How a new state of an object is known.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StateOrigin {
    pub measured: bool,
    pub predicted: bool,
}

impl StateOrigin {
    pub const MEASURED: StateOrigin = StateOrigin { measured: true, predicted: false };
    pub const PREDICTED: StateOrigin = StateOrigin { measured: false, predicted: true };
    /// Computed from an object that was neither measured nor predicted (its state was held).
    pub const HELD: StateOrigin = StateOrigin { measured: false, predicted: false };
}

impl Object {
    pub fn record(&self) -> Option<&Arc<Record>> {
        match &self.value {
            Value::Record(r) => Some(r),
            _ => None,
        }
    }

    /// Sets the state at `time`, with its status attributes (`measured`, `predicted_since`).
    pub fn set_state(&mut self, record: Record, time: Time, origin: StateOrigin) {
        self.state_time = time;
        self.note_origin(time, origin);
        let record = with_status(record, self.status());
        // Into the last state's allocation when nothing else holds it.
        if let Value::Record(state) = &mut self.value
            && let Some(state) = Arc::get_mut(state)
        {
            *state = record;
            return;
        }
        self.value = Value::Record(Arc::new(record));
    }

    /// Sets the state from a value that is a record (anything else is kept as it is: an
    /// ingested object is checked before).
    pub fn set_state_value(&mut self, value: &Value, time: Time, origin: StateOrigin) {
        match value {
            Value::Record(record) => {
                self.state_time = time;
                self.note_origin(time, origin);
                let status = self.status();
                // In place when the last state is not held elsewhere (no allocation per step).
                if let Value::Record(state) = &mut self.value
                    && write_status_of(state, record, status)
                {
                    return;
                }
                self.value = Value::Record(Arc::new(with_status_of(record, status)));
            }
            other => {
                self.state_time = time;
                self.note_origin(time, origin);
                self.value = other.clone();
            }
        }
    }

    /// The state was not renewed at `time` (its source did not report, its model gave nothing):
    /// it is kept, and is no longer measured.
    pub fn keep_state_unmeasured(&mut self, time: Time) {
        if !self.measured && self.predicted_since.is_some() {
            return;
        }
        self.note_origin(time, StateOrigin { measured: false, predicted: self.predicted });
        let status = self.status();
        if let Value::Record(record) = &mut self.value {
            match Arc::get_mut(record) {
                Some(record) => set_status(record, status),
                None => *record = Arc::new(with_status_of(record, status)),
            }
        }
    }

    fn note_origin(&mut self, time: Time, origin: StateOrigin) {
        self.measured = origin.measured;
        self.predicted = origin.predicted;
        if origin.measured {
            self.predicted_since = None;
        } else if self.predicted_since.is_none() {
            self.predicted_since = Some(time);
        }
    }

    /// The status attributes of the current state.
    pub fn status(&self) -> ObjectStatus {
        ObjectStatus { measured: self.measured, predicted_since: self.predicted_since }
    }

    /// The memory a stateful link unit keeps under `key`.
    pub(crate) fn memory_mut(&mut self, key: &Arc<str>) -> &mut UnitMemory {
        let i = match self.memory.iter().position(|(k, _)| k == key) {
            Some(i) => i,
            None => {
                self.memory.push((key.clone(), UnitMemory::default()));
                self.memory.len() - 1
            }
        };
        &mut self.memory[i].1
    }

    pub fn incoming_via(&self, link: LinkId) -> Option<ObjectKey> {
        self.incoming.iter().find(|(l, _)| *l == link).map(|(_, k)| *k)
    }

    pub fn outgoing_via(&self, link: LinkId) -> Option<ObjectKey> {
        self.outgoing.iter().find(|(l, _)| *l == link).map(|(_, k)| *k)
    }

    pub fn is_partial(&self) -> bool {
        self.origin == Origin::Partial
    }
}

#[derive(Debug, Clone, Default)]
struct Slot {
    generation: u32,
    object: Option<Object>,
}

/// All objects, by key, by type (in creation order) and by symbol.
#[derive(Debug, Clone)]
pub struct Store {
    slots: Vec<Slot>,
    free: Vec<u32>,
    by_type: Vec<BTreeMap<u64, ObjectKey>>,
    symbols: Vec<HashMap<Arc<str>, ObjectKey>>,
    counters: Vec<u64>,
    prefixes: Vec<Arc<str>>,
    numbering: Numbering,
    next_seq: u64,
    len: usize,
}

/// Which numbers a store gives its new symbols: `first`, `first + stride`, `first + 2 stride`, ...
/// (`wo1`, `wo2`, ... by default). Stores of several regions or hosts that each take their own
/// `first` of a common `stride` never make the same symbol, without asking each other, so a
/// structure handed from one to another keeps its symbols (`crate::handover`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Numbering {
    pub first: u64,
    pub stride: u64,
}

impl Default for Numbering {
    fn default() -> Numbering {
        Numbering { first: 1, stride: 1 }
    }
}

impl Numbering {
    /// Region `index` (from 0) of `count`: numbers `index + 1` modulo `count`.
    pub fn region(index: u64, count: u64) -> Numbering {
        let stride = count.max(1);
        Numbering { first: index % stride + 1, stride }
    }
}

impl Store {
    /// A store for types with these symbol prefixes (indexed by [`TypeId`]).
    pub fn new(prefixes: Vec<Arc<str>>) -> Store {
        let n = prefixes.len();
        Store {
            slots: Vec::new(),
            free: Vec::new(),
            by_type: vec![BTreeMap::new(); n],
            symbols: vec![HashMap::new(); n],
            counters: vec![0; n],
            prefixes,
            numbering: Numbering::default(),
            next_seq: 0,
            len: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn get(&self, key: ObjectKey) -> Option<&Object> {
        let slot = self.slots.get(key.index())?;
        if slot.generation != key.generation {
            return None;
        }
        slot.object.as_ref()
    }

    pub fn get_mut(&mut self, key: ObjectKey) -> Option<&mut Object> {
        let slot = self.slots.get_mut(key.index())?;
        if slot.generation != key.generation {
            return None;
        }
        slot.object.as_mut()
    }

    pub fn by_symbol(&self, ty: TypeId, symbol: &str) -> Option<ObjectKey> {
        self.symbols.get(ty as usize)?.get(symbol).copied()
    }

    /// The objects of a type, in creation order.
    pub fn objects_of(&self, ty: TypeId) -> impl Iterator<Item = ObjectKey> + '_ {
        self.by_type.get(ty as usize).into_iter().flat_map(|m| m.values().copied())
    }

    /// Every object, by type then creation order.
    pub fn all(&self) -> impl Iterator<Item = &Object> + '_ {
        self.by_type.iter().flat_map(|m| m.values()).filter_map(|k| self.get(*k))
    }

    /// Calls `f` on every object.
    pub fn for_each_mut(&mut self, mut f: impl FnMut(&mut Object)) {
        for slot in &mut self.slots {
            if let Some(object) = &mut slot.object {
                f(object);
            }
        }
    }

    /// Gives new symbols numbers of `numbering` (before the first object is made).
    pub fn set_numbering(&mut self, numbering: Numbering) {
        self.numbering = Numbering { first: numbering.first.max(1), stride: numbering.stride.max(1) };
    }

    /// A fresh symbol of a type: its prefix and the next number of the store's [`Numbering`]
    /// not in use.
    pub fn new_symbol(&mut self, ty: TypeId) -> Arc<str> {
        let t = ty as usize;
        let Numbering { first, stride } = self.numbering;
        loop {
            self.counters[t] += 1;
            let number = first.saturating_add((self.counters[t] - 1).saturating_mul(stride));
            let symbol: Arc<str> = Arc::from(format!("{}{}", self.prefixes[t], number));
            if !self.symbols[t].contains_key(&symbol) {
                return symbol;
            }
        }
    }

    /// Adds an object; its `value` gets the symbol as `id`.
    pub fn insert(
        &mut self,
        ty: TypeId,
        symbol: Arc<str>,
        origin: Origin,
        record: Record,
        time: Time,
    ) -> ObjectKey {
        let index = match self.free.pop() {
            Some(i) => i,
            None => {
                self.slots.push(Slot::default());
                (self.slots.len() - 1) as u32
            }
        };
        let slot = &mut self.slots[index as usize];
        let key = ObjectKey { index, generation: slot.generation };
        let seq = self.next_seq;
        self.next_seq += 1;
        let record = Record { id: Some(symbol.clone()), fields: record.fields };
        slot.object = Some(Object {
            key,
            symbol: symbol.clone(),
            ty,
            seq,
            origin,
            created: time,
            value: Value::Record(Arc::new(record)),
            hypotheses: Vec::new(),
            state_time: time,
            measured: false,
            predicted: false,
            predicted_since: Some(time),
            prediction_root: None,
            branch_of: None,
            incoming: Vec::new(),
            outgoing: Vec::new(),
            anchored: false,
            last_anchored: time,
            forget_now: false,
            names: Vec::new(),
            prediction: None,
            seen_step: 0,
            present: true,
            last_seen: time,
            computed: None,
            memory: Vec::new(),
        });
        self.by_type[ty as usize].insert(seq, key);
        self.symbols[ty as usize].insert(symbol, key);
        self.len += 1;
        key
    }

    /// Removes an object and every link into or out of it (the caller handles what that means
    /// for the link processes first).
    pub fn remove(&mut self, key: ObjectKey) -> Option<Object> {
        let object = {
            let slot = self.slots.get_mut(key.index())?;
            if slot.generation != key.generation {
                return None;
            }
            let object = slot.object.take()?;
            slot.generation = slot.generation.wrapping_add(1);
            object
        };
        self.free.push(key.index);
        self.by_type[object.ty as usize].remove(&object.seq);
        self.symbols[object.ty as usize].remove(&object.symbol);
        for (link, to) in &object.outgoing {
            if let Some(o) = self.get_mut(*to) {
                o.incoming.retain(|(l, k)| !(*l == *link && *k == key));
            }
        }
        for (link, from) in &object.incoming {
            if let Some(o) = self.get_mut(*from) {
                o.outgoing.retain(|(l, k)| !(*l == *link && *k == key));
            }
        }
        self.len -= 1;
        Some(object)
    }

    /// Links `from` to `to` by `link`.
    pub fn link(&mut self, link: LinkId, from: ObjectKey, to: ObjectKey) {
        if let Some(f) = self.get_mut(from) {
            f.outgoing.push((link, to));
            f.outgoing.sort_by_key(|(l, _)| *l);
        }
        if let Some(t) = self.get_mut(to) {
            t.incoming.push((link, from));
            t.incoming.sort_by_key(|(l, _)| *l);
        }
    }

    /// Removes the link from `from` to `to` by `link`; whether it existed.
    pub fn unlink(&mut self, link: LinkId, from: ObjectKey, to: ObjectKey) -> bool {
        let mut existed = false;
        if let Some(f) = self.get_mut(from) {
            let before = f.outgoing.len();
            f.outgoing.retain(|(l, k)| !(*l == link && *k == to));
            existed = f.outgoing.len() != before;
        }
        if let Some(t) = self.get_mut(to) {
            t.incoming.retain(|(l, k)| !(*l == link && *k == from));
        }
        existed
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    #[test]
    fn keys_of_removed_objects_go_stale() {
        let mut store = Store::new(vec!["vp".into(), "wo".into()]);
        let a = store.insert(0, "vp1".into(), Origin::Percept { source: 0 }, Record::default(), 0);
        let s = store.new_symbol(1);
        assert_eq!(&*s, "wo1");
        let b = store.insert(1, s, Origin::Derived, Record::default(), 0);
        store.link(0, a, b);
        assert_eq!(store.get(b).unwrap().incoming_via(0), Some(a));
        store.remove(a).unwrap();
        assert!(store.get(a).is_none());
        assert!(store.get(b).unwrap().incoming.is_empty());
        // The slot is reused with a new generation: the old key stays dead.
        let c = store.insert(0, "vp2".into(), Origin::Percept { source: 0 }, Record::default(), 1);
        assert_eq!(c.index(), a.index());
        assert!(store.get(a).is_none());
        assert_eq!(&*store.get(c).unwrap().symbol, "vp2");
        assert_eq!(store.by_symbol(0, "vp2"), Some(c));
        assert_eq!(store.objects_of(0).collect::<Vec<_>>(), vec![c]);
        assert_eq!(&*store.new_symbol(1), "wo2");
    }
}
