//! The progressor's contract with its callers: errors leave it unchanged, time must increase,
//! decided formulas stay decided, host functions and bound variables work, and the types can be
//! shared across threads.

#![allow(clippy::unwrap_used)] // a test fails loudly

use std::sync::Arc;

use kpl_core::{Record, TimeUnit, Value};
use kpl_mtl::{
    BinOp, Context, EvalError, EveryMonitor, Formula, Function, Mtl, Progressor, SlotState, StartVerdict,
    State, Term, Window,
};

fn bools(p: bool) -> SlotState {
    SlotState::bools(&[p])
}

#[test]
fn shared_types_can_cross_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Formula>();
    assert_send_sync::<Progressor>();
    assert_send_sync::<EveryMonitor>();
}

#[test]
fn a_failed_step_changes_nothing() {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let p = ctx.declare_value("p");
    let f = Mtl::always(Window::bounded(0, 10), Mtl::atom(Term::slot(p)));
    let mut progressor = Progressor::new(Arc::new(Formula::new(&f, &ctx).unwrap()));
    progressor.step(0, &bools(true)).unwrap();
    let before = progressor.residual();
    // The state has no value for p.
    let err = progressor.step(5, &SlotState::new(vec![None])).unwrap_err();
    assert_eq!(err, EvalError::Missing { name: "p".into() });
    assert_eq!(progressor.residual(), before);
    assert_eq!(progressor.last_time(), Some(0));
    // Time must increase; an equal time stamp is refused and changes nothing either.
    assert!(matches!(
        progressor.step(0, &bools(true)),
        Err(EvalError::TimeNotIncreasing { time: 0, previous: 0 })
    ));
    // The same time stamp with a good state then goes through.
    assert_eq!(progressor.step(5, &bools(true)).unwrap(), None);
    assert_eq!(progressor.step(11, &bools(false)).unwrap(), Some(true));
    assert_eq!(progressor.decided_at(), Some(11));
    // Decided: later states change nothing, even ones that would have failed.
    assert_eq!(progressor.step(12, &SlotState::new(vec![None])).unwrap(), Some(true));
}

#[test]
fn host_functions_and_link_variables() {
    // reestablish: eventually[0, 1s] xydist(from.pos, to.pos) < 10 and on_road(from.pos)
    let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Ms);
    let from = ctx.declare_value("from");
    let to = ctx.declare_value("to");
    let on_road = ctx.register_function(Function::new("on_road", (1, Some(1)), |args| match &args[0] {
        Value::Vec2([_, y]) => Ok(Value::Bool(y.abs() < 5.0)),
        other => Err(format!("expected a position, found {}", other.kind())),
    }));
    let xydist = ctx.function("xydist").unwrap();
    let pos = |slot| Term::slot(slot).field("pos");
    let close = Term::binary(BinOp::Lt, Term::call(xydist, vec![pos(from), pos(to)]), Term::num(10.0));
    let f = Mtl::eventually(
        Window::bounded(0, 1_000_000),
        Mtl::and(vec![Mtl::atom(close), Mtl::atom(Term::call(on_road, vec![pos(from)]))]),
    );
    let formula = Arc::new(Formula::new(&f, &ctx).unwrap());
    let object = |x: f64, y: f64| {
        Some(Value::Record(Arc::new(Record {
            id: None,
            fields: vec![(Arc::from("pos"), Value::vec2(x, y))],
        })))
    };
    let mut progressor = Progressor::new(formula.clone());
    // 20 m apart, then 6 m apart but off road, then 6 m apart on the road: true at 0.5 s.
    let states = [(0, object(0.0, 0.0), object(20.0, 0.0)), (250_000, object(0.0, 8.0), object(6.0, 8.0))];
    for (t, a, b) in states {
        assert_eq!(progressor.step(t, &SlotState::new(vec![a, b])).unwrap(), None);
    }
    let state = SlotState::new(vec![object(0.0, 1.0), object(6.0, 1.0)]);
    assert_eq!(progressor.step(500_000, &state).unwrap(), Some(true));
    // A function's error is reported with its name; a missing attribute with its path.
    let bad_pos =
        Some(Value::Record(Arc::new(Record { id: None, fields: vec![(Arc::from("pos"), Value::Int(1))] })));
    let mut progressor = Progressor::new(formula.clone());
    let err = progressor.step(0, &SlotState::new(vec![bad_pos, object(0.0, 0.0)])).unwrap_err();
    assert!(matches!(&err, EvalError::Function { func, .. } if func == "xydist"), "{err}");
    let mut progressor = Progressor::new(formula);
    let err = progressor.step(0, &SlotState::new(vec![Some(Value::Int(1)), object(0.0, 0.0)])).unwrap_err();
    assert_eq!(err.to_string(), "`from` has no attribute `pos`");
}

