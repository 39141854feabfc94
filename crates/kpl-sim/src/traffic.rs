//! Cars driving through the road network: each keeps its lane (with a little lateral wander),
//! follows the car ahead with the Intelligent Driver Model, slows down for turns, picks a random
//! branch at every crossing, and leaves the map at boundary nodes, where a new car (with a new id)
//! enters at a free entry lane to keep the count constant. This module owns the ground truth.
//!
//! Cars do not yield to each other inside crossings; the model is meant to give a tracker
//! plausible motion, not to study traffic.

use std::sync::Arc;

use kpl_core::{Record, Value};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::error::ParamsError;
use kpl_roads::geom::{self, Point};
use kpl_roads::{LaneId, LaneKind, Place, RoadNetwork};

/// A vehicle's identity within one run (numbered from 1 in order of appearance, never reused);
/// [`CarState::name`] is what it is called.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CarId(pub u32);

/// The true state of one vehicle at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct CarState {
    pub id: CarId,
    /// `car1`, `car2`, ... for simulated traffic; the recorded id for recorded traffic.
    pub name: Arc<str>,
    /// The vehicle's centre.
    pub pos: Point,
    pub vel: Point,
    /// Direction of travel in radians, counter-clockwise from east.
    pub heading: f64,
    pub speed_mps: f64,
    /// The lane it is on (`None`: a recorded vehicle off the network).
    pub lane: Option<LaneId>,
    pub place: Option<Place>,
    /// Arc length along `lane`.
    pub offset_m: f64,
    pub length_m: f64,
    pub width_m: f64,
}

impl CarState {
    /// The road it is on (`None` inside a junction or off the network).
    pub fn road(&self) -> Option<kpl_roads::RoadId> {
        match self.place {
            Some(Place::Road { road, .. }) => Some(road),
            _ => None,
        }
    }

    /// The ground truth as a record: `id` (the vehicle's name), fields `pos` (its centre), `vel`,
    /// `heading`, `speed`, `road` and `lane` (the road index and lane number, left to right; -1
    /// inside a junction or off the network), `node` (the junction's index, -1 elsewhere),
    /// `length`, `width`.
    pub fn to_record(&self) -> Record {
        let (road, lane, node) = match self.place {
            Some(Place::Road { road, lane }) => (i64::from(road.0), i64::from(lane), -1),
            Some(Place::Crossing { node }) => (-1, -1, i64::from(node.0)),
            None => (-1, -1, -1),
        };
        Record {
            id: Some(self.name.clone()),
            fields: vec![
                ("pos".into(), Value::Vec2(self.pos)),
                ("vel".into(), Value::Vec2(self.vel)),
                ("heading".into(), Value::Float(self.heading)),
                ("speed".into(), Value::Float(self.speed_mps)),
                ("road".into(), Value::Int(road)),
                ("lane".into(), Value::Int(lane)),
                ("node".into(), Value::Int(node)),
                ("length".into(), Value::Float(self.length_m)),
                ("width".into(), Value::Float(self.width_m)),
            ],
        }
    }

    pub fn to_value(&self) -> Value {
        Value::Record(Arc::new(self.to_record()))
    }
}

/// Width of simulated cars, metres.
pub const CAR_WIDTH_M: f64 = 1.8;

// Intelligent Driver Model constants (Treiber et al.), typical urban values.
const MAX_ACCEL: f64 = 1.5;
const COMFORT_DECEL: f64 = 2.0;
const MAX_DECEL: f64 = 8.0;
const TIME_HEADWAY_S: f64 = 1.2;
const MIN_GAP_M: f64 = 2.0;
/// Free road needed at the start of an entry lane before a new car may enter.
const ENTRY_CLEARANCE_M: f64 = 15.0;
/// Lane length per car that a network must offer for a requested number of cars.
const LANE_M_PER_CAR: f64 = 15.0;
/// Slow drift of each car's desired speed: relative standard deviation and time constant.
const SPEED_DRIFT_SD: f64 = 0.03;
const SPEED_DRIFT_TAU_S: f64 = 5.0;
/// Lateral wander around the lane centre: standard deviation, time constant and bound.
const WANDER_SD_M: f64 = 0.15;
const WANDER_TAU_S: f64 = 3.0;
const WANDER_MAX_M: f64 = 0.5;

