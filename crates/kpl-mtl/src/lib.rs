//! Metric temporal logic for KPL: formulas, their progression through timed states, verdicts.
//!
//! A formula is compiled once against a [`Context`] (which names, object types and functions
//! exist; the time unit of time stamps and of bare interval bounds) into a [`Formula`], then
//! progressed through streams of states: a [`Progressor`] for one stream (a monitor's formula),
//! a [`ProgressorGroup`] for many instances of one formula that share their work (a link
//! process's condition for each of its objects or pairs), an [`EveryMonitor`] for the verdict
//! from every state of one stream.
//!
//! The crate is pure and synchronous: no clock, no I/O, no tasks. Time is an argument of
//! [`Progressor::step`] (integers, strictly increasing, in the context's time unit; microseconds
//! in the runtime). The semantics (point-wise, DyKnow's until, finite-trace closure, missing
//! values) and the residual simplifications are documented in `docs/mtl.md`.
//!
//! ```
//! use std::sync::Arc;
//! use kpl_core::TimeUnit;
//! use kpl_mtl::{Context, Formula, Mtl, Progressor, SlotState, Term, Window};
//!
//! let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
//! let (p, q) = (ctx.declare_value("p"), ctx.declare_value("q"));
//! // always[0, 10] (p -> eventually[0, 3] q)
//! let f = Mtl::always(
//!     Window::bounded(0, 10),
//!     Mtl::implies(Mtl::atom(Term::slot(p)), Mtl::eventually(Window::bounded(0, 3), Mtl::atom(Term::slot(q)))),
//! );
//! let mut progressor = Progressor::new(Arc::new(Formula::new(&f, &ctx).unwrap()));
//! for (t, p, q) in [(0, true, false), (2, false, true), (7, true, false), (11, false, false)] {
//!     progressor.step(t, &SlotState::bools(&[p, q])).unwrap();
//! }
//! // p at 7 needed q by 10; the state at 11 shows it did not come.
//! assert_eq!(progressor.verdict(), Some(false));
//! assert_eq!(progressor.decided_at(), Some(11));
//! ```

mod atoms;
mod context;
mod engine;
mod error;
mod formula;
pub mod gate;
mod group;
mod handover;
mod lower;
mod progress;
mod residual;
mod state;
mod term;

pub use context::Context;
pub use engine::{EngineConfig, EngineStats};
pub use error::{CompileError, EvalError, FormulaError};
pub use formula::{Formula, Mtl, Window};
pub use group::{InstanceId, ProgressorGroup};
pub use handover::{HandedNode, HandedOp, Handover, HandoverError};
pub use lower::{bound_in_unit, lower};
pub use progress::{EveryMonitor, Progressor, StartVerdict};
pub use state::{SlotState, State};
pub use term::{
    BinOp, Binding, DomainId, FieldName, FuncId, Function, FunctionBody, SlotId, Term, VarId, builtins,
};
