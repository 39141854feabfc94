//! The evaluation driver: runs a model over the videos of a data directory (in parallel), scores it
//! against the ground truth and returns Table I's row for that model and perception, with the
//! per-video results. A video whose files are missing or bad (no snitch, a box or frame number out
//! of range, a movement of an object that does not exist, perception of another length) is skipped
//! and reported with the reason, never scored with a wrong number.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use kpl_aapa::Params;
use serde::{Deserialize, Serialize};

use crate::categories::{FrameCategories, carried_frames, contained_frames, visible_frames};
use crate::error::CaterError;
use crate::formats::{
    Annotations, GroundTruth, IntBox, PerceptionFile, SNITCH_CLASS, Scene, read_annotation_file,
    write_predictions,
};
use crate::layout::{
    CARRIED_FILE, CONTAINMENT_FILE, Perception, VISIBLE_FILE, annotations_dir, find_ground_truth,
    list_videos, perception_path, pickle_path, scene_path,
};
use crate::models::{Model, predict};
use crate::score::{Category, CategoryTable, FramesScored, VideoScore, score_video};

/// Where a video's perception comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum PerceptionSource {
    /// This project's JSON in the data directory.
    Json(Perception),
    /// OPNet's per-video pickles `<video>.pkl` in this directory.
    Pickles(PathBuf),
}

impl PerceptionSource {
    pub fn name(&self) -> String {
        match self {
            PerceptionSource::Json(p) => p.name().to_owned(),
            PerceptionSource::Pickles(dir) => format!("pickles {}", dir.display()),
        }
    }

    /// Whether its boxes are a detector's, with noise: this project's detector perception and
    /// OPNet's pickles (its detector's `od_perception`; for its perfect-perception pickles,
    /// `--params` can turn `average_still` off).
    pub fn noisy(&self) -> bool {
        !matches!(self, PerceptionSource::Json(Perception::Perfect))
    }

    pub fn load(&self, data: &Path, video: &str) -> Result<PerceptionFile, CaterError> {
        match self {
            PerceptionSource::Json(p) => PerceptionFile::read(&perception_path(data, video, *p)),
            PerceptionSource::Pickles(dir) => {
                PerceptionFile::read_pickle(&pickle_path(dir, video), video, "pickle")
            }
        }
    }
}

/// How the visible category is decided.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum VisibleFrom {
    /// OPNet's definition (its annotation file, or computed from the scene and ground truth).
    #[default]
    Opnet,
    /// The snitch is in this perception (the previous choice: perfect perception).
    Perception(PerceptionSource),
}

/// What to evaluate.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    pub data: PathBuf,
    pub model: Model,
    pub perception: PerceptionSource,
    /// AAPA parameters; the model's defaults when `None`.
    pub params: Option<Params>,
    pub threads: usize,
    /// Write each video's predictions as `<video>_bb.json` here.
    pub predictions_dir: Option<PathBuf>,
    /// The videos to evaluate (a split); every scene of the directory when `None`.
    pub videos: Option<Vec<String>>,
    /// OPNet's annotation files; `DIR/containment_and_occlusions` when `None` and it exists.
    pub annotations: Option<PathBuf>,
    pub frames: FramesScored,
    pub visible: VisibleFrom,
}

impl EvalOptions {
    /// OPNet's scoring of `model` over every video of `data` with this project's perception.
    pub fn new(data: &Path, model: Model, perception: Perception) -> EvalOptions {
        EvalOptions {
            data: data.to_owned(),
            model,
            perception: PerceptionSource::Json(perception),
            params: None,
            threads: 1,
            predictions_dir: None,
            videos: None,
            annotations: None,
            frames: FramesScored::All,
            visible: VisibleFrom::Opnet,
        }
    }
}

/// A video left out, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Skipped {
    pub video: String,
    pub reason: String,
}

/// One video's results.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoResult {
    pub video: String,
    pub score: VideoScore,
}

/// Table I's row for one model and perception.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    pub model: String,
    pub perception: String,
    /// Videos scored.
    pub videos: usize,
    pub skipped: Vec<Skipped>,
    /// Where the categories came from: `annotation files` or `scenes`.
    pub categories_from: String,
    pub frames: FramesScored,
    /// Mean IoU in percent.
    pub iou: CategoryTable,
    /// Mean L2 distance of box centres in pixels.
    pub l2: CategoryTable,
    /// Frames scored per category, over all videos.
    pub frame_counts: [usize; 5],
    pub per_video: Vec<VideoResult>,
}

/// OPNet's annotation files, those present.
#[derive(Debug, Clone, Default)]
pub struct AnnotationSet {
    pub contained: Option<Annotations>,
    pub carried: Option<Annotations>,
    pub visible: Option<Annotations>,
}

