//! The data AAPA exchanges with the rest of the system: percepts, actions and camera poses in, the
//! world state out. The world state is also the algorithm's only memory: it is fed back as the next
//! cycle's input (paper Fig. 2), so a runtime wrapper keeps nothing else. Everything is serde, boxes
//! as `[x1, y1, x2, y2]` arrays, so a runtime can carry these values as JSON.

use std::sync::Arc;

use kpl_core::{BBox, Time};
use serde::{Deserialize, Serialize};

/// A symbol, label or type name. Shared, so copying a world state between cycles is cheap.
pub type Symbol = Arc<str>;

/// One detection of one frame (paper III-A: an identification label and the attributes type,
/// position and size, optionally colour).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Percept {
    /// The detector's label (`case0`). Detectors reassign these, so AAPA only uses it to name a new
    /// anchor, never to align.
    pub label: Symbol,
    /// The object category (`case`, `large_red_cone_rubber`).
    #[serde(rename = "type")]
    pub object_type: Symbol,
    /// Pixel box.
    #[serde(rename = "box", with = "bbox_array")]
    pub bbox: BBox,
    /// Mean colour, if the detector reports one (RGB in [0, 1]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<[f64; 3]>,
}

impl Percept {
    pub fn new(label: &str, object_type: &str, bbox: BBox) -> Percept {
        Percept { label: label.into(), object_type: object_type.into(), bbox, colour: None }
    }
}

/// Whether an action event reports the start or the completion of an action.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionPhase {
    Started,
    /// Most effects (an object held, inserted, contained) hold once the action is done.
    #[default]
    Completed,
}

/// An agent action event, `pick_up(gripper, gear0)`. Arguments name anchors by symbol, or by type
/// when the caller only knows the category (the CATER annotations name object classes).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Action {
    pub name: Symbol,
    pub args: Vec<Symbol>,
    #[serde(default)]
    pub phase: ActionPhase,
    /// When a started action is expected to complete, if known (used to bound motion prediction).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expected_end: Option<Time>,
}

impl Action {
    pub fn completed(name: &str, args: &[&str]) -> Action {
        Action {
            name: name.into(),
            args: args.iter().map(|a| Symbol::from(*a)).collect(),
            phase: ActionPhase::Completed,
            expected_end: None,
        }
    }
    pub fn started(name: &str, args: &[&str], expected_end: Option<Time>) -> Action {
        Action {
            name: name.into(),
            args: args.iter().map(|a| Symbol::from(*a)).collect(),
            phase: ActionPhase::Started,
            expected_end,
        }
    }
}

/// The camera position in metres, in a fixed frame whose axes are those of the camera (x to the
/// image's right, y to the image's bottom, z along the optical axis). An eye-in-hand camera that
/// translates over a work surface reports one per cycle; rotation is not modelled (the paper's
/// compensation is a translation too).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct CameraPose {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// What AAPA believes about an anchored object this cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnchorStatus {
    /// Aligned to a percept this cycle.
    Visible,
    /// Not detected, but its box intersects a detected object (III-B.2a).
    Occluded,
    /// Not detected and its predicted box lies outside the field of view.
    OutOfView,
    /// Not detected, maintained because an ancestor in its attachment hierarchy is anchored.
    Attached,
    /// Not detected with no explanation: removed from view without an action. Its confidence
    /// decays by `conf_minus` per cycle until it is dropped.
    Lost,
}

/// A binary relation of the world state: `attached(plug0, case0)`, `holding(gripper0, gear0)`,
/// `left_of(a, b)`.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Relation {
    pub name: Symbol,
    pub args: [Symbol; 2],
}

impl Relation {
    pub fn new(name: &str, a: &str, b: &str) -> Relation {
        Relation { name: name.into(), args: [a.into(), b.into()] }
    }
}

