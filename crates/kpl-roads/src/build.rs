//! Building a network from the project's JSON form ([`NetworkFile`]): checks the whole file
//! (reporting every problem at once), then derives what the file leaves implicit: the lanes of
//! each road (its centre line shifted sideways, cut back at the crossings), the connector lanes
//! inside crossings (one per incoming lane and other road end, no U-turns), the crossing areas
//! and the occluder areas.

use std::collections::HashMap;

use crate::error::{NetworkError, NetworkProblem};
use crate::format::{FORMAT_NAME, FORMAT_VERSION, LaneDirection, NetworkFile, OccluderSpec};
use crate::geom::{self, Point, Polyline, connector_curve, convex_hull, heading_difference};
use crate::network::{
    Lane, LaneId, LaneKind, Node, NodeId, NodeKind, Parts, Road, RoadId, RoadLane, Source, TURN_LATERAL_ACCEL,
};
use crate::occluders::{Occluder, OccluderId};

/// Extra width of a crossing's radius beyond the widest half road meeting there.
const CROSSING_MARGIN_M: f64 = 1.5;
/// Shortest stretch of road lane allowed between two crossings.
const MIN_LANE_LENGTH_M: f64 = 1.0;
/// Largest coordinate accepted, in metres (keeps grids and arithmetic sane).
pub(crate) const MAX_COORDINATE_M: f64 = 1.0e7;

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

    fn finish(&mut self) -> Result<(), NetworkError> {
        if self.problems.is_empty() {
            Ok(())
        } else {
            Err(NetworkError::Invalid(std::mem::take(&mut self.problems)))
        }
    }
}

/// Checks a network file and derives its lanes, connectors, crossing areas and occluders.
pub(crate) fn parts_of(file: &NetworkFile) -> Result<Parts, NetworkError> {
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
            check.number("node", &spec.id, "radius_m", r, (0.0..=500.0).contains(&r), "between 0 and 500 m");
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
        check.number("road", &spec.id, "speed_limit_mps", v, v > 0.0 && v <= 100.0, "between 0 and 100 m/s");
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
    check.finish()?;
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
                junction_type: None,
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
                name: format!("{}_{index}", spec.id),
                kind: LaneKind::Road { road: id, index: index as u32 },
                path,
                width_m: lane_spec.width_m,
                speed_limit_mps: spec.speed_limit_mps,
                successors: Vec::new(),
                predecessors: Vec::new(),
                turnaround: false,
                may_change_left: !lane_spec.solid_left,
                may_change_right: !lane_spec.solid_right,
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
        });
    }
    check.finish()?;

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
                    let k = lanes.len() - first_connector;
                    connect(&mut lanes, node, k, from_lane, to_lane);
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
        let road_id = |name: &str, check: &mut Checker| match road_index.get(name) {
            Some(&id) => Some(id),
            None => {
                check
                    .problems
                    .push(NetworkProblem::UnknownRoad { occluder: spec.id.clone(), road: name.to_string() });
                None
            }
        };
        if let Some(occluder) = occluder_of(spec, &roads, &mut check, road_id) {
            occluders.push(occluder);
        }
    }
    check.finish()?;

    Ok(Parts {
        nodes,
        roads,
        lanes,
        occluders,
        snap_radius_m: file.snap_radius_m,
        source: Source::Json(file.clone()),
        location: None,
        roundabouts: Vec::new(),
    })
}

/// The occluder an occluder spec describes, its roads looked up by `road_id`.
pub(crate) fn occluder_of<C>(
    spec: &OccluderSpec,
    roads: &[Road],
    check: &mut C,
    mut road_id: impl FnMut(&str, &mut C) -> Option<RoadId>,
) -> Option<Occluder>
where
    C: ProblemSink,
{
    let occluder = |area: Vec<Point>, roads: Vec<RoadId>| Occluder {
        id: OccluderId(0),
        name: spec.id.clone(),
        kind: spec.kind,
        area,
        roads,
    };
    match (&spec.polygon, &spec.road, spec.from_m, spec.to_m) {
        (Some(polygon), None, None, None) if polygon.len() >= 3 => {
            let mut ok = true;
            for p in polygon {
                for c in p {
                    if !(c.is_finite() && c.abs() <= MAX_COORDINATE_M) {
                        check.problem(NetworkProblem::BadNumber {
                            what: "occluder",
                            id: spec.id.clone(),
                            field: "polygon",
                            expected: "a coordinate within 10,000 km",
                            found: *c,
                        });
                        ok = false;
                    }
                }
            }
            let hidden_roads: Vec<RoadId> =
                spec.roads.iter().filter_map(|name| road_id(name, check)).collect();
            (ok && hidden_roads.len() == spec.roads.len()).then(|| occluder(polygon.clone(), hidden_roads))
        }
        (None, Some(road_name), Some(from_m), Some(to_m)) if spec.roads.is_empty() => {
            let id = road_id(road_name, check)?;
            let road = &roads[id.0 as usize];
            let length = road.centerline.length();
            let valid =
                from_m.is_finite() && to_m.is_finite() && 0.0 <= from_m && from_m < to_m && to_m <= length;
            let Some(stretch) = valid.then(|| road.centerline.slice(from_m, to_m)).flatten() else {
                check.problem(NetworkProblem::OccluderOutsideRoad {
                    occluder: spec.id.clone(),
                    road: road_name.clone(),
                    from_m,
                    to_m,
                    length,
                });
                return None;
            };
            let half = road.width_m / 2.0 + 0.5;
            let mut area: Vec<Point> = stretch.offset(half).map(|l| l.points().to_vec()).unwrap_or_default();
            let right: Vec<Point> = stretch.offset(-half).map(|l| l.points().to_vec()).unwrap_or_default();
            area.extend(right.into_iter().rev());
            Some(occluder(area, vec![id]))
        }
        _ => {
            check.problem(NetworkProblem::OccluderShape { occluder: spec.id.clone() });
            None
        }
    }
}

/// Where problems found while reading go.
pub(crate) trait ProblemSink {
    fn problem(&mut self, problem: NetworkProblem);
}

impl ProblemSink for Checker {
    fn problem(&mut self, problem: NetworkProblem) {
        self.problems.push(problem);
    }
}

impl ProblemSink for Vec<NetworkProblem> {
    fn problem(&mut self, problem: NetworkProblem) {
        self.push(problem);
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

/// Joins `from` to `to` through the `k`-th connector curve inside the crossing at `node`.
fn connect(lanes: &mut Vec<Lane>, node: &Node, k: usize, from: LaneId, to: LaneId) {
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
        name: format!(":{}_{k}", node.name),
        kind: LaneKind::Connector { node: node.id, from, to },
        path,
        width_m: width,
        speed_limit_mps,
        successors: vec![to],
        predecessors: vec![from],
        turnaround: false,
        may_change_left: true,
        may_change_right: true,
    });
    lanes[from.0 as usize].successors.push(id);
    lanes[to.0 as usize].predecessors.push(id);
}