impl AnnotationSet {
    /// Reads the files of a directory (none if it does not exist).
    pub fn read(dir: &Path) -> Result<AnnotationSet, CaterError> {
        let read = |name: &str| {
            let path = dir.join(name);
            if path.is_file() { read_annotation_file(&path).map(Some) } else { Ok(None) }
        };
        Ok(AnnotationSet {
            contained: read(CONTAINMENT_FILE)?,
            carried: read(CARRIED_FILE)?,
            visible: read(VISIBLE_FILE)?,
        })
    }

    pub fn is_empty(&self) -> bool {
        self.contained.is_none() && self.carried.is_none() && self.visible.is_none()
    }
}

/// One video, loaded.
#[derive(Debug, Clone)]
pub struct VideoData {
    pub scene: Scene,
    pub ground_truth: GroundTruth,
    pub perception: PerceptionFile,
}

/// Loads a video's scene, ground truth and perception.
pub fn load_video(data: &Path, video: &str, perception: &PerceptionSource) -> Result<VideoData, CaterError> {
    let scene = Scene::read(&scene_path(data, video))?;
    let ground_truth = GroundTruth::read(&find_ground_truth(data, video))?;
    let perception = perception.load(data, video)?;
    Ok(VideoData { scene, ground_truth, perception })
}

fn frames_of(annotations: &Annotations, video: &str, frames: usize, file: &str) -> Result<Vec<bool>, String> {
    let list = annotations.get(video).ok_or_else(|| format!("not in the annotation file {file}"))?;
    let mut mask = vec![false; frames];
    for &f in list {
        if let Some(slot) = mask.get_mut(f) {
            *slot = true;
        }
    }
    Ok(mask)
}

/// A video's frame categories: from OPNet's annotation files where given, else from its scene and
/// ground truth as OPNet's scripts compute them; visibility from perception if asked.
pub fn categories_of(
    data: &Path,
    video: &VideoData,
    annotations: &AnnotationSet,
    visible: &VisibleFrom,
) -> Result<FrameCategories, String> {
    let frames = video.ground_truth.frames();
    let name = video.scene.video.as_str();
    let contained = match &annotations.contained {
        Some(a) => frames_of(a, name, frames, CONTAINMENT_FILE)?,
        None => contained_frames(&video.scene, frames),
    };
    let carried = match &annotations.carried {
        Some(a) => frames_of(a, name, frames, CARRIED_FILE)?,
        None => carried_frames(&video.scene, frames),
    };
    let visible = match visible {
        VisibleFrom::Opnet => match &annotations.visible {
            Some(a) => frames_of(a, name, frames, VISIBLE_FILE)?,
            None => {
                visible_frames(&video.scene, &video.ground_truth, frames, 0.0).map_err(|e| e.to_string())?
            }
        },
        VisibleFrom::Perception(source) => {
            let perception = source.load(data, name).map_err(|e| e.to_string())?;
            if perception.frames.len() != frames {
                return Err(format!(
                    "{} frames of perception for visibility, {frames} of ground truth",
                    perception.frames.len()
                ));
            }
            (0..frames).map(|f| perception.has_class(f, SNITCH_CLASS)).collect()
        }
    };
    Ok(FrameCategories { visible, contained, carried })
}

/// Scores one loaded video with a model.
pub fn evaluate_video(
    video: &VideoData,
    categories: &FrameCategories,
    model: Model,
    params: &Params,
    frames_scored: FramesScored,
) -> Result<(VideoScore, Vec<IntBox>), String> {
    let truth = video
        .ground_truth
        .snitch_boxes(Path::new(""))
        .map_err(|_| "no snitch in the ground truth".to_owned())?;
    if video.scene.object(crate::formats::SNITCH_INSTANCE).is_none() {
        return Err("no snitch (`Spl_0`) among the scene's objects".into());
    }
    let frames = truth.len();
    if video.perception.frames.len() != frames {
        return Err(format!("{frames} ground-truth frames but {} perceived", video.perception.frames.len()));
    }
    let first_frame = match frames_scored {
        FramesScored::All => Some(0),
        FramesScored::FromFirstDetection => {
            (0..frames).find(|&f| video.perception.has_class(f, SNITCH_CLASS))
        }
    };
    let predictions = predict(model, params, &video.scene, &video.perception).map_err(|e| e.to_string())?;
    Ok((score_video(&predictions, &truth, categories, first_frame), predictions))
}

