//! End-to-end tests of `specs/gearbox/assembly.kpl`: `kpl run` the AAPA paper's gearbox assembly
//! (`sim.gearbox` into `aapa.anchor`, its world fed back) and check the recorded output:
//! - every part keeps its symbol on the right object through all five steps, while the detector's
//!   own labels (the control) land on other objects;
//! - parts go out of view and are carried while attached, and the attachments of the assembly are
//!   in the final world state;
//! - the recorded world states are those of the library run directly (the runtime's wiring,
//!   synchronization and feedback add nothing and lose nothing);
//! - misdeclared specs are refused with a message that says what to fix; an `action_rules` file
//!   replaces the built-in table; two runs record the same bytes.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

mod common;

use std::collections::{BTreeMap, BTreeSet};

use common::{kpl, root};

use kpl_aapa::gearbox;
use kpl_aapa::{Aapa, WorldState};
use serde_json::Value;

fn temp_dir(name: &str) -> common::TestDir {
    common::fresh_dir("gearbox", name)
}

/// One recorded cycle: the world state, the detector's frame and the truth, by stream.
#[derive(Debug, Default)]
struct Cycle {
    world: Option<Value>,
    frame: Option<Value>,
    truth: Option<Value>,
}

/// Runs the spec once (shared by the tests) and returns its cycles by valid time.
fn recorded() -> &'static BTreeMap<i64, Cycle> {
    static RUN: std::sync::OnceLock<BTreeMap<i64, Cycle>> = std::sync::OnceLock::new();
    RUN.get_or_init(|| {
        let out = temp_dir("assembly");
        let result = kpl(&["run", "--quiet", "specs/gearbox/assembly.kpl", "--out", out.to_str().unwrap()]);
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        // No process failed, counted an error or a malformed input, and nothing was dropped.
        let summary: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
        assert_eq!(summary["failures"], serde_json::json!([]));
        for process in summary["summary"]["processes"].as_array().unwrap() {
            assert!(process["errors"] == 0 && process["malformed"] == 0, "{process}");
        }
        for stream in summary["summary"]["streams"].as_array().unwrap() {
            assert!(stream["produced"] == stream["delivered"] && stream["produced"] == 206, "{stream}");
        }
        let text = std::fs::read_to_string(out.join("world.jsonl")).unwrap();
        let mut cycles: BTreeMap<i64, Cycle> = BTreeMap::new();
        for line in text.lines() {
            let record: Value = serde_json::from_str(line).unwrap();
            let cycle = cycles.entry(record["valid"].as_i64().unwrap()).or_default();
            let value = Some(record["value"].clone());
            match record["stream"].as_str().unwrap() {
                "world" => cycle.world = value,
                "frames" => cycle.frame = value,
                "gearbox.truth" => cycle.truth = value,
                other => panic!("unexpected stream {other}"),
            }
        }
        cycles
    })
}

fn bbox(v: &Value) -> [f64; 4] {
    let a: Vec<f64> = v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    [a[0], a[1], a[2], a[3]]
}

fn iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let w = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let h = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = w * h;
    inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)
}

fn items<'a>(v: &'a Value, key: &str) -> &'a [Value] {
    v[key].as_array().unwrap()
}

fn find<'a>(list: &'a [Value], key: &str, name: &str) -> Option<&'a Value> {
    list.iter().find(|x| x[key] == name)
}

/// θ_anch of the spec (the paper's gearbox value).
const THETA_ANCH: f64 = 0.5;

