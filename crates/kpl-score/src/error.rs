//! The crate's errors: building a sequence, reading recordings, aligning a stream with the
//! ground truth, and bad configurations.

use std::path::PathBuf;

use kpl_core::Time;

use crate::sequence::Side;
use crate::time::seconds;

/// A frame refused by [`Sequence::push_frame`](crate::Sequence::push_frame).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SequenceError {
    #[error("frame at {} is not after the previous frame at {}", seconds(*time), seconds(*previous))]
    TimeNotIncreasing { time: Time, previous: Time },
    #[error("the {side} list `{id}` twice at {}", seconds(*time))]
    DuplicateId { time: Time, side: Side, id: String },
    #[error("the {side} give `{id}` a position (or box) that is not finite numbers at {}", seconds(*time))]
    NotFinite { time: Time, side: Side, id: String },
    #[error("frame at {}: boxes and points in one sequence", seconds(*time))]
    MixedGeometry { time: Time },
}

/// A scoring configuration that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConfigError {
    #[error("the gating distance must be a positive number of metres, not {0}")]
    MaxDistance(f64),
    #[error("HOTA's zero-similarity distance must be a positive number of metres, not {0}")]
    ZeroDistance(f64),
    #[error("the IoU threshold must be above 0 and at most 1, not {0}")]
    Iou(f64),
}

/// Reading recorded files failed as a whole (single bad lines are counted, not errors).
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{}:{line}: a line longer than {limit} MiB; is this a JSON-lines recording?", path.display(), limit = crate::recording::MAX_LINE_BYTES >> 20)]
    LineTooLong { path: PathBuf, line: usize },
    #[error("{}: not a file or a folder (a device?); give a run's output folder or recorded `.jsonl` files", path.display())]
    NotAFile { path: PathBuf },
    #[error("{}: no recordings (`*.jsonl` files) in this folder", path.display())]
    EmptyFolder { path: PathBuf },
    #[error("{}: folders nested deeper than {limit} levels", path.display(), limit = crate::recording::MAX_DEPTH)]
    TooDeep { path: PathBuf },
    #[error("nothing to read: give a run's output folder or recorded `.jsonl` files")]
    NoPaths,
}

impl ReadError {
    /// Something the user must fix in the data (as opposed to the file system).
    pub fn is_data_error(&self) -> bool {
        matches!(
            self,
            ReadError::LineTooLong { .. } | ReadError::EmptyFolder { .. } | ReadError::NotAFile { .. }
        )
    }
}

/// Choosing the streams to score failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SelectError {
    #[error(
        "no ground-truth stream in the recording: record the tracker's `truth` port (e.g. `sink s = file.jsonl(tracker, tracker.truth, path: \"tracks.jsonl\")`) or name the stream with --truth{}",
        listing("object streams", object_streams)
    )]
    NoTruth { object_streams: Vec<String> },
    #[error("several streams could be the ground truth ({}): choose one with --truth", candidates.join(", "))]
    AmbiguousTruth { candidates: Vec<String> },
    #[error("no stream `{name}` in the recording{}{}", did_you_mean(suggestion.as_deref()), listing("object streams", known))]
    UnknownStream { name: String, suggestion: Option<String>, known: Vec<String> },
    #[error("`{name}` is not an object stream (its values are not lists of records with `id` and `pos`)")]
    NotObjects { name: String },
    #[error(
        "no object streams besides the ground truth `{truth}` to score{}",
        listing("other streams", others)
    )]
    NothingToScore { truth: String, others: Vec<String> },
}

fn did_you_mean(name: Option<&str>) -> String {
    name.map(|n| format!("; did you mean `{n}`?")).unwrap_or_default()
}

fn listing(label: &str, names: &[String]) -> String {
    if names.is_empty() { String::new() } else { format!(" ({label}: {})", names.join(", ")) }
}

/// A hypothesis stream whose times cannot be matched with the ground truth's.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AlignError {
    #[error("`{stream}` has no samples")]
    Empty { stream: String },
    #[error(
        "`{stream}` ({}) and the ground truth `{truth}` ({}) do not overlap in valid time",
        span(*stream_span), span(*truth_span)
    )]
    NoOverlap { stream: String, truth: String, stream_span: (Time, Time), truth_span: (Time, Time) },
    #[error(
        "`{stream}` has no sample at {count} of the ground truth's {total} valid times between {} and {} (first: {}); \
         --missing empty scores them as frames in which it saw nothing, --missing skip leaves them out",
        seconds(span.0), seconds(span.1), times(first)
    )]
    MissingFrames { stream: String, count: usize, total: usize, first: Vec<Time>, span: (Time, Time) },
    #[error(
        "`{stream}` has {count} samples at valid times the ground truth `{truth}` has none (first: {}): the two are not \
         sampled at the same times; --missing skip scores only the times both have",
        times(first)
    )]
    ExtraTimes { stream: String, truth: String, count: usize, first: Vec<Time> },
    #[error("`{stream}`: {source}")]
    Sequence { stream: String, source: SequenceError },
    #[error(
        "`{stream}` ({side}): `{id}` has no `box` ([left, top, width, height] in pixels), which scoring by IoU needs"
    )]
    NoBox { stream: String, side: &'static str, id: String },
}

fn span((from, to): (Time, Time)) -> String {
    format!("{} – {}", seconds(from), seconds(to))
}

fn times(ts: &[Time]) -> String {
    ts.iter().map(|&t| seconds(t)).collect::<Vec<_>>().join(", ")
}
