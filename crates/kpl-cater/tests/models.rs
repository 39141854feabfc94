//! Data-driven model tests: a hand-made video with known outcomes (a snitch contained by a cone that
//! slides away, then revealed), and generated videos where AAPA must beat the heuristic.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::collections::BTreeMap;

use kpl_cater::categories::FrameCategories;
use kpl_cater::dataset::{self, GeneratorConfig};
use kpl_cater::eval::{EvalOptions, VideoData, evaluate, evaluate_video};
use kpl_cater::formats::{
    Detection, GroundTruth, Locations, Movement, PerceptionFile, SNITCH_CLASS, SNITCH_KEY, Scene, SceneObject,
};
use kpl_cater::layout::Perception;
use kpl_cater::models::{Model, predict};
use kpl_cater::score::{FramesScored, iou};
use kpl_cater::sim::Motion;

const CONE: &str = "large_red_cone_rubber";
const CUBE: &str = "medium_blue_cube_metal";

fn object(instance: &str, shape: &str, size: &str, color: &str, material: &str) -> SceneObject {
    SceneObject {
        instance: instance.into(),
        shape: shape.into(),
        size: size.into(),
        color: color.into(),
        material: material.into(),
        sized: None,
        coords: [0.0; 3],
        rotation: 0.0,
        pixel_coords: None,
        locations: Locations::default(),
    }
}

fn lerp(a: [f64; 4], b: [f64; 4], u: f64) -> [f64; 4] {
    std::array::from_fn(|i| a[i] + (b[i] - a[i]) * u.clamp(0.0, 1.0))
}

/// Frames 0-299. The cone comes down over the snitch (`_contain` 20..=40), slides to the right
/// carrying it (60..=100), and is picked up off it (150..=170): the snitch reappears at 200 px.
fn cone_slides_away_with_the_snitch() -> VideoData {
    let snitch_start = [100.0, 100.0, 110.0, 110.0];
    let snitch_end = [200.0, 100.0, 210.0, 110.0];
    let cone_rest = [150.0, 50.0, 180.0, 90.0];
    let cone_on_snitch = [90.0, 78.0, 120.0, 112.0];
    let cone_carried = [190.0, 78.0, 220.0, 112.0];
    let cone_away = [260.0, 40.0, 290.0, 74.0];
    let cube = [20.0, 150.0, 40.0, 170.0];
    let mut truth = Vec::new();
    let mut frames = Vec::new();
    for f in 0..300 {
        let u = |a: f64, b: f64| (f as f64 - a) / (b - a);
        let snitch = if f < 60 { snitch_start } else { lerp(snitch_start, snitch_end, u(60.0, 100.0)) };
        let cone = if f <= 40 {
            lerp(cone_rest, cone_on_snitch, u(20.0, 40.0))
        } else if f < 150 {
            lerp(cone_on_snitch, cone_carried, u(60.0, 100.0))
        } else {
            lerp(cone_carried, cone_away, u(150.0, 170.0))
        };
        truth.push(snitch.map(|v| v.round() as i32));
        let mut detections = vec![Detection { class: 1, bbox: cone }, Detection { class: 2, bbox: cube }];
        if !(35..=160).contains(&f) {
            detections.push(Detection { class: 0, bbox: snitch });
        }
        frames.push(detections);
    }
    let scene = Scene {
        video: "handmade".into(),
        split: None,
        image_index: None,
        image_filename: None,
        directions: BTreeMap::new(),
        objects: vec![
            object("Spl_0", "spl", "small", "gold", "metal"),
            object("Cone_0", "cone", "large", "red", "rubber"),
            object("Cube_0", "cube", "medium", "blue", "metal"),
        ],
        movements: BTreeMap::from([
            (
                "Cone_0".to_owned(),
                vec![
                    Movement { action: "_contain".into(), other: Some("Spl_0".into()), start: 20, end: 40 },
                    Movement { action: "_slide".into(), other: None, start: 60, end: 100 },
                    Movement { action: "_pick_place".into(), other: None, start: 150, end: 170 },
                ],
            ),
            ("Spl_0".to_owned(), vec![]),
        ]),
        camera: None,
    };
    let ground_truth = GroundTruth {
        objects: BTreeMap::from([(
            SNITCH_KEY.to_owned(),
            truth.iter().map(|b| [b[0], b[1], b[2] - b[0], b[3] - b[1]]).collect(),
        )]),
    };
    let perception = PerceptionFile {
        video: "handmade".into(),
        perception: "perfect".into(),
        classes: vec![SNITCH_CLASS.into(), CONE.into(), CUBE.into()],
        frames,
    };
    VideoData { scene, ground_truth, perception }
}

