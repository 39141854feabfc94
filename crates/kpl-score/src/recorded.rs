//! Scoring a recording as `kpl score` does: choose the ground truth and the streams, align each
//! with the ground truth, score it, and collect the report.

use crate::align::{AlignOptions, Aligned, align};
use crate::error::SelectError;
use crate::recording::{ObjectStream, Recording};
use crate::report::{Failed, Report, StreamReport};
use crate::scores::{Config, Evaluation, evaluate};

/// What to score and how.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// The ground-truth stream (found by itself when `None`).
    pub truth: Option<String>,
    /// The streams to score (every object stream but the truth when empty).
    pub streams: Vec<String>,
    pub config: Config,
    pub align: AlignOptions,
    /// Ground truth from outside the recording (a data set's file, [`crate::truth_file`]),
    /// instead of one of its streams.
    pub external_truth: Option<ObjectStream>,
}

/// One stream, scored.
#[derive(Debug, Clone)]
pub struct ScoredStream {
    pub stream: String,
    pub aligned: Aligned,
    pub evaluation: Evaluation,
}

/// The report and, per stream scored, what it was scored on.
#[derive(Debug, Clone)]
pub struct Scored {
    pub report: Report,
    pub streams: Vec<ScoredStream>,
}

/// Scores the chosen streams of `recording`. A stream that cannot be aligned with the ground
/// truth is listed in [`Report::failed`]; choosing the streams can fail as a whole.
pub fn score_recording(recording: &Recording, options: &Options) -> Result<Scored, SelectError> {
    let truth = match &options.external_truth {
        Some(truth) => truth,
        None => recording.truth(options.truth.as_deref())?,
    };
    let mut chosen = recording.hypotheses(&options.streams, &truth.name)?;
    let mut report_notes = Vec::new();
    if options.align.boxes && options.streams.is_empty() {
        // Scoring by IoU: every stream of boxes (a world-coordinate stream cannot be).
        let (boxes, others): (Vec<&ObjectStream>, Vec<&ObjectStream>) =
            chosen.into_iter().partition(|s| s.has_boxes);
        if !others.is_empty() {
            let names: Vec<&str> = others.iter().map(|s| s.name.as_str()).collect();
            report_notes.push(format!(
                "scored by IoU: {} not scored (records without `box` [left, top, width, height])",
                names.join(", ")
            ));
        }
        chosen = boxes;
    }
    let mut report = Report::new(&truth.name, &options.config);
    report.problems = recording.problems().into();
    report.notes = recording.notes().to_vec();
    report.notes.extend(report_notes);
    let mut streams = Vec::new();
    for stream in chosen {
        if stream.name == truth.name {
            report
                .notes
                .push(format!("`{}` is the ground truth; it is not scored against itself", truth.name));
            continue;
        }
        match align(truth, stream, &options.align) {
            Ok(aligned) => {
                let evaluation = evaluate(&aligned.sequence, &options.config);
                report.streams.push(StreamReport {
                    stream: stream.name.clone(),
                    alignment: aligned.alignment.clone(),
                    scores: evaluation.scores.clone(),
                });
                streams.push(ScoredStream { stream: stream.name.clone(), aligned, evaluation });
            }
            Err(e) => report.failed.push(Failed { stream: stream.name.clone(), error: e.to_string() }),
        }
    }
    Ok(Scored { report, streams })
}