#[test]
fn every_monitor_verdicts_are_in_decision_order_with_their_start() {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let p = ctx.declare_value("p");
    let f = Mtl::eventually(Window::bounded(0, 2), Mtl::atom(Term::slot(p)));
    let mut monitor = EveryMonitor::new(Arc::new(Formula::new(&f, &ctx).unwrap()));
    let mut out: Vec<StartVerdict> = Vec::new();
    for (t, v) in [(0, false), (1, false), (2, true), (10, false)] {
        monitor.step(t, &bools(v), &mut out).unwrap();
    }
    monitor.finish(&mut out);
    let got: Vec<(usize, bool, Option<i64>)> =
        out.iter().map(|v| (v.start, v.verdict, v.decided_at)).collect();
    assert_eq!(
        got,
        vec![(0, true, Some(2)), (1, true, Some(2)), (2, true, Some(2)), (3, false, None)],
        "the last state's window is still open at the end"
    );
}

#[test]
fn quantified_objects_are_followed_by_id() {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let car = ctx.declare_object_type("Car");
    // forall c: Car . always (c.speed < 25)
    let speed = Term::binary(BinOp::Lt, Term::Var(0).field("speed"), Term::num(25.0));
    let f = Mtl::Forall(car, Box::new(Mtl::always(Window::UNBOUNDED, Mtl::atom(speed))));
    let formula = Arc::new(Formula::new(&f, &ctx).unwrap());
    let cars = |list: &[(&str, f64)]| SlotState {
        values: vec![],
        objects: vec![
            list.iter()
                .map(|(id, s)| {
                    Value::Record(Arc::new(Record {
                        id: Some(Arc::from(*id)),
                        fields: vec![(Arc::from("speed"), Value::Float(*s))],
                    }))
                })
                .collect(),
        ],
    };
    let mut progressor = Progressor::new(formula.clone());
    progressor.step(0, &cars(&[("c1", 10.0), ("c2", 20.0)])).unwrap();
    // A car that appears later is not in the domain of the quantifier evaluated at 0.
    assert_eq!(progressor.step(1, &cars(&[("c1", 11.0), ("c2", 21.0), ("c3", 99.0)])).unwrap(), None);
    // A bound car that left is a missing object: an error, not a guess.
    let err = progressor.step(2, &cars(&[("c1", 12.0)])).unwrap_err();
    assert!(matches!(err, EvalError::MissingObject { ref id, .. } if id == "c2"), "{err}");
    assert_eq!(progressor.step(2, &cars(&[("c1", 12.0), ("c2", 30.0)])).unwrap(), Some(false));
    let state = cars(&[("c1", 1.0)]);
    assert!(state.object(car, "c1").is_some() && state.object(car, "c9").is_none());
}

#[test]
fn malformed_windows_are_refused() {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let p = Mtl::atom(Term::slot(ctx.declare_value("p")));
    assert!(Formula::new(&Mtl::eventually(Window::bounded(5, 2), p.clone()), &ctx).is_err());
    assert!(Formula::new(&Mtl::eventually(Window::bounded(-1, 2), p.clone()), &ctx).is_err());
    assert!(Formula::new(&Mtl::atom(Term::Var(0)), &ctx).is_err());
}

#[test]
fn a_bound_of_i64_max_is_finite_not_inf() {
    let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Us);
    let p = Mtl::atom(Term::slot(ctx.declare_value("p")));
    let finite =
        Arc::new(Formula::new(&Mtl::eventually(Window::bounded(0, i64::MAX), p.clone()), &ctx).unwrap());
    let infinite = Arc::new(Formula::new(&Mtl::eventually(Window::UNBOUNDED, p), &ctx).unwrap());
    assert_eq!(finite.horizon(), Some(i64::MAX));
    assert_eq!(infinite.horizon(), None);
    let mut progressor = Progressor::new(finite.clone());
    progressor.step(-10, &bools(false)).unwrap();
    assert_eq!(progressor.residual(), format!("eventually[0, {}] p", i64::MAX));
    // i64::MAX + 9 after the first state: past the finite window, inside `inf`.
    assert_eq!(progressor.step(i64::MAX - 1, &bools(true)).unwrap(), Some(false));
    let mut progressor = Progressor::new(infinite);
    progressor.step(-10, &bools(false)).unwrap();
    assert_eq!(progressor.step(i64::MAX - 1, &bools(true)).unwrap(), Some(true));
    // Within the finite window, the same as inf.
    let mut progressor = Progressor::new(finite);
    progressor.step(0, &bools(false)).unwrap();
    assert_eq!(progressor.step(i64::MAX, &bools(true)).unwrap(), Some(true));
}

