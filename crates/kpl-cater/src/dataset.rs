//! A data directory in LA-CATER's layout, written by the generator and read by the evaluation:
//!
//! ```text
//! DIR/manifest.json                         generator, seed, number of videos
//! DIR/scenes/<video>.json                   CATER scene JSON (objects, movements, camera)
//! DIR/bb/<video>_bb.json                    LA-CATER ground truth boxes
//! DIR/perception/<video>_perfect.json       perfect perception
//! DIR/perception/<video>_detector.json      the simulated detector
//! ```
//!
//! Generation is deterministic given the seed: video `i` draws from ChaCha8 seeded with the seed on
//! stream `i`, so the output does not depend on the number of threads.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::detector::{DetectorNoise, detect_video, perfect};
use crate::error::CaterError;
use crate::formats::{GroundTruth, PerceptionFile, Scene, read_json, write_json};
use crate::render::{Camera, Rendered, render};
use crate::scene::simulate;

/// `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub generator: String,
    pub seed: u64,
    pub videos: usize,
}

/// A perception mode.
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

pub fn video_name(index: usize) -> String {
    format!("CATER_new_{index:06}")
}

pub fn scene_path(dir: &Path, video: &str) -> PathBuf {
    dir.join("scenes").join(format!("{video}.json"))
}

pub fn ground_truth_path(dir: &Path, video: &str) -> PathBuf {
    dir.join("bb").join(format!("{video}_bb.json"))
}

pub fn perception_path(dir: &Path, video: &str, perception: Perception) -> PathBuf {
    dir.join("perception").join(format!("{video}_{}.json", perception.name()))
}

/// Everything generated for one video.
#[derive(Debug, Clone)]
pub struct GeneratedVideo {
    pub scene: Scene,
    pub ground_truth: GroundTruth,
    pub perfect: PerceptionFile,
    pub detector: PerceptionFile,
}

/// Generates video `index` of a data set with this seed.
pub fn generate_video(seed: u64, index: usize) -> GeneratedVideo {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index as u64);
    let name = video_name(index);
    let sim = simulate(&mut rng, &name);
    let camera = Camera::new(&sim.scene.camera.unwrap_or_else(|| crate::scene::sample_camera(&mut rng)));
    let frames: Vec<Vec<Rendered>> =
        sim.states.iter().map(|states| render(&camera, &sim.objects, states)).collect();
    let mut ground_truth = GroundTruth::default();
    let gt_per_object: Vec<Vec<[i32; 4]>> = (0..sim.objects.len())
        .map(|i| {
            frames
                .iter()
                .map(|f| match f[i].bbox {
                    Some(b) => {
                        let (x1, y1) = (b.x1.round() as i32, b.y1.round() as i32);
                        [x1, y1, b.x2.round() as i32 - x1, b.y2.round() as i32 - y1]
                    }
                    None => [0, 0, 0, 0],
                })
                .collect()
        })
        .collect();
    for (object, boxes) in sim.objects.iter().zip(&gt_per_object) {
        ground_truth.objects.insert(object.info.key(), boxes.clone());
    }
    let classes: Vec<String> = sim.objects.iter().map(|o| o.info.class()).collect();
    let perfect_frames = frames
        .iter()
        .enumerate()
        .map(|(f, frame)| {
            let boxes: Vec<[i32; 4]> = gt_per_object.iter().map(|b| b[f]).collect();
            perfect(frame, &boxes)
        })
        .collect();
    let mut detector_classes = classes.clone();
    let detector_frames = detect_video(&mut rng, &frames, &mut detector_classes, &DetectorNoise::default());
    GeneratedVideo {
        perfect: PerceptionFile {
            video: name.clone(),
            perception: "perfect".into(),
            classes,
            frames: perfect_frames,
        },
        detector: PerceptionFile {
            video: name,
            perception: "detector".into(),
            classes: detector_classes,
            frames: detector_frames,
        },
        scene: sim.scene,
        ground_truth,
    }
}

fn create_dir(path: &Path) -> Result<(), CaterError> {
    std::fs::create_dir_all(path).map_err(|source| CaterError::Io { path: path.to_owned(), source })
}

/// Writes `videos` videos into `dir` with `threads` workers.
pub fn generate(dir: &Path, videos: usize, seed: u64, threads: usize) -> Result<Manifest, CaterError> {
    for sub in ["scenes", "bb", "perception"] {
        create_dir(&dir.join(sub))?;
    }
    let next = AtomicUsize::new(0);
    let first_error: Mutex<Option<CaterError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1) {
            scope.spawn(|| {
                loop {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    if index >= videos {
                        break;
                    }
                    if let Err(e) = write_video(dir, &generate_video(seed, index)) {
                        if let Ok(mut slot) = first_error.lock() {
                            slot.get_or_insert(e);
                        }
                        next.store(videos, Ordering::Relaxed);
                        break;
                    }
                }
            });
        }
    });
    if let Some(e) = first_error.into_inner().ok().flatten() {
        return Err(e);
    }
    let manifest = Manifest { generator: format!("kpl-cater {}", env!("CARGO_PKG_VERSION")), seed, videos };
    write_json(&dir.join("manifest.json"), &manifest)?;
    Ok(manifest)
}

/// Writes one video's four files, creating the layout's folders if needed.
pub fn write_video(dir: &Path, video: &GeneratedVideo) -> Result<(), CaterError> {
    for sub in ["scenes", "bb", "perception"] {
        create_dir(&dir.join(sub))?;
    }
    let name = &video.scene.video;
    video.scene.write(&scene_path(dir, name))?;
    video.ground_truth.write(&ground_truth_path(dir, name))?;
    video.perfect.write(&perception_path(dir, name, Perception::Perfect))?;
    video.detector.write(&perception_path(dir, name, Perception::Detector))
}

/// The videos of a data directory: the stems of `scenes/*.json`, sorted.
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
        {
            names.push(stem.to_owned());
        }
    }
    names.sort();
    Ok(names)
}

pub fn read_manifest(dir: &Path) -> Result<Manifest, CaterError> {
    read_json(&dir.join("manifest.json"))
}
