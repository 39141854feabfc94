//! Reading SUMO networks (`.net.xml`) as SUMO's `netconvert` and `netgenerate` write them, into
//! the same model the JSON form builds:
//!
//! - `junction` (except `type="internal"`, SUMO's waiting points inside junctions): a node with its
//!   `x`, `y`, `type` and `shape` (the junction's area); `intLanes` says which internal lanes lie
//!   inside it (every lane `incLanes` and `intLanes` name must be in the file).
//! - `edge` without a `function` (or `function="normal"`): a road from `from` to `to`; its `lane`s
//!   keep their `shape` (each direction of a street is its own edge, on its own side), `width`
//!   (SUMO's default 3.2 m when absent), `speed`, and `allow` / `disallow`: only lanes that
//!   passenger cars may use are kept (sidewalks, bicycle lanes and rails are left out);
//!   `changeLeft` / `changeRight` (the classes that may change to the neighbouring lane) say
//!   whether a car may cross the marking on that side (not: a solid line).
//! - `edge function="internal"`: its lanes are connector lanes inside the junction whose
//!   `intLanes` lists them; edges of other functions (`walkingarea`, `crossing`, `connector`) are
//!   left out.
//! - `connection`: lane `fromLane` of edge `from` continues into the lane `via` (an internal
//!   lane), or directly into lane `toLane` of edge `to`; connections from internal edges chain
//!   internal lanes. `dir="t"` marks a U-turn. These are the allowed turns that prediction follows.
//! - `location` (`netOffset`, `convBoundary`, `origBoundary`, `projParameter`) and `roundabout`
//!   (`nodes`, `edges`) are kept as they are.
//!
//! Everything else (`type`, `tlLogic`, `request`, `param`, `neigh`, `prohibition`, ...) is about
//! driving rules, not geometry, and is skipped. Every problem found is reported at once, with the
//! line of the element.
//!
//! ```
//! let text = r#"<net version="1.20">
//!   <location netOffset="0.00,0.00" convBoundary="0.00,0.00,100.00,0.00" origBoundary="0,0,100,0" projParameter="!"/>
//!   <edge id="ab" from="a" to="b" priority="-1">
//!     <lane id="ab_0" index="0" speed="13.89" length="100.00" shape="0.00,-1.60 100.00,-1.60"/>
//!   </edge>
//!   <junction id="a" type="dead_end" x="0.00" y="0.00" incLanes="" intLanes="" shape="0.00,0.00 0.00,-3.20"/>
//!   <junction id="b" type="dead_end" x="100.00" y="0.00" incLanes="ab_0" intLanes="" shape="100.00,-3.20 100.00,0.00"/>
//! </net>"#;
//! let net = kpl_roads::RoadNetwork::from_sumo_str(text).unwrap();
//! assert!(net.on_road([50.0, -1.0]));
//! assert!(!net.on_road([50.0, 1.0])); // the other side of the street has no edge
//! ```

use std::collections::{HashMap, HashSet};

use quick_xml::Reader;
use quick_xml::events::{BytesStart, Event};

use crate::build::MAX_COORDINATE_M;
use crate::error::{NetworkError, NetworkProblem};
use crate::format::{LaneDirection, OccluderKind};
use crate::geom::{self, Point, Polyline};
use crate::network::{
    Lane, LaneId, LaneKind, Location, Node, NodeId, NodeKind, Parts, Road, RoadId, RoadLane, Roundabout,
    Source,
};
use crate::occluders::{Occluder, OccluderId};

/// SUMO's lane width when a lane has no `width` (`SUMO_const_laneWidth`).
pub const DEFAULT_LANE_WIDTH_M: f64 = 3.2;
/// SUMO's speed limit when a lane has no `speed` (13.89 m/s, 50 km/h).
pub const DEFAULT_SPEED_MPS: f64 = 13.89;
/// How far from a lane centre snapping still snaps on a SUMO network.
pub const SNAP_RADIUS_M: f64 = 10.0;
/// The vehicle class whose lanes are kept.
pub const VEHICLE_CLASS: &str = "passenger";

/// Line numbers of byte offsets.
struct Lines {
    starts: Vec<usize>,
}

