//! The rules of paper section III-B, one behaviour per test, driven through `Aapa::step` only.
#![allow(clippy::unwrap_used, reason = "tests")]

use kpl_aapa::{
    Aapa, AapaError, Action, AnchorStatus, CameraModel, CameraPose, Extensions, ImageSize, MotionProfile,
    Params, Percept, WorldState,
};
use kpl_core::BBox;

const FRAME: i64 = 33_333;

fn bx(x1: f64, y1: f64, x2: f64, y2: f64) -> BBox {
    BBox::new(x1, y1, x2, y2)
}

fn p(label: &str, object_type: &str, b: BBox) -> Percept {
    Percept::new(label, object_type, b)
}

/// Runs frames of (percepts, actions) from an empty world; returns every world state.
fn run(aapa: &Aapa, frames: &[(Vec<Percept>, Vec<Action>)]) -> Vec<WorldState> {
    let mut world = WorldState::default();
    let mut out = Vec::new();
    for (i, (percepts, actions)) in frames.iter().enumerate() {
        world = aapa.step(i as i64 * FRAME, percepts, actions, None, &world).unwrap();
        out.push(world.clone());
    }
    out
}

fn still(percepts: Vec<Percept>, n: usize) -> Vec<(Vec<Percept>, Vec<Action>)> {
    vec![(percepts, vec![]); n]
}

fn cater() -> Aapa {
    Aapa::new(Params::cater()).unwrap()
}

#[test]
fn confidence_starts_at_zero_grows_by_conf_plus_and_caps_at_one() {
    let worlds = run(&cater(), &still(vec![p("a", "cube", bx(10., 10., 30., 30.))], 14));
    let conf: Vec<f64> = worlds.iter().map(|w| w.anchor("a").unwrap().confidence).collect();
    for (i, c) in conf.iter().enumerate() {
        let expected = (i as f64 * 0.1).min(1.0);
        assert!((c - expected).abs() < 1e-9, "cycle {i}: {c} != {expected}");
    }
}

#[test]
fn a_flickering_detection_is_dropped_before_it_is_anchored() {
    // Seen once (confidence 0), missed once: 0 - conf- < 0, removed.
    let mut frames = still(vec![p("ghost", "cube", bx(10., 10., 30., 30.))], 1);
    frames.push((vec![], vec![]));
    let worlds = run(&cater(), &frames);
    assert!(worlds[0].anchor("ghost").is_some());
    assert!(worlds[1].anchor("ghost").is_none());
}

#[test]
fn an_anchored_object_hidden_behind_a_detection_is_occluded_and_stays_put() {
    let snitch = p("s", "snitch", bx(100., 100., 120., 120.));
    let wall = p("w", "cube", bx(90., 80., 160., 140.));
    let mut frames = still(vec![snitch.clone(), wall.clone()], 3);
    frames.extend(still(vec![wall], 20));
    let worlds = run(&cater(), &frames);
    let last = worlds.last().unwrap().anchor("s").unwrap();
    assert_eq!(last.status, AnchorStatus::Occluded);
    assert_eq!(last.bbox, snitch.bbox, "H1: objects do not move on their own");
    assert!((last.confidence - 0.2).abs() < 1e-9, "occlusion does not cost confidence");
}

#[test]
fn an_unexplained_disappearance_is_lost_decays_and_is_removed() {
    // The paper's rule: `keep_lost` off.
    let mut params = Params::cater();
    params.extensions.keep_lost = 0.0;
    let mut frames = still(vec![p("a", "cube", bx(100., 100., 120., 120.))], 11); // confidence 1.0
    frames.extend(still(vec![p("far", "cone", bx(0., 0., 10., 10.))], 12));
    let worlds = run(&Aapa::new(params).unwrap(), &frames);
    let lost = worlds[11].anchor("a").unwrap();
    assert_eq!(lost.status, AnchorStatus::Lost);
    assert!((lost.confidence - 0.9).abs() < 1e-9);
    // 1.0 - 11 * 0.1 < 0 on the 11th missed cycle.
    assert!(worlds[20].anchor("a").is_some());
    assert!(worlds[21].anchor("a").is_none());
}

#[test]
fn an_established_object_that_vanishes_is_kept_for_keep_lost_seconds() {
    // `Params::cater()` keeps an established anchor that vanishes unexplained for 10 s (H1), then
    // the paper's decay takes it; a short-lived detection (not established) decays at once.
    let mut frames =
        still(vec![p("a", "cube", bx(100., 100., 120., 120.)), p("g", "cube", bx(0., 0., 9., 9.))], 1);
    frames.extend(still(vec![p("a", "cube", bx(100., 100., 120., 120.))], 10)); // a: confidence 1.0
    frames.extend(still(vec![p("far", "cone", bx(200., 0., 210., 10.))], 320));
    let worlds = run(&cater(), &frames);
    assert!(worlds[2].anchor("g").is_none(), "seen once, then lost: dropped");
    let kept = worlds[300].anchor("a").unwrap();
    assert_eq!((kept.status, kept.bbox), (AnchorStatus::Lost, bx(100., 100., 120., 120.)));
    let full = worlds[10].anchor("a").unwrap().confidence;
    assert!(full > 0.99 && kept.confidence == full, "{full} then {}", kept.confidence);
    // Last seen at frame 10; 10 s later (frame 311) it starts to decay, 11 cycles later it is gone.
    assert!(worlds[311].anchor("a").unwrap().confidence < full);
    assert!(worlds[330].anchor("a").is_none());
}

