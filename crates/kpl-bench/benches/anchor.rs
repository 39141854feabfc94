//! Criterion benchmark of one anchoring step (one tracker frame through two link levels, with the
//! link outputs built), per car, at 100 and 1,000 cars: the workload of `kpl_bench::anchor`,
//! after 5 s of warm-up, frames produced outside the timing. `kpl bench anchor` runs the same
//! workload up to 10,000 cars and reports the real-time factor (docs/performance.md).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::disallowed_methods)] // a benchmark fails loudly, and times work with the wall clock

use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use kpl_bench::anchor::{self as scale, ScaleSetup};

fn anchor_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("anchor step");
    group.sample_size(20).measurement_time(Duration::from_secs(10));
    for cars in [100u32, 1000] {
        let mut driver = scale::driver(&ScaleSetup::new(cars)).unwrap();
        while let Some(frames) = driver.next_frames(5_000_000) {
            driver.step(&frames).unwrap();
        }
        group.throughput(Throughput::Elements(u64::from(cars)));
        group.bench_with_input(BenchmarkId::from_parameter(cars), &cars, |b, _| {
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let frames = driver.next_frames(i64::MAX).unwrap();
                    let start = Instant::now();
                    let output = driver.step(&frames).unwrap();
                    std::hint::black_box(scale::emit(&driver.engine, &output));
                    total += start.elapsed();
                }
                total
            });
        });
    }
    group.finish();
}

criterion_group!(benches, anchor_step);
criterion_main!(benches);
