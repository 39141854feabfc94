//! Semantic analysis of KPL: name resolution with "did you mean", types of attributes and
//! expressions, duration units, the type hierarchy, policies, link specifications, deployment,
//! and the process graph (petgraph) with its cycle check.
//!
//! The pipeline reads like the layers it crosses: `kpl_syntax::parse` gives a syntax tree,
//! [`check`] turns it into a [`hir::Spec`] (or diagnostics), and [`render`] draws its graph.
//!
//! ```
//! use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, Registry, TypeReq};
//! let mut registry = Registry::default();
//! registry.add(Entry::new(EntryKind::Source, "timer", "A counter every period.")
//!     .param(Param::required("period", ParamType::Duration, "time between samples"))
//!     .output(TypeReq::Exact(kpl_core::ValueType::Int)));
//! registry.add(Entry::new(EntryKind::Sink, "console", "Prints samples.").variadic(1, "in", TypeReq::Any, "streams to print"));
//! let parse = kpl_syntax::parse("source ticks : int = timer(period: 1s)\nsink out = console(tickz)\n");
//! let checked = kpl_semantic::check(&parse.spec, &registry);
//! assert_eq!(checked.diagnostics[0].hint.as_deref(), Some("did you mean `ticks`?"));
//! ```

mod attributes;
mod check;
pub mod diagnostics;
mod formula;
pub mod functions;
pub mod hir;
pub mod registry;
pub mod render;
pub mod svg;
mod types;

pub use check::{Checked, SpecErrors, check, check_identification, check_in, check_text};
pub use formula::bound_micros;
pub use kpl_core::{closest, did_you_mean};
pub use types::{BUILTIN_TYPES, default_symbol};
