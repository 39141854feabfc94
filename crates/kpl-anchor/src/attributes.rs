//! The road attributes of an object on the road network, as `anchor.snap_to_lane` and the
//! `along_roads` prediction compute them: where on the network it is (road, lane, distance along
//! the lane, in a junction), how it moves (speed, heading) and what the lane allows (its speed
//! limit). A record gets those of the attributes its type declares (by name, with a fitting
//! type); the others are left alone. The relations of traffic situations
//! ([`crate::relations`]) are functions of these attributes.

use kpl_core::{Record, Value};
use kpl_roads::{LaneId, LaneKind, LanePosition, Place, RoadNetwork, geom};

/// Every attribute [`set_road_attributes`] may set, with its type as a spec declares it.
pub const ROAD_ATTRIBUTES: &[(&str, &str, &str)] = &[
    ("road", "int", "the road's index (-1 inside a junction or off the network)"),
    ("lane", "string", "the lane's name (SUMO's lane id; `\"\"` off the network); an `int` gets its index"),
    ("lane_pos", "float", "distance along the lane from its start, in its direction of travel (m)"),
    ("lane_length", "float", "the lane's length (m)"),
    ("in_junction", "bool", "whether the lane is a connection inside a junction"),
    (
        "crossed_solid_line",
        "bool",
        "whether the lane is new since the last state and was reached across a solid line (the lane left may not change to that side)",
    ),
    ("speed_limit", "float", "the lane's speed limit (m/s)"),
    ("speed", "float", "the speed: the length of `vel` (m/s)"),
    (
        "heading",
        "float",
        "direction of travel (radians counter-clockwise from east): of `vel` when moving, else the lane's",
    ),
    (
        "lane_heading",
        "float",
        "direction of the lane the position lies on, whatever the direction of travel (radians)",
    ),
];

/// The names of [`ROAD_ATTRIBUTES`].
pub fn road_attribute_names() -> Vec<&'static str> {
    ROAD_ATTRIBUTES.iter().map(|(name, _, _)| *name).collect()
}

/// What is known of an object's place and motion on the network.
#[derive(Debug, Clone, Copy)]
pub struct OnLane<'a> {
    pub network: &'a RoadNetwork,
    /// The lane the object is on and where along it.
    pub at: &'a LanePosition,
    /// Its velocity (along the lane), when known.
    pub vel: Option<[f64; 2]>,
    /// Below this speed the heading is the lane's, not the velocity's.
    pub min_heading_speed_mps: f64,
    /// The direction of the lane the object physically lies on (for `lane_heading`); the lane's
    /// own when not given.
    pub lane_heading: Option<f64>,
    /// The lane of the object's previous state, when it was measured on one (for
    /// `crossed_solid_line`; `None` for a prediction, which never changes lanes across one).
    pub previous_lane: Option<LaneId>,
}

/// Sets the road attributes of `record` that its type declares (see [`ROAD_ATTRIBUTES`]).
pub fn set_road_attributes(record: &mut Record, on: &OnLane<'_>) {
    let lane = on.network.lane(on.at.lane);
    let road = match on.at.place {
        Place::Road { road, .. } => i64::from(road.0),
        Place::Crossing { .. } => -1,
    };
    let speed = on.vel.map_or(0.0, geom::norm);
    let heading = match on.vel {
        Some(v) if geom::norm(v) >= on.min_heading_speed_mps => geom::heading_of(v),
        _ => on.at.heading,
    };
    for (name, value) in &mut record.fields {
        let new = match (&**name, &*value) {
            ("road", Value::Int(_)) => Value::Int(road),
            ("lane", Value::Str(_)) => Value::str(&lane.name),
            ("lane", Value::Int(_)) => Value::Int(i64::from(on.at.lane.0)),
            ("lane_pos", Value::Float(_)) => Value::Float(on.at.offset_m),
            ("lane_length", Value::Float(_)) => Value::Float(lane.path.length()),
            ("in_junction", Value::Bool(_)) => Value::Bool(matches!(lane.kind, LaneKind::Connector { .. })),
            ("crossed_solid_line", Value::Bool(_)) => Value::Bool(
                on.previous_lane
                    .is_some_and(|from| on.network.crosses_solid_line(from, on.at.lane, on.at.point)),
            ),
            ("speed_limit", Value::Float(_)) => Value::Float(lane.speed_limit_mps),
            ("speed", Value::Float(_)) => Value::Float(speed),
            ("heading", Value::Float(_)) => Value::Float(heading),
            ("lane_heading", Value::Float(_)) => Value::Float(on.lane_heading.unwrap_or(on.at.heading)),
            _ => continue,
        };
        *value = new;
    }
}

