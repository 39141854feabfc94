//! Generating a data directory in LA-CATER's layout ([`crate::layout`]): per video the CATER scene
//! JSON, `<video>_bb.json` beside it, perfect and detector perception, and, for the whole set,
//! OPNet's annotation files and a manifest with the frame mix per category.
//!
//! Generation is deterministic given the seed: video `i` draws from ChaCha8 seeded with the seed on
//! stream `i`, so the output does not depend on the number of threads.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::categories::{FrameCategories, carried_frames, contained_frames, visible_frames};
use crate::classes::{SNITCH_INDEX, opnet_index};
use crate::detector::{DetectorNoise, detect_video, perfect};
use crate::detector_b::{DetectorBNoise, detect_video_b};
use crate::error::CaterError;
use crate::formats::pickle::write_perception_pickle;
use crate::formats::{
    Annotations, CameraField, FRAMES, GroundTruth, PerceptionFile, Scene, read_json, write_annotation_file,
    write_json,
};
use crate::layout::{
    ANNOTATIONS_DIR, CARRIED_FILE, CONTAINMENT_FILE, DETECTOR_PICKLES_DIR, LABELS_DIR, PERCEPTION_DIR,
    PERFECT_PICKLES_DIR, Perception, VISIBLE_FILE, ground_truth_path, perception_path, pickle_path,
    scene_path,
};
use crate::perfect_pickles::{Occlusion, perfect_perception};
use crate::render::{Camera, Rendered, render};
use crate::sim::{Motion, directions, simulate};

/// What the generator makes.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GeneratorConfig {
    pub motion: Motion,
    pub noise: DetectorNoise,
    pub noise_b: DetectorBNoise,
    pub layout: Layout,
}

/// Which files a generated directory has.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Layout {
    /// This project's: `scenes/` with the scene JSON and `<video>_bb.json`, `perception/` with the
    /// three perceptions as JSON.
    #[default]
    Kpl,
    /// LA-CATER's, as OPNet's code reads it: `scenes/`, `labels/<video>_bb.json`, OPNet's pickles
    /// in `perfect_perception/` (made by OPNet's rule, [`crate::perfect_pickles`]),
    /// `od_perception/` (the detector) and `od_perception_b/` (the second detector), and
    /// `samples.txt`. A detection whose class is not one of OPNet's gets label `-1`.
    LaCater,
}

/// How many frames fall in each category over a set of videos (OPNet's definitions).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct FrameMix {
    pub frames: usize,
    pub visible: usize,
    pub occluded: usize,
    pub contained: usize,
    pub carried: usize,
    /// Videos in which the snitch is contained at some frame.
    pub videos_with_containment: usize,
}

impl FrameMix {
    fn add(&mut self, c: &FrameCategories) {
        self.frames += c.frames();
        self.visible += c.visible.iter().filter(|v| **v).count();
        self.occluded += (0..c.frames()).filter(|&f| c.occluded(f)).count();
        self.contained += c.contained.iter().filter(|v| **v).count();
        self.carried += c.carried.iter().filter(|v| **v).count();
        self.videos_with_containment += usize::from(c.contained.iter().any(|v| *v));
    }

    /// A category's share of all frames, in percent.
    pub fn percent(&self, count: usize) -> f64 {
        if self.frames == 0 { 0.0 } else { 100.0 * count as f64 / self.frames as f64 }
    }
}

/// `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub generator: String,
    pub seed: u64,
    pub videos: usize,
    /// `max-two` (LA-CATER), `all` (every object moves) or `hard` (this project's hard scenes).
    pub motion: String,
    /// `kpl` or `la-cater` (which files, [`Layout`]).
    #[serde(default)]
    pub layout: String,
    pub frame_mix: FrameMix,
    /// Videos drawn again because objects collided.
    pub redraws: usize,
}

pub fn video_name(index: usize) -> String {
    format!("CATER_new_{index:06}")
}

/// Everything generated for one video.
#[derive(Debug, Clone)]
pub struct GeneratedVideo {
    pub scene: Scene,
    pub ground_truth: GroundTruth,
    pub perfect: PerceptionFile,
    pub detector: PerceptionFile,
    pub detector_b: PerceptionFile,
    /// OPNet's perfect perception (its rule, or the union of nearer boxes in hard scenes): per
    /// frame `(OPNet label, [x1, y1, x2, y2])`.
    pub opnet_perfect: Vec<Vec<(i64, [i64; 4])>>,
    pub categories: FrameCategories,
    pub redraws: usize,
}

