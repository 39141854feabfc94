//! Example IV.1 of the DyKnow anchoring paper, replayed as a trace: a car seen as the vision
//! percept vp1 becomes the world object wo1 and then the on-road object oo1; the tracker loses it
//! (it drives under the bridge), so wo1 and oo1 are predicted along the road; a new percept vp2
//! appears, its establish condition becomes false and reestablish(vp2, wo1) true, so vp2 is
//! linked to wo1 and oo1 is anchored again. Every intermediate structure is checked: the objects,
//! their status, each link instance with its pending conditions, and the changes of each step.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use std::sync::Arc;

use kpl_anchor::{Anchoring, InstanceView, Snapshot, Status};
use kpl_core::{Time, Value};

const SPEC: &str = r#"
type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
type WorldObject   symbol wo { pos: vec2, vel: vec2 }
type OnRoadObject  : WorldObject symbol oo { road: int, lane_offset: float }

source tracker : list<VisionPercept> = engine.input()

// A percept is a new world object if it stays big enough for half a second and nothing known
// was reacquired within a second; it is a known world object if it stays within 10 m of it for
// 300 ms, within a second.
link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
  establish   eventually[1s, inf] true and always[0, 500ms] from.size > 2.0
  reestablish eventually[0, 1s] always[0, 300ms] xydist(from.pos, to.pos) < 10.0
  maintain    true
}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "bridge") {
  establish   eventually[1s, inf] always[0, 1s] on_road(from.pos)
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    always eventually[0, 10s] always[0, 1s] on_road(from.pos)
}
predict WorldObject  = constant_velocity
predict OnRoadObject = along_roads(scenario: "bridge")
forget after 30s
"#;

const SPEED: f64 = 12.0;
/// The eastbound lane of the bridge scenario's road `main` is at y = -1.75.
const LANE_Y: f64 = -1.75;

fn percept(id: &str, x: f64, y: f64, size: f64) -> Value {
    common::percept(id, [x, y], [SPEED, 0.0], size)
}

/// The tracker's snapshot at step `i` (100 ms apart): vp1 from 0 to 4.9 s, nothing from 5.0 to
/// 6.9 s (under the bridge), vp2 from 7.0 s, 3 m ahead of where wo1 is predicted, small (1.5 m,
/// half hidden) at 7.1 and 7.2 s.
fn snapshot(i: i64) -> Value {
    let t = i as f64 / 10.0;
    let x = -150.0 + SPEED * t;
    let items = match i {
        0..=49 => vec![percept("vp1", x, LANE_Y + 0.3, 4.5)],
        50..=69 => vec![],
        71 | 72 => vec![percept("vp2", x + 3.0, LANE_Y - 0.4, 1.5)],
        _ => vec![percept("vp2", x + 3.0, LANE_Y - 0.4, 4.5)],
    };
    Value::List(items.into())
}

fn time(i: i64) -> Time {
    i * 100_000
}

/// The structure after each step: (first step, last step, text of `Anchoring::describe`).
const STRUCTURES: &[(i64, i64, &str)] = &[
    (0, 9, "vp1 anchored | vision_world: establish ?\n"),
    (
        10,
        10,
        "vp1 anchored | vision_world: -> wo1 maintain ?\n\
         wo1 anchored | world_onroad: establish ?\n",
    ),
    (
        11,
        29,
        "vp1 anchored | vision_world: -> wo1 maintain true\n\
         wo1 anchored | world_onroad: establish ?\n",
    ),
    (
        30,
        49,
        "vp1 anchored | vision_world: -> wo1 maintain true\n\
         wo1 anchored | world_onroad: -> oo1 maintain ?\n\
         oo1 anchored\n",
    ),
    (
        50,
        69,
        "wo1 predicted | world_onroad: -> oo1 maintain ?\n\
         oo1 predicted\n",
    ),
    (
        70,
        70,
        "vp2 anchored | vision_world: establish ?, reestablish wo1 ?\n\
         wo1 predicted | world_onroad: -> oo1 maintain ?\n\
         oo1 predicted\n",
    ),
    (
        71,
        72,
        "vp2 anchored | vision_world: establish false, reestablish wo1 ?\n\
         wo1 predicted | world_onroad: -> oo1 maintain ?\n\
         oo1 predicted\n",
    ),
    (
        73,
        73,
        "vp2 anchored | vision_world: -> wo1 maintain ?\n\
         wo1 anchored | world_onroad: -> oo1 maintain ?\n\
         oo1 anchored\n",
    ),
    (
        74,
        90,
        "vp2 anchored | vision_world: -> wo1 maintain true\n\
         wo1 anchored | world_onroad: -> oo1 maintain ?\n\
         oo1 anchored\n",
    ),
];

