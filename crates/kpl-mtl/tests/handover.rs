//! Handing an instance of a `ProgressorGroup` over to another group (`hand_over`, `take_over`):
//! an instance taken over goes on exactly as the one that stayed, on random formulas (every
//! operator, quantifiers) and random traces, through JSON, into groups whose arenas hold other
//! instances and number their nodes differently, with and without the transition cache and with
//! collections after nearly every step; a handover of another formula or a malformed one (it may
//! come from the network) is refused, and none makes the engine panic.

#![allow(clippy::unwrap_used, clippy::expect_used)] // a test fails loudly

mod common;

use common::{F, Gen, TraceState, compile, show, slot_state};
use kpl_mtl::{EngineConfig, HandedNode, Handover, HandoverError, ProgressorGroup};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const CONFIGS: [EngineConfig; 3] = [
    EngineConfig { transition_cache: true, collect_slack: 4096 },
    EngineConfig { transition_cache: false, collect_slack: 4096 },
    EngineConfig { transition_cache: true, collect_slack: 1 },
];

/// Steps `id` of `group` through `states`, returning what each step returned.
fn run(group: &mut ProgressorGroup, id: kpl_mtl::InstanceId, states: &[TraceState]) -> Vec<Option<bool>> {
    states
        .iter()
        .map(|s| group.step(id, s.time, &slot_state(s)).expect("test states have every value"))
        .collect()
}

/// Through JSON, as a handover between processes goes.
fn through_json(handover: &Handover) -> Handover {
    serde_json::from_str(&serde_json::to_string(handover).unwrap()).unwrap()
}

/// A group of `f` with `others` instances stepped through their own traces, so that its arena
/// holds residuals of its own before anything is taken over.
fn busy_group(f: &F, config: EngineConfig, generator: &mut Gen, others: usize) -> ProgressorGroup {
    let mut group = ProgressorGroup::with_config(compile(f), config);
    for _ in 0..others {
        let id = group.start();
        let len = generator.rng.random_range(1..=20);
        let trace = generator.trace(len, false);
        run(&mut group, id, &trace);
    }
    group
}

#[test]
fn a_taken_over_instance_goes_on_as_the_one_that_stayed() {
    let mut generator = Gen {
        rng: ChaCha8Rng::seed_from_u64(2811),
        max_bound: 12,
        quantifiers: true,
        unbounded: true,
        constants: true,
    };
    let (mut moved_pending, mut moved_decided, mut decided_after) = (0, 0, 0);
    let cases = 1500;
    for case in 0..cases {
        // A temporal operator on top keeps more instances pending at the cut.
        let f = loop {
            let f = generator.formula(4, 0);
            if matches!(f, F::Ev(..) | F::Al(..) | F::Until(..)) || generator.rng.random_bool(0.1) {
                break f;
            }
        };
        let config = CONFIGS[case % CONFIGS.len()];
        let len = generator.rng.random_range(1..=30);
        let trace = generator.trace(len, false);
        let cut = if generator.rng.random_bool(0.8) {
            generator.rng.random_range(0..=len / 3)
        } else {
            generator.rng.random_range(0..=len)
        };
        let mut here = busy_group(&f, config, &mut generator, 2);
        let stays = here.start();
        let before = run(&mut here, stays, &trace[..cut]);
        let handover = through_json(&here.hand_over(stays).unwrap());
        let mut there = busy_group(&f, CONFIGS[(case + 1) % CONFIGS.len()], &mut generator, case % 3);
        let moved = there.take_over(&handover).unwrap_or_else(|e| {
            panic!("case {case}: refused its own handover ({e}): {}\n{handover:?}", show(&f))
        });
        let context = || format!("case {case}, cut at {cut} of {len}: {}\ntrace {trace:?}", show(&f));
        assert_eq!(there.residual_size(moved), here.residual_size(stays), "{}", context());
        assert_eq!(there.verdict(moved), here.verdict(stays), "{}", context());
        if here.verdict(stays).is_some() {
            moved_decided += 1;
        } else if cut > 0 {
            moved_pending += 1;
        }
        // The rest of the trace, in both; half of the time the moved one is handed back midway.
        let back = generator.rng.random_bool(0.5).then(|| generator.rng.random_range(cut..=len));
        let (rest_here, rest_there) = match back {
            Some(at) => {
                let mut got = run(&mut there, moved, &trace[cut..at]);
                let returned = here_again(&f, config, &there.hand_over(moved).unwrap());
                let (mut group, id) = returned;
                got.extend(run(&mut group, id, &trace[at..]));
                let verdict = (group.finish(id), group.decided_at(id));
                (run(&mut here, stays, &trace[cut..]), (got, verdict))
            }
            None => {
                let got = run(&mut there, moved, &trace[cut..]);
                (run(&mut here, stays, &trace[cut..]), (got, (there.finish(moved), there.decided_at(moved))))
            }
        };
        assert_eq!(rest_there.0, rest_here, "{}", context());
        let stayed = (here.finish(stays), here.decided_at(stays));
        assert_eq!(rest_there.1, stayed, "{}", context());
        if before.iter().all(Option::is_none) && rest_here.iter().any(Option::is_some) && cut > 0 {
            decided_after += 1;
        }
    }
    eprintln!(
        "{cases} cases: moved pending {moved_pending}, moved decided {moved_decided}, decided after the move {decided_after}"
    );
    // The cases must move residuals that still have work to do, or they prove little.
    assert!(moved_pending > cases / 5 && decided_after > cases / 10 && moved_decided > cases / 20);
}