/// The handmade video's categories: contained from the contain's end to the pick-up's start,
/// carried while sliding, visible when perceived.
fn handmade_categories(video: &VideoData) -> FrameCategories {
    FrameCategories {
        visible: (0..300).map(|f| video.perception.has_class(f, SNITCH_CLASS)).collect(),
        contained: (0..300).map(|f| (40..=150).contains(&f)).collect(),
        carried: (0..300).map(|f| (60..=100).contains(&f)).collect(),
    }
}

#[test]
fn aapa_follows_the_cone_that_carries_the_snitch() {
    let video = cone_slides_away_with_the_snitch();
    let truth = video.ground_truth.snitch_boxes(std::path::Path::new("handmade")).unwrap();
    let run =
        |model: Model| predict(model, &model.default_params(), &video.scene, &video.perception).unwrap();
    let aapa = run(Model::Aapa);
    // Carried (60..=100) and contained after the slide: AAPA's snitch is under the cone.
    for f in (60..=100).chain([120, 149]) {
        assert!(iou(aapa[f], truth[f]) > 0.5, "frame {f}: {:?} vs {:?}", aapa[f], truth[f]);
    }
    // Without actions the snitch stays where it was last seen (occluded by the cone), and once the
    // cone has left it is lost.
    let blind = run(Model::AapaNoActions);
    assert!(iou(blind[50], truth[30]) > 0.9, "{:?}", blind[50]);
    assert!(iou(blind[120], truth[120]) < 0.1, "{:?}", blind[120]);
    // The heuristic switches to the nearest object, the cone, and predicts a snitch-sized box at its
    // centre, 15 pixels lower for a large cone, as OPNet's code outputs it.
    let heuristic = run(Model::Heuristic);
    let cone = video.perception.frames[120].iter().find(|d| d.class == 1).unwrap().bbox;
    let (cx, cy) = (((cone[0] + cone[2]) / 2.0).floor(), ((cone[1] + cone[3]) / 2.0).floor() + 15.0);
    assert_eq!(heuristic[120], [(cx - 5.0) as i32, (cy - 5.0) as i32, (cx + 5.0) as i32, (cy + 5.0) as i32]);
    // Once revealed, everyone sees the snitch again.
    for predictions in [&aapa, &blind, &heuristic] {
        assert!(iou(predictions[200], truth[200]) > 0.9);
    }
    let categories = handmade_categories(&video);
    let score_of = |model: Model| {
        evaluate_video(&video, &categories, model, &model.default_params(), FramesScored::All).unwrap().0
    };
    let (score, h_score) = (score_of(Model::Aapa), score_of(Model::Heuristic));
    assert!(score.iou[3].unwrap() > 0.8, "carried {:?}", score.iou[3]);
    assert!(score.iou[3].unwrap() > h_score.iou[3].unwrap() + 0.5);
}

#[test]
fn aapa_beats_the_heuristic_on_generated_videos() {
    for (motion, seed) in [(Motion::MaxTwo, 5), (Motion::All, 6)] {
        let dir = std::env::temp_dir().join(format!("kpl-cater-models-{}-{seed}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dataset::generate(&dir, 24, seed, 2, &GeneratorConfig { motion, ..GeneratorConfig::default() })
            .unwrap();
        for perception in [Perception::Perfect, Perception::Detector] {
            let run = |model| {
                evaluate(&EvalOptions { threads: 2, ..EvalOptions::new(&dir, model, perception) }).unwrap()
            };
            let (aapa, heuristic) = (run(Model::Aapa), run(Model::Heuristic));
            assert_eq!(aapa.videos, 24);
            for (a, h) in [
                (aapa.iou.overall, heuristic.iou.overall),
                (aapa.iou.contained, heuristic.iou.contained),
                (aapa.iou.occluded, heuristic.iou.occluded),
                (aapa.iou.carried, heuristic.iou.carried),
            ] {
                assert!(a.mean > h.mean, "{motion:?} {perception:?}: AAPA {a:?} vs heuristic {h:?}");
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