#[test]
fn constant_bodies_are_decided_at_the_first_state() {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let p = Mtl::atom(Term::slot(ctx.declare_value("p")));
    let cases = [
        (Mtl::always(Window::bounded(0, 5), Mtl::Const(true)), true),
        (Mtl::eventually(Window::bounded(2, 4), Mtl::Const(false)), false),
        (Mtl::always(Window::bounded(0, 5), Mtl::Const(false)), false),
        (Mtl::eventually(Window::bounded(0, 4), Mtl::or(vec![p.clone(), Mtl::Const(true)])), true),
        (Mtl::until(Window::bounded(1, 4), p.clone(), Mtl::Const(false)), false),
        (
            Mtl::not(Mtl::eventually(Window::bounded(3, 9), Mtl::and(vec![p.clone(), Mtl::Const(false)]))),
            true,
        ),
    ];
    for (f, verdict) in cases {
        let formula = Arc::new(Formula::new(&f, &ctx).unwrap());
        assert_eq!(formula.constant(), Some(verdict), "{f:?}");
        let mut progressor = Progressor::new(formula);
        // Decided before reading anything: a missing `p` is no error.
        assert_eq!(progressor.step(0, &SlotState::new(vec![None])).unwrap(), Some(verdict), "{f:?}");
        assert_eq!(progressor.decided_at(), Some(0));
    }
    // A window that starts later with a body that can hold is not constant: it needs a state there.
    let f = Formula::new(&Mtl::eventually(Window::bounded(2, 4), Mtl::Const(true)), &ctx).unwrap();
    assert_eq!(f.constant(), None);
}

#[test]
fn group_instances_are_independent_and_removed_ids_are_refused() {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let p = ctx.declare_value("p");
    let f = Mtl::always(Window::bounded(0, 10), Mtl::atom(Term::slot(p)));
    let mut group = kpl_mtl::ProgressorGroup::new(Arc::new(Formula::new(&f, &ctx).unwrap()));
    let a = group.start();
    let b = group.start();
    assert_eq!(group.len(), 2);
    assert_eq!(group.step(a, 0, &bools(true)).unwrap(), None);
    // Each instance has its own clock: b starts later, and its errors leave a alone.
    assert!(group.step(b, 5, &SlotState::new(vec![None])).is_err());
    assert_eq!(group.last_time(b), None);
    assert_eq!(group.step(b, 5, &bools(true)).unwrap(), None);
    assert_eq!(group.step(a, 3, &bools(false)).unwrap(), Some(false));
    assert_eq!(group.decided_at(a), Some(3));
    assert_eq!(group.verdict(b), None);
    assert_eq!(group.residual(b), "always[0, 10] p");
    assert_eq!(group.finish(b), Some(true));
    // Restarted, a is a fresh instance.
    group.restart(a);
    assert_eq!(group.verdict(a), None);
    assert_eq!(group.step(a, 1, &bools(true)).unwrap(), None);
    group.remove(a);
    assert_eq!(group.len(), 1);
    assert_eq!(group.step(a, 2, &bools(true)), Err(EvalError::NoInstance));
    // Its slot is reused, but the old id stays refused.
    let c = group.start();
    assert_ne!(c, a);
    assert_eq!(group.step(a, 2, &bools(true)), Err(EvalError::NoInstance));
    assert_eq!(group.verdict(a), None);
    assert_eq!(group.step(c, 0, &bools(true)).unwrap(), None);
}

