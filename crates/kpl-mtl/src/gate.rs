//! Gating formulas over two objects: the distance between the objects beyond which a formula
//! cannot be true ([`PairGate::distance`]), and the grid that finds the pairs within it
//! ([`GateGrid`]), so that progressing a formula for pairs of objects costs about the objects and
//! their neighbours, not every pair. Link processes gate their reestablish condition over `from`
//! and `to`; monitors `forall a: T . forall b: T . φ` gate φ over `a` and `b`.
//!
//! The distance is read off the formula: an atom comparing a distance between the two objects
//! (`xydist(a, b)`, `dist(a.pos, b.pos)`, `norm(a.pos - b.pos)`, objects or their `pos`, either
//! order) below a constant `c` requires `c`; a predicate declared with a margin
//! ([`crate::Function::within`]: `close(a, b, d)` measures along the road, so the straight-line
//! gate is `d` plus the lateral margin) requires `d + margin`.
//! How far it looks in time is the [`Horizon`]:
//! - *some state* (a link's reestablish condition, whose candidates are looked for at every state):
//!   `not` flips a comparison; `and` requires the smallest requirement of its parts, `or` the
//!   largest (none if some part has none); `a -> b` is `not a or b`; `eventually`, `always` and the
//!   right side of `until` pass their body's requirement on;
//! - *now* (a monitor starts a binding for every pair at every state, and a pair beyond the gate
//!   is false at once): the smallest requirement of the formula's top-level conjuncts that are
//!   atoms, and nothing else, so `(close(a, b, d) or false)` asks for no gate.
//!
//! Anything else requires nothing: no gate, every pair is a candidate.
//!
//! ```
//! use kpl_mtl::gate::{Horizon, PairGate};
//! use kpl_mtl::Context;
//! use kpl_core::TimeUnit;
//! let mut context = Context::new(TimeUnit::Us, TimeUnit::Ms);
//! let (a, b) = (context.declare_value("a"), context.declare_value("b"));
//! let formula = kpl_syntax::parse_formula("eventually[0, 1000] xydist(a, b) < 10.0").unwrap();
//! let mtl = kpl_mtl::lower(&formula, &mut context).unwrap();
//! let gate = PairGate::new(&context, a, b);
//! assert_eq!(gate.distance(&mtl, Horizon::SomeState), Some(10.0));
//! assert_eq!(gate.distance(&mtl, Horizon::Now), None);
//! ```

use crate::context::Context;
use crate::formula::Mtl;
use crate::term::{BinOp, FuncId, SlotId, Term};

/// How far in time a gate looks (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Horizon {
    /// The formula can only be true at the current state if the objects are within the gate.
    Now,
    /// The formula can only become true if the objects are within the gate at some state.
    SomeState,
}

/// The gate analysis of formulas over the objects in two slots.
#[derive(Debug, Clone)]
pub struct PairGate {
    a: SlotId,
    b: SlotId,
    /// `xydist`, `dist`: a distance of two positions or objects.
    distances: Vec<FuncId>,
    norm: Option<FuncId>,
    /// Functions `f(a, b, d)` true only within `d + margin`.
    within: Vec<(FuncId, f64)>,
}

/// `None`: no requirement. `Some(c)`: true only if the distance is at most `c`.
type Requirement = Option<f64>;

fn both(a: Requirement, b: Requirement) -> Requirement {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, None) | (None, x) => x,
    }
}

fn either(a: Requirement, b: Requirement) -> Requirement {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.max(y)),
        _ => None,
    }
}

impl PairGate {
    /// The analysis over the objects in slots `a` and `b`, with `context`'s distance functions and
    /// its predicates with a margin ([`crate::Function::within`]).
    pub fn new(context: &Context, a: SlotId, b: SlotId) -> PairGate {
        let distances = ["xydist", "dist"].iter().filter_map(|name| context.function(name)).collect();
        let within = context
            .functions()
            .iter()
            .filter_map(|f| Some((context.function(&f.name)?, f.within_margin?)))
            .collect();
        PairGate { a, b, distances, norm: context.function("norm"), within }
    }

    /// The gate of `formula` (module doc), if it has one.
    pub fn distance(&self, formula: &Mtl, horizon: Horizon) -> Option<f64> {
        let requirement = match horizon {
            Horizon::SomeState => self.requirement(formula, true),
            Horizon::Now => self.now(formula),
        };
        requirement.filter(|c| c.is_finite())
    }

