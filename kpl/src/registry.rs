//! The registry `kpl check`, `kpl list` and `kpl run` use: the standard one (`kpl_std::assemble`:
//! the runtime's built-ins, the standard processes, anchoring, zenoh, ROS 2, MCAP) and whatever a user's
//! crate adds (`kpl::main_with`). Checking and listing keep only signatures
//! ([`signatures`]); only `kpl run` builds the registry of implementations ([`registry`]).

use kpl_runtime::Registry;

/// Extra processes from a user's crate (`kpl::main_with`).
static EXTENSION: std::sync::OnceLock<fn(&mut Registry)> = std::sync::OnceLock::new();

pub(crate) fn extend_with(extend: fn(&mut Registry)) {
    let _ = EXTENSION.set(extend);
}

fn assemble(registry: &mut Registry) {
    kpl_std::assemble(registry);
    if let Some(extend) = EXTENSION.get() {
        extend(registry);
    }
}

/// What `kpl run` builds processes from.
pub fn registry() -> Registry {
    let mut registry = Registry::default();
    assemble(&mut registry);
    registry
}

/// The signatures of [`registry`], without its implementations: what `kpl check` and `kpl list`
/// check and show.
pub fn signatures() -> kpl_semantic::registry::Registry {
    let mut registry = Registry::signatures_only();
    assemble(&mut registry);
    registry.into_signatures()
}
