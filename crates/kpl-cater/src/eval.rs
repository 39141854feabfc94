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
    Annotations, Dropped, GroundTruth, IntBox, PerceptionFile, SNITCH_CLASS, Scene, read_annotation_file,
    write_predictions,
};
use crate::layout::{
    CARRIED_FILE, CONTAINMENT_FILE, PERCEPTION_DIR, Perception, VISIBLE_FILE, annotations_dir,
    find_ground_truth, list_videos, perception_path, pickle_path, scene_path,
};
use crate::models::{Model, predict_traced};
use crate::score::{Category, CategoryTable, FramesScored, VideoScore, score_video};

/// Where a video's perception comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum PerceptionSource {
    /// This project's JSON in the data directory (`perception/<video>_<kind>.json`).
    Json(Perception),
    /// OPNet's per-video pickles `<video>.pkl` in this directory.
    Pickles { dir: PathBuf, boxes: Boxes },
}

/// What a perception's boxes are: exact (perfect perception: the ground truth's boxes of the
/// objects seen) or a detector's, with noise. Averaging the boxes of objects standing still
/// (`average_still`) helps only the latter, and costs the former its exactness.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Boxes {
    Exact,
    Noisy,
    /// Decided per video: exact if every box perceived is, pixel for pixel, the ground-truth box of
    /// an object in that frame (as perfect perception's are; a detector's never all are).
    Measured,
}

impl PerceptionSource {
    /// A short name for tables.
    pub fn name(&self) -> String {
        match self {
            PerceptionSource::Json(p) => p.name().to_owned(),
            PerceptionSource::Pickles { dir, .. } => format!("pickles {}", dir.display()),
        }
    }

    /// Where the perception is read from and what its boxes are taken to be, for the output.
    pub fn describe(&self, data: &Path) -> String {
        match self {
            PerceptionSource::Json(p) => format!(
                "{} ({}: this project's JSON, {})",
                p.name(),
                if p.exact() { "exact boxes" } else { "a detector's boxes" },
                perception_path(data, "<video>", *p).display()
            ),
            PerceptionSource::Pickles { dir, boxes } => format!(
                "OPNet's pickles in {} ({})",
                dir.display(),
                match boxes {
                    Boxes::Exact => "exact boxes, as given",
                    Boxes::Noisy => "a detector's boxes, as given",
                    Boxes::Measured => "exact or a detector's, measured per video against the ground truth",
                }
            ),
        }
    }

    pub fn boxes(&self) -> Boxes {
        match self {
            PerceptionSource::Json(p) if p.exact() => Boxes::Exact,
            PerceptionSource::Json(_) => Boxes::Noisy,
            PerceptionSource::Pickles { boxes, .. } => *boxes,
        }
    }

    pub fn load(&self, data: &Path, video: &str) -> Result<PerceptionFile, CaterError> {
        match self {
            PerceptionSource::Json(p) => PerceptionFile::read(&perception_path(data, video, *p)),
            PerceptionSource::Pickles { dir, .. } => {
                PerceptionFile::read_pickle(&pickle_path(dir, video), video, "pickle")
            }
        }
    }

    /// The perception a data directory holds for `kind`, as it comes: this project's JSON
    /// (`perception/`), else LA-CATER's pickles (`perfect_perception/` for perfect perception,
    /// `od_perception/` for the detector, `od_perception_b/` for the second detector).
    pub fn find(data: &Path, kind: Perception) -> Result<PerceptionSource, CaterError> {
        if !data.is_dir() {
            let source = std::io::Error::new(std::io::ErrorKind::NotFound, "no such data directory");
            return Err(CaterError::Io { path: data.to_owned(), source });
        }
        let json_dir = data.join(PERCEPTION_DIR);
        let suffix = format!("_{}.json", kind.name());
        let has_json = std::fs::read_dir(&json_dir).is_ok_and(|mut entries| {
            entries.any(|e| e.is_ok_and(|e| e.file_name().to_string_lossy().ends_with(&suffix)))
        });
        if has_json {
            return Ok(PerceptionSource::Json(kind));
        }
        let pickles = data.join(kind.pickle_dir());
        if pickles.is_dir() {
            let boxes = if kind.exact() { Boxes::Exact } else { Boxes::Noisy };
            return Ok(PerceptionSource::Pickles { dir: pickles, boxes });
        }
        Err(CaterError::invalid(
            data,
            format!(
                "no {} perception: neither {}/<video>{suffix} nor OPNet's pickles in {}/ (or give --pickles DIR)",
                kind.name(),
                PERCEPTION_DIR,
                kind.pickle_dir()
            ),
        ))
    }
}

