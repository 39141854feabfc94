//! Multi-sensor anchoring: two simulated UAVs watch the bridge scenario's road with overlapping
//! camera footprints (UAV a sees x <= 60 m, UAV b x >= 20 m), each with its own tracker (its own
//! noise, missed detections and percept ids `a1`, `b1`, ...). Two link specifications, one per UAV,
//! feed the same world objects through `anchor.kalman`, whose filter is the world object's memory:
//! in the overlap a world object is linked from both UAVs' percepts and the filter fuses them.
//!
//! Shown: every car that crosses from one footprint into the other keeps its world object,
//! on-road object and car symbols (no car's symbols change in the whole run, over 3 seeds); the
//! Kalman estimate's position error against the ground truth is below the raw percepts' (both
//! are printed; docs/anchoring.md reports them).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // tests fail loudly

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use kpl_anchor::{AnchorConfig, Anchoring, Snapshot};
use kpl_core::{Record, Time, Value};
use kpl_sim::camera::Camera;
use kpl_sim::tracker::{Tracker, TrackerConfig, View};
use kpl_sim::traffic::Traffic;
use kpl_sim::{CarId, Params, PerceptSource, RoadNetwork};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const SPEC: &str = r#"
type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
type WorldObject symbol wo { pos: vec2, vel: vec2 }
type OnRoadObject : WorldObject symbol oo { road: int, lane_offset: float }
type Car : OnRoadObject symbol co { }

source uav_a : list<VisionPercept> = sim.uav_tracker(scenario: "bridge")
source uav_b : list<VisionPercept> = sim.uav_tracker(scenario: "bridge")

// One link specification per UAV into the same world objects; a percept of the other UAV near a
// world object (and moving alike) is that world object.
link a_world : VisionPercept -> WorldObject via anchor.kalman(position_noise_m: 1.0) {
  input       uav_a
  establish   eventually[1s, inf] true
  reestablish eventually[0, 1s] (xydist(from.pos, to.pos) < 10.0 and norm(from.vel - to.vel) < 5.0)
  maintain    true
}
link b_world : VisionPercept -> WorldObject via anchor.kalman(position_noise_m: 1.0) {
  input       uav_b
  establish   eventually[1s, inf] true
  reestablish eventually[0, 1s] (xydist(from.pos, to.pos) < 10.0 and norm(from.vel - to.vel) < 5.0)
  maintain    true
}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "bridge") {
  establish   eventually[1s, inf] always[0, 1s] (from.measured and on_road(from.pos))
  reestablish eventually[0, 1s] (from.measured and xydist(from.pos, to.pos) < 10.0)
  maintain    always eventually[0, 10s] (from.measured and always[0, 1s] (from.measured -> on_road(from.pos)))
}
link onroad_car : OnRoadObject -> Car via anchor.copy {
  establish   eventually[2s, inf] always[0, 2s] (from.measured and norm(from.vel) > 2.0)
  reestablish eventually[0, 1s] (from.measured and xydist(from.pos, to.pos) < 5.0)
  maintain    true
}
predict WorldObject = constant_velocity
predict OnRoadObject = along_roads(scenario: "bridge")
forget after 10s
forget VisionPercept after 600ms
"#;

/// The x range each UAV's camera sees.
const FOOTPRINTS: [(&str, f64, f64); 2] = [("a", f64::NEG_INFINITY, 60.0), ("b", 20.0, f64::INFINITY)];
const TYPES: [&str; 3] = ["WorldObject", "OnRoadObject", "Car"];

fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// What one run showed.
#[derive(Debug, Default)]
struct Outcome {
    /// (car, type) -> the distinct symbols anchored to it, in order.
    symbols: BTreeMap<(CarId, &'static str), Vec<Arc<str>>>,
    /// Cars seen by UAV a only, later by b only (or the reverse), with a car symbol at both ends.
    handovers: BTreeSet<CarId>,
    /// Steps at which some world object was linked from both UAVs' percepts.
    fused: usize,
    /// Sums of squared position errors against the truth, and counts: raw percepts, Kalman.
    raw: (f64, usize),
    kalman: (f64, usize),
}

fn run(seed: u64) -> Outcome {
    let network = Arc::new(RoadNetwork::build(&kpl_roads::scenarios::bridge()).unwrap());
    let params = Params {
        scenario: "bridge".into(),
        seed,
        n_cars: 6,
        noise_m: 1.0,
        dropout: 0.05,
        false_positive_rate: 0.0,
        ..Params::default()
    };
    let mut traffic = Traffic::new(&network, params.n_cars, params.speed_sd, rng(seed, 1)).unwrap();
    let mut trackers: Vec<Tracker> =
        (0..2).map(|k| Tracker::new(TrackerConfig::from_params(&params), rng(seed, 2 + k))).collect();
    let spec = kpl_std::check_text(SPEC).unwrap();
    let mut config = AnchorConfig::default();
    config.networks.insert("bridge", network.clone());
    let mut engine = Anchoring::from_spec(&spec, config).unwrap();

    let mut outcome = Outcome::default();
    // car -> (seen by a only at some point, then by b only) and the reverse.
    let mut regions: BTreeMap<CarId, Vec<&str>> = BTreeMap::new();
    let dt = 0.1;
    // Each UAV's footprint is applied below (cars outside it lose their track); the camera sees
    // the rest, the bridge hides what is under it.
    let camera = Camera::Everything;
    for i in 0..1200 {
        let time: Time = i * 100_000;
        if i > 0 {
            let left = traffic.step(&network, dt);
            for tracker in &mut trackers {
                tracker.forget(&left);
            }
        }
        let cars = traffic.states(&network);
        let truth: BTreeMap<CarId, [f64; 2]> = cars.iter().map(|c| (c.id, c.pos)).collect();
        let mut snapshots = Vec::new();
        let mut seen: Vec<(CarId, String, [f64; 2])> = Vec::new();
        for (k, (prefix, lo, hi)) in FOOTPRINTS.iter().enumerate() {
            let (inside, outside): (Vec<_>, Vec<_>) =
                cars.iter().cloned().partition(|c| (*lo..=*hi).contains(&c.pos[0]));
            // A car out of view loses its track: it gets a new id when it comes back.
            trackers[k].forget(&outside.iter().map(|c| c.id).collect::<Vec<_>>());
            let view = View { camera: &camera, occluders: network.occluders(), elapsed: time };
            let (percepts, _) = trackers[k].observe(&network, &view, &inside, dt);
            let mut items = Vec::new();
            for p in &percepts {
                let id: Arc<str> = Arc::from(format!("{prefix}{}", p.id.0));
                let mut record: Record = p.to_record();
                record.id = Some(id.clone());
                items.push(Value::Record(Arc::new(record)));
                if let PerceptSource::Car(car) = p.source {
                    seen.push((car, id.to_string(), p.pos));
                }
            }
            snapshots.push(Value::List(items.into()));
        }
        let inputs = [
            Snapshot { source: "uav_a", ty: "VisionPercept", objects: &snapshots[0] },
            Snapshot { source: "uav_b", ty: "VisionPercept", objects: &snapshots[1] },
        ];
        let output = engine.step(time, &inputs).unwrap();
        assert!(output.warnings.is_empty(), "{:?}", output.warnings);

        let by_uav =
            |car: CarId, prefix: &str| seen.iter().any(|(c, id, _)| *c == car && id.starts_with(prefix));
        for (car, id, pos) in &seen {
            let p = truth[car];
            outcome.raw.0 += (pos[0] - p[0]).powi(2) + (pos[1] - p[1]).powi(2);
            outcome.raw.1 += 1;
            let chain = engine.chain(id);
            for (ty, symbol) in &chain {
                let Some(ty) = TYPES.iter().find(|t| **t == &**ty) else { continue };
                let list = outcome.symbols.entry((*car, ty)).or_default();
                if list.last() != Some(symbol) {
                    list.push(symbol.clone());
                }
            }
            // The world object's estimate, once per car and step.
            if id.starts_with('a') || !by_uav(*car, "a") {
                if let Some((_, wo)) = chain.first() {
                    let view = engine.object("WorldObject", wo).unwrap();
                    if view.measured {
                        let e = view.state.as_record().unwrap().get("pos").unwrap().as_vec2().unwrap();
                        outcome.kalman.0 += (e[0] - p[0]).powi(2) + (e[1] - p[1]).powi(2);
                        outcome.kalman.1 += 1;
                    }
                }
            }
            let has_car = chain.len() == TYPES.len();
            let region = match (by_uav(*car, "a"), by_uav(*car, "b")) {
                (true, false) => "a",
                (false, true) => "b",
                _ => "both",
            };
            if has_car && region != "both" {
                let list = regions.entry(*car).or_default();
                if list.last() != Some(&region) {
                    list.push(region);
                }
            }
        }
        outcome.fused +=
            engine.objects().iter().filter(|v| &*v.ty == "WorldObject" && v.from.len() == 2).count();
    }
    for (car, list) in regions {
        if list.len() >= 2 {
            outcome.handovers.insert(car);
        }
    }
    outcome
}

fn rms((sum, n): (f64, usize)) -> f64 {
    (sum / n.max(1) as f64).sqrt()
}

#[test]
fn cars_keep_their_symbols_from_one_uav_to_the_other() {
    let (mut raw, mut kalman) = ((0.0, 0), (0.0, 0));
    let mut handovers = 0;
    for seed in [1, 2, 3] {
        let outcome = run(seed);
        for ty in TYPES {
            let switched: Vec<_> =
                outcome.symbols.iter().filter(|((_, t), list)| *t == ty && list.len() > 1).collect();
            assert!(switched.is_empty(), "seed {seed}: {ty} symbols changed: {switched:?}");
        }
        assert!(outcome.handovers.len() >= 2, "seed {seed}: only {:?} handed over", outcome.handovers);
        assert!(outcome.fused > 0, "seed {seed}: no world object was ever linked from both UAVs");
        handovers += outcome.handovers.len();
        raw = (raw.0 + outcome.raw.0, raw.1 + outcome.raw.1);
        kalman = (kalman.0 + outcome.kalman.0, kalman.1 + outcome.kalman.1);
    }
    let (raw, kalman) = (rms(raw), rms(kalman));
    eprintln!(
        "two UAVs, 3 seeds x 120 s: {handovers} cars handed over with their symbols; position error against the truth: raw percepts {raw:.3} m RMS, Kalman world objects {kalman:.3} m RMS"
    );
    assert!(kalman < raw, "Kalman {kalman:.3} m is not below the raw percepts' {raw:.3} m");
}
