//! The report of scoring a recording: per stream its alignment and scores, what was left out,
//! as JSON (serde) or as text tables.

use std::fmt::Write as _;

use serde::Serialize;

use crate::align::{Alignment, BranchFilter, MeasuredFilter, Missing};
use crate::recording::Problems;
use crate::scores::{Config, Scores};
use crate::time::seconds;

/// Scoring one recording against its ground truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The ground-truth stream.
    pub truth: String,
    pub max_distance: f64,
    pub hota_zero_distance: f64,
    /// Boxes scored by IoU with this threshold (then `max_distance` is `1 - threshold`, MOTP the
    /// mean `1 - IoU` of the matched pairs, and HOTA's similarity the IoU).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iou_threshold: Option<f64>,
    pub streams: Vec<StreamReport>,
    /// Streams that could not be scored, with why.
    pub failed: Vec<Failed>,
    /// Lines and records of the recording that were left out.
    pub problems: ProblemsReport,
    /// What the reader decided that a user should know.
    pub notes: Vec<String>,
}

/// One scored stream.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StreamReport {
    pub stream: String,
    pub alignment: Alignment,
    #[serde(flatten)]
    pub scores: Scores,
}

/// A stream that could not be scored.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Failed {
    pub stream: String,
    pub error: String,
}

#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct ProblemsReport {
    pub count: usize,
    pub examples: Vec<String>,
}

impl From<&Problems> for ProblemsReport {
    fn from(p: &Problems) -> ProblemsReport {
        ProblemsReport { count: p.count, examples: p.examples.clone() }
    }
}

impl Report {
    pub fn new(truth: &str, config: &Config) -> Report {
        Report {
            truth: truth.to_string(),
            max_distance: config.max_distance(),
            hota_zero_distance: config.hota_zero_distance(),
            iou_threshold: config.iou_threshold(),
            streams: Vec::new(),
            failed: Vec::new(),
            problems: ProblemsReport::default(),
            notes: Vec::new(),
        }
    }

    /// Notes about single streams: what was not scored, and why.
    pub fn stream_notes(&self) -> Vec<String> {
        let mut notes = Vec::new();
        for s in &self.streams {
            let a = &s.alignment;
            let name = &s.stream;
            if a.truth_outside > 0 {
                notes.push(format!(
                    "{name}: {} ground-truth frames outside the stream's span ({} – {}) not scored",
                    a.truth_outside,
                    seconds(a.from),
                    seconds(a.to)
                ));
            }
            if a.stream_outside > 0 {
                notes.push(format!(
                    "{name}: {} snapshots outside the ground truth's span not scored",
                    a.stream_outside
                ));
            }
            match a.missing_as {
                Missing::Empty if a.missing > 0 => notes.push(format!(
                    "{name}: {} ground-truth frames without a snapshot scored as frames in which it saw nothing",
                    a.missing
                )),
                Missing::Skip if a.missing > 0 => {
                    notes.push(format!("{name}: {} ground-truth frames without a snapshot left out", a.missing))
                }
                _ => {}
            }
            if a.extra > 0 {
                notes.push(format!("{name}: {} snapshots at times without ground truth left out", a.extra));
            }
            if let Some(o) = a.out_of_view {
                notes.push(format!(
                    "{name}: {} true states out of the sensor's view (`in_view: false`) and {} hypotheses at them left out",
                    o.truth, o.hypotheses
                ));
            }
            if let MeasuredFilter::Applied { left_out } = a.measured
                && left_out > 0
            {
                notes.push(format!("{name}: {left_out} predicted states left out"));
            }
            match a.branches {
                BranchFilter::NoBranches => {}
                BranchFilter::LeftOut { branch_states, branch_objects } => notes.push(format!(
                    "{name}: {branch_states} states of {branch_objects} branch objects (records with `branch_of`: \
                     other hypotheses of predictions split at junctions) left out; --branches scores them"
                )),
                BranchFilter::Scored { branch_states, branch_objects } => notes.push(format!(
                    "{name}: {branch_states} states of {branch_objects} branch objects scored as tracks of their own"
                )),
            }
        }
        let unfiltered: Vec<&str> = self
            .streams
            .iter()
            .filter(|s| s.alignment.measured == MeasuredFilter::NotAvailable)
            .map(|s| s.stream.as_str())
            .collect();
        if !unfiltered.is_empty() {
            notes.push(format!(
                "only measured states are scored, but {} say nothing about which states were measured (no `measured` field), so every \
                 state of theirs was scored",
                unfiltered.join(", ")
            ));
        }
        notes
    }

