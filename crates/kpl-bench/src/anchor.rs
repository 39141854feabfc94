//! The workload of the scale benchmark (`kpl bench anchor`, `cargo bench -p kpl-bench --bench anchor`): N cars
//! in a grid town (about 11 per 100 m block) seen by the simulated tracker at 10 Hz with 10 %
//! dropouts, noise and false positives, anchored through two link levels, vision percept ->
//! world object -> on-road object, with the paper's conditions (section V), the reestablish
//! condition of the first level also asking for similar velocities (as `specs/traffic/bridge.kpl`
//! does: in a town, crossing traffic and oncoming lanes come within 10 m), and vision percepts
//! kept for 600 ms after a missed detection (the tracker keeps their ids over 5 missed frames).
//! This module builds the spec and the driver and says what a step emits ([`spec_text`],
//! [`driver`], [`emit`]); [`run`] times it (`kpl bench anchor`).
//!
//! [`run`], for each number of cars N, on one thread: after a warm-up, each frame is timed twice,
//! producing it (the simulator and the snapshot value, the baseline) and anchoring it (one engine
//! step plus the link processes' outputs: the snapshots of both object types and the change
//! records). Reported: anchoring time per frame, per object-update (per car per frame) and its
//! ratio to the smallest N, the real-time factor (100 ms / anchoring time per frame), the ratio to
//! the baseline, and how well the cars were anchored (world-object symbol switches, coverage).
//! Times are the thread's CPU time ([`CpuClock`]): what the work costs one core, which other
//! processes on a shared machine do not change.

use std::io::Write;

use clap::Args as ClapArgs;
use kpl_core::Value;
use kpl_std::driver::IdentityScore;

use crate::BenchError;
use crate::clock::CpuClock;
use kpl_roads::scenarios::GridTownSize;

