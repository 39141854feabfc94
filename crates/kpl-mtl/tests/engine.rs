//! The engine's machinery on long streams, where the naive evaluator would be too slow: the
//! transition cache, the collection of the arena and the sharing of instances in a group must
//! not change a verdict or the state at which it is decided. Each of DyKnow's link conditions
//! (over generated pairs) is run with the cache, without it, and collecting after nearly every
//! step; the runs must agree state by state. (The same on the Timescales properties, with their
//! benchmark traces: `crates/kpl-bench/tests/timescales.rs`.)

#![allow(clippy::unwrap_used)] // a test fails loudly

use std::sync::Arc;

use kpl_core::{Record, Time, TimeUnit, Value};
use kpl_mtl::{Context, EngineConfig, Formula, Function, Progressor, ProgressorGroup, SlotState};

const CONFIGS: [EngineConfig; 3] = [
    EngineConfig { transition_cache: true, collect_slack: 4096 },
    EngineConfig { transition_cache: false, collect_slack: 4096 },
    EngineConfig { transition_cache: true, collect_slack: 1 },
];

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
