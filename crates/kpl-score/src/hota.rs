//! HOTA, the higher order tracking accuracy (Luiten et al., 2021), with TrackEval's definitions:
//! HOTA, DetA, AssA, LocA (and DetRe, DetPr, AssRe, AssPr, OWTA), each the mean over the
//! localisation thresholds α = 0.05, 0.10, …, 0.95, plus HOTA(0), LocA(0) and HOTALocA(0) at the
//! lowest threshold.
//!
//! **Similarity on the ground plane.** TrackEval scores boxes by their overlap; for positions it
//! turns the Euclidean distance into a similarity as its `_calculate_euclidean_similarity` does:
//! `S = max(0, 1 − d / zero_distance)`. TrackEval's convention (MOT15-3D) is a zero distance of
//! twice the distance that counts as a match for CLEAR MOT and the identity measures, so that
//! `S ≥ 0.5` is exactly `d ≤ gate`; [`Config`](crate::Config) does the same by default. A pair
//! counts at threshold α when `S ≥ α`, i.e. `d ≤ (1 − α) · zero_distance`.
//!
//! As TrackEval's `HOTA.eval_sequence`: a first pass accumulates, per pair of ids, the frames'
//! normalised similarities into a global alignment score; each frame then matches the pairs that
//! maximise the sum of alignment score × similarity, and at each α the matched pairs with
//! `S ≥ α` are the true positives. AssA at α is the mean, over true positives, of the Jaccard
//! index of their pair's matched frames (TPA / (TPA + FNA + FPA)).

use std::collections::HashMap;

use serde::Serialize;

use crate::assign::{self, Edge};
use crate::ratio::{serialize_ratio, serialize_ratios};
use crate::sequence::{Frame, Pair};

/// The number of localisation thresholds.
pub const ALPHA_COUNT: usize = 19;

/// The localisation thresholds: `numpy.arange(0.05, 0.99, 0.05)`, value for value.
pub fn alphas() -> [f64; ALPHA_COUNT] {
    std::array::from_fn(|i| 0.05 + i as f64 * 0.05)
}

/// The HOTA family of a sequence: means over the thresholds, and the values at each.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Hota {
    #[serde(serialize_with = "serialize_ratio")]
    pub hota: f64,
    #[serde(rename = "det_a", serialize_with = "serialize_ratio")]
    pub det_a: f64,
    #[serde(rename = "ass_a", serialize_with = "serialize_ratio")]
    pub ass_a: f64,
    #[serde(rename = "loc_a", serialize_with = "serialize_ratio")]
    pub loc_a: f64,
    #[serde(serialize_with = "serialize_ratio")]
    pub det_re: f64,
    #[serde(serialize_with = "serialize_ratio")]
    pub det_pr: f64,
    #[serde(serialize_with = "serialize_ratio")]
    pub ass_re: f64,
    #[serde(serialize_with = "serialize_ratio")]
    pub ass_pr: f64,
    #[serde(serialize_with = "serialize_ratio")]
    pub owta: f64,
    /// HOTA at the lowest threshold.
    #[serde(rename = "hota_0", serialize_with = "serialize_ratio")]
    pub hota_0: f64,
    #[serde(rename = "loc_a_0", serialize_with = "serialize_ratio")]
    pub loc_a_0: f64,
    #[serde(rename = "hota_loc_a_0", serialize_with = "serialize_ratio")]
    pub hota_loc_a_0: f64,
    pub per_alpha: PerAlpha,
}

/// Each field at each threshold (index `a` is `alphas()[a]`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PerAlpha {
    pub alpha: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub hota: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub det_a: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub ass_a: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub loc_a: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub det_re: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub det_pr: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub ass_re: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub ass_pr: Vec<f64>,
    #[serde(serialize_with = "serialize_ratios")]
    pub owta: Vec<f64>,
    pub tp: Vec<usize>,
    #[serde(rename = "fn")]
    pub fn_: Vec<usize>,
    pub fp: Vec<usize>,
}

