//! The simulated UAV object tracker: turns the true car states of one frame into vision percepts
//! as an image-based tracker would report them. Positions, velocities and sizes are noisy; a car
//! is missed with the dropout probability; a car outside the camera's footprint or hidden by an
//! occluder (under a bridge, in a tunnel, behind trees) is not seen and gets a new percept id
//! when it reappears, as does a car whose track was missing for more than `max_gap_frames`
//! frames; short-lived false positives appear on and off the roads inside the footprint. Percept
//! ids (`vp1`, `vp2`, ...) are never reused, and each percept carries what it really was.

use std::collections::HashMap;
use std::fmt;
use std::sync::Arc;

use kpl_core::{Record, Time, Value};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Geometric, Poisson, StandardNormal};

use crate::params::Params;
use crate::traffic::{CarId, CarState};
use kpl_roads::geom::Point;
use kpl_roads::{Occluders, RoadNetwork};

use crate::camera::Camera;

/// A percept's identity; shown as `vp1`, `vp2`, ... and never reused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PerceptId(pub u64);

impl fmt::Display for PerceptId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "vp{}", self.0)
    }
}

/// What a percept really was, for scoring anchoring.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PerceptSource {
    Car(CarId),
    FalsePositive,
}

/// One vision percept of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Percept {
    pub id: PerceptId,
    /// Estimated position, metres.
    pub pos: Point,
    /// Estimated velocity, m/s.
    pub vel: Point,
    /// Longest extent of the blob, metres.
    pub size_m: f64,
    /// Ground truth: not part of what the tracker reports.
    pub source: PerceptSource,
}

/// The fields of a vision percept record, in order, as [`Percept::to_record`] builds it.
pub const PERCEPT_FIELDS: [(&str, kpl_core::ValueType); 3] = [
    ("pos", kpl_core::ValueType::Vec2),
    ("vel", kpl_core::ValueType::Vec2),
    ("size", kpl_core::ValueType::Float),
];

impl Percept {
    /// The percept as the record a `VisionPercept { pos: vec2, vel: vec2, size: float }` sample
    /// carries: `id` `vpN`, fields `pos`, `vel`, `size`. The ground truth is left out.
    pub fn to_record(&self) -> Record {
        self.to_record_prefixed("vp")
    }

    /// The record with the id `{prefix}N` instead of `vpN` (a tracker's `percept_prefix`).
    pub fn to_record_prefixed(&self, prefix: &str) -> Record {
        Record {
            id: Some(format!("{prefix}{}", self.id.0).into()),
            fields: vec![
                ("pos".into(), Value::Vec2(self.pos)),
                ("vel".into(), Value::Vec2(self.vel)),
                ("size".into(), Value::Float(self.size_m)),
            ],
        }
    }

    pub fn to_value(&self) -> Value {
        Value::Record(Arc::new(self.to_record()))
    }
}

/// The tracker's settings, taken from [`Params`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerConfig {
    pub noise_m: f64,
    pub vel_noise_mps: f64,
    pub size_noise_m: f64,
    pub dropout: f64,
    pub max_gap_frames: u32,
    pub false_positive_rate: f64,
    pub false_positive_on_road: f64,
    pub false_positive_duration_s: f64,
}

impl TrackerConfig {
    pub fn from_params(params: &Params) -> TrackerConfig {
        TrackerConfig {
            noise_m: params.noise_m,
            vel_noise_mps: params.vel_noise_mps,
            size_noise_m: params.size_noise_m,
            dropout: params.dropout,
            max_gap_frames: params.max_gap_frames,
            false_positive_rate: params.false_positive_rate,
            false_positive_on_road: params.false_positive_on_road,
            false_positive_duration_s: params.false_positive_duration_s,
        }
    }
}

#[derive(Debug, Clone, Default)]
struct Track {
    percept: Option<PerceptId>,
    /// Frames in a row the car was visible but not detected.
    missed: u32,
    /// The car was hidden (by an occluder, or outside the footprint) since it was last detected.
    hidden: bool,
}

