//! LA-CATER's perfect perception as OPNet's script makes it
//! (`get_perfect_perception_and_visible_snitch_ratio.py`, `perception_mode="visible_only"`; read,
//! reimplemented), and the same with occlusion by the union of nearer boxes (hard scenes):
//!
//! 1. every object of the scene, in the scene's order, with its OPNet class index and its box
//!    from `<video>_bb.json` (`[x, y, w, h]` -> `[x, y, x + w, y + h]`);
//! 2. left out while contained: an object whose *class* a cone contains, from the contain's end
//!    to the start of that cone's next pick-up (frame 300 if none), both included;
//! 3. left out while occluded: of two remaining objects whose boxes overlap by at least `1 -
//!    visible_ratio` of the smaller one (OPNet's +1-pixel areas), the smaller is left out if it is
//!    also further from OPNet's fixed camera position ([`OPNET_CAMERA`]); with
//!    [`Occlusion::Union`], an object is left out when the union of the boxes of the remaining
//!    objects nearer to the video's camera covers its box.
//!
//! The result is what OPNet's pickle holds: per frame the boxes `[x1, y1, x2, y2]` and the labels.

use crate::categories::{OPNET_CAMERA, containments};
use crate::classes::opnet_index;
use crate::formats::{GroundTruth, Scene};

/// How occlusion is decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Occlusion {
    /// OPNet's: one box at a time, with its visibility ratio (`0.0`: the box must lie entirely
    /// within the other's).
    OneBox { visible_ratio: f64 },
    /// The union of the nearer objects' boxes covers the box (hard scenes), distances from this
    /// camera location.
    Union { camera: [f64; 3] },
}

/// One frame's perception: `(OPNet label, [x1, y1, x2, y2])` of each object perceived.
pub type FrameDetections = Vec<(i64, [i64; 4])>;

/// Per frame, `(OPNet label, [x1, y1, x2, y2])` of each object perceived; `None` if an object's
/// class is not one of OPNet's or the files disagree (no boxes or locations for an object).
pub fn perfect_perception(
    scene: &Scene,
    truth: &GroundTruth,
    frames: usize,
    occlusion: Occlusion,
) -> Option<Vec<FrameDetections>> {
    struct Object<'a> {
        label: i64,
        boxes: &'a [[i32; 4]],
        locations: &'a [[f64; 3]],
    }
    let mut objects = Vec::with_capacity(scene.objects.len());
    for o in &scene.objects {
        let boxes = truth.objects.get(&o.key()).filter(|b| b.len() >= frames)?;
        if o.locations.0.len() < frames {
            return None;
        }
        objects.push(Object { label: i64::from(opnet_index(&o.class())?), boxes, locations: &o.locations.0 });
    }
    // Contained ranges by label.
    let mut hidden: Vec<(i64, i64, i64)> = Vec::new();
    for (_, other, from, to, _) in containments(scene, 300) {
        if let Some(o) = scene.objects.iter().find(|o| o.instance == other) {
            hidden.push((i64::from(opnet_index(&o.class())?), from, to));
        }
    }
    let xyxy = |[x, y, w, h]: [i32; 4]| {
        let [x, y, w, h] = [x, y, w, h].map(i64::from);
        [x, y, x + w, y + h]
    };
    let mut out = Vec::with_capacity(frames);
    for f in 0..frames {
        let at = f as i64;
        let shown: Vec<&Object> = objects
            .iter()
            .filter(|o| hidden.iter().all(|&(label, a, b)| label != o.label || at < a || at > b))
            .collect();
        let boxes: Vec<[i64; 4]> = shown.iter().map(|o| xyxy(o.boxes[f])).collect();
        let mut occluded = vec![false; shown.len()];
        match occlusion {
            Occlusion::OneBox { visible_ratio } => {
                let distances: Vec<f64> =
                    shown.iter().map(|o| distance(OPNET_CAMERA, o.locations[f])).collect();
                for i in 0..shown.len() {
                    for j in i..shown.len() {
                        match one_box(boxes[i], boxes[j], distances[i], distances[j], 1.0 - visible_ratio) {
                            Some(true) => occluded[i] = true,
                            Some(false) => occluded[j] = true,
                            None => {}
                        }
                    }
                }
            }
            Occlusion::Union { camera } => {
                let distances: Vec<f64> = shown.iter().map(|o| distance(camera, o.locations[f])).collect();
                for i in 0..shown.len() {
                    let nearer: Vec<[i64; 4]> =
                        (0..shown.len()).filter(|&j| distances[j] < distances[i]).map(|j| boxes[j]).collect();
                    occluded[i] = union_covers(boxes[i], &nearer);
                }
            }
        }
        out.push(
            shown
                .iter()
                .zip(&boxes)
                .zip(&occluded)
                .filter(|(_, hidden)| !**hidden)
                .map(|((o, b), _)| (o.label, *b))
                .collect(),
        );
    }
    Some(out)
}