    /// What `formula` requires now: the smallest requirement of its top-level conjuncts that are
    /// atoms (deliberately no more: `(close(a, b, d) or false)` is how a spec asks for a monitor
    /// without a gate).
    fn now(&self, formula: &Mtl) -> Requirement {
        match formula {
            Mtl::And(items) => items.iter().map(|f| self.now_conjunct(f)).fold(None, both),
            other => self.now_conjunct(other),
        }
    }

    fn now_conjunct(&self, formula: &Mtl) -> Requirement {
        match formula {
            Mtl::Atom(term) => self.atom(term, true),
            _ => None,
        }
    }

    /// What `formula` (or its negation when `positive` is false) requires to be true at some state.
    fn requirement(&self, formula: &Mtl, positive: bool) -> Requirement {
        match formula {
            // `false` can never be true: a requirement no distance meets.
            Mtl::Const(b) => (*b != positive).then_some(0.0),
            Mtl::Atom(term) => self.atom(term, positive),
            Mtl::Not(inner) => self.requirement(inner, !positive),
            Mtl::And(items) | Mtl::Or(items) => {
                let conjunction = matches!(formula, Mtl::And(_)) == positive;
                let mut parts = items.iter().map(|f| self.requirement(f, positive));
                let first = parts.next()?;
                if conjunction { parts.fold(first, both) } else { parts.fold(first, either) }
            }
            Mtl::Implies(a, b) => {
                let (na, pb) = (self.requirement(a, !positive), self.requirement(b, positive));
                if positive { either(na, pb) } else { both(na, pb) }
            }
            Mtl::Eventually(_, body) | Mtl::Always(_, body) => self.requirement(body, positive),
            Mtl::Until(_, _, rhs) if positive => self.requirement(rhs, true),
            Mtl::Until(..) | Mtl::Forall(..) | Mtl::Exists(..) => None,
        }
    }

    fn atom(&self, term: &Term, positive: bool) -> Requirement {
        match term {
            Term::Call(f, args) if positive && args.len() == 3 && self.pair(&args[0], &args[1]) => {
                let margin = self.within.iter().find(|(w, _)| w == f)?.1;
                constant(&args[2]).filter(|d| *d >= 0.0).map(|d| d + margin)
            }
            Term::Binary(op, lhs, rhs) => {
                // Normalised to `distance OP constant`.
                let (op, constant_side) = match (self.is_distance(lhs), self.is_distance(rhs)) {
                    (true, false) => (*op, rhs),
                    (false, true) => (flip(*op)?, lhs),
                    _ => return None,
                };
                let c = constant(constant_side)?;
                // Positive `d < c` / `d <= c`, or negated `d > c` / `d >= c`, require d <= c.
                match (op, positive) {
                    (BinOp::Lt | BinOp::Le, true) | (BinOp::Gt | BinOp::Ge, false) => Some(c),
                    _ => None,
                }
            }
            _ => None,
        }
    }

    fn is_distance(&self, term: &Term) -> bool {
        match term {
            Term::Call(f, args) if self.distances.contains(f) && args.len() == 2 => {
                self.pair(&args[0], &args[1])
            }
            Term::Call(f, args) if Some(*f) == self.norm && args.len() == 1 => match &args[0] {
                Term::Binary(BinOp::Sub, x, y) => self.pair(x, y),
                _ => false,
            },
            _ => false,
        }
    }

    /// `x` and `y` are the two objects (or their `pos`), in either order.
    fn pair(&self, x: &Term, y: &Term) -> bool {
        match (object_slot(x), object_slot(y)) {
            (Some(x), Some(y)) => (x == self.a && y == self.b) || (x == self.b && y == self.a),
            _ => false,
        }
    }
}

fn constant(term: &Term) -> Option<f64> {
    match term {
        Term::Const(c) => c.as_f64(),
        _ => None,
    }
}

fn flip(op: BinOp) -> Option<BinOp> {
    Some(match op {
        BinOp::Lt => BinOp::Gt,
        BinOp::Le => BinOp::Ge,
        BinOp::Gt => BinOp::Lt,
        BinOp::Ge => BinOp::Le,
        _ => return None,
    })
}

/// An object's slot, or its `pos`: the slot of the object whose position the term is.
fn object_slot(term: &Term) -> Option<SlotId> {
    match term {
        Term::Slot(s) => Some(*s),
        Term::Field(inner, name) if &**name == "pos" => match &**inner {
            Term::Slot(s) => Some(*s),
            _ => None,
        },
        _ => None,
    }
}

