//! Link processes as DyKnow's knowledge processes, at the level of specs run by the runtime
//! (`kpl run` with simulated time): each link subscribes to its own input streams with their
//! policies, and its states come from the runtime's state synchronization.
//!
//! - The input policy of a link in a chain changes its decisions (`sample every 2s` on the world
//!   objects makes `world_onroad` step, and so decide, every 2 s).
//! - `no approximation` leaves a source that did not report missing: its percepts are not stepped
//!   at the other source's states (with `use most recent` they are, held over and not measured).
//! - Two sources reporting at one valid time make one state (one step, one output), not two
//!   steps a microsecond apart.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use kpl_core::Time;
use kpl_runtime::RunConfig;

/// A fresh directory for one test's run.
fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-anchor-links-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Every recorded sample by stream: valid time -> value (one sample per time and stream).
type Recorded = BTreeMap<String, BTreeMap<Time, serde_json::Value>>;

/// Checks `text` against the runtime's registry and runs it with simulated time for `duration`,
/// reading relative paths from `dir` and writing there; returns what `path` recorded.
fn run(text: &str, dir: &Path, duration: Time, path: &str) -> Recorded {
    let registry = kpl_std::registry();
    let parse = kpl_syntax::parse(text);
    assert!(!parse.has_errors(), "{:?}", parse.diagnostics);
    let checked = kpl_semantic::check(&parse.spec, registry.signatures());
    assert!(!checked.has_errors(), "{:?}", checked.diagnostics);
    let spec = checked.spec.unwrap();
    let config = RunConfig {
        duration: Some(duration),
        seed: 3,
        out_dir: dir.to_path_buf(),
        spec_dir: dir.to_path_buf(),
        spec_name: "links".into(),
        ..RunConfig::default()
    };
    let report = kpl_runtime::run(&spec, &registry, &config, None).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    for process in &report.summary.processes {
        assert_eq!(process.errors, 0, "{process:?}");
    }
    let mut out: Recorded = BTreeMap::new();
    for line in std::fs::read_to_string(dir.join(path)).unwrap().lines() {
        let j: serde_json::Value = serde_json::from_str(line).unwrap();
        let stream = j["stream"].as_str().unwrap().to_string();
        let valid = j["valid"].as_i64().unwrap();
        let previous = out.entry(stream.clone()).or_default().insert(valid, j["value"].clone());
        assert!(previous.is_none(), "two samples of {stream} at {valid}");
    }
    out
}

/// The change records of a link's `changes` stream: (time, kind, cause, symbol, from).
fn changes(recorded: &Recorded, stream: &str) -> Vec<(Time, String, String, String, String)> {
    let text = |v: &serde_json::Value| v.as_str().unwrap_or("").to_string();
    recorded
        .get(stream)
        .into_iter()
        .flat_map(|samples| samples.iter())
        .flat_map(|(t, list)| {
            list.as_array().unwrap().iter().map(move |c| {
                assert_eq!(c["time"].as_i64(), Some(*t), "a change is emitted at its own time");
                (*t, text(&c["kind"]), text(&c["cause"]), text(&c["symbol"]), text(&c["from"]))
            })
        })
        .collect()
}

fn bridge() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic/bridge.kpl");
    std::fs::read_to_string(path).unwrap()
}

