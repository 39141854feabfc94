//! Every LA-CATER format written then read gives back the same data; malformed files are data
//! errors, missing ones I/O errors.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::path::PathBuf;

use kpl_cater::CaterError;
use kpl_cater::dataset::{self, Perception};
use kpl_cater::formats::{
    Detection, GroundTruth, Movement, PerceptionFile, SNITCH_KEY, Scene, read_predictions, write_predictions,
};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-cater-formats-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn generated_files_round_trip() {
    let dir = scratch("roundtrip");
    let video = dataset::generate_video(3, 5);
    dataset::write_video(&dir, &video).unwrap();
    let name = &video.scene.video;
    assert_eq!(Scene::read(&dataset::scene_path(&dir, name)).unwrap(), video.scene);
    assert_eq!(GroundTruth::read(&dataset::ground_truth_path(&dir, name)).unwrap(), video.ground_truth);
    for (mode, file) in [(Perception::Perfect, &video.perfect), (Perception::Detector, &video.detector)] {
        assert_eq!(&PerceptionFile::read(&dataset::perception_path(&dir, name, mode)).unwrap(), file);
    }
    let predictions = vec![[1, 2, 3, 4], [0, 0, 0, 0], [300, 200, 319, 239]];
    let path = dir.join("p_bb.json");
    write_predictions(&path, &predictions).unwrap();
    assert_eq!(read_predictions(&path).unwrap(), predictions);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_layouts_are_those_opnet_reads() {
    let dir = scratch("layout");
    let video = dataset::generate_video(3, 1);
    dataset::write_video(&dir, &video).unwrap();
    let name = &video.scene.video;
    // `<video>_bb.json`: object key -> per-frame [x, y, w, h] integers; the snitch key is fixed.
    let bb: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dataset::ground_truth_path(&dir, name)).unwrap()).unwrap();
    let snitch = bb[SNITCH_KEY].as_array().unwrap();
    assert_eq!(snitch.len(), 300);
    assert!(snitch[0].as_array().unwrap().iter().all(|v| v.is_i64()));
    // Scene JSON: movements as [action, other, start, end].
    let scene: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dataset::scene_path(&dir, name)).unwrap()).unwrap();
    let some_move =
        scene["movements"].as_object().unwrap().values().find_map(|v| v.as_array()?.first().cloned());
    let m = some_move.unwrap();
    assert!(m[0].as_str().unwrap().starts_with('_') && m[2].is_i64() && m[3].is_i64());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn movements_are_four_element_arrays() {
    let json = r#"[["_contain", "Spl_0", 10, 30], ["_slide", null, 40, 60]]"#;
    let moves: Vec<Movement> = serde_json::from_str(json).unwrap();
    assert_eq!(
        moves[0],
        Movement { action: "_contain".into(), other: Some("Spl_0".into()), start: 10, end: 30 }
    );
    assert_eq!(moves[1].other, None);
    assert_eq!(serde_json::to_string(&moves).unwrap().replace(' ', ""), json.replace(' ', ""));
}

#[test]
fn percepts_are_numbered_left_to_right_per_shape() {
    let file = PerceptionFile {
        video: "v".into(),
        perception: "perfect".into(),
        classes: vec![
            "large_red_cone_rubber".into(),
            "small_blue_cone_metal".into(),
            "small_gold_spl_metal".into(),
        ],
        frames: vec![vec![
            Detection { class: 0, bbox: [100.0, 0.0, 120.0, 20.0] },
            Detection { class: 1, bbox: [10.0, 0.0, 20.0, 10.0] },
            Detection { class: 2, bbox: [50.0, 0.0, 60.0, 10.0] },
        ]],
    };
    let labels: Vec<(String, String)> =
        file.percepts(0).iter().map(|p| (p.label.to_string(), p.object_type.to_string())).collect();
    assert!(labels.contains(&("cone0".into(), "small_blue_cone_metal".into())));
    assert!(labels.contains(&("cone1".into(), "large_red_cone_rubber".into())));
    assert!(labels.contains(&("spl0".into(), "small_gold_spl_metal".into())));
    assert!(file.has_class(0, "small_gold_spl_metal") && !file.has_class(0, "nothing"));
}

#[test]
fn bad_files_are_data_errors_and_missing_ones_io_errors() {
    let dir = scratch("bad");
    let missing = GroundTruth::read(&dir.join("nope_bb.json")).unwrap_err();
    assert!(matches!(missing, CaterError::Io { .. }) && !missing.is_data_error());
    let path = dir.join("x_bb.json");
    std::fs::write(&path, "{\"a\": [[1, 2, 3]]}").unwrap();
    assert!(GroundTruth::read(&path).unwrap_err().is_data_error());
    std::fs::write(&path, "{\"a\": [[1, 2, -3, 4]]}").unwrap();
    assert!(matches!(GroundTruth::read(&path).unwrap_err(), CaterError::Invalid { .. }));
    let p = dir.join("p.json");
    std::fs::write(
        &p,
        r#"{"video": "v", "perception": "perfect", "classes": ["a"], "frames": [[[3, 0, 0, 1, 1]]]}"#,
    )
    .unwrap();
    assert!(matches!(PerceptionFile::read(&p).unwrap_err(), CaterError::Invalid { .. }));
    std::fs::write(
        &p,
        r#"{"video": "v", "perception": "perfect", "classes": ["a"], "frames": [[[0, 5, 0, 1, 1]]]}"#,
    )
    .unwrap();
    assert!(matches!(PerceptionFile::read(&p).unwrap_err(), CaterError::Invalid { .. }));
    let s = dir.join("s.json");
    std::fs::write(&s, r#"{"objects": [], "movements": {"Cone_0": [["_slide", null, 50, 40]]}}"#).unwrap();
    assert!(matches!(Scene::read(&s).unwrap_err(), CaterError::Invalid { .. }));
    std::fs::remove_dir_all(&dir).unwrap();
}
