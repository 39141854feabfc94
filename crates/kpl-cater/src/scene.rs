//! The CATER-style scene generator: objects on a table and their movements under CATER's rules,
//! simulated frame by frame in 3D.
//!
//! Rules (CATER, Girdhar and Ramanan 2020, as LA-CATER uses them):
//! - 5 to 10 objects, one of them the snitch (`small_gold_spl_metal`); the others are cubes,
//!   spheres, cylinders and cones of 3 sizes, 8 colours and 2 materials, each class used once,
//!   placed apart on the table (x, y in [-3, 3]);
//! - 300 frames in 10 slots of 30; in each slot every free object acts with probability 1/2, once;
//!   a move lasts 20 to 30 frames and eases in and out (Blender's default keyframe interpolation);
//! - `_slide` moves along the table; `_pick_place` lifts, carries and puts down; `_rotate` turns in
//!   place (cubes and cylinders); `_contain` is a cone's pick-and-place onto a smaller object, which
//!   is then hidden and moves with the cone until the cone is next picked up; cones nest (a larger
//!   cone can contain a cone that contains something); a cone that contains something can slide
//!   (carrying its contents) or be picked up (releasing them) but does not contain anything else;
//!   contained objects do not act, and a contain target stays still during that slot;
//! - a cone that acts and may contain something does so half the time, and then chooses the snitch
//!   (or the outermost cone around it) half the time when it may, as CATER's localisation videos
//!   are made to hide the snitch often.

use std::collections::BTreeMap;

use rand::Rng;
use rand::seq::{IndexedRandom, SliceRandom};
use rand_chacha::ChaCha8Rng;

use crate::formats::{FRAMES, Movement, SNITCH_INSTANCE, Scene, SceneCamera, SceneObject};

pub const SLOTS: usize = 10;
pub const SLOT_FRAMES: usize = 30;
pub const MIN_MOVE_FRAMES: usize = 20;
pub const MAX_MOVE_FRAMES: usize = 30;
/// Probability that a free object acts in a slot.
pub const ACT_PROBABILITY: f64 = 0.5;
/// Probability that a cone that acts and may contain something does.
pub const CONTAIN_PROBABILITY: f64 = 0.5;
/// Probability that a containing cone picks the snitch (or its outermost container) when allowed.
pub const SNITCH_TARGET_PROBABILITY: f64 = 0.5;
/// How high `_pick_place` and `_contain` lift an object, CATER units.
pub const LIFT_HEIGHT: f64 = 1.5;
/// The table's half extent.
pub const TABLE: f64 = 3.0;

pub const SIZES: [(&str, f64); 3] = [("small", 0.35), ("medium", 0.5), ("large", 0.7)];
pub const COLORS: [&str; 8] = ["gray", "red", "blue", "green", "brown", "purple", "cyan", "yellow"];
pub const MATERIALS: [&str; 2] = ["rubber", "metal"];
pub const SHAPES: [&str; 4] = ["cube", "sphere", "cylinder", "cone"];

/// Shape of an object, for rendering.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    Cube,
    Sphere,
    Cylinder,
    Cone,
    Snitch,
}

/// An object with what rendering needs.
#[derive(Debug, Clone, PartialEq)]
pub struct SimObject {
    pub info: SceneObject,
    pub shape: Shape,
    /// Half extent (CLEVR's size: small 0.35, medium 0.5, large 0.7).
    pub half: f64,
}

/// An object's state in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ObjectState {
    /// x, y on the table; z the height of the object's base (lifted while picked up).
    pub position: [f64; 3],
    /// Rotation about the vertical axis, radians.
    pub yaw: f64,
    /// Hidden inside a cone.
    pub contained: bool,
}

/// A generated video: its scene JSON and every object's state in every frame.
#[derive(Debug, Clone)]
pub struct Simulation {
    pub scene: Scene,
    pub objects: Vec<SimObject>,
    /// `states[frame][object]`.
    pub states: Vec<Vec<ObjectState>>,
}

/// CLEVR's camera, jittered per video by up to half a unit on each axis, looking at the table's
/// centre; 350 px focal length at 320x240 (a 49 degree horizontal field of view).
pub fn sample_camera(rng: &mut ChaCha8Rng) -> SceneCamera {
    let base = [7.48, -6.51, 5.34];
    let location = base.map(|v| v + rng.random_range(-0.5..0.5));
    SceneCamera { location, look_at: [0.0, 0.0, 0.0], focal_px: 350.0 }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    Slide,
    PickPlace,
    Rotate,
    Contain(usize),
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Slide => "_slide",
            Kind::PickPlace => "_pick_place",
            Kind::Rotate => "_rotate",
            Kind::Contain(_) => "_contain",
        }
    }
}

#[derive(Debug, Clone)]
struct Plan {
    object: usize,
    kind: Kind,
    start: usize,
    end: usize,
    from: [f64; 2],
    to: [f64; 2],
    yaw_from: f64,
    yaw_to: f64,
}

