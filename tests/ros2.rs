//! ROS 2 in and out, end to end, with the built `kpl` binary and a ROS 2 node that is not kpl:
//! `tests/ros2_node.py` publishes, exactly as an rmw_zenoh node (zenoh-ros2-sdk's keys, tokens
//! and attachment, rosidl's type hash, rclpy's CDR), the vehicles of a SUMO recording of
//! specs/traffic/sumo/grid as a MarkerArray on /tracker/markers; `kpl run specs/ros2/markers.kpl
//! --clock wall --ros2-router ENDPOINT --out DIR` (the shipped spec's contract) anchors them as
//! cars, records them and publishes them back on /kpl/cars (MarkerArray) and /kpl/detections
//! (vision_msgs); the node decodes them (rclpy, rosbags) and every car of kpl's own recording is
//! among them, `ns` its symbol and `id` a number that stays with it. The node's three bad
//! messages (no attachment, a wrong type hash, cut CDR) are counted, and kpl ends on its own
//! once the publisher has gone. Recordings: a rosbag2 bag of `rosbags` converts to JSON lines
//! field for field, and replays through markers.kpl's mapping (specs/ros2/replay.kpl) into cars,
//! whose bag kpl writes and `rosbags` and `mcap-ros2-support` read. Skipped without `KPL_PYTHON`
//! unless `KPL_REQUIRE_ORACLES=1`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr, clippy::disallowed_methods)] // tests; waits are bounded by the wall clock

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use common::{free_ports, lines, python, root};
use serde_json::Value;

const HANG: Duration = Duration::from_secs(180);

