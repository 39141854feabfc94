//! Scoring as OPNet's code does it: the +1-pixel IoU in 64-bit arithmetic, its category rules on
//! hand-made scenes (containment, carrying with nested stacks, visibility by covering boxes), every
//! frame scored by default and from the first detection on request, mean ± SEM over videos; and a
//! data directory with bad videos among good ones reports each skip with its reason.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::collections::BTreeMap;

use kpl_cater::categories::{FrameCategories, carried_frames, contained_frames, visible_frames};
use kpl_cater::dataset::{self, GeneratorConfig};
use kpl_cater::eval::{EvalOptions, evaluate};
use kpl_cater::formats::{GroundTruth, Locations, Movement, MovementKind, Scene, SceneObject};
use kpl_cater::layout::{self, Perception};
use kpl_cater::models::Model;
use kpl_cater::score::{FramesScored, centre_distance, iou, score_video, summarize};

fn mv(kind: MovementKind, other: Option<&str>, start: i64, end: i64) -> Movement {
    Movement::new(kind, other, start, end)
}

fn object(instance: &str, class: &str, locations: Vec<[f64; 3]>) -> SceneObject {
    let parts: Vec<&str> = class.split('_').collect();
    SceneObject {
        instance: instance.into(),
        size: parts[0].into(),
        color: parts[1].into(),
        shape: parts[2].into(),
        material: parts[3].into(),
        sized: None,
        coords: locations.first().copied().unwrap_or_default(),
        rotation: 0.0,
        pixel_coords: None,
        locations: Locations(locations),
    }
}

fn scene(objects: Vec<SceneObject>, movements: Vec<(&str, Vec<Movement>)>) -> Scene {
    Scene {
        video: "v".into(),
        split: None,
        image_index: None,
        image_filename: None,
        directions: BTreeMap::new(),
        objects,
        movements: movements.into_iter().map(|(k, v)| (k.to_owned(), v)).collect(),
        camera: None,
    }
}

fn frames(v: &[bool]) -> Vec<usize> {
    v.iter().enumerate().filter(|(_, b)| **b).map(|(f, _)| f).collect()
}

#[test]
fn iou_counts_pixels_inclusively_and_never_overflows() {
    assert_eq!(iou([0, 0, 9, 9], [0, 0, 9, 9]), 1.0);
    assert!((iou([0, 0, 9, 9], [5, 0, 14, 9]) - 50.0 / 150.0).abs() < 1e-12);
    assert_eq!(iou([0, 0, 0, 0], [0, 0, 0, 0]), 1.0);
    assert_eq!(iou([0, 0, 0, 0], [10, 10, 20, 20]), 0.0);
    assert!((iou([0, 0, 9, 9], [9, 0, 18, 9]) - 10.0 / 190.0).abs() < 1e-12);
    assert_eq!(centre_distance([0, 0, 10, 10], [3, 4, 13, 14]), 5.0);
    // A box at the limits of i32 gives a tiny IoU, not 5.8e14 %.
    let huge = iou([0, 0, i32::MAX, i32::MAX], [0, 0, 9, 9]);
    assert!((0.0..1e-15).contains(&huge), "{huge}");
    assert_eq!(
        iou([i32::MIN, i32::MIN, i32::MAX, i32::MAX], [0, 0, 9, 9]),
        100.0 / (2f64.powi(32) * 2f64.powi(32))
    );
}

#[test]
fn containment_and_carrying_follow_opnets_rules() {
    let s = scene(
        vec![],
        vec![
            (
                "Cone_1",
                vec![
                    mv(MovementKind::Contain, Some("Spl_0"), 10, 30),
                    mv(MovementKind::Slide, None, 40, 60),
                    mv(MovementKind::PickPlace, None, 80, 100),
                    mv(MovementKind::Slide, None, 110, 130), // after the release: not carried
                ],
            ),
            // A cone containing something else, and a non-cone: neither counts.
            (
                "Cone_2",
                vec![
                    mv(MovementKind::Contain, Some("Cube_0"), 0, 20),
                    mv(MovementKind::Slide, None, 150, 170),
                ],
            ),
            ("SmoothCube_v2_0", vec![mv(MovementKind::Slide, None, 200, 220)]),
            // Never released: contained to the last frame (299), and its slides carried, but not one
            // ending at frame 300, after that end (OPNet compares the slide's end with 299).
            (
                "Cone_3",
                vec![
                    mv(MovementKind::Contain, Some("Spl_0"), 240, 260),
                    mv(MovementKind::Slide, None, 265, 275),
                    mv(MovementKind::Slide, None, 280, 300),
                ],
            ),
        ],
    );
    let expected_contained: Vec<usize> = (30..=80).chain(260..=299).collect();
    assert_eq!(frames(&contained_frames(&s, 300)), expected_contained);
    let expected_carried: Vec<usize> = (40..=60).chain(265..=275).collect();
    assert_eq!(frames(&carried_frames(&s, 300)), expected_carried);
}

