//! The registry `kpl check` and `kpl list` use: every source, computational unit, link unit,
//! sink, prediction model and formula function the runtime provides, with its signature.

use kpl_core::{Value, ValueType};
use kpl_semantic::registry::{Entry, EntryKind, Function, Param, ParamType, Registry, TypeReq};

fn fields(list: &[(&str, ValueType)]) -> TypeReq {
    TypeReq::Fields(list.iter().map(|(n, t)| (n.to_string(), t.clone())).collect())
}

fn choice(options: &[&str]) -> ParamType {
    ParamType::Choice(options.iter().map(|o| o.to_string()).collect())
}

/// The formula functions every context has (implemented by `kpl_mtl::builtins`).
fn functions(registry: &mut Registry) {
    use ValueType::{Any, Float, Vec2};
    for (name, summary) in [
        ("abs", "absolute value"),
        ("sqrt", "square root (an error on negative numbers)"),
        ("floor", "largest integer not above"),
        ("ceil", "smallest integer not below"),
    ] {
        registry.add_function(Function::new(name, vec![Float], Float, summary));
    }
    registry.add_function(Function::new("min", vec![Float], Float, "smallest of its arguments").variadic());
    registry.add_function(Function::new("max", vec![Float], Float, "largest of its arguments").variadic());
    registry.add_function(Function::new("norm", vec![Vec2], Float, "length of a vector"));
    registry.add_function(Function::new("vec2", vec![Float, Float], Vec2, "the vector (x, y)"));
    registry.add_function(Function::new(
        "xydist",
        vec![Any, Any],
        Float,
        "distance in the x/y plane between two positions, or two objects' `pos`",
    ));
    registry.add_function(Function::new(
        "dist",
        vec![Any, Any],
        Float,
        "distance between two positions (or objects' `pos`), or |a - b| of two numbers",
    ));
}

fn on_road() -> Function {
    Function::new(
        "on_road",
        vec![ValueType::Any],
        ValueType::Bool,
        "whether a position (or an object's `pos`) is on a road of the network",
    )
}

fn scenario_param() -> Param {
    Param::optional(
        "scenario",
        choice(&["crossing", "bridge", "grid_town"]),
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

pub fn registry() -> Registry {
    use ValueType::{Float, Int, Vec2};
    let mut r = Registry::default();
    functions(&mut r);

    // Generic sources and sinks.
    r.add(
        Entry::new(EntryKind::Source, "timer", "Emits 0, 1, 2, ... once every period.")
            .param(Param::required("period", ParamType::Duration, "time between samples"))
            .param(Param::optional(
                "count",
                ParamType::Int,
                Value::Int(0),
                "samples to emit (0: until the run ends)",
            ))
            .output(TypeReq::Exact(Int)),
    );
    r.add(
        Entry::new(
            EntryKind::Source,
            "file.jsonl",
            "Replays samples recorded as JSON lines (docs/streams.md).",
        )
        .param(Param::required("path", ParamType::Str, "file to read"))
        .param(Param::optional(
            "stream",
            ParamType::Str,
            Value::str(""),
            "only lines whose `stream` is this (empty: all)",
        )),
    );
    r.add(
        Entry::new(
            EntryKind::Source,
            "zenoh.subscribe",
            "Samples published on a zenoh key by a program outside the spec.",
        )
        .param(Param::required("key", ParamType::Str, "key expression to subscribe to")),
    );
    r.add(
        Entry::new(EntryKind::Compute, "kpl.merge", "Forwards every sample of each of its inputs, in arrival order.")
            .variadic(1, "in", TypeReq::Any, "streams to merge"),
    );
    r.add(
        Entry::new(EntryKind::Sink, "console", "Prints each sample as a JSON line on standard output.")
            .variadic(1, "in", TypeReq::Any, "streams to print"),
    );
    r.add(
        Entry::new(
            EntryKind::Sink,
            "file.jsonl",
            "Records samples as JSON lines, one per sample (docs/streams.md).",
        )
        .variadic(1, "in", TypeReq::Any, "streams to record")
        .param(Param::required("path", ParamType::Str, "file to write (created with its directory)")),
    );
    r.add(
        Entry::new(
            EntryKind::Sink,
            "zenoh.publish",
            "Publishes samples on a zenoh key for programs outside the spec.",
        )
        .input("in", TypeReq::Any, "stream to publish")
        .param(Param::required("key", ParamType::Str, "key expression to publish on")),
    );

    // The UAV traffic scenario.
    let mut tracker = Entry::new(
        EntryKind::Source,
        "sim.uav_tracker",
        "Vision percepts of cars from a simulated UAV tracker.",
    )
    .output(fields(&[("pos", Vec2), ("vel", Vec2), ("size", Float)]));
    for info in kpl_sim::Params::describe() {
        let ty = match info.ty {
            "int" => ParamType::Int,
            "float" => ParamType::Float,
            "bool" => ParamType::Bool,
            _ => ParamType::Str,
        };
        let default = serde_json::from_str::<serde_json::Value>(&info.default)
            .ok()
            .and_then(|j| Value::from_json_untyped(&j).ok())
            .unwrap_or_else(|| Value::str(""));
        tracker = tracker.param(Param::optional(info.name, ty, default, info.doc));
    }
    r.add(tracker);

    // Link units.
    r.add(
        Entry::new(EntryKind::Link, "anchor.copy", "Copies the attributes the two types share.")
            .output(TypeReq::Any),
    );
    r.add(
        Entry::new(
            EntryKind::Link,
            "anchor.world_from_percept",
            "World position and velocity from a vision percept.",
        )
        .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
    );
    r.add(
        Entry::new(
            EntryKind::Link,
            "anchor.snap_to_lane",
            "Snaps a world object to the nearest lane of the road network.",
        )
        .param(scenario_param())
        .param(network_file_param())
        .output(fields(&[("pos", Vec2), ("vel", Vec2), ("road", Int), ("lane_offset", Float)]))
        .provides(on_road()),
    );

    // Prediction models.
    r.add(
        Entry::new(EntryKind::Predict, "constant_velocity", "Moves on with the velocity it last had.")
            .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
    );
    r.add(
        Entry::new(EntryKind::Predict, "stationary", "Stays where it was last seen.")
            .output(fields(&[("pos", Vec2)])),
    );
    r.add(
        Entry::new(
            EntryKind::Predict,
            "along_roads",
            "Keeps its speed along the road network, one hypothesis per branch at a crossing.",
        )
        .param(scenario_param())
        .param(network_file_param())
        .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
    );
    r
}
