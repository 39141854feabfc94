//! What a perception module reported for a video, frame by frame: per frame the detections, each a
//! class and a pixel box `[x1, y1, x2, y2]`. Two files give it:
//!
//! - OPNet's per-video pickle `<video>.pkl` (`bb` and `labels`, OPNet's class indices; see
//!   [`super::pickle`]), read by [`PerceptionFile::read_pickle`];
//! - this project's JSON, `{"video", "perception", "classes": [class names], "frames":
//!   [[[class_index, x1, y1, x2, y2], ...], ...]}`, read by [`PerceptionFile::read`].

use std::collections::BTreeMap;
use std::path::Path;

use kpl_aapa::Percept;
use kpl_core::BBox;
use serde::{Deserialize, Serialize};

use super::pickle::read_perception_pickle;
use super::{coordinate_ok, read_json, write_json};
use crate::classes::{opnet_classes, shape_of};
use crate::error::CaterError;

/// One detection: index into the file's class list and a pixel box.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "(u32, f64, f64, f64, f64)", into = "(u32, f64, f64, f64, f64)")]
pub struct Detection {
    pub class: u32,
    pub bbox: [f64; 4],
}

impl From<(u32, f64, f64, f64, f64)> for Detection {
    fn from((class, x1, y1, x2, y2): (u32, f64, f64, f64, f64)) -> Detection {
        Detection { class, bbox: [x1, y1, x2, y2] }
    }
}

impl From<Detection> for (u32, f64, f64, f64, f64) {
    fn from(d: Detection) -> Self {
        (d.class, d.bbox[0], d.bbox[1], d.bbox[2], d.bbox[3])
    }
}

/// What a perception module reported for a video, frame by frame.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct PerceptionFile {
    pub video: String,
    /// `perfect`, `detector`, or the pickle's origin.
    pub perception: String,
    pub classes: Vec<String>,
    pub frames: Vec<Vec<Detection>>,
    /// Detections the file had but that could not be used, dropped on reading (not in the file).
    #[serde(skip)]
    pub dropped: Dropped,
}

/// Detections dropped on reading, by reason. A detector's bad detection costs that detection, not
/// the video; a file whose detections are mostly bad is refused ([`MAX_DROPPED_SHARE`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Dropped {
    /// A label that is not a class of the file (for OPNet's pickles: not one of its class indices,
    /// such as `-1`).
    pub unknown_class: usize,
    /// A box with a coordinate that is not a finite number within ±[`super::MAX_COORDINATE`], or
    /// with `x2 < x1` or `y2 < y1`.
    pub bad_box: usize,
}

impl Dropped {
    pub fn total(&self) -> usize {
        self.unknown_class + self.bad_box
    }

    pub fn add(&mut self, other: &Dropped) {
        self.unknown_class += other.unknown_class;
        self.bad_box += other.bad_box;
    }
}

/// The share of a file's detections that may be dropped before the file is refused as a whole.
pub const MAX_DROPPED_SHARE: f64 = 0.5;

impl PerceptionFile {
    /// Reads this project's JSON perception and checks it ([`PerceptionFile::tidy`]).
    pub fn read(path: &Path) -> Result<PerceptionFile, CaterError> {
        let file: PerceptionFile = read_json(path)?;
        file.tidy().map_err(|reason| CaterError::invalid(path, reason))
    }

    /// Reads OPNet's per-video perception pickle: labels are OPNet's class indices; a detection
    /// whose label is not one of them (`-1`) is dropped and counted.
    pub fn read_pickle(path: &Path, video: &str, perception: &str) -> Result<PerceptionFile, CaterError> {
        let raw = read_perception_pickle(path)?;
        let classes = opnet_classes().to_vec();
        let mut unknown_class = 0;
        let mut first_bad = None;
        let mut frames = Vec::with_capacity(raw.len());
        for (frame, detections) in raw.into_iter().enumerate() {
            let mut out = Vec::with_capacity(detections.len());
            for (label, bbox) in detections {
                match u32::try_from(label).ok().filter(|c| (*c as usize) < classes.len()) {
                    Some(class) => out.push(Detection { class, bbox }),
                    None => {
                        unknown_class += 1;
                        first_bad.get_or_insert_with(|| {
                            format!(
                                "frame {frame}: label {label} is not one of OPNet's {} class indices",
                                classes.len()
                            )
                        });
                    }
                }
            }
            frames.push(out);
        }
        let file = PerceptionFile {
            video: video.to_owned(),
            perception: perception.to_owned(),
            classes,
            frames,
            dropped: Dropped { unknown_class, bad_box: 0 },
        };
        file.tidy_from(first_bad).map_err(|reason| CaterError::invalid(path, reason))
    }

