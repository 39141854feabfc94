//! Differential test against RTAMT (PyPI `rtamt`, offline discrete-time STL), an independent
//! monitor, on evenly spaced traces (one state per time unit).
//!
//! RTAMT's `φ until[a:b] ψ` asks for φ from the current state on; ours (DyKnow's) only strictly
//! after it. Each of our untils is therefore translated with RTAMT's strong next `s_next`:
//! `φ until[0, b] ψ` becomes `ψ or s_next(φ until[0:b-1] ψ)` and `φ until[a, b] ψ` with `a > 0`
//! becomes `s_next(φ until[a-1:b-1] ψ)` (see `docs/mtl.md`). Atoms compare half-integer signals
//! with integers, so robustness is never 0 and its sign is the verdict.
//!
//! At least 1,000 bounded formulas are compared at every state whose whole window lies inside the
//! trace, where end-of-trace conventions cannot matter. The verdicts near the end and those of
//! formulas with unbounded operators are compared too: RTAMT's offline monitor pads the signal
//! past its end with -inf for `eventually`/`until` and +inf for `always`, which is our
//! finite-trace closure, and its strong next is false at the last state, as our strict until's
//! "a later state" is. Needs the Python of `scripts/test` (`KPL_PYTHON`).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // a test reports and fails loudly

mod common;

use std::path::PathBuf;
use std::process::Command;

use common::{F, Gen, NUMS, PROPS, TraceState, compile, show, slot_state};
use kpl_core::Time;
use kpl_mtl::{EveryMonitor, StartVerdict};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;

/// The formula in RTAMT's syntax, with our strict until translated.
fn rtamt(f: &F) -> String {
    match f {
        F::True | F::False | F::ObjCmp { .. } | F::Forall(_) | F::Exists(_) => {
            unreachable!("not generated for this test")
        }
        F::Prop(i) => format!("({} >= 0)", PROPS[*i]),
        F::Cmp { var, greater, c } => format!("({} {} {c:.1})", NUMS[*var], if *greater { ">" } else { "<" }),
        F::Not(g) => format!("(not {})", rtamt(g)),
        F::And(gs) => format!("({})", gs.iter().map(rtamt).collect::<Vec<_>>().join(" and ")),
        F::Or(gs) => format!("({})", gs.iter().map(rtamt).collect::<Vec<_>>().join(" or ")),
        F::Implies(a, b) => format!("({} -> {})", rtamt(a), rtamt(b)),
        F::Ev(lo, hi, g) => match hi {
            Some(hi) => format!("(eventually[{lo}:{hi}] {})", rtamt(g)),
            None if *lo == 0 => format!("(eventually {})", rtamt(g)),
            None => format!("(eventually[{lo}:{lo}] (eventually {}))", rtamt(g)),
        },
        F::Al(lo, hi, g) => match hi {
            Some(hi) => format!("(always[{lo}:{hi}] {})", rtamt(g)),
            None if *lo == 0 => format!("(always {})", rtamt(g)),
            None => format!("(always[{lo}:{lo}] (always {}))", rtamt(g)),
        },
        F::Until(lo, hi, a, b) => {
            let (a, b) = (rtamt(a), rtamt(b));
            // RTAMT's (non-strict) until over [lo, hi] relative to the next state.
            let from_next = |lo: Time, hi: Option<Time>| match hi {
                Some(hi) => format!("({a} until[{lo}:{hi}] {b})"),
                None if lo == 0 => format!("({a} until {b})"),
                None => format!("((always[0:{}] {a}) and (eventually[{lo}:{lo}] ({a} until {b})))", lo - 1),
            };
            if *lo == 0 {
                match hi {
                    Some(0) => b.clone(),
                    Some(hi) => format!("({b} or (s_next {}))", from_next(0, Some(hi - 1))),
                    None => format!("({b} or (s_next {}))", from_next(0, None)),
                }
            } else {
                format!("(s_next {})", from_next(lo - 1, hi.map(|h| h - 1)))
            }
        }
    }
}

/// The largest offset a verdict depends on, `None` if unbounded.
fn horizon(f: &F) -> Option<Time> {
    match f {
        F::Not(g) => horizon(g),
        F::And(gs) | F::Or(gs) => gs.iter().try_fold(0, |acc, g| horizon(g).map(|h| acc.max(h))),
        F::Implies(a, b) => Some(horizon(a)?.max(horizon(b)?)),
        F::Ev(_, hi, g) | F::Al(_, hi, g) => Some((*hi)? + horizon(g)?),
        F::Until(_, hi, a, b) => Some((*hi)? + horizon(a)?.max(horizon(b)?)),
        _ => Some(0),
    }
}

fn engine_every(f: &F, trace: &[TraceState]) -> Vec<bool> {
    let mut monitor = EveryMonitor::new(compile(f));
    let mut out: Vec<StartVerdict> = Vec::new();
    for s in trace {
        monitor.step(s.time, &slot_state(s), &mut out).unwrap();
    }
    monitor.finish(&mut out);
    let mut verdicts = vec![false; trace.len()];
    for v in out {
        verdicts[v.start] = v.verdict;
    }
    verdicts
}