#[test]
fn quantified_objects_share_their_residual_and_its_transitions() {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let car = ctx.declare_object_type("Car");
    // forall c: Car . always (c.braking -> eventually[0, 20] c.stopped)
    let attr = |name: &str| Mtl::atom(Term::Var(0).field(name));
    let f = Mtl::Forall(
        car,
        Box::new(Mtl::always(
            Window::UNBOUNDED,
            Mtl::implies(attr("braking"), Mtl::eventually(Window::bounded(0, 20), attr("stopped"))),
        )),
    );
    let mut progressor = Progressor::new(Arc::new(Formula::new(&f, &ctx).unwrap()));
    // 1,000 cars; car i brakes at state i % 10 and stops 5 states later.
    let state = |step: usize| SlotState {
        values: vec![],
        objects: vec![
            (0..1000)
                .map(|i| {
                    let phase = (step + i) % 10;
                    Value::Record(Arc::new(Record {
                        id: Some(Arc::from(format!("car{i}"))),
                        fields: vec![
                            (Arc::from("braking"), Value::Bool(phase == 0)),
                            (Arc::from("stopped"), Value::Bool(phase == 5)),
                        ],
                    }))
                })
                .collect(),
        ],
    };
    for step in 0..50 {
        assert_eq!(progressor.step(step as i64, &state(step)).unwrap(), None);
    }
    // The cars are in 10 situations: their residuals are 10 distinct nodes (plus the bindings),
    // and after the first round every car's step is a cached transition.
    let stats = progressor.stats();
    assert!(stats.cache_hits >= 40 * 1000, "{stats:?}");
    assert!(stats.cache_misses <= 20 * 10 + 50, "{stats:?}");
    assert!(progressor.residual_size() <= 1 + 2 * 1000 + 20, "{}", progressor.residual_size());
}

/// The distance atoms of link conditions (`xydist(from.pos, to.pos) < 10.0`, `10 > dist(a, b)`)
/// are read by a compiled plan; the same distance with `+ 0.0` (which changes no finite distance)
/// goes through the general evaluator. Both must give the same value, or the same error, on
/// positions, records standing for their `pos`, and malformed states.
#[test]
fn compiled_distance_atoms_read_as_the_general_evaluator_does() {
    use proptest::prelude::*;
    let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Ms);
    let (a, b) = (ctx.declare_value("a"), ctx.declare_value("b"));
    let functions = [ctx.function("xydist").unwrap(), ctx.function("dist").unwrap()];
    let ops = [BinOp::Lt, BinOp::Le, BinOp::Gt, BinOp::Ge];
    let args = [
        (Term::slot(a).field("pos"), Term::slot(b).field("pos")),
        (Term::slot(a), Term::slot(b)),
        (Term::slot(a).field("pos"), Term::slot(b)),
    ];
    let mut pairs = Vec::new();
    for func in functions {
        for op in ops {
            for (x, y) in &args {
                for bound in [Term::num(10.0), Term::int(3)] {
                    for mirrored in [false, true] {
                        let call = Term::call(func, vec![x.clone(), y.clone()]);
                        let general = Term::binary(BinOp::Add, call.clone(), Term::num(0.0));
                        let atom = |lhs: Term| {
                            if mirrored {
                                Term::binary(op, bound.clone(), lhs)
                            } else {
                                Term::binary(op, lhs, bound.clone())
                            }
                        };
                        let formula = |term: Term| Arc::new(Formula::new(&Mtl::atom(term), &ctx).unwrap());
                        pairs.push((formula(atom(call)), formula(atom(general))));
                    }
                }
            }
        }
    }
    let value = prop_oneof![
        (-30.0f64..30.0, -30.0f64..30.0).prop_map(|(x, y)| Value::vec2(x, y)),
        (-30.0f64..30.0, -30.0f64..30.0).prop_map(|(x, y)| Value::Record(Arc::new(Record {
            id: Some("o1".into()),
            fields: vec![(Arc::from("size"), Value::Float(2.0)), (Arc::from("pos"), Value::vec2(x, y))],
        }))),
        Just(Value::Record(Arc::new(Record { id: None, fields: vec![(Arc::from("pos"), Value::Int(4))] }))),
        Just(Value::Record(Arc::new(Record { id: None, fields: vec![] }))),
        (-30.0f64..30.0).prop_map(Value::Float),
        Just(Value::vec2(f64::MAX, 0.0)),
    ];
    let state = (proptest::option::weighted(0.95, value.clone()), proptest::option::weighted(0.95, value));
    proptest!(ProptestConfig::with_cases(400), |((x, y) in state)| {
        let state = SlotState::new(vec![x, y]);
        for (planned, general) in &pairs {
            let got = Progressor::new(planned.clone()).step(0, &state);
            let want = Progressor::new(general.clone()).step(0, &state);
            // Errors too: the function fails before `+` is reached.
            prop_assert_eq!(&got, &want, "on {:?}", state);
        }
    });
}

