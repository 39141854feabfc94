//! Chronicles on the runtime, as `kpl run specs/traffic/sumo_chronicles.kpl` (and
//! `sumo_reckless.kpl`, `sumo_weaving.kpl`) run them: the spec's `overtake` (`reckless_overtake`,
//! `weaving`, `speed_swings`) chronicle is
//! recognised over the cars that anchoring makes of recorded SUMO traffic seen by the simulated
//! tracker, and every recognition it recorded is what the pure
//! recogniser (`kpl-chronicle`) gives on the events computed here, independently of the adapter,
//! from the recorded cars: the spec's predicates written out in Rust over the traffic relations'
//! implementations, a tuple's first value a change from false, a tuple that is gone false, for
//! every pair of cars (the adapter gates pairs by distance: that must change nothing), and the
//! recognitions of one situation merged as the adapter merges them.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use kpl_chronicle::merge::Merge;
use kpl_chronicle::model::{Chronicle, Event, Hold, Pattern, SourceId};
use kpl_chronicle::recognise::{Config, Recogniser};
use kpl_chronicle::stn::Constraint;
use kpl_core::{Time, Value};
use kpl_runtime::RunConfig;

const S: Time = 1_000_000;

fn traffic_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic")
}

fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-chronicle-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `(stream, valid, value)` of every recorded line.
fn read_samples(path: &Path) -> Vec<(String, Time, serde_json::Value)> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .map(|line| {
            let json: serde_json::Value = serde_json::from_str(line).unwrap();
            let stream = json["stream"].as_str().unwrap().to_string();
            (stream, json["valid"].as_i64().unwrap(), json["value"].clone())
        })
        .collect()
}

/// The spec's predicates over the relations' implementations (not its formulas).
struct Relations {
    functions: BTreeMap<String, kpl_mtl::Function>,
}

impl Relations {
    fn new() -> Relations {
        let functions =
            kpl_anchor::relations::functions().into_iter().map(|f| (f.name.to_string(), f)).collect();
        Relations { functions }
    }
    fn call(&self, name: &str, args: &[Value]) -> bool {
        matches!((self.functions[name].body)(args), Ok(Value::Bool(true)))
    }
    fn num(car: &Value, field: &str) -> f64 {
        let Value::Record(r) = car else { return f64::NAN };
        r.get(field).and_then(Value::as_f64).unwrap_or(f64::NAN)
    }
    /// The length of a `vec2` attribute.
    fn norm(car: &Value, field: &str) -> f64 {
        let Value::Record(r) = car else { return f64::NAN };
        r.get(field).and_then(Value::as_vec2).map_or(f64::NAN, |[x, y]| x.hypot(y))
    }
    fn flag(car: &Value, field: &str) -> bool {
        let Value::Record(r) = car else { return false };
        matches!(r.get(field), Some(Value::Bool(true)))
    }
    /// `behind(a, b) and close(a, b, 50.0) and a.measured and b.measured and a.speed > 3.0 and b.speed > 3.0`
    fn back(&self, a: &Value, b: &Value) -> bool {
        self.call("behind", &[a.clone(), b.clone()])
            && self.close(a, b)
            && Self::flag(a, "measured")
            && Self::flag(b, "measured")
            && Self::num(a, "speed") > 3.0
            && Self::num(b, "speed") > 3.0
    }
    /// `beside(a, b)`
    fn side(&self, a: &Value, b: &Value) -> bool {
        self.call("beside", &[a.clone(), b.clone()])
    }
    /// `in_front(a, b) and a.speed > 4.0 and b.speed > 4.0`
    fn front(&self, a: &Value, b: &Value) -> bool {
        self.call("in_front", &[a.clone(), b.clone()])
            && Self::num(a, "speed") > 4.0
            && Self::num(b, "speed") > 4.0
    }
    /// `abs(b.lane_offset) < 1.2`: the car keeps to its lane (it is not changing lanes).
    fn in_lane(b: &Value) -> bool {
        Self::num(b, "lane_offset").abs() < 1.2
    }
    /// `close(a, b, 50.0)`
    fn close(&self, a: &Value, b: &Value) -> bool {
        self.call("close", &[a.clone(), b.clone(), Value::Float(50.0)])
    }
    /// `same_lane(a, b) and in_front(a, b) and time_gap(b, a) < 1.0 and a.measured and
    /// b.measured and b.speed > 3.0`
    fn cut(&self, a: &Value, b: &Value) -> bool {
        let time_gap = (self.functions["time_gap"].body)(&[b.clone(), a.clone()]);
        self.call("same_lane", &[a.clone(), b.clone()])
            && self.call("in_front", &[a.clone(), b.clone()])
            && matches!(time_gap, Ok(Value::Float(t)) if t < 1.0)
            && Self::flag(a, "measured")
            && Self::flag(b, "measured")
            && Self::num(b, "speed") > 3.0
    }
}

