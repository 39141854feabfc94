//! The CLEAR MOT metrics (Bernardin and Stiefelhagen, 2008) with py-motmetrics' definitions:
//! MOTA, MOTP, identity switches, fragmentations, mostly tracked / partially tracked / mostly
//! lost, precision and recall.
//!
//! Per frame, as py-motmetrics' `MOTAccumulator.update`:
//! 1. each true object (in the frame's order) whose last matched hypothesis is present, not yet
//!    taken and within the gate keeps it (a match, never a switch);
//! 2. the remaining pairs within the gate are matched, as many as possible and then with the
//!    smallest total distance; a true object matched to another hypothesis than the one it was
//!    last matched to (in any earlier frame) is an identity switch;
//! 3. true objects left are misses, hypotheses left false positives.
//!
//! MOTA = 1 − (misses + false positives + switches) / true objects; MOTP is the mean distance of
//! the matched pairs, in metres (lower is better); a fragmentation is a run of misses of a true
//! object between two frames in which it was tracked; an object is mostly tracked when matched in
//! at least 80 % of the frames it is in, mostly lost when in less than 20 %.

use serde::Serialize;

use crate::assign::{self, Edge};
use crate::ratio::serialize_ratio;
use crate::sequence::{Frame, Pair};

/// The CLEAR MOT metrics of a sequence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClearMot {
    /// Frames scored.
    pub frames: usize,
    /// True objects over all frames (py-motmetrics' `num_objects`).
    pub objects: usize,
    /// Hypotheses over all frames (`num_predictions`).
    pub predictions: usize,
    /// Distinct true objects.
    pub unique_objects: usize,
    /// Matches that are not switches (`num_matches`).
    pub matches: usize,
    /// Identity switches (`num_switches`).
    pub switches: usize,
    pub false_positives: usize,
    pub misses: usize,
    pub fragmentations: usize,
    pub mostly_tracked: usize,
    pub partially_tracked: usize,
    pub mostly_lost: usize,
    /// 1 − (misses + false positives + switches) / objects; not a number without true objects.
    #[serde(serialize_with = "serialize_ratio")]
    pub mota: f64,
    /// Mean distance of the matched pairs, metres; not a number without matches.
    #[serde(serialize_with = "serialize_ratio")]
    pub motp: f64,
    /// Matched / hypotheses.
    #[serde(serialize_with = "serialize_ratio")]
    pub precision: f64,
    /// Matched / true objects.
    #[serde(serialize_with = "serialize_ratio")]
    pub recall: f64,
}

impl ClearMot {
    /// Matched pairs, switches included (`num_detections`).
    pub fn detections(&self) -> usize {
        self.matches + self.switches
    }
}

/// One matched pair of a frame, by interned ids.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Match {
    pub truth: u32,
    pub hypothesis: u32,
    pub distance: f64,
    /// The true object was last matched to another hypothesis.
    pub switch: bool,
}

/// What a true object's frames looked like so far.
#[derive(Debug, Clone, Copy, Default)]
struct Track {
    present: usize,
    tracked: usize,
    /// The hypothesis it was last matched to.
    last: Option<u32>,
    /// Missed since it was last tracked (a fragment ends if it is tracked again).
    in_gap: bool,
}

/// The CLEAR MOT state, fed one frame at a time.
#[derive(Debug, Clone, Default)]
pub(crate) struct Clear {
    tracks: Vec<Track>,
    frames: usize,
    objects: usize,
    predictions: usize,
    matches: usize,
    switches: usize,
    false_positives: usize,
    misses: usize,
    fragmentations: usize,
    distance_sum: f64,
    // Scratch space kept between frames.
    hypothesis_slot: Vec<usize>,
    edges: Vec<Edge>,
}

const NONE: usize = usize::MAX;

impl Clear {
    pub(crate) fn new(truth_ids: usize, hypothesis_ids: usize) -> Clear {
        Clear {
            tracks: vec![Track::default(); truth_ids],
            hypothesis_slot: vec![NONE; hypothesis_ids],
            ..Clear::default()
        }
    }

