//! The signatures of the formula functions every spec may use: `kpl-mtl`'s built-ins (which
//! implements them) and `vec2`. They belong to the language, not to a runtime, so the checker
//! knows them without one ([`Registry::with_builtin_functions`]).

use kpl_core::ValueType;

use crate::registry::{Function, Registry};

/// The built-in formula functions' signatures.
pub fn builtin_functions() -> Vec<Function> {
    use ValueType::{Any, Float, Vec2};
    let mut functions: Vec<Function> = [
        ("abs", "absolute value"),
        ("sqrt", "square root (an error on negative numbers)"),
        ("floor", "largest integer not above"),
        ("ceil", "smallest integer not below"),
    ]
    .into_iter()
    .map(|(name, summary)| Function::new(name, vec![Float], Float, summary))
    .collect();
    functions.push(Function::new("min", vec![Float], Float, "smallest of its arguments").variadic());
    functions.push(Function::new("max", vec![Float], Float, "largest of its arguments").variadic());
    functions.push(Function::new("norm", vec![Vec2], Float, "length of a vector"));
    functions.push(Function::new(
        "xydist",
        vec![Any, Any],
        Float,
        "distance in the x/y plane between two positions, or two objects' `pos`",
    ));
    functions.push(Function::new(
        "dist",
        vec![Any, Any],
        Float,
        "distance between two positions (or objects' `pos`), or |a - b| of two numbers",
    ));
    functions.push(Function::new("vec2", vec![Float, Float], Vec2, "the vector (x, y)"));
    functions
}

impl Registry {
    /// A registry with the built-in formula functions and nothing else.
    pub fn with_builtin_functions() -> Registry {
        let mut registry = Registry::default();
        for function in builtin_functions() {
            registry.add_function(function);
        }
        registry
    }
}