/// Generates video `index` of a data set with this seed.
pub fn generate_video(seed: u64, index: usize, config: &GeneratorConfig) -> GeneratedVideo {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index as u64);
    let name = video_name(index);
    let sim = simulate(&mut rng, config.motion);
    let camera = Camera::new(sim.camera);
    let frames: Vec<Vec<Rendered>> =
        sim.states.iter().map(|states| render(&camera, &sim.objects, states)).collect();
    let mut ground_truth = GroundTruth::default();
    for (i, object) in sim.objects.iter().enumerate() {
        ground_truth.objects.insert(object.info.key(), frames.iter().map(|f| f[i].ground_truth).collect());
    }
    // One class index per distinct class: identical objects share theirs, as a detector's labels do.
    let mut classes: Vec<String> = Vec::new();
    let object_class: Vec<u32> = sim
        .objects
        .iter()
        .map(|o| {
            let class = o.info.class();
            let index = classes.iter().position(|c| *c == class).unwrap_or_else(|| {
                classes.push(class);
                classes.len() - 1
            });
            index as u32
        })
        .collect();
    let perfect_frames = frames.iter().map(|frame| perfect(frame, &object_class)).collect();
    let mut detector_classes = classes.clone();
    let detector_frames =
        detect_video(&mut rng, &frames, &mut detector_classes, &object_class, &config.noise);
    // The second detector draws from a generator of its own.
    let mut rng_b = ChaCha8Rng::seed_from_u64(seed ^ DETECTOR_B_SEED);
    rng_b.set_stream(index as u64);
    let mut detector_b_classes = classes.clone();
    let detector_b_frames =
        detect_video_b(&mut rng_b, &frames, &mut detector_b_classes, &object_class, &config.noise_b);
    let objects = sim
        .objects
        .iter()
        .map(|o| {
            let mut info = o.info.clone();
            info.pixel_coords = Some(camera.pixel_coords(info.coords));
            info
        })
        .collect();
    let scene = Scene {
        video: name.clone(),
        split: Some("new".into()),
        image_index: Some(index as u64),
        image_filename: Some(format!("{name}.avi")),
        directions: directions(),
        objects,
        movements: sim.movements,
        camera: Some(CameraField::Location(sim.camera)),
    };
    let occlusion = if config.motion == Motion::Hard {
        Occlusion::Union { camera: sim.camera }
    } else {
        Occlusion::OneBox { visible_ratio: 0.0 }
    };
    let opnet_perfect = perfect_perception(&scene, &ground_truth, FRAMES, occlusion)
        .unwrap_or_else(|| vec![Vec::new(); FRAMES]);
    let visible = if config.motion == Motion::Hard {
        // Visible when OPNet's rule, with the union of nearer boxes, keeps the snitch.
        opnet_perfect.iter().map(|f| f.iter().any(|(label, _)| *label == i64::from(SNITCH_INDEX))).collect()
    } else {
        visible_frames(&scene, &ground_truth, FRAMES, 0.0).unwrap_or_else(|_| vec![false; FRAMES])
    };
    let categories = FrameCategories {
        visible,
        contained: contained_frames(&scene, FRAMES),
        carried: carried_frames(&scene, FRAMES),
    };
    GeneratedVideo {
        perfect: PerceptionFile {
            video: name.clone(),
            perception: "perfect".into(),
            classes,
            frames: perfect_frames,
            ..PerceptionFile::default()
        },
        detector: PerceptionFile {
            video: name.clone(),
            perception: "detector".into(),
            classes: detector_classes,
            frames: detector_frames,
            ..PerceptionFile::default()
        },
        detector_b: PerceptionFile {
            video: name,
            perception: "detector-b".into(),
            classes: detector_b_classes,
            frames: detector_b_frames,
            ..PerceptionFile::default()
        },
        opnet_perfect,
        scene,
        ground_truth,
        categories,
        redraws: sim.redraws,
    }
}

fn create_dir(path: &Path) -> Result<(), CaterError> {
    std::fs::create_dir_all(path).map_err(|source| CaterError::Io { path: path.to_owned(), source })
}

/// The frame lists of a mask, as OPNet's annotation files hold them.
fn frame_list(mask: &[bool]) -> Vec<usize> {
    mask.iter().enumerate().filter(|(_, v)| **v).map(|(f, _)| f).collect()
}

