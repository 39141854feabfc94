//! Link units: the computational units of link specifications (`via UNIT(params)`), which compute
//! the state of a linked-to object from the state of the object linked to it, and may provide
//! predicates to their link's conditions (`anchor.snap_to_lane` provides `on_road`).
//!
//! Built in: `anchor.copy` (the attributes the two types share), `anchor.world_from_percept`
//! (position and velocity of a percept in world coordinates: the simulated tracker already
//! reports them there, so this checks and copies them) and `anchor.snap_to_lane` (the position
//! snapped to the centre of the nearest lane of a road network, with the road and the lateral
//! offset from the lane centre).

use std::fmt;
use std::sync::Arc;

use kpl_core::{Record, RecordType, Value};
use kpl_mtl::Function;
use kpl_roads::geom;
use kpl_roads::{RoadNetwork, SnapHint};

use crate::attributes::{OnLane, set_off_road_attributes, set_road_attributes, wants_lane_heading};
use crate::predict::previous_lane;
use crate::records::{fill, position, velocity};
use crate::stateful::UnitCall;

/// Computes the state of a linked-to object (type `to`) from the state of the object linked to it.
pub trait LinkUnit: fmt::Debug + Send + Sync {
    /// The new state of the linked-to object `symbol`. `previous` is its last state (absent for
    /// an object being created). An `Err` is reported as a warning and the object keeps its state.
    fn compute(
        &self,
        from: &Record,
        previous: Option<&Record>,
        to: &RecordType,
        symbol: &Arc<str>,
    ) -> Result<Record, String>;

    /// Functions this unit adds to the conditions of its link (`on_road`).
    fn functions(&self) -> Vec<Function> {
        Vec::new()
    }

    /// The new state with everything the engine knows at this state: the time, the unit's
    /// extra input streams and its memory of the object ([`crate::stateful`]). Stateful units
    /// override this; the default is [`LinkUnit::compute`].
    fn compute_with(&self, call: &mut UnitCall<'_>) -> Result<Record, String> {
        self.compute(call.from, call.previous, call.to, call.symbol)
    }

    /// The key under which this unit keeps a memory of each object it computes (shared by every
    /// link into the object whose unit names the same key); `None` for a stateless unit.
    fn memory_key(&self) -> Option<&Arc<str>> {
        None
    }
}

/// `anchor.copy`: every attribute of the linked-to type that the linked-from object also has
/// (same name, a fitting type) is copied; the others keep their last value (their default at
/// first).
#[derive(Debug, Clone, Copy, Default)]
pub struct Copy;

impl LinkUnit for Copy {
    fn compute(
        &self,
        from: &Record,
        previous: Option<&Record>,
        to: &RecordType,
        symbol: &Arc<str>,
    ) -> Result<Record, String> {
        Ok(fill(to, symbol, from, previous))
    }
}

/// `anchor.world_from_percept`: the world position and velocity of a vision percept. The
/// simulated tracker reports percepts in world coordinates, so this copies `pos` and `vel` (and
/// any other shared attribute), and refuses a percept without them.
#[derive(Debug, Clone, Copy, Default)]
pub struct WorldFromPercept;

impl LinkUnit for WorldFromPercept {
    fn compute(
        &self,
        from: &Record,
        previous: Option<&Record>,
        to: &RecordType,
        symbol: &Arc<str>,
    ) -> Result<Record, String> {
        if position(from).is_none() || velocity(from).is_none() {
            return Err("a percept needs `pos` and `vel` (vec2) to give a world position".to_string());
        }
        Ok(fill(to, symbol, from, previous))
    }
}

/// Below this speed (m/s) a measured velocity says nothing about the direction of travel: the
/// simulated tracker's velocity noise (0.5 m/s on each axis) alone gives a standing car a speed
/// above 2 m/s in fewer than one frame in 2,900.
pub const MIN_HEADING_SPEED_MPS: f64 = 2.0;

/// The attribute `anchor.snap_to_lane` sets to the offset of the linked-from object's
/// `smoothed_pos` (`anchor.kalman(smooth: ...)`) from its lane's centre.
pub const SMOOTHED_LANE_OFFSET: &str = "smoothed_lane_offset";

