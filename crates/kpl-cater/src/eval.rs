//! The evaluation driver: runs a model over every video of a data directory (in parallel), scores
//! it against the ground truth and returns Table I's row for that model and perception mode.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use kpl_aapa::Params;
use serde::{Deserialize, Serialize};

use crate::dataset::{Perception, ground_truth_path, list_videos, perception_path, scene_path};
use crate::error::CaterError;
use crate::formats::{GroundTruth, PerceptionFile, SNITCH_CLASS, Scene, write_predictions};
use crate::models::{Model, predict};
use crate::score::{Categories, CategoryTable, VideoScore, score_video};

/// What to evaluate.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    pub data: PathBuf,
    pub model: Model,
    pub perception: Perception,
    /// AAPA parameters; the model's defaults when `None`.
    pub params: Option<Params>,
    pub threads: usize,
    /// Write each video's predictions as `<video>_bb.json` here.
    pub predictions_dir: Option<PathBuf>,
}

/// Table I's row for one model and perception mode (`--json` output).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    pub model: String,
    pub perception: String,
    pub videos: usize,
    /// Mean IoU in percent.
    pub iou: CategoryTable,
    /// Mean L2 distance of box centres in pixels.
    pub l2: CategoryTable,
}

/// One video, loaded.
#[derive(Debug, Clone)]
pub struct VideoData {
    pub scene: Scene,
    pub ground_truth: GroundTruth,
    pub perception: PerceptionFile,
    /// Perfect perception, for the visible category (the same file when evaluating with it).
    pub perfect: Option<PerceptionFile>,
}

pub fn load_video(dir: &Path, video: &str, perception: Perception) -> Result<VideoData, CaterError> {
    let scene = Scene::read(&scene_path(dir, video))?;
    let ground_truth = GroundTruth::read(&ground_truth_path(dir, video))?;
    let perception_file = PerceptionFile::read(&perception_path(dir, video, perception))?;
    let perfect = match perception {
        Perception::Perfect => None,
        Perception::Detector => {
            Some(PerceptionFile::read(&perception_path(dir, video, Perception::Perfect))?)
        }
    };
    Ok(VideoData { scene, ground_truth, perception: perception_file, perfect })
}

/// Scores one loaded video with a model.
pub fn evaluate_video(
    data: &VideoData,
    model: Model,
    params: &Params,
    gt_path: &Path,
) -> Result<(VideoScore, Vec<[i32; 4]>), CaterError> {
    let truth = data.ground_truth.snitch_boxes(gt_path)?;
    let perfect = data.perfect.as_ref().unwrap_or(&data.perception);
    let frames = truth.len();
    if data.perception.frames.len() != frames || perfect.frames.len() != frames {
        return Err(CaterError::invalid(
            gt_path,
            format!(
                "{} ground-truth frames but {} perceived and {} perfectly perceived",
                frames,
                data.perception.frames.len(),
                perfect.frames.len()
            ),
        ));
    }
    let visible: Vec<bool> = (0..frames).map(|f| perfect.has_class(f, SNITCH_CLASS)).collect();
    let categories = Categories::new(&data.scene, visible);
    let first_frame = (0..frames).find(|&f| data.perception.has_class(f, SNITCH_CLASS));
    let predictions = predict(model, params, &data.scene, &data.perception)?;
    Ok((score_video(&predictions, &truth, &categories, first_frame), predictions))
}

pub fn evaluate(options: &EvalOptions) -> Result<Report, CaterError> {
    let videos = list_videos(&options.data)?;
    if videos.is_empty() {
        return Err(CaterError::invalid(&options.data.join("scenes"), "no scene JSON files"));
    }
    if let Some(dir) = &options.predictions_dir {
        std::fs::create_dir_all(dir).map_err(|source| CaterError::Io { path: dir.clone(), source })?;
    }
    let params = options.params.clone().unwrap_or_else(|| options.model.default_params(options.perception));
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<VideoScore>>> = Mutex::new(vec![None; videos.len()]);
    let first_error: Mutex<Option<(usize, CaterError)>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..options.threads.max(1) {
            scope.spawn(|| {
                loop {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    if index >= videos.len() {
                        break;
                    }
                    let video = &videos[index];
                    let outcome = load_video(&options.data, video, options.perception).and_then(|data| {
                        let gt_path = ground_truth_path(&options.data, video);
                        let (score, predictions) = evaluate_video(&data, options.model, &params, &gt_path)?;
                        if let Some(dir) = &options.predictions_dir {
                            write_predictions(&dir.join(format!("{video}_bb.json")), &predictions)?;
                        }
                        Ok(score)
                    });
                    match outcome {
                        Ok(score) => {
                            if let Ok(mut r) = results.lock() {
                                r[index] = Some(score);
                            }
                        }
                        Err(e) => {
                            if let Ok(mut slot) = first_error.lock() {
                                // Report the first failing video in order, whatever the scheduling.
                                if slot.as_ref().is_none_or(|(i, _)| index < *i) {
                                    *slot = Some((index, e));
                                }
                            }
                        }
                    }
                }
            });
        }
    });
    if let Some((_, e)) = first_error.into_inner().ok().flatten() {
        return Err(e);
    }
    let scores: Vec<VideoScore> = results.into_inner().unwrap_or_default().into_iter().flatten().collect();
    Ok(Report {
        model: options.model.name().to_owned(),
        perception: options.perception.name().to_owned(),
        videos: scores.len(),
        iou: CategoryTable::from_scores(&scores, true),
        l2: CategoryTable::from_scores(&scores, false),
    })
}
