//! Seeing a run (docs/view.md), checked with Foxglove's and the browser's own tools:
//! - an MCAP recording of `specs/traffic/sumo_situations.kpl` holds Foxglove's views of its
//!   streams, which Foxglove's `foxglove-schemas-protobuf` package parses exactly and the `mcap`
//!   package reads (`tests/foxglove_mcap.py`);
//! - a Foxglove WebSocket client (`@foxglove/ws-protocol`, `tests/node/foxglove_client.mjs`)
//!   connected to `kpl run --foxglove` receives every car of the run with the symbols and times of
//!   its JSON-lines recording (`tests/foxglove_live.py` compares them);
//! - headless Chromium (`playwright-core`, `tests/node/view_page.mjs`) loads the page of a running
//!   spec: the cars it draws are the stream's, a recognised overtake is listed and a click jumps
//!   to it; screenshots are kept;
//! - `kpl view` serves a recording.
//!
//! They need the Python of scripts/test (`KPL_PYTHON`), Node with `tests/node`'s packages and
//! Chromium (scripts/test installs them); without them they are skipped, or fail under
//! `KPL_REQUIRE_ORACLES=1`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // tests: they unwrap, and say what they skip

mod common;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::{fresh_dir, kpl, kpl_command, lines, python, root};
use serde_json::Value;

/// Node with tests/node's packages (`npm ci` there; scripts/test does it), or `None` when the
/// test is to be skipped.
fn node() -> Option<String> {
    let installed = root().join("tests/node/node_modules/@foxglove/ws-protocol").exists();
    let works = Command::new("node").arg("--version").output().is_ok_and(|o| o.status.success());
    if installed && works {
        return Some("node".into());
    }
    if std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1") {
        panic!(
            "KPL_REQUIRE_ORACLES=1 but node or tests/node/node_modules is missing (scripts/test installs them)"
        );
    }
    eprintln!("skipped: needs node and `npm ci` in tests/node (scripts/test does it)");
    None
}

fn chromium() -> Option<String> {
    let path = std::env::var("KPL_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into());
    if Path::new(&path).exists() {
        return Some(path);
    }
    if std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1") {
        panic!("KPL_REQUIRE_ORACLES=1 but {path} is missing (scripts/test installs Debian's chromium)");
    }
    eprintln!("skipped: needs Chromium at {path} (scripts/test installs it)");
    None
}