#[test]
fn an_object_outside_the_field_of_view_is_kept() {
    let params = Params { image: Some(ImageSize { width: 100.0, height: 100.0 }), ..Params::cater() };
    let aapa = Aapa::new(params.clone()).unwrap();
    let mut world = WorldState::default();
    for i in 0..3 {
        world = aapa.step(i * FRAME, &[p("a", "cube", bx(80., 40., 99., 60.))], &[], None, &world).unwrap();
    }
    // Move the world so the box lies beyond the right edge: feed the box as if compensated.
    world.anchors[0].bbox = bx(110., 40., 130., 60.);
    for i in 3..40 {
        world = aapa.step(i * FRAME, &[], &[], None, &world).unwrap();
    }
    let a = world.anchor("a").unwrap();
    assert_eq!(a.status, AnchorStatus::OutOfView);
    assert!((a.confidence - 0.2).abs() < 1e-9);
}

#[test]
fn alignment_respects_theta_with_squared_distances() {
    let aapa = cater();
    // A jump of 56 px: 56^2 = 3136 < 6500, aligned. A jump of 81 px: 6561 >= 6500, a new anchor.
    for (jump, aligned) in [(56.0, true), (81.0, false)] {
        let mut frames = still(vec![p("a", "cube", bx(10., 10., 30., 30.))], 2);
        frames.push((vec![p("x", "cube", bx(10. + jump, 10., 30. + jump, 30.))], vec![]));
        let last = run(&aapa, &frames).pop().unwrap();
        assert_eq!(last.anchor("a").unwrap().status == AnchorStatus::Visible, aligned, "jump {jump}");
        assert_eq!(last.anchor("x").is_some(), !aligned, "jump {jump}");
    }
}

#[test]
fn a_type_mismatch_multiplies_the_cost() {
    let aapa = cater();
    // 30 px: 900 with the same type, 9000 >= θ with another type.
    for (object_type, aligned) in [("cube", true), ("sphere", false)] {
        let mut frames = still(vec![p("a", "cube", bx(10., 10., 30., 30.))], 2);
        frames.push((vec![p("x", object_type, bx(40., 10., 60., 30.))], vec![]));
        let last = run(&aapa, &frames).pop().unwrap();
        assert_eq!(last.anchor("x").is_none(), aligned, "{object_type}");
    }
}

#[test]
fn symbols_survive_detector_label_swaps() {
    // Two cubes pass each other (one row apart); the detector labels left to right, so its labels
    // swap half way.
    let aapa = cater();
    let mut frames = Vec::new();
    for k in 0..20 {
        let x_a = 10.0 + 5.0 * k as f64; // moves right
        let x_b = 100.0 - 5.0 * k as f64; // moves left
        let mut boxes = [(x_a, 50.0), (x_b, 80.0)];
        boxes.sort_by(|a, b| a.0.total_cmp(&b.0));
        let percepts = boxes
            .iter()
            .enumerate()
            .map(|(i, (x, y))| p(&format!("cube{i}"), "cube", bx(*x, *y, x + 20., y + 20.)))
            .collect();
        frames.push((percepts, vec![]));
    }
    let worlds = run(&aapa, &frames);
    let last = worlds.last().unwrap();
    assert_eq!(last.anchors.len(), 2);
    // cube0 was A (started left, moved right): it must now be on the right.
    assert!(last.anchor("cube0").unwrap().bbox.x1 > last.anchor("cube1").unwrap().bbox.x1);
}

fn hand_and_gear() -> Vec<(Vec<Percept>, Vec<Action>)> {
    let hand = |x: f64| p("hand0", "hand", bx(x, 0., x + 40., 40.));
    let gear = |x: f64| p("gear0", "gear", bx(x + 10., 40., x + 30., 60.));
    let mut frames = still(vec![hand(0.), gear(0.)], 3);
    frames.push((vec![hand(0.), gear(0.)], vec![Action::completed("pick_up", &["hand0", "gear0"])]));
    // The gear is no longer detected while carried; the hand moves right.
    for k in 1..=10 {
        frames.push((vec![hand(5.0 * k as f64)], vec![]));
    }
    frames
}

#[test]
fn pick_up_attaches_and_the_child_follows_its_parent() {
    let worlds = run(&cater(), &hand_and_gear());
    let at_pick = &worlds[3];
    assert!(at_pick.has_relation("attached", "gear0", "hand0"));
    assert!(at_pick.has_relation("holding", "hand0", "gear0"));
    let last = worlds.last().unwrap();
    let gear = last.anchor("gear0").unwrap();
    assert_eq!(gear.status, AnchorStatus::Attached);
    assert!((gear.bbox.x1 - 60.0).abs() < 1e-9, "followed the hand by 50 px: {:?}", gear.bbox);
}