#[derive(Debug, Clone)]
struct Car {
    id: CarId,
    name: Arc<str>,
    lane: LaneId,
    offset: f64,
    speed: f64,
    /// Desired speed as a fraction of the speed limit, fixed per car.
    speed_factor: f64,
    /// Slowly drifting deviation from `speed_factor`.
    speed_drift: f64,
    lateral: f64,
    /// The branch this car will take at the end of its lane (`None`: it leaves the map there).
    next_lane: Option<LaneId>,
    length: f64,
}

/// All cars on a network.
#[derive(Debug, Clone)]
pub struct Traffic {
    cars: Vec<Car>,
    next_id: u32,
    rng: ChaCha8Rng,
    speed_sd: f64,
    /// Cars that left the map and still have to be replaced.
    pending_entries: u32,
    /// Scratch: car indices sorted by (lane, offset), and the first of each lane in that order.
    order: Vec<u32>,
    /// Scratch: each car's key lane and offset along it (see `sort`).
    keys: Vec<(LaneId, f64)>,
    first_in_lane: Vec<u32>,
    /// Lanes whose `first_in_lane` entry is set.
    marked_lanes: Vec<u32>,
}

/// The lane a car at `offset` on `lane` is ordered along, and its offset there (see `Traffic::sort`).
fn key_of(net: &RoadNetwork, lane: LaneId, offset: f64) -> (LaneId, f64) {
    let l = net.lane(lane);
    match l.kind {
        LaneKind::Connector { to, .. } => (to, offset - connector_length(net, lane)),
        LaneKind::Road { .. } => (lane, offset),
    }
}

/// From the start of a connector lane to the road lane it leads into: its length and that of the
/// connectors after it (a SUMO turn may pass two internal lanes).
fn connector_length(net: &RoadNetwork, lane: LaneId) -> f64 {
    let mut length = net.lane(lane).path.length();
    let mut current = lane;
    for _ in 0..8 {
        match net.onward(current).next() {
            Some(next) if matches!(net.lane(next).kind, LaneKind::Connector { .. }) => {
                length += net.lane(next).path.length();
                current = next;
            }
            _ => break,
        }
    }
    length
}

/// The speed a car placed at `offset` on `lane` starts with: its share of the speed limit,
/// lowered near the end of the lane so that it can brake comfortably to the next lane's limit.
fn desired_speed(
    net: &RoadNetwork,
    lane: LaneId,
    offset: f64,
    next_lane: Option<LaneId>,
    factor: f64,
) -> f64 {
    let l = net.lane(lane);
    let mut desired = l.speed_limit_mps * factor;
    if let Some(next_lane) = next_lane {
        let to_lane_end = (l.path.length() - offset).max(0.0);
        let v_next = net.lane(next_lane).speed_limit_mps * factor;
        desired = desired.min((v_next * v_next + 2.0 * COMFORT_DECEL * to_lane_end).sqrt());
    }
    desired.max(0.5)
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample(StandardNormal)
}

impl Traffic {
    /// Places `n_cars` cars on random road lanes, spaced apart where possible.
    pub fn new(
        net: &RoadNetwork,
        n_cars: u32,
        speed_sd: f64,
        rng: ChaCha8Rng,
    ) -> Result<Traffic, ParamsError> {
        let lane_m = net.road_lane_length_m();
        let capacity = (lane_m / LANE_M_PER_CAR).floor() as u64;
        if u64::from(n_cars) > capacity {
            return Err(ParamsError::TooManyCars { n_cars, lane_km: lane_m / 1000.0, capacity });
        }
        let mut traffic = Traffic {
            cars: Vec::with_capacity(n_cars as usize),
            next_id: 1,
            rng,
            speed_sd,
            pending_entries: 0,
            order: Vec::new(),
            keys: Vec::new(),
            first_in_lane: vec![u32::MAX; net.lanes().len()],
            marked_lanes: Vec::new(),
        };
        let mut taken: std::collections::HashMap<LaneId, Vec<f64>> = std::collections::HashMap::new();
        for _ in 0..n_cars {
            let mut chosen = None;
            for _attempt in 0..20 {
                let u: f64 = traffic.rng.random();
                let Some(position) = net.road_lane_position_at_fraction(u) else { break };
                let free = taken
                    .get(&position.lane)
                    .is_none_or(|offsets| offsets.iter().all(|o| (o - position.offset_m).abs() >= 10.0));
                chosen = Some(position);
                if free {
                    break;
                }
            }
            let Some(position) = chosen else { break };
            taken.entry(position.lane).or_default().push(position.offset_m);
            traffic.add_car(net, position.lane, position.offset_m);
        }
        Ok(traffic)
    }