    /// Scores one frame given its pairs within the gate (ordered by true object, then
    /// hypothesis, as [`Frame::pairs_within`] gives them); appends the frame's matches to `out`.
    pub(crate) fn frame(&mut self, frame: &Frame, gated: &[Pair], out: &mut Vec<Match>) {
        let first_match = out.len();
        self.frames += 1;
        self.objects += frame.truth.len();
        self.predictions += frame.hypotheses.len();
        let mut truth_taken = vec![false; frame.truth.len()];
        let mut hypothesis_taken = vec![false; frame.hypotheses.len()];
        // Where each true object's pairs start in `gated`.
        let mut starts = vec![gated.len(); frame.truth.len() + 1];
        for (k, p) in gated.iter().enumerate().rev() {
            starts[p.truth] = k;
        }
        for i in (0..frame.truth.len()).rev() {
            starts[i] = starts[i].min(starts[i + 1]);
        }
        for (j, h) in frame.hypotheses.iter().enumerate() {
            self.hypothesis_slot[h.id as usize] = j;
        }

        // 1. Keep last frame's correspondences that are still within the gate.
        for (i, t) in frame.truth.iter().enumerate() {
            let Some(previous) = self.tracks[t.id as usize].last else { continue };
            let j = self.hypothesis_slot[previous as usize];
            if j == NONE || hypothesis_taken[j] {
                continue;
            }
            let pairs = &gated[starts[i]..starts[i + 1]];
            if let Ok(k) = pairs.binary_search_by_key(&j, |p| p.hypothesis) {
                truth_taken[i] = true;
                hypothesis_taken[j] = true;
                out.push(Match {
                    truth: t.id,
                    hypothesis: previous,
                    distance: pairs[k].distance,
                    switch: false,
                });
            }
        }

        // 2. The most pairs with the least total distance among the rest.
        self.edges.clear();
        self.edges.extend(
            gated.iter().filter(|p| !truth_taken[p.truth] && !hypothesis_taken[p.hypothesis]).map(|p| Edge {
                row: p.truth,
                col: p.hypothesis,
                value: p.distance,
            }),
        );
        for (i, j) in assign::gated(frame.truth.len(), frame.hypotheses.len(), &self.edges) {
            let (t, h) = (frame.truth[i].id, frame.hypotheses[j].id);
            let pairs = &gated[starts[i]..starts[i + 1]];
            let distance = pairs.iter().find(|p| p.hypothesis == j).map_or(f64::NAN, |p| p.distance);
            let switch = self.tracks[t as usize].last.is_some_and(|last| last != h);
            truth_taken[i] = true;
            hypothesis_taken[j] = true;
            out.push(Match { truth: t, hypothesis: h, distance, switch });
        }

        // 3. Count, and carry each true object's state on.
        for m in &out[first_match..] {
            if m.switch {
                self.switches += 1;
            } else {
                self.matches += 1;
            }
            self.distance_sum += m.distance;
            self.tracks[m.truth as usize].last = Some(m.hypothesis);
        }
        for (i, t) in frame.truth.iter().enumerate() {
            let track = &mut self.tracks[t.id as usize];
            track.present += 1;
            if truth_taken[i] {
                if track.in_gap {
                    self.fragmentations += 1;
                    track.in_gap = false;
                }
                track.tracked += 1;
            } else {
                self.misses += 1;
                track.in_gap = track.tracked > 0;
            }
        }
        self.false_positives += hypothesis_taken.iter().filter(|taken| !**taken).count();
        for h in &frame.hypotheses {
            self.hypothesis_slot[h.id as usize] = NONE;
        }
    }

    pub(crate) fn finish(&self) -> ClearMot {
        let (mut mostly_tracked, mut partially_tracked, mut mostly_lost) = (0, 0, 0);
        let mut unique_objects = 0;
        for track in self.tracks.iter().filter(|t| t.present > 0) {
            unique_objects += 1;
            let ratio = track.tracked as f64 / track.present as f64;
            if ratio >= 0.8 {
                mostly_tracked += 1;
            } else if ratio >= 0.2 {
                partially_tracked += 1;
            } else {
                mostly_lost += 1;
            }
        }
        let detections = (self.matches + self.switches) as f64;
        let objects = self.objects as f64;
        ClearMot {
            frames: self.frames,
            objects: self.objects,
            predictions: self.predictions,
            unique_objects,
            matches: self.matches,
            switches: self.switches,
            false_positives: self.false_positives,
            misses: self.misses,
            fragmentations: self.fragmentations,
            mostly_tracked,
            partially_tracked,
            mostly_lost,
            mota: 1.0 - (self.misses + self.switches + self.false_positives) as f64 / objects,
            motp: self.distance_sum / detections,
            precision: detections / (self.false_positives as f64 + detections),
            recall: detections / objects,
        }
    }
}
