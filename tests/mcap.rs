//! MCAP recordings end to end (docs/streams.md, "MCAP files"), on the traffic scenario of
//! `specs/traffic/bridge.kpl` recorded both as JSON lines and as MCAP in one run:
//! - the `mcap` Python package reads the MCAP file (stream names, counts, times, values; every
//!   message checked against its channel's JSON schema with `jsonschema`) and finds the JSON
//!   lines' samples (`tests/mcap_reader.py`; needs the Python of `scripts/test`, `KPL_PYTHON`);
//! - `kpl convert` turns the MCAP file into the same JSON lines, and JSON lines -> MCAP -> JSON
//!   lines gives back the same bytes;
//! - replaying the percepts from the MCAP file anchors the same cars as replaying them from the
//!   JSON lines, and as the live run.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // tests: they unwrap, and say what they skip

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{kpl, lines, python, root};
use serde_json::Value;

fn ok(args: &[&str]) -> String {
    let out = kpl(args);
    assert!(out.status.success(), "kpl {args:?}:\n{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The samples of each stream of a JSON-lines recording, in order.
fn by_stream(path: &Path) -> BTreeMap<String, Vec<Value>> {
    let mut map: BTreeMap<String, Vec<Value>> = BTreeMap::new();
    for line in lines(path) {
        map.entry(line["stream"].as_str().unwrap().to_string()).or_default().push(line);
    }
    map
}

const RECORDED: [&str; 4] = ["percepts", "tracker.truth", "onroad_car", "vision_world.changes"];

/// The bridge scenario, recording what the test reads in both formats.
fn record(dir: &Path) -> PathBuf {
    let mut spec = std::fs::read_to_string(root().join("specs/traffic/bridge.kpl")).unwrap();
    let inputs = RECORDED.join(", ");
    spec.push_str(&format!("sink rec_jsonl = file.jsonl({inputs}, path: \"rec.jsonl\")\n"));
    spec.push_str(&format!("sink rec_mcap = file.mcap({inputs}, path: \"rec.mcap\")\n"));
    let spec_path = dir.join("bridge.kpl");
    std::fs::write(&spec_path, spec).unwrap();
    let out = dir.join("out");
    ok(&["run", "--quiet", spec_path.to_str().unwrap(), "--for", "20s", "--out", out.to_str().unwrap()]);
    out
}

/// The bridge scenario's anchoring (`specs/traffic/bridge.kpl` itself: its links, predictions and
/// forgetting), its percepts replayed by `source` instead of simulated, the cars recorded.
fn replay(dir: &Path, name: &str, source: &str) -> Vec<Value> {
    let bridge = std::fs::read_to_string(root().join("specs/traffic/bridge.kpl")).unwrap();
    let (head, rest) = bridge.split_once("source tracker ").expect("bridge.kpl simulates `tracker`");
    let (_, links) = rest
        .split_once("stream percepts = tracker with strict order\n")
        .expect("bridge.kpl orders `percepts`");
    let links = links.split("\nsink ").next().unwrap();
    let spec = format!(
        "{head}source percepts : list<VisionPercept> = {source}\n{links}\nsink cars = file.jsonl(onroad_car, path: \"cars.jsonl\")\n"
    );
    let spec_path = dir.join(format!("{name}.kpl"));
    std::fs::write(&spec_path, spec).unwrap();
    let out = dir.join(name);
    ok(&["run", "--quiet", spec_path.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(
        summary["summary"]["processes"]
            .as_array()
            .map_or(0, |p| p.iter().filter(|p| p["malformed"] != 0).count()),
        0,
        "{summary}"
    );
    lines(&out.join("cars.jsonl"))
}

#[test]
fn a_traffic_run_recorded_to_mcap_reads_converts_and_replays_like_its_json_lines() {
    let dir = common::fresh_dir("mcap", "traffic");
    let out = record(&dir);
    let (jsonl, mcap) = (out.join("rec.jsonl"), out.join("rec.mcap"));
    let streams = by_stream(&jsonl);
    assert_eq!(streams.keys().map(String::as_str).collect::<Vec<_>>(), {
        let mut names = RECORDED.to_vec();
        names.sort_unstable();
        names
    });
    assert!(streams["percepts"].len() >= 190, "20 s of frames at 10 Hz");
    assert!(!streams["onroad_car"].is_empty(), "cars were anchored");

    // The mcap Python package reads the same samples.
    if let Some(python) = python("mcap") {
        let result = Command::new(&python)
            .arg(root().join("tests/mcap_reader.py"))
            .args([&mcap, &jsonl])
            .output()
            .unwrap();
        assert!(result.status.success(), "python:\n{}", String::from_utf8_lossy(&result.stderr));
        let report: Value = serde_json::from_slice(&result.stdout).unwrap();
        for (name, samples) in &streams {
            let stream = &report["streams"][name];
            assert_eq!(stream["count"], samples.len(), "{name}: {report}");
            assert_eq!(stream["valid"][0], samples[0]["valid"], "{name}");
        }
        assert_eq!(report["streams"]["percepts"]["schema"], "list<VisionPercept>");
        assert_eq!(report["streams"]["percepts"]["type"], "list<VisionPercept>");
        assert!(report["library"].as_str().unwrap().starts_with("kpl "), "{report}");
    }

    // MCAP -> JSON lines: the same lines, stream by stream; JSON lines -> MCAP -> JSON lines: the
    // same bytes.
    let back = dir.join("back.jsonl");
    let said = ok(&["convert", mcap.to_str().unwrap(), back.to_str().unwrap()]);
    let total: usize = streams.values().map(Vec::len).sum();
    assert!(said.contains(&format!("{total} sample(s)")), "{said}");
    assert_eq!(by_stream(&back), streams);
    let again_mcap = dir.join("again.mcap");
    let again = dir.join("again.jsonl");
    let spec = dir.join("bridge.kpl");
    ok(&["convert", jsonl.to_str().unwrap(), again_mcap.to_str().unwrap(), "--spec", spec.to_str().unwrap()]);
    ok(&["convert", again_mcap.to_str().unwrap(), again.to_str().unwrap()]);
    assert_eq!(
        std::fs::read(&again).unwrap(),
        std::fs::read(&jsonl).unwrap(),
        "JSON lines -> MCAP -> JSON lines"
    );

    // Replays from either file anchor the same cars, and the same as the live run.
    let rec = |file: &str, kind: &str| format!("file.{kind}(path: \"out/{file}\", stream: \"percepts\")");
    let from_jsonl = replay(&dir, "from-jsonl", &rec("rec.jsonl", "jsonl"));
    let from_mcap = replay(&dir, "from-mcap", &rec("rec.mcap", "mcap"));
    assert!(!from_mcap.is_empty());
    assert_eq!(from_mcap, from_jsonl, "replayed from MCAP and from JSON lines");
    let live: Vec<Value> = streams["onroad_car"].clone();
    assert_eq!(from_mcap, live, "replayed and live");
}

/// A run killed with -9 while it records (issue 21): the MCAP file it leaves reads up to its last
/// whole chunk, with `kpl convert` and with the `mcap` Python package alike, and holds what the
/// JSON lines beside it hold, less at most the last chunk's second.
#[test]
fn a_run_killed_while_recording_mcap_leaves_a_file_that_reads_up_to_its_last_chunk() {
    let dir = common::fresh_dir("mcap", "killed");
    let mut spec = std::fs::read_to_string(root().join("specs/traffic/bridge.kpl")).unwrap();
    spec.push_str("sink rec_jsonl = file.jsonl(percepts, onroad_car, path: \"rec.jsonl\")\n");
    spec.push_str("sink rec_mcap = file.mcap(percepts, onroad_car, path: \"rec.mcap\")\n");
    let spec_path = dir.join("bridge.kpl");
    std::fs::write(&spec_path, spec).unwrap();
    let out = dir.join("out");
    let mut run = common::kpl_command(&[
        "run",
        "--quiet",
        spec_path.to_str().unwrap(),
        "--clock",
        "wall",
        "--for",
        "60s",
        "--out",
        out.to_str().unwrap(),
    ])
    .spawn()
    .unwrap();
    // Some seconds of recording (the JSON lines flush as they go), then kill -9.
    let jsonl = out.join("rec.jsonl");
    for _ in 0..200 {
        std::thread::sleep(std::time::Duration::from_millis(100));
        if std::fs::metadata(&jsonl).map_or(0, |m| m.len()) > 60_000 {
            break;
        }
    }
    std::thread::sleep(std::time::Duration::from_secs(2));
    run.kill().unwrap(); // SIGKILL
    assert!(!run.wait().unwrap().success());
    let mcap = out.join("rec.mcap");

    // kpl convert reads what the file holds, and says it was cut short.
    let back = dir.join("back.jsonl");
    let converted = kpl(&["convert", mcap.to_str().unwrap(), back.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&converted.stderr);
    assert_eq!(converted.status.code(), Some(1), "{said}");
    assert!(said.contains("the file is cut short"), "{said}");
    let recovered = by_stream(&back);
    let recorded = by_stream(&jsonl);
    for (stream, samples) in &recorded {
        let got = recovered.get(stream).map_or(&[][..], Vec::as_slice);
        let n = got.len().min(samples.len());
        assert_eq!(&got[..n], &samples[..n], "{stream}: the same samples, in order");
        let last = |s: &[Value]| s.last().map_or(0, |l| l["available"].as_i64().unwrap());
        assert!(
            last(got) >= last(samples) - 2_000_000,
            "{stream}: {} of {} recorded samples, the last at {} and {}",
            got.len(),
            samples.len(),
            last(got),
            last(samples)
        );
    }
    assert!(recovered["percepts"].len() >= 20, "{} percepts", recovered["percepts"].len());

    // The mcap Python package reads the same, linearly, until the file ends.
    if let Some(python) = python("mcap") {
        let result = Command::new(&python)
            .arg(root().join("tests/mcap_reader.py"))
            .arg("--cut")
            .arg(&mcap)
            .output()
            .unwrap();
        assert!(result.status.success(), "python:\n{}", String::from_utf8_lossy(&result.stderr));
        let text = String::from_utf8_lossy(&result.stdout);
        let mut read: Vec<Value> = text.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        let end = read.pop().unwrap();
        assert!(end["end"].as_str().unwrap().starts_with("EndOfFile"), "{end}");
        let mut by: BTreeMap<String, Vec<Value>> = BTreeMap::new();
        for mut message in read {
            let stream = message["stream"].as_str().unwrap().to_string();
            message.as_object_mut().unwrap().remove("stream");
            by.entry(stream).or_default().push(message);
        }
        let strip = |samples: &Vec<Value>| {
            samples
                .iter()
                .map(|s| {
                    let mut s = s.clone();
                    s.as_object_mut().unwrap().remove("stream");
                    s
                })
                .collect::<Vec<_>>()
        };
        // The same messages; kpl also decompresses what an unfinished last chunk holds (when the
        // kill came in the middle of writing one), which the package leaves.
        let unfinished = said.contains("not finished");
        for (stream, samples) in &recovered {
            let python_read = by.get(stream).cloned().unwrap_or_default();
            let ours = strip(samples);
            assert_eq!(&ours[..python_read.len().min(ours.len())], &python_read[..], "{stream}");
            if !unfinished {
                assert_eq!(python_read.len(), ours.len(), "{stream}");
            }
        }
    }
}