#[test]
fn one_parent_per_child_and_release_only_from_the_holder() {
    let mut frames = hand_and_gear();
    let hand = p("hand0", "hand", bx(50., 0., 90., 40.));
    let case = p("case0", "case", bx(40., 60., 120., 100.));
    frames.extend(still(vec![hand.clone(), case.clone()], 2));
    frames.push((
        vec![hand.clone(), case.clone()],
        vec![
            Action::completed("insert", &["gear0", "case0"]),
            Action::completed("release", &["hand0", "gear0"]),
        ],
    ));
    let last = run(&cater(), &frames).pop().unwrap();
    assert!(last.has_relation("attached", "gear0", "case0"));
    assert!(last.has_relation("inserted", "gear0", "case0"));
    assert!(!last.has_relation("attached", "gear0", "hand0"), "one parent per child");
    assert_eq!(last.relations.iter().filter(|r| &*r.name == "attached").count(), 1);
}

#[test]
fn attachments_are_followed_recursively() {
    // plug in case, case in hand; only the hand is seen; both follow it.
    let hand = |x: f64| p("hand0", "hand", bx(x, 0., x + 40., 40.));
    let case = p("case0", "case", bx(0., 40., 40., 80.));
    let plug = p("plug0", "plug", bx(15., 45., 25., 55.));
    let mut frames = still(vec![hand(0.), case.clone(), plug.clone()], 3);
    frames.push((
        vec![hand(0.), case, plug],
        vec![
            Action::completed("insert", &["plug0", "case0"]),
            Action::completed("pick_up", &["hand0", "case0"]),
        ],
    ));
    for k in 1..=6 {
        frames.push((vec![hand(10.0 * k as f64)], vec![]));
    }
    let last = run(&cater(), &frames).pop().unwrap();
    let case = last.anchor("case0").unwrap();
    let plug = last.anchor("plug0").unwrap();
    assert_eq!((case.status, plug.status), (AnchorStatus::Attached, AnchorStatus::Attached));
    assert!((case.bbox.x1 - 60.0).abs() < 1e-9);
    assert!((plug.bbox.x1 - 75.0).abs() < 1e-9);
}

#[test]
fn a_child_is_kept_only_while_an_ancestor_is_anchored() {
    // Params where a single sighting is not enough to anchor: the hand is never anchored.
    let params = Params { theta_anch: 0.5, theta_inf: 0.5, ..Params::cater() };
    let aapa = Aapa::new(params).unwrap();
    let gear = p("gear0", "gear", bx(10., 40., 30., 60.));
    let hand = p("hand0", "hand", bx(0., 0., 40., 40.));
    let mut frames = still(vec![gear.clone()], 6); // gear confidence 0.5: anchored
    frames.push((vec![gear, hand], vec![Action::completed("pick_up", &["hand0", "gear0"])]));
    frames.push((vec![], vec![]));
    let worlds = run(&aapa, &frames);
    let gear = worlds.last().unwrap().anchor("gear0").unwrap();
    // The hand (confidence 0) does not keep it: the gear is reasoned about on its own, and lost.
    assert_eq!(gear.status, AnchorStatus::Lost);
}

#[test]
fn attachment_cycles_are_refused() {
    let a = p("a0", "a", bx(0., 0., 10., 10.));
    let b = p("b0", "b", bx(20., 0., 30., 10.));
    let mut frames = still(vec![a.clone(), b.clone()], 2);
    frames.push((vec![a.clone(), b.clone()], vec![Action::completed("insert", &["a0", "b0"])]));
    frames.push((vec![a, b], vec![Action::completed("insert", &["b0", "a0"])]));
    let last = run(&cater(), &frames).pop().unwrap();
    assert!(last.has_relation("attached", "a0", "b0"));
    assert!(!last.has_relation("attached", "b0", "a0"));
    assert!(last.notes.iter().any(|n| n.contains("cycle")), "{:?}", last.notes);
}

#[test]
fn actions_may_name_types_and_unknown_names_become_notes() {
    let cone = p("cone0", "large_cone", bx(0., 0., 40., 40.));
    let snitch = p("spl0", "snitch", bx(10., 20., 20., 40.));
    let mut frames = still(vec![cone.clone(), snitch], 3);
    frames.push((
        vec![cone],
        vec![
            Action::completed("_contain", &["large_cone", "snitch"]),
            Action::completed("_contain", &["large_cone", "nothing_here"]),
        ],
    ));
    let last = run(&cater(), &frames).pop().unwrap();
    assert!(last.has_relation("attached", "spl0", "cone0"));
    assert!(last.has_relation("contained", "spl0", "cone0"));
    assert!(last.notes.iter().any(|n| n.contains("nothing_here")));
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let aapa = cater();
    let world = WorldState::default();
    let nan = p("n", "cube", bx(f64::NAN, 0., 1., 1.));
    assert!(matches!(aapa.step(0, &[nan], &[], None, &world), Err(AapaError::InvalidBox { .. })));
    let inverted = p("i", "cube", bx(10., 0., 1., 1.));
    assert!(matches!(aapa.step(0, &[inverted], &[], None, &world), Err(AapaError::InvalidBox { .. })));
    let world = aapa.step(10, &[], &[], None, &world).unwrap();
    assert!(matches!(aapa.step(10, &[], &[], None, &world), Err(AapaError::TimeNotIncreasing { .. })));
    let short = Action::completed("pick_up", &["hand0"]);
    assert!(matches!(aapa.step(20, &[], &[short], None, &world), Err(AapaError::ActionArity { .. })));
    let pose = CameraPose::default();
    assert!(matches!(aapa.step(20, &[], &[], Some(&pose), &world), Err(AapaError::NoCameraModel)));
    let bad = Params { theta_inf: 0.05, ..Params::cater() };
    assert!(matches!(Aapa::new(bad), Err(AapaError::InvalidParam { name: "theta_inf", .. })));
}

