//! The workload of the Timescales benchmark (Ulus, "Timescales: A Benchmark Generator for MTL
//! Monitoring Tools", RV 2019): ten timed properties (bounded absence, universality, recurrence
//! and response; globally, after Q, before R, between Q and R) in their future-time form, each
//! under a global `always`, and trace generators that follow the published generator's rules
//! (one state per time unit; segments of random length within the bounds).
//!
//! Used by `kpl bench mtl` and by tests that check every property holds on its generated trace.
//! The published properties use the usual (non-strict) until, which requires φ at the current
//! state too; ours is DyKnow's strict until, so [`Property::formula`] writes theirs as
//! `ψ or (φ and φ until ψ)` (lower bound 0) or `φ and φ until ψ` (lower bound above 0).
//!
//! One deviation: the published future form of "response between Q and R" lacks the `until r`
//! that its past form and the other "between" properties have, which makes it check `p` only at
//! the state of `q`; here it reads `(p -> eventually[a, b] s) until r`.

use kpl_core::Time;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use kpl_mtl::{Context, Mtl, SlotId, Term, Window};

/// The ten timed properties.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Property {
    AbsentAQ,
    AbsentBR,
    AbsentBQR,
    AlwaysAQ,
    AlwaysBR,
    AlwaysBQR,
    RecurGLB,
    RecurBQR,
    RespondGLB,
    RespondBQR,
}

/// The propositions of a Timescales trace, in slot order.
pub const PROPOSITIONS: [&str; 4] = ["p", "q", "r", "s"];

/// One state: the values of p, q, r, s.
pub type TimescalesState = [bool; 4];

const P: usize = 0;
const Q: usize = 1;
const R: usize = 2;
const S: usize = 3;

