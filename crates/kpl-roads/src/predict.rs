//! Prediction along the road network: where can something on a lane be after travelling a given
//! distance? One hypothesis per allowed branch taken at every junction on the way (the network's
//! connections, U-turns excepted), each with its route, which is what the on-road prediction model
//! of anchoring needs while a car is not seen (the paper's "travel along the road network,
//! splitting into multiple objects at crossings"). A route that reaches a lane nothing continues
//! (a dead end, the network's border) stops there.
//!
//! ```
//! use kpl_roads::{RoadNetwork, scenarios};
//! let net = RoadNetwork::build(&scenarios::crossing()).unwrap();
//! let start = net.snap_to_lane([-20.0, -1.75], Some(0.0)).unwrap(); // eastbound, before the crossing
//! let hypotheses = net.advance(&start, 60.0, 16);
//! assert_eq!(hypotheses.len(), 3); // left, straight on, right
//! ```

use crate::network::{LaneId, LanePosition, RoadNetwork};

/// One way the travel may have gone.
#[derive(Debug, Clone, PartialEq)]
pub struct Hypothesis {
    /// Where it ends.
    pub position: LanePosition,
    /// The lanes passed through, the start lane first and the end lane last.
    pub route: Vec<LaneId>,
    /// Distance travelled, equal to the requested distance unless the route reached a dead end.
    pub travelled_m: f64,
    /// The route reached a lane nothing continues (a dead end or the map's border): it stops at
    /// the end of that lane, having travelled less than asked.
    pub reached_end: bool,
}

impl RoadNetwork {
    /// Advances `from` along its lane by `distance_m` (negative or NaN counts as 0), branching
    /// into every onward lane ([`RoadNetwork::onward`]) at the end of a lane. Returns at most `max_hypotheses`
    /// hypotheses; when there are more, the ones found first in a depth-first walk that takes
    /// successors in lane order are kept. The order of the result is deterministic. A position
    /// whose lane is not in this network gives no hypotheses.
    pub fn advance(&self, from: &LanePosition, distance_m: f64, max_hypotheses: usize) -> Vec<Hypothesis> {
        if from.lane.0 as usize >= self.lanes().len() {
            return Vec::new();
        }
        let distance_m = if distance_m.is_nan() { 0.0 } else { distance_m.max(0.0) };
        let mut result = Vec::new();
        // (lane, offset on it, distance still to go, route so far)
        let mut stack: Vec<(LaneId, f64, f64, Vec<LaneId>)> =
            vec![(from.lane, from.offset_m, distance_m, vec![from.lane])];
        while let Some((lane_id, offset, remaining, route)) = stack.pop() {
            if result.len() >= max_hypotheses {
                break;
            }
            let lane = self.lane(lane_id);
            let left_on_lane = (lane.path.length() - offset).max(0.0);
            if remaining <= left_on_lane {
                result.push(Hypothesis {
                    position: self.lane_position(lane_id, offset + remaining),
                    route,
                    travelled_m: distance_m,
                    reached_end: false,
                });
                continue;
            }
            let onward: Vec<LaneId> = self.onward(lane_id).collect();
            if onward.is_empty() {
                result.push(Hypothesis {
                    position: self.lane_position(lane_id, lane.path.length()),
                    route,
                    travelled_m: distance_m - (remaining - left_on_lane),
                    reached_end: true,
                });
                continue;
            }
            // Push in reverse so that the first successor is explored first.
            for &next in onward.iter().rev() {
                let mut next_route = route.clone();
                next_route.push(next);
                stack.push((next, 0.0, remaining - left_on_lane, next_route));
            }
        }
        result
    }
}
