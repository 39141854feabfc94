//! Recorded traffic under the simulated tracker: SUMO FCD as SUMO writes it (front bumpers,
//! compass angles, vehicle types), plain JSON lines and CSV, interpolation between recorded
//! times, malformed input skipped and reported, hostile files refused; the camera footprint and
//! occluders; SUMO's vehicle sizes checked against SUMO itself, and a scenario regenerated with
//! SUMO and read back (both with the Python of `scripts/test`).
#![allow(clippy::unwrap_used, reason = "tests")]
#![allow(clippy::print_stderr, reason = "tests say when an oracle is missing and what they measured")]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use kpl_roads::RoadNetwork;
use kpl_sim::recorded::{Playback, VehicleTypes, compass_to_heading, sumo_class_size};
use kpl_sim::{Params, PerceptSource, UavTrackerSim, Visibility};

fn sumo_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic/sumo")
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-sim-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn grid() -> Arc<RoadNetwork> {
    Arc::new(RoadNetwork::load(&sumo_dir().join("grid/net.xml.gz")).unwrap())
}

/// `name="value"` of an XML line.
fn attribute(line: &str, name: &str) -> String {
    let start = line.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
    line[start..].split('"').next().unwrap().to_string()
}

#[test]
fn fcd_positions_are_front_bumpers_and_angles_compass_headings() {
    let text = kpl_roads::load::read_text(&sumo_dir().join("grid/fcd.xml.gz")).unwrap();
    let line = text.lines().find(|l| l.trim_start().starts_with("<vehicle ")).unwrap();
    let (x, y, angle) = (
        attribute(line, "x").parse::<f64>().unwrap(),
        attribute(line, "y").parse::<f64>().unwrap(),
        attribute(line, "angle").parse::<f64>().unwrap(),
    );
    let net = grid();
    let mut playback =
        Playback::open(&sumo_dir().join("grid/fcd.xml.gz"), VehicleTypes::builtin(), net.clone()).unwrap();
    let (cars, _) = playback.states_at(0);
    let car = &cars[0];
    assert_eq!(&*car.name, attribute(line, "id").as_str(), "recorded ids are kept");
    assert_eq!((car.length_m, car.width_m), (5.0, 1.8), "SUMO's default passenger car");
    // 0 degrees is north, 90 east: heading (counter-clockwise from east) = 90 - angle.
    assert!((car.heading - compass_to_heading(angle)).abs() < 1e-12);
    let front =
        kpl_roads::geom::add(car.pos, kpl_roads::geom::scale(kpl_roads::geom::unit(car.heading), 2.5));
    assert!((front[0] - x).abs() < 1e-9 && (front[1] - y).abs() < 1e-9, "{front:?} vs {x}, {y}");
    // The lane SUMO names, and the centre on it.
    let lane = net.lane(car.lane.unwrap());
    assert_eq!(lane.name, attribute(line, "lane"));
    assert!(lane.path.project(car.pos).lateral.abs() < 0.01);
    assert!(playback.take_problems().is_empty());
    assert!((compass_to_heading(0.0) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert!((compass_to_heading(90.0)).abs() < 1e-12);
    assert!((compass_to_heading(180.0) - 1.5 * std::f64::consts::PI).abs() < 1e-12);
}

#[test]
fn recorded_vehicles_are_on_their_lanes_and_sized_by_their_types() {
    let highway = Arc::new(RoadNetwork::load(&sumo_dir().join("highway/net.xml.gz")).unwrap());
    let types = VehicleTypes::read(&sumo_dir().join("highway/vtypes.xml")).unwrap();
    assert_eq!(types.size("truck"), Some((12.0, 2.5)));
    assert_eq!(types.size("car"), Some((4.6, 1.8)));
    let mut playback =
        Playback::open(&sumo_dir().join("highway/fcd.xml.gz"), types, highway.clone()).unwrap();
    let mut by_length: BTreeMap<String, usize> = BTreeMap::new();
    let mut frames = 0;
    let mut elapsed = 0;
    while !playback.finished(elapsed) {
        let (cars, _) = playback.states_at(elapsed);
        for car in &cars {
            *by_length.entry(format!("{:.1}", car.length_m)).or_default() += 1;
            assert!(highway.on_road(car.pos), "{car:?}");
            let lane = highway.lane(car.lane.unwrap());
            // Within half the 3.2 m lane spacing: a lane change between two recorded times is
            // interpolated across.
            assert!(
                lane.path.project(car.pos).lateral.abs() <= 1.6 + 1e-9,
                "{car:?} off its lane {}",
                lane.name
            );
            assert!(car.speed_mps <= 36.0 * 1.3, "{car:?}");
        }
        frames += 1;
        elapsed += 100_000;
    }
    assert_eq!(frames, 2396, "240 s at 10 Hz, from the first recorded time 0.5 s to 239.5 s");
    assert_eq!(by_length.keys().collect::<Vec<_>>(), vec!["12.0", "4.6"]);
    assert!(playback.take_problems().is_empty());
    // Without the vehicle types, the unknown types are reported once each and get SUMO's default.
    let mut playback =
        Playback::open(&sumo_dir().join("highway/fcd.xml.gz"), VehicleTypes::builtin(), highway).unwrap();
    for t in 0..600 {
        playback.states_at(t * 100_000);
    }
    let problems = playback.take_problems();
    assert_eq!(problems.len(), 2, "{problems:?}");
    assert!(problems.iter().all(|p| p.error.contains("is not defined") && p.error.contains("5 m x 1.8 m")));
}

#[test]
fn rows_are_interpolated_between_recorded_times() {
    let dir = temp_dir("rows");
    // Two vehicles recorded once a second: `a` drives east at 10 m/s, `b` stands, then leaves.
    let jsonl = "{\"time\": 0, \"id\": \"a\", \"x\": 0, \"y\": 0}\n\
                 {\"time\": 0, \"id\": \"b\", \"x\": 50, \"y\": 5, \"length\": 12, \"width\": 2.5, \"heading\": 1.5}\n\
                 {\"time\": 1, \"id\": \"a\", \"x\": 10, \"y\": 0}\n\
                 {\"time\": 1, \"id\": \"b\", \"x\": 50, \"y\": 5}\n\
                 {\"time\": 2, \"id\": \"a\", \"x\": 20, \"y\": 0, \"colour\": \"red\"}\n\
                 {\"time\": 1.5, \"id\": \"a\", \"x\": 15, \"y\": 0}\n\
                 {\"time\": 3, \"id\": \"a\", \"x\": \"far\", \"y\": 0}\n\
                 not json\n";
    let csv =
        "time,id,x,y\n0,a,0,0\n0,b,50,5\n1,a,10,0\n1,b,50,5\n2,a,20,0\n1.5,a,15,0\n3,a,far,0\n3,a,1,2,3\n";
    let net = Arc::new(RoadNetwork::build(&kpl_roads::scenarios::crossing()).unwrap());
    for (name, text) in [("rows.jsonl", jsonl), ("rows.csv", csv)] {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let mut playback = Playback::open(&path, VehicleTypes::builtin(), net.clone()).unwrap();
        let (cars, gone) = playback.states_at(300_000);
        assert!(gone.is_empty());
        assert_eq!(cars.len(), 2, "{name}");
        let a = cars.iter().find(|c| &*c.name == "a").unwrap();
        assert!((a.pos[0] - 3.0).abs() < 1e-9 && a.pos[1].abs() < 1e-9, "{name}: {a:?}");
        assert!((a.vel[0] - 10.0).abs() < 1e-9 && a.heading.abs() < 1e-9, "{name}: motion gives the heading");
        let b = cars.iter().find(|c| &*c.name == "b").unwrap();
        if name.ends_with(".jsonl") {
            assert_eq!((b.length_m, b.width_m, b.heading), (12.0, 2.5, 1.5));
        }
        let (cars, gone) = playback.states_at(1_500_000);
        assert_eq!(cars.len(), 1, "{name}: `b` is not recorded after 1 s");
        assert_eq!(gone.len(), 1);
        assert!((cars[0].pos[0] - 15.0).abs() < 1e-9);
        let (cars, _) = playback.states_at(2_000_000);
        assert_eq!(cars.len(), 1);
        assert!(playback.finished(2_100_000));
        let problems = playback.take_problems();
        let text: Vec<String> = problems.iter().map(|p| format!("{}: {}", p.location, p.error)).collect();
        assert!(text.iter().any(|p| p.contains("time goes backwards")), "{name}: {text:?}");
        assert!(text.iter().any(|p| p.contains("`x` and `y` must be numbers")), "{name}: {text:?}");
        if name.ends_with(".jsonl") {
            assert!(text.iter().any(|p| p.contains("unknown field `colour`")), "{text:?}");
            assert!(text.iter().any(|p| p.starts_with("line 8: not a JSON object")), "{text:?}");
        } else {
            assert!(text.iter().any(|p| p.contains("5 cells where the header has 4")), "{text:?}");
        }
    }
    std::fs::write(dir.join("bad.csv"), "when,who,x,y\n0,a,0,0\n").unwrap();
    let err =
        Playback::open(&dir.join("bad.csv"), VehicleTypes::builtin(), net.clone()).unwrap_err().to_string();
    assert!(err.contains("lacks a column `time`"), "{err}");
    std::fs::write(dir.join("empty.jsonl"), "").unwrap();
    let err = Playback::open(&dir.join("empty.jsonl"), VehicleTypes::builtin(), net.clone())
        .unwrap_err()
        .to_string();
    assert!(err.contains("empty"), "{err}");
    assert!(Playback::open(&dir, VehicleTypes::builtin(), net.clone()).is_err(), "a directory");
    // A file that is one endless line ends with an error naming the line, not with memory
    // filling up.
    if Path::new("/dev/zero").exists() {
        let err =
            Playback::open(Path::new("/dev/zero"), VehicleTypes::builtin(), net).unwrap_err().to_string();
        assert!(err.contains("its header (line 1) is longer than 1 MiB; the recording ends here"), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A vehicle twice at one time is counted as a problem, with where; the first entry is kept and
/// the second skipped (SUMO writes each vehicle once per timestep; two files pasted together do not).
#[test]
fn a_vehicle_twice_in_one_timestep_is_counted_and_the_first_kept() {
    let dir = temp_dir("twice");
    let fcd = r#"<?xml version="1.0" encoding="UTF-8"?>
<fcd-export>
    <timestep time="0.00">
        <vehicle id="a" x="0.00" y="0.00" angle="90.00" type="DEFAULT_VEHTYPE" speed="10.00" pos="5.00" lane="e_0"/>
        <vehicle id="b" x="50.00" y="5.00" angle="90.00" type="DEFAULT_VEHTYPE" speed="0.00" pos="5.00" lane="e_0"/>
        <vehicle id="a" x="99.00" y="99.00" angle="90.00" type="DEFAULT_VEHTYPE" speed="10.00" pos="5.00" lane="e_0"/>
    </timestep>
    <timestep time="1.00">
        <vehicle id="a" x="10.00" y="0.00" angle="90.00" type="DEFAULT_VEHTYPE" speed="10.00" pos="15.00" lane="e_0"/>
        <vehicle id="a" x="77.00" y="0.00" angle="90.00" type="DEFAULT_VEHTYPE" speed="10.00" pos="15.00" lane="e_0"/>
        <vehicle id="a" x="78.00" y="0.00" angle="90.00" type="DEFAULT_VEHTYPE" speed="10.00" pos="15.00" lane="e_0"/>
    </timestep>
</fcd-export>
"#;
    let jsonl = "{\"time\": 0, \"id\": \"a\", \"x\": 0, \"y\": 0}\n\
                 {\"time\": 0, \"id\": \"b\", \"x\": 50, \"y\": 5}\n\
                 {\"time\": 0, \"id\": \"a\", \"x\": 99, \"y\": 99}\n\
                 {\"time\": 1, \"id\": \"a\", \"x\": 10, \"y\": 0}\n\
                 {\"time\": 1, \"id\": \"a\", \"x\": 77, \"y\": 0}\n\
                 {\"time\": 1, \"id\": \"a\", \"x\": 78, \"y\": 0}\n";
    let csv = "time,id,x,y\n0,a,0,0\n0,b,50,5\n0,a,99,99\n1,a,10,0\n1,a,77,0\n1,a,78,0\n";
    for (name, text) in [("twice.xml", fcd), ("twice.jsonl", jsonl), ("twice.csv", csv)] {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let (steps, problems) = kpl_sim::recorded::read_steps(&path, VehicleTypes::builtin()).unwrap();
        let ids: Vec<Vec<&str>> =
            steps.iter().map(|s| s.vehicles.iter().map(|v| &*v.name).collect()).collect();
        assert_eq!(ids, [vec!["a", "b"], vec!["a"]], "{name}");
        // The first entries are the ones kept (FCD's x is the front bumper: 2.5 m ahead of the centre).
        let first_x: Vec<f64> = steps.iter().map(|s| s.vehicles[0].pos[0]).collect();
        let offset = if name.ends_with(".xml") { -2.5 } else { 0.0 };
        assert_eq!(first_x, [offset, 10.0 + offset], "{name}");
        let twice: Vec<&kpl_sim::recorded::Problem> =
            problems.iter().filter(|p| p.error.contains("already in this timestep")).collect();
        assert_eq!(twice.len(), 3, "{name}: {problems:?}");
        assert!(twice.iter().all(|p| p.location.contains("vehicle \"a\"")), "{name}: {twice:?}");
        assert!(twice[0].error.contains("the first is kept"), "{name}: {twice:?}");
        if name.ends_with(".xml") {
            assert!(twice[0].location.starts_with("timestep 0.00"), "{twice:?}");
        } else {
            let line = if name.ends_with(".csv") { "line 4" } else { "line 3" };
            assert!(twice[0].location.starts_with(line), "{name}: {twice:?}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// XML that never closes a tag, and vehicle type files that are not XML, end in an error, not in
/// memory filling up.
#[test]
fn endless_xml_is_an_error() {
    let dir = temp_dir("endless-xml");
    let path = dir.join("endless.xml");
    let mut text = String::from("<fcd-export>\n<timestep time=\"0\">\n<vehicle id=\"");
    text.push_str(&"\n".repeat((1 << 20) + 10));
    std::fs::write(&path, &text).unwrap();
    let (steps, problems) = kpl_sim::recorded::read_steps(&path, VehicleTypes::builtin()).unwrap();
    assert!(steps.iter().all(|s| s.vehicles.is_empty()), "{steps:?}");
    assert!(problems.iter().any(|p| p.error.contains("more than 1 MiB without `<` or `>`")), "{problems:?}");
    if Path::new("/dev/zero").exists() {
        let err = VehicleTypes::read(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(err.contains("more than 1 MiB without `<` or `>`"), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A recording of one car driving east along the crossing's `west` and `east` roads at 10 m/s.
fn eastbound_recording(dir: &Path) -> PathBuf {
    let path = dir.join("east.jsonl");
    let rows: String = (0..=30)
        .map(|t| format!("{{\"time\": {t}, \"id\": \"car\", \"x\": {}, \"y\": -1.75}}\n", -145 + 10 * t))
        .collect();
    std::fs::write(&path, rows).unwrap();
    path
}

fn crossing_file(dir: &Path) -> PathBuf {
    let path = dir.join("crossing.json");
    RoadNetwork::build(&kpl_roads::scenarios::crossing()).unwrap().save(&path).unwrap();
    path
}

fn frames_of(params: &Params) -> Vec<kpl_sim::Frame> {
    let network = Arc::new(params.load_network().unwrap());
    let mut sim = UavTrackerSim::new(params, network, 0).unwrap();
    let frames = sim.frames_until(i64::MAX / 2);
    assert!(sim.finished());
    frames
}

#[test]
fn the_camera_sees_only_its_footprint_and_occluders_hide_what_is_under_them() {
    let dir = temp_dir("camera");
    let base = Params {
        network_file: Some(crossing_file(&dir).to_string_lossy().into_owned()),
        traffic_file: Some(eastbound_recording(&dir).to_string_lossy().into_owned()),
        dropout: 0.0,
        false_positive_rate: 2.0,
        ..Params::default()
    };
    // A fixed footprint over the crossing: the car is seen only between x = -50 and 50.
    let fixed = Params {
        footprint: vec![[-50.0, -50.0], [50.0, -50.0], [50.0, 50.0], [-50.0, 50.0]],
        ..base.clone()
    };
    let frames = frames_of(&fixed);
    assert_eq!(frames.len(), 301);
    let mut ids = Vec::new();
    for frame in &frames {
        let car = &frame.cars[0];
        let inside = car.pos[0].abs() <= 50.0;
        assert_eq!(frame.visibility[0], if inside { Visibility::Detected } else { Visibility::OutOfView });
        for p in &frame.percepts {
            assert!(
                p.pos[0].abs() < 55.0 && p.pos[1].abs() < 55.0,
                "nothing is seen outside the footprint: {p:?}"
            );
            if let PerceptSource::Car(_) = p.source {
                ids.push(p.id);
            }
        }
    }
    ids.dedup();
    assert_eq!(ids.len(), 1, "one track while in view");
    // A camera flying along with the car at 10 m/s sees it all the time.
    let flying = Params {
        footprint_size_m: vec![40.0, 40.0],
        camera_path: vec![[0.0, -140.0, 0.0], [30.0, 160.0, 0.0]],
        ..base.clone()
    };
    let frames = frames_of(&flying);
    assert!(frames.iter().all(|f| f.visibility[0] == Visibility::Detected));
    // A row of trees over the east road from x = 60 to 80 (param) and a bridge from a file that
    // hides only the north road: the car is hidden for 2 s and comes back with a new percept id.
    let occluders_file = dir.join("occluders.json");
    std::fs::write(
        &occluders_file,
        r#"{"occluders": [{"id": "bridge", "kind": "bridge", "polygon": [[-20, 20], [20, 20], [20, 30], [-20, 30]], "roads": ["north"]}]}"#,
    )
    .unwrap();
    let hidden = Params {
        occluders: vec![vec![[60.0, -5.0], [80.0, -5.0], [80.0, 5.0], [60.0, 5.0]]],
        occluders_file: Some(occluders_file.to_string_lossy().into_owned()),
        ..base
    };
    let network = Arc::new(hidden.load_network().unwrap());
    let mut sim = UavTrackerSim::new(&hidden, network, 0).unwrap();
    assert_eq!(sim.occluders().len(), 2);
    let frames = sim.frames_until(i64::MAX / 2);
    let occluded = frames.iter().filter(|f| f.visibility[0] == Visibility::Occluded).count();
    assert!((19..=21).contains(&occluded), "{occluded} frames under the trees");
    let mut ids: Vec<_> = frames
        .iter()
        .flat_map(|f| f.percepts.iter().filter(|p| p.source != PerceptSource::FalsePositive).map(|p| p.id))
        .collect();
    ids.dedup();
    assert_eq!(ids.len(), 2, "a new percept id after the trees");
    // Parameters that would be ignored are refused.
    let err = Params::from_json(serde_json::json!({"camera_path": [[0, 1, 2]]})).unwrap_err().to_string();
    assert!(err.contains("camera_path"), "{err}");
    let err =
        Params::from_json(serde_json::json!({"traffic_file": "x.jsonl", "n_cars": 9, "network_file": "n"}))
            .unwrap_err()
            .to_string();
    assert!(err.contains("`n_cars` has no effect"), "{err}");
    let err = Params::from_json(serde_json::json!({"traffic_file": "x.jsonl"})).unwrap_err().to_string();
    assert!(err.contains("needs `network_file`"), "{err}");
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

/// The sizes SUMO gives each vehicle class, asked of SUMO itself (TraCI) for a type that sets only
/// `vClass`, are the ones the FCD reader uses.
#[test]
fn vehicle_class_sizes_are_sumos() {
    let Some(python) = python() else { return };
    let classes = [
        "passenger",
        "private",
        "taxi",
        "bus",
        "coach",
        "delivery",
        "truck",
        "trailer",
        "motorcycle",
        "moped",
        "bicycle",
        "evehicle",
        "emergency",
        "army",
        "authority",
        "vip",
        "hov",
        "custom1",
        "custom2",
        "tram",
        "rail_urban",
        "rail",
        "rail_electric",
        "rail_fast",
        "ship",
        "pedestrian",
        "scooter",
        "container",
        "cable_car",
        "subway",
        "aircraft",
        "wheelchair",
        "drone",
    ];
    let dir = temp_dir("vclass");
    let types: String = classes.iter().map(|c| format!("<vType id=\"t_{c}\" vClass=\"{c}\"/>\n")).collect();
    std::fs::write(dir.join("types.rou.xml"), format!("<routes>\n{types}</routes>\n")).unwrap();
    let net = sumo_dir().join("highway/net.xml.gz");
    let code = format!(
        r#"
import os, sys, sumo
sys.path.append(os.path.join(sumo.SUMO_HOME, 'tools'))
import traci
traci.start([os.path.join(sumo.SUMO_HOME, 'bin', 'sumo'), '-n', {net:?}, '-r', {types:?}, '--no-step-log'])
for c in {classes:?}:
    print(c, traci.vehicletype.getLength('t_' + c), traci.vehicletype.getWidth('t_' + c))
traci.close()
"#,
        net = net.to_string_lossy(),
        types = dir.join("types.rou.xml").to_string_lossy(),
        classes = classes,
    );
    let output = std::process::Command::new(&python).args(["-c", &code]).output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let text = String::from_utf8(output.stdout).unwrap();
    let mut checked = 0;
    for line in text.lines() {
        let parts: Vec<&str> = line.split_whitespace().collect();
        if let [class, length, width] = parts[..] {
            let (length, width): (f64, f64) = (length.parse().unwrap(), width.parse().unwrap());
            assert_eq!(sumo_class_size(class), Some((length, width)), "{class}");
            checked += 1;
        }
    }
    assert_eq!(checked, classes.len(), "{text}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The truth functions of `scripts/sumo-scenarios.py` (which situations happened, from SUMO's own
/// floating car data) keep the examples written in their docstrings (Python's doctest).
#[test]
fn the_scenario_scripts_truth_keeps_its_examples() {
    let Some(python) = python() else { return };
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/sumo-scenarios.py");
    let output =
        std::process::Command::new(&python).args(["-m", "doctest", "-v"]).arg(&script).output().unwrap();
    let text = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{text}{}", String::from_utf8_lossy(&output.stderr));
    let passed = text.lines().find_map(|line| line.strip_suffix(" passed and 0 failed."));
    assert!(passed.is_some_and(|n| n.parse::<u32>().is_ok_and(|n| n >= 5)), "{text}");
}

/// SUMO of the test environment makes a grid scenario afresh with `scripts/sumo-scenarios.py`,
/// and it reads as the shipped one does: a network, and vehicles on its lanes (catches changes
/// of SUMO's formats).
#[test]
fn a_scenario_made_afresh_with_sumo_reads() {
    let Some(python) = python() else { return };
    let dir = temp_dir("regenerate");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/sumo-scenarios.py");
    let output = std::process::Command::new(&python)
        .arg(&script)
        .args(["--only", "grid", "--duration", "40", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let net = Arc::new(RoadNetwork::load(&dir.join("grid/net.xml.gz")).unwrap());
    assert_eq!(net.nodes().len(), grid().nodes().len());
    let mut playback =
        Playback::open(&dir.join("grid/fcd.xml.gz"), VehicleTypes::builtin(), net.clone()).unwrap();
    let mut seen = 0;
    for t in 0..390 {
        let (cars, _) = playback.states_at(t * 100_000);
        for car in &cars {
            assert!(net.on_road(car.pos), "{car:?}");
            assert!(car.lane.is_some(), "{car:?}");
            seen += 1;
        }
    }
    assert!(seen > 1000, "{seen} vehicle positions");
    assert!(playback.take_problems().is_empty());
    // The occluders made for it: two bridges, each across roads between the junctions (nothing
    // of a junction under them) and as wide as 2 s at the recording's median speed (SUMO's
    // town speed limit is 13.9 m/s).
    let occluders = kpl_roads::load::read_occluders(&dir.join("grid/occluders.json"), &net).unwrap();
    assert_eq!(occluders.len(), 2, "{occluders:?}");
    for occluder in &occluders {
        let xs = occluder.area.iter().map(|p| p[0]);
        let ys = occluder.area.iter().map(|p| p[1]);
        let width = |v: Vec<f64>| {
            v.iter().copied().fold(f64::MIN, f64::max) - v.iter().copied().fold(f64::MAX, f64::min)
        };
        let narrow = width(xs.collect()).min(width(ys.collect()));
        assert!((8.0..=2.0 * 13.9).contains(&narrow), "{} is {narrow} m wide", occluder.name);
        for node in net.nodes() {
            assert!(
                !kpl_roads::geom::point_in_polygon(node.pos, &occluder.area),
                "{node:?} under {}",
                occluder.name
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