#[test]
fn camera_movement_is_compensated() {
    // f = 500 px, surface 0.5 m away: a 2 cm move to the right shifts the scene 20 px left.
    let camera = CameraModel { focal_px: 500.0, principal: [160.0, 120.0], surface_z: 0.5 };
    let params = Params { camera: Some(camera), ..Params::cater() };
    let aapa = Aapa::new(params).unwrap();
    let mut world = WorldState::default();
    let object = p("a", "cube", bx(100., 100., 120., 120.));
    for i in 0..3 {
        world = aapa
            .step(i * FRAME, std::slice::from_ref(&object), &[], Some(&CameraPose::default()), &world)
            .unwrap();
    }
    let moved = CameraPose { x: 0.02, y: 0.0, z: 0.0 };
    world = aapa.step(3 * FRAME, &[], &[], Some(&moved), &world).unwrap();
    let a = world.anchor("a").unwrap();
    assert!((a.bbox.x1 - 80.0).abs() < 1e-9 && (a.bbox.y1 - 100.0).abs() < 1e-9, "{:?}", a.bbox);
    // Moving towards the surface (half the depth) doubles sizes about the principal point.
    let closer = CameraPose { x: 0.02, y: 0.0, z: 0.25 };
    world = aapa.step(4 * FRAME, &[], &[], Some(&closer), &world).unwrap();
    let a = world.anchor("a").unwrap();
    assert!((a.bbox.width() - 40.0).abs() < 1e-9, "{:?}", a.bbox);
    assert!((a.bbox.x1 - (160.0 + (80.0 - 160.0) * 2.0)).abs() < 1e-9, "{:?}", a.bbox);
}

#[test]
fn theta_inf_filters_what_is_passed_on_and_spatial_relations_use_it() {
    let params = Params { theta_inf: 0.3, spatial_relations: true, ..Params::cater() };
    let aapa = Aapa::new(params).unwrap();
    let left = p("l", "cube", bx(0., 50., 20., 70.));
    let right = p("r", "cube", bx(40., 50., 60., 70.));
    let back = p("b", "cube", bx(35., 10., 65., 30.));
    let worlds = run(&aapa, &still(vec![left, right, back], 4));
    assert!(!worlds[2].anchor("l").unwrap().for_inference);
    assert!(!worlds[2].has_relation("left_of", "l", "r"));
    let last = &worlds[3];
    assert!(last.anchor("l").unwrap().for_inference);
    assert!(last.has_relation("left_of", "l", "r"));
    assert!(!last.has_relation("left_of", "r", "l"));
    assert!(last.has_relation("behind", "b", "r"));
    assert!(!last.has_relation("behind", "r", "b"));
}

#[test]
fn reacquisition_keeps_one_symbol_for_an_object_that_moved_while_hidden() {
    // The snitch hides behind a wall, moves 150 px while hidden, and reappears.
    let wall = p("w", "cube", bx(90., 60., 170., 140.));
    let before = p("s0", "snitch", bx(100., 100., 120., 120.));
    let after = p("s1", "snitch", bx(250., 100., 270., 120.));
    let mut frames = still(vec![before, wall.clone()], 3);
    frames.extend(still(vec![wall.clone()], 5));
    frames.extend(still(vec![after, wall], 3));
    for (extension, symbols) in [(true, 1), (false, 2)] {
        let params = Params {
            extensions: Extensions { reacquire: extension, ..Extensions::default() },
            ..Params::cater()
        };
        let last = run(&Aapa::new(params).unwrap(), &frames).pop().unwrap();
        let snitches: Vec<_> = last.anchors.iter().filter(|a| &*a.object_type == "snitch").collect();
        assert_eq!(snitches.len(), symbols, "reacquire {extension}: {snitches:?}");
        if extension {
            assert_eq!(&*snitches[0].symbol, "s0");
            assert_eq!(snitches[0].bbox.x1, 250.0);
        }
    }
}

