//! Road-network geometry: on_road, snapping, branching prediction, occluders, the file format.
#![allow(clippy::unwrap_used, reason = "tests")]

use kpl_roads::format::{LaneDirection, LaneSpec, OccluderKind, OccluderSpec};
use kpl_roads::network::{LaneKind, NodeKind};
use kpl_roads::scenarios::{self, GridTownSize};
use kpl_roads::{NetworkError, NetworkFile, NetworkProblem, Place, RoadNetwork};
use proptest::prelude::*;
use std::sync::LazyLock;

static CROSSING: LazyLock<RoadNetwork> =
    LazyLock::new(|| RoadNetwork::build(&scenarios::crossing()).unwrap());
static TOWN: LazyLock<RoadNetwork> = LazyLock::new(|| town(3));

fn crossing() -> RoadNetwork {
    CROSSING.clone()
}

fn town(blocks: u32) -> RoadNetwork {
    RoadNetwork::build(&scenarios::grid_town(GridTownSize {
        blocks_x: blocks,
        blocks_y: blocks,
        block_m: 100.0,
    }))
    .unwrap()
}

const EAST: f64 = 0.0;
const NORTH: f64 = std::f64::consts::FRAC_PI_2;
const WEST: f64 = std::f64::consts::PI;

#[test]
fn on_road_follows_the_paved_width() {
    let net = crossing();
    // (point, expected): the arms are 7 m wide (two 3.5 m lanes) along the axes.
    let cases = [
        ([0.0, 0.0], true),
        ([-50.0, 3.4], true),
        ([-50.0, -3.4], true),
        ([-50.0, 3.6], false),
        ([-50.0, -3.6], false),
        ([3.6, 60.0], false),
        ([3.4, 60.0], true),
        // The crossing area joins the arms' edges where they start, 5 m from the centre, so
        // its corners are cut diagonally like kerbs: from (5, 3.5) to (3.5, 5).
        ([4.0, 4.0], true),
        ([4.5, 4.5], false),
        ([8.0, 8.0], false),
        ([-149.0, 0.0], true),
        ([-151.0, 0.0], true),  // still within the half width of the dead end
        ([-154.0, 0.0], false), // beyond the end of the road
        ([1e12, 0.0], false),
        ([f64::NAN, 0.0], false),
    ];
    for (p, expected) in cases {
        assert_eq!(net.on_road(p), expected, "on_road({p:?})");
    }
}

#[test]
fn crossing_structure() {
    let net = crossing();
    let centre = net.node_by_name("c").unwrap();
    assert_eq!(centre.kind, NodeKind::Crossing);
    assert_eq!(centre.radius_m, 5.0, "half of 7 m plus the 1.5 m margin");
    assert_eq!(net.node_by_name("w").unwrap().kind, NodeKind::Boundary);
    // 4 roads x 2 lanes, and at the crossing 4 incoming lanes x 3 other roads.
    let connectors = net.lanes().iter().filter(|l| matches!(l.kind, LaneKind::Connector { .. })).count();
    assert_eq!(net.lanes().len(), 8 + connectors);
    assert_eq!(connectors, 12);
    assert_eq!(net.entry_lanes().len(), 4);
}

#[test]
fn snapping_picks_the_lane_of_the_direction_of_travel() {
    let net = crossing();
    let west_road = net.road_by_name("west").unwrap().id;
    // On the west arm, lanes run at y = -1.75 (eastbound) and y = +1.75 (westbound).
    let east = net.snap_to_lane([-50.0, 0.5], Some(EAST)).unwrap();
    assert_eq!(east.place, Place::Road { road: west_road, lane: 1 });
    assert_eq!(east.point, [-50.0, -1.75]);
    assert!((east.lateral_m - 2.25).abs() < 1e-9, "query point is left of the eastbound lane");
    assert!((east.heading - EAST).abs() < 1e-9);
    // The eastbound lane starts at the boundary node (x = -150), so 100 m along.
    assert!((east.offset_m - 100.0).abs() < 1e-9);

    let west = net.snap_to_lane([-50.0, 0.5], Some(WEST)).unwrap();
    assert_eq!(west.place, Place::Road { road: west_road, lane: 0 });
    assert_eq!(west.point, [-50.0, 1.75]);
    // The westbound lane starts where the crossing ends (x = -5): 45 m along.
    assert!((west.offset_m - 45.0).abs() < 1e-9);

    let nearest = net.snap_to_lane([-50.0, 0.5], None).unwrap();
    assert_eq!(nearest.place, Place::Road { road: west_road, lane: 0 }, "nearest without a heading");

    assert!(net.snap_to_lane([-50.0, 40.0], None).is_none(), "beyond the 10 m snap radius");
    assert!(net.snap_to_lane([f64::NAN, 0.0], None).is_none());
}

