//! End-to-end test of `specs/cater/snitch.kpl`: AAPA over one generated CATER-style video through
//! the runtime (`cater.video` into `aapa.anchor`, its world fed back) predicts, frame by frame,
//! exactly the snitch boxes `kpl cater eval --model aapa` predicts for that video, for two
//! generator seeds and both perception modes.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

mod common;

use std::path::Path;

use common::root;
use kpl_aapa::WorldState;
use serde_json::Value;

/// What `kpl cater eval` reads the snitch from (kpl_cater::formats::SNITCH_CLASS).
const SNITCH_CLASS: &str = "small_gold_spl_metal";
/// θ_anch of the spec and of `kpl cater eval`'s `aapa` model.
const THETA_ANCH: f64 = 0.1;

fn kpl(dir: &Path, args: &[&str]) {
    let out = common::kpl_command(args).current_dir(dir).output().unwrap();
    assert!(out.status.success(), "kpl {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// The spec's snitch per frame, as `kpl cater eval` turns a world state into a prediction.
fn predictions_of_the_spec(world_jsonl: &Path) -> Vec<[i32; 4]> {
    std::fs::read_to_string(world_jsonl)
        .unwrap()
        .lines()
        .map(|line| {
            let record: Value = serde_json::from_str(line).unwrap();
            assert_eq!(record["stream"], "world");
            let world: WorldState = serde_json::from_value(record["value"].clone()).unwrap();
            world.best_of_type(SNITCH_CLASS, THETA_ANCH).map_or([0, 0, 0, 0], |a| {
                let b = a.bbox;
                [b.x1.round() as i32, b.y1.round() as i32, b.x2.round() as i32, b.y2.round() as i32]
            })
        })
        .collect()
}

#[test]
fn the_spec_predicts_what_kpl_cater_eval_predicts() {
    let spec = std::fs::read_to_string(root().join("specs/cater/snitch.kpl")).unwrap();
    for seed in ["7", "11"] {
        for perception in ["perfect", "detector"] {
            // The spec reads ../../out/cater-video relative to itself: lay the same tree out in a
            // temporary directory.
            let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
                .join(format!("kpl-cater-spec-{seed}-{perception}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(dir.join("specs/cater")).unwrap();
            let data = dir.join("out/cater-video");
            kpl(
                &dir,
                &["cater", "generate", "--videos", "1", "--seed", seed, "--out", data.to_str().unwrap()],
            );
            let text = if perception == "detector" {
                // `kpl cater eval` averages a detector's boxes of objects standing still.
                spec.replace("perception: \"perfect\"", "perception: \"detector\"")
                    .replace("spatial_relations: false,", "spatial_relations: false,\n  average_still: true,")
            } else {
                spec.clone()
            };
            assert_ne!(text.contains("\"detector\""), perception == "perfect", "the spec's text changed");
            let spec_path = dir.join("specs/cater/snitch.kpl");
            std::fs::write(&spec_path, text).unwrap();
            let run_out = dir.join("run");
            kpl(&dir, &["run", "--quiet", spec_path.to_str().unwrap(), "--out", run_out.to_str().unwrap()]);
            let predictions = dir.join("predictions");
            kpl(
                &dir,
                &[
                    "cater",
                    "eval",
                    "--data",
                    data.to_str().unwrap(),
                    "--model",
                    "aapa",
                    "--perception",
                    perception,
                    "--predictions",
                    predictions.to_str().unwrap(),
                ],
            );
            let eval: Vec<[i32; 4]> = serde_json::from_str(
                &std::fs::read_to_string(predictions.join("CATER_new_000000_bb.json")).unwrap(),
            )
            .unwrap();
            let spec_predictions = predictions_of_the_spec(&run_out.join("world.jsonl"));
            assert_eq!(spec_predictions.len(), 300, "seed {seed}, {perception}");
            assert!(eval.iter().any(|b| *b != [0, 0, 0, 0]), "the snitch is found at all");
            let differing: Vec<usize> =
                (0..eval.len()).filter(|&f| spec_predictions.get(f) != eval.get(f)).collect();
            assert!(differing.is_empty(), "seed {seed}, {perception}: frames {differing:?} differ");
        }
    }
}
