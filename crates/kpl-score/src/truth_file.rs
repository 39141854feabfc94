//! Ground truth from a data set's file instead of a recorded stream: MOTChallenge's `gt.txt`
//! (and the other formats `kpl_camera::formats` reads: VisDrone, UA-DETRAC XML, COCO JSON), as
//! an object stream of boxes in pixels with one snapshot per frame, so a run that anchored a
//! tracker's output in the image plane is scored as MOTChallenge's evaluation scores it.
//!
//! - Frame `f` is at valid time `(f - first_frame) / fps` (the replay sources' convention: the
//!   first frame at time 0). Every frame from `first_frame` to the last frame with a box (or the
//!   sequence's length, when `seqinfo.ini` gives it) has a snapshot, empty where the file lists
//!   nothing.
//! - Rows with a score below `min_score` are left out: in MOTChallenge's ground truth the score
//!   column is a flag, 0 for boxes not to be considered (py-motmetrics reads ground truth with
//!   `min_confidence = 1`, which is the default here).
//! - Ids become `gt{id}`.
//!
//! `seqinfo.ini` (MOTChallenge's sequence description, `[Sequence]` with `frameRate` and
//! `seqLength`) is read from the ground truth's folder or the one above it (`SEQ/gt/gt.txt`
//! beside `SEQ/seqinfo.ini`) by [`seqinfo`].

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use kpl_camera::formats::{self, Format};
use kpl_core::Time;

use crate::error::ReadError;
use crate::recording::{ObjectStream, RecordedObject, Snapshot};

/// How a ground-truth file becomes a stream.
#[derive(Debug, Clone, PartialEq)]
pub struct TruthFile {
    pub path: PathBuf,
    pub format: Format,
    /// Frames per second.
    pub fps: f64,
    /// The frame at valid time 0.
    pub first_frame: i64,
    /// The last frame (a sequence's length); `None`: the last frame with a box.
    pub last_frame: Option<i64>,
    /// Boxes with a lower score are left out.
    pub min_score: f64,
}

/// What `seqinfo.ini` says of a sequence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeqInfo {
    pub frame_rate: Option<f64>,
    pub seq_length: Option<i64>,
    pub file: &'static str,
}

/// Reads `seqinfo.ini` beside `gt` or in the folder above; `None` when there is none. Returns
/// the file it read too.
pub fn seqinfo(gt: &Path) -> Option<(PathBuf, SeqInfo)> {
    let dir = gt.parent()?;
    let candidates =
        [dir.join("seqinfo.ini"), dir.parent().map(|p| p.join("seqinfo.ini")).unwrap_or_default()];
    let file = candidates.into_iter().find(|c| c.is_file())?;
    let bytes = kpl_core::read::read_file(&file, 1 << 20).ok()?;
    let text = String::from_utf8_lossy(&bytes);
    let mut info = SeqInfo { frame_rate: None, seq_length: None, file: "seqinfo.ini" };
    for line in text.lines() {
        let Some((key, value)) = line.split_once('=') else { continue };
        match key.trim() {
            "frameRate" => {
                info.frame_rate = value.trim().parse::<f64>().ok().filter(|f| f.is_finite() && *f > 0.0)
            }
            "seqLength" => info.seq_length = value.trim().parse::<i64>().ok().filter(|n| *n > 0),
            _ => {}
        }
    }
    Some((file, info))
}

