//! The workload of the scale benchmark (`kpl bench anchor`, `cargo bench -p kpl-anchor`): N cars
//! in a grid town (about 11 per 100 m block) seen by the simulated tracker at 10 Hz with 10 %
//! dropouts, noise and false positives, anchored through two link levels, vision percept ->
//! world object -> on-road object, with the paper's conditions (section V), the reestablish
//! condition of the first level also asking for similar velocities (as `specs/traffic/bridge.kpl`
//! does: in a town, crossing traffic and oncoming lanes come within 10 m), and vision percepts
//! kept for 600 ms after a missed detection (the tracker keeps their ids over 5 missed frames).
//! This module builds the spec and the driver and says what a step emits; the callers time it
//! (nothing here reads a clock).

use kpl_core::Value;
use kpl_roads::scenarios::GridTownSize;

use crate::driver::{DriverError, SimDriver};
use crate::engine::{AnchorConfig, Anchoring, StepOutput};

/// The parameters of one run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleSetup {
    pub cars: u32,
    pub seed: u64,
    /// Probability that a car is missed in a frame.
    pub dropout: f64,
    /// False positives per second per 100 cars.
    pub false_positives_per_100_cars: f64,
    /// Seconds after which an object that is not anchored is forgotten.
    pub forget_s: u32,
}

impl ScaleSetup {
    pub fn new(cars: u32) -> ScaleSetup {
        ScaleSetup { cars, seed: 1, dropout: 0.1, false_positives_per_100_cars: 0.2, forget_s: 5 }
    }
}

/// The spec of a run: two link levels with the paper's conditions.
pub fn spec_text(setup: &ScaleSetup) -> String {
    let town = GridTownSize::for_cars(setup.cars);
    let fp_rate = setup.false_positives_per_100_cars * f64::from(setup.cars) / 100.0;
    format!(
        r#"// Scale benchmark: {cars} cars, two link levels.
type VisionPercept symbol vp {{ pos: vec2, vel: vec2, size: float }}
type WorldObject   symbol wo {{ pos: vec2, vel: vec2 }}
type OnRoadObject  : WorldObject symbol oo {{ road: int, lane_offset: float }}

source tracker : list<VisionPercept> = sim.uav_tracker(scenario: "grid_town", grid_blocks_x: {bx}, grid_blocks_y: {by}, n_cars: {cars}, seed: {seed}, dropout: {dropout:?}, false_positive_rate: {fp_rate:?})

link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {{
  establish   eventually[1s, inf] true
  reestablish eventually[0, 1s] (xydist(from.pos, to.pos) < 10.0 and norm(from.vel - to.vel) < 5.0)
  maintain    true
}}
link world_onroad : WorldObject -> OnRoadObject via anchor.snap_to_lane(scenario: "grid_town") {{
  establish   eventually[1s, inf] always[0, 1s] on_road(from.pos)
  reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
  maintain    always eventually[0, 10s] always[0, 1s] on_road(from.pos)
}}
predict WorldObject  = constant_velocity
predict OnRoadObject = along_roads(scenario: "grid_town")
forget after {forget}s
forget VisionPercept after 600ms
"#,
        cars = setup.cars,
        bx = town.blocks_x,
        by = town.blocks_y,
        seed = setup.seed,
        dropout = setup.dropout,
        forget = setup.forget_s,
    )
}

/// The driver of a run: the simulated tracker and the engine, at time 0.
pub fn driver(setup: &ScaleSetup) -> Result<SimDriver, DriverError> {
    let spec = crate::registry::check_text(&spec_text(setup))
        .map_err(|e| DriverError::Source { name: "tracker".to_string(), message: e.to_string() })?;
    SimDriver::from_spec(&spec, AnchorConfig::default())
}

/// What the link processes emit after a step, as a runtime would send it: the snapshots of
/// their output types and the changes. Returns the number of items (so the work is not optimised
/// away).
pub fn emit(engine: &Anchoring, output: &StepOutput) -> usize {
    let count = |v: Option<Value>| match v {
        Some(Value::List(items)) => items.len(),
        _ => 0,
    };
    count(engine.snapshot("WorldObject"))
        + count(engine.snapshot("OnRoadObject"))
        + count(Some(output.changes_value()))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    /// A small run anchors most cars through both levels and keeps their world objects.
    #[test]
    fn a_small_run_anchors_through_two_levels() {
        let setup = ScaleSetup::new(60);
        let mut driver = driver(&setup).unwrap();
        let mut score = crate::driver::IdentityScore::default();
        let mut items = 0;
        driver
            .run_until(12_000_000, |step| {
                items += emit(step.engine, step.output);
                if step.time >= 4_000_000 {
                    score.record(&step);
                }
            })
            .unwrap();
        assert!(items > 0);
        let cars = score.detected.len();
        assert!(cars >= 50, "{cars}");
        // Almost every detected car has a world object and an on-road object.
        assert!(score.cars_with("WorldObject") * 100 >= cars * 95, "{}", score.cars_with("WorldObject"));
        assert!(score.cars_with("OnRoadObject") * 100 >= cars * 90, "{}", score.cars_with("OnRoadObject"));
    }
}