#[test]
fn snapping_inside_a_crossing_uses_the_heading_to_pick_the_connector() {
    let net = crossing();
    let centre = net.node_by_name("c").unwrap().id;
    let snapped = net.snap_to_lane([0.5, 0.5], Some(NORTH)).unwrap();
    assert_eq!(snapped.place, Place::Crossing { node: centre });
    assert!(kpl_roads::geom::heading_difference(snapped.heading, NORTH) < 0.6, "{snapped:?}");
}

#[test]
fn advancing_branches_once_per_outgoing_road_at_a_crossing() {
    let net = crossing();
    let start = net.snap_to_lane([-20.0, -1.75], Some(EAST)).unwrap();
    // 15 m to the crossing: a short advance stays on the lane.
    let short = net.advance(&start, 10.0, 16);
    assert_eq!(short.len(), 1);
    assert_eq!(short[0].route, vec![start.lane]);
    assert_eq!(short[0].position.point, [-10.0, -1.75]);

    let long = net.advance(&start, 60.0, 16);
    assert_eq!(long.len(), 3);
    let mut roads: Vec<&str> = long
        .iter()
        .map(|h| {
            assert_eq!(h.route.len(), 3, "start lane, connector, outgoing lane");
            assert_eq!(h.route[0], start.lane);
            assert!(matches!(net.lane(h.route[1]).kind, LaneKind::Connector { .. }));
            assert!(!h.reached_end);
            assert_eq!(h.travelled_m, 60.0);
            net.road(h.position.road().unwrap()).name.as_str()
        })
        .collect();
    roads.sort_unstable();
    assert_eq!(roads, vec!["east", "north", "south"], "left, straight and right; no U-turn");
    for h in &long {
        // Each hypothesis is in its road's lane leading away from the crossing, and the distance
        // along the route adds up to 60 m.
        let along: f64 = h.route[..h.route.len() - 1].iter().map(|&l| net.lane(l).path.length()).sum::<f64>()
            - start.offset_m
            + h.position.offset_m;
        assert!((along - 60.0).abs() < 1e-9);
        assert!(kpl_roads::geom::dist([0.0, 0.0], h.position.point) > 30.0);
    }

    // Far enough to leave the map: every branch ends at its boundary.
    let out = net.advance(&start, 1000.0, 16);
    assert_eq!(out.len(), 3);
    assert!(out.iter().all(|h| h.reached_end && h.travelled_m < 1000.0));
}

#[test]
fn advancing_through_two_crossings_multiplies_branches_up_to_the_cap() {
    let net = town(4);
    // Eastbound on h1_1, between crossings x1y1 and x2y1 (100 m apart), 10 m after x1y1.
    let start = net.snap_to_lane([110.0, 98.25], Some(EAST)).unwrap();
    assert_eq!(net.road(start.road().unwrap()).name, "h1_1");
    assert_eq!(net.advance(&start, 150.0, 100).len(), 3);
    assert_eq!(net.advance(&start, 250.0, 100).len(), 9);
    let capped = net.advance(&start, 250.0, 4);
    assert_eq!(capped.len(), 4);
    assert_eq!(capped, net.advance(&start, 250.0, 100)[..4].to_vec(), "the cap keeps the first found");
    // Negative and NaN distances stay put.
    assert_eq!(net.advance(&start, -5.0, 10)[0].position.point, start.point);
    assert_eq!(net.advance(&start, f64::NAN, 10)[0].position.point, start.point);
}

