//! `kpl bench anchor`: hierarchical anchoring at scale. Figures go to `docs/performance.md`.
//!
//! For each number of cars N, the workload of `kpl_anchor::scale`: N cars in a grid town seen by
//! the simulated tracker at 10 Hz (10 % missed detections, noise, false positives), anchored
//! through two link levels (vision percept -> world object -> on-road object) with the DyKnow
//! paper's conditions (the first level's reestablish also compares velocities), on one thread. After a warm-up, each frame is timed twice: producing it
//! (the simulator and the snapshot value, the baseline) and anchoring it (one engine step plus
//! the link processes' outputs: the snapshots of both object types and the change records).
//! Reported: anchoring time per frame, per object-update (per car per frame) and its ratio to the
//! smallest N, the real-time factor (100 ms / anchoring time per frame), the ratio to the
//! baseline, and how well the cars were anchored (world-object symbol switches, coverage). Times
//! are the thread's CPU time (`CpuClock`): what the work costs one core, which other processes on
//! a shared machine do not change.

use std::process::ExitCode;

use clap::Args as ClapArgs;
use kpl_anchor::driver::IdentityScore;
use kpl_anchor::scale::{self, ScaleSetup};

use crate::cmd::bench::CpuClock;

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
fn work(engine: &kpl_anchor::Anchoring) -> (u64, u64) {
    engine
        .link_names()
        .iter()
        .filter_map(|l| engine.link_stats(l))
        .fold((0, 0), |(c, k), s| (c + s.condition_steps, k + s.candidate_steps))
}

fn run_one(args: &Args, cars: u32) -> Result<Row, String> {
    let setup = ScaleSetup { dropout: args.dropout, seed: args.seed, ..ScaleSetup::new(cars) };
    let mut driver = scale::driver(&setup).map_err(|e| e.to_string())?;
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
        let emitted = scale::emit(&driver.engine, &output);
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
            score.record(&kpl_anchor::driver::DriverStep {
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

pub fn run(args: Args) -> ExitCode {
    println!(
        "Anchoring at scale: two link levels (the paper's conditions, kpl_anchor::scale), 10 Hz, {:.0} % missed detections, {:.0} s warm-up, {:.0} s timed, one thread; times are {} (what one core spends).\n",
        args.dropout * 100.0,
        args.warmup,
        args.seconds,
        CpuClock::name()
    );
    println!(
        "| cars | frames | anchoring per frame | per object-update | per update / smallest N | real-time factor | simulator per frame (baseline) | anchoring / baseline | objects | conditions per update | candidate pairs per update | changes per frame | world-object switches | anchored through both levels |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut first_per_update = None;
    let mut largest_real_time = None;
    for &cars in &args.cars {
        let row = match run_one(&args, cars) {
            Ok(row) => row,
            Err(e) => {
                eprintln!("error: {cars} cars: {e}");
                return ExitCode::from(1);
            }
        };
        let frames = row.frames.max(1) as f64;
        let per_frame = row.anchor_s / frames;
        let per_update = per_frame / f64::from(row.cars.max(1));
        let base = *first_per_update.get_or_insert(per_update);
        let real_time = 0.1 / per_frame;
        if real_time >= 1.0 {
            largest_real_time = Some(row.cars);
        }
        println!(
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
        );
    }
    match largest_real_time {
        Some(n) => println!("\nLargest N run faster than real time: {n} cars."),
        None => println!("\nNo N ran faster than real time."),
    }
    ExitCode::SUCCESS
}