/// One indexed position: an object (by the caller's key) and which of its hypotheses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateEntry<K> {
    pub key: K,
    pub hypothesis: u32,
    pub pos: [f64; 2],
}

/// The candidates of a gate: positions in square cells one gate wide, kept as a sorted vector, so
/// building is a sort, a query is nine binary searches, and the order of results is
/// deterministic. Objects without a position ([`GateGrid::insert_unplaced`]) are in every answer.
#[derive(Debug, Clone)]
pub struct GateGrid<K> {
    radius: f64,
    cells: Vec<((i32, i32), GateEntry<K>)>,
    unplaced: Vec<K>,
}

impl<K: Copy + Ord> GateGrid<K> {
    /// An empty grid for a gate distance (at least a millimetre).
    pub fn new(radius: f64) -> GateGrid<K> {
        GateGrid { radius: radius.max(1e-3), cells: Vec::new(), unplaced: Vec::new() }
    }

    pub fn radius(&self) -> f64 {
        self.radius
    }

    pub fn clear(&mut self) {
        self.cells.clear();
        self.unplaced.clear();
    }

    fn cell(&self, pos: [f64; 2]) -> (i32, i32) {
        let c = |x: f64| (x / self.radius).floor().clamp(i32::MIN as f64, i32::MAX as f64) as i32;
        (c(pos[0]), c(pos[1]))
    }

    /// Indexes a position; one that is not finite makes the key unplaced.
    pub fn insert(&mut self, key: K, hypothesis: u32, pos: [f64; 2]) {
        if pos[0].is_finite() && pos[1].is_finite() {
            let cell = self.cell(pos);
            self.cells.push((cell, GateEntry { key, hypothesis, pos }));
        } else {
            self.unplaced.push(key);
        }
    }

    /// An object whose position is unknown: a candidate for every query.
    pub fn insert_unplaced(&mut self, key: K) {
        self.unplaced.push(key);
    }

    /// Call once after inserting and before querying.
    pub fn finish(&mut self) {
        self.cells.sort_by(|a, b| {
            a.0.cmp(&b.0).then(a.1.key.cmp(&b.1.key)).then(a.1.hypothesis.cmp(&b.1.hypothesis))
        });
        self.unplaced.sort();
        self.unplaced.dedup();
    }