impl Lines {
    fn new(text: &str) -> Lines {
        let mut starts = vec![0];
        starts.extend(text.bytes().enumerate().filter(|&(_, b)| b == b'\n').map(|(i, _)| i + 1));
        Lines { starts }
    }

    /// 1-based line and column of a byte offset.
    fn at(&self, offset: usize) -> (usize, usize) {
        let line = self.starts.partition_point(|&s| s <= offset);
        (line, offset - self.starts[line.saturating_sub(1)] + 1)
    }
}

/// An element's attributes as strings, with the line it starts on.
struct Element {
    line: usize,
    attributes: HashMap<String, String>,
}

impl Element {
    fn get(&self, name: &str) -> Option<&str> {
        self.attributes.get(name).map(String::as_str)
    }

    fn id(&self) -> String {
        self.get("id").unwrap_or("").to_string()
    }
}

/// Problems found while reading, with the element they belong to.
struct Problems {
    list: Vec<NetworkProblem>,
}

impl Problems {
    fn missing(&mut self, e: &Element, element: &'static str, attribute: &'static str) {
        self.list.push(NetworkProblem::MissingAttribute { line: e.line, element, id: e.id(), attribute });
    }

    fn bad(&mut self, e: &Element, element: &'static str, attribute: &'static str, expected: &'static str) {
        self.list.push(NetworkProblem::BadAttribute {
            line: e.line,
            element,
            id: e.id(),
            attribute,
            expected,
            found: e.get(attribute).unwrap_or("").chars().take(80).collect(),
        });
    }

    fn unknown(&mut self, e: &Element, element: &'static str, what: &'static str, name: &str) {
        self.list.push(NetworkProblem::UnknownReference {
            line: e.line,
            element,
            id: e.id(),
            what,
            name: name.to_string(),
        });
    }

    /// A required attribute.
    fn text<'e>(
        &mut self,
        e: &'e Element,
        element: &'static str,
        attribute: &'static str,
    ) -> Option<&'e str> {
        let value = e.get(attribute);
        if value.is_none() {
            self.missing(e, element, attribute);
        }
        value
    }

    /// An optional number (`None` when absent or wrong, the latter reported).
    fn number(&mut self, e: &Element, element: &'static str, attribute: &'static str) -> Option<f64> {
        let text = e.get(attribute)?;
        match text.trim().parse::<f64>() {
            Ok(v) if v.is_finite() && v.abs() <= MAX_COORDINATE_M => Some(v),
            _ => {
                self.bad(e, element, attribute, "a number");
                None
            }
        }
    }

    /// An optional shape `x,y[,z] x,y[,z] ...` (z is dropped).
    fn shape(&mut self, e: &Element, element: &'static str, attribute: &'static str) -> Option<Vec<Point>> {
        let text = e.get(attribute)?;
        match parse_points(text) {
            Some(points) => Some(points),
            None => {
                self.bad(e, element, attribute, "a list of points `x,y x,y ...`");
                None
            }
        }
    }
}

/// `x,y[,z] x,y[,z] ...` as points; `None` when a point is not two or three finite numbers.
pub fn parse_points(text: &str) -> Option<Vec<Point>> {
    text.split_ascii_whitespace()
        .map(|pair| {
            let mut numbers = pair.split(',').map(|n| n.parse::<f64>().ok().filter(|v| v.is_finite()));
            let x = numbers.next()??;
            let y = numbers.next()??;
            match (numbers.next(), numbers.next()) {
                (None, _) | (Some(Some(_)), None) => {}
                _ => return None,
            }
            (x.abs() <= MAX_COORDINATE_M && y.abs() <= MAX_COORDINATE_M).then_some([x, y])
        })
        .collect()
}

/// Whether lanes with these `allow` / `disallow` attributes admit `class` (SUMO: `allow` lists
/// the classes admitted, `disallow` the ones refused; `all` stands for every class; neither
/// means every class).
pub fn permits(allow: Option<&str>, disallow: Option<&str>, class: &str) -> bool {
    let has = |list: &str| list.split_ascii_whitespace().any(|c| c == class || c == "all");
    match (allow, disallow) {
        (Some(allow), _) => has(allow),
        (None, Some(disallow)) => !has(disallow),
        (None, None) => true,
    }
}