#[test]
fn bridge_occludes_only_the_road_below() {
    let net = RoadNetwork::build(&scenarios::bridge()).unwrap();
    let main = net.road_by_name("main").unwrap().id;
    let overpass = net.road_by_name("overpass").unwrap().id;
    let bridge = net.occluders().list()[0].id;
    let half = scenarios::BRIDGE_LENGTH_M / 2.0;
    for (p, expected) in [
        ([0.0, -1.75], true),
        ([half - 0.1, 1.75], true),
        ([-half + 0.1, -1.75], true),
        ([half + 0.1, -1.75], false),
        ([-half - 0.1, 1.75], false),
        ([0.0, 20.0], false),
    ] {
        assert_eq!(net.occluders().at(p) == Some(bridge), expected, "at({p:?})");
        assert_eq!(net.occluders().hiding(p, Some(main)) == Some(bridge), expected, "hiding({p:?}, main)");
        assert_eq!(net.occluders().hiding(p, None), None, "only what is on main is hidden");
    }
    assert_eq!(net.occluders().hiding([0.0, 0.0], Some(overpass)), None, "a car on the bridge is seen");
    // Both roads cover the point where they cross, without a crossing node.
    assert!(net.on_road([0.0, 0.0]));
    assert!(net.nodes().iter().all(|n| n.kind == NodeKind::Boundary));
    // A car driving east under the bridge snaps to main, not to the overpass.
    let snapped = net.snap_to_lane([0.0, -1.0], Some(EAST)).unwrap();
    assert_eq!(snapped.road(), Some(main));
}

