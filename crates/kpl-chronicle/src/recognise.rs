//! The incremental recogniser: one [`Recogniser::step`] per instant with the events that occurred
//! at it, in their order. Time is an argument; nothing here reads a clock.
//!
//! Each chronicle keeps partial instances: a binding of some parameters and an occurrence (and its
//! time) for some nodes. An event matching a node extends every partial instance it is consistent
//! with (binding, and the minimal network's bounds against every node already matched), keeping
//! the instance it extends, and starts a new one. An instance is dropped as soon as its deadline
//! passes (the latest time its earliest-due open node may still occur), so an instance never lives
//! longer than the chronicle's window, and as soon as one of its `hold`s fails before its `to`
//! event, or an event one of its `never`s forbids occurs after its `from` event while its `to`
//! event is still open (it could only complete into a failure). Instances are grouped by the objects bound to the
//! parameters that every event binds, so an event is tried only against the instances of its own
//! objects. A complete instance is checked against its `hold` and
//! `never` conditions when its step is done (so every event at that instant is known), and each
//! one that passes is a [`Recognition`] whose valid time is the step's time. Recognitions are
//! events of the chronicle's own source for chronicles that use them, at the same step (chronicles
//! run in the order of that use; a cycle is refused).
//!
//! Memory is bounded: at most [`Config::max_instances`] partial instances per chronicle (an event
//! that would exceed it starts or extends none, and [`Stats::refused`] counts it), each of size
//! `O(params + nodes)`; plus, for the sources that conditions read, the events of the last
//! `window` (the longest window of any chronicle) and one bit per fluent that is true before it.
//!
//! Semantics, which `tests/agree.rs` checks against a brute-force matcher over whole sequences: a
//! recognition is an injective assignment of event occurrences to the nodes (distinct nodes,
//! distinct occurrences) with one binding of all parameters, such that every constraint holds and
//! every condition holds.

use std::collections::{HashMap, HashSet, VecDeque};
use std::hash::Hash;

use kpl_core::Time;
use thiserror::Error;

use crate::model::{Compiled, Event, Pattern, SourceId};

/// Limits of a recogniser.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Partial instances kept per chronicle.
    pub max_instances: usize,
}

impl Default for Config {
    fn default() -> Config {
        Config { max_instances: 10_000 }
    }
}

/// A chronicle recognised: its index among the recogniser's chronicles, the objects bound to its
/// parameters, the time of each node's event and the valid time (the last of them).
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Recognition<O> {
    pub chronicle: usize,
    pub binding: Vec<O>,
    pub times: Vec<Time>,
    pub valid_time: Time,
}

/// What the recogniser did, for the run's summary.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stats {
    /// Partial instances alive now, and at most so far.
    pub instances: usize,
    pub peak_instances: usize,
    /// Partial instances dropped because their deadline passed.
    pub expired: u64,
    /// Partial instances dropped because a `hold` already failed (its fluent became false after
    /// its `from` event, before its `to` event) or a `never`'s event occurred after its `from`
    /// event with its `to` event still open: they could only complete into a failure.
    pub broken: u64,
    /// Instances not started or extended because a chronicle had `max_instances` already.
    pub refused: u64,
    /// Complete instances whose `hold` or `never` condition failed.
    pub failed_conditions: u64,
    pub recognitions: u64,
    /// Steps refused because their time was not after the previous step's.
    pub late_steps: u64,
}

/// A step at or before the previous one: steps must come in increasing time, all the events of
/// an instant in one step (two steps at one instant would split its events, and a `hold` or
/// `never` condition could not tell which of them came first).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
#[error(
    "events at {time} us arrived when the recogniser had stepped at {now} us (steps must come in increasing time)"
)]
pub struct Late {
    pub time: Time,
    pub now: Time,
}

/// A cycle of chronicles recognising each other.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("chronicles {0:?} use each other's recognitions in a cycle")]
pub struct DependencyCycle(pub Vec<String>);

#[derive(Debug, Clone)]
struct Partial<O> {
    binding: Vec<Option<O>>,
    times: Vec<Option<Time>>,
    occurrences: Vec<Option<u64>>,
    open: usize,
    deadline: Time,
}