struct RawLane {
    element: Element,
    index: u32,
}

struct RawEdge {
    element: Element,
    lanes: Vec<RawLane>,
}

/// The elements of a SUMO network file that matter for geometry.
#[derive(Default)]
struct Raw {
    has_net: bool,
    location: Option<Element>,
    edges: Vec<RawEdge>,
    junctions: Vec<Element>,
    connections: Vec<Element>,
    roundabouts: Vec<Element>,
}

fn element_of(e: &BytesStart<'_>, line: usize) -> Result<Element, String> {
    Ok(Element { line, attributes: attributes(e)? })
}

/// The attributes of a SUMO XML element, unescaped, by name: how every SUMO file KPL reads (the
/// network, polygons, and `kpl-sim`'s trajectories and vehicle types) takes an element's values.
pub fn attributes(e: &BytesStart<'_>) -> Result<HashMap<String, String>, String> {
    let mut attributes = HashMap::new();
    for attribute in e.attributes() {
        let attribute = attribute.map_err(|err| err.to_string())?;
        let key = String::from_utf8_lossy(attribute.key.as_ref()).into_owned();
        let value = attribute.unescape_value().map_err(|err| err.to_string())?.into_owned();
        attributes.insert(key, value);
    }
    Ok(attributes)
}

fn xml_error(what: &'static str, lines: &Lines, position: u64, message: String) -> NetworkError {
    let (line, column) = lines.at(position as usize);
    NetworkError::Xml { what, line, column, message }
}

