//! The hard cases of issue 27, one per test, driven through `Aapa::step` with CATER's action
//! rules (`Params::cater()`): moves with other speed profiles than Blender's easing, an object
//! turning where it stands, a false detection of the contained object's class, nested cones moved
//! as one, a contain onto a stack that is moving, simultaneous actions on identical objects,
//! occlusion by several objects together, a stack told from its twin by its contents moving with
//! it, and a carried object's size following its carrier's width and height apart. Each failed
//! before the rule it tests was added; the three decided by `identity_by_place` are also run with
//! it off, as the published algorithm.
#![allow(clippy::unwrap_used, reason = "tests")]

use kpl_aapa::{Aapa, Action, AnchorStatus, Params, Percept, WorldState};
use kpl_core::BBox;

const FRAME: i64 = 33_333;

fn bx(x1: f64, y1: f64, x2: f64, y2: f64) -> BBox {
    BBox::new(x1, y1, x2, y2)
}

/// A box of size `w` x `h` with its bottom centre at `(x, y)`.
fn at(x: f64, y: f64, w: f64, h: f64) -> BBox {
    bx(x - w / 2.0, y - h, x + w / 2.0, y)
}

fn p(label: &str, object_type: &str, b: BBox) -> Percept {
    Percept::new(label, object_type, b)
}

fn started(name: &str, args: &[&str], end_frame: i64) -> Action {
    Action::started(name, args, Some(end_frame * FRAME))
}

fn completed(name: &str, args: &[&str]) -> Action {
    Action::completed(name, args)
}

/// Runs `frames` frames; `scene(f)` gives frame `f`'s percepts and actions. Returns every world.
fn run(
    aapa: &Aapa,
    frames: usize,
    mut scene: impl FnMut(usize) -> (Vec<Percept>, Vec<Action>),
) -> Vec<WorldState> {
    let mut world = WorldState::default();
    let mut out = Vec::with_capacity(frames);
    for f in 0..frames {
        let (percepts, actions) = scene(f);
        world = aapa.step(f as i64 * FRAME, &percepts, &actions, None, &world).unwrap();
        out.push(world.clone());
    }
    out
}

/// CATER's setting, as `kpl cater eval` and `specs/cater/snitch.kpl` use it.
fn cater() -> Aapa {
    Aapa::new(Params::cater()).unwrap()
}

/// CATER's setting without `identity_by_place`: which of identical objects an action means is then
/// decided by the order of motion and by confidence alone, as in the published algorithm.
fn cater_without_identity_by_place() -> Aapa {
    let mut p = Params::cater();
    p.extensions.identity_by_place = false;
    Aapa::new(p).unwrap()
}

/// Where the best anchor of a type is (its box centre).
fn centre_of(world: &WorldState, object_type: &str) -> [f64; 2] {
    let a = world.best_of_type(object_type, 0.1).unwrap();
    a.bbox.center()
}

/// A move from `x0` to `x1` along a profile, over frames `start..=end`; where it is at `frame`.
fn along(profile: fn(f64) -> f64, x0: f64, x1: f64, start: usize, end: usize, frame: usize) -> f64 {
    let u = ((frame as f64 - start as f64) / (end - start) as f64).clamp(0.0, 1.0);
    x0 + (x1 - x0) * profile(u)
}

