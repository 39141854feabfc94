//! Where a data directory keeps each file. Both this project's layout and LA-CATER's (as OPNet's
//! configurations name its folders) are read as they come:
//!
//! ```text
//! DIR/scenes/<video>.json                        CATER scene JSON
//! DIR/scenes/<video>_bb.json                     ground truth, beside the scene (as CATER's renderer
//!                                                writes it); DIR/labels/ (LA-CATER, OPNet's
//!                                                `labels_dir`) and DIR/bb/ are looked in too
//! DIR/perception/<video>_<perception>.json       this project's perception (perfect, detector,
//!                                                detector-b)
//! DIR/perfect_perception/<video>.pkl             OPNet's perception pickles: perfect perception,
//! DIR/od_perception/<video>.pkl                  its detector's (OPNet's `sample_dir`), and the
//! DIR/od_perception_b/<video>.pkl                second detector's (this project's)
//! DIR/containment_and_occlusions/*.txt           OPNet's frame annotations, when present
//! DIR/manifest.json                              what generated the directory
//! ```
//!
//! The videos of a directory are its scenes, or the names a list file gives (OPNet's
//! `samples.txt`: one video per line, a name or a path whose stem is the name).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::CaterError;

/// A perception of a video: perfect perception (the ground-truth boxes of the objects seen) or one
/// of two simulated detectors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Perception {
    Perfect,
    /// The detector calibrated against the AAPA paper's Faster R-CNN ([`crate::detector`]).
    Detector,
    /// A second, independent detector with other kinds of noise ([`crate::detector_b`]).
    DetectorB,
}

impl Perception {
    pub const ALL: [Perception; 3] = [Perception::Perfect, Perception::Detector, Perception::DetectorB];

    pub fn name(self) -> &'static str {
        match self {
            Perception::Perfect => "perfect",
            Perception::Detector => "detector",
            Perception::DetectorB => "detector-b",
        }
    }

    /// Whether its boxes are exact (the ground truth's).
    pub fn exact(self) -> bool {
        self == Perception::Perfect
    }

    /// Where LA-CATER keeps OPNet's pickles of this perception in a data directory.
    pub fn pickle_dir(self) -> &'static str {
        match self {
            Perception::Perfect => PERFECT_PICKLES_DIR,
            Perception::Detector => DETECTOR_PICKLES_DIR,
            Perception::DetectorB => "od_perception_b",
        }
    }
}

/// This project's perception JSON, in a data directory.
pub const PERCEPTION_DIR: &str = "perception";
/// OPNet's perception pickles in LA-CATER: its perfect perception and its detector's (`sample_dir`
/// in OPNet's configurations).
pub const PERFECT_PICKLES_DIR: &str = "perfect_perception";
pub const DETECTOR_PICKLES_DIR: &str = "od_perception";
/// Where LA-CATER keeps the ground truth (`labels_dir` in OPNet's configurations).
pub const LABELS_DIR: &str = "labels";

/// OPNet's annotation files, by the names its README gives them.
pub const CONTAINMENT_FILE: &str = "containment_annotations.txt";
pub const CARRIED_FILE: &str = "containment_with_move_annotations.txt";
pub const VISIBLE_FILE: &str = "visibility_rate_gt_0.txt";
/// Where OPNet keeps them within a data directory.
pub const ANNOTATIONS_DIR: &str = "containment_and_occlusions";

pub fn scene_path(dir: &Path, video: &str) -> PathBuf {
    dir.join("scenes").join(format!("{video}.json"))
}

/// Where the ground truth is written: beside the scene.
pub fn ground_truth_path(dir: &Path, video: &str) -> PathBuf {
    dir.join("scenes").join(format!("{video}_bb.json"))
}

/// The ground truth of a video: the first of `scenes/`, `labels/` and `bb/` that has it (the first
/// when none has, for the error message).
pub fn find_ground_truth(dir: &Path, video: &str) -> PathBuf {
    let name = format!("{video}_bb.json");
    let candidates =
        [dir.join("scenes").join(&name), dir.join(LABELS_DIR).join(&name), dir.join("bb").join(&name)];
    candidates.iter().find(|p| p.is_file()).unwrap_or(&candidates[0]).clone()
}

pub fn perception_path(dir: &Path, video: &str, perception: Perception) -> PathBuf {
    dir.join(PERCEPTION_DIR).join(format!("{video}_{}.json", perception.name()))
}

pub fn pickle_path(dir: &Path, video: &str) -> PathBuf {
    dir.join(format!("{video}.pkl"))
}

pub fn annotations_dir(dir: &Path) -> PathBuf {
    dir.join(ANNOTATIONS_DIR)
}

/// The videos of a data directory: the stems of `scenes/*.json` that are not ground truth
/// (`*_bb.json`), sorted.
pub fn list_videos(dir: &Path) -> Result<Vec<String>, CaterError> {
    let scenes = dir.join("scenes");
    let entries =
        std::fs::read_dir(&scenes).map_err(|source| CaterError::Io { path: scenes.clone(), source })?;
    let mut names = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|source| CaterError::Io { path: scenes.clone(), source })?;
        let path = entry.path();
        if path.extension().is_some_and(|e| e == "json")
            && let Some(stem) = path.file_stem().and_then(|s| s.to_str())
            && !stem.ends_with("_bb")
        {
            names.push(stem.to_owned());
        }
    }
    names.sort();
    Ok(names)
}

/// A list of videos (a split): one per line, a name or a path (`.../CATER_new_005748.avi`) whose
/// stem is the name; blank lines and lines starting with `#` are skipped. A name listed twice is a
/// data error.
pub fn read_video_list(path: &Path) -> Result<Vec<String>, CaterError> {
    let text = crate::formats::read_capped_text(path, crate::formats::MAX_LIST_BYTES)?;
    let mut names = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let name = Path::new(line).file_stem().and_then(|s| s.to_str()).unwrap_or(line).to_owned();
        if !seen.insert(name.clone()) {
            return Err(CaterError::invalid(path, format!("line {}: `{name}` is listed twice", n + 1)));
        }
        names.push(name);
    }
    Ok(names)
}
