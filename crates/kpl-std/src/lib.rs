//! KPL's standard library of processes: the adapters that make the simulators and algorithms of
//! the workspace available to specs by name, and the one registry `kpl` runs with
//! ([`registry::registry`], [`registry::signatures`]).
//!
//! - `sim.uav_tracker`: vision percepts from the simulated UAV tracker (`kpl-sim`).
//! - `aapa.anchor`, `sim.gearbox`, `cater.video`: action-aware perceptual anchoring (`kpl-aapa`),
//!   docs/aapa.md.
//! - [`anchor`]: hierarchical anchoring on the runtime (`kpl-anchor`'s engine): link processes,
//!   `anchor.world_model`, `anchor.identify`; a user's link units and prediction models.
//! - [`driver`]: a spec's simulated trackers fed straight into the anchoring engine, with their
//!   ground truth (tests and `kpl bench anchor`, without the runtime).

mod aapa;
pub mod anchor;
pub mod driver;
pub mod registry;
mod tracker;

pub use registry::{assemble, check_text, registry, signatures};
