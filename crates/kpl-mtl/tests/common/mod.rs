//! Shared by the differential tests: a small formula type of their own, random formulas and
//! traces, and the conversion to the engine's `Mtl`. The naive evaluator lives in
//! `naive_oracle.rs`; the RTAMT translation in `rtamt_oracle.rs`.

#![allow(dead_code)] // each test file uses a different part

use std::sync::Arc;

use kpl_core::{Record, Time, TimeUnit, Value};
use kpl_mtl::{BinOp, Context, Formula, Mtl, SlotState, Term, Window};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

pub const PROPS: [&str; 3] = ["p", "q", "r"];
pub const NUMS: [&str; 2] = ["x", "y"];
pub const OBJECTS: [&str; 3] = ["a", "b", "c"];

/// A formula of the tests' own. Bounds are in time units; `None` is `inf`.
#[derive(Debug, Clone, PartialEq)]
pub enum F {
    True,
    False,
    Prop(usize),
    /// `nums[var] > c` (or `<` when `greater` is false).
    Cmp {
        var: usize,
        greater: bool,
        c: f64,
    },
    /// `$depth.v > c` for the object bound by the quantifier at nesting `depth`.
    ObjCmp {
        depth: u32,
        greater: bool,
        c: f64,
    },
    Not(Box<F>),
    And(Vec<F>),
    Or(Vec<F>),
    Implies(Box<F>, Box<F>),
    Ev(Time, Option<Time>, Box<F>),
    Al(Time, Option<Time>, Box<F>),
    Until(Time, Option<Time>, Box<F>, Box<F>),
    Forall(Box<F>),
    Exists(Box<F>),
}

#[derive(Debug, Clone)]
pub struct TraceState {
    pub time: Time,
    pub props: [bool; 3],
    pub nums: [f64; 2],
    /// The `v` attribute of objects a, b, c (all present in every state).
    pub objects: [f64; 3],
}

pub struct Gen {
    pub rng: ChaCha8Rng,
    pub max_bound: Time,
    pub quantifiers: bool,
    pub unbounded: bool,
    /// Whether `true` and `false` may appear as atoms.
    pub constants: bool,
}

impl Gen {
    fn window(&mut self) -> (Time, Option<Time>) {
        let lo = if self.rng.random_bool(0.4) { 0 } else { self.rng.random_range(0..=self.max_bound / 2) };
        let hi = if self.unbounded && self.rng.random_bool(0.2) {
            None
        } else {
            Some(lo + self.rng.random_range(0..=self.max_bound - self.max_bound / 2))
        };
        (lo, hi)
    }

    fn atom(&mut self, qdepth: u32) -> F {
        let choice = self.rng.random_range(if self.constants { 0 } else { 2 }..20);
        match choice {
            0 => F::True,
            1 => F::False,
            2..=10 => F::Prop(self.rng.random_range(0..PROPS.len())),
            _ if qdepth > 0 && choice >= 16 => F::ObjCmp {
                depth: self.rng.random_range(0..qdepth),
                greater: self.rng.random_bool(0.5),
                c: f64::from(self.rng.random_range(-2..=2)),
            },
            _ => F::Cmp {
                var: self.rng.random_range(0..NUMS.len()),
                greater: self.rng.random_bool(0.5),
                c: f64::from(self.rng.random_range(-2..=2)),
            },
        }
    }

    /// A random formula of nesting depth at most `depth`.
    pub fn formula(&mut self, depth: u32, qdepth: u32) -> F {
        if depth == 0 || self.rng.random_bool(0.2) {
            return self.atom(qdepth);
        }
        let ops = if self.quantifiers && qdepth < 2 { 9 } else { 7 };
        match self.rng.random_range(0..ops) {
            0 => F::Not(Box::new(self.formula(depth - 1, qdepth))),
            1 => F::And((0..self.rng.random_range(2..=3)).map(|_| self.formula(depth - 1, qdepth)).collect()),
            2 => F::Or((0..self.rng.random_range(2..=3)).map(|_| self.formula(depth - 1, qdepth)).collect()),
            3 => F::Implies(
                Box::new(self.formula(depth - 1, qdepth)),
                Box::new(self.formula(depth - 1, qdepth)),
            ),
            4 => {
                let (lo, hi) = self.window();
                F::Ev(lo, hi, Box::new(self.formula(depth - 1, qdepth)))
            }
            5 => {
                let (lo, hi) = self.window();
                F::Al(lo, hi, Box::new(self.formula(depth - 1, qdepth)))
            }
            6 => {
                let (lo, hi) = self.window();
                F::Until(
                    lo,
                    hi,
                    Box::new(self.formula(depth - 1, qdepth)),
                    Box::new(self.formula(depth - 1, qdepth)),
                )
            }
            7 => F::Forall(Box::new(self.formula(depth - 1, qdepth + 1))),
            _ => F::Exists(Box::new(self.formula(depth - 1, qdepth + 1))),
        }
    }