/// Writes `videos` videos into `dir` with `threads` workers, then OPNet's annotation files and the
/// manifest.
pub fn generate(
    dir: &Path,
    videos: usize,
    seed: u64,
    threads: usize,
    config: &GeneratorConfig,
) -> Result<Manifest, CaterError> {
    for sub in ["scenes", ANNOTATIONS_DIR] {
        create_dir(&dir.join(sub))?;
    }
    let next = AtomicUsize::new(0);
    let first_error: Mutex<Option<CaterError>> = Mutex::new(None);
    let categories: Mutex<BTreeMap<usize, (String, FrameCategories, usize)>> = Mutex::new(BTreeMap::new());
    std::thread::scope(|scope| {
        for _ in 0..threads.max(1) {
            scope.spawn(|| {
                loop {
                    let index = next.fetch_add(1, Ordering::Relaxed);
                    if index >= videos {
                        break;
                    }
                    let video = generate_video(seed, index, config);
                    if let Err(e) = write_video(dir, &video, config.layout) {
                        if let Ok(mut slot) = first_error.lock() {
                            slot.get_or_insert(e);
                        }
                        next.store(videos, Ordering::Relaxed);
                        break;
                    }
                    if let Ok(mut c) = categories.lock() {
                        c.insert(index, (video.scene.video.clone(), video.categories, video.redraws));
                    }
                }
            });
        }
    });
    if let Some(e) = first_error.into_inner().ok().flatten() {
        return Err(e);
    }
    let categories = categories.into_inner().unwrap_or_default();
    let mut mix = FrameMix::default();
    let (mut contained, mut carried, mut visible) =
        (Annotations::new(), Annotations::new(), Annotations::new());
    let mut redraws = 0;
    for (name, c, r) in categories.values() {
        mix.add(c);
        redraws += r;
        contained.insert(name.clone(), frame_list(&c.contained));
        carried.insert(name.clone(), frame_list(&c.carried));
        visible.insert(name.clone(), frame_list(&c.visible));
    }
    let annotations = dir.join(ANNOTATIONS_DIR);
    write_annotation_file(&annotations.join(CONTAINMENT_FILE), &contained)?;
    write_annotation_file(&annotations.join(CARRIED_FILE), &carried)?;
    write_annotation_file(&annotations.join(VISIBLE_FILE), &visible)?;
    if config.layout == Layout::LaCater {
        // OPNet's list of a split: one video file per line.
        let samples: String = categories.values().map(|(name, ..)| format!("{name}.avi\n")).collect();
        let path = dir.join("samples.txt");
        std::fs::write(&path, samples).map_err(|source| CaterError::Io { path, source })?;
    }
    let manifest = Manifest {
        generator: format!("kpl-cater {}", env!("CARGO_PKG_VERSION")),
        seed,
        videos,
        motion: config.motion.name().into(),
        layout: match config.layout {
            Layout::Kpl => "kpl".into(),
            Layout::LaCater => "la-cater".into(),
        },
        frame_mix: mix,
        redraws,
    };
    write_json(&dir.join("manifest.json"), &manifest)?;
    Ok(manifest)
}

/// Writes one video's files in a layout, creating its folders if needed.
pub fn write_video(dir: &Path, video: &GeneratedVideo, layout: Layout) -> Result<(), CaterError> {
    let name = &video.scene.video;
    create_dir(&dir.join("scenes"))?;
    video.scene.write(&scene_path(dir, name))?;
    match layout {
        Layout::Kpl => {
            create_dir(&dir.join(PERCEPTION_DIR))?;
            video.ground_truth.write(&ground_truth_path(dir, name))?;
            video.perfect.write(&perception_path(dir, name, Perception::Perfect))?;
            video.detector.write(&perception_path(dir, name, Perception::Detector))?;
            video.detector_b.write(&perception_path(dir, name, Perception::DetectorB))
        }
        Layout::LaCater => {
            for sub in
                [LABELS_DIR, PERFECT_PICKLES_DIR, DETECTOR_PICKLES_DIR, Perception::DetectorB.pickle_dir()]
            {
                create_dir(&dir.join(sub))?;
            }
            video.ground_truth.write(&dir.join(LABELS_DIR).join(format!("{name}_bb.json")))?;
            write_perception_pickle(
                &pickle_path(&dir.join(PERFECT_PICKLES_DIR), name),
                &video.opnet_perfect,
            )?;
            for (perception, file) in
                [(Perception::Detector, &video.detector), (Perception::DetectorB, &video.detector_b)]
            {
                write_perception_pickle(
                    &pickle_path(&dir.join(perception.pickle_dir()), name),
                    &opnet_labels(file),
                )?;
            }
            Ok(())
        }
    }
}

/// A perception's frames with OPNet's class indices (`-1` for a class OPNet does not have) and
/// boxes rounded to whole pixels.
fn opnet_labels(file: &PerceptionFile) -> Vec<Vec<(i64, [i64; 4])>> {
    let labels: Vec<i64> = file.classes.iter().map(|c| opnet_index(c).map_or(-1, i64::from)).collect();
    file.frames
        .iter()
        .map(|f| {
            f.iter()
                .map(|d| {
                    (labels.get(d.class as usize).copied().unwrap_or(-1), d.bbox.map(|v| v.round() as i64))
                })
                .collect()
        })
        .collect()
}

/// Xor-ed into the seed for the second detector's generator.
const DETECTOR_B_SEED: u64 = 0xde7e_c70b;

pub fn read_manifest(dir: &Path) -> Result<Manifest, CaterError> {
    read_json(&dir.join("manifest.json"))
}
