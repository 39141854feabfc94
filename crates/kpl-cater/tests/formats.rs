//! LA-CATER's files as CATER's renderer and OPNet's scripts write them: hand-made files of their
//! exact shapes read unchanged, generated ones read back, and every kind of bad data is an error
//! naming the file and what is wrong (never a number that overflows into a score).
#![allow(clippy::unwrap_used, reason = "tests")]

use std::path::PathBuf;

use kpl_cater::CaterError;
use kpl_cater::classes::{SNITCH_INDEX, is_large_cone, opnet_class, opnet_classes, opnet_index, parse_class};
use kpl_cater::dataset::{self, GeneratorConfig, Layout};
use kpl_cater::eval::{Boxes, PerceptionSource, boxes_are_exact};
use kpl_cater::formats::{
    CameraField, Dropped, GroundTruth, MovementKind, PerceptionFile, SNITCH_KEY, Scene, read_annotation_file,
    read_predictions, write_predictions,
};
use kpl_cater::layout::{self, Perception};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-cater-formats-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A scene JSON shaped as CATER (OPNet's fork) writes it: extra fields, Blender instance names,
/// `_no_op` records, per-frame `locations` (cut to three frames), the camera as a location list.
const CATER_SCENE: &str = r#"{
  "split": "new", "image_index": 5748, "image_filename": "CATER_new_005748.avi",
  "directions": {"behind": [-0.75, 0.66, 0.0], "front": [0.75, -0.66, -0.0]},
  "objects": [
    {"shape": "spl", "size": "small", "sized": 0.3, "material": "metal",
     "3d_coords": [1.0, -1.0, 0.3], "rotation": 12.5, "pixel_coords": [160, 140, 9.1],
     "color": "gold", "instance": "Spl_0",
     "locations": {"0": [1.0, -1.0, 0.3], "1": [1.0, -1.0, 0.3], "2": [1.0, -1.0, 0.3]}},
    {"shape": "cone", "size": "large", "sized": 0.75, "material": "rubber",
     "3d_coords": [-1.0, 2.0, 0.75], "rotation": 99.0, "pixel_coords": [190, 90, 12.0],
     "color": "red", "instance": "Cone_1",
     "locations": {"2": [-1.0, 2.0, 0.75], "0": [-1.0, 2.0, 0.75], "1": [-1.0, 2.0, 0.75]}},
    {"shape": "cylinder", "size": "medium", "sized": 0.5, "material": "metal",
     "3d_coords": [2.0, 2.0, 0.5], "rotation": 3.0, "pixel_coords": [240, 100, 11.0],
     "color": "cyan", "instance": "SmoothCylinder-Short_0",
     "locations": {"0": [2.0, 2.0, 0.5], "1": [2.0, 2.0, 0.5], "2": [2.0, 2.0, 0.5]}}
  ],
  "relationships": {"behind": [[1], [], []]},
  "movements": {
    "Cone_1": [["_contain", "Spl_0", 10, 35], ["_slide", null, 40, 66], ["_pick_place", null, 80, 104]],
    "Spl_0": [["_slide", null, 40, 66], ["_no_op", null, 80, 104]],
    "SmoothCylinder-Short_0": [["_rotate", null, 270, 300]]
  },
  "camera": [7.1146, -6.1746, 5.5963]
}"#;

