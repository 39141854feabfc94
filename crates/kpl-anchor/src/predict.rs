//! Prediction models: the state of an object that has no incoming link, from its last state
//! (`predict TYPE = MODEL(params)`). A model may give several hypotheses, most likely first.
//!
//! Built in: `constant_velocity` (moves on with the velocity it last had), `stationary` (stays
//! where it was last seen, velocity zero) and `along_roads` (keeps its speed along the lanes of a
//! road network, one hypothesis per branch taken at every crossing on the way; straightest first).
//!
//! Predictions are always made from the state the object had when prediction began, never from
//! the previous prediction, so errors do not accumulate step by step.

use std::fmt;
use std::sync::Arc;

use kpl_core::{Record, Time, Value};
use kpl_roads::{LanePosition, RoadNetwork, geom};

use crate::attributes::{OnLane, set_road_attributes};
use crate::records::{position, velocity, with_fields};
use crate::units::{MIN_HEADING_SPEED_MPS, heading_of_velocity};

/// Where a prediction starts: the last known state, its time, and (for road models) the lane it
/// was snapped to then.
#[derive(Debug, Clone)]
pub struct PredictionStart {
    pub state: Arc<Record>,
    pub time: Time,
    pub lane: Option<LanePosition>,
}

/// How objects of a type move while nothing is linked to them.
pub trait PredictionModel: fmt::Debug + Send + Sync {
    /// The name used in specs and change records (`constant_velocity`).
    fn name(&self) -> &str;

    /// Begins a prediction from the last known `state` at `time`.
    fn start(&self, state: Arc<Record>, time: Time) -> PredictionStart {
        PredictionStart { state, time, lane: None }
    }

    /// The hypotheses at `time` (at or after the start), most likely first; at least one.
    fn predict(&self, start: &PredictionStart, time: Time, out: &mut Vec<Record>);

    /// Whether the prediction has ended by `time`: the model cannot say where the object is any
    /// more (it left the observed area). The structure then keeps its last state, unanchored.
    fn ended(&self, _start: &PredictionStart, _time: Time) -> bool {
        false
    }

    /// Whether a structure whose prediction ended is forgotten at once (its objects removed at
    /// that step, cause `forgotten`) rather than after the spec's `forget` time: what left the
    /// map is not waiting at its edge to be seen again.
    fn forget_when_ended(&self) -> bool {
        false
    }
}

fn seconds(from: Time, to: Time) -> f64 {
    (to.saturating_sub(from)).max(0) as f64 / 1e6
}

/// `constant_velocity`: `pos + vel * dt`, `vel` unchanged; a `box` in pixels (`[left, top,
/// width, height]`, an object in the image plane whose `pos` is the box's centre) moves with
/// it. A state without a vec2 `pos` and `vel` stays as it is.
#[derive(Debug, Clone, Copy, Default)]
pub struct ConstantVelocity;

impl PredictionModel for ConstantVelocity {
    fn name(&self) -> &str {
        "constant_velocity"
    }

    fn predict(&self, start: &PredictionStart, time: Time, out: &mut Vec<Record>) {
        let dt = seconds(start.time, time);
        match (position(&start.state), velocity(&start.state)) {
            (Some(p), Some(v)) => {
                let moved = geom::scale(v, dt);
                let mut fields = vec![("pos", Value::Vec2(geom::add(p, moved)))];
                if let Some(Value::List(b)) = start.state.get("box")
                    && b.len() == 4
                    && let (Some(left), Some(top)) = (b[0].as_f64(), b[1].as_f64())
                {
                    let mut shifted: Vec<Value> = b.to_vec();
                    shifted[0] = Value::Float(left + moved[0]);
                    shifted[1] = Value::Float(top + moved[1]);
                    fields.push(("box", Value::List(shifted.into())));
                }
                out.push(with_fields(&start.state, &fields));
            }
            _ => out.push((*start.state).clone()),
        }
    }
}

/// `stationary`: stays at its last position; a `vel` attribute becomes zero.
#[derive(Debug, Clone, Copy, Default)]
pub struct Stationary;

impl PredictionModel for Stationary {
    fn name(&self) -> &str {
        "stationary"
    }

    fn predict(&self, start: &PredictionStart, _time: Time, out: &mut Vec<Record>) {
        out.push(with_fields(&start.state, &[("vel", Value::vec2(0.0, 0.0))]));
    }
}