#[test]
fn anchors_keep_their_labels_through_all_five_steps() {
    let cycles = recorded();
    assert_eq!(cycles.len(), gearbox::scenario().len(), "one recorded cycle per simulated one");
    let mut anchored: BTreeSet<String> = BTreeSet::new();
    let mut steps = BTreeSet::new();
    let mut checked_detected = 0;
    for (t, cycle) in cycles {
        let (world, truth) = (cycle.world.as_ref().unwrap(), cycle.truth.as_ref().unwrap());
        steps.insert(truth["step"].as_i64().unwrap());
        let anchors = items(world, "anchors");
        let objects = items(truth, "objects");
        for object in objects {
            let name = object["name"].as_str().unwrap();
            let Some(anchor) = find(anchors, "symbol", name) else {
                assert!(!anchored.contains(name), "t={t}: `{name}` was anchored and is gone");
                continue;
            };
            if anchor["confidence"].as_f64().unwrap() >= THETA_ANCH {
                anchored.insert(name.to_string());
            }
            if object["detected"] == true {
                let overlap = iou(bbox(&anchor["box"]), bbox(&object["box"]));
                assert!(overlap > 0.5, "t={t}: the anchor `{name}` is on another object (IoU {overlap:.2})");
                checked_detected += 1;
            }
        }
        // Only real parts are ever anchored: the ghost plug never is.
        for anchor in anchors.iter().filter(|a| a["confidence"].as_f64().unwrap() >= THETA_ANCH) {
            let symbol = anchor["symbol"].as_str().unwrap();
            assert!(find(objects, "name", symbol).is_some(), "t={t}: `{symbol}` is anchored but no object");
        }
        for note in items(world, "notes") {
            assert!(!note.as_str().unwrap().contains("had not come back"), "t={t}: feedback late: {note}");
        }
    }
    assert_eq!(steps, (0..=5).collect(), "every step of the assembly was run");
    let names: BTreeSet<String> = gearbox::scenario()[0].truth.iter().map(|t| t.name.clone()).collect();
    assert_eq!(anchored, names, "every part (and the gripper) was anchored");
    assert!(checked_detected > 500, "{checked_detected} detected object-cycles checked");
    // After step 5 every part is still there, under its own name, confident enough for inference.
    let last = cycles.values().next_back().unwrap().world.as_ref().unwrap();
    for name in &names {
        let anchor = find(items(last, "anchors"), "symbol", name).unwrap();
        assert_eq!(anchor["for_inference"], true, "{name}");
    }
}

#[test]
fn the_detectors_own_labels_do_not_stay_on_their_objects() {
    // The control: the detector numbers each type left to right in every frame, so the label it
    // gives a part is often another part's name; the anchors' symbols never are (test above).
    let (mut mislabelled, mut seen) = (BTreeSet::new(), 0);
    for (t, cycle) in recorded() {
        let percepts = cycle.frame.as_ref().unwrap().as_array().unwrap();
        for object in items(cycle.truth.as_ref().unwrap(), "objects").iter().filter(|o| o["detected"] == true)
        {
            let name = object["name"].as_str().unwrap();
            let percept = percepts.iter().find(|p| iou(bbox(&p["box"]), bbox(&object["box"])) > 0.5).unwrap();
            seen += 1;
            if percept["label"] != name {
                mislabelled.insert((*t, name.to_string()));
            }
        }
    }
    let parts: BTreeSet<&str> = mislabelled.iter().map(|(_, name)| name.as_str()).collect();
    assert!(
        mislabelled.len() >= 10,
        "{} of {seen} detections mislabelled: {mislabelled:?}",
        mislabelled.len()
    );
    assert!(parts.contains("case1") && parts.len() >= 2, "{parts:?}");
}

