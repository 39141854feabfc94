//! The atoms of one state: each atom of a formula is evaluated at most once per state and per
//! environment of quantified objects, and kept as bits (known, value, failed) so that the
//! transition cache can be keyed by the values of the atoms a residual reads.
//!
//! Evaluation is lazy: an atom is evaluated when the progression (or a cache key) first needs
//! it. A failure (a missing value, a type error) is kept and becomes the step's error only if the
//! progression actually uses that atom's value, as `docs/mtl.md` ("Missing values") promises.

use crate::error::EvalError;
use crate::formula::{AtomId, Formula, WORD_ATOMS};
use crate::residual::Env;
use crate::state::State;
use crate::term::{BinOp, FieldName, Function, Native, SlotId, Term, TermEnv};

use kpl_core::Value;

/// How an atom is read. Most go through the general evaluator ([`TermEnv`]); the distance
/// comparison of link conditions (`xydist(from.pos, to.pos) < 10.0`), read for every pair at
/// every state, is compiled to two attribute reads, one `hypot` and one comparison. Whenever the
/// state holds something else than that path expects (no record, no such attribute, not a
/// `vec2`), the general evaluator reads the atom, so the value and the errors are the same.
#[derive(Debug, Clone)]
pub(crate) enum AtomPlan {
    General,
    /// `xydist(a, b) op bound` (or `dist` of two positions), with `a` and `b` positions.
    Distance {
        a: PointPath,
        b: PointPath,
        op: BinOp,
        bound: f64,
    },
}

/// Where a position is: a name of the state (a `vec2`, or a record's `pos`) or one attribute
/// of a record of the state (`from.pos`).
#[derive(Debug, Clone)]
pub(crate) struct PointPath {
    slot: SlotId,
    field: Option<FieldName>,
}

impl PointPath {
    fn of(term: &Term) -> Option<PointPath> {
        match term {
            Term::Slot(slot) => Some(PointPath { slot: *slot, field: None }),
            // `id` is computed, not an attribute.
            Term::Field(base, field) if &**field != "id" => match &**base {
                Term::Slot(slot) => Some(PointPath { slot: *slot, field: Some(field.clone()) }),
                _ => None,
            },
            _ => None,
        }
    }

    #[inline]
    fn read<S: State + ?Sized>(&self, state: &S) -> Option<[f64; 2]> {
        let mut value = state.value(self.slot)?;
        if let Some(field) = &self.field {
            let Value::Record(record) = value else { return None };
            value = field.of(record)?;
        }
        match value {
            Value::Vec2(p) => Some(*p),
            // A record stands for its `pos`, as the built-ins read it.
            Value::Record(record) => record.get("pos")?.as_vec2(),
            _ => None,
        }
    }
}

impl AtomPlan {
    /// The plan of an atom of a formula calling `functions`.
    pub fn of(term: &Term, functions: &[Function]) -> AtomPlan {
        let Term::Binary(op, lhs, rhs) = term else { return AtomPlan::General };
        // `bound op distance` is `distance op' bound`, op' the mirrored comparison.
        let (op, call, bound) = match (op, &**lhs, &**rhs) {
            (BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge, call, Term::Const(c)) => (*op, call, c),
            (BinOp::Lt, Term::Const(c), call) => (BinOp::Gt, call, c),
            (BinOp::Le, Term::Const(c), call) => (BinOp::Ge, call, c),
            (BinOp::Gt, Term::Const(c), call) => (BinOp::Lt, call, c),
            (BinOp::Ge, Term::Const(c), call) => (BinOp::Le, call, c),
            _ => return AtomPlan::General,
        };
        let Some(bound) = bound.as_f64().filter(|b| !b.is_nan()) else { return AtomPlan::General };
        let Term::Call(func, args) = call else { return AtomPlan::General };
        let native = functions.get(*func as usize).and_then(|f| f.native);
        match (native, args.as_slice()) {
            (Some(Native::XyDist | Native::Dist), [a, b]) => match (PointPath::of(a), PointPath::of(b)) {
                (Some(a), Some(b)) => AtomPlan::Distance { a, b, op, bound },
                _ => AtomPlan::General,
            },
            _ => AtomPlan::General,
        }
    }

    /// The atom's value by the plan, or `None` when the general evaluator must read it.
    #[inline]
    fn read<S: State + ?Sized>(&self, state: &S) -> Option<bool> {
        match self {
            AtomPlan::General => None,
            AtomPlan::Distance { a, b, op, bound } => {
                let ([x1, y1], [x2, y2]) = (a.read(state)?, b.read(state)?);
                let d = (x1 - x2).hypot(y1 - y2);
                if !d.is_finite() {
                    return None; // the general evaluator's error
                }
                Some(match op {
                    BinOp::Lt => d < *bound,
                    BinOp::Le => d <= *bound,
                    BinOp::Gt => d > *bound,
                    _ => d >= *bound,
                })
            }
        }
    }
}