/// `along_roads`: the object keeps the speed it had and follows the lanes of the network from the
/// lane it was snapped to (preferring the lane of its direction of travel, when it moves at least
/// `min_heading_speed`), through the network's allowed connections at the end of each lane: one
/// hypothesis per route, at most `max_hypotheses`, ordered by how little the route turns
/// (straight on first). `pos` is the point on the lane centre, `vel` the speed along the lane
/// there, a `road` attribute (int) the road's index (-1 inside a junction) and a `lane` attribute
/// (string) the lane's name. A route that reaches a lane nothing continues (a dead end, the
/// network's border) is dropped; when every route has, the prediction has ended
/// ([`PredictionModel::ended`]): the object stays where it was last predicted, unanchored, and
/// the spec's `forget` removes it (or at once, with `forget_at_end`). An object that cannot be snapped (no lane within the snap
/// radius) is predicted with constant velocity. An object that moves against the lane it was
/// snapped to (a wrong-way driver where no lane goes its way) keeps moving backwards along that
/// lane, still against it, until the lane's start, where its prediction ends.
#[derive(Debug, Clone)]
pub struct AlongRoads {
    network: Arc<RoadNetwork>,
    max_hypotheses: usize,
    min_heading_speed_mps: f64,
    forget_at_end: bool,
}

/// Default cap on the hypotheses of `along_roads` (two four-way crossings give nine).
pub const DEFAULT_MAX_HYPOTHESES: usize = 9;

impl AlongRoads {
    pub fn new(network: Arc<RoadNetwork>, max_hypotheses: usize) -> AlongRoads {
        AlongRoads {
            network,
            max_hypotheses: max_hypotheses.max(1),
            min_heading_speed_mps: MIN_HEADING_SPEED_MPS,
            forget_at_end: false,
        }
    }

    /// Forget a structure as soon as every route reached the end of the network (the spec's
    /// `forget_at_end: true`): [`PredictionModel::forget_when_ended`].
    pub fn with_forget_at_end(mut self, forget: bool) -> AlongRoads {
        self.forget_at_end = forget;
        self
    }

    /// Below this speed (m/s) the velocity's direction is not used to pick the lane.
    pub fn with_min_heading_speed(mut self, mps: f64) -> AlongRoads {
        self.min_heading_speed_mps = mps;
        self
    }

    fn routes(
        &self,
        start: &PredictionStart,
        lane: &LanePosition,
        time: Time,
    ) -> (Vec<kpl_roads::Hypothesis>, f64, f64) {
        let speed = velocity(&start.state).map_or(0.0, geom::norm);
        let distance = speed * seconds(start.time, time);
        (self.network.advance(lane, distance, self.max_hypotheses), speed, distance)
    }

    /// Whether the object moved against its lane when prediction began.
    fn against_lane(&self, start: &PredictionStart, lane: &LanePosition) -> bool {
        velocity(&start.state).is_some_and(|v| {
            geom::norm(v) >= self.min_heading_speed_mps && geom::dot(v, geom::unit(lane.heading)) < 0.0
        })
    }

    /// How far back along its lane an object moving against it is at `time` (negative: it has
    /// passed the lane's start), and its speed.
    fn backwards(&self, start: &PredictionStart, lane: &LanePosition, time: Time) -> (f64, f64) {
        let speed = velocity(&start.state).map_or(0.0, geom::norm);
        (lane.offset_m - speed * seconds(start.time, time), speed)
    }

    /// The prediction of an object moving against its lane ([`AlongRoads`]).
    fn predict_backwards(
        &self,
        start: &PredictionStart,
        lane: &LanePosition,
        time: Time,
        out: &mut Vec<Record>,
    ) {
        let (offset, speed) = self.backwards(start, lane, time);
        if offset < 0.0 {
            out.push((*start.state).clone());
            return;
        }
        let at = self.network.lane_position(lane.lane, offset);
        let vel = geom::scale(geom::unit(at.heading), -speed);
        let mut record =
            with_fields(&start.state, &[("pos", Value::Vec2(at.point)), ("vel", Value::Vec2(vel))]);
        let on = OnLane {
            network: &self.network,
            at: &at,
            vel: Some(vel),
            min_heading_speed_mps: self.min_heading_speed_mps,
            lane_heading: None,
            previous_lane: None,
        };
        set_road_attributes(&mut record, &on);
        out.push(record);
    }
}

impl PredictionModel for AlongRoads {
    fn name(&self) -> &str {
        "along_roads"
    }

