//! From pixels to the world, end to end (docs/camera.md): `specs/mot/image_plane.kpl` on the
//! shipped sequence and on trackers' outputs py-motmetrics ships (data we did not make), scored by
//! `kpl score --gt` against their ground truth; malformed lines of a tracker's file counted; every
//! format of `file.tracker`; a fixed camera calibrated from point pairs; `camera_grid.kpl` through
//! the simulated UAV camera and the georeferencing unit, scored in world coordinates, with the
//! percepts' covariances checked against their true errors.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::print_stderr,
    reason = "tests report and fail loudly"
)]

mod common;

use std::path::{Path, PathBuf};

use common::{fresh_dir, kpl, lines, python, root};
use serde_json::Value;

fn run_ok(args: &[&str]) -> String {
    let out = kpl(args);
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "kpl {args:?} failed:\n{}\n{stderr}", String::from_utf8_lossy(&out.stdout));
    stderr
}

/// `kpl score --format json`: per stream name, its scores.
fn scores(args: &[&str]) -> Vec<(String, Value)> {
    let mut all = args.to_vec();
    all.extend(["--format", "json"]);
    let out = kpl(&all);
    assert!(out.status.success(), "kpl {all:?}: {}", String::from_utf8_lossy(&out.stderr));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    report["streams"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| (s["stream"].as_str().unwrap().to_string(), s.clone()))
        .collect()
}

fn idf1(scores: &[(String, Value)], stream: &str) -> f64 {
    scores.iter().find(|(n, _)| n == stream).unwrap_or_else(|| panic!("no {stream}")).1["identity"]["idf1"]
        .as_f64()
        .unwrap()
}

/// The image-plane spec in a folder of its own with `tracker` as its tracker.txt; the run's output.
fn image_plane_run(name: &str, tracker: &Path) -> common::InTestDir {
    let dir = fresh_dir("camera", name);
    std::fs::copy(root().join("specs/mot/image_plane.kpl"), dir.join("image_plane.kpl")).unwrap();
    std::fs::copy(tracker, dir.join("tracker.txt")).unwrap();
    let out = dir.join("out");
    run_ok(&["run", dir.join("image_plane.kpl").to_str().unwrap(), "--out", out.to_str().unwrap()]);
    dir.holding(out)
}

#[test]
fn the_image_plane_spec_keeps_fragmented_tracks_together() {
    let out = fresh_dir("camera", "shipped");
    run_ok(&["run", "specs/mot/image_plane.kpl", "--out", out.to_str().unwrap()]);
    // The contract: JSON lines whose objects carry `id` and `box` ([left, top, width, height]).
    let samples = lines(&out.join("tracks.jsonl"));
    let tracks: Vec<&Value> = samples.iter().filter(|s| s["stream"] == "image_tracks").collect();
    assert_eq!(tracks.len(), 500, "one snapshot per frame");
    let first = tracks.iter().flat_map(|s| s["value"].as_array().unwrap()).next().unwrap();
    assert!(first["id"].as_str().unwrap().starts_with("tr") && first["box"].as_array().unwrap().len() == 4);
    assert_eq!(tracks[1]["valid"], 40_000, "25 frames per second from 0");
    let s = scores(&["score", out.to_str().unwrap(), "--gt", "specs/mot/gt.txt"]);
    let (tracker, anchored) = (idf1(&s, "tracker"), idf1(&s, "image_tracks"));
    eprintln!("shipped sequence: IDF1 tracker {tracker:.3}, anchored {anchored:.3}");
    assert!(anchored > tracker + 0.005, "anchoring joins the tracker's fragments: {anchored} vs {tracker}");
    // What was measured is the tracker's boxes: the same detections, fewer switches.
    let clear = |n: &str| s.iter().find(|(m, _)| m == n).unwrap().1["clear"].clone();
    assert_eq!(
        clear("tracker")["matches"].as_u64().unwrap() + clear("tracker")["switches"].as_u64().unwrap(),
        clear("image_tracks")["matches"].as_u64().unwrap()
            + clear("image_tracks")["switches"].as_u64().unwrap()
    );
    assert!(clear("image_tracks")["switches"].as_u64() <= clear("tracker")["switches"].as_u64());
    // --predicted scores the predicted states too: more hypotheses.
    let p = scores(&["score", out.to_str().unwrap(), "--gt", "specs/mot/gt.txt", "--predicted"]);
    let predictions = |s: &[(String, Value)]| {
        s.iter().find(|(n, _)| n == "image_tracks").unwrap().1["clear"]["predictions"].as_u64().unwrap()
    };
    assert!(predictions(&p) > predictions(&s));
}