/// Atom values for one environment of bound objects (first word of atoms only).
#[derive(Debug, Clone, Copy, Default)]
struct EnvWord {
    epoch: u32,
    known: u64,
    value: u64,
    failed: u64,
}

/// The atoms of the current state.
#[derive(Debug, Default)]
pub(crate) struct AtomMemo {
    /// Per environment id (0: no quantified objects), the first word of atoms, stamped with the
    /// state's epoch.
    envs: Vec<EnvWord>,
    /// Without quantified objects, the atoms past the first word: (known, value, failed) words.
    rest: Vec<(u64, u64, u64)>,
    epoch: u32,
    /// The errors behind `failed` bits: (atom, environment, error).
    errors: Vec<(AtomId, u32, EvalError)>,
}

impl AtomMemo {
    /// Forgets the previous state's atoms.
    pub fn begin(&mut self, atoms: usize, epoch: u32) {
        self.epoch = epoch;
        let words = atoms.div_ceil(64).saturating_sub(1);
        if words > 0 {
            self.rest.clear();
            self.rest.resize(words, (0, 0, 0));
        }
        if !self.errors.is_empty() {
            self.errors.clear();
        }
        if self.envs.is_empty() {
            self.envs.push(EnvWord::default());
        }
    }

    /// Environments were renumbered (the arena was compacted).
    pub fn forget_envs(&mut self) {
        self.envs.clear();
    }

    /// The value of one atom in environment `env`.
    pub fn get<S: State + ?Sized>(
        &mut self,
        atom: AtomId,
        env: u32,
        envs: &[Env],
        formula: &Formula,
        state: &S,
    ) -> Result<bool, EvalError> {
        let bit = 1u64 << (atom % 64);
        if atom >= WORD_ATOMS {
            if env != 0 {
                return evaluate(atom, &envs[env as usize], formula, state);
            }
            let w = (atom / 64 - 1) as usize;
            let (known, value, failed) = &mut self.rest[w];
            if *known & bit == 0 {
                match evaluate(atom, &envs[0], formula, state) {
                    Ok(v) => *value |= u64::from(v) << (atom % 64),
                    Err(e) => {
                        *failed |= bit;
                        self.errors.push((atom, 0, e));
                    }
                }
                *known |= bit;
            }
            let (_, value, failed) = self.rest[w];
            if failed & bit != 0 {
                return Err(self.error(atom, 0));
            }
            return Ok(value & bit != 0);
        }
        let (value, failed) = self.word(bit, env, envs, formula, state);
        if failed != 0 {
            return Err(self.error(atom, env));
        }
        Ok(value != 0)
    }

    /// The values and failures of the atoms in `mask` (first word) in environment `env`.
    pub fn word<S: State + ?Sized>(
        &mut self,
        mask: u64,
        env: u32,
        envs: &[Env],
        formula: &Formula,
        state: &S,
    ) -> (u64, u64) {
        let e = env as usize;
        if self.envs.len() <= e {
            self.envs.resize(e + 1, EnvWord::default());
        }
        let word = &mut self.envs[e];
        if word.epoch != self.epoch {
            *word = EnvWord { epoch: self.epoch, ..EnvWord::default() };
        }
        let EnvWord { mut known, mut value, mut failed, .. } = *word;
        let mut todo = mask & !known;
        if todo == 0 {
            return (value & mask, failed & mask);
        }
        while todo != 0 {
            let atom = todo.trailing_zeros();
            let bit = 1u64 << atom;
            todo &= !bit;
            match evaluate(atom, &envs[env as usize], formula, state) {
                Ok(v) => value |= u64::from(v) << atom,
                Err(e) => {
                    failed |= bit;
                    self.errors.push((atom, env, e));
                }
            }
            known |= bit;
        }
        let word = &mut self.envs[e];
        (word.known, word.value, word.failed) = (known, value, failed);
        (value & mask, failed & mask)
    }

    fn error(&self, atom: AtomId, env: u32) -> EvalError {
        self.errors
            .iter()
            .find(|(a, e, _)| *a == atom && *e == env)
            .map(|(_, _, err)| err.clone())
            .unwrap_or_else(|| EvalError::Arithmetic("internal: an atom failed without an error".into()))
    }
}

#[inline]
fn evaluate<S: State + ?Sized>(
    atom: AtomId,
    bindings: &Env,
    formula: &Formula,
    state: &S,
) -> Result<bool, EvalError> {
    let term = &formula.atoms[atom as usize];
    // The commonest atom, a boolean of the state, without the general evaluator.
    if let Term::Slot(slot) = term
        && let Some(Value::Bool(b)) = state.value(*slot)
    {
        return Ok(*b);
    }
    if let Some(value) = formula.plans.get(atom as usize).and_then(|plan| plan.read(state)) {
        return Ok(value);
    }
    let env = TermEnv {
        state,
        bindings,
        functions: &formula.functions,
        slot_names: &formula.slot_names,
        domain_names: &formula.domain_names,
    };
    env.eval_bool(term)
}
