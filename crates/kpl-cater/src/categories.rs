//! The frame categories of Table I as OPNet's scripts define them, computed from a video's scene
//! JSON and `<video>_bb.json` (or read from OPNet's annotation files, [`crate::formats::Annotations`]):
//!
//! - **contained** (`gen_video_labels.py`, `snitch_containment`): for each cone (`"Cone"` in its
//!   instance name) and each of its `_contain`s of the snitch, the frames from that contain's *end*
//!   to the *start* of the cone's next `_pick_place` (frame 299 if none), inclusive;
//! - **carried** (`snitch_containment_with_move`): the frames `start..=end` of that cone's `_slide`s
//!   listed from the contain on whose end is not after the containment's end (a nested cone's slides
//!   count: CATER records a slide for every object of a moving stack);
//! - **visible** (`get_perfect_perception_and_visible_snitch_ratio.py`, visibility ratio > 0): the
//!   snitch is not inside a cone (objects whose class a cone contains are left out from the contain's
//!   end to its next pick-up's start, frame 300 if none), and no other object left in covers it: a
//!   box covers the snitch's when their overlap is at least `1 - ratio` of the smaller box, the
//!   snitch's box is the smaller and the snitch is further from OPNet's fixed camera position
//!   ([`OPNET_CAMERA`]) than that object (centres from the scene's per-frame `locations`);
//! - **occluded** (OPNet's `full_occlusion`): neither visible nor contained.
//!
//! Frames past the video's last frame (a slide ending at frame 300) are ignored.

use std::collections::HashMap;

use crate::classes::is_cone_instance;
use crate::formats::{GroundTruth, MovementKind, SNITCH_CLASS, SNITCH_INSTANCE, Scene};

/// The camera position OPNet's visibility script measures distances from.
pub const OPNET_CAMERA: [f64; 3] = [7.1146, -6.1746, 5.5963];

/// Per-frame membership of one video's frames in the categories.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameCategories {
    pub visible: Vec<bool>,
    pub contained: Vec<bool>,
    pub carried: Vec<bool>,
}

impl FrameCategories {
    pub fn frames(&self) -> usize {
        self.visible.len()
    }

    pub fn occluded(&self, frame: usize) -> bool {
        !self.visible[frame] && !self.contained[frame]
    }
}

fn mask(frames: usize, ranges: impl IntoIterator<Item = (i64, i64)>) -> Vec<bool> {
    let mut out = vec![false; frames];
    for (from, to) in ranges {
        let to = to.min(frames as i64 - 1);
        for f in from.max(0)..=to {
            out[f as usize] = true;
        }
    }
    out
}

/// The containment ranges of objects by cones: `(cone, contained instance, from, to)`, with `to`
/// the start of the cone's next `_pick_place` or `open_end` when there is none.
pub(crate) fn containments(scene: &Scene, open_end: i64) -> Vec<(&str, &str, i64, i64, usize)> {
    let mut out = Vec::new();
    for (cone, moves) in &scene.movements {
        if !is_cone_instance(cone) {
            continue;
        }
        for (k, m) in moves.iter().enumerate() {
            let (Some(MovementKind::Contain), Some(other)) = (m.kind(), m.other.as_deref()) else { continue };
            let release = moves[k..]
                .iter()
                .find(|n| n.kind() == Some(MovementKind::PickPlace))
                .map_or(open_end, |n| n.start);
            out.push((cone.as_str(), other, m.end, release, k));
        }
    }
    out
}

/// OPNet's contained frames of the snitch.
pub fn contained_frames(scene: &Scene, frames: usize) -> Vec<bool> {
    let ranges = containments(scene, 299)
        .into_iter()
        .filter(|(_, other, ..)| *other == SNITCH_INSTANCE)
        .map(|(_, _, from, to, _)| (from, to));
    mask(frames, ranges)
}

/// OPNet's contained-and-moving (carried) frames of the snitch.
pub fn carried_frames(scene: &Scene, frames: usize) -> Vec<bool> {
    let mut ranges = Vec::new();
    for (cone, other, _, release, k) in containments(scene, 299) {
        if other != SNITCH_INSTANCE {
            continue;
        }
        let moves = &scene.movements[cone];
        for slide in moves[k..].iter().filter(|n| n.kind() == Some(MovementKind::Slide)) {
            if slide.end <= release {
                ranges.push((slide.start, slide.end));
            }
        }
    }
    mask(frames, ranges)
}

