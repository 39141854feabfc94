//! The bindings of a quantified monitor (`forall x: T . φ`, `forall a: T . forall b: U . φ`):
//! one instance of φ per object, or per pair of distinct objects, all in one shared
//! [`kpl_mtl::ProgressorGroup`] (bindings in the same situation share residuals and cached
//! transitions, so a binding costs its atoms and a lookup); which bindings a state steps; and the
//! episodes they report.
//!
//! The bookkeeping per state is linear in the objects and the bindings stepped: objects are
//! numbered by symbol while they are present, a binding is found by the numbers of its objects in
//! a hash map, and only the episodes reported at a state are sorted (by symbols, so that a run is
//! reproducible).

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::sync::Arc;

use kpl_core::{Record, Time, Value};
use kpl_mtl::{DomainId, Formula, InstanceId, ProgressorGroup, SlotId, SlotState, State};

use crate::stats::ProcessStats;
use kpl_mtl::gate::GateGrid;

/// One variable of the bindings: its name (a field of each verdict), its slot in the state and
/// the domain of its type.
pub(super) struct Var {
    pub name: Arc<str>,
    pub slot: usize,
    pub domain: usize,
}

/// A verdict that lasted: equal verdicts decided one after the other (each progression starting
/// at the state after the previous verdict) from `start` to `end`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Episode {
    verdict: bool,
    start: Time,
    end: Time,
    /// When its first verdict was decided: the valid time of the episode's sample.
    decided: Time,
}

/// A verdict that began an episode of a binding: its objects' symbols (one per variable) and the
/// verdict.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub ids: Box<[Arc<str>]>,
    pub verdict: bool,
}

/// One binding: its instance of the body in the group, and the episode it has not reported yet.
struct Binding {
    key: u64,
    /// The symbols of its objects, one per variable.
    ids: Box<[Arc<str>]>,
    /// The numbers of its objects (see [`Symbols`]), one per variable.
    numbers: [u32; 2],
    instance: InstanceId,
    /// The first state of the open progression.
    started: Option<Time>,
    /// The last state of the open progression.
    last_valid: Option<Time>,
    pending: Option<Episode>,
    /// The last state (epoch) this binding was stepped at.
    stepped: u64,
}

impl Binding {
    /// Whether no progression is open (the last state decided a verdict).
    fn idle(&self) -> bool {
        self.started.is_none()
    }

    /// Adds a verdict decided at `end` by the progression that began at `start`: the episode that
    /// ended, if this verdict differs from the pending one.
    fn decided(&mut self, verdict: bool, start: Time, end: Time) -> Option<Episode> {
        match &mut self.pending {
            Some(episode) if episode.verdict == verdict => {
                episode.end = end;
                None
            }
            pending => pending.replace(Episode { verdict, start, end, decided: end }),
        }
    }

    fn step(
        &mut self,
        group: &mut ProgressorGroup,
        valid: Time,
        state: &BoundState<'_>,
        stats: &ProcessStats,
    ) -> Option<Episode> {
        match group.step(self.instance, valid, state) {
            Ok(Some(verdict)) => {
                group.restart(self.instance);
                let start = self.started.take().unwrap_or(valid);
                self.last_valid = None;
                self.decided(verdict, start, valid)
            }
            Ok(None) => {
                self.started.get_or_insert(valid);
                self.last_valid = Some(valid);
                None
            }
            Err(e) => {
                stats.error(format!("at {valid}: {e}"));
                None
            }
        }
    }

    /// Closes the open progression (finite-trace semantics) and drops the instance: the episodes
    /// still to report.
    fn close(&mut self, group: &mut ProgressorGroup) -> Vec<Episode> {
        let mut out = Vec::new();
        if let (Some(start), Some(last)) = (self.started.take(), self.last_valid.take())
            && let Some(verdict) = group.finish(self.instance)
            && let Some(done) = self.decided(verdict, start, last)
        {
            out.push(done);
        }
        out.extend(self.pending.take());
        group.remove(self.instance);
        out
    }
}

/// The objects of one variable's type, numbered by symbol while they are present: a number is
/// given back when its object is missing from a state (its bindings are closed at that state).
#[derive(Default)]
struct Symbols {
    number: HashMap<Arc<str>, u32>,
    /// Per number: the symbol.
    names: Vec<Arc<str>>,
    /// Per number: the epoch of the last state the object was present at, and its position in
    /// that state's [`Present`] list.
    seen: Vec<(u64, u32)>,
    free: Vec<u32>,
}