    /// The keys with some hypothesis within the gate distance of `pos` (`<=`), each once, sorted,
    /// followed by the unplaced ones. `pos` `None`: every key.
    pub fn near(&self, pos: Option<[f64; 2]>, out: &mut Vec<K>) {
        out.clear();
        match pos {
            Some(pos) if pos[0].is_finite() && pos[1].is_finite() => {
                let (cx, cy) = self.cell(pos);
                let r2 = self.radius * self.radius;
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        let cell = (cx.saturating_add(dx), cy.saturating_add(dy));
                        let start = self.cells.partition_point(|e| e.0 < cell);
                        for (c, entry) in &self.cells[start..] {
                            if *c != cell {
                                break;
                            }
                            let (ddx, ddy) = (entry.pos[0] - pos[0], entry.pos[1] - pos[1]);
                            if ddx * ddx + ddy * ddy <= r2 {
                                out.push(entry.key);
                            }
                        }
                    }
                }
            }
            _ => out.extend(self.cells.iter().map(|(_, e)| e.key)),
        }
        out.sort();
        out.dedup();
        out.extend(self.unplaced.iter().copied());
    }

    pub fn len(&self) -> usize {
        self.cells.len() + self.unplaced.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use kpl_core::{TimeUnit, Value};
    use proptest::prelude::*;

    /// The gate of a formula over `a` and `b`, with `close(a, b, d)` at a margin of 15 m.
    fn gate(text: &str, horizon: Horizon) -> Option<f64> {
        let mut context = Context::new(TimeUnit::Us, TimeUnit::Ms);
        let (a, b) = (context.declare_value("a"), context.declare_value("b"));
        context.declare_value("p");
        context.register_function(
            crate::Function::new("close", (3, Some(3)), |_| Ok(Value::Bool(true))).within(15.0),
        );
        context.register_function(crate::Function::new("on_road", (1, Some(1)), |_| Ok(Value::Bool(true))));
        let expr = kpl_syntax::parse_formula(text).unwrap();
        let mtl = crate::lower(&expr, &mut context).unwrap();
        PairGate::new(&context, a, b).distance(&mtl, horizon)
    }

    #[test]
    fn a_link_condition_is_gated_by_what_it_needs_at_some_state() {
        let g = |t| gate(t, Horizon::SomeState);
        assert_eq!(g("eventually[0, 1s] xydist(a.pos, b.pos) < 10.0"), Some(10.0));
        assert_eq!(g("eventually[0, 1000] xydist(a, b) <= 7"), Some(7.0));
        assert_eq!(g("eventually[0, 1s] 12.5 > dist(b.pos, a.pos)"), Some(12.5));
        assert_eq!(g("eventually[0, 1s] (norm(a.pos - b.pos) < 4.0 and on_road(a.pos))"), Some(4.0));
        assert_eq!(g("eventually[0, 1s] not (xydist(a.pos, b.pos) >= 6.0)"), Some(6.0));
        // The tighter of two requirements, the looser of two alternatives.
        assert_eq!(g("xydist(a.pos, b.pos) < 10.0 and always[0, 1s] xydist(a.pos, b.pos) < 3.0"), Some(3.0));
        assert_eq!(g("xydist(a.pos, b.pos) < 10.0 or xydist(a.pos, b.pos) < 3.0"), Some(10.0));
        // No bound: no gate.
        assert_eq!(g("xydist(a.pos, b.pos) < 10.0 or on_road(b.pos)"), None);
        assert_eq!(g("eventually[0, 1s] xydist(a.pos, b.pos) > 10.0"), None);
        assert_eq!(g("not (xydist(a.pos, b.pos) < 10.0)"), None);
        assert_eq!(g("on_road(a.pos) -> xydist(a.pos, b.pos) < 5.0"), None);
        assert_eq!(g("false"), Some(0.0));
        assert_eq!(g("true until[0, 1s] xydist(a.pos, b.pos) < 2.0"), Some(2.0));
        assert_eq!(g("xydist(a.pos, p) < 2.0"), None, "another object");
    }

    #[test]
    fn a_monitor_is_gated_by_what_it_needs_now() {
        let g = |t| gate(t, Horizon::Now);
        assert_eq!(g("close(a, b, 50.0) and on_road(a)"), Some(65.0));
        assert_eq!(g("xydist(a.pos, b.pos) < 30.0 and p"), Some(30.0));
        assert_eq!(g("20 > dist(b, a)"), Some(20.0));
        assert_eq!(g("close(a, b, 50.0) and xydist(a, b) < 10"), Some(10.0));
        // Under a temporal operator, negated, in a disjunction, or of another object: no gate.
        assert_eq!(g("eventually close(a, b, 50.0)"), None);
        assert_eq!(g("always[0, 1s] xydist(a, b) < 3.0"), None);
        assert_eq!(g("close(a, b, 50.0) or p"), None);
        assert_eq!(g("not (xydist(a, b) > 5)"), None);
        assert_eq!(g("(close(a, b, 50.0) or false) and on_road(a)"), None);
        assert_eq!(g("close(a, p, 50.0)"), None);
        assert_eq!(g("not close(a, b, 50.0)"), None);
    }

    proptest! {
        /// The grid answers exactly what a scan of every entry answers.
        #[test]
        fn grid_equals_a_full_scan(
            points in proptest::collection::vec((-50.0f64..50.0, -50.0f64..50.0), 0..60),
            queries in proptest::collection::vec((-60.0f64..60.0, -60.0f64..60.0), 1..10),
            radius in 0.5f64..20.0,
        ) {
            let mut grid = GateGrid::new(radius);
            for (i, (x, y)) in points.iter().enumerate() {
                grid.insert(i / 2, (i % 2) as u32, [*x, *y]);
            }
            grid.finish();
            let mut got = Vec::new();
            for (qx, qy) in queries {
                grid.near(Some([qx, qy]), &mut got);
                let mut want: Vec<usize> = points
                    .iter()
                    .enumerate()
                    .filter(|(_, (x, y))| (x - qx).powi(2) + (y - qy).powi(2) <= radius * radius)
                    .map(|(i, _)| i / 2)
                    .collect();
                want.sort();
                want.dedup();
                prop_assert_eq!(&got, &want);
            }
        }
    }

    #[test]
    fn unplaced_and_unknown_positions() {
        let mut grid = GateGrid::new(5.0);
        grid.insert(1u32, 0, [0.0, 0.0]);
        grid.insert(2, 0, [100.0, 0.0]);
        grid.insert_unplaced(3);
        grid.finish();
        let mut out = Vec::new();
        grid.near(Some([1.0, 1.0]), &mut out);
        assert_eq!(out, vec![1, 3]);
        grid.near(None, &mut out);
        assert_eq!(out, vec![1, 2, 3]);
    }
}
