//! The generator follows CATER's procedure (its `render_videos.py` and `actions.py`): objects,
//! sizes, Blender instance names, move timing, who may contain whom, the records of a stack's
//! contents, no collisions, at most two movers at a time in LA-CATER's mode; and it is deterministic
//! given a seed, whatever the thread count.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::collections::{BTreeMap, HashSet};

use kpl_cater::classes::{SNITCH_CLASS, blender_name};
use kpl_cater::dataset::{self, GeneratorConfig, generate_video};
use kpl_cater::formats::{FRAMES, MovementKind, SNITCH_INSTANCE, SNITCH_KEY, Scene};
use kpl_cater::layout;
use kpl_cater::sim::{KEYFRAMES, MIN_DIST, MOVEMENT_MAX, MOVEMENT_MIN, Motion};

const VIDEOS: usize = 40;

#[test]
fn same_seed_same_video_other_seed_other_video() {
    let config = GeneratorConfig::default();
    let a = generate_video(11, 3, &config);
    let b = generate_video(11, 3, &config);
    assert_eq!(a.scene, b.scene);
    assert_eq!(a.ground_truth, b.ground_truth);
    assert_eq!(a.detector, b.detector);
    assert_ne!(generate_video(12, 3, &config).scene, a.scene);
    assert_ne!(generate_video(11, 4, &config).scene, a.scene);
}

#[test]
fn output_does_not_depend_on_the_thread_count() {
    let base = std::env::temp_dir().join(format!("kpl-cater-gen-{}", std::process::id()));
    let (one, two) = (base.join("one"), base.join("two"));
    let config = GeneratorConfig::default();
    let m1 = dataset::generate(&one, 4, 9, 1, &config).unwrap();
    let m2 = dataset::generate(&two, 4, 9, 2, &config).unwrap();
    assert_eq!(m1, m2);
    for video in layout::list_videos(&one).unwrap() {
        for path in [layout::scene_path, layout::ground_truth_path] {
            assert_eq!(
                std::fs::read(path(&one, &video)).unwrap(),
                std::fs::read(path(&two, &video)).unwrap()
            );
        }
    }
    for file in [layout::CONTAINMENT_FILE, layout::CARRIED_FILE, layout::VISIBLE_FILE] {
        let read = |d: &std::path::Path| std::fs::read(layout::annotations_dir(d).join(file)).unwrap();
        assert_eq!(read(&one), read(&two));
    }
    assert_eq!(layout::list_videos(&two).unwrap().len(), 4);
    let mix = m1.frame_mix;
    assert_eq!(mix.frames, 4 * FRAMES);
    // Every frame is visible, occluded or contained, and only one of them.
    assert_eq!(mix.visible + mix.occluded + mix.contained, mix.frames);
    std::fs::remove_dir_all(&base).unwrap();
}

fn size_of(scene: &Scene, instance: &str) -> f64 {
    scene.object(instance).unwrap().sized.unwrap()
}

/// Replays CATER's `contains` record: which object each cone holds at each frame (from the
/// contain's start to the end of the cone's next pick-up).
fn contains(scene: &Scene) -> BTreeMap<String, Vec<Option<String>>> {
    let mut out: BTreeMap<String, Vec<Option<String>>> =
        scene.objects.iter().map(|o| (o.instance.clone(), vec![None; KEYFRAMES])).collect();
    for (cone, moves) in &scene.movements {
        for m in moves {
            match m.kind().unwrap() {
                MovementKind::Contain => {
                    for f in m.start as usize..KEYFRAMES {
                        out.get_mut(cone).unwrap()[f] = m.other.clone();
                    }
                }
                MovementKind::PickPlace => {
                    for f in m.end as usize..KEYFRAMES {
                        out.get_mut(cone).unwrap()[f] = None;
                    }
                }
                _ => {}
            }
        }
    }
    out
}

/// Everything inside `instance` (at any depth) at a frame.
fn contents(held: &BTreeMap<String, Vec<Option<String>>>, instance: &str, frame: usize) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = held[instance][frame].clone();
    while let Some(c) = current {
        current = held[&c][frame].clone();
        out.push(c);
    }
    out
}

