//! KPL's front end: the pest grammar, the syntax tree ([`ast`]), spans and diagnostics.
//!
//! This crate knows nothing of name resolution, graphs, tokio or zenoh.

pub mod ast;
