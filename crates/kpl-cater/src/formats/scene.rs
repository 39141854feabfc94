//! CATER's scene JSON, as its renderer (and OPNet's fork of it) writes it:
//!
//! ```text
//! {"split", "image_index", "image_filename", "directions": {"left": [x, y, z], ...},
//!  "objects": [{"instance": "Cone_1", "shape", "size", "sized", "color", "material",
//!               "3d_coords", "rotation", "pixel_coords", "locations": {"0": [x, y, z], ...}}],
//!  "movements": {"Cone_1": [["_contain", "Spl_0", 12, 40], ["_slide", null, 45, 70]], ...},
//!  "camera": [x, y, z]}
//! ```
//!
//! Movements are `[action, other, start, end]` with `_slide`, `_pick_place`, `_rotate`, `_contain`
//! (`other`: the contained object's instance) and `_no_op` (an object that stays put, recorded for
//! the contents of a cone that is picked up and when no move fits); frames run from 0 to 300 (the
//! 301 frames Blender renders). Fields this project does not use are kept out of the way, not
//! refused: real files carry more than it reads.

use std::collections::{BTreeMap, HashSet};
use std::path::Path;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

use super::{LAST_KEYFRAME, read_json, write_json};
use crate::error::CaterError;

/// The kinds of CATER movement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MovementKind {
    Slide,
    PickPlace,
    Rotate,
    Contain,
    NoOp,
}

impl MovementKind {
    pub const ALL: [MovementKind; 5] = [
        MovementKind::Slide,
        MovementKind::PickPlace,
        MovementKind::Rotate,
        MovementKind::Contain,
        MovementKind::NoOp,
    ];

    /// The name CATER records (its action function's name).
    pub fn name(self) -> &'static str {
        match self {
            MovementKind::Slide => "_slide",
            MovementKind::PickPlace => "_pick_place",
            MovementKind::Rotate => "_rotate",
            MovementKind::Contain => "_contain",
            MovementKind::NoOp => "_no_op",
        }
    }

    pub fn from_name(name: &str) -> Option<MovementKind> {
        MovementKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// One CATER movement: `[action, other, start_frame, end_frame]`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "(String, Option<String>, i64, i64)", into = "(String, Option<String>, i64, i64)")]
pub struct Movement {
    pub action: String,
    pub other: Option<String>,
    pub start: i64,
    pub end: i64,
}

impl Movement {
    pub fn new(kind: MovementKind, other: Option<&str>, start: i64, end: i64) -> Movement {
        Movement { action: kind.name().to_owned(), other: other.map(str::to_owned), start, end }
    }

    /// The kind, if the action is one of CATER's (checked when a scene is read).
    pub fn kind(&self) -> Option<MovementKind> {
        MovementKind::from_name(&self.action)
    }
}

impl From<(String, Option<String>, i64, i64)> for Movement {
    fn from((action, other, start, end): (String, Option<String>, i64, i64)) -> Movement {
        Movement { action, other, start, end }
    }
}

impl From<Movement> for (String, Option<String>, i64, i64) {
    fn from(m: Movement) -> Self {
        (m.action, m.other, m.start, m.end)
    }
}

/// Per-frame positions of an object's centre, `{"0": [x, y, z], "1": ...}` in the file (CATER's
/// `sanitize_locations`; frames 0 to 300).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Locations(pub Vec<[f64; 3]>);

impl Serialize for Locations {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (frame, p) in self.0.iter().enumerate() {
            map.serialize_entry(&frame.to_string(), p)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for Locations {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Locations, D::Error> {
        use serde::de::Error;
        let raw: BTreeMap<String, [f64; 3]> = BTreeMap::deserialize(d)?;
        let mut frames: Vec<(usize, [f64; 3])> = Vec::with_capacity(raw.len());
        for (key, p) in raw {
            let frame: usize = key
                .parse()
                .map_err(|_| D::Error::custom(format!("location key `{key}` is not a frame number")))?;
            if !p.iter().all(|v| v.is_finite()) {
                return Err(D::Error::custom(format!("location of frame {frame} is not finite")));
            }
            frames.push((frame, p));
        }
        frames.sort_by_key(|(f, _)| *f);
        if frames.iter().enumerate().any(|(i, (f, _))| i != *f) {
            return Err(D::Error::custom("locations must cover frames 0, 1, 2, ... without gaps"));
        }
        Ok(Locations(frames.into_iter().map(|(_, p)| p).collect()))
    }
}

/// One object of a CATER scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneObject {
    /// The Blender object name, `Cone_1`, `SmoothCylinder-Short_0`, `Spl_0`.
    pub instance: String,
    pub shape: String,
    pub size: String,
    pub color: String,
    pub material: String,
    /// The scale Blender applied (0.25 / 0.5 / 0.75, the snitch 0.3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sized: Option<f64>,
    /// Initial position of the object's centre (x, y on the table, z up), CATER units.
    #[serde(rename = "3d_coords", default)]
    pub coords: [f64; 3],
    /// Initial rotation about the vertical axis, degrees.
    #[serde(default)]
    pub rotation: f64,
    /// Initial pixel position and depth of the centre, as CLEVR's `get_camera_coords` gives it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_coords: Option<[f64; 3]>,
    /// Per-frame centre positions as CATER records them (linear between keyframes).
    #[serde(default, skip_serializing_if = "locations_empty")]
    pub locations: Locations,
}

fn locations_empty(l: &Locations) -> bool {
    l.0.is_empty()
}

impl SceneObject {
    /// `size_color_shape_material`, the class OPNet and the detectors use.
    pub fn class(&self) -> String {
        format!("{}_{}_{}_{}", self.size, self.color, self.shape, self.material)
    }

    /// The object's key in `<video>_bb.json`.
    pub fn key(&self) -> String {
        format!("{}_{}", self.class(), self.instance)
    }
}

/// The camera as a scene records it: CATER's (OPNet's fork) location list, or the older form this
/// project wrote, `{"location", "look_at", "focal_px"}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum CameraField {
    Location([f64; 3]),
    Full { location: [f64; 3], look_at: [f64; 3], focal_px: f64 },
}

impl CameraField {
    pub fn location(&self) -> [f64; 3] {
        match self {
            CameraField::Location(l) | CameraField::Full { location: l, .. } => *l,
        }
    }
}

/// CLEVR's cardinal directions on the table plane, from the camera.
pub type Directions = BTreeMap<String, [f64; 3]>;

/// A CATER scene JSON (the parts this project reads and writes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    /// The video's name, from the file name (not stored in the file).
    #[serde(skip)]
    pub video: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub split: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_index: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_filename: Option<String>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub directions: Directions,
    pub objects: Vec<SceneObject>,
    pub movements: BTreeMap<String, Vec<Movement>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraField>,
}