impl Property {
    pub const ALL: [Property; 10] = [
        Property::AbsentAQ,
        Property::AbsentBR,
        Property::AbsentBQR,
        Property::AlwaysAQ,
        Property::AlwaysBR,
        Property::AlwaysBQR,
        Property::RecurGLB,
        Property::RecurBQR,
        Property::RespondGLB,
        Property::RespondBQR,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Property::AbsentAQ => "AbsentAQ",
            Property::AbsentBR => "AbsentBR",
            Property::AbsentBQR => "AbsentBQR",
            Property::AlwaysAQ => "AlwaysAQ",
            Property::AlwaysBR => "AlwaysBR",
            Property::AlwaysBQR => "AlwaysBQR",
            Property::RecurGLB => "RecurGLB",
            Property::RecurBQR => "RecurBQR",
            Property::RespondGLB => "RespondGLB",
            Property::RespondBQR => "RespondBQR",
        }
    }

    /// The lower bound the benchmark pairs with an upper bound `b` (the published suites use
    /// 3/10, 30/100, 300/1000 for the properties that have one).
    pub fn lower_bound(self, b: Time) -> Time {
        match self {
            Property::AbsentBQR | Property::AlwaysBQR | Property::RespondGLB | Property::RespondBQR => {
                b * 3 / 10
            }
            _ => 0,
        }
    }

    /// The property in KPL syntax, as the benchmark states it (usual until, as in the paper).
    pub fn kpl_text(self, b: Time) -> String {
        let a = self.lower_bound(b);
        match self {
            Property::AbsentAQ => format!("always (q -> always[0, {b}] not p)"),
            Property::AbsentBR => format!("always (eventually[0, {b}] r -> (not p until r))"),
            Property::AbsentBQR => {
                format!("always ((q and not r and eventually r) -> (not p until[{a}, {b}] r))")
            }
            Property::AlwaysAQ => format!("always (q -> always[0, {b}] p)"),
            Property::AlwaysBR => format!("always (eventually[0, {b}] r -> (p until r))"),
            Property::AlwaysBQR => {
                format!("always ((q and not r and eventually r) -> (p until[{a}, {b}] r))")
            }
            Property::RecurGLB => format!("always eventually[0, {b}] p"),
            Property::RecurBQR => {
                format!("always ((q and not r and eventually r) -> (eventually[0, {b}] (p or r) until r))")
            }
            Property::RespondGLB => format!("always (p -> eventually[{a}, {b}] s)"),
            Property::RespondBQR => {
                format!("always ((q and not r and eventually r) -> ((p -> eventually[{a}, {b}] s) until r))")
            }
        }
    }

    /// The property as a formula over slots p, q, r, s declared (in that order) in `context`.
    pub fn formula(self, b: Time, context: &mut Context) -> Mtl {
        let slots: Vec<SlotId> = PROPOSITIONS.iter().map(|n| context.declare_value(n)).collect();
        let prop = |i: usize| Mtl::atom(Term::slot(slots[i]));
        let not = |i: usize| Mtl::not(prop(i));
        let a = self.lower_bound(b);
        let always = |f: Mtl| Mtl::always(Window::UNBOUNDED, f);
        let between = || Mtl::and(vec![prop(Q), not(R), Mtl::eventually(Window::UNBOUNDED, prop(R))]);
        let body = match self {
            Property::AbsentAQ => Mtl::implies(prop(Q), Mtl::always(Window::bounded(0, b), not(P))),
            Property::AbsentBR => Mtl::implies(
                Mtl::eventually(Window::bounded(0, b), prop(R)),
                usual_until(Window::UNBOUNDED, not(P), prop(R)),
            ),
            Property::AbsentBQR => {
                Mtl::implies(between(), usual_until(Window::bounded(a, b), not(P), prop(R)))
            }
            Property::AlwaysAQ => Mtl::implies(prop(Q), Mtl::always(Window::bounded(0, b), prop(P))),
            Property::AlwaysBR => Mtl::implies(
                Mtl::eventually(Window::bounded(0, b), prop(R)),
                usual_until(Window::UNBOUNDED, prop(P), prop(R)),
            ),
            Property::AlwaysBQR => {
                Mtl::implies(between(), usual_until(Window::bounded(a, b), prop(P), prop(R)))
            }
            Property::RecurGLB => Mtl::eventually(Window::bounded(0, b), prop(P)),
            Property::RecurBQR => Mtl::implies(
                between(),
                usual_until(
                    Window::UNBOUNDED,
                    Mtl::eventually(Window::bounded(0, b), Mtl::or(vec![prop(P), prop(R)])),
                    prop(R),
                ),
            ),
            Property::RespondGLB => Mtl::implies(prop(P), Mtl::eventually(Window::bounded(a, b), prop(S))),
            Property::RespondBQR => Mtl::implies(
                between(),
                usual_until(
                    Window::UNBOUNDED,
                    Mtl::implies(prop(P), Mtl::eventually(Window::bounded(a, b), prop(S))),
                    prop(R),
                ),
            ),
        };
        always(body)
    }

    /// A trace of at least `len` states (time stamps 0, 1, 2, ...; it ends with a whole segment,
    /// so it may be up to one segment longer) following the benchmark's generator for bound `b`;
    /// the property holds on it unless `failing_end` appends the benchmark's violating suffix.
    pub fn trace(self, b: Time, len: usize, seed: u64, failing_end: bool) -> Vec<TimescalesState> {
        let mut g = TraceGen { rng: ChaCha8Rng::seed_from_u64(seed), rows: Vec::with_capacity(len + 16) };
        let b = usize::try_from(b.max(1)).unwrap_or(1);
        let a = usize::try_from(self.lower_bound(b as Time)).unwrap_or(0);
        while g.rows.len() < len {
            match self {
                Property::AbsentAQ | Property::AlwaysAQ => {
                    let universal = self == Property::AlwaysAQ;
                    g.push(&[(Q, true), (P, universal)]);
                    g.repeat(b, &[(P, universal)]);
                    for _ in 0..b {
                        let p = g.coin();
                        g.push(&[(P, p)]);
                    }
                }
                Property::AbsentBR | Property::AlwaysBR => {
                    let universal = self == Property::AlwaysBR;
                    for _ in 0..b {
                        let p = g.coin();
                        g.push(&[(P, p)]);
                    }
                    g.repeat(b, &[(P, universal)]);
                    g.push(&[(P, universal), (R, true)]);
                }
                Property::AbsentBQR | Property::AlwaysBQR => {
                    let universal = self == Property::AlwaysBQR;
                    g.push(&[(Q, true), (P, universal)]);
                    let k = g.rng.random_range(a..b);
                    g.repeat(k, &[(P, universal)]);
                    g.push(&[(P, universal), (R, true)]);
                    let p = if universal { false } else { g.coin() };
                    g.push(&[(P, p)]);
                }
                Property::RecurGLB => {
                    let k = g.rng.random_range(1..=b);
                    g.repeat(k - 1, &[]);
                    g.push(&[(P, true)]);
                }
                Property::RecurBQR => {
                    g.push(&[(Q, true)]);
                    let recurrences = g.rng.random_range(1..=7);
                    let mut k = 1;
                    for _ in 0..recurrences {
                        k = g.rng.random_range(1..=b);
                        g.repeat(k - 1, &[]);
                        g.push(&[(P, true)]);
                    }
                    g.repeat(k - 1, &[]);
                    g.push(&[(R, true)]);
                    g.repeat(k - 1, &[]);
                }
                Property::RespondGLB => {
                    g.push(&[(P, true)]);
                    let k = g.rng.random_range(a + 1..=b);
                    g.repeat(k - 1, &[]);
                    g.push(&[(S, true)]);
                }
                Property::RespondBQR => {
                    g.push(&[(Q, true)]);
                    g.push(&[]);
                    for _ in 0..g.rng.random_range(1..=7) {
                        g.push(&[(P, true)]);
                        let k = g.rng.random_range(a + 1..=b);
                        g.repeat(k - 1, &[]);
                        g.push(&[(S, true)]);
                        g.push(&[]);
                    }
                    g.push(&[(R, true)]);
                }
            }
        }
        if failing_end {
            self.violate(&mut g, b);
        }
        g.rows
    }

    /// Appends the benchmark's violating suffix.
    fn violate(self, g: &mut TraceGen, b: usize) {
        match self {
            Property::AbsentAQ => {
                g.push(&[(Q, true)]);
                g.repeat(b - 1, &[]);
                g.push(&[(P, true)]);
            }
            Property::AlwaysAQ => {
                g.push(&[(Q, true), (P, true)]);
                g.repeat(b - 1, &[(P, true)]);
                g.push(&[]);
            }
            Property::AbsentBR => {
                g.push(&[(P, true)]);
                g.repeat(b - 1, &[]);
                g.push(&[(R, true)]);
            }
            Property::AlwaysBR => {
                g.push(&[]);
                g.repeat(b - 1, &[(P, true)]);
                g.push(&[(P, true), (R, true)]);
            }
            Property::AbsentBQR => {
                g.push(&[(Q, true)]);
                g.repeat(b - 1, &[]);
                g.push(&[(P, true)]);
                g.push(&[(R, true)]);
            }
            Property::AlwaysBQR => {
                g.push(&[(Q, true), (P, true)]);
                g.repeat(b + 1, &[(P, true)]);
                g.push(&[(P, true), (R, true)]);
            }
            Property::RecurGLB => g.repeat(b + 1, &[]),
            Property::RecurBQR => {
                g.push(&[(Q, true)]);
                g.repeat(b + 1, &[]);
                g.push(&[(R, true)]);
            }
            Property::RespondGLB => {
                g.push(&[(P, true)]);
                g.repeat(b, &[]);
            }
            Property::RespondBQR => {
                g.push(&[(Q, true)]);
                g.push(&[(P, true)]);
                g.repeat(b + 1, &[]);
                g.push(&[(R, true)]);
            }
        }
    }
}

