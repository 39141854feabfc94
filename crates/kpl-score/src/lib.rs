//! Multi-object tracking metrics on the ground plane, for scoring what a tracker or an anchoring
//! reports against ground truth: CLEAR MOT (MOTA, MOTP, identity switches, fragmentations, mostly
//! tracked / lost) and the identity measures (IDF1, IDP, IDR) as py-motmetrics defines them, and
//! HOTA with DetA, AssA and LocA as TrackEval defines it. Positions are metres; a pair is matched
//! only within a gating distance; or boxes in pixels, matched when their intersection over union
//! reaches a threshold, as MOTChallenge's evaluation matches them, with the ground truth read
//! from a data set's file ([`truth_file`]: MOTChallenge's `gt.txt`, ...). See `docs/scoring.md`.
//!
//! - [`Sequence`]: frames of true objects and hypotheses; [`score`] / [`evaluate`] compute
//!   [`Scores`] (and the [`Mapping`] of hypotheses to true objects over time).
//! - [`Recording`]: recorded runs (`file.jsonl` sinks) read into object streams;
//!   [`align()`] matches a stream with the ground truth by valid time; [`score_recording`] does
//!   both for every stream and returns a [`Report`] (text tables or JSON).
//! - [`motchallenge::export`]: the scored frames as MOTChallenge-style files.
//!
//! The crate is pure: no clock, no threads; the only I/O is reading recordings.
//!
//! ```
//! use kpl_score::{Config, Sequence, score};
//! let mut seq = Sequence::new();
//! seq.push_frame(0, [("car1", [0.0, 0.0])], [("co1", [0.5, 0.0])])?;
//! seq.push_frame(100_000, [("car1", [1.0, 0.0])], [("co1", [1.2, 0.0]), ("co2", [30.0, 0.0])])?;
//! let scores = score(&seq, &Config::new(2.0)?);
//! assert_eq!(scores.clear.false_positives, 1);
//! assert_eq!(scores.clear.mota, 0.5);
//! assert_eq!(scores.identity.idtp, 2);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod align;
pub mod assign;
pub mod clear;
mod error;
pub mod hota;
pub mod identity;
pub mod mapping;
pub mod motchallenge;
mod ratio;
pub mod recorded;
pub mod recording;
pub mod report;
pub mod scores;
pub mod sequence;
pub mod situations;
mod time;
pub mod truth_file;

pub use align::{AlignOptions, Aligned, Alignment, BranchFilter, MeasuredFilter, Missing, align};
pub use clear::ClearMot;
pub use error::{AlignError, ConfigError, ReadError, SelectError, SequenceError};
pub use hota::Hota;
pub use identity::Identity;
pub use mapping::{Correspondence, IdentityAssignment, IdentityPair, Mapping};
pub use recorded::{Options, Scored, ScoredStream, score_recording};
pub use recording::{ObjectStream, Recording};
pub use report::Report;
pub use scores::{Config, DEFAULT_IOU, DEFAULT_MAX_DISTANCE, Evaluation, Scores, evaluate, mapping, score};
pub use sequence::{Bbox, Pos, Sequence};
pub use truth_file::{SeqInfo, TruthFile, read_truth_file, seqinfo};