    fn add_car(&mut self, net: &RoadNetwork, lane: LaneId, offset: f64) {
        let speed_factor = (1.0 + self.speed_sd * normal(&mut self.rng)).clamp(0.5, 1.5);
        let length = self.rng.random_range(4.0..5.0);
        let next_lane = self.choose_branch(net, lane);
        let speed = desired_speed(net, lane, offset, next_lane, speed_factor);
        self.cars.push(Car {
            id: CarId(self.next_id),
            name: format!("car{}", self.next_id).into(),
            lane,
            offset,
            speed,
            speed_factor,
            speed_drift: 0.0,
            lateral: 0.0,
            next_lane,
            length,
        });
        self.next_id += 1;
    }

    fn choose_branch(&mut self, net: &RoadNetwork, lane: LaneId) -> Option<LaneId> {
        let n = net.onward(lane).count();
        if n == 0 {
            return None;
        }
        let pick = self.rng.random_range(0..n);
        net.onward(lane).nth(pick)
    }

    pub fn len(&self) -> usize {
        self.cars.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cars.is_empty()
    }

    /// Sorts cars along their "key lane" and records where each key lane's cars start. A car on
    /// a road lane is keyed by that lane and its offset; a car on a connector by the road lane the
    /// connector leads into, at a negative offset (the distance still to go to that lane). So cars
    /// merging from different connectors into one lane follow each other.
    fn sort(&mut self, net: &RoadNetwork) {
        for &lane in &self.marked_lanes {
            self.first_in_lane[lane as usize] = u32::MAX;
        }
        self.marked_lanes.clear();
        self.keys.clear();
        self.keys.extend(self.cars.iter().map(|car| key_of(net, car.lane, car.offset)));
        self.order.clear();
        self.order.extend(0..self.cars.len() as u32);
        let (cars, keys) = (&self.cars, &self.keys);
        self.order.sort_unstable_by(|&a, &b| {
            let (ka, kb) = (keys[a as usize], keys[b as usize]);
            ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1)).then(cars[a as usize].id.cmp(&cars[b as usize].id))
        });
        for (rank, &i) in self.order.iter().enumerate() {
            let lane = self.keys[i as usize].0.0;
            if self.first_in_lane[lane as usize] == u32::MAX {
                self.first_in_lane[lane as usize] = rank as u32;
                self.marked_lanes.push(lane);
            }
        }
    }

    /// Lets replacement cars enter at free entry lanes.
    fn enter_pending(&mut self, net: &RoadNetwork) {
        let entries = net.entry_lanes();
        if self.pending_entries == 0 || entries.is_empty() {
            return;
        }
        let mut used: Vec<LaneId> = Vec::new();
        // A few tries per pending car; the rest wait for the next step.
        for _ in 0..self.pending_entries.saturating_mul(3).min(1000) {
            if self.pending_entries == 0 {
                break;
            }
            let lane = entries[self.rng.random_range(0..entries.len())];
            if used.contains(&lane) {
                continue;
            }
            let first = self.first_in_lane[lane.0 as usize];
            let clear = first == u32::MAX || {
                let i = self.order[first as usize] as usize;
                self.keys[i].1 - self.cars[i].length > ENTRY_CLEARANCE_M
            };
            if clear {
                used.push(lane);
                self.add_car(net, lane, 0.0);
                self.pending_entries -= 1;
            }
        }
    }

    /// The car ahead of car `i` (at `rank` in the order): the next one along its key lane, or
    /// else the first one along the key lane it turns into. Returns the gap and its speed.
    fn leader(&self, net: &RoadNetwork, rank: usize) -> Option<(f64, f64)> {
        let i = self.order[rank] as usize;
        let (key_lane, key_offset) = self.keys[i];
        if let Some(&j) = self.order.get(rank + 1) {
            let j = j as usize;
            if self.keys[j].0 == key_lane {
                return Some((self.keys[j].1 - self.cars[j].length - key_offset, self.cars[j].speed));
            }
        }
        let car = &self.cars[i];
        if key_lane != car.lane {
            return None; // on a connector with nobody ahead in the lane it leads into
        }
        let next = car.next_lane?;
        // Where the next key lane starts, measured from the car.
        let (next_key_lane, start_offset) = key_of(net, next, 0.0);
        let to_lane_end = (net.lane(car.lane).path.length() - car.offset).max(0.0);
        let first = self.first_in_lane[next_key_lane.0 as usize];
        (first != u32::MAX).then(|| {
            let j = self.order[first as usize] as usize;
            (to_lane_end - start_offset + self.keys[j].1 - self.cars[j].length, self.cars[j].speed)
        })
    }

    /// Advances every car by `dt_s` seconds. Returns the cars that left the map.
    pub fn step(&mut self, net: &RoadNetwork, dt_s: f64) -> Vec<CarId> {
        self.sort(net);
        let n = self.cars.len();
        let mut accelerations = vec![0.0; n];
        for rank in 0..n {
            let car = &self.cars[self.order[rank] as usize];
            let leader = self.leader(net, rank);
            let factor = car.speed_factor + car.speed_drift;
            let lane = net.lane(car.lane);
            let desired = (lane.speed_limit_mps * factor).max(0.5);
            let v = car.speed;
            let mut accel = MAX_ACCEL * (1.0 - (v / desired).powi(4));
            if let Some(next_lane) = car.next_lane {
                // Brake for a slower next lane (a turn) so as to reach its speed at the lane end.
                let v_next = net.lane(next_lane).speed_limit_mps * factor;
                let to_lane_end = (lane.path.length() - car.offset).max(0.5);
                let needed = (v * v - v_next * v_next) / (2.0 * to_lane_end);
                if needed > 0.5 * COMFORT_DECEL {
                    accel = accel.min(-needed);
                }
            }
            if let Some((gap, v_leader)) = leader {
                let gap = gap.max(0.1);
                let wanted_gap = MIN_GAP_M
                    + (v * TIME_HEADWAY_S + v * (v - v_leader) / (2.0 * (MAX_ACCEL * COMFORT_DECEL).sqrt()))
                        .max(0.0);
                accel -= MAX_ACCEL * (wanted_gap / gap).powi(2);
            }
            accelerations[self.order[rank] as usize] = accel.max(-MAX_DECEL);
        }

        let mut left_map = Vec::new();
        let drift_keep = 1.0 - dt_s / SPEED_DRIFT_TAU_S;
        let drift_kick = SPEED_DRIFT_SD * (2.0 * dt_s / SPEED_DRIFT_TAU_S).sqrt();
        let wander_keep = 1.0 - dt_s / WANDER_TAU_S;
        let wander_kick = WANDER_SD_M * (2.0 * dt_s / WANDER_TAU_S).sqrt();
        let mut i = 0;
        while i < self.cars.len() {
            let accel = accelerations[i];
            let drift_noise = normal(&mut self.rng);
            let wander_noise = normal(&mut self.rng);
            let car = &mut self.cars[i];
            let new_speed = (car.speed + accel * dt_s).max(0.0);
            car.offset += (car.speed + new_speed) / 2.0 * dt_s;
            car.speed = new_speed;
            car.speed_drift = car.speed_drift * drift_keep + drift_kick * drift_noise;
            car.lateral =
                (car.lateral * wander_keep + wander_kick * wander_noise).clamp(-WANDER_MAX_M, WANDER_MAX_M);
            let mut exited = false;
            loop {
                let car = &mut self.cars[i];
                let length = net.lane(car.lane).path.length();
                if car.offset <= length {
                    break;
                }
                match car.next_lane {
                    Some(next) => {
                        car.offset -= length;
                        car.lane = next;
                        let branch = self.choose_branch(net, next);
                        self.cars[i].next_lane = branch;
                    }
                    None => {
                        exited = true;
                        break;
                    }
                }
            }
            if exited {
                left_map.push(self.cars[i].id);
                // Keep `accelerations` aligned with `cars` when swapping the last car in.
                self.cars.swap_remove(i);
                accelerations.swap_remove(i);
                self.pending_entries += 1;
            } else {
                i += 1;
            }
        }
        if self.pending_entries > 0 {
            self.sort(net);
            self.enter_pending(net);
        }
        left_map
    }

    /// The true state of every car, in a deterministic order.
    pub fn states(&self, net: &RoadNetwork) -> Vec<CarState> {
        self.cars
            .iter()
            .map(|car| {
                let lane = net.lane(car.lane);
                let centre = lane.path.point_at(car.offset);
                let heading = lane.path.heading_at(car.offset);
                let direction = geom::unit(heading);
                let pos = geom::add(centre, geom::scale(geom::left_normal(direction), car.lateral));
                CarState {
                    id: car.id,
                    name: car.name.clone(),
                    pos,
                    vel: geom::scale(direction, car.speed),
                    heading,
                    speed_mps: car.speed,
                    lane: Some(car.lane),
                    place: Some(net.place_of(car.lane)),
                    offset_m: car.offset,
                    length_m: car.length,
                    width_m: CAR_WIDTH_M,
                }
            })
            .collect()
    }
}