/// The `overtake` chronicle of sumo_chronicles.kpl (within 60 s) or `reckless_overtake` of
/// sumo_reckless.kpl (within 30 s), for the pure recogniser: sources 0 to 3 are the predicates
/// `back`, `side`, `front` (`cut`) and the hold's `close`; with `b_holds_lane`, source 5 is
/// the reckless overtake's second hold, `b`'s [`Relations::in_lane`] from `side` to `cut`.
fn overtake_model(name: &str, within: Time, b_holds_lane: bool) -> Chronicle {
    let c = |later, earlier| Constraint { later, earlier, lo: Some(0), hi: Some(within) };
    let event = |source| Pattern { source: SourceId(source), args: vec![0, 1], value: true };
    Chronicle {
        name: name.into(),
        source: SourceId(4),
        params: 2,
        events: vec![event(0), event(1), event(2)],
        constraints: vec![c(1, 0), c(2, 1), c(2, 0)],
        holds: [Hold { source: SourceId(3), args: vec![0, 1], from: 0, to: 2 }]
            .into_iter()
            .chain(b_holds_lane.then(|| Hold { source: SourceId(5), args: vec![1], from: 1, to: 2 }))
            .collect(),
        nevers: vec![],
    }
}

type Recognised = BTreeSet<(Vec<String>, Vec<Time>, Time)>;

/// The cars of each state: `(valid, [(symbol, car)])`.
type Snapshots = Vec<(Time, Vec<(String, Value)>)>;

/// A predicate's events from one state to the next, in order: the tuples whose value changed
/// (absent before counts as false) and those true before and gone now (false).
fn changes<K: Ord + Clone>(last: &BTreeMap<K, bool>, now: &BTreeMap<K, bool>) -> Vec<(K, bool)> {
    let mut out: Vec<(K, bool)> = now
        .iter()
        .filter(|(k, value)| last.get(*k).copied().unwrap_or(false) != **value)
        .map(|(k, value)| (k.clone(), *value))
        .collect();
    out.extend(
        last.iter().filter(|(k, value)| **value && !now.contains_key(*k)).map(|(k, _)| (k.clone(), false)),
    );
    out.sort();
    out
}

/// The recognitions the pure recogniser gives on the events of the recorded car snapshots, with
/// `third` as the predicate of the third event (`front` or `cut`) and, with `single`, a predicate
/// of one car as source 5.
fn expected(
    snapshots: &[(Time, Vec<(String, Value)>)],
    model: Chronicle,
    third: fn(&Relations, &Value, &Value) -> bool,
    single: Option<fn(&Value) -> bool>,
) -> (Recognised, usize) {
    let relations = Relations::new();
    let mut recogniser: Recogniser<Arc<str>> =
        Recogniser::new(vec![model.compile().unwrap()], Config::default()).unwrap();
    let mut merge = Merge::new(recogniser.chronicles()[0].window);
    let mut previous: Vec<BTreeMap<(String, String), bool>> = vec![BTreeMap::new(); 4];
    let mut previous_single: BTreeMap<String, bool> = BTreeMap::new();
    let mut found = BTreeSet::new();
    let mut events_total = 0;
    for (valid, cars) in snapshots {
        let mut events = Vec::new();
        for (source, last) in previous.iter_mut().enumerate() {
            let mut now = BTreeMap::new();
            for (ida, a) in cars {
                for (idb, b) in cars {
                    if ida == idb {
                        continue;
                    }
                    let value = match source {
                        0 => relations.back(a, b),
                        1 => relations.side(a, b),
                        2 => third(&relations, a, b),
                        _ => relations.close(a, b),
                    };
                    now.insert((ida.clone(), idb.clone()), value);
                }
            }
            for ((a, b), value) in changes(last, &now) {
                let args = vec![Arc::from(a.as_str()), Arc::from(b.as_str())];
                events.push(Event { source: SourceId(source as u32), args, value, time: *valid });
            }
            *last = now;
        }
        if let Some(single) = single {
            let now: BTreeMap<String, bool> =
                cars.iter().map(|(id, car)| (id.clone(), single(car))).collect();
            for (id, value) in changes(&previous_single, &now) {
                events.push(Event {
                    source: SourceId(5),
                    args: vec![Arc::from(id.as_str())],
                    value,
                    time: *valid,
                });
            }
            previous_single = now;
        }
        events_total += events.len();
        for r in recogniser.step(*valid, events).unwrap() {
            // One report per situation, as the adapter sends them (`kpl_chronicle::merge`).
            if merge.admit(&r) {
                found.insert((r.binding.iter().map(|o| o.to_string()).collect(), r.times, r.valid_time));
            }
        }
    }
    (found, events_total)
}

