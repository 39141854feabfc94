//! `kpl cater generate` + `kpl cater eval --json` end to end: the JSON's shape, AAPA ahead of the
//! heuristic, a split and the per-video CSV, skipped videos reported (and exit 1 with `--strict`),
//! and the exit codes for bad data (1) and usage / I/O errors (2).
#![allow(clippy::unwrap_used, reason = "tests")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn kpl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kpl")).args(args).output().unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-cater-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn eval_json(data: &Path, model: &str, perception: &str, out: &Path) -> serde_json::Value {
    let json = out.join(format!("{model}-{perception}.json"));
    let output = kpl(&[
        "cater",
        "eval",
        "--data",
        data.to_str().unwrap(),
        "--model",
        model,
        "--perception",
        perception,
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let table = String::from_utf8(output.stdout).unwrap();
    assert!(
        table.contains("Mean IoU ±SEM") && table.contains("Mean L2 ±SEM") && table.contains(model),
        "{table}"
    );
    serde_json::from_slice(&std::fs::read(json).unwrap()).unwrap()
}

#[test]
fn generate_then_eval_reports_table_one_and_aapa_wins() {
    let dir = scratch("e2e");
    let data = dir.join("data");
    let output = kpl(&["cater", "generate", "--videos", "8", "--seed", "3", "--out", data.to_str().unwrap()]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("% contained") && stderr.contains("snitch is contained in"), "{stderr}");
    let beside = std::fs::read_dir(data.join("scenes"))
        .unwrap()
        .filter(|e| e.as_ref().unwrap().file_name().to_str().unwrap().ends_with("_bb.json"));
    assert_eq!(beside.count(), 8);
    for perception in ["perfect", "detector"] {
        let aapa = eval_json(&data, "aapa", perception, &dir);
        let heuristic = eval_json(&data, "heuristic", perception, &dir);
        for report in [&aapa, &heuristic] {
            assert_eq!(report["perception"], perception);
            assert_eq!(report["videos"], 8);
            for metric in ["iou", "l2"] {
                for category in ["visible", "occluded", "contained", "carried", "overall"] {
                    let cell = &report[metric][category];
                    assert!(cell["mean"].is_f64() && cell["sem"].is_f64(), "{metric}.{category}: {cell}");
                }
            }
        }
        assert_eq!(aapa["model"], "aapa");
        let overall = |r: &serde_json::Value| r["iou"]["overall"]["mean"].as_f64().unwrap();
        assert!((0.0..=100.0).contains(&overall(&aapa)), "IoU is in percent");
        assert!(overall(&aapa) > overall(&heuristic), "{perception}: {aapa} vs {heuristic}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_split_and_per_video_results() {
    let dir = scratch("split");
    let data = dir.join("data");
    assert!(
        kpl(&[
            "cater",
            "generate",
            "--videos",
            "3",
            "--seed",
            "2",
            "--motion",
            "all",
            "--out",
            data.to_str().unwrap()
        ])
        .status
        .success()
    );
    let list = dir.join("samples.txt");
    std::fs::write(&list, "videos/CATER_new_000002.avi\nCATER_new_000000\n").unwrap();
    let csv = dir.join("per-video.csv");
    let output = kpl(&[
        "cater",
        "eval",
        "--data",
        data.to_str().unwrap(),
        "--model",
        "heuristic",
        "--videos",
        list.to_str().unwrap(),
        "--frames",
        "from-first-detection",
        "--per-video",
        csv.to_str().unwrap(),
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    assert!(rows[0].starts_with("videos_names,visible_mean_iou,occluded_mean_iou"), "{}", rows[0]);
    assert_eq!(rows.len(), 3);
    assert!(rows[1].starts_with("CATER_new_000002,") && rows[2].starts_with("CATER_new_000000,"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_videos_are_skipped_and_reported_strict_exits_1_missing_data_exits_2() {
    let dir = scratch("codes");
    let data = dir.join("data");
    assert!(
        kpl(&["cater", "generate", "--videos", "2", "--seed", "1", "--out", data.to_str().unwrap()])
            .status
            .success()
    );
    let missing = dir.join("nothing");
    let run = |d: &Path, extra: &[&str]| {
        let mut a = vec!["cater", "eval", "--data", d.to_str().unwrap(), "--model", "aapa"];
        a.extend_from_slice(extra);
        kpl(&a)
    };
    assert_eq!(run(&missing, &[]).status.code(), Some(2));
    let scene = data.join("scenes").join("CATER_new_000001.json");
    std::fs::write(&scene, "{ not json").unwrap();
    let output = run(&data, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("skipped CATER_new_000001:") && stderr.contains("CATER_new_000001.json"),
        "{stderr}"
    );
    assert!(stderr.contains("evaluated 1 videos (1 skipped)"), "{stderr}");
    assert_eq!(run(&data, &["--strict"]).status.code(), Some(1));
    // No video left to score: bad data.
    std::fs::write(data.join("scenes").join("CATER_new_000000.json"), "[]").unwrap();
    assert_eq!(run(&data, &[]).status.code(), Some(1));
    assert_eq!(kpl(&["cater", "eval", "--model", "nope"]).status.code(), Some(2));
    let help = kpl(&["cater", "eval", "--help"]);
    assert!(String::from_utf8_lossy(&help.stdout).contains("kpl cater eval --data"));
    std::fs::remove_dir_all(&dir).unwrap();
}
