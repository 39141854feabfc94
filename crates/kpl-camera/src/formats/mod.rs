//! Readers for the files detectors and trackers write, as percepts in the image plane: every
//! format gives [`Detection`]s (frame, track id when there is one, box in pixels, score, class),
//! and [`frames`] turns them into one snapshot per frame with times and velocities.
//!
//! | format | reader | columns used |
//! |---|---|---|
//! | MOTChallenge text (MOT15/16/17/20 results, `det.txt`, `gt.txt`) | [`mot::read_motchallenge`] | `frame, id, left, top, width, height, conf[, class, visibility]` (the rest ignored; an id of -1 is a detection without identity) |
//! | VisDrone MOT (VisDrone2018-MOT toolkit) | [`mot::read_visdrone`] | `frame, id, left, top, width, height, score, category[, truncation, occlusion]`; category 0 (ignored region) and 11 (others) are left out, as the toolkit leaves them out |
//! | UA-DETRAC XML annotations | [`detrac::read`] | `<frame num>`, `<target id>`, `<box left top width height>`, `<attribute vehicle_type>`; `<ignored_region>` is left out |
//! | COCO-style JSON detections | [`coco::read`] | a result list `[{image_id, bbox: [x, y, w, h], score, category_id[, track_id]}]` or a data set `{images: [{id, frame_id | frame_index}], annotations: [...]}` |
//!
//! Boxes are kept as the file writes them, `[left, top, width, height]` in pixels (MOTChallenge's
//! and UA-DETRAC's count from 1 at the top-left pixel; py-motmetrics subtracts 1 when it reads
//! them, which moves both sides of a comparison alike and changes no overlap). A malformed line
//! or entry is a [`Problem`] with its line number, counted and skipped; the rest is read. Rows
//! may come in any order: they are grouped by frame.

pub mod coco;
pub mod detrac;
pub mod mot;

use std::collections::{BTreeMap, HashMap};

use crate::boxes::PixelBox;

/// Files larger than this are refused (a tracker's output for an hour of 30 fps video with a
/// hundred objects per frame is some 700 MB of text at most; MOT17's largest is 10 MB).
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// At most this many frames from the first to the last (46 hours at 25 fps); boxes of later
/// frames are problems.
pub const MAX_FRAMES: i64 = 1 << 22;

/// One box of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// The frame number as the file writes it.
    pub frame: i64,
    /// The tracker's id; `None` for a detection without identity.
    pub id: Option<i64>,
    pub bbox: PixelBox,
    /// The detector's or tracker's confidence (MOTChallenge ground truth: 1 considered, 0 not).
    pub score: f64,
    /// The class, when the format has one (MOT16+ ground truth, VisDrone's category, COCO's
    /// `category_id`, UA-DETRAC's vehicle type as an index of [`detrac::VEHICLE_TYPES`]).
    pub class: Option<i64>,
    /// The visible fraction, when the format has one (MOT16+ ground truth).
    pub visibility: Option<f64>,
}

/// A line or entry that could not be read, with where it is (line 0: the file as a whole, or an
/// entry of a JSON document, numbered from 1 in `entry`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    pub line: usize,
    pub message: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.line > 0 {
            write!(f, "line {}: {}", self.line, self.message)
        } else {
            f.write_str(&self.message)
        }
    }
}

/// What a reader read: the detections in file order and the problems it skipped.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Parsed {
    pub detections: Vec<Detection>,
    pub problems: Vec<Problem>,
}

/// A file that cannot be read at all.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("the file has {0} bytes, more than the {MAX_FILE_BYTES} a tracker's file is allowed")]
    TooLarge(u64),
    #[error("not JSON: {0}")]
    Json(String),
    #[error("{0}")]
    Shape(String),
}

/// The formats, by the names specs use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    MotChallenge,
    VisDrone,
    Detrac,
    Coco,
}

