//! `kpl cater generate` + `kpl cater eval --json` end to end: the JSON's shape, AAPA ahead of the
//! heuristic, and the exit codes for bad data (1) and usage / I/O errors (2).
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
    assert_eq!(std::fs::read_dir(data.join("bb")).unwrap().count(), 8);
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
fn bad_data_exits_1_and_missing_data_exits_2() {
    let dir = scratch("codes");
    let data = dir.join("data");
    assert!(
        kpl(&["cater", "generate", "--videos", "2", "--seed", "1", "--out", data.to_str().unwrap()])
            .status
            .success()
    );
    let missing = dir.join("nothing");
    let args = |d: &Path| {
        vec![
            "cater".to_owned(),
            "eval".into(),
            "--data".into(),
            d.to_str().unwrap().into(),
            "--model".into(),
            "aapa".into(),
            "--perception".into(),
            "perfect".into(),
        ]
    };
    let run = |d: &Path| {
        let a = args(d);
        kpl(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    assert_eq!(run(&missing).status.code(), Some(2));
    let scene = std::fs::read_dir(data.join("scenes")).unwrap().next().unwrap().unwrap().path();
    std::fs::write(&scene, "{ not json").unwrap();
    let output = run(&data);
    assert_eq!(output.status.code(), Some(1), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(String::from_utf8_lossy(&output.stderr).contains(scene.file_name().unwrap().to_str().unwrap()));
    assert_eq!(kpl(&["cater", "eval", "--model", "nope"]).status.code(), Some(2));
    let help = kpl(&["cater", "eval", "--help"]);
    assert!(String::from_utf8_lossy(&help.stdout).contains("kpl cater eval --data"));
    std::fs::remove_dir_all(&dir).unwrap();
}