impl Symbols {
    /// The number of object `id`, present at `epoch` at position `at`; `None` if an object of
    /// that symbol was already present at this state (the first one counts).
    fn present(&mut self, id: &Arc<str>, epoch: u64, at: u32) -> Option<u32> {
        let n = match self.number.get(id) {
            Some(&n) => {
                if self.seen[n as usize].0 == epoch {
                    return None;
                }
                n
            }
            None => {
                let n = match self.free.pop() {
                    Some(n) => n,
                    None => {
                        self.seen.push((0, 0));
                        self.names.push(id.clone());
                        (self.seen.len() - 1) as u32
                    }
                };
                self.names[n as usize] = id.clone();
                self.number.insert(id.clone(), n);
                n
            }
        };
        self.seen[n as usize] = (epoch, at);
        Some(n)
    }

    /// The position of object `n` at the state of `epoch`, if it is present.
    fn position(&self, n: u32, epoch: u64) -> Option<u32> {
        let (seen, at) = self.seen[n as usize];
        (seen == epoch).then_some(at)
    }

    /// Gives back the numbers of the objects missing from the state of `epoch`.
    fn sweep(&mut self, epoch: u64) {
        let (seen, free) = (&self.seen, &mut self.free);
        self.number.retain(|_, n| {
            let keep = seen[*n as usize].0 == epoch;
            if !keep {
                free.push(*n);
            }
            keep
        });
    }
}

/// One variable's objects at a state (those with a symbol, each symbol once).
#[derive(Default)]
struct Present {
    /// Index in the state's list of objects of the variable's type.
    index: Vec<u32>,
    number: Vec<u32>,
    pos: Vec<Option<[f64; 2]>>,
}

/// A hasher for keys that are already well mixed integers (the numbers of a binding's objects,
/// multiplied out).
#[derive(Default)]
struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    fn write_u64(&mut self, x: u64) {
        // A multiplicative mix (Fibonacci hashing): the high bits depend on every bit of `x`.
        let x = x.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = x ^ (x >> 29);
    }
}

/// Episodes to report, each with the symbols of its binding.
type Reports = Vec<(Box<[Arc<str>]>, Episode)>;

fn key(numbers: [u32; 2]) -> u64 {
    (u64::from(numbers[0]) << 32) | u64::from(numbers[1])
}

/// What the body reads at a state: the monitor's state with each variable bound to its object.
struct BoundState<'a> {
    base: &'a SlotState,
    bound: [(SlotId, &'a Value); 2],
    vars: usize,
}

impl State for BoundState<'_> {
    fn value(&self, slot: SlotId) -> Option<&Value> {
        match self.bound[..self.vars].iter().find(|(s, _)| *s == slot) {
            Some((_, value)) => Some(value),
            None => self.base.value(slot),
        }
    }

    fn objects(&self, domain: DomainId) -> &[Value] {
        self.base.objects(domain)
    }
}

/// The bindings of `forall x: T . φ` or `forall a: T . forall b: U . φ`.
pub(super) struct Bindings {
    vars: Vec<Var>,
    /// Pairs farther apart than this are not progressed (`kpl_mtl::gate`).
    gate: Option<f64>,
    group: ProgressorGroup,
    symbols: Vec<Symbols>,
    /// The bindings, by slot; `None`: a free slot.
    bindings: Vec<Option<Binding>>,
    free: Vec<u32>,
    by_key: HashMap<u64, u32, BuildHasherDefault<KeyHasher>>,
    /// Counts the states: a binding or object marked with this epoch was seen at this state.
    epoch: u64,
    /// Working memory reused from state to state.
    present: Vec<Present>,
    todo: Vec<(u32, [u32; 2])>,
}

impl Bindings {
    pub fn new(body: Arc<Formula>, vars: Vec<Var>, gate: Option<f64>) -> Bindings {
        let n = vars.len();
        Bindings {
            vars,
            gate,
            group: ProgressorGroup::new(body),
            symbols: (0..n).map(|_| Symbols::default()).collect(),
            bindings: Vec::new(),
            free: Vec::new(),
            by_key: HashMap::default(),
            epoch: 0,
            present: (0..n).map(|_| Present::default()).collect(),
            todo: Vec::new(),
        }
    }

