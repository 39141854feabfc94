//! State synchronization: a process's input streams merged into states that share a valid time,
//! as formulas (and synchronized units such as AAPA) need them.
//!
//! A state for valid time `t` is emitted, in increasing `t`, when it is complete (every input has
//! a sample at `t`), or when every missing input has moved past `t` or ended, or when `t` plus
//! the input's `max delay` has passed. A value still missing then stays missing (`None`) unless
//! the input's policy says `use most recent`: then it is the most recent sample before `t` (which
//! keeps its own valid time, so the consumer can tell it is approximated). `feedback` inputs are
//! never waited for: they contribute their most recent sample before `t`.
//! Samples for a time whose state is already out are late ([`DropReason::LateForState`]) but
//! still update the most recent value.
//!
//! Pure: `now` is an argument, and [`StateSync::deadline`] says when to call
//! [`StateSync::on_timer`].

use std::collections::BTreeMap;
use std::sync::Arc;

use kpl_core::Time;

use crate::sample::Sample;
use crate::stats::{DropReason, EdgeStats};

/// One input of a synchronized process.
#[derive(Debug, Clone)]
pub struct SyncInput {
    pub max_delay: Option<Time>,
    /// `use most recent`: a missing value is filled with the most recent sample.
    pub approximate: bool,
    pub feedback: bool,
    pub stats: Arc<EdgeStats>,
}

/// A synchronized state: its valid time and one sample per input (`None`: no value yet).
#[derive(Debug, Clone, PartialEq)]
pub struct SyncState {
    pub valid: Time,
    pub values: Vec<Option<Sample>>,
}

#[derive(Debug)]
pub struct StateSync {
    inputs: Vec<SyncInput>,
    pending: BTreeMap<Time, Vec<Option<Sample>>>,
    /// Recent samples of each input in valid-time order: the latest at or before the last emitted
    /// state, and everything after it.
    history: Vec<std::collections::VecDeque<Sample>>,
    /// The largest valid time seen on each input.
    seen_up_to: Vec<Option<Time>>,
    ended: Vec<bool>,
    emitted_up_to: Option<Time>,
}

impl StateSync {
    pub fn new(inputs: Vec<SyncInput>) -> StateSync {
        let n = inputs.len();
        StateSync {
            inputs,
            pending: BTreeMap::new(),
            history: vec![std::collections::VecDeque::new(); n],
            seen_up_to: vec![None; n],
            ended: vec![false; n],
            emitted_up_to: None,
        }
    }

    /// Adds a sample of input `port`; states that became ready are pushed to `out`.
    pub fn push(&mut self, port: usize, sample: Sample, now: Time, out: &mut Vec<SyncState>) {
        let valid = sample.valid;
        self.record_feedback(port, sample.clone());
        if self.inputs[port].feedback {
            self.flush(now, out);
            return;
        }
        if self.emitted_up_to.is_some_and(|e| valid <= e) {
            self.inputs[port].stats.count_drop(DropReason::LateForState);
            return;
        }
        let n = self.inputs.len();
        self.pending.entry(valid).or_insert_with(|| vec![None; n])[port] = Some(sample);
        self.flush(now, out);
    }

    /// Marks input `port` as ended (it will send nothing more).
    pub fn end(&mut self, port: usize, now: Time, out: &mut Vec<SyncState>) {
        self.ended[port] = true;
        self.flush(now, out);
    }

    /// Emits the states whose `max delay` has passed.
    pub fn on_timer(&mut self, now: Time, out: &mut Vec<SyncState>) {
        self.flush(now, out);
    }

    /// When a pending state's `max delay` will have passed.
    pub fn deadline(&self) -> Option<Time> {
        let (&t, values) = self.pending.iter().next()?;
        self.inputs
            .iter()
            .enumerate()
            .filter(|(i, input)| !input.feedback && values[*i].is_none())
            .filter_map(|(_, input)| input.max_delay.map(|d| t.saturating_add(d)))
            .max()
    }

    /// Emits every pending state, oldest first, as the inputs end.
    pub fn finish(&mut self, out: &mut Vec<SyncState>) {
        while let Some((t, values)) = self.pending.pop_first() {
            self.emit(t, values, out);
        }
    }

    /// Records a sample of a feedback input without releasing any state.
    pub fn record_feedback(&mut self, port: usize, sample: Sample) {
        let valid = sample.valid;
        let history = &mut self.history[port];
        let at = history.partition_point(|h| h.valid <= valid);
        history.insert(at, sample);
        self.seen_up_to[port] = Some(self.seen_up_to[port].map_or(valid, |s| s.max(valid)));
    }

    /// Whether input `port` is a feedback input.
    pub fn is_feedback(&self, port: usize) -> bool {
        self.inputs[port].feedback
    }

    /// The value a feedback input contributes to the state at `t`: its latest sample before `t`
    /// (the consumer's own output for `t` cannot exist yet).
    pub fn feedback_value(&self, port: usize, t: Time) -> Option<Sample> {
        let history = &self.history[port];
        let before = history.partition_point(|h| h.valid < t);
        before.checked_sub(1).and_then(|i| history.get(i)).cloned()
    }

    fn ready(&self, t: Time, values: &[Option<Sample>], now: Time) -> bool {
        self.inputs.iter().enumerate().all(|(i, input)| {
            input.feedback
                || values[i].is_some()
                || self.ended[i]
                || self.seen_up_to[i].is_some_and(|s| s > t)
                || input.max_delay.is_some_and(|d| now >= t.saturating_add(d))
        })
    }

