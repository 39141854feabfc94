//! SUMO networks as SUMO writes them (the scenarios of `scripts/sumo-scenarios.py` shipped in
//! `specs/traffic/sumo/`): read directly, checked against sumolib (SUMO's own Python reader, in
//! the test environment of `scripts/test`), and queried: lanes on their own side of the street,
//! turns only where SUMO connects lanes, prediction that stops at the border.
#![allow(clippy::unwrap_used, reason = "tests")]
#![allow(clippy::print_stderr, reason = "tests say when an oracle is missing and what they measured")]

use std::path::{Path, PathBuf};
use std::sync::LazyLock;

use kpl_roads::{LaneKind, NetworkError, NetworkProblem, NodeKind, RoadNetwork};

fn sumo_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic/sumo")
}

fn load(name: &str) -> RoadNetwork {
    RoadNetwork::load(&sumo_dir().join(name).join("net.xml.gz")).unwrap()
}

static GRID: LazyLock<RoadNetwork> = LazyLock::new(|| load("grid"));

#[test]
fn the_grid_is_read_with_its_junctions_lanes_and_connections() {
    let net = &*GRID;
    assert!(net.is_sumo() && net.file().is_none());
    // 4 x 4 crossings and the ends of the 16 roads out of town, all with traffic lights (as
    // netgenerate makes them with --default-junction-type traffic_light).
    assert_eq!(net.nodes().len(), 32);
    assert!(net.nodes().iter().all(|n| n.junction_type.as_deref() == Some("traffic_light")));
    let kinds = |kind| net.nodes().iter().filter(|n| n.kind == kind).count();
    assert_eq!((kinds(NodeKind::Crossing), kinds(NodeKind::Boundary)), (16, 16));
    // Every street is two edges, one per direction, each of one 3.2 m lane (SUMO's default).
    assert!(net.roads().iter().all(|r| r.lanes.len() == 1 && (r.width_m - 3.2).abs() < 1e-9));
    let a = net.road_by_name("A1B1").unwrap();
    let b = net.road_by_name("B1A1").unwrap();
    assert_eq!((a.from, a.to), (b.to, b.from));
    // The two directions lie side by side, 3.2 m apart: a point on one is not on the other's lane.
    let on_a = net.lane(a.lanes[0].lane).path.point_at(40.0);
    let across = net.lane(b.lanes[0].lane).path.project(on_a);
    assert!((across.lateral.abs() - 3.2).abs() < 0.01, "{on_a:?} {across:?}");
    let snapped = net.snap_to_lane(on_a, None).unwrap();
    assert_eq!(snapped.road(), Some(a.id));
    // A junction's area is its SUMO shape; the middle of a crossing is on the road.
    let crossing = net.node_by_name("B1").unwrap();
    assert!(crossing.area.len() >= 8 && net.on_road(crossing.pos));
    assert_eq!(net.location().unwrap().proj_parameter, "!");
}

#[test]
fn turns_follow_sumos_connections_through_internal_lanes() {
    let net = &*GRID;
    let incoming = net.lane_by_name("A1B1_0").unwrap();
    // At B1 the lane may go left, straight and right (and turn around, which nothing takes).
    let onward: Vec<&str> = net.onward(incoming.id).map(|l| net.lane(l).name.as_str()).collect();
    assert_eq!(onward.len(), 3, "{onward:?}");
    assert!(onward.iter().all(|name| name.starts_with(":B1_")));
    assert_eq!(incoming.successors.len(), 4, "with the U-turn");
    let mut ends: Vec<String> = Vec::new();
    for connector in net.onward(incoming.id) {
        let LaneKind::Connector { node, from, to } = net.lane(connector).kind else {
            panic!("not a connector")
        };
        assert_eq!(net.node(node).name, "B1");
        assert_eq!(from, incoming.id);
        ends.push(net.lane(to).name.clone());
    }
    ends.sort();
    assert_eq!(ends, vec!["B1B0_0", "B1B2_0", "B1C1_0"]);
    // Prediction from before B1 splits into exactly those three roads.
    let start = net.lane_position(incoming.id, net.lane(incoming.id).path.length() - 10.0);
    let mut reached: Vec<String> = net
        .advance(&start, 60.0, 20)
        .iter()
        .map(|h| net.road(h.position.road().unwrap()).name.clone())
        .collect();
    reached.sort();
    assert_eq!(reached, vec!["B1B0", "B1B2", "B1C1"]);
}

