//! The registry `kpl check`, `kpl list` and `kpl run` use: the runtime's built-ins, the standard
//! processes (`kpl-std`), and the signatures of the anchoring units and prediction models.

use kpl_core::{Value, ValueType};
use kpl_runtime::Registry;
use kpl_semantic::registry::{Entry, EntryKind, Function, Param, ParamType, TypeReq};

fn fields(list: &[(&str, ValueType)]) -> TypeReq {
    TypeReq::Fields(list.iter().map(|(n, t)| (n.to_string(), t.clone())).collect())
}

fn scenario_param() -> Param {
    Param::optional(
        "scenario",
        ParamType::Choice(["crossing", "bridge", "grid_town"].iter().map(|s| s.to_string()).collect()),
        Value::str("crossing"),
        "built-in road network (ignored when `network_file` is set)",
    )
}

fn network_file_param() -> Param {
    Param::optional(
        "network_file",
        ParamType::Str,
        Value::str(""),
        "road network JSON file (docs/simulator.md)",
    )
}

/// Signatures of the link units and prediction models that link processes run.
fn anchoring_signatures(r: &mut Registry) {
    use ValueType::{Float, Int, Vec2};
    let on_road = Function::new(
        "on_road",
        vec![ValueType::Any],
        ValueType::Bool,
        "whether a position (or an object's `pos`) is on a road of the network",
    );
    r.add_signature(Entry::new(EntryKind::Link, "anchor.copy", "Copies the attributes the two types share."));
    r.add_signature(
        Entry::new(
            EntryKind::Link,
            "anchor.world_from_percept",
            "World position and velocity from a vision percept.",
        )
        .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
    );
    r.add_signature(
        Entry::new(
            EntryKind::Link,
            "anchor.snap_to_lane",
            "Snaps a world object to the nearest lane of the road network.",
        )
        .param(scenario_param())
        .param(network_file_param())
        .output(fields(&[("pos", Vec2), ("vel", Vec2), ("road", Int), ("lane_offset", Float)]))
        .provides(on_road),
    );
    r.add_signature(
        Entry::new(EntryKind::Predict, "constant_velocity", "Moves on with the velocity it last had.")
            .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
    );
    r.add_signature(
        Entry::new(EntryKind::Predict, "stationary", "Stays where it was last seen.")
            .output(fields(&[("pos", Vec2)])),
    );
    r.add_signature(
        Entry::new(
            EntryKind::Predict,
            "along_roads",
            "Keeps its speed along the road network, one hypothesis per branch at a crossing.",
        )
        .param(scenario_param())
        .param(network_file_param())
        .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
    );
}

/// Extra processes from a user's crate (`kpl::main_with`).
static EXTENSION: std::sync::OnceLock<fn(&mut Registry)> = std::sync::OnceLock::new();

pub(crate) fn extend_with(extend: fn(&mut Registry)) {
    let _ = EXTENSION.set(extend);
}

pub fn registry() -> Registry {
    let mut registry = Registry::with_builtins();
    kpl_std::register(&mut registry);
    kpl_zenoh::register(&mut registry);
    anchoring_signatures(&mut registry);
    if let Some(extend) = EXTENSION.get() {
        extend(&mut registry);
    }
    registry
}
