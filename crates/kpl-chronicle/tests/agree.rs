//! Differential tests: the incremental recogniser finds exactly the recognitions a brute-force
//! matcher finds over the whole event sequence, on random event sequences and random networks
//! (consistent or not), with `hold` and `never` conditions; plus the bounds and errors.
#![allow(clippy::unwrap_used, clippy::indexing_slicing)] // tests

use kpl_chronicle::model::{Chronicle, Event, Hold, ModelError, Never, Pattern, SourceId};
use kpl_chronicle::recognise::{Config, Late, Recogniser, Recognition};
use kpl_chronicle::stn::{Constraint, Stn};
use kpl_core::Time;
use proptest::prelude::*;

/// Sources 0 and 1 take two objects, 2 and 3 one.
fn arity(source: u32) -> usize {
    if source < 2 { 2 } else { 1 }
}

type Occurrence = (Event<u8>, usize);

/// Every recognition by definition: injective assignments of occurrences to nodes with one
/// binding, all constraints and all conditions holding.
fn brute_force(c: &Chronicle, steps: &[(Time, Vec<Event<u8>>)]) -> Vec<Recognition<u8>> {
    let mut occurrences: Vec<Occurrence> = Vec::new();
    for (time, events) in steps {
        for e in events {
            let mut e = e.clone();
            e.time = *time;
            let index = occurrences.len();
            occurrences.push((e, index));
        }
    }
    let mut out = Vec::new();
    let mut chosen: Vec<usize> = Vec::new();
    assign(c, &occurrences, &mut chosen, &mut vec![None; c.params], &mut out);
    out.sort();
    out
}

fn assign(
    c: &Chronicle,
    occ: &[Occurrence],
    chosen: &mut Vec<usize>,
    binding: &mut Vec<Option<u8>>,
    out: &mut Vec<Recognition<u8>>,
) {
    let node = chosen.len();
    if node == c.events.len() {
        let times: Vec<Time> = chosen.iter().map(|&i| occ[i].0.time).collect();
        let constraints_hold = c.constraints.iter().all(|k| {
            let d = times[k.later] - times[k.earlier];
            k.lo.is_none_or(|lo| d >= lo) && k.hi.is_none_or(|hi| d <= hi)
        });
        let objects = |args: &[usize]| -> Vec<u8> { args.iter().map(|&a| binding[a].unwrap()).collect() };
        let holds = c.holds.iter().all(|h| {
            let (t1, t2) = (times[h.from], times[h.to]);
            let args = objects(&h.args);
            let of_fluent = || occ.iter().filter(|(e, _)| e.source == h.source && e.args == args);
            let at_start = of_fluent().rfind(|(e, _)| e.time <= t1).is_some_and(|(e, _)| e.value);
            at_start && !of_fluent().any(|(e, _)| e.time > t1 && e.time <= t2 && !e.value)
        });
        let nevers = c.nevers.iter().all(|n| {
            let (t1, t2) = (times[n.from], times[n.to]);
            let args = objects(&n.pattern.args);
            !occ.iter().any(|(e, _)| {
                e.source == n.pattern.source
                    && e.args == args
                    && e.value == n.pattern.value
                    && e.time > t1
                    && e.time < t2
            })
        });
        if constraints_hold && holds && nevers {
            let valid_time = *times.iter().max().unwrap();
            out.push(Recognition {
                chronicle: 0,
                binding: binding.iter().map(|b| b.unwrap()).collect(),
                times,
                valid_time,
            });
        }
        return;
    }
    let pattern = &c.events[node];
    for (i, (e, _)) in occ.iter().enumerate() {
        if chosen.contains(&i)
            || e.source != pattern.source
            || e.value != pattern.value
            || e.args.len() != pattern.args.len()
        {
            continue;
        }
        let saved = binding.clone();
        let fits = pattern.args.iter().zip(&e.args).all(|(&p, &o)| match binding[p] {
            Some(b) => b == o,
            None => {
                binding[p] = Some(o);
                true
            }
        });
        if fits {
            chosen.push(i);
            assign(c, occ, chosen, binding, out);
            chosen.pop();
        }
        *binding = saved;
    }
}

