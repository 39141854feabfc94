//! `check_identification`: a description asked for at run time is checked as the spec's
//! `identify` items are.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

use kpl_core::ValueType;
use kpl_semantic::registry::{Function, Registry};

fn setup() -> (Registry, kpl_semantic::hir::TypeTable) {
    let mut registry = Registry::default();
    registry.add_function(Function::new(
        "xydist",
        vec![ValueType::Vec2, ValueType::Vec2],
        ValueType::Float,
        "planar distance",
    ));
    registry.add_function(Function::new(
        "vec2",
        vec![ValueType::Float, ValueType::Float],
        ValueType::Vec2,
        "a vector",
    ));
    let parse = kpl_syntax::parse(
        "type WorldObject symbol wo { pos: vec2, vel: vec2 }\ntype Car : WorldObject symbol co { plate: string }\n",
    );
    let checked = kpl_semantic::check(&parse.spec, &registry);
    assert!(!checked.has_errors(), "{:?}", checked.diagnostics);
    (registry, checked.spec.unwrap().types)
}

fn errors(ty: &str, description: &str) -> Vec<String> {
    let (registry, types) = setup();
    let expr = kpl_syntax::parse_formula(description).unwrap();
    kpl_semantic::check_identification(&registry, &types, ty, &expr).into_iter().map(|d| d.message).collect()
}

#[test]
fn a_well_typed_description_has_no_errors() {
    assert_eq!(
        errors("Car", "xydist(this.pos, vec2(1.0, 2.0)) < 20.0 and this.plate == \"ABC\""),
        Vec::<String>::new()
    );
    // Inherited attributes and temporal operators are fine.
    assert_eq!(errors("Car", "eventually[0, 2s] this.vel.x > 5.0"), Vec::<String>::new());
}

#[test]
fn mistakes_are_reported() {
    assert_eq!(errors("Car", "this.speeed > 1.0"), vec!["`Car` has no attribute `speeed`"]);
    assert_eq!(errors("WorldObject", "this.plate == \"x\""), vec!["`WorldObject` has no attribute `plate`"]);
    assert!(
        errors("Car", "this.pos > 1.0").iter().any(|m| m.contains("vec2")),
        "{:?}",
        errors("Car", "this.pos > 1.0")
    );
    assert!(errors("Car", "that.pos.x > 0.0").iter().any(|m| m.contains("that")));
    assert!(errors("Car", "this.vel.x").iter().any(|m| m.contains("boolean")));
    assert!(errors("Truck", "true").iter().any(|m| m.contains("Truck")));
    assert!(errors("Car", "nearest(this.pos) < 1.0").iter().any(|m| m.contains("nearest")));
}