    fn verdict(&self, ids: &[Arc<str>], episode: Episode) -> Value {
        let mut fields: Vec<(Arc<str>, Value)> =
            self.vars.iter().zip(ids).map(|(var, id)| (var.name.clone(), Value::Str(id.clone()))).collect();
        fields.push((Arc::from("verdict"), Value::Bool(episode.verdict)));
        fields.push((Arc::from("start"), Value::Int(episode.start)));
        fields.push((Arc::from("end"), Value::Int(episode.end)));
        Value::Record(Arc::new(Record { id: None, fields }))
    }

    /// Emits episodes in the order of their bindings' symbols (stable: one binding's in order).
    fn report(&self, mut episodes: Reports, out: &mut dyn FnMut(Time, Value)) {
        episodes.sort_by(|a, b| a.0.cmp(&b.0));
        for (ids, episode) in episodes {
            out(episode.decided, self.verdict(&ids, episode));
        }
    }

    /// Numbers the objects of each variable's type present at this state.
    fn find_present(&mut self, state: &SlotState) {
        let epoch = self.epoch;
        for (v, var) in self.vars.iter().enumerate() {
            let present = &mut self.present[v];
            present.index.clear();
            present.number.clear();
            present.pos.clear();
            let objects = state.objects.get(var.domain).map_or(&[][..], Vec::as_slice);
            for (k, object) in objects.iter().enumerate() {
                let Value::Record(record) = object else { continue };
                let Some(id) = &record.id else { continue };
                let at = present.index.len() as u32;
                let Some(n) = self.symbols[v].present(id, epoch, at) else { continue };
                present.index.push(k as u32);
                present.number.push(n);
                present.pos.push(record.get("pos").and_then(Value::as_vec2));
            }
        }
    }

    /// Calls `visit` with the positions (in [`Present`]) of the tuples to progress at this state:
    /// every object (one variable), or the pairs of distinct objects within the gate (two).
    fn candidates(&self, mut visit: impl FnMut([u32; 2])) {
        match self.vars.as_slice() {
            [_] => (0..self.present[0].index.len() as u32).for_each(|i| visit([i, 0])),
            [a, b] => {
                let (pa, pb) = (&self.present[0], &self.present[1]);
                // Both variables range over the same list of objects: equal positions, one object.
                let distinct = |i: usize, j: usize| a.domain != b.domain || i != j;
                match self.gate {
                    Some(radius) => {
                        // Objects without a (finite) position are never within a gate.
                        let placed =
                            |p: &Option<[f64; 2]>| p.filter(|p| p[0].is_finite() && p[1].is_finite());
                        let mut grid = GateGrid::new(radius);
                        for (j, pos) in pb.pos.iter().enumerate() {
                            if let Some(p) = placed(pos) {
                                grid.insert(j, 0, p);
                            }
                        }
                        grid.finish();
                        let mut near = Vec::new();
                        for (i, pos) in pa.pos.iter().enumerate() {
                            let Some(p) = placed(pos) else { continue };
                            grid.near(Some(p), &mut near);
                            for &j in near.iter().filter(|&&j| distinct(i, j)) {
                                visit([i as u32, j as u32]);
                            }
                        }
                    }
                    None => {
                        for i in 0..pa.index.len() {
                            for j in (0..pb.index.len()).filter(|&j| distinct(i, j)) {
                                visit([i as u32, j as u32]);
                            }
                        }
                    }
                }
            }
            _ => {}
        }
    }

    /// The slot of the binding of these objects, made if it is new.
    fn binding(&mut self, numbers: [u32; 2]) -> u32 {
        let key = key(numbers);
        if let Some(&slot) = self.by_key.get(&key) {
            return slot;
        }
        let ids: Box<[Arc<str>]> =
            (0..self.vars.len()).map(|v| self.symbols[v].names[numbers[v] as usize].clone()).collect();
        let binding = Binding {
            key,
            ids,
            numbers,
            instance: self.group.start(),
            started: None,
            last_valid: None,
            pending: None,
            stepped: 0,
        };
        let slot = match self.free.pop() {
            Some(slot) => {
                self.bindings[slot as usize] = Some(binding);
                slot
            }
            None => {
                self.bindings.push(Some(binding));
                (self.bindings.len() - 1) as u32
            }
        };
        self.by_key.insert(key, slot);
        slot
    }