/// A chronicle's partial instances, grouped by the objects bound to the parameters that every one
/// of its events binds (for the overtake, both cars): an event can only extend the instances of its
/// own group, so it is tried against those alone. A chronicle with no such parameter has one group.
#[derive(Debug)]
struct Instances<O> {
    /// The parameters every event binds, in increasing order.
    key_params: Vec<usize>,
    /// Per `hold` of the chronicle: where each of `key_params` is among its arguments, so that a
    /// false event of its fluent names a group (`None`: its arguments do not name one).
    hold_keys: Vec<Option<Vec<usize>>>,
    /// The same per `never`, for an event of its pattern.
    never_keys: Vec<Option<Vec<usize>>>,
    /// The events of the last instant that a `never` forbids, by the `never`'s index: applied
    /// ([`drop_forbidden`]) once a step at a later instant comes.
    forbidden: Vec<(usize, Event<O>)>,
    groups: HashMap<Vec<O>, Vec<Partial<O>>>,
    len: usize,
}

impl<O: Clone + Eq + Hash> Instances<O> {
    fn new(compiled: &Compiled) -> Instances<O> {
        let events = &compiled.chronicle.events;
        let key_params: Vec<usize> =
            (0..compiled.chronicle.params).filter(|p| events.iter().all(|e| e.args.contains(p))).collect();
        let positions =
            |args: &[usize]| key_params.iter().map(|p| args.iter().position(|a| a == p)).collect();
        let hold_keys = compiled.chronicle.holds.iter().map(|h| positions(&h.args)).collect();
        let never_keys = compiled.chronicle.nevers.iter().map(|n| positions(&n.pattern.args)).collect();
        Instances { key_params, hold_keys, never_keys, forbidden: Vec::new(), groups: HashMap::new(), len: 0 }
    }

    /// The group of an event matching `pattern` with these arguments.
    fn key(&self, pattern: &Pattern, args: &[O]) -> Vec<O> {
        if self.key_params.is_empty() {
            return Vec::new();
        }
        self.key_params
            .iter()
            .filter_map(|p| pattern.args.iter().position(|a| a == p).map(|k| args[k].clone()))
            .collect()
    }
}

/// The events of one fluent (or point source) on one tuple of objects within the window.
#[derive(Debug, Default)]
struct History {
    /// The value before the first entry.
    base: bool,
    entries: VecDeque<(Time, bool)>,
}

#[derive(Debug)]
pub struct Recogniser<O> {
    chronicles: Vec<Compiled>,
    /// Chronicle indices, each after the chronicles whose recognitions it uses.
    order: Vec<usize>,
    partial: Vec<Instances<O>>,
    logged: HashSet<SourceId>,
    log: HashMap<(SourceId, Vec<O>), History>,
    window: Time,
    now: Option<Time>,
    next_occurrence: u64,
    config: Config,
    stats: Stats,
}

impl<O: Clone + Eq + Hash> Recogniser<O> {
    pub fn new(chronicles: Vec<Compiled>, config: Config) -> Result<Recogniser<O>, DependencyCycle> {
        let order = dependency_order(&chronicles)?;
        let mut logged = HashSet::new();
        for c in &chronicles {
            logged.extend(c.chronicle.holds.iter().map(|h| h.source));
            logged.extend(c.chronicle.nevers.iter().map(|n| n.pattern.source));
        }
        let window = chronicles.iter().map(|c| c.window).max().unwrap_or(0);
        let partial = chronicles.iter().map(Instances::new).collect();
        Ok(Recogniser {
            chronicles,
            order,
            partial,
            logged,
            log: HashMap::new(),
            window,
            now: None,
            next_occurrence: 0,
            config,
            stats: Stats::default(),
        })
    }

    pub fn chronicles(&self) -> &[Compiled] {
        &self.chronicles
    }

    pub fn stats(&self) -> Stats {
        self.stats
    }

