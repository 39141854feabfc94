//! The errors of this crate: building a formula ([`FormulaError`]), lowering a syntax tree
//! ([`CompileError`], which carries the span it is about) and evaluating a state ([`EvalError`]).

use kpl_core::Time;
use kpl_syntax::ast::Span;

/// A formula built with the [`crate::Mtl`] constructors that cannot be compiled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FormulaError {
    #[error("interval [{lo}, {hi}] is empty: the lower bound is above the upper bound")]
    EmptyInterval { lo: Time, hi: Time },
    #[error("interval bound {0} is negative")]
    NegativeBound(Time),
    #[error("variable {var} is used outside the quantifier that binds it")]
    UnboundVariable { var: u32 },
    #[error("function #{func} does not exist in this context")]
    UnknownFunction { func: u32 },
    #[error("`{name}` takes {expected} argument(s), found {found}")]
    Arity { name: String, expected: String, found: usize },
}

/// A problem found while lowering a syntax tree to a formula, with the span it is about.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct CompileError {
    pub span: Span,
    pub message: String,
    /// An optional hint such as "did you mean `xydist`?".
    pub help: Option<String>,
}

impl CompileError {
    pub fn new(span: Span, message: impl Into<String>) -> CompileError {
        CompileError { span, message: message.into(), help: None }
    }
    pub fn with_help(mut self, help: impl Into<String>) -> CompileError {
        self.help = Some(help.into());
        self
    }
}

/// Why a state could not be progressed. The progressor that returned it is unchanged: the state
/// was not consumed, and the caller may skip it, fix it or stop.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// A name the formula needs has no value in this state.
    #[error("`{name}` has no value in this state")]
    Missing { name: String },
    /// An object bound by `forall`/`exists` is no longer in the state.
    #[error("object `{id}` of type {domain} is not in this state")]
    MissingObject { domain: String, id: String },
    /// An object of a quantified type has no `id`, so it cannot be followed through time.
    #[error("an object of type {domain} has no `id`")]
    ObjectWithoutId { domain: String },
    /// A record or vector has no such attribute.
    #[error("`{path}` has no attribute `{field}`")]
    NoField { path: String, field: String },
    #[error("{context}: expected {expected}, found {found}")]
    Type { context: String, expected: String, found: String },
    /// Division by zero, integer overflow, or a result that is not a finite number.
    #[error("{0}")]
    Arithmetic(String),
    /// A built-in or host function refused its arguments.
    #[error("{func}: {message}")]
    Function { func: String, message: String },
    #[error("time {time} is not after the previous state's time {previous}")]
    TimeNotIncreasing { time: Time, previous: Time },
    /// A [`crate::ProgressorGroup`] was asked to step an instance it no longer holds.
    #[error("this instance was removed from its group")]
    NoInstance,
}