/// Evaluates a model over a data directory.
pub fn evaluate(options: &EvalOptions) -> Result<Report, CaterError> {
    let videos = match &options.videos {
        Some(list) => list.clone(),
        None => list_videos(&options.data)?,
    };
    if videos.is_empty() {
        return Err(CaterError::invalid(&options.data.join("scenes"), "no videos to evaluate"));
    }
    if let Some(dir) = &options.predictions_dir {
        std::fs::create_dir_all(dir).map_err(|source| CaterError::Io { path: dir.clone(), source })?;
    }
    let annotations = match &options.annotations {
        Some(dir) => {
            let set = AnnotationSet::read(dir)?;
            if set.is_empty() {
                return Err(CaterError::invalid(
                    dir,
                    format!(
                        "none of OPNet's annotation files ({CONTAINMENT_FILE}, {CARRIED_FILE}, {VISIBLE_FILE})"
                    ),
                ));
            }
            set
        }
        None => AnnotationSet::read(&annotations_dir(&options.data))?,
    };
    let params =
        options.params.clone().unwrap_or_else(|| options.model.params_for(options.perception.noisy()));
    let next = AtomicUsize::new(0);
    type Outcome = Result<VideoScore, String>;
    let results: Mutex<Vec<Option<Outcome>>> = Mutex::new(vec![None; videos.len()]);
    let fatal: Mutex<Option<CaterError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..options.threads.max(1) {
            scope.spawn(|| {
                loop {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    if index >= videos.len() {
                        break;
                    }
                    let name = &videos[index];
                    let outcome = load_video(&options.data, name, &options.perception)
                        .map_err(|e| e.to_string())
                        .and_then(|video| {
                            let categories =
                                categories_of(&options.data, &video, &annotations, &options.visible)?;
                            evaluate_video(&video, &categories, options.model, &params, options.frames)
                        });
                    let outcome = match (outcome, &options.predictions_dir) {
                        (Ok((score, predictions)), Some(dir)) => {
                            match write_predictions(&dir.join(format!("{name}_bb.json")), &predictions) {
                                Ok(()) => Ok(score),
                                Err(e) => {
                                    if let Ok(mut slot) = fatal.lock() {
                                        slot.get_or_insert(e);
                                    }
                                    next.store(videos.len(), Ordering::Relaxed);
                                    break;
                                }
                            }
                        }
                        (outcome, _) => outcome.map(|(score, _)| score),
                    };
                    if let Ok(mut r) = results.lock() {
                        r[index] = Some(outcome);
                    }
                }
            });
        }
    });
    if let Some(e) = fatal.into_inner().ok().flatten() {
        return Err(e);
    }
    let mut per_video = Vec::new();
    let mut skipped = Vec::new();
    for (name, outcome) in videos.iter().zip(results.into_inner().unwrap_or_default()) {
        match outcome {
            Some(Ok(score)) => per_video.push(VideoResult { video: name.clone(), score }),
            Some(Err(reason)) => skipped.push(Skipped { video: name.clone(), reason }),
            None => skipped.push(Skipped { video: name.clone(), reason: "not evaluated".into() }),
        }
    }
    let scores: Vec<VideoScore> = per_video.iter().map(|v| v.score.clone()).collect();
    let frame_counts = std::array::from_fn(|c| scores.iter().map(|s| s.frames[c]).sum());
    let categories_from = if annotations.is_empty() { "scenes" } else { "annotation files" };
    Ok(Report {
        model: options.model.name().to_owned(),
        perception: options.perception.name(),
        videos: per_video.len(),
        skipped,
        categories_from: categories_from.to_owned(),
        frames: options.frames,
        iou: CategoryTable::from_scores(&scores, true),
        l2: CategoryTable::from_scores(&scores, false),
        frame_counts,
        per_video,
    })
}

/// The per-video results as CSV, one row per video with OPNet-style column names:
/// `videos_names,{category}_mean_iou,...,{category}_mean_l2,...,{category}_frames,...` (`nan` where a
/// video has no frame of a category).
pub fn per_video_csv(report: &Report) -> String {
    let mut out = String::from("videos_names");
    for metric in ["mean_iou", "mean_l2", "frames"] {
        for c in Category::ALL {
            out.push_str(&format!(",{}_{metric}", c.name()));
        }
    }
    out.push('\n');
    let cell = |v: Option<f64>| v.map_or("nan".to_owned(), |v| format!("{v:.17}"));
    for v in &report.per_video {
        out.push_str(&v.video);
        for x in v.score.iou {
            out.push(',');
            out.push_str(&cell(x));
        }
        for x in v.score.l2 {
            out.push(',');
            out.push_str(&cell(x));
        }
        for n in v.score.frames {
            out.push_str(&format!(",{n}"));
        }
        out.push('\n');
    }
    out
}