fn wait(child: &mut Child, name: &str) -> (i32, String) {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            if let Some(mut e) = child.stderr.take() {
                let _ = e.read_to_string(&mut err);
            }
            return (status.code().unwrap_or(-1), err);
        }
        if start.elapsed() > HANG {
            child.kill().unwrap();
            panic!("{name} did not finish within {HANG:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn markers_in_cars_out_with_a_ros2_node() {
    let Some(python) = python("rclpy, rosbags, zenoh-ros2-sdk") else { return };
    let dir = common::fresh_dir("ros2", "markers");
    let port = free_ports(1);
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let result_path = dir.join("node.json");
    let mut node = std::process::Command::new(&python)
        .arg(root().join("tests/ros2_node.py"))
        .args(["--listen", &endpoint, "--fcd"])
        .arg(root().join("specs/traffic/sumo/grid/fcd.xml.gz"))
        .args(["--start", "100", "--seconds", "15", "--out"])
        .arg(&result_path)
        .current_dir(root())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let out = dir.join("out");
    let mut kpl = common::kpl_command(&[
        "run",
        "specs/ros2/markers.kpl",
        "--clock",
        "wall",
        "--ros2-router",
        &endpoint,
        "--out",
    ])
    .arg(&out)
    .args(["--for", "120s", "--quiet"])
    .stdin(Stdio::null())
    .stdout(Stdio::null())
    .stderr(Stdio::piped())
    .spawn()
    .unwrap();
    let (kpl_code, kpl_err) = wait(&mut kpl, "kpl run");
    let (node_code, node_err) = wait(&mut node, "the ROS 2 node");
    assert_eq!(node_code, 0, "the ROS 2 node failed:\n{node_err}");
    assert_eq!(kpl_code, 0, "kpl run failed:\n{kpl_err}");

    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(
        summary["ending"], "sources_ended",
        "kpl ends when the publisher has gone, not at --for: {summary:#}"
    );
    let result: Value = serde_json::from_slice(&std::fs::read(&result_path).unwrap()).unwrap();

    // kpl's recording: every car symbol and the percepts it read.
    let mut recorded_cars = BTreeSet::new();
    let mut percepts = 0;
    for line in lines(&out.join("tracks.jsonl")) {
        let objects = line["value"].as_array().cloned().unwrap_or_default();
        match line["stream"].as_str() {
            Some("onroad_car") => {
                recorded_cars.extend(objects.iter().map(|o| o["id"].as_str().unwrap().to_string()))
            }
            Some("markers") => percepts += objects.len(),
            _ => {}
        }
    }
    assert_eq!(
        percepts as u64,
        result["published_markers"].as_u64().unwrap(),
        "every marker became a percept"
    );
    assert!(recorded_cars.len() >= 10, "only {} cars anchored", recorded_cars.len());

    // What the node received: every recorded car, with a number that stays with its symbol.
    let mut numbers: BTreeMap<String, BTreeSet<i64>> = BTreeMap::new();
    for car in result["cars"].as_array().unwrap() {
        numbers
            .entry(car["ns"].as_str().unwrap().to_string())
            .or_default()
            .insert(car["id"].as_i64().unwrap());
        assert_eq!(car["frame"], "map");
        assert_eq!(car["length"], 5.0);
    }
    let received: BTreeSet<String> = numbers.keys().cloned().collect();
    assert_eq!(received, recorded_cars, "the cars on /kpl/cars are those of kpl's recording");
    for (symbol, ids) in &numbers {
        assert_eq!(ids.len(), 1, "{symbol} changed its number: {ids:?}");
    }
    let detected: BTreeSet<String> = result["detections"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["id"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(detected, recorded_cars, "the cars on /kpl/detections are those of kpl's recording");
    assert_eq!(result["bad_attachments"], 0, "kpl's messages carry rmw_zenoh's 33-byte attachment");

    // kpl is in the ROS 2 graph: its node, its subscription and its two publishers.
    let graph: Vec<String> =
        result["graph"].as_array().unwrap().iter().map(|g| g.as_str().unwrap().to_string()).collect();
    for (kind, topic) in
        [("NN", ""), ("MS", "%tracker%markers"), ("MP", "%kpl%cars"), ("MP", "%kpl%detections")]
    {
        assert!(
            graph.iter().any(|g| g.contains(&format!("/{kind}/")) && g.contains("/kpl") && g.contains(topic)),
            "no {kind} token for `{topic}` in {graph:#?}"
        );
    }

    // The three bad messages: counted and reported, the run went on.
    let malformed: u64 = summary["summary"]["processes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["process"] == "markers")
        .map(|p| p["malformed"].as_u64().unwrap_or(0))
        .sum();
    assert_eq!(
        malformed, 3,
        "kpl counts the message without attachment, the wrong hash and the cut CDR: {summary:#}"
    );
}

/// A rosbag2 recording that `rosbags` wrote (MCAP, CDR messages, `ros2msg` schemas: what
/// `ros2 bag record` writes) is read by `kpl convert`: every message, in order, on its topic, at
/// its time, with every field equal to what rosbags serialized (random PoseStamped and
/// MarkerArray messages, every field of a marker filled).
#[test]
fn rosbag2_of_rosbags_converts_to_json_lines() {
    let Some(python) = python("rosbags") else { return };
    let dir = common::fresh_dir("ros2", "rosbag2");
    let bag = dir.join("bag");
    let expected = dir.join("expected.jsonl");
    let script = root().join("tests/rosbag2_oracle.py");
    let written = std::process::Command::new(&python)
        .arg(&script)
        .arg("write")
        .arg(&bag)
        .arg(&expected)
        .args(["--seed", "11", "--count", "60"])
        .output()
        .unwrap();
    assert!(written.status.success(), "{}", String::from_utf8_lossy(&written.stderr));
    let converted = dir.join("kpl.jsonl");
    let out = common::kpl(&["convert", bag.join("bag.mcap").to_str().unwrap(), converted.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let checked = std::process::Command::new(&python)
        .arg(&script)
        .arg("check")
        .arg(&expected)
        .arg(&converted)
        .output()
        .unwrap();
    assert!(
        checked.status.success(),
        "{}{}",
        String::from_utf8_lossy(&checked.stdout),
        String::from_utf8_lossy(&checked.stderr)
    );
    assert_eq!(lines(&converted).len(), 60);
}

/// A rosbag2 bag that `rosbags` wrote (specs/ros2/tracker/: a MarkerArray of the vehicles of the
/// SUMO scenario per time step, made again here and equal byte for byte) replayed through the
/// mapping of specs/ros2/markers.kpl in simulated time (specs/ros2/replay.kpl): every marker is a
/// percept at its `header.stamp`, and the cars come out. The run's recording then goes into a
/// rosbag2 bag through markers.kpl's ros2.publish sinks (`kpl convert`), which rosbags and
/// mcap-ros2-support read: a MarkerArray and a Detection3DArray per sample of the cars, equal to
/// them; and so is the bag the run wrote as it went (replay.kpl's `ros2.bag` sinks).
#[test]
fn a_bag_of_rosbags_replays_and_the_cars_go_into_a_bag() {
    let Some(python) = python("rosbags, mcap-ros2-support") else { return };
    let dir = common::fresh_dir("ros2", "replay");
    let script = root().join("tests/rosbag2_oracle.py");
    let made = std::process::Command::new(&python)
        .arg(&script)
        .arg("markers")
        .arg(dir.join("tracker"))
        .arg("--fcd")
        .arg(root().join("specs/traffic/sumo/grid/fcd.xml.gz"))
        .args(["--start", "100", "--seconds", "30"])
        .output()
        .unwrap();
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    let made: Value = serde_json::from_slice(&made.stdout).unwrap();
    for file in ["metadata.yaml", "tracker.mcap"] {
        assert!(
            std::fs::read(dir.join("tracker").join(file)).unwrap()
                == std::fs::read(root().join("specs/ros2/tracker").join(file)).unwrap(),
            "specs/ros2/tracker/{file} is not what rosbags writes: make it again with tests/rosbag2_oracle.py markers"
        );
    }

    let out = dir.join("out");
    let run = common::kpl(&["run", "specs/ros2/replay.kpl", "--quiet", "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["ending"], "sources_ended", "{summary:#}");
    let tracks = lines(&out.join("tracks.jsonl"));
    let frames: Vec<&Value> = tracks.iter().filter(|l| l["stream"] == "markers").collect();
    assert_eq!(frames.len() as u64, made["messages"].as_u64().unwrap(), "a sample per message");
    let percepts: usize = frames.iter().map(|l| l["value"].as_array().unwrap().len()).sum();
    assert_eq!(percepts as u64, made["markers"].as_u64().unwrap(), "a percept per marker");
    for (i, frame) in frames.iter().enumerate() {
        // The bag's time steps are 0.5 s apart from 2023-11-14T22:13:20Z; the stamp is the valid time.
        let stamp = 1_700_000_000_000_000 + 500_000 * i as i64;
        assert_eq!((frame["valid"].as_i64(), frame["available"].as_i64()), (Some(stamp), Some(stamp)));
    }
    let cars: BTreeSet<String> = tracks
        .iter()
        .filter(|l| l["stream"] == "onroad_car")
        .flat_map(|l| l["value"].as_array().unwrap().iter().map(|c| c["id"].as_str().unwrap().to_string()))
        .collect();
    assert!(cars.len() >= 20, "only {} of the bag's {} vehicles became cars", cars.len(), made["vehicles"]);

    let bag = dir.join("cars");
    let converted = common::kpl(&[
        "convert",
        out.join("tracks.jsonl").to_str().unwrap(),
        bag.to_str().unwrap(),
        "--spec",
        "specs/ros2/markers.kpl",
    ]);
    let said = String::from_utf8_lossy(&converted.stderr);
    assert!(converted.status.success(), "{said}");
    assert!(said.contains("sample(s) of `markers` are not in the bag"), "{said}");
    assert!(bag.join("metadata.yaml").is_file() && bag.join("cars_0.mcap").is_file());
    oracle_reads_bag(&python, &bag, &out.join("tracks.jsonl"));

    // The bag the run wrote itself (`ros2.bag` sinks of replay.kpl, the same mappings), read the
    // same way.
    assert!(out.join("cars/metadata.yaml").is_file() && out.join("cars/cars_0.mcap").is_file());
    oracle_reads_bag(&python, &out.join("cars"), &out.join("tracks.jsonl"));
}

/// A bag split as `ros2 bag record --max-bag-duration` splits it: replay.kpl's `ros2.bag` sinks
/// with `max_bag_duration: 5s` write the 30 s of cars into several files (`cars_0.mcap`,
/// `cars_1.mcap`, ...), each spanning less than 5 s, all listed in `metadata.yaml`; rosbags
/// (through `metadata.yaml`) and mcap-ros2-support (file by file) read every message, equal to
/// the recording. `kpl convert` reads the split bag back whole, and a bag whose `metadata.yaml`
/// records another type hash for a topic than its definition's has that topic's messages
/// skipped, each saying so.
#[test]
fn a_split_bag_is_one_recording() {
    let Some(python) = python("rosbags, mcap-ros2-support") else { return };
    let dir = common::fresh_dir("ros2", "split");
    let text = std::fs::read_to_string(root().join("specs/ros2/replay.kpl")).unwrap();
    let abs = |p: &str| root().join(p).display().to_string();
    let mut variant =
        text.replace("path: \"tracker\"", &format!("path: \"{}\"", abs("specs/ros2/tracker"))).replace(
            "\"../traffic/sumo/grid/net.xml.gz\"",
            &format!("\"{}\"", abs("specs/traffic/sumo/grid/net.xml.gz")),
        );
    assert_eq!(variant.matches("  path: \"cars\",\n").count(), 2, "replay.kpl's two ros2.bag sinks");
    variant = variant.replace("  path: \"cars\",\n", "  path: \"cars\",\n  max_bag_duration: 5s,\n");
    let spec = dir.join("split.kpl");
    std::fs::write(&spec, variant).unwrap();
    let out = dir.join("out");
    let run = common::kpl(&["run", spec.to_str().unwrap(), "--quiet", "--out", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));

    let bag = out.join("cars");
    let mut files: Vec<String> = std::fs::read_dir(&bag)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".mcap"))
        .collect();
    files.sort_by_key(|n| n.trim_start_matches("cars_").trim_end_matches(".mcap").parse::<u32>().unwrap());
    assert!(files.len() >= 5, "30 s in files of under 5 s: {files:?}");
    assert_eq!(files, (0..files.len()).map(|i| format!("cars_{i}.mcap")).collect::<Vec<_>>());
    let metadata = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
    for file in &files {
        assert!(
            metadata.contains(&format!("  - path: \"{file}\"\n")),
            "{file} in metadata.yaml:\n{metadata}"
        );
    }
    oracle_reads_bag(&python, &bag, &out.join("tracks.jsonl"));

    // Back to JSON lines: every message of every file, in order, as the run recorded the cars.
    let tracks = lines(&out.join("tracks.jsonl"));
    let cars: Vec<&Value> = tracks.iter().filter(|l| l["stream"] == "onroad_car").collect();
    let back = dir.join("back.jsonl");
    let converted = common::kpl(&["convert", bag.to_str().unwrap(), back.to_str().unwrap()]);
    assert!(converted.status.success(), "{}", String::from_utf8_lossy(&converted.stderr));
    let back = lines(&back);
    let markers: Vec<&Value> = back.iter().filter(|l| l["stream"] == "/kpl/cars").collect();
    assert_eq!((markers.len(), back.len()), (cars.len(), 2 * cars.len()));
    for (car, marker) in cars.iter().zip(&markers) {
        assert_eq!(marker["available"], car["available"]);
        let ns: Vec<&str> = marker["value"]["markers"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["ns"].as_str().unwrap())
            .collect();
        let ids: Vec<&str> =
            car["value"].as_array().unwrap().iter().map(|c| c["id"].as_str().unwrap()).collect();
        assert_eq!(ns, ids);
    }

    // metadata.yaml records another type hash for /kpl/cars: its messages are skipped, each saying why.
    let hash = kpl_ros2_hash(&metadata, "/kpl/cars");
    let mut altered = hash.clone();
    altered.replace_range(hash.len() - 1.., if hash.ends_with('0') { "1" } else { "0" });
    std::fs::write(bag.join("metadata.yaml"), metadata.replace(&hash, &altered)).unwrap();
    let converted =
        common::kpl(&["convert", bag.to_str().unwrap(), dir.join("altered.jsonl").to_str().unwrap()]);
    let said = String::from_utf8_lossy(&converted.stderr);
    assert_eq!(converted.status.code(), Some(1), "{said}");
    assert!(
        said.contains(&format!(
            "{}: {} sample(s), {} skipped",
            dir.join("altered.jsonl").display(),
            cars.len(),
            cars.len()
        )),
        "{said}"
    );
    assert!(
        said.contains("metadata.yaml records") && said.contains(&altered) && said.contains(&hash),
        "{said}"
    );
}

/// The `type_description_hash` that `metadata.yaml` (as kpl writes it) records for `topic`.
fn kpl_ros2_hash(metadata: &str, topic: &str) -> String {
    let from = metadata.find(&format!("name: \"{topic}\"")).unwrap();
    let line =
        metadata[from..].lines().find(|l| l.trim_start().starts_with("type_description_hash:")).unwrap();
    line.split('"').nth(1).unwrap().to_string()
}

/// Has `tests/rosbag2_oracle.py read` check the bag at `bag` (rosbags through its metadata.yaml,
/// mcap-ros2-support file by file) against the cars of the recording `tracks`.
fn oracle_reads_bag(python: &str, bag: &Path, tracks: &Path) {
    let read = std::process::Command::new(python)
        .arg(root().join("tests/rosbag2_oracle.py"))
        .arg("read")
        .arg(bag)
        .arg(tracks)
        .output()
        .unwrap();
    assert!(
        read.status.success(),
        "{}: {}{}",
        bag.display(),
        String::from_utf8_lossy(&read.stdout),
        String::from_utf8_lossy(&read.stderr)
    );
}

/// `--for` on a replayed bag whose stamps are dates (specs/ros2/tracker/, 0.5 s steps from
/// 2023-11-14T22:13:20Z for 30 s) counts from its first stamp, as the summary does: the run keeps
/// the messages of the first 10 s, [first, first + 10 s) as on any clock, and says that `--for`
/// ended it. (Counted from simulated time 0, it ended before the first message, with nothing.)
#[test]
fn for_counts_from_the_first_stamp_of_a_dated_bag() {
    let base = common::fresh_dir("ros2", "replay-for");
    let out = base.join("out");
    let run = common::kpl(&["run", "specs/ros2/replay.kpl", "--for", "10s", "--out", out.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{said}");
    assert!(
        said.contains("(--for reached) after 10.000 s simulated time from 2023-11-14T22:13:20"),
        "{said}"
    );
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["ending"], "duration_reached", "{summary:#}");
    let tracks = lines(&out.join("tracks.jsonl"));
    let stamps: Vec<i64> =
        tracks.iter().filter(|l| l["stream"] == "markers").map(|l| l["valid"].as_i64().unwrap()).collect();
    let first = 1_700_000_000_000_000;
    assert_eq!(stamps, (0..20).map(|i| first + 500_000 * i).collect::<Vec<_>>());
    assert!(tracks.iter().any(|l| l["stream"] == "onroad_car"), "the first 10 s make cars too");
}

/// A spec in `dir` that replays `/tracker/markers` of the bag at `path` (beside it) as percepts,
/// through markers.kpl's subscription mapping, into `tracks.jsonl`.
fn replay_spec(dir: &Path, path: &str) -> PathBuf {
    let spec = dir.join("replay.kpl");
    let text = format!(
        r#"type VisionPercept symbol vp {{ pos: vec2, size: float }}
source markers : list<VisionPercept> = ros2.replay(
  path: "{path}",
  topic: "/tracker/markers",
  type: "visualization_msgs/msg/MarkerArray",
  each: "markers",
  identity: "id",
  map: ["pos = pose.position", "size = scale.x"],
)
sink tracks = file.jsonl(markers, path: "tracks.jsonl")
"#
    );
    std::fs::write(&spec, text).unwrap();
    spec
}

/// Runs a [`replay_spec`] into `out`, which must succeed: its standard error, the `markers`
/// process's summary and how many samples of `markers` it recorded.
fn replay(spec: &Path, out: &Path) -> (String, Value, usize) {
    let run = common::kpl(&["run", spec.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&run.stderr).to_string();
    assert!(run.status.success(), "{said}");
    let summary: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let process = summary["summary"]["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["process"] == "markers")
        .cloned()
        .unwrap_or_default(); // left out of the summary when it has nothing to report
    let replayed = lines(&out.join("tracks.jsonl")).iter().filter(|l| l["stream"] == "markers").count();
    (said, process, replayed)
}

/// The type hash a bag records for a topic (`topic_type_hash` in its MCAP channel, as `ros2 bag
/// record` writes it from Jazzy on) is compared with the declared type's: the bag of rosbags
/// with the hash rosbags computes for MarkerArray replays whole, the same bag with a hash one
/// digit off has every message counted as malformed, the error naming both hashes. The run's
/// summary counts simulated time from the bag's first stamp, a date.
#[test]
fn a_bag_recorded_with_another_type_hash_is_refused_message_by_message() {
    let Some(python) = python("rosbags, mcap") else { return };
    let dir = common::fresh_dir("ros2", "type-hash");
    let spec = replay_spec(&dir, "bag.mcap");
    let script = root().join("tests/rosbag2_oracle.py");
    let mut hashes = Vec::new();
    for (case, flip) in [("same", false), ("flipped", true)] {
        let made = std::process::Command::new(&python)
            .arg(&script)
            .arg("hash")
            .arg(root().join("specs/ros2/tracker/tracker.mcap"))
            .arg(dir.join("bag.mcap"))
            .args(flip.then_some("--flip"))
            .output()
            .unwrap();
        assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
        let made: Value = serde_json::from_slice(&made.stdout).unwrap();
        let recorded = made["/tracker/markers"].as_str().unwrap().to_string();
        hashes.push(recorded.clone());
        let (said, process, replayed) = replay(&spec, &dir.join(case));
        if flip {
            assert_eq!((replayed, process["malformed"].as_u64().unwrap_or(0)), (0, 61), "{process}");
            let example = process["malformed_examples"][0]["error"].as_str().unwrap();
            assert!(example.contains(&recorded) && example.contains(&hashes[0]), "{example}");
            assert!(said.contains(&recorded) && said.contains(&hashes[0]), "{said}");
        } else {
            assert_eq!((replayed, process["malformed"].as_u64().unwrap_or(0)), (61, 0), "{process}");
            // The bag's stamps are dates: 30 s of simulated time from the first one.
            assert!(
                said.contains(
                    "after 30.000 s simulated time from 2023-11-14T22:13:20.000Z (the first sample)"
                ),
                "{said}"
            );
        }
    }
}

/// The type hash a bag's `metadata.yaml` records for a topic (`type_description_hash`, as `ros2
/// bag record` writes it from Jazzy on) is compared with the declared type's too: specs/ros2/tracker
/// with its metadata.yaml's hash one digit off has every message counted as malformed, the error
/// naming metadata.yaml and both hashes (the bag as shipped replays whole: `ros2.replay` above).
#[test]
fn a_bag_whose_metadata_records_another_type_hash_is_refused_message_by_message() {
    let dir = common::fresh_dir("ros2", "metadata-hash");
    let bag = dir.join("bag");
    std::fs::create_dir_all(&bag).unwrap();
    std::fs::copy(root().join("specs/ros2/tracker/tracker.mcap"), bag.join("tracker.mcap")).unwrap();
    let metadata = std::fs::read_to_string(root().join("specs/ros2/tracker/metadata.yaml")).unwrap();
    let shipped = "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf";
    let altered = "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dce";
    assert!(metadata.contains(shipped), "specs/ros2/tracker/metadata.yaml records another hash");
    std::fs::write(bag.join("metadata.yaml"), metadata.replace(shipped, altered)).unwrap();
    let spec = replay_spec(&dir, "bag");
    let (_, process, replayed) = replay(&spec, &dir.join("out"));
    assert_eq!((replayed, process["malformed"].as_u64().unwrap_or(0)), (0, 61), "{process}");
    let example = process["malformed_examples"][0]["error"].as_str().unwrap();
    assert!(
        example.contains("metadata.yaml") && example.contains(altered) && example.contains(shipped),
        "{example}"
    );
}

/// `kpl bench ros2 --quick` (two processes on loopback: kpl's ROS 2 path against bare zenoh
/// with the same CDR bytes) completes and every message of every throughput run arrives, for
/// the PoseStamped and the 100-marker MarkerArray; no timing is asserted.
#[test]
fn the_ros2_benchmark_runs_and_every_message_arrives() {
    let run = common::kpl(&["bench", "ros2", "--quick", "--format", "json"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let reports: Value = serde_json::from_slice(&run.stdout).unwrap();
    let reports = reports.as_array().unwrap();
    let payloads: Vec<&str> = reports.iter().map(|r| r["payload"].as_str().unwrap()).collect();
    assert_eq!(payloads, ["pose_stamped", "marker_array"]);
    for report in reports {
        let cases = report["cases"].as_array().unwrap();
        let codes: Vec<&str> = cases.iter().map(|c| c["implementation"].as_str().unwrap()).collect();
        assert_eq!(codes, ["bare", "kpl"], "{report:#}");
        for case in cases {
            assert_eq!(case["lost"], 0, "every message arrives: {case}");
            assert!(case["samples_per_s"].as_f64().unwrap() > 0.0, "{case}");
            assert!(case["round_trip_p50_us"].as_f64().unwrap() > 0.0, "{case}");
        }
        assert!(report["ratios"][0]["throughput"]["median"].as_f64().unwrap().is_finite(), "{report:#}");
    }
}
