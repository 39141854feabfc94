//! The shipped SUMO specs (`specs/traffic/sumo_*.kpl`) anchoring recorded SUMO traffic, run
//! through the simulated tracker straight into the engine: cars standing in queues stay on their
//! own lane (snapping keeps lane continuity), cars waiting at red lights get a car symbol without
//! having to drive first, every moving car gets its car symbol within 3 s, symbols of cars that left the map are not driven off it, and identity
//! switches stay rare.
#![allow(clippy::unwrap_used, reason = "tests")]
#![allow(clippy::print_stderr, reason = "tests say when an oracle is missing and what they measured")]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use kpl_anchor::views::Status;
use kpl_core::Value;
use kpl_sim::{CarId, PerceptSource};
use kpl_std::driver::{IdentityScore, SimDriver};

fn traffic_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic")
}

fn driver(name: &str) -> SimDriver {
    driver_of(&std::fs::read_to_string(traffic_dir().join(name)).unwrap())
}

fn driver_of(text: &str) -> SimDriver {
    let spec = kpl_std::check_text(text).unwrap();
    SimDriver::from_spec_in(&spec, Default::default(), &traffic_dir()).unwrap()
}

/// What a run of a spec showed.
#[derive(Debug, Default)]
struct Outcome {
    score: IdentityScore,
    /// Frames in which a detected car stood still (below 0.5 m/s) on a road lane, and those in
    /// which its on-road object was on another road (for SUMO: the other direction, or a
    /// crossing street).
    standing: usize,
    standing_elsewhere: usize,
    /// The same, snapping the percept as before lane continuity (nearest lane, heading of the
    /// noisy velocity above 0.5 m/s).
    standing_elsewhere_before: usize,
    /// Issue 9's measure, per moving car: seconds from its first percept while moving (above
    /// 2 m/s) to its first car symbol, leaving out the frames in which it was hidden (under an
    /// occluder or out of view), with the car's name; a car that had its symbol before it moved
    /// counts 0.
    moving_car_symbol_delay_s: Vec<(f64, String)>,
    /// Cars that stood still from their first percept on for at least 5 s, and those of them that
    /// had no car symbol after those 5 s.
    queued_from_start: BTreeSet<CarId>,
    queued_without_symbol: BTreeSet<CarId>,
    /// On-road objects and cars predicted while off the network's bounding box.
    predicted_off_map: usize,
}

fn run(name: &str) -> Outcome {
    run_driver(driver(name))
}

