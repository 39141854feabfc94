//! Monitors over `forall c: Car` on many objects, against independent progressions: `kpl run`
//! progresses every car's binding as an instance of one shared `kpl_mtl::ProgressorGroup` (the
//! cars in the same situation share residuals and cached transitions); this test progresses each
//! car's binding with a `Progressor` of its own, applying the monitor's documented rules
//! (docs/runtime.md: a binding starts at the car's first state and is closed at its last, a
//! decided verdict starts the progression over, a decision repeated at the next state is reported
//! once), and the two must report the same verdicts for the same cars at the same times.
//!
//! The traffic is generated: 300 cars that come and go and change between four speeds, over 80
//! states half a second apart, so that thousands of bindings are started, decided, restarted and
//! dropped, and most situations are shared by many cars.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use common::{kpl_command as kpl, lines};
use kpl_core::{Record, Time, TimeUnit, Value};
use kpl_mtl::{Context, Formula, Progressor, SlotState};

const CARS: usize = 300;
const STATES: usize = 80;
/// Microseconds between states.
const PERIOD: Time = 500_000;
const SPEEDS: [f64; 4] = [10.0, 18.0, 22.0, 30.0];

/// The monitors of the spec: (name, formula body over `c`).
const MONITORS: [(&str, &str); 3] = [
    ("slow_down", "always (c.speed > 25.0 -> eventually[0, 2s] c.speed < 20.0)"),
    ("settles", "eventually[1s, 3s] always[0, 1s] c.speed < 15.0"),
    ("steady", "always[0, 2s] (c.speed > 15.0 and c.speed < 25.0)"),
];

/// A small deterministic generator (xorshift64*), so that the traffic is the same at every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// True with probability `p`.
    fn chance(&mut self, p: f64) -> bool {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }
}

/// The states: for each, the cars present with their speeds (in symbol order).
fn traffic(seed: u64) -> Vec<Vec<(String, f64)>> {
    let mut rng = Rng(seed);
    let mut present: Vec<bool> = (0..CARS).map(|_| rng.chance(0.5)).collect();
    let mut speed: Vec<usize> = (0..CARS).map(|_| (rng.next() % 4) as usize).collect();
    let mut states = Vec::with_capacity(STATES);
    for _ in 0..STATES {
        let mut cars = Vec::new();
        for car in 0..CARS {
            if rng.chance(0.08) {
                present[car] = !present[car];
            }
            if rng.chance(0.3) {
                speed[car] = (rng.next() % 4) as usize;
            }
            if present[car] {
                cars.push((format!("car{car:03}"), SPEEDS[speed[car]]));
            }
        }
        states.push(cars);
    }
    states
}

fn write_spec(dir: &Path, states: &[Vec<(String, f64)>]) {
    let mut spec = String::from(
        "type Car symbol car { speed: float }\n\
         source cars : list<Car> = file.jsonl(path: \"cars.jsonl\")\n",
    );
    for (name, body) in MONITORS {
        spec.push_str(&format!("monitor {name} = forall c: Car . {body}\n"));
        spec.push_str(&format!("sink record_{name} = file.jsonl({name}, path: \"{name}.jsonl\")\n"));
    }
    std::fs::write(dir.join("bindings.kpl"), spec).unwrap();
    let mut data = String::new();
    for (i, cars) in states.iter().enumerate() {
        let value: Vec<serde_json::Value> =
            cars.iter().map(|(id, speed)| serde_json::json!({"id": id, "speed": speed})).collect();
        let line = serde_json::json!({"stream": "cars", "valid": i as Time * PERIOD, "value": value});
        data.push_str(&format!("{line}\n"));
    }
    std::fs::write(dir.join("cars.jsonl"), data).unwrap();
}

/// One car's binding, progressed alone.
struct Binding {
    progressor: Progressor,
    last_valid: Option<Time>,
    /// The verdict of the episode not yet ended: an equal verdict that follows (with undecided
    /// states between or not) continues it and is not reported again (docs/language.md, monitors).
    repeat: Option<bool>,
}

