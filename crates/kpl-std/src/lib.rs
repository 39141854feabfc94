//! KPL's standard library of processes: the adapters that make the simulators and algorithms of
//! the workspace available to specs by name, and the one registry `kpl` runs with
//! ([`registry::registry`], [`registry::signatures`]).
//!
//! - `sim.uav_tracker`: vision percepts from the simulated UAV tracker (`kpl-sim`).
//! - `camera.georeference`, `camera.homography`, `sim.uav_camera` and the camera functions
//!   (`kpl-camera`: from pixels to the world), `file.tracker` (trackers' files as percepts),
//!   docs/camera.md.
//! - `aapa.anchor`, `sim.gearbox`, `cater.video`: action-aware perceptual anchoring (`kpl-aapa`),
//!   docs/aapa.md.
//! - [`anchor`]: hierarchical anchoring on the runtime (`kpl-anchor`'s engine): link processes,
//!   `anchor.world_model`, `anchor.identify`; a user's link units and prediction models.
//! - `chronicle`: every `chronicle` of a spec recognised on the runtime (`kpl-chronicle`'s
//!   recogniser fed with the changes of its predicates), docs/language.md#chronicles.
//! - [`python`]: `python.unit`, computational units in Python (or any language that speaks the
//!   process-unit protocol) run in worker processes kpl supervises, docs/python.md.
//! - [`driver`]: a spec's simulated trackers fed straight into the anchoring engine, with their
//!   ground truth (tests and `kpl bench anchor`, without the runtime).

mod aapa;
pub mod anchor;
mod camera;
pub mod chronicle;
pub mod driver;
pub mod python;
pub mod registry;
mod tracker;
mod trackfiles;

pub use registry::{assemble, check_text, registry, signatures};
