//! The MTL engine's machinery on the Timescales properties' long traces, where the naive
//! evaluator would be too slow: the transition cache and the collection of the arena must not
//! change a verdict or the state at which it is decided. Each property (over its benchmark trace,
//! holding and with the failing end, evenly and unevenly spaced) is run with the cache, without
//! it, and collecting after nearly every step; the runs must agree state by state.

#![allow(clippy::unwrap_used)] // a test fails loudly

use std::sync::Arc;

use kpl_bench::timescales::Property;
use kpl_core::{Time, TimeUnit};
use kpl_mtl::{Context, EngineConfig, EveryMonitor, Formula, Progressor, SlotState, StartVerdict};

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