/// The verdicts (valid time, car, verdict) the monitor's rules give with one progressor per car.
fn independent(body: &str, states: &[Vec<(String, f64)>]) -> Vec<(Time, String, bool)> {
    independent_bindings(&["c"], body, states)
}

/// The same with one progressor per binding of `vars` (one variable: each car; two: each
/// ordered pair of distinct cars), a binding named by its cars joined with `|`.
fn independent_bindings(
    vars: &[&str],
    body: &str,
    states: &[Vec<(String, f64)>],
) -> Vec<(Time, String, bool)> {
    let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Ms);
    for (i, var) in vars.iter().enumerate() {
        assert_eq!(ctx.declare_value(var), i as u32);
    }
    let expr = kpl_syntax::parse_formula(body).unwrap();
    let formula = Arc::new(Formula::from_ast(&expr, &mut ctx).unwrap());
    let mut open: BTreeMap<String, Binding> = BTreeMap::new();
    let mut verdicts = Vec::new();
    let close = |id: &str, mut binding: Binding, verdicts: &mut Vec<(Time, String, bool)>| {
        if let Some(last) = binding.last_valid
            && let Some(verdict) = binding.progressor.finish()
            && binding.repeat != Some(verdict)
        {
            verdicts.push((last, id.to_string(), verdict));
        }
    };
    for (i, cars) in states.iter().enumerate() {
        let valid = i as Time * PERIOD;
        let record = |(id, speed): &(String, f64)| {
            Value::Record(Arc::new(Record {
                id: Some(Arc::from(id.as_str())),
                fields: vec![(Arc::from("speed"), Value::Float(*speed))],
            }))
        };
        let bindings: Vec<(String, SlotState)> = match vars.len() {
            1 => cars.iter().map(|car| (car.0.clone(), SlotState::new(vec![Some(record(car))]))).collect(),
            _ => cars
                .iter()
                .flat_map(|a| cars.iter().filter(move |b| b.0 != a.0).map(move |b| (a, b)))
                .map(|(a, b)| {
                    (format!("{}|{}", a.0, b.0), SlotState::new(vec![Some(record(a)), Some(record(b))]))
                })
                .collect(),
        };
        let gone: Vec<String> =
            open.keys().filter(|id| !bindings.iter().any(|(b, _)| b == *id)).cloned().collect();
        for id in gone {
            let binding = open.remove(&id).unwrap();
            close(&id, binding, &mut verdicts);
        }
        for (id, state) in bindings {
            let binding = open.entry(id.clone()).or_insert_with(|| Binding {
                progressor: Progressor::new(formula.clone()),
                last_valid: None,
                repeat: None,
            });
            match binding.progressor.step(valid, &state).unwrap() {
                Some(verdict) => {
                    if binding.repeat != Some(verdict) {
                        verdicts.push((valid, id.clone(), verdict));
                    }
                    binding.repeat = Some(verdict);
                    binding.progressor.reset();
                    binding.last_valid = None;
                }
                None => binding.last_valid = Some(valid),
            }
        }
    }
    for (id, binding) in std::mem::take(&mut open) {
        close(&id, binding, &mut verdicts);
    }
    verdicts.sort();
    verdicts
}

fn reported(path: &Path) -> Vec<(Time, String, bool)> {
    reported_bindings(path, &["c"])
}

/// The verdicts a monitor over `vars` reported, each binding named as [`independent_bindings`]
/// names it.
fn reported_bindings(path: &Path, vars: &[&str]) -> Vec<(Time, String, bool)> {
    let mut verdicts: Vec<(Time, String, bool)> = lines(path)
        .iter()
        .map(|r| {
            let v = &r["value"];
            let ids: Vec<&str> = vars.iter().map(|var| v[*var].as_str().unwrap()).collect();
            (r["valid"].as_i64().unwrap(), ids.join("|"), v["verdict"].as_bool().unwrap())
        })
        .collect();
    verdicts.sort();
    verdicts
}