#[test]
fn prediction_stops_at_the_border() {
    let net = &*GRID;
    // Every lane leaving town ends at a dead end: nothing continues it but the U-turn.
    let out_of_town: Vec<_> = net
        .lanes()
        .iter()
        .filter(|l| matches!(l.kind, LaneKind::Road { .. }) && net.onward(l.id).next().is_none())
        .collect();
    assert_eq!(out_of_town.len(), 16);
    for lane in out_of_town {
        let start = net.lane_position(lane.id, 10.0);
        let ahead = net.advance(&start, 500.0, 9);
        assert_eq!(ahead.len(), 1);
        assert!(ahead[0].reached_end && ahead[0].travelled_m < 100.0, "{:?}", ahead[0]);
        let end = ahead[0].position.point;
        let (lo, hi) = net.bounds();
        assert!(end[0] >= lo[0] && end[1] >= lo[1] && end[0] <= hi[0] && end[1] <= hi[1]);
    }
}

#[test]
fn every_shipped_network_reads_and_its_lanes_are_on_the_road() {
    for name in ["grid", "random", "highway", "town400"] {
        let net = load(name);
        assert!(!net.roads().is_empty(), "{name}");
        for lane in net.lanes() {
            let middle = lane.path.point_at(lane.path.length() / 2.0);
            assert!(net.on_road(middle), "{name}: {} at {middle:?}", lane.name);
            let snapped =
                net.snap_to_lane(middle, Some(lane.path.heading_at(lane.path.length() / 2.0))).unwrap();
            assert!(snapped.lateral_m.abs() < 1e-6, "{name}: {}", lane.name);
        }
    }
    let town = load("town400");
    assert_eq!(town.nodes().len(), 400);
    let highway = load("highway");
    let eastbound = highway.road_by_name("eastbound").unwrap();
    assert_eq!(eastbound.lanes.len(), 2);
    // Left to right: SUMO's lane 1 (the left one) first.
    assert_eq!(highway.lane(eastbound.lanes[0].lane).name, "eastbound_1");
    assert!((eastbound.speed_limit_mps - 33.33).abs() < 1e-9);
}