/// One frame's pairs with a positive similarity: (true index, hypothesis index, similarity).
type Similarities = Vec<(u32, u32, f64)>;

/// The HOTA state: each frame's similarities, kept for the second pass.
#[derive(Debug, Clone)]
pub(crate) struct HotaFrames {
    zero_distance: f64,
    truth_ids: usize,
    hypothesis_ids: usize,
    frames: Vec<(Vec<u32>, Vec<u32>, Similarities)>,
}

impl HotaFrames {
    pub(crate) fn new(zero_distance: f64, truth_ids: usize, hypothesis_ids: usize) -> HotaFrames {
        HotaFrames { zero_distance, truth_ids, hypothesis_ids, frames: Vec::new() }
    }

    /// Keeps the frame's similarities; `close` must hold every pair within the zero distance.
    pub(crate) fn frame(&mut self, frame: &Frame, close: &[Pair]) {
        let similarities = close
            .iter()
            .filter_map(|p| {
                // Boxes: the IoU itself, as TrackEval's box similarity.
                let s = if frame.boxes { p.iou } else { (1.0 - p.distance / self.zero_distance).max(0.0) };
                (s > 0.0).then_some((p.truth as u32, p.hypothesis as u32, s))
            })
            .collect();
        self.frames.push((
            frame.truth.iter().map(|o| o.id).collect(),
            frame.hypotheses.iter().map(|o| o.id).collect(),
            similarities,
        ));
    }

    pub(crate) fn finish(&self) -> Hota {
        let alphas = alphas();
        let truth_dets: usize = self.frames.iter().map(|f| f.0.len()).sum();
        let hypothesis_dets: usize = self.frames.iter().map(|f| f.1.len()).sum();
        // TrackEval returns early: everything 0 but the misses or false positives, LocA 1.
        if hypothesis_dets == 0 {
            return empty(&alphas, truth_dets, 0);
        }
        if truth_dets == 0 {
            return empty(&alphas, 0, hypothesis_dets);
        }
        let ids = IdAlignment::new(self);
        let counts = Counts::new(self, &ids, &alphas);
        finish(&alphas, &counts.per_threshold(&ids))
    }
}

/// The first pass: how well each pair of ids aligns over the whole sequence.
struct IdAlignment {
    truth_count: Vec<usize>,
    hypothesis_count: Vec<usize>,
    /// Per pair, the sum over frames of S / (row sum + column sum − S).
    potential: HashMap<(u32, u32), f64>,
}

impl IdAlignment {
    fn new(h: &HotaFrames) -> IdAlignment {
        let mut truth_count = vec![0usize; h.truth_ids];
        let mut hypothesis_count = vec![0usize; h.hypothesis_ids];
        let mut potential: HashMap<(u32, u32), f64> = HashMap::new();
        for (truth, hypotheses, sims) in &h.frames {
            let mut row_sum = vec![0.0; truth.len()];
            let mut col_sum = vec![0.0; hypotheses.len()];
            for &(i, j, s) in sims {
                row_sum[i as usize] += s;
                col_sum[j as usize] += s;
            }
            for &(i, j, s) in sims {
                let denominator = col_sum[j as usize] + row_sum[i as usize] - s;
                if denominator > f64::EPSILON {
                    *potential.entry((truth[i as usize], hypotheses[j as usize])).or_default() +=
                        s / denominator;
                }
            }
            for &t in truth {
                truth_count[t as usize] += 1;
            }
            for &h in hypotheses {
                hypothesis_count[h as usize] += 1;
            }
        }
        IdAlignment { truth_count, hypothesis_count, potential }
    }

    /// The global alignment score of a pair of ids (a Jaccard index of weighted frames).
    fn score(&self, t: u32, h: u32) -> f64 {
        let p = self.potential.get(&(t, h)).copied().unwrap_or(0.0);
        p / (self.truth_count[t as usize] as f64 + self.hypothesis_count[h as usize] as f64 - p)
    }
}

