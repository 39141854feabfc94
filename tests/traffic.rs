//! The shipped traffic specs end to end, as a user runs them: `kpl run`, then `kpl score` and
//! `kpl plot` on what the run recorded.
//! - `specs/traffic/fig5.kpl` (the DyKnow paper's Fig. 5): four percept tracks, one symbol per
//!   level through all of them, predicted states in the gaps, branch objects in the crossing; and
//!   its picture shows that.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

mod common;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use common::{kpl, lines};
use serde_json::Value;

fn run(spec: &str, name: &str) -> PathBuf {
    let out = common::fresh_dir("traffic", name);
    let result = kpl(&["run", "--quiet", spec, "--out", out.to_str().unwrap()]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    out
}

fn score(out: &Path, extra: &[&str]) -> Value {
    let mut args = vec!["score", out.to_str().unwrap(), "--format", "json"];
    args.extend_from_slice(extra);
    let result = kpl(&args);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    serde_json::from_slice(&result.stdout).unwrap()
}

fn stream<'a>(scores: &'a Value, name: &str) -> &'a Value {
    scores["streams"].as_array().unwrap().iter().find(|s| s["stream"] == name).unwrap()
}

/// The ids of a recorded stream's objects, leaving out branch objects (`branch_of`).
fn ids(records: &[Value], stream: &str) -> BTreeSet<String> {
    let mut ids = BTreeSet::new();
    for r in records.iter().filter(|r| r["stream"] == stream) {
        for o in r["value"].as_array().unwrap() {
            if o.get("branch_of").is_none() {
                ids.insert(o["id"].as_str().unwrap().to_string());
            }
        }
    }
    ids
}

#[test]
fn fig5_keeps_one_symbol_per_level_through_four_percept_tracks() {
    let out = run("specs/traffic/fig5.kpl", "fig5");
    let records = lines(&out.join("fig5/tracks.jsonl"));
    assert_eq!(ids(&records, "tracker").len(), 4, "four tracks, a new percept id each");
    for (level, symbol) in [("vision_world", "wo1"), ("world_onroad", "oo1"), ("onroad_car", "co1")] {
        assert_eq!(ids(&records, level), BTreeSet::from([symbol.to_string()]), "{level}");
    }
    // Predicted states in the gaps, and at the crossing one branch object per other way out.
    let predicted = records
        .iter()
        .filter(|r| r["stream"] == "world_onroad")
        .flat_map(|r| r["value"].as_array().unwrap().iter())
        .filter(|o| o["measured"] == false && o.get("branch_of").is_none())
        .count();
    assert!(predicted >= 20, "{predicted} predicted on-road states");
    let branches: BTreeSet<&str> = records
        .iter()
        .filter(|r| r["stream"] == "world_onroad")
        .flat_map(|r| r["value"].as_array().unwrap().iter())
        .filter(|o| o["branch_of"] == "oo1")
        .map(|o| o["id"].as_str().unwrap())
        .collect();
    assert_eq!(branches.len(), 2, "{branches:?}");
    // kpl score agrees: no identity switch at any level above the percepts, the percepts' three
    // (measured states: in the crossing a branch object may pass closer to the car than `oo1`).
    let scores = score(&out, &["--measured-only"]);
    assert_eq!(stream(&scores, "tracker")["clear"]["switches"], 3);
    for level in ["vision_world", "world_onroad", "onroad_car"] {
        assert_eq!(stream(&scores, level)["clear"]["switches"], 0, "{level}");
    }

    // The picture: the four percept tracks labelled, the on-road object's squares, hollow ones.
    let result = kpl(&[
        "plot",
        out.to_str().unwrap(),
        "--network",
        "specs/traffic/fig5/crossing.json",
        "--stream",
        "tracker",
        "--stream",
        "world_onroad",
    ]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let svg = std::fs::read_to_string(out.join("plot.svg")).unwrap();
    for label in ["vp1", "vp2", "vp3", "vp4", "oo1", "oo2", "oo3"] {
        assert_eq!(svg.matches(&format!(">{label}</text>")).count(), 1, "{label}");
    }
    let hollow = svg.matches(r##"fill="none" stroke="#1f5fbf""##).count();
    assert!(hollow >= 20, "{hollow} hollow squares");
    // The trees and the overpass are drawn.
    for occluder in ["trees1", "trees2", "overpass"] {
        assert!(svg.contains(&format!("<title>{occluder}</title>")), "{occluder}");
    }
}

#[test]
fn plot_refuses_what_it_cannot_draw_and_says_why() {
    let out = run("specs/traffic/fig5.kpl", "fig5-errors");
    let dir = out.to_str().unwrap();
    let unknown = kpl(&["plot", dir, "--stream", "world_onroads"]);
    assert_eq!(unknown.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("did you mean `world_onroad`?"));
    let window = kpl(&["plot", dir, "--from", "5s", "--to", "2s"]);
    assert_eq!(window.status.code(), Some(2));
    let scenario = kpl(&["plot", dir, "--scenario", "atlantis"]);
    assert_eq!(scenario.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&scenario.stderr).contains("no built-in road network `atlantis`"));
    // An empty window is drawn, and said to be empty.
    let empty = kpl(&["plot", dir, "--from", "100s", "-o", out.join("empty.svg").to_str().unwrap()]);
    assert!(empty.status.success());
    assert!(String::from_utf8_lossy(&empty.stderr).contains("nothing to draw"));
}
