//! Signatures for the checker (`kpl check`, `kpl list`): the link units and prediction models
//! this crate implements ([`entries`]), and what the engine's own specs are checked against
//! without a runtime ([`signatures`], [`check_text`]). The registry `kpl` runs with is assembled
//! in `kpl-std`.

use kpl_core::{Value, ValueType};
use kpl_semantic::hir;
use kpl_semantic::registry::{Entry, EntryKind, Function, Param, ParamType, Registry, TypeReq};

fn fields(list: &[(&str, ValueType)]) -> TypeReq {
    TypeReq::Fields(list.iter().map(|(n, t)| (n.to_string(), t.clone())).collect())
}

fn network_params(entry: Entry) -> Entry {
    entry
        .param(Param::optional(
            "scenario",
            ParamType::Choice(kpl_roads::scenarios::NAMES.iter().map(|s| s.to_string()).collect()),
            Value::str("crossing"),
            "built-in road network (ignored when `network_file` is set)",
        ))
        .param(Param::optional(
            "network_file",
            ParamType::Str,
            Value::str(""),
            "road network file: SUMO .net.xml or the project's JSON, either gzipped (docs/roads.md)",
        ))
        .param(Param::optional(
            "min_heading_speed",
            ParamType::Float,
            Value::Float(crate::units::MIN_HEADING_SPEED_MPS),
            "below this speed (m/s) the direction of `vel` is not used to pick the lane",
        ))
}

/// The filter parameters of `anchor.kalman` and `anchor.fuse`.
fn kalman_params(entry: Entry) -> Entry {
    let defaults = crate::kalman::KalmanParams::default();
    entry
        .param(Param::optional(
            "position_noise_m",
            ParamType::Float,
            Value::Float(defaults.position_noise_m),
            "standard deviation of the linked-from object's position, per axis (m)",
        ))
        .param(Param::optional(
            "initial_velocity_sd_mps",
            ParamType::Float,
            Value::Float(defaults.initial_velocity_sd_mps),
            "standard deviation of the first velocity (the linked-from object's `vel`), per axis (m/s)",
        ))
        .param(Param::optional(
            "acceleration_noise",
            ParamType::Float,
            Value::Float(defaults.acceleration_noise),
            "spectral density of the white-noise acceleration (m²/s³): how fast the velocity may change",
        ))
        .param(Param::optional(
            "velocity_noise_mps",
            ParamType::Float,
            Value::Float(defaults.velocity_noise_mps.unwrap_or(0.0)),
            "standard deviation of the linked-from object's `vel` as a measurement, per axis (m/s); 0: only `pos` is measured",
        ))
        .param(Param::optional(
            "smooth",
            ParamType::Duration,
            Value::Duration(0),
            "set `smoothed_pos` and `smoothed_vel` (when the linked-to type declares them) to a fixed-lag smoother's estimate this long before the state's time (0s: not smoothed; at most 60s)",
        )
        .acting_on(&crate::kalman::SMOOTHED_ATTRIBUTES))
}

/// `on_road(pos)`, provided by `anchor.snap_to_lane`.
pub fn on_road_signature() -> Function {
    Function::new(
        "on_road",
        vec![ValueType::Any],
        ValueType::Bool,
        "whether a position (or an object's `pos`) is on a road of the network",
    )
}

/// What `anchor.snap_to_lane` sets: the position, velocity, offset from the lane centre (and the
/// smoothed position's) and the road attributes ([`crate::attributes::ROAD_ATTRIBUTES`]).
fn snap_computes() -> Vec<&'static str> {
    let mut names = vec!["pos", "vel", "lane_offset", crate::units::SMOOTHED_LANE_OFFSET];
    names.extend(crate::attributes::road_attribute_names());
    names
}

