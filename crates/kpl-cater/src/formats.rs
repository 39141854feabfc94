//! The LA-CATER file formats, read and written:
//!
//! - `<video>_bb.json` ground truth: object key (`size_color_shape_material_instance`, the snitch is
//!   `small_gold_spl_metal_Spl_0`) -> per-frame `[x, y, w, h]`, the full box of the object in every
//!   frame, hidden or not (as OPNet's `DataHelper.parse_obj_gt_bb` reads it);
//! - CATER scene JSON: `objects` (instance, shape, size, color, material, `3d_coords`) and
//!   `movements[instance] = [[action, other, start, end], ...]` with `_slide`, `_pick_place`,
//!   `_rotate`, `_contain` (`other` is the contained object for `_contain`, else null);
//! - predictions `<video>_bb.json`: a list of per-frame `[x1, y1, x2, y2]` integer boxes (OPNet's
//!   `write_bb_predictions_to_file`);
//! - perception (this project's): per frame the detections `[class_index, x1, y1, x2, y2]` with the
//!   list of class names, for perfect perception and for the simulated detector.

use std::collections::BTreeMap;
use std::path::Path;

use kpl_aapa::Percept;
use kpl_core::BBox;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::error::CaterError;

/// Frames per video.
pub const FRAMES: usize = 300;
/// Frame size in pixels.
pub const WIDTH: f64 = 320.0;
pub const HEIGHT: f64 = 240.0;
/// The snitch's instance name in scene JSON.
pub const SNITCH_INSTANCE: &str = "Spl_0";
/// The snitch's class (`size_color_shape_material`).
pub const SNITCH_CLASS: &str = "small_gold_spl_metal";
/// The snitch's key in `<video>_bb.json`.
pub const SNITCH_KEY: &str = "small_gold_spl_metal_Spl_0";

/// An integer box `[x1, y1, x2, y2]`, OPNet's convention (inclusive pixel corners).
pub type IntBox = [i32; 4];

pub(crate) fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, CaterError> {
    let bytes = std::fs::read(path).map_err(|source| CaterError::Io { path: path.to_owned(), source })?;
    serde_json::from_slice(&bytes).map_err(|source| CaterError::Json { path: path.to_owned(), source })
}

pub(crate) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), CaterError> {
    let text =
        serde_json::to_vec(value).map_err(|source| CaterError::Json { path: path.to_owned(), source })?;
    std::fs::write(path, text).map_err(|source| CaterError::Io { path: path.to_owned(), source })
}

/// `<video>_bb.json`: every object's `[x, y, w, h]` per frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct GroundTruth {
    pub objects: BTreeMap<String, Vec<[i32; 4]>>,
}

impl GroundTruth {
    pub fn read(path: &Path) -> Result<GroundTruth, CaterError> {
        // Read numbers as floats so files with `12.0` load too; boxes are whole pixels.
        let raw: BTreeMap<String, Vec<[f64; 4]>> = read_json(path)?;
        let mut objects = BTreeMap::new();
        for (key, boxes) in raw {
            let mut out = Vec::with_capacity(boxes.len());
            for (frame, b) in boxes.iter().enumerate() {
                if b.iter().any(|v| !v.is_finite()) || b[2] < 0.0 || b[3] < 0.0 {
                    return Err(CaterError::invalid(path, format!("`{key}` frame {frame}: bad box {b:?}")));
                }
                out.push(b.map(|v| v.round() as i32));
            }
            objects.insert(key, out);
        }
        Ok(GroundTruth { objects })
    }

    pub fn write(&self, path: &Path) -> Result<(), CaterError> {
        write_json(path, &self.objects)
    }

    /// The snitch's boxes as `[x1, y1, x2, y2]` (`x2 = x + w`, as OPNet converts them).
    pub fn snitch_boxes(&self, path: &Path) -> Result<Vec<IntBox>, CaterError> {
        let boxes = self
            .objects
            .get(SNITCH_KEY)
            .ok_or_else(|| CaterError::invalid(path, format!("no `{SNITCH_KEY}` in the ground truth")))?;
        Ok(boxes.iter().map(|&[x, y, w, h]| [x, y, x + w, y + h]).collect())
    }
}

/// One CATER movement: `[action, other, start_frame, end_frame]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "(String, Option<String>, i64, i64)", into = "(String, Option<String>, i64, i64)")]
pub struct Movement {
    pub action: String,
    pub other: Option<String>,
    pub start: i64,
    pub end: i64,
}

