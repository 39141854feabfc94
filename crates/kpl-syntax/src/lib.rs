//! KPL's front end: the pest grammar, the syntax tree ([`ast`]), spans, diagnostics, and the
//! canonical formatter ([`format`]).
//!
//! This crate knows nothing of name resolution, graphs, tokio or zenoh. Parsing never fails and
//! never panics: it returns what parsed plus diagnostics.
//!
//! ```
//! let parse = kpl_syntax::parse("stream percepts = tracker with sample every 100ms, strict order\n");
//! assert!(parse.diagnostics.is_empty());
//! let formula = kpl_syntax::parse_formula("eventually[0, 1s] xydist(from.pos, to.pos) < 10.0").unwrap();
//! assert!(matches!(formula.kind, kpl_syntax::ast::ExprKind::Temporal { .. }));
//! ```

pub mod ast;
pub mod diagnostic;
pub mod diagnostics;
pub mod format;
pub mod lex;
mod parser;

pub use diagnostic::{Diagnostic, JsonDiagnostic, JsonLabel, LineIndex, Severity};

/// Reads a file's bytes as UTF-8 text; on failure the diagnostic points at the first bad byte.
pub fn decode_source(bytes: &[u8]) -> Result<&str, Diagnostic> {
    std::str::from_utf8(bytes).map_err(|e| diagnostics::not_utf8(e.valid_up_to()))
}
pub use parser::{MAX_EXPR_DEPTH, MAX_SOURCE_BYTES, Parse, parse, parse_formula};
