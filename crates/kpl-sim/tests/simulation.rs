//! The simulated world over time: determinism, traffic plausibility, tracker statistics, the
//! bridge gap and percept ids. Every run is seeded, so the statistical checks are not flaky; their
//! tolerances are several standard errors wide so that they hold for any seed, not just these.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;

use kpl_core::Value;
use kpl_sim::{CarId, Frame, Params, PerceptId, PerceptSource, Place, RoadNetwork, UavTrackerSim};

fn run(params: &Params, seconds: f64) -> (Arc<RoadNetwork>, Vec<Frame>) {
    let network = Arc::new(params.load_network().unwrap());
    let mut sim = UavTrackerSim::new(params, network.clone(), 0).unwrap();
    let frames = sim.frames_until((seconds * 1e6) as i64);
    (network, frames)
}

fn mean_sd(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

#[test]
fn same_seed_same_frames_and_tracker_settings_do_not_change_the_traffic() {
    let params = Params { scenario: "crossing".into(), seed: 11, n_cars: 12, ..Params::default() };
    let (_, a) = run(&params, 30.0);
    let (_, b) = run(&params, 30.0);
    assert_eq!(a, b);
    assert_eq!(a.len(), 301);

    let (_, other_seed) = run(&Params { seed: 12, ..params.clone() }, 30.0);
    assert_ne!(a[100].cars, other_seed[100].cars);

    let noisier = Params { noise_m: 3.0, dropout: 0.3, false_positive_rate: 2.0, ..params.clone() };
    let (_, c) = run(&noisier, 30.0);
    for (x, y) in a.iter().zip(&c) {
        assert_eq!(x.cars, y.cars, "frame {}", x.index);
    }
    assert_ne!(a[50].percepts, c[50].percepts);
}

#[test]
fn frames_follow_the_rate_from_the_start_time() {
    let params = Params { scenario: "bridge".into(), rate_hz: 4.0, ..Params::default() };
    let network = Arc::new(params.load_network().unwrap());
    let mut sim = UavTrackerSim::new(&params, network, 5_000_000).unwrap();
    assert_eq!(sim.next_frame_time(), 5_000_000);
    let frames = sim.frames_until(6_000_000);
    let times: Vec<i64> = frames.iter().map(|f| f.time).collect();
    assert_eq!(times, vec![5_000_000, 5_250_000, 5_500_000, 5_750_000, 6_000_000]);
    assert!(sim.frames_until(6_100_000).is_empty());
    assert_eq!(sim.next_frame().index, 5);
}

#[test]
fn cars_drive_plausibly_along_their_lanes() {
    let params = Params {
        scenario: "grid_town".into(),
        grid_blocks_x: 4,
        grid_blocks_y: 4,
        n_cars: 120,
        seed: 5,
        ..Params::default()
    };
    let (net, frames) = run(&params, 120.0);
    let mut speeds = Vec::new();
    let mut last_pos: HashMap<CarId, [f64; 2]> = HashMap::new();
    let mut ids_seen = std::collections::BTreeSet::new();
    let mut full_frames = 0;
    for frame in &frames {
        // A car that leaves is replaced at once unless every entry is blocked by a queue.
        assert!(frame.cars.len() <= 120);
        full_frames += usize::from(frame.cars.len() == 120);
        for car in &frame.cars {
            ids_seen.insert(car.id);
            assert!(net.on_road(car.pos), "{car:?} is off the road");
            let lane = net.lane(car.lane.unwrap());
            assert!(car.speed_mps >= 0.0 && car.speed_mps <= lane.speed_limit_mps * 1.5 + 1e-9, "{car:?}");
            // Lane keeping: within half a metre of the lane centre.
            let centre = lane.path.point_at(car.offset_m);
            assert!(kpl_roads::geom::dist(centre, car.pos) <= 0.5 + 1e-9);
            if let Some(previous) = last_pos.insert(car.id, car.pos) {
                // Moves at most its speed's worth (plus the lateral wander) per frame: no jumps.
                assert!(kpl_roads::geom::dist(previous, car.pos) <= 0.1 * 21.0 + 0.2, "{car:?} jumped");
            }
            speeds.push(car.speed_mps);
        }
    }
    assert!(full_frames * 100 >= frames.len() * 99, "{full_frames} of {} frames had every car", frames.len());
    let (mean_speed, _) = mean_sd(&speeds);
    assert!((6.0..14.0).contains(&mean_speed), "mean speed {mean_speed} m/s in a town at 13.9 m/s");
    assert!(ids_seen.len() > 120, "cars left the town and new ones entered");
    // Cars turn: some were seen inside crossings.
    assert!(frames.iter().flat_map(|f| &f.cars).any(|c| matches!(c.place, Some(Place::Crossing { .. }))));
}

#[test]
fn cars_keep_their_distance_on_a_lane() {
    let params = Params {
        scenario: "grid_town".into(),
        grid_blocks_x: 3,
        grid_blocks_y: 3,
        n_cars: 150,
        seed: 9,
        ..Params::default()
    };
    let (net, frames) = run(&params, 120.0);
    let mut violations = 0;
    let mut pairs = 0;
    for frame in &frames {
        let mut by_lane: BTreeMap<u32, Vec<(f64, f64)>> = BTreeMap::new();
        for car in &frame.cars {
            by_lane.entry(car.lane.unwrap().0).or_default().push((car.offset_m, car.length_m));
        }
        for (lane, mut cars) in by_lane {
            if !matches!(net.lanes()[lane as usize].kind, kpl_roads::LaneKind::Road { .. }) {
                continue; // connectors cross each other inside crossings
            }
            cars.sort_by(|a, b| a.0.total_cmp(&b.0));
            for w in cars.windows(2) {
                pairs += 1;
                if w[1].0 - w[1].1 < w[0].0 {
                    violations += 1;
                }
            }
        }
    }
    assert!(pairs > 1000, "the test saw enough following cars ({pairs})");
    assert_eq!(violations, 0, "overlapping pairs of {pairs}");
}

#[test]
fn noise_and_dropout_rates_match_the_parameters() {
    let params = Params {
        scenario: "grid_town".into(),
        grid_blocks_x: 3,
        grid_blocks_y: 3,
        n_cars: 60,
        seed: 21,
        noise_m: 1.5,
        vel_noise_mps: 0.8,
        dropout: 0.1,
        false_positive_rate: 0.0,
        max_gap_frames: 1000,
        ..Params::default()
    };
    let (_, frames) = run(&params, 300.0);
    let mut dx = Vec::new();
    let mut dy = Vec::new();
    let mut dvx = Vec::new();
    let mut visible = 0usize;
    let mut detected = 0usize;
    for frame in &frames {
        let truth: HashMap<CarId, &kpl_sim::CarState> = frame.cars.iter().map(|c| (c.id, c)).collect();
        visible += frame.cars.len(); // no occluders in a grid town
        for p in &frame.percepts {
            let PerceptSource::Car(car) = p.source else { panic!("no false positives asked for") };
            let car = truth[&car];
            dx.push(p.pos[0] - car.pos[0]);
            dy.push(p.pos[1] - car.pos[1]);
            dvx.push(p.vel[0] - car.vel[0]);
            detected += 1;
        }
    }
    let n = dx.len() as f64;
    assert!(n > 100_000.0);
    for (name, values, sd) in [("x", &dx, 1.5), ("y", &dy, 1.5), ("vx", &dvx, 0.8)] {
        let (mean, measured_sd) = mean_sd(values);
        assert!(mean.abs() < 5.0 * sd / n.sqrt(), "{name}: mean {mean}");
        assert!((measured_sd / sd - 1.0).abs() < 0.02, "{name}: sd {measured_sd}, wanted {sd}");
    }
    let rate = 1.0 - detected as f64 / visible as f64;
    let standard_error = (0.1 * 0.9 / visible as f64).sqrt();
    assert!((rate - 0.1).abs() < 5.0 * standard_error, "dropout rate {rate}");
}

#[test]
fn false_positives_are_short_lived_and_half_on_the_road() {
    let params = Params {
        scenario: "crossing".into(),
        n_cars: 0,
        seed: 4,
        noise_m: 0.0,
        false_positive_rate: 5.0,
        false_positive_on_road: 0.3,
        false_positive_duration_s: 0.8,
        ..Params::default()
    };
    let (net, frames) = run(&params, 1000.0);
    let mut lifetimes: BTreeMap<PerceptId, u32> = BTreeMap::new();
    let mut on_road: BTreeMap<PerceptId, bool> = BTreeMap::new();
    for frame in &frames {
        for p in &frame.percepts {
            assert_eq!(p.source, PerceptSource::FalsePositive);
            *lifetimes.entry(p.id).or_default() += 1;
            on_road.entry(p.id).or_insert_with(|| net.on_road(p.pos));
        }
    }
    let n = lifetimes.len() as f64;
    // A Poisson count over 1000 s at 5/s: 5000 +- 71.
    assert!((n - 5000.0).abs() < 5.0 * 5000f64.sqrt(), "{n} false positives");
    let mean_frames = lifetimes.values().map(|&f| f64::from(f)).sum::<f64>() / n;
    // Geometric lifetimes with mean 8 frames have a standard deviation of about 7.5 frames.
    assert!((mean_frames - 8.0).abs() < 5.0 * 7.5 / n.sqrt(), "mean lifetime {mean_frames} frames");
    let fraction = on_road.values().filter(|&&b| b).count() as f64 / n;
    assert!((fraction - 0.3).abs() < 5.0 * (0.3f64 * 0.7 / n).sqrt(), "on-road fraction {fraction}");
}

/// Per car, its detections as (frame index, percept id).
fn detections_by_car(frames: &[Frame]) -> BTreeMap<CarId, Vec<(u64, PerceptId)>> {
    let mut by_car: BTreeMap<CarId, Vec<(u64, PerceptId)>> = BTreeMap::new();
    for frame in frames {
        for p in &frame.percepts {
            if let PerceptSource::Car(car) = p.source {
                by_car.entry(car).or_default().push((frame.index, p.id));
            }
        }
    }
    by_car
}

#[test]
fn a_car_under_the_bridge_is_lost_for_about_two_seconds_and_comes_back_with_a_new_id() {
    for dropout in [0.0, 0.05] {
        let params = Params {
            scenario: "bridge".into(),
            seed: 2,
            dropout,
            false_positive_rate: 0.0,
            ..Params::default()
        };
        let (net, frames) = run(&params, 120.0);
        let main = net.road_by_name("main").unwrap().id;
        let mut passages = 0;
        for (car, detections) in detections_by_car(&frames) {
            // Frames in which this car was under the bridge.
            let hidden: Vec<u64> = frames
                .iter()
                .filter(|f| {
                    f.cars.iter().any(|c| {
                        c.id == car
                            && matches!(c.place, Some(Place::Road { road, .. }) if road == main)
                            && net.occluders().hiding(c.pos, Some(main)).is_some()
                    })
                })
                .map(|f| f.index)
                .collect();
            let Some((&first_hidden, &last_hidden)) = hidden.first().zip(hidden.last()) else { continue };
            if first_hidden == 0 || last_hidden + 1 == frames.len() as u64 {
                continue; // the passage is cut by the start or the end of the run
            }
            passages += 1;
            let hidden_s = (last_hidden - first_hidden + 1) as f64 / 10.0;
            assert!((1.6..=2.5).contains(&hidden_s), "{car:?}: hidden {hidden_s} s");
            let before = detections.iter().rev().find(|d| d.0 < first_hidden).unwrap();
            let after = detections.iter().find(|d| d.0 > last_hidden).unwrap();
            let gap_s = (after.0 - before.0) as f64 / 10.0;
            // Lost about 2 s (the hidden time, plus a frame or two when the frames around the
            // bridge happen to drop out).
            assert!(gap_s >= hidden_s && gap_s <= hidden_s + 0.5, "{car:?}: percept gap {gap_s} s");
            assert_ne!(before.1, after.1, "{car:?} must get a new percept id after the bridge");
            assert!(after.1 > before.1, "ids are handed out in increasing order");
            assert!(detections.iter().all(|d| d.0 < first_hidden || d.0 > last_hidden), "not seen under it");
        }
        assert!(passages >= 2, "the run must contain passages under the bridge ({passages})");
    }
}

#[test]
fn percept_ids_are_never_reused_and_change_exactly_after_long_gaps() {
    let params = Params {
        scenario: "crossing".into(),
        n_cars: 10,
        seed: 8,
        dropout: 0.4,
        max_gap_frames: 2,
        false_positive_rate: 3.0,
        ..Params::default()
    };
    let (_, frames) = run(&params, 120.0);
    // Each id has one source, and the frames an id appears in have gaps of at most
    // max_gap_frames missing frames.
    let mut source_of: HashMap<PerceptId, PerceptSource> = HashMap::new();
    let mut last_frame_of: HashMap<PerceptId, u64> = HashMap::new();
    let mut highest_first_seen = 0;
    for frame in &frames {
        let mut in_frame = std::collections::HashSet::new();
        for p in &frame.percepts {
            assert!(in_frame.insert(p.id), "{} twice in one frame", p.id);
            assert_eq!(*source_of.entry(p.id).or_insert(p.source), p.source, "{} changed source", p.id);
            if let Some(last) = last_frame_of.insert(p.id, frame.index) {
                assert!(frame.index - last <= 3, "{} came back after {} frames", p.id, frame.index - last);
            } else {
                assert!(p.id.0 > highest_first_seen, "{} is not new", p.id);
                highest_first_seen = p.id.0;
            }
        }
    }
    // Per car: the id changes exactly when more than max_gap_frames frames were missed.
    let mut changes = 0;
    let mut keeps = 0;
    for detections in detections_by_car(&frames).values() {
        for w in detections.windows(2) {
            let missed = w[1].0 - w[0].0 - 1;
            if missed > 2 {
                assert_ne!(w[0].1, w[1].1);
                changes += 1;
            } else {
                assert_eq!(w[0].1, w[1].1);
                keeps += 1;
            }
        }
    }
    assert!(changes > 50 && keeps > 1000, "the run exercised both cases ({changes}, {keeps})");
}

#[test]
fn percepts_become_kpl_records() {
    let params =
        Params { scenario: "crossing".into(), n_cars: 3, seed: 1, dropout: 0.0, ..Params::default() };
    let (_, frames) = run(&params, 0.0);
    let percept = &frames[0].percepts[0];
    let value = percept.to_value();
    let record = value.as_record().unwrap();
    assert_eq!(record.id.as_deref(), Some("vp1"));
    let names: Vec<&str> = record.fields.iter().map(|(n, _)| &**n).collect();
    assert_eq!(names, vec!["pos", "vel", "size"]);
    assert_eq!(value.field("pos"), Some(Value::Vec2(percept.pos)));
    assert_eq!(value.field("size").and_then(|v| v.as_f64()), Some(percept.size_m));
    assert_eq!(
        value.to_json(),
        serde_json::json!({ "id": "vp1", "pos": percept.pos, "vel": percept.vel, "size": percept.size_m })
    );
    let car = frames[0].cars[0].to_value();
    assert_eq!(car.field("id").and_then(|v| v.as_str().map(str::to_string)), Some("car1".to_string()));
    assert!(car.field("road").and_then(|v| v.as_i64()).is_some());
}

#[test]
fn parameters_have_defaults_docs_and_clear_errors() {
    assert_eq!(Params::from_json(serde_json::json!({})).unwrap(), Params::default());
    let described = Params::describe();
    let serialized = serde_json::to_value(Params::default()).unwrap();
    let keys: Vec<&String> = serialized.as_object().unwrap().keys().collect();
    assert_eq!(described.len(), keys.len());
    for info in &described {
        assert!(serialized.get(info.name).is_some(), "{} is documented but not a field", info.name);
        assert!(!info.doc.is_empty() && !info.doc.contains('\n'), "{}", info.name);
        assert!(
            ["int", "float", "bool", "string", "list<float>", "list<list<float>>", "list<list<list<float>>>"]
                .contains(&info.ty)
        );
    }
    assert_eq!(described.iter().find(|p| p.name == "rate_hz").unwrap().default, "10.0");

    let err = Params::from_json(serde_json::json!({ "noise": 1.0 })).unwrap_err().to_string();
    assert!(err.contains("unknown field `noise`"), "{err}");
    let err = Params::from_json(serde_json::json!({ "dropout": 1.5 })).unwrap_err().to_string();
    assert_eq!(err, "parameter `dropout` must be a probability between 0 and 1, found 1.5");
    let err = Params::from_json(serde_json::json!({ "scenario": "moon" })).unwrap_err().to_string();
    assert!(err.contains("unknown scenario \"moon\"") && err.contains("bridge"), "{err}");
    let err = Params::from_json(serde_json::json!({ "rate_hz": 0 })).unwrap_err().to_string();
    assert!(err.contains("rate_hz"), "{err}");
    let err = Params::from_json(serde_json::json!({ "seed": -1 })).unwrap_err().to_string();
    assert!(err.contains("invalid value"), "{err}");

    let seed = Value::Int(7);
    let lifetime = Value::Duration(250_000);
    let scenario = Value::str("bridge");
    let params = Params::from_args([
        ("seed", &seed),
        ("false_positive_duration_s", &lifetime),
        ("scenario", &scenario),
    ])
    .unwrap();
    assert_eq!(
        (params.seed, params.false_positive_duration_s, params.scenario.as_str()),
        (7, 0.25, "bridge")
    );

    let too_many = Params { n_cars: 1000, ..Params::default() };
    let network = Arc::new(too_many.load_network().unwrap());
    let err = UavTrackerSim::new(&too_many, network, 0).unwrap_err().to_string();
    assert!(err.contains("1000 cars do not fit"), "{err}");
    let missing = Params { network_file: Some("/nonexistent/net.json".into()), ..Params::default() };
    assert!(missing.load_network().unwrap_err().to_string().contains("/nonexistent/net.json"));
}

#[test]
fn the_parameter_table_in_the_docs_matches_the_code() {
    let docs =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/simulator.md")).unwrap();
    let rows: Vec<&str> = docs.lines().filter(|l| l.starts_with("| `")).collect();
    let described = Params::describe();
    for info in &described {
        let row = format!("| `{}` | {} | `{}` | {} |", info.name, info.ty, info.default, info.doc);
        assert!(rows.contains(&row.as_str()), "docs/simulator.md should have the row\n{row}");
    }
    let param_rows =
        rows.iter().filter(|r| described.iter().any(|p| r.starts_with(&format!("| `{}` |", p.name))));
    assert_eq!(param_rows.count(), described.len());
}

#[test]
fn a_town_sized_for_ten_thousand_cars_holds_them() {
    let size = kpl_roads::scenarios::GridTownSize::for_cars(10_000);
    assert_eq!((size.blocks_x, size.blocks_y), (30, 30));
    let params = Params {
        scenario: "grid_town".into(),
        grid_blocks_x: size.blocks_x,
        grid_blocks_y: size.blocks_y,
        n_cars: 10_000,
        dropout: 0.1,
        ..Params::default()
    };
    let (_, frames) = run(&params, 1.0);
    assert_eq!(frames.len(), 11);
    let counts: Vec<usize> = frames.iter().map(|f| f.cars.len()).collect();
    // Cars leaving the town are replaced as soon as an entry lane is free.
    assert!(counts.iter().all(|&n| (9_990..=10_000).contains(&n)), "{counts:?}");
    let detected =
        frames.iter().map(|f| f.percepts.iter().filter(|p| p.source != PerceptSource::FalsePositive).count());
    assert!(detected.clone().all(|n| (8_800..=9_200).contains(&n)), "{:?}", detected.collect::<Vec<_>>());
}

/// Simulated traffic drives on SUMO networks too: along the lanes and through the connections
/// SUMO gives, never off the road, leaving and entering at the border.
#[test]
fn simulated_cars_drive_on_sumo_networks() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic/sumo");
    for name in ["grid", "random", "highway"] {
        let params = Params {
            network_file: Some(dir.join(name).join("net.xml.gz").to_string_lossy().into_owned()),
            n_cars: 20,
            seed: 3,
            ..Params::default()
        };
        let (net, frames) = run(&params, 120.0);
        let mut names = std::collections::BTreeSet::new();
        for frame in &frames {
            for car in &frame.cars {
                assert!(net.on_road(car.pos), "{name}: {car:?} is off the road");
                let lane = net.lane(car.lane.unwrap());
                assert!(!lane.turnaround, "{name}: no U-turns");
                names.insert(car.name.clone());
            }
        }
        assert!(names.len() > 20, "{name}: cars left and new ones entered ({})", names.len());
    }
}
