//! The paper's gearbox assembly (section V) as a simulated scenario: a table seen by an eye-in-hand
//! camera that translates with the gripper, the five assembly steps as actions, and a detector
//! that labels objects `typeN` in left-to-right order each frame (so labels swap as objects leave
//! the view), misses parts while the casing top is carried, and reports a flickering ghost.
//!
//! [`scenario`] returns one [`Cycle`] per 100 ms: the percepts, actions and camera pose to feed to
//! AAPA, plus the ground truth (true boxes, which objects are visible, the step number) to check
//! the world state against. The steps:
//!
//! 1. the robot puts the small hub cover onto the casing top (`case0`);
//! 2. a human screws the two hub cover plugs in;
//! 3. the robot inserts the input subassembly into the casing base (`case1`);
//! 4. the human moves the casing base towards the robot;
//! 5. the robot picks up the casing top and mounts it onto the casing base.
//!
//! ```
//! use kpl_aapa::gearbox;
//! let cycles = gearbox::scenario();
//! assert_eq!(cycles.last().map(|c| c.step), Some(5));
//! ```

use kpl_core::{BBox, Time};
use serde::{Deserialize, Serialize};

use crate::params::{CameraModel, ImageSize, Params};
use crate::types::{Action, CameraPose, Percept};

/// Cycle period: 10 Hz.
pub const CYCLE: Time = 100_000;
/// Image size of the simulated camera.
pub const IMAGE: ImageSize = ImageSize { width: 640.0, height: 480.0 };
/// Focal length and principal point of the simulated camera; the table is at z = 0.6 m.
pub const CAMERA: CameraModel = CameraModel { focal_px: 600.0, principal: [320.0, 240.0], surface_z: 0.6 };
/// Depth at which the gripper holds a part, metres from the camera.
const HELD_DEPTH: f64 = 0.25;
/// Camera height above the table while manipulating (z of the pose); looking around it is higher.
const WORK_Z: f64 = 0.2;
const LOOK_Z: f64 = -0.1;
/// Cycles to lift a part off the table or lower it.
const LIFT_CYCLES: usize = 4;

/// AAPA's parameters for this scenario: the paper's gearbox values with this camera.
pub fn params() -> Params {
    Params::gearbox(IMAGE, CAMERA)
}

/// One object's truth in one cycle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthObject {
    /// The object's name, which is also the symbol its anchor should keep.
    pub name: String,
    #[serde(rename = "type")]
    pub object_type: String,
    #[serde(rename = "box", with = "crate::types::bbox_array")]
    pub bbox: BBox,
    /// Detected this cycle.
    pub detected: bool,
}

/// One cycle of the scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Cycle {
    pub time: Time,
    /// The assembly step in progress (1-5; 0 while the robot first looks at the table).
    pub step: u8,
    pub percepts: Vec<Percept>,
    pub actions: Vec<Action>,
    pub camera: CameraPose,
    pub truth: Vec<TruthObject>,
}

#[derive(Debug, Clone)]
struct Part {
    name: &'static str,
    object_type: &'static str,
    /// Table position of the centre (camera-axes frame, metres); relative to the parent if any.
    position: [f64; 2],
    footprint: [f64; 2],
    /// Physically fixed to another part (moves with it).
    parent: Option<usize>,
    held: bool,
    /// Not detectable (inserted inside another part, screwed flush, or the detector fails on it).
    hidden: bool,
}

struct Sim {
    parts: Vec<Part>,
    camera: [f64; 3],
    /// Depth of the held part below the camera.
    held_depth: f64,
    cycles: Vec<Cycle>,
    step: u8,
    pending_actions: Vec<Action>,
    /// Parts the detector misses in this many of three cycles while the casing top is carried.
    flicker: Vec<usize>,
    ghost_cycles: Vec<usize>,
}