    fn start(&self, state: Arc<Record>, time: Time) -> PredictionStart {
        let heading = heading_of_velocity(velocity(&state), self.min_heading_speed_mps);
        let previous = previous_lane(&self.network, &state);
        let lane =
            position(&state).and_then(|p| self.network.snap(p, &kpl_roads::SnapHint { heading, previous }));
        PredictionStart { state, time, lane }
    }

    fn ended(&self, start: &PredictionStart, time: Time) -> bool {
        let Some(lane) = &start.lane else { return false };
        if self.against_lane(start, lane) {
            return self.backwards(start, lane, time).0 < 0.0;
        }
        let (routes, _, _) = self.routes(start, lane, time);
        !routes.is_empty() && routes.iter().all(|h| h.reached_end)
    }

    fn forget_when_ended(&self) -> bool {
        self.forget_at_end
    }

    fn predict(&self, start: &PredictionStart, time: Time, out: &mut Vec<Record>) {
        let Some(lane) = &start.lane else {
            ConstantVelocity.predict(start, time, out);
            return;
        };
        if self.against_lane(start, lane) {
            self.predict_backwards(start, lane, time, out);
            return;
        }
        let (mut hypotheses, speed, _) = self.routes(start, lane, time);
        // A route that left the map is not where the object can be.
        hypotheses.retain(|h| !h.reached_end);
        // Straightest first; `advance` gives a deterministic order, which breaks ties.
        let turn = |h: &kpl_roads::Hypothesis| geom::heading_difference(h.position.heading, lane.heading);
        hypotheses.sort_by(|a, b| turn(a).total_cmp(&turn(b)));
        for h in &hypotheses {
            let direction = geom::unit(h.position.heading);
            let vel = geom::scale(direction, speed);
            let mut record = with_fields(
                &start.state,
                &[("pos", Value::Vec2(h.position.point)), ("vel", Value::Vec2(vel))],
            );
            let on = OnLane {
                network: &self.network,
                at: &h.position,
                vel: Some(vel),
                min_heading_speed_mps: self.min_heading_speed_mps,
                lane_heading: None,
                previous_lane: None,
            };
            set_road_attributes(&mut record, &on);
            out.push(record);
        }
        if out.is_empty() {
            out.push((*start.state).clone());
        }
    }
}

