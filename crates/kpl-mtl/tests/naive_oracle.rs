//! Differential test against a naive, direct evaluator of the semantics in `docs/mtl.md`.
//!
//! The evaluator here knows nothing of progression: it quantifies over trace positions as the
//! definitions do. The final verdict uses the finite-trace semantics; the time a verdict became
//! certain uses the three-valued (Kleene) semantics over each prefix, where a window not yet
//! closed by the last state's time is unknown, and where a subformula that has one value on every
//! trace by the constant rules of `docs/mtl.md` (`always[2, 4] true`, `eventually[1, 3] false`)
//! has it at once. Thousands of random formulas (nesting depth up to
//! 4, every operator, bounded and unbounded windows, quantifiers) over random traces with uneven
//! time steps must give the same verdicts, the same `decided_at`, and the same verdicts from every
//! state (`--every`), as the engine: in its default configuration, without the transition cache,
//! collecting its arena after nearly every step, and with instances of one formula on different
//! traces stepped in turn in one `ProgressorGroup` (so that they share residuals and cached
//! transitions).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // a test reports and fails loudly

mod common;

use common::{F, Gen, TraceState, compile, show, slot_state};
use kpl_core::Time;
use kpl_mtl::{EngineConfig, EveryMonitor, Progressor, ProgressorGroup, StartVerdict};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The objects bound by enclosing quantifiers: indices into `TraceState::objects`.
type Env = Vec<usize>;

fn atom(f: &F, s: &TraceState, env: &Env) -> Option<bool> {
    Some(match f {
        F::True => true,
        F::False => false,
        F::Prop(i) => s.props[*i],
        F::Cmp { var, greater, c } => {
            if *greater {
                s.nums[*var] > *c
            } else {
                s.nums[*var] < *c
            }
        }
        F::ObjCmp { depth, greater, c } => {
            let v = s.objects[env[*depth as usize]];
            if *greater { v > *c } else { v < *c }
        }
        _ => return None,
    })
}

/// Kleene conjunction / disjunction of three-valued truth values.
fn and3(values: impl Iterator<Item = Option<bool>>) -> Option<bool> {
    let mut all_true = true;
    for v in values {
        match v {
            Some(false) => return Some(false),
            None => all_true = false,
            Some(true) => {}
        }
    }
    if all_true { Some(true) } else { None }
}

fn or3(values: impl Iterator<Item = Option<bool>>) -> Option<bool> {
    and3(values.map(|v| v.map(|b| !b))).map(|b| !b)
}

fn in_window(trace: &[TraceState], i: usize, j: usize, lo: Time, hi: Option<Time>) -> bool {
    let d = trace[j].time - trace[i].time;
    d >= lo && hi.is_none_or(|h| d <= h)
}

/// The window of position `i` cannot receive another state after the prefix ending at `k`
/// (later states are at least one time unit after `trace[k].time`).
fn closed(trace: &[TraceState], i: usize, k: usize, hi: Option<Time>) -> bool {
    hi.is_some_and(|h| trace[i].time + h <= trace[k].time)
}

/// The value of `f` on every trace, if the constant rules of `docs/mtl.md` give one: `true` and
/// `false`, the connectives over constants, `always[a, b] true` and `eventually[a, b] false`
/// (and `always[0, b] false`, `eventually[0, b] true`: the window holds the current state), the
/// same for until's right side, `forall` of `true` and `exists` of `false`.
fn constant(f: &F) -> Option<bool> {
    let all = |gs: &[F], of: bool| {
        let values: Vec<Option<bool>> = gs.iter().map(constant).collect();
        if values.contains(&Some(!of)) {
            Some(!of)
        } else if values.iter().all(|v| *v == Some(of)) {
            Some(of)
        } else {
            None
        }
    };
    match f {
        F::True => Some(true),
        F::False => Some(false),
        F::Not(g) => constant(g).map(|b| !b),
        F::And(gs) => all(gs, true),
        F::Or(gs) => all(gs, false),
        F::Implies(a, b) => match (constant(a), constant(b)) {
            (Some(false), _) | (_, Some(true)) => Some(true),
            (Some(true), Some(false)) => Some(false),
            _ => None,
        },
        F::Ev(lo, _, g) | F::Until(lo, _, _, g) => match constant(g) {
            Some(false) => Some(false),
            Some(true) if *lo == 0 => Some(true),
            _ => None,
        },
        F::Al(lo, _, g) => match constant(g) {
            Some(true) => Some(true),
            Some(false) if *lo == 0 => Some(false),
            _ => None,
        },
        F::Forall(g) => constant(g).filter(|b| *b),
        F::Exists(g) => constant(g).filter(|b| !*b),
        F::Prop(_) | F::Cmp { .. } | F::ObjCmp { .. } => None,
    }
}

