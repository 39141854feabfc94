//! The road network: roads with lanes, nodes (crossings, joints, map boundaries), turn connectors
//! inside crossings, occluders (bridges, tunnels), and the geometry queries that anchoring and
//! formulas use (`on_road`, `snap_to_lane`, `occluder_at`), answered through spatial grids.
//!
//! Lanes form a directed graph. Every road lane is a path along its road, shifted sideways to the
//! lane's centre and cut back at both ends by the radius of the crossing there; inside a crossing,
//! a connector lane (a smooth curve) joins each incoming lane to one outgoing lane of every other
//! road at that node. So "which branch does a car take" is "which successor lane", and prediction
//! along the network ([`crate::predict`]) walks this graph.
//!
//! ```
//! use kpl_sim::{RoadNetwork, scenarios};
//! let net = RoadNetwork::build(&scenarios::crossing()).unwrap();
//! assert!(net.on_road([0.0, 0.0]));          // the middle of the crossing
//! assert!(!net.on_road([30.0, 30.0]));       // a field beside it
//! let snapped = net.snap_to_lane([-50.0, -1.0], Some(0.0)).unwrap(); // eastbound, south of the axis
//! assert!((snapped.point[1] + 1.75).abs() < 1e-9);                   // the eastbound lane centre
//! ```

use std::collections::HashMap;
use std::path::Path;

use crate::error::{NetworkError, NetworkProblem};
use crate::format::{FORMAT_NAME, FORMAT_VERSION, LaneDirection, NetworkFile, OccluderKind};
use crate::geom::{
    self, Point, Polyline, bounds_of, connector_curve, convex_hull, dist_to_segment, heading_difference,
    point_in_polygon,
};
use crate::index::{Grid, GridBuilder};

/// Index of a road in [`RoadNetwork::roads`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct RoadId(pub u32);
/// Index of a node in [`RoadNetwork::nodes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct NodeId(pub u32);
/// Index of a lane (a road lane or a connector) in [`RoadNetwork::lanes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct LaneId(pub u32);
/// Index of an occluder in [`RoadNetwork::occluders`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct OccluderId(pub u32);

/// Extra width of a crossing's radius beyond the widest half road meeting there.
const CROSSING_MARGIN_M: f64 = 1.5;
/// Shortest stretch of road lane allowed between two crossings.
const MIN_LANE_LENGTH_M: f64 = 1.0;
/// What a lane heading opposite to the given one adds to the snapping cost, in metres.
const HEADING_PENALTY_M: f64 = 10.0;
/// Largest coordinate accepted, in metres (keeps grids and arithmetic sane).
const MAX_COORDINATE_M: f64 = 1.0e7;
/// Lateral acceleration cars accept in turns; gives connector speed limits.
const TURN_LATERAL_ACCEL: f64 = 2.5;
/// Side of a spatial-grid cell.
const GRID_CELL_M: f64 = 15.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NodeKind {
    /// One road end: the edge of the map, where cars enter and leave.
    Boundary,
    /// Two road ends: a bend or a change of road.
    Joint,
    /// Three or more road ends.
    Crossing,
}

#[derive(Debug, Clone)]
pub struct Node {
    pub id: NodeId,
    pub name: String,
    pub pos: Point,
    pub kind: NodeKind,
    /// Where roads stop and connectors start, measured from `pos` along each road.
    pub radius_m: f64,
    pub roads: Vec<RoadId>,
    /// The crossing's area as a convex polygon (empty at a boundary node).
    pub area: Vec<Point>,
}

#[derive(Debug, Clone)]
pub struct Road {
    pub id: RoadId,
    pub name: String,
    pub from: NodeId,
    pub to: NodeId,
    /// From the `from` node's position to the `to` node's.
    pub centerline: Polyline,
    /// Left to right looking from `from` to `to`.
    pub lanes: Vec<RoadLane>,
    pub width_m: f64,
    pub speed_limit_mps: f64,
    pub level: i32,
    pub occluders: Vec<OccluderId>,
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
    /// A turn or straight connection inside a crossing from one road lane to another.
    Connector { node: NodeId, from: LaneId, to: LaneId },
}