fn run_driver(mut driver: SimDriver) -> Outcome {
    let network = driver.sources[0].sim.network().clone();
    let (lo, hi) = network.bounds();
    let mut outcome = Outcome::default();
    let mut first_seen: BTreeMap<CarId, (f64, bool)> = BTreeMap::new();
    let mut has_car: BTreeSet<CarId> = BTreeSet::new();
    let mut moved: BTreeSet<CarId> = BTreeSet::new();
    // Per car seen moving: (when first seen moving, seconds hidden since).
    let mut moving_since: BTreeMap<CarId, (f64, f64)> = BTreeMap::new();
    let mut last_t: Option<f64> = None;
    driver
        .run_until(i64::MAX / 4, |step| {
            outcome.score.record(&step);
            let t = step.time as f64 / 1e6;
            let (_, frame) = step.frames[0];
            let truth: BTreeMap<CarId, &kpl_sim::CarState> = frame.cars.iter().map(|c| (c.id, c)).collect();
            let dt = last_t.map_or(0.0, |last| t - last);
            last_t = Some(t);
            for (car, seen) in frame.cars.iter().zip(&frame.visibility) {
                if let Some((_, hidden)) = moving_since.get_mut(&car.id) {
                    if !seen.in_view() {
                        *hidden += dt;
                    }
                } else if *seen == kpl_sim::Visibility::Detected && car.speed_mps > 2.0 {
                    moving_since.insert(car.id, (t, 0.0));
                    if has_car.contains(&car.id) {
                        outcome.moving_car_symbol_delay_s.push((0.0, car.name.to_string()));
                    }
                }
            }
            // Cars that moved since their first percept.
            for car in &frame.cars {
                if car.speed_mps > 2.0 && first_seen.contains_key(&car.id) {
                    moved.insert(car.id);
                }
            }
            for percept in &frame.percepts {
                let PerceptSource::Car(car) = percept.source else { continue };
                let state = truth[&car];
                let chain = step.engine.chain(&percept.id.to_string());
                let standing = state.speed_mps < 0.5;
                let entry = first_seen.entry(car).or_insert((t, standing));
                if chain.iter().any(|(ty, _)| &**ty == "Car")
                    && has_car.insert(car)
                    && let Some((since, hidden)) = moving_since.get(&car)
                {
                    outcome.moving_car_symbol_delay_s.push((t - since - hidden, state.name.to_string()));
                }
                if entry.1 && !moved.contains(&car) && t - entry.0 >= 5.0 {
                    outcome.queued_from_start.insert(car);
                    if !has_car.contains(&car) {
                        outcome.queued_without_symbol.insert(car);
                    }
                }
                let (Some(road), true) = (state.road(), standing) else { continue };
                let Some((_, symbol)) = chain.iter().find(|(ty, _)| &**ty == "OnRoadObject") else {
                    continue;
                };
                let Some(object) = step.engine.object("OnRoadObject", symbol) else { continue };
                let Some(Value::Int(oo_road)) = object.state.field("road") else { continue };
                outcome.standing += 1;
                if oo_road != i64::from(road.0) && oo_road >= 0 {
                    outcome.standing_elsewhere += 1;
                }
                // The same percept snapped as before this fix: the nearest lane, with the heading
                // of its noisy velocity above 0.5 m/s.
                let old_heading = (kpl_roads::geom::norm(percept.vel) >= 0.5)
                    .then(|| kpl_roads::geom::heading_of(percept.vel));
                if network
                    .snap_to_lane(percept.pos, old_heading)
                    .and_then(|s| s.road())
                    .is_some_and(|r| r != road)
                {
                    outcome.standing_elsewhere_before += 1;
                }
            }
            for object in step.engine.objects() {
                // Objects predicted along the roads (constant-velocity world objects may drift).
                if object.status == Status::Predicted
                    && (&*object.ty == "OnRoadObject" || &*object.ty == "Car")
                    && let Some(Value::Vec2(p)) = object.state.field("pos")
                    && (p[0] < lo[0] - 1.0 || p[1] < lo[1] - 1.0 || p[0] > hi[0] + 1.0 || p[1] > hi[1] + 1.0)
                {
                    outcome.predicted_off_map += 1;
                }
            }
        })
        .unwrap();
    outcome
}

#[test]
fn sumo_grid_keeps_standing_cars_on_their_lane_and_gives_queued_cars_a_symbol() {
    let outcome = run("sumo_grid.kpl");
    let score = &outcome.score;
    let cars = score.detected.len();
    assert!(cars >= 150, "{cars} vehicles seen");
    // The grid has queues at red lights: many frames of standing cars. With 1 m of noise and lane
    // centres 3.2 m apart a single position is ambiguous; lane continuity keeps all but a few
    // frames on the car's own road, where snapping each percept on its own (the old way) put one
    // in fifteen elsewhere.
    let (standing, now, before) =
        (outcome.standing, outcome.standing_elsewhere, outcome.standing_elsewhere_before);
    assert!(standing > 2_000, "{standing} frames of standing cars");
    assert!(now * 100 <= standing, "{now} of {standing} standing frames snapped off their road");
    assert!(now * 10 <= before, "{now} against {before} before lane continuity");
    let (median, late, max) = moving_cars_get_their_symbol_within_3_s("sumo_grid.kpl", &outcome);
    assert_eq!(outcome.predicted_off_map, 0, "nothing is predicted beyond the border");
    // Identity: world objects and cars switch rarely.
    for ty in ["WorldObject", "Car"] {
        let switches = score.switches(ty);
        assert!(
            switches * 10 <= score.cars_with(ty),
            "{ty}: {switches} switches over {} cars",
            score.cars_with(ty)
        );
    }
    eprintln!(
        "grid: {cars} vehicles, with a world object {} on-road object {} car {}; switches WorldObject {} OnRoadObject {} Car {}; standing frames {standing}, \
         off their road {now} (before {before}); moving cars' car symbol delay median {median:.1} s, over 3 s {late}, max {max:.1} s",
        score.cars_with("WorldObject"),
        score.cars_with("OnRoadObject"),
        score.cars_with("Car"),
        score.switches("WorldObject"),
        score.switches("OnRoadObject"),
        score.switches("Car"),
    );
}