#[test]
fn cater_rules_hold() {
    let mut duplicate_videos = 0;
    let mut nested = 0;
    let mut no_ops = 0;
    let mut most_movers = [0usize; 2];
    for (m, motion) in [Motion::MaxTwo, Motion::All].into_iter().enumerate() {
        let config = GeneratorConfig { motion, ..GeneratorConfig::default() };
        for index in 0..VIDEOS {
            let video = generate_video(1, index, &config);
            let scene = &video.scene;
            let n = scene.objects.len();
            assert!((5..=10).contains(&n));
            // The snitch, a medium and a large cone, then anything; instance names as Blender's.
            let first: Vec<(String, String)> =
                scene.objects[..3].iter().map(|o| (o.class(), o.instance.clone())).collect();
            assert_eq!((first[0].0.as_str(), first[0].1.as_str()), (SNITCH_CLASS, SNITCH_INSTANCE));
            assert!(
                first[1].0.starts_with("medium_") && first[1].0.contains("_cone_") && first[1].1 == "Cone_0"
            );
            assert!(
                first[2].0.starts_with("large_") && first[2].0.contains("_cone_") && first[2].1 == "Cone_1"
            );
            let mut per_shape: BTreeMap<&str, usize> = BTreeMap::new();
            for o in &scene.objects {
                let k = per_shape.entry(o.shape.as_str()).or_insert(0);
                assert_eq!(o.instance, format!("{}_{k}", blender_name(&o.shape)));
                *k += 1;
                let expected = match (o.shape.as_str(), o.size.as_str()) {
                    ("spl", _) => 0.3,
                    (_, "small") => 0.25,
                    (_, "medium") => 0.5,
                    _ => 0.75,
                };
                assert_eq!(o.sized, Some(expected));
                assert_eq!(o.locations.0.len(), KEYFRAMES);
            }
            let classes: HashSet<String> = scene.objects.iter().map(|o| o.class()).collect();
            duplicate_videos += usize::from(classes.len() < n);
            assert_eq!(video.ground_truth.objects.len(), n);
            assert!(video.ground_truth.objects.contains_key(SNITCH_KEY));

            let held = contains(scene);
            let mut moving = vec![0usize; KEYFRAMES];
            for (instance, moves) in &scene.movements {
                let object = scene.object(instance).unwrap();
                for mv in moves {
                    let kind = mv.kind().unwrap();
                    let (start, end) = (mv.start as usize, mv.end as usize);
                    assert!(
                        end - start >= MOVEMENT_MIN && end - start <= MOVEMENT_MAX || end == KEYFRAMES - 1
                    );
                    match kind {
                        MovementKind::Rotate => assert!(!["cone", "sphere"].contains(&object.shape.as_str())),
                        MovementKind::Contain => {
                            let other = mv.other.as_deref().unwrap();
                            let target = scene.object(other).unwrap();
                            assert_eq!(object.shape, "cone");
                            assert!(["cone", "sphere", "spl"].contains(&target.shape.as_str()));
                            assert!(size_of(scene, instance) > size_of(scene, other));
                            nested += usize::from(target.shape == "cone" && held[other][end].is_some());
                        }
                        MovementKind::Slide | MovementKind::PickPlace => {
                            // A stack's contents get records of the same frames: a slide for a
                            // slide, `_no_op` for a pick-up.
                            let want = if kind == MovementKind::Slide {
                                MovementKind::Slide
                            } else {
                                MovementKind::NoOp
                            };
                            for inside in contents(&held, instance, start) {
                                assert!(
                                    scene.movements[&inside].iter().any(|n| n.kind() == Some(want)
                                        && n.start == mv.start
                                        && n.end == mv.end),
                                    "{}: {inside} inside {instance} has no {} for {mv:?}",
                                    scene.video,
                                    want.name()
                                );
                            }
                        }
                        MovementKind::NoOp => no_ops += 1,
                    }
                    // Count each stack once: by its outermost object.
                    let outer = !held.values().any(|h| h[start].as_deref() == Some(instance.as_str()));
                    if kind != MovementKind::NoOp && outer {
                        for slot in &mut moving[start..=end] {
                            *slot += 1;
                        }
                    }
                }
            }
            let peak = moving.iter().copied().max().unwrap_or(0);
            if motion == Motion::MaxTwo {
                assert!(peak <= 2, "{}: {peak} stacks move at once", scene.video);
            }
            most_movers[m] = most_movers[m].max(peak);
            // No collisions, except within a stack.
            for (i, a) in scene.objects.iter().enumerate() {
                for b in &scene.objects[i + 1..] {
                    for f in 0..KEYFRAMES {
                        let (p, q) = (a.locations.0[f], b.locations.0[f]);
                        let d =
                            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                        let together = contents(&held, &a.instance, f).contains(&b.instance)
                            || contents(&held, &b.instance, f).contains(&a.instance);
                        assert!(
                            together || d - a.sized.unwrap() - b.sized.unwrap() >= MIN_DIST - 1e-9,
                            "{}: {} and {} collide at frame {f}",
                            scene.video,
                            a.instance,
                            b.instance
                        );
                    }
                }
            }
        }
    }
    assert!(duplicate_videos > 0, "classes are drawn with replacement: some video has two identical objects");
    assert!(nested > 0, "some cone contains a cone that contains something");
    assert!(no_ops > 0, "contents of a picked-up cone get _no_op records");
    assert!(most_movers[1] > 2, "in the all-objects mode more than two stacks move at once: {most_movers:?}");
}

#[test]
fn a_contained_snitch_is_never_visible_and_boxes_stay_in_the_image() {
    for index in 0..VIDEOS {
        let video = generate_video(2, index, &GeneratorConfig::default());
        let c = &video.categories;
        for f in 0..FRAMES {
            assert!(!(c.visible[f] && c.contained[f]), "{} frame {f}", video.scene.video);
            assert!(!c.carried[f] || c.contained[f]);
        }
        for boxes in video.ground_truth.objects.values() {
            for &[x, y, w, h] in boxes {
                assert!(x >= 0 && y >= 0 && w >= 0 && h >= 0 && x + w <= 320 && y + h <= 240);
            }
        }
        // Perfect perception never sees the snitch while a cone holds it.
        let snitch = video.perfect.classes.iter().position(|c| c == SNITCH_CLASS).unwrap() as u32;
        for (f, frame) in video.perfect.frames.iter().enumerate() {
            if c.contained[f] && f > 0 && c.contained[f - 1] {
                assert!(frame.iter().all(|d| d.class != snitch), "{} frame {f}", video.scene.video);
            }
        }
    }
}
