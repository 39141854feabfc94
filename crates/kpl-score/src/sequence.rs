//! What the metrics score: a [`Sequence`] of frames at increasing valid times, each with the true
//! objects and the hypotheses (a tracker's percepts, an anchoring's symbols), either as points on
//! the ground plane (compared by distance) or as boxes in pixels (compared by intersection over
//! union, as MOTChallenge's evaluation does: the pair's distance is `1 - IoU`). Ids are interned
//! per side, so the metrics work on dense indices; the order of the objects in a frame is kept
//! (py-motmetrics' matching visits them in that order).

use std::collections::HashMap;

use kpl_core::Time;

use crate::error::SequenceError;

/// A position on the ground plane, metres.
pub type Pos = [f64; 2];

/// A box in pixels, `[left, top, width, height]` (MOTChallenge's convention).
pub type Bbox = [f64; 4];

/// One object in one frame: its interned id, its position (a box's centre) and its box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Object {
    pub id: u32,
    pub pos: Pos,
    /// The box, in a sequence of boxes.
    pub bbox: Option<Bbox>,
}

/// The objects of both sides at one valid time.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub time: Time,
    pub truth: Vec<Object>,
    pub hypotheses: Vec<Object>,
    /// The objects are boxes, compared by IoU.
    pub boxes: bool,
}

/// A pair of a true object and a hypothesis of one frame (indices into the frame's lists) and
/// their distance: Euclidean for points, `1 - IoU` for boxes (whose IoU is kept too).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    pub truth: usize,
    pub hypothesis: usize,
    pub distance: f64,
    /// The boxes' intersection over union (0 for points).
    pub iou: f64,
}

/// Names of one side's objects, interned in order of first appearance.
#[derive(Debug, Clone, Default)]
pub struct Ids {
    names: Vec<String>,
    index: HashMap<String, u32>,
}

impl Ids {
    /// The names, indexed by id.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// The name of an id of this side.
    pub fn name(&self, id: u32) -> &str {
        &self.names[id as usize]
    }

    /// The id of a name, if it appeared.
    pub fn get(&self, name: &str) -> Option<u32> {
        self.index.get(name).copied()
    }

    fn intern(&mut self, name: &str) -> u32 {
        if let Some(&id) = self.index.get(name) {
            return id;
        }
        let id = u32::try_from(self.names.len()).unwrap_or(u32::MAX);
        self.names.push(name.to_string());
        self.index.insert(name.to_string(), id);
        id
    }
}

/// Frames in increasing valid time, with both sides' ids.
#[derive(Debug, Clone, Default)]
pub struct Sequence {
    frames: Vec<Frame>,
    truth_ids: Ids,
    hypothesis_ids: Ids,
    /// The frames hold boxes (set by the first frame pushed).
    boxes: bool,
}

/// Which side of a sequence an object is on (for messages).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Truth,
    Hypotheses,
}

impl std::fmt::Display for Side {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Side::Truth => "ground truth",
            Side::Hypotheses => "hypotheses",
        })
    }
}

impl Sequence {
    pub fn new() -> Sequence {
        Sequence::default()
    }

