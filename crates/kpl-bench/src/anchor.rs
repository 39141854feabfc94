//! The workload of the scale benchmark (`kpl bench anchor`, `cargo bench -p kpl-bench --bench
//! anchor`), the shipped `specs/bench/anchor_town.kpl` with N cars: cars in a grid town (about 11 per 100 m block) seen by the simulated tracker at 10 Hz with 10 %
//! dropouts, noise and false positives, anchored through two link levels, vision percept ->
//! world object -> on-road object, with the paper's conditions (section V), the reestablish
//! condition of the first level also asking for similar velocities (as `specs/traffic/bridge.kpl`
//! does: in a town, crossing traffic and oncoming lanes come within 10 m), and vision percepts
//! kept for 600 ms after a missed detection (the tracker keeps their ids over 5 missed frames).
//! This module reads the spec and builds the driver and says what a step emits ([`spec`],
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
use kpl_semantic::hir;
use kpl_std::driver::IdentityScore;

use crate::BenchError;
use crate::clock::CpuClock;
use kpl_roads::scenarios::GridTownSize;

use kpl_anchor::{AnchorConfig, Anchoring, StepOutput};
use kpl_std::driver::{DriverError, RegionalDriver, SimDriver};

/// The parameters of one run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleSetup {
    pub cars: u32,
    pub seed: u64,
    /// Probability that a car is missed in a frame.
    pub dropout: f64,
    /// False positives per second per 100 cars.
    pub false_positives_per_100_cars: f64,
}

impl ScaleSetup {
    pub fn new(cars: u32) -> ScaleSetup {
        ScaleSetup { cars, seed: 1, dropout: 0.1, false_positives_per_100_cars: 0.2 }
    }
}

/// The workload's spec as shipped (`specs/bench/anchor_town.kpl`): two link levels with the
/// paper's conditions; its tracker is set up per run by [`spec`].
pub const SPEC: &str = include_str!("../../../specs/bench/anchor_town.kpl");

/// The shipped spec, checked, with its tracker set to `setup`'s cars (and a town sized for them),
/// seed, dropout and false positives.
pub fn spec(setup: &ScaleSetup) -> Result<hir::Spec, String> {
    let mut spec = kpl_std::check_text(SPEC).map_err(|e| format!("specs/bench/anchor_town.kpl: {e}"))?;
    let town = GridTownSize::for_cars(setup.cars);
    let fp_rate = setup.false_positives_per_100_cars * f64::from(setup.cars) / 100.0;
    let call = spec
        .processes
        .iter_mut()
        .find_map(|p| match &mut p.kind {
            hir::ProcessKind::Source(call) if p.name == "tracker" => Some(call),
            _ => None,
        })
        .ok_or("specs/bench/anchor_town.kpl has no source `tracker`")?;
    for (name, value) in [
        ("n_cars", Value::Int(i64::from(setup.cars))),
        ("grid_blocks_x", Value::Int(i64::from(town.blocks_x))),
        ("grid_blocks_y", Value::Int(i64::from(town.blocks_y))),
        ("seed", Value::Int(setup.seed as i64)),
        ("dropout", Value::Float(setup.dropout)),
        ("false_positive_rate", Value::Float(fp_rate)),
    ] {
        call.params.insert(name.to_string(), value);
    }
    Ok(spec)
}

/// The driver of a run: the simulated tracker and the engine, at time 0.
pub fn driver(setup: &ScaleSetup) -> Result<SimDriver, DriverError> {
    let spec = spec(setup).map_err(|message| DriverError::Source { name: "tracker".to_string(), message })?;
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
    after_help = "Examples:\n  kpl bench anchor                         # 100 to 10,000 cars\n  kpl bench anchor --cars 5000 --seconds 30\n  kpl bench anchor --cars 10000 --regions 2x1 --workers 1,2"
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
    /// Anchoring partitioned by region over a grid of COLSxROWS cells of the town (`2x1`), one
    /// engine per region stepped on worker threads (kpl_anchor::regions); times are wall clock.
    #[arg(long, value_name = "COLSxROWS", value_parser = parse_regions)]
    pub regions: Option<(u32, u32)>,
    /// With --regions: the numbers of worker threads to run each size with.
    #[arg(long, value_delimiter = ',', requires = "regions")]
    pub workers: Vec<usize>,
    /// With --regions: how far (m) a percept may go past its region's border before it moves.
    #[arg(long, requires = "regions")]
    pub margin: Option<f64>,
}