#[test]
fn shared_bindings_report_what_independent_progressions_report() {
    for seed in [1, 7] {
        let dir = common::fresh_dir("bindings", &format!("seed{seed}"));
        let states = traffic(seed);
        write_spec(&dir, &states);
        let out = dir.join("out");
        let spec = dir.join("bindings.kpl");
        let result = kpl(&["run", "--quiet", spec.to_str().unwrap(), "--out", out.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
        for (name, body) in MONITORS {
            let expected = independent(body, &states);
            let got = reported(&out.join(format!("{name}.jsonl")));
            // The case exercises what it should: many cars, both verdicts, decisions at a state
            // and at a car's last state.
            let cars: std::collections::BTreeSet<&String> = expected.iter().map(|(_, car, _)| car).collect();
            assert!(cars.len() > CARS / 2, "{name}: {} cars decided", cars.len());
            assert!(expected.iter().any(|v| v.2) && expected.iter().any(|v| !v.2), "{name}: one-sided");
            assert!(expected.len() > 500, "{name}: {} verdicts", expected.len());
            if got != expected {
                let missing: Vec<_> = expected.iter().filter(|v| !got.contains(v)).take(5).collect();
                let extra: Vec<_> = got.iter().filter(|v| !expected.contains(v)).take(5).collect();
                panic!(
                    "seed {seed}, {name}: {} verdicts reported, {} expected; missing {missing:?}, extra {extra:?}",
                    got.len(),
                    expected.len()
                );
            }
        }
    }
}

/// A pair monitor (`forall a: Car . forall b: Car . φ`, without a gate: every ordered pair of
/// distinct cars) on 40 of the cars: the pairs' progressions in the shared group against one
/// `Progressor` per pair, under the same rules (a pair starts when both cars are present and
/// closes when either is gone).
#[test]
fn shared_pair_bindings_report_what_independent_progressions_report() {
    const PAIR_MONITORS: [(&str, &str); 2] = [
        ("faster", "always[0, 1s] a.speed > b.speed"),
        ("catches_up", "a.speed < b.speed -> eventually[0, 2s] a.speed > b.speed"),
    ];
    let dir = common::fresh_dir("bindings", "pairs");
    let states: Vec<Vec<(String, f64)>> = traffic(3)
        .into_iter()
        .map(|cars| cars.into_iter().filter(|(id, _)| id.as_str() < "car040").collect())
        .collect();
    write_spec(&dir, &states);
    let mut spec = String::from(
        "type Car symbol car { speed: float }\n\
         source cars : list<Car> = file.jsonl(path: \"cars.jsonl\")\n",
    );
    for (name, body) in PAIR_MONITORS {
        spec.push_str(&format!("monitor {name} = forall a: Car . forall b: Car . {body}\n"));
        spec.push_str(&format!("sink record_{name} = file.jsonl({name}, path: \"{name}.jsonl\")\n"));
    }
    std::fs::write(dir.join("pairs.kpl"), spec).unwrap();
    let out = dir.join("out");
    let spec = dir.join("pairs.kpl");
    let result =
        kpl(&["run", "--quiet", spec.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    for (name, body) in PAIR_MONITORS {
        let expected = independent_bindings(&["a", "b"], body, &states);
        let got = reported_bindings(&out.join(format!("{name}.jsonl")), &["a", "b"]);
        let pairs: std::collections::BTreeSet<&String> = expected.iter().map(|(_, pair, _)| pair).collect();
        assert!(pairs.len() > 500, "{name}: {} pairs decided", pairs.len());
        assert!(expected.iter().any(|v| v.2) && expected.iter().any(|v| !v.2), "{name}: one-sided");
        if got != expected {
            let missing: Vec<_> = expected.iter().filter(|v| !got.contains(v)).take(5).collect();
            let extra: Vec<_> = got.iter().filter(|v| !expected.contains(v)).take(5).collect();
            panic!(
                "{name}: {} verdicts reported, {} expected; missing {missing:?}, extra {extra:?}",
                got.len(),
                expected.len()
            );
        }
    }
}