fn read_raw(text: &str) -> Result<Raw, NetworkError> {
    let lines = Lines::new(text);
    let mut reader = Reader::from_str(text);
    let mut raw = Raw::default();
    let mut edge: Option<RawEdge> = None;
    // Elements open inside the current edge (a lane's `param`s, ...); lanes are direct children.
    let mut depth_in_edge = 0usize;
    loop {
        let start = reader.buffer_position();
        let event = reader
            .read_event()
            .map_err(|e| xml_error("the SUMO network", &lines, reader.error_position(), e.to_string()))?;
        let line = lines.at(start as usize + leading_space(text, start as usize)).0;
        let (e, empty) = match &event {
            Event::Start(e) => (e, false),
            Event::Empty(e) => (e, true),
            Event::End(e) => {
                if edge.is_some() {
                    if depth_in_edge == 0 && e.name().as_ref() == b"edge" {
                        raw.edges.extend(edge.take());
                    } else {
                        depth_in_edge = depth_in_edge.saturating_sub(1);
                    }
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let to_element = |e: &BytesStart<'_>| {
            element_of(e, line).map_err(|m| xml_error("the SUMO network", &lines, start, m))
        };
        if let Some(current) = &mut edge {
            if depth_in_edge == 0 && e.name().as_ref() == b"lane" {
                let element = to_element(e)?;
                let index = current.lanes.len() as u32;
                current.lanes.push(RawLane { element, index });
            }
            if !empty {
                depth_in_edge += 1;
            }
            continue;
        }
        match e.name().as_ref() {
            b"net" => raw.has_net = true,
            b"location" => raw.location = Some(to_element(e)?),
            b"edge" => {
                let element = to_element(e)?;
                if empty {
                    raw.edges.push(RawEdge { element, lanes: Vec::new() });
                } else {
                    edge = Some(RawEdge { element, lanes: Vec::new() });
                    depth_in_edge = 0;
                }
            }
            b"junction" => raw.junctions.push(to_element(e)?),
            b"connection" => raw.connections.push(to_element(e)?),
            b"roundabout" => raw.roundabouts.push(to_element(e)?),
            _ => {}
        }
    }
    Ok(raw)
}

/// White space before the tag that starts at `offset` (quick-xml reports the end of the
/// previous event, which is often the end of the previous line).
fn leading_space(text: &str, offset: usize) -> usize {
    text.get(offset..).map_or(0, |rest| rest.len() - rest.trim_start().len())
}

/// The model of a SUMO network's text.
pub(crate) fn parts_of(text: &str) -> Result<Parts, NetworkError> {
    let raw = read_raw(text)?;
    if !raw.has_net {
        return Err(NetworkError::Invalid(vec![NetworkProblem::NotASumoNetwork]));
    }
    let mut problems = Problems { list: Vec::new() };

    // Junctions (nodes).
    let mut nodes: Vec<Node> = Vec::new();
    let mut node_index: HashMap<String, NodeId> = HashMap::new();
    // Internal lane id -> the junction listing it in `intLanes`.
    let mut internal_owner: HashMap<String, NodeId> = HashMap::new();
    for j in &raw.junctions {
        if j.get("type") == Some("internal") {
            continue;
        }
        let Some(name) = problems.text(j, "junction", "id") else { continue };
        let x = problems.number(j, "junction", "x");
        let y = problems.number(j, "junction", "y");
        let (Some(x), Some(y)) = (x, y) else {
            if j.get("x").is_none() {
                problems.missing(j, "junction", "x");
            }
            if j.get("y").is_none() {
                problems.missing(j, "junction", "y");
            }
            continue;
        };
        let id = NodeId(nodes.len() as u32);
        if node_index.insert(name.to_string(), id).is_some() {
            problems.list.push(NetworkProblem::DuplicateId { what: "junction", id: name.to_string() });
            continue;
        }
        for lane in j.get("intLanes").unwrap_or("").split_ascii_whitespace() {
            internal_owner.insert(lane.to_string(), id);
        }
        let area = problems.shape(j, "junction", "shape").unwrap_or_default();
        let pos = [x, y];
        let radius_m = area.iter().map(|&p| geom::dist(p, pos)).fold(0.0, f64::max);
        nodes.push(Node {
            id,
            name: name.to_string(),
            pos,
            kind: NodeKind::Boundary,
            junction_type: j.get("type").map(str::to_string),
            radius_m,
            roads: Vec::new(),
            area: if area.len() >= 3 { area } else { Vec::new() },
        });
    }

    // Edges and their lanes. Every lane id in the file, so that connections to lanes left out
    // (sidewalks, ...) are told from connections to lanes that do not exist.
    let mut all_lane_ids: HashSet<&str> = HashSet::new();
    let mut all_edge_ids: HashSet<&str> = HashSet::new();
    let mut roads: Vec<Road> = Vec::new();
    let mut lanes: Vec<Lane> = Vec::new();
    let mut lane_index: HashMap<String, LaneId> = HashMap::new();
    let mut edge_roads: HashMap<String, RoadId> = HashMap::new();
    for edge in &raw.edges {
        let e = &edge.element;
        let Some(edge_id) = problems.text(e, "edge", "id") else { continue };
        if !all_edge_ids.insert(edge_id) {
            problems.list.push(NetworkProblem::DuplicateId { what: "edge", id: edge_id.to_string() });
            continue;
        }
        for lane in &edge.lanes {
            if let Some(id) = lane.element.get("id") {
                all_lane_ids.insert(id);
            }
        }
        let function = e.get("function").unwrap_or("normal");
        match function {
            "normal" => {
                if let Some(road) = read_road(edge, &node_index, &mut problems, &mut lanes, roads.len()) {
                    for l in &road.lanes {
                        lane_index.insert(lanes[l.lane.0 as usize].name.clone(), l.lane);
                    }
                    edge_roads.insert(road.name.clone(), road.id);
                    roads.push(road);
                }
            }
            "internal" => {
                for lane in &edge.lanes {
                    if let Some(l) = read_lane(
                        &lane.element,
                        &mut problems,
                        LaneKind::Connector {
                            node: NodeId(u32::MAX),
                            from: LaneId(u32::MAX),
                            to: LaneId(u32::MAX),
                        },
                    ) {
                        let l = Lane { id: LaneId(lanes.len() as u32), ..l };
                        lane_index.insert(l.name.clone(), l.id);
                        lanes.push(l);
                    }
                }
            }
            _ => {} // walking areas, pedestrian crossings, district connectors
        }
    }

    // Connections: the lane graph, by lane name first (source, destination, U-turn).
    let mut links: Vec<(String, String, bool)> = Vec::new();
    for c in &raw.connections {
        let (Some(from), Some(from_lane)) =
            (problems.text(c, "connection", "from"), problems.text(c, "connection", "fromLane"))
        else {
            continue;
        };
        let src_name = format!("{from}_{from_lane}");
        let dst_name = match c.get("via") {
            Some(via) => via.to_string(),
            None => {
                let (Some(to), Some(to_lane)) =
                    (problems.text(c, "connection", "to"), problems.text(c, "connection", "toLane"))
                else {
                    continue;
                };
                format!("{to}_{to_lane}")
            }
        };
        if let Some(to) = c.get("to").filter(|to| !all_edge_ids.contains(to)) {
            problems.unknown(c, "connection", "edge", to);
        }
        for name in [&src_name, &dst_name] {
            if !all_lane_ids.contains(name.as_str()) {
                problems.unknown(c, "connection", "lane", name);
            }
        }
        links.push((src_name, dst_name, c.get("dir") == Some("t")));
    }
    // An internal lane of no length (SUMO writes them where lanes meet without a curve) is left
    // out of the model: what leads into it leads on to what follows it.
    let mut skipped: HashMap<&str, Vec<&str>> = HashMap::new();
    for (src, dst, _) in &links {
        if src.starts_with(':') && !lane_index.contains_key(src) && all_lane_ids.contains(src.as_str()) {
            skipped.entry(src.as_str()).or_default().push(dst.as_str());
        }
    }
    for (src_name, dst_name, turnaround) in &links {
        let Some(&src) = lane_index.get(src_name) else { continue };
        let mut targets = vec![dst_name.as_str()];
        for _ in 0..8 {
            if !targets.iter().any(|t| skipped.contains_key(t)) {
                break;
            }
            targets =
                targets.iter().flat_map(|t| skipped.get(t).cloned().unwrap_or_else(|| vec![*t])).collect();
        }
        // A connection of lanes cars may not use (bicycles, pedestrians) is left out quietly.
        for dst in targets.iter().filter_map(|t| lane_index.get(*t).copied()) {
            if src == dst {
                continue;
            }
            lanes[src.0 as usize].successors.push(dst);
            lanes[dst.0 as usize].predecessors.push(src);
            if *turnaround {
                for lane in [src, dst] {
                    if matches!(lanes[lane.0 as usize].kind, LaneKind::Connector { .. }) {
                        lanes[lane.0 as usize].turnaround = true;
                    }
                }
            }
        }
    }

    // Every lane a junction lists as incoming or internal is in the file.
    for j in &raw.junctions {
        for attribute in ["incLanes", "intLanes"] {
            for lane in j.get(attribute).unwrap_or("").split_ascii_whitespace() {
                if !all_lane_ids.contains(lane) {
                    problems.unknown(j, "junction", "lane", lane);
                }
            }
        }
    }

    // Connector lanes: their junction and the road lanes they join.
    let n_lanes = lanes.len();
    for i in 0..n_lanes {
        if !matches!(lanes[i].kind, LaneKind::Connector { .. }) {
            continue;
        }
        let node = internal_owner.get(&lanes[i].name).copied().or_else(|| {
            // `:JUNCTION_k_n`: the junction id is what comes before the last two parts.
            let trimmed = lanes[i].name.strip_prefix(':')?;
            let edge = trimmed.rsplit_once('_')?.0;
            let junction = edge.rsplit_once('_')?.0;
            node_index.get(junction).copied()
        });
        let Some(node) = node else {
            problems.list.push(NetworkProblem::UnknownReference {
                line: 0,
                element: "lane",
                id: lanes[i].name.clone(),
                what: "junction",
                name: "(none lists it in intLanes)".to_string(),
            });
            continue;
        };
        let from = chain_end(&lanes, LaneId(i as u32), false);
        let to = chain_end(&lanes, LaneId(i as u32), true);
        lanes[i].kind = LaneKind::Connector { node, from, to };
    }

    // Node kinds and incident roads.
    let mut neighbours: Vec<HashSet<NodeId>> = vec![HashSet::new(); nodes.len()];
    for road in &roads {
        if road.from != road.to {
            neighbours[road.from.0 as usize].insert(road.to);
            neighbours[road.to.0 as usize].insert(road.from);
        }
        nodes[road.from.0 as usize].roads.push(road.id);
        nodes[road.to.0 as usize].roads.push(road.id);
    }
    for node in &mut nodes {
        node.roads.sort_unstable();
        node.roads.dedup();
        node.kind = match neighbours[node.id.0 as usize].len() {
            0 | 1 => NodeKind::Boundary,
            2 => NodeKind::Joint,
            _ => NodeKind::Crossing,
        };
    }
    if roads.is_empty() {
        problems.list.push(NetworkProblem::Empty);
    }

    let location = raw.location.as_ref().and_then(|l| read_location(l, &mut problems));
    let roundabouts = raw
        .roundabouts
        .iter()
        .map(|r| {
            let mut lookup = |attribute: &'static str, what: &'static str| -> Vec<u32> {
                r.get(attribute)
                    .unwrap_or("")
                    .split_ascii_whitespace()
                    .filter_map(|name| {
                        let found = match what {
                            "junction" => node_index.get(name).map(|n| n.0),
                            _ => edge_roads.get(name).map(|e| e.0),
                        };
                        if found.is_none() && (what == "junction" || !all_edge_ids.contains(name)) {
                            problems.unknown(r, "roundabout", what, name);
                        }
                        found
                    })
                    .collect()
            };
            let nodes = lookup("nodes", "junction").into_iter().map(NodeId).collect();
            let roads = lookup("edges", "edge").into_iter().map(RoadId).collect();
            Roundabout { nodes, roads }
        })
        .collect();

    if !problems.list.is_empty() {
        return Err(NetworkError::Invalid(problems.list));
    }
    Ok(Parts {
        nodes,
        roads,
        lanes,
        occluders: Vec::new(),
        snap_radius_m: SNAP_RADIUS_M,
        source: Source::Sumo,
        location,
        roundabouts,
    })
}

/// The road lane at the end of a chain of connector lanes from `lane`, forwards or backwards
/// (the first lane in each step; `lane` itself when the chain ends in nothing).
fn chain_end(lanes: &[Lane], lane: LaneId, forward: bool) -> LaneId {
    let mut current = lane;
    for _ in 0..16 {
        let l = &lanes[current.0 as usize];
        let next = if forward { l.successors.first() } else { l.predecessors.first() };
        match next {
            Some(&n) if matches!(lanes[n.0 as usize].kind, LaneKind::Road { .. }) => return n,
            Some(&n) => current = n,
            None => break,
        }
    }
    lane
}

/// One lane of an edge (its kind filled in by the caller), or `None` when cars may not use it
/// or it is broken (reported).
fn read_lane(e: &Element, problems: &mut Problems, kind: LaneKind) -> Option<Lane> {
    if !permits(e.get("allow"), e.get("disallow"), VEHICLE_CLASS) {
        return None;
    }
    let name = problems.text(e, "lane", "id")?.to_string();
    let width_m = problems.number(e, "lane", "width").filter(|&w| w > 0.0).unwrap_or(DEFAULT_LANE_WIDTH_M);
    let speed_limit_mps =
        problems.number(e, "lane", "speed").filter(|&v| v > 0.0).unwrap_or(DEFAULT_SPEED_MPS);
    let shape = problems.text(e, "lane", "shape").and_then(|_| problems.shape(e, "lane", "shape"))?;
    let path = match Polyline::new(shape) {
        Some(path) => path,
        None if matches!(kind, LaneKind::Connector { .. }) => return None, // a junction without internal geometry
        None => {
            problems.bad(e, "lane", "shape", "at least two distinct points");
            return None;
        }
    };
    Some(Lane {
        id: LaneId(0),
        name,
        kind,
        path,
        width_m,
        speed_limit_mps,
        successors: Vec::new(),
        predecessors: Vec::new(),
        turnaround: false,
        // SUMO's lane change restrictions: the classes that may change to the left / right
        // neighbour (a solid line when cars are not among them); every class when absent.
        may_change_left: e.get("changeLeft").is_none_or(|c| permits(Some(c), None, VEHICLE_CLASS)),
        may_change_right: e.get("changeRight").is_none_or(|c| permits(Some(c), None, VEHICLE_CLASS)),
    })
}

/// A normal edge as a road (its lanes appended to `lanes`), or `None` when no car may use it.
fn read_road(
    edge: &RawEdge,
    node_index: &HashMap<String, NodeId>,
    problems: &mut Problems,
    lanes: &mut Vec<Lane>,
    road_index: usize,
) -> Option<Road> {
    let e = &edge.element;
    let name = e.id();
    let mut endpoint = |attribute: &'static str| {
        let id = problems.text(e, "edge", attribute)?;
        let node = node_index.get(id).copied();
        if node.is_none() {
            problems.unknown(e, "edge", "junction", id);
        }
        node
    };
    let (from, to) = (endpoint("from"), endpoint("to"));
    let road_id = RoadId(road_index as u32);
    // SUMO lists lanes rightmost first (`index` 0); the model lists them left to right.
    let mut kept: Vec<(u32, Lane)> = Vec::new();
    for raw in &edge.lanes {
        let index = match raw.element.get("index") {
            Some(text) => match text.parse::<u32>() {
                Ok(i) => i,
                Err(_) => {
                    problems.bad(&raw.element, "lane", "index", "a lane number");
                    raw.index
                }
            },
            None => raw.index,
        };
        if let Some(lane) = read_lane(&raw.element, problems, LaneKind::Road { road: road_id, index: 0 }) {
            kept.push((index, lane));
        }
    }
    let (from, to) = (from?, to?);
    if kept.is_empty() {
        return None;
    }
    kept.sort_by_key(|(index, _)| std::cmp::Reverse(*index));
    let width_m: f64 = kept.iter().map(|(_, l)| l.width_m).sum();
    let speed_limit_mps = kept.iter().map(|(_, l)| l.speed_limit_mps).fold(0.0, f64::max);
    // The middle of the band: the rightmost lane shifted left by half the band minus half itself.
    let (_, rightmost) = &kept[kept.len() - 1];
    let centerline =
        rightmost.path.offset(width_m / 2.0 - rightmost.width_m / 2.0).unwrap_or(rightmost.path.clone());
    let mut road_lanes = Vec::with_capacity(kept.len());
    let mut left_edge = width_m / 2.0;
    for (position, (_, mut lane)) in kept.into_iter().enumerate() {
        let lane_id = LaneId(lanes.len() as u32);
        lane.id = lane_id;
        lane.kind = LaneKind::Road { road: road_id, index: position as u32 };
        road_lanes.push(RoadLane {
            width_m: lane.width_m,
            direction: LaneDirection::Forward,
            lateral_m: left_edge - lane.width_m / 2.0,
            lane: lane_id,
        });
        left_edge -= lane.width_m;
        lanes.push(lane);
    }
    Some(Road {
        id: road_id,
        name,
        from,
        to,
        centerline,
        lanes: road_lanes,
        width_m,
        speed_limit_mps,
        level: 0,
    })
}

fn read_location(e: &Element, problems: &mut Problems) -> Option<Location> {
    let numbers = |attribute: &'static str, n: usize, problems: &mut Problems| -> Option<Vec<f64>> {
        let text = e.get(attribute)?;
        let values: Option<Vec<f64>> =
            text.split(',').map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite())).collect();
        match values {
            Some(values) if values.len() == n => Some(values),
            _ => {
                problems.bad(e, "location", attribute, "comma-separated numbers");
                None
            }
        }
    };
    let boundary = |v: Vec<f64>| ([v[0], v[1]], [v[2], v[3]]);
    let net_offset = numbers("netOffset", 2, problems).map(|v| [v[0], v[1]]).unwrap_or([0.0, 0.0]);
    let conv_boundary = numbers("convBoundary", 4, problems).map(boundary).unwrap_or_default();
    let orig_boundary = numbers("origBoundary", 4, problems).map(boundary).unwrap_or_default();
    Some(Location {
        net_offset,
        conv_boundary,
        orig_boundary,
        proj_parameter: e.get("projParameter").unwrap_or("!").to_string(),
    })
}

