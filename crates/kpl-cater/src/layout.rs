//! Where a data directory keeps each file, in LA-CATER's layout:
//!
//! ```text
//! DIR/scenes/<video>.json                        CATER scene JSON
//! DIR/scenes/<video>_bb.json                     ground truth, beside the scene (as CATER's renderer
//!                                                writes it); DIR/labels/ (OPNet's test data) and
//!                                                DIR/bb/ are looked in too
//! DIR/perception/<video>_{perfect,detector}.json this project's perception
//! DIR/containment_and_occlusions/*.txt           OPNet's frame annotations, when present
//! DIR/manifest.json                              what generated the directory
//! ```
//!
//! OPNet's perception pickles live in a directory of their own (`<video>.pkl`, OPNet's
//! `sample_dir`). The videos of a directory are its scenes, or the names a list file gives (OPNet's
//! `samples.txt`: one video per line, a name or a path whose stem is the name).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::CaterError;

/// A perception file of this project's JSON layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Perception {
    Perfect,
    Detector,
}

impl Perception {
    pub fn name(self) -> &'static str {
        match self {
            Perception::Perfect => "perfect",
            Perception::Detector => "detector",
        }
    }
}

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
        [dir.join("scenes").join(&name), dir.join("labels").join(&name), dir.join("bb").join(&name)];
    candidates.iter().find(|p| p.is_file()).unwrap_or(&candidates[0]).clone()
}

pub fn perception_path(dir: &Path, video: &str, perception: Perception) -> PathBuf {
    dir.join("perception").join(format!("{video}_{}.json", perception.name()))
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
    let text =
        std::fs::read_to_string(path).map_err(|source| CaterError::Io { path: path.to_owned(), source })?;
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
