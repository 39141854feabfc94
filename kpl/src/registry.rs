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

/// A user's extension, if `kpl::main_with` gave one.
fn extend(registry: &mut Registry) {
    if let Some(extend) = EXTENSION.get() {
        extend(registry);
    }
}

/// What `kpl run` builds processes from.
pub fn registry() -> Registry {
    kpl_std::registry::registry_with(extend)
}

/// The signatures of [`registry`], without its implementations: what `kpl check` and `kpl list`
/// check and show.
pub fn signatures() -> kpl_semantic::registry::Registry {
    kpl_std::registry::signatures_with(extend)
}