impl Format {
    pub const NAMES: [&'static str; 4] = ["motchallenge", "visdrone", "detrac", "coco"];

    pub fn from_name(name: &str) -> Option<Format> {
        match name {
            "motchallenge" | "mot" => Some(Format::MotChallenge),
            "visdrone" => Some(Format::VisDrone),
            "detrac" | "ua-detrac" => Some(Format::Detrac),
            "coco" => Some(Format::Coco),
            _ => None,
        }
    }

    /// Reads a file's bytes in this format.
    pub fn read(self, bytes: &[u8]) -> Result<Parsed, FormatError> {
        match self {
            Format::MotChallenge => Ok(mot::read_motchallenge(bytes)),
            Format::VisDrone => Ok(mot::read_visdrone(bytes)),
            Format::Detrac => Ok(detrac::read(bytes)),
            Format::Coco => coco::read(bytes),
        }
    }
}

/// Reads a file (at most [`MAX_FILE_BYTES`]) in a format.
pub fn read_file(path: &std::path::Path, format: Format) -> Result<Parsed, FormatError> {
    let size = std::fs::metadata(path)?.len();
    if size > MAX_FILE_BYTES {
        return Err(FormatError::TooLarge(size));
    }
    // A device or a pipe says its size is 0: read no further than the cap (`/dev/zero`).
    let bytes = kpl_core::read::read_file(path, MAX_FILE_BYTES as usize).map_err(std::io::Error::from)?;
    format.read(&bytes)
}

/// One box in a frame's snapshot, with its percept id and velocity.
#[derive(Debug, Clone, PartialEq)]
pub struct FramePercept {
    /// `{prefix}{id}` for a tracked box; `{prefix}d{frame}_{k}` for the k-th box without
    /// identity of a frame (a new percept every frame).
    pub id: String,
    pub bbox: PixelBox,
    /// The box centre's velocity, pixels per second, from the same id's box in the previous
    /// frame (0 at its first frame, or after a gap).
    pub vel: [f64; 2],
    pub score: f64,
    pub class: Option<i64>,
}

/// The snapshot of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameSnapshot {
    pub frame: i64,
    /// Microseconds: `(frame - first_frame) / fps`.
    pub time: i64,
    pub percepts: Vec<FramePercept>,
}

/// How frames become snapshots.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameOptions {
    /// Frames per second.
    pub fps: f64,
    /// The frame number at time 0 (MOTChallenge's first frame is 1).
    pub first_frame: i64,
    /// Percept ids are this followed by the tracker's id.
    pub prefix: String,
    /// Boxes with a lower score are left out.
    pub min_score: f64,
    /// Only these classes (empty: every class); a box without a class is kept.
    pub classes: Vec<i64>,
}

impl Default for FrameOptions {
    fn default() -> FrameOptions {
        FrameOptions {
            fps: 25.0,
            first_frame: 1,
            prefix: String::new(),
            min_score: f64::NEG_INFINITY,
            classes: Vec::new(),
        }
    }
}