use kpl_anchor::{AnchorConfig, Anchoring, StepOutput};
use kpl_std::driver::{DriverError, SimDriver};

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
    let spec = kpl_std::check_text(&spec_text(setup))
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

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl bench anchor                         # 100 to 10,000 cars\n  kpl bench anchor --cars 5000 --seconds 30"
)]
pub struct Args {
    /// Numbers of cars to run.
    #[arg(long, value_delimiter = ',', default_values_t = [100, 300, 1000, 3000, 5000, 7000, 10000])]
    pub cars: Vec<u32>,
    /// Simulated seconds before timing starts (every car is anchored through both levels after
    /// about 3 s).
    #[arg(long, default_value_t = 5.0)]
    pub warmup: f64,
    /// Simulated seconds timed.
    #[arg(long, default_value_t = 15.0)]
    pub seconds: f64,
    /// Probability that a car is missed in a frame.
    #[arg(long, default_value_t = 0.1)]
    pub dropout: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

struct Row {
    cars: u32,
    frames: usize,
    anchor_s: f64,
    source_s: f64,
    objects: usize,
    changes: usize,
    switches: usize,
    coverage: f64,
    /// Condition progressions and, of these, candidate pairs, over the timed frames.
    condition_steps: u64,
    candidate_steps: u64,
}

/// Condition progressions and candidate-pair progressions of all links so far.
fn work(engine: &Anchoring) -> (u64, u64) {
    engine
        .link_names()
        .iter()
        .filter_map(|l| engine.link_stats(l))
        .fold((0, 0), |(c, k), s| (c + s.condition_steps, k + s.candidate_steps))
}

fn run_one(args: &Args, cars: u32) -> Result<Row, String> {
    let setup = ScaleSetup { dropout: args.dropout, seed: args.seed, ..ScaleSetup::new(cars) };
    let mut driver = driver(&setup).map_err(|e| e.to_string())?;
    let warmup = (args.warmup * 1e6) as i64;
    let end = warmup + (args.seconds * 1e6) as i64;
    let (mut anchor_s, mut source_s, mut frames, mut changes) = (0.0, 0.0, 0, 0);
    let mut score = IdentityScore::default();
    let mut work_at_warmup = None;
    loop {
        let clock = CpuClock::start();
        let Some(batch) = driver.next_frames(end) else { break };
        let t1 = clock.seconds();
        let output = driver.step(&batch).map_err(|e| e.to_string())?;
        let emitted = emit(&driver.engine, &output);
        let t2 = clock.seconds();
        std::hint::black_box(emitted);
        if batch.time >= warmup {
            work_at_warmup.get_or_insert_with(|| work(&driver.engine));
            source_s += t1;
            anchor_s += t2 - t1;
            frames += 1;
            changes += output.changes.len();
            let frames_seen =
                batch.frames.iter().map(|(i, f)| (driver.sources[*i].name.as_str(), f)).collect();
            score.record(&kpl_std::driver::DriverStep {
                time: batch.time,
                frames: frames_seen,
                output: &output,
                engine: &driver.engine,
            });
        }
    }
    let detected: u64 = score.detected.values().sum();
    let with_both: u64 =
        score.anchored.iter().filter(|((_, ty), _)| ty == "OnRoadObject").map(|(_, n)| *n).sum();
    let (c0, k0) = work_at_warmup.unwrap_or_default();
    let (c1, k1) = work(&driver.engine);
    Ok(Row {
        condition_steps: c1 - c0,
        candidate_steps: k1 - k0,
        cars,
        frames,
        anchor_s,
        source_s,
        objects: driver.engine.n_objects(),
        changes,
        switches: score.switches("WorldObject"),
        coverage: if detected == 0 { 0.0 } else { with_both as f64 / detected as f64 },
    })
}

/// Runs the benchmark and writes its table to `out`.
pub fn run(args: &Args, out: &mut dyn Write) -> Result<(), BenchError> {
    writeln!(
        out,
        "Anchoring at scale: two link levels (the paper's conditions, kpl_bench::anchor), 10 Hz, {:.0} % missed detections, {:.0} s warm-up, {:.0} s timed, one thread; times are {} (what one core spends).\n",
        args.dropout * 100.0,
        args.warmup,
        args.seconds,
        CpuClock::name()
    )?;
    writeln!(
        out,
        "| cars | frames | anchoring per frame | per object-update | per update / smallest N | real-time factor | simulator per frame (baseline) | anchoring / baseline | objects | conditions per update | candidate pairs per update | changes per frame | world-object switches | anchored through both levels |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    let mut first_per_update = None;
    let mut largest_real_time = None;
    for &cars in &args.cars {
        let row = run_one(args, cars).map_err(|e| BenchError::Failed(format!("{cars} cars: {e}")))?;
        let frames = row.frames.max(1) as f64;
        let per_frame = row.anchor_s / frames;
        let per_update = per_frame / f64::from(row.cars.max(1));
        let base = *first_per_update.get_or_insert(per_update);
        let real_time = 0.1 / per_frame;
        if real_time >= 1.0 {
            largest_real_time = Some(row.cars);
        }
        writeln!(
            out,
            "| {} | {} | {:.2} ms | {:.2} µs | {:.2} | {:.1} x | {:.2} ms | {:.1} | {} | {:.2} | {:.3} | {:.0} | {} | {:.1} % |",
            row.cars,
            row.frames,
            per_frame * 1e3,
            per_update * 1e6,
            per_update / base,
            real_time,
            row.source_s / frames * 1e3,
            row.anchor_s / row.source_s.max(1e-12),
            row.objects,
            row.condition_steps as f64 / (frames * f64::from(row.cars.max(1))),
            row.candidate_steps as f64 / (frames * f64::from(row.cars.max(1))),
            row.changes as f64 / frames,
            row.switches,
            row.coverage * 100.0,
        )?;
    }
    match largest_real_time {
        Some(n) => writeln!(out, "\nLargest N run faster than real time: {n} cars.")?,
        None => writeln!(out, "\nNo N ran faster than real time.")?,
    }
    Ok(())
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
        let mut score = IdentityScore::default();
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