fn incremental(c: &Chronicle, steps: &[(Time, Vec<Event<u8>>)]) -> Result<Vec<Recognition<u8>>, ModelError> {
    let compiled = c.clone().compile()?;
    let mut r = Recogniser::new(vec![compiled], Config { max_instances: 1_000_000 }).unwrap();
    let mut out = Vec::new();
    for (time, events) in steps {
        out.extend(r.step(*time, events.clone()).unwrap());
    }
    assert_eq!(r.stats().refused, 0);
    out.sort();
    Ok(out)
}

fn args_for(source: u32) -> impl Strategy<Value = Vec<usize>> {
    proptest::collection::vec(0..2usize, arity(source))
}

fn pattern() -> impl Strategy<Value = Pattern> {
    (0..4u32)
        .prop_flat_map(|s| (Just(s), args_for(s), proptest::bool::weighted(0.75)))
        .prop_map(|(s, args, value)| Pattern { source: SourceId(s), args, value })
}

fn bound() -> impl Strategy<Value = (Option<Time>, Option<Time>)> {
    prop_oneof![
        4 => (-4..5i64, 0..8i64).prop_map(|(lo, w)| (Some(lo), Some(lo + w))),
        1 => (-4..5i64).prop_map(|lo| (Some(lo), None)),
        1 => (-4..5i64).prop_map(|hi| (None, Some(hi))),
    ]
}

fn chronicle() -> impl Strategy<Value = Chronicle> {
    (2..5usize)
        .prop_flat_map(|n| {
            let first = (any::<bool>(), any::<bool>()).prop_map(|(value, swap)| Pattern {
                source: SourceId(0),
                args: if swap { vec![1, 0] } else { vec![0, 1] },
                value,
            });
            let tree = proptest::collection::vec((0..n, -4..5i64, 2..12i64), n - 1).prop_map(|v| {
                v.into_iter()
                    .enumerate()
                    .map(|(i, (j, lo, w))| Constraint {
                        later: i + 1,
                        earlier: j % (i + 1),
                        lo: Some(lo),
                        hi: Some(lo + w),
                    })
                    .collect::<Vec<_>>()
            });
            let extra = proptest::collection::vec((0..n, 0..n, bound()), 0..3).prop_map(|v| {
                v.into_iter()
                    .map(|(a, b, (lo, hi))| Constraint { later: a, earlier: b, lo, hi })
                    .collect::<Vec<_>>()
            });
            let holds = proptest::collection::vec((0..4u32, 0..n, 0..n), 0..2).prop_flat_map(|v| {
                v.into_iter()
                    .map(|(s, from, to)| {
                        args_for(s).prop_map(move |args| Hold { source: SourceId(s), args, from, to })
                    })
                    .collect::<Vec<_>>()
            });
            let nevers = proptest::collection::vec((pattern(), 0..n, 0..n), 0..2).prop_map(|v| {
                v.into_iter().map(|(pattern, from, to)| Never { pattern, from, to }).collect::<Vec<_>>()
            });
            (first, proptest::collection::vec(pattern(), n - 1), tree, extra, holds, nevers)
        })
        .prop_map(|(first, rest, mut constraints, extra, holds, nevers)| {
            constraints.extend(extra);
            let mut events = vec![first];
            events.extend(rest);
            let mut c = Chronicle {
                name: "c".into(),
                source: SourceId(9),
                params: 2,
                events,
                constraints,
                holds,
                nevers,
            };
            // Keep the conditions whose `from` cannot come after their `to` (as `kpl check` demands).
            if let Ok(m) = Stn::new(c.events.len(), c.constraints.clone()).minimal() {
                let ordered = |from: usize, to: usize| m.lower(from, to).is_some_and(|lo| lo >= 0);
                c.holds.retain(|h| ordered(h.from, h.to));
                c.nevers.retain(|n| ordered(n.from, n.to));
            }
            c
        })
}