/// A drivable path in its direction of travel.
#[derive(Debug, Clone)]
pub struct Lane {
    pub id: LaneId,
    pub kind: LaneKind,
    pub path: Polyline,
    pub width_m: f64,
    pub speed_limit_mps: f64,
    pub successors: Vec<LaneId>,
    pub predecessors: Vec<LaneId>,
}

#[derive(Debug, Clone)]
pub struct Occluder {
    pub id: OccluderId,
    pub name: String,
    pub kind: OccluderKind,
    pub road: RoadId,
    pub from_m: f64,
    pub to_m: f64,
    /// The hidden stretch of road as a polygon (the road's width plus half a metre each side).
    pub area: Vec<Point>,
}

/// Where on the network something is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// On lane `lane` (left to right) of `road`.
    Road { road: RoadId, lane: u32 },
    /// Inside the crossing at `node`.
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
    /// The road, when not inside a crossing.
    pub fn road(&self) -> Option<RoadId> {
        match self.place {
            Place::Road { road, .. } => Some(road),
            Place::Crossing { .. } => None,
        }
    }
}

/// A checked road network with its derived lanes and spatial indexes. Immutable once built.
#[derive(Debug, Clone)]
pub struct RoadNetwork {
    file: NetworkFile,
    nodes: Vec<Node>,
    roads: Vec<Road>,
    lanes: Vec<Lane>,
    occluders: Vec<Occluder>,
    bounds: (Point, Point),
    snap_radius_m: f64,
    /// `(road, segment)` per item of `road_grid`.
    road_segments: Vec<(RoadId, u32)>,
    road_grid: Grid,
    crossing_grid: Grid,
    /// `(lane, segment)` per item of `lane_grid`.
    lane_segments: Vec<LaneSegment>,
    lane_grid: Grid,
    max_half_lane_width_m: f64,
    occluder_grid: Grid,
    /// Road lanes that start at a map boundary.
    entry_lanes: Vec<LaneId>,
    /// Road lanes and the running total of their lengths, for sampling positions uniformly.
    road_lane_cumulative: Vec<(f64, LaneId)>,
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

/// Which end of a road meets a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RoadEnd {
    Start,
    End,
}

struct Checker {
    problems: Vec<NetworkProblem>,
}

impl Checker {
    fn number(
        &mut self,
        what: &'static str,
        id: &str,
        field: &'static str,
        value: f64,
        ok: bool,
        expected: &'static str,
    ) {
        if !ok || !value.is_finite() {
            self.problems.push(NetworkProblem::BadNumber {
                what,
                id: id.to_string(),
                field,
                expected,
                found: value,
            });
        }
    }

    fn point(&mut self, what: &'static str, id: &str, field: &'static str, p: Point) {
        for c in p {
            self.number(what, id, field, c, c.abs() <= MAX_COORDINATE_M, "a coordinate within 10,000 km");
        }
    }
}