/// The benchmark's (non-strict) `φ until ψ` in terms of DyKnow's strict one.
fn usual_until(window: Window, lhs: Mtl, rhs: Mtl) -> Mtl {
    let strict = Mtl::until(window, lhs.clone(), rhs.clone());
    let with_lhs_now = Mtl::and(vec![lhs, strict]);
    if window.lo == 0 { Mtl::or(vec![rhs, with_lhs_now]) } else { with_lhs_now }
}

struct TraceGen {
    rng: ChaCha8Rng,
    rows: Vec<TimescalesState>,
}

impl TraceGen {
    fn coin(&mut self) -> bool {
        self.rng.random_bool(0.5)
    }
    /// A state where the listed propositions have the given values and the others are false.
    fn push(&mut self, set: &[(usize, bool)]) {
        let mut state = [false; 4];
        for (i, v) in set {
            state[*i] = *v;
        }
        self.rows.push(state);
    }
    fn repeat(&mut self, n: usize, set: &[(usize, bool)]) {
        for _ in 0..n {
            self.push(set);
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing test should fail loudly
mod tests {
    use std::sync::Arc;

    use kpl_core::{TimeUnit, Value};

    use super::*;
    use kpl_mtl::{Formula, Progressor, SlotState};

    fn verdict(property: Property, b: Time, failing_end: bool) -> (Option<bool>, usize) {
        let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
        let formula = Arc::new(Formula::new(&property.formula(b, &mut ctx), &ctx).unwrap());
        let mut progressor = Progressor::new(formula);
        let mut state = SlotState::new(vec![None; 4]);
        let mut largest = 0;
        for (t, row) in property.trace(b, 3000, 7, failing_end).iter().enumerate() {
            for (slot, v) in row.iter().enumerate() {
                state.values[slot] = Some(Value::Bool(*v));
            }
            progressor.step(t as Time, &state).unwrap();
            largest = largest.max(progressor.residual_size());
        }
        (progressor.finish(), largest)
    }

    #[test]
    fn every_property_holds_on_its_trace_and_fails_with_the_failing_end() {
        for property in Property::ALL {
            for b in [10, 100] {
                let (holds, largest) = verdict(property, b, false);
                assert_eq!(holds, Some(true), "{} with bound {b}", property.name());
                assert!(largest <= 12, "{} with bound {b}: residual of {largest} nodes", property.name());
                assert_eq!(
                    verdict(property, b, true).0,
                    Some(false),
                    "{} failing end, bound {b}",
                    property.name()
                );
            }
        }
    }
}