/// The `<poly>` elements of a SUMO additional file (as `polyconvert` writes them) as occluders:
/// `id`, `type` (its kind: `bridge`, `tunnel`, `tree`/`forest`/`wood`, `building`, else other)
/// and `shape`. A `<param key="roads" value="E1 E2"/>` inside a polygon makes it hide only what
/// is on those edges (a bridge over them). Polygons with `fill="0"` (outlines) or fewer than
/// three points hide nothing and are left out.
pub fn read_polygons(text: &str, net: &crate::RoadNetwork) -> Result<Vec<Occluder>, NetworkError> {
    let lines = Lines::new(text);
    let mut reader = Reader::from_str(text);
    let mut problems = Problems { list: Vec::new() };
    let mut polygons: Vec<(Element, Vec<String>)> = Vec::new();
    let mut open_poly = false;
    loop {
        let start = reader.buffer_position();
        let event = reader
            .read_event()
            .map_err(|e| xml_error("the polygon file", &lines, reader.error_position(), e.to_string()))?;
        let line = lines.at(start as usize + leading_space(text, start as usize)).0;
        let to_element = |e: &BytesStart<'_>| {
            element_of(e, line).map_err(|m| xml_error("the polygon file", &lines, start, m))
        };
        match &event {
            Event::Start(e) | Event::Empty(e) if e.name().as_ref() == b"poly" => {
                polygons.push((to_element(e)?, Vec::new()));
                open_poly = matches!(event, Event::Start(_));
            }
            Event::Start(e) | Event::Empty(e) if open_poly && e.name().as_ref() == b"param" => {
                let param = to_element(e)?;
                if param.get("key") == Some("roads")
                    && let Some((_, roads)) = polygons.last_mut()
                {
                    roads.extend(
                        param.get("value").unwrap_or("").split_ascii_whitespace().map(str::to_string),
                    );
                }
            }
            Event::End(e) if e.name().as_ref() == b"poly" => open_poly = false,
            Event::Eof => break,
            _ => {}
        }
    }
    let mut occluders = Vec::new();
    for (p, road_names) in &polygons {
        if matches!(p.get("fill"), Some("0" | "false")) {
            continue;
        }
        let Some(shape) = problems.text(p, "poly", "shape").and_then(|_| problems.shape(p, "poly", "shape"))
        else {
            continue;
        };
        if shape.len() < 3 {
            continue;
        }
        let mut roads = Vec::new();
        for name in road_names {
            match net.road_by_name(name) {
                Some(road) => roads.push(road.id),
                None => problems.unknown(p, "poly", "edge", name),
            }
        }
        occluders.push(Occluder {
            id: OccluderId(0),
            name: p.id(),
            kind: OccluderKind::from_sumo_type(p.get("type").unwrap_or("")),
            area: shape,
            roads,
        });
    }
    if problems.list.is_empty() { Ok(occluders) } else { Err(NetworkError::Invalid(problems.list)) }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "tests")]
    use super::*;

    #[test]
    fn points_and_permissions() {
        assert_eq!(parse_points("0,1 2.5,-3,7"), Some(vec![[0.0, 1.0], [2.5, -3.0]]));
        assert_eq!(parse_points("0,1 2"), None);
        assert_eq!(parse_points("0,1,2,3"), None);
        assert_eq!(parse_points("nan,1"), None);
        assert_eq!(parse_points(""), Some(vec![]));
        assert!(permits(None, None, "passenger"));
        assert!(permits(Some("bus passenger"), None, "passenger"));
        assert!(!permits(Some("pedestrian"), None, "passenger"));
        assert!(!permits(None, Some("all"), "passenger"));
        assert!(permits(None, Some("pedestrian bicycle"), "passenger"));
        assert!(permits(Some("all"), None, "passenger"));
    }

    #[test]
    fn lines_count_from_one() {
        let lines = Lines::new("a\nbc\n\nd");
        assert_eq!(lines.at(0), (1, 1));
        assert_eq!(lines.at(3), (2, 2));
        assert_eq!(lines.at(5), (3, 1));
        assert_eq!(lines.at(6), (4, 1));
    }
}
