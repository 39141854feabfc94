//! Matching a recorded object stream with the ground truth by valid time, into a [`Sequence`].
//!
//! A stream's snapshot at valid time t is compared with the ground truth's snapshot at the same
//! valid time t; nothing is interpolated. Only the times in both streams' spans are scored (a
//! recording may begin or end a frame apart: the link processes emit after the tracker). Inside
//! that span, a ground-truth time without a snapshot of the stream (a missing frame) and a
//! snapshot at a time without ground truth are errors unless [`Missing`] says what to do.
//!
//! Two filters choose the objects of a snapshot that are scored: branch objects (records with
//! `branch_of`, the other hypotheses of a prediction split at a junction) are left out unless
//! [`AlignOptions::score_branches`], and with [`AlignOptions::measured_only`] so are predicted
//! states. What each left out is counted in the [`Alignment`].

use std::collections::HashSet;

use kpl_core::Time;
use serde::Serialize;

use crate::error::AlignError;
use crate::recording::{ObjectStream, RecordedObject};
use crate::sequence::Sequence;

/// What to do with ground-truth times at which a stream has no snapshot.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Missing {
    /// Refuse to score the stream.
    #[default]
    Error,
    /// Score them as frames in which the stream saw nothing (every true object missed).
    Empty,
    /// Leave them out (and the stream's snapshots at times without ground truth).
    Skip,
}

/// How to align.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AlignOptions {
    pub missing: Missing,
    /// Compare boxes (`box`, in pixels) instead of positions: every record of both sides needs
    /// one.
    pub boxes: bool,
    /// Score every time of the ground truth, also before the stream's first snapshot and after
    /// its last (as frames in which the stream saw nothing): a tracker's file scored against a
    /// data set's ground truth.
    pub whole_truth: bool,
    /// Leave out the true objects the sensor could not see (records with `in_view: false`) and
    /// the hypotheses closest to them within `ignore_gate` (closest first, each once; a
    /// hypothesis closer to a true object in view is not left out): what lies outside a
    /// camera's view is neither a miss nor a false positive.
    pub in_view_only: bool,
    /// The gate of `in_view_only`: metres, or `1 - IoU` for boxes.
    pub ignore_gate: f64,
    /// Leave out the objects whose `measured` is false (states that were only predicted).
    pub measured_only: bool,
    /// Score branch objects (records with `branch_of`) as tracks of their own; by default they
    /// are left out: a branch object is one more hypothesis of where an object may be, not an
    /// object, and would be scored as false positives.
    pub score_branches: bool,
}

/// Whether predicted states were left out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "measured")]
pub enum MeasuredFilter {
    /// Not asked for: every object is scored.
    Off,
    /// Objects with `measured: false` were left out.
    Applied { left_out: usize },
    /// Asked for, but the stream's records have no `measured` field: every object is scored.
    NotAvailable,
}

/// What became of branch objects (records with `branch_of`) in the scored frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case", tag = "branches")]
pub enum BranchFilter {
    /// No record with `branch_of` was left out or scored in the scored frames.
    #[serde(rename = "none")]
    NoBranches,
    /// Their records were left out (the default).
    LeftOut { branch_states: usize, branch_objects: usize },
    /// Their records were scored as tracks of their own ([`AlignOptions::score_branches`]; with
    /// `measured_only` those are left out as predicted states, never measured, and not counted
    /// here).
    Scored { branch_states: usize, branch_objects: usize },
}