/// A formula's attributes are read through hints (`FieldHint`: where the attribute was found last);
/// over records whose fields come in any order, some without the attribute, each state's verdict
/// is what reading the fields by name gives, and a missing attribute is the same error.
#[test]
fn attributes_read_by_hint_are_those_of_the_record_in_any_field_order() {
    use proptest::prelude::*;
    let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Ms);
    let a = ctx.declare_value("a");
    let f = Mtl::and(vec![
        Mtl::atom(Term::binary(BinOp::Gt, Term::slot(a).field("speed"), Term::num(3.0))),
        Mtl::atom(Term::binary(BinOp::Lt, Term::slot(a).field("lane_pos"), Term::num(100.0))),
    ]);
    let formula = Arc::new(Formula::new(&f, &ctx).unwrap());
    let names = ["pos", "speed", "lane_pos", "lane", "size", "heading"];
    // Per state: a permutation of the names (by sort keys), which to leave out, the two values.
    let state = (proptest::collection::vec(any::<u16>(), 6), 0..8usize, 0.0..6.0f64, 0.0..200.0f64);
    proptest!(ProptestConfig::with_cases(300), |(states in proptest::collection::vec(state, 1..40))| {
        // One progressor, so one formula and its hints, for every record of the sequence.
        let mut progressor = Progressor::new(formula.clone());
        for (order, left_out, speed, lane_pos) in states {
            let mut keyed: Vec<(u16, &str)> = order.into_iter().zip(names).collect();
            keyed.sort();
            let fields: Vec<(Arc<str>, Value)> = keyed
                .into_iter()
                .map(|(_, n)| n)
                .filter(|n| names.get(left_out) != Some(n))
                .map(|n| {
                    let v = match n {
                        "speed" => Value::Float(speed),
                        "lane_pos" => Value::Float(lane_pos),
                        other => Value::Str(Arc::from(other)),
                    };
                    (Arc::from(n), v)
                })
                .collect();
            let record = Record { id: None, fields };
            let by_name = |n: &str| record.get(n).and_then(Value::as_f64);
            let (speed, lane_pos) = (by_name("speed"), by_name("lane_pos"));
            progressor.reset();
            let got = progressor.step(0, &SlotState::new(vec![Some(Value::Record(Arc::new(record.clone())))]));
            match (speed, lane_pos, got) {
                (Some(s), Some(l), got) => prop_assert_eq!(got, Ok(Some(s > 3.0 && l < 100.0))),
                // With an attribute missing: its error, or false if the other conjunct decides.
                (_, _, Err(EvalError::NoField { field, .. })) => {
                    prop_assert!(by_name(&field).is_none(), "`{}` is there", field)
                }
                (Some(s), None, got) => prop_assert!(s <= 3.0 && got == Ok(Some(false)), "{got:?}"),
                (None, _, got) => prop_assert!(false, "speed missing, yet {got:?}"),
            }
        }
    });
}

/// A function declared on borrowed arguments (`Function::borrowing`) gives in a formula what its
/// owned body gives when called directly, for one to four arguments.
#[test]
fn a_borrowing_function_gives_what_its_owned_body_gives() {
    let sum = Function::borrowing("sum_x", (1, None), |args| {
        let mut total = 0.0;
        for a in args {
            match a {
                Value::Vec2([x, _]) => total += x,
                Value::Record(r) => total += r.get("pos").and_then(Value::as_vec2).ok_or("no pos")?[0],
                other => return Err(format!("sum_x needs positions, found {}", other.kind())),
            }
        }
        Ok(Value::Float(total))
    });
    let object = |x: f64| {
        Value::Record(Arc::new(Record { id: None, fields: vec![(Arc::from("pos"), Value::vec2(x, 0.0))] }))
    };
    for n in 1..=4usize {
        let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Ms);
        let slots: Vec<_> = (0..n).map(|k| ctx.declare_value(&format!("o{k}"))).collect();
        let f = ctx.register_function(sum.clone());
        let call = Term::call(f, slots.iter().map(|&s| Term::slot(s)).collect());
        let mtl = Mtl::atom(Term::binary(BinOp::Gt, call, Term::num(2.5)));
        let mut progressor = Progressor::new(Arc::new(Formula::new(&mtl, &ctx).unwrap()));
        let values: Vec<Value> = (0..n).map(|k| object(k as f64 + 0.5)).collect();
        let owned = (sum.body)(&values).unwrap().as_f64().unwrap();
        assert_eq!(owned, (0..n).map(|k| k as f64 + 0.5).sum::<f64>());
        let state = SlotState::new(values.into_iter().map(Some).collect());
        assert_eq!(progressor.step(0, &state).unwrap(), Some(owned > 2.5), "{n} arguments");
        // An error of the body is the function's error, by name.
        let mut progressor = Progressor::new(progressor.formula().clone());
        let bad = SlotState::new((0..n).map(|_| Some(Value::Int(1))).collect());
        assert!(matches!(progressor.step(0, &bad), Err(EvalError::Function { func, .. }) if func == "sum_x"));
    }
}
