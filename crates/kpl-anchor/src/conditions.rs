//! The three conditions of a link specification compiled once per link, the state a condition
//! reads (`from`, `to` and, for identifications, `this`), a [`Condition`] of one object or pair
//! (an instance of its formula's `ProgressorGroup`, so that the thousands of objects of a link
//! share residuals and cached transitions: each object in a situation already seen costs its
//! atoms and a lookup), and the **gate** of the reestablish condition: the distance within which
//! a candidate pair is worth progressing at all.
//!
//! The gate is read off the formula by `kpl_mtl::gate` (shared with the monitors' pair gate): if
//! `reestablish` can only become true when, at some state, `xydist(from.pos, to.pos) < c` (or
//! `<=`, `dist`, `norm(from.pos - to.pos)`, objects instead of their `pos`), the gate is `c`. A link
//! whose reestablish condition has no such bound has no gate: every unlinked object is a candidate
//! (quadratic; the engine reports it in its notes).

use std::sync::Arc;

use kpl_core::{Time, TimeUnit, Value};
use kpl_mtl::gate::{Horizon, PairGate};
use kpl_mtl::{
    CompileError, Context, EvalError, Formula, Function, InstanceId, Mtl, ProgressorGroup, SlotId, State,
};
use kpl_semantic::hir::{self, SPEC_TICK};
use kpl_syntax::ast;

/// Slots every link condition is compiled with.
pub const FROM: SlotId = 0;
pub const TO: SlotId = 1;
pub const THIS: SlotId = 2;

/// The first slot of the streams a condition names (`in_view(cam, to.pos)`): slot `ENV + i` is
/// the i-th of the engine's stream names ([`link_context`]).
pub const ENV: SlotId = 3;

/// What a link condition reads at one time stamp.
#[derive(Debug, Clone, Copy)]
pub struct LinkState<'a> {
    pub from: &'a Value,
    pub to: Option<&'a Value>,
    pub this: Option<&'a Value>,
    /// The current values of the streams conditions name, by slot from [`ENV`] (`None`: no
    /// sample at this state).
    pub env: &'a [Option<Value>],
}

impl State for LinkState<'_> {
    fn value(&self, slot: SlotId) -> Option<&Value> {
        match slot {
            FROM => Some(self.from),
            TO => self.to,
            THIS => self.this,
            _ => self.env.get(slot.checked_sub(ENV)? as usize)?.as_ref(),
        }
    }
}

/// The condition of one object or pair: pending (an instance of the group of its formula, which
/// the holder knows), or decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Condition {
    Pending(InstanceId),
    Decided(bool),
}

impl Condition {
    /// A new condition of `group`'s formula, before its first state.
    pub fn start(group: &mut ProgressorGroup) -> Condition {
        Condition::Pending(group.start())
    }

    /// `None` while pending.
    pub fn verdict(&self) -> Option<bool> {
        match self {
            Condition::Pending(_) => None,
            Condition::Decided(v) => Some(*v),
        }
    }

    /// Progresses a pending condition through its state at `time`; once decided, it is settled
    /// and its instance leaves the group. A decided condition stays as it is.
    pub fn step<S: State + ?Sized>(
        &mut self,
        group: &mut ProgressorGroup,
        time: Time,
        state: &S,
    ) -> Result<Option<bool>, EvalError> {
        let Condition::Pending(id) = *self else { return Ok(self.verdict()) };
        let verdict = group.step(id, time, state)?;
        if let Some(v) = verdict {
            group.remove(id);
            *self = Condition::Decided(v);
        }
        Ok(verdict)
    }

    /// Frees the instance of a pending condition that is no longer needed.
    pub fn release(&self, group: &mut ProgressorGroup) {
        if let Condition::Pending(id) = self {
            group.remove(*id);
        }
    }
}

/// A link's compiled conditions.
#[derive(Debug, Clone)]
pub struct LinkConditions {
    pub context: Context,
    pub establish: Arc<Formula>,
    pub reestablish: Arc<Formula>,
    pub maintain: Arc<Formula>,
    reestablish_mtl: Mtl,
    /// Distance within which a pair is a candidate for reestablish (see the module doc).
    pub gate: Option<f64>,
}

/// Why a condition does not compile (the checker reports these first; this is a second line).
#[derive(Debug, Clone)]
pub struct ConditionError {
    pub condition: &'static str,
    pub messages: Vec<String>,
}

fn messages(errors: Vec<CompileError>) -> Vec<String> {
    errors.into_iter().map(|e| e.message).collect()
}

/// A context with `from`, `to` and `this` (slots 0, 1, 2), the streams conditions name (`env`,
/// slots from [`ENV`]), time stamps in microseconds and bare bounds in milliseconds, and the
/// unit's and the host's functions.
pub fn link_context(functions: Vec<Function>, env: &[Arc<str>]) -> Context {
    let mut context = Context::new(TimeUnit::Us, SPEC_TICK);
    let slots = [context.declare_value("from"), context.declare_value("to"), context.declare_value("this")];
    debug_assert_eq!(slots, [FROM, TO, THIS]);
    for name in env {
        context.declare_value(name);
    }
    for function in functions {
        context.register_function(function);
    }
    context
}

/// Lowers an expression in `context` and compiles it: the lowered and the compiled formula.
fn lower_and_compile(expr: &ast::Expr, context: &mut Context) -> Result<(Mtl, Arc<Formula>), Vec<String>> {
    let mtl = kpl_mtl::lower(expr, context).map_err(messages)?;
    let formula = Formula::new(&mtl, context).map_err(|e| vec![e.to_string()])?;
    Ok((mtl, Arc::new(formula)))
}