impl Scene {
    /// Reads and checks a scene (see [`Scene::check`]); the video's name is the file's stem.
    pub fn read(path: &Path) -> Result<Scene, CaterError> {
        let mut scene: Scene = read_json(path)?;
        scene.video = path.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_owned();
        scene.check().map_err(|reason| CaterError::invalid(path, reason))?;
        Ok(scene)
    }

    pub fn write(&self, path: &Path) -> Result<(), CaterError> {
        write_json(path, self)
    }

    /// Instance names are unique; every movement is one of CATER's, of an object the scene has,
    /// between frames 0 and 300 with its start not after its end; a `_contain` names the object it
    /// contains, and that object exists.
    pub fn check(&self) -> Result<(), String> {
        let mut instances = HashSet::new();
        for o in &self.objects {
            if !instances.insert(o.instance.as_str()) {
                return Err(format!("two objects are named `{}`", o.instance));
            }
        }
        for (instance, moves) in &self.movements {
            if !instances.contains(instance.as_str()) {
                return Err(format!("movements of `{instance}`, which is not among the objects"));
            }
            for m in moves {
                let Some(kind) = m.kind() else {
                    return Err(format!(
                        "`{instance}`: unknown action `{}` (CATER's are _slide, _pick_place, _rotate, _contain, _no_op)",
                        m.action
                    ));
                };
                if m.start < 0 || m.end < m.start || m.end > LAST_KEYFRAME {
                    return Err(format!(
                        "`{instance}`: {} from frame {} to {} is outside frames 0 to {LAST_KEYFRAME}",
                        m.action, m.start, m.end
                    ));
                }
                match (&m.other, kind) {
                    (None, MovementKind::Contain) => {
                        return Err(format!("`{instance}`: _contain at frame {} names no object", m.start));
                    }
                    (Some(other), _) if !instances.contains(other.as_str()) => {
                        return Err(format!(
                            "`{instance}`: {} names `{other}`, which is not among the objects",
                            m.action
                        ));
                    }
                    _ => {}
                }
            }
        }
        Ok(())
    }

    pub fn object(&self, instance: &str) -> Option<&SceneObject> {
        self.objects.iter().find(|o| o.instance == instance)
    }
}
