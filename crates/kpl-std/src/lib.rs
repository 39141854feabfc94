//! KPL's standard library of processes: adapters that make the simulators and algorithms of the
//! workspace available to specs by name. `register` adds them to a runtime registry.
//!
//! - `sim.uav_tracker`: vision percepts from the simulated UAV tracker (`kpl-sim`).
//! - `camera.georeference`, `camera.homography`, `sim.uav_camera` and the camera functions
//!   (`kpl-camera`: from pixels to the world), `file.tracker` (trackers' files as percepts),
//!   docs/camera.md.
//! - `aapa.anchor`, `sim.gearbox`: action-aware perceptual anchoring (`kpl-aapa`), docs/aapa.md.

mod aapa;
mod camera;
mod tracker;
mod trackfiles;

/// Adds every process of this crate to `registry`.
pub fn register(registry: &mut kpl_runtime::Registry) {
    tracker::register(registry);
    aapa::register(registry);
    camera::register(registry);
    trackfiles::register(registry);
}
