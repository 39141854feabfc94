//! What the metrics score: a [`Sequence`] of frames at increasing valid times, each with the true
//! objects and the hypotheses (a tracker's percepts, an anchoring's symbols) on the ground plane.
//! Ids are interned per side, so the metrics work on dense indices; the order of the objects in a
//! frame is kept (py-motmetrics' matching visits them in that order).

use std::collections::HashMap;

use kpl_core::Time;

use crate::error::SequenceError;

/// A position on the ground plane, metres.
pub type Pos = [f64; 2];

/// One object in one frame: its interned id and its position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Object {
    pub id: u32,
    pub pos: Pos,
}

/// The objects of both sides at one valid time.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub time: Time,
    pub truth: Vec<Object>,
    pub hypotheses: Vec<Object>,
}

/// A pair of a true object and a hypothesis of one frame (indices into the frame's lists) and
/// their Euclidean distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    pub truth: usize,
    pub hypothesis: usize,
    pub distance: f64,
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
        if let Some(last) = self.frames.last()
            && time <= last.time
        {
            return Err(SequenceError::TimeNotIncreasing { time, previous: last.time });
        }
        let truth: Vec<(&str, Pos)> = truth.into_iter().collect();
        let hypotheses: Vec<(&str, Pos)> = hypotheses.into_iter().collect();
        check_side(time, Side::Truth, &truth)?;
        check_side(time, Side::Hypotheses, &hypotheses)?;
        let truth = truth.iter().map(|&(id, pos)| Object { id: self.truth_ids.intern(id), pos }).collect();
        let hypotheses =
            hypotheses.iter().map(|&(id, pos)| Object { id: self.hypothesis_ids.intern(id), pos }).collect();
        self.frames.push(Frame { time, truth, hypotheses });
        Ok(())
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
                .map(|f| Frame { time: f.time, truth: f.hypotheses.clone(), hypotheses: f.truth.clone() })
                .collect(),
            truth_ids: self.hypothesis_ids.clone(),
            hypothesis_ids: self.truth_ids.clone(),
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

/// Above this many candidate pairs a frame's close pairs are found through a grid.
const BRUTE_FORCE_PAIRS: usize = 1024;

impl Frame {
    /// The pairs of a true object and a hypothesis at most `radius` apart, ordered by the true
    /// object's index, then the hypothesis'. The distance is `sqrt(dx² + dy²)` as NumPy's norm
    /// computes it, so a pair exactly at the radius is the same pair for the reference tools.
    pub fn pairs_within(&self, radius: f64, out: &mut Vec<Pair>) {
        out.clear();
        if self.truth.is_empty() || self.hypotheses.is_empty() {
            return;
        }
        if self.truth.len() * self.hypotheses.len() <= BRUTE_FORCE_PAIRS || radius.is_nan() || radius <= 0.0 {
            for (i, t) in self.truth.iter().enumerate() {
                for (j, h) in self.hypotheses.iter().enumerate() {
                    let distance = distance(t.pos, h.pos);
                    if distance <= radius {
                        out.push(Pair { truth: i, hypothesis: j, distance });
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
                            out.push(Pair { truth: i, hypothesis: j, distance });
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
                        brute.push(Pair { truth: i, hypothesis: j, distance: d });
                    }
                }
            }
            assert_eq!(grid, brute, "radius {radius}");
        }
    }
}
