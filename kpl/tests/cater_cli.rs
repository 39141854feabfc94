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
    // Which perception and which options were used.
    assert!(table.contains("perception: ") && table.contains("options: "), "{table}");
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

/// A pickle of `n` nested lists as Python's pickle writes it with protocol 2 (`]` n times, `a`
/// n - 1 times): 4 KB for 2,000 levels.
fn nested_lists_pickle(n: usize) -> Vec<u8> {
    let mut p = vec![0x80, 2];
    p.extend(std::iter::repeat_n(b']', n));
    p.extend(std::iter::repeat_n(b'a', n - 1));
    p.push(b'.');
    p
}

#[test]
fn hostile_files_get_a_clear_error_or_a_skip_never_an_abort() {
    let dir = scratch("hostile");
    let data = dir.join("data");
    let output = kpl(&[
        "cater",
        "generate",
        "--videos",
        "3",
        "--seed",
        "4",
        "--layout",
        "la-cater",
        "--out",
        data.to_str().unwrap(),
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    // 2,000 nested lists in place of one video's perfect perception: that video is skipped with the
    // reason, the others are scored.
    let pickle = data.join("perfect_perception").join("CATER_new_000001.pkl");
    std::fs::write(&pickle, nested_lists_pickle(2000)).unwrap();
    let run = |extra: &[&str]| {
        let mut a = vec!["cater", "eval", "--data", data.to_str().unwrap(), "--model", "aapa"];
        a.extend_from_slice(extra);
        kpl(&a)
    };
    let output = run(&[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("skipped CATER_new_000001:") && stderr.contains("nested"), "{stderr}");
    assert!(stderr.contains("evaluated 2 videos (1 skipped)"), "{stderr}");
    // Files that never end: a size cap, exit 1 (bad data), within a few hundred megabytes read.
    if Path::new("/dev/zero").exists() {
        for option in ["--videos", "--params"] {
            let output = run(&[option, "/dev/zero"]);
            let stderr = String::from_utf8_lossy(&output.stderr);
            assert_eq!(output.status.code(), Some(1), "{option}: {stderr}");
            assert!(stderr.contains("/dev/zero") && stderr.contains("larger than"), "{option}: {stderr}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn la_caters_perfect_perception_pickles_are_found_and_never_averaged() {
    // LA-CATER's layout as it comes: `--data` alone finds perfect_perception/, and its exact
    // boxes are scored exactly on the visible frames (no averaging of boxes that are exact).
    let dir = scratch("la-cater");
    let data = dir.join("data");
    let output = kpl(&[
        "cater",
        "generate",
        "--videos",
        "4",
        "--seed",
        "6",
        "--layout",
        "la-cater",
        "--out",
        data.to_str().unwrap(),
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let json = dir.join("perfect.json");
    let output = kpl(&[
        "cater",
        "eval",
        "--data",
        data.to_str().unwrap(),
        "--model",
        "aapa",
        "--json",
        json.to_str().unwrap(),
    ]);
    let table = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(
        table.contains("perfect_perception")
            && table.contains("average_still off for exact boxes (4 videos)"),
        "{table}"
    );
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["iou"]["visible"]["mean"], 100.0, "{}", report["iou"]);
    assert_eq!(report["noisy_videos"], 0);
    // Given as --pickles without --perception, the boxes are measured: exact, so not averaged;
    // the detector's pickles are not exact, so averaged.
    for (sub, noisy) in [("perfect_perception", 0), ("od_perception", 4)] {
        let pickles = data.join(sub);
        let output = kpl(&[
            "cater",
            "eval",
            "--data",
            data.to_str().unwrap(),
            "--model",
            "aapa",
            "--pickles",
            pickles.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ]);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        assert_eq!(report["noisy_videos"], noisy, "{sub}");
        assert!(report["perception_source"].as_str().unwrap().contains("measured"), "{sub}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