    /// The report as text: a header, two tables, notes and problems.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let motp = match self.iou_threshold {
            Some(threshold) => {
                let _ = writeln!(
                    out,
                    "scored against `{}` by box overlap: a pair matches at IoU >= {threshold}; MOTP is the mean 1 - IoU of \
                     the matches; HOTA similarity IoU",
                    self.truth
                );
                "MOTP"
            }
            None => {
                let _ = writeln!(
                    out,
                    "scored against `{}`; gate {} m; HOTA similarity max(0, 1 - d / {} m)",
                    self.truth, self.max_distance, self.hota_zero_distance
                );
                "MOTP m"
            }
        };
        if !self.streams.is_empty() {
            let width = self.streams.iter().map(|s| s.stream.len()).max().unwrap_or(0).max("stream".len());
            out.push('\n');
            let _ = writeln!(
                out,
                "{:<width$} {:>6} {:>7} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6}",
                "stream", "frames", "MOTA", motp, "IDF1", "IDP", "IDR", "HOTA", "DetA", "AssA", "LocA"
            );
            for s in &self.streams {
                let (c, i, h) = (&s.scores.clear, &s.scores.identity, &s.scores.hota);
                let _ = writeln!(
                    out,
                    "{:<width$} {:>6} {:>7} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6}",
                    s.stream,
                    c.frames,
                    fixed(c.mota),
                    fixed(c.motp),
                    fixed(i.idf1),
                    fixed(i.idp),
                    fixed(i.idr),
                    fixed(h.hota),
                    fixed(h.det_a),
                    fixed(h.ass_a),
                    fixed(h.loc_a)
                );
            }
            out.push('\n');
            let _ = writeln!(
                out,
                "{:<width$} {:>7} {:>7} {:>7} {:>7} {:>5} {:>5} {:>6} {:>4} {:>4} {:>4}",
                "stream", "objects", "matched", "FP", "FN", "IDsw", "Frag", "truths", "MT", "PT", "ML"
            );
            for s in &self.streams {
                let c = &s.scores.clear;
                let _ = writeln!(
                    out,
                    "{:<width$} {:>7} {:>7} {:>7} {:>7} {:>5} {:>5} {:>6} {:>4} {:>4} {:>4}",
                    s.stream,
                    c.objects,
                    c.detections(),
                    c.false_positives,
                    c.misses,
                    c.switches,
                    c.fragmentations,
                    c.unique_objects,
                    c.mostly_tracked,
                    c.partially_tracked,
                    c.mostly_lost
                );
            }
        }
        let notes: Vec<String> = self.notes.iter().cloned().chain(self.stream_notes()).collect();
        if !notes.is_empty() {
            out.push('\n');
            for n in notes {
                let _ = writeln!(out, "note: {n}");
            }
        }
        if self.problems.count > 0 {
            let _ =
                writeln!(out, "\n{} lines or records of the recording were left out:", self.problems.count);
            for e in &self.problems.examples {
                let _ = writeln!(out, "  {e}");
            }
        }
        for f in &self.failed {
            let _ = writeln!(out, "\nnot scored: {}", f.error);
        }
        out
    }
}

/// A ratio with three decimals, `-` when it is undefined.
fn fixed(x: f64) -> String {
    if x.is_finite() { format!("{x:.3}") } else { "-".to_string() }
}