    fn flush(&mut self, now: Time, out: &mut Vec<SyncState>) {
        while let Some((&t, values)) = self.pending.iter().next() {
            if !self.ready(t, values, now) {
                break;
            }
            let Some((t, values)) = self.pending.pop_first() else { break };
            self.emit(t, values, out);
        }
    }

    fn emit(&mut self, t: Time, mut values: Vec<Option<Sample>>, out: &mut Vec<SyncState>) {
        for (i, value) in values.iter_mut().enumerate() {
            let history = &mut self.history[i];
            // Keep the latest sample at or before t (for later states) and the newer ones.
            let upto = history.partition_point(|h| h.valid <= t);
            if upto > 1 {
                history.drain(..upto - 1);
            }
            if value.is_none() && (self.inputs[i].approximate || self.inputs[i].feedback) {
                // Approximate with the most recent value at or before t.
                *value = history.front().filter(|h| h.valid <= t).cloned();
                if value.is_some() {
                    self.inputs[i].stats.approximated.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
            }
        }
        self.emitted_up_to = Some(t);
        out.push(SyncState { valid: t, values });
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use kpl_core::Value;

    fn input(max_delay: Option<Time>) -> SyncInput {
        SyncInput { max_delay, approximate: false, stats: Arc::default(), feedback: false }
    }

    fn approximated(max_delay: Option<Time>) -> SyncInput {
        SyncInput { approximate: true, ..input(max_delay) }
    }

    fn s(t: Time, v: i64) -> Sample {
        Sample::new(t, t, Value::Int(v))
    }

    fn shape(states: &[SyncState]) -> Vec<(Time, Vec<Option<i64>>)> {
        states
            .iter()
            .map(|st| {
                (st.valid, st.values.iter().map(|v| v.as_ref().and_then(|s| s.value.as_i64())).collect())
            })
            .collect()
    }

    #[test]
    fn complete_states_are_emitted_at_once_in_order() {
        let mut sync = StateSync::new(vec![input(None), input(None)]);
        let mut out = Vec::new();
        sync.push(0, s(10, 1), 10, &mut out);
        assert!(out.is_empty());
        sync.push(1, s(10, 2), 10, &mut out);
        assert_eq!(shape(&out), [(10, vec![Some(1), Some(2)])]);
    }

    #[test]
    fn with_use_most_recent_a_missing_value_is_the_most_recent_one() {
        let mut sync = StateSync::new(vec![input(None), approximated(None)]);
        let mut out = Vec::new();
        sync.push(0, s(0, 1), 0, &mut out);
        sync.push(1, s(0, 5), 0, &mut out);
        sync.push(0, s(10, 2), 10, &mut out); // input 1 has no sample at 10 yet
        sync.push(1, s(20, 6), 20, &mut out); // now it has moved past 10
        assert_eq!(shape(&out), [(0, vec![Some(1), Some(5)]), (10, vec![Some(2), Some(5)])]);
        // The filled-in sample keeps its own valid time: the consumer sees it is older.
        assert_eq!(out[1].values[1].as_ref().map(|s| s.valid), Some(0));
        assert_eq!(sync.inputs[1].stats.approximated.load(std::sync::atomic::Ordering::Relaxed), 1);
    }

    #[test]
    fn without_approximation_a_missing_value_stays_missing() {
        let mut sync = StateSync::new(vec![input(None), input(None)]);
        let mut out = Vec::new();
        sync.push(0, s(0, 1), 0, &mut out);
        sync.push(1, s(0, 5), 0, &mut out);
        sync.push(0, s(10, 2), 10, &mut out);
        sync.push(1, s(20, 6), 20, &mut out);
        assert_eq!(shape(&out), [(0, vec![Some(1), Some(5)]), (10, vec![Some(2), None])]);
        assert_eq!(sync.inputs[1].stats.approximated.load(std::sync::atomic::Ordering::Relaxed), 0);
    }

    #[test]
    fn max_delay_releases_incomplete_states() {
        let mut sync = StateSync::new(vec![input(Some(50)), input(Some(50))]);
        let mut out = Vec::new();
        sync.push(0, s(100, 1), 100, &mut out);
        assert_eq!(sync.deadline(), Some(150));
        sync.on_timer(149, &mut out);
        assert!(out.is_empty());
        sync.on_timer(150, &mut out);
        assert_eq!(shape(&out), [(100, vec![Some(1), None])]);
        // A sample for 100 arriving now is late for its state.
        sync.push(1, s(100, 9), 160, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(sync.inputs[1].stats.dropped(DropReason::LateForState), 1);
    }

    #[test]
    fn feedback_inputs_are_not_waited_for() {
        let mut inputs = vec![input(None), input(None)];
        inputs[1].feedback = true;
        let mut sync = StateSync::new(inputs);
        let mut out = Vec::new();
        sync.push(0, s(0, 1), 0, &mut out);
        assert_eq!(shape(&out), [(0, vec![Some(1), None])]);
        sync.push(1, s(0, 7), 1, &mut out); // the consumer's own output for 0, fed back
        sync.push(0, s(10, 2), 10, &mut out);
        assert_eq!(shape(&out)[1], (10, vec![Some(2), Some(7)]));
    }
}