/// The three-valued value of `f` at every position `0..=k` of the prefix `trace[..=k]`. With
/// `end` set, the prefix is the whole trace and no state follows: every window is closed, which
/// is the finite-trace semantics (and then no value is unknown).
fn eval(f: &F, trace: &[TraceState], k: usize, end: bool, env: &Env) -> Vec<Option<bool>> {
    let positions = 0..=k;
    if let Some(v) = constant(f) {
        return positions.map(|_| Some(v)).collect();
    }
    let is_closed = |i: usize, hi: Option<Time>| end || closed(trace, i, k, hi);
    match f {
        F::Not(g) => eval(g, trace, k, end, env).into_iter().map(|v| v.map(|b| !b)).collect(),
        F::And(gs) | F::Or(gs) => {
            let parts: Vec<Vec<Option<bool>>> = gs.iter().map(|g| eval(g, trace, k, end, env)).collect();
            positions
                .map(|i| {
                    let values = parts.iter().map(|p| p[i]);
                    if matches!(f, F::And(_)) { and3(values) } else { or3(values) }
                })
                .collect()
        }
        F::Implies(a, b) => {
            let (va, vb) = (eval(a, trace, k, end, env), eval(b, trace, k, end, env));
            positions.map(|i| or3([va[i].map(|x| !x), vb[i]].into_iter())).collect()
        }
        F::Ev(lo, hi, g) | F::Al(lo, hi, g) => {
            let vg = eval(g, trace, k, end, env);
            let eventually = matches!(f, F::Ev(..));
            positions
                .map(|i| {
                    let window: Vec<Option<bool>> =
                        (i..=k).filter(|&j| in_window(trace, i, j, *lo, *hi)).map(|j| vg[j]).collect();
                    let (decisive, other) = if eventually { (true, false) } else { (false, true) };
                    if window.contains(&Some(decisive)) {
                        Some(decisive)
                    } else if is_closed(i, *hi) && window.iter().all(|v| *v == Some(other)) {
                        Some(other)
                    } else {
                        None
                    }
                })
                .collect()
        }
        F::Until(lo, hi, a, b) => {
            let (va, vb) = (eval(a, trace, k, end, env), eval(b, trace, k, end, env));
            positions
                .map(|i| {
                    // psi at j in the window, phi at every position strictly between i and j.
                    let witness = (i..=k).any(|j| {
                        in_window(trace, i, j, *lo, *hi)
                            && vb[j] == Some(true)
                            && (i + 1..j).all(|m| va[m] == Some(true))
                    });
                    if witness {
                        return Some(true);
                    }
                    let every_candidate_fails = (i..=k)
                        .filter(|&j| in_window(trace, i, j, *lo, *hi))
                        .all(|j| vb[j] == Some(false) || (i + 1..j).any(|m| va[m] == Some(false)));
                    let future_blocked = is_closed(i, *hi) || (i + 1..=k).any(|m| va[m] == Some(false));
                    if every_candidate_fails && future_blocked { Some(false) } else { None }
                })
                .collect()
        }
        F::Forall(g) | F::Exists(g) => {
            let per_object: Vec<Vec<Option<bool>>> = (0..common::OBJECTS.len())
                .map(|o| {
                    let mut inner = env.clone();
                    inner.push(o);
                    eval(g, trace, k, end, &inner)
                })
                .collect();
            positions
                .map(|i| {
                    let values = per_object.iter().map(|v| v[i]);
                    if matches!(f, F::Forall(_)) { and3(values) } else { or3(values) }
                })
                .collect()
        }
        _ => positions.map(|i| atom(f, &trace[i], env)).collect(),
    }
}

/// For every start position: its finite-trace verdict and the time at which the three-valued
/// prefix semantics first decided it (`None`: only the end of the trace did).
fn naive(f: &F, trace: &[TraceState]) -> Vec<(bool, Option<Time>)> {
    let n = trace.len();
    let last = trace.len() - 1;
    let finals: Vec<bool> = eval(f, trace, last, true, &Vec::new())
        .into_iter()
        .map(|v| v.expect("the finite-trace semantics is two-valued"))
        .collect();
    let mut decided: Vec<Option<Time>> = vec![None; n];
    for k in 0..n {
        let values = eval(f, trace, k, false, &Vec::new());
        for i in 0..=k {
            if decided[i].is_none()
                && let Some(v) = values[i]
            {
                assert_eq!(
                    v, finals[i],
                    "the prefix semantics decided {v} at {k} but the trace gives {}",
                    finals[i]
                );
                decided[i] = Some(trace[k].time);
            }
        }
    }
    finals.into_iter().zip(decided).collect()
}

/// The configurations every case runs in: the default, no transition cache, and collecting
/// the arena after nearly every step.
const CONFIGS: [EngineConfig; 3] = [
    EngineConfig { transition_cache: true, collect_slack: 4096 },
    EngineConfig { transition_cache: false, collect_slack: 4096 },
    EngineConfig { transition_cache: true, collect_slack: 1 },
];

fn engine_single(f: &F, trace: &[TraceState], config: EngineConfig) -> (bool, Option<Time>, usize) {
    let mut progressor = Progressor::with_config(compile(f), config);
    let mut largest = 0;
    for s in trace {
        progressor.step(s.time, &slot_state(s)).expect("test states have every value");
        largest = largest.max(progressor.residual_size());
    }
    let verdict = progressor.finish().expect("the trace is not empty");
    (verdict, progressor.decided_at(), largest)
}

