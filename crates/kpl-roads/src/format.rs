//! The project's road-network file format: plain serde structures mirroring the JSON documented in
//! `docs/roads.md`. Nothing here is validated; [`crate::RoadNetwork::build`] checks a
//! [`NetworkFile`] and derives the geometry. Occluder files (`docs/roads.md`, "Occluders") use
//! [`OccluderSpec`] too.

use serde::{Deserialize, Serialize};

use crate::geom::Point;

/// The value of [`NetworkFile::format`].
pub const FORMAT_NAME: &str = "kpl-road-network";
/// The only version this crate reads and writes.
pub const FORMAT_VERSION: u32 = 1;

/// A road network as stored in a JSON file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkFile {
    /// Always `"kpl-road-network"`.
    pub format: String,
    /// Always 1.
    pub version: u32,
    /// How far from a lane's centre line `snap_to_lane` still snaps, in metres.
    #[serde(default = "default_snap_radius_m")]
    pub snap_radius_m: f64,
    pub nodes: Vec<NodeSpec>,
    pub roads: Vec<RoadSpec>,
    #[serde(default)]
    pub occluders: Vec<OccluderSpec>,
}

fn default_snap_radius_m() -> f64 {
    10.0
}

/// A place where roads end or meet: a crossing when three or more road ends meet there, a joint
/// with two, a map boundary (where cars enter and leave) with one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeSpec {
    pub id: String,
    pub pos: Point,
    /// Radius of the crossing area, where roads stop and turn connectors start; default: the
    /// widest half road width at the node plus 1.5 m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
}

/// A road from node `from` to node `to` through the points `via`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoadSpec {
    pub id: String,
    pub from: String,
    pub to: String,
    /// Intermediate centre-line points between the two nodes.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub via: Vec<Point>,
    /// Lanes from left to right when looking from `from` towards `to`.
    #[serde(default = "default_lanes")]
    pub lanes: Vec<LaneSpec>,
    #[serde(default = "default_speed_limit_mps")]
    pub speed_limit_mps: f64,
    /// Drawing order; a road on a bridge has a higher level than the road below it.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub level: i32,
}

fn is_zero(level: &i32) -> bool {
    *level == 0
}

/// One lane each way, 3.5 m wide, driving on the right.
pub fn default_lanes() -> Vec<LaneSpec> {
    vec![LaneSpec::new(3.5, LaneDirection::Backward), LaneSpec::new(3.5, LaneDirection::Forward)]
}

/// 50 km/h.
pub fn default_speed_limit_mps() -> f64 {
    13.9
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaneSpec {
    #[serde(default = "default_lane_width_m")]
    pub width_m: f64,
    pub direction: LaneDirection,
    /// A solid line on the lane's left, looking in its direction of travel: a car on it may not
    /// change to the lane there.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub solid_left: bool,
    /// The same on its right.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub solid_right: bool,
}

impl LaneSpec {
    /// A lane of this width and direction, with dashed lines on both sides.
    pub fn new(width_m: f64, direction: LaneDirection) -> LaneSpec {
        LaneSpec { width_m, direction, solid_left: false, solid_right: false }
    }
}

fn default_lane_width_m() -> f64 {
    3.5
}

/// Which way a lane's traffic flows relative to its road.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LaneDirection {
    /// From the road's `from` node to its `to` node.
    Forward,
    /// From `to` to `from`.
    Backward,
}

/// Something that hides what is under it from the UAV: either a stretch of one road (`road`,
/// `from_m`, `to_m`: arc length along the road's centre line from its `from` node; it hides only
/// what is on that road, not the road on a bridge above it) or a `polygon`, which hides
/// everything under it, or only what is on the roads listed in `roads`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OccluderSpec {
    pub id: String,
    pub kind: OccluderKind,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub road: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub from_m: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to_m: Option<f64>,
    /// Corners of the hidden area, in order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub polygon: Option<Vec<Point>>,
    /// With `polygon`: hide only what is on these roads (by name); empty hides everything.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub roads: Vec<String>,
}

impl OccluderSpec {
    /// A stretch of `road` from `from_m` to `to_m`.
    pub fn stretch(id: &str, kind: OccluderKind, road: &str, from_m: f64, to_m: f64) -> OccluderSpec {
        OccluderSpec {
            id: id.to_string(),
            kind,
            road: Some(road.to_string()),
            from_m: Some(from_m),
            to_m: Some(to_m),
            polygon: None,
            roads: Vec::new(),
        }
    }

    /// A polygon hiding everything under it.
    pub fn area(id: &str, kind: OccluderKind, polygon: Vec<Point>) -> OccluderSpec {
        OccluderSpec {
            id: id.to_string(),
            kind,
            road: None,
            from_m: None,
            to_m: None,
            polygon: Some(polygon),
            roads: Vec::new(),
        }
    }
}

/// What an occluder is; only drawing tells them apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OccluderKind {
    Bridge,
    Tunnel,
    /// Trees (a row along a road, a wood).
    Trees,
    Building,
    Other,
}

impl OccluderKind {
    /// The kind a SUMO polygon's `type` names (`bridge`, `tunnel`, `forest`, `building.yes`, ...).
    pub fn from_sumo_type(text: &str) -> OccluderKind {
        let text = text.to_ascii_lowercase();
        if text.contains("bridge") {
            OccluderKind::Bridge
        } else if text.contains("tunnel") {
            OccluderKind::Tunnel
        } else if ["tree", "forest", "wood"].iter().any(|w| text.contains(w)) {
            OccluderKind::Trees
        } else if text.contains("building") {
            OccluderKind::Building
        } else {
            OccluderKind::Other
        }
    }
}

/// An occluder file: `{"occluders": [...]}` with the items of [`NetworkFile::occluders`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OccluderFile {
    pub occluders: Vec<OccluderSpec>,
}

impl NetworkFile {
    /// An empty network of the current format version.
    pub fn new() -> NetworkFile {
        NetworkFile {
            format: FORMAT_NAME.to_string(),
            version: FORMAT_VERSION,
            snap_radius_m: default_snap_radius_m(),
            nodes: Vec::new(),
            roads: Vec::new(),
            occluders: Vec::new(),
        }
    }

    pub fn add_node(&mut self, id: &str, pos: Point) {
        self.nodes.push(NodeSpec { id: id.to_string(), pos, radius_m: None });
    }

    /// Adds a road with the default lanes and speed limit.
    pub fn add_road(&mut self, id: &str, from: &str, to: &str, via: Vec<Point>) {
        self.roads.push(RoadSpec {
            id: id.to_string(),
            from: from.to_string(),
            to: to.to_string(),
            via,
            lanes: default_lanes(),
            speed_limit_mps: default_speed_limit_mps(),
            level: 0,
        });
    }
}

impl Default for NetworkFile {
    fn default() -> Self {
        NetworkFile::new()
    }
}