#[test]
fn a_scene_as_cater_writes_it_is_read() {
    let dir = scratch("cater-scene");
    let path = dir.join("CATER_new_005748.json");
    std::fs::write(&path, CATER_SCENE).unwrap();
    let scene = Scene::read(&path).unwrap();
    assert_eq!(scene.video, "CATER_new_005748");
    assert_eq!(scene.camera.unwrap().location(), [7.1146, -6.1746, 5.5963]);
    let cylinder = scene.object("SmoothCylinder-Short_0").unwrap();
    assert_eq!(cylinder.key(), "medium_cyan_cylinder_metal_SmoothCylinder-Short_0");
    assert_eq!(cylinder.locations.0.len(), 3);
    assert_eq!(scene.object("Cone_1").unwrap().locations.0[2], [-1.0, 2.0, 0.75]);
    assert_eq!(scene.movements["Spl_0"][1].kind(), Some(MovementKind::NoOp));
    // The camera form this project wrote before is still read.
    let old = CATER_SCENE.replace(
        r#""camera": [7.1146, -6.1746, 5.5963]"#,
        r#""camera": {"location": [7.0, -6.0, 5.0], "look_at": [0, 0, 0], "focal_px": 350.0}"#,
    );
    std::fs::write(&path, old).unwrap();
    assert!(matches!(Scene::read(&path).unwrap().camera, Some(CameraField::Full { .. })));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn generated_files_round_trip_and_lie_where_opnet_looks() {
    let dir = scratch("roundtrip");
    let video = dataset::generate_video(3, 5, &GeneratorConfig::default());
    dataset::write_video(&dir, &video, Layout::Kpl).unwrap();
    let name = &video.scene.video;
    // `<video>_bb.json` beside the scene, as CATER's renderer writes it.
    assert_eq!(layout::find_ground_truth(&dir, name), dir.join("scenes").join(format!("{name}_bb.json")));
    assert_eq!(Scene::read(&layout::scene_path(&dir, name)).unwrap(), video.scene);
    let truth = GroundTruth::read(&layout::find_ground_truth(&dir, name)).unwrap();
    assert_eq!(truth, video.ground_truth);
    assert_eq!(truth.frames(), 300);
    for (mode, file) in [
        (Perception::Perfect, &video.perfect),
        (Perception::Detector, &video.detector),
        (Perception::DetectorB, &video.detector_b),
    ] {
        assert_eq!(&PerceptionFile::read(&layout::perception_path(&dir, name, mode)).unwrap(), file);
    }
    // The ground truth beside the scenes is not taken for a video.
    assert_eq!(layout::list_videos(&dir).unwrap(), vec![name.clone()]);
    // OPNet's test data keeps it in labels/; older directories in bb/.
    for sub in ["labels", "bb"] {
        std::fs::create_dir_all(dir.join(sub)).unwrap();
        let moved = dir.join(sub).join(format!("{name}_bb.json"));
        std::fs::rename(layout::find_ground_truth(&dir, name), &moved).unwrap();
        assert_eq!(layout::find_ground_truth(&dir, name), moved);
    }
    let raw: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("bb").join(format!("{name}_bb.json"))).unwrap())
            .unwrap();
    assert!(raw[SNITCH_KEY][0].as_array().unwrap().iter().all(serde_json::Value::is_i64));
    let predictions = vec![[1, 2, 3, 4], [0, 0, 0, 0], [300, 200, 319, 239]];
    let path = dir.join("p_bb.json");
    write_predictions(&path, &predictions).unwrap();
    assert_eq!(read_predictions(&path).unwrap(), predictions);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn la_caters_layout_is_found_as_it_comes() {
    // LA-CATER as OPNet's configurations name its folders: scenes/, labels/<video>_bb.json,
    // perfect_perception/ and od_perception/ (OPNet's pickles); no perception/ of this project's.
    let dir = scratch("la-cater");
    let video = dataset::generate_video(3, 5, &GeneratorConfig::default());
    dataset::write_video(&dir, &video, Layout::LaCater).unwrap();
    let name = &video.scene.video;
    assert!(!dir.join("perception").exists());
    assert_eq!(layout::find_ground_truth(&dir, name), dir.join("labels").join(format!("{name}_bb.json")));
    let perfect = PerceptionSource::find(&dir, Perception::Perfect).unwrap();
    assert_eq!(
        perfect,
        PerceptionSource::Pickles { dir: dir.join("perfect_perception"), boxes: Boxes::Exact }
    );
    let detector = PerceptionSource::find(&dir, Perception::Detector).unwrap();
    assert_eq!(detector, PerceptionSource::Pickles { dir: dir.join("od_perception"), boxes: Boxes::Noisy });
    assert!(perfect.describe(&dir).contains("perfect_perception"));
    // The perfect perception pickle holds OPNet's perfect perception, and its boxes are the ground
    // truth's, pixel for pixel.
    let file = perfect.load(&dir, name).unwrap();
    let truth = GroundTruth::read(&layout::find_ground_truth(&dir, name)).unwrap();
    assert!(boxes_are_exact(&file, &truth));
    let expected: Vec<Vec<(&str, [f64; 4])>> = video
        .opnet_perfect
        .iter()
        .map(|f| f.iter().map(|(l, b)| (opnet_class(*l).unwrap(), b.map(|v| v as f64))).collect())
        .collect();
    let got: Vec<Vec<(&str, [f64; 4])>> =
        file.frames.iter().map(|f| f.iter().map(|d| (file.class_of(d), d.bbox)).collect()).collect();
    assert_eq!(got, expected);
    // The detector's: a class OPNet does not have is label -1 in the pickle, dropped and counted on
    // reading; the other detections are the detector's, rounded to whole pixels.
    let file = detector.load(&dir, name).unwrap();
    assert!(!boxes_are_exact(&file, &truth));
    let unknown: usize = video
        .detector
        .frames
        .iter()
        .flatten()
        .filter(|d| opnet_index(video.detector.class_of(d)).is_none())
        .count();
    assert_eq!(file.dropped.unknown_class, unknown);
    let kept: usize = file.frames.iter().map(Vec::len).sum();
    assert_eq!(kept + unknown, video.detector.frames.iter().map(Vec::len).sum::<usize>());
    // A directory with neither this project's perception nor pickles says what it looked for.
    let e = PerceptionSource::find(&dir, Perception::DetectorB).map(|_| ());
    assert!(e.is_ok(), "od_perception_b/ is written too");
    std::fs::remove_dir_all(dir.join("od_perception_b")).unwrap();
    let e = PerceptionSource::find(&dir, Perception::DetectorB).unwrap_err().to_string();
    assert!(e.contains("od_perception_b") && e.contains("perception/"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_split_is_a_list_of_names_or_paths() {
    let dir = scratch("split");
    let path = dir.join("samples.txt");
    std::fs::write(&path, "# test split\ndata/videos/CATER_new_005748.avi\n\nCATER_new_000001\n").unwrap();
    assert_eq!(layout::read_video_list(&path).unwrap(), vec!["CATER_new_005748", "CATER_new_000001"]);
    std::fs::write(&path, "a.avi\nb\na\n").unwrap();
    let e = layout::read_video_list(&path).unwrap_err();
    assert!(e.is_data_error() && e.to_string().contains("line 3: `a` is listed twice"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn opnets_class_indices() {
    let table = opnet_classes();
    assert_eq!(table.len(), 193);
    assert_eq!(opnet_index("small_gold_spl_metal"), Some(SNITCH_INDEX));
    assert_eq!(opnet_class(0), Some("large_blue_cone_metal"));
    assert_eq!(opnet_class(64), Some("medium_blue_cone_metal"));
    assert_eq!(opnet_class(139), Some("small_cyan_sphere_metal"));
    assert_eq!(opnet_class(141), Some("small_gray_cone_metal"));
    assert_eq!(opnet_class(192), Some("small_yellow_sphere_rubber"));
    assert_eq!(opnet_class(193), None);
    assert_eq!(opnet_class(-1), None);
    // OPNet's LARGE_CONS_INDICES = range(0, 64, 4).
    let large: Vec<usize> = (0..193).filter(|&i| is_large_cone(&table[i])).collect();
    assert_eq!(large, (0..64).step_by(4).collect::<Vec<_>>());
    assert!(table.iter().all(|c| parse_class(c).is_some()));
}

fn expect_invalid(result: Result<impl std::fmt::Debug, CaterError>, says: &str) {
    let e = result.unwrap_err();
    assert!(matches!(e, CaterError::Invalid { .. } | CaterError::Json { .. }), "{e:?}");
    assert!(e.is_data_error());
    assert!(e.to_string().contains(says), "`{e}` does not say `{says}`");
}

#[test]
fn bad_data_is_an_error_that_says_what_is_wrong() {
    let dir = scratch("bad");
    let missing = GroundTruth::read(&dir.join("nope_bb.json")).unwrap_err();
    assert!(matches!(missing, CaterError::Io { .. }) && !missing.is_data_error());
    let gt = dir.join("x_bb.json");
    for (text, says) in [
        (r#"{"a": [[1, 2, 3]]}"#, "invalid length"),
        (r#"{"a": [[1, 2, -3, 4]]}"#, "not a box"),
        (r#"{"a": [[2000000000, 2, 3, 4]]}"#, "not a box"),
        (r#"{"a": [[1, 2, 3.5, 4]]}"#, "whole pixels"),
        (r#"{"a": [[1, 2, 3, 4]], "b": [[1, 2, 3, 4], [1, 2, 3, 4]]}"#, "has 2 frames"),
    ] {
        std::fs::write(&gt, text).unwrap();
        expect_invalid(GroundTruth::read(&gt), says);
    }
    std::fs::write(&gt, r#"{"a": [[1, 2, 3, 4]]}"#).unwrap();
    expect_invalid(GroundTruth::read(&gt).unwrap().snitch_boxes(&gt), "no snitch");

    let scene = dir.join("s.json");
    let objects = r#""objects": [{"instance": "Cone_0", "shape": "cone", "size": "large", "color": "red", "material": "rubber"},
                                 {"instance": "Spl_0", "shape": "spl", "size": "small", "color": "gold", "material": "metal"}]"#;
    for (movements, says) in [
        (r#"{"Cone_0": [["_slide", null, 50, 40]]}"#, "outside frames 0 to 300"),
        (r#"{"Cone_0": [["_slide", null, 290, 310]]}"#, "outside frames 0 to 300"),
        (r#"{"Cone_0": [["_slide", null, 0, 9223372036854775807]]}"#, "outside frames"),
        (r#"{"Cube_7": [["_slide", null, 1, 20]]}"#, "`Cube_7`, which is not among the objects"),
        (r#"{"Cone_0": [["_contain", "Sphere_3", 1, 20]]}"#, "names `Sphere_3`"),
        (r#"{"Cone_0": [["_contain", null, 1, 20]]}"#, "names no object"),
        (r#"{"Cone_0": [["_teleport", null, 1, 20]]}"#, "unknown action `_teleport`"),
        (r#"{"Cone_0": [["_slide", null, 1e30, 20]]}"#, "invalid type"),
    ] {
        std::fs::write(&scene, format!(r#"{{{objects}, "movements": {movements}}}"#)).unwrap();
        expect_invalid(Scene::read(&scene), says);
    }
    std::fs::write(&scene, format!(r#"{{{}, "movements": {{}}}}"#, objects.replace("Spl_0", "Cone_0")))
        .unwrap();
    expect_invalid(Scene::read(&scene), "two objects are named `Cone_0`");

    let p = dir.join("p.json");
    for (frames, says) in [
        ("[[[3, 0, 0, 1, 1]]]", "class index 3"),
        ("[[[0, 5, 0, 1, 1]]]", "bad box"),
        ("[[[0, 0, 0, 3e9, 1]]]", "bad box"),
    ] {
        std::fs::write(
            &p,
            format!(r#"{{"video": "v", "perception": "perfect", "classes": ["a"], "frames": {frames}}}"#),
        )
        .unwrap();
        expect_invalid(PerceptionFile::read(&p), says);
    }
    // A bad detection among good ones costs that detection: dropped and counted.
    std::fs::write(
        &p,
        r#"{"video": "v", "perception": "detector", "classes": ["a"],
            "frames": [[[0, 0, 0, 1, 1], [7, 0, 0, 1, 1]], [[0, 1, 1, 2, 2], [0, 5, 0, 1, 1]], [[0, 1, 1, 2, 2]]]}"#,
    )
    .unwrap();
    let file = PerceptionFile::read(&p).unwrap();
    assert_eq!(file.dropped, Dropped { unknown_class: 1, bad_box: 1 });
    assert_eq!(file.frames.iter().map(Vec::len).collect::<Vec<_>>(), vec![1, 1, 1]);
    let a = dir.join("a.txt");
    for (text, says) in [
        ("v\t1,2,x\n", "line 1: `x` is not a frame number"),
        ("v\t1,301\n", "past the last frame"),
        ("v\t1\nv\t2\n", "appears twice"),
        ("v 1,2\n", "expected `<video><TAB><frames>`"),
    ] {
        std::fs::write(&a, text).unwrap();
        expect_invalid(read_annotation_file(&a), says);
    }
    std::fs::write(&a, "v\t\nw\t3,4\n").unwrap();
    let ok = read_annotation_file(&a).unwrap();
    assert_eq!((ok["v"].len(), ok["w"].clone()), (0, vec![3, 4]));
    let pred = dir.join("p_bb.json");
    std::fs::write(&pred, "[[0, 0, 1, 1], [0, 0, 2e9, 1]]").unwrap();
    expect_invalid(read_predictions(&pred), "frame 1");
    std::fs::remove_dir_all(&dir).unwrap();
}
