//! Scoring of snitch localisation as OPNet's `ResultsAnalyzer` does it: IoU on integer boxes with the
//! +1-pixel convention (`(x2 - x1 + 1) * (y2 - y1 + 1)`), a mean per video over the frames of a
//! category (a video without frames in a category is left out of it), and the mean ± SEM (sample
//! standard deviation over √n, as pandas gives it) over videos. The second metric is the L2 distance
//! of box centres in pixels (the AAPA paper's).
//!
//! By default every frame counts, as in OPNet's code; [`FramesScored::FromFirstDetection`] counts
//! frames from the first one in which the snitch is perceived, as the AAPA paper does (IV-C).

use serde::{Deserialize, Serialize};

use crate::categories::FrameCategories;
use crate::formats::IntBox;

/// IoU of two integer boxes, OPNet's +1 convention. Arithmetic is in 64 bits, so no box a file
/// can hold overflows it; a box with no area gives 0.
pub fn iou(a: IntBox, b: IntBox) -> f64 {
    let [a, b] = [a, b].map(|x| x.map(i64::from));
    let w = (a[2].min(b[2]) - a[0].max(b[0]) + 1).max(0);
    let h = (a[3].min(b[3]) - a[1].max(b[1]) + 1).max(0);
    let inter = w as f64 * h as f64;
    let area = |x: [i64; 4]| (x[2] - x[0] + 1).max(0) as f64 * (x[3] - x[1] + 1).max(0) as f64;
    let union = area(a) + area(b) - inter;
    if union <= 0.0 { 0.0 } else { inter / union }
}

/// Distance of the box centres in pixels.
pub fn centre_distance(a: IntBox, b: IntBox) -> f64 {
    let c =
        |x: IntBox| [(f64::from(x[0]) + f64::from(x[2])) / 2.0, (f64::from(x[1]) + f64::from(x[3])) / 2.0];
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

    pub fn contains(self, categories: &FrameCategories, frame: usize) -> bool {
        match self {
            Category::Visible => categories.visible[frame],
            Category::Occluded => categories.occluded(frame),
            Category::Contained => categories.contained[frame],
            Category::Carried => categories.carried[frame],
            Category::Overall => true,
        }
    }
}

/// Which frames of a video are scored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FramesScored {
    /// Every frame (OPNet's analysis).
    #[default]
    All,
    /// From the first frame in which the snitch is perceived (the AAPA paper, IV-C); a video in
    /// which it never is contributes nothing.
    FromFirstDetection,
}

/// One video's mean IoU and mean L2 per category (`None`: no scored frame of that category), and
/// how many frames of each were scored.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoScore {
    pub iou: [Option<f64>; 5],
    pub l2: [Option<f64>; 5],
    pub frames: [usize; 5],
}

/// Scores predictions against the snitch's ground truth on the frames from `first_frame` on.
pub fn score_video(
    predictions: &[IntBox],
    truth: &[IntBox],
    categories: &FrameCategories,
    first_frame: Option<usize>,
) -> VideoScore {
    let mut iou_sum = [0.0; 5];
    let mut l2_sum = [0.0; 5];
    let mut count = [0usize; 5];
    let frames = predictions.len().min(truth.len()).min(categories.frames());
    if let Some(first) = first_frame {
        for f in first..frames {
            let (i, d) = (iou(predictions[f], truth[f]), centre_distance(predictions[f], truth[f]));
            for (c, category) in Category::ALL.iter().enumerate() {
                if category.contains(categories, f) {
                    iou_sum[c] += i;
                    l2_sum[c] += d;
                    count[c] += 1;
                }
            }
        }
    }
    let mean = |sum: [f64; 5]| std::array::from_fn(|c| (count[c] > 0).then(|| sum[c] / count[c] as f64));
    VideoScore { iou: mean(iou_sum), l2: mean(l2_sum), frames: count }
}

/// Mean ± SEM over the videos that have the category.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub mean: f64,
    pub sem: f64,
    /// Videos with at least one scored frame of the category.
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