fn compile_one(
    expr: &ast::Expr,
    context: &mut Context,
    condition: &'static str,
) -> Result<(Mtl, Arc<Formula>), ConditionError> {
    lower_and_compile(expr, context).map_err(|messages| ConditionError { condition, messages })
}

impl LinkConditions {
    pub fn compile(
        link: &hir::Link,
        functions: Vec<Function>,
        env: &[Arc<str>],
    ) -> Result<LinkConditions, ConditionError> {
        let mut context = link_context(functions, env);
        let (_, establish) = compile_one(&link.establish, &mut context, "establish")?;
        let (reestablish_mtl, reestablish) = compile_one(&link.reestablish, &mut context, "reestablish")?;
        let (_, maintain) = compile_one(&link.maintain, &mut context, "maintain")?;
        let gate = distance_gate(&reestablish_mtl, &context);
        Ok(LinkConditions { context, establish, reestablish, maintain, reestablish_mtl, gate })
    }

    /// `reestablish and description`, for completing an identification through this link: `to`
    /// and `this` are both the object this link would make of `from`.
    pub fn identification(&self, description: &ast::Expr) -> Result<Arc<Formula>, Vec<String>> {
        let mut context = self.context.clone();
        let description = kpl_mtl::lower(description, &mut context).map_err(messages)?;
        let both = Mtl::and(vec![self.reestablish_mtl.clone(), description]);
        Formula::new(&both, &context).map(Arc::new).map_err(|e| vec![e.to_string()])
    }
}

/// The description of an identification alone (`this` is an existing object of the type; the
/// built-in functions only).
pub fn description_formula(description: &ast::Expr) -> Result<Arc<Formula>, Vec<String>> {
    lower_and_compile(description, &mut link_context(Vec::new(), &[])).map(|(_, formula)| formula)
}

/// The condition of `forget ... after T when C`: `this` is the object, the streams it names are
/// `env`, and the host's functions are available.
pub fn forget_formula(
    condition: &ast::Expr,
    functions: Vec<Function>,
    env: &[Arc<str>],
) -> Result<Arc<Formula>, Vec<String>> {
    lower_and_compile(condition, &mut link_context(functions, env)).map(|(_, formula)| formula)
}

/// The gate of a reestablish condition over `from` and `to`: the distance they must be within
/// at some state for it to become true ([`kpl_mtl::gate`]).
pub fn distance_gate(formula: &Mtl, context: &Context) -> Option<f64> {
    PairGate::new(context, FROM, TO).distance(formula, Horizon::SomeState)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    fn gate(text: &str) -> Option<f64> {
        let mut context =
            link_context(vec![Function::new("on_road", (1, Some(1)), |_| Ok(Value::Bool(true)))], &[]);
        let expr = kpl_syntax::parse_formula(text).unwrap();
        let mtl = kpl_mtl::lower(&expr, &mut context).unwrap();
        distance_gate(&mtl, &context)
    }

    #[test]
    fn gates_are_read_off_the_formula() {
        assert_eq!(gate("eventually[0, 1s] xydist(from.pos, to.pos) < 10.0"), Some(10.0));
        assert_eq!(gate("eventually[0, 1000] xydist(from, to) <= 7"), Some(7.0));
        assert_eq!(gate("eventually[0, 1s] 12.5 > dist(to.pos, from.pos)"), Some(12.5));
        assert_eq!(
            gate("eventually[0, 1s] (norm(from.pos - to.pos) < 4.0 and on_road(from.pos))"),
            Some(4.0)
        );
        assert_eq!(gate("eventually[0, 1s] not (xydist(from.pos, to.pos) >= 6.0)"), Some(6.0));
        // The tighter of two requirements, the looser of two alternatives.
        assert_eq!(
            gate("xydist(from.pos, to.pos) < 10.0 and always[0, 1s] xydist(from.pos, to.pos) < 3.0"),
            Some(3.0)
        );
        assert_eq!(gate("xydist(from.pos, to.pos) < 10.0 or xydist(from.pos, to.pos) < 3.0"), Some(10.0));
        // No bound: no gate.
        assert_eq!(gate("xydist(from.pos, to.pos) < 10.0 or on_road(to.pos)"), None);
        assert_eq!(gate("eventually[0, 1s] xydist(from.pos, to.pos) > 10.0"), None);
        assert_eq!(gate("not (xydist(from.pos, to.pos) < 10.0)"), None);
        assert_eq!(gate("on_road(from.pos) -> xydist(from.pos, to.pos) < 5.0"), None);
        assert_eq!(gate("false"), Some(0.0));
        assert_eq!(gate("true until[0, 1s] xydist(from.pos, to.pos) < 2.0"), Some(2.0));
    }

    #[test]
    fn link_state_reads_its_slots() {
        let a = Value::Int(1);
        let b = Value::Int(2);
        let env = [None, Some(Value::Int(3))];
        let s = LinkState { from: &a, to: Some(&b), this: None, env: &env };
        assert_eq!(s.value(FROM), Some(&a));
        assert_eq!(s.value(TO), Some(&b));
        assert_eq!(s.value(THIS), None);
        assert_eq!(s.value(ENV), None);
        assert_eq!(s.value(ENV + 1), Some(&Value::Int(3)));
        assert_eq!(s.value(9), None);
    }
}