/// `anchor.snap_to_lane`: the object on the road network. `pos` is the point on the centre of the
/// lane chosen by [`kpl_roads::RoadNetwork::snap`]: the nearest, counting lanes against the
/// direction of `vel` as further away when the object moves at least `min_heading_speed`, and
/// lanes that do not continue the lane its last state was on as further away (lane continuity:
/// a car standing in a queue, whose velocity is noise, stays on its lane). `vel` is the velocity
/// along that lane, `road` the road's index (-1 inside a junction or off the network), `lane`
/// (string) the lane's name, `lane_offset` the signed distance of the unsnapped position from the
/// lane centre (positive to the left). Off the network (no lane within the network's snap radius)
/// the position and velocity are copied, `road` is -1 and `lane_offset` 0. The other road
/// attributes the type declares (`lane_pos`, `speed`, `heading`, `speed_limit`, `in_junction`,
/// ...: [`crate::attributes::ROAD_ATTRIBUTES`]) are set from the lane and the measured velocity,
/// and [`SMOOTHED_LANE_OFFSET`] from a smoothed position. Provides `on_road(pos)`.
#[derive(Debug, Clone)]
pub struct SnapToLane {
    network: Arc<RoadNetwork>,
    min_heading_speed_mps: f64,
}

impl SnapToLane {
    pub fn new(network: Arc<RoadNetwork>) -> SnapToLane {
        SnapToLane { network, min_heading_speed_mps: MIN_HEADING_SPEED_MPS }
    }

    /// Below this speed (m/s) the velocity's direction is not used to pick the lane.
    pub fn with_min_heading_speed(mut self, mps: f64) -> SnapToLane {
        self.min_heading_speed_mps = mps;
        self
    }

    /// The smoothed position's offset from its lane's centre, as `lane_offset` is the position's
    /// (0 without a `smoothed_pos` or off the network): the lane is the nearest to
    /// `smoothed_pos` in the direction of `smoothed_vel` (or `vel`), chosen on its own, since the
    /// smoothed position is an earlier time's.
    fn smoothed_lane_offset(&self, from: &Record) -> f64 {
        let Some(pos) = from.get("smoothed_pos").and_then(Value::as_vec2) else { return 0.0 };
        let vel = from.get("smoothed_vel").and_then(Value::as_vec2).or_else(|| velocity(from));
        let hint = SnapHint { heading: heading_of_velocity(vel, self.min_heading_speed_mps), previous: None };
        self.network.snap(pos, &hint).map_or(0.0, |s| s.lateral_m)
    }
}

/// The heading of a velocity, when it is at least `min_speed` (m/s).
pub fn heading_of_velocity(vel: Option<[f64; 2]>, min_speed: f64) -> Option<f64> {
    vel.filter(|v| geom::norm(*v) >= min_speed).map(geom::heading_of)
}

impl LinkUnit for SnapToLane {
    fn compute(
        &self,
        from: &Record,
        previous: Option<&Record>,
        to: &RecordType,
        symbol: &Arc<str>,
    ) -> Result<Record, String> {
        let mut record = fill(to, symbol, from, previous);
        let Some(pos) = position(from) else {
            return Err("snapping to a lane needs a `pos` (vec2)".to_string());
        };
        let measured = pos;
        let vel = velocity(from);
        let previous_lane = previous.and_then(|p| previous_lane(&self.network, p));
        let hint = SnapHint {
            heading: heading_of_velocity(vel, self.min_heading_speed_mps),
            previous: previous_lane,
        };
        // Standing still, the velocity says nothing and one noisy position little: the lane is
        // chosen for the middle of this position and the last one (the previous state's point
        // on its lane plus its `lane_offset`), which halves the noise's variance.
        let query = match (hint.heading, previous, previous_lane) {
            (None, Some(previous), Some(lane)) => last_position(&self.network, previous, lane)
                .map_or(pos, |last| geom::scale(geom::add(pos, last), 0.5)),
            _ => pos,
        };
        let snapped = self.network.snap(query, &hint).map(|s| {
            // The lane chosen, the point and the offset of this measurement.
            let projection = self.network.lane(s.lane).path.project(pos);
            let mut at = self.network.lane_position(s.lane, projection.offset);
            at.point = projection.point;
            at.lateral_m = projection.lateral;
            at
        });
        let (pos, vel, lane_offset) = match &snapped {
            Some(lane) => {
                let along = geom::unit(lane.heading);
                let vel = vel.map(|v| geom::scale(along, geom::dot(v, along)));
                (lane.point, vel, lane.lateral_m)
            }
            None => (pos, vel, 0.0),
        };
        for (name, value) in &mut record.fields {
            match &**name {
                "pos" => *value = Value::Vec2(pos),
                "vel" => {
                    if let Some(v) = vel {
                        *value = Value::Vec2(v);
                    }
                }
                "lane_offset" if matches!(value, Value::Float(_)) => *value = Value::Float(lane_offset),
                SMOOTHED_LANE_OFFSET if matches!(value, Value::Float(_)) => {
                    *value = Value::Float(self.smoothed_lane_offset(from));
                }
                _ => {}
            }
        }
        match &snapped {
            Some(lane) => {
                // The lane the measured position lies on, whatever way the object moves (a car
                // driving the wrong way is snapped to the lane of its direction of travel).
                let lane_heading = wants_lane_heading(&record)
                    .then(|| self.network.snap(measured, &SnapHint::default()).map(|l| l.heading))
                    .flatten();
                // The speed and heading of the measurement: a car driving against its lane moves
                // against `vel` projected on it.
                let on = OnLane {
                    network: &self.network,
                    at: lane,
                    vel: velocity(from),
                    min_heading_speed_mps: self.min_heading_speed_mps,
                    lane_heading,
                    previous_lane,
                };
                set_road_attributes(&mut record, &on);
            }
            None => set_off_road_attributes(&mut record, vel),
        }
        Ok(record)
    }