/// The changes of each step that has any (rendered with `Change`'s `Display`).
const CHANGES: &[(i64, &[&str])] = &[
    (0, &["created vp1 (source)"]),
    (10, &["created wo1 <- vp1 (establish, vision_world)", "linked wo1 <- vp1 (establish, vision_world)"]),
    (30, &["created oo1 <- wo1 (establish, world_onroad)", "linked oo1 <- wo1 (establish, world_onroad)"]),
    (
        50,
        &[
            "unlinked wo1 <- vp1 (from_removed, vision_world)",
            "removed vp1 (lost)",
            "predicted wo1 (no_incoming_link, along_roads)",
        ],
    ),
    (70, &["created vp2 (source)"]),
    (73, &["linked wo1 <- vp2 (reestablish, vision_world)"]),
];

fn engine() -> Anchoring {
    common::engine(SPEC)
}

fn position(view: &kpl_anchor::ObjectView) -> [f64; 2] {
    view.state.as_record().unwrap().get("pos").unwrap().as_vec2().unwrap()
}

fn assert_near(p: [f64; 2], q: [f64; 2], what: &str) {
    assert!((p[0] - q[0]).abs() < 1e-6 && (p[1] - q[1]).abs() < 1e-6, "{what}: {p:?} is not {q:?}");
}

