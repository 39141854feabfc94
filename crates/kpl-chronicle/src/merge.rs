//! One report per situation: a chronicle's recognitions merged where they tell of the same one.
//!
//! Every distinct choice of event occurrences is a recognition (DyKnow's semantics, and
//! [`crate::recognise`]'s), so an overtake whose `beside` or `in_front` relation flickers under a
//! tracker's noise is recognised once per flicker: the same cars, the same first event, ends a
//! few tenths of a second apart. [`Merge`] keeps, per chronicle and binding, the time span of the
//! recognition it let through last, and lets a later one through only if it starts after that
//! span ended; the others are counted ([`Merge::merged`]). The recogniser is unchanged: the
//! recognitions a chronicle uses as events of another are all there.
//!
//! Memory: one entry per chronicle and binding whose last span ended within the longest window
//! of the chronicles (an older one cannot overlap anything still to come, whose start is at most
//! a window before its end); entries are dropped as time passes.
//!
//! ```
//! use kpl_chronicle::merge::Merge;
//! use kpl_chronicle::recognise::Recognition;
//! let r = |times: Vec<i64>| Recognition { chronicle: 0, binding: vec!["co1", "co2"], valid_time: times[2], times };
//! let mut merge = Merge::new(60_000_000);
//! assert!(merge.admit(&r(vec![0, 5_000_000, 9_000_000])));
//! // `front` flickered: the same overtake, recognised again half a second later
//! assert!(!merge.admit(&r(vec![0, 5_000_000, 9_500_000])));
//! // a second overtake of the same car, after the first one ended
//! assert!(merge.admit(&r(vec![30_000_000, 33_000_000, 38_000_000])));
//! assert_eq!(merge.merged(), 1);
//! ```

use std::collections::HashMap;
use std::hash::Hash;

use kpl_core::Time;

use crate::recognise::Recognition;

/// Merges recognitions of the same situation (module doc).
#[derive(Debug)]
pub struct Merge<O> {
    /// (chronicle, binding) -> the end of the last span let through.
    ends: HashMap<(usize, Vec<O>), Time>,
    window: Time,
    merged: u64,
    /// The last valid time seen, and when entries were last pruned.
    now: Time,
    pruned: Time,
}

impl<O: Clone + Eq + Hash> Merge<O> {
    /// For chronicles whose longest window (time between their first and last event) is `window`.
    pub fn new(window: Time) -> Merge<O> {
        Merge { ends: HashMap::new(), window: window.max(0), merged: 0, now: Time::MIN, pruned: Time::MIN }
    }

    /// Whether `r` tells of a situation not reported yet: no recognition of its chronicle and
    /// binding let through before has a span that reaches its start. Recognitions come in the
    /// order of their valid times.
    pub fn admit(&mut self, r: &Recognition<O>) -> bool {
        let start = r.times.iter().copied().min().unwrap_or(r.valid_time);
        let end = r.valid_time;
        self.now = self.now.max(end);
        self.prune();
        let key = (r.chronicle, r.binding.clone());
        match self.ends.get_mut(&key) {
            Some(last) if start <= *last => {
                *last = (*last).max(end);
                self.merged += 1;
                false
            }
            Some(last) => {
                *last = end;
                true
            }
            None => {
                self.ends.insert(key, end);
                true
            }
        }
    }

    /// Recognitions merged into an earlier one so far.
    pub fn merged(&self) -> u64 {
        self.merged
    }

    /// Drops the spans that nothing still to come can reach (once per window of time).
    fn prune(&mut self) {
        if self.now.saturating_sub(self.pruned) < self.window.max(1) {
            return;
        }
        let oldest = self.now.saturating_sub(self.window);
        self.ends.retain(|_, end| *end >= oldest);
        self.pruned = self.now;
    }

    /// Entries kept now (for tests of the memory bound).
    pub fn len(&self) -> usize {
        self.ends.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(chronicle: usize, binding: [&'static str; 2], start: Time, end: Time) -> Recognition<&'static str> {
        Recognition { chronicle, binding: binding.to_vec(), times: vec![start, end], valid_time: end }
    }

    #[test]
    fn overlapping_recognitions_of_one_binding_are_one_situation() {
        let mut m = Merge::new(60);
        assert!(m.admit(&r(0, ["a", "b"], 0, 10)));
        assert!(!m.admit(&r(0, ["a", "b"], 0, 12)));
        // The merged span reaches 12 now: one starting at 11 is the same situation still.
        assert!(!m.admit(&r(0, ["a", "b"], 11, 14)));
        assert!(m.admit(&r(0, ["a", "b"], 15, 20)));
        // Another binding, another chronicle, the other order of the same cars: not merged.
        assert!(m.admit(&r(0, ["b", "a"], 0, 20)));
        assert!(m.admit(&r(1, ["a", "b"], 0, 20)));
        assert_eq!(m.merged(), 2);
    }

    #[test]
    fn spans_older_than_the_window_are_forgotten() {
        let mut m = Merge::new(10);
        for k in 0..1_000 {
            let name: &'static str = Box::leak(format!("co{k}").into_boxed_str());
            assert!(m.admit(&r(0, [name, "x"], k * 5, k * 5 + 1)));
        }
        // Only the spans of the last window (and a window before the last pruning) remain.
        assert!(m.len() <= 5, "{}", m.len());
    }
}