impl RoadNetwork {
    /// Reads and builds a network from a JSON file.
    pub fn load(path: &Path) -> Result<RoadNetwork, NetworkError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| NetworkError::Read { path: path.to_path_buf(), source })?;
        RoadNetwork::from_json_str(&text)
    }

    /// Writes the network's file form as pretty JSON.
    pub fn save(&self, path: &Path) -> Result<(), NetworkError> {
        std::fs::write(path, self.to_json_string())
            .map_err(|source| NetworkError::Write { path: path.to_path_buf(), source })
    }

    pub fn from_json_str(text: &str) -> Result<RoadNetwork, NetworkError> {
        let file: NetworkFile = serde_json::from_str(text)?;
        RoadNetwork::build(&file)
    }

    pub fn to_json_string(&self) -> String {
        // Serialising plain structs of strings and finite numbers cannot fail.
        serde_json::to_string_pretty(&self.file).unwrap_or_default()
    }

    /// The file this network was built from.
    pub fn file(&self) -> &NetworkFile {
        &self.file
    }

    /// Checks a network file (reporting every problem found) and derives lanes, connectors,
    /// crossing areas, occluder areas and the spatial indexes.
    pub fn build(file: &NetworkFile) -> Result<RoadNetwork, NetworkError> {
        let mut check = Checker { problems: Vec::new() };
        if file.format != FORMAT_NAME {
            check.problems.push(NetworkProblem::WrongFormat { found: file.format.clone() });
        }
        if file.version != FORMAT_VERSION {
            check.problems.push(NetworkProblem::UnsupportedVersion { found: file.version });
        }
        check.number(
            "network",
            "",
            "snap_radius_m",
            file.snap_radius_m,
            file.snap_radius_m > 0.0 && file.snap_radius_m <= 1000.0,
            "between 0 and 1000 m",
        );
        if file.roads.is_empty() {
            check.problems.push(NetworkProblem::Empty);
        }

        let mut node_index: HashMap<&str, NodeId> = HashMap::new();
        for (i, spec) in file.nodes.iter().enumerate() {
            if node_index.insert(&spec.id, NodeId(i as u32)).is_some() {
                check.problems.push(NetworkProblem::DuplicateId { what: "node", id: spec.id.clone() });
            }
            check.point("node", &spec.id, "pos", spec.pos);
            if let Some(r) = spec.radius_m {
                check.number(
                    "node",
                    &spec.id,
                    "radius_m",
                    r,
                    (0.0..=500.0).contains(&r),
                    "between 0 and 500 m",
                );
            }
        }

        let mut road_index: HashMap<&str, RoadId> = HashMap::new();
        let mut centerlines: Vec<Option<Polyline>> = Vec::with_capacity(file.roads.len());
        let mut ends: Vec<(NodeId, NodeId)> = Vec::with_capacity(file.roads.len());
        for (i, spec) in file.roads.iter().enumerate() {
            if road_index.insert(&spec.id, RoadId(i as u32)).is_some() {
                check.problems.push(NetworkProblem::DuplicateId { what: "road", id: spec.id.clone() });
            }
            if spec.lanes.is_empty() {
                check.problems.push(NetworkProblem::NoLanes { road: spec.id.clone() });
            }
            for lane in &spec.lanes {
                let w = lane.width_m;
                check.number("road", &spec.id, "lane width_m", w, w > 0.0 && w <= 50.0, "between 0 and 50 m");
            }
            let v = spec.speed_limit_mps;
            check.number(
                "road",
                &spec.id,
                "speed_limit_mps",
                v,
                v > 0.0 && v <= 100.0,
                "between 0 and 100 m/s",
            );
            for &p in &spec.via {
                check.point("road", &spec.id, "via", p);
            }
            let mut endpoint = |name: &String| match node_index.get(name.as_str()) {
                Some(&id) => Some(id),
                None => {
                    check
                        .problems
                        .push(NetworkProblem::UnknownNode { road: spec.id.clone(), node: name.clone() });
                    None
                }
            };
            let (from, to) = (endpoint(&spec.from), endpoint(&spec.to));
            let (Some(from), Some(to)) = (from, to) else {
                centerlines.push(None);
                ends.push((NodeId(0), NodeId(0)));
                continue;
            };
            let mut points = vec![file.nodes[from.0 as usize].pos];
            points.extend_from_slice(&spec.via);
            points.push(file.nodes[to.0 as usize].pos);
            let line = Polyline::new(points);
            if line.is_none() {
                check.problems.push(NetworkProblem::ZeroLength { road: spec.id.clone() });
            }
            centerlines.push(line);
            ends.push((from, to));
        }
        if !check.problems.is_empty() {
            return Err(NetworkError::Invalid(check.problems));
        }
        // From here on every road has a centre line and known end nodes.
        let centerlines: Vec<Polyline> = centerlines.into_iter().flatten().collect();

        // Nodes: incident road ends, kind and radius.
        let mut node_ends: Vec<Vec<(RoadId, RoadEnd)>> = vec![Vec::new(); file.nodes.len()];
        for (i, &(from, to)) in ends.iter().enumerate() {
            node_ends[from.0 as usize].push((RoadId(i as u32), RoadEnd::Start));
            node_ends[to.0 as usize].push((RoadId(i as u32), RoadEnd::End));
        }
        let half_width = |road: RoadId| -> f64 {
            file.roads[road.0 as usize].lanes.iter().map(|l| l.width_m).sum::<f64>() / 2.0
        };
        let mut nodes: Vec<Node> = file
            .nodes
            .iter()
            .enumerate()
            .map(|(i, spec)| {
                let incident = &node_ends[i];
                let kind = match incident.len() {
                    0 | 1 => NodeKind::Boundary,
                    2 => NodeKind::Joint,
                    _ => NodeKind::Crossing,
                };
                let radius_m = if kind == NodeKind::Boundary {
                    0.0
                } else {
                    spec.radius_m.unwrap_or_else(|| {
                        incident.iter().map(|&(r, _)| half_width(r)).fold(0.0, f64::max) + CROSSING_MARGIN_M
                    })
                };
                let mut roads: Vec<RoadId> = incident.iter().map(|&(r, _)| r).collect();
                roads.dedup();
                Node {
                    id: NodeId(i as u32),
                    name: spec.id.clone(),
                    pos: spec.pos,
                    kind,
                    radius_m,
                    roads,
                    area: Vec::new(),
                }
            })
            .collect();

        // Roads and their lanes.
        let mut roads: Vec<Road> = Vec::with_capacity(file.roads.len());
        let mut lanes: Vec<Lane> = Vec::new();
        for (i, spec) in file.roads.iter().enumerate() {
            let id = RoadId(i as u32);
            let (from, to) = ends[i];
            let centerline = centerlines[i].clone();
            let trim_start = nodes[from.0 as usize].radius_m;
            let trim_end = nodes[to.0 as usize].radius_m;
            let length = centerline.length();
            let Some(trimmed) =
                centerline.slice(trim_start, length - trim_end).filter(|t| t.length() >= MIN_LANE_LENGTH_M)
            else {
                check.problems.push(NetworkProblem::TooShort {
                    road: spec.id.clone(),
                    length,
                    trim: trim_start + trim_end,
                });
                continue;
            };
            let width_m: f64 = spec.lanes.iter().map(|l| l.width_m).sum();
            let mut left_edge = width_m / 2.0;
            let mut road_lanes = Vec::with_capacity(spec.lanes.len());
            for (index, lane_spec) in spec.lanes.iter().enumerate() {
                let lateral_m = left_edge - lane_spec.width_m / 2.0;
                left_edge -= lane_spec.width_m;
                let shifted = trimmed.offset(lateral_m);
                let path = match (shifted, lane_spec.direction) {
                    (Some(p), LaneDirection::Forward) => p,
                    (Some(p), LaneDirection::Backward) => p.reversed(),
                    (None, _) => {
                        check.problems.push(NetworkProblem::ZeroLength { road: spec.id.clone() });
                        continue;
                    }
                };
                let lane_id = LaneId(lanes.len() as u32);
                lanes.push(Lane {
                    id: lane_id,
                    kind: LaneKind::Road { road: id, index: index as u32 },
                    path,
                    width_m: lane_spec.width_m,
                    speed_limit_mps: spec.speed_limit_mps,
                    successors: Vec::new(),
                    predecessors: Vec::new(),
                });
                road_lanes.push(RoadLane {
                    width_m: lane_spec.width_m,
                    direction: lane_spec.direction,
                    lateral_m,
                    lane: lane_id,
                });
            }
            roads.push(Road {
                id,
                name: spec.id.clone(),
                from,
                to,
                centerline,
                lanes: road_lanes,
                width_m,
                speed_limit_mps: spec.speed_limit_mps,
                level: spec.level,
                occluders: Vec::new(),
            });
        }
        if !check.problems.is_empty() {
            return Err(NetworkError::Invalid(check.problems));
        }

        // Connectors and crossing areas.
        for node in &mut nodes {
            if node.kind == NodeKind::Boundary {
                continue;
            }
            let incident = &node_ends[node.id.0 as usize];
            let mut area_points = Vec::new();
            for &(road_id, end) in incident {
                let road = &roads[road_id.0 as usize];
                let along = match end {
                    RoadEnd::Start => node.radius_m,
                    RoadEnd::End => road.centerline.length() - node.radius_m,
                };
                let centre = road.centerline.point_at(along);
                let normal = geom::left_normal(geom::unit(road.centerline.heading_at(along)));
                area_points.push(geom::add(centre, geom::scale(normal, road.width_m / 2.0)));
                area_points.push(geom::sub(centre, geom::scale(normal, road.width_m / 2.0)));
            }
            let first_connector = lanes.len();
            for &(in_road, in_end) in incident {
                let incoming = ranked_lanes(&roads[in_road.0 as usize], in_end, true);
                for &(out_road, out_end) in incident {
                    if (out_road, out_end) == (in_road, in_end) {
                        continue; // no U-turns
                    }
                    let outgoing = ranked_lanes(&roads[out_road.0 as usize], out_end, false);
                    if outgoing.is_empty() {
                        continue;
                    }
                    for (rank, &from_lane) in incoming.iter().enumerate() {
                        let to_lane = outgoing[rank.min(outgoing.len() - 1)];
                        connect(&mut lanes, node.id, from_lane, to_lane);
                    }
                }
            }
            // The area covers the road ends and every connector, so that turning cars (and points
            // snapped to connectors) are on the road even where roads meet at sharp angles.
            for lane in &lanes[first_connector..] {
                area_points.extend_from_slice(lane.path.points());
            }
            node.area = convex_hull(&area_points);
        }

        // Occluders.
        let mut occluders = Vec::with_capacity(file.occluders.len());
        let mut occluder_names: HashMap<&str, ()> = HashMap::new();
        for spec in &file.occluders {
            if occluder_names.insert(&spec.id, ()).is_some() {
                check.problems.push(NetworkProblem::DuplicateId { what: "occluder", id: spec.id.clone() });
            }
            let Some(&road_id) = road_index.get(spec.road.as_str()) else {
                check
                    .problems
                    .push(NetworkProblem::UnknownRoad { occluder: spec.id.clone(), road: spec.road.clone() });
                continue;
            };
            let road = &mut roads[road_id.0 as usize];
            let length = road.centerline.length();
            let valid = spec.from_m.is_finite()
                && spec.to_m.is_finite()
                && 0.0 <= spec.from_m
                && spec.from_m < spec.to_m
                && spec.to_m <= length;
            let stretch = valid.then(|| road.centerline.slice(spec.from_m, spec.to_m)).flatten();
            let Some(stretch) = stretch else {
                check.problems.push(NetworkProblem::OccluderOutsideRoad {
                    occluder: spec.id.clone(),
                    road: spec.road.clone(),
                    from_m: spec.from_m,
                    to_m: spec.to_m,
                    length,
                });
                continue;
            };
            let half = road.width_m / 2.0 + 0.5;
            let mut area: Vec<Point> = stretch.offset(half).map(|l| l.points().to_vec()).unwrap_or_default();
            let right: Vec<Point> = stretch.offset(-half).map(|l| l.points().to_vec()).unwrap_or_default();
            area.extend(right.into_iter().rev());
            let id = OccluderId(occluders.len() as u32);
            road.occluders.push(id);
            occluders.push(Occluder {
                id,
                name: spec.id.clone(),
                kind: spec.kind,
                road: road_id,
                from_m: spec.from_m,
                to_m: spec.to_m,
                area,
            });
        }
        if !check.problems.is_empty() {
            return Err(NetworkError::Invalid(check.problems));
        }

        Ok(RoadNetwork::index(file.clone(), nodes, roads, lanes, occluders))
    }

    fn index(
        file: NetworkFile,
        nodes: Vec<Node>,
        roads: Vec<Road>,
        lanes: Vec<Lane>,
        occluders: Vec<Occluder>,
    ) -> RoadNetwork {
        let mut all_points: Vec<Point> = Vec::new();
        for road in &roads {
            let (lo, hi) = road.centerline.bounds();
            let margin = road.width_m;
            all_points.push([lo[0] - margin, lo[1] - margin]);
            all_points.push([hi[0] + margin, hi[1] + margin]);
        }
        for node in &nodes {
            all_points.extend_from_slice(&node.area);
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
        let mut lane_grid = GridBuilder::new(bounds.0, bounds.1, GRID_CELL_M);
        for lane in &lanes {
            for s in 0..lane.path.n_segments() {
                let (a, b, _) = lane.path.segment(s);
                lane_grid.insert_segment(lane_segments.len() as u32, a, b, 0.0);
                let direction = geom::unit(geom::heading_of(geom::sub(b, a)));
                lane_segments.push(LaneSegment { lane: lane.id, segment: s as u32, a, b, direction });
            }
        }
        let mut occluder_grid = GridBuilder::new(bounds.0, bounds.1, GRID_CELL_M);
        for occluder in &occluders {
            let (lo, hi) = bounds_of(&occluder.area);
            occluder_grid.insert_box(occluder.id.0, lo, hi);
        }
        let entry_lanes = lanes
            .iter()
            .filter(|l| matches!(l.kind, LaneKind::Road { .. }) && l.predecessors.is_empty())
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
        RoadNetwork {
            snap_radius_m: file.snap_radius_m,
            file,
            nodes,
            roads,
            lanes,
            occluders,
            bounds,
            road_segments,
            road_grid: road_grid.build(),
            crossing_grid: crossing_grid.build(),
            lane_segments,
            lane_grid: lane_grid.build(),
            max_half_lane_width_m,
            occluder_grid: occluder_grid.build(),
            entry_lanes,
            road_lane_cumulative,
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

    pub fn occluders(&self) -> &[Occluder] {
        &self.occluders
    }

    // The accessors below take ids handed out by this network and panic on others; use the
    // slices (`nodes()`, `roads()`, `lanes()`, `occluders()`) with `get` for ids of unknown origin.

    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id.0 as usize]
    }

    pub fn road(&self, id: RoadId) -> &Road {
        &self.roads[id.0 as usize]
    }

    pub fn lane(&self, id: LaneId) -> &Lane {
        &self.lanes[id.0 as usize]
    }

    pub fn occluder(&self, id: OccluderId) -> &Occluder {
        &self.occluders[id.0 as usize]
    }

    pub fn road_by_name(&self, name: &str) -> Option<&Road> {
        self.roads.iter().find(|r| r.name == name)
    }

    pub fn node_by_name(&self, name: &str) -> Option<&Node> {
        self.nodes.iter().find(|n| n.name == name)
    }

    /// The bounding box of everything drivable, as `(min, max)`.
    pub fn bounds(&self) -> (Point, Point) {
        self.bounds
    }

    pub fn snap_radius_m(&self) -> f64 {
        self.snap_radius_m
    }

    /// Road lanes starting at a map boundary: where new cars enter.
    pub fn entry_lanes(&self) -> &[LaneId] {
        &self.entry_lanes
    }

    /// Total length of all road lanes (connectors excluded), in metres.
    pub fn road_lane_length_m(&self) -> f64 {
        self.road_lane_cumulative.last().map_or(0.0, |&(total, _)| total)
    }

    /// Whether `pos` is on the paved surface: within half a road's width of its centre line,
    /// inside a crossing, or within half a lane's width of the lane's centre (which only adds
    /// the outside of sharp bends, where mitred lanes reach beyond the round-cornered road band).
    pub fn on_road(&self, pos: Point) -> bool {
        self.road_at(pos).is_some() || self.crossing_at(pos).is_some() || self.on_lane(pos)
    }

    fn on_lane(&self, pos: Point) -> bool {
        let mut found = false;
        self.lane_grid.for_each_near(pos, self.max_half_lane_width_m, |item| {
            let segment = &self.lane_segments[item as usize];
            if !found {
                let half = self.lanes[segment.lane.0 as usize].width_m / 2.0;
                found = dist_to_segment(pos, segment.a, segment.b) <= half + 1e-9;
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
                dist_to_segment(pos, a, b) <= road.width_m / 2.0 + 1e-9
            })
            .map(|(road, _)| road)
            .min()
    }

    /// The crossing (or joint) whose area contains `pos`.
    pub fn crossing_at(&self, pos: Point) -> Option<NodeId> {
        self.crossing_grid
            .at(pos)
            .iter()
            .map(|&n| NodeId(n))
            .find(|&n| point_in_polygon(pos, &self.nodes[n.0 as usize].area))
    }

    /// The occluder whose area contains `pos`, whatever road the point is on.
    pub fn occluder_at(&self, pos: Point) -> Option<OccluderId> {
        self.occluder_grid
            .at(pos)
            .iter()
            .map(|&o| OccluderId(o))
            .find(|&o| point_in_polygon(pos, &self.occluders[o.0 as usize].area))
    }

    /// The occluder hiding `pos` when it is on `road` (a car on a bridge is not hidden by the
    /// bridge over another road).
    pub fn occluder_over(&self, road: RoadId, pos: Point) -> Option<OccluderId> {
        self.roads[road.0 as usize]
            .occluders
            .iter()
            .copied()
            .find(|&o| point_in_polygon(pos, &self.occluders[o.0 as usize].area))
    }

    /// The nearest lane centre within the network's snap radius of `pos`. With a `heading`
    /// (radians), lanes going the other way count as up to 10 m further away, so a car is snapped
    /// to the lane of its own direction and, inside a crossing, to the connector it follows.
    pub fn snap_to_lane(&self, pos: Point, heading: Option<f64>) -> Option<LanePosition> {
        let mut best: Option<(f64, LaneId, u32)> = None;
        let wanted = heading.filter(|h| h.is_finite()).map(geom::unit);
        self.lane_grid.for_each_near(pos, self.snap_radius_m, |item| {
            let segment = &self.lane_segments[item as usize];
            let d = dist_to_segment(pos, segment.a, segment.b);
            // The penalty is never negative, so a segment already further than the best is out.
            if d > self.snap_radius_m || best.is_some_and(|(cost, _, _)| d > cost + 1e-12) {
                return;
            }
            let penalty = match wanted {
                // (1 - cos(heading difference)) / 2: 0 when aligned, 1 when opposite.
                Some(u) => HEADING_PENALTY_M * (1.0 - geom::dot(u, segment.direction)) / 2.0,
                None => 0.0,
            };
            let candidate = (d + penalty, segment.lane, segment.segment);
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
        let (_, lane_id, s) = best?;
        let lane = &self.lanes[lane_id.0 as usize];
        let projection = lane.path.project_on(pos, s as usize);
        let mut position = self.lane_position(lane_id, projection.offset);
        position.point = projection.point;
        position.lateral_m = projection.lateral;
        Some(position)
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

/// The lanes of `road` that arrive at (`incoming`) or leave from its `end`, rightmost first.
fn ranked_lanes(road: &Road, end: RoadEnd, incoming: bool) -> Vec<LaneId> {
    // Forward lanes arrive at the End and leave from the Start; backward lanes the other way.
    let wanted = match (end, incoming) {
        (RoadEnd::End, true) | (RoadEnd::Start, false) => LaneDirection::Forward,
        (RoadEnd::Start, true) | (RoadEnd::End, false) => LaneDirection::Backward,
    };
    let mut picked: Vec<LaneId> =
        road.lanes.iter().filter(|l| l.direction == wanted).map(|l| l.lane).collect();
    // Lanes are listed left to right along the road: for forward traffic the rightmost is last,
    // for backward traffic it is first.
    if wanted == LaneDirection::Forward {
        picked.reverse();
    }
    picked
}

/// Joins `from` to `to` through a connector curve inside the crossing at `node`.
fn connect(lanes: &mut Vec<Lane>, node: NodeId, from: LaneId, to: LaneId) {
    let (p0, h0, width, v_in) = {
        let l = &lanes[from.0 as usize];
        (l.path.end(), l.path.end_heading(), l.width_m, l.speed_limit_mps)
    };
    let (p3, h3, v_out) = {
        let l = &lanes[to.0 as usize];
        (l.path.start(), l.path.start_heading(), l.speed_limit_mps)
    };
    let Some(path) = connector_curve(p0, h0, p3, h3) else {
        // The lanes already meet (a crossing of radius 0): link them directly.
        lanes[from.0 as usize].successors.push(to);
        lanes[to.0 as usize].predecessors.push(from);
        return;
    };
    let turn = heading_difference(h0, h3);
    let chord = geom::dist(p0, p3);
    let mut speed_limit_mps = v_in.min(v_out);
    if turn > 0.1 {
        let radius = chord / (2.0 * (turn / 2.0).sin());
        speed_limit_mps = speed_limit_mps.min((TURN_LATERAL_ACCEL * radius).sqrt().max(2.0));
    }
    let id = LaneId(lanes.len() as u32);
    lanes.push(Lane {
        id,
        kind: LaneKind::Connector { node, from, to },
        path,
        width_m: width,
        speed_limit_mps,
        successors: vec![to],
        predecessors: vec![from],
    });
    lanes[from.0 as usize].successors.push(id);
    lanes[to.0 as usize].predecessors.push(id);
}
