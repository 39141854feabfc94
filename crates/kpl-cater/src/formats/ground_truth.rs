//! `<video>_bb.json`: `{"size_color_shape_material_instance": [[x, y, w, h], ...], ...}`, the whole
//! box of every object in every frame, hidden or not, clipped to the image (what OPNet's fork of
//! CATER's renderer writes beside the scene JSON, and what OPNet's `DataHelper.parse_obj_gt_bb`
//! reads, turning each into `[x, y, x + w, y + h]`).

use std::collections::BTreeMap;
use std::path::Path;

use super::{IntBox, SNITCH_KEY, coordinate_ok, read_json, write_json};
use crate::error::CaterError;

#[derive(Debug, Clone, PartialEq, Default)]
pub struct GroundTruth {
    pub objects: BTreeMap<String, Vec<[i32; 4]>>,
}

impl GroundTruth {
    /// Reads and checks the file: every number a whole pixel (written as `12` or `12.0`) within
    /// ±[`super::MAX_COORDINATE`], sizes not negative, every object with the same number of frames.
    pub fn read(path: &Path) -> Result<GroundTruth, CaterError> {
        let raw: BTreeMap<String, Vec<[f64; 4]>> = read_json(path)?;
        let mut objects = BTreeMap::new();
        let mut frames: Option<(String, usize)> = None;
        for (key, boxes) in raw {
            match &frames {
                Some((first, n)) if *n != boxes.len() => {
                    return Err(CaterError::invalid(
                        path,
                        format!("`{key}` has {} frames but `{first}` has {n}", boxes.len()),
                    ));
                }
                None => frames = Some((key.clone(), boxes.len())),
                _ => {}
            }
            let mut out = Vec::with_capacity(boxes.len());
            for (frame, b) in boxes.iter().enumerate() {
                let whole = b.iter().all(|v| coordinate_ok(*v) && v.fract() == 0.0);
                if !whole || b[2] < 0.0 || b[3] < 0.0 {
                    return Err(CaterError::invalid(
                        path,
                        format!("`{key}` frame {frame}: {b:?} is not a box [x, y, w, h] of whole pixels"),
                    ));
                }
                out.push(b.map(|v| v as i32));
            }
            objects.insert(key, out);
        }
        Ok(GroundTruth { objects })
    }

    pub fn write(&self, path: &Path) -> Result<(), CaterError> {
        write_json(path, &self.objects)
    }

    /// Frames in the file (0 if it has no object).
    pub fn frames(&self) -> usize {
        self.objects.values().next().map_or(0, Vec::len)
    }

    /// An object's boxes as `[x1, y1, x2, y2]` (`x2 = x + w`, as OPNet converts them).
    pub fn boxes_of(&self, key: &str) -> Option<Vec<IntBox>> {
        self.objects.get(key).map(|boxes| boxes.iter().map(|&[x, y, w, h]| [x, y, x + w, y + h]).collect())
    }

    /// The snitch's boxes as `[x1, y1, x2, y2]`.
    pub fn snitch_boxes(&self, path: &Path) -> Result<Vec<IntBox>, CaterError> {
        self.boxes_of(SNITCH_KEY)
            .ok_or_else(|| CaterError::invalid(path, format!("no snitch: `{SNITCH_KEY}` is not in the file")))
    }
}
