//! The road network model: nodes (junctions: crossings, joints, map boundaries), roads with their
//! lanes, connector lanes inside junctions (SUMO's internal lanes), occluders, and the geometry
//! queries that anchoring and formulas use (`on_road`, `snap_to_lane`, lane positions), answered
//! through spatial grids. Built from the project's JSON form ([`crate::build`]) or read from a
//! SUMO network ([`crate::sumo`]); both give the same model.
//!
//! Lanes form a directed graph: a road lane's successors are the connector lanes that leave from
//! its end (the allowed turns), a connector's successor is the next connector or the road lane it
//! leads into. So "which branch does a car take" is "which successor lane", and prediction along
//! the network ([`crate::predict`]) walks this graph.
//!
//! ```
//! use kpl_roads::{RoadNetwork, scenarios};
//! let net = RoadNetwork::build(&scenarios::crossing()).unwrap();
//! assert!(net.on_road([0.0, 0.0]));          // the middle of the crossing
//! assert!(!net.on_road([30.0, 30.0]));       // a field beside it
//! let snapped = net.snap_to_lane([-50.0, -1.0], Some(0.0)).unwrap(); // eastbound, south of the axis
//! assert!((snapped.point[1] + 1.75).abs() < 1e-9);                   // the eastbound lane centre
//! ```

use std::collections::HashMap;
use std::sync::OnceLock;

use crate::format::{LaneDirection, NetworkFile};
use crate::geom::{self, Point, Polyline, bounds_of, dist_to_segment, dist2_to_segment, point_in_polygon};
use crate::index::{Grid, GridBuilder};
use crate::occluders::{Occluder, Occluders};

/// Index of a road in [`RoadNetwork::roads`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct RoadId(pub u32);
/// Index of a node in [`RoadNetwork::nodes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct NodeId(pub u32);
/// Index of a lane (a road lane or a connector) in [`RoadNetwork::lanes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct LaneId(pub u32);

/// Lateral acceleration cars accept in turns; gives the speed limits of generated connectors.
pub(crate) const TURN_LATERAL_ACCEL: f64 = 2.5;
/// What a lane heading opposite to the given one adds to the snapping cost, in metres.
pub const HEADING_PENALTY_M: f64 = 10.0;
/// What snapping adds for a lane of the same road and direction as the previous lane (a lane
/// change), in metres.
pub const LANE_CHANGE_PENALTY_M: f64 = 1.0;
/// What snapping adds for a lane that does not continue the previous lane (neither the lane
/// itself, nor a lane a few steps before or after it, nor a neighbour of those), in metres. Less
/// than the distance between neighbouring lane centres, so that a wrong first guess is corrected
/// by the measurements that follow.
pub const DISCONTINUITY_PENALTY_M: f64 = 2.0;
/// Side of a spatial-grid cell.
const GRID_CELL_M: f64 = 15.0;
/// What a snap searches beyond the cost of the lane it was on (see [`RoadNetwork::snap`]): far
/// above the rounding of distances, so the segment that cost was found on is always among those
/// searched.
const SNAP_BOUND_MARGIN_M: f64 = 0.01;
/// Side of a cell of the fine lane grid (used by searches no wider than a cell).
const FINE_GRID_CELL_M: f64 = 3.0;
/// Most cells the fine lane grid may have (4 MB of offsets); bigger networks get coarser cells.
const FINE_GRID_MAX_CELLS: f64 = 1.0e6;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeKind {
    /// One neighbour: the edge of the map (where cars enter and leave) or a dead end.
    Boundary,
    /// Two neighbours: a bend or a change of road.
    Joint,
    /// Three or more neighbours.
    Crossing,
}

#[derive(Debug, Clone)]
pub struct Node {
    pub id: NodeId,
    pub name: String,
    pub pos: Point,
    pub kind: NodeKind,
    /// SUMO's junction type (`traffic_light`, `priority`, `dead_end`, ...); `None` for JSON.
    pub junction_type: Option<String>,
    /// Where roads stop and connectors start, measured from `pos` (for SUMO: the farthest corner
    /// of the junction's shape).
    pub radius_m: f64,
    pub roads: Vec<RoadId>,
    /// The junction's area as a polygon (empty at a boundary of a JSON network, or where SUMO
    /// gives no shape).
    pub area: Vec<Point>,
}

