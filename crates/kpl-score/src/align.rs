//! Matching a recorded object stream with the ground truth by valid time, into a [`Sequence`].
//!
//! A stream's snapshot at valid time t is compared with the ground truth's snapshot at the same
//! valid time t; nothing is interpolated. Only the times in both streams' spans are scored (a
//! recording may begin or end a frame apart: the link processes emit after the tracker). Inside
//! that span, a ground-truth time without a snapshot of the stream (a missing frame) and a
//! snapshot at a time without ground truth are errors unless [`Missing`] says what to do.

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
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct AlignOptions {
    pub missing: Missing,
    /// Leave out the objects whose `measured` is false (states that were only predicted).
    pub measured_only: bool,
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
    #[serde(flatten)]
    pub measured: MeasuredFilter,
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
    let Some(stream_span) = span(stream) else {
        return Err(AlignError::Empty { stream: stream.name.clone() });
    };
    let Some(truth_span) = span(truth) else { return Err(AlignError::Empty { stream: truth.name.clone() }) };
    let from = stream_span.0.max(truth_span.0);
    let to = stream_span.1.min(truth_span.1);
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
    if options.missing == Missing::Error {
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

    let filter = options.measured_only && stream.has_measured;
    let mut left_out = 0;
    let mut sequence = Sequence::new();
    let mut scored: Vec<Time> = Vec::with_capacity(pairs.len());
    for (t, s) in pairs {
        if s.is_none() && options.missing == Missing::Skip {
            continue;
        }
        let hypotheses: Vec<&RecordedObject> = s
            .map(|s| {
                s.objects
                    .iter()
                    .filter(|o| {
                        let keep = !filter || o.measured != Some(false);
                        left_out += usize::from(!keep);
                        keep
                    })
                    .collect()
            })
            .unwrap_or_default();
        sequence
            .push_frame(
                t.time,
                t.objects.iter().map(|o| (o.id.as_str(), o.pos)),
                hypotheses.iter().map(|o| (o.id.as_str(), o.pos)),
            )
            .map_err(|source| AlignError::Sequence { stream: stream.name.clone(), source })?;
        scored.push(t.time);
    }
    let measured = match (options.measured_only, stream.has_measured) {
        (false, _) => MeasuredFilter::Off,
        (true, true) => MeasuredFilter::Applied { left_out },
        (true, false) => MeasuredFilter::NotAvailable,
    };
    let alignment = Alignment {
        frames: scored.len(),
        from: scored.first().copied().unwrap_or(from),
        to: scored.last().copied().unwrap_or(to),
        truth_outside: truth.snapshots.len() - truth_in.len(),
        stream_outside: stream.snapshots.len() - stream_in.len(),
        missing: missing.len(),
        missing_as: options.missing,
        extra: extra.len(),
        measured,
    };
    Ok(Aligned { sequence, alignment })
}
