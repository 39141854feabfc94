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
use crate::term::{Term, TermEnv};

use kpl_core::Value;

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
    let env = TermEnv {
        state,
        bindings,
        functions: &formula.functions,
        slot_names: &formula.slot_names,
        domain_names: &formula.domain_names,
    };
    env.eval_bool(term)
}
