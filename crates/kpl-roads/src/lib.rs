//! Road networks for KPL: the model (junctions, roads, lanes, connections through junctions,
//! occluders), geometric queries (`on_road`, snapping to a lane with heading and lane continuity),
//! lane coordinates, prediction along the allowed connections, SVG pictures, and readers for SUMO
//! networks (`.net.xml`, `.net.xml.gz`) and the project's JSON form. Used by the simulator
//! (`kpl-sim`), anchoring (`kpl-anchor`: `anchor.snap_to_lane`, `on_road`, `along_roads`) and
//! whatever else needs to know where the roads are.
//!
//! Pure library: no clock; the only I/O is in [`load`] (reading files) and [`RoadNetwork::save`].
//! Positions are metres on a plane (x east, y north), headings radians counter-clockwise from
//! east.
//!
//! ```
//! use kpl_roads::{RoadNetwork, scenarios};
//! let net = RoadNetwork::build(&scenarios::crossing()).unwrap();
//! let on_lane = net.snap_to_lane([-50.0, -1.0], Some(0.0)).unwrap();   // eastbound on `west`
//! let ahead = net.advance(&on_lane, 80.0, 9);                          // across the crossing
//! assert_eq!(ahead.len(), 3);                                          // left, straight, right
//! ```
//!
//! Modules: [`geom`] (plane geometry), `index` (spatial grids), [`format`] (the JSON form),
//! `build` (JSON to model), [`sumo`] (SUMO to model), [`load`] (files, gzip, format detection),
//! [`network`] (the model and its queries), [`occluders`], [`predict`] (branching prediction along
//! lanes), [`scenarios`] (built-in networks), [`svg`] (pictures).

mod build;
pub mod error;
pub mod format;
pub mod geom;
mod index;
pub mod load;
pub mod network;
pub mod occluders;
pub mod predict;
pub mod scenarios;
pub mod sumo;
pub mod svg;

pub use error::{NetworkError, NetworkProblem};
pub use format::NetworkFile;
pub use network::{
    Lane, LaneId, LaneKind, LanePosition, Location, Node, NodeId, NodeKind, Place, Road, RoadId, RoadNetwork,
    SnapHint,
};
pub use occluders::{Occluder, OccluderId, Occluders};
pub use predict::Hypothesis;