#[test]
fn example_iv1_step_by_step() {
    let mut anchoring = engine();
    assert_eq!(anchoring.type_names(), vec!["VisionPercept", "WorldObject", "OnRoadObject"]);
    assert_eq!(anchoring.link_names(), vec!["vision_world", "world_onroad"]);
    // Both reestablish conditions bound the distance: candidates are gated at 10 m.
    assert_eq!(anchoring.link_gate("vision_world"), Some(10.0));
    assert_eq!(anchoring.link_gate("world_onroad"), Some(10.0));
    assert!(anchoring.notes().is_empty());
    for i in 0..=90 {
        let objects = snapshot(i);
        let output = anchoring
            .step(time(i), &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }])
            .unwrap();
        assert!(output.warnings.is_empty(), "step {i}: {:?}", output.warnings);

        let (_, _, expected) = STRUCTURES.iter().find(|(a, b, _)| (*a..=*b).contains(&i)).unwrap();
        assert_eq!(anchoring.describe(), *expected, "structure after step {i} (t = {} s)", i as f64 / 10.0);

        let changes: Vec<String> = output.changes.iter().map(ToString::to_string).collect();
        let expected: Vec<String> = CHANGES
            .iter()
            .find(|(step, _)| *step == i)
            .map_or_else(Vec::new, |(_, list)| list.iter().map(|s| s.to_string()).collect());
        assert_eq!(changes, expected, "changes at step {i}");
        assert!(output.changes.iter().all(|c| c.time == time(i)));

        // The states along the way.
        match i {
            // wo1 follows vp1; oo1 is wo1 snapped to the centre of its lane.
            30..=49 => {
                let wo1 = anchoring.object("WorldObject", "wo1").unwrap();
                let oo1 = anchoring.object("OnRoadObject", "oo1").unwrap();
                let x = -150.0 + SPEED * i as f64 / 10.0;
                assert_near(position(&wo1), [x, LANE_Y + 0.3], "wo1");
                assert_near(position(&oo1), [x, LANE_Y], "oo1");
                let offset = oo1.state.as_record().unwrap().get("lane_offset").unwrap().as_f64().unwrap();
                assert!((offset - 0.3).abs() < 1e-9);
                assert!(wo1.measured && oo1.measured && wo1.anchored && oo1.anchored);
            }
            // Under the bridge: oo1 moves along its lane from where it was last seen (4.9 s),
            // at the speed it had, and wo1 takes oo1's position (its more specific model).
            50..=72 => {
                let wo1 = anchoring.object("WorldObject", "wo1").unwrap();
                let oo1 = anchoring.object("OnRoadObject", "oo1").unwrap();
                let x = -150.0 + SPEED * 4.9 + SPEED * (i - 49) as f64 / 10.0;
                assert_near(position(&oo1), [x, LANE_Y], "oo1 under the bridge");
                assert_near(position(&wo1), [x, LANE_Y], "wo1 under the bridge");
                for view in [&wo1, &oo1] {
                    assert_eq!(view.status, Status::Predicted);
                    assert!(!view.anchored && !view.measured && view.predicted);
                    assert_eq!(view.last_anchored, time(49));
                }
                assert!(wo1.from.is_empty());
                assert_eq!(oo1.from, vec![("world_onroad".into(), "wo1".into())]);
            }
            // Reacquired: wo1 is vp2's position again.
            73.. => {
                let wo1 = anchoring.object("WorldObject", "wo1").unwrap();
                let x = -150.0 + SPEED * i as f64 / 10.0 + 3.0;
                assert_near(position(&wo1), [x, LANE_Y - 0.4], "wo1 reacquired");
                assert_eq!(anchoring.grounded_in("oo1"), vec![Arc::from("vp2")]);
                assert_eq!(
                    anchoring.chain("vp2"),
                    vec![("WorldObject".into(), "wo1".into()), ("OnRoadObject".into(), "oo1".into())]
                );
            }
            _ => {}
        }
    }
    // One instance per percept (vp1 removed with its percept), one for wo1.
    let vision = anchoring.link_stats("vision_world").unwrap();
    assert_eq!((vision.instances_created, vision.instances_removed), (2, 1));
    let onroad = anchoring.link_stats("world_onroad").unwrap();
    assert_eq!((onroad.instances_created, onroad.instances_removed), (1, 0));
}

#[test]
fn the_instance_views_say_what_is_pending() {
    let mut anchoring = engine();
    for i in 0..=71 {
        let objects = snapshot(i);
        anchoring
            .step(time(i), &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }])
            .unwrap();
    }
    assert_eq!(
        anchoring.instance("vision_world", "vp2"),
        Some(InstanceView::Unlinked {
            establish: Some(false),
            candidates: vec![("wo1".into(), None)],
            identifications: vec![],
        })
    );
    assert_eq!(
        anchoring.instance("world_onroad", "wo1"),
        Some(InstanceView::Linked { to: "oo1".into(), maintain: None })
    );
    assert_eq!(anchoring.instance("vision_world", "vp1"), None, "vp1 is gone");
}

/// Without a reacquisition (no vp2), the structure is forgotten 30 s after it was last anchored,
/// and not a step earlier.
#[test]
fn an_unanchored_structure_is_forgotten_after_the_forget_time() {
    let mut anchoring = engine();
    let empty = Value::List(Vec::new().into());
    let mut removed_at = None;
    for i in 0..=400 {
        let objects = if i < 50 { snapshot(i) } else { empty.clone() };
        let output = anchoring
            .step(time(i), &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }])
            .unwrap();
        let removed: Vec<String> = output
            .changes
            .iter()
            .filter(|c| c.kind == kpl_anchor::ChangeKind::Removed && c.cause == kpl_anchor::Cause::Forgotten)
            .map(|c| c.symbol.to_string())
            .collect();
        if !removed.is_empty() {
            assert_eq!(removed, vec!["wo1", "oo1"]);
            assert!(removed_at.is_none());
            removed_at = Some(i);
        }
    }
    // Last anchored at step 49 (4.9 s): removed at 34.9 s.
    assert_eq!(removed_at, Some(349));
    assert_eq!(anchoring.n_objects(), 0);
}