#[test]
fn motion_is_predicted_only_while_an_action_moves_the_object() {
    // A cube slides right at 3 px per frame, disappears behind a wall for 10 frames, and the
    // slide action is known to end 5 frames after it disappeared.
    let wall = p("w", "cylinder", bx(30., 0., 200., 100.));
    let cube = |k: usize| p("c", "cube", bx(3.0 * k as f64, 40., 3.0 * k as f64 + 20., 60.));
    let mut frames: Vec<(Vec<Percept>, Vec<Action>)> = Vec::new();
    for k in 0..6 {
        let actions =
            if k == 0 { vec![Action::started("_slide", &["cube"], Some(10 * FRAME))] } else { vec![] };
        frames.push((vec![cube(k), wall.clone()], actions));
    }
    frames.extend(still(vec![wall], 10));
    let with_profile = |motion_profile| {
        let params =
            Params { extensions: Extensions { motion_profile, ..Extensions::default() }, ..Params::cater() };
        run(&Aapa::new(params).unwrap(), &frames).pop().unwrap().anchor("c").unwrap().bbox.x1
    };
    // Constant velocity: 3 px per frame for the 5 frames left of the action.
    let x_constant = with_profile(MotionProfile::ConstantVelocity);
    assert!((x_constant - 30.0).abs() < 1e-6, "moved to the end of the action: {x_constant}");
    // Ease in and out: seen half way (u = 0.5, speed 1.5 times the mean), so the whole move is
    // 3 px * 10 frames / 1.5 = 20 px, half of it still to come.
    let x_eased = with_profile(MotionProfile::EaseInOut);
    assert!((x_eased - 25.0).abs() < 1e-6, "decelerated to a stop: {x_eased}");
    let frozen = Params {
        extensions: Extensions { predict_motion: false, ..Extensions::default() },
        ..Params::cater()
    };
    let without = run(&Aapa::new(frozen).unwrap(), &frames).pop().unwrap();
    assert_eq!(without.anchor("c").unwrap().bbox.x1, 15.0, "H1: stays where last seen");
}

#[test]
fn a_carried_child_scales_with_its_parent() {
    let cone = |s: f64| p("cone0", "cone", bx(100. - 20. * s, 100. - 40. * s, 100. + 20. * s, 100.));
    let snitch = p("spl0", "snitch", bx(95., 90., 105., 100.));
    let mut frames = still(vec![cone(1.0), snitch], 3);
    frames.push((vec![cone(1.0)], vec![Action::completed("_contain", &["cone0", "spl0"])]));
    frames.push((vec![cone(1.5)], vec![])); // the cone comes closer: 1.5x bigger
    for (scale, width) in [(true, 15.0), (false, 10.0)] {
        let params = Params {
            extensions: Extensions { scale_attached: scale, ..Extensions::default() },
            ..Params::cater()
        };
        let last = run(&Aapa::new(params).unwrap(), &frames).pop().unwrap();
        let s = last.anchor("spl0").unwrap();
        assert!((s.bbox.width() - width).abs() < 1e-6, "scale {scale}: {:?}", s.bbox);
        assert!((s.bbox.y2 - 100.0).abs() < 1e-6);
    }
}

#[test]
fn contain_places_a_stale_child_inside_its_container() {
    let cone = p("cone0", "cone", bx(200., 60., 240., 100.));
    let snitch = p("spl0", "snitch", bx(20., 20., 30., 30.)); // last seen far away
    let mut frames = still(vec![cone.clone(), snitch], 3);
    frames.push((vec![cone.clone()], vec![]));
    frames.push((vec![cone], vec![Action::completed("_contain", &["cone0", "spl0"])]));
    let last = run(&cater(), &frames).pop().unwrap();
    let s = last.anchor("spl0").unwrap();
    assert_eq!(s.bbox, bx(215., 90., 225., 100.));
    let paper = run(&Aapa::new(Params::paper_cater()).unwrap(), &frames[..]).pop().unwrap();
    assert_eq!(paper.anchor("spl0").unwrap().bbox, bx(20., 20., 30., 30.));
}