#[test]
fn parts_go_out_of_view_and_are_carried_while_attached() {
    let cycles = recorded();
    let mut statuses: BTreeSet<(String, String)> = BTreeSet::new();
    let mut carried_in_step5 = false;
    for cycle in cycles.values() {
        let world = cycle.world.as_ref().unwrap();
        for anchor in items(world, "anchors") {
            statuses.insert((
                anchor["symbol"].as_str().unwrap().into(),
                anchor["status"].as_str().unwrap().into(),
            ));
        }
        let holding = |hand: &str, part: &str| {
            items(world, "relations")
                .iter()
                .any(|r| r["name"] == "holding" && r["args"] == serde_json::json!([hand, part]))
        };
        if cycle.truth.as_ref().unwrap()["step"] == 5 && holding("gripper0", "case0") {
            let hub = find(items(world, "anchors"), "symbol", "hub_cover0").unwrap();
            carried_in_step5 |= hub["status"] == "attached";
        }
    }
    for (symbol, status) in [
        ("case1", "out_of_view"),
        ("hub_cover0", "attached"),
        ("input_sub0", "attached"),
        ("plug0", "attached"),
        ("case0", "attached"),
    ] {
        assert!(statuses.contains(&(symbol.into(), status.into())), "`{symbol}` never {status}");
    }
    assert!(carried_in_step5, "the hub cover rides on the carried casing top, two levels below the gripper");
    let last = cycles.values().next_back().unwrap().world.as_ref().unwrap();
    let relations: BTreeSet<(String, String, String)> = items(last, "relations")
        .iter()
        .map(|r| {
            let args = r["args"].as_array().unwrap();
            (
                r["name"].as_str().unwrap().into(),
                args[0].as_str().unwrap().into(),
                args[1].as_str().unwrap().into(),
            )
        })
        .collect();
    for (name, a, b) in [
        ("attached", "hub_cover0", "case0"),
        ("attached", "plug0", "hub_cover0"),
        ("attached", "plug1", "hub_cover0"),
        ("attached", "input_sub0", "case1"),
        ("attached", "case0", "case1"),
        ("inserted", "input_sub0", "case1"),
        ("mounted", "case0", "case1"),
    ] {
        assert!(relations.contains(&(name.into(), a.into(), b.into())), "{name}({a}, {b}) missing");
    }
}

/// Equal JSON, numbers to a relative 1e-9 (JSON text does not round-trip every float's last bit).
fn close(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            (x - y).abs() <= 1e-9 * x.abs().max(y.abs()).max(1.0)
        }
        (Value::Array(x), Value::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(x, y)| close(x, y)),
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| close(v, w)))
        }
        _ => a == b,
    }
}

#[test]
fn the_recorded_world_states_are_the_librarys() {
    // The same scenario through `kpl_aapa` directly, with the spec's parameters.
    let aapa = Aapa::new(gearbox::params()).unwrap();
    let mut world = WorldState::default();
    let cycles = recorded();
    for (c, (t, cycle)) in gearbox::scenario().iter().zip(cycles) {
        assert_eq!(c.time, *t);
        world = aapa.step(c.time, &c.percepts, &c.actions, Some(&c.camera), &world).unwrap();
        let recorded: WorldState = serde_json::from_value(cycle.world.clone().unwrap()).unwrap();
        let (got, want) = (serde_json::to_value(&recorded).unwrap(), serde_json::to_value(&world).unwrap());
        assert!(close(&got, &want), "t={t}:\n{got}\n{want}");
    }
}