    /// Drops the binding in `slot`; the episodes it still had to report go to `reports`.
    fn close_binding(&mut self, slot: u32, reports: &mut Reports) {
        let Some(mut binding) = self.bindings.get_mut(slot as usize).and_then(Option::take) else { return };
        self.free.push(slot);
        self.by_key.remove(&binding.key);
        let episodes = binding.close(&mut self.group);
        reports.extend(episodes.into_iter().map(|e| (binding.ids.clone(), e)));
    }

    /// Steps the bindings of the objects present (those within the gate, and those with an open
    /// progression); closes those of objects that are gone, and idle pairs that left the gate.
    /// Emits the episodes that ended; gives the verdicts decided at this state that began an
    /// episode (a binding's first verdict, or one that differs from its last), by symbols.
    pub fn step(
        &mut self,
        valid: Time,
        state: &SlotState,
        stats: &ProcessStats,
        out: &mut dyn FnMut(Time, Value),
    ) -> Vec<Decision> {
        self.epoch += 1;
        let epoch = self.epoch;
        self.find_present(state);
        let mut todo = std::mem::take(&mut self.todo);
        todo.clear();
        let mut tuples = Vec::new();
        self.candidates(|positions| tuples.push(positions));
        for positions in tuples {
            let numbers: [u32; 2] =
                std::array::from_fn(|v| self.present.get(v).map_or(0, |p| p.number[positions[v] as usize]));
            let slot = self.binding(numbers);
            if let Some(binding) = self.bindings[slot as usize].as_mut()
                && binding.stepped != epoch
            {
                binding.stepped = epoch;
                todo.push((slot, positions));
            }
        }
        // The bindings not among the candidates: stepped while their progression is open and
        // their objects are present, closed otherwise. Those that end report first: their
        // episodes are older than this state.
        let mut ended = Vec::new();
        for (slot, binding) in self.bindings.iter_mut().enumerate() {
            let Some(binding) = binding else { continue };
            if binding.stepped == epoch {
                continue;
            }
            let mut positions = [0; 2];
            let mut all_present = true;
            for (v, symbols) in self.symbols.iter().enumerate() {
                match symbols.position(binding.numbers[v], epoch) {
                    Some(at) => positions[v] = at,
                    None => all_present = false,
                }
            }
            if all_present && !binding.idle() {
                binding.stepped = epoch;
                todo.push((slot as u32, positions));
            } else {
                ended.push(slot as u32);
            }
        }
        let mut reports = Vec::new();
        let mut began = Vec::new();
        for slot in ended {
            self.close_binding(slot, &mut reports);
        }
        self.report(std::mem::take(&mut reports), out);
        for &(slot, positions) in &todo {
            let mut bound = BoundState { base: state, bound: [(0, &Value::Bool(false)); 2], vars: 0 };
            for (v, var) in self.vars.iter().enumerate() {
                let k = self.present[v].index[positions[v] as usize] as usize;
                bound.bound[v] = (var.slot as SlotId, &state.objects[var.domain][k]);
                bound.vars = v + 1;
            }
            let Some(binding) = self.bindings[slot as usize].as_mut() else { continue };
            if let Some(episode) = binding.step(&mut self.group, valid, &bound, stats) {
                reports.push((binding.ids.clone(), episode));
            }
            if let Some(episode) = binding.pending.filter(|e| e.decided == valid) {
                began.push(Decision { ids: binding.ids.clone(), verdict: episode.verdict });
            }
        }
        self.report(reports, out);
        self.todo = todo;
        for symbols in &mut self.symbols {
            symbols.sweep(epoch);
        }
        began.sort_by(|a, b| a.ids.cmp(&b.ids));
        began
    }

    /// Closes every binding at the end of the streams.
    pub fn close(&mut self, out: &mut dyn FnMut(Time, Value)) {
        let mut reports = Vec::new();
        for slot in 0..self.bindings.len() as u32 {
            self.close_binding(slot, &mut reports);
        }
        self.report(reports, out);
    }
}
