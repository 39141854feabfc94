//! "Did you mean ...?" hints from the names that exist: the one implementation every layer uses
//! (names in specs, formulas, streams of a recording, plots).
//!
//! A hint costs little even when a spec has many unknown names and many names: one pass over a
//! candidate's letters rules most of them out without computing the distance
//! (Damerau-Levenshtein's distance is at least the difference of the lengths, and at least the
//! number of letters of either name that the other lacks), and at most [`MAX_COMPARED`]
//! candidates are compared in full for one name. And the hints of one check cost at most
//! [`HINT_BUDGET`] in all ([`with_budget`], [`candidates`]): a spec with tens of thousands of
//! unknown names among tens of thousands of names is checked in linear time, its first unknown
//! names with hints and the others without.

use std::cell::Cell;

/// Most candidates whose distance to one name is computed in full; the others are not looked at.
pub const MAX_COMPARED: usize = 1_000;

/// What the hints of one check may cost in all: a candidate listed costs 1, a candidate compared
/// in full [`COMPARE_COST`].
pub const HINT_BUDGET: usize = 10_000_000;

/// What comparing a candidate in full costs of [`HINT_BUDGET`] (it takes some fifty times as long
/// as passing over one).
const COMPARE_COST: usize = 50;

thread_local! {
    /// What is left of the budget of the check running on this thread (`None`: no check runs).
    static BUDGET: Cell<Option<usize>> = const { Cell::new(None) };
}

/// Runs `check` with a budget of [`HINT_BUDGET`] candidates for its hints.
pub fn with_budget<R>(check: impl FnOnce() -> R) -> R {
    /// Gives the outer budget back however `check` ends.
    struct Restore(Option<usize>);
    impl Drop for Restore {
        fn drop(&mut self) {
            BUDGET.set(self.0);
        }
    }
    let _restore = Restore(BUDGET.replace(Some(HINT_BUDGET)));
    check()
}

/// The candidates of a hint, or none once the running check's budget cannot pay for them (then
/// no later hint of that check gets any). Outside a check, always all of them.
pub fn candidates<'n>(names: impl Iterator<Item = &'n str>) -> Vec<&'n str> {
    let (low, high) = names.size_hint();
    if spend(high.unwrap_or(low)) { names.collect() } else { Vec::new() }
}

/// Takes `cost` from the running check's budget, if it has that much left (else it has nothing
/// left from now on). Outside a check everything is paid for.
fn spend(cost: usize) -> bool {
    BUDGET.with(|budget| match budget.get() {
        None => true,
        Some(left) if left >= cost => {
            budget.set(Some(left - cost));
            true
        }
        Some(_) => {
            budget.set(Some(0));
            false
        }
    })
}

/// The closest candidate to `name`, if one is close enough to be a likely typo (case is ignored;
/// on a tie the candidate first in alphabetical order).
pub fn closest<'a>(name: &str, candidates: &[&'a str]) -> Option<&'a str> {
    let lower: Vec<char> = name.chars().flat_map(char::to_lowercase).collect();
    let limit = (name.chars().count() / 3).max(1);
    let letters = lower.iter().fold(0u64, |mask, &c| mask | kind(c));
    let mut best: Option<(usize, &'a str)> = None;
    let mut compared = 0;
    for &candidate in candidates {
        if candidate == name || !within_bounds(&lower, letters, candidate, limit) {
            continue;
        }
        if compared == MAX_COMPARED || !spend(COMPARE_COST) {
            break;
        }
        compared += 1;
        let other: Vec<char> = candidate.chars().flat_map(char::to_lowercase).collect();
        let distance = strsim::generic_damerau_levenshtein(&lower, &other);
        if distance <= limit && best.is_none_or(|best| (distance, candidate) < best) {
            best = Some((distance, candidate));
        }
    }
    best.map(|(_, c)| c)
}

/// One of 64 kinds of letter, as a bit (letters folded together only weaken the bounds below,
/// which stay bounds).
fn kind(c: char) -> u64 {
    1 << (c as u32 % 64)
}