    /// Processes the events that occurred at `time`, in their order (an event's `time` field is
    /// ignored: they are all at `time`), and returns the chronicles recognised at `time`. A step
    /// with no events only lets deadlines pass. A step at or before the previous one's time is
    /// refused ([`Late`], counted in [`Stats::late_steps`]) and changes nothing.
    pub fn step(&mut self, time: Time, events: Vec<Event<O>>) -> Result<Vec<Recognition<O>>, Late> {
        if let Some(now) = self.now
            && time <= now
        {
            self.stats.late_steps += 1;
            return Err(Late { time, now });
        }
        self.now = Some(time);
        self.prune_log(time);
        let mut batch: Vec<(Event<O>, u64)> = Vec::with_capacity(events.len());
        for mut event in events {
            event.time = time;
            self.push_occurrence(&mut batch, event);
        }
        let mut recognitions = Vec::new();
        for position in 0..self.order.len() {
            let c = self.order[position];
            let done = self.step_chronicle(c, time, &batch);
            for instance in done {
                if !self.conditions_hold(c, &instance) {
                    self.stats.failed_conditions += 1;
                    continue;
                }
                let binding: Vec<O> = instance.binding.into_iter().flatten().collect();
                let times: Vec<Time> = instance.times.into_iter().map(|t| t.unwrap_or(time)).collect();
                let source = self.chronicles[c].chronicle.source;
                self.push_occurrence(&mut batch, Event { source, args: binding.clone(), value: true, time });
                self.stats.recognitions += 1;
                recognitions.push(Recognition { chronicle: c, binding, times, valid_time: time });
            }
        }
        self.stats.instances = self.partial.iter().map(|i| i.len).sum();
        self.stats.peak_instances = self.stats.peak_instances.max(self.stats.instances);
        Ok(recognitions)
    }

    fn push_occurrence(&mut self, batch: &mut Vec<(Event<O>, u64)>, event: Event<O>) {
        if self.logged.contains(&event.source) {
            let history = self.log.entry((event.source, event.args.clone())).or_default();
            history.entries.push_back((event.time, event.value));
        }
        batch.push((event, self.next_occurrence));
        self.next_occurrence += 1;
    }

    /// Forgets logged events older than the longest window; the value they leave is the base.
    fn prune_log(&mut self, time: Time) {
        let cutoff = time.saturating_sub(self.window);
        self.log.retain(|_, history| {
            while let Some(&(t, value)) = history.entries.front() {
                if t >= cutoff {
                    break;
                }
                history.base = value;
                history.entries.pop_front();
            }
            history.base || !history.entries.is_empty()
        });
    }

    /// Expires, extends and starts chronicle `c`'s partial instances with the batch; returns the
    /// instances it completed.
    fn step_chronicle(&mut self, c: usize, time: Time, batch: &[(Event<O>, u64)]) -> Vec<Partial<O>> {
        let compiled = &self.chronicles[c];
        let instances = &mut self.partial[c];
        let before = instances.len;
        instances.groups.retain(|_, group| {
            group.retain(|p| p.deadline >= time);
            !group.is_empty()
        });
        instances.len = instances.groups.values().map(Vec::len).sum();
        self.stats.expired += (before - instances.len) as u64;
        let broken =
            drop_broken(compiled, instances, time, batch) + drop_forbidden(compiled, instances, time);
        instances.len -= broken;
        self.stats.broken += broken as u64;
        // The groups touched, in the order first touched (so that what completes comes out in an
        // order that does not depend on hashing).
        let mut touched: Vec<Vec<O>> = Vec::new();
        // The same, to ask whether a group is in it (a step has as many events as changes).
        let mut seen: HashSet<Vec<O>> = HashSet::new();
        for (event, occurrence) in batch {
            for (node, pattern) in compiled.chronicle.events.iter().enumerate() {
                if !pattern.matches(event) {
                    continue;
                }
                let key = instances.key(pattern, &event.args);
                let group = instances.groups.entry(key.clone()).or_default();
                let existing = group.len();
                let mut added = 0;
                for i in 0..existing {
                    if let Some(extended) = extend(compiled, &group[i], node, event, *occurrence) {
                        if instances.len + added >= self.config.max_instances {
                            self.stats.refused += 1;
                            continue;
                        }
                        group.push(extended);
                        added += 1;
                    }
                }
                let fresh = Partial {
                    binding: vec![None; compiled.chronicle.params],
                    times: vec![None; compiled.chronicle.events.len()],
                    occurrences: vec![None; compiled.chronicle.events.len()],
                    open: compiled.chronicle.events.len(),
                    deadline: Time::MAX,
                };
                if let Some(started) = extend(compiled, &fresh, node, event, *occurrence) {
                    if instances.len + added >= self.config.max_instances {
                        self.stats.refused += 1;
                    } else {
                        group.push(started);
                        added += 1;
                    }
                }
                instances.len += added;
                if added > 0 && seen.insert(key.clone()) {
                    touched.push(key);
                }
            }
        }
        let mut done = Vec::new();
        for key in touched {
            let Some(group) = instances.groups.get_mut(&key) else { continue };
            let mut i = 0;
            while i < group.len() {
                if group[i].open == 0 { done.push(group.swap_remove(i)) } else { i += 1 }
            }
            if group.is_empty() {
                instances.groups.remove(&key);
            }
        }
        instances.len -= done.len();
        for (k, never) in compiled.chronicle.nevers.iter().enumerate() {
            if instances.never_keys[k].is_some() {
                let matching = batch.iter().filter(|(e, _)| never.pattern.matches(e));
                instances.forbidden.extend(matching.map(|(e, _)| (k, e.clone())));
            }
        }
        done
    }

