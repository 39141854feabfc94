//! Properties of anchoring over random percept traces (two percept sources fused into world
//! objects, on-road objects above them, maintain conditions that fail, forgetting), checked after
//! every step from the engine's public views only:
//!
//! - no object is linked from two objects by one link specification (and no object links to two
//!   objects by one);
//! - an object is anchored exactly when it is grounded: a percept, or reachable by links from one
//!   (computed here by a search of the structures);
//! - an object is removed as forgotten only once it has not been anchored for its type's forget
//!   time, and every object that has not been anchored for that long is gone; a percept its
//!   source stops listing is removed exactly when it has not been listed for its type's forget
//!   time (0 for radar percepts, 300 ms for vision percepts); a branch object (a hypothesis of a
//!   predicted object) has been unanchored since its owner was last anchored;
//! - the same trace gives the same structures (determinism).
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use kpl_anchor::{Anchoring, Cause, ChangeKind, Snapshot};
use kpl_core::{Time, Value};
use proptest::prelude::*;

const SPEC: &str = r#"
type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
type RadarPercept  symbol rp { pos: vec2, vel: vec2, size: float }
type WorldObject   symbol wo { pos: vec2, vel: vec2 }
type OnRoadObject  : WorldObject symbol oo { road: int, lane_offset: float }

source camera : list<VisionPercept> = engine.input()
source radar  : list<RadarPercept>  = engine.input()

link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
  establish   eventually[300ms, inf] true
  reestablish eventually[0, 500ms] xydist(from.pos, to.pos) < 6.0
  maintain    always from.size > 1.0
}
link radar_world : RadarPercept -> WorldObject via anchor.world_from_percept {
  establish   eventually[500ms, inf] true
  reestablish eventually[0, 500ms] xydist(from.pos, to.pos) < 6.0
  maintain    true
}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "crossing") {
  establish   eventually[200ms, inf] always[0, 300ms] on_road(from.pos)
  reestablish eventually[0, 500ms] xydist(from.pos, to.pos) < 8.0
  maintain    always eventually[0, 1s] on_road(from.pos)
}
predict WorldObject  = constant_velocity
predict OnRoadObject = along_roads(scenario: "crossing")
forget WorldObject after 1s
forget OnRoadObject after 1500ms
forget VisionPercept after 300ms
"#;

const PERCEPT_TYPES: [&str; 2] = ["VisionPercept", "RadarPercept"];

fn forget_after(ty: &str) -> Option<Time> {
    match ty {
        "WorldObject" => Some(1_000_000),
        "OnRoadObject" => Some(1_500_000),
        _ => None,
    }
}

/// How long a percept its source stops listing is kept (absent) before it is removed.
fn percept_grace(ty: &str) -> Time {
    match ty {
        "VisionPercept" => 300_000,
        _ => 0,
    }
}

/// One percept track: which steps it is listed at, where, and how big.
#[derive(Debug, Clone)]
struct Track {
    camera: bool,
    present: Vec<bool>,
    start: (f64, f64),
    vel: (f64, f64),
    sizes: Vec<f64>,
}

fn track(steps: usize) -> impl Strategy<Value = Track> {
    (
        any::<bool>(),
        proptest::collection::vec(prop_oneof![3 => Just(true), 1 => Just(false)], steps),
        (-30.0f64..30.0, -30.0f64..30.0),
        (-8.0f64..8.0, -8.0f64..8.0),
        proptest::collection::vec(prop_oneof![5 => 1.5f64..5.0, 1 => 0.3f64..1.0], steps),
    )
        .prop_map(|(camera, present, start, vel, sizes)| Track { camera, present, start, vel, sizes })
}

fn percept(id: &str, t: f64, track: &Track, step: usize) -> Value {
    let (x, y) = (track.start.0 + track.vel.0 * t, track.start.1 + track.vel.1 * t);
    common::percept(id, [x, y], [track.vel.0, track.vel.1], track.sizes[step])
}

fn snapshots(tracks: &[Track], step: usize) -> (Value, Value) {
    let t = step as f64 / 10.0;
    let (mut camera, mut radar) = (Vec::new(), Vec::new());
    for (i, track) in tracks.iter().enumerate() {
        if !track.present[step] {
            continue;
        }
        if track.camera {
            camera.push(percept(&format!("vp{}", i + 1), t, track, step));
        } else {
            radar.push(percept(&format!("rp{}", i + 1), t, track, step));
        }
    }
    (Value::List(camera.into()), Value::List(radar.into()))
}

fn engine() -> Anchoring {
    common::engine(SPEC)
}

