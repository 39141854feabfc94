//! The `sim.uav_tracker` source as one deterministic object: traffic (simulated, or played back
//! from a recording) plus camera and tracker, stepped one frame at a time. Time is an argument
//! (the start time) and a counter (the frame index): nothing here reads a clock, so the runtime
//! can run it in simulated or wall-clock time alike.
//!
//! ```
//! use std::sync::Arc;
//! use kpl_sim::{Params, UavTrackerSim};
//! let params = Params { scenario: "bridge".into(), seed: 7, ..Params::default() };
//! let network = Arc::new(params.load_network().unwrap());
//! let mut sim = UavTrackerSim::new(&params, network, 0).unwrap();
//! let frames = sim.frames_until(1_000_000); // one second at 10 Hz: frames at 0, 0.1 s, ..., 1 s
//! assert_eq!(frames.len(), 11);
//! assert_eq!(frames[3].time, 300_000);
//! ```

use std::path::Path;
use std::sync::Arc;

use kpl_core::Time;
use kpl_roads::{Occluder, OccluderId, Occluders, RoadNetwork};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::camera::Camera;
use crate::error::ParamsError;
use crate::image::{CameraParams, ImageObservation, ImageTracker, SharedSettings};
use crate::params::Params;
use crate::recorded::{Playback, Problem, VehicleTypes};
use crate::tracker::{Percept, Tracker, TrackerConfig, View, Visibility};
use crate::traffic::{CarState, Traffic};

/// Random streams of one seed: traffic and tracker draw from separate streams, so changing a
/// tracker parameter (noise, dropout) leaves the cars' motion unchanged.
const TRAFFIC_STREAM: u64 = 1;
const TRACKER_STREAM: u64 = 2;

/// Everything about one tracker frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// 0 for the first frame.
    pub index: u64,
    /// Valid time of the frame, microseconds.
    pub time: Time,
    pub percepts: Vec<Percept>,
    /// Ground truth: every car on the map, seen or not.
    pub cars: Vec<CarState>,
    /// What the camera could see of each car (in the order of `cars`).
    pub visibility: Vec<Visibility>,
    /// In camera mode ([`UavTrackerSim::with_camera`]): the boxes in pixels and the pose (then
    /// `percepts` is empty).
    pub image: Option<ImageObservation>,
}

/// What looks at the vehicles: the world tracker (percepts in metres), or the UAV camera and its
/// image tracker (boxes in pixels).
#[derive(Debug)]
enum Observer {
    World(Tracker),
    Camera(Box<ImageTracker>),
}

/// Where the cars come from.
#[derive(Debug)]
enum Vehicles {
    Simulated(Traffic),
    Recorded(Box<Playback>),
}

/// A running simulation of cars on a road network watched by a UAV tracker.
#[derive(Debug)]
pub struct UavTrackerSim {
    network: Arc<RoadNetwork>,
    vehicles: Vehicles,
    observer: Observer,
    camera: Camera,
    occluders: Occluders,
    start: Time,
    period_us: Time,
    next_index: u64,
}