/// Runs `SPEC.kpl` for `seconds` and returns the car snapshots its chronicle saw and the
/// recognitions of `stream` it recorded (binding, event times, valid time).
fn run_spec(spec_name: &str, stream: &str, seconds: Time) -> (Snapshots, Recognised) {
    run_spec_with(spec_name, stream, seconds, &["a", "b"])
}

/// [`run_spec`] for a chronicle whose parameters are `params`.
fn run_spec_with(spec_name: &str, stream: &str, seconds: Time, params: &[&str]) -> (Snapshots, Recognised) {
    let registry = kpl_std::registry();
    let text = std::fs::read_to_string(traffic_dir().join(format!("{spec_name}.kpl"))).unwrap();
    let spec = kpl_std::check_text(&text).unwrap();
    let out_dir = fresh_dir(&format!("{spec_name}-{stream}"));
    let config = RunConfig {
        duration: Some(seconds * S),
        seed: 3,
        out_dir: out_dir.clone(),
        spec_dir: traffic_dir(),
        spec_name: spec_name.into(),
        ..RunConfig::default()
    };
    let report = kpl_runtime::run(&spec, &registry, &config, None).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);

    // The cars the chronicle's process saw: every `onroad_car` sample (its one input).
    let car_type = spec.process("onroad_car").unwrap().output.clone().unwrap();
    let samples = read_samples(&out_dir.join(format!("{spec_name}/tracks.jsonl")));
    let mut snapshots = Vec::new();
    for (stream, valid, json) in samples.iter().filter(|(s, _, _)| s == "onroad_car") {
        let Value::List(items) = Value::from_json(json, &car_type).unwrap() else {
            panic!("{stream}: not a list")
        };
        let cars = items
            .iter()
            .filter_map(|car| match car {
                Value::Record(r) => r.id.as_ref().map(|id| (id.to_string(), car.clone())),
                _ => None,
            })
            .collect();
        snapshots.push((*valid, cars));
    }
    assert!(snapshots.len() > 500, "{} car snapshots", snapshots.len());

    let mut recorded = read_samples(&out_dir.join(format!("{spec_name}/situations.jsonl")));
    recorded.retain(|(name, _, _)| name == stream);
    let mut got = BTreeSet::new();
    for (_, valid, value) in &recorded {
        assert_eq!(value["verdict"], true);
        let times: Vec<Time> =
            value["times"].as_array().unwrap().iter().map(|t| t.as_i64().unwrap()).collect();
        assert_eq!(value["end"].as_i64(), Some(*valid));
        assert_eq!(value["start"].as_i64(), times.iter().copied().min());
        let binding: Vec<String> = params.iter().map(|p| value[*p].as_str().unwrap().to_string()).collect();
        got.insert((binding, times, *valid));
    }
    assert_eq!(got.len(), recorded.len(), "a recognition recorded twice");
    let _ = std::fs::remove_dir_all(&out_dir);
    (snapshots, got)
}

#[test]
fn the_overtake_chronicle_runs_as_the_pure_recogniser_recognises_it() {
    let (snapshots, got) = run_spec("sumo_chronicles", "overtake", 90);
    let (want, events) =
        expected(&snapshots, overtake_model("overtake", 60 * S, false), Relations::front, None);
    assert!(events > 100, "only {events} events");
    assert!(want.len() >= 3, "the scenario's overtakes: {want:?}");
    assert_eq!(got, want);
}

/// The reckless overtake of sumo_reckless.kpl on the first 90 s of its traffic (the truth of
/// scripts/sumo-scenarios.py has 12 reckless cut-ins in them). Its second hold (`b` keeps to its
/// lane from `side` to `cut`) is in the model: without it in the spec, the recognitions differ.
#[test]
fn the_reckless_overtake_chronicle_runs_as_the_pure_recogniser_recognises_it() {
    let (snapshots, got) = run_spec("sumo_reckless", "reckless_overtake", 90);
    let model = overtake_model("reckless_overtake", 30 * S, true);
    let (want, events) = expected(&snapshots, model, Relations::cut, Some(Relations::in_lane));
    assert!(events > 100, "only {events} events");
    assert!(!want.is_empty(), "the scenario's reckless overtake: {want:?}");
    assert_eq!(got, want);
}

/// One line of a `cars` stream for `file.jsonl`: the cars (JSON objects) at `valid`.
fn cars_line(valid: Time, cars: &[String]) -> String {
    format!("{{\"stream\": \"cars\", \"valid\": {valid}, \"value\": [{}]}}\n", cars.join(", "))
}

/// Runs a spec written in the test, with `dir` as its folder (its data) and output folder; what
/// its sink recorded in `out.jsonl`.
fn run_text(dir: &Path, name: &str, text: &str) -> Vec<(String, Time, serde_json::Value)> {
    let spec = kpl_std::check_text(text).unwrap();
    let config = RunConfig {
        out_dir: dir.to_path_buf(),
        spec_dir: dir.to_path_buf(),
        spec_name: name.into(),
        ..RunConfig::default()
    };
    let report = kpl_runtime::run(&spec, &kpl_std::registry(), &config, None).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    read_samples(&dir.join("out.jsonl"))
}

