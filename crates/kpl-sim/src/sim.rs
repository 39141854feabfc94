//! The `sim.uav_tracker` source as one deterministic object: traffic plus tracker, stepped one
//! frame at a time. Time is an argument (the start time) and a counter (the frame index): nothing
//! here reads a clock, so the runtime can run it in simulated or wall-clock time alike.
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

use std::sync::Arc;

use kpl_core::Time;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::error::ParamsError;
use crate::params::Params;
use crate::tracker::{Percept, Tracker, TrackerConfig};
use crate::traffic::{CarState, Traffic};
use kpl_roads::RoadNetwork;

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
}

/// A running simulation of cars on a road network watched by a UAV tracker.
#[derive(Debug, Clone)]
pub struct UavTrackerSim {
    network: Arc<RoadNetwork>,
    traffic: Traffic,
    tracker: Tracker,
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
    pub fn new(
        params: &Params,
        network: Arc<RoadNetwork>,
        start: Time,
    ) -> Result<UavTrackerSim, ParamsError> {
        params.validate()?;
        let traffic =
            Traffic::new(&network, params.n_cars, params.speed_sd, rng_stream(params.seed, TRAFFIC_STREAM))?;
        let tracker =
            Tracker::new(TrackerConfig::from_params(params), rng_stream(params.seed, TRACKER_STREAM));
        Ok(UavTrackerSim { network, traffic, tracker, start, period_us: params.period_us(), next_index: 0 })
    }

    pub fn network(&self) -> &Arc<RoadNetwork> {
        &self.network
    }

    /// Time between frames, microseconds.
    pub fn period_us(&self) -> Time {
        self.period_us
    }

    /// The valid time of the frame [`UavTrackerSim::next_frame`] will return.
    pub fn next_frame_time(&self) -> Time {
        let offset = i64::try_from(self.next_index).unwrap_or(i64::MAX).saturating_mul(self.period_us);
        self.start.saturating_add(offset)
    }

    /// Produces the next frame: moves the cars by one period (except before the first frame) and
    /// lets the tracker look at them.
    pub fn next_frame(&mut self) -> Frame {
        let dt_s = self.period_us as f64 / 1e6;
        if self.next_index > 0 {
            let left_map = self.traffic.step(&self.network, dt_s);
            self.tracker.forget(&left_map);
        }
        let time = self.next_frame_time();
        let cars = self.traffic.states(&self.network);
        let percepts = self.tracker.observe(&self.network, &cars, dt_s);
        let frame = Frame { index: self.next_index, time, percepts, cars };
        self.next_index += 1;
        frame
    }

    /// All frames with valid time at or before `until` that were not produced yet.
    pub fn frames_until(&mut self, until: Time) -> Vec<Frame> {
        let mut frames = Vec::new();
        while self.next_frame_time() <= until && self.next_frame_time() < Time::MAX {
            frames.push(self.next_frame());
        }
        frames
    }

    /// Percept ids handed out so far (the last one is `vp{n}`).
    pub fn n_percept_ids(&self) -> u64 {
        self.tracker.n_percept_ids()
    }
}