/// A fresh group of the formula with the handover taken over.
fn here_again(f: &F, config: EngineConfig, handover: &Handover) -> (ProgressorGroup, kpl_mtl::InstanceId) {
    let mut group = ProgressorGroup::with_config(compile(f), config);
    let id = group.take_over(&through_json(handover)).expect("a handover of the group's own formula");
    (group, id)
}

/// A pending instance of `f` after a few states, and its handover.
fn pending(f: &F, times: &[i64]) -> (ProgressorGroup, Handover) {
    let mut group = ProgressorGroup::new(compile(f));
    let id = group.start();
    for t in times {
        let s = TraceState { time: *t, props: [false; 3], nums: [0.0; 2], objects: [0.0; 3] };
        group.step(id, s.time, &slot_state(&s)).unwrap();
    }
    let handover = group.hand_over(id).unwrap();
    (group, handover)
}

#[test]
fn handovers_of_another_formula_or_malformed_are_refused() {
    // always[0, 10] (p or eventually[0, 3] q), pending after two states.
    let f = F::Al(0, Some(10), Box::new(F::Or(vec![F::Prop(0), F::Ev(0, Some(3), Box::new(F::Prop(1)))])));
    let (mut group, good) = pending(&f, &[0, 1]);
    assert!(good.nodes.len() > 1, "{good:?}");
    assert!(group.take_over(&good).is_ok());

    let other = F::Al(0, Some(10), Box::new(F::Prop(0)));
    let mut other_group = ProgressorGroup::new(compile(&other));
    assert!(matches!(other_group.take_over(&good), Err(HandoverError::OtherFormula { .. })));

    let mut refused = |edit: &dyn Fn(&mut Handover)| {
        let mut bad = good.clone();
        edit(&mut bad);
        let before = group.len();
        let result = group.take_over(&bad);
        assert_eq!(group.len(), before, "a refused handover adds no instance");
        result.expect_err(&format!("accepted {bad:?}"))
    };
    // A child after its parent, or not there at all.
    let last = good.nodes.len() - 1;
    let forward = refused(&|h| {
        let n = h.nodes.len() as u32;
        for node in &mut h.nodes {
            if let HandedNode::And { kids, .. } | HandedNode::Or { kids, .. } = node {
                kids[0] = n;
            }
        }
    });
    assert!(matches!(forward, HandoverError::BadNode { .. }), "{forward}");
    // A temporal node whose template is not one, or not of its operator.
    let template = refused(&|h| {
        for node in &mut h.nodes {
            if let HandedNode::Temporal { template, .. } = node {
                *template = 0;
            }
        }
    });
    assert!(template.to_string().contains("template"), "{template}");
    let empty_window = refused(&|h| {
        for node in &mut h.nodes {
            if let HandedNode::Temporal { lo, hi, .. } = node {
                *lo = hi.unwrap_or(5) + 1;
            }
        }
    });
    assert!(empty_window.to_string().contains("window"), "{empty_window}");
    // A verdict the residual does not have; a residual without its states; none at all.
    refused(&|h| {
        h.verdict = Some(true);
        h.decided_at = Some(1);
    });
    refused(&|h| h.last_time = None);
    refused(&|h| h.nodes.clear());
    refused(&|h| h.nodes[last] = HandedNode::Start);
    refused(&|h| h.nodes.insert(0, HandedNode::Start));
    refused(&|h| h.nodes.push(HandedNode::Bind { objects: vec![(7, "a".into())], kid: 0 }));
    // A decided instance goes over with its verdict.
    let (mut decided_group, _) = pending(&f, &[0, 1]);
    let id = decided_group.start();
    let s = TraceState { time: 0, props: [false; 3], nums: [0.0; 2], objects: [0.0; 3] };
    decided_group.step(id, 0, &slot_state(&s)).unwrap();
    assert_eq!(decided_group.step(id, 20, &slot_state(&s)).unwrap(), Some(false));
    let decided = decided_group.hand_over(id).unwrap();
    let taken = group.take_over(&decided).unwrap();
    assert_eq!((group.verdict(taken), group.decided_at(taken)), (Some(false), Some(20)));
}