#[test]
fn misdeclared_specs_are_refused_with_what_to_fix() {
    let dir = temp_dir("errors");
    std::fs::write(
        dir.join("old.jsonl"),
        "{\"valid\": 0, \"value\": {\"anchors\": [], \"relations\": []}}\n",
    )
    .unwrap();
    let spec = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path.to_str().unwrap().to_string()
    };
    let header = "type Detection { label: string, type: string, box: box }\n\
                  source gearbox : list<Detection> = sim.gearbox()\n";
    let camera = "image: [640.0, 480.0], focal_px: 600.0, surface_z: 0.6";
    let cases = [
        // `kpl check`: the percepts lack a field the unit needs.
        (
            "check",
            format!(
                "type Seen {{ label: string, box: box }}\n{header}source seen : list<Seen> = file.jsonl(path: \"old.jsonl\")\n\
                 compute world = aapa.anchor(seen, gearbox.actions, gearbox.camera, previous)\n\
                 stream previous = world with feedback\nsink s = file.jsonl(world, path: \"w.jsonl\")\n"
            ),
            "input `percepts` of `aapa.anchor` takes list<{ label: string, type: string, box: box }>",
        ),
        // `kpl run`: the previous world is not fed back.
        (
            "run",
            format!(
                "{header}source old : any = file.jsonl(path: \"old.jsonl\")\n\
                 compute world = aapa.anchor(gearbox, gearbox.actions, gearbox.camera, old, {camera})\n\
                 sink s = file.jsonl(world, path: \"w.jsonl\")\n"
            ),
            "input `previous` (old) must be a feedback stream",
        ),
        // `kpl run`: an anchor type naming a field the world state does not have.
        (
            "run",
            format!(
                "{header}type Anchor {{ symbol: string, colour: string }}\n\
                 type World {{ anchors: list<Anchor>, relations: list<any> }}\n\
                 compute world : World = aapa.anchor(gearbox, gearbox.actions, gearbox.camera, previous, {camera})\n\
                 stream previous = world with feedback\nsink s = file.jsonl(world, path: \"w.jsonl\")\n"
            ),
            "`Anchor` declares `colour`, which aapa.anchor's anchors do not have",
        ),
        // `kpl run`: parameters outside the paper's constraints.
        (
            "run",
            format!(
                "{header}compute world = aapa.anchor(gearbox, gearbox.actions, gearbox.camera, previous, \
                 theta_anch: 0.9, theta_inf: 0.5, {camera})\n\
                 stream previous = world with feedback\nsink s = file.jsonl(world, path: \"w.jsonl\")\n"
            ),
            "invalid parameter `theta_inf`: must be in [theta_anch, 1]",
        ),
    ];
    for (k, (command, text, expected)) in cases.iter().enumerate() {
        let path = spec(&format!("case{k}.kpl"), text);
        let out_dir = dir.join(format!("out{k}"));
        let output = match *command {
            "check" => kpl(&["check", &path]),
            _ => kpl(&["run", "--quiet", &path, "--out", out_dir.to_str().unwrap()]),
        };
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "case {k}: {stderr}");
        assert!(stderr.contains(expected), "case {k}: expected `{expected}` in:\n{stderr}");
    }
}

#[test]
fn an_action_rules_file_replaces_the_built_in_table() {
    // Only `pick_up` has an effect: the parts stay in the gripper (no `release` rule) and nothing
    // is inserted, screwed or mounted.
    let dir = temp_dir("rules");
    let rules = r#"[{"action": "pick_up", "phase": "completed", "effects": [{"effect": "attach", "child": 1,
        "parent": 0, "relation": {"name": "holding", "args": [0, 1]}}]}]"#;
    std::fs::write(dir.join("rules.json"), rules).unwrap();
    let spec = std::fs::read_to_string(root().join("specs/gearbox/assembly.kpl")).unwrap();
    let spec = spec.replace("surface_z: 0.6,\n", "surface_z: 0.6,\n  action_rules: \"rules.json\",\n");
    assert!(spec.contains("rules.json"), "the spec's text changed");
    std::fs::write(dir.join("assembly.kpl"), spec).unwrap();
    let out = dir.join("out");
    let result =
        kpl(&["run", "--quiet", dir.join("assembly.kpl").to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let text = std::fs::read_to_string(out.join("world.jsonl")).unwrap();
    let last_world: Value = text
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .rfind(|r| r["stream"] == "world")
        .unwrap()["value"]
        .clone();
    let names: BTreeSet<&str> =
        items(&last_world, "relations").iter().map(|r| r["name"].as_str().unwrap()).collect();
    assert!(names.contains("holding"), "{names:?}");
    for absent in ["inserted", "screwed", "mounted"] {
        assert!(!names.contains(absent), "{absent} without a rule for it: {names:?}");
    }
    // A file that is not a list of rules is refused before the run, naming the file.
    std::fs::write(dir.join("rules.json"), r#"[{"action": "pick_up", "effects": [{"effect": "glue"}]}]"#)
        .unwrap();
    let result =
        kpl(&["run", "--quiet", dir.join("assembly.kpl").to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("rules.json: not a list of action rules"), "{stderr}");
}

#[test]
fn a_run_is_reproducible_byte_for_byte() {
    let read = |name: &str| {
        let out = temp_dir(name);
        let result = kpl(&["run", "--quiet", "specs/gearbox/assembly.kpl", "--out", out.to_str().unwrap()]);
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        std::fs::read(out.join("world.jsonl")).unwrap()
    };
    let (a, b) = (read("repro-a"), read("repro-b"));
    assert!(a.len() > 100_000);
    assert!(a == b, "two runs of the spec recorded different bytes");
}