/// The snapshots of every frame from the first frame with a box (or `first_frame`, if later) to
/// the last, empty frames included (a tracker that lost everything is a snapshot without
/// percepts, so anchoring sees the loss); frames before `first_frame` are problems. A second box
/// of one id in one frame is a problem and left out.
pub fn frames(detections: &[Detection], options: &FrameOptions) -> (Vec<FrameSnapshot>, Vec<Problem>) {
    let mut problems = Vec::new();
    let mut by_frame: BTreeMap<i64, Vec<&Detection>> = BTreeMap::new();
    for d in detections {
        if d.score < options.min_score
            || d.class.is_some_and(|c| !options.classes.is_empty() && !options.classes.contains(&c))
        {
            continue;
        }
        if d.frame < options.first_frame {
            problems.push(Problem {
                line: 0,
                message: format!(
                    "frame {} is before the first frame {}; left out",
                    d.frame, options.first_frame
                ),
            });
            continue;
        }
        by_frame.entry(d.frame).or_default().push(d);
    }
    if let Some(&first) = by_frame.keys().next() {
        let beyond = by_frame.split_off(&first.saturating_add(MAX_FRAMES));
        if let Some((&frame, _)) = beyond.iter().next() {
            let boxes: usize = beyond.values().map(Vec::len).sum();
            problems.push(Problem {
                line: 0,
                message: format!(
                    "frame {frame} is more than {MAX_FRAMES} frames after the first ({first}); it and the {boxes} boxes from there on are left out"
                ),
            });
        }
    }
    let (Some(&first), Some(&last)) = (by_frame.keys().next(), by_frame.keys().next_back()) else {
        return (Vec::new(), problems);
    };
    let period_us = 1e6 / options.fps;
    let mut previous: HashMap<i64, (i64, PixelBox)> = HashMap::new();
    let mut snapshots = Vec::with_capacity(usize::try_from(last - first + 1).unwrap_or(0).min(1 << 24));
    for frame in first..=last {
        let mut percepts = Vec::new();
        let mut seen = std::collections::HashSet::new();
        let mut anonymous = 0usize;
        for d in by_frame.get(&frame).map(Vec::as_slice).unwrap_or(&[]) {
            let (id, vel) = match d.id {
                Some(id) => {
                    if !seen.insert(id) {
                        problems.push(Problem {
                            line: 0,
                            message: format!("frame {frame}: id {id} twice; the second box is left out"),
                        });
                        continue;
                    }
                    let vel = match previous.get(&id) {
                        Some(&(f, b)) if f == frame - 1 => {
                            let (a, c) = (b.centre(), d.bbox.centre());
                            [(c[0] - a[0]) * options.fps, (c[1] - a[1]) * options.fps]
                        }
                        _ => [0.0, 0.0],
                    };
                    previous.insert(id, (frame, d.bbox));
                    (format!("{}{id}", options.prefix), vel)
                }
                None => {
                    anonymous += 1;
                    (format!("{}d{frame}_{anonymous}", options.prefix), [0.0, 0.0])
                }
            };
            percepts.push(FramePercept { id, bbox: d.bbox, vel, score: d.score, class: d.class });
        }
        let time = ((frame - options.first_frame) as f64 * period_us).round() as i64;
        snapshots.push(FrameSnapshot { frame, time, percepts });
    }
    (snapshots, problems)
}

/// Splits a text file into lines (numbered from 1), refusing none: a line that is not UTF-8 is
/// given as lossy text so its number is still reported.
pub(crate) fn lines(bytes: &[u8]) -> impl Iterator<Item = (usize, std::borrow::Cow<'_, str>)> {
    bytes.split(|b| *b == b'\n').enumerate().map(|(i, line)| {
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        (i + 1, String::from_utf8_lossy(line))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(frame: i64, id: Option<i64>, left: f64) -> Detection {
        Detection {
            frame,
            id,
            bbox: PixelBox::new(left, 0.0, 10.0, 10.0),
            score: 1.0,
            class: None,
            visibility: None,
        }
    }

    #[test]
    fn snapshots_fill_gaps_and_give_velocities() {
        let detections = [
            det(3, Some(1), 4.0),
            det(1, Some(1), 0.0),
            det(1, None, 50.0),
            det(1, None, 60.0),
            det(3, Some(1), 9.0),
        ];
        let options = FrameOptions { fps: 10.0, prefix: "t".into(), ..FrameOptions::default() };
        let (frames, problems) = frames(&detections, &options);
        assert_eq!(
            frames.iter().map(|f| (f.frame, f.time, f.percepts.len())).collect::<Vec<_>>(),
            [(1, 0, 3), (2, 100_000, 0), (3, 200_000, 1)]
        );
        assert_eq!(frames[0].percepts[1].id, "td1_1");
        assert_eq!(frames[0].percepts[2].id, "td1_2");
        // Frame 3 follows a gap: no velocity; the duplicate of id 1 is a problem.
        assert_eq!(frames[2].percepts[0].vel, [0.0, 0.0]);
        assert_eq!(problems.len(), 1, "{problems:?}");
        let moving = [det(1, Some(7), 0.0), det(2, Some(7), 2.0)];
        let (frames, _) = super::frames(&moving, &options);
        assert_eq!(frames[1].percepts[0].vel, [20.0, 0.0]);
        assert_eq!(frames[1].percepts[0].id, "t7");
    }
}