/// Whether every detection of a perception is, exactly, the ground-truth box of an object in its
/// frame (`[x, y, x + w, y + h]`): perfect perception's are, a detector's are not.
pub fn boxes_are_exact(perception: &PerceptionFile, truth: &GroundTruth) -> bool {
    perception.frames.iter().enumerate().all(|(f, detections)| {
        detections.iter().all(|d| {
            truth.objects.values().any(|boxes| {
                boxes.get(f).is_some_and(|&[x, y, w, h]| {
                    d.bbox == [f64::from(x), f64::from(y), f64::from(x + w), f64::from(y + h)]
                })
            })
        })
    })
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
    /// AAPA parameters for every video, as given; when `None`, the model's defaults for the
    /// perception's boxes ([`Model::params_for`]) with `param_overrides` over them.
    pub params: Option<Params>,
    /// A JSON object of parameters merged over the defaults (objects field by field), as
    /// `kpl cater eval --params FILE` gives it.
    pub param_overrides: Option<serde_json::Value>,
    pub threads: usize,
    /// Write each video's predictions as `<video>_bb.json` here.
    pub predictions_dir: Option<PathBuf>,
    /// The videos to evaluate (a split); every scene of the directory when `None`.
    pub videos: Option<Vec<String>>,
    /// OPNet's annotation files; `DIR/containment_and_occlusions` when `None` and it exists.
    pub annotations: Option<PathBuf>,
    pub frames: FramesScored,
    pub visible: VisibleFrom,
    /// Write the world state of every frame of these videos as JSON lines,
    /// `<predictions_dir>/<video>_worlds.jsonl` (AAPA models; needs `predictions_dir`).
    pub trace: Vec<String>,
}

impl EvalOptions {
    /// OPNet's scoring of `model` over every video of `data` with this project's perception.
    pub fn new(data: &Path, model: Model, perception: Perception) -> EvalOptions {
        EvalOptions {
            data: data.to_owned(),
            model,
            perception: PerceptionSource::Json(perception),
            params: None,
            param_overrides: None,
            threads: 1,
            predictions_dir: None,
            videos: None,
            annotations: None,
            frames: FramesScored::All,
            visible: VisibleFrom::Opnet,
            trace: Vec::new(),
        }
    }

    /// The parameters for a video whose boxes are exact or noisy.
    pub fn params_for(&self, noisy: bool) -> Result<Params, String> {
        if let Some(params) = &self.params {
            return Ok(params.clone());
        }
        let base = self.model.params_for(noisy);
        let Some(overrides) = &self.param_overrides else { return Ok(base) };
        let mut value =
            serde_json::to_value(base).map_err(|e| format!("encoding default parameters: {e}"))?;
        if !overrides.is_object() {
            return Err("expected a JSON object of AAPA parameters".into());
        }
        merge(&mut value, overrides);
        let params: Params = serde_json::from_value(value).map_err(|e| e.to_string())?;
        kpl_aapa::Aapa::new(params.clone()).map_err(|e| e.to_string())?;
        Ok(params)
    }
}

