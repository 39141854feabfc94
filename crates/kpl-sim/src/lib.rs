//! A simulated UAV traffic-monitoring world for KPL: cars on a road network (`kpl-roads`), either
//! simulated or played back from a recording (SUMO FCD, JSON lines, CSV), a camera footprint and
//! occluders, and a simulated object tracker that reports noisy vision percepts with tracker ids,
//! the input of DyKnow-style hierarchical anchoring (percept -> world object -> on-road object ->
//! car), with the ground truth beside them.
//!
//! Pure library: no clock; the only I/O is reading the files the parameters name (road network,
//! recorded traffic, vehicle types, occluders). For a given seed everything is deterministic
//! (ChaCha random streams).
//!
//! ```
//! use std::sync::Arc;
//! use kpl_sim::{Params, UavTrackerSim};
//! let params = Params { scenario: "crossing".into(), seed: 3, n_cars: 5, ..Params::default() };
//! let network = Arc::new(params.load_network().unwrap());
//! let mut sim = UavTrackerSim::new(&params, network.clone(), 0).unwrap();
//! let frame = sim.next_frame();
//! for percept in &frame.percepts {
//!     let record = percept.to_value(); // { id: "vp1", pos: [x, y], vel: [vx, vy], size: 4.4 }
//!     let on_road = network.on_road(percept.pos);
//!     # let _ = (record, on_road);
//! }
//! ```
//!
//! Modules: [`traffic`] (simulated cars and ground truth), [`recorded`] (recorded traffic played
//! back), [`camera`] (the footprint), [`tracker`] (percepts), [`image`] (the camera mode: a UAV
//! camera and an image tracker reporting boxes in pixels), [`params`] (source parameters),
//! [`sim`] (the source object), [`error`].

pub mod camera;
pub mod error;
pub mod image;
pub mod params;
pub mod recorded;
pub mod sim;
pub mod tracker;
pub mod traffic;

pub use error::ParamsError;
pub use image::{CameraParams, ImageObservation, ImagePercept, ImageTracker};
pub use kpl_roads::{LaneId, LanePosition, NetworkError, NodeId, OccluderId, Place, RoadId, RoadNetwork};
pub use params::{ParamInfo, Params};
pub use sim::{Frame, UavTrackerSim};
pub use tracker::{Percept, PerceptId, PerceptSource, Visibility};
pub use traffic::{CarId, CarState};
