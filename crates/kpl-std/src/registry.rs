//! The one registry `kpl` runs with, assembled in one place: the runtime's built-ins, the
//! standard processes of this crate (simulators, AAPA, CATER), anchoring (link processes, link
//! units, prediction models, traffic relations), the zenoh sources and sinks, ROS 2 topics
//! (`ros2.subscribe`, `ros2.publish`), MCAP recordings and the live view (`view.live`).
//! [`registry`] builds it for running; [`signatures`] keeps only the signatures, for `kpl check`
//! and `kpl list`, without building anything of the runtime. A user's crate extends either with
//! the same function (`kpl::main_with`): units with `Registry::add_unit`, link units and
//! prediction models with [`crate::anchor::add_link_unit`] and [`crate::anchor::add_model`].

use kpl_runtime::Registry;
use kpl_semantic::hir;

/// Adds every process, function and implementation of the standard registry to `registry`.
pub fn assemble(registry: &mut Registry) {
    registry.add_builtins();
    crate::tracker::register(registry);
    crate::trackfiles::register(registry);
    crate::camera::register(registry);
    crate::aapa::register(registry);
    crate::anchor::register(registry);
    crate::chronicle::register(registry);
    crate::python::register(registry);
    kpl_zenoh::register(registry);
    kpl_zenoh::ros2::register(registry);
    kpl_mcap::register(registry);
    kpl_view::register(registry);
}

/// The registry `kpl run` builds processes from.
pub fn registry() -> Registry {
    registry_with(|_| {})
}

/// The signatures of [`registry`]: what specs are checked against.
pub fn signatures() -> kpl_semantic::registry::Registry {
    signatures_with(|_| {})
}

/// [`registry`] with what `extend` adds (a user's crate: `kpl::main_with`).
pub fn registry_with(extend: impl FnOnce(&mut Registry)) -> Registry {
    let mut registry = Registry::default();
    assemble(&mut registry);
    extend(&mut registry);
    registry
}

/// The signatures of [`registry_with`] the same `extend`, without building anything.
pub fn signatures_with(extend: impl FnOnce(&mut Registry)) -> kpl_semantic::registry::Registry {
    let mut registry = Registry::signatures_only();
    assemble(&mut registry);
    extend(&mut registry);
    registry.into_signatures()
}

/// Parses and checks a spec's text as `kpl check` does (against [`signatures`]): for tests,
/// benchmarks and programs that hold a spec in a string.
pub fn check_text(text: &str) -> Result<hir::Spec, kpl_semantic::SpecErrors> {
    kpl_semantic::check_text(text, &signatures())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checking and running see the same names: the signatures-only assembly is the running one's
    /// signatures, and everything with a signature can be built.
    #[test]
    fn signatures_are_the_registrys() {
        let running = registry();
        let checking = signatures();
        let names = |r: &kpl_semantic::registry::Registry| {
            let entries: Vec<(String, String)> =
                r.entries().map(|e| (e.kind.noun().to_string(), e.name.clone())).collect();
            let functions: Vec<String> = r.functions().map(|f| f.name.clone()).collect();
            (entries, functions, r.link_protocols().to_vec())
        };
        assert_eq!(names(running.signatures()), names(&checking));
        assert!(running.unimplemented().is_empty(), "{:?}", running.unimplemented());
        assert!(names(&checking).0.len() > 10);
    }
}