/// Each trace run by its own instance of one group, the instances stepped in turn.
fn engine_group(f: &F, traces: &[Vec<TraceState>], config: EngineConfig) -> Vec<(bool, Option<Time>)> {
    let mut group = ProgressorGroup::with_config(compile(f), config);
    let ids: Vec<_> = traces.iter().map(|_| group.start()).collect();
    let longest = traces.iter().map(Vec::len).max().unwrap_or(0);
    for i in 0..longest {
        for (id, trace) in ids.iter().zip(traces) {
            if let Some(s) = trace.get(i) {
                group.step(*id, s.time, &slot_state(s)).expect("test states have every value");
            }
        }
    }
    ids.iter().map(|id| (group.finish(*id).expect("not empty"), group.decided_at(*id))).collect()
}

fn engine_every(f: &F, trace: &[TraceState], config: EngineConfig) -> Vec<(bool, Option<Time>)> {
    let mut monitor = EveryMonitor::with_config(compile(f), config);
    let mut out: Vec<StartVerdict> = Vec::new();
    for s in trace {
        monitor.step(s.time, &slot_state(s), &mut out).expect("test states have every value");
    }
    monitor.finish(&mut out);
    let mut by_start = vec![None; trace.len()];
    for v in out {
        assert!(by_start[v.start].is_none(), "two verdicts for start {}", v.start);
        by_start[v.start] = Some((v.verdict, v.decided_at));
    }
    by_start.into_iter().map(|v| v.expect("a verdict for every start")).collect()
}

fn times(trace: &[TraceState]) -> Vec<Time> {
    trace.iter().map(|s| s.time).collect()
}

fn check(seed: u64, cases: usize, quantifiers: bool) {
    let mut generator = Gen {
        rng: ChaCha8Rng::seed_from_u64(seed),
        max_bound: 12,
        quantifiers,
        unbounded: true,
        constants: true,
    };
    let (mut at_first, mut later, mut at_end) = (0, 0, 0);
    let mut largest_residual = 0;
    for case in 0..cases {
        // A temporal operator on top makes the decision time interesting more often.
        let f = loop {
            let f = generator.formula(4, 0);
            if matches!(f, F::Ev(..) | F::Al(..) | F::Until(..))
                || rand::Rng::random_bool(&mut generator.rng, 0.2)
            {
                break f;
            }
        };
        let len = rand::Rng::random_range(&mut generator.rng, 1..=30);
        let trace = generator.trace(len, false);
        let expected = naive(&f, &trace);
        let config = CONFIGS[case % CONFIGS.len()];
        let (verdict, decided_at, largest) = engine_single(&f, &trace, config);
        largest_residual = largest_residual.max(largest);
        assert_eq!(
            (verdict, decided_at),
            expected[0],
            "case {case} ({config:?}): formula {}\ntimes {:?}\ntrace {:?}",
            show(&f),
            times(&trace),
            trace
        );
        if case % 4 == 0 {
            // Two more traces of the same formula, all three in one group.
            let others: Vec<Vec<TraceState>> = (0..2)
                .map(|_| {
                    let len = rand::Rng::random_range(&mut generator.rng, 1..=30);
                    let even = rand::Rng::random_bool(&mut generator.rng, 0.5);
                    generator.trace(len, even)
                })
                .collect();
            let mut traces = vec![trace.clone()];
            traces.extend(others);
            let got = engine_group(&f, &traces, config);
            for (n, (t, got)) in traces.iter().zip(got).enumerate() {
                assert_eq!(
                    got,
                    naive(&f, t)[0],
                    "case {case}, instance {n} of a group ({config:?}): formula {}\ntimes {:?}\ntrace {:?}",
                    show(&f),
                    times(t),
                    t
                );
            }
        }
        match decided_at {
            Some(t) if t == trace[0].time => at_first += 1,
            Some(_) => later += 1,
            None => at_end += 1,
        }
        let every = engine_every(&f, &trace, config);
        for (i, (got, want)) in every.iter().zip(expected.iter()).enumerate() {
            assert_eq!(
                got,
                want,
                "case {case}, start {i} ({config:?}): formula {}\ntimes {:?}\ntrace {:?}",
                show(&f),
                times(&trace),
                trace
            );
        }
    }
    eprintln!(
        "{cases} cases: decided at the first state {at_first}, later {later}, only by the end {at_end}; \
         largest residual {largest_residual}"
    );
    // The suite must exercise every kind of decision, or it proves little.
    assert!(later > cases / 5 && at_end > cases / 20, "too few non-trivial cases");
}

#[test]
fn agrees_with_the_naive_evaluator_on_random_formulas() {
    check(0x5eed_0001, 10_000, false);
}

#[test]
fn agrees_with_the_naive_evaluator_with_quantifiers() {
    check(0x5eed_0002, 3000, true);
}