fn distance(camera: [f64; 3], p: [f64; 3]) -> f64 {
    ((camera[0] - p[0]).powi(2) + (camera[1] - p[1]).powi(2) + (camera[2] - p[2]).powi(2)).sqrt()
}

/// OPNet's `_check_if_obj_occluded` on `[x1, y1, x2, y2]` boxes: `Some(true)` if the first is
/// occluded, `Some(false)` if the second is, `None` if neither.
fn one_box(a: [i64; 4], b: [i64; 4], distance_a: f64, distance_b: f64, threshold: f64) -> Option<bool> {
    let inter = (a[2].min(b[2]) - a[0].max(b[0]) + 1).max(0) * (a[3].min(b[3]) - a[1].max(b[1]) + 1).max(0);
    let area = |x: [i64; 4]| (x[2] - x[0] + 1) * (x[3] - x[1] + 1);
    let (area_a, area_b) = (area(a), area(b));
    let smaller = area_a.min(area_b);
    if smaller <= 0 || (inter as f64 / smaller as f64) < threshold {
        return None;
    }
    if area_a < area_b && distance_a > distance_b {
        Some(true)
    } else if area_b < area_a && distance_b > distance_a {
        Some(false)
    } else {
        None
    }
}

/// Whether the union of `others` covers every pixel of `target` (boxes of inclusive pixel corners),
/// by cutting the target at every occluder's edge.
pub fn union_covers(target: [i64; 4], others: &[[i64; 4]]) -> bool {
    let [tx1, ty1, tx2, ty2] = target;
    if tx2 < tx1 || ty2 < ty1 {
        return false;
    }
    let clipped: Vec<[i64; 4]> = others
        .iter()
        .map(|o| [o[0].max(tx1), o[1].max(ty1), o[2].min(tx2), o[3].min(ty2)])
        .filter(|o| o[0] <= o[2] && o[1] <= o[3])
        .collect();
    if clipped.is_empty() {
        return false;
    }
    let mut xs: Vec<i64> = vec![tx1, tx2 + 1];
    let mut ys: Vec<i64> = vec![ty1, ty2 + 1];
    for o in &clipped {
        xs.extend([o[0], o[2] + 1]);
        ys.extend([o[1], o[3] + 1]);
    }
    xs.sort_unstable();
    xs.dedup();
    ys.sort_unstable();
    ys.dedup();
    xs.windows(2).all(|x| {
        ys.windows(2).all(|y| {
            clipped.iter().any(|o| o[0] <= x[0] && x[1] - 1 <= o[2] && o[1] <= y[0] && y[1] - 1 <= o[3])
        })
    })
}

#[cfg(test)]
mod tests {
    use super::union_covers;

    #[test]
    fn two_boxes_that_each_cover_half_cover_the_whole() {
        let target = [10, 10, 19, 19];
        assert!(!union_covers(target, &[[0, 0, 14, 30]]));
        assert!(union_covers(target, &[[0, 0, 14, 30], [15, 5, 40, 25]]));
        // A one-pixel gap between them.
        assert!(!union_covers(target, &[[0, 0, 14, 30], [16, 5, 40, 25]]));
        assert!(!union_covers(target, &[]));
    }
}
