//! Differential test against an independent Python re-implementation of OPNet's evaluation
//! (`tests/oracle/opnet.py`, written from OPNet's scripts, numpy as OPNet uses it): on generated
//! videos of both motion modes it recomputes the frame annotations from the scene JSON and the boxes,
//! runs OPNet's programmed heuristic over the perception, and analyses the prediction files
//! `kpl-cater` wrote. Everything must agree: the annotation files frame for frame, the heuristic's
//! boxes exactly, and every per-video mean IoU to 1e-12. On directories in LA-CATER's layout it
//! makes OPNet's perfect perception pickles (its `visible_only` mode; for hard scenes with the union
//! of nearer boxes) with numpy and pickle as OPNet's script does: they must hold exactly what the
//! generator's pickles hold, and `kpl cater eval --data` must score them identically. Needs the
//! Python of `scripts/test` (`KPL_PYTHON`, with numpy).
#![allow(clippy::unwrap_used, clippy::print_stderr, reason = "tests report and fail loudly")]

use std::path::{Path, PathBuf};
use std::process::Command;

use kpl_cater::dataset::{self, GeneratorConfig, Layout};
use kpl_cater::eval::{Boxes, EvalOptions, PerceptionSource, evaluate};
use kpl_cater::formats::{PerceptionFile, read_annotation_file};
use kpl_cater::layout::{self, CARRIED_FILE, CONTAINMENT_FILE, Perception, VISIBLE_FILE};
use kpl_cater::models::{Model, heuristic};
use kpl_cater::score::Category;
use kpl_cater::sim::Motion;
use serde_json::Value;

fn python() -> Option<String> {
    match std::env::var("KPL_PYTHON") {
        Ok(p) => Some(p),
        Err(_) => {
            let required = std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1");
            assert!(!required, "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set: run scripts/test");
            eprintln!("skipped: KPL_PYTHON is not set (scripts/test sets it up with numpy)");
            None
        }
    }
}

fn oracle(python: &str, data: &Path, perception: &str, predictions: &Path) -> Value {
    let out = data.join("oracle.json");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/oracle/opnet.py");
    let status = Command::new(python)
        .arg(&script)
        .arg(data)
        .arg(perception)
        .arg(predictions)
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success(), "the oracle failed");
    serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap()
}

fn frames(v: &Value) -> Vec<usize> {
    v.as_array().unwrap().iter().map(|f| f.as_u64().unwrap() as usize).collect()
}

fn check_directory(python: &str, dir: &Path, motion: Motion, seed: u64, videos: usize) {
    let config = GeneratorConfig { motion, ..GeneratorConfig::default() };
    dataset::generate(dir, videos, seed, 2, &config).unwrap();
    for (model, perception) in [(Model::Aapa, Perception::Perfect), (Model::Heuristic, Perception::Detector)]
    {
        let predictions = dir.join(format!("predictions-{}-{}", model.name(), perception.name()));
        let report = evaluate(&EvalOptions {
            predictions_dir: Some(predictions.clone()),
            threads: 2,
            ..EvalOptions::new(dir, model, perception)
        })
        .unwrap();
        assert_eq!(report.videos, videos, "skipped: {:?}", report.skipped);
        let oracle = oracle(python, dir, perception.name(), &predictions);

        // The annotation files the generator wrote are OPNet's.
        let annotations = layout::annotations_dir(dir);
        for (file, key) in
            [(CONTAINMENT_FILE, "contained"), (CARRIED_FILE, "carried"), (VISIBLE_FILE, "visible")]
        {
            let ours = read_annotation_file(&annotations.join(file)).unwrap();
            for (video, theirs) in oracle["annotations"].as_object().unwrap() {
                assert_eq!(ours[video], frames(&theirs[key]), "{file} of {video}");
            }
        }
        // OPNet's heuristic, box for box.
        for (video, theirs) in oracle["heuristic"].as_object().unwrap() {
            let file = PerceptionFile::read(&layout::perception_path(dir, video, perception)).unwrap();
            let ours = heuristic(&file);
            let theirs: Vec<[i32; 4]> = serde_json::from_value(theirs.clone()).unwrap();
            assert_eq!(ours, theirs, "heuristic on {video} ({})", perception.name());
        }
        // OPNet's analysis of the prediction files.
        let analysis = oracle["analysis"].as_object().unwrap();
        assert_eq!(analysis.len(), videos);
        let mut compared = 0;
        for result in &report.per_video {
            let theirs = &analysis[&result.video];
            for (c, category) in Category::ALL.iter().enumerate() {
                let ours = result.score.iou[c];
                let theirs = theirs[category.name()].as_f64();
                match (ours, theirs) {
                    (Some(a), Some(b)) => {
                        assert!((a - b).abs() <= 1e-12, "{} {}: {a} vs {b}", result.video, category.name());
                        compared += 1;
                    }
                    (None, None) => {}
                    other => panic!("{} {}: {other:?}", result.video, category.name()),
                }
            }
        }
        assert!(compared >= videos * 3, "only {compared} values compared");
    }
}