/// A random edit of a handover: any number, index, operator or node changed, nodes dropped,
/// repeated or moved.
fn mutate(h: &mut Handover, rng: &mut ChaCha8Rng) {
    let n = h.nodes.len().max(1);
    let any = |rng: &mut ChaCha8Rng| rng.random_range(0..(n as u32 + 2));
    for _ in 0..rng.random_range(1..=3) {
        let i = rng.random_range(0..n);
        match rng.random_range(0..9) {
            0 => h.last_time = if rng.random_bool(0.5) { None } else { Some(rng.random_range(-5..50)) },
            1 => (h.verdict, h.decided_at) = (Some(rng.random_bool(0.5)), Some(rng.random_range(0..50))),
            2 if i < h.nodes.len() => {
                h.nodes.remove(i);
            }
            3 if i < h.nodes.len() => {
                let node = h.nodes[i].clone();
                h.nodes.insert(rng.random_range(0..n), node);
            }
            _ => {
                let Some(node) = h.nodes.get_mut(i) else { continue };
                match node {
                    HandedNode::And { kids, simplified } | HandedNode::Or { kids, simplified } => {
                        if let Some(k) = kids.first_mut() {
                            *k = any(rng);
                        }
                        if rng.random_bool(0.3) {
                            kids.truncate(rng.random_range(0..2));
                        }
                        *simplified = rng.random_bool(0.5);
                    }
                    HandedNode::Temporal { lo, hi, template, .. } => match rng.random_range(0..4) {
                        0 => *lo = rng.random_range(0..40),
                        1 => *hi = rng.random_bool(0.8).then(|| rng.random_range(0..40)),
                        2 => *template = rng.random_range(0..40),
                        _ => *hi = Some(u64::MAX - 1),
                    },
                    HandedNode::Bind { objects, kid } => {
                        *kid = any(rng);
                        if let Some(o) = objects.first_mut() {
                            o.0 = rng.random_range(0..3);
                            o.1 = ["a", "b", "zz"][rng.random_range(0..3)].into();
                        }
                    }
                    other => {
                        *other = [HandedNode::True, HandedNode::False, HandedNode::Start]
                            [rng.random_range(0..3)]
                        .clone()
                    }
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Whatever arrives, `take_over` answers, and an instance it accepted steps without panicking.
    #[test]
    fn a_malformed_handover_never_makes_the_engine_panic(seed in any::<u64>()) {
        let mut generator = Gen {
            rng: ChaCha8Rng::seed_from_u64(seed),
            max_bound: 12,
            quantifiers: true,
            unbounded: true,
            constants: false,
        };
        let f = generator.formula(4, 0);
        let len = generator.rng.random_range(1..=12);
        let trace = generator.trace(len, false);
        let mut group = ProgressorGroup::new(compile(&f));
        let id = group.start();
        run(&mut group, id, &trace);
        let mut handover = group.hand_over(id).unwrap();
        mutate(&mut handover, &mut generator.rng);
        let mut other = busy_group(&f, CONFIGS[(seed % 3) as usize], &mut generator, 1);
        if let Ok(taken) = other.take_over(&handover) {
            let last = trace[trace.len() - 1].time;
            let later = generator.trace(5, false);
            for s in later {
                let _ = other.step(taken, last + 1 + s.time, &slot_state(&s));
            }
            let _ = other.finish(taken);
        }
    }
}