#[test]
fn bad_sumo_files_are_reported_with_their_lines() {
    let text = "<net>\n  <edge id=\"e\" from=\"a\" to=\"nowhere\">\n    <lane id=\"e_0\" index=\"0\" speed=\"x\" shape=\"0,0 10,0\"/>\n  </edge>\n  <junction id=\"a\" type=\"priority\" x=\"0\" y=\"0\"/>\n  <connection from=\"e\" to=\"f\" fromLane=\"0\" toLane=\"0\"/>\n</net>\n";
    let NetworkError::Invalid(problems) = RoadNetwork::from_sumo_str(text).unwrap_err() else { panic!() };
    let messages: Vec<String> = problems.iter().map(ToString::to_string).collect();
    assert!(
        messages.iter().any(|m| m.starts_with("line 2: edge \"e\" refers to junction \"nowhere\"")),
        "{messages:?}"
    );
    assert!(
        messages.iter().any(|m| m.starts_with("line 3: lane \"e_0\": attribute `speed` is not a number")),
        "{messages:?}"
    );
    assert!(messages.iter().any(|m| m.starts_with("line 6: connection")), "{messages:?}");
    let err = RoadNetwork::from_sumo_str("<net>\n  <edge id=\"e\">\n</net>").unwrap_err();
    assert!(matches!(err, NetworkError::Xml { line: 3, .. }), "{err}");
    let err = RoadNetwork::from_sumo_str("<routes/>").unwrap_err();
    assert!(matches!(&err, NetworkError::Invalid(p) if p == &vec![NetworkProblem::NotASumoNetwork]), "{err}");
    let dir = std::env::temp_dir().join(format!("kpl-roads-sumo-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("odd.txt"), "hello").unwrap();
    assert!(matches!(
        RoadNetwork::load(&dir.join("odd.txt")).unwrap_err(),
        NetworkError::UnknownFormat { .. }
    ));
    assert!(matches!(RoadNetwork::load(&dir).unwrap_err(), NetworkError::Read { .. }), "a directory");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The Python of the test environment (`KPL_PYTHON`, set by `scripts/test`), if any.
fn python() -> Option<String> {
    match std::env::var("KPL_PYTHON") {
        Ok(python) => Some(python),
        Err(_) => {
            assert!(
                std::env::var("KPL_REQUIRE_ORACLES").is_err(),
                "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set"
            );
            eprintln!("skipped: KPL_PYTHON is not set (scripts/test sets it up with eclipse-sumo)");
            None
        }
    }
}

/// Runs Python code with SUMO's tools (sumolib) importable; its standard output.
fn run_python(python: &str, code: &str) -> String {
    let output = std::process::Command::new(python)
        .args([
            "-c",
            &format!("import os, sys, sumo; sys.path.append(os.path.join(sumo.SUMO_HOME, 'tools'))\n{code}"),
        ])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    String::from_utf8(output.stdout).unwrap()
}

/// sumolib, SUMO's own reader, and this one agree on each shipped network: the junctions and
/// their types, the edges and lanes cars may use, their shapes, and the connections between
/// them (through internal lanes).
#[test]
fn sumolib_reads_the_same_networks() {
    let Some(python) = python() else { return };
    for name in ["grid", "random", "highway"] {
        let path = sumo_dir().join(name).join("net.xml.gz");
        let code = format!(
            r#"
import sumolib
net = sumolib.net.readNet({path:?}, withInternal=True)
for n in net.getNodes():
    if n.getType() != 'internal':
        print('node', n.getID(), n.getType(), '%.2f,%.2f' % n.getCoord())
for e in net.getEdges(withInternal=False):
    lanes = [l for l in e.getLanes() if l.allows('passenger')]
    if lanes:
        print('edge', e.getID(), e.getFromNode().getID(), e.getToNode().getID(), len(lanes))
    for l in lanes:
        print('lane', l.getID(), '%.2f' % l.getWidth(), '%.2f' % l.getSpeed(), ' '.join('%.2f,%.2f' % p[:2] for p in l.getShape()))
        for c in l.getOutgoing():
            to = c.getToLane()
            via = c.getViaLaneID()
            # An internal lane of no length leads straight on (this reader leaves it out).
            if via and len(set(net.getLane(via).getShape())) < 2:
                via = ''
            if to.allows('passenger'):
                print('connection', l.getID(), via or to.getID(), c.getDirection())
"#,
            path = path.to_string_lossy()
        );
        let mut theirs: Vec<String> = run_python(&python, &code).lines().map(str::to_string).collect();
        let net = load(name);
        let mut ours: Vec<String> = Vec::new();
        for node in net.nodes() {
            ours.push(format!(
                "node {} {} {:.2},{:.2}",
                node.name,
                node.junction_type.as_deref().unwrap_or(""),
                node.pos[0],
                node.pos[1]
            ));
        }
        for road in net.roads() {
            ours.push(format!(
                "edge {} {} {} {}",
                road.name,
                net.node(road.from).name,
                net.node(road.to).name,
                road.lanes.len()
            ));
            for road_lane in &road.lanes {
                let lane = net.lane(road_lane.lane);
                let shape: Vec<String> =
                    lane.path.points().iter().map(|p| format!("{:.2},{:.2}", p[0], p[1])).collect();
                ours.push(format!(
                    "lane {} {:.2} {:.2} {}",
                    lane.name,
                    lane.width_m,
                    lane.speed_limit_mps,
                    shape.join(" ")
                ));
                for &next in &lane.successors {
                    // sumolib gives the connection's direction; ours knows only whether it turns around.
                    let dir = theirs
                        .iter()
                        .find(|l| {
                            l.starts_with(&format!("connection {} {} ", lane.name, net.lane(next).name))
                        })
                        .and_then(|l| l.rsplit(' ').next())
                        .unwrap_or("?");
                    assert_eq!(
                        dir == "t",
                        net.lane(next).turnaround,
                        "{name}: {} -> {}",
                        lane.name,
                        net.lane(next).name
                    );
                    ours.push(format!("connection {} {} {dir}", lane.name, net.lane(next).name));
                }
            }
        }
        theirs.sort();
        ours.sort();
        // Shapes are compared as SUMO prints them (two decimals); our copy drops repeated points.
        let only_ours: Vec<&String> = ours.iter().filter(|l| !theirs.contains(l)).collect();
        let only_theirs: Vec<&String> = theirs.iter().filter(|l| !ours.contains(l)).collect();
        assert!(
            only_ours.is_empty() && only_theirs.is_empty(),
            "{name}: ours {only_ours:#?} sumolib {only_theirs:#?}"
        );
        assert_eq!(ours.len(), theirs.len(), "{name}");
        for (a, b) in ours.iter().zip(&theirs) {
            assert_eq!(a, b, "{name}");
        }
    }
}

/// SUMO itself and this reader agree on where a car may change lanes (SUMO's `changeLeft` /
/// `changeRight`, lists of vehicle classes): on the shipped no-passing network and on one that
/// `netconvert` makes here with restrictions of every form (classes with and without cars,
/// `all`, a class of no vehicle), asked of SUMO through TraCI (`lane.getChangePermissions`).
#[test]
fn sumo_agrees_on_solid_lines() {
    let Some(python) = python() else { return };
    let dir = std::env::temp_dir().join(format!("kpl-roads-solid-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let shipped = sumo_dir().join("no_passing").join("net.xml.gz");
    let code = format!(
        r#"
import os, subprocess, traci
d = {dir:?}
with open(os.path.join(d, 'n.nod.xml'), 'w') as f:
    f.write('<nodes><node id="w" x="0" y="0"/><node id="m" x="300" y="0"/><node id="e" x="600" y="0"/></nodes>')
with open(os.path.join(d, 'n.edg.xml'), 'w') as f:
    f.write('''<edges>
  <edge id="a" from="w" to="m" numLanes="3" speed="25.0">
    <lane index="0" changeLeft="emergency authority"/>
    <lane index="1" changeRight="passenger" changeLeft="truck bus"/>
    <lane index="2" changeRight="all"/>
  </edge>
  <edge id="b" from="m" to="e" numLanes="3" speed="25.0">
    <lane index="0" changeLeft="custom1"/>
    <lane index="1" changeRight="passenger truck" changeLeft="private"/>
  </edge>
</edges>''')
made = os.path.join(d, 'made.net.xml')
subprocess.run([os.path.join(sumo.SUMO_HOME, 'bin', 'netconvert'), '-n', os.path.join(d, 'n.nod.xml'),
                '-e', os.path.join(d, 'n.edg.xml'), '-o', made], check=True, capture_output=True)
for net in (made, {shipped:?}):
    traci.start([os.path.join(sumo.SUMO_HOME, 'bin', 'sumo'), '-n', net, '--no-step-log', '--end', '1'],
                stdout=subprocess.DEVNULL)
    for lane in sorted(traci.lane.getIDList()):
        if not lane.startswith(':'):
            left = 'passenger' in traci.lane.getChangePermissions(lane, 1)
            right = 'passenger' in traci.lane.getChangePermissions(lane, -1)
            print(net, lane, left, right)
    traci.close()
"#,
        dir = dir.to_string_lossy(),
        shipped = shipped.to_string_lossy()
    );
    let theirs = run_python(&python, &code);
    let mut checked = 0;
    let mut solid = 0;
    for path in [dir.join("made.net.xml"), shipped] {
        let net = RoadNetwork::load(&path).unwrap();
        let mut ours: Vec<String> = net
            .lanes()
            .iter()
            .filter(|l| !l.name.starts_with(':'))
            .map(|l| {
                format!(
                    "{} {} {} {}",
                    path.display(),
                    l.name,
                    py_bool(l.may_change_left),
                    py_bool(l.may_change_right)
                )
            })
            .collect();
        ours.sort();
        let prefix = format!("{} ", path.display());
        let mut sumo: Vec<&str> = theirs.lines().filter(|l| l.starts_with(&prefix)).collect();
        sumo.sort_unstable();
        assert_eq!(ours, sumo, "{}", path.display());
        checked += ours.len();
        solid += ours.iter().filter(|l| l.contains("False")).count();
    }
    assert_eq!((checked, solid), (13, 6), "lanes checked, lanes with a solid line");
    std::fs::remove_dir_all(&dir).unwrap();
}

fn py_bool(b: bool) -> &'static str {
    if b { "True" } else { "False" }
}