#[derive(Debug, Clone)]
pub struct Road {
    pub id: RoadId,
    /// The JSON road id, or the SUMO edge id.
    pub name: String,
    pub from: NodeId,
    pub to: NodeId,
    /// The middle of the paved band: for JSON from the `from` node's position to the `to`
    /// node's; for SUMO the middle of the edge's lanes (which end at the junctions' borders).
    pub centerline: Polyline,
    /// Left to right looking from `from` to `to`.
    pub lanes: Vec<RoadLane>,
    pub width_m: f64,
    pub speed_limit_mps: f64,
    pub level: i32,
}

#[derive(Debug, Clone)]
pub struct RoadLane {
    pub width_m: f64,
    pub direction: LaneDirection,
    /// Signed distance of the lane centre from the road centre line, positive to the left.
    pub lateral_m: f64,
    pub lane: LaneId,
}

/// What a lane belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaneKind {
    /// Lane `index` (left to right) of a road.
    Road { road: RoadId, index: u32 },
    /// A connection inside a junction from road lane `from` to road lane `to` (a SUMO internal
    /// lane; a turn may pass two of them).
    Connector { node: NodeId, from: LaneId, to: LaneId },
}

/// A drivable path in its direction of travel.
#[derive(Debug, Clone)]
pub struct Lane {
    pub id: LaneId,
    /// The SUMO lane id (`E3_0`, `:J1_2_0`); for JSON networks `ROAD_INDEX` for road lanes and
    /// `:NODE_K` for connectors.
    pub name: String,
    pub kind: LaneKind,
    pub path: Polyline,
    pub width_m: f64,
    pub speed_limit_mps: f64,
    pub successors: Vec<LaneId>,
    pub predecessors: Vec<LaneId>,
    /// A connector of a U-turn (SUMO's `dir="t"`): neither prediction nor simulated traffic takes
    /// it.
    pub turnaround: bool,
    /// Whether a car on this lane may change to the neighbouring lane on its left (false: a
    /// solid line; SUMO's `changeLeft`, JSON's `solid_left`).
    pub may_change_left: bool,
    /// The same to its right (SUMO's `changeRight`, JSON's `solid_right`).
    pub may_change_right: bool,
}

/// Where on the network something is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// On lane `lane` (left to right) of `road`.
    Road { road: RoadId, lane: u32 },
    /// Inside the junction at `node`.
    Crossing { node: NodeId },
}

/// A position on a lane, as returned by [`RoadNetwork::snap_to_lane`] and by prediction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LanePosition {
    pub lane: LaneId,
    pub place: Place,
    /// Arc length along the lane, in its direction of travel, from the lane's start.
    pub offset_m: f64,
    /// Signed distance of the query point from the lane centre, positive to the left of travel.
    pub lateral_m: f64,
    /// The point on the lane centre.
    pub point: Point,
    /// The lane's direction of travel there (radians, counter-clockwise from east).
    pub heading: f64,
}

impl LanePosition {
    /// The road, when not inside a junction.
    pub fn road(&self) -> Option<RoadId> {
        match self.place {
            Place::Road { road, .. } => Some(road),
            Place::Crossing { .. } => None,
        }
    }
}

/// What snapping knows besides the position.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SnapHint {
    /// The direction of travel (radians), when it is known: lanes going the other way count as up
    /// to [`HEADING_PENALTY_M`] further away.
    pub heading: Option<f64>,
    /// The lane the object was on before: lanes that do not continue it count as up to
    /// [`DISCONTINUITY_PENALTY_M`] further away.
    pub previous: Option<LaneId>,
}

/// SUMO's `location`: how the network's coordinates relate to the original ones.
#[derive(Debug, Clone, PartialEq)]
pub struct Location {
    /// Added to the original coordinates to give the network's.
    pub net_offset: Point,
    /// The network's bounds after conversion, `(min, max)`.
    pub conv_boundary: (Point, Point),
    /// The bounds of the original data, `(min, max)`.
    pub orig_boundary: (Point, Point),
    /// The projection used (`!` for none).
    pub proj_parameter: String,
}

/// A SUMO roundabout: its junctions and the edges around it.
#[derive(Debug, Clone, PartialEq)]
pub struct Roundabout {
    pub nodes: Vec<NodeId>,
    pub roads: Vec<RoadId>,
}

/// Where a network came from.
#[derive(Debug, Clone)]
pub(crate) enum Source {
    Json(NetworkFile),
    Sumo,
}

/// The parts of a network before indexing, as the JSON builder and the SUMO reader make them.
#[derive(Debug)]
pub(crate) struct Parts {
    pub nodes: Vec<Node>,
    pub roads: Vec<Road>,
    pub lanes: Vec<Lane>,
    pub occluders: Vec<Occluder>,
    pub snap_radius_m: f64,
    pub source: Source,
    pub location: Option<Location>,
    pub roundabouts: Vec<Roundabout>,
}

