//! The generator's scenes: objects and movements drawn by CATER's own procedure (Girdhar and
//! Ramanan; `render_videos.py` and `actions.py` of its generator, which OPNet's fork used for
//! LA-CATER), simulated frame by frame. Reimplemented from reading that code:
//!
//! - 5 to 10 objects: the snitch (`Spl_0`, scale 0.3), a medium and a large cone, then objects of
//!   random size (0.25 / 0.5 / 0.75), shape, colour and material, drawn with replacement (two
//!   identical objects happen); placed on `[-3, 3]²` at least 0.25 apart (plus sizes) and 0.4 apart
//!   along the camera's cardinal directions, Blender instance names `Cone_0`, `SmoothCube_v2_1`...;
//! - time is cut in segments: from the current frame, either a contain (a random pair, the first a
//!   cone containing nothing that is larger than the second, a cone, sphere or snitch, and no other
//!   object in the way at its end) plus single moves of other objects, or single moves only; a
//!   single move starts 0 to 10 frames into the segment and lasts 20 to 30 frames; the next segment
//!   starts after the last move ends, until frame 270. [`Motion::MaxTwo`] moves at most two
//!   objects (or stacks) per segment, as LA-CATER was made; [`Motion::All`] moves all of them
//!   (CATER's `all_actions`);
//! - a single object slides, is picked up and placed (2 units up over 20 % of the move, across, down
//!   over the last 20 %), or rotates (not cones and spheres); a cone holding a stack slides with it
//!   (every object of the stack gets a `_slide` record) or is picked up off it (its contents get
//!   `_no_op` records and stay); a move that keeps colliding with other objects (3D distance minus
//!   sizes below 0.25 at any later frame) is redrawn up to 100 times, then becomes `_no_op`;
//! - a video in which objects still collide (CATER's `assert_no_collisions`) is drawn again, as
//!   CATER drops such videos;
//! - positions between keyframes follow Blender's default (auto-clamped Bézier) easing when
//!   rendered, while the scene's `locations` record them linearly, as CATER does.

use std::collections::BTreeMap;

use rand::Rng;
use rand::seq::{IndexedRandom, SliceRandom};
use rand_chacha::ChaCha8Rng;

use crate::classes::{COLORS, MATERIALS, SHAPES, SIZES, SNITCH_SCALE, instance_name};
use crate::formats::{FRAMES, LAST_KEYFRAME, Locations, Movement, MovementKind, SceneObject};

/// Frames with positions: 0 to 300, as Blender renders them.
pub const KEYFRAMES: usize = LAST_KEYFRAME as usize + 1;
pub const MOVEMENT_MIN: usize = 20;
pub const MOVEMENT_MAX: usize = 30;
/// How high `_pick_place` lifts an object.
pub const PICK_HEIGHT: f64 = 2.0;
/// CATER's `min_dist` (placement and collisions) and `margin` (placement along directions).
pub const MIN_DIST: f64 = 0.25;
pub const MARGIN: f64 = 0.4;
/// Redraws of a move before it becomes `_no_op`.
pub const MAX_TRIALS: usize = 100;
/// CATER's rotation: 90 degrees about the object's own y axis, converted with its 3.14 for π.
pub const ROTATE_ANGLE: f64 = 90.0 / 180.0 * CATER_PI;
/// The value of π CATER's `_rotate` converts degrees with.
#[allow(clippy::approx_constant, reason = "CATER's own approximation, kept to rotate as it does")]
const CATER_PI: f64 = 3.14;

/// How many objects move per segment, and how.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Motion {
    /// At most two objects or stacks (`--max_motions=2`, LA-CATER).
    #[default]
    MaxTwo,
    /// Every object or stack (CATER's `all_actions`).
    All,
    /// This project's hard scenes (not CATER's procedure; see [`HardScenes`]).
    Hard,
}

impl Motion {
    fn max_motions(self) -> usize {
        match self {
            Motion::MaxTwo => 2,
            Motion::All | Motion::Hard => usize::MAX,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Motion::MaxTwo => "max-two",
            Motion::All => "all",
            Motion::Hard => "hard",
        }
    }
}

