//! Anchoring partitioned by region (`kpl_anchor::regions`): the crossing split at x = 0 into two
//! regions, cars driving through it both ways, a car standing on the border with noise. Every car
//! keeps its world-object and on-road symbols across the border (its structure follows its
//! percept), a car on the border does not go back and forth, and the run's outputs are the same,
//! change for change and object for object, with one worker thread and with two.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

mod common;

use std::collections::BTreeMap;

use kpl_anchor::regions::{RegionGrid, Regional};
use kpl_anchor::{AnchorConfig, Snapshot};
use kpl_core::Value;

const SPEC: &str = common::CROSSING_SPEC;

const GRID: RegionGrid =
    RegionGrid { min: [-150.0, -150.0], max: [150.0, 150.0], cols: 2, rows: 1, margin: 5.0 };

fn regional(margin: f64) -> Regional {
    regional_of(RegionGrid { margin, ..GRID })
}

fn regional_of(grid: RegionGrid) -> Regional {
    regional_with(SPEC, grid)
}

fn regional_with(spec: &str, grid: RegionGrid) -> Regional {
    let spec = kpl_anchor::registry::check_text(spec).unwrap();
    Regional::from_spec(&spec, &AnchorConfig::default(), grid).unwrap()
}

/// The crossing's spec with a Kalman filter as the first link's unit (a memory per world
/// object, handed over with it) and a third level, cars.
fn kalman_spec() -> String {
    SPEC.replace("via anchor.world_from_percept", "via anchor.kalman(acceleration_noise: 4.0)")
        .replace("type OnRoadObject ", "type Car : OnRoadObject symbol co { }\ntype OnRoadObject ")
        + "link onroad_car : OnRoadObject -> Car via anchor.copy {\n  establish eventually[0.5s, inf] true\n  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0\n  maintain true\n}\n"
}

/// At every step, for every percept listed: the states of the objects of its structure, without
/// their symbols (regions number symbols differently).
fn structure_states(spec: &str, grid: RegionGrid) -> Vec<Vec<(String, Vec<Value>)>> {
    let mut regional = regional_with(spec, grid);
    let mut out = Vec::new();
    for i in 0..240 {
        let objects = percepts(i);
        regional
            .step(i * 100_000, &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }], 1)
            .unwrap();
        let Value::List(items) = &objects else { unreachable!() };
        let mut states = Vec::new();
        for item in items.iter() {
            let id = item.as_record().unwrap().id.clone().unwrap();
            let region = regional.region_of_percept("tracker", &id).unwrap();
            let chain = regional.chain("tracker", &id);
            let values = chain
                .iter()
                .map(|(ty, symbol)| {
                    let state = regional.engines[region].object(ty, symbol).unwrap().state;
                    let mut record = state.as_record().unwrap().clone();
                    record.id = None;
                    Value::Record(std::sync::Arc::new(record))
                })
                .collect();
            states.push((id.to_string(), values));
        }
        out.push(states);
    }
    out
}

/// The percepts at step i (0.1 s): eastbound cars on `west`/`east` (y = -1.75) 15 m apart from
/// x = -140, westbound ones (y = 1.75) from x = 140, each missed now and then, and one car standing
/// at x = 1 whose position jitters by up to 2 m.
fn percepts(i: i64) -> Value {
    let jitter = |k: i64| [0.0, 0.4, -0.3, 0.2, -0.4][((i + k) % 5) as usize];
    let mut items = Vec::new();
    for k in 0..4 {
        let x = -140.0 - 15.0 * k as f64 + i as f64;
        if (i + 3 * k) % 17 != 0 {
            items.push(common::percept(&format!("vp{k}"), [x, -1.75 + jitter(k)], [10.0, 0.0], 4.5));
        }
        let x = 140.0 + 15.0 * k as f64 - i as f64;
        if (i + 5 * k) % 13 != 0 {
            items.push(common::percept(&format!("vp{}", 10 + k), [x, 1.75 + jitter(k)], [-10.0, 0.0], 4.5));
        }
    }
    let wobble = [1.5, -1.8, 0.7, 2.0, -0.9, 0.3][(i % 6) as usize];
    items.push(common::percept("vp20", [1.0 + wobble, -5.25], [0.0, 0.0], 4.5));
    Value::List(items.into())
}