/// A checked road network with its derived lanes and spatial indexes. Immutable once built.
#[derive(Debug, Clone)]
pub struct RoadNetwork {
    source: Source,
    nodes: Vec<Node>,
    roads: Vec<Road>,
    lanes: Vec<Lane>,
    occluders: Occluders,
    location: Option<Location>,
    roundabouts: Vec<Roundabout>,
    bounds: (Point, Point),
    snap_radius_m: f64,
    /// `(road, segment)` per item of `road_grid`.
    road_segments: Vec<(RoadId, u32)>,
    road_grid: Grid,
    crossing_grid: Grid,
    /// `(lane, segment)` per item of `lane_grid`, lane by lane.
    lane_segments: Vec<LaneSegment>,
    /// The segments of lane `l` are `lane_segments[lane_segment_start[l]..lane_segment_start[l + 1]]`.
    lane_segment_start: Vec<u32>,
    lane_grid: Grid,
    /// The same items in cells of [`FINE_GRID_CELL_M`], for searches that short (a snap bounded
    /// by the lane an object was on, a lane-centre lookup): a 15 m cell at a junction holds
    /// dozens of connector segments.
    fine_lane_grid: Grid,
    max_half_lane_width_m: f64,
    /// Road lanes where traffic enters the map (no predecessor but U-turns).
    entry_lanes: Vec<LaneId>,
    /// Road lanes and the running total of their lengths, for sampling positions uniformly.
    road_lane_cumulative: Vec<(f64, LaneId)>,
    road_names: HashMap<String, RoadId>,
    node_names: HashMap<String, NodeId>,
    lane_names: HashMap<String, LaneId>,
    /// Per lane, the lanes that continue it ([`RoadNetwork::continuation`]), worked out the first
    /// time a snap asks (every car's every step asks, for the lane it was on).
    continuations: Vec<OnceLock<Continuation>>,
}

/// A segment of a lane's path, as the lane grid indexes it.
#[derive(Debug, Clone, Copy)]
struct LaneSegment {
    lane: LaneId,
    segment: u32,
    a: Point,
    b: Point,
    /// Unit vector from `a` to `b`.
    direction: Point,
}

impl RoadNetwork {
    /// Checks a network file (reporting every problem found) and derives lanes, connectors,
    /// crossing areas, occluder areas and the spatial indexes.
    pub fn build(file: &NetworkFile) -> Result<RoadNetwork, crate::NetworkError> {
        Ok(RoadNetwork::index(crate::build::parts_of(file)?))
    }

    /// The file this network was built from (`None` for a SUMO network).
    pub fn file(&self) -> Option<&NetworkFile> {
        match &self.source {
            Source::Json(file) => Some(file),
            Source::Sumo => None,
        }
    }

    /// Whether the network was read from a SUMO file.
    pub fn is_sumo(&self) -> bool {
        matches!(self.source, Source::Sumo)
    }