    fn functions(&self) -> Vec<Function> {
        vec![on_road(self.network.clone())]
    }
}

/// The unsnapped position a previous state stood for: its point on `lane` moved sideways by its
/// `lane_offset`.
fn last_position(network: &RoadNetwork, previous: &Record, lane: kpl_roads::LaneId) -> Option<[f64; 2]> {
    let point = position(previous)?;
    let offset = previous.get("lane_offset").and_then(Value::as_f64)?;
    let path = &network.lane(lane).path;
    let along = path.project(point);
    if along.lateral.abs() > 0.05 {
        return None; // not a point on that lane
    }
    let left = geom::left_normal(geom::unit(path.heading_at(along.offset)));
    Some(geom::add(along.point, geom::scale(left, offset)))
}

/// `on_road(p)`: whether a position (or an object's `pos`) is on the paved surface of the network.
pub fn on_road(network: Arc<RoadNetwork>) -> Function {
    Function::new("on_road", (1, Some(1)), move |args| {
        let pos = match &args[0] {
            Value::Vec2(p) => *p,
            Value::Record(r) => position(r)
                .ok_or_else(|| "on_road needs a position; the object has no vec2 `pos`".to_string())?,
            other => return Err(format!("on_road needs a vec2 position, found {}", other.kind())),
        };
        Ok(Value::Bool(network.on_road(pos)))
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use kpl_core::{FieldType, ValueType};

    fn onroad_type() -> RecordType {
        let f = |n: &str, t: ValueType| FieldType { name: n.into(), ty: t };
        RecordType {
            name: "OnRoadObject".into(),
            parent: Some("WorldObject".into()),
            symbol: "oo".into(),
            fields: vec![
                f("pos", ValueType::Vec2),
                f("vel", ValueType::Vec2),
                f("road", ValueType::Int),
                f("lane_offset", ValueType::Float),
            ],
        }
    }

    fn world(pos: [f64; 2], vel: [f64; 2]) -> Record {
        Record {
            id: Some("wo1".into()),
            fields: vec![("pos".into(), Value::Vec2(pos)), ("vel".into(), Value::Vec2(vel))],
        }
    }

    /// `crossed_solid_line` is true on the one state whose lane was reached across a solid line,
    /// in the direction the line forbids only.
    #[test]
    fn a_lane_reached_across_a_solid_line_is_marked_on_that_state() {
        use kpl_roads::format::{LaneDirection, LaneSpec};
        let mut file = kpl_roads::NetworkFile::new();
        file.add_node("w", [0.0, 0.0]);
        file.add_node("e", [400.0, 0.0]);
        file.add_road("we", "w", "e", Vec::new());
        // Two lanes east (left one at y = 1.75); the left one may not change to the right.
        let mut left = LaneSpec::new(3.5, LaneDirection::Forward);
        left.solid_right = true;
        file.roads[0].lanes = vec![left, LaneSpec::new(3.5, LaneDirection::Forward)];
        let unit = SnapToLane::new(Arc::new(RoadNetwork::build(&file).unwrap()));
        let mut to = onroad_type();
        to.fields.push(FieldType { name: "lane".into(), ty: ValueType::Str });
        to.fields.push(FieldType { name: "crossed_solid_line".into(), ty: ValueType::Bool });
        let mut previous: Option<Record> = None;
        let mut marked = Vec::new();
        for (x, y) in
            [(100.0, 1.75), (120.0, 1.6), (140.0, -1.75), (160.0, -1.8), (180.0, 1.75), (200.0, -1.75)]
        {
            let out =
                unit.compute(&world([x, y], [20.0, 0.0]), previous.as_ref(), &to, &"oo1".into()).unwrap();
            marked.push(out.get("crossed_solid_line") == Some(&Value::Bool(true)));
            previous = Some(out);
        }
        assert_eq!(marked, [false, false, true, false, false, true]);
    }

    #[test]
    fn snap_to_lane_centres_the_object_on_its_lane() {
        let network = Arc::new(RoadNetwork::build(&kpl_roads::scenarios::bridge()).unwrap());
        let main = network.road_by_name("main").unwrap().id;
        let unit = SnapToLane::new(network);
        // Eastbound on `main` (lanes at y = +-1.75, driving on the right: eastbound at y = -1.75).
        let out =
            unit.compute(&world([-100.0, -1.0], [13.0, 0.4]), None, &onroad_type(), &"oo1".into()).unwrap();
        let pos = out.get("pos").unwrap().as_vec2().unwrap();
        assert!((pos[1] + 1.75).abs() < 1e-6, "{pos:?}");
        assert_eq!(out.get("road"), Some(&Value::Int(i64::from(main.0))));
        let offset = out.get("lane_offset").unwrap().as_f64().unwrap();
        assert!((offset - 0.75).abs() < 1e-6, "left of the lane centre by 0.75 m: {offset}");
        let vel = out.get("vel").unwrap().as_vec2().unwrap();
        assert!((vel[0] - 13.0).abs() < 1e-6 && vel[1].abs() < 1e-6, "{vel:?}");
        // Far from any road: copied, road -1.
        let out =
            unit.compute(&world([90.0, 90.0], [1.0, 0.0]), None, &onroad_type(), &"oo1".into()).unwrap();
        assert_eq!(out.get("pos"), Some(&Value::vec2(90.0, 90.0)));
        assert_eq!(out.get("road"), Some(&Value::Int(-1)));
    }

    #[test]
    fn a_smoothed_position_gets_its_own_lane_offset() {
        let network = Arc::new(RoadNetwork::build(&kpl_roads::scenarios::bridge()).unwrap());
        let unit = SnapToLane::new(network);
        let mut to = onroad_type();
        to.fields.push(FieldType { name: SMOOTHED_LANE_OFFSET.into(), ty: ValueType::Float });
        // Now 0.75 m left of the eastbound lane's centre (y = -1.75); 2 s ago 0.5 m right of it,
        // 26 m back.
        let mut from = world([-100.0, -1.0], [13.0, 0.4]);
        let offset = |out: &Record| out.get(SMOOTHED_LANE_OFFSET).unwrap().as_f64().unwrap();
        assert_eq!(offset(&unit.compute(&from, None, &to, &"oo1".into()).unwrap()), 0.0, "no smoothed_pos");
        from.fields.push(("smoothed_pos".into(), Value::vec2(-126.0, -2.25)));
        from.fields.push(("smoothed_vel".into(), Value::vec2(13.0, 0.0)));
        let out = unit.compute(&from, None, &to, &"oo1".into()).unwrap();
        assert!((offset(&out) + 0.5).abs() < 1e-6, "{}", offset(&out));
        assert!((out.get("lane_offset").unwrap().as_f64().unwrap() - 0.75).abs() < 1e-6);
        // Moving west 2 s ago, at the same place: the westbound lane (y = +1.75) is its lane.
        from.fields.last_mut().unwrap().1 = Value::vec2(-13.0, 0.0);
        let out = unit.compute(&from, None, &to, &"oo1".into()).unwrap();
        assert!((offset(&out).abs() - 4.0).abs() < 1e-6, "{}", offset(&out));
    }

    #[test]
    fn on_road_reads_positions_and_objects() {
        let network = Arc::new(RoadNetwork::build(&kpl_roads::scenarios::bridge()).unwrap());
        let f = on_road(network);
        assert_eq!((f.body)(&[Value::vec2(-100.0, -1.0)]).unwrap(), Value::Bool(true));
        assert_eq!((f.body)(&[Value::vec2(-100.0, -40.0)]).unwrap(), Value::Bool(false));
        let object = Value::Record(Arc::new(world([-100.0, 1.0], [0.0, 0.0])));
        assert_eq!((f.body)(&[object]).unwrap(), Value::Bool(true));
        assert!((f.body)(&[Value::Int(3)]).is_err());
    }
}