/// What the camera could see of a car in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Visibility {
    /// Detected: a percept shows it.
    Detected,
    /// In view but missed (a dropout).
    Missed,
    /// In the footprint but under an occluder.
    Occluded,
    /// Outside the camera's footprint.
    OutOfView,
}

impl Visibility {
    /// Whether the tracker could have seen it (detected or missed).
    pub fn in_view(self) -> bool {
        matches!(self, Visibility::Detected | Visibility::Missed)
    }
}

/// Where the camera looks in one frame and what hides things from it.
#[derive(Debug, Clone, Copy)]
pub struct View<'a> {
    pub camera: &'a Camera,
    pub occluders: &'a Occluders,
    /// Microseconds since the start (for a moving camera).
    pub elapsed: Time,
}

#[derive(Debug, Clone)]
struct FalsePositive {
    id: PerceptId,
    pos: Point,
    size_m: f64,
    frames_left: u64,
}

/// Tracker state between frames.
#[derive(Debug, Clone)]
pub struct Tracker {
    config: TrackerConfig,
    rng: ChaCha8Rng,
    next_percept: u64,
    tracks: HashMap<CarId, Track>,
    false_positives: Vec<FalsePositive>,
}

/// Bounded tries to find a point for a false positive (off the road, or in the footprint).
const OFF_ROAD_TRIES: usize = 20;

impl Tracker {
    pub fn new(config: TrackerConfig, rng: ChaCha8Rng) -> Tracker {
        Tracker { config, rng, next_percept: 1, tracks: HashMap::new(), false_positives: Vec::new() }
    }

    fn new_percept_id(&mut self) -> PerceptId {
        let id = PerceptId(self.next_percept);
        self.next_percept += 1;
        id
    }

    fn gaussian(&mut self, sd: f64) -> f64 {
        if sd == 0.0 {
            return 0.0;
        }
        let z: f64 = self.rng.sample(StandardNormal);
        z * sd
    }

    fn noisy(&mut self, p: Point, sd: f64) -> Point {
        [p[0] + self.gaussian(sd), p[1] + self.gaussian(sd)]
    }

    /// Forgets the tracks of cars that left the map.
    pub fn forget(&mut self, cars: &[CarId]) {
        for car in cars {
            self.tracks.remove(car);
        }
    }

    /// The percepts of one frame, `dt_s` seconds after the previous one: cars first (in the order
    /// given), then false positives; and what the camera could see of each car.
    pub fn observe(
        &mut self,
        net: &RoadNetwork,
        view: &View<'_>,
        cars: &[CarState],
        dt_s: f64,
    ) -> (Vec<Percept>, Vec<Visibility>) {
        let mut percepts = Vec::with_capacity(cars.len() + self.false_positives.len());
        let mut visibility = Vec::with_capacity(cars.len());
        for car in cars {
            let seen = if !view.camera.sees(car.pos, view.elapsed) {
                Visibility::OutOfView
            } else if view.occluders.hiding(car.pos, car.road()).is_some() {
                Visibility::Occluded
            } else {
                Visibility::Detected
            };
            let mut track = self.tracks.remove(&car.id).unwrap_or_default();
            let seen = if seen != Visibility::Detected {
                track.hidden = true;
                seen
            } else if self.config.dropout > 0.0 && self.rng.random::<f64>() < self.config.dropout {
                track.missed = track.missed.saturating_add(1);
                Visibility::Missed
            } else {
                let percept = match track.percept {
                    Some(id) if !track.hidden && track.missed <= self.config.max_gap_frames => id,
                    _ => self.new_percept_id(),
                };
                track = Track { percept: Some(percept), missed: 0, hidden: false };
                let pos = self.noisy(car.pos, self.config.noise_m);
                let vel = self.noisy(car.vel, self.config.vel_noise_mps);
                let size_m = (car.length_m + self.gaussian(self.config.size_noise_m)).max(0.1);
                percepts.push(Percept { id: percept, pos, vel, size_m, source: PerceptSource::Car(car.id) });
                Visibility::Detected
            };
            visibility.push(seen);
            self.tracks.insert(car.id, track);
        }
        self.false_positives_frame(net, view, dt_s, &mut percepts);
        (percepts, visibility)
    }

