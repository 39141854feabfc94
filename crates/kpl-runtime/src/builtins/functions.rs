//! Formula functions: the signatures of `kpl-mtl`'s built-ins (which implements them).

use kpl_core::ValueType;
use kpl_semantic::registry::Function;

use crate::registry::Registry;

pub(super) fn register(registry: &mut Registry) {
    use ValueType::{Any, Float, Vec2};
    for (name, summary) in [
        ("abs", "absolute value"),
        ("sqrt", "square root (an error on negative numbers)"),
        ("floor", "largest integer not above"),
        ("ceil", "smallest integer not below"),
    ] {
        registry.add_builtin_function(Function::new(name, vec![Float], Float, summary));
    }
    registry.add_builtin_function(
        Function::new("min", vec![Float], Float, "smallest of its arguments").variadic(),
    );
    registry.add_builtin_function(
        Function::new("max", vec![Float], Float, "largest of its arguments").variadic(),
    );
    registry.add_builtin_function(Function::new("norm", vec![Vec2], Float, "length of a vector"));
    registry.add_builtin_function(Function::new(
        "xydist",
        vec![Any, Any],
        Float,
        "distance in the x/y plane between two positions, or two objects' `pos`",
    ));
    registry.add_builtin_function(Function::new(
        "dist",
        vec![Any, Any],
        Float,
        "distance between two positions (or objects' `pos`), or |a - b| of two numbers",
    ));
    registry.add_builtin_function(Function::new("vec2", vec![Float, Float], Vec2, "the vector (x, y)"));
    registry.add_builtin_function(Function::new(
        "iou",
        vec![Any, Any],
        Float,
        "intersection over union of two boxes in pixels ([left, top, width, height], a box, or two objects' `box`)",
    ));
    registry.add_builtin_function(Function::new(
        "box_dist",
        vec![Any, Any],
        Float,
        "distance in pixels between the centres of two boxes (as iou takes them)",
    ));
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
