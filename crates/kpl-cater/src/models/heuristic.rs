//! OPNet's programmed heuristic baseline (`HeuristicReasoner` and `track_and_predict` in its
//! `baselines/`), reimplemented from its code, with its output exactly as it writes it:
//!
//! - while the snitch (its class) is detected, its detection box;
//! - when it disappears, track the detected object whose centre is nearest the last tracked
//!   position (`(x1 + x2) // 2`), remembering the lost one on a stack; when the tracked object
//!   disappears too, switch again and push it; when the object under it on the stack is detected
//!   again, go back to it; the snitch's reappearance clears the stack;
//! - objects are named by class: "the tracked object" is the first detection of that class in a
//!   frame (so of two identical cones, the first listed);
//! - while the snitch is not detected the prediction is a box of the snitch's last detected size
//!   centred on the tracked object, 15 pixels lower when that object is a large cone (OPNet's
//!   `LARGE_CONS_INDICES`); before the snitch was ever detected, the tracked object's own box;
//!   coordinates truncated to integers as Python's `int()` does;
//! - a frame with no detection at all leaves the state as it was (OPNet's `ValueError` path).

use crate::classes::{SNITCH_CLASS, is_large_cone};
use crate::formats::{Detection, IntBox, PerceptionFile};

#[derive(Debug, Clone, Copy)]
struct Found {
    cx: f64,
    cy: f64,
    w: f64,
    h: f64,
    bbox: [f64; 4],
}

/// OPNet's `get_label_bb`: the first detection of a class, its floor-divided centre and size.
fn label_bb(detections: &[Detection], class: Option<u32>) -> Option<Found> {
    let d = detections.iter().find(|d| Some(d.class) == class)?;
    let [x1, y1, x2, y2] = d.bbox;
    Some(Found {
        cx: ((x1 + x2) / 2.0).floor(),
        cy: ((y1 + y2) / 2.0).floor(),
        w: x2 - x1,
        h: y2 - y1,
        bbox: d.bbox,
    })
}

/// `cx >= 0 and cy >= 0`: how OPNet tests that a class was found.
fn found(f: Option<Found>) -> Option<Found> {
    f.filter(|f| f.cx >= 0.0 && f.cy >= 0.0)
}

#[derive(Debug)]
struct State {
    target_pos: (f64, f64),
    target_sz: (f64, f64),
    snitch_box: [f64; 4],
    object_label: Option<u32>,
    object_sz: Option<(f64, f64)>,
    stack: Vec<Option<u32>>,
    snitch_visible: bool,
}

impl State {
    fn update(&mut self, f: Found, label: Option<u32>, snitch: Option<u32>) {
        self.target_pos = (f.cx, f.cy);
        self.target_sz = (f.w, f.h);
        self.object_label = label;
        if label == snitch {
            self.object_sz = Some((f.w, f.h));
        }
    }

    /// OPNet's `_get_index_of_closest_object`: the class of the detection nearest the target.
    fn closest(&self, detections: &[Detection]) -> Option<u32> {
        let (tx, ty) = self.target_pos;
        let mut best: Option<(f64, u32)> = None;
        for d in detections {
            let [x1, y1, x2, y2] = d.bbox;
            let (cx, cy) = (((x1 + x2) / 2.0).floor(), ((y1 + y2) / 2.0).floor());
            let distance = ((cx - tx).powi(2) + (cy - ty).powi(2)).sqrt();
            if best.is_none_or(|(b, _)| distance < b) {
                best = Some((distance, d.class));
            }
        }
        best.map(|(_, class)| class)
    }
}

/// Runs the heuristic over a video's perception; one box per frame.
pub fn heuristic(perception: &PerceptionFile) -> Vec<IntBox> {
    let snitch =
        perception.classes.iter().position(|c| c == SNITCH_CLASS).and_then(|i| u32::try_from(i).ok());
    let mut s = State {
        target_pos: (-1.0, 1.0),
        target_sz: (0.0, 0.0),
        snitch_box: [-1.0; 4],
        object_label: None,
        object_sz: None,
        stack: Vec::new(),
        snitch_visible: false,
    };
    let large_cone = |label: Option<u32>| {
        label.and_then(|l| perception.classes.get(l as usize)).is_some_and(|c| is_large_cone(c))
    };
    let mut out = Vec::with_capacity(perception.frames.len());
    for detections in &perception.frames {
        step(&mut s, detections, snitch);
        let trunc = |v: f64| v.trunc() as i32;
        let prediction = if s.snitch_visible {
            s.snitch_box.map(trunc)
        } else {
            let (cx, cy) = s.target_pos;
            let (w, h) = match s.object_sz {
                Some(size) => size,
                None => s.target_sz,
            };
            let cy = if s.object_sz.is_some() && large_cone(s.object_label) { cy + 15.0 } else { cy };
            [trunc(cx - w / 2.0), trunc(cy - h / 2.0), trunc(cx + w / 2.0), trunc(cy + h / 2.0)]
        };
        out.push(prediction);
    }
    out
}

/// One frame of `HeuristicReasoner.track_for_frame`.
fn step(s: &mut State, detections: &[Detection], snitch: Option<u32>) {
    if let Some(f) = found(label_bb(detections, snitch)) {
        s.snitch_visible = true;
        s.snitch_box = f.bbox;
        s.update(f, snitch, snitch);
        s.stack.clear();
        return;
    }
    s.snitch_visible = false;
    // Switch to the nearest object; OPNet's argmin over no detection raises and skips the frame.
    let switch = |s: &mut State, push: Option<u32>| {
        let Some(label) = s.closest(detections) else { return };
        if let Some(f) = label_bb(detections, Some(label)) {
            s.update(f, Some(label), snitch);
        }
        s.stack.push(push);
    };
    if s.stack.is_empty() {
        switch(s, snitch);
        return;
    }
    let current = s.object_label;
    match label_bb(detections, current) {
        None => switch(s, current),
        Some(f) => {
            let previous = s.stack.last().copied().flatten();
            match found(label_bb(detections, previous)) {
                Some(p) => {
                    s.update(p, previous, snitch);
                    s.stack.pop();
                }
                None => s.update(f, current, snitch),
            }
        }
    }
}
