//! The engine's machinery on long streams, where the naive evaluator would be too slow: the
//! transition cache, the collection of the arena and the sharing of instances in a group must
//! not change a verdict or the state at which it is decided. Each Timescales property (over its
//! benchmark trace, holding and with the failing end) and each of DyKnow's link conditions
//! (over generated pairs) is run with the cache, without it, and collecting after nearly every
//! step; the runs must agree state by state.

#![allow(clippy::unwrap_used)] // a test fails loudly

use std::sync::Arc;

use kpl_core::{Record, Time, TimeUnit, Value};
use kpl_mtl::timescales::Property;
use kpl_mtl::{
    Context, EngineConfig, EveryMonitor, Formula, Function, Progressor, ProgressorGroup, SlotState,
    StartVerdict,
};

const CONFIGS: [EngineConfig; 3] = [
    EngineConfig { transition_cache: true, collect_slack: 4096 },
    EngineConfig { transition_cache: false, collect_slack: 4096 },
    EngineConfig { transition_cache: true, collect_slack: 1 },
];

/// Every state's step result and the final verdict with its decision time.
type Run = (Vec<Option<bool>>, Option<bool>, Option<Time>);

fn run(
    formula: &Arc<Formula>,
    states: &[(Time, SlotState)],
    config: EngineConfig,
) -> (Run, kpl_mtl::EngineStats) {
    let mut progressor = Progressor::with_config(formula.clone(), config);
    let steps = states.iter().map(|(t, s)| progressor.step(*t, s).unwrap()).collect();
    let verdict = progressor.finish();
    ((steps, verdict, progressor.decided_at()), progressor.stats())
}

fn timescales_states(property: Property, b: Time, failing: bool, uneven: bool) -> Vec<(Time, SlotState)> {
    let mut time = 0;
    property
        .trace(b, 3000, 11, failing)
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let state = SlotState::bools(row);
            let t = time;
            // Uneven spacing: now and then a gap of 3 (windows shift by more than one).
            time += if uneven && i % 7 == 3 { 3 } else { 1 };
            (t, state)
        })
        .collect()
}

#[test]
fn cache_and_collection_change_no_verdict_on_the_timescales_properties() {
    let mut hits = 0;
    let mut collections = 0;
    for property in Property::ALL {
        for b in [10, 100] {
            let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
            let formula = Arc::new(Formula::new(&property.formula(b, &mut ctx), &ctx).unwrap());
            for (failing, uneven) in [(false, false), (true, false), (false, true)] {
                let states = timescales_states(property, b, failing, uneven);
                let (reference, _) = run(&formula, &states, CONFIGS[1]);
                if !uneven {
                    assert_eq!(reference.1, Some(!failing), "{} bound {b}", property.name());
                }
                for config in [CONFIGS[0], CONFIGS[2]] {
                    let (got, stats) = run(&formula, &states, config);
                    assert_eq!(got, reference, "{} bound {b} failing {failing} {config:?}", property.name());
                    hits += stats.cache_hits;
                    collections += stats.collections;
                }
            }
        }
    }
    // The machinery under test was exercised.
    assert!(hits > 100_000, "cache hits: {hits}");
    assert!(collections > 100, "collections: {collections}");
}

#[test]
fn every_monitor_agrees_with_and_without_the_cache() {
    for property in [Property::RecurGLB, Property::RespondGLB, Property::AbsentBR, Property::RecurBQR] {
        let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
        let formula = Arc::new(Formula::new(&property.formula(20, &mut ctx), &ctx).unwrap());
        let states = timescales_states(property, 20, true, true);
        let verdicts: Vec<Vec<StartVerdict>> = CONFIGS
            .iter()
            .map(|config| {
                let mut monitor = EveryMonitor::with_config(formula.clone(), *config);
                let mut out = Vec::new();
                for (t, s) in &states {
                    monitor.step(*t, s, &mut out).unwrap();
                }
                monitor.finish(&mut out);
                out.sort_by_key(|v| v.start);
                out
            })
            .collect();
        assert_eq!(verdicts[0].len(), states.len());
        assert_eq!(verdicts[0], verdicts[1], "{}", property.name());
        assert_eq!(verdicts[0], verdicts[2], "{}", property.name());
    }
}

fn record(x: f64, y: f64) -> Value {
    Value::Record(Arc::new(Record { id: None, fields: vec![(Arc::from("pos"), Value::vec2(x, y))] }))
}

fn link_formula(text: &str) -> Arc<Formula> {
    let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Ms);
    ctx.declare_value("from");
    ctx.declare_value("to");
    ctx.register_function(Function::new("on_road", (1, Some(1)), |args| match &args[0] {
        Value::Vec2([_, y]) => Ok(Value::Bool(y.abs() < 5.0)),
        other => Err(format!("expected a position, found {}", other.kind())),
    }));
    let expr = kpl_syntax::parse_formula(text).unwrap();
    Arc::new(Formula::from_ast(&expr, &mut ctx).unwrap())
}

/// DyKnow's link conditions for 300 pairs over 200 states at 10 Hz: each pair in a group of all
/// pairs (stepped in turn, as a link process does) must give what an independent progressor
/// without the cache gives, state by state, and a decided condition restarts.
#[test]
fn groups_share_work_without_changing_a_verdict() {
    const PAIRS: usize = 300;
    const STATES: usize = 200;
    let conditions = [
        "eventually[0, 1000] xydist(from.pos, to.pos) < 10.0",
        "eventually[1000, inf] always[0, 1000] on_road(from.pos)",
        "always eventually[0, 10000] always[0, 1000] on_road(from.pos)",
    ];
    // Pair i: off the road for 3 states in 17 (shifted by i), and one pair in 7 for 11 s from
    // 5 s on; partner near or far in turns.
    let state = |step: usize, i: usize| {
        let off_road = (step + i) % 17 < 3 || (i % 7 == 0 && (50..160).contains(&step));
        let y = if off_road { 8.0 } else { 1.0 };
        let gap = if (step / 25 + i) % 2 == 0 { 4.0 } else { 30.0 };
        let x = i as f64 * 50.0 + step as f64;
        SlotState::new(vec![Some(record(x, y)), Some(record(x + gap, y))])
    };
    for text in conditions {
        let formula = link_formula(text);
        for config in CONFIGS {
            let mut group = ProgressorGroup::with_config(formula.clone(), config);
            let ids: Vec<_> = (0..PAIRS).map(|_| group.start()).collect();
            let mut alone: Vec<Progressor> =
                (0..PAIRS).map(|_| Progressor::with_config(formula.clone(), CONFIGS[1])).collect();
            let mut decisions = 0;
            for step in 0..STATES {
                let time = step as Time * 100_000;
                for i in 0..PAIRS {
                    let s = state(step, i);
                    let got = group.step(ids[i], time, &s).unwrap();
                    let want = alone[i].step(time, &s).unwrap();
                    assert_eq!(got, want, "{text}: pair {i} at state {step} ({config:?})");
                    if want.is_some() {
                        decisions += 1;
                        group.restart(ids[i]);
                        alone[i].reset();
                    }
                }
            }
            assert!(decisions > 0, "{text}: no decision");
            let stats = group.stats();
            if config.transition_cache {
                // Most instance-steps are answered by a transition another instance computed.
                assert!(
                    stats.cache_hits > 10 * stats.cache_misses,
                    "{text}: {} hits, {} misses",
                    stats.cache_hits,
                    stats.cache_misses
                );
            }
        }
    }
}
