//! Occluders: areas the UAV cannot see into (bridges, tunnels, tree rows, buildings), each a
//! polygon that hides everything under it or only what is on some roads (a bridge hides the road
//! below, not the cars on the bridge). A network carries the occluders of its file; a tracker may
//! add more ([`Occluders::with`]) read from an occluder file ([`crate::load::read_occluders`]).
//!
//! ```
//! use kpl_roads::{RoadNetwork, scenarios};
//! let net = RoadNetwork::build(&scenarios::bridge()).unwrap();
//! let main = net.road_by_name("main").unwrap().id;
//! let overpass = net.road_by_name("overpass").unwrap().id;
//! assert!(net.occluders().hiding([0.0, -1.75], Some(main)).is_some()); // under the bridge
//! assert!(net.occluders().hiding([0.0, -1.75], Some(overpass)).is_none()); // on it
//! ```

use crate::format::OccluderKind;
use crate::geom::{Point, bounds_of, point_in_polygon};
use crate::index::{Grid, GridBuilder};
use crate::network::RoadId;

/// Index of an occluder in [`Occluders::list`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub struct OccluderId(pub u32);

#[derive(Debug, Clone, PartialEq)]
pub struct Occluder {
    pub id: OccluderId,
    pub name: String,
    pub kind: OccluderKind,
    /// The hidden area (for a stretch of road: the road's width plus half a metre each side).
    pub area: Vec<Point>,
    /// Hides only what is on these roads; empty: everything under it.
    pub roads: Vec<RoadId>,
}

/// A set of occluders with a spatial grid over them.
#[derive(Debug, Clone, Default)]
pub struct Occluders {
    list: Vec<Occluder>,
    grid: Option<Grid>,
}

/// Side of a grid cell.
const CELL_M: f64 = 25.0;

impl Occluders {
    /// Indexes `list`; ids are renumbered by position.
    pub fn new(mut list: Vec<Occluder>) -> Occluders {
        list.retain(|o| o.area.len() >= 3 && o.area.iter().all(|p| p[0].is_finite() && p[1].is_finite()));
        for (i, occluder) in list.iter_mut().enumerate() {
            occluder.id = OccluderId(i as u32);
        }
        if list.is_empty() {
            return Occluders { list, grid: None };
        }
        let corners: Vec<Point> = list.iter().flat_map(|o| o.area.iter().copied()).collect();
        let (lo, hi) = bounds_of(&corners);
        let mut grid = GridBuilder::new(lo, hi, CELL_M);
        for occluder in &list {
            let (lo, hi) = bounds_of(&occluder.area);
            grid.insert_box(occluder.id.0, lo, hi);
        }
        Occluders { list, grid: Some(grid.build()) }
    }

    /// These occluders and `more`.
    pub fn with(&self, more: Vec<Occluder>) -> Occluders {
        let mut list = self.list.clone();
        list.extend(more);
        Occluders::new(list)
    }

    pub fn list(&self) -> &[Occluder] {
        &self.list
    }

    pub fn len(&self) -> usize {
        self.list.len()
    }

    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// The first occluder whose area contains `pos`, whatever it hides.
    pub fn at(&self, pos: Point) -> Option<OccluderId> {
        self.find(pos, |_| true)
    }

    /// The first occluder hiding something at `pos` on `road` (`None`: not on a known road, so
    /// only occluders that hide everything count).
    pub fn hiding(&self, pos: Point, road: Option<RoadId>) -> Option<OccluderId> {
        self.find(pos, |o| o.roads.is_empty() || road.is_some_and(|r| o.roads.contains(&r)))
    }

    fn find(&self, pos: Point, applies: impl Fn(&Occluder) -> bool) -> Option<OccluderId> {
        let grid = self.grid.as_ref()?;
        grid.at(pos)
            .iter()
            .map(|&i| &self.list[i as usize])
            .find(|o| applies(o) && point_in_polygon(pos, &o.area))
            .map(|o| o.id)
    }
}

impl std::ops::Index<OccluderId> for Occluders {
    type Output = Occluder;

    fn index(&self, id: OccluderId) -> &Occluder {
        &self.list[id.0 as usize]
    }
}