/// Whether `candidate` may be within `limit` edits of `name` (`lower`, its letters `letters`), by
/// bounds that cost one pass over it: an edit changes the length by at most one, and each letter
/// of one name whose kind the other lacks needs an edit of its own (an insertion, a deletion or a
/// substitution; a transposition brings no new letter).
fn within_bounds(lower: &[char], letters: u64, candidate: &str, limit: usize) -> bool {
    let (mut len, mut missing, mut candidate_letters) = (0, 0, 0u64);
    for c in candidate.chars().flat_map(char::to_lowercase) {
        len += 1;
        candidate_letters |= kind(c);
        if letters & kind(c) == 0 {
            missing += 1;
            if missing > limit {
                return false;
            }
        }
        if len > lower.len() + limit {
            return false;
        }
    }
    let missing_there = lower.iter().filter(|&&c| candidate_letters & kind(c) == 0).count();
    len + limit >= lower.len() && missing_there <= limit
}

/// `Some("did you mean `x`?")` when a candidate is close to `name`.
pub fn did_you_mean(name: &str, candidates: &[&str]) -> Option<String> {
    closest(name, candidates).map(|c| format!("did you mean `{c}`?"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggests_close_names_only() {
        let names = ["percepts", "tracker", "world_onroad"];
        assert_eq!(closest("percept", &names), Some("percepts"));
        assert_eq!(closest("Tracker", &names), Some("tracker"));
        assert_eq!(closest("world_onraod", &names), Some("world_onroad"));
        assert_eq!(closest("zzz", &names), None);
        assert_eq!(closest("a", &["b"]), Some("b"));
        // A tie goes to the first in alphabetical order, whatever the order given.
        assert_eq!(closest("cat", &["hat", "bat"]), Some("bat"));
    }

    /// Every candidate compared in full, as the hint was computed before the bounds.
    fn full<'a>(name: &str, candidates: &[&'a str]) -> Option<&'a str> {
        let limit = (name.chars().count() / 3).max(1);
        candidates
            .iter()
            .filter(|c| **c != name)
            .map(|c| (strsim::damerau_levenshtein(&name.to_lowercase(), &c.to_lowercase()), *c))
            .filter(|(distance, _)| *distance <= limit)
            .min()
            .map(|(_, c)| c)
    }

    proptest::proptest! {
        /// The bounds only skip what the distance would reject: the same hints as comparing every
        /// candidate in full.
        #[test]
        fn the_bounds_never_change_a_hint(
            name in "[abAB_1éß]{0,9}",
            candidates in proptest::collection::vec("[abAB_1éß]{0,9}", 0..40),
        ) {
            let candidates: Vec<&str> = candidates.iter().map(String::as_str).collect();
            proptest::prop_assert_eq!(closest(&name, &candidates), full(&name, &candidates));
        }
    }

    #[test]
    fn the_bounds_never_change_a_hint_on_real_names() {
        let words = [
            "percepts",
            "percept",
            "tracker",
            "Tracker",
            "trakcer",
            "world_onroad",
            "world_onraod",
            "a",
            "b",
            "ab",
            "ba",
            "abc",
            "cab",
            "xydist",
            "xy_dist",
            "dist",
            "speed",
            "sped",
            "spede",
            "Äpfel",
            "äpfel",
            "straße",
            "STRASSE",
            "car_12",
            "car_21",
            "car_2",
            "",
            "x",
        ];
        for name in words {
            assert_eq!(closest(name, &words), full(name, &words), "{name}");
        }
    }

    #[test]
    fn a_check_pays_for_at_most_its_budget_of_candidates() {
        let names = ["percepts", "tracker", "world_onroad"];
        let (listed, hint_before, hint_after) = with_budget(|| {
            // A check that has spent all but 4 of its budget: one list of 3 is paid for, then
            // the hint's full comparison is not, and after that nothing.
            assert!(spend(HINT_BUDGET - 4));
            let listed = candidates(names.into_iter()).len();
            let hint_before = closest("percept", &names);
            (listed, hint_before, candidates(names.into_iter()).len())
        });
        assert_eq!((listed, hint_before, hint_after), (3, None, 0));
        // Outside a check, and in the next one, everything is paid for again.
        assert_eq!(candidates(names.into_iter()).len(), 3);
        assert_eq!(with_budget(|| closest("percept", &candidates(names.into_iter()))), Some("percepts"));
    }

    #[test]
    fn a_typo_among_thousands_of_similar_names() {
        let names: Vec<String> = (0..5 * MAX_COMPARED).map(|i| format!("n{:05}", i)).collect();
        let candidates: Vec<&str> = names.iter().map(String::as_str).collect();
        assert_eq!(closest("n00001x", &candidates), Some("n00001"));
        assert!(closest("zzzzzz", &candidates).is_none());
    }
}