/// Merges `over` into `base`: objects field by field, anything else replaced.
fn merge(base: &mut serde_json::Value, over: &serde_json::Value) {
    match (base, over) {
        (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
            for (k, v) in o {
                match b.get_mut(k) {
                    Some(slot) => merge(slot, v),
                    None => {
                        b.insert(k.clone(), v.clone());
                    }
                }
            }
        }
        (slot, v) => *slot = v.clone(),
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
    /// Where the perception was read from and what its boxes were taken to be.
    pub perception_source: String,
    /// Videos scored.
    pub videos: usize,
    /// Of those, the videos whose boxes were taken as a detector's (noisy), so averaged while
    /// still (`average_still`, for the models that have it).
    pub noisy_videos: usize,
    /// The parameters used for exact boxes and for noisy ones (AAPA models; the heuristic has none).
    pub params: [Option<Params>; 2],
    pub skipped: Vec<Skipped>,
    /// Detections dropped on reading (a label no class has, a bad box), over all scored videos, and
    /// in how many videos.
    pub dropped: Dropped,
    pub dropped_videos: usize,
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

impl Report {
    /// The AAPA options that matter for the output: which extensions are on, and whether boxes
    /// were averaged while still, in how many videos.
    pub fn options(&self) -> String {
        let on = |p: &Params| {
            let e = &p.extensions;
            let mut names = Vec::new();
            for (name, flag) in [
                ("predict_motion", e.predict_motion),
                ("reacquire", e.reacquire),
                ("scale_attached", e.scale_attached),
                ("restore_partial_boxes", e.restore_partial_boxes),
                ("established_first", e.established_first),
                ("infer_hidden", e.infer_hidden),
                ("still_stays", e.still_stays),
                ("merge_duplicates", e.merge_duplicates),
                ("identity_by_place", e.identity_by_place),
            ] {
                if flag {
                    names.push(name.to_owned());
                }
            }
            if e.keep_lost > 0.0 {
                names.push(format!("keep_lost {} s", e.keep_lost));
            }
            if names.is_empty() { "none (as published)".to_owned() } else { names.join(", ") }
        };
        let averaging = |p: &Option<Params>| p.as_ref().is_some_and(|p| p.extensions.average_still);
        match &self.params {
            [None, None] => "no parameters (not an AAPA model)".to_owned(),
            [exact, noisy] => {
                let any = exact.as_ref().or(noisy.as_ref());
                let extensions = any.map_or(String::new(), on);
                let exact_videos = self.videos - self.noisy_videos;
                format!(
                    "extensions {extensions}; average_still {} for exact boxes ({exact_videos} videos), {} for a \
                     detector's ({} videos)",
                    if averaging(exact) { "on" } else { "off" },
                    if averaging(noisy) { "on" } else { "off" },
                    self.noisy_videos
                )
            }
        }
    }
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
    evaluate_video_traced(video, categories, model, params, frames_scored, |_, _| {})
}

/// [`evaluate_video`], handing each frame's world state to `trace`.
pub fn evaluate_video_traced(
    video: &VideoData,
    categories: &FrameCategories,
    model: Model,
    params: &Params,
    frames_scored: FramesScored,
    trace: impl FnMut(usize, &kpl_aapa::WorldState),
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
    let predictions =
        predict_traced(model, params, &video.scene, &video.perception, trace).map_err(|e| e.to_string())?;
    Ok((score_video(&predictions, &truth, categories, first_frame), predictions))
}

/// One video's outcome in [`evaluate`].
#[derive(Clone)]
struct Scored {
    score: VideoScore,
    noisy: bool,
    dropped: Dropped,
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
    let bad_params = |e: String| CaterError::invalid(Path::new("--params"), e);
    let params =
        [options.params_for(false).map_err(bad_params)?, options.params_for(true).map_err(bad_params)?];
    let boxes = options.perception.boxes();
    let next = AtomicUsize::new(0);
    type Outcome = Result<Scored, String>;
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
                            let noisy = match boxes {
                                Boxes::Exact => false,
                                Boxes::Noisy => true,
                                Boxes::Measured => !boxes_are_exact(&video.perception, &video.ground_truth),
                            };
                            let mut worlds = String::new();
                            let traced = options.trace.contains(name) && options.predictions_dir.is_some();
                            let (score, predictions) = evaluate_video_traced(
                                &video,
                                &categories,
                                options.model,
                                &params[usize::from(noisy)],
                                options.frames,
                                |_, world| {
                                    if traced && let Ok(line) = serde_json::to_string(world) {
                                        worlds.push_str(&line);
                                        worlds.push('\n');
                                    }
                                },
                            )?;
                            if let (true, Some(dir)) = (traced, &options.predictions_dir) {
                                let path = dir.join(format!("{name}_worlds.jsonl"));
                                std::fs::write(&path, worlds)
                                    .map_err(|e| format!("{}: {e}", path.display()))?;
                            }
                            Ok((Scored { score, noisy, dropped: video.perception.dropped }, predictions))
                        });
                    let outcome = match (outcome, &options.predictions_dir) {
                        (Ok((scored, predictions)), Some(dir)) => {
                            match write_predictions(&dir.join(format!("{name}_bb.json")), &predictions) {
                                Ok(()) => Ok(scored),
                                Err(e) => {
                                    if let Ok(mut slot) = fatal.lock() {
                                        slot.get_or_insert(e);
                                    }
                                    next.store(videos.len(), Ordering::Relaxed);
                                    break;
                                }
                            }
                        }
                        (outcome, _) => outcome.map(|(scored, _)| scored),
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
    let (mut noisy_videos, mut dropped, mut dropped_videos) = (0, Dropped::default(), 0);
    for (name, outcome) in videos.iter().zip(results.into_inner().unwrap_or_default()) {
        match outcome {
            Some(Ok(scored)) => {
                noisy_videos += usize::from(scored.noisy);
                dropped.add(&scored.dropped);
                dropped_videos += usize::from(scored.dropped.total() > 0);
                per_video.push(VideoResult { video: name.clone(), score: scored.score });
            }
            Some(Err(reason)) => skipped.push(Skipped { video: name.clone(), reason }),
            None => skipped.push(Skipped { video: name.clone(), reason: "not evaluated".into() }),
        }
    }
    let scores: Vec<VideoScore> = per_video.iter().map(|v| v.score.clone()).collect();
    let frame_counts = std::array::from_fn(|c| scores.iter().map(|s| s.frames[c]).sum());
    let categories_from = if annotations.is_empty() { "scenes" } else { "annotation files" };
    let [exact, noisy] = params;
    let aapa = options.model != Model::Heuristic;
    Ok(Report {
        model: options.model.name().to_owned(),
        perception: options.perception.name(),
        perception_source: options.perception.describe(&options.data),
        videos: per_video.len(),
        noisy_videos,
        params: if aapa { [Some(exact), Some(noisy)] } else { [None, None] },
        skipped,
        dropped,
        dropped_videos,
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