/// What [`Motion::Hard`] changes in CATER's procedure, to make scenes that are hard to follow:
///
/// - any number of stacks move in a time slot (1 to all, drawn per slot), their moves starting 0
///   to 20 frames into the slot and lasting 15 to 45 frames, so simultaneous moves start and end
///   at different frames;
/// - a contain is tried in 60 % of the slots, half of them onto the snitch's stack (so a cone comes
///   over a cone that holds the snitch: nested containment, moved as one when the outer cone
///   slides); in 30 % of the contains the stack contained slides first in the same slot and the cone
///   comes down over it where it stops (a contain onto a stack that is itself carried);
/// - each move follows one of four motion profiles: smooth (Blender's easing), linear, ease-in or
///   ease-out;
/// - the snitch has wings (its silhouette is an ellipsoid 1.6 times as long as it is wide), so its
///   `_rotate` changes its box while it stays put, and a snitch standing alone rotates in 30 % of
///   its moves;
/// - more identical objects: 40 % of the random objects copy the class of one already there, cones
///   included;
/// - occlusion is decided by the union of the nearer objects' boxes (the generator's visibility
///   annotation and perfect perception), not by one box at a time as OPNet's scripts do.
#[derive(Debug, Clone, Copy)]
pub struct HardScenes;

impl HardScenes {
    pub const CONTAIN_PROBABILITY: f64 = 0.6;
    pub const SNITCH_TARGET: f64 = 0.5;
    pub const TARGET_MOVES_FIRST: f64 = 0.3;
    pub const SNITCH_ROTATES: f64 = 0.3;
    pub const TWIN_PROBABILITY: f64 = 0.4;
    /// The snitch's wings: its silhouette's length over its width.
    pub const SNITCH_ELONGATION: f64 = 1.6;
    pub const START_OFFSET_MAX: usize = 20;
    pub const DURATION: (usize, usize) = (15, 45);
}

/// How a move proceeds between two keyframes: the fraction of the way covered at a fraction `u` of
/// the time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Profile {
    /// Blender's default easing (`3u² - 2u³`).
    #[default]
    Smooth,
    Linear,
    /// Starts slowly (`u²`).
    EaseIn,
    /// Stops slowly (`1 - (1 - u)²`).
    EaseOut,
}

impl Profile {
    pub const ALL: [Profile; 4] = [Profile::Smooth, Profile::Linear, Profile::EaseIn, Profile::EaseOut];

    pub fn at(self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        match self {
            Profile::Smooth => u * u * (3.0 - 2.0 * u),
            Profile::Linear => u,
            Profile::EaseIn => u * u,
            Profile::EaseOut => 1.0 - (1.0 - u) * (1.0 - u),
        }
    }
}

/// Shape of an object, for rendering.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    Cube,
    Sphere,
    Cylinder,
    Cone,
    Snitch,
}

impl Shape {
    fn from_name(name: &str) -> Shape {
        match name {
            "cube" => Shape::Cube,
            "sphere" => Shape::Sphere,
            "cylinder" => Shape::Cylinder,
            "cone" => Shape::Cone,
            _ => Shape::Snitch,
        }
    }
}

/// An object with what rendering needs.
#[derive(Debug, Clone, PartialEq)]
pub struct SimObject {
    pub info: SceneObject,
    pub shape: Shape,
    /// Blender's scale: half extent of a cube, radius of a sphere, cylinder or cone base.
    pub size: f64,
    /// A sphere's (the snitch's) length along its own x axis over its width: 1 for a ball, more
    /// for the winged snitch of hard scenes.
    pub elongation: f64,
}

/// An object's pose in one frame (as rendered: eased between keyframes).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ObjectState {
    /// The object's centre (z = its size when it stands on the table).
    pub position: [f64; 3],
    /// Rotation about the vertical axis, radians.
    pub yaw: f64,
    /// Rotation about the object's own y axis (CATER's `_rotate`), radians.
    pub tilt: f64,
}

/// A generated video: its objects and movements and every object's pose in every frame.
#[derive(Debug, Clone)]
pub struct Simulation {
    pub objects: Vec<SimObject>,
    pub movements: BTreeMap<String, Vec<Movement>>,
    /// `states[frame][object]`, frames 0 to 299.
    pub states: Vec<Vec<ObjectState>>,
    /// The camera's location (CATER's base camera jittered).
    pub camera: [f64; 3],
    /// How many times the video was drawn again because objects collided.
    pub redraws: usize,
}

/// CLEVR's base camera (its `base_scene.blend`): location, orientation (XYZ Euler, degrees) and
/// focal length at 320x240 (35 mm lens on a 32 mm sensor).
pub const BASE_CAMERA: [f64; 3] = [7.4811, -6.5076, 5.3437];
pub const CAMERA_ROTATION_DEG: [f64; 3] = [63.559, 0.62, 46.692];
pub const FOCAL_PX: f64 = 350.0;
/// CATER's `--camera_jitter`.
pub const CAMERA_JITTER: f64 = 0.5;