fn rtamt_trace(trace: &[TraceState]) -> serde_json::Value {
    let mut obj = serde_json::Map::new();
    obj.insert("time".into(), json!(trace.iter().map(|s| s.time).collect::<Vec<_>>()));
    for (i, name) in PROPS.iter().enumerate() {
        let values: Vec<f64> = trace.iter().map(|s| if s.props[i] { 1.0 } else { -1.0 }).collect();
        obj.insert((*name).into(), json!(values));
    }
    for (i, name) in NUMS.iter().enumerate() {
        obj.insert((*name).into(), json!(trace.iter().map(|s| s.nums[i]).collect::<Vec<_>>()));
    }
    serde_json::Value::Object(obj)
}

struct Case {
    formula: F,
    trace: Vec<TraceState>,
    bounded: bool,
}

fn python() -> Option<String> {
    match std::env::var("KPL_PYTHON") {
        Ok(p) if !p.is_empty() => Some(p),
        _ => {
            let required = std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1");
            assert!(!required, "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set: run scripts/test");
            eprintln!("skipped: KPL_PYTHON is not set (scripts/test sets it up with RTAMT)");
            None
        }
    }
}

#[test]
fn agrees_with_rtamt_on_random_formulas() {
    let Some(python) = python() else { return };
    let mut generator = Gen {
        rng: ChaCha8Rng::seed_from_u64(0x47a3_7001),
        max_bound: 10,
        quantifiers: false,
        unbounded: false,
        constants: false,
    };
    let mut cases = Vec::new();
    for i in 0..1500 {
        // One in four formulas may have unbounded operators.
        generator.unbounded = i % 4 == 3;
        let formula = loop {
            let f = generator.formula(4, 0);
            if matches!(f, F::Ev(..) | F::Al(..) | F::Until(..)) || generator.rng.random_bool(0.3) {
                break f;
            }
        };
        let len = generator.rng.random_range(20..=45);
        let trace = generator.trace(len, true);
        let bounded = horizon(&formula).is_some();
        cases.push(Case { formula, trace, bounded });
    }
    let batch = json!({
        "cases": cases.iter().map(|c| json!({
            "spec": rtamt(&c.formula),
            "vars": PROPS.iter().chain(NUMS.iter()).collect::<Vec<_>>(),
            "trace": rtamt_trace(&c.trace),
        })).collect::<Vec<_>>()
    });
    let dir = std::env::temp_dir().join(format!("kpl-mtl-rtamt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let batch_path = dir.join("batch.json");
    let results_path = dir.join("results.json");
    std::fs::write(&batch_path, batch.to_string()).unwrap();
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/rtamt_oracle.py");
    let status = Command::new(&python).arg(&script).arg(&batch_path).arg(&results_path).status().unwrap();
    assert!(status.success(), "{python} {} failed", script.display());
    let results: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&results_path).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let results = results["results"].as_array().unwrap();
    assert_eq!(results.len(), cases.len());

    let (mut bounded_formulas, mut inside_windows, mut near_end, mut unbounded) = (0, 0, 0, 0);
    for (n, (case, result)) in cases.iter().zip(results).enumerate() {
        if let Some(error) = result.get("error") {
            panic!("case {n}: RTAMT failed on {}: {error}", rtamt(&case.formula));
        }
        let theirs: Vec<bool> =
            result["verdicts"].as_array().unwrap().iter().map(|v| v.as_bool().unwrap()).collect();
        let ours = engine_every(&case.formula, &case.trace);
        assert_eq!(theirs.len(), ours.len(), "case {n}: one verdict per state");
        let last = case.trace.len() as Time - 1;
        for (i, (o, t)) in ours.iter().zip(&theirs).enumerate() {
            let inside = horizon(&case.formula).is_some_and(|h| i as Time + h <= last);
            let class = if inside {
                inside_windows += 1;
                "the whole window lies inside the trace"
            } else if case.bounded {
                near_end += 1;
                "the window reaches past the end of the trace"
            } else {
                unbounded += 1;
                "unbounded formula"
            };
            assert_eq!(
                o,
                t,
                "case {n}, state {i} ({class}): ours {o}, RTAMT {t}\nformula: {}\nRTAMT:   {}\ntrace: {:?}",
                show(&case.formula),
                rtamt(&case.formula),
                case.trace
            );
        }
        bounded_formulas += usize::from(case.bounded);
    }
    eprintln!(
        "{} formulas ({bounded_formulas} bounded); verdicts compared: {inside_windows} with the whole window \
         inside the trace, {near_end} near the end, {unbounded} of unbounded formulas",
        cases.len()
    );
    assert!(bounded_formulas >= 1000, "at least 1000 bounded formulas, got {bounded_formulas}");
}