/// Issue 9's target: every moving car has its car symbol within 3 s of its first percept (the
/// time it was hidden left out: a car that drives under a bridge in its first seconds cannot be
/// anchored there). Returns the median, the number over 3 s (0) and the longest, and prints the
/// distribution.
fn moving_cars_get_their_symbol_within_3_s(spec: &str, outcome: &Outcome) -> (f64, usize, f64) {
    let mut delays = outcome.moving_car_symbol_delay_s.clone();
    delays.sort_by(|a, b| a.0.total_cmp(&b.0));
    assert!(delays.len() >= 80, "{spec}: only {} moving cars got a car symbol", delays.len());
    let quantile = |q: f64| delays[((delays.len() - 1) as f64 * q) as usize].0;
    let late: Vec<&(f64, String)> = delays.iter().filter(|(d, _)| *d > 3.0).collect();
    eprintln!(
        "{spec}: moving cars' car symbol after their first percept (hidden time left out), {} cars: \
         median {:.1} s, 90 % {:.1} s, 99 % {:.1} s, longest {:.1} s",
        delays.len(),
        quantile(0.5),
        quantile(0.9),
        quantile(0.99),
        quantile(1.0)
    );
    assert!(late.is_empty(), "{spec}: cars that waited more than 3 s for a car symbol: {late:?}");
    (quantile(0.5), late.len(), quantile(1.0))
}

/// The UAV arrives over the town after two minutes: the cars queued at red lights then are seen
/// standing from their first percept, and get their car symbol within 5 s, before they move
/// (they used to wait until they drove: up to 55 s).
#[test]
fn cars_queued_when_the_camera_arrives_get_a_car_symbol_before_they_move() {
    let text = std::fs::read_to_string(traffic_dir().join("sumo_grid.kpl")).unwrap().replace(
        "  seed: 7,\n",
        "  seed: 7,\n  footprint_size_m: [440.0, 440.0],\n  \
         camera_path: [[0.0, -5000.0, -5000.0], [120.0, -5000.0, -5000.0], [120.1, 180.0, 180.0]],\n",
    );
    let outcome = run_driver(driver_of(&text));
    eprintln!("camera arriving: {} cars queued from their first percept", outcome.queued_from_start.len());
    assert!(
        outcome.queued_from_start.len() >= 3,
        "{} cars started in a queue",
        outcome.queued_from_start.len()
    );
    assert!(outcome.queued_without_symbol.is_empty(), "{:?} waited", outcome.queued_without_symbol);
}

#[test]
fn sumo_highway_and_random_network_anchor_their_traffic() {
    for spec in ["sumo_highway.kpl", "sumo_random.kpl"] {
        let outcome = run(spec);
        let score = &outcome.score;
        let cars = score.detected.len();
        assert!(cars >= 80, "{spec}: {cars} vehicles seen");
        assert!(
            score.cars_with("Car") * 100 >= cars * 95,
            "{spec}: {} of {cars} got a car symbol",
            score.cars_with("Car")
        );
        assert!(outcome.standing_elsewhere * 100 <= outcome.standing.max(100), "{spec}");
        moving_cars_get_their_symbol_within_3_s(spec, &outcome);
        assert_eq!(outcome.predicted_off_map, 0, "{spec}");
        for ty in ["WorldObject", "Car"] {
            let switches = score.switches(ty);
            assert!(switches * 10 <= score.cars_with(ty), "{spec} {ty}: {switches} switches");
        }
        eprintln!(
            "{spec}: {cars} vehicles, with a world object {} on-road object {} car {}; switches WorldObject {} OnRoadObject {} Car {}",
            score.cars_with("WorldObject"),
            score.cars_with("OnRoadObject"),
            score.cars_with("Car"),
            score.switches("WorldObject"),
            score.switches("OnRoadObject"),
            score.switches("Car")
        );
    }
}