/// `stream wos = vision_world with sample every 2s` as the input of `world_onroad`: the link
/// steps every 2 s, on the world objects as they were then, so it outputs and decides only at
/// multiples of 2 s, and its decisions are not those of the default policy (every update).
#[test]
fn the_input_policy_of_a_chained_link_changes_its_decisions() {
    let record = "\nsink recorded = file.jsonl(vision_world, world_onroad, world_onroad.changes, path: \"all.jsonl\")\n";
    let default_dir = fresh_dir("policy-default");
    let default = run(&format!("{}{record}", bridge()), &default_dir, 30_000_000, "all.jsonl");

    let sampled_text = bridge().replace(
        "link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: \"bridge\") {\n",
        "stream wos = vision_world with sample every 2s\nlink world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: \"bridge\") {\n  input       wos\n",
    );
    assert!(sampled_text.contains("input       wos"));
    let sampled_dir = fresh_dir("policy-sampled");
    let sampled = run(&format!("{sampled_text}{record}"), &sampled_dir, 30_000_000, "all.jsonl");

    // vision_world still runs at 10 Hz; world_onroad only every 2 s.
    assert!(sampled["vision_world"].len() >= 290, "{}", sampled["vision_world"].len());
    let steps: Vec<Time> = sampled["world_onroad"].keys().copied().collect();
    assert!(steps.len() >= 14 && steps.len() <= 16, "{steps:?}");
    assert!(steps.iter().all(|t| t % 2_000_000 == 0), "{steps:?}");
    assert!(default["world_onroad"].len() >= 290);

    // Decisions only at its states, and not the default policy's.
    let decisions = changes(&sampled, "world_onroad.changes");
    let established: Vec<_> = decisions.iter().filter(|c| c.2 == "establish").collect();
    assert!(!established.is_empty(), "{decisions:?}");
    assert!(decisions.iter().all(|c| c.0 % 2_000_000 == 0), "{decisions:?}");
    let default_decisions = changes(&default, "world_onroad.changes");
    assert!(
        default_decisions.iter().any(|c| c.2 == "establish" && c.0 % 2_000_000 != 0),
        "{default_decisions:?}"
    );
    assert_ne!(decisions, default_decisions);
    // What it decided at a state, it decided on the world objects of that state.
    for (t, objects) in &sampled["world_onroad"] {
        assert_eq!(objects.as_array().map(Vec::len).unwrap_or(0) > 0, established.iter().any(|c| c.0 <= *t));
    }
    let _ = std::fs::remove_dir_all(&default_dir);
    let _ = std::fs::remove_dir_all(&sampled_dir);
}

/// A percept line of a replayed tracker file.
fn frame(stream: &str, t: Time, percepts: &[(&str, f64)]) -> String {
    let items: Vec<serde_json::Value> = percepts
        .iter()
        .map(|(id, x)| serde_json::json!({"id": id, "pos": [x, -1.75], "vel": [10.0, 0.0], "size": 4.0}))
        .collect();
    serde_json::json!({"stream": stream, "valid": t, "value": items}).to_string()
}

/// Two trackers replayed from files: `fast` reports every 100 ms (percept a1), `slow` every 500 ms
/// (percept b1), both for 3 s.
fn two_trackers(dir: &Path) {
    let mut fast = Vec::new();
    let mut slow = Vec::new();
    for i in 0..=30 {
        let t = i * 100_000;
        let x = -100.0 + 10.0 * t as f64 / 1e6;
        fast.push(frame("fast", t, &[("a1", x)]));
        if i % 5 == 0 {
            slow.push(frame("slow", t, &[("b1", x + 20.0)]));
        }
    }
    std::fs::write(dir.join("fast.jsonl"), fast.join("\n") + "\n").unwrap();
    std::fs::write(dir.join("slow.jsonl"), slow.join("\n") + "\n").unwrap();
}

fn two_tracker_spec(slow_policy: &str) -> String {
    format!(
        r#"
type VisionPercept symbol vp {{ pos: vec2, vel: vec2, size: float }}
type WorldObject symbol wo {{ pos: vec2, vel: vec2 }}
source fast : list<VisionPercept> = file.jsonl(path: "fast.jsonl")
source slow : list<VisionPercept> = file.jsonl(path: "slow.jsonl")
stream slow_percepts = slow with {slow_policy}
// A world object stays linked to its percept as long as every state of the link measures it.
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {{
  input       fast
  input       slow_percepts
  establish   eventually[300ms, inf] true
  reestablish eventually[0, 1s] (xydist(from.pos, to.pos) < 5.0)
  maintain    always from.measured
}}
predict WorldObject = constant_velocity
sink recorded = file.jsonl(vision_world, vision_world.changes, path: "all.jsonl")
"#
    )
}

