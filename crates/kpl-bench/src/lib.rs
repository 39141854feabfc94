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
//! - [`chronicles`]: the chronicles of the shipped specs over the same cars, gated and not
//!   (`kpl bench chronicles`).
//! - [`python`]: a Python unit's call against a Rust unit's, in simulated time (`kpl bench python`).
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
pub mod chronicles;
pub mod clock;
pub mod mtl;
pub mod python;
pub mod runtime;
pub mod situations;
pub mod timescales;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use kpl_runtime::Registry;
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use kpl_semantic::registry::{Entry, EntryKind, TypeReq};

/// Counts the samples that arrive and that `counts` accepts.
struct Count {
    counted: Arc<AtomicU64>,
    counts: fn(&Input<'_>) -> bool,
}

impl Unit for Count {
    fn on_input(&mut self, input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
        if (self.counts)(input) {
            self.counted.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }
}

/// Registers the sink `bench.count`, which adds to `counted` each sample that `counts` accepts.
fn add_count_sink(registry: &mut Registry, counted: Arc<AtomicU64>, counts: fn(&Input<'_>) -> bool) {
    registry.add_unit(
        Entry::new(EntryKind::Sink, "bench.count", "Counts samples.").variadic(
            1,
            "in",
            TypeReq::Any,
            "anything",
        ),
        move |_| Ok(Box::new(SyncUnit(Count { counted: counted.clone(), counts }))),
    );
}

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
