//! `kpl situations` end to end on recorded SUMO traffic (the `overtake` scenario of
//! scripts/sumo-scenarios.py): `specs/traffic/sumo_situations.kpl` runs under the noisy tracker,
//! its situations are scored against the true ones computed from SUMO's own trajectories, and the
//! target holds (precision and recall >= 0.9 for overtakes and speeding); every situation names
//! cars and a time interval; bad input gets clear errors and exit codes.
#![allow(clippy::unwrap_used, clippy::expect_used, reason = "tests")]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use serde_json::Value;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn kpl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kpl")).args(args).current_dir(workspace()).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

const SCENARIO: &str = "specs/traffic/sumo/overtake";

/// The spec run once over the whole recording; its output folder.
fn situations_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("kpl-situations-cli-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let out = kpl(&[
            "run",
            "--quiet",
            "specs/traffic/sumo_situations.kpl",
            "--clock",
            "sim",
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        dir.join("sumo_situations")
    })
}

fn score(extra: &[&str]) -> Output {
    let run = situations_run().to_str().unwrap().to_string();
    let traffic = format!("{SCENARIO}/fcd.xml.gz");
    let network = format!("{SCENARIO}/net.xml.gz");
    let vtypes = format!("{SCENARIO}/vtypes.xml");
    let mut args =
        vec!["situations", &run, "--traffic", &traffic, "--network", &network, "--vtypes", &vtypes];
    args.extend_from_slice(extra);
    kpl(&args)
}

#[test]
fn overtakes_and_speeding_are_recognised_with_precision_and_recall_over_0_9() {
    let out = score(&["--format", "json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();
    for kind in ["overtake", "speeding"] {
        let s = json["scores"].as_array().unwrap().iter().find(|s| s["kind"] == kind).unwrap();
        let (p, r) = (s["precision"].as_f64().unwrap(), s["recall"].as_f64().unwrap());
        assert!(p >= 0.9 && r >= 0.9, "{kind}: precision {p}, recall {r}: {s}");
        assert!(s["truth"].as_u64().unwrap() >= 10, "{kind}: too few true situations to say much: {s}");
    }
    // The broken-down car is found, and nothing on the road drives the wrong way.
    let stopped = json["scores"].as_array().unwrap().iter().find(|s| s["kind"] == "stopped").unwrap();
    assert_eq!(stopped["found"], 1, "{stopped}");
    assert!(json["scores"].as_array().unwrap().iter().all(|s| s["kind"] != "wrong_way"));
    for r in json["recognised"].as_array().unwrap() {
        assert!(r["start"].as_i64().unwrap() <= r["end"].as_i64().unwrap(), "{r}");
        for o in r["objects"].as_array().unwrap() {
            assert!(o.as_str().unwrap().starts_with("co"), "{r}");
        }
    }
    // The table says the same.
    let table = score(&[]);
    assert!(table.status.success());
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(text.lines().any(|l| l.starts_with("overtake")), "{text}");
}

#[test]
fn bad_input_gets_clear_errors() {
    let run = situations_run().to_str().unwrap().to_string();
    // Floating car data without positions along lanes (the highway scenario's) cannot give truth
    // (its network and vehicle types are found beside it).
    let out = kpl(&["situations", &run, "--traffic", "specs/traffic/sumo/highway/fcd.xml.gz"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("lane,pos"), "{}", stderr(&out));
    // A missing file is an I/O error.
    let out =
        kpl(&["situations", &run, "--traffic", "nope.xml", "--network", &format!("{SCENARIO}/net.xml.gz")]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("nope.xml"), "{}", stderr(&out));
    // A car stream the recording does not have.
    let out = score(&["--stream", "no_such_stream"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("no_such_stream"), "{}", stderr(&out));
}
