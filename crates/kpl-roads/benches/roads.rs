//! Benchmarks of road networks: geometry queries on a small and on a large network (to show that
//! they do not grow with the network), and reading a SUMO network of about 400 junctions.
//!
//! Run: `cargo bench -p kpl-roads --bench roads`

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use kpl_roads::RoadNetwork;
use kpl_roads::scenarios::{self, GridTownSize};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn random_points(net: &RoadNetwork, n: usize) -> Vec<[f64; 2]> {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (lo, hi) = net.bounds();
    (0..n).map(|_| [rng.random_range(lo[0]..hi[0]), rng.random_range(lo[1]..hi[1])]).collect()
}

fn queries(c: &mut Criterion) {
    let town = |blocks| {
        RoadNetwork::build(&scenarios::grid_town(GridTownSize {
            blocks_x: blocks,
            blocks_y: blocks,
            block_m: 100.0,
        }))
        .expect("built-in scenario")
    };
    // The same street pattern at 1 and at 100 times the size: the cost per query should not change.
    let (small, large) = (town(5), town(50));
    let mut group = c.benchmark_group("query");
    for (name, net) in [("town5x5", &small), ("town50x50", &large)] {
        // Points near roads, where queries have work to do: random points snapped, then shifted.
        let points: Vec<[f64; 2]> = random_points(net, 20_000)
            .into_iter()
            .filter_map(|p| net.snap_to_lane(p, None).map(|s| [s.point[0] + 1.0, s.point[1] - 1.0]))
            .take(1000)
            .collect();
        group.throughput(Throughput::Elements(points.len() as u64));
        group.bench_function(BenchmarkId::new("on_road", name), |b| {
            b.iter(|| points.iter().filter(|&&p| net.on_road(black_box(p))).count())
        });
        group.bench_function(BenchmarkId::new("snap_to_lane", name), |b| {
            b.iter(|| points.iter().filter_map(|&p| net.snap_to_lane(black_box(p), Some(0.3))).count())
        });
        let starts: Vec<_> = points.iter().filter_map(|&p| net.snap_to_lane(p, None)).collect();
        group.bench_function(BenchmarkId::new("advance_150m", name), |b| {
            b.iter(|| starts.iter().map(|s| net.advance(black_box(s), 150.0, 64).len()).sum::<usize>())
        });
    }
    group.finish();
}

/// Reading SUMO's 20 x 20 grid (400 junctions with traffic lights; `scripts/sumo-scenarios.py`
/// makes it), gzipped as shipped and from its text in memory; the baseline is decompressing the
/// file alone, measured in the same run.
fn load(c: &mut Criterion) {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic/sumo/town400/net.xml.gz");
    let text = kpl_roads::load::read_text(&path).expect("the shipped network");
    let mut group = c.benchmark_group("load_town400");
    group.sample_size(20);
    group.bench_function("gunzip_only", |b| {
        b.iter(|| kpl_roads::load::read_text(black_box(&path)).map(|t| t.len()))
    });
    group.bench_function("parse_and_index", |b| {
        b.iter(|| RoadNetwork::from_sumo_str(black_box(&text)).map(|n| n.lanes().len()))
    });
    group.bench_function("load_file", |b| {
        b.iter(|| RoadNetwork::load(black_box(&path)).map(|n| n.lanes().len()))
    });
    group.finish();
}

criterion_group!(benches, load, queries);
criterion_main!(benches);