/// The second pass: each frame matched, counted at each threshold.
struct Counts {
    tp: [usize; ALPHA_COUNT],
    fn_: [usize; ALPHA_COUNT],
    fp: [usize; ALPHA_COUNT],
    /// Sum of the similarities of the true positives.
    similarity: [f64; ALPHA_COUNT],
    /// Per pair of ids, its true positives at each threshold.
    matched: HashMap<(u32, u32), [usize; ALPHA_COUNT]>,
}

impl Counts {
    fn new(h: &HotaFrames, ids: &IdAlignment, alphas: &[f64; ALPHA_COUNT]) -> Counts {
        let mut c = Counts {
            tp: [0; ALPHA_COUNT],
            fn_: [0; ALPHA_COUNT],
            fp: [0; ALPHA_COUNT],
            similarity: [0.0; ALPHA_COUNT],
            matched: HashMap::new(),
        };
        let mut edges = Vec::new();
        for (truth, hypotheses, sims) in &h.frames {
            if truth.is_empty() || hypotheses.is_empty() {
                for a in 0..ALPHA_COUNT {
                    c.fn_[a] += truth.len();
                    c.fp[a] += hypotheses.len();
                }
                continue;
            }
            edges.clear();
            let mut similarity: HashMap<(usize, usize), f64> = HashMap::with_capacity(sims.len());
            for &(i, j, s) in sims {
                let score = ids.score(truth[i as usize], hypotheses[j as usize]) * s;
                if score > 0.0 {
                    edges.push(Edge { row: i as usize, col: j as usize, value: score });
                }
                similarity.insert((i as usize, j as usize), s);
            }
            let pairs = assign::max_weight(truth.len(), hypotheses.len(), &edges);
            for (a, &alpha) in alphas.iter().enumerate() {
                let mut n = 0;
                for &(i, j) in &pairs {
                    let s = similarity[&(i, j)];
                    if s >= alpha - f64::EPSILON {
                        n += 1;
                        c.similarity[a] += s;
                        c.matched.entry((truth[i], hypotheses[j])).or_insert([0; ALPHA_COUNT])[a] += 1;
                    }
                }
                c.tp[a] += n;
                c.fn_[a] += truth.len() - n;
                c.fp[a] += hypotheses.len() - n;
            }
        }
        c
    }

    /// Association and localisation at each threshold.
    fn per_threshold(&self, ids: &IdAlignment) -> PerThreshold {
        let mut p = PerThreshold {
            tp: self.tp,
            fn_: self.fn_,
            fp: self.fp,
            ass_a: [0.0; ALPHA_COUNT],
            ass_re: [0.0; ALPHA_COUNT],
            ass_pr: [0.0; ALPHA_COUNT],
            loc_a: std::array::from_fn(|a| self.similarity[a].max(1e-10) / (self.tp[a] as f64).max(1e-10)),
        };
        let mut keys: Vec<&(u32, u32)> = self.matched.keys().collect();
        keys.sort_unstable();
        for a in 0..ALPHA_COUNT {
            let (mut sum_a, mut sum_re, mut sum_pr) = (0.0, 0.0, 0.0);
            for key in &keys {
                let m = self.matched[*key][a] as f64;
                if m == 0.0 {
                    continue;
                }
                let gt = ids.truth_count[key.0 as usize] as f64;
                let tr = ids.hypothesis_count[key.1 as usize] as f64;
                sum_a += m * (m / (gt + tr - m).max(1.0));
                sum_re += m * (m / gt.max(1.0));
                sum_pr += m * (m / tr.max(1.0));
            }
            let positives = (self.tp[a] as f64).max(1.0);
            p.ass_a[a] = sum_a / positives;
            p.ass_re[a] = sum_re / positives;
            p.ass_pr[a] = sum_pr / positives;
        }
        p
    }
}