/// With `no approximation` (the default), the slow tracker is missing at the fast tracker's
/// other states: its percept is not stepped there, so `always from.measured` holds. With `use
/// most recent` its last snapshot is held over: the percept is stepped with that old state, not
/// measured now, and the maintain condition fails at the first such state.
#[test]
fn no_approximation_leaves_a_source_that_did_not_report_missing() {
    let dir = fresh_dir("missing");
    two_trackers(&dir);
    let missing = run(&two_tracker_spec("no approximation, strict order"), &dir, 3_100_000, "all.jsonl");
    let held = run(&two_tracker_spec("use most recent, strict order"), &dir, 3_100_000, "all.jsonl");

    // Both percepts became world objects (after 300 ms of their own states).
    let created = |r: &Recorded| -> Vec<(Time, String)> {
        changes(r, "vision_world.changes")
            .into_iter()
            .filter(|c| c.1 == "created" && c.2 == "establish")
            .map(|c| (c.0, c.4))
            .collect()
    };
    assert_eq!(created(&missing), vec![(300_000, "a1".to_string()), (500_000, "b1".to_string())]);
    let unlinked =
        |r: &Recorded| changes(r, "vision_world.changes").into_iter().filter(|c| c.1 == "unlinked").count();
    assert_eq!(unlinked(&missing), 0, "{:?}", changes(&missing, "vision_world.changes"));
    // b1's world object is measured at the slow tracker's states and held (not measured) between.
    let b1_world = |r: &Recorded, t: Time| -> serde_json::Value {
        r["vision_world"][&t].as_array().unwrap().iter().find(|o| o["id"] == "wo2").cloned().unwrap()
    };
    assert_eq!(b1_world(&missing, 1_000_000)["measured"], true);
    assert_eq!(b1_world(&missing, 1_100_000)["measured"], false);
    assert_eq!(b1_world(&missing, 1_100_000)["predicted_since"], 1_100_000);

    // Held over: b1 is stepped at 0.6 s with its 0.5 s state, not measured, and its link fails.
    let held_changes = changes(&held, "vision_world.changes");
    assert!(
        held_changes.contains(&(
            600_000,
            "unlinked".to_string(),
            "maintain".to_string(),
            "wo2".to_string(),
            "b1".to_string()
        )),
        "{held_changes:?}"
    );
    assert!(held_changes.iter().all(|c| c.4 != "a1" || c.1 != "unlinked"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Two trackers reporting at the same valid times are one state of the link: one step and one
/// output per time (not two steps a microsecond apart), with both percepts in it.
#[test]
fn two_sources_at_one_valid_time_make_one_state() {
    let dir = fresh_dir("one-state");
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for i in 0..=20 {
        let t = i * 100_000;
        let x = -100.0 + t as f64 / 1e5;
        a.push(frame("a", t, &[("a1", x)]));
        b.push(frame("b", t, &[("b1", x + 30.0)]));
    }
    std::fs::write(dir.join("a.jsonl"), a.join("\n") + "\n").unwrap();
    std::fs::write(dir.join("b.jsonl"), b.join("\n") + "\n").unwrap();
    let text = r#"
type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
type WorldObject symbol wo { pos: vec2, vel: vec2 }
source a : list<VisionPercept> = file.jsonl(path: "a.jsonl")
source b : list<VisionPercept> = file.jsonl(path: "b.jsonl")
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
  input       a
  input       b
  establish   eventually[1s, inf] true
  reestablish eventually[0, 1s] (xydist(from.pos, to.pos) < 5.0)
  maintain    true
}
sink recorded = file.jsonl(vision_world, vision_world.changes, path: "all.jsonl")
"#;
    let recorded = run(text, &dir, 2_100_000, "all.jsonl");
    let times: Vec<Time> = recorded["vision_world"].keys().copied().collect();
    let expected: Vec<Time> = (0..=20).map(|i| i * 100_000).collect();
    assert_eq!(times, expected, "one output per valid time, on the trackers' grid");
    let first = changes(&recorded, "vision_world.changes");
    let at_zero: Vec<_> = first.iter().filter(|c| c.0 == 0).map(|c| (c.1.as_str(), c.3.as_str())).collect();
    assert_eq!(at_zero, vec![("created", "a1"), ("created", "b1")]);
    // Both world objects made at 1 s, in one step, and both in every later output.
    let established: Vec<_> = first.iter().filter(|c| c.1 == "created" && c.2 == "establish").collect();
    assert_eq!(established.iter().map(|c| c.0).collect::<Vec<_>>(), vec![1_000_000, 1_000_000]);
    for t in (10..=20).map(|i| i * 100_000) {
        let objects = recorded["vision_world"][&t].as_array().unwrap();
        assert_eq!(objects.len(), 2, "at {t}: {objects:?}");
        assert!(objects.iter().all(|o| o["measured"] == true));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