/// The ground truth of a data set's file as an object stream named `name`, with the problems
/// met (`FILE:LINE: what`).
pub fn read_truth_file(truth: &TruthFile, name: &str) -> Result<(ObjectStream, Vec<String>), ReadError> {
    let io = |source| ReadError::Io { path: truth.path.clone(), source };
    let parsed = formats::read_file(&truth.path, truth.format).map_err(|e| match e {
        formats::FormatError::Io(source) => io(source),
        other => ReadError::Io { path: truth.path.clone(), source: std::io::Error::other(other.to_string()) },
    })?;
    let mut problems: Vec<String> = parsed
        .problems
        .iter()
        .map(|p| format!("{}:{}: {}", truth.path.display(), p.line, p.message))
        .collect();
    let mut by_frame: BTreeMap<i64, Vec<RecordedObject>> = BTreeMap::new();
    let mut last = truth.first_frame;
    for d in &parsed.detections {
        if d.score < truth.min_score {
            continue;
        }
        if d.frame < truth.first_frame || truth.last_frame.is_some_and(|l| d.frame > l) {
            problems.push(format!(
                "{}: a box of frame {} outside the sequence's frames ({} to {}); left out",
                truth.path.display(),
                d.frame,
                truth.first_frame,
                truth.last_frame.map_or("its last box".to_string(), |l| l.to_string())
            ));
            continue;
        }
        let Some(id) = d.id else {
            problems.push(format!(
                "{}: a box of frame {} without an id; left out",
                truth.path.display(),
                d.frame
            ));
            continue;
        };
        let objects = by_frame.entry(d.frame).or_default();
        let id = format!("gt{id}");
        if objects.iter().any(|o| o.id == id) {
            problems.push(format!(
                "{}: frame {}: `{id}` twice; the first is scored",
                truth.path.display(),
                d.frame
            ));
            continue;
        }
        last = last.max(d.frame);
        objects.push(RecordedObject {
            id,
            pos: d.bbox.centre(),
            bbox: Some(d.bbox.to_array()),
            in_view: None,
            measured: None,
            branch_of: None,
        });
    }
    let last = truth.last_frame.unwrap_or(last);
    let frames = (last - truth.first_frame + 1).clamp(0, formats::MAX_FRAMES);
    let period_us = 1e6 / truth.fps;
    let snapshots = (0..frames)
        .map(|k| {
            let frame = truth.first_frame + k;
            Snapshot {
                time: (k as f64 * period_us).round() as Time,
                line: 0,
                objects: by_frame.remove(&frame).unwrap_or_default(),
            }
        })
        .collect();
    let stream = ObjectStream {
        name: name.to_string(),
        file: truth.path.clone(),
        snapshots,
        has_measured: false,
        has_seen_as: false,
        has_boxes: true,
    };
    Ok((stream, problems))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_times_and_flags() {
        let dir = std::env::temp_dir().join(format!("kpl-score-truth-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("gt")).unwrap();
        std::fs::write(dir.join("seqinfo.ini"), "[Sequence]\nname=X\nframeRate=30\nseqLength=5\n").unwrap();
        let gt = dir.join("gt/gt.txt");
        std::fs::write(
            &gt,
            "1,1,10,10,5,5,1,1,1\n3,1,12,10,5,5,1,1,1\n3,2,50,50,5,5,0,7,1\n9,1,1,1,1,1,1,1,1\n",
        )
        .unwrap();
        let (file, info) = seqinfo(&gt).unwrap();
        assert_eq!(file, dir.join("seqinfo.ini"));
        assert_eq!((info.frame_rate, info.seq_length), (Some(30.0), Some(5)));
        let truth = TruthFile {
            path: gt,
            format: Format::MotChallenge,
            fps: 30.0,
            first_frame: 1,
            last_frame: info.seq_length,
            min_score: 1.0,
        };
        let (stream, problems) = read_truth_file(&truth, "gt").unwrap();
        assert_eq!(stream.snapshots.len(), 5);
        let counts: Vec<usize> = stream.snapshots.iter().map(|s| s.objects.len()).collect();
        assert_eq!(counts, [1, 0, 1, 0, 0], "the flagged box is left out");
        assert_eq!(stream.snapshots[2].time, 66_667);
        assert_eq!(stream.snapshots[2].objects[0].bbox, Some([12.0, 10.0, 5.0, 5.0]));
        assert_eq!(problems.len(), 1, "frame 9 is after the sequence: {problems:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