#[test]
fn on_trackers_outputs_py_motmetrics_ships_anchoring_never_lowers_idf1() {
    let Some(python) = python("py-motmetrics") else { return };
    let out = std::process::Command::new(python)
        .args([
            "-c",
            "import motmetrics, os; print(os.path.join(os.path.dirname(motmetrics.__file__), 'data'))",
        ])
        .output()
        .unwrap();
    let data = PathBuf::from(String::from_utf8(out.stdout).unwrap().trim());
    let mut raised = 0;
    for sequence in ["TUD-Campus", "TUD-Stadtmitte"] {
        let run = image_plane_run(sequence, &data.join(sequence).join("test.txt"));
        let gt = data.join(sequence).join("gt.txt");
        let s = scores(&["score", run.to_str().unwrap(), "--gt", gt.to_str().unwrap()]);
        let (tracker, anchored) = (idf1(&s, "tracker"), idf1(&s, "image_tracks"));
        eprintln!("{sequence}: IDF1 tracker {tracker:.3}, anchored {anchored:.3}");
        if sequence == "TUD-Campus" {
            // The tracker's own scores are the ones published for this sequence (py-motmetrics'
            // README): IDF1 55.8 %, MOTA 52.6 %, MOTP 0.277, 13 false positives, 150 misses, 7 switches.
            let clear = &s.iter().find(|(n, _)| n == "tracker").unwrap().1["clear"];
            assert!((tracker - 0.558).abs() < 5e-4 && (clear["mota"].as_f64().unwrap() - 0.526).abs() < 5e-4);
            assert!((clear["motp"].as_f64().unwrap() - 0.277).abs() < 5e-4);
            assert_eq!(
                (clear["false_positives"].as_u64(), clear["misses"].as_u64(), clear["switches"].as_u64()),
                (Some(13), Some(150), Some(7))
            );
        }
        assert!(anchored >= tracker, "{sequence}: anchoring lowered IDF1 from {tracker} to {anchored}");
        if anchored > tracker {
            raised += 1;
        }
    }
    assert!(raised >= 1, "the TUD-Campus tracker fragments tracks that anchoring joins");
}

