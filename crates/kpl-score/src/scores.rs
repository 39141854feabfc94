//! Scoring a sequence: the configuration (gating distance, HOTA's zero-similarity distance) and
//! one pass over the frames that feeds CLEAR MOT, the identity measures and HOTA.

use serde::Serialize;

use crate::clear::{Clear, ClearMot, Match};
use crate::error::ConfigError;
use crate::hota::{Hota, HotaFrames};
use crate::identity::{Identity, IdentityCounts};
use crate::mapping::{IdentityAssignment, IdentityPair, Mapping};
use crate::sequence::{Pair, Sequence};

/// The gating distance by default, metres: three times the simulated tracker's default noise,
/// below the 3.5 m between lane centres and a car's length.
pub const DEFAULT_MAX_DISTANCE: f64 = 3.0;

/// How pairs are compared: points by distance (gate in metres, HOTA's similarity
/// `max(0, 1 - d / zero_distance)`), or boxes by IoU (a pair may be matched when its IoU is at
/// least the threshold; HOTA's similarity is the IoU, as MOTChallenge's evaluation has it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Config {
    max_distance: f64,
    hota_zero_distance: f64,
    /// Boxes compared by IoU with this threshold (the distance of a pair is `1 - IoU`).
    #[serde(skip_serializing_if = "Option::is_none")]
    iou_threshold: Option<f64>,
}

/// The IoU threshold of MOTChallenge's evaluation.
pub const DEFAULT_IOU: f64 = 0.5;

impl Default for Config {
    fn default() -> Config {
        Config {
            max_distance: DEFAULT_MAX_DISTANCE,
            hota_zero_distance: 2.0 * DEFAULT_MAX_DISTANCE,
            iou_threshold: None,
        }
    }
}

impl Config {
    /// A true object and a hypothesis at most `max_distance` metres apart may be matched (CLEAR
    /// MOT and identity measures); HOTA's similarity reaches zero at twice that distance.
    pub fn new(max_distance: f64) -> Result<Config, ConfigError> {
        if !max_distance.is_finite() || max_distance <= 0.0 {
            return Err(ConfigError::MaxDistance(max_distance));
        }
        Ok(Config { max_distance, hota_zero_distance: 2.0 * max_distance, iou_threshold: None })
    }

    /// Boxes, matched when their IoU is at least `threshold` (py-motmetrics'
    /// `iou_matrix(max_iou = 1 - threshold)`; MOTChallenge uses 0.5); HOTA's similarity is the IoU.
    pub fn iou(threshold: f64) -> Result<Config, ConfigError> {
        if !(threshold.is_finite() && threshold > 0.0 && threshold <= 1.0) {
            return Err(ConfigError::Iou(threshold));
        }
        Ok(Config { max_distance: 1.0 - threshold, hota_zero_distance: 1.0, iou_threshold: Some(threshold) })
    }

    /// The IoU threshold, when boxes are compared.
    pub fn iou_threshold(&self) -> Option<f64> {
        self.iou_threshold
    }

    /// HOTA's similarity `max(0, 1 − d / zero_distance)` with another zero distance.
    pub fn with_hota_zero_distance(self, zero_distance: f64) -> Result<Config, ConfigError> {
        if !zero_distance.is_finite() || zero_distance <= 0.0 {
            return Err(ConfigError::ZeroDistance(zero_distance));
        }
        Ok(Config { hota_zero_distance: zero_distance, ..self })
    }

    /// The gating distance, metres.
    pub fn max_distance(&self) -> f64 {
        self.max_distance
    }

    /// The distance at which HOTA's similarity reaches zero, metres.
    pub fn hota_zero_distance(&self) -> f64 {
        self.hota_zero_distance
    }
}

/// Every metric of a sequence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Scores {
    pub clear: ClearMot,
    pub identity: Identity,
    pub hota: Hota,
}

/// The scores with the correspondences behind them.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    pub scores: Scores,
    /// Which hypothesis stood for which true object over time (the CLEAR MOT matching).
    pub mapping: Mapping,
    /// The trajectories paired by the identity measures.
    pub identity_assignment: IdentityAssignment,
}

/// Every metric of `sequence`.
pub fn score(sequence: &Sequence, config: &Config) -> Scores {
    evaluate(sequence, config).scores
}

/// Every metric of `sequence`, with the mapping and the identity assignment.
pub fn evaluate(sequence: &Sequence, config: &Config) -> Evaluation {
    let (n_truth, n_hyp) = (sequence.truth_ids().len(), sequence.hypothesis_ids().len());
    let mut clear = Clear::new(n_truth, n_hyp);
    let mut identity = IdentityCounts::new(n_truth, n_hyp);
    let mut hota = HotaFrames::new(config.hota_zero_distance, n_truth, n_hyp);
    // Boxes: the radius 1 takes every overlapping pair (1 - IoU below 1).
    let radius = config.max_distance.max(config.hota_zero_distance);
    let (mut close, mut gated) = (Vec::new(), Vec::new());
    let mut matches: Vec<Vec<Match>> = Vec::with_capacity(sequence.frames().len());
    for frame in sequence.frames() {
        frame.pairs_within(radius, &mut close);
        gated.clear();
        gated.extend(close.iter().filter(|p: &&Pair| p.distance <= config.max_distance));
        let mut frame_matches = Vec::new();
        clear.frame(frame, &gated, &mut frame_matches);
        identity.frame(frame, &gated);
        hota.frame(frame, &close);
        matches.push(frame_matches);
    }
    let (identity_scores, assigned) = identity.finish();
    let identity_assignment = IdentityAssignment {
        pairs: assigned
            .into_iter()
            .map(|a| IdentityPair {
                truth: sequence.truth_ids().name(a.truth).to_string(),
                hypothesis: sequence.hypothesis_ids().name(a.hypothesis).to_string(),
                frames: a.frames,
            })
            .collect(),
    };
    Evaluation {
        scores: Scores { clear: clear.finish(), identity: identity_scores, hota: hota.finish() },
        mapping: Mapping::from_matches(sequence, &matches),
        identity_assignment,
    }
}

/// Which hypothesis stood for which true object over time, without the other metrics.
pub fn mapping(sequence: &Sequence, config: &Config) -> Mapping {
    let mut clear = Clear::new(sequence.truth_ids().len(), sequence.hypothesis_ids().len());
    let mut gated = Vec::new();
    let matches: Vec<Vec<Match>> = sequence
        .frames()
        .iter()
        .map(|frame| {
            frame.pairs_within(config.max_distance, &mut gated);
            let mut frame_matches = Vec::new();
            clear.frame(frame, &gated, &mut frame_matches);
            frame_matches
        })
        .collect();
    Mapping::from_matches(sequence, &matches)
}