/// Sets the road attributes of an object off the network: `road` -1, `lane` empty (or -1),
/// `speed` and `heading` from its velocity; the lane's attributes keep their last values.
pub fn set_off_road_attributes(record: &mut Record, vel: Option<[f64; 2]>) {
    let speed = vel.map(geom::norm);
    for (name, value) in &mut record.fields {
        match (&**name, &*value) {
            ("road", Value::Int(_)) => *value = Value::Int(-1),
            ("lane", Value::Str(_)) => *value = Value::str(""),
            ("lane", Value::Int(_)) => *value = Value::Int(-1),
            ("in_junction" | "crossed_solid_line", Value::Bool(_)) => *value = Value::Bool(false),
            ("speed", Value::Float(_)) => {
                if let Some(speed) = speed {
                    *value = Value::Float(speed);
                }
            }
            ("heading", Value::Float(_)) => {
                if let Some(v) = vel.filter(|v| geom::norm(*v) > 0.0) {
                    *value = Value::Float(geom::heading_of(v));
                }
            }
            _ => {}
        }
    }
}

/// Whether a record declares `lane_heading` (an extra snapping of its position is then needed).
pub fn wants_lane_heading(record: &Record) -> bool {
    matches!(record.get("lane_heading"), Some(Value::Float(_)))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use std::sync::Arc;

    fn record(names: &[(&str, Value)]) -> Record {
        Record {
            id: Some("co1".into()),
            fields: names.iter().map(|(n, v)| (Arc::from(*n), v.clone())).collect(),
        }
    }

    #[test]
    fn sets_what_the_type_declares() {
        let network = RoadNetwork::build(&kpl_roads::scenarios::bridge()).unwrap();
        let main = network.road_by_name("main").unwrap();
        let lane = main.lanes.last().unwrap().lane;
        let at = network.lane_position(lane, 30.0);
        let mut r = record(&[
            ("road", Value::Int(0)),
            ("lane", Value::str("")),
            ("lane_pos", Value::Float(0.0)),
            ("lane_length", Value::Float(0.0)),
            ("in_junction", Value::Bool(true)),
            ("speed_limit", Value::Float(0.0)),
            ("speed", Value::Float(0.0)),
            ("heading", Value::Float(9.0)),
            ("size", Value::Float(4.0)),
        ]);
        let vel = geom::scale(geom::unit(at.heading), 12.0);
        set_road_attributes(
            &mut r,
            &OnLane {
                network: &network,
                at: &at,
                vel: Some(vel),
                min_heading_speed_mps: 2.0,
                lane_heading: None,
                previous_lane: None,
            },
        );
        assert_eq!(r.get("road"), Some(&Value::Int(i64::from(main.id.0))));
        assert_eq!(r.get("lane"), Some(&Value::str(&network.lane(lane).name)));
        assert_eq!(r.get("lane_pos"), Some(&Value::Float(30.0)));
        assert_eq!(r.get("lane_length"), Some(&Value::Float(network.lane(lane).path.length())));
        assert_eq!(r.get("in_junction"), Some(&Value::Bool(false)));
        assert_eq!(r.get("speed_limit"), Some(&Value::Float(network.lane(lane).speed_limit_mps)));
        assert!((r.get("speed").unwrap().as_f64().unwrap() - 12.0).abs() < 1e-9);
        assert!((r.get("heading").unwrap().as_f64().unwrap() - at.heading).abs() < 1e-9);
        assert_eq!(r.get("size"), Some(&Value::Float(4.0)), "undeclared attributes are left alone");
        // Standing still: the heading is the lane's.
        set_road_attributes(
            &mut r,
            &OnLane {
                network: &network,
                at: &at,
                vel: Some([0.3, -0.2]),
                min_heading_speed_mps: 2.0,
                lane_heading: None,
                previous_lane: None,
            },
        );
        assert!((r.get("heading").unwrap().as_f64().unwrap() - at.heading).abs() < 1e-9);
        // Off the network.
        set_off_road_attributes(&mut r, Some([0.0, 3.0]));
        assert_eq!(r.get("road"), Some(&Value::Int(-1)));
        assert_eq!(r.get("lane"), Some(&Value::str("")));
        assert_eq!(r.get("speed"), Some(&Value::Float(3.0)));
    }
}