#[test]
fn scoring_categories_and_heuristic_agree_with_opnets_code() {
    let Some(python) = python() else { return };
    let base: PathBuf = std::env::temp_dir().join(format!("kpl-cater-oracle-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    check_directory(&python, &base.join("max-two"), Motion::MaxTwo, 31, 16);
    check_directory(&python, &base.join("all"), Motion::All, 32, 8);
    std::fs::remove_dir_all(&base).unwrap();
}

/// OPNet's perfect perception, made by the oracle from the scenes and labels, equals the
/// generator's pickles, and `--data` finds and scores them (exact boxes: no averaging) as it
/// scores the oracle's.
fn check_perfect_pickles(python: &str, dir: &Path, motion: Motion, seed: u64, videos: usize) {
    let config = GeneratorConfig { motion, layout: Layout::LaCater, ..GeneratorConfig::default() };
    dataset::generate(dir, videos, seed, 2, &config).unwrap();
    let theirs = dir.join("oracle_perfect_perception");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/oracle/opnet.py");
    let rule = if motion == Motion::Hard { "union" } else { "opnet" };
    let status = Command::new(python)
        .arg(&script)
        .arg("perfect-pickles")
        .arg(dir)
        .arg(&theirs)
        .arg(rule)
        .status()
        .unwrap();
    assert!(status.success(), "the oracle failed");
    let mut detections = 0;
    for video in layout::list_videos(dir).unwrap() {
        let pickle =
            |d: &Path| PerceptionFile::read_pickle(&layout::pickle_path(d, &video), &video, "perfect");
        let ours = pickle(&dir.join(layout::PERFECT_PICKLES_DIR)).unwrap();
        let oracle = pickle(&theirs).unwrap();
        assert_eq!(ours.frames, oracle.frames, "{video}");
        detections += ours.frames.iter().map(Vec::len).sum::<usize>();
    }
    assert!(detections > videos * 300 * 3, "{detections} detections");
    let found = PerceptionSource::find(dir, Perception::Perfect).unwrap();
    assert_eq!(found.boxes(), Boxes::Exact, "{found:?}");
    let report = |perception| {
        evaluate(&EvalOptions {
            perception,
            threads: 2,
            ..EvalOptions::new(dir, Model::Aapa, Perception::Perfect)
        })
        .unwrap()
    };
    let (ours, oracle) =
        (report(found), report(PerceptionSource::Pickles { dir: theirs, boxes: Boxes::Measured }));
    assert_eq!(ours.videos, videos, "skipped: {:?}", ours.skipped);
    assert_eq!((ours.noisy_videos, oracle.noisy_videos), (0, 0), "perfect perception's boxes are exact");
    assert_eq!(ours.iou, oracle.iou);
}

#[test]
fn perfect_perception_pickles_are_opnets() {
    let Some(python) = python() else { return };
    let base: PathBuf = std::env::temp_dir().join(format!("kpl-cater-oracle-pp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&base);
    check_perfect_pickles(&python, &base.join("max-two"), Motion::MaxTwo, 33, 8);
    check_perfect_pickles(&python, &base.join("hard"), Motion::Hard, 34, 6);
    std::fs::remove_dir_all(&base).unwrap();
}