fn steps() -> impl Strategy<Value = Vec<(Time, Vec<Event<u8>>)>> {
    let event = (0..4u32)
        .prop_flat_map(|s| {
            (Just(s), proptest::collection::vec(0..2u8, arity(s)), proptest::bool::weighted(0.75))
        })
        .prop_map(|(s, args, value)| Event { source: SourceId(s), args, value, time: 0 });
    proptest::collection::vec((1..3i64, proptest::collection::vec(event, 1..6)), 1..20).prop_map(|v| {
        let mut time = 0;
        v.into_iter()
            .map(|(dt, events)| {
                time += dt;
                (time, events)
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(600))]

    #[test]
    fn incremental_agrees_with_brute_force(c in chronicle(), steps in steps()) {
        let expected = brute_force(&c, &steps);
        match incremental(&c, &steps) {
            Ok(found) => prop_assert_eq!(found, expected),
            // An inconsistent network has no solution: the matcher must find none.
            Err(ModelError::Inconsistent { .. }) => prop_assert!(expected.is_empty()),
            Err(e) => prop_assert!(false, "{e}"),
        }
    }

    /// Shortest paths say "consistent" exactly when some assignment of integer times satisfies
    /// every constraint (searched exhaustively on a small range).
    #[test]
    fn consistency_agrees_with_search(c in chronicle()) {
        let n = c.events.len();
        let consistent = Stn::new(n, c.constraints.clone()).minimal().is_ok();
        let range = 4 * 9 * n as i64;
        let mut times = vec![0i64; n];
        let found = search(&c.constraints, &mut times, 1, range);
        prop_assert_eq!(consistent, found);
    }
}

fn search(constraints: &[Constraint], times: &mut Vec<i64>, i: usize, range: i64) -> bool {
    let ok = |times: &[i64], upto: usize| {
        constraints.iter().filter(|k| k.later < upto && k.earlier < upto).all(|k| {
            let d = times[k.later] - times[k.earlier];
            k.lo.is_none_or(|lo| d >= lo) && k.hi.is_none_or(|hi| d <= hi)
        })
    };
    if i == times.len() {
        return ok(times, i);
    }
    for t in -range..=range {
        times[i] = t;
        if ok(times, i + 1) && search(constraints, times, i + 1, range) {
            return true;
        }
    }
    false
}

fn two_step(lo: Time, hi: Time) -> Chronicle {
    Chronicle {
        name: "two".into(),
        source: SourceId(9),
        params: 1,
        events: vec![
            Pattern { source: SourceId(2), args: vec![0], value: true },
            Pattern { source: SourceId(3), args: vec![0], value: true },
        ],
        constraints: vec![Constraint { later: 1, earlier: 0, lo: Some(lo), hi: Some(hi) }],
        holds: vec![],
        nevers: vec![],
    }
}

fn ev(source: u32, object: u8) -> Event<u8> {
    Event { source: SourceId(source), args: vec![object], value: true, time: 0 }
}

#[test]
fn partial_instances_expire_at_their_deadline() {
    let mut r = Recogniser::new(vec![two_step(1, 5).compile().unwrap()], Config::default()).unwrap();
    for t in 0..100 {
        r.step(t * 10, vec![ev(2, (t % 7) as u8)]).unwrap();
        // Each instance waits at most 5 time units: never more than one alive at a step's end.
        assert!(r.stats().instances <= 1, "{:?}", r.stats());
    }
    assert_eq!(r.stats().expired, 99);
}

#[test]
fn the_instance_bound_is_kept_and_counted() {
    let mut r =
        Recogniser::new(vec![two_step(1, 1000).compile().unwrap()], Config { max_instances: 3 }).unwrap();
    r.step(0, (0..5).map(|o| ev(2, o)).collect()).unwrap();
    assert_eq!(r.stats().instances, 3);
    assert_eq!(r.stats().refused, 2);
}

/// Steps come in increasing time: a second step at an instant (or an earlier one) is refused,
/// counted, and changes nothing; the instant's events belong in one step.
#[test]
fn a_step_not_after_the_last_is_refused_and_changes_nothing() {
    let mut r = Recogniser::new(vec![two_step(1, 5).compile().unwrap()], Config::default()).unwrap();
    r.step(10, vec![ev(2, 1)]).unwrap();
    assert_eq!(r.stats().instances, 1);
    assert_eq!(r.step(10, vec![ev(2, 2), ev(3, 1)]), Err(Late { time: 10, now: 10 }));
    assert_eq!(r.step(9, vec![ev(3, 1)]), Err(Late { time: 9, now: 10 }));
    assert_eq!((r.stats().late_steps, r.stats().instances), (2, 1));
    assert_eq!(r.step(11, vec![ev(3, 1)]).unwrap().len(), 1);
}

/// A partial instance whose `hold` fails before its `to` event is dropped then (it could only
/// complete into a failure), not kept to its deadline; a hold failing on other objects keeps it.
#[test]
fn an_instance_whose_hold_failed_is_dropped_at_once() {
    let mut c = two_step(1, 1000);
    c.holds = vec![Hold { source: SourceId(4), args: vec![0], from: 0, to: 1 }];
    let fluent = |object: u8, value: bool| Event { value, ..ev(4, object) };
    let run = |fails: Option<u8>| {
        let mut r = Recogniser::new(vec![c.clone().compile().unwrap()], Config::default()).unwrap();
        r.step(0, vec![fluent(1, true), fluent(2, true), ev(2, 1)]).unwrap();
        assert_eq!(r.stats().instances, 1);
        r.step(5, fails.map(|o| fluent(o, false)).into_iter().collect()).unwrap();
        let instances = r.stats().instances;
        let found = r.step(6, vec![ev(3, 1)]).unwrap();
        (instances, r.stats().broken, found.len())
    };
    assert_eq!(run(None), (1, 0, 1));
    assert_eq!(run(Some(2)), (1, 0, 1));
    assert_eq!(run(Some(1)), (0, 1, 0));
}

/// A partial instance after whose `from` event an event its `never` forbids occurs is dropped at
/// the next instant (it could only complete into a failure), not kept to its deadline; at the
/// forbidden event's own instant a `to` event may still come (the event is then not strictly
/// between the two), and a forbidden event on other objects keeps it.
#[test]
fn an_instance_that_a_never_forbids_is_dropped_at_the_next_instant() {
    let mut c = two_step(1, 1000);
    c.nevers =
        vec![Never { pattern: Pattern { source: SourceId(4), args: vec![0], value: true }, from: 0, to: 1 }];
    let run = |forbidden: Option<u8>| {
        let mut r = Recogniser::new(vec![c.clone().compile().unwrap()], Config::default()).unwrap();
        r.step(0, vec![ev(2, 1)]).unwrap();
        r.step(5, forbidden.map(|o| ev(4, o)).into_iter().collect()).unwrap();
        let instances = r.stats().instances;
        let found = r.step(6, vec![ev(3, 1)]).unwrap();
        (instances, r.stats().broken, found.len())
    };
    assert_eq!(run(None), (1, 0, 1));
    assert_eq!(run(Some(2)), (1, 0, 1));
    assert_eq!(run(Some(1)), (1, 1, 0));
    // The `to` event at the forbidden event's instant (after it, in the same step).
    let mut r = Recogniser::new(vec![c.clone().compile().unwrap()], Config::default()).unwrap();
    r.step(0, vec![ev(2, 1)]).unwrap();
    assert_eq!(r.step(5, vec![ev(4, 1), ev(3, 1)]).unwrap().len(), 1);
    assert_eq!(r.stats().broken, 0);
}

#[test]
fn a_recognition_is_an_event_of_chronicles_that_use_it() {
    // outer: `recognised two(x)` then source 2 on x again within 3.
    let inner = two_step(1, 5);
    let outer = Chronicle {
        name: "outer".into(),
        source: SourceId(10),
        params: 1,
        events: vec![
            Pattern { source: SourceId(9), args: vec![0], value: true },
            Pattern { source: SourceId(2), args: vec![0], value: true },
        ],
        constraints: vec![Constraint { later: 1, earlier: 0, lo: Some(0), hi: Some(3) }],
        holds: vec![],
        nevers: vec![],
    };
    // Given in the "wrong" order: the recogniser runs `two` first.
    let mut r =
        Recogniser::new(vec![outer.compile().unwrap(), inner.compile().unwrap()], Config::default()).unwrap();
    assert!(r.step(0, vec![ev(2, 1)]).unwrap().is_empty());
    let at_2 = r.step(2, vec![ev(3, 1)]).unwrap();
    assert_eq!(at_2.iter().map(|x| x.chronicle).collect::<Vec<_>>(), [1]);
    let at_4 = r.step(4, vec![ev(2, 1)]).unwrap();
    assert_eq!(at_4.len(), 1);
    assert_eq!((at_4[0].chronicle, at_4[0].times.clone()), (0, vec![2, 4]));
}

#[test]
fn chronicles_recognising_each_other_are_refused() {
    let mut a = two_step(1, 5);
    a.events[1].source = SourceId(10);
    let mut b = two_step(1, 5);
    b.source = SourceId(10);
    b.events[1].source = SourceId(9);
    assert!(
        Recogniser::<u8>::new(vec![a.compile().unwrap(), b.compile().unwrap()], Config::default()).is_err()
    );
}

#[test]
fn unbounded_and_unbound_chronicles_are_refused() {
    let mut c = two_step(1, 5);
    c.constraints[0].hi = None;
    assert!(matches!(c.compile(), Err(ModelError::Unbounded { .. })));
    let mut c = two_step(1, 5);
    c.params = 2;
    assert!(matches!(c.compile(), Err(ModelError::Unbound { param: 1, .. })));
}

/// The generators reach the interesting cases: recognitions found, and conditions that reject
/// some complete matches (so the differential test compares more than empty sets).
#[test]
fn generated_cases_are_not_trivial() {
    use proptest::strategy::ValueTree;
    use proptest::test_runner::{Config as RunnerConfig, TestRng, TestRunner};
    let mut runner = TestRunner::new_with_rng(
        RunnerConfig::default(),
        TestRng::deterministic_rng(RunnerConfig::default().rng_algorithm),
    );
    let (mut with_recognitions, mut conditions_matter, mut inconsistent) = (0, 0, 0);
    for _ in 0..400 {
        let c = chronicle().new_tree(&mut runner).unwrap().current();
        let steps = steps().new_tree(&mut runner).unwrap().current();
        let found = brute_force(&c, &steps);
        let mut unconditional = c.clone();
        unconditional.holds.clear();
        unconditional.nevers.clear();
        with_recognitions += usize::from(!found.is_empty());
        conditions_matter += usize::from(brute_force(&unconditional, &steps).len() > found.len());
        inconsistent += usize::from(matches!(c.compile(), Err(ModelError::Inconsistent { .. })));
    }
    assert!(with_recognitions >= 40, "{with_recognitions} of 400 cases recognise something");
    assert!(conditions_matter >= 10, "conditions reject matches in {conditions_matter} of 400 cases");
    assert!(inconsistent >= 10, "{inconsistent} of 400 networks are inconsistent");
}
