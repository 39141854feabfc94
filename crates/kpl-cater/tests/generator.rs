//! The generator follows CATER's procedure (its `render_videos.py` and `actions.py`): objects,
//! sizes, Blender instance names, move timing, who may contain whom, the records of a stack's
//! contents, no collisions, at most two movers at a time in LA-CATER's mode; and it is deterministic
//! given a seed, whatever the thread count. Hard scenes have every hard property of issue 27, and
//! the second detector the kinds of noise its documentation names.
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

/// Where the snitch's outermost container is at a frame: the stack it is in (or itself).
fn snitch_stack_top(held: &BTreeMap<String, Vec<Option<String>>>, frame: usize) -> String {
    let mut top = SNITCH_INSTANCE.to_owned();
    loop {
        let holder =
            held.iter().find(|(_, v)| v[frame].as_deref() == Some(top.as_str())).map(|(k, _)| k.clone());
        match holder {
            Some(h) => top = h,
            None => return top,
        }
    }
}

#[test]
fn hard_scenes_have_every_hard_property() {
    use kpl_cater::perfect_pickles::union_covers;
    use kpl_cater::sim::{Profile, simulate};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    let config = GeneratorConfig { motion: Motion::Hard, ..GeneratorConfig::default() };
    let (mut crowded_slots, mut staggered, mut nested, mut on_snitch, mut contain_count) = (0, 0, 0, 0, 0);
    let (mut onto_moving, mut turning_snitch, mut twin_videos, mut union_only) = (0, 0, 0, 0);
    let mut profiles = HashSet::new();
    for i in 0..VIDEOS {
        let video = generate_video(21, i, &config);
        let scene = &video.scene;
        let held = contains(scene);
        // Several stacks moving at once, starting and ending at different frames.
        let moves: Vec<(i64, i64, &str)> = scene
            .movements
            .iter()
            .flat_map(|(o, ms)| {
                ms.iter()
                    .filter(|m| m.kind() != Some(MovementKind::NoOp))
                    .map(move |m| (m.start, m.end, o.as_str()))
            })
            .collect();
        for f in 0..FRAMES as i64 {
            let at: Vec<&(i64, i64, &str)> = moves.iter().filter(|m| m.0 <= f && f <= m.1).collect();
            let tops: HashSet<String> = at
                .iter()
                .filter(|m| !held.values().any(|v| v[f as usize].as_deref() == Some(m.2)))
                .map(|m| m.2.to_owned())
                .collect();
            if tops.len() >= 3 {
                crowded_slots += 1;
                let starts: HashSet<i64> = at.iter().map(|m| m.0).collect();
                let ends: HashSet<i64> = at.iter().map(|m| m.1).collect();
                staggered += usize::from(starts.len() >= 3 && ends.len() >= 3);
                break;
            }
        }
        // Contains onto the snitch's stack (nested when that stack is a cone holding it), and onto
        // a stack that slid in the same slot.
        for (cone, ms) in &scene.movements {
            for m in ms.iter().filter(|m| m.kind() == Some(MovementKind::Contain)) {
                contain_count += 1;
                let target = m.other.clone().unwrap();
                let start = m.start as usize;
                if target == snitch_stack_top(&held, start.saturating_sub(1)) {
                    on_snitch += 1;
                    nested += usize::from(target != SNITCH_INSTANCE);
                }
                let slid = scene.movements[&target]
                    .iter()
                    .any(|s| s.kind() == Some(MovementKind::Slide) && s.start >= m.start && s.end < m.end);
                onto_moving += usize::from(slid);
                assert!(cone.contains("Cone"));
            }
        }
        // The winged snitch turns where it stands: its box changes, its location does not.
        for m in scene.movements[SNITCH_INSTANCE].iter().filter(|m| m.kind() == Some(MovementKind::Rotate)) {
            let locations = &scene.object(SNITCH_INSTANCE).unwrap().locations.0;
            let boxes = &video.ground_truth.objects[SNITCH_KEY];
            let (s, e) = (m.start as usize, (m.end as usize).min(FRAMES - 1));
            assert_eq!(locations[s], locations[e]);
            let change = (boxes[s][2] - boxes[e][2]).abs().max((boxes[s][3] - boxes[e][3]).abs());
            turning_snitch += usize::from(change >= 3);
        }
        // Identical objects.
        let mut classes: Vec<String> = scene.objects.iter().map(|o| o.class()).collect();
        classes.sort();
        twin_videos += usize::from(classes.windows(2).any(|w| w[0] == w[1]));
        // Occlusion by the union of nearer boxes: the visible annotation is the snitch in the
        // perfect perception, and some frame hides it behind two boxes, neither of which hides it.
        let camera = video.scene.camera.unwrap().location();
        let snitch_boxes = video.ground_truth.boxes_of(SNITCH_KEY).unwrap();
        for (f, frame) in video.opnet_perfect.iter().enumerate() {
            assert_eq!(video.categories.visible[f], frame.iter().any(|(l, _)| *l == 140), "frame {f}");
            if video.categories.visible[f] || video.categories.contained[f] {
                continue;
            }
            let distance = |p: [f64; 3]| {
                ((p[0] - camera[0]).powi(2) + (p[1] - camera[1]).powi(2) + (p[2] - camera[2]).powi(2)).sqrt()
            };
            let me = distance(scene.object(SNITCH_INSTANCE).unwrap().locations.0[f]);
            let nearer: Vec<[i64; 4]> = scene
                .objects
                .iter()
                .filter(|o| o.instance != SNITCH_INSTANCE && distance(o.locations.0[f]) < me)
                .filter_map(|o| video.ground_truth.boxes_of(&o.key()).map(|b| b[f].map(i64::from)))
                .collect();
            let target = snitch_boxes[f].map(i64::from);
            if union_covers(target, &nearer) && nearer.iter().all(|b| !union_covers(target, &[*b])) {
                union_only += 1;
            }
        }
    }
    // The four motion profiles, from the simulation's poses a quarter into each single slide.
    for i in 0..VIDEOS as u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        rng.set_stream(1000 + i);
        let sim = simulate(&mut rng, Motion::Hard);
        for (k, object) in sim.objects.iter().enumerate() {
            for m in &sim.movements[&object.info.instance] {
                let (s, e) = (m.start as usize, m.end as usize);
                if m.kind() != Some(MovementKind::Slide) || e >= FRAMES || (e - s) % 4 != 0 {
                    continue;
                }
                let at = |f: usize| sim.states[f][k].position;
                let (a, b, q) = (at(s), at(e), at(s + (e - s) / 4));
                let total = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
                if total < 0.5 {
                    continue;
                }
                let done = ((q[0] - a[0]).powi(2) + (q[1] - a[1]).powi(2)).sqrt() / total;
                if let Some(p) = Profile::ALL.into_iter().find(|p| (p.at(0.25) - done).abs() < 0.01) {
                    profiles.insert(format!("{p:?}"));
                }
            }
        }
    }
    eprintln!(
        "{crowded_slots} videos with 3+ stacks moving at once ({staggered} staggered), {contain_count} contains, \
         {on_snitch} onto the snitch's stack ({nested} nested), {onto_moving} onto a stack that slid, \
         {turning_snitch} snitch turns that change its box, {twin_videos} videos with identical objects, \
         {union_only} frames hidden only by a union, profiles {profiles:?}"
    );
    assert!(crowded_slots >= VIDEOS / 2 && staggered >= VIDEOS / 4);
    assert!(on_snitch * 4 >= contain_count && nested >= 5 && onto_moving >= 3);
    assert!(turning_snitch >= 3 && twin_videos >= VIDEOS / 2 && union_only >= 1);
    assert_eq!(profiles.len(), 4, "{profiles:?}");
}