/// The camera's axes (right, down, forward) from CLEVR's base orientation.
pub fn camera_axes() -> [[f64; 3]; 3] {
    let [a, b, c] = CAMERA_ROTATION_DEG.map(f64::to_radians);
    // R = Rz(c) Ry(b) Rx(a); the camera looks along -z, +y is up, +x is right.
    let rotate = |v: [f64; 3]| {
        let (sa, ca) = a.sin_cos();
        let (sb, cb) = b.sin_cos();
        let (sc, cc) = c.sin_cos();
        let x1 = [v[0], ca * v[1] - sa * v[2], sa * v[1] + ca * v[2]];
        let x2 = [cb * x1[0] + sb * x1[2], x1[1], -sb * x1[0] + cb * x1[2]];
        [cc * x2[0] - sc * x2[1], sc * x2[0] + cc * x2[1], x2[2]]
    };
    let right = rotate([1.0, 0.0, 0.0]);
    let up = rotate([0.0, 1.0, 0.0]);
    let forward = rotate([0.0, 0.0, -1.0]);
    [right, [-up[0], -up[1], -up[2]], forward]
}

/// CLEVR's cardinal directions on the table: `behind` and `left` are the camera's forward and left
/// projected on the table.
pub fn directions() -> BTreeMap<String, [f64; 3]> {
    let [right, _, forward] = camera_axes();
    let flat = |v: [f64; 3]| {
        let n = (v[0] * v[0] + v[1] * v[1]).sqrt().max(1e-12);
        [v[0] / n, v[1] / n, 0.0]
    };
    let behind = flat(forward);
    let left = flat([-right[0], -right[1], -right[2]]);
    let neg = |v: [f64; 3]| [-v[0], -v[1], -v[2]];
    BTreeMap::from([
        ("behind".to_owned(), behind),
        ("front".to_owned(), neg(behind)),
        ("left".to_owned(), left),
        ("right".to_owned(), neg(left)),
        ("above".to_owned(), [0.0, 0.0, 1.0]),
        ("below".to_owned(), [0.0, 0.0, -1.0]),
    ])
}

/// CATER's `_obj_overlap`: 3D distance minus both sizes below `MIN_DIST`.
fn overlap(a: [f64; 3], size_a: f64, b: [f64; 3], size_b: f64) -> bool {
    let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
    d - size_a - size_b < MIN_DIST
}

/// One keyframe of an object: frame, location, tilt, and how the object gets there from the
/// previous keyframe.
#[derive(Debug, Clone, Copy)]
struct Keyframe {
    frame: usize,
    location: [f64; 3],
    tilt: f64,
    profile: Profile,
}

/// The state of one video's generation.
struct Generator<'a> {
    rng: &'a mut ChaCha8Rng,
    objects: Vec<SimObject>,
    /// Stacks, outermost object first (CATER's "tied together" lists).
    groups: Vec<Vec<usize>>,
    /// Per object, its recorded (linear) location in frames 0 to 300.
    locations: Vec<Vec<[f64; 3]>>,
    /// Per object, its current location (Blender's `obj.location`).
    current: Vec<[f64; 3]>,
    tilt: Vec<f64>,
    keyframes: Vec<Vec<Keyframe>>,
    movements: Vec<Vec<Movement>>,
    /// `contains[cone][frame]`: the object the cone contains (CATER's `MovementRecord.contains`).
    contains: Vec<Vec<Option<usize>>>,
    max_motions: usize,
    motion: Motion,
    /// The profile of the move being keyframed.
    profile: Profile,
}

/// Linear interpolation of CATER's `move_to_location` over `start..=end`.
fn move_to(from: [f64; 3], to: [f64; 3], start: usize, end: usize) -> Vec<[f64; 3]> {
    (start..=end)
        .map(|f| {
            let u = if end == start { 1.0 } else { (f - start) as f64 / (end - start) as f64 };
            std::array::from_fn(|k| from[k] + (to[k] - from[k]) * u)
        })
        .collect()
}