#[test]
fn world_state_and_params_round_trip_through_json() {
    let worlds = run(&cater(), &hand_and_gear());
    let last = worlds.last().unwrap();
    let json = serde_json::to_value(last).unwrap();
    assert!(json["anchors"][0]["box"].is_array());
    let back: WorldState = serde_json::from_value(json).unwrap();
    assert_eq!(&back, last);
    for params in [Params::default(), Params::paper_cater(), kpl_aapa::gearbox::params()] {
        let text = serde_json::to_string(&params).unwrap();
        assert_eq!(serde_json::from_str::<Params>(&text).unwrap(), params);
    }
    let partial: Params = serde_json::from_str(r#"{"theta": 100.0}"#).unwrap();
    assert_eq!(partial.theta, 100.0);
    assert_eq!(partial.conf_plus, 0.1);
    assert!(serde_json::from_str::<Params>(r#"{"thetta": 1}"#).is_err());
    let action: Action = serde_json::from_str(r#"{"name": "pick_up", "args": ["hand0", "gear0"]}"#).unwrap();
    assert_eq!(action, Action::completed("pick_up", &["hand0", "gear0"]));
    let percept: Percept =
        serde_json::from_str(r#"{"label": "a", "type": "cube", "box": [1, 2, 3, 4]}"#).unwrap();
    assert_eq!(percept.bbox, bx(1., 2., 3., 4.));
}

#[test]
fn partial_boxes_are_restored_only_when_one_side_is_being_cut() {
    let restoring = Params {
        extensions: Extensions { restore_partial_boxes: true, ..Extensions::default() },
        ..Params::cater()
    };
    let aapa = Aapa::new(restoring).unwrap();
    let cone = p("cone0", "cone", bx(90., 40., 130., 95.));
    // Seen whole (alone), then a cone comes down: the visible part loses its top row by row.
    let mut frames = vec![(vec![p("s", "snitch", bx(100., 80., 120., 100.))], vec![]); 2];
    for top in [84., 88., 92.] {
        frames.push((vec![p("s", "snitch", bx(100., top, 120., 100.)), cone.clone()], vec![]));
    }
    let last = run(&aapa, &frames).pop().unwrap();
    assert_eq!(last.anchor("s").unwrap().bbox, bx(100., 80., 120., 100.));
    // Without the extension the anchor takes the cut box.
    let plain = run(&cater(), &frames).pop().unwrap();
    assert_eq!(plain.anchor("s").unwrap().bbox, bx(100., 92., 120., 100.));
    // An object that shrinks because it moves away (both edges move) keeps its new size.
    let mut away = vec![(vec![p("s", "snitch", bx(100., 80., 120., 100.))], vec![]); 2];
    for k in 1..=3 {
        let d = 2.0 * k as f64;
        away.push((
            vec![p("s", "snitch", bx(100. + d, 80. + d, 120. - d, 100. - 1.5 * d)), cone.clone()],
            vec![],
        ));
    }
    let last = run(&aapa, &away).pop().unwrap();
    assert_eq!(last.anchor("s").unwrap().bbox, bx(106., 86., 114., 91.));
}

const CONE: &str = "large_red_cone_rubber";
const SNITCH: &str = "small_gold_spl_metal";

/// Two identical cones and the snitch, anchored; then the cone on the right (`right`, not the one
/// the type alone would pick) comes down over the snitch: it rises for 5 frames, crosses, comes
/// down, while the other one stays put or (`other_moves`) slides away at the same time.
fn identical_cones(other_moves: bool) -> Vec<(Vec<Percept>, Vec<Action>)> {
    let snitch = bx(100.0, 100.0, 110.0, 110.0);
    let mut frames = Vec::new();
    for f in 0..40 {
        // Frames 10..=30: the right cone picks up (up 30 px over 5 frames), moves over the snitch, comes down.
        let u = |a: f64, b: f64| ((f as f64 - a) / (b - a)).clamp(0.0, 1.0);
        let lift = 30.0 * (u(10.0, 15.0) - u(25.0, 30.0));
        let x = 200.0 + (100.0 - 200.0) * u(15.0, 25.0);
        let right = bx(x - 8.0, 80.0 - lift, x + 18.0, 112.0 - lift);
        // The left cone stays at 40, or slides left from frame 10 to 30.
        let lx = if other_moves { 40.0 - 30.0 * u(10.0, 30.0) } else { 40.0 };
        let left = bx(lx, 80.0, lx + 26.0, 112.0);
        // The right cone is seen from frame 1: the left one is older, the one a type alone names.
        let mut percepts = vec![p("cone0", CONE, left)];
        if f > 0 {
            percepts.push(p("cone1", CONE, right));
        }
        if f < 26 {
            percepts.push(p("spl0", SNITCH, snitch));
        }
        let mut actions = Vec::new();
        if f == 10 {
            actions.push(Action::started("_contain", &[CONE, SNITCH], Some(30 * FRAME)));
            if other_moves {
                actions.push(Action::started("_slide", &[CONE], Some(30 * FRAME)));
            }
        }
        if f == 30 {
            actions.push(Action::completed("_contain", &[CONE, SNITCH]));
            if other_moves {
                actions.push(Action::completed("_slide", &[CONE]));
            }
        }
        frames.push((percepts, actions));
    }
    frames
}

#[test]
fn a_contain_by_one_of_two_identical_cones_attaches_to_the_one_that_moved() {
    for other_moves in [false, true] {
        let frames = identical_cones(other_moves);
        let worlds = run(&cater(), &frames);
        let last = worlds.last().unwrap();
        let snitch = last.anchor("spl0").unwrap();
        let parent = &snitch.attachment.as_ref().unwrap().parent;
        let cone = last.anchor(parent).unwrap();
        assert!(cone.bbox.x1 > 80.0, "other_moves {other_moves}: attached to {parent} at {:?}", cone.bbox);
        assert_eq!(snitch.status, AnchorStatus::Attached);
        assert!(last.has_relation("contained", "spl0", parent));
        // No binding is left open once the actions completed.
        assert!(last.bindings.iter().all(|b| b.completed), "{:?}", last.bindings);
    }
}

#[test]
fn a_contained_object_is_not_taken_by_another_detection() {
    let mut frames = identical_cones(false);
    // After the contain, a false detection of the snitch's class appears near the cone, then goes.
    for (percepts, _) in &mut frames[31..34] {
        percepts.push(p("ghost", SNITCH, bx(130.0, 95.0, 140.0, 105.0)));
    }
    let worlds = run(&cater(), &frames);
    let snitch = worlds.last().unwrap().anchor("spl0").unwrap().clone();
    assert_eq!(snitch.status, AnchorStatus::Attached);
    assert!((snitch.bbox.x1 - 100.0).abs() < 3.0, "{:?}", snitch.bbox);
}

#[test]
fn an_action_that_never_completes_is_forgotten() {
    let aapa = cater();
    let cones = vec![p("a", CONE, bx(0.0, 0.0, 20.0, 20.0)), p("b", CONE, bx(100.0, 0.0, 120.0, 20.0))];
    let mut world = WorldState::default();
    for f in 0..80 {
        let actions =
            if f == 20 { vec![Action::started("_slide", &[CONE], Some(25 * FRAME))] } else { vec![] };
        world = aapa.step(f * FRAME, &cones, &actions, None, &world).unwrap();
        if f == 21 {
            assert_eq!(world.bindings.len(), 1, "an open binding");
        }
    }
    assert!(world.bindings.is_empty());
}

#[test]
fn an_object_a_contain_names_but_never_perceived_is_inferred_inside_the_cone() {
    let cone = p("cone0", "cone", bx(200., 60., 240., 100.));
    let mut frames = still(vec![cone.clone()], 3);
    frames.push((vec![cone.clone()], vec![Action::completed("_contain", &["cone0", "snitch"])]));
    frames.push((vec![cone], vec![]));
    let last = run(&cater(), &frames).pop().unwrap();
    let s = last.best_of_type("snitch", 0.1).expect("inferred from the action");
    // A square of 0.42 of the cone's width centred 0.6 of its height down, attached, hidden.
    let expected = bx(220. - 8.4, 84. - 8.4, 220. + 8.4, 84. + 8.4);
    for (a, b) in [
        (s.bbox.x1, expected.x1),
        (s.bbox.y1, expected.y1),
        (s.bbox.x2, expected.x2),
        (s.bbox.y2, expected.y2),
    ] {
        assert!((a - b).abs() < 1e-9, "{:?}", s.bbox);
    }
    assert_eq!(s.status, AnchorStatus::Attached);
    assert!(s.attachment.as_ref().is_some_and(|a| &*a.parent == "cone0" && a.hidden));
    // The published algorithm has no anchor to attach, nor with the extension off.
    let off =
        Params { extensions: Extensions { infer_hidden: false, ..Extensions::default() }, ..Params::cater() };
    for params in [Params::paper_cater(), off] {
        let last = run(&Aapa::new(params).unwrap(), &frames).pop().unwrap();
        assert!(last.best_of_type("snitch", 0.0).is_none());
    }
}

#[test]
fn a_cone_that_came_down_unseen_is_put_over_its_content() {
    // The cone is last seen far away; it moves hidden and comes down over the snitch, which is
    // hidden by the cone in the completion frame. The contained snitch stays where it was, the cone
    // is believed over it, and when the cone is seen again the snitch keeps its place.
    let snitch = p("spl0", "snitch", bx(100., 90., 110., 100.));
    let far = p("cone0", "cone", bx(200., 60., 240., 100.));
    let mut frames = still(vec![far, snitch.clone()], 8);
    frames.push((vec![snitch], vec![Action::started("_contain", &["cone0", "spl0"], Some(11 * FRAME))]));
    frames.push((vec![], vec![]));
    frames.push((vec![], vec![]));
    frames.push((vec![], vec![Action::completed("_contain", &["cone0", "spl0"])]));
    let worlds = run(&cater(), &frames);
    let at_completion = &worlds[11];
    assert_eq!(at_completion.anchor("spl0").unwrap().bbox, bx(100., 90., 110., 100.));
    let cone = at_completion.anchor("cone0").unwrap();
    assert_eq!((cone.bbox.x1 + cone.bbox.x2) / 2.0, 105.0, "{:?}", cone.bbox);
    // Seen again a little lower (its rim is in front of the snitch): the snitch does not move.
    let mut frames = frames.clone();
    frames.push((vec![p("cone0", "cone", bx(85., 66., 125., 106.))], vec![]));
    frames.push((vec![p("cone0", "cone", bx(85., 66., 125., 106.))], vec![]));
    let last = run(&cater(), &frames).pop().unwrap();
    assert_eq!(last.anchor("spl0").unwrap().bbox, bx(100., 90., 110., 100.));
    assert_eq!(last.anchor("spl0").unwrap().status, AnchorStatus::Attached);
}

#[test]
fn a_cone_percept_taken_by_its_content_goes_back_to_the_cone() {
    // The cone moved hidden; when it lands over the snitch, its percept is nearer the snitch's
    // anchor than the cone's and is aligned to the snitch (type mismatch and all). The contain
    // completing in that frame gives it back.
    let snitch = p("spl0", "snitch", bx(100., 90., 110., 100.));
    let far = p("cone0", "cone", bx(250., 20., 270., 40.));
    let mut frames = still(vec![far, snitch], 3);
    frames.push((vec![], vec![Action::started("_contain", &["cone0", "spl0"], Some(5 * FRAME))]));
    let landed = p("cone0", "cone", bx(95., 80., 115., 101.));
    frames.push((vec![landed.clone()], vec![Action::completed("_contain", &["cone0", "spl0"])]));
    frames.push((vec![landed], vec![]));
    let worlds = run(&cater(), &frames);
    for w in &worlds[4..] {
        assert_eq!(w.anchor("cone0").unwrap().bbox, bx(95., 80., 115., 101.));
        assert_eq!(w.anchor("spl0").unwrap().bbox, bx(100., 90., 110., 100.));
    }
}

#[test]
fn a_contain_decided_by_proximity_takes_its_cone_back_from_a_slide_bound_by_motion_order() {
    // Two identical cones: a slide of the type starts first, then a contain of the snitch. The
    // contain's cone (lifted) shows motion before the slider, so the slide binds it first; the
    // contain completes over the snitch and takes that cone back.
    const CONE: &str = "large_blue_cone";
    let snitch = bx(100., 100., 110., 110.);
    let mut frames = Vec::new();
    for f in 0..40 {
        let u = |a: f64, b: f64| ((f as f64 - a) / (b - a)).clamp(0.0, 1.0);
        let lift = 30.0 * (u(12.0, 16.0) - u(26.0, 30.0));
        let x = 200.0 + (100.0 - 200.0) * u(16.0, 26.0);
        let lifted = bx(x - 8.0, 80.0 - lift, x + 18.0, 112.0 - lift);
        // The slider creeps from frame 10 and shows no motion before frame 14.
        let lx = 40.0 - 20.0 * u(14.0, 30.0).powi(2);
        let slider = bx(lx, 80.0, lx + 26.0, 112.0);
        let mut percepts = vec![p("cone0", CONE, slider), p("cone1", CONE, lifted)];
        if f < 26 {
            percepts.push(p("spl0", "snitch", snitch));
        }
        let mut actions = Vec::new();
        if f == 10 {
            actions.push(Action::started("_slide", &[CONE], Some(30 * FRAME)));
        }
        if f == 12 {
            actions.push(Action::started("_contain", &[CONE, "snitch"], Some(30 * FRAME)));
        }
        if f == 30 {
            actions.push(Action::completed("_slide", &[CONE]));
            actions.push(Action::completed("_contain", &[CONE, "snitch"]));
        }
        frames.push((percepts, actions));
    }
    let worlds = run(&cater(), &frames);
    let last = worlds.last().unwrap();
    let parent = &last.anchor("spl0").unwrap().attachment.as_ref().expect("contained").parent;
    assert_eq!(&**parent, "cone1");
    assert!(worlds.iter().any(|w| w.notes.iter().any(|n| n.contains("rebound"))));
}

#[test]
fn the_boxes_of_an_object_standing_still_are_averaged_when_asked() {
    // A detector's noise around a fixed box; the object is not moved by any action.
    let truth = [50.0, 50.0, 80.0, 90.0];
    let noise = [0.8, -1.1, 0.4, 1.3, -0.9, 0.2, -0.6, 1.0, -1.2, 0.7];
    let frames: Vec<(Vec<Percept>, Vec<Action>)> = (0..20)
        .map(|f| {
            let e = |k: usize| noise[(f * 3 + k) % noise.len()];
            let b = bx(truth[0] + e(0), truth[1] + e(1), truth[2] + e(2), truth[3] + e(3));
            (vec![p("cube0", "cube", b)], vec![])
        })
        .collect();
    let error = |b: &BBox| {
        [b.x1 - truth[0], b.y1 - truth[1], b.x2 - truth[2], b.y2 - truth[3]]
            .iter()
            .map(|d| d.abs())
            .sum::<f64>()
    };
    let averaging =
        Params { extensions: Extensions { average_still: true, ..Extensions::default() }, ..Params::cater() };
    let raw = run(&cater(), &frames).pop().unwrap().anchor("cube0").unwrap().bbox;
    let mean =
        run(&Aapa::new(averaging.clone()).unwrap(), &frames).pop().unwrap().anchor("cube0").unwrap().bbox;
    assert_eq!(raw, frames[19].0[0].bbox, "off by default: the latest box");
    assert!(error(&mean) < 0.5 * error(&raw), "mean {mean:?}, raw {raw:?}");
    // A move (an action) starts the mean again: right after it, the box is the new one.
    let mut moved = frames.clone();
    moved.push((
        vec![p("cube0", "cube", bx(60., 50., 90., 90.))],
        vec![Action::started("_slide", &["cube0"], None)],
    ));
    moved.push((
        vec![p("cube0", "cube", bx(70., 50., 100., 90.))],
        vec![Action::completed("_slide", &["cube0"])],
    ));
    let last = run(&Aapa::new(averaging).unwrap(), &moved).pop().unwrap();
    assert_eq!(last.anchor("cube0").unwrap().bbox, bx(70., 50., 100., 90.));
}