/// What aligning did, for the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Alignment {
    /// Frames scored.
    pub frames: usize,
    /// Valid time of the first and last frame scored, microseconds.
    pub from: Time,
    pub to: Time,
    /// Ground-truth times outside the stream's span (not scored).
    pub truth_outside: usize,
    /// Stream snapshots outside the ground truth's span (not scored).
    pub stream_outside: usize,
    /// Ground-truth times inside the span without a snapshot of the stream.
    pub missing: usize,
    pub missing_as: Missing,
    /// Stream snapshots inside the span at times without ground truth (not scored).
    pub extra: usize,
    /// Predicted states left out (a branch object left out is counted under `branches` only).
    #[serde(flatten)]
    pub measured: MeasuredFilter,
    #[serde(flatten)]
    pub branches: BranchFilter,
    /// With [`AlignOptions::in_view_only`]: what was left out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub out_of_view: Option<OutOfView>,
}

/// True objects out of the sensor's view and the hypotheses at them, left out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct OutOfView {
    pub truth: usize,
    pub hypotheses: usize,
}

/// Leaves out the true objects out of view and the hypotheses at them.
#[derive(Debug, Default)]
struct Ignored {
    truth: usize,
    hypotheses: usize,
}

impl Ignored {
    fn frame(
        &mut self,
        truths: &mut Vec<&RecordedObject>,
        hypotheses: &mut Vec<&RecordedObject>,
        options: &AlignOptions,
    ) {
        if truths.iter().all(|t| t.in_view != Some(false)) {
            return;
        }
        let distance = |t: &RecordedObject, h: &RecordedObject| match (options.boxes, t.bbox, h.bbox) {
            (true, Some(a), Some(b)) => {
                let iou = crate::sequence::iou(a, b);
                if iou > 0.0 { 1.0 - iou } else { f64::INFINITY }
            }
            _ => crate::sequence::distance(t.pos, h.pos),
        };
        let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
        for (i, t) in truths.iter().enumerate() {
            for (j, h) in hypotheses.iter().enumerate() {
                let d = distance(t, h);
                if d <= options.ignore_gate {
                    pairs.push((d, i, j));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let (mut truth_used, mut hyp_used) = (vec![false; truths.len()], vec![false; hypotheses.len()]);
        let mut drop_hyp = vec![false; hypotheses.len()];
        for (_, i, j) in pairs {
            if truth_used[i] || hyp_used[j] {
                continue;
            }
            truth_used[i] = true;
            hyp_used[j] = true;
            drop_hyp[j] = truths[i].in_view == Some(false);
        }
        let before = (truths.len(), hypotheses.len());
        truths.retain(|t| t.in_view != Some(false));
        let mut k = 0;
        hypotheses.retain(|_| {
            k += 1;
            !drop_hyp[k - 1]
        });
        self.truth += before.0 - truths.len();
        self.hypotheses += before.1 - hypotheses.len();
    }
}

/// A stream aligned with the ground truth.
#[derive(Debug, Clone)]
pub struct Aligned {
    pub sequence: Sequence,
    pub alignment: Alignment,
}

/// At most this many times are named in an error.
const FIRST: usize = 5;

/// Aligns `stream` with `truth` (both in increasing valid time, as [`crate::Recording`] gives them).
pub fn align(
    truth: &ObjectStream,
    stream: &ObjectStream,
    options: &AlignOptions,
) -> Result<Aligned, AlignError> {
    let span = |s: &ObjectStream| Some((s.snapshots.first()?.time, s.snapshots.last()?.time));
    let Some(truth_span) = span(truth) else { return Err(AlignError::Empty { stream: truth.name.clone() }) };
    let stream_span = match span(stream) {
        Some(span) => span,
        // A tracker that reported nothing still has every true object missed.
        None if options.whole_truth => truth_span,
        None => return Err(AlignError::Empty { stream: stream.name.clone() }),
    };
    if options.boxes {
        for (side, s) in [(truth, "ground truth"), (stream, "hypotheses")] {
            if let Some(o) = side.snapshots.iter().flat_map(|s| &s.objects).find(|o| o.bbox.is_none()) {
                return Err(AlignError::NoBox { stream: side.name.clone(), side: s, id: o.id.clone() });
            }
        }
    }
    let (from, to) = if options.whole_truth {
        truth_span
    } else {
        (stream_span.0.max(truth_span.0), stream_span.1.min(truth_span.1))
    };
    if from > to {
        return Err(AlignError::NoOverlap {
            stream: stream.name.clone(),
            truth: truth.name.clone(),
            stream_span,
            truth_span,
        });
    }
    let inside = |t: Time| from <= t && t <= to;
    let truth_in: Vec<_> = truth.snapshots.iter().filter(|s| inside(s.time)).collect();
    let stream_in: Vec<_> = stream.snapshots.iter().filter(|s| inside(s.time)).collect();

    // Walk both in time order.
    let (mut i, mut j) = (0, 0);
    let mut pairs = Vec::with_capacity(truth_in.len());
    let (mut missing, mut extra) = (Vec::new(), Vec::new());
    while i < truth_in.len() || j < stream_in.len() {
        match (truth_in.get(i), stream_in.get(j)) {
            (Some(t), Some(s)) if t.time == s.time => {
                pairs.push((*t, Some(*s)));
                i += 1;
                j += 1;
            }
            (Some(t), s) if s.is_none_or(|s| t.time < s.time) => {
                missing.push(t.time);
                pairs.push((*t, None));
                i += 1;
            }
            (_, Some(s)) => {
                extra.push(s.time);
                j += 1;
            }
            (_, None) => break,
        }
    }
    let missing_as = if options.whole_truth { Missing::Empty } else { options.missing };
    if missing_as == Missing::Error {
        if !extra.is_empty() {
            return Err(AlignError::ExtraTimes {
                stream: stream.name.clone(),
                truth: truth.name.clone(),
                count: extra.len(),
                first: extra.iter().copied().take(FIRST).collect(),
            });
        }
        if !missing.is_empty() {
            return Err(AlignError::MissingFrames {
                stream: stream.name.clone(),
                count: missing.len(),
                total: truth_in.len(),
                first: missing.iter().copied().take(FIRST).collect(),
                span: (from, to),
            });
        }
    }

    let mut filter = ObjectFilter::new(options, stream.has_measured);
    let mut sequence = Sequence::new();
    let mut scored: Vec<Time> = Vec::with_capacity(pairs.len());
    let mut ignored = Ignored::default();
    for (t, s) in pairs {
        if s.is_none() && missing_as == Missing::Skip {
            continue;
        }
        let mut hypotheses: Vec<&RecordedObject> =
            s.map(|s| s.objects.iter().filter(|o| filter.keep(o)).collect()).unwrap_or_default();
        let mut truths: Vec<&RecordedObject> = t.objects.iter().collect();
        if options.in_view_only {
            ignored.frame(&mut truths, &mut hypotheses, options);
        }
        let pushed = if options.boxes {
            let bbox = |o: &&RecordedObject| o.bbox.unwrap_or_default();
            sequence.push_frame_boxes(
                t.time,
                truths.iter().map(|o| (o.id.as_str(), bbox(o))),
                hypotheses.iter().map(|o| (o.id.as_str(), bbox(o))),
            )
        } else {
            sequence.push_frame(
                t.time,
                truths.iter().map(|o| (o.id.as_str(), o.pos)),
                hypotheses.iter().map(|o| (o.id.as_str(), o.pos)),
            )
        };
        pushed.map_err(|source| AlignError::Sequence { stream: stream.name.clone(), source })?;
        scored.push(t.time);
    }
    let measured = match (options.measured_only, stream.has_measured) {
        (false, _) => MeasuredFilter::Off,
        (true, true) => MeasuredFilter::Applied { left_out: filter.predicted },
        (true, false) => MeasuredFilter::NotAvailable,
    };
    let branches = filter.branches();
    let alignment = Alignment {
        frames: scored.len(),
        from: scored.first().copied().unwrap_or(from),
        to: scored.last().copied().unwrap_or(to),
        truth_outside: truth.snapshots.len() - truth_in.len(),
        stream_outside: stream.snapshots.len() - stream_in.len(),
        missing: missing.len(),
        missing_as,
        extra: extra.len(),
        measured,
        branches,
        out_of_view: options
            .in_view_only
            .then_some(OutOfView { truth: ignored.truth, hypotheses: ignored.hypotheses }),
    };
    Ok(Aligned { sequence, alignment })
}

/// Chooses the objects of the scored snapshots that are scored, and counts the others.
struct ObjectFilter<'a> {
    score_branches: bool,
    measured_only: bool,
    /// Predicted states left out.
    predicted: usize,
    branch_states: usize,
    branch_objects: HashSet<&'a str>,
}

impl<'a> ObjectFilter<'a> {
    fn new(options: &AlignOptions, has_measured: bool) -> ObjectFilter<'a> {
        ObjectFilter {
            score_branches: options.score_branches,
            measured_only: options.measured_only && has_measured,
            predicted: 0,
            branch_states: 0,
            branch_objects: HashSet::new(),
        }
    }

    /// Whether `object` is scored. A branch object left out is counted as such; one scored
    /// (`score_branches`) is still subject to `measured_only`, and counted as a branch only when
    /// it is scored.
    fn keep(&mut self, object: &'a RecordedObject) -> bool {
        let branch = object.branch_of.is_some();
        if branch && !self.score_branches {
            self.count_branch(object);
            return false;
        }
        if self.measured_only && object.measured == Some(false) {
            self.predicted += 1;
            return false;
        }
        if branch {
            self.count_branch(object);
        }
        true
    }

    fn count_branch(&mut self, object: &'a RecordedObject) {
        self.branch_states += 1;
        self.branch_objects.insert(&object.id);
    }

    fn branches(&self) -> BranchFilter {
        let (branch_states, branch_objects) = (self.branch_states, self.branch_objects.len());
        match (branch_states, self.score_branches) {
            (0, _) => BranchFilter::NoBranches,
            (_, false) => BranchFilter::LeftOut { branch_states, branch_objects },
            (_, true) => BranchFilter::Scored { branch_states, branch_objects },
        }
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use serde_json::json;

    use super::*;
    use crate::recording::Recording;
    use crate::scores::{Config, score};

    /// Two frames: the true car1, its on-road object oo3 (measured, then predicted) and, in the
    /// second frame, oo9, a branch object of oo3 within the gate of car1 and predicted, as the
    /// anchoring writes them.
    const SPLIT: &str = concat!(
        r#"{"stream":"truth","valid":0,"value":[{"id":"car1","pos":[0.0,0.0]}]}"#,
        "\n",
        r#"{"stream":"truth","valid":100000,"value":[{"id":"car1","pos":[1.0,0.0]}]}"#,
        "\n",
        r#"{"stream":"onroad","valid":0,"value":[{"id":"oo3","pos":[0.5,0.0],"measured":true}]}"#,
        "\n",
        r#"{"stream":"onroad","valid":100000,"value":[{"id":"oo3","pos":[1.5,0.0],"measured":false,"likelihood":0.6},{"id":"oo9","pos":[1.0,1.0],"measured":false,"likelihood":0.4,"branch_of":"oo3"}]}"#,
        "\n",
    );

    fn aligned(text: &str, options: AlignOptions) -> Aligned {
        let rec = Recording::read_from(Path::new("rec.jsonl"), text.as_bytes()).unwrap();
        assert_eq!(rec.problems().count, 0, "{:?}", rec.problems());
        align(rec.stream("truth").unwrap(), rec.stream("onroad").unwrap(), &options).unwrap()
    }

    fn hypotheses(a: &Aligned) -> Vec<Vec<&str>> {
        let ids = a.sequence.hypothesis_ids();
        a.sequence.frames().iter().map(|f| f.hypotheses.iter().map(|h| ids.name(h.id)).collect()).collect()
    }

    #[test]
    fn branch_objects_are_left_out_and_counted() {
        let a = aligned(SPLIT, AlignOptions::default());
        assert_eq!(hypotheses(&a), [vec!["oo3"], vec!["oo3"]]);
        assert_eq!(a.alignment.branches, BranchFilter::LeftOut { branch_states: 1, branch_objects: 1 });
        assert_eq!(a.alignment.measured, MeasuredFilter::Off);
        let scores = score(&a.sequence, &Config::new(3.0).unwrap());
        assert_eq!(scores.clear.false_positives, 0);
        assert_eq!(scores.clear.mota, 1.0);
        let json = serde_json::to_value(&a.alignment).unwrap();
        assert_eq!(json["branches"], json!("left_out"));
        assert_eq!(json["branch_states"], json!(1));
        assert_eq!(json["branch_objects"], json!(1));
        assert_eq!(json["measured"], json!("off"));
    }

    #[test]
    fn branch_objects_are_scored_as_tracks_when_asked() {
        let options = AlignOptions { score_branches: true, ..AlignOptions::default() };
        let a = aligned(SPLIT, options);
        assert_eq!(hypotheses(&a), [vec!["oo3"], vec!["oo3", "oo9"]]);
        assert_eq!(a.alignment.branches, BranchFilter::Scored { branch_states: 1, branch_objects: 1 });
        let scores = score(&a.sequence, &Config::new(3.0).unwrap());
        assert_eq!(scores.clear.false_positives, 1, "the branch object is a false positive");
        assert_eq!(serde_json::to_value(&a.alignment).unwrap()["branches"], json!("scored"));
    }

    #[test]
    fn predicted_states_and_branch_objects_are_counted_once() {
        // By default the branch object is left out as a branch, not as a predicted state.
        let measured_only = AlignOptions { measured_only: true, ..AlignOptions::default() };
        let a = aligned(SPLIT, measured_only);
        assert_eq!(hypotheses(&a), [vec!["oo3"], vec![]]);
        assert_eq!(a.alignment.measured, MeasuredFilter::Applied { left_out: 1 });
        assert_eq!(a.alignment.branches, BranchFilter::LeftOut { branch_states: 1, branch_objects: 1 });
        // Asked to score branch objects, the predicted-only filter still leaves them out (they are
        // never measured), and they count as predicted states.
        let both = AlignOptions { measured_only: true, score_branches: true, ..AlignOptions::default() };
        let a = aligned(SPLIT, both);
        assert_eq!(hypotheses(&a), [vec!["oo3"], vec![]]);
        assert_eq!(a.alignment.measured, MeasuredFilter::Applied { left_out: 2 });
        assert_eq!(a.alignment.branches, BranchFilter::NoBranches);
    }

    #[test]
    fn a_stream_without_branch_objects_says_nothing() {
        let plain = SPLIT.replace(r#","branch_of":"oo3""#, "");
        for score_branches in [false, true] {
            let a = aligned(&plain, AlignOptions { score_branches, ..AlignOptions::default() });
            assert_eq!(hypotheses(&a), [vec!["oo3"], vec!["oo3", "oo9"]]);
            assert_eq!(a.alignment.branches, BranchFilter::NoBranches);
            let json = serde_json::to_value(&a.alignment).unwrap();
            assert_eq!(json["branches"], json!("none"));
            assert!(json.get("branch_states").is_none());
        }
    }

    #[test]
    fn branch_objects_of_frames_not_scored_are_not_counted() {
        // The branch object's snapshot is past the ground truth's span: nothing is left out.
        let truth_ends = SPLIT.lines().filter(|l| !l.contains(r#""stream":"truth","valid":100000"#));
        let text: String = truth_ends.map(|l| format!("{l}\n")).collect();
        let a = aligned(&text, AlignOptions::default());
        assert_eq!(a.alignment.frames, 1);
        assert_eq!(a.alignment.branches, BranchFilter::NoBranches);
    }
}