#[test]
fn a_move_seen_in_part_continues_with_the_profile_it_showed() {
    // A cube slides from x = 40 to x = 240 over frames 10 to 40, seen until frame 22, then behind
    // a wide wall until it stops. Its speed profile is linear, ease-in or ease-out (CATER renders
    // Blender's smooth easing; hard scenes use all four).
    type Profile = (&'static str, fn(f64) -> f64);
    let profiles: [Profile; 3] =
        [("linear", |u| u), ("ease-in", |u| u * u), ("ease-out", |u| 1.0 - (1.0 - u) * (1.0 - u))];
    for (name, profile) in profiles {
        let worlds = run(&cater(), 41, |f| {
            let x = along(profile, 40.0, 240.0, 10, 40, f);
            let wall = p("wall", "wall", bx(0.0, 120.0, 320.0, 200.0));
            let mut percepts = vec![wall];
            if f <= 22 {
                percepts.push(p("cube", "cube", at(x, 150.0, 20.0, 20.0)));
            }
            let actions = match f {
                10 => vec![started("_slide", &["cube"], 40)],
                40 => vec![completed("_slide", &["cube"])],
                _ => vec![],
            };
            (percepts, actions)
        });
        for f in [28, 34, 40] {
            let truth = along(profile, 40.0, 240.0, 10, 40, f);
            let predicted = centre_of(&worlds[f], "cube")[0];
            assert!(
                (predicted - truth).abs() < 3.0,
                "{name}, frame {f}: at {predicted:.1}, truly at {truth:.1}"
            );
        }
        assert_eq!(worlds[40].anchor("cube").unwrap().status, AnchorStatus::Occluded);
    }
}

#[test]
fn an_object_turning_in_place_is_followed_not_averaged() {
    // With a detector's averaging of still objects (`average_still`), a cube that turns where it
    // stands (CATER's `_rotate`) goes from 30 x 18 to 18 x 30 pixels over frames 20 to 40: its box
    // must follow the turn, and after it the new box, not a mean of old and new.
    let mut params = Params::cater();
    params.extensions.average_still = true;
    let aapa = Aapa::new(params).unwrap();
    let size = |f: usize| {
        let u = ((f as f64 - 20.0) / 20.0).clamp(0.0, 1.0);
        [30.0 - 12.0 * u, 18.0 + 12.0 * u]
    };
    let worlds = run(&aapa, 60, |f| {
        let [w, h] = size(f);
        let actions = match f {
            20 => vec![started("_rotate", &["cube"], 40)],
            40 => vec![completed("_rotate", &["cube"])],
            _ => vec![],
        };
        (vec![p("cube", "cube", at(100.0, 150.0, w, h))], actions)
    });
    for (f, world) in worlds.iter().enumerate().skip(20) {
        let [w, h] = size(f);
        let b = world.anchor("cube").unwrap().bbox;
        assert!(
            (b.width() - w).abs() < 0.5 && (b.height() - h).abs() < 0.5,
            "frame {f}: {b:?}, truly {w} x {h}"
        );
    }
}

#[test]
fn a_false_detection_of_the_contained_class_is_not_what_the_cone_covers() {
    // The snitch stands at x = 100 from the start. A cone comes down over it from frame 10 to 30
    // (hiding it from frame 26); at frames 28 and 29 a false detection of the snitch's class
    // appears by the cone's top, long enough to be anchored. The snitch, which no action moved, is
    // not re-acquired there, and the cone covers the snitch, not the false one: when the cone then
    // slides to x = 250, the snitch goes with it, where it was in the cone.
    let worlds = run(&cater(), 60, |f| {
        let cone_x = if f < 30 {
            along(|u| u, 200.0, 100.0, 10, 30, f)
        } else {
            along(|u| u, 100.0, 250.0, 35, 55, f)
        };
        let mut percepts = vec![p("cone", "cone", at(cone_x, 160.0, 50.0, 60.0))];
        if f < 26 {
            percepts.push(p("snitch", "snitch", at(100.0, 158.0, 16.0, 16.0)));
        }
        if (28..=29).contains(&f) {
            percepts.push(p("ghost", "snitch", at(120.0, 110.0, 15.0, 15.0)));
        }
        let actions = match f {
            10 => vec![started("_contain", &["cone", "snitch"], 30)],
            30 => vec![completed("_contain", &["cone", "snitch"])],
            35 => vec![started("_slide", &["cone"], 55), started("_slide", &["snitch"], 55)],
            55 => vec![completed("_slide", &["cone"]), completed("_slide", &["snitch"])],
            _ => vec![],
        };
        (percepts, actions)
    });
    let last = worlds.last().unwrap();
    assert!(last.has_relation("contained", "snitch", "cone"), "{:?}", last.relations);
    let x = centre_of(last, "snitch")[0];
    assert!((x - 250.0).abs() < 3.0, "the snitch is at {x:.1}, its cone at 250");
}

/// A box moving linearly from `a` to `b` over frames `start..=end` (held before and after).
fn lerp(a: BBox, b: BBox, start: usize, end: usize, frame: usize) -> BBox {
    let u = ((frame as f64 - start as f64) / (end - start) as f64).clamp(0.0, 1.0);
    let m = |p: f64, q: f64| p + (q - p) * u;
    bx(m(a.x1, b.x1), m(a.y1, b.y1), m(a.x2, b.x2), m(a.y2, b.y2))
}

fn starts(f: usize, at: usize, end: usize, name: &str, args: &[&str]) -> Option<Action> {
    (f == at).then(|| started(name, args, end as i64))
}

fn ends(f: usize, at: usize, name: &str, args: &[&str]) -> Option<Action> {
    (f == at).then(|| completed(name, args))
}

/// The actions at frame `f` of a cone that contains the snitch over `contain` and then slides
/// with it over `slide`, logged as CATER logs them (the contents' slide with its container's frames).
fn contain_then_slide(f: usize, contain: (usize, usize), slide: (usize, usize)) -> Vec<Action> {
    let actions = [
        starts(f, contain.0, contain.1, "_contain", &["cone", "snitch"]),
        ends(f, contain.1, "_contain", &["cone", "snitch"]),
        starts(f, slide.0, slide.1, "_slide", &["cone"]),
        starts(f, slide.0, slide.1, "_slide", &["snitch"]),
        ends(f, slide.1, "_slide", &["cone"]),
        ends(f, slide.1, "_slide", &["snitch"]),
    ];
    actions.into_iter().flatten().collect()
}

/// The scene of [`nested_cones_keep_their_contents_when_an_identical_cone_is_picked_up_unseen`]; its
/// last world.
fn nested_cones(aapa: &Aapa) -> WorldState {
    // Cone A (type `cone_m`) comes over the snitch (10..30), the large cone B over A (40..60): the
    // snitch is two levels down. A's identical twin A2 stands at x = 60; while A is contained, a
    // perception like OPNet's leaves out every object of A's class, A2 included. A2 is picked up
    // (70..90) unseen: the action must not be taken for A, which is inside B and cannot be picked
    // up, so the snitch stays in A. Then B slides to x = 260 (100..130), carrying A and the snitch.
    let snitch = at(160.0, 150.0, 14.0, 14.0);
    let a_on = at(160.0, 152.0, 36.0, 44.0);
    let b_on = at(160.0, 154.0, 52.0, 64.0);
    let b_end = at(260.0, 154.0, 52.0, 64.0);
    let worlds = run(aapa, 140, |f| {
        let mut percepts = vec![];
        if f < 60 {
            percepts.push(p("a", "cone_m", lerp(at(100.0, 152.0, 36.0, 44.0), a_on, 10, 30, f)));
            percepts.push(p("a2", "cone_m", at(60.0, 152.0, 36.0, 44.0)));
        }
        if f < 26 {
            percepts.push(p("s", "snitch", snitch));
        }
        let b = if f <= 100 {
            lerp(at(240.0, 154.0, 52.0, 64.0), b_on, 40, 60, f)
        } else {
            lerp(b_on, b_end, 100, 130, f)
        };
        percepts.push(p("b", "cone_l", b));
        let actions = [
            starts(f, 10, 30, "_contain", &["cone_m", "snitch"]),
            ends(f, 30, "_contain", &["cone_m", "snitch"]),
            starts(f, 40, 60, "_contain", &["cone_l", "cone_m"]),
            ends(f, 60, "_contain", &["cone_l", "cone_m"]),
            starts(f, 70, 90, "_pick_place", &["cone_m"]),
            ends(f, 90, "_pick_place", &["cone_m"]),
            starts(f, 100, 130, "_slide", &["cone_l"]),
            starts(f, 100, 130, "_slide", &["cone_m"]),
            starts(f, 100, 130, "_slide", &["snitch"]),
            ends(f, 130, "_slide", &["cone_l"]),
            ends(f, 130, "_slide", &["cone_m"]),
            ends(f, 130, "_slide", &["snitch"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    });
    worlds.last().unwrap().clone()
}

#[test]
fn nested_cones_keep_their_contents_when_an_identical_cone_is_picked_up_unseen() {
    let last = &nested_cones(&cater());
    assert!(
        last.has_relation("contained", "s", "a") && last.has_relation("contained", "a", "b"),
        "{:?}",
        last.relations
    );
    let x = centre_of(last, "snitch")[0];
    assert!((x - 260.0).abs() < 3.0, "the snitch is at {x:.1}, carried two levels down to 260");
}

/// The scene of [`a_contain_is_decided_by_the_cone_over_the_object_even_one_not_established_when_it_started`].
fn late_cone(aapa: &Aapa) -> WorldState {
    // Two identical cones: `x` at x = 60 from the start; `y` first seen at frame 8 (it was behind
    // something), so when the contain starts at frame 10 only `x` is established. `y` comes over
    // the snitch (10..30) and slides with it to x = 250 (40..60): the snitch is in `y`.
    let snitch = at(150.0, 150.0, 14.0, 14.0);
    let worlds = run(aapa, 70, |f| {
        let mut percepts = vec![p("x", "cone", at(60.0, 152.0, 34.0, 42.0))];
        if f >= 8 {
            let y = if f <= 30 {
                lerp(at(230.0, 152.0, 34.0, 42.0), at(150.0, 152.0, 34.0, 42.0), 10, 30, f)
            } else {
                lerp(at(150.0, 152.0, 34.0, 42.0), at(250.0, 152.0, 34.0, 42.0), 40, 60, f)
            };
            percepts.push(p("y", "cone", y));
        }
        if f < 26 {
            percepts.push(p("s", "snitch", snitch));
        }
        (percepts, contain_then_slide(f, (10, 30), (40, 60)))
    });
    worlds.last().unwrap().clone()
}

#[test]
fn a_contain_is_decided_by_the_cone_over_the_object_even_one_not_established_when_it_started() {
    let last = &late_cone(&cater());
    assert!(last.has_relation("contained", "s", "y"), "{:?}", last.relations);
    assert!((centre_of(last, "snitch")[0] - 250.0).abs() < 3.0);
}

#[test]
fn a_contain_is_decided_by_the_cone_over_the_object_whatever_the_order_of_motion() {
    // Three identical cones. Two are picked up and placed (c1: 10..40, from x = 60 to x = 280;
    // c2: 14..44, from x = 140 to x = 20) and a third comes over the snitch (c3: 16..46, from
    // x = 220 to x = 100), the actions starting at different frames. The order in which they are
    // first seen to move is not the order of the actions (c3 starts lifting before c2). The
    // snitch must end in the cone that is over it, and go with that one when it slides (60..90).
    let cone = |x: f64, y: f64| at(x, y, 34.0, 42.0);
    let lift = |from: BBox, to: BBox, start: usize, end: usize, f: usize| {
        // Up 40 px over the first fifth, across, down over the last fifth.
        let (s, e) = (start as f64, end as f64);
        let (t1, t2) = (s + 0.2 * (e - s), s + 0.8 * (e - s));
        let up = |b: BBox| bx(b.x1, b.y1 - 40.0, b.x2, b.y2 - 40.0);
        let ff = f as f64;
        if ff <= t1 {
            lerp(from, up(from), start, t1 as usize, f)
        } else if ff <= t2 {
            lerp(up(from), up(to), t1 as usize, t2 as usize, f)
        } else {
            lerp(up(to), to, t2 as usize, end, f)
        }
    };
    let snitch = at(100.0, 150.0, 14.0, 14.0);
    let worlds = run(&cater(), 100, |f| {
        let c1 = lift(cone(60.0, 120.0), cone(280.0, 120.0), 10, 40, f);
        let c2 = lift(cone(140.0, 200.0), cone(20.0, 200.0), 14, 44, f);
        let c3 = if f <= 46 {
            lift(cone(220.0, 152.0), cone(100.0, 152.0), 16, 46, f)
        } else {
            lerp(cone(100.0, 152.0), cone(250.0, 152.0), 60, 90, f)
        };
        let mut percepts = vec![p("x", "cone", c1), p("y", "cone", c2), p("z", "cone", c3)];
        if f < 42 {
            percepts.push(p("s", "snitch", snitch));
        }
        let actions = [
            starts(f, 10, 40, "_pick_place", &["cone"]),
            ends(f, 40, "_pick_place", &["cone"]),
            starts(f, 14, 44, "_pick_place", &["cone"]),
            ends(f, 44, "_pick_place", &["cone"]),
            starts(f, 16, 46, "_contain", &["cone", "snitch"]),
            ends(f, 46, "_contain", &["cone", "snitch"]),
            starts(f, 60, 90, "_slide", &["cone"]),
            starts(f, 60, 90, "_slide", &["snitch"]),
            ends(f, 90, "_slide", &["cone"]),
            ends(f, 90, "_slide", &["snitch"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    });
    let last = worlds.last().unwrap();
    let x = centre_of(last, "snitch")[0];
    assert!((x - 250.0).abs() < 3.0, "the snitch is at {x:.1}; its cone slid to 250");
}

#[test]
fn an_identical_object_left_out_of_the_perception_keeps_its_identity() {
    // Two identical cones, `left` at x = 60 and `right` at x = 200. A perception like OPNet's
    // leaves out every object of a class while one of them is contained: from frame 20 to 120 no
    // cone is reported at all. Then both are seen again where they were: each keeps its symbol
    // (H1: nothing moved them), and the contained snitch is still in `right`.
    let worlds = run(&cater(), 140, |f| {
        let mut percepts = vec![];
        if !(20..=120).contains(&f) {
            percepts.push(p("left", "cone", at(60.0, 150.0, 34.0, 42.0)));
            percepts.push(p("right", "cone", at(200.0, 150.0, 34.0, 42.0)));
        }
        if f < 10 {
            percepts.push(p("s", "snitch", at(200.0, 148.0, 14.0, 14.0)));
        }
        let actions = [
            starts(f, 10, 19, "_contain", &["cone", "snitch"]),
            ends(f, 19, "_contain", &["cone", "snitch"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    });
    let last = worlds.last().unwrap();
    assert_eq!(last.anchors.iter().filter(|a| &*a.object_type == "cone").count(), 2);
    assert!((last.anchor("left").unwrap().bbox.center()[0] - 60.0).abs() < 1.0);
    assert!((last.anchor("right").unwrap().bbox.center()[0] - 200.0).abs() < 1.0);
    assert!(last.has_relation("contained", "s", "right"), "{:?}", last.relations);
}

#[test]
fn a_stack_released_where_it_stands_is_not_taken_for_its_twin_sliding_by() {
    // The snitch in cone `a` (contain 10..30), `a` under the large cone `b` (40..60). `a`'s twin
    // `a2` is left out of the perception while `a` is contained (as OPNet's perception does) and
    // slides from x = 60 to x = 200 (100..130). `b` is picked up at 110..140 and `a` is seen again
    // where it stands (x = 160), next to the sliding twin: `a` stays (H1) and keeps the snitch.
    let worlds = run(&cater(), 160, |f| {
        let mut percepts = vec![];
        let hidden = (60..=110).contains(&f);
        if !hidden {
            percepts.push(p(
                "a",
                "cone_m",
                lerp(at(100.0, 152.0, 34.0, 42.0), at(160.0, 152.0, 34.0, 42.0), 10, 30, f),
            ));
            percepts.push(p(
                "a2",
                "cone_m",
                lerp(at(60.0, 152.0, 34.0, 42.0), at(200.0, 152.0, 34.0, 42.0), 100, 130, f),
            ));
        }
        if f < 26 {
            percepts.push(p("s", "snitch", at(160.0, 150.0, 14.0, 14.0)));
        }
        let b = lerp(at(260.0, 154.0, 52.0, 64.0), at(160.0, 154.0, 52.0, 64.0), 40, 60, f);
        percepts.push(p(
            "b",
            "cone_l",
            if f > 110 { lerp(b, bx(b.x1, b.y1 - 80.0, b.x2, b.y2 - 80.0), 110, 120, f) } else { b },
        ));
        let actions = [
            starts(f, 10, 30, "_contain", &["cone_m", "snitch"]),
            ends(f, 30, "_contain", &["cone_m", "snitch"]),
            starts(f, 40, 60, "_contain", &["cone_l", "cone_m"]),
            ends(f, 60, "_contain", &["cone_l", "cone_m"]),
            starts(f, 100, 130, "_slide", &["cone_m"]),
            ends(f, 130, "_slide", &["cone_m"]),
            starts(f, 110, 140, "_pick_place", &["cone_l"]),
            ends(f, 140, "_pick_place", &["cone_l"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    });
    let last = worlds.last().unwrap();
    assert!(last.has_relation("contained", "s", "a"), "{:?}", last.relations);
    assert!((last.anchor("a").unwrap().bbox.center()[0] - 160.0).abs() < 1.0);
    assert!((last.anchor("a2").unwrap().bbox.center()[0] - 200.0).abs() < 1.0);
    assert!((centre_of(last, "snitch")[0] - 160.0).abs() < 2.0);
}

#[test]
fn an_object_detected_under_another_class_for_a_while_stays_one_anchor() {
    // A detector takes the snitch for a sphere in frames 20 to 23 (and reports both at frame 20):
    // the anchor those detections made is merged back into the snitch's (`merge_duplicates`), so
    // that the cone that then covers the snitch carries the one snitch there is.
    let snitch = at(150.0, 150.0, 14.0, 14.0);
    let worlds = run(&cater(), 80, |f| {
        let mut percepts =
            vec![p("c", "cone", lerp(at(240.0, 152.0, 34.0, 42.0), at(150.0, 152.0, 34.0, 42.0), 30, 50, f))];
        if f < 46 {
            let kind = if (20..=23).contains(&f) { "sphere" } else { "snitch" };
            percepts.push(p("s", kind, snitch));
            if f == 20 {
                percepts.push(p("s2", "snitch", snitch));
            }
        }
        let actions = [
            starts(f, 30, 50, "_contain", &["cone", "snitch"]),
            ends(f, 50, "_contain", &["cone", "snitch"]),
            starts(f, 55, 75, "_slide", &["cone"]),
            ends(f, 75, "_slide", &["cone"]),
        ];
        if f >= 55 {
            percepts[0] =
                p("c", "cone", lerp(at(150.0, 152.0, 34.0, 42.0), at(60.0, 152.0, 34.0, 42.0), 55, 75, f));
        }
        (percepts, actions.into_iter().flatten().collect())
    });
    let last = worlds.last().unwrap();
    let snitches: Vec<_> = last.anchors.iter().filter(|a| &*a.object_type == "snitch").collect();
    assert_eq!(snitches.len(), 1, "{snitches:?}");
    assert!((centre_of(last, "snitch")[0] - 60.0).abs() < 3.0);
}

#[test]
fn a_noisy_detectors_outlier_neither_moves_a_still_object_nor_its_contents() {
    // `average_still` (a detector's boxes): a still cube reported with a 9-pixel outlier at frame
    // 40 keeps its averaged box; a snitch inside a still cone keeps its box while the cone's boxes
    // jitter by ±2 pixels, and the geometry is measured on the cone's averaged box.
    let mut params = Params::cater();
    params.extensions.average_still = true;
    let aapa = Aapa::new(params).unwrap();
    let jitter = |f: usize| [(f * 7 % 5) as f64 - 2.0, (f * 3 % 5) as f64 - 2.0];
    let snitch = at(150.0, 150.0, 14.0, 14.0);
    let worlds = run(&aapa, 90, |f| {
        let [dx, dy] = jitter(f);
        let cube_shift = if f == 40 { 9.0 } else { 0.0 };
        let cone = if f <= 30 {
            lerp(at(240.0, 152.0, 34.0, 42.0), at(150.0, 152.0, 34.0, 42.0), 10, 30, f)
        } else {
            let b = at(150.0, 152.0, 34.0, 42.0);
            bx(b.x1 + dx, b.y1 + dy, b.x2 - dy, b.y2 + dx)
        };
        let mut percepts =
            vec![p("k", "cube", at(60.0 + cube_shift, 100.0, 20.0, 20.0)), p("c", "cone", cone)];
        if f < 26 {
            percepts.push(p("s", "snitch", snitch));
        }
        let actions = [
            starts(f, 10, 30, "_contain", &["cone", "snitch"]),
            ends(f, 30, "_contain", &["cone", "snitch"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    });
    assert_eq!(worlds[40].anchor("k").unwrap().bbox, at(60.0, 100.0, 20.0, 20.0), "the outlier is left out");
    for (f, world) in worlds.iter().enumerate().skip(31) {
        let b = world.anchor("s").unwrap().bbox;
        assert_eq!(b, snitch, "frame {f}: the snitch inside the still cone does not move");
    }
}

/// The scene of [`a_container_no_one_saw_is_inferred_over_what_it_covers`].
fn unseen_container(aapa: &Aapa) -> Vec<WorldState> {
    // The only cone of its type is inside a large cone when a `_contain(cone_m, snitch)` comes
    // over the snitch (the cone that does it was never perceived): a contained cone comes over
    // nothing, so the container is inferred over the snitch, and the snitch stays where it is.
    let snitch = at(60.0, 150.0, 14.0, 14.0);
    run(aapa, 80, |f| {
        let mut percepts = vec![p(
            "b",
            "cone_l",
            lerp(at(260.0, 154.0, 52.0, 64.0), at(200.0, 154.0, 52.0, 64.0), 10, 30, f),
        )];
        if f < 30 {
            percepts.push(p("a", "cone_m", at(200.0, 152.0, 34.0, 42.0)));
        }
        if f < 56 {
            percepts.push(p("s", "snitch", snitch));
        }
        let actions = [
            starts(f, 10, 30, "_contain", &["cone_l", "cone_m"]),
            ends(f, 30, "_contain", &["cone_l", "cone_m"]),
            starts(f, 40, 60, "_contain", &["cone_m", "snitch"]),
            ends(f, 60, "_contain", &["cone_m", "snitch"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    })
}

#[test]
fn a_container_no_one_saw_is_inferred_over_what_it_covers() {
    let worlds = unseen_container(&cater());
    let last = worlds.last().unwrap();
    assert!(last.has_relation("contained", "a", "b"), "{:?}", last.relations);
    assert!(!last.has_relation("contained", "s", "a"), "{:?}", last.relations);
    assert!((centre_of(last, "snitch")[0] - 60.0).abs() < 1.0);
    assert!(worlds[60].notes.iter().any(|n| n.contains("inferred over `s`")), "{:?}", worlds[60].notes);
    let container = last.anchors.iter().find(|a| &*a.object_type == "cone_m" && &*a.symbol != "a").unwrap();
    assert!(last.has_relation("contained", "s", &container.symbol), "{:?}", last.relations);
}

#[test]
fn identity_by_place_is_what_decides_the_cases_of_identical_cones() {
    // The three scenes above with `identity_by_place` off: the published algorithm has no rule for
    // which of identical objects an action names, so the order of motion and confidence decide, and
    // each goes wrong the way the extension exists to prevent.
    let aapa = cater_without_identity_by_place();
    // The contained cone `a` is taken for the one picked up: the snitch is released from it.
    let last = nested_cones(&aapa);
    assert!(!last.has_relation("contained", "s", "a"), "{:?}", last.relations);
    // Only the cone established when the contain started is a candidate: the snitch goes into `x`,
    // which never moved.
    let last = late_cone(&aapa);
    assert!(last.has_relation("contained", "s", "x"), "{:?}", last.relations);
    // The only `cone_m` is inside `b`; the snitch is put into it, nothing is inferred.
    let worlds = unseen_container(&aapa);
    assert!(worlds.last().unwrap().has_relation("contained", "s", "a"));
    assert!(!worlds[60].notes.iter().any(|n| n.contains("inferred over")), "{:?}", worlds[60].notes);
}

/// The scene of [`a_stack_is_told_from_its_twin_by_its_contents_moving_with_it`]; every world.
fn contents_move_with_the_stack(aapa: &Aapa) -> Vec<WorldState> {
    // Two identical cones: `a` comes over the snitch (10..30) at x = 160, `t` stands at x = 60. From
    // frame 35 `a` is not perceived (behind something). At frame 40 `a` slides to x = 200 unseen
    // (40..70), and CATER reports the snitch sliding with it; at frame 42 `t` is picked up and
    // placed at x = 20 (42..60), seen, so it is the first of the type to move. The slide is `a`'s
    // (the snitch's own slide starts and ends with it), the pick-and-place `t`'s: the snitch stays
    // in `a`, and is at x = 200 when `a` is seen again there (from frame 75).
    let snitch = at(160.0, 150.0, 14.0, 14.0);
    let cone = |x: f64, y: f64| at(x, y, 34.0, 42.0);
    run(aapa, 90, |f| {
        let mut percepts = vec![];
        if f < 35 {
            percepts.push(p("a", "cone", lerp(cone(240.0, 152.0), cone(160.0, 152.0), 10, 30, f)));
        } else if f >= 75 {
            percepts.push(p("a", "cone", cone(200.0, 152.0)));
        }
        let t = if f <= 51 {
            lerp(cone(60.0, 152.0), cone(60.0, 112.0), 42, 51, f)
        } else {
            lerp(cone(60.0, 112.0), cone(20.0, 152.0), 51, 60, f)
        };
        percepts.push(p("t", "cone", t));
        if f < 26 {
            percepts.push(p("s", "snitch", snitch));
        }
        let actions = [
            starts(f, 10, 30, "_contain", &["cone", "snitch"]),
            ends(f, 30, "_contain", &["cone", "snitch"]),
            starts(f, 40, 70, "_slide", &["cone"]),
            starts(f, 40, 70, "_slide", &["snitch"]),
            starts(f, 42, 60, "_pick_place", &["cone"]),
            ends(f, 60, "_pick_place", &["cone"]),
            ends(f, 70, "_slide", &["cone"]),
            ends(f, 70, "_slide", &["snitch"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    })
}

#[test]
fn a_stack_is_told_from_its_twin_by_its_contents_moving_with_it() {
    let worlds = contents_move_with_the_stack(&cater());
    let last = worlds.last().unwrap();
    assert!(last.has_relation("contained", "s", "a"), "{:?}", last.relations);
    let x = centre_of(last, "snitch")[0];
    assert!((x - 200.0).abs() < 3.0, "the snitch is at {x:.1}, carried by `a` to 200");
}

#[test]
fn a_carried_object_scales_with_its_carriers_width_and_height_apart() {
    // A cone comes over the snitch (10..30) and slides (40..70) to where its box is as wide but
    // 10 px taller (nearer the camera, seen more from the side): the snitch under it keeps its width
    // and grows in height by the same ratio, 52 / 42.
    let snitch = at(160.0, 150.0, 14.0, 14.0);
    let worlds = run(&cater(), 80, |f| {
        let cone = if f <= 30 {
            lerp(at(240.0, 152.0, 34.0, 42.0), at(160.0, 152.0, 34.0, 42.0), 10, 30, f)
        } else {
            lerp(at(160.0, 152.0, 34.0, 42.0), at(200.0, 152.0, 34.0, 52.0), 40, 70, f)
        };
        let mut percepts = vec![p("c", "cone", cone)];
        if f < 26 {
            percepts.push(p("s", "snitch", snitch));
        }
        (percepts, contain_then_slide(f, (10, 30), (40, 70)))
    });
    let s = worlds.last().unwrap().best_of_type("snitch", 0.1).unwrap().bbox;
    assert!((s.width() - 14.0).abs() < 0.5, "width {:.2}, the cone's width did not change", s.width());
    let h = 14.0 * 52.0 / 42.0;
    assert!((s.height() - h).abs() < 0.5, "height {:.2}, the cone's grew to {h:.2}", s.height());
}

/// The scene of [`a_cone_lifted_off_the_snitch_is_told_from_its_moving_twin`] with the lift starting
/// `lift_delay` frames after the pick-up's action; every world.
fn lifted_off_while_the_twin_moves(aapa: &Aapa, lift_delay: usize) -> Vec<WorldState> {
    // Two identical cones. `b` comes over the snitch (10..20) and stays. At frame 40 `a` starts a
    // contain onto a ball (40..70: it slides from x = 80 to 140); at frame 43, while `a` moves, a
    // pick-up of a cone starts (43..70): `b` is lifted off the snitch, carried to x = 300 and put
    // down. The snitch stays where it was and is seen again once `b` is up.
    let snitch = at(220.0, 150.0, 14.0, 14.0);
    let ball = at(140.0, 150.0, 14.0, 14.0);
    let lift = 43 + lift_delay;
    run(aapa, 80, |f| {
        let a = lerp(at(80.0, 152.0, 34.0, 42.0), at(140.0, 152.0, 34.0, 42.0), 40, 70, f);
        let b = if f <= 20 {
            lerp(at(260.0, 152.0, 34.0, 42.0), at(220.0, 152.0, 34.0, 42.0), 10, 20, f)
        } else if f <= lift + 10 {
            // Up, slowly at first (CATER's easing).
            let y = along(|u| u * u, 152.0, 100.0, lift, lift + 10, f);
            at(220.0, y, 34.0, 42.0)
        } else if f <= lift + 20 {
            at(along(|u| u, 220.0, 300.0, lift + 10, lift + 20, f), 100.0, 34.0, 42.0)
        } else {
            at(300.0, along(|u| u, 100.0, 152.0, lift + 20, lift + 25, f), 34.0, 42.0)
        };
        let mut percepts = vec![p("a", "cone", a), p("b", "cone", b)];
        if f < 17 || f >= lift + 5 {
            percepts.push(p("s", "snitch", snitch));
        }
        if f < 66 {
            percepts.push(p("ball", "ball", ball));
        }
        let actions = [
            starts(f, 10, 20, "_contain", &["cone", "snitch"]),
            ends(f, 20, "_contain", &["cone", "snitch"]),
            starts(f, 40, 70, "_contain", &["cone", "ball"]),
            ends(f, 70, "_contain", &["cone", "ball"]),
            starts(f, 43, 70, "_pick_place", &["cone"]),
            ends(f, 70, "_pick_place", &["cone"]),
        ];
        (percepts, actions.into_iter().flatten().collect())
    })
}

#[test]
fn a_cone_lifted_off_the_snitch_is_told_from_its_moving_twin() {
    // The twin `a` was already moving when the pick-up started; `b` starts after it (one to three
    // frames later). The pick-up is `b`'s: the snitch is released where it stands, not carried off.
    for delay in [1, 3] {
        let worlds = lifted_off_while_the_twin_moves(&cater(), delay);
        for f in [50, 60, 79] {
            let x = centre_of(&worlds[f], "snitch");
            assert!(
                (x[0] - 220.0).abs() < 2.0 && (x[1] - 143.0).abs() < 2.0,
                "lift {delay} frames late, frame {f}: the snitch at {x:?}, it stands at [220, 143]"
            );
        }
    }
}