/// The whole scenario, deterministic.
pub fn scenario() -> Vec<Cycle> {
    let part = |name, object_type, x: f64, y: f64, w: f64, h: f64| Part {
        name,
        object_type,
        position: [x, y],
        footprint: [w, h],
        parent: None,
        held: false,
        hidden: false,
    };
    let parts = vec![
        part("case0", "case", -0.12, 0.02, 0.12, 0.08),
        part("case1", "case", 0.12, 0.03, 0.14, 0.10),
        part("hub_cover0", "hub_cover", -0.05, -0.10, 0.05, 0.05),
        part("plug0", "plug", 0.00, 0.12, 0.015, 0.015),
        part("plug1", "plug", 0.04, 0.12, 0.015, 0.015),
        part("input_sub0", "input_sub", 0.17, -0.11, 0.06, 0.04),
    ];
    let mut sim = Sim {
        parts,
        camera: [0.0, 0.0, LOOK_Z],
        held_depth: HELD_DEPTH,
        cycles: Vec::new(),
        step: 0,
        pending_actions: Vec::new(),
        flicker: Vec::new(),
        ghost_cycles: Vec::new(),
    };
    let [case0, case1, hub, plug0, plug1, input] = [0, 1, 2, 3, 4, 5];

    // Look at the whole table long enough for every part to be anchored (θ_anch 0.5 at conf+ 0.05).
    sim.wait(15);

    // Step 1: hub cover onto the casing top.
    sim.step = 1;
    sim.move_camera_over(hub, 12);
    sim.pick_up(hub);
    sim.move_camera_over(case0, 12);
    sim.place_on(hub, case0, [0.0, 0.0], "insert");
    sim.wait(3);

    // Step 2: the human screws the plugs into the hub cover; a ghost plug flickers meanwhile.
    sim.step = 2;
    sim.move_camera_to([-0.06, 0.04, LOOK_Z], 10);
    let start = sim.cycles.len();
    sim.ghost_cycles.extend([start + 4, start + 5]);
    for (plug, dx) in [(plug0, -0.012), (plug1, 0.012)] {
        sim.human_move(plug, add(sim.world_position(hub), [dx, 0.0]), 8);
        sim.parts[plug].parent = Some(hub);
        sim.parts[plug].position = [dx, 0.0];
        sim.parts[plug].hidden = true;
        let name = sim.parts[plug].name;
        sim.act(Action::completed("screw", &[name, "hub_cover0"]));
        sim.wait(2);
    }
    sim.wait(3);

    // Step 3: the input subassembly into the casing base.
    sim.step = 3;
    sim.move_camera_over(input, 14);
    sim.pick_up(input);
    sim.move_camera_over(case1, 10);
    sim.place_on(input, case1, [0.0, 0.0], "insert");
    sim.parts[input].hidden = true;
    sim.wait(3);

    // Step 4: the human slides the casing base (with what is inside) towards the robot.
    sim.step = 4;
    sim.move_camera_to([0.10, 0.06, LOOK_Z], 8);
    let target = add(sim.world_position(case1), [-0.04, 0.10]);
    sim.human_move(case1, target, 15);
    sim.wait(3);

    // Step 5: pick up the casing top (hub cover and plugs on it) and mount it on the casing base.
    sim.step = 5;
    sim.move_camera_over(case0, 16);
    sim.pick_up(case0);
    for part in [hub, plug0, plug1] {
        sim.parts[part].hidden = true;
    }
    sim.flicker.push(case0);
    sim.move_camera_over(case1, 16);
    sim.flicker.clear();
    sim.place_on(case0, case1, [0.0, 0.0], "mount");
    sim.move_camera_to([sim.camera[0], sim.camera[1], -0.3], 8);
    sim.wait(5);
    sim.cycles
}

fn add(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] + b[0], a[1] + b[1]]
}

impl Sim {
    fn world_position(&self, i: usize) -> [f64; 2] {
        let p = &self.parts[i];
        match p.parent {
            Some(parent) => add(self.world_position(parent), p.position),
            None if p.held => [self.camera[0], self.camera[1]],
            None => p.position,
        }
    }

    fn held_root(&self, i: usize) -> bool {
        let p = &self.parts[i];
        p.held || p.parent.is_some_and(|parent| self.held_root(parent))
    }

    fn act(&mut self, action: Action) {
        self.pending_actions.push(action);
    }

    fn wait(&mut self, cycles: usize) {
        for _ in 0..cycles {
            self.emit();
        }
    }

    fn move_camera_to(&mut self, target: [f64; 3], cycles: usize) {
        let start = self.camera;
        for k in 1..=cycles {
            let s = k as f64 / cycles as f64;
            for a in 0..3 {
                self.camera[a] = start[a] + (target[a] - start[a]) * s;
            }
            self.emit();
        }
    }

    /// Brings the gripper down over a part (the part ends up under the image centre).
    fn move_camera_over(&mut self, part: usize, cycles: usize) {
        let [x, y] = self.world_position(part);
        self.move_camera_to([x, y, WORK_Z], cycles);
    }

    /// Lifts a part gradually from the table to the gripper.
    fn pick_up(&mut self, part: usize) {
        self.parts[part].parent = None;
        self.parts[part].held = true;
        let name = self.parts[part].name;
        self.act(Action::completed("pick_up", &["gripper0", name]));
        self.lift(CAMERA.surface_z - self.camera[2], HELD_DEPTH);
    }