    /// A random trace; `even` gives time stamps 0, 1, 2, ...
    pub fn trace(&mut self, len: usize, even: bool) -> Vec<TraceState> {
        const STEPS: [Time; 10] = [1, 1, 1, 1, 2, 2, 3, 4, 7, 12];
        let mut time = if even { 0 } else { self.rng.random_range(0..5) };
        let mut out = Vec::with_capacity(len);
        let half = |rng: &mut ChaCha8Rng| f64::from(rng.random_range(-3..3)) + 0.5;
        for _ in 0..len {
            out.push(TraceState {
                time,
                props: [self.rng.random_bool(0.5), self.rng.random_bool(0.4), self.rng.random_bool(0.3)],
                nums: [half(&mut self.rng), half(&mut self.rng)],
                objects: [half(&mut self.rng), half(&mut self.rng), half(&mut self.rng)],
            });
            time += if even { 1 } else { STEPS[self.rng.random_range(0..STEPS.len())] };
        }
        out
    }
}

/// The context the engine compiles test formulas against: slots p, q, r, x, y; domain `Obj`.
pub fn context() -> Context {
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    for name in PROPS.iter().chain(NUMS.iter()) {
        ctx.declare_value(name);
    }
    ctx.declare_object_type("Obj");
    ctx
}

fn window(lo: Time, hi: Option<Time>) -> Window {
    Window::new(lo, hi)
}

pub fn to_mtl(f: &F) -> Mtl {
    let cmp = |t: Term, greater: bool, c: f64| {
        Mtl::atom(Term::binary(if greater { BinOp::Gt } else { BinOp::Lt }, t, Term::num(c)))
    };
    match f {
        F::True => Mtl::Const(true),
        F::False => Mtl::Const(false),
        F::Prop(i) => Mtl::atom(Term::slot(*i as u32)),
        F::Cmp { var, greater, c } => cmp(Term::slot((PROPS.len() + var) as u32), *greater, *c),
        F::ObjCmp { depth, greater, c } => cmp(Term::Var(*depth).field("v"), *greater, *c),
        F::Not(g) => Mtl::not(to_mtl(g)),
        F::And(gs) => Mtl::and(gs.iter().map(to_mtl).collect()),
        F::Or(gs) => Mtl::or(gs.iter().map(to_mtl).collect()),
        F::Implies(a, b) => Mtl::implies(to_mtl(a), to_mtl(b)),
        F::Ev(lo, hi, g) => Mtl::eventually(window(*lo, *hi), to_mtl(g)),
        F::Al(lo, hi, g) => Mtl::always(window(*lo, *hi), to_mtl(g)),
        F::Until(lo, hi, a, b) => Mtl::until(window(*lo, *hi), to_mtl(a), to_mtl(b)),
        F::Forall(g) => Mtl::Forall(0, Box::new(to_mtl(g))),
        F::Exists(g) => Mtl::Exists(0, Box::new(to_mtl(g))),
    }
}

pub fn compile(f: &F) -> Arc<Formula> {
    Arc::new(Formula::new(&to_mtl(f), &context()).expect("test formulas are well formed"))
}

pub fn slot_state(s: &TraceState) -> SlotState {
    let mut values: Vec<Option<Value>> = s.props.iter().map(|b| Some(Value::Bool(*b))).collect();
    values.extend(s.nums.iter().map(|x| Some(Value::Float(*x))));
    let objects = OBJECTS
        .iter()
        .zip(s.objects.iter())
        .map(|(id, v)| {
            Value::Record(Arc::new(Record {
                id: Some(Arc::from(*id)),
                fields: vec![(Arc::from("v"), Value::Float(*v))],
            }))
        })
        .collect();
    SlotState { values, objects: vec![objects] }
}

/// The formula in KPL syntax (for failure messages).
pub fn show(f: &F) -> String {
    let w = |lo: &Time, hi: &Option<Time>| match hi {
        Some(h) => format!("[{lo}, {h}]"),
        None => format!("[{lo}, inf]"),
    };
    match f {
        F::True => "true".into(),
        F::False => "false".into(),
        F::Prop(i) => PROPS[*i].into(),
        F::Cmp { var, greater, c } => format!("{} {} {c}", NUMS[*var], if *greater { ">" } else { "<" }),
        F::ObjCmp { depth, greater, c } => format!("o{depth}.v {} {c}", if *greater { ">" } else { "<" }),
        F::Not(g) => format!("not ({})", show(g)),
        F::And(gs) => gs.iter().map(|g| format!("({})", show(g))).collect::<Vec<_>>().join(" and "),
        F::Or(gs) => gs.iter().map(|g| format!("({})", show(g))).collect::<Vec<_>>().join(" or "),
        F::Implies(a, b) => format!("({}) -> ({})", show(a), show(b)),
        F::Ev(lo, hi, g) => format!("eventually{} ({})", w(lo, hi), show(g)),
        F::Al(lo, hi, g) => format!("always{} ({})", w(lo, hi), show(g)),
        F::Until(lo, hi, a, b) => format!("({}) until{} ({})", show(a), w(lo, hi), show(b)),
        F::Forall(g) => format!("forall o: Obj . ({})", show(g)),
        F::Exists(g) => format!("exists o: Obj . ({})", show(g)),
    }
}
