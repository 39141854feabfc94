//! Residual sizes: bounded by a constant for the patterns the simplifications cover, whatever
//! the window length and the sampling rate; and the documented limit where they cannot be.

#![allow(clippy::unwrap_used, clippy::print_stderr)] // a test fails loudly

use std::sync::Arc;

use kpl_core::{Time, TimeUnit};
use kpl_mtl::{Context, Formula, Mtl, Progressor, SlotState, Term, Window};

/// The largest residual while progressing `f` over `states` states `step` time units apart,
/// with p, q given by `values(i)`.
fn largest(f: &Mtl, ctx: &Context, states: usize, step: Time, values: impl Fn(usize) -> [bool; 2]) -> usize {
    let mut progressor = Progressor::new(Arc::new(Formula::new(f, ctx).unwrap()));
    let mut largest = 0;
    for i in 0..states {
        progressor.step(i as Time * step, &SlotState::bools(&values(i))).unwrap();
        largest = largest.max(progressor.residual_size());
    }
    largest
}

fn ctx() -> (Context, Mtl, Mtl) {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let p = Mtl::atom(Term::slot(ctx.declare_value("p")));
    let q = Mtl::atom(Term::slot(ctx.declare_value("q")));
    (ctx, p, q)
}

#[test]
fn started_windows_merge_so_size_does_not_depend_on_bound_or_rate() {
    let (ctx, p, q) = ctx();
    let always = |f| Mtl::always(Window::UNBOUNDED, f);
    let formulas = |b: Time| {
        vec![
            // recurrence: every instance's pending `eventually[0, x] p` merges into one
            always(Mtl::eventually(Window::bounded(0, b), p.clone())),
            // absence after q: pending `always[0, x] not p` merge into one
            always(Mtl::implies(q.clone(), Mtl::always(Window::bounded(0, b), Mtl::not(p.clone())))),
            // a lower bound on an `always` inside `always`: overlapping windows are joined
            always(Mtl::always(Window::bounded(b / 2, b), Mtl::not(Mtl::and(vec![p.clone(), q.clone()])))),
        ]
    };
    for (n, _) in formulas(10).iter().enumerate() {
        let mut sizes = Vec::new();
        for (b, step) in [(100, 1), (10_000, 1), (10_000, 7), (1_000_000, 13)] {
            let f = &formulas(b)[n];
            let values = |i: usize| match n {
                // absence after q: q one state in eleven, never p (so the formula stays open)
                1 => [false, i.is_multiple_of(11)],
                _ => [!i.is_multiple_of(4), i.is_multiple_of(11)],
            };
            sizes.push(largest(f, &ctx, 20_000, step, values));
        }
        eprintln!("formula {n}: largest residuals {sizes:?}");
        let max = *sizes.iter().max().unwrap();
        assert!(max <= 12, "formula {n}: residual sizes {sizes:?}");
    }
}

#[test]
fn lower_bounded_eventually_under_always_keeps_one_node_per_pending_trigger() {
    // always (p -> eventually[a, b] q) with a > 0: each trigger waits for its own window, which
    // no other window contains; information-theoretically the residual must remember them all.
    // This is the documented limit: size grows with the triggers in the last `a` time units.
    let (ctx, p, q) = ctx();
    let f = |a, b| {
        Mtl::always(
            Window::UNBOUNDED,
            Mtl::implies(p.clone(), Mtl::eventually(Window::bounded(a, b), q.clone())),
        )
    };
    let sparse = largest(&f(50, 60), &ctx, 5_000, 1, |i| [i % 100 == 0, i % 100 == 55]);
    let dense = largest(&f(50, 60), &ctx, 5_000, 1, |i| [i % 5 == 0, i % 5 == 1]);
    eprintln!("sparse triggers: {sparse}, dense triggers: {dense}");
    assert!(sparse <= 4, "one pending trigger at a time: {sparse}");
    assert!(dense > sparse && dense <= 2 + 60 / 5 + 2, "about one node per trigger in the window: {dense}");
}

#[test]
fn dyknow_maintain_condition_keeps_one_node_per_state_of_the_current_run() {
    // always eventually[0, b] always[0, b/10] on_road: every instance started during the current
    // run of on_road waits for the run to last b/10 or for a later run; they differ by their start
    // times, so the residual holds about one node per state since the run began (here runs are
    // cut every 13 states). It does not depend on b.
    let (ctx, p, _) = ctx();
    let f = |b: Time| {
        Mtl::always(
            Window::UNBOUNDED,
            Mtl::eventually(Window::bounded(0, b), Mtl::always(Window::bounded(0, b / 10), p.clone())),
        )
    };
    let sizes: Vec<usize> = [(100, 1), (10_000, 1), (1_000_000, 7)]
        .into_iter()
        .map(|(b, step)| largest(&f(b), &ctx, 20_000, step, |i| [(i / 50) % 7 != 0 && i % 13 != 0, false]))
        .collect();
    eprintln!("maintain condition: largest residuals {sizes:?}");
    assert!(sizes.iter().all(|s| *s <= 3 * 13 + 3), "{sizes:?}");
    assert_eq!(sizes[1], sizes[2], "independent of the bound once runs are shorter than the window");
}