#[test]
fn the_second_detector_has_its_own_kinds_of_noise() {
    use kpl_cater::detector_b::{DetectorBNoise, SNITCH_LOOKALIKE, UNKNOWN_CLASS, detect_video_b};
    use kpl_cater::render::{Camera, render};
    use kpl_cater::sim::simulate;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    let noise = DetectorBNoise::default();
    let (mut seen_clear, mut clear, mut seen_faint, mut faint) = (0usize, 0usize, 0usize, 0usize);
    let (mut snitch, mut lookalike, mut unknown, mut duplicates) = (0usize, 0usize, 0usize, 0usize);
    let (mut errors, mut sigmas, mut pairs) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..12u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        rng.set_stream(i);
        let sim = simulate(&mut rng, Motion::MaxTwo);
        let camera = Camera::new(sim.camera);
        let frames: Vec<_> = sim.states.iter().map(|s| render(&camera, &sim.objects, s)).collect();
        let mut classes: Vec<String> = Vec::new();
        let object_class: Vec<u32> = sim
            .objects
            .iter()
            .map(|o| {
                let c = o.info.class();
                let k = classes.iter().position(|x| *x == c).unwrap_or_else(|| {
                    classes.push(c);
                    classes.len() - 1
                });
                k as u32
            })
            .collect();
        let unique = |k: usize| object_class.iter().filter(|c| **c == object_class[k]).count() == 1;
        let detections = detect_video_b(&mut rng, &frames, &mut classes, &object_class, &noise);
        // Per object of a class of its own: its detection in each frame (the nearest of its class).
        let mut previous_error: Vec<Option<f64>> = vec![None; sim.objects.len()];
        for (frame, found) in frames.iter().zip(&detections) {
            for (k, r) in frame.iter().enumerate() {
                let Some(whole) = r.bbox else { continue };
                let own: Vec<_> = found.iter().filter(|d| d.class == object_class[k]).collect();
                let matched = own
                    .iter()
                    .find(|d| (d.bbox[0] - whole.x1).abs() < 8.0 && (d.bbox[1] - whole.y1).abs() < 8.0);
                if unique(k) && r.visible_fraction >= 0.6 {
                    clear += 1;
                    seen_clear += usize::from(matched.is_some());
                }
                if unique(k) && (0.1..0.2).contains(&r.visible_fraction) {
                    faint += 1;
                    seen_faint += usize::from(matched.is_some());
                }
                duplicates += usize::from(unique(k) && own.len() >= 2);
                match matched {
                    Some(d) if unique(k) && r.visible_fraction >= 0.99 => {
                        let e = d.bbox[0] - whole.x1;
                        errors.push(e);
                        sigmas.push(noise.edge_sigma_px + noise.edge_sigma_relative * whole.width());
                        if let Some(p) = previous_error[k] {
                            pairs.push((p, e));
                        }
                        previous_error[k] = Some(e);
                    }
                    _ => previous_error[k] = None,
                }
            }
            let real_lookalike = sim.objects.iter().any(|o| o.info.class() == SNITCH_LOOKALIKE);
            for d in found {
                let name = classes[d.class as usize].as_str();
                snitch += usize::from(name == SNITCH_CLASS);
                lookalike += usize::from(name == SNITCH_LOOKALIKE && !real_lookalike);
                unknown += usize::from(name == UNKNOWN_CLASS);
            }
        }
    }
    // Detection falls with the visible fraction (a logistic, half at 30 %).
    let (p_clear, p_faint) = (seen_clear as f64 / clear as f64, seen_faint as f64 / faint.max(1) as f64);
    assert!(p_clear > 0.85 && p_faint < 0.3, "clear {p_clear:.3}, faint {p_faint:.3}");
    // Edge errors of 0.6 px plus 3 % of the box (rounded to whole pixels), correlated frame to frame.
    let spread = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let sigma = sigmas.iter().sum::<f64>() / sigmas.len() as f64;
    assert!((spread / sigma - 1.0).abs() < 0.35, "spread {spread:.2} against sigma {sigma:.2}");
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (a, b): (Vec<f64>, Vec<f64>) = pairs.iter().copied().unzip();
    let (ma, mb) = (mean(&a), mean(&b));
    let cov = pairs.iter().map(|(x, y)| (x - ma) * (y - mb)).sum::<f64>();
    let var = |v: &[f64], m: f64| v.iter().map(|x| (x - m).powi(2)).sum::<f64>();
    let correlation = cov / (var(&a, ma) * var(&b, mb)).sqrt();
    assert!(correlation > 0.3, "frame-to-frame correlation {correlation:.2}");
    // The snitch taken for a small yellow sphere now and then (4 %, and its share of the 2 % of
    // wrong attributes, which stick for 1 to 4 frames), unclassified detections, duplicates.
    let share = lookalike as f64 / (snitch + lookalike) as f64;
    assert!((0.03..0.15).contains(&share), "the snitch taken for a sphere in {share:.3}");
    assert!(unknown > 0 && duplicates > 0, "{unknown} unclassified, {duplicates} duplicates");
}