    fn conditions_hold(&self, c: usize, instance: &Partial<O>) -> bool {
        let chronicle = &self.chronicles[c].chronicle;
        let time = |node: usize| instance.times[node].unwrap_or(Time::MIN);
        let objects =
            |args: &[usize]| -> Vec<O> { args.iter().filter_map(|&a| instance.binding[a].clone()).collect() };
        for hold in &chronicle.holds {
            let (t1, t2) = (time(hold.from), time(hold.to));
            let Some(history) = self.log.get(&(hold.source, objects(&hold.args))) else { return false };
            let at_start =
                history.entries.iter().take_while(|(t, _)| *t <= t1).last().map_or(history.base, |e| e.1);
            let falls = history.entries.iter().any(|&(t, value)| t > t1 && t <= t2 && !value);
            if !at_start || falls {
                return false;
            }
        }
        for never in &chronicle.nevers {
            let (t1, t2) = (time(never.from), time(never.to));
            let key = (never.pattern.source, objects(&never.pattern.args));
            if let Some(history) = self.log.get(&key)
                && history.entries.iter().any(|&(t, value)| t > t1 && t < t2 && value == never.pattern.value)
            {
                return false;
            }
        }
        true
    }
}

/// Drops the partial instances of a chronicle that a `hold` already fails: its fluent became false
/// in this batch (at `time`), after the instance's `from` event and before its `to` event, on the
/// objects the instance binds. Such an instance could only complete at `time` or later, when its
/// hold would fail (`Recogniser::conditions_hold`), so dropping it now changes no recognition; it
/// only keeps instances from living out the chronicle's window. A hold whose arguments do not
/// name the instances' group (every event's parameters) is left to the check at completion.
/// Returns how many were dropped.
fn drop_broken<O: Clone + Eq + Hash>(
    compiled: &Compiled,
    instances: &mut Instances<O>,
    time: Time,
    batch: &[(Event<O>, u64)],
) -> usize {
    let mut dropped = 0;
    let Instances { hold_keys, groups, .. } = instances;
    for (hold, positions) in compiled.chronicle.holds.iter().zip(hold_keys.iter()) {
        let Some(positions) = positions else { continue };
        for (event, _) in batch {
            if event.source != hold.source || event.value || event.args.len() != hold.args.len() {
                continue;
            }
            dropped += drop_failing(groups, positions, (&hold.args, hold.from, hold.to), event, time);
        }
    }
    dropped
}

/// Drops from the group of `event`'s objects (`positions`: where the group's key parameters are
/// among the condition's `args`) the instances whose condition over `args` from node `from` to node
/// `to` already fails through `event`: `from` matched before `since`, `to` still open, and `args`
/// bound to `event`'s objects. Returns how many were dropped.
fn drop_failing<O: Clone + Eq + Hash>(
    groups: &mut HashMap<Vec<O>, Vec<Partial<O>>>,
    positions: &[usize],
    (args, from, to): (&[usize], usize, usize),
    event: &Event<O>,
    since: Time,
) -> usize {
    let key: Vec<O> = positions.iter().map(|&k| event.args[k].clone()).collect();
    let Some(group) = groups.get_mut(&key) else { return 0 };
    let before = group.len();
    group.retain(|p| {
        let open = p.times[from].is_some_and(|t1| t1 < since) && p.times[to].is_none();
        let same = args.iter().zip(&event.args).all(|(a, o)| p.binding[*a].as_ref() == Some(o));
        !(open && same)
    });
    let dropped = before - group.len();
    if group.is_empty() {
        groups.remove(&key);
    }
    dropped
}