/// The attachment of a child anchor to its one parent, with the geometry that lets the child follow
/// the parent while it is not seen.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Attachment {
    pub parent: Symbol,
    /// The relation the attaching action produced besides `attached`, e.g. `holding(gripper, obj)`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relation: Option<Relation>,
    /// Child bottom-centre minus parent bottom-centre, pixels, when last fixed.
    pub offset: [f64; 2],
    /// Child width and height, pixels, when last fixed.
    pub size: [f64; 2],
    /// The parent's scale (square root of its box area) when the geometry was fixed.
    pub parent_scale: f64,
    /// The parent's width and height when the geometry was fixed (`[0, 0]`: unknown, the offset
    /// then scales with `parent_scale`).
    #[serde(default)]
    pub parent_size: [f64; 2],
    /// The child cannot be seen while attached (contained): it is not aligned to percepts.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub hidden: bool,
    /// The parent's box was a guess when the geometry was fixed (it came over the child unseen):
    /// the geometry is fixed again, with the child where it is, when the parent is next seen
    /// before it moves.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub provisional: bool,
    /// The geometry is still being measured (extension `average_still`): a hidden child keeps its
    /// box while its parent stands still, and the geometry is fixed again each cycle against the
    /// parent's averaged box, until the parent first moves.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub settling: bool,
}

/// One anchor: a symbol grounded in percepts (III-B).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Anchor {
    pub symbol: Symbol,
    #[serde(rename = "type")]
    pub object_type: Symbol,
    #[serde(rename = "box", with = "bbox_array")]
    pub bbox: BBox,
    /// In [0, 1]: 0 when first detected, `conf_plus` more per aligned cycle (III-B.2c).
    pub confidence: f64,
    pub status: AnchorStatus,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<[f64; 3]>,
    pub first_seen: Time,
    pub last_seen: Time,
    /// Image velocity of the box centre in pixels per second, from consecutive alignments.
    #[serde(default)]
    pub velocity: [f64; 2],
    /// Set while an action moves this object (motion prediction); `moving_until` bounds it.
    #[serde(default)]
    pub moving: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_until: Option<Time>,
    /// When an action last moved this object (its move's start, or its end once over).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_moved: Option<Time>,
    /// Set while an action turns this object in place (its box changes, its place does not).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub turning: bool,
    /// Width and height when last seen with no other detection overlapping it (partial-box
    /// restoration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub full_size: Option<[f64; 2]>,
    /// The last percept aligned to this anchor, as detected (before any restoration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_percept_box: Option<[f64; 4]>,
    /// The current box is a restored partial view.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub partial: bool,
    /// When the action moving this object started.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_since: Option<Time>,
    /// How this object's box was seen during the move in progress: `[time, centre x, centre y,
    /// width, height]`, the first as it was when the move started (for
    /// [`crate::MotionProfile::Fitted`], and to smooth a detector's boxes of a carrier).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub move_track: Vec<[f64; 5]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attachment: Option<Attachment>,
    /// `confidence >= theta_inf`: passed on for world state inference (III-B.3).
    pub for_inference: bool,
    /// How often each type was detected for this anchor; `object_type` is the most frequent, so a
    /// detector's occasional misclassification does not rename the object.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub type_votes: Vec<(Symbol, u32)>,
    /// While the object stands still (extension `average_still`): the mean of the boxes seen since
    /// it last moved, and how many there were.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub still: Option<StillBox>,
}

/// The running mean of the boxes of an object standing still.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StillBox {
    pub mean: [f64; 4],
    pub count: u32,
    /// Boxes in a row that strayed from the mean (a detector's outliers, left out of it).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub strays: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

impl Anchor {
    /// A new anchor first seen at `time`: not moving, not attached, no history; one type vote.
    pub fn new(symbol: Symbol, object_type: Symbol, bbox: BBox, status: AnchorStatus, time: Time) -> Self {
        Anchor {
            symbol,
            type_votes: vec![(object_type.clone(), 1)],
            object_type,
            bbox,
            confidence: 0.0,
            status,
            colour: None,
            first_seen: time,
            last_seen: time,
            velocity: [0.0, 0.0],
            moving: false,
            moving_until: None,
            turning: false,
            last_moved: None,
            moving_since: None,
            move_track: Vec::new(),
            full_size: None,
            last_percept_box: None,
            partial: false,
            attachment: None,
            for_inference: false,
            still: None,
        }
    }