/// The lane an object's last state was on: its `lane` attribute (a lane name, or index), else
/// the lane whose centre its `pos` lies on (states made by `anchor.snap_to_lane` and
/// `along_roads` are on a lane centre).
pub fn previous_lane(network: &RoadNetwork, state: &Record) -> Option<kpl_roads::LaneId> {
    match state.get("lane") {
        Some(Value::Str(name)) if !name.is_empty() => return network.lane_by_name(name).map(|l| l.id),
        Some(Value::Int(i)) if *i >= 0 && (*i as usize) < network.lanes().len() => {
            return Some(kpl_roads::LaneId(*i as u32));
        }
        _ => {}
    }
    network.lane_centre_at(position(state)?, 0.05)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    fn state(pos: [f64; 2], vel: [f64; 2]) -> Arc<Record> {
        Arc::new(Record {
            id: Some("oo1".into()),
            fields: vec![
                ("pos".into(), Value::Vec2(pos)),
                ("vel".into(), Value::Vec2(vel)),
                ("road".into(), Value::Int(0)),
            ],
        })
    }

    fn predict(model: &dyn PredictionModel, s: Arc<Record>, dt_s: f64) -> Vec<Record> {
        let start = model.start(s, 1_000_000);
        let mut out = Vec::new();
        model.predict(&start, 1_000_000 + (dt_s * 1e6) as Time, &mut out);
        out
    }

    #[test]
    fn constant_velocity_and_stationary() {
        let out = predict(&ConstantVelocity, state([1.0, 2.0], [3.0, -1.0]), 2.0);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].get("pos"), Some(&Value::vec2(7.0, 0.0)));
        assert_eq!(out[0].get("vel"), Some(&Value::vec2(3.0, -1.0)));
        let out = predict(&Stationary, state([1.0, 2.0], [3.0, -1.0]), 2.0);
        assert_eq!(out[0].get("pos"), Some(&Value::vec2(1.0, 2.0)));
        assert_eq!(out[0].get("vel"), Some(&Value::vec2(0.0, 0.0)));
        // In the image plane the box moves with its centre.
        let numbers =
            |v: [f64; 4]| Value::List(v.iter().map(|x| Value::Float(*x)).collect::<Vec<_>>().into());
        let mut track = (*state([15.0, 25.0], [10.0, -5.0])).clone();
        track.fields.push(("box".into(), numbers([10.0, 20.0, 10.0, 10.0])));
        let out = predict(&ConstantVelocity, Arc::new(track), 0.5);
        assert_eq!(out[0].get("pos"), Some(&Value::vec2(20.0, 22.5)));
        assert_eq!(out[0].get("box"), Some(&numbers([15.0, 17.5, 10.0, 10.0])));
    }

    #[test]
    fn along_roads_splits_at_a_crossing_straightest_first() {
        let network = Arc::new(RoadNetwork::build(&kpl_roads::scenarios::crossing()).unwrap());
        let model = AlongRoads::new(network.clone(), DEFAULT_MAX_HYPOTHESES);
        // Eastbound on `west`, 30 m before the crossing at 10 m/s: after 1 s still one hypothesis.
        let out = predict(&model, state([-30.0, -1.75], [10.0, 0.0]), 1.0);
        assert_eq!(out.len(), 1);
        let pos = out[0].get("pos").unwrap().as_vec2().unwrap();
        assert!((pos[0] + 20.0).abs() < 1e-6 && (pos[1] + 1.75).abs() < 1e-6, "{pos:?}");
        // After 6 s (60 m) it has passed the crossing: left, straight on, right; straight first.
        let out = predict(&model, state([-30.0, -1.75], [10.0, 0.0]), 6.0);
        assert_eq!(out.len(), 3);
        let first = out[0].get("pos").unwrap().as_vec2().unwrap();
        assert!(first[0] > 20.0 && first[1].abs() < 3.0, "straight on first: {first:?}");
        let east = network.road_by_name("east").unwrap().id;
        assert_eq!(out[0].get("road"), Some(&Value::Int(i64::from(east.0))));
        for h in &out {
            let p = h.get("pos").unwrap().as_vec2().unwrap();
            assert!(network.on_road(p), "{p:?}");
            let v = h.get("vel").unwrap().as_vec2().unwrap();
            assert!((geom::norm(v) - 10.0).abs() < 1e-9);
        }
        // Leaving the map at the east end (x = 150): the prediction ends there, not beyond.
        let start = model.start(state([140.0, -1.75], [10.0, 0.0]), 1_000_000);
        assert!(!model.ended(&start, 1_500_000), "still on the map after 0.5 s");
        assert!(model.ended(&start, 4_000_000), "off the map after 3 s");
        // Off the network: constant velocity.
        let out = predict(&model, state([60.0, 60.0], [1.0, 0.0]), 2.0);
        assert_eq!(out[0].get("pos"), Some(&Value::vec2(62.0, 60.0)));
    }

    #[test]
    fn along_roads_keeps_a_wrong_way_driver_going_against_its_lane() {
        // A one-way road, 200 m west to east; a car drives it westwards at 20 m/s.
        let mut file = kpl_roads::NetworkFile::new();
        file.add_node("w", [0.0, 0.0]);
        file.add_node("e", [200.0, 0.0]);
        file.add_road("main", "w", "e", Vec::new());
        file.roads[0].lanes =
            vec![kpl_roads::format::LaneSpec::new(3.5, kpl_roads::format::LaneDirection::Forward)];
        let network = Arc::new(RoadNetwork::build(&file).unwrap());
        let model = AlongRoads::new(network.clone(), DEFAULT_MAX_HYPOTHESES);
        let mut s = (*state([150.0, -1.75], [-20.0, 0.0])).clone();
        for (name, value) in [("heading", Value::Float(0.0)), ("lane_heading", Value::Float(0.0))] {
            s.fields.push((name.into(), value));
        }
        let s = Arc::new(s);
        let out = predict(&model, s.clone(), 2.0);
        assert_eq!(out.len(), 1);
        let pos = out[0].get("pos").unwrap().as_vec2().unwrap();
        assert!((pos[0] - 110.0).abs() < 0.5, "40 m back along the lane: {pos:?}");
        let vel = out[0].get("vel").unwrap().as_vec2().unwrap();
        assert!((vel[0] + 20.0).abs() < 1e-9 && vel[1].abs() < 1e-9, "{vel:?}");
        let heading = out[0].get("heading").unwrap().as_f64().unwrap();
        let lane_heading = out[0].get("lane_heading").unwrap().as_f64().unwrap();
        assert!(crate::relations::angle_between(heading, lane_heading) > 3.0, "still against the lane");
        // At the lane's start (150 m back, after 7.5 s) the prediction ends.
        let start = model.start(s, 1_000_000);
        assert!(!model.ended(&start, 8_000_000));
        assert!(model.ended(&start, 9_000_000));
    }
}