    pub(crate) fn index(parts: Parts) -> RoadNetwork {
        let Parts { nodes, roads, mut lanes, occluders, snap_radius_m, source, location, roundabouts } =
            parts;
        let mut all_points: Vec<Point> = Vec::new();
        for road in &roads {
            let (lo, hi) = road.centerline.bounds();
            let margin = road.width_m;
            all_points.push([lo[0] - margin, lo[1] - margin]);
            all_points.push([hi[0] + margin, hi[1] + margin]);
        }
        for node in &nodes {
            all_points.extend_from_slice(&node.area);
            all_points.push(node.pos);
        }
        for lane in &lanes {
            // Mitred lanes can reach beyond the road band at sharp bends.
            let (lo, hi) = lane.path.bounds();
            let margin = lane.width_m;
            all_points.push([lo[0] - margin, lo[1] - margin]);
            all_points.push([hi[0] + margin, hi[1] + margin]);
        }
        let bounds = bounds_of(&all_points);

        let mut road_segments = Vec::new();
        let mut road_grid = GridBuilder::new(bounds.0, bounds.1, GRID_CELL_M);
        for road in &roads {
            for s in 0..road.centerline.n_segments() {
                let (a, b, _) = road.centerline.segment(s);
                road_grid.insert_segment(road_segments.len() as u32, a, b, road.width_m / 2.0);
                road_segments.push((road.id, s as u32));
            }
        }
        let mut crossing_grid = GridBuilder::new(bounds.0, bounds.1, GRID_CELL_M);
        for node in &nodes {
            if node.area.len() >= 3 {
                let (lo, hi) = bounds_of(&node.area);
                crossing_grid.insert_box(node.id.0, lo, hi);
            }
        }
        let mut lane_segments = Vec::new();
        let mut lane_segment_start = Vec::with_capacity(lanes.len() + 1);
        let mut lane_grid = GridBuilder::new(bounds.0, bounds.1, GRID_CELL_M);
        let mut fine_lane_grid =
            GridBuilder::with_max_cells(bounds.0, bounds.1, FINE_GRID_CELL_M, FINE_GRID_MAX_CELLS);
        for lane in &lanes {
            lane_segment_start.push(lane_segments.len() as u32);
            for s in 0..lane.path.n_segments() {
                let (a, b, _) = lane.path.segment(s);
                lane_grid.insert_segment(lane_segments.len() as u32, a, b, 0.0);
                fine_lane_grid.insert_segment(lane_segments.len() as u32, a, b, 0.0);
                let direction = geom::unit(geom::heading_of(geom::sub(b, a)));
                lane_segments.push(LaneSegment { lane: lane.id, segment: s as u32, a, b, direction });
            }
        }
        lane_segment_start.push(lane_segments.len() as u32);
        for lane in &mut lanes {
            lane.successors.sort_unstable();
            lane.successors.dedup();
            lane.predecessors.sort_unstable();
            lane.predecessors.dedup();
        }
        let entry_lanes = lanes
            .iter()
            .filter(|l| {
                matches!(l.kind, LaneKind::Road { .. })
                    && l.predecessors.iter().all(|&p| lanes[p.0 as usize].turnaround)
            })
            .map(|l| l.id)
            .collect();
        let mut total = 0.0;
        let road_lane_cumulative = lanes
            .iter()
            .filter(|l| matches!(l.kind, LaneKind::Road { .. }))
            .map(|l| {
                total += l.path.length();
                (total, l.id)
            })
            .collect();
        let max_half_lane_width_m = lanes.iter().map(|l| l.width_m / 2.0).fold(0.0, f64::max);
        let mut road_names = HashMap::with_capacity(roads.len());
        for road in &roads {
            road_names.entry(road.name.clone()).or_insert(road.id);
        }
        let mut node_names = HashMap::with_capacity(nodes.len());
        for node in &nodes {
            node_names.entry(node.name.clone()).or_insert(node.id);
        }
        let n_lanes = lanes.len();
        let mut lane_names = HashMap::with_capacity(lanes.len());
        for lane in &lanes {
            lane_names.entry(lane.name.clone()).or_insert(lane.id);
        }
        RoadNetwork {
            snap_radius_m,
            source,
            nodes,
            roads,
            lanes,
            occluders: Occluders::new(occluders),
            location,
            roundabouts,
            bounds,
            road_segments,
            road_grid: road_grid.build(),
            crossing_grid: crossing_grid.build(),
            lane_segments,
            lane_segment_start,
            lane_grid: lane_grid.build(),
            fine_lane_grid: fine_lane_grid.build(),
            max_half_lane_width_m,
            entry_lanes,
            road_lane_cumulative,
            road_names,
            node_names,
            lane_names,
            continuations: (0..n_lanes).map(|_| OnceLock::new()).collect(),
        }
    }

    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    pub fn roads(&self) -> &[Road] {
        &self.roads
    }

    pub fn lanes(&self) -> &[Lane] {
        &self.lanes
    }

    /// The occluders of the network's file.
    pub fn occluders(&self) -> &Occluders {
        &self.occluders
    }

    /// SUMO's `location` element, for a SUMO network.
    pub fn location(&self) -> Option<&Location> {
        self.location.as_ref()
    }

    /// SUMO's roundabouts, for a SUMO network.
    pub fn roundabouts(&self) -> &[Roundabout] {
        &self.roundabouts
    }

