//! KPL's standard library of processes: adapters that make the simulators and algorithms of the
//! workspace available to specs by name. `register` adds them to a runtime registry.
//!
//! - `sim.uav_tracker`: vision percepts from the simulated UAV tracker (`kpl-sim`).

mod tracker;

/// Adds every process of this crate to `registry`.
pub fn register(registry: &mut kpl_runtime::Registry) {
    tracker::register(registry);
}