/// Every percept's structure kept one world object and one on-road object (once it had one);
/// returns how many of the moving cars were anchored.
fn assert_symbols_kept(symbols: &BTreeMap<String, Vec<Vec<String>>>) -> usize {
    let mut crossed = 0;
    for (id, chains) in symbols {
        let full: Vec<&Vec<String>> = chains.iter().filter(|c| c.len() == 2).collect();
        assert!(!full.is_empty(), "{id} never anchored through both levels: {chains:?}");
        assert!(full.windows(2).all(|w| w[0] == w[1]), "{id} changed symbols: {chains:?}");
        let wo = &full[0][0];
        assert!(chains.iter().all(|c| &c[0] == wo), "{id} changed world object: {chains:?}");
        if id != "vp20" {
            crossed += 1;
        }
    }
    crossed
}

/// Runs 24 s with `workers` threads: every step's changes (as their records) and, per percept,
/// the world-object and on-road symbols it was anchored to in order.
fn run(workers: usize, margin: f64) -> (Regional, Vec<Value>, BTreeMap<String, Vec<Vec<String>>>) {
    let mut regional = regional(margin);
    let mut changes = Vec::new();
    let mut symbols: BTreeMap<String, Vec<Vec<String>>> = BTreeMap::new();
    for i in 0..240 {
        let objects = percepts(i);
        let step = regional
            .step(
                i * 100_000,
                &[Snapshot { source: "tracker", ty: "VisionPercept", objects: &objects }],
                workers,
            )
            .unwrap();
        for out in &step.outputs {
            assert!(out.warnings.is_empty(), "{:?}", out.warnings);
            changes.push(out.changes_value());
        }
        let Value::List(items) = &objects else { unreachable!() };
        for item in items.iter() {
            let id = item.as_record().unwrap().id.clone().unwrap();
            let chain: Vec<String> =
                regional.chain("tracker", &id).into_iter().map(|(_, s)| s.to_string()).collect();
            let seen = symbols.entry(id.to_string()).or_default();
            if !chain.is_empty() && seen.last() != Some(&chain) {
                seen.push(chain);
            }
        }
    }
    (regional, changes, symbols)
}

#[test]
fn cars_keep_their_symbols_across_the_border_and_workers_change_nothing() {
    let (one, changes_one, symbols) = run(1, 5.0);
    // Every car that crossed did so with its structure: one world object and one on-road object
    // over the whole run.
    assert_eq!(assert_symbols_kept(&symbols), 8);
    // Eight cars crossed with their structures; the standing one stayed where it was.
    assert_eq!(one.stats.followed, 8, "{:?}", one.stats);
    assert_eq!(one.stats.refused, 0);
    assert_eq!(one.region_of_percept("tracker", "vp20"), Some(1));
    // Symbols of both regions: region 0 odd numbers, region 1 even ones.
    let numbers: Vec<&str> = symbols.values().map(|c| c[0][0].as_str()).collect();
    assert!(numbers.iter().any(|s| s.ends_with(['1', '3', '5', '7', '9'])), "{numbers:?}");
    assert!(numbers.iter().any(|s| s.ends_with(['0', '2', '4', '6', '8'])), "{numbers:?}");

    let (two, changes_two, symbols_two) = run(2, 5.0);
    assert_eq!(changes_two, changes_one, "the changes depend on the number of workers");
    assert_eq!(symbols_two, symbols);
    for (a, b) in one.engines.iter().zip(&two.engines) {
        assert_eq!(a.describe(), b.describe());
        assert_eq!(a.world_model(), b.world_model());
    }
}

#[test]
fn without_a_margin_a_car_on_the_border_goes_back_and_forth_and_keeps_its_symbols() {
    let (regional, _, symbols) = run(1, 0.0);
    assert_eq!(assert_symbols_kept(&symbols), 8);
    // The standing car's percept crosses x = 0 with its jitter: it and its structure move often.
    assert!(regional.stats.percepts_moved > 50, "{:?}", regional.stats);
    assert_eq!(regional.stats.refused, 0);
}

#[test]
fn the_partition_changes_no_state_of_any_structure() {
    let kalman = kalman_spec();
    for spec in [SPEC, kalman.as_str()] {
        let single = structure_states(spec, RegionGrid { cols: 1, ..GRID });
        // Three levels with the Kalman spec, once the cars are anchored.
        let depth = single.last().unwrap().iter().map(|(_, chain)| chain.len()).max();
        assert_eq!(depth, Some(if spec == SPEC { 2 } else { 3 }));
        for grid in
            [GRID, RegionGrid { margin: 0.0, ..GRID }, RegionGrid { cols: 3, rows: 2, margin: 2.0, ..GRID }]
        {
            let partitioned = structure_states(spec, grid);
            for (i, (a, b)) in single.iter().zip(&partitioned).enumerate() {
                assert_eq!(a, b, "step {i}, {grid:?}");
            }
        }
    }
}