/// The counts and averages at each threshold, from which the rest follows.
struct PerThreshold {
    tp: [usize; ALPHA_COUNT],
    fn_: [usize; ALPHA_COUNT],
    fp: [usize; ALPHA_COUNT],
    ass_a: [f64; ALPHA_COUNT],
    ass_re: [f64; ALPHA_COUNT],
    ass_pr: [f64; ALPHA_COUNT],
    loc_a: [f64; ALPHA_COUNT],
}

/// TrackEval's early result for a sequence without hypotheses or without true objects.
fn empty(alphas: &[f64; ALPHA_COUNT], misses: usize, false_positives: usize) -> Hota {
    let zeros = vec![0.0; ALPHA_COUNT];
    Hota {
        hota: 0.0,
        det_a: 0.0,
        ass_a: 0.0,
        loc_a: 1.0,
        det_re: 0.0,
        det_pr: 0.0,
        ass_re: 0.0,
        ass_pr: 0.0,
        owta: 0.0,
        hota_0: 0.0,
        loc_a_0: 1.0,
        hota_loc_a_0: 0.0,
        per_alpha: PerAlpha {
            alpha: alphas.to_vec(),
            hota: zeros.clone(),
            det_a: zeros.clone(),
            ass_a: zeros.clone(),
            loc_a: vec![1.0; ALPHA_COUNT],
            det_re: zeros.clone(),
            det_pr: zeros.clone(),
            ass_re: zeros.clone(),
            ass_pr: zeros.clone(),
            owta: zeros,
            tp: vec![0; ALPHA_COUNT],
            fn_: vec![misses; ALPHA_COUNT],
            fp: vec![false_positives; ALPHA_COUNT],
        },
    }
}

/// The fields that follow from the counts (TrackEval's `_compute_final_fields`), and the means.
fn finish(alphas: &[f64; ALPHA_COUNT], p: &PerThreshold) -> Hota {
    let (tp, fn_, fp) = (&p.tp, &p.fn_, &p.fp);
    let per = |f: &dyn Fn(usize) -> f64| -> Vec<f64> { (0..ALPHA_COUNT).map(f).collect() };
    let det_re = per(&|a| tp[a] as f64 / ((tp[a] + fn_[a]) as f64).max(1.0));
    let det_pr = per(&|a| tp[a] as f64 / ((tp[a] + fp[a]) as f64).max(1.0));
    let det_a = per(&|a| tp[a] as f64 / ((tp[a] + fn_[a] + fp[a]) as f64).max(1.0));
    let hota = per(&|a| (det_a[a] * p.ass_a[a]).sqrt());
    let owta = per(&|a| (det_re[a] * p.ass_a[a]).sqrt());
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    Hota {
        hota: mean(&hota),
        det_a: mean(&det_a),
        ass_a: mean(&p.ass_a),
        loc_a: mean(&p.loc_a),
        det_re: mean(&det_re),
        det_pr: mean(&det_pr),
        ass_re: mean(&p.ass_re),
        ass_pr: mean(&p.ass_pr),
        owta: mean(&owta),
        hota_0: hota[0],
        loc_a_0: p.loc_a[0],
        hota_loc_a_0: hota[0] * p.loc_a[0],
        per_alpha: PerAlpha {
            alpha: alphas.to_vec(),
            hota,
            det_a,
            ass_a: p.ass_a.to_vec(),
            loc_a: p.loc_a.to_vec(),
            det_re,
            det_pr,
            ass_re: p.ass_re.to_vec(),
            ass_pr: p.ass_pr.to_vec(),
            owta,
            tp: tp.to_vec(),
            fn_: fn_.to_vec(),
            fp: fp.to_vec(),
        },
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn thresholds_are_numpys() {
        let a = super::alphas();
        assert_eq!(a.len(), 19);
        assert_eq!(a[2], 0.15000000000000002);
        assert_eq!(a[18], 0.9500000000000001);
    }
}
