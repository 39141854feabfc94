//! `kpl score` end to end, on a run of `specs/traffic/bridge.kpl` (data the scorer was not made
//! for): every link stream and the tracker get sane scores, the JSON parses, the exported
//! MOTChallenge-style files score the same with py-motmetrics and TrackEval (the Python of
//! docs/scoring.md; needs `KPL_PYTHON` as set by scripts/test), a world model scored per type
//! agrees with the link outputs it repeats, `--measured-only` leaves out predicted states, branch
//! objects of predictions split at junctions (a run of `specs/traffic/sumo_random.kpl`) are left
//! out unless `--branches`, and bad input gets clear errors and exit codes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr, reason = "tests")]

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

fn scratch(name: &str) -> PathBuf {
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("kpl-score-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `bridge.kpl` with a world model recorded too, run once for 60 s of simulated time; its output
/// folder.
fn bridge_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = scratch("bridge");
        let spec = std::fs::read_to_string(workspace().join("specs/traffic/bridge.kpl")).unwrap();
        let spec = format!(
            "{spec}\ncompute world = anchor.world_model(onroad_car)\nsink world_model = file.jsonl(world, path: \"world.jsonl\")\n"
        );
        let spec_path = dir.join("bridge_world.kpl");
        std::fs::write(&spec_path, spec).unwrap();
        let out = dir.join("out");
        let o = kpl(&["run", "-q", spec_path.to_str().unwrap(), "--for", "60s", "--out", out.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
        out
    })
}

/// The plain bridge recording alone (tracks.jsonl), as `kpl run specs/traffic/bridge.kpl` writes it.
fn tracks() -> PathBuf {
    bridge_run().join("tracks.jsonl")
}

fn score_json(args: &[&str]) -> Value {
    let mut all = vec!["score", "--format", "json"];
    all.extend_from_slice(args);
    let o = kpl(&all);
    assert!(o.status.success(), "kpl {all:?}: {}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn stream<'a>(report: &'a Value, name: &str) -> &'a Value {
    report["streams"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stream"] == name)
        .unwrap_or_else(|| panic!("no stream {name} in {report}"))
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn n(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not a count: {v}"))
}

#[test]
fn every_link_stream_of_the_bridge_run_gets_sane_scores() {
    let tracks = tracks();
    let report = score_json(&[tracks.to_str().unwrap()]);
    assert_eq!(report["truth"], "tracker.truth");
    assert_eq!(f(&report["max_distance"]), 3.0);
    let names: Vec<&str> =
        report["streams"].as_array().unwrap().iter().map(|s| s["stream"].as_str().unwrap()).collect();
    assert_eq!(names, ["onroad_car", "tracker", "vision_world", "world_onroad"]);
    for name in names {
        let s = stream(&report, name);
        let (c, i, h) = (&s["clear"], &s["identity"], &s["hota"]);
        // 60 s at 10 Hz, four cars at a time.
        assert!(n(&s["alignment"]["frames"]) >= 590, "{name}: {}", s["alignment"]);
        assert_eq!(n(&c["objects"]), 4 * n(&c["frames"]), "{name}: four cars in every frame");
        assert_eq!(n(&c["matches"]) + n(&c["switches"]) + n(&c["misses"]), n(&c["objects"]), "{name}");
        assert_eq!(
            n(&c["matches"]) + n(&c["switches"]) + n(&c["false_positives"]),
            n(&c["predictions"]),
            "{name}"
        );
        for (field, v) in [
            ("mota", &c["mota"]),
            ("idf1", &i["idf1"]),
            ("hota", &h["hota"]),
            ("det_a", &h["det_a"]),
            ("ass_a", &h["ass_a"]),
        ] {
            let v = f(v);
            assert!(v > 0.2 && v < 1.0, "{name}: {field} = {v}");
        }
        // Matched states lie within the gate, on average well within it.
        assert!(f(&c["motp"]) > 0.0 && f(&c["motp"]) < 2.0, "{name}: MOTP {}", c["motp"]);
        assert!(f(&h["loc_a"]) > 0.6, "{name}: LocA {}", h["loc_a"]);
        assert!(n(&c["unique_objects"]) >= 8, "{name}: cars leave and new ones enter");
    }
    // The tracker: 1 m noise, 5 % dropouts, a false positive every 2 s, a new id after the bridge.
    let tracker = stream(&report, "tracker");
    assert!(f(&tracker["clear"]["mota"]) > 0.7, "{}", tracker["clear"]);
    assert!(n(&tracker["clear"]["fragmentations"]) > 10, "dropouts fragment the percept tracks");
    // World objects persist through the bridge: most of each car's frames have its one world object.
    let world = stream(&report, "vision_world");
    assert!(f(&world["identity"]["idr"]) > 0.85, "{}", world["identity"]);
    assert!(
        f(&world["identity"]["idr"]) > f(&tracker["identity"]["idr"]),
        "anchoring keeps identities the tracker loses"
    );
}

#[test]
fn a_table_by_default() {
    let o = kpl(&["score", bridge_run().to_str().unwrap(), "--stream", "onroad_car", "--stream", "tracker"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(
        text.starts_with("scored against `tracker.truth`; gate 3 m; HOTA similarity max(0, 1 - d / 6 m)"),
        "{text}"
    );
    for header in [
        "MOTA", "MOTP m", "IDF1", "IDP", "IDR", "HOTA", "DetA", "AssA", "LocA", "IDsw", "Frag", "MT", "PT",
        "ML",
    ] {
        assert!(text.contains(header), "{header} in\n{text}");
    }
    let rows = text.lines().filter(|l| l.starts_with("onroad_car ") || l.starts_with("tracker ")).count();
    assert_eq!(rows, 4, "two streams in two tables:\n{text}");
}

#[test]
fn a_world_model_is_scored_per_type_and_agrees_with_the_link_outputs() {
    let report = score_json(&[bridge_run().to_str().unwrap()]);
    let same = |a: &str, b: &str| {
        for part in ["clear", "identity", "hota"] {
            assert_eq!(stream(&report, a)[part], stream(&report, b)[part], "{a} and {b}: {part}");
        }
    };
    // The world model's objects of a type are the link output of that type.
    same("world[WorldObject]", "vision_world");
    same("world[OnRoadObject]", "world_onroad");
    same("world[Car]", "onroad_car");

    // Only measured states: the world model's percepts are then exactly the tracker's snapshots
    // (absent percepts are left out); predicted world objects no longer count as false positives.
    let measured = score_json(&[bridge_run().to_str().unwrap(), "--measured-only"]);
    for part in ["clear", "identity", "hota"] {
        assert_eq!(
            stream(&measured, "world[VisionPercept]")[part],
            stream(&measured, "tracker")[part],
            "{part}"
        );
    }
    let (all, only) = (stream(&report, "world[WorldObject]"), stream(&measured, "world[WorldObject]"));
    assert_eq!(all["alignment"]["measured"], "off");
    assert_eq!(all["alignment"]["branches"], "none", "the bridge has no junction: no branch objects");
    assert_eq!(only["alignment"]["measured"], "applied");
    assert!(n(&only["alignment"]["left_out"]) > 100, "{}", only["alignment"]);
    assert!(n(&only["clear"]["false_positives"]) < n(&all["clear"]["false_positives"]) / 4);
    assert!(n(&only["clear"]["misses"]) > n(&all["clear"]["misses"]), "predicted states matched cars too");
    // A link's output says per object whether it was measured, as the world model does: the two
    // agree with only measured states too.
    assert_eq!(stream(&measured, "vision_world")["alignment"]["measured"], "applied");
    for part in ["clear", "identity", "hota"] {
        assert_eq!(stream(&measured, "vision_world")[part], only[part], "{part}");
    }
    // Streams without a `measured` field (a tracker's percepts) are scored whole, and the report
    // says so.
    assert_eq!(stream(&measured, "tracker")["alignment"]["measured"], "not_available");
    let o = kpl(&["score", bridge_run().to_str().unwrap(), "--measured-only", "--stream", "tracker"]);
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(
        text.contains(
            "only measured states are scored, but tracker say nothing about which states were measured"
        ),
        "{text}"
    );
}

/// `specs/traffic/sumo_random.kpl` (recorded SUMO traffic on a network with junctions) run for
/// 120 s of simulated time: on-road objects predicted through junctions split into branch objects.
fn sumo_random_run() -> &'static Path {
    static RUN: OnceLock<PathBuf> = OnceLock::new();
    RUN.get_or_init(|| {
        let out = scratch("sumo_random");
        let o = kpl(&[
            "run",
            "-q",
            "specs/traffic/sumo_random.kpl",
            "--for",
            "120s",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        out
    })
}

#[test]
fn branch_objects_are_left_out_unless_asked_for() {
    let run = sumo_random_run().to_str().unwrap();
    let default = score_json(&[run]);
    let branches = score_json(&[run, "--branches"]);
    let (left, scored) = (stream(&default, "world_onroad"), stream(&branches, "world_onroad"));
    assert_eq!(left["alignment"]["branches"], "left_out", "{}", left["alignment"]);
    assert_eq!(scored["alignment"]["branches"], "scored", "{}", scored["alignment"]);
    let states = n(&left["alignment"]["branch_states"]);
    let objects = n(&left["alignment"]["branch_objects"]);
    assert!(states > 20 && objects > 2 && objects < states, "{}", left["alignment"]);
    assert_eq!(n(&scored["alignment"]["branch_states"]), states);
    assert_eq!(n(&scored["alignment"]["branch_objects"]), objects);
    // Left out, they are no hypotheses at all; scored, they are hypotheses of their own, most of
    // them false positives (the car took one branch).
    let (c_left, c_scored) = (&left["clear"], &scored["clear"]);
    assert_eq!(n(&c_scored["predictions"]) - n(&c_left["predictions"]), states);
    assert_eq!(c_scored["objects"], c_left["objects"]);
    assert!(
        n(&c_scored["false_positives"]) > n(&c_left["false_positives"]) + states / 2,
        "{c_left} / {c_scored}"
    );
    assert!(f(&c_scored["mota"]) < f(&c_left["mota"]));
    // Streams without branch objects say nothing, with or without --branches.
    for report in [&default, &branches] {
        for name in ["tracker", "vision_world", "onroad_car"] {
            let s = stream(report, name);
            assert_eq!(s["alignment"]["branches"], "none", "{name}: {}", s["alignment"]);
            assert!(s["alignment"].get("branch_states").is_none(), "{name}");
        }
    }
    // The table says what was left out, and how to score it.
    let o = kpl(&["score", run]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    let notes: Vec<&str> = text.lines().filter(|l| l.contains("branch objects")).collect();
    assert_eq!(
        notes,
        [format!(
            "note: world_onroad: {states} states of {objects} branch objects (records with `branch_of`: \
             other hypotheses of predictions split at junctions) left out; --branches scores them"
        )],
        "{text}"
    );
    let o = kpl(&["score", run, "--branches", "--stream", "world_onroad"]);
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(
        text.contains(&format!(
            "note: world_onroad: {states} states of {objects} branch objects scored as tracks"
        )),
        "{text}"
    );
}

#[test]
fn the_export_scores_the_same_in_py_motmetrics_and_trackeval() {
    let Some(python) = std::env::var("KPL_PYTHON").ok().filter(|p| !p.is_empty()) else {
        let required = std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1");
        assert!(!required, "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set: run scripts/test");
        eprintln!("skipped: KPL_PYTHON is not set (scripts/test sets it up)");
        return;
    };
    let dir = scratch("export");
    let export = dir.join("mot");
    let report = score_json(&[
        tracks().to_str().unwrap(),
        "--max-distance",
        "2.5",
        "--export",
        export.to_str().unwrap(),
    ]);
    let streams = ["tracker", "vision_world", "world_onroad", "onroad_car"];
    let batch = serde_json::json!({"cases": streams.iter().map(|s| serde_json::json!({
        "folder": export.join(s), "max_distance": 2.5, "zero_distance": 5.0
    })).collect::<Vec<_>>()});
    let (batch_path, results_path) = (dir.join("batch.json"), dir.join("results.json"));
    std::fs::write(&batch_path, batch.to_string()).unwrap();
    let o = Command::new(&python)
        .arg(workspace().join("crates/kpl-score/tests/oracles.py"))
        .arg(workspace().join("docs/scoring.md"))
        .arg(&batch_path)
        .arg(&results_path)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let results: Value = serde_json::from_str(&std::fs::read_to_string(&results_path).unwrap()).unwrap();
    for (name, theirs) in streams.iter().zip(results["results"].as_array().unwrap()) {
        assert!(theirs.get("error").is_none(), "{name}: {theirs}");
        let ours = stream(&report, name);
        for (field, mine) in [
            ("num_switches", &ours["clear"]["switches"]),
            ("num_fragmentations", &ours["clear"]["fragmentations"]),
            ("num_false_positives", &ours["clear"]["false_positives"]),
            ("num_misses", &ours["clear"]["misses"]),
            ("mostly_tracked", &ours["clear"]["mostly_tracked"]),
            ("mostly_lost", &ours["clear"]["mostly_lost"]),
            ("idtp", &ours["identity"]["idtp"]),
        ] {
            assert_eq!(f(mine), f(&theirs[field]), "{name}: {field}");
        }
        for (field, mine) in [
            ("mota", &ours["clear"]["mota"]),
            ("motp", &ours["clear"]["motp"]),
            ("idf1", &ours["identity"]["idf1"]),
            ("HOTA", &ours["hota"]["hota"]),
            ("DetA", &ours["hota"]["det_a"]),
            ("AssA", &ours["hota"]["ass_a"]),
            ("LocA", &ours["hota"]["loc_a"]),
        ] {
            assert!(
                (f(mine) - f(&theirs[field])).abs() < 1e-9,
                "{name}: {field}: ours {mine}, theirs {}",
                theirs[field]
            );
        }
    }
    // The mapping file says which symbol was which car, and when.
    let mapping = std::fs::read_to_string(export.join("onroad_car/mapping.csv")).unwrap();
    assert!(mapping.starts_with("hypothesis,truth,from_us,to_us,frames\nco1,car"), "{mapping}");

    // For the percepts, the simulator knows the answer: the ground truth says which percept sees
    // each car (`seen_as`). The mapping agrees with it, but for the few percepts whose noise put
    // them beyond the gate.
    let mapping = std::fs::read_to_string(export.join("tracker/mapping.csv")).unwrap();
    let intervals: Vec<(String, String, i64, i64)> = mapping
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].to_string(), f[1].to_string(), f[2].parse().unwrap(), f[3].parse().unwrap())
        })
        .collect();
    let (mut agree, mut seen) = (0, 0);
    for line in std::fs::read_to_string(tracks()).unwrap().lines() {
        let sample: Value = serde_json::from_str(line).unwrap();
        if sample["stream"] != "tracker.truth" {
            continue;
        }
        let t = sample["valid"].as_i64().unwrap();
        for car in sample["value"].as_array().unwrap() {
            let percept = car["seen_as"].as_str().unwrap();
            if percept.is_empty() {
                continue;
            }
            seen += 1;
            let mapped = intervals.iter().find(|(h, _, from, to)| h == percept && *from <= t && t <= *to);
            agree += usize::from(mapped.is_some_and(|(_, truth, _, _)| car["id"] == truth.as_str()));
        }
    }
    assert!(seen > 2000, "{seen}");
    assert!(agree as f64 > 0.93 * seen as f64, "the mapping agrees with seen_as {agree} times of {seen}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn missing_frames_unknown_streams_and_bad_input_get_clear_errors() {
    let dir = scratch("errors");
    // Cut every tenth car snapshot out of a recording.
    let text = std::fs::read_to_string(tracks()).unwrap();
    let mut k = 0;
    let cut: String = text
        .lines()
        .filter(|l| {
            let car = l.starts_with("{\"stream\":\"onroad_car\"");
            k += usize::from(car);
            !(car && k % 10 == 5)
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let cut_path = dir.join("cut.jsonl");
    std::fs::write(&cut_path, &cut).unwrap();
    let cut_arg = cut_path.to_str().unwrap();
    let o = kpl(&["score", cut_arg, "--stream", "onroad_car"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("`onroad_car` has no sample at 60 of the ground truth's"), "{}", stderr(&o));
    assert!(stderr(&o).contains("--missing empty"), "{}", stderr(&o));
    let empty = score_json(&[cut_arg, "--stream", "onroad_car", "--missing", "empty"]);
    let skip = score_json(&[cut_arg, "--stream", "onroad_car", "--missing", "skip"]);
    let whole = score_json(&[tracks().to_str().unwrap(), "--stream", "onroad_car"]);
    let frames = |r: &Value| n(&stream(r, "onroad_car")["clear"]["frames"]);
    assert_eq!(frames(&empty), frames(&whole));
    assert_eq!(frames(&skip), frames(&whole) - 60);
    let misses = |r: &Value| n(&stream(r, "onroad_car")["clear"]["misses"]);
    assert!(misses(&empty) > misses(&whole), "the cut frames count as frames that saw nothing");

    // A typo, a stream that is not objects, no ground truth.
    let o = kpl(&["score", tracks().to_str().unwrap(), "--stream", "onroad_cars"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("no stream `onroad_cars` in the recording; did you mean `onroad_car`?"),
        "{}",
        stderr(&o)
    );
    let changes = bridge_run().join("changes.jsonl");
    let o = kpl(&["score", bridge_run().to_str().unwrap(), "--stream", "onroad_car.changes"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("`onroad_car.changes` is not an object stream"), "{}", stderr(&o));
    let o = kpl(&["score", changes.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no ground-truth stream in the recording"), "{}", stderr(&o));
    let o = kpl(&["score", tracks().to_str().unwrap(), "--truth", "tracker.truht"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("no stream `tracker.truht` in the recording; did you mean `tracker.truth`?"),
        "{}",
        stderr(&o)
    );

    // Malformed lines are counted and reported; the scoring goes on.
    let bad_path = dir.join("bad.jsonl");
    std::fs::write(
        &bad_path,
        format!("{text}not json\n{{\"stream\":\"tracker\",\"valid\":1,\"value\":[{{\"id\":\"vp1\"}}]}}\n"),
    )
    .unwrap();
    let o = kpl(&["score", "--format", "json", bad_path.to_str().unwrap(), "--missing", "skip"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(n(&report["problems"]["count"]), 2, "{}", report["problems"]);
    assert!(stderr(&o).contains("bad.jsonl:"), "{}", stderr(&o));

    // Not a recording at all; usage errors.
    let o = kpl(&["score", "/dev/zero"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("/dev/zero: not a file or a folder"), "{}", stderr(&o));
    let o = kpl(&["score", dir.join("nothing-here").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = kpl(&["score", tracks().to_str().unwrap(), "--max-distance=-1"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("-1 m is out of range: a distance is more than 0"), "{}", stderr(&o));
    let empty_dir = scratch("empty");
    let o = kpl(&["score", empty_dir.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("no recordings (`*.jsonl` files) in this folder"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&dir);
    let _ = std::fs::remove_dir_all(&empty_dir);
}