#[test]
fn nested_stacks_are_carried_through_their_slide_records() {
    // The snitch in a medium cone, that cone in a large one which slides: CATER records a slide
    // for every object of the stack, and OPNet counts the medium cone's.
    let s = scene(
        vec![],
        vec![
            (
                "Cone_0",
                vec![mv(MovementKind::Contain, Some("Spl_0"), 5, 20), mv(MovementKind::Slide, None, 60, 80)],
            ),
            (
                "Cone_1",
                vec![
                    mv(MovementKind::Contain, Some("Cone_0"), 30, 50),
                    mv(MovementKind::Slide, None, 60, 80),
                ],
            ),
            ("Spl_0", vec![mv(MovementKind::Slide, None, 60, 80)]),
        ],
    );
    assert_eq!(frames(&carried_frames(&s, 100)), (60..=80).collect::<Vec<_>>());
    assert_eq!(frames(&contained_frames(&s, 100)), (20..=99).collect::<Vec<_>>());
}

#[test]
fn visibility_is_opnets_covering_rule() {
    // Boxes [x, y, w, h]; the camera is at OPNet's fixed position (7.1, -6.2, 5.6).
    let near = [4.0, -4.0, 0.75];
    let far = [-4.0, 4.0, 0.3];
    let mut truth = GroundTruth::default();
    // Frame 0: the snitch's box inside the cone's, the snitch further: hidden.
    // Frame 1: the same boxes, the snitch nearer: visible.
    // Frame 2: overlapping but not inside: visible (ratio 0 needs full cover).
    truth.objects.insert("small_gold_spl_metal_Spl_0".into(), vec![[100, 100, 10, 10]; 3]);
    truth.objects.insert(
        "large_red_cone_rubber_Cone_0".into(),
        vec![[90, 90, 40, 40], [90, 90, 40, 40], [105, 90, 40, 40]],
    );
    let s = scene(
        vec![
            object("Spl_0", "small_gold_spl_metal", vec![far, near, far]),
            object("Cone_0", "large_red_cone_rubber", vec![near, far, near]),
        ],
        vec![],
    );
    assert_eq!(visible_frames(&s, &truth, 3, 0.0).unwrap(), vec![false, true, true]);
    // With a visibility ratio of 0.5, half covered suffices: frame 2's snitch is covered 66 of 121
    // pixels.
    assert_eq!(visible_frames(&s, &truth, 3, 0.5).unwrap(), vec![false, true, false]);
    // A contained object is no occluder, and neither is an identical one (OPNet removes by class).
    let mut s2 = s.clone();
    s2.objects.push(object("Cone_1", "large_red_cone_rubber", vec![far, far, far]));
    truth.objects.insert("large_red_cone_rubber_Cone_1".into(), vec![[0, 0, 5, 5]; 3]);
    s2.movements.insert("Cone_2".into(), vec![]);
    s2.objects.push(object("Cone_2", "large_blue_cone_rubber", vec![far, far, far]));
    truth.objects.insert("large_blue_cone_rubber_Cone_2".into(), vec![[0, 0, 5, 5]; 3]);
    s2.movements.insert("Cone_2".into(), vec![mv(MovementKind::Contain, Some("Cone_1"), 0, 0)]);
    assert_eq!(visible_frames(&s2, &truth, 3, 0.0).unwrap(), vec![true, true, true]);
    // The snitch itself contained: not visible.
    s2.movements.insert(
        "Cone_2".into(),
        vec![mv(MovementKind::Contain, Some("Spl_0"), 1, 1), mv(MovementKind::PickPlace, None, 2, 2)],
    );
    assert_eq!(visible_frames(&s2, &truth, 3, 0.0).unwrap(), vec![false, false, false]);
    // Without per-frame locations OPNet's rule cannot be applied.
    let mut s3 = s.clone();
    s3.objects[1].locations = Locations::default();
    assert!(
        visible_frames(&s3, &truth, 3, 0.0)
            .unwrap_err()
            .to_string()
            .contains("`Cone_0` has no per-frame `locations`")
    );
}