/// Drops the partial instances of a chronicle that a `never` already fails: an event of its
/// pattern occurred at an earlier instant than `time` (kept in `forbidden` by the step that saw
/// it), after the instance's `from` event, on the objects the instance binds, and the instance's
/// `to` event is still open. It can only get its `to` event at `time` or later, with the forbidden
/// event strictly between the two (`Recogniser::conditions_hold`), so dropping it changes no
/// recognition (at the forbidden event's own instant a `to` event could still come, in a later
/// step at that instant: hence the wait). A `never` whose arguments do not name the instances'
/// group is left to the check at completion. Returns how many were dropped.
fn drop_forbidden<O: Clone + Eq + Hash>(
    compiled: &Compiled,
    instances: &mut Instances<O>,
    time: Time,
) -> usize {
    let mut dropped = 0;
    let Instances { never_keys, forbidden, groups, .. } = instances;
    let (due, waiting): (Vec<_>, Vec<_>) =
        std::mem::take(forbidden).into_iter().partition(|(_, e)| e.time < time);
    *forbidden = waiting;
    for (k, event) in due {
        let never = &compiled.chronicle.nevers[k];
        let Some(positions) = &never_keys[k] else { continue };
        let condition = (never.pattern.args.as_slice(), never.from, never.to);
        dropped += drop_failing(groups, positions, condition, &event, event.time);
    }
    dropped
}

/// `instance` with `node` matched by `event`, if the binding and the network allow it.
fn extend<O: Clone + Eq>(
    compiled: &Compiled,
    instance: &Partial<O>,
    node: usize,
    event: &Event<O>,
    occurrence: u64,
) -> Option<Partial<O>> {
    if instance.times[node].is_some() || instance.occurrences.contains(&Some(occurrence)) {
        return None;
    }
    let pattern: &Pattern = &compiled.chronicle.events[node];
    // The binding and the network are checked before anything is copied: most instances an event
    // is tried against are about other objects.
    let bound_elsewhere = pattern.args.iter().zip(&event.args).enumerate().any(|(k, (param, object))| {
        // Bound by the instance, or by an earlier argument of this event (a parameter twice).
        let earlier = pattern.args[..k].iter().position(|p| p == param).map(|j| &event.args[j]);
        instance.binding[*param].as_ref().or(earlier).is_some_and(|bound| bound != object)
    });
    if bound_elsewhere {
        return None;
    }
    let consistent = instance
        .times
        .iter()
        .enumerate()
        .all(|(m, t)| t.is_none_or(|t| compiled.minimal.allows(m, node, event.time.saturating_sub(t))));
    if !consistent {
        return None;
    }
    let mut binding = instance.binding.clone();
    for (param, object) in pattern.args.iter().zip(&event.args) {
        binding[*param].get_or_insert_with(|| object.clone());
    }
    let mut times = instance.times.clone();
    times[node] = Some(event.time);
    let mut occurrences = instance.occurrences.clone();
    occurrences[node] = Some(occurrence);
    let deadline = deadline(compiled, &times);
    Some(Partial { binding, times, occurrences, open: instance.open - 1, deadline })
}

/// The latest time at which every open node can still occur: past it the instance is dead.
fn deadline(compiled: &Compiled, times: &[Option<Time>]) -> Time {
    let mut deadline = Time::MAX;
    for (open, _) in times.iter().enumerate().filter(|(_, t)| t.is_none()) {
        for (m, t) in times.iter().enumerate() {
            if let (Some(t), Some(upper)) = (t, compiled.minimal.upper(m, open)) {
                deadline = deadline.min(t.saturating_add(upper));
            }
        }
    }
    deadline
}

/// Chronicle indices such that every chronicle comes after those whose recognitions it uses.
fn dependency_order(chronicles: &[Compiled]) -> Result<Vec<usize>, DependencyCycle> {
    let by_source: HashMap<SourceId, usize> =
        chronicles.iter().enumerate().map(|(i, c)| (c.chronicle.source, i)).collect();
    let uses = |c: &Compiled| -> Vec<usize> {
        let patterns = c.chronicle.events.iter().chain(c.chronicle.nevers.iter().map(|n| &n.pattern));
        patterns.filter_map(|p| by_source.get(&p.source).copied()).collect()
    };
    let mut order = Vec::with_capacity(chronicles.len());
    let mut placed = vec![false; chronicles.len()];
    while order.len() < chronicles.len() {
        let ready: Vec<usize> = (0..chronicles.len())
            .filter(|&i| !placed[i] && uses(&chronicles[i]).iter().all(|&d| placed[d] && d != i))
            .collect();
        if ready.is_empty() {
            let stuck = (0..chronicles.len()).filter(|&i| !placed[i]);
            return Err(DependencyCycle(stuck.map(|i| chronicles[i].chronicle.name.clone()).collect()));
        }
        for i in ready {
            placed[i] = true;
            order.push(i);
        }
    }
    Ok(order)
}