/// Why OPNet's visibility cannot be computed for a video.
#[derive(Debug, Clone, PartialEq)]
pub enum VisibilityError {
    /// An object of the scene has no boxes in `<video>_bb.json`.
    NoBoxes(String),
    /// An object has fewer per-frame `locations` than the video has frames.
    NoLocations(String),
}

impl std::fmt::Display for VisibilityError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            VisibilityError::NoBoxes(key) => write!(f, "`{key}` has no boxes in the ground truth"),
            VisibilityError::NoLocations(instance) => write!(
                f,
                "`{instance}` has no per-frame `locations` in the scene, which OPNet's visibility needs \
                 (give its annotation files, or score visibility from perception)"
            ),
        }
    }
}

/// OPNet's visible frames of the snitch with a visibility ratio (`0.0` for its `visibility_rate_gt_0`).
pub fn visible_frames(
    scene: &Scene,
    truth: &GroundTruth,
    frames: usize,
    ratio: f64,
) -> Result<Vec<bool>, VisibilityError> {
    let threshold = 1.0 - ratio;
    // Objects left out as contained: by class, over [contain end, next pick-up start or 300].
    let class_of: HashMap<&str, String> =
        scene.objects.iter().map(|o| (o.instance.as_str(), o.class())).collect();
    let mut hidden_classes: HashMap<String, Vec<(i64, i64)>> = HashMap::new();
    for (_, other, from, to, _) in containments(scene, 300) {
        if let Some(class) = class_of.get(other) {
            hidden_classes.entry(class.clone()).or_default().push((from, to));
        }
    }
    struct Object<'a> {
        class: String,
        boxes: &'a [[i32; 4]],
        locations: &'a [[f64; 3]],
    }
    let mut objects = Vec::with_capacity(scene.objects.len());
    for o in &scene.objects {
        let key = o.key();
        let boxes = truth.objects.get(&key).ok_or(VisibilityError::NoBoxes(key))?;
        if boxes.len() < frames {
            return Err(VisibilityError::NoBoxes(o.key()));
        }
        if o.locations.0.len() < frames {
            return Err(VisibilityError::NoLocations(o.instance.clone()));
        }
        objects.push(Object { class: o.class(), boxes, locations: &o.locations.0 });
    }
    let distance = |p: [f64; 3]| {
        ((OPNET_CAMERA[0] - p[0]).powi(2)
            + (OPNET_CAMERA[1] - p[1]).powi(2)
            + (OPNET_CAMERA[2] - p[2]).powi(2))
        .sqrt()
    };
    let mut out = vec![false; frames];
    for (f, visible) in out.iter_mut().enumerate() {
        let shown = |o: &Object| {
            hidden_classes
                .get(&o.class)
                .is_none_or(|ranges| ranges.iter().all(|&(a, b)| (f as i64) < a || (f as i64) > b))
        };
        let present: Vec<&Object> = objects.iter().filter(|o| shown(o)).collect();
        let Some(snitch_at) = present.iter().position(|o| o.class == SNITCH_CLASS) else { continue };
        let snitch = present[snitch_at];
        let covered = present.iter().enumerate().any(|(j, other)| {
            j != snitch_at
                && snitch_is_covered(
                    snitch.boxes[f],
                    other.boxes[f],
                    distance(snitch.locations[f]),
                    distance(other.locations[f]),
                    threshold,
                )
        });
        *visible = !covered;
    }
    Ok(out)
}

/// OPNet's `_check_if_obj_occluded` for the snitch (first box) against another object (second),
/// boxes `[x, y, w, h]`.
fn snitch_is_covered(a: [i32; 4], b: [i32; 4], distance_a: f64, distance_b: f64, threshold: f64) -> bool {
    let xyxy = |[x, y, w, h]: [i32; 4]| {
        [i64::from(x), i64::from(y), i64::from(x) + i64::from(w), i64::from(y) + i64::from(h)]
    };
    let (a, b) = (xyxy(a), xyxy(b));
    let inter = (a[2].min(b[2]) - a[0].max(b[0]) + 1).max(0) * (a[3].min(b[3]) - a[1].max(b[1]) + 1).max(0);
    let area = |x: [i64; 4]| (x[2] - x[0] + 1) * (x[3] - x[1] + 1);
    let (area_a, area_b) = (area(a), area(b));
    let smaller = area_a.min(area_b);
    if smaller == 0 {
        return false;
    }
    let ratio = inter as f64 / smaller as f64;
    ratio >= threshold && area_a < area_b && distance_a > distance_b
}
