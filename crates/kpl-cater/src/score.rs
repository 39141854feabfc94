//! OPNet-style scoring of snitch localisation.
//!
//! Matched to OPNet's evaluation code (Shamsian et al., `ResultsAnalyzer` in its tracking utilities
//! and the containment annotations script; see docs/cater.md): IoU on integer boxes with the
//! +1-pixel convention (`(x2 - x1 + 1) * (y2 - y1 + 1)`), a mean per video over the frames of a
//! category, a video without frames in a category left out of that category, and the mean ± SEM
//! (sample standard deviation over √n) over videos. Categories per frame:
//!
//! - contained: from the end of a cone's `_contain` of the snitch to the start of that cone's next
//!   `_pick_place` (to the last frame if none), inclusive;
//! - carried: the frames of that cone's `_slide`s after the contain that end by the containment's end;
//! - visible: the snitch is in the perfect perception of the frame;
//! - occluded: neither visible nor contained.
//!
//! As in the AAPA paper (IV-C), frames count from the first frame the snitch is detected in the
//! perception mode used. The second metric is the L2 distance of box centres in pixels.

use serde::{Deserialize, Serialize};

use crate::formats::{IntBox, SNITCH_INSTANCE, Scene};

/// IoU of two integer boxes, OPNet's +1 convention.
pub fn iou(a: IntBox, b: IntBox) -> f64 {
    let w = (a[2].min(b[2]) - a[0].max(b[0]) + 1).max(0);
    let h = (a[3].min(b[3]) - a[1].max(b[1]) + 1).max(0);
    let inter = f64::from(w) * f64::from(h);
    let area = |x: IntBox| f64::from((x[2] - x[0] + 1).max(0)) * f64::from((x[3] - x[1] + 1).max(0));
    let union = area(a) + area(b) - inter;
    if union <= 0.0 { 0.0 } else { inter / union }
}

/// Distance of the box centres in pixels.
pub fn centre_distance(a: IntBox, b: IntBox) -> f64 {
    let c = |x: IntBox| [f64::from(x[0] + x[2]) / 2.0, f64::from(x[1] + x[3]) / 2.0];
    let (p, q) = (c(a), c(b));
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
}

/// The categories of Table I, in its column order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Category {
    Visible,
    Occluded,
    Contained,
    Carried,
    Overall,
}

impl Category {
    pub const ALL: [Category; 5] =
        [Category::Visible, Category::Occluded, Category::Contained, Category::Carried, Category::Overall];

    pub fn name(self) -> &'static str {
        match self {
            Category::Visible => "visible",
            Category::Occluded => "occluded",
            Category::Contained => "contained",
            Category::Carried => "carried",
            Category::Overall => "overall",
        }
    }
}

/// Per-frame category membership of one video.
#[derive(Debug, Clone, PartialEq)]
pub struct Categories {
    pub visible: Vec<bool>,
    pub contained: Vec<bool>,
    pub carried: Vec<bool>,
}

impl Categories {
    /// `visible[f]`: the snitch is visible in frame f (from perfect perception).
    pub fn new(scene: &Scene, visible: Vec<bool>) -> Categories {
        let frames = visible.len();
        let (contained, carried) = containment_frames(scene, frames);
        Categories { visible, contained, carried }
    }

    pub fn contains(&self, category: Category, frame: usize) -> bool {
        match category {
            Category::Visible => self.visible[frame],
            Category::Occluded => !self.visible[frame] && !self.contained[frame],
            Category::Contained => self.contained[frame],
            Category::Carried => self.carried[frame],
            Category::Overall => true,
        }
    }
}

