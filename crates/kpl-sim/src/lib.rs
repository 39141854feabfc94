//! A simulated UAV traffic-monitoring world for KPL: a road network (roads with lanes, crossings,
//! bridges and tunnels) with fast geometry queries, cars driving through it, and a simulated
//! object tracker that reports noisy vision percepts with tracker ids, the input of DyKnow-style
//! hierarchical anchoring (percept -> world object -> on-road object -> car).
//!
//! Pure library: no clock and no I/O except the explicit `load`/`save` functions and
//! [`Params::load_network`] when a network file is named. For a given seed everything is
//! deterministic (ChaCha random streams).
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
//! Modules: [`geom`] (plane geometry), `index` (spatial grids), [`format`] (the JSON file form),
//! [`network`] (checked network and queries), [`predict`] (branching prediction along lanes),
//! [`scenarios`] (built-in networks), [`traffic`] (cars and ground truth), [`tracker`] (percepts),
//! [`params`] (source parameters), [`sim`] (the source object), [`svg`] (pictures).

pub mod camera;
pub mod error;
pub mod params;
pub mod recorded;
pub mod sim;
pub mod tracker;
pub mod traffic;

pub use error::ParamsError;
pub use kpl_roads::{LaneId, LanePosition, NetworkError, NodeId, OccluderId, Place, RoadId, RoadNetwork};
pub use params::{ParamInfo, Params};
pub use sim::{Frame, UavTrackerSim};
pub use tracker::{Percept, PerceptId, PerceptSource, Visibility};
pub use traffic::{CarId, CarState};
