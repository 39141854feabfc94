//! The registry `kpl check`, `kpl list` and `kpl run` use: the runtime's built-ins, the standard
//! processes (`kpl-std`), the anchoring (`kpl-anchor`: link processes, link units, prediction
//! models), the zenoh sources and sinks, the MCAP recordings (`file.mcap`), the live view (`view.live`), and whatever a user's crate adds (`kpl::main_with`).

use kpl_runtime::Registry;

/// Extra processes from a user's crate (`kpl::main_with`).
static EXTENSION: std::sync::OnceLock<fn(&mut Registry)> = std::sync::OnceLock::new();

pub(crate) fn extend_with(extend: fn(&mut Registry)) {
    let _ = EXTENSION.set(extend);
}

pub fn registry() -> Registry {
    let mut registry = Registry::with_builtins();
    kpl_std::register(&mut registry);
    kpl_zenoh::register(&mut registry);
    kpl_mcap::register(&mut registry);
    kpl_view::register(&mut registry);
    kpl_anchor::runtime::register(&mut registry);
    if let Some(extend) = EXTENSION.get() {
        extend(&mut registry);
    }
    registry
}
