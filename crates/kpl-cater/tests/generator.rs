//! The generator follows CATER's rules, is deterministic given a seed (whatever the thread count),
//! and renders occlusion consistently with containment.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::collections::{BTreeMap, HashSet};

use kpl_cater::dataset::{self, generate_video};
use kpl_cater::formats::{FRAMES, HEIGHT, SNITCH_CLASS, SNITCH_INSTANCE, SNITCH_KEY, WIDTH};
use kpl_cater::scene::{MAX_MOVE_FRAMES, MIN_MOVE_FRAMES, SLOT_FRAMES};
use kpl_cater::score::containment_frames;

const VIDEOS: usize = 60;

#[test]
fn same_seed_same_video_other_seed_other_video() {
    let a = generate_video(11, 3);
    let b = generate_video(11, 3);
    assert_eq!(a.scene, b.scene);
    assert_eq!(a.ground_truth, b.ground_truth);
    assert_eq!(a.detector, b.detector);
    assert_ne!(generate_video(12, 3).scene, a.scene);
    assert_ne!(generate_video(11, 4).scene, a.scene);
}

#[test]
fn output_does_not_depend_on_the_thread_count() {
    let base = std::env::temp_dir().join(format!("kpl-cater-gen-{}", std::process::id()));
    let (one, two) = (base.join("one"), base.join("two"));
    dataset::generate(&one, 4, 9, 1).unwrap();
    dataset::generate(&two, 4, 9, 2).unwrap();
    for video in dataset::list_videos(&one).unwrap() {
        for path in [dataset::scene_path, dataset::ground_truth_path] {
            assert_eq!(
                std::fs::read(path(&one, &video)).unwrap(),
                std::fs::read(path(&two, &video)).unwrap()
            );
        }
    }
    assert_eq!(dataset::list_videos(&two).unwrap().len(), 4);
    std::fs::remove_dir_all(&base).unwrap();
}

#[test]
fn cater_rules_hold() {
    let mut nested = 0;
    let mut snitch_contained_videos = 0;
    let mut carried_frames = 0;
    for index in 0..VIDEOS {
        let video = generate_video(1, index);
        let scene = &video.scene;
        assert!((5..=10).contains(&scene.objects.len()));
        let classes: HashSet<String> = scene.objects.iter().map(|o| o.class()).collect();
        assert_eq!(classes.len(), scene.objects.len(), "classes are unique");
        assert_eq!(scene.objects.iter().filter(|o| o.instance == SNITCH_INSTANCE).count(), 1);
        let size_rank = |instance: &str| {
            let o = scene.object(instance).unwrap();
            ["small", "medium", "large"].iter().position(|s| *s == o.size).unwrap()
        };
        // Who is contained by whom, frame by frame, replayed from the movements.
        let mut per_slot: BTreeMap<(usize, String), usize> = BTreeMap::new();
        for (instance, moves) in &scene.movements {
            for m in moves {
                let frames = (m.end - m.start + 1) as usize;
                assert!((MIN_MOVE_FRAMES..=MAX_MOVE_FRAMES).contains(&frames), "{instance} {m:?}");
                let slot = m.start as usize / SLOT_FRAMES;
                assert_eq!(m.end as usize / SLOT_FRAMES, slot, "a move stays in its slot: {m:?}");
                assert!((m.end as usize) < FRAMES);
                *per_slot.entry((slot, instance.clone())).or_default() += 1;
                if m.action == "_contain" {
                    assert!(instance.starts_with("Cone_"), "only cones contain: {instance}");
                    let target = m.other.as_deref().unwrap();
                    assert!(size_rank(target) < size_rank(instance), "{instance} contains larger {target}");
                    if target.starts_with("Cone_") {
                        nested += 1;
                    }
                } else {
                    assert_eq!(m.other, None);
                }
                if m.action == "_rotate" {
                    let shape = &scene.object(instance).unwrap().shape;
                    assert!(shape == "cube" || shape == "cylinder", "{shape} rotates");
                }
            }
        }
        assert!(per_slot.values().all(|&n| n == 1), "one move per object per slot");

        // The snitch is never visible while contained, and boxes lie in the image.
        let (contained, carried) = containment_frames(scene, FRAMES);
        if contained.iter().any(|c| *c) {
            snitch_contained_videos += 1;
        }
        carried_frames += carried.iter().filter(|c| **c).count();
        for (f, is_contained) in contained.iter().enumerate() {
            if *is_contained {
                assert!(
                    !video.perfect.has_class(f, SNITCH_CLASS),
                    "video {index} frame {f}: contained but visible"
                );
            }
        }
        for boxes in video.ground_truth.objects.values() {
            assert_eq!(boxes.len(), FRAMES);
            for &[x, y, w, h] in boxes {
                assert!(x >= 0 && y >= 0 && w >= 0 && h >= 0);
                assert!(f64::from(x + w) <= WIDTH && f64::from(y + h) <= HEIGHT);
            }
        }
        assert!(video.ground_truth.objects.contains_key(SNITCH_KEY));
    }
    assert!(nested > 0, "containment nests in some videos");
    assert!(snitch_contained_videos > VIDEOS / 4, "the snitch is often contained: {snitch_contained_videos}");
    assert!(carried_frames > 0, "and carried");
}

#[test]
fn contained_objects_do_not_act() {
    for index in 0..VIDEOS {
        let video = generate_video(2, index);
        let scene = &video.scene;
        // Containment intervals of every object, by OPNet's rule generalised to any target.
        for (cone, moves) in &scene.movements {
            for (k, m) in moves.iter().enumerate().filter(|(_, m)| m.action == "_contain") {
                let target = m.other.clone().unwrap();
                let release =
                    moves[k..].iter().find(|n| n.action == "_pick_place").map_or(FRAMES as i64, |n| n.start);
                for own in scene.movements.get(&target).into_iter().flatten() {
                    assert!(
                        own.start < m.end || own.start >= release,
                        "video {index}: {target} moves at {} while in {cone} ({}..{release})",
                        own.start,
                        m.end
                    );
                }
            }
        }
    }
}