/// Runs the trace and checks the properties after every step; returns the structures.
fn run(tracks: &[Track], steps: usize) -> Result<Vec<String>, TestCaseError> {
    let mut anchoring = engine();
    let mut last_anchored: BTreeMap<(String, String), Time> = BTreeMap::new();
    let mut last_listed: BTreeMap<String, Time> = BTreeMap::new();
    let mut structures = Vec::new();
    let (mut forgotten, mut linked) = (0, 0);
    for step in 0..steps {
        let time = step as Time * 100_000;
        let (camera, radar) = snapshots(tracks, step);
        let output = anchoring
            .step(
                time,
                &[
                    Snapshot { source: "camera", ty: "VisionPercept", objects: &camera },
                    Snapshot { source: "radar", ty: "RadarPercept", objects: &radar },
                ],
            )
            .unwrap();
        prop_assert!(output.warnings.is_empty(), "{:?}", output.warnings);
        let views = anchoring.objects();
        for list in [&camera, &radar] {
            let Value::List(items) = list else { unreachable!() };
            for item in items.iter() {
                last_listed.insert(item.as_record().unwrap().id.as_deref().unwrap().to_string(), time);
            }
        }

        // Removal only after the forget time.
        for change in &output.changes {
            if change.kind == ChangeKind::Created && change.cause == Cause::Branch {
                // A branch is a hypothesis of its owner: unanchored for as long as the owner.
                let owner = change.branch_of.as_deref().expect("a branch names its owner");
                let since = last_anchored[&(change.ty.to_string(), owner.to_string())];
                last_anchored.insert((change.ty.to_string(), change.symbol.to_string()), since);
            }
            if change.kind == ChangeKind::Removed && change.cause == Cause::Forgotten {
                forgotten += 1;
                let key = (change.ty.to_string(), change.symbol.to_string());
                let last = last_anchored[&key];
                let after = forget_after(&change.ty).unwrap();
                prop_assert!(
                    time - last >= after,
                    "{} forgotten at {time}, last anchored at {last}",
                    change.symbol
                );
            }
            if change.kind == ChangeKind::Linked {
                linked += 1;
            }
            if change.kind == ChangeKind::Removed && change.cause == Cause::Lost {
                let absent = time - last_listed[&*change.symbol];
                prop_assert!(
                    absent >= percept_grace(&change.ty).max(1),
                    "{} removed after {absent} us",
                    change.symbol
                );
            }
        }

        // No object linked from (or to) two objects by one link specification.
        for view in &views {
            for list in [&view.from, &view.to] {
                let links: Vec<&Arc<str>> = list.iter().map(|(link, _)| link).collect();
                let distinct: BTreeSet<&Arc<str>> = links.iter().copied().collect();
                prop_assert_eq!(
                    links.len(),
                    distinct.len(),
                    "{} has two links of one specification: {:?}",
                    view.symbol,
                    list
                );
            }
        }

        // Anchored exactly when grounded: reachable from a percept along links.
        let by_symbol: BTreeMap<&str, &kpl_anchor::ObjectView> =
            views.iter().map(|v| (&*v.symbol, v)).collect();
        let mut grounded: BTreeSet<&str> = BTreeSet::new();
        let mut stack: Vec<&str> =
            views.iter().filter(|v| PERCEPT_TYPES.contains(&&*v.ty)).map(|v| &*v.symbol).collect();
        while let Some(symbol) = stack.pop() {
            if grounded.insert(symbol) {
                stack.extend(by_symbol[symbol].to.iter().map(|(_, s)| &**s));
            }
        }
        for view in &views {
            prop_assert_eq!(view.anchored, grounded.contains(&*view.symbol), "{}", view.symbol);
            // Both ends of every link are in the store and agree.
            for (link, to) in &view.to {
                prop_assert!(by_symbol[&**to].from.contains(&(link.clone(), view.symbol.clone())));
            }
        }

        // Every object not anchored for its forget time is gone.
        for view in &views {
            let key = (view.ty.to_string(), view.symbol.to_string());
            let last = last_anchored.entry(key).or_insert(time);
            if view.anchored {
                *last = time;
            }
            if PERCEPT_TYPES.contains(&&*view.ty) {
                let absent = time - last_listed[&*view.symbol];
                prop_assert!(
                    absent < percept_grace(&view.ty).max(1),
                    "{} absent for {absent} us, still there",
                    view.symbol
                );
                prop_assert_eq!(view.measured, absent == 0);
            }
            if let Some(after) = forget_after(&view.ty) {
                prop_assert!(
                    view.anchored || time - *last < after,
                    "{} unanchored since {last}, still there at {time}",
                    view.symbol
                );
            }
        }
        structures.push(anchoring.describe());
    }
    let _ = (forgotten, linked);
    Ok(structures)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn structures_stay_consistent(tracks in proptest::collection::vec(track(60), 1..8)) {
        let first = run(&tracks, 60)?;
        let second = run(&tracks, 60)?;
        prop_assert_eq!(first, second, "the same trace gave different structures");
    }
}

/// The random traces exercise what the properties are about: links made and broken by every
/// cause, fused world objects, predictions and forgetting (so the properties are not vacuous).
#[test]
fn the_traces_exercise_every_kind_of_change() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::TestRunner;
    let mut runner = TestRunner::deterministic();
    let mut seen: BTreeSet<(ChangeKind, Cause)> = BTreeSet::new();
    let mut fused = 0;
    for _ in 0..40 {
        let tracks = proptest::collection::vec(track(60), 3..8).new_tree(&mut runner).unwrap().current();
        let mut anchoring = engine();
        for step in 0..60 {
            let (camera, radar) = snapshots(&tracks, step);
            let output = anchoring
                .step(
                    step as Time * 100_000,
                    &[
                        Snapshot { source: "camera", ty: "VisionPercept", objects: &camera },
                        Snapshot { source: "radar", ty: "RadarPercept", objects: &radar },
                    ],
                )
                .unwrap();
            seen.extend(output.changes.iter().map(|c| (c.kind, c.cause)));
            fused += anchoring.objects().iter().filter(|v| v.from.len() > 1).count();
        }
    }
    for wanted in [
        (ChangeKind::Created, Cause::Establish),
        (ChangeKind::Linked, Cause::Establish),
        (ChangeKind::Linked, Cause::Reestablish),
        (ChangeKind::Unlinked, Cause::Maintain),
        (ChangeKind::Unlinked, Cause::FromRemoved),
        (ChangeKind::Predicted, Cause::NoIncomingLink),
        (ChangeKind::Removed, Cause::Forgotten),
        (ChangeKind::Removed, Cause::Lost),
    ] {
        assert!(seen.contains(&wanted), "never saw {wanted:?}; saw {seen:?}");
    }
    assert!(fused > 0, "no world object was ever linked from a camera and a radar percept at once");
}