    // The accessors below take ids handed out by this network and panic on others; use the
    // slices (`nodes()`, `roads()`, `lanes()`) with `get` for ids of unknown origin.

    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id.0 as usize]
    }

    pub fn road(&self, id: RoadId) -> &Road {
        &self.roads[id.0 as usize]
    }

    pub fn lane(&self, id: LaneId) -> &Lane {
        &self.lanes[id.0 as usize]
    }

    pub fn road_by_name(&self, name: &str) -> Option<&Road> {
        self.road_names.get(name).map(|&id| self.road(id))
    }

    pub fn node_by_name(&self, name: &str) -> Option<&Node> {
        self.node_names.get(name).map(|&id| self.node(id))
    }

    pub fn lane_by_name(&self, name: &str) -> Option<&Lane> {
        self.lane_names.get(name).map(|&id| self.lane(id))
    }

    /// Whether a car that was on lane `from` and is now on lane `to` at `at` (a point of `to`)
    /// changed lanes across a solid line: both are lanes of one road going one way, and `from`
    /// forbids changing to the side `to` lies on (its `may_change_left` or `may_change_right`).
    /// A change over more than one lane counts the first marking only.
    pub fn crosses_solid_line(&self, from: LaneId, to: LaneId, at: Point) -> bool {
        if from == to {
            return false;
        }
        let (old, new) = (self.lane(from), self.lane(to));
        let (LaneKind::Road { road: old_road, .. }, LaneKind::Road { road: new_road, .. }) =
            (old.kind, new.kind)
        else {
            return false;
        };
        if old_road != new_road {
            return false;
        }
        let there = old.path.project(at);
        let new_heading = new.path.heading_at(new.path.project(at).offset);
        if geom::heading_difference(old.path.heading_at(there.offset), new_heading)
            >= std::f64::consts::FRAC_PI_2
        {
            return false; // the other direction of a two-way road
        }
        if there.lateral > 0.0 { !old.may_change_left } else { !old.may_change_right }
    }

    /// The bounding box of everything drivable, as `(min, max)`.
    pub fn bounds(&self) -> (Point, Point) {
        self.bounds
    }

    pub fn snap_radius_m(&self) -> f64 {
        self.snap_radius_m
    }

    /// Road lanes where traffic enters the map (no predecessor but U-turns).
    pub fn entry_lanes(&self) -> &[LaneId] {
        &self.entry_lanes
    }

    /// The lanes traffic may take after `lane`: its successors but U-turns.
    pub fn onward(&self, lane: LaneId) -> impl Iterator<Item = LaneId> + '_ {
        self.lanes[lane.0 as usize]
            .successors
            .iter()
            .copied()
            .filter(|&s| !self.lanes[s.0 as usize].turnaround)
    }

    /// The direction of a road lane relative to its road (`None` for a connector).
    pub fn direction_of(&self, lane: LaneId) -> Option<(RoadId, LaneDirection)> {
        match self.lanes[lane.0 as usize].kind {
            LaneKind::Road { road, index } => {
                Some((road, self.roads[road.0 as usize].lanes[index as usize].direction))
            }
            LaneKind::Connector { .. } => None,
        }
    }

    /// Total length of all road lanes (connectors excluded), in metres.
    pub fn road_lane_length_m(&self) -> f64 {
        self.road_lane_cumulative.last().map_or(0.0, |&(total, _)| total)
    }

    /// Whether `pos` is on the paved surface: within half a road's width of its centre line,
    /// inside a junction, or within half a lane's width of the lane's centre (which adds the
    /// outside of sharp bends, where mitred lanes reach beyond the round-cornered road band, and
    /// the connector lanes of SUMO junctions without a shape).
    pub fn on_road(&self, pos: Point) -> bool {
        self.road_at(pos).is_some() || self.crossing_at(pos).is_some() || self.on_lane(pos)
    }

    fn on_lane(&self, pos: Point) -> bool {
        let mut found = false;
        self.lane_grid.for_each_near(pos, self.max_half_lane_width_m, |item| {
            let segment = &self.lane_segments[item as usize];
            if !found {
                let half = self.lanes[segment.lane.0 as usize].width_m / 2.0;
                found = geom::within_segment(pos, segment.a, segment.b, half + 1e-9);
            }
        });
        found
    }

    /// A road whose paved width contains `pos` (the lowest-numbered one when several overlap).
    pub fn road_at(&self, pos: Point) -> Option<RoadId> {
        self.road_grid
            .at(pos)
            .iter()
            .map(|&item| self.road_segments[item as usize])
            .filter(|&(road, s)| {
                let road = &self.roads[road.0 as usize];
                let (a, b, _) = road.centerline.segment(s as usize);
                geom::within_segment(pos, a, b, road.width_m / 2.0 + 1e-9)
            })
            .map(|(road, _)| road)
            .min()
    }

    /// The junction whose area contains `pos`.
    pub fn crossing_at(&self, pos: Point) -> Option<NodeId> {
        self.crossing_grid
            .at(pos)
            .iter()
            .map(|&n| NodeId(n))
            .find(|&n| point_in_polygon(pos, &self.nodes[n.0 as usize].area))
    }

    /// The nearest lane centre within the network's snap radius of `pos`. With a `heading`
    /// (radians), lanes going the other way count as up to 10 m further away, so a car is snapped
    /// to the lane of its own direction and, inside a crossing, to the connector it follows.
    pub fn snap_to_lane(&self, pos: Point, heading: Option<f64>) -> Option<LanePosition> {
        self.snap(pos, &SnapHint { heading, previous: None })
    }

    /// The lane centre within the snap radius of `pos` with the least cost: the distance, plus
    /// `HEADING_PENALTY_M * (1 - cos(angle between heading and lane)) / 2` with a heading, plus,
    /// with a previous lane, nothing for a lane that continues it (the lane itself, its
    /// successors and predecessors up to three lanes away), [`LANE_CHANGE_PENALTY_M`] for a lane
    /// beside one of those (same road, same direction) and [`DISCONTINUITY_PENALTY_M`] for any
    /// other. So a car standing in a queue, whose velocity says nothing about its heading, stays
    /// on its lane instead of jumping to the oncoming one when noise puts it nearer.
    pub fn snap(&self, pos: Point, hint: &SnapHint) -> Option<LanePosition> {
        self.snap_within(pos, hint, self.snap_radius_m)
    }

    /// The lane whose centre line passes within `tolerance_m` of `pos` (nearer than the network's
    /// snap radius), the nearest: what [`RoadNetwork::snap_to_lane`] without a heading gives when
    /// its `lateral_m` is within the tolerance, looking only that far (a point that an earlier
    /// snap put on a lane centre is found in the cell it is in).
    pub fn lane_centre_at(&self, pos: Point, tolerance_m: f64) -> Option<LaneId> {
        let radius_m = tolerance_m.min(self.snap_radius_m);
        let (lane, s) = self.nearest_segment(pos, &SnapHint::default(), radius_m, true)?;
        // The lateral offset `snap_within` would give, without the rest of the lane position.
        let lateral_m = self.lanes[lane.0 as usize].path.project_on(pos, s as usize).lateral;
        (lateral_m.abs() < tolerance_m).then_some(lane)
    }

    /// [`RoadNetwork::snap`] among the lanes within `radius_m` (at most the snap radius).
    fn snap_within(&self, pos: Point, hint: &SnapHint, radius_m: f64) -> Option<LanePosition> {
        self.snap_search(pos, hint, radius_m, true)
    }

    /// [`RoadNetwork::snap_within`], searching the grid only as far as the previous lane's cost
    /// when `bounded` (the same answer: the tests hold the two to it).
    fn snap_search(&self, pos: Point, hint: &SnapHint, radius_m: f64, bounded: bool) -> Option<LanePosition> {
        let (lane_id, s) = self.nearest_segment(pos, hint, radius_m, bounded)?;
        let lane = &self.lanes[lane_id.0 as usize];
        let projection = lane.path.project_on(pos, s as usize);
        let mut position = self.lane_position(lane_id, projection.offset);
        position.point = projection.point;
        position.lateral_m = projection.lateral;
        Some(position)
    }

    /// The lane and segment [`RoadNetwork::snap_search`] snaps to.
    fn nearest_segment(
        &self,
        pos: Point,
        hint: &SnapHint,
        radius_m: f64,
        bounded: bool,
    ) -> Option<(LaneId, u32)> {
        let radius_m = radius_m.min(self.snap_radius_m);
        let mut best: Option<(f64, LaneId, u32)> = None;
        let wanted = hint.heading.filter(|h| h.is_finite()).map(geom::unit);
        let continuity = hint.previous.and_then(|p| {
            self.continuations.get(p.0 as usize).map(|c| c.get_or_init(|| self.continuation(p)))
        });
        let cost = |segment: &LaneSegment, d: f64| {
            let heading_penalty = match wanted {
                // (1 - cos(heading difference)) / 2: 0 when aligned, 1 when opposite.
                Some(u) => HEADING_PENALTY_M * (1.0 - geom::dot(u, segment.direction)) / 2.0,
                None => 0.0,
            };
            d + heading_penalty + continuity.map_or(0.0, |c| c.penalty(self, segment.lane))
        };
        // The lane the object was on is usually where it still is: the least cost among its
        // segments bounds the answer's cost, and so its distance, so the
        // grid is searched only that far (plus a margin far above rounding), in the fine grid
        // when that is short. The segments left out are too far to be chosen, and the choice
        // among the others does not depend on the order they come in (least cost, then least
        // lane and segment), so the answer is the full search's (a property test holds them to
        // it).
        let search_m = hint
            .previous
            .filter(|_| bounded)
            .and_then(|p| self.bound_along(p, pos, radius_m, &cost))
            .map_or(radius_m, |bound| (bound + SNAP_BOUND_MARGIN_M).min(radius_m));
        let grid =
            if bounded && search_m <= FINE_GRID_CELL_M { &self.fine_lane_grid } else { &self.lane_grid };
        grid.for_each_near(pos, search_m, |item| {
            let segment = &self.lane_segments[item as usize];
            // Penalties are never negative, so a segment already further than the best is out.
            let limit = best.map_or(radius_m, |(cost, _, _)| (cost + 1e-12).min(radius_m));
            // First on the squared distance, which needs no `hypot`: the margin is far above
            // their rounding, so only segments the exact distance rules out are skipped here.
            if dist2_to_segment(pos, segment.a, segment.b) > limit * limit * (1.0 + 1e-9) + 1e-300 {
                return;
            }
            let d = dist_to_segment(pos, segment.a, segment.b);
            if d > radius_m || best.is_some_and(|(cost, _, _)| d > cost + 1e-12) {
                return;
            }
            let candidate = (cost(segment, d), segment.lane, segment.segment);
            let better = match best {
                None => true,
                Some(current) => {
                    candidate.0 < current.0 - 1e-12
                        || (candidate.0 <= current.0 + 1e-12
                            && (candidate.1, candidate.2) < (current.1, current.2))
                }
            };
            if better {
                best = Some(candidate);
            }
        });
        best.map(|(_, lane, s)| (lane, s))
    }

    /// The least snapping cost (by `cost`) among the segments of `lane` within `radius_m` of
    /// `pos`; `None` when none is that near.
    fn bound_along(
        &self,
        lane: LaneId,
        pos: Point,
        radius_m: f64,
        cost: &impl Fn(&LaneSegment, f64) -> f64,
    ) -> Option<f64> {
        let start = *self.lane_segment_start.get(lane.0 as usize)? as usize;
        let end = *self.lane_segment_start.get(lane.0 as usize + 1)? as usize;
        let mut bound: Option<f64> = None;
        for segment in &self.lane_segments[start..end] {
            let d = dist_to_segment(pos, segment.a, segment.b);
            if d <= radius_m {
                let c = cost(segment, d);
                bound = Some(bound.map_or(c, |b| b.min(c)));
            }
        }
        bound
    }

    /// The lanes that continue `lane`: itself, and its successors and predecessors up to three
    /// lanes away (a road lane, a connector or two, the next road lane), U-turns excepted.
    fn continuation(&self, lane: LaneId) -> Continuation {
        let mut lanes = vec![lane];
        for forward in [true, false] {
            let mut frontier = vec![lane];
            for _ in 0..3 {
                let mut next = Vec::new();
                for l in frontier {
                    let l = &self.lanes[l.0 as usize];
                    let neighbours = if forward { &l.successors } else { &l.predecessors };
                    for &n in neighbours {
                        // A U-turn does not continue a lane: it would make the oncoming lane one.
                        if !self.lanes[n.0 as usize].turnaround && !lanes.contains(&n) {
                            lanes.push(n);
                            next.push(n);
                        }
                    }
                }
                frontier = next;
            }
        }
        let sides = lanes.iter().filter_map(|&l| self.direction_of(l)).collect();
        Continuation { lanes, sides }
    }

    /// The position at `offset_m` along a lane (clamped to the lane), on its centre line.
    pub fn lane_position(&self, lane_id: LaneId, offset_m: f64) -> LanePosition {
        let lane = &self.lanes[lane_id.0 as usize];
        let offset_m = if offset_m.is_nan() { 0.0 } else { offset_m.clamp(0.0, lane.path.length()) };
        LanePosition {
            lane: lane_id,
            place: self.place_of(lane_id),
            offset_m,
            lateral_m: 0.0,
            point: lane.path.point_at(offset_m),
            heading: lane.path.heading_at(offset_m),
        }
    }

    pub fn place_of(&self, lane_id: LaneId) -> Place {
        match self.lanes[lane_id.0 as usize].kind {
            LaneKind::Road { road, index } => Place::Road { road, lane: index },
            LaneKind::Connector { node, .. } => Place::Crossing { node },
        }
    }

    /// A road-lane position drawn uniformly over the length of all road lanes, from `u` in [0, 1).
    pub fn road_lane_position_at_fraction(&self, u: f64) -> Option<LanePosition> {
        let total = self.road_lane_length_m();
        let target = u.clamp(0.0, 1.0) * total;
        let i = self.road_lane_cumulative.partition_point(|&(c, _)| c <= target);
        let &(end, lane) =
            self.road_lane_cumulative.get(i.min(self.road_lane_cumulative.len().checked_sub(1)?))?;
        let length = self.lanes[lane.0 as usize].path.length();
        Some(self.lane_position(lane, target - (end - length)))
    }

    /// A short human-readable name of a place (`road main lane 1`, `crossing c`).
    pub fn describe(&self, place: Place) -> String {
        match place {
            Place::Road { road, lane } => format!("road {} lane {lane}", self.roads[road.0 as usize].name),
            Place::Crossing { node } => format!("crossing {}", self.nodes[node.0 as usize].name),
        }
    }
}