/// The reckless overtake of sumo_reckless.kpl as the spec writes it, on two hand-made pairs at
/// 10 Hz: on road 0, `a1` (25 m/s, 20 m behind) passes `b1` (17 m/s) on the left lane and cuts
/// in at 4.2 s, 9.1 m in front of `b1` (0.54 s at its speed); on road 1, `a2` and `b2` drive
/// the same but `b2` pulls out behind `a2` at 4.2 s (its lane offset swings through the lane
/// marking) and `a2` stays in its lane. Only the first is a cut-in: `b` keeps to its lane from
/// `side` to `cut` (`abs(b.lane_offset) < 1.2`).
#[test]
fn the_reckless_overtake_is_the_cutters_lane_change_not_the_overtaken_ones() {
    let dir = fresh_dir("reckless-lane-change");
    let chronicle = shipped_chronicle("sumo_reckless.kpl", "reckless_overtake");
    let car = |id: &str, road: i64, lane: i64, lane_pos: f64, offset: f64, speed: f64| {
        let y = 1000.0 * road as f64 - 1.6 - 3.2 * (1 - lane) as f64 + offset;
        format!(
            "{{\"id\": \"{id}\", \"pos\": [{lane_pos}, {y}], \"vel\": [{speed}, 0.0], \"size\": 4.5, \"measured\": true, \
             \"road\": {road}, \"lane\": \"r{road}_{lane}\", \"lane_offset\": {offset}, \"lane_pos\": {lane_pos}, \"speed\": {speed}}}"
        )
    };
    let mut data = String::new();
    for k in 0..80 {
        let t = k as f64 / 10.0;
        let (pos_a, pos_b) = (-20.0 + 25.0 * t, 17.0 * t);
        let cut = k >= 42;
        // b2's centre from its lane's centre: out towards the marking, then in on the other side.
        let b2_offset = match k {
            38..=41 => 0.4 * (k - 37) as f64,
            42..=45 => -(1.6 - 0.4 * (k - 41) as f64),
            _ => 0.0,
        };
        let cars = [
            car("a1", 0, if cut { 0 } else { 1 }, pos_a, 0.0, 25.0),
            car("b1", 0, 0, pos_b, 0.0, 17.0),
            car("a2", 1, 1, pos_a, 0.0, 25.0),
            car("b2", 1, if cut { 1 } else { 0 }, pos_b, b2_offset, 17.0),
        ];
        data.push_str(&cars_line(k * S / 10, &cars));
    }
    std::fs::write(dir.join("cars.jsonl"), data).unwrap();
    let text = format!(
        "type Car symbol co {{ pos: vec2, vel: vec2, size: float, road: int, lane: string, lane_offset: float, lane_pos: float, speed: float }}\n\
         source cars : list<Car> = file.jsonl(path: \"cars.jsonl\")\n{chronicle}\n\
         sink out = file.jsonl(reckless_overtake, path: \"out.jsonl\")\n"
    );
    let recorded = run_text(&dir, "reckless_lane_change", &text);
    let pairs: Vec<(String, String, Time)> = recorded
        .iter()
        .map(|(_, valid, v)| {
            (v["a"].as_str().unwrap().to_string(), v["b"].as_str().unwrap().to_string(), *valid)
        })
        .collect();
    assert_eq!(pairs, [("a1".to_string(), "b1".to_string(), 42 * S / 10)], "{recorded:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The chronicle `name` as a shipped spec writes it.
fn shipped_chronicle(spec: &str, name: &str) -> String {
    let shipped = std::fs::read_to_string(traffic_dir().join(spec)).unwrap();
    let start = shipped.find(&format!("chronicle {name}(")).unwrap();
    shipped[start..start + shipped[start..].find("\n}\n").unwrap() + 3].to_string()
}

/// The two reckless overtakes of sumo_no_passing.kpl as the spec writes them, on hand-made pairs
/// at 10 Hz on four streets 100 m apart, each `a` at 25 m/s starting 20 m behind its `b` at 17
/// m/s (beside it from 2.0 s, in front from 3.1 s): on road 0 `a1` cuts in at 4.2 s across a
/// solid line, on road 1 `a2` the same across a dashed one; on road 3 `a4` and `b4` cross a
/// junction (road -1, `in_junction`) from 2.6 s to 3.0 s, onto road 4, while `a4` passes `b4`;
/// on road 5 `a5` has passed `b5` before they cross a junction at 4.0 s (onto road 6). Only `a1`
/// overtakes across a solid line and only `a4` through a junction.
#[test]
fn overtakes_across_a_solid_line_and_through_a_junction() {
    let dir = fresh_dir("no-passing");
    let solid = shipped_chronicle("sumo_no_passing.kpl", "solid_line_overtake");
    let junction = shipped_chronicle("sumo_no_passing.kpl", "junction_overtake");
    // street, road (-1: in a junction), lane (0 right, 1 left), x, speed, crossed a solid line
    let car = |id: &str, (street, road): (i64, i64), lane: i64, x: f64, speed: f64, crossed: bool| {
        let y = 100.0 * street as f64 + 3.2 * lane as f64;
        let (lane_name, in_junction) =
            if road < 0 { (format!(":j_{lane}"), true) } else { (format!("r{road}_{lane}"), false) };
        format!(
            "{{\"id\": \"{id}\", \"pos\": [{x}, {y}], \"vel\": [{speed}, 0.0], \"size\": 4.5, \"road\": {road}, \
             \"lane\": \"{lane_name}\", \"lane_pos\": {x}, \"speed\": {speed}, \"heading\": 0.0, \"in_junction\": {in_junction}, \
             \"crossed_solid_line\": {crossed}}}"
        )
    };
    let mut data = String::new();
    for k in 0..80 {
        let t = k as f64 / 10.0;
        let (x_a, x_b) = (-20.0 + 25.0 * t, 17.0 * t);
        let lane_a = if k >= 42 { 0 } else { 1 };
        let crossing = |from: i64, to: i64, range: std::ops::Range<i64>| {
            if range.contains(&k) {
                -1
            } else if k < range.start {
                from
            } else {
                to
            }
        };
        let (street4, street5) = ((3, crossing(3, 4, 26..30)), (5, crossing(5, 6, 40..44)));
        let cars = [
            car("a1", (0, 0), lane_a, x_a, 25.0, k == 42),
            car("b1", (0, 0), 0, x_b, 17.0, false),
            car("a2", (1, 1), lane_a, x_a, 25.0, false),
            car("b2", (1, 1), 0, x_b, 17.0, false),
            car("a4", street4, 1, x_a, 25.0, false),
            car("b4", street4, 0, x_b, 17.0, false),
            car("a5", street5, 1, x_a, 25.0, false),
            car("b5", street5, 0, x_b, 17.0, false),
        ];
        data.push_str(&cars_line(k * S / 10, &cars));
    }
    std::fs::write(dir.join("cars.jsonl"), data).unwrap();
    let text = format!(
        "type Car symbol co {{ pos: vec2, vel: vec2, size: float, road: int, lane: string, lane_pos: float, speed: float, \
         heading: float, in_junction: bool, crossed_solid_line: bool }}\n\
         source cars : list<Car> = file.jsonl(path: \"cars.jsonl\")\n{solid}\n{junction}\n\
         sink out = file.jsonl(solid_line_overtake, junction_overtake, path: \"out.jsonl\")\n"
    );
    let recorded = run_text(&dir, "no_passing", &text);
    let got: Vec<(&str, &str, &str, Time)> = recorded
        .iter()
        .map(|(stream, valid, v)| {
            (stream.as_str(), v["a"].as_str().unwrap(), v["b"].as_str().unwrap(), *valid)
        })
        .collect();
    assert_eq!(
        got,
        [("junction_overtake", "a4", "b4", 31 * S / 10), ("solid_line_overtake", "a1", "b1", 42 * S / 10)],
        "{recorded:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Hysteresis in a chronicle's predicate, end to end: two cars whose distance jitters around
/// 20 m. The raw threshold becomes true at every dip under 20 m; `hysteresis(d < 20, d > 25)`
/// only at the first dip and after the cars were more than 25 m apart (hand-worked).
#[test]
fn hysteresis_keeps_a_jittering_relation_from_flickering() {
    let dir = fresh_dir("hysteresis");
    let distances = [30.0, 19.5, 20.5, 19.6, 20.4, 19.7, 30.0, 19.0, 20.2];
    let mut data = String::new();
    for (k, d) in distances.iter().enumerate() {
        let x = 10.0 * k as f64;
        data.push_str(&format!(
            "{{\"stream\": \"cars\", \"valid\": {}, \"value\": [{{\"id\": \"c1\", \"pos\": [{x}, 0.0]}}, {{\"id\": \"c2\", \"pos\": [{}, 0.0]}}]}}\n",
            k as i64 * S,
            x + d
        ));
    }
    std::fs::write(dir.join("cars.jsonl"), data).unwrap();
    let text = "type Car symbol co { pos: vec2 }\n\
        source cars : list<Car> = file.jsonl(path: \"cars.jsonl\")\n\
        chronicle near_raw(a: Car, b: Car) {\n  event meet = xydist(a.pos, b.pos) < 20.0 becomes true\n}\n\
        chronicle near(a: Car, b: Car) {\n  event meet = hysteresis(xydist(a.pos, b.pos) < 20.0, xydist(a.pos, b.pos) > 25.0) becomes true\n}\n\
        sink out = file.jsonl(near_raw, near, path: \"out.jsonl\")\n";
    let recorded = run_text(&dir, "hysteresis", text);
    let times = |stream: &str, a: &str| -> Vec<Time> {
        recorded.iter().filter(|(s, _, v)| s == stream && v["a"] == a).map(|(_, t, _)| *t / S).collect()
    };
    // Both ordered pairs, at the same instants.
    for a in ["c1", "c2"] {
        assert_eq!(times("near_raw", a), [1, 3, 5, 7], "{recorded:?}");
        assert_eq!(times("near", a), [1, 7], "{recorded:?}");
    }
    assert_eq!(recorded.len(), 12);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `weaving(c)` of sumo_weaving.kpl for the pure recogniser: source 0 is the fluent
/// `hysteresis(abs(c.smoothed_lane_offset) > 1.3, abs(c.smoothed_lane_offset) < 0.5)`; out1, in1,
/// out2, in2, out3, in3 alternate its becoming true and false, each at least 0.5 s after the one
/// before, all within 30 s.
fn weaving_model() -> Chronicle {
    const HALF_S: Time = S / 2;
    let c = |later, earlier, lo| Constraint { later, earlier, lo: Some(lo), hi: Some(30 * S) };
    let event = |value| Pattern { source: SourceId(0), args: vec![0], value };
    Chronicle {
        name: "weaving".into(),
        source: SourceId(1),
        params: 1,
        events: vec![event(true), event(false), event(true), event(false), event(true), event(false)],
        constraints: vec![
            c(1, 0, HALF_S),
            c(2, 1, HALF_S),
            c(3, 2, HALF_S),
            c(4, 3, HALF_S),
            c(5, 4, HALF_S),
            c(5, 0, 0),
        ],
        holds: vec![],
        nevers: vec![],
    }
}

/// A fluent over one car: its new value from the car and its value before.
type Fluent<'a> = dyn Fn(&Value, bool) -> bool + 'a;

/// What the pure recogniser recognises of `chronicle` (merged as the adapter merges) on events
/// computed here from the recorded cars: source `k` is `fluents[k]` of each car, an event at each
/// change of it (a car that is gone is out of the fluent: false); and how many events there were.
fn recognise_fluents(
    snapshots: &Snapshots,
    chronicle: Chronicle,
    fluents: &[&Fluent<'_>],
) -> (usize, Recognised) {
    let mut recogniser: Recogniser<Arc<str>> =
        Recogniser::new(vec![chronicle.compile().unwrap()], Config::default()).unwrap();
    let mut merge = Merge::new(recogniser.chronicles()[0].window);
    let mut was: Vec<BTreeMap<String, bool>> = vec![BTreeMap::new(); fluents.len()];
    let mut want = BTreeSet::new();
    let mut events_total = 0;
    for (valid, cars) in snapshots {
        let mut events: Vec<Event<Arc<str>>> = Vec::new();
        for (k, fluent) in fluents.iter().enumerate() {
            let now: BTreeMap<String, bool> = cars
                .iter()
                .map(|(id, car)| (id.clone(), fluent(car, was[k].get(id).copied().unwrap_or(false))))
                .collect();
            let mut changes: Vec<(String, bool)> = Vec::new();
            for (id, &value) in &now {
                if was[k].get(id).copied().unwrap_or(false) != value {
                    changes.push((id.clone(), value));
                }
            }
            for (id, &value) in &was[k] {
                if value && !now.contains_key(id) {
                    changes.push((id.clone(), false));
                }
            }
            changes.sort();
            events.extend(changes.into_iter().map(|(id, value)| Event {
                source: SourceId(u32::try_from(k).unwrap()),
                args: vec![Arc::from(id.as_str())],
                value,
                time: *valid,
            }));
            was[k] = now;
        }
        events_total += events.len();
        for r in recogniser.step(*valid, events).unwrap() {
            if merge.admit(&r) {
                want.insert((r.binding.iter().map(|o| o.to_string()).collect(), r.times, r.valid_time));
            }
        }
    }
    (events_total, want)
}

/// The weaving of sumo_weaving.kpl on the first 120 s of its traffic (the truth of
/// scripts/sumo-scenarios.py has two drunk drivers weaving in them): the recognitions recorded
/// are those of the pure recogniser on the fluent computed here from each recorded car's
/// `smoothed_lane_offset` (a car that is gone is out of the fluent).
#[test]
fn the_weaving_chronicle_runs_as_the_pure_recogniser_recognises_it() {
    let (snapshots, got) = run_spec_with("sumo_weaving", "weaving", 120, &["c"]);
    let out = |car: &Value, was: bool| {
        let offset = Relations::num(car, "smoothed_lane_offset").abs();
        if was { offset >= 0.5 } else { offset > 1.3 }
    };
    let (events_total, want) = recognise_fluents(&snapshots, weaving_model(), &[&out]);
    assert!(events_total > 20, "only {events_total} events");
    assert!(!want.is_empty(), "the scenario's weaving");
    assert_eq!(got, want);
}

/// `speed_swings(c)` of sumo_weaving.kpl for the pure recogniser: source 0 is the fluent of a
/// fall (`norm(c.smoothed_vel) - norm(c.vel)` over 2 m/s, until under 0.5), source 1 of a rise
/// (the same the other way); fall1, rise1, fall2, rise2 within 10 s, 20 s and 10 s of the one
/// before, 30 s in all.
fn speed_swings_model() -> Chronicle {
    let c = |later, earlier, hi| Constraint { later, earlier, lo: Some(0), hi: Some(hi * S) };
    let event = |source| Pattern { source: SourceId(source), args: vec![0], value: true };
    Chronicle {
        name: "speed_swings".into(),
        source: SourceId(2),
        params: 1,
        events: vec![event(0), event(1), event(0), event(1)],
        constraints: vec![c(1, 0, 10), c(2, 1, 20), c(3, 2, 10), c(3, 0, 30)],
        holds: vec![],
        nevers: vec![],
    }
}

/// The speed swings of sumo_weaving.kpl on the first 120 s of its traffic (drunk drivers slow
/// down and speed up again every 5 to 12 s, and the cars behind them with them): the recordings
/// are those of the pure recogniser on the fluents computed here from each recorded car's
/// `vel` and `smoothed_vel`.
#[test]
fn the_speed_swings_chronicle_runs_as_the_pure_recogniser_recognises_it() {
    let (snapshots, got) = run_spec_with("sumo_weaving", "speed_swings", 120, &["c"]);
    // `hysteresis(d > 2.0, d < 0.5)` of the drop `d` (fall) or the gain (rise) over 2 s.
    let fluent = |d: f64, was: bool| if was { d >= 0.5 } else { d > 2.0 };
    let drop = |car: &Value| Relations::norm(car, "smoothed_vel") - Relations::norm(car, "vel");
    let fall = |car: &Value, was: bool| fluent(drop(car), was);
    let rise = |car: &Value, was: bool| fluent(-drop(car), was);
    let (events_total, want) = recognise_fluents(&snapshots, speed_swings_model(), &[&fall, &rise]);
    assert!(events_total > 20, "only {events_total} events");
    assert!(!want.is_empty(), "the scenario's speed swings");
    assert_eq!(got, want);
}

/// A monitor's verdicts as events, differentially: the shipped situation monitors of
/// sumo_situations.kpl, verbatim, each with a one-event chronicle `monitor M(...) becomes true`,
/// on its recorded SUMO traffic. Every `true` episode the monitor's own process reports begins
/// with a verdict decided at a state, and the chronicle (which progresses the monitor itself, at
/// its own states) recognises exactly those: the same bindings at the same valid times. (The
/// situation monitors never decide `true` when a binding closes: their `eventually[2s, 3s] true`
/// is then unsatisfied.)
#[test]
fn a_monitors_verdicts_as_events_are_the_monitors_own_episodes() {
    let dir = fresh_dir("monitor-events");
    let shipped = std::fs::read_to_string(traffic_dir().join("sumo_situations.kpl")).unwrap();
    let monitors = [("overtake", 2), ("speeding", 1), ("stopped", 1), ("tailgating", 2)];
    let mut text = shipped.clone();
    for (monitor, arity) in monitors {
        let (params, args) = if arity == 1 { ("a: Car", "a") } else { ("a: Car, b: Car", "a, b") };
        text.push_str(&format!(
            "chronicle {monitor}_event({params}) {{\n  event e = monitor {monitor}({args}) becomes true\n}}\n"
        ));
    }
    let names: Vec<String> = monitors.iter().map(|(m, _)| format!("{m}_event")).collect();
    text.push_str(&format!("sink events = file.jsonl({}, path: \"events.jsonl\")\n", names.join(", ")));
    let spec = kpl_std::check_text(&text).unwrap();
    let config = RunConfig {
        duration: Some(60 * S),
        seed: 3,
        out_dir: dir.clone(),
        spec_dir: traffic_dir(),
        spec_name: "sumo_situations".into(),
        ..RunConfig::default()
    };
    let report = kpl_runtime::run(&spec, &kpl_std::registry(), &config, None).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    let episodes = read_samples(&dir.join("sumo_situations/situations.jsonl"));
    let events = read_samples(&dir.join("events.jsonl"));
    let mut seen = 0;
    for (monitor, arity) in monitors {
        let binding = |v: &serde_json::Value, keys: &[&str]| -> Vec<String> {
            keys[..arity].iter().map(|k| v[*k].as_str().unwrap().to_string()).collect()
        };
        let keys: [&str; 2] = if arity == 1 { ["c", ""] } else { ["a", "b"] };
        let want: Vec<(Vec<String>, Time)> = episodes
            .iter()
            .filter(|(s, _, v)| s == monitor && v["verdict"] == true)
            .map(|(_, valid, v)| (binding(v, &keys), *valid))
            .collect();
        let stream = format!("{monitor}_event");
        let got: Vec<(Vec<String>, Time)> = events
            .iter()
            .filter(|(s, _, _)| *s == stream)
            .map(|(_, valid, v)| (binding(v, &["a", "b"]), *valid))
            .collect();
        let sorted = |mut v: Vec<(Vec<String>, Time)>| {
            v.sort();
            v
        };
        assert_eq!(sorted(got), sorted(want.clone()), "{monitor}");
        seen += want.len();
    }
    // Enough situations that the comparison means something (overtakes and speeding at least).
    assert!(seen >= 10, "{seen} true episodes");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A monitor's verdicts as events, by hand: the example of docs/language.md (`fast_start`: a car
/// goes, then breaks `too_fast` within 10 s), and a monitor without `forall` over a value stream
/// (`high`: the level stream, which the chronicle does not otherwise read). At 1 Hz: `c1` goes at
/// 1 s and is too fast from 4 s to 6 s and again from 9 s (one episode: its verdicts in between
/// are `true` only when its progression closes); `c2` goes at 0 s (its first state) and is never
/// too fast; `c3` goes at 0 s and is too fast only at 12 s, too late. The level breaks 10.0 at
/// 3 s and at 8 s (two episodes: true in between, decided at each state).
#[test]
fn a_monitors_verdicts_become_events_of_a_chronicle() {
    let dir = fresh_dir("monitor-verdicts");
    let speed = |id: &str, t: i64| -> f64 {
        match (id, t) {
            ("c1", 0) => 0.0,
            ("c1", 4..=6) | ("c1", 9..) => 30.0,
            ("c1", _) => 5.0,
            ("c2", _) => 5.0,
            (_, 12) => 30.0,
            _ => 5.0,
        }
    };
    let level = |t: i64| if t == 3 || t == 8 { 12.0 } else { 4.0 };
    let mut cars = String::new();
    let mut levels = String::new();
    for t in 0..15 {
        let objects: Vec<String> = ["c1", "c2", "c3"]
            .iter()
            .map(|id| format!("{{\"id\": \"{id}\", \"pos\": [0.0, 0.0], \"vel\": [{}, 0.0]}}", speed(id, t)))
            .collect();
        cars.push_str(&format!(
            "{{\"stream\": \"cars\", \"valid\": {}, \"value\": [{}]}}\n",
            t * S,
            objects.join(", ")
        ));
        levels.push_str(&format!(
            "{{\"stream\": \"level\", \"valid\": {}, \"value\": {}}}\n",
            t * S,
            level(t)
        ));
    }
    std::fs::write(dir.join("cars.jsonl"), cars).unwrap();
    std::fs::write(dir.join("level.jsonl"), levels).unwrap();
    let text = "type Car symbol co { pos: vec2, vel: vec2 }\n\
        source cars : list<Car> = file.jsonl(path: \"cars.jsonl\")\n\
        source level : float = file.jsonl(path: \"level.jsonl\")\n\
        monitor too_fast = forall c: Car . always (norm(c.vel) < 25.0)\n\
        monitor high = always (level < 10.0)\n\
        chronicle fast_start(a: Car) {\n  event go = norm(a.vel) > 1.0 becomes true\n  event fast = monitor too_fast(a) becomes false\n  fast - go in [0s, 10s]\n}\n\
        chronicle high_while_going(a: Car) {\n  event go = norm(a.vel) > 1.0 becomes true\n  event up = monitor high() becomes false\n  up - go in [0s, 4s]\n}\n\
        sink out = file.jsonl(fast_start, high_while_going, too_fast, path: \"out.jsonl\")\n";
    let recorded = run_text(&dir, "monitor_verdicts", text);
    let found = |stream: &str| -> Vec<(String, Vec<Time>)> {
        recorded
            .iter()
            .filter(|(s, _, _)| s == stream)
            .map(|(_, _, v)| {
                let times = v["times"].as_array().unwrap().iter().map(|t| t.as_i64().unwrap() / S).collect();
                (v["a"].as_str().unwrap().to_string(), times)
            })
            .collect()
    };
    assert_eq!(found("fast_start"), [("c1".to_string(), vec![1, 4])], "{recorded:?}");
    // `high` becomes false at 3 s (c1 went at 1 s; c2 and c3 at 0 s) and at 8 s (too late for all).
    let mut high = found("high_while_going");
    high.sort();
    assert_eq!(
        high,
        [("c1".to_string(), vec![1, 3]), ("c2".to_string(), vec![0, 3]), ("c3".to_string(), vec![0, 3])],
        "{recorded:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
