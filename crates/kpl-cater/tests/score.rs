//! Scoring as OPNet's code does it: the +1-pixel IoU, the containment categories from the movements,
//! per-video means from the first detection and mean ± SEM over videos.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::collections::BTreeMap;

use kpl_cater::formats::{Movement, Scene};
use kpl_cater::score::{
    Categories, Category, centre_distance, containment_frames, iou, score_video, summarize,
};

fn mv(action: &str, other: Option<&str>, start: i64, end: i64) -> Movement {
    Movement { action: action.into(), other: other.map(str::to_owned), start, end }
}

fn scene(movements: Vec<(&str, Vec<Movement>)>) -> Scene {
    Scene {
        video: "v".into(),
        objects: vec![],
        movements: movements.into_iter().map(|(k, v)| (k.to_owned(), v)).collect::<BTreeMap<_, _>>(),
        camera: None,
    }
}

#[test]
fn iou_counts_pixels_inclusively() {
    assert_eq!(iou([0, 0, 9, 9], [0, 0, 9, 9]), 1.0);
    // 10x10 boxes shifted by 5 columns: (9 - 5 + 1) * 10 = 50 pixels shared of 150.
    assert!((iou([0, 0, 9, 9], [5, 0, 14, 9]) - 50.0 / 150.0).abs() < 1e-12);
    // A point box is one pixel: [0,0,0,0] against itself is a perfect match.
    assert_eq!(iou([0, 0, 0, 0], [0, 0, 0, 0]), 1.0);
    assert_eq!(iou([0, 0, 0, 0], [10, 10, 20, 20]), 0.0);
    // Touching boxes share the boundary pixel column under the +1 convention.
    assert!((iou([0, 0, 9, 9], [9, 0, 18, 9]) - 10.0 / 190.0).abs() < 1e-12);
    assert_eq!(centre_distance([0, 0, 10, 10], [3, 4, 13, 14]), 5.0);
}

#[test]
fn containment_and_carrying_follow_opnets_rules() {
    let s = scene(vec![
        (
            "Cone_1",
            vec![
                mv("_contain", Some("Spl_0"), 10, 30),
                mv("_slide", None, 40, 60),
                mv("_pick_place", None, 80, 100),
                mv("_slide", None, 110, 130), // after the release: not carried
            ],
        ),
        // A cone containing something else, and a non-cone: neither counts.
        ("Cone_2", vec![mv("_contain", Some("Cube_0"), 0, 20), mv("_slide", None, 150, 170)]),
        ("Cube_0", vec![mv("_slide", None, 200, 220)]),
        // A containment never released lasts to the last frame, its slides are carried.
        ("Cone_3", vec![mv("_contain", Some("Spl_0"), 240, 260), mv("_slide", None, 270, 290)]),
    ]);
    let (contained, carried) = containment_frames(&s, 300);
    let frames = |v: &[bool]| v.iter().enumerate().filter(|(_, b)| **b).map(|(f, _)| f).collect::<Vec<_>>();
    let expected_contained: Vec<usize> = (30..=80).chain(260..=299).collect();
    assert_eq!(frames(&contained), expected_contained);
    let expected_carried: Vec<usize> = (40..=60).chain(270..=290).collect();
    assert_eq!(frames(&carried), expected_carried);
}

#[test]
fn videos_are_scored_from_the_first_detection_per_category() {
    let s = scene(vec![("Cone_1", vec![mv("_contain", Some("Spl_0"), 0, 5), mv("_pick_place", None, 8, 9)])]);
    let visible = vec![false, false, true, true, true, false, false, false, false, true];
    let categories = Categories::new(&s, visible);
    assert!(categories.contains(Category::Contained, 5) && !categories.contains(Category::Occluded, 5));
    assert!(categories.contains(Category::Occluded, 1));
    let truth = vec![[10, 10, 19, 19]; 10];
    let mut predictions = vec![[10, 10, 19, 19]; 10];
    predictions[0] = [100, 100, 110, 110]; // before the first detection: not counted
    predictions[6] = [10, 13, 19, 22];
    let score = score_video(&predictions, &truth, &categories, Some(2));
    assert_eq!(score.iou[0], Some(1.0)); // visible: frames 2, 3, 4, 9
    assert_eq!(score.iou[1], None); // occluded frames 0, 1 precede the first detection
    // Contained: frames 5..=8; frame 6 is off by 3 rows (70 of 130 pixels).
    assert!((score.iou[2].unwrap() - (3.0 + 70.0 / 130.0) / 4.0).abs() < 1e-12);
    assert!((score.l2[2].unwrap() - 3.0 / 4.0).abs() < 1e-12);
    assert_eq!(score.iou[3], None);
    assert!((score.iou[4].unwrap() - (7.0 + 70.0 / 130.0) / 8.0).abs() < 1e-12);
    let never = score_video(&predictions, &truth, &categories, None);
    assert!(never.iou.iter().all(Option::is_none));
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