#[test]
fn built_in_scenarios_round_trip_through_json() {
    for name in scenarios::NAMES {
        let file =
            scenarios::by_name(name, GridTownSize { blocks_x: 3, blocks_y: 2, block_m: 80.0 }).unwrap();
        let net = RoadNetwork::build(&file).unwrap();
        let again = RoadNetwork::from_json_str(&net.to_json_string().unwrap()).unwrap();
        assert_eq!(again.file(), Some(&file), "{name}");
        assert_eq!(again.lanes().len(), net.lanes().len());
    }
    let dir = std::env::temp_dir().join(format!("kpl-roads-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("bridge.json");
    let net = RoadNetwork::build(&scenarios::bridge()).unwrap();
    net.save(&path).unwrap();
    assert_eq!(RoadNetwork::load(&path).unwrap().file(), net.file());
    let missing = RoadNetwork::load(&dir.join("missing.json")).unwrap_err();
    assert!(matches!(missing, NetworkError::Read { .. }), "{missing}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_minimal_file_uses_the_documented_defaults() {
    let text = r#"{
        "format": "kpl-road-network", "version": 1,
        "nodes": [ { "id": "a", "pos": [0, 0] }, { "id": "b", "pos": [100, 0] } ],
        "roads": [ { "id": "ab", "from": "a", "to": "b" } ]
    }"#;
    let net = RoadNetwork::from_json_str(text).unwrap();
    let road = net.road_by_name("ab").unwrap();
    assert_eq!(road.width_m, 7.0);
    assert_eq!(road.speed_limit_mps, 13.9);
    assert_eq!(road.lanes[1].direction, LaneDirection::Forward);
    assert_eq!(net.snap_radius_m(), 10.0);
}

#[test]
fn every_problem_of_a_bad_file_is_reported_at_once() {
    let mut file = NetworkFile::new();
    file.add_node("a", [0.0, 0.0]);
    file.add_node("a", [50.0, 0.0]);
    file.add_node("c", [5.0, 0.0]);
    file.add_node("d", [100.0, f64::NAN]);
    file.add_road("ab", "a", "nowhere", Vec::new());
    file.add_road("bad_lanes", "a", "c", Vec::new());
    file.roads[1].lanes = vec![LaneSpec::new(-1.0, LaneDirection::Forward)];
    file.add_road("empty", "a", "c", Vec::new());
    file.roads[2].lanes.clear();
    let err = RoadNetwork::build(&file).unwrap_err();
    let NetworkError::Invalid(problems) = &err else { panic!("{err}") };
    assert!(problems.contains(&NetworkProblem::DuplicateId { what: "node", id: "a".into() }));
    assert!(problems.contains(&NetworkProblem::UnknownNode { road: "ab".into(), node: "nowhere".into() }));
    assert!(problems.contains(&NetworkProblem::NoLanes { road: "empty".into() }));
    assert!(problems.iter().any(|p| matches!(p, NetworkProblem::BadNumber { field: "lane width_m", .. })));
    assert!(problems.iter().any(|p| matches!(p, NetworkProblem::BadNumber { field: "pos", .. })));
    assert_eq!(problems.len(), 5, "{err}");

    // Geometry problems: a road too short for its crossings, an occluder outside its road.
    let mut file = scenarios::crossing();
    file.nodes[1].pos = [-5.5, 0.0];
    file.occluders.push(OccluderSpec::stretch("tunnel", OccluderKind::Tunnel, "east", 100.0, 200.0));
    let err = RoadNetwork::build(&file).unwrap_err();
    let message = err.to_string();
    assert!(message.contains("road \"west\" is 5.5 m long, too short"), "{message}");

    let mut file = scenarios::crossing();
    file.occluders.push(OccluderSpec::stretch("tunnel", OccluderKind::Tunnel, "east", 100.0, 200.0));
    file.occluders.push(OccluderSpec::stretch("t2", OccluderKind::Tunnel, "ring", 0.0, 1.0));
    let NetworkError::Invalid(problems) = RoadNetwork::build(&file).unwrap_err() else { panic!() };
    assert_eq!(problems.len(), 2);
    assert!(matches!(problems[0], NetworkProblem::OccluderOutsideRoad { .. }));
    assert!(matches!(problems[1], NetworkProblem::UnknownRoad { .. }));

    let err = RoadNetwork::from_json_str(
        r#"{"format": "kpl-road-network", "version": 1, "nodes": [], "roads": [], "extra": 1}"#,
    )
    .unwrap_err();
    assert!(err.to_string().contains("unknown field `extra`"), "{err}");
    let err =
        RoadNetwork::from_json_str(r#"{"format": "x", "version": 2, "nodes": [], "roads": []}"#).unwrap_err();
    assert_eq!(err.to_string().lines().count(), 4, "{err}"); // header + format + version + empty
}

/// A solid line forbids the change from the lane it is drawn on to that side only, between lanes
/// of one road going one way; it survives the JSON form.
#[test]
fn solid_lines_forbid_lane_changes_one_way() {
    let mut file = NetworkFile::new();
    file.add_node("w", [0.0, 0.0]);
    file.add_node("e", [300.0, 0.0]);
    file.add_node("n", [300.0, 300.0]);
    // Looking from w to e: one lane west, then three lanes east; the left eastbound lane may not
    // change right (the middle one may change left: a line solid on one side only), and a solid
    // line between the directions.
    file.add_road("we", "w", "e", Vec::new());
    let mut west = LaneSpec::new(3.5, LaneDirection::Backward);
    west.solid_left = true;
    let mut east = [0, 1, 2].map(|_| LaneSpec::new(3.5, LaneDirection::Forward));
    east[0].solid_right = true;
    east[0].solid_left = true;
    file.roads[0].lanes = vec![west, east[0].clone(), east[1].clone(), east[2].clone()];
    file.add_road("en", "e", "n", Vec::new());
    let text = serde_json::to_string_pretty(&file).unwrap();
    assert!(text.contains("\"solid_right\": true") && !text.contains("\"solid_right\": false"), "{text}");
    let net = RoadNetwork::from_json_str(&text).unwrap();
    let lanes: Vec<_> = net.road_by_name("we").unwrap().lanes.iter().map(|l| l.lane).collect();
    let at = |lane| net.lane(lane).path.point_at(100.0);
    let crosses = |from, to| net.crosses_solid_line(lanes[from], lanes[to], at(lanes[to]));
    assert!(crosses(1, 2), "left eastbound lane to the right");
    assert!(!crosses(2, 1), "middle to the left: the line is on the other lane's side");
    assert!(!crosses(2, 3) && !crosses(3, 2), "dashed between middle and right");
    assert!(crosses(1, 3), "across two lanes, the first line solid");
    assert!(!crosses(1, 0) && !crosses(0, 1), "the other direction is no lane change");
    assert!(!crosses(1, 1), "no change");
    let other = net.road_by_name("en").unwrap().lanes[0].lane;
    assert!(!net.crosses_solid_line(lanes[1], other, at(other)), "another road");
    let (left, right) = (net.lane(lanes[1]), net.lane(lanes[3]));
    assert_eq!((left.may_change_left, left.may_change_right), (false, false));
    assert_eq!((right.may_change_left, right.may_change_right), (true, true));
}

#[test]
fn curved_roads_and_multi_lane_roads_connect() {
    // A bent two-lane-each-way road into a crossing with a one-lane-each-way road.
    let mut file = NetworkFile::new();
    file.add_node("a", [-100.0, -50.0]);
    file.add_node("c", [0.0, 0.0]);
    file.add_node("b", [100.0, 0.0]);
    file.add_node("d", [0.0, 100.0]);
    file.add_road("bent", "a", "c", vec![[-60.0, 0.0]]);
    file.roads[0].lanes = vec![
        LaneSpec::new(3.0, LaneDirection::Backward),
        LaneSpec::new(3.0, LaneDirection::Backward),
        LaneSpec::new(3.0, LaneDirection::Forward),
        LaneSpec::new(3.0, LaneDirection::Forward),
    ];
    file.add_road("cb", "c", "b", Vec::new());
    file.add_road("cd", "c", "d", Vec::new());
    let net = RoadNetwork::build(&file).unwrap();
    let bent = net.road_by_name("bent").unwrap();
    assert_eq!(bent.width_m, 12.0);
    assert_eq!(net.node_by_name("c").unwrap().radius_m, 7.5);
    // Each of the two incoming lanes of `bent` reaches both other roads.
    for lane in &bent.lanes[2..] {
        assert_eq!(net.lane(lane.lane).successors.len(), 2);
    }
    // The one incoming lane of `cb` joins only the rightmost of the two lanes of `bent` it meets.
    let cb_in = net.road_by_name("cb").unwrap().lanes[0].lane;
    let to_bent: Vec<_> = net
        .lane(cb_in)
        .successors
        .iter()
        .map(|&c| match net.lane(c).kind {
            LaneKind::Connector { to, .. } => to,
            LaneKind::Road { .. } => c,
        })
        .filter(|&to| net.place_of(to) == Place::Road { road: bent.id, lane: 0 })
        .collect();
    assert_eq!(to_bent.len(), 1, "enters the rightmost westbound lane of `bent`");
    // Lanes follow the bend: the outer left lane's centre is 4.5 m left of the centre line
    // everywhere (on the inside of the bend, where the distance is exact).
    let lane = net.lane(bent.lanes[0].lane);
    for k in 0..20 {
        let p = lane.path.point_at(lane.path.length() * f64::from(k) / 19.0);
        let projection = bent.centerline.project(p);
        assert!((projection.lateral - 4.5).abs() < 1e-6, "{p:?} {projection:?}");
    }
}

fn arb_point_near(net: &RoadNetwork) -> impl Strategy<Value = [f64; 2]> {
    let (lo, hi) = net.bounds();
    (lo[0]..hi[0], lo[1]..hi[1]).prop_map(|(x, y)| [x, y])
}

fn check_snapping(net: &RoadNetwork, p: [f64; 2], heading: Option<f64>) -> Result<(), TestCaseError> {
    let Some(snapped) = net.snap_to_lane(p, heading) else {
        return Ok(());
    };
    prop_assert!(net.on_road(snapped.point), "snapped point {:?} is off the road", snapped.point);
    prop_assert!(kpl_roads::geom::dist(p, snapped.point) <= net.snap_radius_m() + 1e-9);
    prop_assert!((kpl_roads::geom::dist(p, snapped.point) - snapped.lateral_m.abs()).abs() < 1e-6);
    let lane = net.lane(snapped.lane);
    prop_assert!(kpl_roads::geom::dist(lane.path.point_at(snapped.offset_m), snapped.point) < 1e-6);
    // Idempotent: snapping the snapped point (with or without the lane's heading) stays there.
    let again = net.snap_to_lane(snapped.point, Some(snapped.heading)).unwrap();
    prop_assert!(kpl_roads::geom::dist(again.point, snapped.point) < 1e-6, "{snapped:?} -> {again:?}");
    prop_assert!(kpl_roads::geom::heading_difference(again.heading, snapped.heading) < 1e-6);
    prop_assert!(again.lateral_m.abs() < 1e-6);
    let again = net.snap_to_lane(snapped.point, None).unwrap();
    prop_assert!(kpl_roads::geom::dist(again.point, snapped.point) < 1e-6, "{snapped:?} -> {again:?}");
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn snapping_in_the_crossing_is_on_road_and_idempotent(
        p in arb_point_near(&CROSSING),
        heading in proptest::option::of(-4.0..4.0f64),
    ) {
        check_snapping(&CROSSING, p, heading)?;
    }

    #[test]
    fn snapping_in_a_town_is_on_road_and_idempotent(
        p in arb_point_near(&TOWN),
        heading in proptest::option::of(-4.0..4.0f64),
    ) {
        check_snapping(&TOWN, p, heading)?;
    }

    #[test]
    fn on_road_agrees_with_a_brute_force_scan(p in arb_point_near(&TOWN)) {
        let net = &*TOWN;
        let brute = net.roads().iter().any(|r| {
            let proj = r.centerline.project(p);
            proj.lateral.abs() <= r.width_m / 2.0
        }) || net.nodes().iter().any(|n| kpl_roads::geom::point_in_polygon(p, &n.area))
            || net.lanes().iter().any(|l| l.path.project(p).lateral.abs() <= l.width_m / 2.0);
        prop_assert_eq!(net.on_road(p), brute);
    }

    #[test]
    fn snapping_agrees_with_a_brute_force_scan(p in arb_point_near(&TOWN)) {
        let net = &*TOWN;
        let brute = net
            .lanes()
            .iter()
            .map(|l| l.path.project(p).lateral.abs())
            .fold(f64::INFINITY, f64::min);
        match net.snap_to_lane(p, None) {
            Some(s) => prop_assert!((s.lateral_m.abs() - brute).abs() < 1e-9),
            None => prop_assert!(brute > net.snap_radius_m()),
        }
    }
}

/// Random small networks: nodes anywhere, roads between any two (loops too), any lane layout.
fn arb_network_file() -> impl Strategy<Value = NetworkFile> {
    let node = (-200.0..200.0f64, -200.0..200.0f64, proptest::option::of(0.0..30.0f64));
    let lane = (0.5..6.0f64, any::<bool>());
    let road = (
        0..6usize,
        0..6usize,
        proptest::collection::vec((-250.0..250.0f64, -250.0..250.0f64), 0..3),
        proptest::collection::vec(lane, 1..4),
    );
    (proptest::collection::vec(node, 2..6), proptest::collection::vec(road, 1..8)).prop_map(
        |(nodes, roads)| {
            let mut file = NetworkFile::new();
            for (i, &(x, y, radius)) in nodes.iter().enumerate() {
                file.add_node(&format!("n{i}"), [x, y]);
                file.nodes[i].radius_m = radius;
            }
            for (i, (from, to, via, lanes)) in roads.into_iter().enumerate() {
                let (from, to) = (from % nodes.len(), to % nodes.len());
                file.add_road(
                    &format!("r{i}"),
                    &format!("n{from}"),
                    &format!("n{to}"),
                    via.into_iter().map(|(x, y)| [x, y]).collect(),
                );
                file.roads[i].lanes = lanes
                    .into_iter()
                    .map(|(width_m, forward)| {
                        LaneSpec::new(
                            width_m,
                            if forward { LaneDirection::Forward } else { LaneDirection::Backward },
                        )
                    })
                    .collect();
            }
            file
        },
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    /// Any file either builds or is rejected with problems; a built network answers every query
    /// without panicking (kpl-sim's tests run traffic on such networks).
    #[test]
    fn random_networks_build_or_are_rejected_and_never_panic(
        file in arb_network_file(),
        points in proptest::collection::vec((-300.0..300.0f64, -300.0..300.0f64, -4.0..4.0f64), 10),
    ) {
        let net = match RoadNetwork::build(&file) {
            Ok(net) => net,
            Err(NetworkError::Invalid(problems)) => {
                prop_assert!(!problems.is_empty());
                return Ok(());
            }
            Err(other) => return Err(TestCaseError::fail(format!("unexpected error {other}"))),
        };
        for (x, y, heading) in points {
            let _ = net.on_road([x, y]);
            let _ = net.occluders().at([x, y]);
            check_snapping(&net, [x, y], Some(heading))?;
            if let Some(snapped) = net.snap_to_lane([x, y], Some(heading)) {
                for h in net.advance(&snapped, 150.0, 32) {
                    prop_assert!(h.travelled_m <= 150.0 + 1e-9);
                    prop_assert_eq!(h.route[0], snapped.lane);
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1000))]

    /// `lane_centre_at` (a snap that looks only within the tolerance) answers what snapping
    /// without a heading answers within the tolerance, on points on lane centres (as an earlier
    /// snap leaves them), a little off them, and anywhere.
    #[test]
    fn lane_centre_at_is_snapping_within_the_tolerance(
        lane in 0usize..10_000,
        along in 0.0..1.0f64,
        off in prop_oneof![Just(0.0), -0.08..0.08f64, -5.0..5.0f64],
        p in arb_point_near(&TOWN),
        anywhere in proptest::bool::weighted(0.2),
    ) {
        let net = &*TOWN;
        let lane = &net.lanes()[lane % net.lanes().len()];
        let at = net.lane_position(lane.id, along * lane.path.length());
        let left = [-at.heading.sin(), at.heading.cos()];
        let q = if anywhere { p } else { [at.point[0] + off * left[0], at.point[1] + off * left[1]] };
        let expected = net.snap_to_lane(q, None).filter(|s| s.lateral_m.abs() < 0.05).map(|s| s.lane);
        prop_assert_eq!(net.lane_centre_at(q, 0.05), expected, "at {:?}", q);
    }
}
