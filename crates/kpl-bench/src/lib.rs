//! KPL's benchmark workloads, in one place: what `kpl bench` runs, and the criterion benchmarks
//! that span crates. Each workload reads its specs and monitors from the shipped spec files where
//! there is one, so that a benchmark measures what users run; each reports ratios against a
//! baseline measured in the same run (docs/performance.md), and writes its table to the writer it
//! is given (`kpl bench` passes standard output).
//!
//! - [`anchor`]: N cars in a grid town through two link levels (`kpl bench anchor`).
//! - [`runtime`]: the in-process runtime against bare tokio channels, and its memory
//!   (`kpl bench runtime`).
//! - [`situations`]: the situation monitors of `specs/traffic/sumo_situations.kpl` over N cars
//!   (`kpl bench situations`).
//! - [`mtl`]: the MTL engine on the Timescales properties ([`timescales`]), against R2U2 when
//!   built with the `r2u2` feature, and DyKnow's link conditions (`kpl bench mtl`).
//!
//! Streams between hosts (`kpl bench zenoh`) are measured by `kpl_zenoh::bench`: its baseline is
//! bare zenoh code, and zenoh is used by `kpl-zenoh` alone.
//!
//! Benchmarks time work, so this crate reads clocks (the wall clock and the thread's CPU clock,
//! [`clock::CpuClock`]), which the rest of the workspace may not.
#![allow(clippy::disallowed_methods)] // benchmarks time work: see the module doc

pub mod anchor;
pub mod clock;
pub mod mtl;
pub mod runtime;
pub mod situations;
pub mod timescales;

/// Why a benchmark could not run to its end.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("cannot write the report: {0}")]
    Io(#[from] std::io::Error),
    #[error("{0}")]
    Failed(String),
}

impl From<String> for BenchError {
    fn from(message: String) -> BenchError {
        BenchError::Failed(message)
    }
}