/// The lanes that continue a previous lane, and the road sides (road, direction) they are on.
#[derive(Debug, Clone)]
struct Continuation {
    lanes: Vec<LaneId>,
    sides: Vec<(RoadId, LaneDirection)>,
}

impl Continuation {
    fn penalty(&self, net: &RoadNetwork, lane: LaneId) -> f64 {
        if self.lanes.contains(&lane) {
            0.0
        } else if net.direction_of(lane).is_some_and(|side| self.sides.contains(&side)) {
            LANE_CHANGE_PENALTY_M
        } else {
            DISCONTINUITY_PENALTY_M
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "tests")]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::sync::LazyLock;

    /// The grid town of `kpl bench anchor`, the bridge, and SUMO networks of the shipped specs
    /// (a grid with traffic lights, and the spider's curved roads and many-armed junctions).
    static NETWORKS: LazyLock<Vec<RoadNetwork>> = LazyLock::new(|| {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic/sumo");
        let town = crate::scenarios::GridTownSize { blocks_x: 3, blocks_y: 3, block_m: 100.0 };
        vec![
            RoadNetwork::build(&crate::scenarios::grid_town(town)).unwrap(),
            RoadNetwork::build(&crate::scenarios::bridge()).unwrap(),
            RoadNetwork::load(&root.join("tls_grid/net.xml.gz")).unwrap(),
            RoadNetwork::load(&root.join("spider/net.xml.gz")).unwrap(),
        ]
    });

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]

        /// Snapping bounded by the previous lane's cost gives exactly what the full search of the
        /// grid gives, for points anywhere near the network, any heading and any previous lane
        /// (the lane a nearby point snaps to, as an object moving on; or any lane at all).
        #[test]
        fn bounded_snapping_is_the_full_search(
            which in 0..4usize,
            u in (0.0..1.0f64, 0.0..1.0f64),
            near_lane in (proptest::bool::weighted(0.8), 0..100_000usize, 0.0..1.0f64),
            step in (-8.0..8.0f64, -8.0..8.0f64),
            heading in proptest::option::of(-4.0..4.0f64),
            any_lane in proptest::option::of(0..100_000u32),
            radius in prop_oneof![Just(None), (0.01..12.0f64).prop_map(Some)],
        ) {
            let net = &NETWORKS[which];
            // Near a lane (most objects are), or anywhere in the network's bounds.
            let p = if near_lane.0 {
                let lane = &net.lanes()[near_lane.1 % net.lanes().len()];
                let on = lane.path.point_at(u.0 * lane.path.length());
                [on[0] + (u.1 - 0.5) * 8.0, on[1] + (near_lane.2 - 0.5) * 8.0]
            } else {
                let (lo, hi) = net.bounds();
                [lo[0] + u.0 * (hi[0] - lo[0]), lo[1] + u.1 * (hi[1] - lo[1])]
            };
            let before = [p[0] - step.0, p[1] - step.1];
            let previous = match any_lane {
                Some(i) => Some(LaneId(i % net.lanes().len() as u32)),
                None => net.snap(before, &SnapHint { heading, previous: None }).map(|s| s.lane),
            };
            let hint = SnapHint { heading, previous };
            let radius = radius.unwrap_or(net.snap_radius_m());
            let bounded = net.snap_search(p, &hint, radius, true);
            let full = net.snap_search(p, &hint, radius, false);
            prop_assert_eq!(bounded, full);
            // The lane-centre lookup is the full snap without a hint, within the tolerance.
            for (at, tolerance) in [(p, radius), (full.map_or(p, |s| s.point), 0.05)] {
                let by_snap = net
                    .snap_search(at, &SnapHint::default(), tolerance.min(net.snap_radius_m()), false)
                    .and_then(|s| (s.lateral_m.abs() < tolerance).then_some(s.lane));
                prop_assert_eq!(net.lane_centre_at(at, tolerance), by_snap);
            }
            // And on the lane's centre, where the next step starts from.
            if let Some(s) = full {
                let hint = SnapHint { heading, previous: Some(s.lane) };
                prop_assert_eq!(net.snap_search(s.point, &hint, radius, true), net.snap_search(s.point, &hint, radius, false));
            }
        }
    }
}