fn rng_stream(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

impl UavTrackerSim {
    /// A simulation whose first frame is at `start`; later frames follow every `1 / rate_hz`.
    /// Reads `traffic_file`, `vtypes_file` and `occluders_file` when set (paths as given).
    pub fn new(
        params: &Params,
        network: Arc<RoadNetwork>,
        start: Time,
    ) -> Result<UavTrackerSim, ParamsError> {
        UavTrackerSim::with_traffic_seed(params, network, start, params.seed)
    }

    /// [`UavTrackerSim::new`] with simulated traffic drawn from `traffic_seed` instead of
    /// `params.seed` (the tracker still draws from `params.seed`): trackers given the same
    /// traffic seed watch the same cars with noise of their own.
    pub fn with_traffic_seed(
        params: &Params,
        network: Arc<RoadNetwork>,
        start: Time,
        traffic_seed: u64,
    ) -> Result<UavTrackerSim, ParamsError> {
        let tracker =
            Tracker::new(TrackerConfig::from_params(params), rng_stream(params.seed, TRACKER_STREAM));
        UavTrackerSim::build(params, network, start, traffic_seed, Observer::World(tracker))
    }

    /// The camera mode: the same traffic watched by a UAV camera whose image tracker reports
    /// boxes in pixels ([`crate::image`]); `params` gives the traffic, the seed, the rate, the
    /// occluders and what the world tracker shares (`dropout`, `max_gap_frames`,
    /// `false_positive_rate`, `false_positive_on_road`, `false_positive_duration_s`).
    pub fn with_camera(
        params: &Params,
        camera: &CameraParams,
        network: Arc<RoadNetwork>,
        start: Time,
        traffic_seed: u64,
    ) -> Result<UavTrackerSim, ParamsError> {
        let shared = SharedSettings {
            dropout: params.dropout,
            max_gap_frames: params.max_gap_frames,
            false_positive_rate: params.false_positive_rate,
            false_positive_on_road: params.false_positive_on_road,
            false_positive_duration_s: params.false_positive_duration_s,
        };
        let tracker =
            ImageTracker::new(camera.clone(), shared, &network, rng_stream(params.seed, TRACKER_STREAM))?;
        UavTrackerSim::build(params, network, start, traffic_seed, Observer::Camera(Box::new(tracker)))
    }

    fn build(
        params: &Params,
        network: Arc<RoadNetwork>,
        start: Time,
        traffic_seed: u64,
        observer: Observer,
    ) -> Result<UavTrackerSim, ParamsError> {
        params.validate()?;
        let vehicles = match &params.traffic_file {
            Some(file) => {
                let types = match &params.vtypes_file {
                    Some(types) => VehicleTypes::read(Path::new(types))?,
                    None => VehicleTypes::builtin(),
                };
                Vehicles::Recorded(Box::new(Playback::open(Path::new(file), types, network.clone())?))
            }
            None => Vehicles::Simulated(Traffic::new(
                &network,
                params.n_cars,
                params.speed_sd,
                rng_stream(traffic_seed, TRAFFIC_STREAM),
            )?),
        };
        let mut extra: Vec<Occluder> = params
            .occluders
            .iter()
            .enumerate()
            .map(|(i, polygon)| Occluder {
                id: OccluderId(0),
                name: format!("occluders[{i}]"),
                kind: kpl_roads::format::OccluderKind::Other,
                area: polygon.clone(),
                roads: Vec::new(),
            })
            .collect();
        if let Some(file) = &params.occluders_file {
            extra.extend(kpl_roads::load::read_occluders(Path::new(file), &network)?);
        }
        if let Some(bad) =
            extra.iter().find(|o| o.area.len() < 3 || o.area.iter().flatten().any(|c| !c.is_finite()))
        {
            return Err(ParamsError::OutOfRange {
                name: "occluders",
                expected: "polygons of at least 3 corners [x, y] with finite coordinates",
                found: bad.name.clone(),
            });
        }
        let occluders = network.occluders().with(extra);
        Ok(UavTrackerSim {
            network,
            vehicles,
            observer,
            camera: params.camera()?,
            occluders,
            start,
            period_us: params.period_us(),
            next_index: 0,
        })
    }

    /// The occluders the tracker uses: the network's and those of the parameters.
    pub fn occluders(&self) -> &Occluders {
        &self.occluders
    }

    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Whether the recorded traffic has ended (never, for simulated traffic): there will be no
    /// more vehicles.
    pub fn finished(&self) -> bool {
        match &self.vehicles {
            Vehicles::Simulated(_) => false,
            Vehicles::Recorded(playback) => playback.finished(self.elapsed(self.next_index)),
        }
    }

    /// Problems found in the recording since the last call (each skipped).
    pub fn take_problems(&mut self) -> Vec<Problem> {
        match &mut self.vehicles {
            Vehicles::Simulated(_) => Vec::new(),
            Vehicles::Recorded(playback) => playback.take_problems(),
        }
    }

    fn elapsed(&self, index: u64) -> Time {
        i64::try_from(index).unwrap_or(i64::MAX).saturating_mul(self.period_us)
    }

    pub fn network(&self) -> &Arc<RoadNetwork> {
        &self.network
    }

    /// Time between frames, microseconds.
    pub fn period_us(&self) -> Time {
        self.period_us
    }

    /// The tracker's footprint in world coordinates at a frame's valid time `time` (`None`: it
    /// sees the whole network).
    pub fn footprint_at(&self, time: Time) -> Option<Vec<kpl_roads::geom::Point>> {
        self.camera.footprint_at(time.saturating_sub(self.start))
    }

    /// The valid time of the frame [`UavTrackerSim::next_frame`] will return.
    pub fn next_frame_time(&self) -> Time {
        self.start.saturating_add(self.elapsed(self.next_index))
    }

    /// Produces the next frame: moves the cars by one period (except before the first frame), or
    /// takes the recorded ones at the frame's time, and lets the tracker look at them.
    pub fn next_frame(&mut self) -> Frame {
        let dt_s = self.period_us as f64 / 1e6;
        let elapsed = self.elapsed(self.next_index);
        let cars = match &mut self.vehicles {
            Vehicles::Simulated(traffic) => {
                if self.next_index > 0 {
                    let left_map = traffic.step(&self.network, dt_s);
                    self.observer.forget(&left_map);
                }
                traffic.states(&self.network)
            }
            Vehicles::Recorded(playback) => {
                let (cars, gone) = playback.states_at(elapsed);
                self.observer.forget(&gone);
                cars
            }
        };
        let time = self.next_frame_time();
        let (percepts, visibility, image) = match &mut self.observer {
            Observer::World(tracker) => {
                let view = View { camera: &self.camera, occluders: &self.occluders, elapsed };
                let (percepts, visibility) = tracker.observe(&self.network, &view, &cars, dt_s);
                (percepts, visibility, None)
            }
            Observer::Camera(tracker) => {
                let (image, visibility) =
                    tracker.observe(&self.network, &cars, &self.occluders, elapsed, dt_s);
                (Vec::new(), visibility, Some(image))
            }
        };
        let frame = Frame { index: self.next_index, time, percepts, cars, visibility, image };
        self.next_index += 1;
        frame
    }

    /// All frames with valid time at or before `until` that were not produced yet (up to the end
    /// of recorded traffic).
    pub fn frames_until(&mut self, until: Time) -> Vec<Frame> {
        let mut frames = Vec::new();
        while self.next_frame_time() <= until && self.next_frame_time() < Time::MAX && !self.finished() {
            frames.push(self.next_frame());
        }
        frames
    }

    /// Percept ids handed out so far (the last one is `vp{n}`).
    pub fn n_percept_ids(&self) -> u64 {
        match &self.observer {
            Observer::World(tracker) => tracker.n_percept_ids(),
            Observer::Camera(tracker) => tracker.n_percept_ids(),
        }
    }

    /// The UAV camera's image tracker, in camera mode.
    pub fn image_tracker(&self) -> Option<&ImageTracker> {
        match &self.observer {
            Observer::World(_) => None,
            Observer::Camera(tracker) => Some(tracker),
        }
    }
}

impl Observer {
    fn forget(&mut self, cars: &[crate::traffic::CarId]) {
        match self {
            Observer::World(tracker) => tracker.forget(cars),
            Observer::Camera(tracker) => tracker.forget(cars),
        }
    }
}