/// OPNet's containment rules on a scene's movements (see the module docs).
pub fn containment_frames(scene: &Scene, frames: usize) -> (Vec<bool>, Vec<bool>) {
    let mut contained = vec![false; frames];
    let mut carried = vec![false; frames];
    let last = frames.max(1) as i64 - 1;
    let mark = |flags: &mut Vec<bool>, from: i64, to: i64| {
        for f in from.max(0)..=to.min(last) {
            flags[f as usize] = true;
        }
    };
    for (instance, moves) in &scene.movements {
        if !instance.contains("Cone") {
            continue;
        }
        for (k, m) in moves.iter().enumerate() {
            if !m.action.contains("_contain") || m.other.as_deref() != Some(SNITCH_INSTANCE) {
                continue;
            }
            let later = &moves[k..];
            let end = later.iter().find(|n| n.action.contains("_pick_place")).map_or(last, |n| n.start);
            mark(&mut contained, m.end, end);
            for slide in later.iter().filter(|n| n.action.contains("_slide") && n.end <= end) {
                mark(&mut carried, slide.start, slide.end);
            }
        }
    }
    (contained, carried)
}

/// One video's mean IoU and mean L2 per category (`None`: no frame of that category).
#[derive(Debug, Clone, PartialEq)]
pub struct VideoScore {
    pub iou: [Option<f64>; 5],
    pub l2: [Option<f64>; 5],
}

/// Scores predictions against the snitch's ground truth from `first_frame` on (no frame counts if
/// the snitch is never detected).
pub fn score_video(
    predictions: &[IntBox],
    truth: &[IntBox],
    categories: &Categories,
    first_frame: Option<usize>,
) -> VideoScore {
    let mut iou_sum = [0.0; 5];
    let mut l2_sum = [0.0; 5];
    let mut count = [0usize; 5];
    let frames = predictions.len().min(truth.len()).min(categories.visible.len());
    if let Some(first) = first_frame {
        for f in first..frames {
            let (i, d) = (iou(predictions[f], truth[f]), centre_distance(predictions[f], truth[f]));
            for (c, category) in Category::ALL.iter().enumerate() {
                if categories.contains(*category, f) {
                    iou_sum[c] += i;
                    l2_sum[c] += d;
                    count[c] += 1;
                }
            }
        }
    }
    let mean = |sum: [f64; 5]| std::array::from_fn(|c| (count[c] > 0).then(|| sum[c] / count[c] as f64));
    VideoScore { iou: mean(iou_sum), l2: mean(l2_sum) }
}

/// Mean ± SEM over the videos that have the category.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub mean: f64,
    pub sem: f64,
    /// Videos with at least one frame of the category.
    pub videos: usize,
}

pub fn summarize(values: impl Iterator<Item = f64>, scale: f64) -> Summary {
    let values: Vec<f64> = values.map(|v| v * scale).collect();
    let n = values.len();
    if n == 0 {
        return Summary { mean: 0.0, sem: 0.0, videos: 0 };
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let sem = if n < 2 {
        0.0
    } else {
        let variance = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        (variance / n as f64).sqrt()
    };
    Summary { mean, sem, videos: n }
}

/// A row of Table I for one metric.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CategoryTable {
    pub visible: Summary,
    pub occluded: Summary,
    pub contained: Summary,
    pub carried: Summary,
    pub overall: Summary,
}

impl CategoryTable {
    pub fn get(&self, category: Category) -> Summary {
        match category {
            Category::Visible => self.visible,
            Category::Occluded => self.occluded,
            Category::Contained => self.contained,
            Category::Carried => self.carried,
            Category::Overall => self.overall,
        }
    }

    /// IoU in percent, L2 in pixels.
    pub fn from_scores(scores: &[VideoScore], iou: bool) -> CategoryTable {
        let column = |c: usize| {
            let values = scores.iter().filter_map(|s| if iou { s.iou[c] } else { s.l2[c] });
            summarize(values, if iou { 100.0 } else { 1.0 })
        };
        CategoryTable {
            visible: column(0),
            occluded: column(1),
            contained: column(2),
            carried: column(3),
            overall: column(4),
        }
    }
}