    /// Appends the frame at `time` with the true objects and the hypotheses, each `(id, pos)`.
    /// Refused (and nothing added) when `time` is not after the last frame's, an id appears twice
    /// on one side, or a position is not finite.
    pub fn push_frame<'a>(
        &mut self,
        time: Time,
        truth: impl IntoIterator<Item = (&'a str, Pos)>,
        hypotheses: impl IntoIterator<Item = (&'a str, Pos)>,
    ) -> Result<(), SequenceError> {
        self.check_frame(time, false)?;
        let truth: Vec<(&str, Pos)> = truth.into_iter().collect();
        let hypotheses: Vec<(&str, Pos)> = hypotheses.into_iter().collect();
        check_side(time, Side::Truth, &truth)?;
        check_side(time, Side::Hypotheses, &hypotheses)?;
        let truth = truth
            .iter()
            .map(|&(id, pos)| Object { id: self.truth_ids.intern(id), pos, bbox: None })
            .collect();
        let hypotheses = hypotheses
            .iter()
            .map(|&(id, pos)| Object { id: self.hypothesis_ids.intern(id), pos, bbox: None })
            .collect();
        self.frames.push(Frame { time, truth, hypotheses, boxes: false });
        Ok(())
    }

    /// Appends a frame of boxes in pixels (`[left, top, width, height]`), compared by IoU.
    /// Refused as [`Sequence::push_frame`] is, and when a box is not four finite numbers with
    /// sides at least 0, or the sequence holds points.
    pub fn push_frame_boxes<'a>(
        &mut self,
        time: Time,
        truth: impl IntoIterator<Item = (&'a str, Bbox)>,
        hypotheses: impl IntoIterator<Item = (&'a str, Bbox)>,
    ) -> Result<(), SequenceError> {
        self.check_frame(time, true)?;
        let truth: Vec<(&str, Bbox)> = truth.into_iter().collect();
        let hypotheses: Vec<(&str, Bbox)> = hypotheses.into_iter().collect();
        check_boxes(time, Side::Truth, &truth)?;
        check_boxes(time, Side::Hypotheses, &hypotheses)?;
        let centre = |b: Bbox| [b[0] + b[2] / 2.0, b[1] + b[3] / 2.0];
        let truth = truth
            .iter()
            .map(|&(id, b)| Object { id: self.truth_ids.intern(id), pos: centre(b), bbox: Some(b) })
            .collect();
        let hypotheses = hypotheses
            .iter()
            .map(|&(id, b)| Object { id: self.hypothesis_ids.intern(id), pos: centre(b), bbox: Some(b) })
            .collect();
        self.boxes = true;
        self.frames.push(Frame { time, truth, hypotheses, boxes: true });
        Ok(())
    }

    fn check_frame(&self, time: Time, boxes: bool) -> Result<(), SequenceError> {
        if let Some(last) = self.frames.last() {
            if time <= last.time {
                return Err(SequenceError::TimeNotIncreasing { time, previous: last.time });
            }
            if last.boxes != boxes {
                return Err(SequenceError::MixedGeometry { time });
            }
        }
        Ok(())
    }

    /// Whether the frames hold boxes (compared by IoU) rather than points.
    pub fn boxes(&self) -> bool {
        self.boxes
    }

    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }

    pub fn truth_ids(&self) -> &Ids {
        &self.truth_ids
    }

    pub fn hypothesis_ids(&self) -> &Ids {
        &self.hypothesis_ids
    }

    /// The same frames with the two sides exchanged (the identity measures and HOTA are
    /// symmetric; the CLEAR MOT metrics are not).
    pub fn swapped(&self) -> Sequence {
        Sequence {
            frames: self
                .frames
                .iter()
                .map(|f| Frame {
                    time: f.time,
                    truth: f.hypotheses.clone(),
                    hypotheses: f.truth.clone(),
                    boxes: f.boxes,
                })
                .collect(),
            truth_ids: self.hypothesis_ids.clone(),
            hypothesis_ids: self.truth_ids.clone(),
            boxes: self.boxes,
        }
    }

    /// The number of true objects over all frames.
    pub fn truth_detections(&self) -> usize {
        self.frames.iter().map(|f| f.truth.len()).sum()
    }

    /// The number of hypotheses over all frames.
    pub fn hypothesis_detections(&self) -> usize {
        self.frames.iter().map(|f| f.hypotheses.len()).sum()
    }
}

fn check_side(time: Time, side: Side, objects: &[(&str, Pos)]) -> Result<(), SequenceError> {
    let mut seen = std::collections::HashSet::with_capacity(objects.len());
    for &(id, pos) in objects {
        if !seen.insert(id) {
            return Err(SequenceError::DuplicateId { time, side, id: id.to_string() });
        }
        if !pos.iter().all(|c| c.is_finite()) {
            return Err(SequenceError::NotFinite { time, side, id: id.to_string() });
        }
    }
    Ok(())
}

fn check_boxes(time: Time, side: Side, objects: &[(&str, Bbox)]) -> Result<(), SequenceError> {
    let mut seen = std::collections::HashSet::with_capacity(objects.len());
    for &(id, b) in objects {
        if !seen.insert(id) {
            return Err(SequenceError::DuplicateId { time, side, id: id.to_string() });
        }
        if !(b.iter().all(|c| c.is_finite()) && b[2] >= 0.0 && b[3] >= 0.0) {
            return Err(SequenceError::NotFinite { time, side, id: id.to_string() });
        }
    }
    Ok(())
}

/// The intersection over union of two boxes `[left, top, width, height]`, as py-motmetrics'
/// `boxiou` and TrackEval's `_calculate_box_ious` compute it: corners `left + width` and
/// `top + height`, 0 without overlap.
pub fn iou(a: Bbox, b: Bbox) -> f64 {
    kpl_camera::PixelBox::from_array(a).iou(&kpl_camera::PixelBox::from_array(b))
}

/// Above this many candidate pairs a frame's close pairs are found through a grid.
const BRUTE_FORCE_PAIRS: usize = 1024;

impl Frame {
    /// The pairs of a true object and a hypothesis at most `radius` apart, ordered by the true
    /// object's index, then the hypothesis'. The distance is `sqrt(dx² + dy²)` as NumPy's norm
    /// computes it, so a pair exactly at the radius is the same pair for the reference tools.
    ///
    /// For boxes the distance is `1 - IoU`, and only overlapping pairs (IoU above 0) are given.
    pub fn pairs_within(&self, radius: f64, out: &mut Vec<Pair>) {
        out.clear();
        if self.truth.is_empty() || self.hypotheses.is_empty() {
            return;
        }
        if self.boxes {
            for (i, t) in self.truth.iter().enumerate() {
                for (j, h) in self.hypotheses.iter().enumerate() {
                    let (Some(a), Some(b)) = (t.bbox, h.bbox) else { continue };
                    let iou = iou(a, b);
                    let distance = 1.0 - iou;
                    if iou > 0.0 && distance <= radius {
                        out.push(Pair { truth: i, hypothesis: j, distance, iou });
                    }
                }
            }
            return;
        }
        if self.truth.len() * self.hypotheses.len() <= BRUTE_FORCE_PAIRS || radius.is_nan() || radius <= 0.0 {
            for (i, t) in self.truth.iter().enumerate() {
                for (j, h) in self.hypotheses.iter().enumerate() {
                    let distance = distance(t.pos, h.pos);
                    if distance <= radius {
                        out.push(Pair { truth: i, hypothesis: j, distance, iou: 0.0 });
                    }
                }
            }
            return;
        }
        // A uniform grid of the hypotheses, cells one radius wide: a pair within the radius lies
        // in neighbouring cells. (Cell indices saturate far out; that only merges far cells.)
        let cell = |p: Pos| ((p[0] / radius).floor() as i64, (p[1] / radius).floor() as i64);
        let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for (j, h) in self.hypotheses.iter().enumerate() {
            grid.entry(cell(h.pos)).or_default().push(j);
        }
        for (i, t) in self.truth.iter().enumerate() {
            let (cx, cy) = cell(t.pos);
            let start = out.len();
            for dx in -1..=1 {
                for dy in -1..=1 {
                    let key = (cx.saturating_add(dx), cy.saturating_add(dy));
                    for &j in grid.get(&key).map_or(&[][..], Vec::as_slice) {
                        let distance = distance(t.pos, self.hypotheses[j].pos);
                        if distance <= radius {
                            out.push(Pair { truth: i, hypothesis: j, distance, iou: 0.0 });
                        }
                    }
                }
            }
            out[start..].sort_by_key(|p| p.hypothesis);
            // Saturated cells may be visited twice.
            let mut k = start;
            let mut last = usize::MAX;
            for idx in start..out.len() {
                if out[idx].hypothesis != last {
                    last = out[idx].hypothesis;
                    out[k] = out[idx];
                    k += 1;
                }
            }
            out.truncate(k);
        }
    }
}

/// The Euclidean distance of two positions.
pub fn distance(a: Pos, b: Pos) -> f64 {
    let dx = a[0] - b[0];
    let dy = a[1] - b[1];
    (dx * dx + dy * dy).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_must_advance_and_ids_be_unique() {
        let mut s = Sequence::new();
        s.push_frame(0, [("a", [0.0, 0.0])], [("x", [1.0, 0.0])]).unwrap();
        assert!(matches!(
            s.push_frame(0, [], []),
            Err(SequenceError::TimeNotIncreasing { time: 0, previous: 0 })
        ));
        assert!(matches!(
            s.push_frame(1, [("a", [0.0, 0.0]), ("a", [1.0, 0.0])], []),
            Err(SequenceError::DuplicateId { side: Side::Truth, .. })
        ));
        assert!(matches!(
            s.push_frame(1, [], [("x", [f64::NAN, 0.0])]),
            Err(SequenceError::NotFinite { side: Side::Hypotheses, .. })
        ));
        assert_eq!(s.frames().len(), 1, "refused frames add nothing");
        assert_eq!(s.truth_ids().len(), 1);
    }

    #[test]
    fn the_grid_finds_the_same_pairs_as_brute_force() {
        let mut rng = 12345u64;
        let mut next = move || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((rng >> 11) as f64 / (1u64 << 53) as f64) * 200.0 - 100.0
        };
        let names: Vec<String> = (0..60).map(|i| format!("o{i}")).collect();
        let truth: Vec<(&str, Pos)> = names.iter().map(|n| (n.as_str(), [next(), next()])).collect();
        let hyps: Vec<(&str, Pos)> = names.iter().map(|n| (n.as_str(), [next(), next()])).collect();
        let mut s = Sequence::new();
        s.push_frame(0, truth, hyps).unwrap();
        let frame = &s.frames()[0];
        for radius in [3.0, 10.0, 40.0] {
            let mut grid = Vec::new();
            frame.pairs_within(radius, &mut grid);
            let mut brute = Vec::new();
            for (i, t) in frame.truth.iter().enumerate() {
                for (j, h) in frame.hypotheses.iter().enumerate() {
                    let d = distance(t.pos, h.pos);
                    if d <= radius {
                        brute.push(Pair { truth: i, hypothesis: j, distance: d, iou: 0.0 });
                    }
                }
            }
            assert_eq!(grid, brute, "radius {radius}");
        }
    }
}
