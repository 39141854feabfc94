//! Benchmarks of the simulator: the cost of one tracker frame for N cars (to compare with the
//! 100 ms a frame lasts at 10 Hz). Geometry queries are benchmarked in kpl-roads.
//!
//! Run: `cargo bench -p kpl-sim --bench sim`

use std::hint::black_box;
use std::sync::Arc;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use kpl_roads::scenarios::GridTownSize;
use kpl_sim::{Params, UavTrackerSim};

/// A grid town sized by `GridTownSize::for_cars` (about 11 cars per block).
fn town_params(n_cars: u32) -> Params {
    let size = GridTownSize::for_cars(n_cars);
    Params {
        scenario: "grid_town".into(),
        grid_blocks_x: size.blocks_x,
        grid_blocks_y: size.blocks_y,
        block_m: size.block_m,
        n_cars,
        dropout: 0.1,
        seed: 1,
        ..Params::default()
    }
}

fn frames(c: &mut Criterion) {
    let mut group = c.benchmark_group("frame");
    group.sample_size(20);
    for n_cars in [100u32, 1_000, 10_000] {
        let params = town_params(n_cars);
        let network = Arc::new(params.load_network().expect("built-in scenario"));
        let Ok(mut sim) = UavTrackerSim::new(&params, network, 0) else {
            panic!("{n_cars} cars do not fit the benchmark town");
        };
        // Let traffic settle (queues at crossings, cars leaving and entering).
        sim.frames_until(10_000_000);
        group.throughput(Throughput::Elements(u64::from(n_cars)));
        group.bench_function(BenchmarkId::new("cars", n_cars), |b| b.iter(|| black_box(sim.next_frame())));
    }
    group.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