#[test]
fn a_malformed_line_of_a_trackers_file_is_counted_and_the_run_goes_on() {
    // Its own folder: image_plane_run makes a fresh one for the run.
    let dir = fresh_dir("camera", "malformed-input");
    let tracker = dir.join("tracker.txt");
    std::fs::write(&tracker, "1,1,10,10,20,40,1,-1,-1,-1\n1,2,oops,10,20,40,1\n2,1,12,10,20,40,1,-1,-1,-1\nnot a line\n3,1,14,10,20,40,1,-1,-1,-1\n").unwrap();
    let out = image_plane_run("malformed", &tracker);
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let process = summary["summary"]["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["process"] == "tracker")
        .unwrap()
        .clone();
    assert_eq!(process["malformed"], 2, "{process}");
    let samples = lines(&out.join("tracks.jsonl"));
    assert_eq!(samples.iter().filter(|s| s["stream"] == "image_tracks").count(), 3, "three frames replayed");
}

#[test]
fn file_tracker_reads_every_format_and_a_fixed_camera_maps_it_to_the_ground() {
    let dir = fresh_dir("camera", "formats");
    std::fs::write(
        dir.join("visdrone.txt"),
        "1,1,100,200,20,10,1,4,0,0\n1,0,0,0,50,50,0,0,0,0\n2,1,102,200,20,10,1,4,0,0\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("detrac.xml"),
        r#"<sequence name="x"><ignored_region><box left="0" top="0" width="9" height="9"/></ignored_region>
<frame density="1" num="1"><target_list><target id="3"><box left="100" top="200" width="20" height="10"/><attribute vehicle_type="van"/></target></target_list></frame>
<frame density="1" num="2"><target_list><target id="3"><box left="104" top="200" width="20" height="10"/></target></target_list></frame></sequence>"#,
    )
    .unwrap();
    std::fs::write(
        dir.join("coco.json"),
        r#"[{"image_id": 1, "category_id": 3, "bbox": [100, 200, 20, 10], "score": 0.9}, {"image_id": 2, "category_id": 3, "bbox": [106, 200, 20, 10], "score": 0.8}]"#,
    )
    .unwrap();
    // A fixed camera whose ground is the image scaled: 10 px per metre, v up north (pairs of
    // pixel [u, v] and ground [x, y]); box bottoms (v = 210) are at y = -21 m.
    let spec = r#"
type Box symbol b { box: list<float>, pos: vec2 }
type Ground symbol g { pos: vec2, vel: vec2, pos_cov: list<float> }
source vis : list<Box> = file.tracker(path: "visdrone.txt", format: "visdrone", fps: 10.0, prefix: "v")
source det : list<Box> = file.tracker(path: "detrac.xml", format: "detrac", fps: 10.0, prefix: "d")
source coco : list<Box> = file.tracker(path: "coco.json", format: "coco", fps: 10.0, prefix: "c")
compute ground : list<Ground> = camera.homography(vis, pairs: [[0, 0, 0, 0], [100, 0, 10, 0], [100, 100, 10, -10], [0, 100, 0, -10], [50, 50, 5, -5]], pixel_noise_px: 1.0)
sink out = file.jsonl(vis, det, coco, ground, path: "formats.jsonl")
"#;
    std::fs::write(dir.join("formats.kpl"), spec).unwrap();
    let out = dir.join("out");
    let stderr = run_ok(&["run", dir.join("formats.kpl").to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let samples = lines(&out.join("formats.jsonl"));
    let of = |stream: &str| -> Vec<&Value> { samples.iter().filter(|s| s["stream"] == stream).collect() };
    for (stream, id, second_left) in [("vis", "v1", 102.0), ("det", "d3", 104.0), ("coco", "cd2_1", 106.0)] {
        let frames = of(stream);
        assert_eq!(frames.len(), 2, "{stream}");
        let second = &frames[1]["value"][0];
        assert_eq!(second["box"][0].as_f64(), Some(second_left), "{stream}: {second}");
        assert_eq!(second["id"], id, "{stream}");
    }
    // The VisDrone box moved 2 px in 0.1 s: 20 px/s.
    assert_eq!(of("vis")[1]["value"][0]["vel"], serde_json::json!([20.0, 0.0]));
    // The ground: the box's bottom centre (112, 210) at (11.2, -21.0) m.
    let g = &of("ground")[1]["value"][0];
    let pos: Vec<f64> = g["pos"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((pos[0] - 11.2).abs() < 1e-6 && (pos[1] + 21.0).abs() < 1e-6, "{g}");
    let cov: Vec<f64> = g["pos_cov"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((cov[0] - 0.01).abs() < 1e-6 && cov[1].abs() < 1e-9, "1 px is 0.1 m: {cov:?}");
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let text = summary.to_string();
    assert!(text.contains("calibration residual"), "the fit's residual is reported: {stderr}");
}

#[test]
fn the_camera_spec_anchors_georeferenced_percepts_in_world_coordinates() {
    let out = fresh_dir("camera", "grid");
    run_ok(&["run", "specs/traffic/camera_grid.kpl", "--for", "60s", "--out", out.to_str().unwrap()]);
    let s = scores(&["score", out.to_str().unwrap(), "--in-view-only"]);
    // Measured (seed 7, 2026-11-28): IDF1 0.995 and 0.992; false positives 2 and 2 (before the
    // entry and 4 m/s establish conditions 0.985 / 80 and 0.982 / 10; 276 and 108 false positives
    // without the spec's negative information, which gives up objects predicted out of the image
    // or standing unseen in plain view: docs/anchoring.md, "Through a UAV camera").
    for (stream, at_least, most_false) in [("vision_world", 0.975, 40), ("onroad_car", 0.97, 30)] {
        let value = idf1(&s, stream);
        let scored = &s.iter().find(|(n, _)| n == stream).unwrap().1;
        let false_positives = scored["clear"]["false_positives"].as_u64().unwrap();
        eprintln!("camera_grid 60 s: {stream} IDF1 {value:.3}, {false_positives} false positives");
        assert!(value >= at_least, "{stream}: {value}");
        assert!(false_positives <= most_false, "{stream}: {false_positives} false positives");
    }
    // Every world percept's true error against its covariance: inside the 2-sigma ellipse
    // (Mahalanobis 2.486, 95.45 % for a Gaussian) for most of them.
    let samples = lines(&out.join("camera_grid/tracks.jsonl"));
    let truth: std::collections::HashMap<i64, &Value> = samples
        .iter()
        .filter(|s| s["stream"] == "uav.truth")
        .map(|s| (s["valid"].as_i64().unwrap(), &s["value"]))
        .collect();
    let (mut inside, mut total) = (0usize, 0usize);
    for sample in samples.iter().filter(|s| s["stream"] == "percepts") {
        let Some(cars) = truth.get(&sample["valid"].as_i64().unwrap()) else { continue };
        for p in sample["value"].as_array().unwrap() {
            let xy = |v: &Value| [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()];
            let pos = xy(&p["pos"]);
            let nearest = cars.as_array().unwrap().iter().map(|c| xy(&c["pos"])).min_by(|a, b| {
                let d = |q: [f64; 2]| (q[0] - pos[0]).hypot(q[1] - pos[1]);
                d(*a).total_cmp(&d(*b))
            });
            let Some(t) = nearest else { continue };
            let e = [pos[0] - t[0], pos[1] - t[1]];
            if e[0].hypot(e[1]) > 5.0 {
                continue; // a false positive
            }
            let c: Vec<f64> = p["pos_cov"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
            let det = c[0] * c[2] - c[1] * c[1];
            let m2 = (c[2] * e[0] * e[0] - 2.0 * c[1] * e[0] * e[1] + c[0] * e[1] * e[1]) / det;
            total += 1;
            if m2.sqrt() <= 2.486 {
                inside += 1;
            }
        }
    }
    let fraction = inside as f64 / total as f64;
    eprintln!(
        "camera_grid 60 s: {inside} of {total} percepts ({:.1} %) inside their 2-sigma ellipse",
        fraction * 100.0
    );
    assert!(total > 1000 && fraction > 0.8, "{fraction}");
}

#[test]
fn a_vehicle_entering_the_image_has_its_world_object_and_car_at_its_percepts_second_frame() {
    use std::collections::{BTreeMap, HashMap};
    // A percept moving in from outside the image (by its velocity it was out of it a second ago)
    // is a world object, an on-road object and a car at once (camera_*.kpl's establish
    // conditions): nothing else can be where it came from. Before, the world object waited half a
    // second of motion and each level above it 200 ms (seed 7, 60 s: 0 of 20 entries; after: 16).
    let out = fresh_dir("camera", "highway_entry");
    run_ok(&["run", "specs/traffic/camera_highway.kpl", "--for", "60s", "--out", out.to_str().unwrap()]);
    let samples = lines(&out.join("camera_highway/tracks.jsonl"));
    let mut frames: BTreeMap<i64, HashMap<&str, &Value>> = BTreeMap::new();
    for s in &samples {
        frames
            .entry(s["valid"].as_i64().unwrap())
            .or_default()
            .insert(s["stream"].as_str().unwrap(), &s["value"]);
    }
    let times: Vec<i64> = frames.keys().copied().collect();
    // Each vehicle that enters the image during the run: the frame of its first percept.
    let mut in_view: HashMap<&str, bool> = HashMap::new();
    let mut first_percept: HashMap<&str, Option<usize>> = HashMap::new();
    for (k, t) in times.iter().enumerate() {
        let Some(truth) = frames[t].get("uav.truth") else { continue };
        for v in truth.as_array().unwrap() {
            let id = v["id"].as_str().unwrap();
            let now = v["in_view"].as_bool().unwrap();
            if now && in_view.get(id) == Some(&false) {
                first_percept.entry(id).or_insert(None);
            }
            in_view.insert(id, now);
            let seen = !v["seen_as"].as_str().unwrap().is_empty();
            if let Some(first) = first_percept.get_mut(id)
                && first.is_none()
                && seen
            {
                *first = Some(k);
            }
        }
    }
    let xy = |v: &Value| [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()];
    for link in ["vision_world", "onroad_car"] {
        let (mut found, mut entries) = (0, 0);
        for (id, first) in &first_percept {
            let Some(next) = first.and_then(|k| times.get(k + 1)) else { continue };
            let Some(truth) = frames[next].get("uav.truth") else { continue };
            let car = truth.as_array().unwrap().iter().find(|v| v["id"] == *id).unwrap();
            let at = xy(&car["pos"]);
            entries += 1;
            let objects = frames[next].get(link).and_then(|v| v.as_array()).cloned().unwrap_or_default();
            if objects.iter().any(|o| {
                let p = xy(&o["pos"]);
                (p[0] - at[0]).hypot(p[1] - at[1]) < 3.0
            }) {
                found += 1;
            }
        }
        eprintln!(
            "camera_highway 60 s: {link}: {found} of {entries} entering vehicles at their percept's second frame"
        );
        assert!(entries >= 10 && found * 10 >= entries * 7, "{link}: {found} of {entries}");
    }
}
