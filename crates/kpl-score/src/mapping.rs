//! Which hypothesis stands for which true object, over time: the anchoring's ground-truth
//! mapping (symbol `co3` is car `car7` from 12.3 s to 20.1 s).
//!
//! The mapping is the CLEAR MOT matching (see [`crate::clear`]): per frame, each true object is
//! matched to at most one hypothesis and each hypothesis to at most one true object within the
//! gate. Consecutive scored frames in which the same pair is matched make one [`Correspondence`]
//! interval. Scoring whatever refers to symbols (situations that name objects, for example) goes
//! through [`Mapping::truth_of`]: the true object a symbol stood for at a time.
//!
//! [`IdentityAssignment`] is the other, global, view: the one-to-one pairing of whole
//! trajectories behind IDF1.

use std::collections::HashMap;

use kpl_core::Time;
use serde::Serialize;

use crate::clear::Match;
use crate::sequence::Sequence;

/// A hypothesis matched to one true object in consecutive scored frames.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Correspondence {
    pub hypothesis: String,
    pub truth: String,
    /// Valid times of the first and last frame, microseconds (inclusive).
    pub from: Time,
    pub to: Time,
    /// Frames in the interval.
    pub frames: usize,
}

/// The correspondences of a sequence, ordered by hypothesis then time.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Mapping {
    correspondences: Vec<Correspondence>,
    by_hypothesis: HashMap<String, (usize, usize)>,
    by_truth: HashMap<String, Vec<usize>>,
}

impl Mapping {
    /// Builds the intervals from each frame's matches (`matches[k]` are frame k's).
    pub(crate) fn from_matches(sequence: &Sequence, matches: &[Vec<Match>]) -> Mapping {
        // Open interval per (hypothesis id): (truth id, index of the last frame, from, frames).
        let mut open: HashMap<u32, (u32, usize, Time, usize)> = HashMap::new();
        let mut closed: Vec<(u32, u32, Time, Time, usize)> = Vec::new();
        let frames = sequence.frames();
        for (k, (frame, frame_matches)) in frames.iter().zip(matches).enumerate() {
            for m in frame_matches {
                match open.get_mut(&m.hypothesis) {
                    Some(o) if o.0 == m.truth && o.1 + 1 == k => {
                        o.1 = k;
                        o.3 += 1;
                    }
                    _ => {
                        if let Some((truth, last, from, n)) =
                            open.insert(m.hypothesis, (m.truth, k, frame.time, 1))
                        {
                            closed.push((m.hypothesis, truth, from, frames[last].time, n));
                        }
                    }
                }
            }
        }
        for (hypothesis, (truth, last, from, n)) in open {
            closed.push((hypothesis, truth, from, frames[last].time, n));
        }
        let hyp_ids = sequence.hypothesis_ids();
        let truth_ids = sequence.truth_ids();
        let mut correspondences: Vec<Correspondence> = closed
            .into_iter()
            .map(|(h, t, from, to, frames)| Correspondence {
                hypothesis: hyp_ids.name(h).to_string(),
                truth: truth_ids.name(t).to_string(),
                from,
                to,
                frames,
            })
            .collect();
        correspondences.sort_by(|a, b| a.hypothesis.cmp(&b.hypothesis).then(a.from.cmp(&b.from)));
        let mut by_hypothesis: HashMap<String, (usize, usize)> = HashMap::new();
        let mut by_truth: HashMap<String, Vec<usize>> = HashMap::new();
        for (k, c) in correspondences.iter().enumerate() {
            by_hypothesis.entry(c.hypothesis.clone()).and_modify(|r| r.1 = k + 1).or_insert((k, k + 1));
            by_truth.entry(c.truth.clone()).or_default().push(k);
        }
        for list in by_truth.values_mut() {
            list.sort_by_key(|&k| correspondences[k].from);
        }
        Mapping { correspondences, by_hypothesis, by_truth }
    }

    /// Every interval, ordered by hypothesis then time.
    pub fn correspondences(&self) -> &[Correspondence] {
        &self.correspondences
    }

    /// The intervals of one hypothesis, in time order.
    pub fn of_hypothesis(&self, hypothesis: &str) -> &[Correspondence] {
        self.by_hypothesis.get(hypothesis).map_or(&[], |&(a, b)| &self.correspondences[a..b])
    }

    /// The intervals of one true object, in time order.
    pub fn of_truth(&self, truth: &str) -> impl Iterator<Item = &Correspondence> {
        self.by_truth.get(truth).into_iter().flatten().map(|&k| &self.correspondences[k])
    }

    /// The true object `hypothesis` stood for at `time` (inside one of its intervals).
    pub fn truth_of(&self, hypothesis: &str, time: Time) -> Option<&str> {
        let list = self.of_hypothesis(hypothesis);
        let k = list.partition_point(|c| c.to < time);
        list.get(k).filter(|c| c.from <= time).map(|c| c.truth.as_str())
    }

    /// The hypothesis that stood for `truth` at `time`.
    pub fn hypothesis_of(&self, truth: &str, time: Time) -> Option<&str> {
        self.of_truth(truth).find(|c| c.from <= time && time <= c.to).map(|c| c.hypothesis.as_str())
    }
}

/// One pair of the global identity assignment, by name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct IdentityPair {
    pub truth: String,
    pub hypothesis: String,
    /// Frames in which the two were within the gate (their IDTP).
    pub frames: usize,
}

/// The one-to-one pairing of whole trajectories that IDF1 scores, ordered by true object.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct IdentityAssignment {
    pub pairs: Vec<IdentityPair>,
}

impl IdentityAssignment {
    /// The hypothesis trajectory assigned to a true one.
    pub fn hypothesis_of(&self, truth: &str) -> Option<&str> {
        self.pairs.iter().find(|p| p.truth == truth).map(|p| p.hypothesis.as_str())
    }

    /// The true trajectory assigned to a hypothesis.
    pub fn truth_of(&self, hypothesis: &str) -> Option<&str> {
        self.pairs.iter().find(|p| p.hypothesis == hypothesis).map(|p| p.truth.as_str())
    }
}