    fn false_positives_frame(
        &mut self,
        net: &RoadNetwork,
        view: &View<'_>,
        dt_s: f64,
        percepts: &mut Vec<Percept>,
    ) {
        self.false_positives.retain_mut(|fp| {
            fp.frames_left -= 1;
            fp.frames_left > 0
        });
        let n_new = poisson_count(&mut self.rng, self.config.false_positive_rate * dt_s);
        let mean_frames = (self.config.false_positive_duration_s / dt_s).max(1.0);
        for _ in 0..n_new {
            let on_road = self.rng.random::<f64>() < self.config.false_positive_on_road;
            let pos = if on_road { self.on_road_point(net, view) } else { self.off_road_point(net, view) };
            let Some(pos) = pos else { continue };
            // Frames alive: 1 + a geometric number, so the mean is `mean_frames`.
            let extra = Geometric::new(1.0 / mean_frames).map_or(0, |g| self.rng.sample(g));
            let id = self.new_percept_id();
            let size_m = self.rng.random_range(0.5..6.0);
            self.false_positives.push(FalsePositive { id, pos, size_m, frames_left: 1 + extra });
        }
        for i in 0..self.false_positives.len() {
            let fp = self.false_positives[i].clone();
            let pos = self.noisy(fp.pos, self.config.noise_m);
            let vel = self.noisy([0.0, 0.0], self.config.vel_noise_mps);
            let size_m = (fp.size_m + self.gaussian(self.config.size_noise_m)).max(0.1);
            percepts.push(Percept { id: fp.id, pos, vel, size_m, source: PerceptSource::FalsePositive });
        }
    }

    /// A random point of a road lane that the camera sees.
    fn on_road_point(&mut self, net: &RoadNetwork, view: &View<'_>) -> Option<Point> {
        let tries = if matches!(view.camera, Camera::Everything) { 1 } else { OFF_ROAD_TRIES };
        for _ in 0..tries {
            let u: f64 = self.rng.random();
            let p = net.road_lane_position_at_fraction(u)?.point;
            if view.camera.sees(p, view.elapsed) {
                return Some(p);
            }
        }
        None
    }

    /// A random point off the roads that the camera sees.
    fn off_road_point(&mut self, net: &RoadNetwork, view: &View<'_>) -> Option<Point> {
        let (mut lo, mut hi) = net.bounds();
        if let Some((flo, fhi)) = view.camera.bounds_at(view.elapsed) {
            lo = [lo[0].max(flo[0]), lo[1].max(flo[1])];
            hi = [hi[0].min(fhi[0]), hi[1].min(fhi[1])];
            if lo[0] > hi[0] || lo[1] > hi[1] {
                return None;
            }
        }
        for _ in 0..OFF_ROAD_TRIES {
            let p = [self.rng.random_range(lo[0]..=hi[0]), self.rng.random_range(lo[1]..=hi[1])];
            if !net.on_road(p) && view.camera.sees(p, view.elapsed) {
                return Some(p);
            }
        }
        None
    }

    /// Percept ids handed out so far.
    pub fn n_percept_ids(&self) -> u64 {
        self.next_percept - 1
    }
}

/// How many of something with Poisson mean `expected` happen (none when `expected` is not
/// positive): new false positives per frame, in both tracker modes.
pub(crate) fn poisson_count(rng: &mut ChaCha8Rng, expected: f64) -> u64 {
    match Poisson::new(expected) {
        Ok(poisson) if expected > 0.0 => {
            let n: f64 = rng.sample(poisson);
            n as u64
        }
        _ => 0,
    }
}