    fn lift(&mut self, from: f64, to: f64) {
        for k in 0..=LIFT_CYCLES {
            self.held_depth = from + (to - from) * k as f64 / LIFT_CYCLES as f64;
            self.emit();
        }
    }

    /// Lowers the held part onto another and lets go.
    fn place_on(&mut self, part: usize, base: usize, offset: [f64; 2], action: &str) {
        self.lift(HELD_DEPTH, CAMERA.surface_z - self.camera[2]);
        self.parts[part].held = false;
        self.parts[part].parent = Some(base);
        self.parts[part].position = offset;
        let (name, base_name) = (self.parts[part].name, self.parts[base].name);
        self.act(Action::completed(action, &[name, base_name]));
        self.act(Action::completed("release", &["gripper0", name]));
        self.emit();
    }

    fn human_move(&mut self, part: usize, target: [f64; 2], cycles: usize) {
        let name = self.parts[part].name;
        let end = (self.cycles.len() + cycles) as Time * CYCLE;
        self.act(Action::started("move", &["human", name], Some(end)));
        let start = self.parts[part].position;
        for k in 1..=cycles {
            let s = k as f64 / cycles as f64;
            self.parts[part].position =
                [start[0] + (target[0] - start[0]) * s, start[1] + (target[1] - start[1]) * s];
            if k == cycles {
                self.act(Action::completed("move", &["human", name]));
            }
            self.emit();
        }
    }

    /// Renders the current state into one cycle.
    fn emit(&mut self) {
        let index = self.cycles.len();
        let time = index as Time * CYCLE;
        let [cx, cy] = CAMERA.principal;
        let table_depth = CAMERA.surface_z - self.camera[2];
        let mut truth = Vec::new();
        // The gripper's fingers are always in the bottom of the view.
        truth.push(TruthObject {
            name: "gripper0".into(),
            object_type: "gripper".into(),
            bbox: BBox::new(290.0, 420.0, 350.0, 480.0),
            detected: true,
        });
        for i in 0..self.parts.len() {
            let part = &self.parts[i];
            let [x, y] = self.world_position(i);
            let depth = if self.held_root(i) { self.held_depth } else { table_depth };
            let f = CAMERA.focal_px / depth;
            let u = cx + f * (x - self.camera[0]);
            let v = cy + f * (y - self.camera[1]);
            let (w, h) = (f * part.footprint[0], f * part.footprint[1]);
            let bbox = BBox::new(u - w / 2.0, v - h / 2.0, u + w / 2.0, v + h / 2.0);
            let in_view =
                bbox.x1 >= 0.0 && bbox.y1 >= 0.0 && bbox.x2 <= IMAGE.width && bbox.y2 <= IMAGE.height;
            let flickering = self.flicker.contains(&i) && index.is_multiple_of(3);
            truth.push(TruthObject {
                name: part.name.into(),
                object_type: part.object_type.into(),
                bbox,
                detected: in_view && !part.hidden && !flickering,
            });
        }
        let mut detections: Vec<(&str, BBox)> = truth
            .iter()
            .filter(|t| t.detected)
            .enumerate()
            .map(|(k, t)| (t.object_type.as_str(), jitter(&t.bbox, index, k)))
            .collect();
        if self.ghost_cycles.contains(&index) {
            detections.push(("plug", BBox::new(500.0, 60.0, 512.0, 72.0)));
        }
        // The detector numbers each type left to right within the frame.
        detections.sort_by(|a, b| a.0.cmp(b.0).then(a.1.x1.total_cmp(&b.1.x1)));
        let mut percepts = Vec::new();
        let mut counter: Vec<(&str, usize)> = Vec::new();
        for (object_type, bbox) in detections {
            let n = match counter.iter_mut().find(|(t, _)| *t == object_type) {
                Some((_, n)) => {
                    *n += 1;
                    *n
                }
                None => {
                    counter.push((object_type, 0));
                    0
                }
            };
            percepts.push(Percept::new(&format!("{object_type}{n}"), object_type, bbox));
        }
        let camera = CameraPose { x: self.camera[0], y: self.camera[1], z: self.camera[2] };
        self.cycles.push(Cycle {
            time,
            step: self.step,
            percepts,
            actions: std::mem::take(&mut self.pending_actions),
            camera,
            truth,
        });
    }
}

/// Deterministic detector noise of up to a pixel per edge (splitmix64 of cycle and detection).
fn jitter(b: &BBox, cycle: usize, k: usize) -> BBox {
    let mut state =
        (cycle as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (k as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    let mut next = || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    BBox::new(b.x1 + next(), b.y1 + next(), b.x2 + next(), b.y2 + next())
}