    /// Drops (and counts) the detections that name no class of the file or whose box is not a box
    /// (a coordinate that is not a finite number within ±[`super::MAX_COORDINATE`], `x2 < x1` or
    /// `y2 < y1`); refuses the file if more than [`MAX_DROPPED_SHARE`] of its detections go.
    pub fn tidy(self) -> Result<PerceptionFile, String> {
        self.tidy_from(None)
    }

    /// [`PerceptionFile::tidy`] of a file whose reader already dropped detections (`first_bad`
    /// says what the first was).
    fn tidy_from(mut self, mut first_bad: Option<String>) -> Result<PerceptionFile, String> {
        let classes = self.classes.len();
        let mut kept_total = 0usize;
        for (frame, detections) in self.frames.iter_mut().enumerate() {
            detections.retain(|d| {
                let [x1, y1, x2, y2] = d.bbox;
                if d.class as usize >= classes {
                    self.dropped.unknown_class += 1;
                    first_bad
                        .get_or_insert_with(|| format!("frame {frame}: class index {} unknown", d.class));
                    false
                } else if !d.bbox.iter().all(|v| coordinate_ok(*v)) || x2 < x1 || y2 < y1 {
                    self.dropped.bad_box += 1;
                    first_bad.get_or_insert_with(|| format!("frame {frame}: bad box {:?}", d.bbox));
                    false
                } else {
                    true
                }
            });
            kept_total += detections.len();
        }
        let dropped = self.dropped.total();
        if dropped > 0 && dropped as f64 > MAX_DROPPED_SHARE * (dropped + kept_total) as f64 {
            return Err(format!(
                "{dropped} of its {} detections cannot be used ({} with a label that is no class, {} with a \
                 bad box{})",
                dropped + kept_total,
                self.dropped.unknown_class,
                self.dropped.bad_box,
                first_bad.map_or(String::new(), |b| format!("; the first: {b}"))
            ));
        }
        Ok(self)
    }

    pub fn write(&self, path: &Path) -> Result<(), CaterError> {
        write_json(path, self)
    }

    /// The class name of a detection.
    pub fn class_of(&self, d: &Detection) -> &str {
        self.classes.get(d.class as usize).map_or("", String::as_str)
    }

    /// A frame's detections as AAPA percepts. Labels are `shapeN`, numbered left to right within
    /// the frame, the way a detector numbers instances (and so not stable over time).
    pub fn percepts(&self, frame: usize) -> Vec<Percept> {
        let Some(detections) = self.frames.get(frame) else { return Vec::new() };
        // Detections naming no class are skipped (`check` rejects such files). Each one's class and
        // shape are looked up once, not in every comparison of the sort.
        let mut order: Vec<(&str, &str, &Detection)> = detections
            .iter()
            .filter_map(|d| {
                let class = self.classes.get(d.class as usize)?.as_str();
                Some((shape_of(class), class, d))
            })
            .collect();
        order.sort_by(|a, b| a.0.cmp(b.0).then(a.2.bbox[0].total_cmp(&b.2.bbox[0])));
        let mut out = Vec::with_capacity(order.len());
        let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
        for (shape, class, d) in order {
            let n = counts.entry(shape).or_insert(0);
            let [x1, y1, x2, y2] = d.bbox;
            out.push(Percept::new(&format!("{shape}{n}"), class, BBox::new(x1, y1, x2, y2)));
            *n += 1;
        }
        out
    }

    /// Whether a frame has a detection of this class.
    pub fn has_class(&self, frame: usize, class: &str) -> bool {
        let Some(index) = self.classes.iter().position(|c| c == class) else { return false };
        self.frames.get(frame).is_some_and(|ds| ds.iter().any(|d| d.class as usize == index))
    }
}
