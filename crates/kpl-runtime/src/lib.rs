//! The KPL stream runtime: knowledge processes exchanging timestamped samples.
//!
//! - [`sample::Sample`]: a value with its valid and available times.
//! - [`clock::Clock`]: the one source of time (wall, or simulated as fast as the work allows).
//! - [`process`]: the traits of sources and computational units (sinks are units).
//! - [`edge`]: bounded in-process queues with explicit overflow behaviour.
//! - [`policy`]: DyKnow's stream policies, enforced for each consumer.
//! - [`sync`]: state synchronization for formulas and synchronized units.
//! - [`instances`]: process instances created at run time (one per object).
//! - [`registry`]: implementations by name, with their signatures.
//! - [`plan`]: what one host runs of a checked spec (processes, edges, streams between hosts),
//!   built without tokio; [`run`]: executing a plan; [`transport`]: streams between hosts.
//!
//! The runtime builds only from a checked spec (`kpl_semantic::hir::Spec`), never from text.

pub mod builtins;
pub mod clock;
pub mod context;
pub mod edge;
pub mod instances;
pub mod monitor;
pub mod plan;
pub mod policy;
pub mod process;
pub mod registry;
pub mod run;
pub mod sample;
pub mod stats;
pub mod sync;
pub mod transport;

pub use clock::{Clock, ClockKind};
pub use registry::Registry;
pub use run::{Ending, RunConfig, RunError, RunReport, run};
pub use sample::Sample;