    /// Anchored in the paper's sense: confidence at or above `theta_anch`.
    pub fn is_anchored(&self, theta_anch: f64) -> bool {
        self.confidence >= theta_anch
    }
}

/// The world state AAPA outputs each cycle and reads back the next (paper Fig. 2).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct WorldState {
    /// The time of the cycle that produced this state; `None` before the first cycle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<Time>,
    /// The camera pose of that cycle, for the next cycle's camera movement alignment.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraPose>,
    pub anchors: Vec<Anchor>,
    pub relations: Vec<Relation>,
    /// What this cycle could not use (an action naming no known anchor, ...). Cleared each cycle.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// Actions in progress whose moving object is named by a type that several anchors share: which
    /// anchor it is, once its motion tells (or still undecided). Part of the memory, like the anchors.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bindings: Vec<Binding>,
}

/// An anchor that may be the one an action moves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub symbol: Symbol,
    /// Its box centre when the action started.
    pub start: [f64; 2],
    /// When it was first seen to have moved from there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub onset: Option<Time>,
    /// Whether it was moving already when the action started (it moved in that cycle): that
    /// motion is an earlier action's.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub moving_at_start: bool,
}

/// An action whose first argument (the object it moves) names a type several anchors have, from its
/// `started` event to its `completed` one. Its started effects wait until the anchor is known: for an
/// action that names another, single object (`_contain(cone, snitch)`), the candidate nearest that
/// object when the action completes; otherwise the candidate that started moving first after the
/// action started, not one already moving then (the earlier of two open actions on such a type
/// takes the earlier mover; two started at once wait for their completion), or at completion the
/// one that moved most.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Binding {
    /// The `started` event.
    pub action: Action,
    /// When it started.
    pub started: Time,
    /// The anchors of the type then.
    pub candidates: Vec<Candidate>,
    /// The anchor decided on, once known (its started effects are then applied).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bound: Option<Symbol>,
    /// The action is over; the binding is kept while another action on the type is undecided, so
    /// that one is not given this one's object.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub completed: bool,
}

impl WorldState {
    pub fn anchor(&self, symbol: &str) -> Option<&Anchor> {
        self.anchors.iter().find(|a| &*a.symbol == symbol)
    }

    pub fn has_relation(&self, name: &str, a: &str, b: &str) -> bool {
        self.relations.iter().any(|r| &*r.name == name && &*r.args[0] == a && &*r.args[1] == b)
    }

    /// The best anchor of a type: anchored before tentative, then the most confident, then the
    /// most recently seen, then the oldest. This is how a consumer asking "where is the snitch"
    /// should read the state (a ghost anchored for a frame or two loses to the real object).
    pub fn best_of_type(&self, object_type: &str, theta_anch: f64) -> Option<&Anchor> {
        self.anchors.iter().filter(|a| &*a.object_type == object_type).max_by(|a, b| {
            a.is_anchored(theta_anch)
                .cmp(&b.is_anchored(theta_anch))
                .then(a.confidence.total_cmp(&b.confidence))
                .then(a.last_seen.cmp(&b.last_seen))
                // Older anchors win the remaining ties (max_by keeps the last maximum).
                .then(b.first_seen.cmp(&a.first_seen))
        })
    }
}

/// Serde for [`BBox`] as a `[x1, y1, x2, y2]` array (kpl-core's `BBox` carries no serde).
pub mod bbox_array {
    use kpl_core::BBox;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(b: &BBox, s: S) -> Result<S::Ok, S::Error> {
        [b.x1, b.y1, b.x2, b.y2].serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<BBox, D::Error> {
        let [x1, y1, x2, y2] = <[f64; 4]>::deserialize(d)?;
        Ok(BBox::new(x1, y1, x2, y2))
    }
}