/// CATER's `_pick_place` positions: up over the first 20 % of the frames, across, down over the
/// last 20 %; and the frames of its keyframes.
fn pick_place(from: [f64; 3], x: f64, y: f64, start: usize, end: usize) -> (Vec<[f64; 3]>, [usize; 3]) {
    let total = end - start + 1;
    let end1 = start + (0.2 * total as f64) as usize;
    let end2 = start + (0.8 * total as f64) as usize;
    let lifted = [from[0], from[1], from[2] + PICK_HEIGHT];
    let mut pos = move_to(from, lifted, start, end1);
    let top = [x, y, lifted[2]];
    pos.extend(move_to(lifted, top, end1 + 1, end2));
    pos.extend(move_to(top, [x, y, from[2]], end2 + 1, end));
    (pos, [end1, end2, end])
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Act {
    Slide,
    PickPlace,
    Rotate,
    NoOp,
}

impl Generator<'_> {
    fn sizes(&self, object: usize) -> f64 {
        self.objects[object].size
    }

    fn record(&mut self, object: usize, kind: MovementKind, other: Option<usize>, start: usize, end: usize) {
        let other_name = other.map(|o| self.objects[o].info.instance.clone());
        self.movements[object].push(Movement::new(kind, other_name.as_deref(), start as i64, end as i64));
        match kind {
            MovementKind::Contain => {
                if let Some(o) = other {
                    for slot in &mut self.contains[object][start..] {
                        *slot = Some(o);
                    }
                }
            }
            MovementKind::PickPlace => {
                for slot in &mut self.contains[object][end..] {
                    *slot = None;
                }
            }
            _ => {}
        }
    }

    fn keyframe(&mut self, object: usize, frame: usize) {
        let k = Keyframe {
            frame,
            location: self.current[object],
            tilt: self.tilt[object],
            profile: self.profile,
        };
        self.keyframes[object].push(k);
    }

    /// The profile of the next move: smooth as Blender's default, or in hard scenes any of four.
    fn draw_profile(&mut self) {
        self.profile = if self.motion == Motion::Hard {
            *Profile::ALL.choose(self.rng).unwrap_or(&Profile::Smooth)
        } else {
            Profile::Smooth
        };
    }

    /// Sets an object's recorded locations over `start..=end` and holds the last one after.
    fn set_locations(&mut self, object: usize, start: usize, positions: &[[f64; 3]]) {
        let locations = &mut self.locations[object];
        for (k, p) in positions.iter().enumerate() {
            locations[start + k] = *p;
        }
        let last = positions.last().copied().unwrap_or(locations[start]);
        for slot in &mut locations[start + positions.len()..] {
            *slot = last;
        }
    }

    /// CATER's `_no_object_overlaps`: the positions over `start..=end`, then the last one held, never
    /// come near any of `others` at the same frame.
    fn clear_of(
        &self,
        positions: &[[f64; 3]],
        size: f64,
        others: &[usize],
        start: usize,
        end: usize,
    ) -> bool {
        (start..KEYFRAMES).all(|f| {
            let p = if f <= end { positions[f - start] } else { positions[positions.len() - 1] };
            others.iter().all(|&o| !overlap(p, size, self.locations[o][f], self.sizes(o)))
        })
    }

    /// CATER's `add_movements` for one stack; returns whether the stack splits (its top picked off).
    /// `forced` makes it slide (hard scenes: a stack that moves before a cone comes over it).
    fn move_group(&mut self, g: usize, start: usize, end: usize, forced: Option<Act>) -> bool {
        let members = self.groups[g].clone();
        let others: Vec<usize> = self
            .groups
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != g)
            .flat_map(|(_, m)| m.iter().copied())
            .collect();
        let top = members[0];
        let choices: &[(Act, bool)] = if members.len() > 1 {
            &[(Act::Slide, false), (Act::PickPlace, true)]
        } else if matches!(self.objects[top].shape, Shape::Cone | Shape::Sphere) {
            &[(Act::Slide, false), (Act::PickPlace, false)]
        } else {
            &[(Act::Slide, false), (Act::PickPlace, false), (Act::Rotate, false)]
        };
        let forced: &[(Act, bool)] = match forced {
            Some(Act::Slide) => &[(Act::Slide, false)],
            _ => choices,
        };
        let choices = if self.motion == Motion::Hard
            && members.len() == 1
            && self.objects[top].shape == Shape::Snitch
            && forced.len() > 1
            && self.rng.random_bool(HardScenes::SNITCH_ROTATES)
        {
            &[(Act::Rotate, false)]
        } else {
            forced
        };
        self.draw_profile();
        let mut trials = 0;
        let (act, split, target) = loop {
            let &(act, split) = choices.choose(self.rng).unwrap_or(&(Act::NoOp, false));
            let target = [self.rng.random_range(-3.0..3.0), self.rng.random_range(-3.0..3.0)];
            let mut clean = true;
            let mut finals = Vec::with_capacity(members.len());
            for (k, &m) in members.iter().enumerate() {
                let member_act = if split && k > 0 { Act::NoOp } else { act };
                let positions = self.positions(m, member_act, target, start, end);
                finals.push(positions[positions.len() - 1]);
                clean &= self.clear_of(&positions, self.sizes(m), &others, start, end);
            }
            if split {
                clean &= !overlap(finals[0], self.sizes(members[0]), finals[1], self.sizes(members[1]));
            }
            if !clean && trials > MAX_TRIALS {
                break (Act::NoOp, false, target);
            }
            if clean {
                break (act, split, target);
            }
            trials += 1;
        };
        for (k, &m) in members.iter().enumerate() {
            let member_act = if split && k > 0 { Act::NoOp } else { act };
            let positions = self.positions(m, member_act, target, start, end);
            self.apply(m, member_act, target, start, end, &positions);
            self.set_locations(m, start, &positions);
        }
        split
    }

    /// The recorded positions of an act.
    fn positions(
        &self,
        object: usize,
        act: Act,
        target: [f64; 2],
        start: usize,
        end: usize,
    ) -> Vec<[f64; 3]> {
        let from = self.current[object];
        match act {
            Act::Slide => move_to(from, [target[0], target[1], from[2]], start, end),
            Act::PickPlace => pick_place(from, target[0], target[1], start, end).0,
            Act::Rotate | Act::NoOp => vec![from; end - start + 1],
        }
    }

    /// Records an act and keyframes it as Blender would.
    fn apply(
        &mut self,
        object: usize,
        act: Act,
        target: [f64; 2],
        start: usize,
        end: usize,
        positions: &[[f64; 3]],
    ) {
        match act {
            Act::Slide => {
                self.keyframe(object, start);
                self.current[object] = positions[positions.len() - 1];
                self.keyframe(object, end);
                self.record(object, MovementKind::Slide, None, start, end);
            }
            Act::PickPlace => {
                self.pick_place_keyframes(object, target, start, end);
                self.record(object, MovementKind::PickPlace, None, start, end);
            }
            Act::Rotate => {
                self.keyframe(object, start);
                self.tilt[object] += ROTATE_ANGLE;
                self.keyframe(object, end);
                self.record(object, MovementKind::Rotate, None, start, end);
            }
            Act::NoOp => {
                self.keyframe(object, end);
                self.record(object, MovementKind::NoOp, None, start, end);
            }
        }
    }

    fn pick_place_keyframes(&mut self, object: usize, target: [f64; 2], start: usize, end: usize) {
        let from = self.current[object];
        let (_, [end1, end2, _]) = pick_place(from, target[0], target[1], start, end);
        self.keyframe(object, start);
        self.current[object] = [from[0], from[1], from[2] + PICK_HEIGHT];
        self.keyframe(object, end1);
        self.keyframe(object, end1 + 1);
        self.current[object] = [target[0], target[1], from[2] + PICK_HEIGHT];
        self.keyframe(object, end2);
        self.current[object] = [target[0], target[1], from[2]];
        self.keyframe(object, end);
    }

    /// A move's frames: it starts 0 to 10 frames into the segment and lasts 20 to 30 frames (hard
    /// scenes: 0 to 20, and 15 to 45).
    fn draw_times(&mut self, segment_start: usize) -> (usize, usize) {
        let (frames, offset) = if self.motion == Motion::Hard {
            let (lo, hi) = HardScenes::DURATION;
            (self.rng.random_range(lo..=hi), self.rng.random_range(0..=HardScenes::START_OFFSET_MAX))
        } else {
            (self.rng.random_range(MOVEMENT_MIN..=MOVEMENT_MAX), self.rng.random_range(0..=10))
        };
        let start = segment_start + offset;
        (start, (start + frames).min(LAST_KEYFRAME as usize))
    }

    /// CATER's `add_movements_singleObj`; returns the last frame a move ends in.
    fn single_moves(
        &mut self,
        segment_start: usize,
        ignore: Option<usize>,
        max_motions: usize,
    ) -> Option<usize> {
        let mut order: Vec<usize> = (0..self.groups.len()).collect();
        order.shuffle(self.rng);
        order.retain(|g| Some(*g) != ignore);
        order.truncate(max_motions);
        if self.motion == Motion::Hard && !order.is_empty() {
            // Any number of stacks, at least one unless a contain runs.
            let least = usize::from(ignore.is_none());
            let count = self.rng.random_range(least..=order.len());
            order.truncate(count);
        }
        let mut last = None;
        let mut splits = Vec::new();
        for &g in &order {
            let (start, end) = self.draw_times(segment_start);
            last = Some(last.map_or(end, |l: usize| l.max(end)));
            if self.move_group(g, start, end, None) {
                splits.push(g);
            }
        }
        let mut groups = Vec::with_capacity(self.groups.len() + splits.len());
        for (g, members) in std::mem::take(&mut self.groups).into_iter().enumerate() {
            if splits.contains(&g) {
                groups.push(vec![members[0]]);
                groups.push(members[1..].to_vec());
            } else {
                groups.push(members);
            }
        }
        self.groups = groups;
        last
    }

    /// CATER's `_can_contain`: `g1` is a lone cone larger than the top of `g2`, a cone, sphere or
    /// snitch, and no other stack's top is near where the cone would end.
    fn can_contain(&self, g1: usize, g2: usize, end: usize) -> bool {
        let (top1, top2) = (self.groups[g1][0], self.groups[g2][0]);
        let fits = self.groups[g1].len() == 1
            && self.sizes(top1) > self.sizes(top2)
            && self.objects[top1].shape == Shape::Cone
            && matches!(self.objects[top2].shape, Shape::Cone | Shape::Sphere | Shape::Snitch);
        if !fits {
            return false;
        }
        let at = [self.current[top2][0], self.current[top2][1], self.current[top1][2]];
        self.groups.iter().enumerate().filter(|(i, _)| *i != g1 && *i != g2).all(|(_, members)| {
            let o = members[0];
            !overlap(at, self.sizes(top1), self.locations[o][end], self.sizes(o))
        })
    }

    /// CATER's `add_movements_multiObj_try`: a contain and single moves of other stacks; `None` if
    /// no pair could contain.
    fn contain_and_moves(&mut self, segment_start: usize) -> Option<usize> {
        for _ in 0..100 {
            let pair: Vec<usize> =
                (0..self.groups.len()).collect::<Vec<_>>().choose_multiple(self.rng, 2).copied().collect();
            let [g1, g2] = pair[..] else { return None };
            let (start, end) = self.draw_times(segment_start);
            if !self.can_contain(g1, g2, end) {
                continue;
            }
            let (cone, target) = (self.groups[g1][0], self.groups[g2][0]);
            let to = [self.current[target][0], self.current[target][1]];
            let (positions, _) = pick_place(self.current[cone], to[0], to[1], start, end);
            self.pick_place_keyframes(cone, to, start, end);
            self.record(cone, MovementKind::Contain, Some(target), start, end);
            self.set_locations(cone, start, &positions);
            let contents = self.groups.remove(g2);
            let g1 = if g1 > g2 { g1 - 1 } else { g1 };
            self.groups[g1].extend(contents);
            let singles = self.single_moves(segment_start, Some(g1), self.max_motions.saturating_sub(1));
            return Some(singles.map_or(end, |s| s.max(end)));
        }
        None
    }

    /// Hard scenes' contain: onto the snitch's stack half of the time, else a random pair; in some,
    /// the stack slides first and the cone comes down over it where it stops. Then single moves of
    /// any number of other stacks. `None` if no pair could contain.
    fn hard_contain_and_moves(&mut self, segment_start: usize) -> Option<usize> {
        for _ in 0..100 {
            let snitch_group = self.groups.iter().position(|m| m.contains(&0));
            let pair: Vec<usize> = match snitch_group {
                Some(g2) if self.rng.random_bool(HardScenes::SNITCH_TARGET) => {
                    let cones: Vec<usize> = (0..self.groups.len()).filter(|&g| g != g2).collect();
                    match cones.choose(self.rng) {
                        Some(&g1) => vec![g1, g2],
                        None => continue,
                    }
                }
                _ => {
                    (0..self.groups.len()).collect::<Vec<_>>().choose_multiple(self.rng, 2).copied().collect()
                }
            };
            let [g1, g2] = pair[..] else { return None };
            let moves_first = self.rng.random_bool(HardScenes::TARGET_MOVES_FIRST);
            let (start, end) = self.draw_times(segment_start);
            if !self.can_contain(g1, g2, end) {
                continue;
            }
            let (cone, target) = (self.groups[g1][0], self.groups[g2][0]);
            let (start, end, moved_end) = if moves_first {
                // The stack slides first; the cone starts with it and comes down over it after it
                // stops (the last 20 % of the contain).
                let (slide_start, slide_end) = self.draw_times(segment_start);
                let snapshot = (self.current.clone(), self.locations.clone(), self.keyframes.clone());
                let movements = self.movements.clone();
                self.move_group(g2, slide_start, slide_end, Some(Act::Slide));
                let slid =
                    self.movements[target].last().is_some_and(|m| m.kind() == Some(MovementKind::Slide));
                let frames = end - start;
                let start = start.min(slide_start);
                let needed = ((slide_end + 2 - start) as f64 / 0.8).ceil() as usize;
                let end = (start + frames.max(needed)).min(LAST_KEYFRAME as usize);
                let descent = start + (0.8 * (end - start + 1) as f64) as usize;
                if !slid || descent <= slide_end || !self.can_contain(g1, g2, end) {
                    // Undo the slide: no contain this time.
                    (self.current, self.locations, self.keyframes) = snapshot;
                    self.movements = movements;
                    continue;
                }
                (start, end, Some(slide_end))
            } else {
                (start, end, None)
            };
            self.draw_profile();
            let to = [self.current[target][0], self.current[target][1]];
            let (positions, _) = pick_place(self.current[cone], to[0], to[1], start, end);
            self.pick_place_keyframes(cone, to, start, end);
            self.record(cone, MovementKind::Contain, Some(target), start, end);
            self.set_locations(cone, start, &positions);
            let contents = self.groups.remove(g2);
            let g1 = if g1 > g2 { g1 - 1 } else { g1 };
            self.groups[g1].extend(contents);
            let singles = self.single_moves(segment_start, Some(g1), usize::MAX);
            let last = moved_end.map_or(end, |m| m.max(end));
            return Some(singles.map_or(last, |s| s.max(last)));
        }
        None
    }

    /// CATER's `record.was_contained(a, b, frame)`: b is inside a (at any depth) at that frame.
    fn was_contained(&self, a: usize, b: usize, frame: usize) -> bool {
        let mut current = Some(a);
        for _ in 0..=self.objects.len() {
            match current {
                None => return false,
                Some(c) if c == b => return true,
                Some(c) => current = self.contains[c][frame],
            }
        }
        false
    }

    /// CATER's `assert_no_collisions` over the current stacks' tops.
    fn collides(&self) -> bool {
        let tops: Vec<usize> = self.groups.iter().map(|g| g[0]).collect();
        for (i, &a) in tops.iter().enumerate() {
            for &b in &tops[i + 1..] {
                for f in 0..KEYFRAMES {
                    if overlap(self.locations[a][f], self.sizes(a), self.locations[b][f], self.sizes(b))
                        && !self.was_contained(a, b, f)
                        && !self.was_contained(b, a, f)
                    {
                        return true;
                    }
                }
            }
        }
        false
    }
}