fn parse_regions(text: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{text}`: expected COLSxROWS with both at least 1, such as `2x1`");
    let (cols, rows) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    let (cols, rows): (u32, u32) =
        (cols.trim().parse().map_err(|_| bad())?, rows.trim().parse().map_err(|_| bad())?);
    if cols == 0 || rows == 0 || cols.saturating_mul(rows) > 1024 {
        return Err(bad());
    }
    Ok((cols, rows))
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

/// One size with anchoring partitioned by region, on `workers` threads.
struct RegionalRow {
    cars: u32,
    workers: usize,
    frames: usize,
    /// Wall-clock seconds of the regions' steps (handovers included), and of making the frames.
    anchor_s: f64,
    source_s: f64,
    objects: usize,
    /// The largest region's objects over the mean (1: balanced).
    imbalance: f64,
    stats: kpl_anchor::regions::RegionStats,
    switches: usize,
    coverage: f64,
}

#[allow(clippy::disallowed_methods)] // a benchmark times its work (wall clock: several threads)
fn run_regional(
    args: &Args,
    cars: u32,
    (cols, rows): (u32, u32),
    workers: usize,
) -> Result<RegionalRow, String> {
    let setup = ScaleSetup { dropout: args.dropout, seed: args.seed, ..ScaleSetup::new(cars) };
    let spec = spec(&setup)?;
    let single = SimDriver::from_spec(&spec, AnchorConfig::default()).map_err(|e| e.to_string())?;
    let (min, max) = single.sources.first().ok_or("no tracker")?.sim.network().bounds();
    let margin = args.margin.unwrap_or(10.0);
    let grid = kpl_anchor::regions::RegionGrid { min, max, cols, rows, margin };
    let mut driver = RegionalDriver::new(single, &spec, grid, workers).map_err(|e| e.to_string())?;
    let warmup = (args.warmup * 1e6) as i64;
    let end = warmup + (args.seconds * 1e6) as i64;
    let (mut anchor_s, mut source_s, mut frames) = (0.0, 0.0, 0);
    let mut score = IdentityScore::default();
    loop {
        let start = std::time::Instant::now();
        let Some(batch) = driver.next_frames(end) else { break };
        let made = std::time::Instant::now();
        let step = driver.step(&batch).map_err(|e| e.to_string())?;
        let stepped = std::time::Instant::now();
        std::hint::black_box(&step);
        if batch.time >= warmup {
            source_s += (made - start).as_secs_f64();
            anchor_s += (stepped - made).as_secs_f64();
            frames += 1;
            let seen: Vec<_> =
                batch.frames.iter().map(|(i, f)| (driver.sources[*i].name.as_str(), f)).collect();
            score.record_with(&seen, |source, id| driver.regional.chain(source, id));
        }
    }
    let detected: u64 = score.detected.values().sum();
    let with_both: u64 =
        score.anchored.iter().filter(|((_, ty), _)| ty == "OnRoadObject").map(|(_, n)| *n).sum();
    Ok(RegionalRow {
        cars,
        workers,
        frames,
        anchor_s,
        source_s,
        objects: driver.regional.engines.iter().map(Anchoring::n_objects).sum(),
        imbalance: {
            let counts: Vec<usize> = driver.regional.engines.iter().map(Anchoring::n_objects).collect();
            let mean = counts.iter().sum::<usize>() as f64 / counts.len().max(1) as f64;
            counts.iter().copied().max().unwrap_or(0) as f64 / mean.max(1.0)
        },
        stats: driver.regional.stats,
        switches: score.switches("WorldObject"),
        coverage: if detected == 0 { 0.0 } else { with_both as f64 / detected as f64 },
    })
}

fn run_regions(args: &Args, regions: (u32, u32), out: &mut dyn Write) -> Result<(), BenchError> {
    let workers = if args.workers.is_empty() { vec![1, 2] } else { args.workers.clone() };
    writeln!(
        out,
        "Anchoring partitioned into {}x{} regions (kpl_anchor::regions, margin {} m): the workload of `kpl bench anchor`, {:.0} s warm-up, {:.0} s timed; times are wall clock (the regions step on worker threads), the frames' making excluded; speed-up against the first worker count of the same size.\n",
        regions.0,
        regions.1,
        args.margin.unwrap_or(10.0),
        args.warmup,
        args.seconds
    )?;
    writeln!(
        out,
        "| cars | workers | frames | anchoring per frame | per object-update | speed-up | real-time factor | simulator per frame | objects | largest region / mean | percepts moved | structures handed with them | drifted | refused | world-object switches | anchored through both levels |"
    )?;
    writeln!(out, "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    for &cars in &args.cars {
        let mut first = None;
        for &w in &workers {
            let row = run_regional(args, cars, regions, w)
                .map_err(|e| BenchError::Failed(format!("{cars} cars, {w} workers: {e}")))?;
            let frames = row.frames.max(1) as f64;
            let per_frame = row.anchor_s / frames;
            let base = *first.get_or_insert(per_frame);
            writeln!(
                out,
                "| {} | {} | {} | {:.2} ms | {:.2} µs | {:.2} | {:.1} x | {:.2} ms | {} | {:.2} | {} | {} | {} | {} | {} | {:.1} % |",
                row.cars,
                row.workers,
                row.frames,
                per_frame * 1e3,
                per_frame / f64::from(row.cars.max(1)) * 1e6,
                base / per_frame,
                0.1 / per_frame,
                row.source_s / frames * 1e3,
                row.objects,
                row.imbalance,
                row.stats.percepts_moved,
                row.stats.followed,
                row.stats.drifted,
                row.stats.refused,
                row.switches,
                row.coverage * 100.0,
            )?;
        }
    }
    Ok(())
}

/// Runs the benchmark and writes its table to `out`.
pub fn run(args: &Args, out: &mut dyn Write) -> Result<(), BenchError> {
    if let Some(regions) = args.regions {
        return run_regions(args, regions, out);
    }
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

    /// Anchoring partitioned by region: cars cross the border with their symbols, and the result
    /// does not depend on the number of workers.
    #[test]
    fn regions_keep_symbols_and_workers_change_nothing() {
        let args = Args {
            cars: vec![300],
            warmup: 3.0,
            seconds: 6.0,
            dropout: 0.1,
            seed: 1,
            regions: Some((2, 2)),
            workers: vec![1, 2],
            margin: Some(5.0),
        };
        let one = run_regional(&args, 300, (2, 2), 1).unwrap();
        let two = run_regional(&args, 300, (2, 2), 2).unwrap();
        assert!(one.stats.percepts_moved > 5, "{:?}", one.stats);
        assert_eq!(one.stats.refused, 0);
        assert_eq!(one.switches, 0);
        assert!(one.coverage > 0.8, "{}", one.coverage);
        assert_eq!(
            (two.stats, two.switches, two.objects, two.frames),
            (one.stats, one.switches, one.objects, one.frames)
        );
        let mut out = Vec::new();
        run(&Args { seconds: 1.0, warmup: 1.0, cars: vec![100], ..args }, &mut out).unwrap();
        let table = String::from_utf8(out).unwrap();
        assert_eq!(table.lines().filter(|l| l.starts_with("| 100 |")).count(), 2, "{table}");
    }

    #[test]
    fn region_grids_are_read_as_cols_x_rows() {
        assert_eq!(parse_regions("2x1"), Ok((2, 1)));
        assert_eq!(parse_regions("4X3"), Ok((4, 3)));
        for bad in ["2", "0x1", "x", "2x-1", "100x100", ""] {
            assert!(parse_regions(bad).is_err(), "{bad}");
        }
    }
}