fn run_python(python: &str, script: &str, args: &[&PathBuf]) -> Value {
    let out = Command::new(python).arg(root().join(script)).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{script} failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The spec of the situations, its paths made absolute so that it runs from `dir`, with `extra`
/// appended.
fn situations_spec(dir: &Path, extra: &str) -> PathBuf {
    let spec = std::fs::read_to_string(root().join("specs/traffic/sumo_situations.kpl")).unwrap();
    let traffic = root().join("specs/traffic");
    let spec = spec.replace("\"sumo/", &format!("\"{}/sumo/", traffic.display()));
    let path = dir.join("situations.kpl");
    std::fs::write(&path, format!("{spec}\n{extra}\n")).unwrap();
    path
}

/// The cars of a JSON-lines recording: symbols by valid time, and the available time of each.
fn recorded_cars(path: &Path) -> BTreeMap<i64, (i64, Vec<String>)> {
    lines(path)
        .into_iter()
        .filter(|l| l["stream"] == "onroad_car")
        .map(|l| {
            let symbols = l["value"]
                .as_array()
                .unwrap()
                .iter()
                .map(|o| o["id"].as_str().unwrap().to_string())
                .collect();
            (l["valid"].as_i64().unwrap(), (l["available"].as_i64().unwrap(), symbols))
        })
        .collect()
}

#[test]
fn an_mcap_recording_holds_foxglove_views_that_foxglove_schemas_parse() {
    let Some(python) = python("mcap and foxglove-schemas-protobuf") else { return };
    let dir = fresh_dir("view", "mcap");
    let spec = situations_spec(
        &dir,
        "sink rec = file.mcap(tracker, vision_world, world_onroad, onroad_car, overtake, speeding, path: \"rec.mcap\")",
    );
    let out = dir.join("out");
    let run =
        kpl(&["run", "--quiet", spec.to_str().unwrap(), "--for", "40s", "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let report = run_python(&python, "tests/foxglove_mcap.py", &[&out.join("rec.mcap")]);
    let channels = &report["channels"];
    for (topic, schema) in [
        ("/kpl/onroad_car", "foxglove.SceneUpdate"),
        ("/kpl/world_onroad", "foxglove.SceneUpdate"),
        ("/kpl/vision_world", "foxglove.SceneUpdate"),
        ("/kpl/tracker", "foxglove.PointCloud"),
        ("/kpl/overtake", "foxglove.Log"),
        ("/kpl/roads", "foxglove.SceneUpdate"),
        ("/kpl/occluders", "foxglove.SceneUpdate"),
        ("/tf", "foxglove.FrameTransforms"),
    ] {
        assert_eq!(channels[topic]["schema"], schema, "{topic}: {report}");
    }
    // Every car sample has its scene update (one per valid time).
    let cars = lines(&dir.join("out/sumo_situations/tracks.jsonl"))
        .iter()
        .filter(|l| l["stream"] == "onroad_car")
        .count();
    assert_eq!(channels["/kpl/onroad_car"]["messages"], cars as u64, "{report}");
    assert!(report["compared"]["objects"].as_u64().unwrap() > 1000, "{report}");
    assert!(report["compared"]["points"].as_u64().unwrap() > 1000, "{report}");
    assert!(report["compared"]["logs"].as_u64().unwrap() >= 1, "{report}");
    // The views do not come back as samples.
    let back = dir.join("back.jsonl");
    let convert = kpl(&["convert", out.join("rec.mcap").to_str().unwrap(), back.to_str().unwrap()]);
    assert!(convert.status.success(), "{}", String::from_utf8_lossy(&convert.stderr));
    assert!(lines(&back).iter().all(|l| !l["stream"].as_str().unwrap().starts_with('/')));
}

/// Starts `kpl run` with `args` and reads its stderr until a line says where `what` is served.
fn start_run(args: &[&str], what: &str) -> (Child, String, std::thread::JoinHandle<String>) {
    let mut child = kpl_command(args).stderr(Stdio::piped()).stdout(Stdio::null()).spawn().unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut seen = String::new();
    let mut line = String::new();
    let url = loop {
        line.clear();
        if stderr.read_line(&mut line).unwrap() == 0 {
            panic!("kpl run ended before serving {what}:\n{seen}");
        }
        seen.push_str(&line);
        if let Some(at) = line.find(what) {
            break line[at + what.len()..].trim().to_string();
        }
    };
    // Read the rest, so the run never blocks on a full pipe.
    let rest = std::thread::spawn(move || {
        let mut rest = String::new();
        let _ = stderr.read_to_string(&mut rest);
        seen + &rest
    });
    (child, url, rest)
}

#[test]
fn a_foxglove_client_receives_every_car_of_a_run_with_its_recorded_symbols_and_times() {
    let Some(python) = python("foxglove-schemas-protobuf") else { return };
    let Some(node) = node() else { return };
    let dir = fresh_dir("view", "live");
    let spec = situations_spec(&dir, "");
    let out = dir.join("out");
    let (mut run, url, stderr) = start_run(
        &[
            "run",
            "--quiet",
            spec.to_str().unwrap(),
            "--for",
            "30s",
            "--out",
            out.to_str().unwrap(),
            "--foxglove",
            "127.0.0.1:0",
            "--foxglove-wait",
            "60s",
        ],
        "Foxglove WebSocket server at ",
    );
    let received = dir.join("received.jsonl");
    let client = Command::new(node)
        .arg(root().join("tests/node/foxglove_client.mjs"))
        .args([url.as_str(), received.to_str().unwrap(), "120"])
        .output()
        .unwrap();
    let status = run.wait().unwrap();
    let stderr = stderr.join().unwrap();
    assert!(status.success(), "{stderr}");
    assert!(client.status.success(), "{}", String::from_utf8_lossy(&client.stderr));
    let report = run_python(
        &python,
        "tests/foxglove_live.py",
        &[&received, &out.join("sumo_situations/tracks.jsonl")],
    );
    assert_eq!(report["missing"], 0, "{report}");
    assert_eq!(report["extra"], 0, "{report}");
    assert!(report["cars"].as_u64().unwrap() > 1000, "{report}");
    assert!(report["time_capability"].as_bool().unwrap(), "{report}");
}

/// A GET of `path` from a page server: its head and body.
fn fetch(url: &str, path: &str) -> (String, String) {
    let address = url.trim_start_matches("http://").trim_end_matches('/');
    let mut stream = std::net::TcpStream::connect(address).unwrap();
    stream.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(stream, "GET {path} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\r\n").unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).unwrap();
    let (head, body) = response.split_once("\r\n\r\n").unwrap();
    assert!(head.starts_with("HTTP/1.1 200"), "{path}: {head}");
    (head.to_string(), body.to_string())
}

/// A GET of `path` from a page server, its body as JSON.
fn get(url: &str, path: &str) -> Value {
    let (_, body) = fetch(url, path);
    serde_json::from_str(&body).unwrap_or_else(|e| panic!("{path}: {e}: {body}"))
}

#[test]
fn the_page_of_a_running_spec_draws_its_cars_and_lists_an_overtake_in_headless_chromium() {
    let Some(node) = node() else { return };
    let Some(chromium) = chromium() else { return };
    let dir = fresh_dir("view", "page");
    let spec = situations_spec(&dir, "");
    let out = dir.join("out");
    // Real time, so the page watches the run go: the first overtake is recognised at 24.7 s.
    let (mut run, url, stderr) = start_run(
        &[
            "run",
            "--quiet",
            spec.to_str().unwrap(),
            "--clock",
            "wall",
            "--for",
            "40s",
            "--out",
            out.to_str().unwrap(),
            "--view",
            "127.0.0.1:0",
        ],
        "the page at ",
    );
    let state = get(&url, "/api/state");
    assert_eq!((state["live"].as_bool(), state["running"].as_bool()), (Some(true), Some(true)), "{state}");
    let scene = get(&url, "/api/scene");
    assert!(scene["lanes"].as_array().unwrap().len() >= 2, "the overtake road's lanes");
    assert_eq!(scene["occluders"].as_array().unwrap().len(), 2, "its two bridges");
    let page = Command::new(node)
        .env("KPL_CHROMIUM", &chromium)
        .arg(root().join("tests/node/view_page.mjs"))
        .args([url.as_str(), dir.to_str().unwrap(), "38", "overtake"])
        .output()
        .unwrap();
    assert!(page.status.success(), "{}", String::from_utf8_lossy(&page.stderr));
    let report: Value = serde_json::from_slice(&page.stdout).unwrap();
    let status = run.wait().unwrap();
    let stderr = stderr.join().unwrap();
    assert!(status.success(), "{stderr}");
    assert_eq!(report["errors"], serde_json::json!([]), "{report}");

    // The cars drawn are the cars of the stream's sample the page says it drew.
    let cars = recorded_cars(&out.join("sumo_situations/tracks.jsonl"));
    let samples = report["samples"].as_array().unwrap();
    assert!(samples.len() >= 5, "{report}");
    let mut compared = 0;
    for sample in samples {
        let (Some(n), Some(valid)) =
            (sample["levels"]["onroad_car"].as_u64(), sample["valid"]["onroad_car"].as_i64())
        else {
            continue;
        };
        let (_, symbols) =
            cars.get(&valid).unwrap_or_else(|| panic!("no recorded sample at {valid}: {sample}"));
        assert_eq!(n as usize, symbols.len(), "at {valid}");
        compared += 1;
    }
    assert!(compared >= 5 && cars.values().any(|(_, s)| !s.is_empty()), "{report}");

    // An overtake was listed; a click showed its start with its cars marked.
    let situation = &report["situation"];
    assert!(situation["text"].as_str().unwrap().starts_with("overtake"), "{report}");
    let jumped = &report["jumped"];
    assert_eq!(jumped["t"], situation["start"], "{report}");
    assert_eq!(jumped["marked"].as_array().unwrap().len(), 2, "both cars of the overtake drawn: {report}");
    for shot in report["screenshots"].as_array().unwrap() {
        let bytes = std::fs::metadata(shot.as_str().unwrap()).unwrap().len();
        assert!(bytes > 10_000, "{shot}: {bytes} bytes");
    }
    eprintln!("screenshots: {}", report["screenshots"]);
}

#[test]
fn kpl_view_serves_a_recording_with_its_scene() {
    let dir = fresh_dir("view", "recording");
    let out = dir.join("out");
    let run = kpl(&["run", "--quiet", "specs/ok/tracker.kpl", "--for", "5s", "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let (mut view, url, stderr) = {
        let mut child = kpl_command(&[
            "view",
            out.to_str().unwrap(),
            "--spec",
            "specs/ok/tracker.kpl",
            "--http",
            "127.0.0.1:0",
            "--for",
            "20s",
        ])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
        let mut reader = BufReader::new(child.stderr.take().unwrap());
        let mut seen = String::new();
        let url = loop {
            let mut line = String::new();
            assert!(reader.read_line(&mut line).unwrap() > 0, "{seen}");
            seen.push_str(&line);
            if let Some(at) = line.find("the page at ") {
                break line[at + 12..].trim().to_string();
            }
        };
        (child, url, seen)
    };
    let state = get(&url, "/api/state");
    assert_eq!(state["live"], false, "{state}");
    let (start, end) = (state["start"].as_i64().unwrap(), state["end"].as_i64().unwrap());
    assert!(end > start, "{state}");
    // The recording's percepts and true positions, frame by frame (the file read without types:
    // positions as lists).
    let recorded = lines(&out.join("percepts.jsonl"));
    let mut compared = 0;
    for line in
        recorded.iter().filter(|l| l["stream"] == "percepts" || l["stream"] == "tracker.truth").step_by(5)
    {
        let t = line["valid"].as_i64().unwrap();
        let frame = get(&url, &format!("/api/frame?t={t}"));
        assert_eq!(frame["t"], t);
        let points =
            frame["points"].as_array().unwrap().iter().find(|p| p["stream"] == line["stream"]).unwrap();
        assert_eq!(
            points["points"].as_array().unwrap().len(),
            line["value"].as_array().unwrap().len(),
            "at {t}"
        );
        compared += line["value"].as_array().unwrap().len();
    }
    assert!(compared > 10, "{compared} percepts compared");
    let (head, page) = fetch(&url, "/");
    assert!(head.to_lowercase().contains("content-type: text/html"), "{head}");
    assert!(page.contains("<canvas id=\"map\""), "the page ships in the binary");
    view.kill().unwrap();
    let _ = view.wait();
    assert!(stderr.contains("sample(s) from"), "{stderr}");
}