fn smoothstep(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * (3.0 - 2.0 * u)
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// Generates one video's objects and movements and simulates all its frames.
pub fn simulate(rng: &mut ChaCha8Rng, video: &str) -> Simulation {
    let camera = sample_camera(rng);
    let objects = sample_objects(rng);
    let n = objects.len();
    let mut position: Vec<[f64; 2]> = objects.iter().map(|o| [o.info.coords[0], o.info.coords[1]]).collect();
    let mut yaw: Vec<f64> = objects.iter().map(|o| o.info.rotation.to_radians()).collect();
    let mut container: Vec<Option<usize>> = vec![None; n];
    let mut movements: BTreeMap<String, Vec<Movement>> =
        objects.iter().map(|o| (o.info.instance.clone(), Vec::new())).collect();
    let mut states = Vec::with_capacity(FRAMES);
    let snitch = 0;

    for slot in 0..SLOTS {
        let slot_start = slot * SLOT_FRAMES;
        let slot_end = (slot_start + SLOT_FRAMES - 1).min(FRAMES - 1);
        let plans = plan_slot(rng, &objects, &position, &yaw, &container, snitch, slot_start, slot_end);
        for plan in &plans {
            let other = match plan.kind {
                Kind::Contain(target) => Some(objects[target].info.instance.clone()),
                _ => None,
            };
            movements.entry(objects[plan.object].info.instance.clone()).or_default().push(Movement {
                action: plan.kind.name().to_owned(),
                other,
                start: plan.start as i64,
                end: plan.end as i64,
            });
        }
        for frame in slot_start..(slot_start + SLOT_FRAMES).min(FRAMES) {
            let mut lift = vec![0.0; n];
            for plan in &plans {
                if frame == plan.start && plan.kind == Kind::PickPlace {
                    // Picking a cone up reveals what it contained, where it stands.
                    for c in container.iter_mut().filter(|c| **c == Some(plan.object)) {
                        *c = None;
                    }
                }
                if frame < plan.start || frame > plan.end {
                    continue;
                }
                let u = (frame - plan.start) as f64 / (plan.end - plan.start) as f64;
                let e = smoothstep(u);
                let i = plan.object;
                match plan.kind {
                    Kind::Rotate => yaw[i] = plan.yaw_from + (plan.yaw_to - plan.yaw_from) * e,
                    Kind::Slide | Kind::PickPlace | Kind::Contain(_) => {
                        position[i] = [
                            plan.from[0] + (plan.to[0] - plan.from[0]) * e,
                            plan.from[1] + (plan.to[1] - plan.from[1]) * e,
                        ];
                        if plan.kind != Kind::Slide {
                            lift[i] = LIFT_HEIGHT * (std::f64::consts::PI * u).sin();
                        }
                    }
                }
                if frame == plan.end
                    && let Kind::Contain(target) = plan.kind
                {
                    container[target] = Some(i);
                    lift[i] = 0.0;
                }
            }
            // Contents move with their (outermost) container.
            for i in 0..n {
                if let Some(root) = outermost(&container, i)
                    && root != i
                {
                    position[i] = position[root];
                }
            }
            states.push(
                (0..n)
                    .map(|i| ObjectState {
                        position: [position[i][0], position[i][1], lift[i]],
                        yaw: yaw[i],
                        contained: container[i].is_some(),
                    })
                    .collect(),
            );
        }
    }
    let scene = Scene {
        video: video.to_owned(),
        objects: objects.iter().map(|o| o.info.clone()).collect(),
        movements,
        camera: Some(camera),
    };
    Simulation { scene, objects, states }
}

fn outermost(container: &[Option<usize>], i: usize) -> Option<usize> {
    let mut current = i;
    for _ in 0..container.len() {
        match container[current] {
            Some(c) => current = c,
            None => return Some(current),
        }
    }
    None
}

fn sample_objects(rng: &mut ChaCha8Rng) -> Vec<SimObject> {
    let count = rng.random_range(5..=10);
    let mut objects: Vec<SimObject> = Vec::with_capacity(count);
    let mut used_classes = Vec::new();
    let mut per_shape: BTreeMap<&str, usize> = BTreeMap::new();
    let mut attempts = 0;
    while objects.len() < count && attempts < 1000 {
        attempts += 1;
        let (shape_name, size, half, color, material) = if objects.is_empty() {
            ("spl", "small", SIZES[0].1, "gold", "metal")
        } else {
            let &(size, half) = SIZES.choose(rng).unwrap_or(&SIZES[0]);
            (
                *SHAPES.choose(rng).unwrap_or(&"cube"),
                size,
                half,
                *COLORS.choose(rng).unwrap_or(&"gray"),
                *MATERIALS.choose(rng).unwrap_or(&"rubber"),
            )
        };
        let class = format!("{size}_{color}_{shape_name}_{material}");
        if used_classes.contains(&class) {
            continue;
        }
        let xy = [rng.random_range(-TABLE..TABLE), rng.random_range(-TABLE..TABLE)];
        let clear = objects.iter().all(|o| {
            distance(xy, [o.info.coords[0], o.info.coords[1]]) >= footprint(o.half) + footprint(half) + 0.1
        });
        if !clear {
            continue;
        }
        used_classes.push(class);
        let k = per_shape.entry(shape_name).or_insert(0);
        let instance = if shape_name == "spl" {
            SNITCH_INSTANCE.to_owned()
        } else {
            let mut title = shape_name.to_owned();
            title[..1].make_ascii_uppercase();
            format!("{title}_{k}")
        };
        *k += 1;
        let shape = match shape_name {
            "cube" => Shape::Cube,
            "sphere" => Shape::Sphere,
            "cylinder" => Shape::Cylinder,
            "cone" => Shape::Cone,
            _ => Shape::Snitch,
        };
        objects.push(SimObject {
            info: SceneObject {
                instance,
                shape: shape_name.to_owned(),
                size: size.to_owned(),
                color: color.to_owned(),
                material: material.to_owned(),
                coords: [xy[0], xy[1], 0.0],
                rotation: rng.random_range(0.0..360.0),
            },
            shape,
            half,
        });
    }
    objects
}

/// Radius of an object's footprint on the table.
fn footprint(half: f64) -> f64 {
    half * 1.2
}

#[allow(clippy::too_many_arguments, reason = "the state of one slot, passed once")]
fn plan_slot(
    rng: &mut ChaCha8Rng,
    objects: &[SimObject],
    position: &[[f64; 2]],
    yaw: &[f64],
    container: &[Option<usize>],
    snitch: usize,
    slot_start: usize,
    slot_end: usize,
) -> Vec<Plan> {
    let n = objects.len();
    let mut involved = vec![false; n];
    let mut destination: Vec<[f64; 2]> = position.to_vec();
    let mut plans = Vec::new();
    let mut order: Vec<usize> = (0..n).collect();
    order.shuffle(rng);
    let free = |i: usize, involved: &[bool]| !involved[i] && container[i].is_none();
    for i in order {
        if !free(i, &involved) || !rng.random_bool(ACT_PROBABILITY) {
            continue;
        }
        let contains_something = container.contains(&Some(i));
        let mut kinds = vec![Kind::Slide, Kind::PickPlace];
        match objects[i].shape {
            Shape::Cube | Shape::Cylinder => kinds.push(Kind::Rotate),
            Shape::Cone if !contains_something => {
                let eligible: Vec<usize> = (0..n)
                    .filter(|&t| t != i && free(t, &involved) && objects[t].half < objects[i].half)
                    .collect();
                if !eligible.is_empty() {
                    let snitch_side = outermost(container, snitch).filter(|t| eligible.contains(t));
                    let target = match snitch_side {
                        Some(t) if rng.random_bool(SNITCH_TARGET_PROBABILITY) => t,
                        _ => *eligible.choose(rng).unwrap_or(&eligible[0]),
                    };
                    kinds.push(Kind::Contain(target));
                }
            }
            _ => {}
        }
        // A cone that may contain does so half the time (CATER's localisation videos are built
        // around containment); otherwise the action is drawn uniformly.
        let contain = kinds.iter().copied().find(|k| matches!(k, Kind::Contain(_)));
        let kind = match contain {
            Some(k) if rng.random_bool(CONTAIN_PROBABILITY) => k,
            _ => {
                kinds.retain(|k| !matches!(k, Kind::Contain(_)));
                let Some(&k) = kinds.choose(rng) else { continue };
                k
            }
        };
        let duration = rng.random_range(MIN_MOVE_FRAMES..=MAX_MOVE_FRAMES);
        // A move covers `duration` frames, `start..=end`, inside its slot.
        let latest_start = (slot_end + 1).saturating_sub(duration).max(slot_start);
        let start = rng.random_range(slot_start..=latest_start);
        let end = (start + duration - 1).min(slot_end);
        let to = match kind {
            Kind::Rotate => position[i],
            Kind::Contain(target) => position[target],
            Kind::Slide | Kind::PickPlace => {
                let found = (0..30)
                    .map(|_| [rng.random_range(-TABLE..TABLE), rng.random_range(-TABLE..TABLE)])
                    .find(|&xy| {
                        (0..n).all(|j| {
                            j == i
                                || container[j].is_some()
                                || distance(xy, destination[j])
                                    >= footprint(objects[i].half) + footprint(objects[j].half) + 0.15
                        })
                    });
                match found {
                    Some(xy) => xy,
                    None => continue,
                }
            }
        };
        let yaw_to = if kind == Kind::Rotate {
            yaw[i]
                + rng.random_range(0.5..1.5)
                    * if rng.random_bool(0.5) { 1.0 } else { -1.0 }
                    * std::f64::consts::PI
        } else {
            yaw[i]
        };
        involved[i] = true;
        if let Kind::Contain(target) = kind {
            involved[target] = true;
        }
        destination[i] = to;
        plans.push(Plan { object: i, kind, start, end, from: position[i], to, yaw_from: yaw[i], yaw_to });
    }
    plans.sort_by_key(|p| (p.start, p.object));
    plans
}
