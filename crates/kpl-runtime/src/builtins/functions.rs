//! Formula functions: the signatures of `kpl-mtl`'s built-ins (`kpl_semantic::functions`), which
//! `kpl-mtl` implements.

use crate::registry::Registry;

pub(super) fn register(registry: &mut Registry) {
    for function in kpl_semantic::functions::builtin_functions() {
        registry.add_builtin_function(function);
    }
}

#[cfg(test)]
mod tests {
    /// Every function the registry declares as built in is one `kpl-mtl` implements.
    #[test]
    fn builtin_signatures_match_the_engine() {
        let registry = crate::registry::Registry::with_builtins();
        let engine: Vec<String> = kpl_mtl::builtins().iter().map(|f| f.name.to_string()).collect();
        let own: Vec<String> = registry.functions().iter().map(|f| f.name.to_string()).collect();
        for f in registry.signatures().functions() {
            assert!(engine.contains(&f.name) || own.contains(&f.name), "{} has no implementation", f.name);
        }
        for name in &engine {
            assert!(registry.signatures().function(name).is_some(), "{name} has no signature");
        }
    }
}