/// The camera's location: CATER's base camera jittered by up to `CAMERA_JITTER` on each axis.
pub fn sample_camera(rng: &mut ChaCha8Rng) -> [f64; 3] {
    BASE_CAMERA.map(|v| v + rng.random_range(-CAMERA_JITTER..CAMERA_JITTER))
}

/// CATER's `add_random_objects`: the snitch, a medium and a large cone, then random objects (in
/// hard scenes, 40 % of them copies of an object already there, and a winged snitch).
fn sample_objects(rng: &mut ChaCha8Rng, motion: Motion) -> Vec<SimObject> {
    let hard = motion == Motion::Hard;
    let count = rng.random_range(5..=10);
    let dirs = directions();
    let cardinal: Vec<[f64; 3]> =
        ["left", "right", "front", "behind"].iter().filter_map(|d| dirs.get(*d).copied()).collect();
    'restart: loop {
        let mut objects: Vec<SimObject> = Vec::with_capacity(count);
        for i in 0..count {
            let (size_name, size, shape) = match i {
                0 => ("small", SNITCH_SCALE, "spl"),
                1 => ("medium", 0.5, "cone"),
                2 => ("large", 0.75, "cone"),
                _ => {
                    let &(name, size) = SIZES.choose(rng).unwrap_or(&SIZES[0]);
                    (name, size, *SHAPES.choose(rng).unwrap_or(&"cube"))
                }
            };
            let (color, material) = if i == 0 {
                ("gold", "metal")
            } else {
                (*COLORS.choose(rng).unwrap_or(&"gray"), *MATERIALS.choose(rng).unwrap_or(&"rubber"))
            };
            // Hard scenes: a twin of an object already there (not the snitch).
            let twin = if hard && i >= 3 && rng.random_bool(HardScenes::TWIN_PROBABILITY) {
                objects[1..].choose(rng).map(|o| {
                    let info = &o.info;
                    (info.size.clone(), o.size, info.shape.clone(), info.color.clone(), info.material.clone())
                })
            } else {
                None
            };
            let (size_name, size, shape, color, material) = match &twin {
                Some((sn, sz, sh, c, m)) => (sn.as_str(), *sz, sh.as_str(), c.as_str(), m.as_str()),
                None => (size_name, size, shape, color, material),
            };
            let mut tries = 0;
            let (x, y) = loop {
                tries += 1;
                if tries > 50 {
                    continue 'restart;
                }
                let (x, y) = (rng.random_range(-3.0..3.0), rng.random_range(-3.0..3.0));
                let good = objects.iter().all(|o| {
                    let (dx, dy) = (x - o.info.coords[0], y - o.info.coords[1]);
                    let far = (dx * dx + dy * dy).sqrt() - size - o.size >= MIN_DIST;
                    far && cardinal.iter().all(|d| {
                        let margin = dx * d[0] + dy * d[1];
                        !(0.0 < margin && margin < MARGIN)
                    })
                });
                if good {
                    break (x, y);
                }
            };
            let same_shape = objects.iter().filter(|o| o.info.shape == shape).count();
            objects.push(SimObject {
                info: SceneObject {
                    instance: instance_name(shape, same_shape),
                    shape: shape.to_owned(),
                    size: size_name.to_owned(),
                    color: color.to_owned(),
                    material: material.to_owned(),
                    sized: Some(size),
                    coords: [x, y, size],
                    rotation: 360.0 * rng.random::<f64>(),
                    pixel_coords: None,
                    locations: Locations::default(),
                },
                shape: Shape::from_name(shape),
                size,
                elongation: if hard && i == 0 { HardScenes::SNITCH_ELONGATION } else { 1.0 },
            });
        }
        return objects;
    }
}