impl From<(String, Option<String>, i64, i64)> for Movement {
    fn from((action, other, start, end): (String, Option<String>, i64, i64)) -> Movement {
        Movement { action, other, start, end }
    }
}

impl From<Movement> for (String, Option<String>, i64, i64) {
    fn from(m: Movement) -> Self {
        (m.action, m.other, m.start, m.end)
    }
}

/// One object of a CATER scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneObject {
    pub instance: String,
    pub shape: String,
    pub size: String,
    pub color: String,
    pub material: String,
    /// Initial position (x, y on the table, z up), CATER units.
    #[serde(rename = "3d_coords", default)]
    pub coords: [f64; 3],
    /// Initial rotation about the vertical axis, degrees.
    #[serde(default)]
    pub rotation: f64,
}

impl SceneObject {
    /// `size_color_shape_material`, the class OPNet and the detectors use.
    pub fn class(&self) -> String {
        format!("{}_{}_{}_{}", self.size, self.color, self.shape, self.material)
    }

    /// The object's key in `<video>_bb.json`.
    pub fn key(&self) -> String {
        format!("{}_{}", self.class(), self.instance)
    }
}

/// The pinhole camera a generated scene was rendered with.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SceneCamera {
    pub location: [f64; 3],
    pub look_at: [f64; 3],
    pub focal_px: f64,
}

/// A CATER scene JSON (the parts this project reads and writes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    #[serde(default)]
    pub video: String,
    pub objects: Vec<SceneObject>,
    pub movements: BTreeMap<String, Vec<Movement>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<SceneCamera>,
}

impl Scene {
    pub fn read(path: &Path) -> Result<Scene, CaterError> {
        let scene: Scene = read_json(path)?;
        for (instance, moves) in &scene.movements {
            for m in moves {
                if m.start < 0 || m.end < m.start {
                    return Err(CaterError::invalid(path, format!("`{instance}`: bad frames in {m:?}")));
                }
            }
        }
        Ok(scene)
    }

    pub fn write(&self, path: &Path) -> Result<(), CaterError> {
        write_json(path, self)
    }

    pub fn object(&self, instance: &str) -> Option<&SceneObject> {
        self.objects.iter().find(|o| o.instance == instance)
    }
}

/// A snitch prediction file: per frame `[x1, y1, x2, y2]`.
pub fn read_predictions(path: &Path) -> Result<Vec<IntBox>, CaterError> {
    read_json(path)
}

pub fn write_predictions(path: &Path, boxes: &[IntBox]) -> Result<(), CaterError> {
    write_json(path, &boxes)
}

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
    /// `perfect` or `detector`.
    pub perception: String,
    pub classes: Vec<String>,
    pub frames: Vec<Vec<Detection>>,
}

impl PerceptionFile {
    pub fn read(path: &Path) -> Result<PerceptionFile, CaterError> {
        let file: PerceptionFile = read_json(path)?;
        for (frame, detections) in file.frames.iter().enumerate() {
            for d in detections {
                let [x1, y1, x2, y2] = d.bbox;
                if d.class as usize >= file.classes.len() {
                    return Err(CaterError::invalid(
                        path,
                        format!("frame {frame}: class index {} unknown", d.class),
                    ));
                }
                if ![x1, y1, x2, y2].iter().all(|v| v.is_finite()) || x2 < x1 || y2 < y1 {
                    return Err(CaterError::invalid(path, format!("frame {frame}: bad box {:?}", d.bbox)));
                }
            }
        }
        Ok(file)
    }

    pub fn write(&self, path: &Path) -> Result<(), CaterError> {
        write_json(path, self)
    }

    /// A frame's detections as AAPA percepts. Labels are `shapeN`, numbered left to right within
    /// the frame, the way a detector numbers instances (and so not stable over time).
    pub fn percepts(&self, frame: usize) -> Vec<Percept> {
        let Some(detections) = self.frames.get(frame) else { return Vec::new() };
        // Detections naming no class are skipped (`read` rejects such files). Each one's class and
        // shape are looked up once, not in every comparison of the sort.
        let mut order: Vec<(&str, &str, &Detection)> = detections
            .iter()
            .filter_map(|d| {
                let class = self.classes.get(d.class as usize)?.as_str();
                Some((class.split('_').nth(2).unwrap_or(class), class, d))
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