/// The link units and prediction models of [`crate::Implementations::default`].
pub fn entries() -> Vec<Entry> {
    use ValueType::{Float, Int, Vec2};
    vec![
        Entry::new(EntryKind::Link, "anchor.copy", "Copies the attributes the two types share.")
            .output(TypeReq::Any)
            .computes(&[], true),
        Entry::new(
            EntryKind::Link,
            "anchor.world_from_percept",
            "World position and velocity from a vision percept.",
        )
        .output(fields(&[("pos", Vec2), ("vel", Vec2)]))
        .computes(&["pos", "vel"], true),
        network_params(Entry::new(
            EntryKind::Link,
            "anchor.snap_to_lane",
            "Snaps a world object to the centre of the nearest lane of the road network.",
        ))
        .output(fields(&[("pos", Vec2), ("vel", Vec2), ("road", Int), ("lane_offset", Float)]))
        .computes(&snap_computes(), true)
        .provides(on_road_signature()),
        kalman_params(Entry::new(
            EntryKind::Link,
            "anchor.kalman",
            "Position and velocity estimated from the linked-from objects' positions by a constant-velocity Kalman filter (shared by every Kalman link into the object).",
        ))
        .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
        kalman_params(Entry::new(
            EntryKind::Link,
            "anchor.fuse",
            "As anchor.kalman, also updated with the closest object of a second source (an extra input stream) within a gate.",
        ))
        .input(
            "other",
            TypeReq::Objects(vec![("pos".to_string(), Vec2)]),
            "the second source's objects (positions in the same frame), one snapshot per time",
        )
        .param(Param::optional(
            "other_noise_m",
            ParamType::Float,
            Value::Float(crate::kalman::FuseParams::default().other_noise_m),
            "standard deviation of the second source's positions, per axis (m)",
        ))
        .param(Param::optional(
            "gate_m",
            ParamType::Float,
            Value::Float(crate::kalman::FuseParams::default().gate_m),
            "a second-source object farther than this from the estimate is another object (m)",
        ))
        .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
        Entry::new(EntryKind::Predict, "constant_velocity", "Moves on with the velocity it last had.")
            .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
        Entry::new(EntryKind::Predict, "stationary", "Stays where it was last seen.")
            .output(fields(&[("pos", Vec2)])),
        network_params(Entry::new(
            EntryKind::Predict,
            "along_roads",
            "Keeps its speed along the road network, one hypothesis per branch at a crossing.",
        ))
        .param(Param::optional(
            "max_hypotheses",
            ParamType::Int,
            Value::Int(crate::predict::DEFAULT_MAX_HYPOTHESES as i64),
            "most hypotheses kept (straightest routes first)",
        ))
        .param(Param::optional(
            "forget_at_end",
            ParamType::Bool,
            Value::Bool(false),
            "forget a structure as soon as every route reached the end of the network (it left the map) instead of after `forget`",
        ))
        .output(fields(&[("pos", Vec2), ("vel", Vec2)])),
    ]
}

/// The name of the source the engine's own specs declare ([`signatures`]): objects the caller
/// hands to [`crate::Anchoring::step`] as snapshots. Specs that `kpl` runs name real sources
/// (`sim.uav_tracker`, `file.jsonl`, ...) instead.
pub const INPUT_SOURCE: &str = "engine.input";

/// What the engine checks its specs against, without a runtime: the built-in formula functions,
/// the traffic relations ([`crate::relations::signatures`]), the link units and prediction models
/// ([`entries`]) and [`INPUT_SOURCE`], a source of any objects.
pub fn signatures() -> Registry {
    let mut registry = Registry::with_builtin_functions();
    for function in crate::relations::signatures() {
        registry.add_function(function);
    }
    for entry in entries() {
        registry.add(entry);
    }
    registry.add(
        Entry::new(
            EntryKind::Source,
            INPUT_SOURCE,
            "Objects handed to the anchoring engine by its caller (Anchoring::step's snapshots).",
        )
        .output(TypeReq::Any),
    );
    registry
}

/// Parses and checks a spec against [`signatures`] (the engine's own: its sources are
/// [`INPUT_SOURCE`]).
pub fn check_text(text: &str) -> Result<hir::Spec, kpl_semantic::SpecErrors> {
    kpl_semantic::check_text(text, &signatures())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use crate::Implementations;

    /// Every signature has an implementation and every implementation a signature.
    #[test]
    fn signatures_match_implementations() {
        let implementations = Implementations::default();
        let mut links: Vec<String> =
            entries().iter().filter(|e| e.kind == EntryKind::Link).map(|e| e.name.clone()).collect();
        let mut models: Vec<String> =
            entries().iter().filter(|e| e.kind == EntryKind::Predict).map(|e| e.name.clone()).collect();
        links.sort();
        models.sort();
        assert_eq!(links, implementations.link_unit_names().map(String::from).collect::<Vec<_>>());
        assert_eq!(models, implementations.model_names().map(String::from).collect::<Vec<_>>());
    }

    #[test]
    fn errors_name_the_line() {
        let err = check_text("type A { x: flot }\n").unwrap_err();
        assert!(err.0.starts_with("1:"), "{err}");
    }
}