/// An object's rendered pose at a frame, from its keyframes.
fn pose_at(keyframes: &[Keyframe], initial: [f64; 3], frame: usize) -> ([f64; 3], f64) {
    let Some(first) = keyframes.first() else { return (initial, 0.0) };
    if frame <= first.frame {
        return (first.location, first.tilt);
    }
    for pair in keyframes.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if frame <= b.frame {
            if b.frame == a.frame {
                return (b.location, b.tilt);
            }
            let e = b.profile.at((frame - a.frame) as f64 / (b.frame - a.frame) as f64);
            let location = std::array::from_fn(|k| a.location[k] + (b.location[k] - a.location[k]) * e);
            return (location, a.tilt + (b.tilt - a.tilt) * e);
        }
    }
    let last = keyframes[keyframes.len() - 1];
    (last.location, last.tilt)
}

/// Generates one video's objects and movements (CATER's procedure) and simulates its frames.
pub fn simulate(rng: &mut ChaCha8Rng, motion: Motion) -> Simulation {
    let camera = sample_camera(rng);
    let mut redraws = 0;
    loop {
        let objects = sample_objects(rng, motion);
        let n = objects.len();
        let initial: Vec<[f64; 3]> = objects.iter().map(|o| o.info.coords).collect();
        let mut generator = Generator {
            rng: &mut *rng,
            groups: (0..n).map(|i| vec![i]).collect(),
            locations: initial.iter().map(|p| vec![*p; KEYFRAMES]).collect(),
            current: initial.clone(),
            tilt: vec![0.0; n],
            keyframes: vec![Vec::new(); n],
            movements: vec![Vec::new(); n],
            contains: vec![vec![None; KEYFRAMES]; n],
            max_motions: motion.max_motions(),
            motion,
            profile: Profile::Smooth,
            objects,
        };
        let mut frame = 0;
        let mut collided = false;
        while frame <= LAST_KEYFRAME as usize - MOVEMENT_MAX {
            let end = if motion == Motion::Hard {
                if generator.rng.random_bool(HardScenes::CONTAIN_PROBABILITY) {
                    generator.hard_contain_and_moves(frame)
                } else {
                    generator.single_moves(frame, None, usize::MAX)
                }
            } else if generator.rng.random_bool(0.5) {
                generator.contain_and_moves(frame)
            } else {
                generator.single_moves(frame, None, generator.max_motions)
            };
            if let Some(end) = end {
                frame = end + 1;
            }
            if generator.collides() {
                collided = true;
                break;
            }
        }
        if collided {
            redraws += 1;
            continue;
        }
        let Generator { objects, locations, keyframes, movements, .. } = generator;
        let states = (0..FRAMES)
            .map(|f| {
                (0..n)
                    .map(|i| {
                        let (position, tilt) = pose_at(&keyframes[i], initial[i], f);
                        ObjectState { position, yaw: objects[i].info.rotation.to_radians(), tilt }
                    })
                    .collect()
            })
            .collect();
        let mut objects = objects;
        for (object, locations) in objects.iter_mut().zip(locations) {
            object.info.locations = Locations(locations);
        }
        let movements =
            objects.iter().zip(movements).map(|(o, moves)| (o.info.instance.clone(), moves)).collect();
        return Simulation { objects, movements, states, camera, redraws };
    }
}