#[test]
fn every_frame_counts_unless_asked_from_the_first_detection() {
    let categories = FrameCategories {
        visible: vec![false, false, true, true, true, false, false, false, false, true],
        contained: vec![false, false, false, false, false, true, true, true, true, false],
        carried: vec![false; 10],
    };
    let truth = vec![[10, 10, 19, 19]; 10];
    let mut predictions = vec![[10, 10, 19, 19]; 10];
    predictions[0] = [100, 100, 110, 110];
    predictions[6] = [10, 13, 19, 22];
    let all = score_video(&predictions, &truth, &categories, Some(0));
    assert_eq!(all.iou[1], Some(0.5)); // occluded: frames 0 (miss) and 1 (hit)
    assert_eq!(all.frames, [4, 2, 4, 0, 10]);
    let from = score_video(&predictions, &truth, &categories, Some(2));
    assert_eq!(from.iou[0], Some(1.0));
    assert_eq!(from.iou[1], None); // occluded frames 0, 1 precede the first detection
    assert!((from.iou[2].unwrap() - (3.0 + 70.0 / 130.0) / 4.0).abs() < 1e-12);
    assert!((from.l2[2].unwrap() - 3.0 / 4.0).abs() < 1e-12);
    assert_eq!(from.iou[3], None);
    assert!(score_video(&predictions, &truth, &categories, None).iou.iter().all(Option::is_none));
}

#[test]
fn summaries_are_mean_and_standard_error() {
    let s = summarize([1.0, 2.0, 3.0].into_iter(), 100.0);
    assert_eq!((s.mean, s.videos), (200.0, 3));
    assert!((s.sem - 100.0 / 3f64.sqrt()).abs() < 1e-9);
    let one = summarize([0.5].into_iter(), 1.0);
    assert_eq!((one.mean, one.sem, one.videos), (0.5, 0.0, 1));
    assert_eq!(summarize(std::iter::empty(), 1.0).videos, 0);
}

#[test]
fn bad_videos_are_skipped_with_their_reason_and_the_rest_scored() {
    let dir = std::env::temp_dir().join(format!("kpl-cater-skips-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dataset::generate(&dir, 6, 4, 2, &GeneratorConfig::default()).unwrap();
    let videos = layout::list_videos(&dir).unwrap();
    // 1: no snitch in the ground truth.
    let gt = layout::find_ground_truth(&dir, &videos[1]);
    let mut truth = GroundTruth::read(&gt).unwrap();
    truth.objects.remove("small_gold_spl_metal_Spl_0");
    truth.write(&gt).unwrap();
    // 2: a box that overflows.
    let gt = layout::find_ground_truth(&dir, &videos[2]);
    let text = std::fs::read_to_string(&gt).unwrap();
    let at = text.find('[').unwrap() + 2;
    std::fs::write(
        &gt,
        format!(
            "{}[2000000000, 0, 5, 5]{}",
            &text[..at - 1],
            &text[text[at..].find(']').unwrap() + at + 1..]
        ),
    )
    .unwrap();
    // 3: a movement of an object the scene does not have.
    let sp = layout::scene_path(&dir, &videos[3]);
    let mut scene: serde_json::Value = serde_json::from_slice(&std::fs::read(&sp).unwrap()).unwrap();
    scene["movements"]["Ghost_0"] = serde_json::json!([["_slide", null, 1, 20]]);
    std::fs::write(&sp, serde_json::to_vec(&scene).unwrap()).unwrap();
    // 4: perception of another length.
    let pp = layout::perception_path(&dir, &videos[4], Perception::Perfect);
    let mut perception: serde_json::Value = serde_json::from_slice(&std::fs::read(&pp).unwrap()).unwrap();
    perception["frames"].as_array_mut().unwrap().pop();
    std::fs::write(&pp, serde_json::to_vec(&perception).unwrap()).unwrap();
    let report = evaluate(&EvalOptions::new(&dir, Model::Aapa, Perception::Perfect)).unwrap();
    assert_eq!(report.videos, 2);
    let reasons: Vec<(&str, &str)> =
        report.skipped.iter().map(|s| (s.video.as_str(), s.reason.as_str())).collect();
    assert_eq!(reasons.len(), 4, "{reasons:?}");
    assert!(reasons[0].1.contains("no snitch"), "{reasons:?}");
    assert!(reasons[1].1.contains("not a box"), "{reasons:?}");
    assert!(reasons[2].1.contains("`Ghost_0`, which is not among the objects"), "{reasons:?}");
    assert!(reasons[3].1.contains("300 ground-truth frames but 299 perceived"), "{reasons:?}");
    assert!(report.iou.overall.mean.is_finite() && report.iou.overall.mean <= 100.0);
    // The same with the categories computed from the scenes instead of the annotation files, and a
    // split naming one good video.
    std::fs::remove_dir_all(layout::annotations_dir(&dir)).unwrap();
    let report = evaluate(&EvalOptions {
        videos: Some(vec![videos[0].clone()]),
        frames: FramesScored::FromFirstDetection,
        ..EvalOptions::new(&dir, Model::Heuristic, Perception::Detector)
    })
    .unwrap();
    assert_eq!((report.videos, report.skipped.len(), report.categories_from.as_str()), (1, 0, "scenes"));
    std::fs::remove_dir_all(&dir).unwrap();
}
