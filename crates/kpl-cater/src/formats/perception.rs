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
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PerceptionFile {
    pub video: String,
    /// `perfect`, `detector`, or the pickle's origin.
    pub perception: String,
    pub classes: Vec<String>,
    pub frames: Vec<Vec<Detection>>,
}

impl PerceptionFile {
    /// Reads this project's JSON perception and checks it ([`PerceptionFile::check`]).
    pub fn read(path: &Path) -> Result<PerceptionFile, CaterError> {
        let file: PerceptionFile = read_json(path)?;
        file.check().map_err(|reason| CaterError::invalid(path, reason))?;
        Ok(file)
    }

    /// Reads OPNet's per-video perception pickle: labels are OPNet's class indices.
    pub fn read_pickle(path: &Path, video: &str, perception: &str) -> Result<PerceptionFile, CaterError> {
        let raw = read_perception_pickle(path)?;
        let classes = opnet_classes().to_vec();
        let mut frames = Vec::with_capacity(raw.len());
        for (frame, detections) in raw.into_iter().enumerate() {
            let mut out = Vec::with_capacity(detections.len());
            for (label, bbox) in detections {
                let class =
                    u32::try_from(label).ok().filter(|c| (*c as usize) < classes.len()).ok_or_else(|| {
                        CaterError::invalid(
                            path,
                            format!(
                                "frame {frame}: label {label} is not one of OPNet's {} class indices",
                                classes.len()
                            ),
                        )
                    })?;
                out.push(Detection { class, bbox });
            }
            frames.push(out);
        }
        let file =
            PerceptionFile { video: video.to_owned(), perception: perception.to_owned(), classes, frames };
        file.check().map_err(|reason| CaterError::invalid(path, reason))?;
        Ok(file)
    }

    /// Every class index names a class of the file; every box has finite coordinates within
    /// ±[`super::MAX_COORDINATE`] with `x1 <= x2` and `y1 <= y2`.
    pub fn check(&self) -> Result<(), String> {
        for (frame, detections) in self.frames.iter().enumerate() {
            for d in detections {
                let [x1, y1, x2, y2] = d.bbox;
                if d.class as usize >= self.classes.len() {
                    return Err(format!("frame {frame}: class index {} unknown", d.class));
                }
                if !d.bbox.iter().all(|v| coordinate_ok(*v)) || x2 < x1 || y2 < y1 {
                    return Err(format!("frame {frame}: bad box {:?}", d.bbox));
                }
            }
        }
        Ok(())
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
